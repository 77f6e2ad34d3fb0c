// Synthetic RTI captures (rti_sim.h): a dome of lights over the painting seen straight down,
// relief shadows from the height-field tracer, handheld defects, noise and encoding.
#include "digitize_synth/rti_sim.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>

#include "digitize/height_field_tracer.h"
#include "digitize/image_io.h"
#include "digitize/photo_set.h"
#include "digitize/tangent_frame.h"
#include "digitize_synth/photo_sim.h"

namespace digitize::synth {
namespace {

constexpr double kDeg = kPi / 180;
constexpr double kGoldenAngleRad = 2.39996322972865332;
// The lowest elevation a jittered light may reach: below it the handheld light would graze the
// canvas, which no capture does on purpose.
constexpr double kMinTrueElevationDeg = 3;

uint64_t Mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// One stream per (purpose, image, row): the same numbers whatever thread draws them.
std::mt19937_64 Stream(uint64_t seed, uint64_t purpose, int image, int row) {
  uint64_t s = Mix(seed ^ 0x52544953494D0000ull ^ purpose);  // "RTISIM"
  s = Mix(s ^ (static_cast<uint64_t>(image) + 1) * 0x9E3779B97F4A7C15ull);
  s = Mix(s ^ (static_cast<uint64_t>(row) + 1) * 0x165667B19E3779F9ull);
  return std::mt19937_64(s);
}

double SrgbOetf(double x) {
  return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055;
}
uint8_t Code8(float linear) {
  const double x = std::clamp(static_cast<double>(linear), 0.0, 1.0);
  return static_cast<uint8_t>(std::lround(SrgbOetf(x) * 255.0));
}

Vec3d Nominal(int j, const RtiSimOptions& o) {
  const double s0 = std::sin(o.min_elevation_deg * kDeg), s1 = std::sin(o.max_elevation_deg * kDeg);
  const double se = s0 + (j + 0.5) / o.lights * (s1 - s0);
  const double ce = std::sqrt(std::max(0.0, 1 - se * se));
  const double az = j * kGoldenAngleRad;
  return {ce * std::cos(az), ce * std::sin(az), se};
}

}  // namespace

Status RtiSimOptions::Validate() const {
  if (lights < 1) return Error{"lights must be >= 1, got " + std::to_string(lights)};
  if (!(min_elevation_deg > 0 && max_elevation_deg <= 90 && min_elevation_deg <= max_elevation_deg))
    return Error{"light elevations must satisfy 0 < min <= max <= 90 deg, got " +
                 FormatNumber(min_elevation_deg) + " .. " + FormatNumber(max_elevation_deg)};
  if (!(std::isfinite(light_distance_mm) && light_distance_mm >= 0))
    return Error{"light_distance_mm must be >= 0 mm (0 = directional), got " +
                 FormatNumber(light_distance_mm)};
  if (!(std::isfinite(direction_jitter_deg) && direction_jitter_deg >= 0 &&
        direction_jitter_deg <= 20))
    return Error{"direction_jitter_deg must be in [0, 20] deg, got " +
                 FormatNumber(direction_jitter_deg)};
  if (!(std::isfinite(intensity_error) && intensity_error >= 0 && intensity_error < 1))
    return Error{"intensity_error must be in [0, 1), got " + FormatNumber(intensity_error)};
  if (!(std::isfinite(white_level) && white_level > 0))
    return Error{"white_level must be > 0 (linear), got " + FormatNumber(white_level)};
  if (!(std::isfinite(noise_sigma) && noise_sigma >= 0))
    return Error{"noise_sigma must be >= 0 (linear), got " + FormatNumber(noise_sigma)};
  return Status::Ok();
}

std::string SyntheticRtiCapture::Brief() const {
  size_t shadow = 0, total = 0;
  for (const auto& s : shadowed) {
    for (uint8_t v : s.data) shadow += v;
    total += s.size();
  }
  double lo = 1, hi = 1;
  if (!true_intensities.empty()) {
    lo = *std::min_element(true_intensities.begin(), true_intensities.end());
    hi = *std::max_element(true_intensities.begin(), true_intensities.end());
  }
  const int w = images.empty() ? 0 : images[0].width, h = images.empty() ? 0 : images[0].height;
  char b[256];
  std::snprintf(b, sizeof b,
                "%zu images %dx%d (%s, %s, jitter %g deg, e %.2f..%.2f), %.1f %% shadowed px, %zu "
                "saturated px; %.2f s",
                images.size(), w, h, options.encoding == RtiEncoding::kSrgb8 ? "srgb8" : "float",
                options.light_distance_mm > 0 ? "point lights" : "directional",
                options.direction_jitter_deg, lo, hi,
                total ? 100.0 * static_cast<double>(shadow) / static_cast<double>(total) : 0.0,
                saturated_pixels, render_seconds);
  return b;
}

SyntheticRtiCapture SimulateRti(const Painting& painting, const RtiSimOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const Status valid = options.Validate();
  DIGITIZE_CHECK(valid.ok(), "SimulateRti: invalid options: " + valid.message());
  const HeightField& field = painting.truth;
  const int w = field.width(), h = field.height();
  const int m = options.lights;

  SyntheticRtiCapture cap;
  cap.options = options;
  cap.pitch_mm = field.pitch_mm;
  cap.normals = painting.normals;
  cap.height_mm = field.height_mm;
  const std::vector<PaintMaterial> materials = DefaultPaintMaterials(false);
  cap.albedo = Grid<Vec3f>(w, h);
  for (size_t i = 0; i < cap.albedo.size(); ++i) {
    const auto& mat = materials[painting.region.data[i] % materials.size()];
    cap.albedo.data[i] = mat.lafortune.rho_d * static_cast<float>(kPi * options.white_level);
  }

  // Lights: nominal, jittered, intensities (mean 1).
  std::mt19937_64 rng = Stream(options.seed, 1, 0, 0);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  double sum_e = 0;
  for (int j = 0; j < m; ++j) {
    const Vec3d nom = Nominal(j, options);
    const TangentFrame f = MakeTangentFrame(nom);
    const double sigma = options.direction_jitter_deg * kDeg;
    Vec3d l = (nom + f.x * (sigma * normal(rng)) + f.y * (sigma * normal(rng))).normalized();
    const double min_z = std::sin(kMinTrueElevationDeg * kDeg);
    if (l.z() < min_z) {
      const double xy = std::hypot(l.x(), l.y());
      const double c = std::sqrt(1 - min_z * min_z) / xy;
      l = Vec3d(l.x() * c, l.y() * c, min_z);
    }
    cap.nominal_directions.push_back(nom);
    cap.true_directions.push_back(l);
    const double e = 1 + options.intensity_error * uniform(rng);
    cap.true_intensities.push_back(e);
    sum_e += e;
    char name[32];
    std::snprintf(name, sizeof name, "img_%03d.%s", j,
                  options.encoding == RtiEncoding::kSrgb8 ? "png" : "exr");
    cap.image_names.push_back(name);
  }
  for (double& e : cap.true_intensities) e *= m / sum_e;

  // Surface points of the texel centres (shadow-ray origins).
  std::vector<Vec3f> origins(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector2d c = field.TexelCentreMm(x, y);
      origins[field.height_mm.Index(x, y)] =
          Vec3f(static_cast<float>(c.x()), static_cast<float>(c.y()), field.height_mm(x, y));
    }
  const Vec3d centre(w * field.pitch_mm / 2, h * field.pitch_mm / 2, 0);
  const bool point = options.light_distance_mm > 0;
  Result<HeightFieldTracer> tracer = HeightFieldTracer::Build(field);
  DIGITIZE_CHECK(!options.shadows || tracer.ok(),
                 "SimulateRti: tracer: " + (tracer.ok() ? std::string() : tracer.error().message));

  const double white = options.white_level * kPi;  // E: albedo 1 at normal incidence -> white
  cap.images.resize(m);
  cap.shadowed.resize(m);
  std::vector<size_t> saturated(m, 0);
  for (int j = 0; j < m; ++j) {
    const Vec3d light_pos = centre + options.light_distance_mm * cap.true_directions[j];
    auto dir_at = [&](size_t i) -> Vec3d {
      if (!point) return cap.true_directions[j];
      return (light_pos - origins[i].cast<double>()).normalized();
    };
    Grid<uint8_t>& shadow = cap.shadowed[j];
    shadow = Grid<uint8_t>(w, h, 0);
    if (options.shadows) {
      std::vector<Vec3f> dirs(origins.size());
      std::vector<float> tfar(origins.size(), std::numeric_limits<float>::infinity());
      for (size_t i = 0; i < origins.size(); ++i) {
        dirs[i] = dir_at(i).cast<float>();
        if (point) tfar[i] = static_cast<float>((light_pos - origins[i].cast<double>()).norm());
      }
      tracer->Occluded(origins, dirs, tfar, shadow.data);
    }
    Grid<Vec3f>& img = cap.images[j];
    img = Grid<Vec3f>(w, h);
    std::vector<size_t> sat_rows(h, 0);
    tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& range) {
      for (int y = range.begin(); y < range.end(); ++y) {
        std::mt19937_64 noise_rng = Stream(options.seed, 2, j, y);
        std::normal_distribution<float> noise(0.0f, 1.0f);
        for (int x = 0; x < w; ++x) {
          const size_t i = img.Index(x, y);
          const Vec3d n = painting.normals.data[i].cast<double>();
          const Vec3d l = dir_at(i);
          const double nl = n.dot(l);
          Vec3f radiance = Vec3f::Zero();
          if (nl > 0 && !shadow.data[i]) {
            double e = white * cap.true_intensities[j];
            if (point) {
              const double ratio =
                  (light_pos - centre).norm() / (light_pos - origins[i].cast<double>()).norm();
              e *= ratio * ratio;
            }
            const auto& mat = materials[painting.region.data[i] % materials.size()];
            Vec3f f = mat.lafortune.rho_d;
            if (!options.lambertian) {
              const TangentFrame tf = MakeTangentFrame(n);
              f = mat.Evaluate(tf.ToLocal(Vec3d::UnitZ()).cast<float>(),
                               tf.ToLocal(l).cast<float>());
            }
            radiance = f * static_cast<float>(nl * e);
          }
          if (options.noise_sigma > 0) {
            for (int c = 0; c < 3; ++c)
              radiance[c] += static_cast<float>(options.noise_sigma) * noise(noise_rng);
          }
          if (options.encoding == RtiEncoding::kSrgb8) {
            bool sat = false;
            for (int c = 0; c < 3; ++c) {
              const uint8_t code = Code8(radiance[c]);
              sat |= code == 255;
              radiance[c] = SrgbToLinear(code / 255.0f);
            }
            sat_rows[y] += sat;
          }
          img.data[i] = radiance;
        }
      }
    });
    for (size_t s : sat_rows) saturated[j] += s;
  }
  for (size_t s : saturated) cap.saturated_pixels += s;
  cap.render_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return cap;
}

