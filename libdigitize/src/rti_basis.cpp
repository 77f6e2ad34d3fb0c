// The classical RTI bases fitted by one shared pseudo-inverse (rti_basis.h). One TBB task per
// band of rows: the band's values (images x (pixels x 3)) are gathered into one matrix and
// multiplied by the pseudo-inverse, so the work is a handful of large matrix products.
#include "digitize/rti_basis.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <string>

namespace digitize {
namespace {

// relight clamps the polar angle short of the horizon (src/rti.cpp): b1, b3 have an infinite
// slope there (sqrt(t - t^2)), and a grazing light would swing the fit.
constexpr double kHshMaxThetaRad = kPi / 2 - 0.01;

double LinearToSrgbD(double c) {
  if (c < 0) return -LinearToSrgbD(-c);
  return c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
}

template <class F>
void RunWithThreads(int num_threads, F&& f) {
  if (num_threads > 0) {
    tbb::task_arena arena(num_threads);
    arena.execute(f);
  } else {
    f();
  }
}

}  // namespace

const char* ToString(RtiBasis basis) {
  switch (basis) {
    case RtiBasis::kPtm:
      return "ptm";
    case RtiBasis::kHsh2:
      return "hsh2";
    case RtiBasis::kHsh3:
      return "hsh3";
  }
  return "?";
}

Result<RtiBasis> ParseRtiBasis(std::string_view name) {
  std::string lower(name);
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (lower == "ptm") return RtiBasis::kPtm;
  if (lower == "hsh2") return RtiBasis::kHsh2;
  if (lower == "hsh3" || lower == "hsh") return RtiBasis::kHsh3;
  return Error{"unknown RTI basis '" + std::string(name) + "' (ptm, hsh2, hsh3)"};
}

int RtiCoefficientCount(RtiBasis basis) {
  switch (basis) {
    case RtiBasis::kPtm:
      return 6;
    case RtiBasis::kHsh2:
      return 4;
    case RtiBasis::kHsh3:
      return 9;
  }
  return 0;
}

std::array<double, kMaxRtiCoefficients> RtiBasisWeights(RtiBasis basis, const Vec3d& light) {
  std::array<double, kMaxRtiCoefficients> w{};
  const double norm = light.norm();
  const Vec3d l = norm > 0 ? Vec3d(light / norm) : Vec3d::UnitZ();
  if (basis == RtiBasis::kPtm) {
    const double u = l.x(), v = l.y();
    w = {u * u, v * v, u * v, u, v, 1.0, 0, 0, 0};
    return w;
  }
  double phi = std::atan2(l.y(), l.x());
  if (phi < 0) phi += 2 * kPi;
  const double theta = std::min(std::acos(std::clamp(l.z(), -1.0, 1.0)), kHshMaxThetaRad);
  const double t = std::cos(theta), t2 = t * t;
  const double s = std::sqrt(std::max(0.0, t - t2));
  const double cp = std::cos(phi), sp = std::sin(phi);
  w[0] = 1.0 / std::sqrt(2 * kPi);
  w[1] = std::sqrt(6 / kPi) * cp * s;
  w[2] = std::sqrt(3 / (2 * kPi)) * (2 * t - 1);
  w[3] = std::sqrt(6 / kPi) * sp * s;
  if (basis == RtiBasis::kHsh3) {
    w[4] = std::sqrt(30 / kPi) * std::cos(2 * phi) * (t2 - t);
    w[5] = std::sqrt(30 / kPi) * cp * (2 * t - 1) * s;
    w[6] = std::sqrt(5 / (2 * kPi)) * (6 * t2 - 6 * t + 1);
    w[7] = std::sqrt(30 / kPi) * sp * (2 * t - 1) * s;
    w[8] = std::sqrt(30 / kPi) * std::sin(2 * phi) * (t2 - t);
  }
  return w;
}

Status RtiFitOptions::Validate() const {
  if (!std::isfinite(ridge) || ridge < 0)
    return Error{"ridge must be finite and >= 0, got " + std::to_string(ridge)};
  if (num_threads < 0)
    return Error{"num_threads must be >= 0 (0 = all cores), got " + std::to_string(num_threads)};
  return Status::Ok();
}

uint8_t ToSrgb8(float value, ColourEncoding encoding) {
  double v = std::isfinite(value) ? std::clamp(static_cast<double>(value), 0.0, 1.0) : 0.0;
  if (encoding != ColourEncoding::kSrgb) v = LinearToSrgbD(v);
  return static_cast<uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255.0));
}

