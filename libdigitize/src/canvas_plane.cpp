// Plane fits of canvas extraction: the public PCA (FitPlanePca), the rough plane of step 1, the
// robust plane of step 4 and the noise estimate (canvas.cpp's header comment).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "canvas_steps.h"
#include "digitize/canvas.h"

namespace digitize {
namespace canvas_detail {
namespace {

// Fewer usable samples than this cannot define a canvas.
constexpr size_t kMinValidSamples = 100;

// Plane fits use a regular subsample of about this many samples (the rough one of the whole
// scan, the robust ones of the canvas): their error stays far below the noise's.
constexpr size_t kRoughSamples = 1000000;
constexpr size_t kFitSamples = 1000000;
// Robust refit: iterations, and the lower trim (outliers below the canvas) in multiples of the
// upper one (relief above).
constexpr int kTrimIterations = 3;
constexpr double kLowerTrimFactor = 2.0;
// Regular subsamples for medians: residuals (MAD), noise (a MAD to better than 1 %), spacing.
constexpr size_t kStatSamples = 250000;
constexpr size_t kNoiseSamples = 100000;
constexpr size_t kSpacingSamples = 50000;

// First and second moments about a fixed shift (keeps the covariance well conditioned).
struct Moments {
  double n = 0;
  double sx = 0, sy = 0, sz = 0;
  double sxx = 0, sxy = 0, sxz = 0, syy = 0, syz = 0, szz = 0;
  void Add(double x, double y, double z) {
    n += 1;
    sx += x, sy += y, sz += z;
    sxx += x * x, sxy += x * y, sxz += x * z;
    syy += y * y, syz += y * z, szz += z * z;
  }
  void Merge(const Moments& o) {
    n += o.n;
    sx += o.sx, sy += o.sy, sz += o.sz;
    sxx += o.sxx, sxy += o.sxy, sxz += o.sxz;
    syy += o.syy, syz += o.syz, szz += o.szz;
  }
  Vec3d Sum() const { return {sx, sy, sz}; }
  Mat3d SecondMoments() const {
    Mat3d m;
    m << sxx, sxy, sxz, sxy, syy, syz, sxz, syz, szz;
    return m;
  }
};

PlaneFit PlaneFromMoments(const Moments& m, const Vec3d& shift) {
  PlaneFit fit;
  fit.count = static_cast<size_t>(m.n);
  if (m.n < 1) return fit;
  const Vec3d mean = m.Sum() / m.n;
  fit.centroid = shift + mean;
  Mat3d cov = m.SecondMoments() / m.n - mean * mean.transpose();
  cov = 0.5 * (cov + cov.transpose());
  Eigen::SelfAdjointEigenSolver<Mat3d> solver(cov);
  if (solver.info() != Eigen::Success) return fit;
  const Vec3d ev = solver.eigenvalues();  // ascending
  const Mat3d vec = solver.eigenvectors();
  Vec3d major = vec.col(2), minor = vec.col(1), normal = vec.col(0);
  if (normal.z() > 0) normal = -normal;  // towards a scanner looking along +Z
  if (major.cross(minor).dot(normal) < 0) minor = -minor;
  fit.axes.col(0) = major;
  fit.axes.col(1) = minor;
  fit.axes.col(2) = normal;
  fit.eigenvalues = Vec3d(std::max(ev(2), 0.0), std::max(ev(1), 0.0), std::max(ev(0), 0.0));
  return fit;
}

// PCA of the usable scan samples for which pred(x, y, p) holds; rows in parallel.
// PCA of the usable scan samples on every `stride`-th row and column for which pred(x, y, p)
// holds; rows in parallel, moments in double about `shift`.
template <class Pred>
PlaneFit FitGrid(const Grid<Vec3f>& xyz, const Vec3d& shift, int stride, const Pred& pred) {
  const int rows_sampled = (xyz.height + stride - 1) / stride;
  // Deterministic reduction (fixed split): the same scan gives the same plane, bit for bit.
  const Moments m = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<int>(0, rows_sampled, 16), Moments{},
      [&](const tbb::blocked_range<int>& rows, Moments acc) {
        for (int r = rows.begin(); r < rows.end(); ++r) {
          const int y = r * stride;
          const Vec3f* row = xyz.Row(y);
          Moments line;
          for (int x = 0; x < xyz.width; x += stride) {
            const Vec3f& p = row[x];
            if (!Usable(p) || !pred(x, y, p)) continue;
            line.Add(p.x() - shift.x(), p.y() - shift.y(), p.z() - shift.z());
          }
          acc.Merge(line);
        }
        return acc;
      },
      [](Moments a, const Moments& b) {
        a.Merge(b);
        return a;
      });
  return PlaneFromMoments(m, shift);
}

// PCA of the points for which pred(p) holds; in parallel, moments in double about `shift`.
template <class Pred>
PlaneFit FitPoints(const std::vector<Vec3f>& points, const Vec3d& shift, const Pred& pred) {
  const Eigen::Vector3f shift_f = shift.cast<float>();
  const Vec3d shift_used = shift_f.cast<double>();
  const Moments m = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<size_t>(0, points.size(), 1 << 14), Moments{},
      [&](const tbb::blocked_range<size_t>& r, Moments acc) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const Vec3f& p = points[i];
          if (!pred(p)) continue;
          // Float subtraction of nearby values is exact to the data's own precision.
          const Eigen::Vector3f d = p - shift_f;
          acc.Add(d.x(), d.y(), d.z());
        }
        return acc;
      },
      [](Moments a, const Moments& b) {
        a.Merge(b);
        return a;
      });
  return PlaneFromMoments(m, shift_used);
}

}  // namespace

