// Simulated structured-light scan of a Scene: one ray per scan pixel (traced once, the pose is
// shared by every exposure), then per exposure its own noise along the ray, random dropouts,
// blob-shaped holes and rare outliers. See scan_sim.h for the pose and camera conventions.
#include "digitize_synth/scan_sim.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <string>

namespace digitize::synth {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kOutlierMinMm = 2, kOutlierMaxMm = 50;  // outlier displacement along the ray
constexpr int kRowGrain = 4;                             // rows per parallel task

uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// One random stream per (exposure, purpose, row): the same numbers whatever thread draws them.
std::mt19937_64 RowStream(uint64_t seed, int exposure, uint64_t purpose, int row) {
  uint64_t s = SplitMix64(seed);
  s = SplitMix64(s ^ (static_cast<uint64_t>(exposure) + 1) * 0x9E3779B97F4A7C15ull);
  s = SplitMix64(s ^ purpose * 0xC2B2AE3D27D4EB4Full);
  s = SplitMix64(s ^ (static_cast<uint64_t>(row) + 1) * 0x165667B19E3779F9ull);
  return std::mt19937_64(s);
}

// The scanner: where pixel (i, j)'s ray starts and where it goes, in the scan frame.
struct Camera {
  ScannerModel model = ScannerModel::kOrthographic;
  int width = 0, height = 0;
  double pitch_mm = 0;  // orthographic
  double focal_px = 0;  // pinhole