Status WriteSyntheticRti(const std::filesystem::path& dir, const SyntheticRtiCapture& capture) {
  std::error_code ec;
  std::filesystem::create_directories(dir / "truth", ec);
  if (ec) return Error{(dir / "truth").string() + ": cannot create: " + ec.message()};
  for (size_t j = 0; j < capture.images.size(); ++j) {
    const Grid<Vec3f>& img = capture.images[j];
    const auto path = dir / capture.image_names[j];
    Status s;
    if (capture.options.encoding == RtiEncoding::kSrgb8) {
      std::vector<uint8_t> codes(img.size() * 3);
      for (size_t i = 0; i < img.size(); ++i)
        for (int c = 0; c < 3; ++c) codes[i * 3 + c] = Code8(img.data[i][c]);
      s = WriteSrgbPng(path, img.width, img.height, 8, codes.data());
    } else {
      s = WriteFloatExr(path, img, {"R", "G", "B"});
    }
    if (!s.ok()) return s;
  }
  std::string lights = "# image, true direction x y z, true intensity; pitch_mm " +
                       FormatNumber(capture.pitch_mm, kRoundTripDigits) + "\n";
  for (size_t j = 0; j < capture.images.size(); ++j) {
    const Vec3d& d = capture.true_directions[j];
    char line[256];
    std::snprintf(line, sizeof line, "%s %.9f %.9f %.9f %.9f\n", capture.image_names[j].c_str(),
                  d.x(), d.y(), d.z(), capture.true_intensities[j]);
    lights += line;
  }
  if (Status s = WriteTextFile(dir / "truth" / "lights.txt", lights); !s.ok()) return s;
  const ImageMetadata meta = {
      {"digitize:pitch_mm", FormatNumber(capture.pitch_mm, kRoundTripDigits)}};
  if (Status s =
          WriteFloatExr(dir / "truth" / "normals.exr", capture.normals, {"X", "Y", "Z"}, meta);
      !s.ok())
    return s;
  if (Status s = WriteFloatExr(dir / "truth" / "height.exr", capture.height_mm, "Z", meta); !s.ok())
    return s;
  if (Status s = WriteFloatExr(dir / "truth" / "albedo.exr", capture.albedo, {"R", "G", "B"}, meta);
      !s.ok())
    return s;
  // Written last: its presence means the capture is complete.
  std::string lp = std::to_string(capture.images.size()) + "\n";
  for (size_t j = 0; j < capture.images.size(); ++j) {
    const Vec3d& d = capture.nominal_directions[j];
    char line[256];
    std::snprintf(line, sizeof line, "%s %.9f %.9f %.9f\n", capture.image_names[j].c_str(), d.x(),
                  d.y(), d.z());
    lp += line;
  }
  return WriteTextFile(dir / "dirs.lp", lp);
}

}  // namespace digitize::synth
