// RegisterPatches (scan_registration.h): coarse alignment (plane + correlation of the relief),
// OpenCV contrib's robust point-to-plane ICP, a height-field polish, resampling and blending onto
// one canvas grid, and the overlap residuals.
//
// Working frame "M": patch 0's own canvas frame (ExtractCanvas on it) at its nominal pose, so that
// heights are Z and the canvas plane is roughly Z = 0 for every patch. Poses are kept as
// m_from_scan; corrections are composed on the left (in M).
#include "digitize/scan_registration.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/surface_matching/icp.hpp>

namespace digitize {
namespace {

std::string Format(const char* fmt, auto... args) {
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer), fmt, args...);
  return buffer;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

// One patch as the registration sees it.
struct Patch {
  const ScanPatch* in = nullptr;
  CanvasResult canvas;         // ExtractCanvas on the patch alone
  std::vector<Vec3d> points;   // valid canvas samples, scan frame
  std::vector<Vec3d> normals;  // per point, scan frame; zero where none could be formed
  RigidTransform m_from_scan;  // current pose in M
  RigidTransform nominal_m_from_scan;
  PatchReport report;
  const std::string& name() const { return in->scan.source; }
};

// Canvas samples and their normals, from the scan smoothed over lowpass_mm on its own grid
// (masked, normalised Gaussian). The raw samples carry the canvas weave (~1 mm period, aliased
// differently by every patch's sampling) and the noise, and their normals are mostly those: the
// in-plane pull of a point-to-plane ICP comes from the normals' tilt, and with noise for normals
// it is too weak to slide a patch home (it stops short by tenths of a mm). Smoothed, the normals
// are the relief's. The merge resamples the raw scan; only registration sees these.
void CollectPoints(Patch& p, double lowpass_mm) {
  const Grid<Vec3f>& xyz = p.in->scan.xyz_mm;
  const Grid<uint8_t>& mask = p.canvas.mask_scan;
  const int w = xyz.width, h = xyz.height;
  auto ok = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < w && y < h && mask(x, y) && IsValid(xyz(x, y));
  };
  std::vector<double> spacing;
  cv::Mat sum(h, w, CV_32FC3, cv::Scalar::all(0)), weight(h, w, CV_32F, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!ok(x, y)) continue;
      const Vec3f& q = xyz(x, y);
      sum.at<cv::Vec3f>(y, x) = cv::Vec3f(q.x(), q.y(), q.z());
      weight.at<float>(y, x) = 1;
      if (x % 3 == 0 && y % 3 == 0 && ok(x + 1, y))
        spacing.push_back((xyz(x + 1, y) - q).cast<double>().norm());
    }
  const double sigma_px = std::max(0.5, lowpass_mm / std::max(1e-6, Median(spacing)));
  cv::GaussianBlur(sum, sum, cv::Size(), sigma_px);
  cv::GaussianBlur(weight, weight, cv::Size(), sigma_px);
  Grid<Vec3f> smooth(w, h, Vec3f::Constant(kMissing));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float wt = weight.at<float>(y, x);
      if (!ok(x, y) || wt < 0.9f) continue;  // near the mask's edge: pulled inwards, left out
      const cv::Vec3f v = sum.at<cv::Vec3f>(y, x) / wt;
      smooth(x, y) = Vec3f(v[0], v[1], v[2]);
    }
  auto good = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < w && y < h && IsValid(smooth(x, y));
  };
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      if (!good(x, y)) continue;
      p.points.push_back(smooth(x, y).cast<double>());
      Vec3d n = Vec3d::Zero();
      if (good(x - 1, y) && good(x + 1, y) && good(x, y - 1) && good(x, y + 1)) {
        const Vec3d dx = (smooth(x + 1, y) - smooth(x - 1, y)).cast<double>();
        const Vec3d dy = (smooth(x, y + 1) - smooth(x, y - 1)).cast<double>();
        n = dx.cross(dy);
        const double len = n.norm();
        n = len > 0 ? Vec3d(n / len) : Vec3d::Zero();
        if (n.z() > 0) n = -n;  // the scanner looks along +Z
      }
      p.normals.push_back(n);
    }
  }
}

// A regular grid of cells over M's XY plane; rows follow +Y.
struct Mosaic {
  double x0 = 0, y0 = 0, cell = 1;
  int w = 0, h = 0;
  bool Cell(const Vec3d& m, int& cx, int& cy) const {
    cx = static_cast<int>(std::floor((m.x() - x0) / cell));
    cy = static_cast<int>(std::floor((m.y() - y0) / cell));
    return cx >= 0 && cy >= 0 && cx < w && cy < h;
  }
  Eigen::Vector2d Centre(double cx, double cy) const {
    return {x0 + (cx + 0.5) * cell, y0 + (cy + 0.5) * cell};
  }
};

// Sum and count of the heights (M's Z) of a patch's points per cell.
void Splat(const Patch& p, const Mosaic& g, cv::Mat& sum, cv::Mat& count) {
  if (sum.empty()) {
    sum = cv::Mat::zeros(g.h, g.w, CV_32F);
    count = cv::Mat::zeros(g.h, g.w, CV_32F);
  }
  for (const Vec3d& q : p.points) {
    const Vec3d m = p.m_from_scan.Apply(q);
    int cx, cy;
    if (!g.Cell(m, cx, cy)) continue;
    sum.at<float>(cy, cx) += static_cast<float>(m.z());
    count.at<float>(cy, cx) += 1.0f;
  }
}

// Cells a patch covers (gaps between samples closed).
cv::Mat Coverage(const cv::Mat& count) {
  cv::Mat cover = count > 0;
  cv::morphologyEx(cover, cover, cv::MORPH_CLOSE, cv::Mat::ones(3, 3, CV_8U));
  return cover;
}

struct Rasters {
  cv::Mat sum, count;
};

Rasters RasterOf(const std::vector<Patch>& patches, const std::vector<int>& which,
                 const Mosaic& g) {
  Rasters r;
  for (int i : which) Splat(patches[static_cast<size_t>(i)], g, r.sum, r.count);
  if (r.sum.empty()) {
    r.sum = cv::Mat::zeros(g.h, g.w, CV_32F);
    r.count = cv::Mat::zeros(g.h, g.w, CV_32F);
  }
  return r;
}

// The overlap of two coverages, eroded so that neither side's ragged border enters it.
cv::Mat OverlapMask(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat o;
  cv::bitwise_and(a, b, o);
  cv::erode(o, o, cv::Mat::ones(3, 3, CV_8U), cv::Point(-1, -1), 2);
  return o;
}