  void Ray(int i, int j, Vec3d& origin, Vec3d& direction) const {
    double u = i + 0.5 - 0.5 * width, v = j + 0.5 - 0.5 * height;
    if (model == ScannerModel::kOrthographic) {
      origin = Vec3d(u * pitch_mm, v * pitch_mm, 0);
      direction = Vec3d(0, 0, 1);
    } else {
      origin = Vec3d::Zero();
      direction = Vec3d(u / focal_px, v / focal_px, 1).normalized();
    }
  }
};

// scan_from_canvas for the options' pose (scan_sim.h).
RigidTransform ScanFromCanvas(const Painting& painting, const ScanSimOptions& o) {
  const double deg = kPi / 180;
  Mat3d upright;  // canvas X -> scan X, canvas Y -> scan -Y, canvas Z -> scan -Z
  upright << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  Mat3d roll = Eigen::AngleAxisd(o.roll_deg * deg, Vec3d::UnitZ()).toRotationMatrix();
  Vec3d axis(std::cos(o.tilt_axis_deg * deg), std::sin(o.tilt_axis_deg * deg), 0);
  Mat3d tilt = Eigen::AngleAxisd(o.tilt_deg * deg, axis).toRotationMatrix();
  RigidTransform t;
  t.rotation = tilt * roll * upright;
  Vec3d centre_canvas(0.5 * painting.width_mm, 0.5 * painting.height_mm, 0);
  if (o.aim_mm.allFinite()) centre_canvas = Vec3d(o.aim_mm.x(), o.aim_mm.y(), 0);
  Vec3d centre_scan(o.offset_mm.x(), o.offset_mm.y(), o.distance_mm + o.offset_mm.z());
  t.translation = centre_scan - t.rotation * centre_canvas;
  return t;
}

// Corners of what should be in view (canvas, plus the frame's outer outline at its base and its
// top when there is one), canvas frame.
std::vector<Vec3d> Footprint(const Painting& painting, const FrameOptions& frame) {
  auto d = [&](int side) { return frame.enabled ? frame.Width(side) : 0.0; };
  std::vector<double> zs = {0.0};
  if (frame.enabled) zs.push_back(frame.raise_mm);
  std::vector<Vec3d> corners;
  for (double z : zs)
    for (double x : {-d(0), painting.width_mm + d(1)})
      for (double y : {-d(2), painting.height_mm + d(3)}) corners.emplace_back(x, y, z);
  return corners;
}

Camera MakeCamera(const Painting& painting, const FrameOptions& frame, const ScanSimOptions& o,
                  const RigidTransform& scan_from_canvas) {
  Camera cam;
  cam.model = o.model;
  cam.width = o.width_px;
  cam.height = o.height_px;
  if (o.field_mm.x() > 0 && o.field_mm.y() > 0) {  // a patch: the field at the aim's distance
    const double pitch = std::max(o.field_mm.x() / o.width_px, o.field_mm.y() / o.height_px);
    if (o.model == ScannerModel::kOrthographic) {
      cam.pitch_mm = pitch;
    } else {
      cam.focal_px = (o.distance_mm + o.offset_mm.z()) / pitch;
    }
    return cam;
  }
  const double scale = 1 + o.field_margin;
  const Vec3d centre =
      scan_from_canvas.Apply(Vec3d(0.5 * painting.width_mm, 0.5 * painting.height_mm, 0));
  double half_x = 0, half_y = 0;
  for (const Vec3d& c : Footprint(painting, frame)) {
    Vec3d p = scan_from_canvas.Apply(c);
    if (o.model == ScannerModel::kOrthographic) {
      half_x = std::max(half_x, std::abs(p.x() - centre.x()));
      half_y = std::max(half_y, std::abs(p.y() - centre.y()));
    } else {
      DIGITIZE_CHECK(p.z() > 1e-6, "SimulateScan: the scene is behind the pinhole (corner at Z = " +
                                       FormatNumber(p.z()) + " mm); increase distance_mm");
      half_x = std::max(half_x, std::abs(p.x() / p.z() - centre.x() / centre.z()));
      half_y = std::max(half_y, std::abs(p.y() / p.z() - centre.y() / centre.z()));
    }
  }
  half_x *= scale, half_y *= scale;
  // Square pixels. A margin >= 0 makes the view contain the scaled footprint along both axes
  // (the tighter axis decides); a negative margin makes it fit inside it (the looser axis
  // decides), so that a cropped view sees nothing beyond the canvas whatever the aspect ratios.
  const bool contain = o.field_margin >= 0;
  const double px = 2 * half_x / o.width_px, py = 2 * half_y / o.height_px;
  if (o.model == ScannerModel::kOrthographic) {
    cam.pitch_mm = contain ? std::max(px, py) : std::min(px, py);
  } else {
    cam.focal_px = 1 / (contain ? std::max(px, py) : std::min(px, py));
  }
  return cam;
}

// Blob-shaped holes of one exposure: irregular discs (two harmonics on the radius), hole_blobs
// anywhere and border_hole_blobs centred on pixels of the canvas outline (`outline`, packed
// y * width + x, raster order).
Grid<uint8_t> HoleMask(const ScanSimOptions& o, int exposure, const std::vector<int>& outline) {
  Grid<uint8_t> holes(o.width_px, o.height_px, 0);
  const int border = outline.empty() ? 0 : o.border_hole_blobs;
  if (o.hole_blobs + border == 0 || o.hole_blob_radius_px <= 0) return holes;
  std::mt19937_64 rng = RowStream(o.seed, exposure, 7, -1);
  std::mt19937_64 border_rng = RowStream(o.seed, exposure, 8, -1);
  std::uniform_real_distribution<double> unit(0, 1);
  for (int b = 0; b < o.hole_blobs + border; ++b) {
    double cx = unit(rng) * o.width_px, cy = unit(rng) * o.height_px;
    if (b >= o.hole_blobs) {
      const size_t k =
          std::min(outline.size() - 1, static_cast<size_t>(unit(border_rng) * outline.size()));
      cx = outline[k] % o.width_px + 0.5, cy = outline[k] / o.width_px + 0.5;
    }
    double radius = o.hole_blob_radius_px * (0.6 + 0.9 * unit(rng));
    double a2 = 0.25 * unit(rng), a3 = 0.15 * unit(rng);
    double p2 = 2 * kPi * unit(rng), p3 = 2 * kPi * unit(rng);
    double reach = radius * (1 + a2 + a3);
    int x0 = std::max(0, static_cast<int>(std::floor(cx - reach)));
    int x1 = std::min(o.width_px - 1, static_cast<int>(std::ceil(cx + reach)));
    int y0 = std::max(0, static_cast<int>(std::floor(cy - reach)));
    int y1 = std::min(o.height_px - 1, static_cast<int>(std::ceil(cy + reach)));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        double dx = x + 0.5 - cx, dy = y + 0.5 - cy;
        double theta = std::atan2(dy, dx);
        double r = radius * (1 + a2 * std::cos(2 * theta + p2) + a3 * std::cos(3 * theta + p3));
        if (dx * dx + dy * dy <= r * r) holes(x, y) = 1;
      }
    }
  }
  return holes;
}

}  // namespace

