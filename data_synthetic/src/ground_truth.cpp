// Accuracy of a preprocessing result, and of a patch registration, against the generator's
// ground truth (ground_truth.h).
#include "digitize_synth/ground_truth.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace digitize::synth {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kMinReliefMm = 1e-3;  // below any scanner's resolution

// Bilinear lookup on the truth grid at canvas-frame (X, Y); false off the canvas.
struct TruthSampler {
  const HeightField& field;
  const Grid<Vec3f>& normals;

  bool Sample(double X, double Y, double& height_mm, Vec3d* normal) const {
    const int w = field.width(), h = field.height();
    Eigen::Vector2d t = field.TexelFromMm(X, Y);
    // The canvas spans half a texel beyond the outer texel centres.
    if (!(t.x() >= -0.5 && t.x() <= w - 0.5 && t.y() >= -0.5 && t.y() <= h - 0.5)) return false;
    double tx = std::clamp(t.x(), 0.0, w - 1.0), ty = std::clamp(t.y(), 0.0, h - 1.0);
    int x0 = std::min(static_cast<int>(tx), std::max(0, w - 2));
    int y0 = std::min(static_cast<int>(ty), std::max(0, h - 2));
    int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
    double fx = tx - x0, fy = ty - y0;
    auto mix = [&](const auto& a, const auto& b, const auto& c, const auto& d) {
      return (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * c + fx * d);
    };
    const Grid<float>& hm = field.height_mm;
    height_mm = mix(double(hm(x0, y0)), double(hm(x1, y0)), double(hm(x0, y1)), double(hm(x1, y1)));
    if (normal) {
      Vec3d n = mix(normals(x0, y0).cast<double>(), normals(x1, y0).cast<double>(),
                    normals(x0, y1).cast<double>(), normals(x1, y1).cast<double>());
      *normal = n.normalized();
    }
    return true;
  }
};