// Points of a patch whose cell is set in `mask` (M frame), every `stride`-th, with normals.
void PointsIn(const Patch& p, const Mosaic& g, const cv::Mat& mask, size_t stride, bool need_normal,
              std::vector<Vec3d>& pts, std::vector<Vec3d>* nrm) {
  for (size_t k = 0; k < p.points.size(); k += stride) {
    if (need_normal && p.normals[k].isZero()) continue;
    const Vec3d m = p.m_from_scan.Apply(p.points[k]);
    int cx, cy;
    if (!g.Cell(m, cx, cy) || !mask.at<uint8_t>(cy, cx)) continue;
    pts.push_back(m);
    if (nrm) nrm->push_back(p.m_from_scan.ApplyToDirection(p.normals[k]));
  }
}

size_t StrideFor(size_t n, size_t limit) { return std::max<size_t>(1, (n + limit - 1) / limit); }

// How far `c` moves the points of a patch (M frame), at most.
double MaxMove(const RigidTransform& c, const Patch& p) {
  double worst = 0;
  const size_t stride = StrideFor(p.points.size(), 4000);
  for (size_t k = 0; k < p.points.size(); k += stride) {
    const Vec3d m = p.m_from_scan.Apply(p.points[k]);
    worst = std::max(worst, (c.Apply(m) - m).norm());
  }
  return worst;
}

RigidTransform AboutPoint(const Mat3d& r, const Vec3d& centre, const Vec3d& shift) {
  RigidTransform t;
  t.rotation = r;
  t.translation = centre - r * centre + shift;
  return t;
}

// Step 2a: the patch's plane in the overlap onto the placed patches' plane there.
RigidTransform PlaneStep(const std::vector<Vec3d>& moving, const std::vector<Vec3d>& fixed) {
  PlaneFit a = FitPlanePca(moving), b = FitPlanePca(fixed);
  Vec3d na = a.axes.col(2), nb = b.axes.col(2);
  if (na.z() < 0) na = -na;
  if (nb.z() < 0) nb = -nb;
  const Mat3d r = Eigen::Quaterniond::FromTwoVectors(na, nb).toRotationMatrix();
  return AboutPoint(r, a.centroid, (b.centroid - a.centroid).dot(nb) * nb);
}

// Band-passed heights of a raster: the masked Gaussian mean at sigma_fine minus the one at
// sigma_coarse, 0 where empty. The fine blur takes out the scanner noise and the canvas weave
// (a ~1 mm period, aliased differently by every patch's sampling), the coarse one the bow and
// tilt, which the plane step handles: what is left is the paint's relief, the same in both.
cv::Mat BandPass(const Rasters& r, double sigma_fine, double sigma_coarse) {
  cv::Mat mask = cv::Mat::zeros(r.count.size(), CV_32F);
  cv::Mat height = cv::Mat::zeros(r.count.size(), CV_32F);
  for (int y = 0; y < r.count.rows; ++y)
    for (int x = 0; x < r.count.cols; ++x) {
      const float c = r.count.at<float>(y, x);
      if (c > 0) {
        mask.at<float>(y, x) = 1;
        height.at<float>(y, x) = r.sum.at<float>(y, x) / c;
      }
    }
  auto masked_blur = [&](double sigma, cv::Mat& out) {
    cv::Mat bh, bm;
    cv::GaussianBlur(height, bh, cv::Size(), sigma);
    cv::GaussianBlur(mask, bm, cv::Size(), sigma);
    out = cv::Mat::zeros(height.size(), CV_32F);
    for (int y = 0; y < height.rows; ++y)
      for (int x = 0; x < height.cols; ++x) {
        const float m = bm.at<float>(y, x);
        if (mask.at<float>(y, x) > 0 && m > 1e-3f) out.at<float>(y, x) = bh.at<float>(y, x) / m;
      }
  };
  cv::Mat fine, coarse;
  masked_blur(std::max(0.5, sigma_fine), fine);
  masked_blur(sigma_coarse, coarse);
  return fine - coarse;
}

// One correlated piece of an overlap: where it is (M, mm), the correction of the moving patch
// there (mm) and the normalised correlation peak.
struct PieceShift {
  Eigen::Vector2d at, shift;
  double peak = 0;
};

// Normalised cross-correlation of the moving patch's band-passed heights (the piece shrunk by the
// search radius) over the fixed ones', in `r`: bounded to search_mm, and its peak (-1..1) says
// whether relief was matched at all.
bool CorrelatePiece(const cv::Mat& hf, const cv::Mat& hm, const cv::Mat& overlap, cv::Rect r,
                    const Mosaic& g, const PatchRegistrationOptions& options, PieceShift& out) {
  const int m = static_cast<int>(std::ceil(options.search_mm / g.cell));
  if (r.width <= 2 * m + 8 || r.height <= 2 * m + 8) return false;
  cv::Mat a = cv::Mat::zeros(r.size(), CV_32F), b = cv::Mat::zeros(r.size(), CV_32F);
  hf(r).copyTo(a, overlap(r));
  hm(r).copyTo(b, overlap(r));
  const cv::Mat templ = b(cv::Rect(m, m, r.width - 2 * m, r.height - 2 * m));
  cv::Mat score;
  cv::matchTemplate(a, templ, score, cv::TM_CCOEFF_NORMED);
  double peak = 0;
  cv::Point loc;
  cv::minMaxLoc(score, nullptr, &peak, nullptr, &loc);
  // Sub-cell: a parabola through the peak and its neighbours, per axis.
  auto vertex = [](double l, double c, double h) {
    const double d = l - 2 * c + h;
    return d < 0 ? std::clamp(0.5 * (l - h) / d, -0.5, 0.5) : 0.0;
  };
  double sx = loc.x, sy = loc.y;
  if (loc.x > 0 && loc.x + 1 < score.cols)
    sx += vertex(score.at<float>(loc.y, loc.x - 1), score.at<float>(loc.y, loc.x),
                 score.at<float>(loc.y, loc.x + 1));
  if (loc.y > 0 && loc.y + 1 < score.rows)
    sy += vertex(score.at<float>(loc.y - 1, loc.x), score.at<float>(loc.y, loc.x),
                 score.at<float>(loc.y + 1, loc.x));
  out.at = g.Centre(r.x + 0.5 * r.width - 0.5, r.y + 0.5 * r.height - 0.5);
  out.shift = Eigen::Vector2d((sx - m) * g.cell, (sy - m) * g.cell);
  out.peak = std::isfinite(peak) && out.shift.allFinite() ? peak : 0.0;
  return true;
}