Status ScanSimOptions::Validate() const {
  auto fail = [](const std::string& what) { return Status(Error{"scan options: " + what}); };
  if (width_px < 1 || height_px < 1 || width_px > 32768 || height_px > 32768)
    return fail("width_px and height_px must be in [1, 32768], got " + std::to_string(width_px) +
                " x " + std::to_string(height_px));
  if (static_cast<double>(width_px) * height_px > static_cast<double>(size_t{1} << 28))
    return fail("width_px x height_px must be at most 2^28 samples, got " +
                std::to_string(width_px) + " x " + std::to_string(height_px));
  if (!(std::isfinite(field_margin) && field_margin > -0.95 && field_margin <= 10))
    return fail("field_margin must be in (-0.95, 10], got " + FormatNumber(field_margin));
  if (!(std::isfinite(tilt_deg) && std::abs(tilt_deg) <= 80))
    return fail("tilt_deg must be in [-80, 80], got " + FormatNumber(tilt_deg));
  if (!std::isfinite(tilt_axis_deg)) return fail("tilt_axis_deg must be finite");
  if (!std::isfinite(roll_deg)) return fail("roll_deg must be finite");
  if (!offset_mm.allFinite()) return fail("offset_mm must be finite");
  if (!(std::isfinite(distance_mm) && distance_mm > 0 && distance_mm <= 1e5))
    return fail("distance_mm must be in (0, 100000], got " + FormatNumber(distance_mm));
  if (!(distance_mm + offset_mm.z() > 0))
    return fail("distance_mm + offset_mm.z must be > 0 (canvas in front of the scanner), got " +
                FormatNumber(distance_mm + offset_mm.z()));
  if (!(std::isfinite(noise_mm) && noise_mm >= 0 && noise_mm <= 1000))
    return fail("noise_mm must be in [0, 1000], got " + FormatNumber(noise_mm));
  if (!(dropout >= 0 && dropout <= 1))
    return fail("dropout must be in [0, 1], got " + FormatNumber(dropout));
  if (hole_blobs < 0 || hole_blobs > 100000)
    return fail("hole_blobs must be in [0, 100000], got " + std::to_string(hole_blobs));
  if (border_hole_blobs < 0 || border_hole_blobs > 100000)
    return fail("border_hole_blobs must be in [0, 100000], got " +
                std::to_string(border_hole_blobs));
  if (!(std::isfinite(hole_blob_radius_px) && hole_blob_radius_px >= 0 &&
        hole_blob_radius_px <= 1e5))
    return fail("hole_blob_radius_px must be in [0, 100000], got " +
                FormatNumber(hole_blob_radius_px));
  if (!(outliers >= 0 && outliers <= 1))
    return fail("outliers must be in [0, 1], got " + FormatNumber(outliers));
  if (!(std::isnan(aim_mm.x()) && std::isnan(aim_mm.y())) && !aim_mm.allFinite())
    return fail("aim_mm must be finite (or both NaN: the canvas centre)");
  if (!(field_mm.allFinite() && field_mm.minCoeff() >= 0 && field_mm.maxCoeff() <= 1e5))
    return fail("field_mm must be in [0, 100000] mm");
  if (!pose_error.rotation.allFinite() || !pose_error.translation.allFinite() ||
      !(pose_error.rotation.transpose() * pose_error.rotation).isApprox(Mat3d::Identity(), 1e-9))
    return fail("pose_error must be a rigid transform");
  if (exposures < 1 || exposures > 64)
    return fail("exposures must be in [1, 64], got " + std::to_string(exposures));
  return Status::Ok();
}