Result<PlaneFit> FitRoughPlane(const Grid<Vec3f>& xyz, const std::string& src) {
  const int w = xyz.width, h = xyz.height;
  // Moments about the first usable sample at or after the centre keep the covariance well
  // conditioned; the rough plane needs only a regular subsample.
  Vec3d shift = Vec3d::Zero();
  {
    const size_t total = xyz.size(), start = total / 2;
    for (size_t k = 0; k < total; ++k) {
      const Vec3f& p = xyz.data[(start + k) % total];
      if (Usable(p)) {
        shift = p.cast<double>();
        break;
      }
    }
  }
  const auto all = [](int, int, const Vec3f&) { return true; };
  const int rough_stride = SampleStride(xyz.size(), kRoughSamples);
  PlaneFit rough = FitGrid(xyz, shift, rough_stride, all);
  if (rough_stride > 1 && rough.count < kRoughSamples / 100) rough = FitGrid(xyz, shift, 1, all);
  if (rough.count < kMinValidSamples)
    return Error{src + ": only " + std::to_string(rough.count) + " valid samples in a " +
                 std::to_string(w) + "x" + std::to_string(h) + " scan (at least " +
                 std::to_string(kMinValidSamples) + " needed to find a canvas)"};
  if (!(rough.eigenvalues(1) > 1e-9 * rough.eigenvalues(0)) || !(rough.eigenvalues(0) > 0))
    return Error{src + ": the valid samples are (nearly) collinear; a " + std::to_string(w) + "x" +
                 std::to_string(h) + " scan does not span a canvas plane"};
  return rough;
}

cv::Mat PlaneFitMask(const GrownRegion& region, const CanvasOptions& options) {
  const cv::Mat& filled = region.filled;
  const cv::Mat& valid = region.valid;
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
  cv::Mat fit_mask;
  if (options.erode_px > 0)
    cv::erode(filled, fit_mask, kernel, cv::Point(-1, -1), options.erode_px);
  else
    fit_mask = filled.clone();
  cv::bitwise_and(fit_mask, valid, fit_mask);  // valid is 0/1: nonzero where valid
  if (static_cast<size_t>(cv::countNonZero(fit_mask)) < kMinValidSamples)
    cv::bitwise_and(filled, valid, fit_mask);  // tiny canvas: fit on all of it
  return fit_mask;
}