// Step 2b: the band-passed heights of the moving patch correlated with each placed patch's in
// their overlap, in two halves along its long side (one piece when it is not long), then a 2-D
// rigid motion fitted to the pieces' shifts (translation only from a single piece). Whole
// halves rather than small tiles: the relief is sparse (strokes, impasto), and a tile without
// any gives a false peak; a half almost always holds some.
Result<RigidTransform> CorrelationStep(const std::vector<Patch>& patches, int moving,
                                       const std::vector<int>& fixed, const Mosaic& g,
                                       const PatchRegistrationOptions& options, int* pieces_used,
                                       double* min_peak) {
  const double fine = options.lowpass_mm / g.cell, coarse = options.highpass_mm / g.cell;
  const Rasters rm = RasterOf(patches, {moving}, g);
  const cv::Mat hm = BandPass(rm, fine, coarse);
  const cv::Mat cover_m = Coverage(rm.count);
  std::vector<PieceShift> pieces;
  double best_peak = -1;
  for (int f : fixed) {
    const Rasters rf = RasterOf(patches, {f}, g);
    const cv::Mat overlap = OverlapMask(cover_m, Coverage(rf.count));
    if (cv::countNonZero(overlap) * g.cell * g.cell < options.min_overlap_mm2) continue;
    const cv::Mat hf = BandPass(rf, fine, coarse);
    const cv::Rect box = cv::boundingRect(overlap);
    const bool along_x = box.width >= box.height;
    const int long_side = along_x ? box.width : box.height;
    const int count = 2 * long_side >= 3 * (along_x ? box.height : box.width) ? 2 : 1;
    for (int k = 0; k < count; ++k) {
      cv::Rect r = box;
      if (count == 2 && along_x) r.width = box.width / 2, r.x = box.x + k * (box.width - r.width);
      if (count == 2 && !along_x)
        r.height = box.height / 2, r.y = box.y + k * (box.height - r.height);
      PieceShift piece;
      if (!CorrelatePiece(hf, hm, overlap, r, g, options, piece)) continue;
      best_peak = std::max(best_peak, piece.peak);
      if (piece.peak >= options.min_correlation_peak) pieces.push_back(piece);
    }
  }
  const std::string& name = patches[static_cast<size_t>(moving)].name();
  if (pieces.empty())
    return Error{name +
                 ": its overlap with the patches placed before it has no relief to register "
                 "(featureless: best normalised correlation " +
                 Format("%.2f", std::max(0.0, best_peak)) + ", below min_correlation_peak " +
                 Format("%.2f", options.min_correlation_peak) +
                 "); scan with more overlap or over painted areas"};
  // Translation only, the median of the pieces' shifts per axis: a rotation from two pieces of
  // a strip swings by a degree when one of them holds a single stroke (the aperture problem); the
  // rotation is left to ICP, which recovers it from the whole overlap.
  std::vector<double> sx, sy;
  for (const PieceShift& k : pieces) sx.push_back(k.shift.x()), sy.push_back(k.shift.y());
  const Eigen::Vector2d t2(Median(sx), Median(sy));
  *pieces_used = static_cast<int>(pieces.size());
  *min_peak = 1;
  for (const PieceShift& k : pieces) *min_peak = std::min(*min_peak, k.peak);
  RigidTransform c;
  c.rotation = Mat3d::Identity();
  c.translation = Vec3d::Zero();
  c.translation.head<2>() = t2;
  return c;
}

cv::Mat AsIcpCloud(const std::vector<Vec3d>& pts, const std::vector<Vec3d>& nrm,
                   const Vec3d& origin) {
  cv::Mat m(static_cast<int>(pts.size()), 6, CV_32F);
  for (size_t i = 0; i < pts.size(); ++i) {
    float* row = m.ptr<float>(static_cast<int>(i));
    const Vec3d q = pts[i] - origin;
    for (int c = 0; c < 3; ++c) {
      row[c] = static_cast<float>(q[c]);
      row[3 + c] = static_cast<float>(nrm[i][c]);
    }
  }
  return m;
}

// Step 3: ICP rounds of `moving` against `fixed` in their overlap until a round moves no point of
// the patch by more than converged_mm.
Status IcpStep(std::vector<Patch>& patches, int moving, const std::vector<int>& fixed,
               const Mosaic& g, const PatchRegistrationOptions& options) {
  Patch& p = patches[static_cast<size_t>(moving)];
  cv::ppf_match_3d::ICP icp(options.icp_iterations, 0.001f,
                            static_cast<float>(options.icp_rejection_scale), options.icp_levels);
  // The clouds are chosen once, at the pose the step starts from: chosen anew every round, the
  // overlap's edge moves with the patch, the answer changes with the sample set by a few
  // hundredths of a mm and the rounds never settle. The moving patch's samples: its overlap,
  // shrunk by two cells; the fixed ones': the overlap grown by four, so that every moving
  // sample finds its neighbour after the patch slid by up to ~4 cells.
  const Rasters rm = RasterOf(patches, {moving}, g), rf = RasterOf(patches, fixed, g);
  const cv::Mat overlap = OverlapMask(Coverage(rm.count), Coverage(rf.count));
  cv::Mat wide;
  cv::dilate(overlap, wide, cv::Mat::ones(3, 3, CV_8U), cv::Point(-1, -1), 4);
  const size_t in_overlap = static_cast<size_t>(cv::countNonZero(overlap));
  std::vector<Vec3d> src_scan, src_n_scan, dst, dst_n;
  {
    const RigidTransform scan_from_m = p.m_from_scan.Inverse();
    std::vector<Vec3d> src, src_n;
    PointsIn(p, g, overlap, StrideFor(in_overlap, static_cast<size_t>(options.max_icp_points)),
             true, src, &src_n);
    for (size_t i = 0; i < src.size(); ++i) {
      src_scan.push_back(scan_from_m.Apply(src[i]));
      src_n_scan.push_back(scan_from_m.ApplyToDirection(src_n[i]));
    }
  }
  // Every fixed sample there, the moving ones thinned: OpenCV's "picky" ICP keeps only the
  // nearest of the moving samples that share a fixed one, and with fixed samples as sparse as
  // the moving ones that choice is a coin toss that moves the answer by ~0.1 mm per call.
  for (int f : fixed) PointsIn(patches[static_cast<size_t>(f)], g, wide, 1, true, dst, &dst_n);
  if (src_scan.size() < 100 || dst.size() < 100)
    return Error{p.name() + ": too few samples in its overlap for ICP (" +
                 std::to_string(src_scan.size()) + " and " + std::to_string(dst.size()) + ")"};
  double move = 0;
  for (int round = 0; round < options.max_icp_rounds; ++round) {
    std::vector<Vec3d> src(src_scan.size()), src_n(src_scan.size());
    for (size_t i = 0; i < src.size(); ++i) {
      src[i] = p.m_from_scan.Apply(src_scan[i]);
      src_n[i] = p.m_from_scan.ApplyToDirection(src_n_scan[i]);
    }
    Vec3d origin = Vec3d::Zero();
    for (const Vec3d& q : src) origin += q;
    origin /= static_cast<double>(src.size());
    double residual = 0;
    cv::Matx44d pose;
    icp.registerModelToScene(AsIcpCloud(src, src_n, origin), AsIcpCloud(dst, dst_n, origin),
                             residual, pose);
    RigidTransform local;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) local.rotation(r, c) = pose(r, c);
      local.translation[r] = pose(r, 3);
    }
    if (!local.rotation.allFinite() || !local.translation.allFinite())
      return Error{p.name() + ": ICP returned a non-finite pose"};
    // Re-orthonormalise (the ICP composes linearised rotations).
    local.rotation = Eigen::Quaterniond(local.rotation).normalized().toRotationMatrix();
    RigidTransform shift_in, shift_out;
    shift_in.translation = -origin;
    shift_out.translation = origin;
    const RigidTransform c = shift_out * local * shift_in;
    move = MaxMove(c, p);
    p.m_from_scan = c * p.m_from_scan;
    ++p.report.icp_rounds;
    p.report.last_icp_move_mm = move;
    if (move <= options.converged_mm) return Status::Ok();
  }
  // Point-to-plane steps on a nearly flat overlap can keep swapping correspondences along its
  // weakly held direction: the last rounds then wobble by a few converged_mm (0.08 mm measured on
  // an AVX-512 machine where OpenCV's kd-tree picks other neighbours). The polish below refines
  // from there and must converge itself; only an ICP still travelling is an error here.
  if (move <= 10 * options.converged_mm) return Status::Ok();
  return Error{p.name() + ": ICP did not converge in " + std::to_string(options.max_icp_rounds) +
               " rounds (the last moved the patch by " + Format("%.4f", move) +
               " mm, converged_mm " + Format("%.4f", options.converged_mm) + ")"};
}