// Median and a higher quantile of a sample (reorders it); NaN when empty.
double Quantile(std::vector<float>& v, double q) {
  if (v.empty()) return kNaN;
  size_t k =
      std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

PreprocessAccuracy MeasureAccuracy(const PreprocessResult& result, const Painting& painting,
                                   const SyntheticScan& scan, const AccuracyOptions& options) {
  PreprocessAccuracy acc;
  const RigidTransform& truth_cfs = scan.canvas_from_scan;
  const RigidTransform& est_cfs = result.canvas.canvas_from_scan;
  const RigidTransform truth_from_est = truth_cfs * est_cfs.Inverse();
  const RigidTransform est_from_truth = truth_from_est.Inverse();

  // Canvas plane: the Z axis of a canvas frame, seen from the scan frame, is the rotation's row 2.
  acc.normal_error_deg =
      AngleDeg(est_cfs.rotation.row(2).transpose(), truth_cfs.rotation.row(2).transpose());

  {
    const Vec3d x_est = truth_from_est.rotation.col(0);
    acc.axis_error_deg =
        std::abs(std::atan2(x_est.y(), x_est.x())) * 180.0 / 3.14159265358979323846;
    const Eigen::Vector2d visible = scan.visible_max_mm - scan.visible_min_mm;
    acc.extent_error_mm = (result.canvas.extent_mm - visible).cwiseAbs().maxCoeff();
    acc.bare_plane_tilt_deg = AngleDeg(est_cfs.rotation.row(2).transpose(),
                                       truth_cfs.rotation.transpose() * painting.bare_plane_normal);
  }

  // Mask in scan pixels.
  const Grid<uint8_t>& est_mask = result.canvas.mask_scan;
  const Grid<uint8_t>& true_mask = scan.canvas_mask_scan;
  if (est_mask.width == true_mask.width && est_mask.height == true_mask.height) {
    size_t inter = 0, uni = 0;
    for (size_t i = 0; i < true_mask.size(); ++i) {
      bool e = est_mask.data[i] != 0, t = true_mask.data[i] != 0;
      inter += e && t;
      uni += e || t;
      uint8_t hit = scan.hit_scan.data[i];
      if (e && (hit == static_cast<uint8_t>(Scene::Hit::kFrame) ||
                hit == static_cast<uint8_t>(Scene::Hit::kWall))) {
        ++acc.frame_pixels_kept;
        // How far above the true canvas plane the kept frame sample lies (first exposure, noisy):
        // a wall-foot sample within the noise of the plane cannot be told from canvas.
        const Vec3f& p = scan.exposures.front().xyz_mm.data[i];
        if (IsValid(p)) {
          const double z = truth_cfs.Apply(p.cast<double>()).z();
          acc.frame_pixels_max_height_mm = std::max(acc.frame_pixels_max_height_mm, std::abs(z));
        }
      }
    }
    acc.mask_iou = uni == 0 ? 1.0 : static_cast<double>(inter) / static_cast<double>(uni);
  } else {
    acc.mask_iou = 0;
  }

  // Heights and normals of the estimate, mapped into the truth frame.
  const HeightField& est = result.field;
  const TruthSampler truth{painting.truth, painting.normals};
  const bool have_normals = result.normals.width == est.width() &&
                            result.normals.height == est.height() && !result.normals.empty();
  const float nan_f = std::numeric_limits<float>::quiet_NaN();
  Grid<float> height_err(est.width(), est.height(), nan_f);
  Grid<float> normal_err(est.width(), est.height(), nan_f);
  tbb::parallel_for(
      tbb::blocked_range<int>(0, est.height(), 16), [&](const tbb::blocked_range<int>& r) {
        for (int y = r.begin(); y < r.end(); ++y) {
          for (int x = 0; x < est.width(); ++x) {
            if (!HasHeight(est.state(x, y))) continue;
            Eigen::Vector2d c = est.TexelCentreMm(x, y);
            Vec3d p = truth_from_est.Apply(Vec3d(c.x(), c.y(), est.height_mm(x, y)));
            double true_h;
            Vec3d true_n;
            if (!truth.Sample(p.x(), p.y(), true_h, &true_n)) continue;
            height_err(x, y) = static_cast<float>((p.z() - true_h) * true_n.z());
            if (!have_normals || x == 0 || y == 0 || x == est.width() - 1 || y == est.height() - 1)
              continue;
            bool full = true;
            for (int dy = -1; dy <= 1 && full; ++dy)
              for (int dx = -1; dx <= 1 && full; ++dx) full = HasHeight(est.state(x + dx, y + dy));
            if (!full) continue;
            Vec3d n = truth_from_est.ApplyToDirection(result.normals(x, y).cast<double>());
            normal_err(x, y) = static_cast<float>(AngleDeg(n, true_n));
          }
        }
      });
  std::vector<float> errors, angles;
  for (float e : height_err.data)
    if (std::isfinite(e)) errors.push_back(e);
  for (float a : normal_err.data)
    if (std::isfinite(a)) angles.push_back(a);
  acc.texels_compared = errors.size();
  acc.normals_compared = angles.size();
  if (errors.empty()) {
    acc.height_offset_mm = acc.height_rmse_mm = kNaN;
  } else {
    std::vector<float> sorted = errors;
    acc.height_offset_mm = Quantile(sorted, 0.5);
    double sum2 = 0;
    for (float e : errors) sum2 += (e - acc.height_offset_mm) * (e - acc.height_offset_mm);
    acc.height_rmse_mm = std::sqrt(sum2 / static_cast<double>(errors.size()));
  }
  acc.normals_median_deg = Quantile(angles, 0.5);
  acc.normals_p90_deg = Quantile(angles, 0.9);

  // Relief coverage: true relief above the estimate's bump plane, specks removed, must be boxed.
  const HeightField& tf = painting.truth;
  Grid<uint8_t> above(tf.width(), tf.height(), 0);
  Grid<Eigen::Vector2f> in_est(tf.width(), tf.height(),
                               Eigen::Vector2f::Zero());  // estimate texel coordinates
  // A bump plane at or below zero (an estimate that found no relief) must not turn float
  // rounding on a flat canvas into "relief": nothing under a micrometre counts.
  const double delta0 = std::max(result.relief.delta0_mm, kMinReliefMm);
  tbb::parallel_for(tbb::blocked_range<int>(0, tf.height(), 16),
                    [&](const tbb::blocked_range<int>& r) {
                      for (int y = r.begin(); y < r.end(); ++y) {
                        for (int x = 0; x < tf.width(); ++x) {
                          Eigen::Vector2d c = tf.TexelCentreMm(x, y);
                          Vec3d p = est_from_truth.Apply(Vec3d(c.x(), c.y(), tf.height_mm(x, y)));
                          above(x, y) = p.z() > delta0 ? 1 : 0;
                          in_est(x, y) = est.TexelFromMm(p.x(), p.y()).cast<float>();
                        }
                      }
                    });
  cv::Mat above_mat(tf.height(), tf.width(), CV_8U, above.data.data());
  cv::Mat labels, stats, centroids;
  int n_labels = cv::connectedComponentsWithStats(above_mat, labels, stats, centroids, 8, CV_32S);
  const double texel_area_mm2 = tf.pitch_mm * tf.pitch_mm;
  std::vector<uint8_t> keep(static_cast<size_t>(std::max(n_labels, 1)), 0);
  for (int l = 1; l < n_labels; ++l)
    keep[static_cast<size_t>(l)] =
        stats.at<int>(l, cv::CC_STAT_AREA) * texel_area_mm2 >= options.min_component_area_mm2;

  Grid<uint8_t> boxed(est.width(), est.height(), 0);
  for (const ReliefBox& b : result.relief.boxes)
    for (int y = std::max(0, b.y0); y < std::min(est.height(), b.y0 + b.height); ++y)
      for (int x = std::max(0, b.x0); x < std::min(est.width(), b.x0 + b.width); ++x)
        boxed(x, y) = 1;

  for (int y = 0; y < tf.height(); ++y) {
    const int* row = labels.ptr<int>(y);
    for (int x = 0; x < tf.width(); ++x) {
      if (!keep[static_cast<size_t>(row[x])]) continue;
      ++acc.relief_texels_true;
      const Eigen::Vector2f& t = in_est(x, y);
      // Far outside (or an empty estimate with pitch 0): nowhere in the grid.
      bool near = std::abs(t.x()) < 1e8f && std::abs(t.y()) < 1e8f;
      int u = near ? static_cast<int>(std::lround(t.x())) : -1;
      int v = near ? static_cast<int>(std::lround(t.y())) : -1;
      if (!est.height_mm.Contains(u, v) || est.state(u, v) == TexelState::kOutside) {
        ++acc.relief_texels_outside;
      } else if (!boxed(u, v)) {
        ++acc.relief_texels_uncovered;
      }
    }
  }
  return acc;
}

RegistrationAccuracy MeasureRegistration(const SyntheticPatchScan& scan,
                                         const PatchRegistrationResult& result) {
  RegistrationAccuracy m;
  const double pitch = result.field.pitch_mm;
  const RigidTransform gauge =
      scan.patches[0].scan.canvas_from_scan * result.patches[0].rig_from_scan.Inverse();
  std::vector<Vec3d> placed, truth;  // every canvas sample: registered (patch 0's gauge), true
  for (size_t i = 0; i < scan.patches.size(); ++i) {
    const SyntheticScan& s = scan.patches[i].scan;
    const RigidTransform est = gauge * result.patches[i].rig_from_scan;
    const Grid<Vec3f>& xyz = s.exposures[0].xyz_mm;
    for (size_t k = 0; k < xyz.data.size(); ++k) {
      if (!s.canvas_mask_scan.data[k] || !IsValid(xyz.data[k])) continue;
      const Vec3d p = xyz.data[k].cast<double>();
      placed.push_back(est.Apply(p));
      truth.push_back(s.canvas_from_scan.Apply(p));
      m.max_error_texels = std::max(m.max_error_texels, (placed.back() - truth.back()).norm());
    }
  }
  if (placed.empty()) return m;
  Eigen::Matrix3Xd a(3, placed.size()), b(3, placed.size());
  for (size_t k = 0; k < placed.size(); ++k) a.col(k) = placed[k], b.col(k) = truth[k];
  const Eigen::Matrix4d best = Eigen::umeyama(a, b, false);
  for (size_t k = 0; k < placed.size(); ++k) {
    const Vec3d moved = best.topLeftCorner<3, 3>() * placed[k] + best.topRightCorner<3, 1>();
    m.best_gauge_error_texels = std::max(m.best_gauge_error_texels, (moved - truth[k]).norm());
  }
  m.max_error_texels /= pitch;
  m.best_gauge_error_texels /= pitch;
  return m;
}

}  // namespace digitize::synth
