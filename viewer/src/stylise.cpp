#include "digitize_viewer/stylise.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numeric>
#include <random>
#include <string>

namespace digitize::viewer {
namespace {
constexpr double kPi = 3.14159265358979323846;
// Waves per channel: with 32 the cube showed a few dominant directions (a woven look).
constexpr int kWaves = 64;
}  // namespace

const char* ToString(Style s) {
  switch (s) {
    case Style::kRealistic:
      return "realistic";
    case Style::kWatercolor:
      return "watercolor";
    case Style::kBinary:
      return "binary";
    case Style::kCollage:
      return "collage";
    case Style::kHatching:
      return "hatching";
    case Style::kPainterly:
      return "painterly";
  }
  return "?";
}

Result<Style> ParseStyle(std::string_view name) {
  for (Style s : kAllStyles)
    if (name == ToString(s)) return s;
  return Error{"unknown style '" + std::string(name) +
               "' (realistic, watercolor, binary, collage, hatching, painterly)"};
}

ZoomCycle InfiniteZoom(double z_cam) {
  const double lz = std::log2(std::max(z_cam, 1e-6));
  ZoomCycle c;
  const double f = std::floor(lz);
  c.s = std::clamp(lz - f, 0.0, 1.0);
  c.scale = std::exp2(f);
  c.weights = {c.s / 2, 0.5 - c.s / 6, 1.0 / 3 - c.s / 6, 1.0 / 6 - c.s / 6};
  return c;
}

double ZoomCycle::ContrastGain() const {
  double sum2 = 0;
  for (double w : weights) sum2 += w * w;
  return 1.0 / std::sqrt(sum2);  // sum2 >= 1/4 (four weights summing to 1)
}

SolidTexture BuildSolidTexture(int size, uint64_t seed) {
  DIGITIZE_CHECK(
      size >= 8 && size <= 256 && (size & (size - 1)) == 0,
      "BuildSolidTexture: size must be a power of two in [8, 256], got " + std::to_string(size));
  SolidTexture t;
  t.size = size;
  const size_t n = size_t(size) * size * size;
  t.texels.assign(n, {0, 0, 0, 0});
  std::mt19937_64 rng(seed);
  std::vector<float> value(n);
  std::vector<uint32_t> order(n);
  for (int ch = 0; ch < 4; ++ch) {
    const auto [kmin, kmax] = SolidTexture::kBands[ch];
    std::fill(value.begin(), value.end(), 0.0f);
    std::uniform_int_distribution<int> comp(-kmax, kmax);
    std::uniform_real_distribution<double> phase(0, 2 * kPi);
    for (int wave = 0; wave < kWaves;) {
      const int kx = comp(rng), ky = comp(rng), kz = comp(rng);
      const double k = std::sqrt(double(kx * kx + ky * ky + kz * kz));
      if (k < kmin || k > kmax) continue;
      ++wave;
      // cos(2 pi k.x + phi) = Re(e^{i phi} e^{i 2 pi kx x} e^{i 2 pi ky y} e^{i 2 pi kz z}):
      // three tables per wave instead of a cosine per texel.
      std::vector<std::complex<double>> ex(size), ey(size), ez(size);
      for (int i = 0; i < size; ++i) {
        const double u = 2 * kPi * i / size;
        ex[i] = std::polar(1.0, kx * u);
        ey[i] = std::polar(1.0, ky * u);
        ez[i] = std::polar(1.0, kz * u);
      }
      const std::complex<double> p = std::polar(1.0, phase(rng));
      size_t idx = 0;
      for (int z = 0; z < size; ++z)
        for (int y = 0; y < size; ++y) {
          const std::complex<double> yz = p * ey[y] * ez[z];
          for (int x = 0; x < size; ++x) value[idx++] += float((yz * ex[x]).real());
        }
    }
    // Equalised: each value replaced by its rank, so the channel is uniform over [0, 255].
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(),
              [&](uint32_t a, uint32_t b) { return value[a] < value[b]; });
    for (size_t r = 0; r < n; ++r) t.texels[order[r]][ch] = uint8_t((r * 256) / n);
  }
  return t;
}

}  // namespace digitize::viewer