// The fixed patches' heights on the mosaic grid (M's Z over its XY, one texel per cell), each
// patch resampled from the triangles of its own scan grid (ResampleToCanvasGrid), averaged where
// several measured a texel, smoothed like the moving samples (CollectPoints); NaN elsewhere.
struct HeightRaster {
  cv::Mat z;  // CV_32F, row 0 at M's Y = y0 (rows follow +Y, as the mosaic's)
  double x0 = 0, y0 = 0, cell = 1;
  // Bilinear height and gradient at M's (x, y); false where a corner is missing.
  bool Sample(double x, double y, double& h, double& hx, double& hy) const {
    const double u = (x - x0) / cell - 0.5, v = (y - y0) / cell - 0.5;
    const int i = static_cast<int>(std::floor(u)), j = static_cast<int>(std::floor(v));
    if (i < 0 || j < 0 || i + 1 >= z.cols || j + 1 >= z.rows) return false;
    const float a = z.at<float>(j, i), b = z.at<float>(j, i + 1);
    const float c = z.at<float>(j + 1, i), d = z.at<float>(j + 1, i + 1);
    if (!std::isfinite(a) || !std::isfinite(b) || !std::isfinite(c) || !std::isfinite(d))
      return false;
    const double fu = u - i, fv = v - j;
    h = (1 - fv) * ((1 - fu) * a + fu * b) + fv * ((1 - fu) * c + fu * d);
    hx = ((1 - fv) * (b - a) + fv * (d - c)) / cell;
    hy = ((1 - fu) * (c - a) + fu * (d - b)) / cell;
    return true;
  }
};

Result<HeightRaster> FixedHeights(const std::vector<Patch>& patches, const std::vector<int>& fixed,
                                  const Mosaic& g, double smooth_mm) {
  HeightRaster out;
  out.x0 = g.x0, out.y0 = g.y0, out.cell = g.cell;
  cv::Mat sum = cv::Mat::zeros(g.h, g.w, CV_32F), count = cv::Mat::zeros(g.h, g.w, CV_32F);
  RigidTransform grid_from_m;  // M shifted so that the mosaic's corner is the origin
  grid_from_m.translation = Vec3d(-g.x0, -g.y0, 0);
  ResampleOptions ro;
  ro.pitch_mm = g.cell;
  ro.find_holes = false;  // only measured texels are read (was a third of the registration)
  for (int f : fixed) {
    const Patch& p = patches[static_cast<size_t>(f)];
    CanvasResult c = p.canvas;
    c.canvas_from_scan = grid_from_m * p.m_from_scan;
    c.extent_mm = Eigen::Vector2d(g.w * g.cell, g.h * g.cell);
    c.frame = FrameBoxes{};
    Result<HeightField> hf = ResampleToCanvasGrid(p.in->scan, c, ro);
    if (!hf.ok()) return hf.error();
    const int rows = std::min(g.h, hf->height()), cols = std::min(g.w, hf->width());
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x) {
        // The field's row 0 is at the top (Y = height): mosaic row y is field row H - 1 - y.
        const int fy = hf->height() - 1 - y;
        if (hf->state(x, fy) != TexelState::kMeasured) continue;
        sum.at<float>(y, x) += hf->height_mm(x, fy);
        count.at<float>(y, x) += 1;
      }
  }
  cv::Mat mask = count > 0, weight;
  mask.convertTo(weight, CV_32F, 1.0 / 255);
  cv::Mat mean = cv::Mat::zeros(g.h, g.w, CV_32F);
  cv::divide(sum, cv::max(count, 1.0f), mean);
  mean = mean.mul(weight);
  const double sigma = std::max(0.3, smooth_mm / g.cell);
  cv::Mat bz, bw;
  cv::GaussianBlur(mean, bz, cv::Size(), sigma);
  cv::GaussianBlur(weight, bw, cv::Size(), sigma);
  out.z = cv::Mat(g.h, g.w, CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  for (int y = 0; y < g.h; ++y)
    for (int x = 0; x < g.w; ++x)
      if (bw.at<float>(y, x) >= 0.9f)
        out.z.at<float>(y, x) = bz.at<float>(y, x) / bw.at<float>(y, x);
  return out;
}