Result<RtiFit> FitRti(const PhotoSet& photos, const RtiFitOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{"RTI fit: " + s.message()};
  const std::string set_name = photos.source.string();
  const int n = RtiCoefficientCount(options.basis);
  const int images = static_cast<int>(photos.photos.size());
  if (images < n) {
    return Error{set_name + ": " + std::to_string(images) + " photos, the " +
                 ToString(options.basis) + " basis needs at least " + std::to_string(n)};
  }
  const int width = photos.photos[0].rgb.width, height = photos.photos[0].rgb.height;
  RtiFit fit;
  fit.basis = options.basis;
  fit.srgb = options.fit_in_srgb;
  for (const Photo& photo : photos.photos) {
    const std::string what = photo.entry + " (" + photo.path.string() + ")";
    if (!photo.loaded()) return Error{what + ": pixels not loaded"};
    if (photo.rgb.width != width || photo.rgb.height != height) {
      return Error{what + ": " + std::to_string(photo.rgb.width) + "x" +
                   std::to_string(photo.rgb.height) + " pixels, the first photo has " +
                   std::to_string(width) + "x" + std::to_string(height)};
    }
    if (photo.light.type != LightType::kDirectional)
      return Error{what + ": an RTI fit needs directional lights, this one is a point light"};
    const Vec3d& d = photo.light.direction;
    if (!IsValid(d.cast<float>()) || d.norm() == 0)
      return Error{what + ": light direction is not a finite non-zero vector"};
    if (d.z() <= 0) {
      return Error{what + ": light at or below the horizon (direction z = " +
                   std::to_string(d.z() / d.norm()) + "), which an RTI basis cannot fit"};
    }
    fit.lights.push_back(d.normalized());
  }
  const auto t0 = std::chrono::steady_clock::now();

  Eigen::MatrixXd basis(images, n);
  for (int i = 0; i < images; ++i) {
    const auto w = RtiBasisWeights(options.basis, fit.lights[i]);
    for (int k = 0; k < n; ++k) basis(i, k) = w[k];
  }
  Eigen::MatrixXd normal = basis.transpose() * basis;
  const double lambda = options.ridge * normal.trace() / n;
  normal.diagonal().array() += lambda;
  // Rank-revealing, so a set whose lights leave a direction of the basis unseen (all lights on
  // one ring, say) is refused instead of fitted with huge cancelling coefficients.
  const Eigen::FullPivLU<Eigen::MatrixXd> lu(normal);
  if (lu.rank() < n || lu.rcond() < 1e-12) {
    return Error{set_name + ": the " + std::to_string(images) +
                 " light directions do not "
                 "determine the " +
                 ToString(options.basis) + " basis (condition number " +
                 std::to_string(1.0 / std::max(lu.rcond(), 1e-300)) +
                 "); spread the lights "
                 "more or raise the ridge"};
  }
  const Eigen::MatrixXf pinv = lu.solve(basis.transpose()).cast<float>();  // n x images

  fit.width = width;
  fit.height = height;
  fit.coefficients.assign(static_cast<size_t>(width) * height * 3 * n, 0.0f);
  std::atomic<bool> non_finite{false};
  const bool srgb = options.fit_in_srgb;
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(
        tbb::blocked_range<int>(0, height, 8), [&](const tbb::blocked_range<int>& rows) {
          const int cols = (rows.end() - rows.begin()) * width * 3;
          Eigen::MatrixXf values(images, cols);
          for (int i = 0; i < images; ++i) {
            const float* src = photos.photos[i].rgb.Row(rows.begin())->data();
            for (int j = 0; j < cols; ++j)
              values(i, j) = srgb ? static_cast<float>(LinearToSrgbD(src[j])) : src[j];
          }
          // Column j of the product holds the n coefficients of value j (pixel, channel): exactly
          // the [pixel][channel][coefficient] layout, so it is copied as one block.
          Eigen::Map<Eigen::MatrixXf> out(
              fit.coefficients.data() + static_cast<size_t>(rows.begin()) * width * 3 * n, n, cols);
          out.noalias() = pinv * values;
          if (!out.allFinite()) non_finite = true;
        });
  });
  if (non_finite) return Error{set_name + ": the RTI fit produced non-finite coefficients"};
  fit.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return fit;
}