SyntheticScan SimulateScan(const Scene& scene, const ScanSimOptions& options) {
  Status valid = options.Validate();
  DIGITIZE_CHECK(valid.ok(), "SimulateScan: " + valid.message());
  const Painting& painting = scene.painting();
  const int w = options.width_px, h = options.height_px;

  SyntheticScan out;
  out.options = options;
  out.frame = scene.frame();
  const RigidTransform nominal_scan_from_canvas = ScanFromCanvas(painting, options);
  const Camera cam = MakeCamera(painting, scene.frame(), options, nominal_scan_from_canvas);
  out.canvas_from_scan = options.pose_error * nominal_scan_from_canvas.Inverse();
  out.pixel_pitch_mm = cam.pitch_mm;
  out.focal_px = cam.focal_px;

  // Trace every pixel once (the pose is the same for all exposures).
  Grid<float> t_mm(w, h, 0.0f);
  out.hit_scan = Grid<uint8_t>(w, h, 0);
  out.canvas_mask_scan = Grid<uint8_t>(w, h, 0);
  const RigidTransform& cfs = out.canvas_from_scan;
  tbb::parallel_for(
      tbb::blocked_range<int>(0, h, kRowGrain), [&](const tbb::blocked_range<int>& r) {
        std::vector<Vec3d> origins(static_cast<size_t>(w)), directions(static_cast<size_t>(w));
        std::vector<Scene::RayHit> hits;
        for (int j = r.begin(); j < r.end(); ++j) {
          for (int i = 0; i < w; ++i) {
            Vec3d o, d;
            cam.Ray(i, j, o, d);
            origins[static_cast<size_t>(i)] = cfs.Apply(o);
            directions[static_cast<size_t>(i)] = cfs.ApplyToDirection(d);
          }
          scene.Intersect(origins, directions, hits);
          for (int i = 0; i < w; ++i) {
            const Scene::RayHit& hit = hits[static_cast<size_t>(i)];
            out.hit_scan(i, j) = static_cast<uint8_t>(hit.what);
            out.canvas_mask_scan(i, j) = hit.what == Scene::Hit::kCanvas ? 1 : 0;
            t_mm(i, j) = static_cast<float>(hit.t);
          }
        }
      });

  // Ground truth of the visible canvas: its outline pixels (canvas pixels with a 4-neighbour
  // that is not canvas, or on the scan's border) and its bounding box in the canvas frame.
  std::vector<int> outline;
  {
    const auto canvas = [&](int i, int j) {
      return i >= 0 && j >= 0 && i < w && j < h && out.canvas_mask_scan(i, j) != 0;
    };
    Eigen::AlignedBox2d box;
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        if (!canvas(i, j)) continue;
        Vec3d o, d;
        cam.Ray(i, j, o, d);
        const Vec3d p = cfs.Apply(o + static_cast<double>(t_mm(i, j)) * d);
        box.extend(Eigen::Vector2d(p.x(), p.y()));
        if (!canvas(i - 1, j) || !canvas(i + 1, j) || !canvas(i, j - 1) || !canvas(i, j + 1))
          outline.push_back(j * w + i);
      }
    if (!box.isEmpty()) {
      out.visible_min_mm = box.min();
      out.visible_max_mm = box.max();
    }
  }

  // Exposures: the same hits, each with its own noise and losses.
  out.exposures.resize(static_cast<size_t>(options.exposures));
  for (int e = 0; e < options.exposures; ++e) {
    Scan& scan = out.exposures[static_cast<size_t>(e)];
    scan.source =
        "synthetic exposure " + std::to_string(e) + " (seed " + std::to_string(options.seed) + ")";
    scan.xyz_mm = Grid<Vec3f>(w, h, Vec3f::Constant(kMissing));
    const Grid<uint8_t> holes = HoleMask(options, e, outline);
    tbb::parallel_for(
        tbb::blocked_range<int>(0, h, kRowGrain), [&](const tbb::blocked_range<int>& r) {
          for (int j = r.begin(); j < r.end(); ++j) {
            std::mt19937_64 rng = RowStream(options.seed, e, 1, j);
            std::mt19937_64 rare = RowStream(options.seed, e, 2, j);  // outlier sizes
            std::normal_distribution<double> noise(0.0, 1.0);
            std::uniform_real_distribution<double> unit(0.0, 1.0);
            for (int i = 0; i < w; ++i) {
              // The same draws for every pixel, whatever happens to it, so that the losses asked
              // for do not shift the noise of the pixels after it. One 64-bit draw gives the two
              // 32-bit uniforms of the dropout and outlier decisions.
              const double n = noise(rng);
              const uint64_t bits = rng();
              const double drop = static_cast<double>(bits & 0xFFFFFFFFu) * 0x1.0p-32;
              const double outlier = static_cast<double>(bits >> 32) * 0x1.0p-32;
              if (out.hit_scan(i, j) == static_cast<uint8_t>(Scene::Hit::kNone)) continue;
              if (holes(i, j) || drop < options.dropout) continue;
              double t = t_mm(i, j) + options.noise_mm * n;
              if (outlier < options.outliers) {
                double magnitude = kOutlierMinMm + (kOutlierMaxMm - kOutlierMinMm) * unit(rare);
                t += (outlier < 0.5 * options.outliers) ? magnitude : -magnitude;
              }
              Vec3d o, d;
              cam.Ray(i, j, o, d);
              scan.xyz_mm(i, j) = (o + t * d).cast<float>();
            }
          }
        });
  }
  return out;
}

int MatchedResolution(const PaintingOptions& painting, const FrameOptions& frame,
                      const ScanSimOptions& scan) {
  const double frame_x = frame.enabled ? frame.Width(0) + frame.Width(1) : 0;
  const double frame_y = frame.enabled ? frame.Width(2) + frame.Width(3) : 0;
  const double field_x = (painting.width_mm + frame_x) * (1 + scan.field_margin);
  const double field_y = (painting.height_mm + frame_y) * (1 + scan.field_margin);
  const double pitch =
      std::max(field_x / std::max(scan.width_px, 1), field_y / std::max(scan.height_px, 1));
  const double long_side = std::max(painting.width_mm, painting.height_mm);
  return std::clamp(static_cast<int>(long_side / (1.1 * pitch)), 64, 8192);
}

}  // namespace digitize::synth