// Step 3b: the polish. Gauss-Newton over the 6 DOF of the moving patch minimising the height
// difference between its (smoothed) samples and the fixed patches' surface, sum of Huber(M's Z -
// H(M's X, Y)), reweighted every iteration (IRLS, scale from the residuals' MAD). Why, after the
// ICP: on a canvas, OpenCV's point-to-plane ICP pins height and tilt but leaves the in-plane
// rotation in a flat valley (it settles anywhere within ~0.1 deg, up to a texel at a patch's far
// end); the height field's gradients in the Jacobian pull in-plane directly and deterministically.
Status PolishStep(std::vector<Patch>& patches, int moving, const std::vector<int>& fixed,
                  const Mosaic& g, const PatchRegistrationOptions& options) {
  Patch& p = patches[static_cast<size_t>(moving)];
  Result<HeightRaster> fixed_z = FixedHeights(patches, fixed, g, options.smooth_mm);
  if (!fixed_z.ok()) return Error{p.name() + ": " + fixed_z.error().message};
  const HeightRaster& H = *fixed_z;
  // The moving samples over the fixed surface, thinned to about max_polish_points.
  std::vector<size_t> use;
  {
    std::vector<size_t> over;
    for (size_t k = 0; k < p.points.size(); ++k) {
      const Vec3d m = p.m_from_scan.Apply(p.points[k]);
      double h, hx, hy;
      if (H.Sample(m.x(), m.y(), h, hx, hy)) over.push_back(k);
    }
    const size_t stride = StrideFor(over.size(), static_cast<size_t>(options.max_polish_points));
    for (size_t i = 0; i < over.size(); i += stride) use.push_back(over[i]);
  }
  if (use.size() < 200)
    return Error{p.name() + ": too few samples over the other patches to register (" +
                 std::to_string(use.size()) + ")"};
  Vec3d origin = Vec3d::Zero();
  for (size_t k : use) origin += p.m_from_scan.Apply(p.points[k]);
  origin /= static_cast<double>(use.size());
  double move = 0;
  std::vector<double> recent;
  for (int it = 0; it < options.polish_iterations; ++it) {
    std::vector<double> res;
    std::vector<Eigen::Matrix<double, 6, 1>> rows;
    res.reserve(use.size()), rows.reserve(use.size());
    for (size_t k : use) {
      const Vec3d m = p.m_from_scan.Apply(p.points[k]);
      double h, hx, hy;
      if (!H.Sample(m.x(), m.y(), h, hx, hy)) continue;
      // r = H(x, y) - z; moving m by delta changes r by grad . delta, grad = (hx, hy, -1).
      const Vec3d grad(hx, hy, -1);
      Eigen::Matrix<double, 6, 1> j;
      j.head<3>() = (m - origin).cross(grad);
      j.tail<3>() = grad;
      rows.push_back(j);
      res.push_back(h - m.z());
    }
    if (rows.size() < 200)
      return Error{p.name() + ": slid off the other patches while registering"};
    std::vector<double> abs_dev(res.size());
    const double med = Median(res);
    for (size_t i = 0; i < res.size(); ++i) abs_dev[i] = std::abs(res[i] - med);
    const double sigma = std::max(1e-4, 1.4826 * Median(abs_dev));
    const double k_huber = options.huber_sigmas * sigma;
    Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    for (size_t i = 0; i < rows.size(); ++i) {
      const double w = std::abs(res[i]) <= k_huber ? 1.0 : k_huber / std::abs(res[i]);
      a += w * rows[i] * rows[i].transpose();
      b += w * rows[i] * res[i];
    }
    // Minimise sum w (r + J delta)^2: delta = -(J'WJ)^-1 J'W r.
    const Eigen::Matrix<double, 6, 1> delta = -a.ldlt().solve(b);
    if (!delta.allFinite()) return Error{p.name() + ": the registration became singular"};
    RigidTransform c;
    const Vec3d w = delta.head<3>();
    c.rotation =
        w.norm() > 0 ? Mat3d(Eigen::AngleAxisd(w.norm(), w.normalized())) : Mat3d::Identity();
    c.translation = origin - c.rotation * origin + delta.tail<3>();
    move = MaxMove(c, p);
    p.m_from_scan = c * p.m_from_scan;
    recent.push_back(move);
    if (move <= 0.2 * options.converged_mm) return Status::Ok();
  }
  // The reweighting and the samples entering and leaving the overlap make the last steps wobble
  // by a few hundredths of a mm where a direction is weakly held: settled when they all stay
  // within converged_mm.
  if (recent.size() >= 5 &&
      *std::max_element(recent.end() - 5, recent.end()) <= options.converged_mm)
    return Status::Ok();
  return Error{p.name() + ": registration did not converge in " +
               std::to_string(options.polish_iterations) + " iterations (the last moved it by " +
               Format("%.4f", move) + " mm, converged_mm " + Format("%.4f", options.converged_mm) +
               ")"};
}

// Canvas frame (in M) from every registered canvas point: robust plane, X from the outlines.
struct CanvasFrame {
  RigidTransform canvas_from_m;
  Eigen::Vector2d extent{0, 0};
  double plane_rms_mm = 0;
  size_t plane_points = 0;
};

CanvasFrame FindCanvasFrame(const std::vector<Patch>& patches, double trim_sigmas) {
  size_t total = 0;
  for (const Patch& p : patches) total += p.points.size();
  const size_t stride = StrideFor(total, 300000);
  std::vector<Vec3d> pts;
  for (const Patch& p : patches)
    for (size_t k = 0; k < p.points.size(); k += stride)
      pts.push_back(p.m_from_scan.Apply(p.points[k]));
  PlaneFit plane = FitPlanePca(pts);
  Vec3d n = plane.axes.col(2);
  if (n.z() < 0) n = -n;
  // Relief trimmed: points far above the plane (in robust sigmas) left out of the refit.
  std::vector<double> d;
  for (const Vec3d& q : pts) d.push_back((q - plane.centroid).dot(n));
  const double med = Median(d);
  std::vector<double> dev;
  for (double v : d) dev.push_back(std::abs(v - med));
  const double sigma = 1.4826 * Median(dev);
  std::vector<Vec3d> kept;
  for (size_t i = 0; i < pts.size(); ++i)
    if (d[i] <= med + trim_sigmas * sigma) kept.push_back(pts[i]);
  if (kept.size() >= 3) {
    plane = FitPlanePca(kept);
    n = plane.axes.col(2);
    if (n.z() < 0) n = -n;
  }
  double ss = 0;
  for (const Vec3d& q : kept) ss += std::pow((q - plane.centroid).dot(n), 2);
  // X: the canvas X axes of the patches whose outline was fitted, else M's X.
  Vec3d x = Vec3d::Zero();
  for (const Patch& p : patches) {
    if (!p.canvas.outline_fitted) continue;
    Vec3d ax =
        p.m_from_scan.ApplyToDirection(p.canvas.canvas_from_scan.rotation.row(0).transpose());
    x += ax.x() >= 0 ? ax : Vec3d(-ax);
  }
  if (x.isZero()) x = Vec3d::UnitX();
  x = (x - x.dot(n) * n).normalized();
  const Vec3d y = n.cross(x);
  CanvasFrame f;
  f.canvas_from_m.rotation.row(0) = x.transpose();
  f.canvas_from_m.rotation.row(1) = y.transpose();
  f.canvas_from_m.rotation.row(2) = n.transpose();
  double u0 = 1e300, v0 = 1e300, u1 = -1e300, v1 = -1e300;
  for (const Patch& p : patches)
    for (const Vec3d& q : p.points) {
      const Vec3d c = f.canvas_from_m.rotation * p.m_from_scan.Apply(q);
      u0 = std::min(u0, c.x()), u1 = std::max(u1, c.x());
      v0 = std::min(v0, c.y()), v1 = std::max(v1, c.y());
    }
  f.canvas_from_m.translation = -Vec3d(u0, v0, n.dot(plane.centroid));
  f.extent = {u1 - u0, v1 - v0};
  f.plane_rms_mm = kept.empty() ? 0 : std::sqrt(ss / static_cast<double>(kept.size()));
  f.plane_points = kept.size();
  return f;
}