Grid<Vec3f> RelightRti(const RtiFit& fit, const Vec3d& light, int num_threads) {
  DIGITIZE_CHECK(
      fit.coefficients.size() == static_cast<size_t>(fit.width) * fit.height * 3 * fit.count(),
      "RtiFit coefficients do not match its size");
  Grid<Vec3f> out(fit.width, fit.height);
  if (!(light.z() > 0) || !IsValid(light.cast<float>())) return out;
  const auto wd = RtiBasisWeights(fit.basis, light);
  const int n = fit.count();
  Eigen::Matrix<float, 1, Eigen::Dynamic> w(n);
  for (int k = 0; k < n; ++k) w[k] = static_cast<float>(wd[k]);
  RunWithThreads(num_threads, [&] {
    tbb::parallel_for(
        tbb::blocked_range<int>(0, fit.height, 8), [&](const tbb::blocked_range<int>& rows) {
          const int cols = (rows.end() - rows.begin()) * fit.width * 3;
          Eigen::Map<const Eigen::MatrixXf> c(fit.At(0, rows.begin(), 0), n, cols);
          Eigen::Map<Eigen::Matrix<float, 1, Eigen::Dynamic>> dst(out.Row(rows.begin())->data(),
                                                                  cols);
          dst.noalias() = w * c;
          dst = dst.array().isFinite().select(dst, 0.0f).cwiseMax(0.0f).cwiseMin(1.0f);
        });
  });
  return out;
}

Status Srgb8PsnrAccumulator::Add(const Grid<Vec3f>& test, ColourEncoding test_encoding,
                                 const Grid<Vec3f>& reference, ColourEncoding reference_encoding,
                                 const Grid<uint8_t>& mask, const std::string& what) {
  if (test.width != reference.width || test.height != reference.height) {
    return Error{what + ": test image is " + std::to_string(test.width) + "x" +
                 std::to_string(test.height) + ", reference " + std::to_string(reference.width) +
                 "x" + std::to_string(reference.height)};
  }
  if (!mask.empty() && (mask.width != test.width || mask.height != test.height))
    return Error{what + ": mask size differs from the image's"};
  double sum = 0;
  size_t pixels = 0;
  for (size_t i = 0; i < test.size(); ++i) {
    if (!mask.empty() && mask.data[i] == 0) continue;
    for (int c = 0; c < 3; ++c) {
      const double d = static_cast<double>(ToSrgb8(test.data[i][c], test_encoding)) -
                       static_cast<double>(ToSrgb8(reference.data[i][c], reference_encoding));
      sum += d * d;
    }
    ++pixels;
  }
  sum_squared_ += sum;
  pixels_ += pixels;
  ++images_;
  return Status::Ok();
}

Srgb8Score Srgb8PsnrAccumulator::Score() const {
  Srgb8Score s;
  s.pixels = pixels_;
  s.images = images_;
  if (pixels_ == 0) return s;
  s.mse = sum_squared_ / (3.0 * static_cast<double>(pixels_));
  s.psnr_db = s.mse > 0 ? 10.0 * std::log10(255.0 * 255.0 / s.mse)
                        : std::numeric_limits<double>::infinity();
  return s;
}

}  // namespace digitize