Result<CanvasPlane> FitCanvasPlane(const Grid<Vec3f>& xyz, const GrownRegion& region,
                                   const PlaneFit& rough, const CanvasOptions& options,
                                   const std::string& src) {
  const int w = xyz.width, h = xyz.height;
  cv::Mat fit_mask = PlaneFitMask(region, options);
  const size_t fit_mask_count = static_cast<size_t>(cv::countNonZero(fit_mask));
  // The fit samples, gathered once (a regular subsample of the eroded canvas).
  std::vector<Vec3f> fit_points;
  {
    const int stride = SampleStride(fit_mask_count, kFitSamples);
    const int rows_sampled = (h + stride - 1) / stride;
    std::vector<std::vector<Vec3f>> per_row(static_cast<size_t>(rows_sampled));
    tbb::parallel_for(tbb::blocked_range<int>(0, rows_sampled),
                      [&](const tbb::blocked_range<int>& r) {
                        for (int i = r.begin(); i < r.end(); ++i) {
                          const int y = i * stride;
                          const uint8_t* m = fit_mask.ptr<uint8_t>(y);
                          const Vec3f* row = xyz.Row(y);
                          for (int x = 0; x < w; x += stride)
                            if (m[x] && Usable(row[x]))
                              per_row[static_cast<size_t>(i)].push_back(row[x]);
                        }
                      });
    size_t total = 0;
    for (const auto& v : per_row) total += v.size();
    fit_points.reserve(total);
    for (const auto& v : per_row) fit_points.insert(fit_points.end(), v.begin(), v.end());
  }
  PlaneFit plane = FitPoints(fit_points, rough.centroid, [](const Vec3f&) { return true; });
  if (plane.count < 3)
    return Error{src + ": too few canvas samples (" + std::to_string(plane.count) +
                 ") to fit the canvas plane"};
  const size_t residual_step = std::max<size_t>(1, fit_points.size() / kStatSamples);
  for (int it = 0; it < kTrimIterations; ++it) {
    const Eigen::Vector3f c = plane.centroid.cast<float>(), n = plane.axes.col(2).cast<float>();
    std::vector<double> r;
    r.reserve(fit_points.size() / residual_step + 1);
    for (size_t i = 0; i < fit_points.size(); i += residual_step)
      r.push_back(n.dot(fit_points[i] - c));
    if (r.size() < 3) break;
    std::vector<double> tmp = r;
    const double med = Median(tmp);
    const double sigma = std::max(kMadToSigma * Mad(r, med), 1e-6);
    const float hi = static_cast<float>(med + options.trim_sigmas * sigma);
    const float lo = static_cast<float>(med - kLowerTrimFactor * options.trim_sigmas * sigma);
    PlaneFit next = FitPoints(fit_points, plane.centroid, [&](const Vec3f& p) {
      const float d = n.dot(p - c);
      return d >= lo && d <= hi;
    });
    if (next.count < 3 || !(next.eigenvalues(1) > 0)) break;
    plane = next;
  }
  return CanvasPlane{fit_mask, fit_mask_count, plane};
}

// Noise: Immerkaer's mask [1 -2 1; -2 4 -2; 1 -2 1] (a product of second differences, blind to
// planes and to curvature along x or y) has a response of 6 sigma on white noise.
double EstimateNoiseSigma(const Grid<Vec3f>& xyz, const cv::Mat& fit_mask, size_t fit_mask_count,
                          const LocalFrame& frame) {
  const int w = xyz.width, h = xyz.height;
  double noise_sigma = 0;
  {
    std::vector<double> resp;
    const int noise_stride = SampleStride(fit_mask_count, kNoiseSamples);
    for (int y = 1; y + 1 < h; y += noise_stride) {
      const uint8_t* m = fit_mask.ptr<uint8_t>(y);
      for (int x = 1; x + 1 < w; x += noise_stride) {
        if (!m[x]) continue;
        static constexpr float k[3][3] = {{1, -2, 1}, {-2, 4, -2}, {1, -2, 1}};
        double acc = 0;
        bool ok = true;
        for (int j = -1; j <= 1 && ok; ++j)
          for (int i = -1; i <= 1; ++i) {
            const Vec3f& p = xyz(x + i, y + j);
            if (!Usable(p)) {
              ok = false;
              break;
            }
            acc += k[j + 1][i + 1] * frame.H(p);
          }
        if (ok) resp.push_back(acc);
      }
    }
    if (!resp.empty()) {
      std::vector<double> tmp = resp;
      const double med = Median(tmp);
      noise_sigma = kMadToSigma * Mad(resp, med) / 6.0;
    }
  }
  return noise_sigma;
}

}  // namespace canvas_detail

PlaneFit FitPlanePca(const std::vector<Vec3d>& points) {
  using canvas_detail::Moments;
  using canvas_detail::PlaneFromMoments;
  // Shift by the first finite point so the second moments stay small.
  Vec3d shift = Vec3d::Zero();
  for (const Vec3d& p : points)
    if (p.allFinite()) {
      shift = p;
      break;
    }
  const Moments m = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<size_t>(0, points.size(), 4096), Moments{},
      [&](const tbb::blocked_range<size_t>& r, Moments acc) {
        for (size_t i = r.begin(); i < r.end(); ++i)
          if (points[i].allFinite()) {
            const Vec3d d = points[i] - shift;
            acc.Add(d.x(), d.y(), d.z());
          }
        return acc;
      },
      [](Moments a, const Moments& b) {
        a.Merge(b);
        return a;
      });
  return PlaneFromMoments(m, shift);
}

}  // namespace digitize