double RotationDeg(const Mat3d& r) {
  return Eigen::AngleAxisd(r).angle() * 180.0 / 3.14159265358979323846;
}

}  // namespace

Status PatchRegistrationOptions::Validate() const {
  auto positive = [](const char* name, double v, const char* unit) -> Status {
    if (!(std::isfinite(v) && v > 0))
      return Error{std::string(name) + " must be > 0 " + unit + ", got " + FormatNumber(v)};
    return Status::Ok();
  };
  for (const auto& [name, v, unit] :
       {std::tuple{"min_overlap_mm2", min_overlap_mm2, "(mm^2)"},
        std::tuple{"lowpass_mm", lowpass_mm, "(mm)"}, std::tuple{"search_mm", search_mm, "(mm)"},
        std::tuple{"smooth_mm", smooth_mm, "(mm)"},
        std::tuple{"huber_sigmas", huber_sigmas, "(MADs)"},
        std::tuple{"highpass_mm", highpass_mm, "(mm)"},
        std::tuple{"icp_rejection_scale", icp_rejection_scale, "(robust sigmas)"},
        std::tuple{"converged_mm", converged_mm, "(mm)"},
        std::tuple{"max_correction_mm", max_correction_mm, "(mm)"},
        std::tuple{"max_overlap_rms_mm", max_overlap_rms_mm, "(mm)"},
        std::tuple{"feather_mm", feather_mm, "(mm)"}})
    if (Status s = positive(name, v, unit); !s.ok()) return s;
  if (!(min_correlation_peak >= 0 && min_correlation_peak < 1))
    return Error{"min_correlation_peak must be in [0, 1), got " +
                 FormatNumber(min_correlation_peak)};
  for (const auto& [name, v, lo, hi] :
       {std::tuple{"icp_iterations", icp_iterations, 1, 10000},
        std::tuple{"icp_levels", icp_levels, 1, 10},
        std::tuple{"max_icp_points", max_icp_points, 100, 10000000},
        std::tuple{"max_icp_rounds", max_icp_rounds, 1, 1000},
        std::tuple{"polish_iterations", polish_iterations, 1, 1000},
        std::tuple{"max_polish_points", max_polish_points, 200, 10000000},
        std::tuple{"global_rounds", global_rounds, 0, 100}})
    if (v < lo || v > hi)
      return Error{std::string(name) + " must be in [" + std::to_string(lo) + ", " +
                   std::to_string(hi) + "], got " + std::to_string(v)};
  return Status::Ok();
}

Result<PatchRegistrationResult> RegisterPatches(const std::vector<ScanPatch>& inputs,
                                                const PatchRegistrationOptions& options,
                                                const CanvasOptions& canvas_options,
                                                const ResampleOptions& resample_options) {
  if (Status s = options.Validate(); !s.ok()) return Error{"patch options: " + s.message()};
  if (inputs.size() < 2)
    return Error{"patches: " + std::to_string(inputs.size()) +
                 " patch(es) given, registration needs at least 2"};
  const int n = static_cast<int>(inputs.size());
  std::vector<Patch> patches(inputs.size());
  for (int i = 0; i < n; ++i) {
    Patch& p = patches[static_cast<size_t>(i)];
    p.in = &inputs[static_cast<size_t>(i)];
    const RigidTransform& pose = p.in->rig_from_scan;
    if (!pose.rotation.allFinite() || !pose.translation.allFinite() ||
        !(pose.rotation.transpose() * pose.rotation).isApprox(Mat3d::Identity(), 1e-6) ||
        !(pose.rotation.determinant() > 0))
      return Error{p.name() + ": its nominal pose (rig_from_scan) is not a rigid transform"};
    Result<CanvasResult> canvas = ExtractCanvas(p.in->scan, canvas_options);
    if (!canvas.ok()) return canvas.error();
    p.canvas = std::move(canvas).value();
    CollectPoints(p, options.smooth_mm);
    if (p.points.size() < 1000)
      return Error{p.name() + ": only " + std::to_string(p.points.size()) +
                   " canvas samples, too few to register"};
    p.report.source = p.name();
    p.report.canvas_points = p.points.size();
    p.report.outline_fitted = p.canvas.outline_fitted;
  }

  // M: patch 0's canvas frame at its nominal pose.
  const RigidTransform m_from_rig =
      patches[0].canvas.canvas_from_scan * inputs[0].rig_from_scan.Inverse();
  for (Patch& p : patches) p.m_from_scan = p.nominal_m_from_scan = m_from_rig * p.in->rig_from_scan;

  // The mosaic grid: the sample spacing of patch 0, over every patch's nominal footprint.
  Mosaic g;
  {
    std::vector<double> spacing;
    const Grid<Vec3f>& xyz = inputs[0].scan.xyz_mm;
    for (int y = 0; y < xyz.height; y += 3)
      for (int x = 0; x + 1 < xyz.width; x += 3)
        if (IsValid(xyz(x, y)) && IsValid(xyz(x + 1, y)))
          spacing.push_back((xyz(x + 1, y) - xyz(x, y)).cast<double>().head<2>().norm());
    g.cell = std::max(1e-3, Median(spacing));
    Eigen::AlignedBox2d box;
    for (const Patch& p : patches)
      for (size_t k = 0; k < p.points.size(); k += 7)
        box.extend(p.m_from_scan.Apply(p.points[k]).head<2>());
    const double margin = options.max_correction_mm;
    g.x0 = box.min().x() - margin, g.y0 = box.min().y() - margin;
    const double gw = (box.sizes().x() + 2 * margin) / g.cell;
    const double gh = (box.sizes().y() + 2 * margin) / g.cell;
    if (!(gw * gh < 1e8))
      return Error{"patches: the nominal poses spread the patches over " +
                   Format("%.0f x %.0f mm", box.sizes().x(), box.sizes().y()) +
                   ", too large a canvas for their sample spacing (are the poses in mm?)"};
    g.w = static_cast<int>(std::ceil(gw)), g.h = static_cast<int>(std::ceil(gh));
  }
  const double cell_area = g.cell * g.cell;

  // Placement: breadth-first over the overlaps from patch 0.
  std::vector<int> placed = {0};
  std::vector<int> order;
  std::vector<bool> is_placed(inputs.size(), false);
  is_placed[0] = true;
  while (static_cast<int>(placed.size()) < n) {
    const cv::Mat cover_placed = Coverage(RasterOf(patches, placed, g).count);
    int best = -1;
    double best_area = 0;
    cv::Mat best_overlap;
    for (int j = 0; j < n; ++j) {
      if (is_placed[static_cast<size_t>(j)]) continue;
      cv::Mat o = OverlapMask(Coverage(RasterOf(patches, {j}, g).count), cover_placed);
      const double area = cv::countNonZero(o) * cell_area;
      if (area > best_area) best = j, best_area = area, best_overlap = o;
    }
    if (best < 0 || best_area < options.min_overlap_mm2) {
      std::string names;
      for (int j = 0; j < n; ++j)
        if (!is_placed[static_cast<size_t>(j)])
          names += (names.empty() ? "" : ", ") + patches[static_cast<size_t>(j)].name();
      return Error{names + ": does not overlap the other patches (largest shared canvas " +
                   Format("%.0f", best_area) + " mm^2 at the nominal poses, min_overlap_mm2 " +
                   Format("%.0f", options.min_overlap_mm2) +
                   "); check its pose in the patch list, or scan with more overlap"};
    }
    Patch& p = patches[static_cast<size_t>(best)];
    // Coarse, twice: plane, then the correlation of the relief.
    for (int pass = 0; pass < 2; ++pass) {
      const cv::Mat overlap =
          pass == 0 ? best_overlap
                    : OverlapMask(Coverage(RasterOf(patches, {best}, g).count), cover_placed);
      std::vector<Vec3d> mine, theirs;
      PointsIn(p, g, overlap, StrideFor(p.points.size(), 60000), false, mine, nullptr);
      for (int f : placed)
        PointsIn(patches[static_cast<size_t>(f)], g, overlap, 3, false, theirs, nullptr);
      if (mine.size() < 100 || theirs.size() < 100)
        return Error{p.name() + ": too few samples in its overlap with the placed patches"};
      p.m_from_scan = PlaneStep(mine, theirs) * p.m_from_scan;
      Result<RigidTransform> c =
          CorrelationStep(patches, best, placed, g, options, &p.report.correlation_pieces,
                          &p.report.correlation_peak);
      if (!c.ok()) return c.error();
      p.m_from_scan = *c * p.m_from_scan;
    }
    if (Status s = IcpStep(patches, best, placed, g, options); !s.ok()) return Error{s.message()};
    if (Status s = PolishStep(patches, best, placed, g, options); !s.ok())
      return Error{s.message()};
    placed.push_back(best);
    order.push_back(best);
    is_placed[static_cast<size_t>(best)] = true;
  }
  // Global passes: each patch against all the others, patch 0 included. Placement fitted every
  // patch to patch 0 one way only; left out here, patch 0 stayed where the others had been put
  // against it, and the rest sat together turned against it by up to 0.09 deg (measured over
  // grid seeds 1-24: registration error 0.03-0.36 texel, 6 of 24 over a quarter; with it and 4
  // passes, 0.03-0.24). The result's frame is fitted to all patches (FindCanvasFrame), so
  // moving patch 0 moves no reference.
  std::vector<int> everyone = {0};
  everyone.insert(everyone.end(), order.begin(), order.end());
  for (int round = 0; round < options.global_rounds; ++round) {
    for (int i : everyone) {
      std::vector<int> others;
      for (int j = 0; j < n; ++j)
        if (j != i) others.push_back(j);
      if (Status s = PolishStep(patches, i, others, g, options); !s.ok()) return Error{s.message()};
    }
  }

  // Corrections against the nominal poses.
  const RigidTransform rig_from_m = m_from_rig.Inverse();
  for (Patch& p : patches) {
    const RigidTransform c = p.m_from_scan * p.nominal_m_from_scan.Inverse();
    Vec3d centroid = Vec3d::Zero();
    for (const Vec3d& q : p.points) centroid += q;
    centroid /= static_cast<double>(p.points.size());
    const Vec3d m = p.nominal_m_from_scan.Apply(centroid);
    p.report.rig_from_scan = rig_from_m * p.m_from_scan;
    p.report.correction_deg = RotationDeg(c.rotation);
    p.report.correction_mm = (c.Apply(m) - m).norm();
    double worst = 0;
    for (size_t k = 0; k < p.points.size(); k += StrideFor(p.points.size(), 4000)) {
      const Vec3d q = p.nominal_m_from_scan.Apply(p.points[k]);
      worst = std::max(worst, (c.Apply(q) - q).norm());
    }
    p.report.max_correction_mm = worst;
    if (worst > options.max_correction_mm)
      return Error{p.name() + ": registration moved it by up to " + Format("%.1f", worst) +
                   " mm from its nominal pose, more than max_correction_mm " +
                   Format("%.1f", options.max_correction_mm) +
                   " (a wrong pose in the patch list, or a false match)"};
  }

  // Canvas frame and the merged grid.
  const CanvasFrame frame = FindCanvasFrame(patches, canvas_options.trim_sigmas);
  PatchRegistrationResult result;
  ResampleOptions ro = resample_options;
  std::vector<HeightField> fields;
  for (const Patch& p : patches) {
    CanvasResult c = p.canvas;
    c.canvas_from_scan = frame.canvas_from_m * p.m_from_scan;
    c.extent_mm = frame.extent;
    ResampleStats stats;
    Result<HeightField> f = ResampleToCanvasGrid(p.in->scan, c, ro, &stats);
    if (!f.ok()) return f.error();
    if (!(ro.pitch_mm > 0)) ro.pitch_mm = f->pitch_mm;
    result.resample.holes_filled += stats.holes_filled;
    result.resample.holes_unfilled += stats.holes_unfilled;
    result.resample.triangles_drawn += stats.triangles_drawn;
    result.resample.triangles_skipped += stats.triangles_skipped;
    fields.push_back(std::move(f).value());
  }
  const int w = fields[0].width(), h = fields[0].height();
  for (const HeightField& f : fields)
    DIGITIZE_CHECK(f.width() == w && f.height() == h, "patch grids differ in size");
  const double pitch = fields[0].pitch_mm;
  // Blend weights: distance (texels) to the patch's unmeasured border, ramped over feather_mm.
  std::vector<cv::Mat> weights;
  for (HeightField& f : fields) {
    cv::Mat measured(h, w, CV_8U);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        measured.at<uint8_t>(y, x) = f.state(x, y) == TexelState::kMeasured ? 255 : 0;
    cv::Mat dist;
    cv::distanceTransform(measured, dist, cv::DIST_L2, 3);
    weights.push_back(dist);
  }
  HeightField& out = result.field;
  out.pitch_mm = pitch;
  out.height_mm = Grid<float>(w, h, 0.0f);
  out.state = Grid<TexelState>(w, h, TexelState::kOutside);
  result.coverage = Grid<uint8_t>(w, h, 0);
  const double ramp = std::max(1.0, options.feather_mm / pitch);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      // The best state any patch has here, then the weighted mean of the patches with it.
      TexelState best = TexelState::kOutside;
      auto rank = [](TexelState s) {
        switch (s) {
          case TexelState::kMeasured:
            return 3;
          case TexelState::kFilled:
            return 2;
          case TexelState::kUnfilled:
            return 1;
          default:
            return 0;
        }
      };
      int covered = 0;
      for (const HeightField& f : fields) {
        if (rank(f.state(x, y)) > rank(best)) best = f.state(x, y);
        covered += f.state(x, y) == TexelState::kMeasured;
      }
      result.coverage(x, y) = static_cast<uint8_t>(std::min(covered, 255));
      if (best == TexelState::kOutside) continue;
      double sum = 0, wsum = 0;
      for (size_t i = 0; i < fields.size(); ++i) {
        if (fields[i].state(x, y) != best) continue;
        const double wt = best == TexelState::kMeasured
                              ? std::clamp(weights[i].at<float>(y, x) / ramp, 0.02, 1.0)
                              : 1.0;
        sum += wt * fields[i].height_mm(x, y);
        wsum += wt;
      }
      out.height_mm(x, y) = static_cast<float>(sum / wsum);
      out.state(x, y) = best;
    }
  }
  ResampleStats& rs = result.resample;
  rs.texels = static_cast<size_t>(w) * h;
  for (TexelState s : out.state.data) {
    rs.measured += s == TexelState::kMeasured;
    rs.filled += s == TexelState::kFilled;
    rs.unfilled += s == TexelState::kUnfilled;
    rs.outside += s == TexelState::kOutside;
  }
  result.uncovered_texels = rs.outside;

  // Residuals per overlap.
  double worst_rms = 0, worst_max = 0;
  for (int a = 0; a < n; ++a) {
    for (int b = a + 1; b < n; ++b) {
      OverlapResidual r;
      r.patch_a = a, r.patch_b = b;
      double ss = 0, sum = 0;
      const HeightField &fa = fields[static_cast<size_t>(a)], &fb = fields[static_cast<size_t>(b)];
      for (size_t i = 0; i < fa.state.data.size(); ++i) {
        if (fa.state.data[i] != TexelState::kMeasured || fb.state.data[i] != TexelState::kMeasured)
          continue;
        const double d = double{fa.height_mm.data[i]} - fb.height_mm.data[i];
        ++r.texels;
        ss += d * d, sum += d;
        r.max_mm = std::max(r.max_mm, std::abs(d));
      }
      if (r.texels == 0) continue;
      r.rms_mm = std::sqrt(ss / static_cast<double>(r.texels));
      r.mean_mm = sum / static_cast<double>(r.texels);
      worst_rms = std::max(worst_rms, r.rms_mm);
      worst_max = std::max(worst_max, r.max_mm);
      result.overlaps.push_back(r);
      if (r.rms_mm > options.max_overlap_rms_mm)
        return Error{patches[static_cast<size_t>(a)].name() + " and " +
                     patches[static_cast<size_t>(b)].name() + ": height residual RMS " +
                     Format("%.3f", r.rms_mm) + " mm over " + std::to_string(r.texels) +
                     " texels of their overlap after registration, above max_overlap_rms_mm " +
                     Format("%.3f", options.max_overlap_rms_mm) +
                     " (the patches do not fit together: a moved painting, a wrong pose?)"};
    }
  }

  // The canvas as later stages see it (the rig frame is "the scan frame").
  CanvasResult& c = result.canvas;
  c = patches[0].canvas;
  c.canvas_from_scan = frame.canvas_from_m * m_from_rig;
  c.extent_mm = frame.extent;
  c.plane_rms_mm = frame.plane_rms_mm;
  c.plane_points = frame.plane_points;
  std::vector<double> sigmas;
  c.frame = FrameBoxes{};
  c.warnings.clear();
  c.hidden_edges.clear();
  c.outline_fitted = false;
  for (const Patch& p : patches) {
    sigmas.push_back(p.canvas.noise_sigma_mm);
    c.outline_fitted = c.outline_fitted || p.canvas.outline_fitted;
    for (int side = 0; side < 4; ++side)
      if (p.canvas.frame.raise_mm[side] > c.frame.raise_mm[side]) {
        c.frame.raise_mm[side] = p.canvas.frame.raise_mm[side];
        c.frame.width_mm[side] = p.canvas.frame.width_mm[side];
        c.frame.gap_mm[side] = p.canvas.frame.gap_mm[side];
      }
    for (const std::string& e : p.canvas.hidden_edges)
      if (std::find(c.hidden_edges.begin(), c.hidden_edges.end(), e) == c.hidden_edges.end())
        c.hidden_edges.push_back(e);
    for (const std::string& wn : p.canvas.warnings) c.warnings.push_back(p.name() + ": " + wn);
  }
  c.noise_sigma_mm = Median(sigmas);
  c.outline_note = c.outline_fitted ? "" : "no patch's canvas outline could be fitted";
  if (result.uncovered_texels > 0)
    c.warnings.push_back(std::to_string(result.uncovered_texels) +
                         " texels of the canvas rectangle are in no patch (a gap in the coverage)");
  out.frame = c.frame;

  for (const Patch& p : patches) result.patches.push_back(p.report);
  double worst_correction = 0;
  for (const PatchReport& r : result.patches)
    worst_correction = std::max(worst_correction, r.max_correction_mm);
  result.brief = Format(
      "%d patches registered, %zu overlaps: residual RMS <= %.4f mm, max %.3f mm; corrections up "
      "to "
      "%.2f mm from the nominal poses",
      n, result.overlaps.size(), worst_rms, worst_max, worst_correction);

  for (float v : out.height_mm.data) DIGITIZE_CHECK(std::isfinite(v), "non-finite merged height");
  return result;
}

}  // namespace digitize
