// Step 5b of canvas extraction (canvas.cpp's header comment): the visible canvas as a rectangle
// in the canvas plane, its mask, and the canvas edges a frame lip hides.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "canvas_steps.h"

namespace digitize::canvas_detail {
namespace {

//
// A canvas is a rectangle and what hides it (the frame's edges) runs parallel to its sides, so
// the visible canvas is a rectangle in the canvas plane. Each scan pixel is placed in the plane
// where its ray meets it, by a homography fitted to the canvas samples (exact for a pinhole or
// orthographic scanner looking at a plane): no noise, no relief, and a place for missing
// samples too. The rectangle's sides are fitted there: angle from line fits of the outermost
// canvas-like samples per bin along each side, position by the threshold that best separates
// canvas-like samples (mask, within the noise of the local canvas height) from the rest. The
// mask is then every pixel the rectangle holds, so dropouts at the border do not notch it and
// samples climbing a bevel or a wall's foot above the canvas height are left out.
constexpr double kOutlineBandMm = 6;          // side band: this far either side of the first guess
constexpr double kOutlineBandSpacings = 20;   // ... or this many sample spacings, the larger
constexpr double kOutlineCornerShare = 0.04;  // side ends left out (corners are rounded by noise)
constexpr double kOutlineCornerMm = 5;
constexpr double kOutlineHeightSigmas = 4;     // canvas-like: within this many noise sigmas
constexpr double kOutlineHeightFloorMm = 0.1;  // ... or this, of the side's local canvas height
constexpr int kOutlineMinBins = 20;            // a side needs this many bins with a sample
constexpr double kOutlineMinSpanShare = 0.3;   // ... spanning this share of its length
constexpr double kOutlineMaxSideDisagreeDeg = 0.5;  // sides' angles agree within this, else no
                                                    // rectangle
constexpr double kOutlineMaxDisagreement = 0.05;    // rectangle vs mask (valid pixels): share
// Overhang: frame samples (higher than the canvas by kOverhangRiseMm) lying over the visible
// canvas by more than max(kOverhangMm, kOverhangSpacings spacings), along kOverhangShare of a
// side, mean the frame hides the canvas's edge there (a lip).
constexpr double kOverhangRiseMm = 1.0;
constexpr double kOverhangMm = 1.0;
constexpr double kOverhangSpacings = 2.0;
constexpr double kOverhangShare = 0.2;
// Where each scan pixel's ray meets the canvas plane: a homography pixel -> (u, v).
struct PlaneMap {
  cv::Matx33d H;
  double z_sign = 1;  // sign of the third coordinate on the plane's side of the horizon
  // Pixels whose rays miss the plane (beyond its horizon in the image: the homography's third
  // coordinate changes sign) have no place on it: NaN, which every test reads as outside.
  Eigen::Vector2d operator()(int x, int y) const {
    const double X = H(0, 0) * x + H(0, 1) * y + H(0, 2), Y = H(1, 0) * x + H(1, 1) * y + H(1, 2),
                 Z = H(2, 0) * x + H(2, 1) * y + H(2, 2);
    if (!(Z * z_sign > 1e-12))
      return Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
    return Eigen::Vector2d(X / Z, Y / Z);
  }
};

// The homography fitted to the (relief-trimmed by reprojection) canvas samples of `fit_mask`;
// none (and why in `note`) from too few samples or a degenerate fit.
std::optional<PlaneMap> FitPlaneMap(const Grid<Vec3f>& xyz, const cv::Mat& fit_mask,
                                    const LocalFrame& frame, std::string* note) {
  const int w = xyz.width, h = xyz.height;
  cv::Mat hom;
  cv::Point2f ref_px;  // a canvas sample's pixel: on the plane's side of the horizon
  {
    const size_t count = static_cast<size_t>(cv::countNonZero(fit_mask));
    const int stride = SampleStride(count, 20000);
    std::vector<cv::Point2f> px, uv;
    for (int y = 0; y < h; y += stride) {
      const uint8_t* m = fit_mask.ptr<uint8_t>(y);
      for (int x = 0; x < w; x += stride)
        if (m[x] && Usable(xyz(x, y))) {
          const Eigen::Vector2f q = frame.UV(xyz(x, y));
          px.emplace_back(static_cast<float>(x), static_cast<float>(y));
          uv.emplace_back(q.x(), q.y());
        }
    }
    if (px.size() < 12) {
      *note = "too few canvas samples for the outline";
      return std::nullopt;
    }
    ref_px = px[px.size() / 2];
    for (int pass = 0; pass < 2; ++pass) {
      hom = cv::findHomography(px, uv, 0);
      if (hom.empty() || pass == 1) break;
      std::vector<cv::Point2f> proj;
      cv::perspectiveTransform(px, proj, hom);
      std::vector<double> err(px.size());
      for (size_t i = 0; i < px.size(); ++i) err[i] = cv::norm(proj[i] - uv[i]);
      std::vector<double> tmp = err;
      const double limit = 3 * kMadToSigma * std::max(Median(tmp), 1e-6);
      std::vector<cv::Point2f> px2, uv2;
      for (size_t i = 0; i < px.size(); ++i)
        if (err[i] <= limit) px2.push_back(px[i]), uv2.push_back(uv[i]);
      if (px2.size() < 12) break;
      px.swap(px2), uv.swap(uv2);
    }
    if (hom.empty() || !cv::checkRange(hom)) {
      *note = "no homography from the scan pixels to the canvas plane";
      return std::nullopt;
    }
  }
  const cv::Matx33d H(hom);
  const double z_sign = H(2, 0) * ref_px.x + H(2, 1) * ref_px.y + H(2, 2) >= 0 ? 1.0 : -1.0;
  return PlaneMap{H, z_sign};
}

// Rows in parallel, gathered in row order (the same result whatever the schedule).
template <class RowFn, class PerRow>
void GatherRows(int h, const RowFn& row_fn, PerRow& per_row) {
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) row_fn(y, per_row[static_cast<size_t>(y)]);
  });
}

// The mask's boundary pixels, placed on the plane.
std::vector<cv::Point2f> MaskBoundaryOnPlane(const cv::Mat& mask, const PlaneMap& plane_of) {
  const int w = mask.cols, h = mask.rows;
  std::vector<cv::Point2f> boundary;
  {
    std::vector<std::vector<cv::Point2f>> per_row(static_cast<size_t>(h));
    GatherRows(
        h,
        [&](int y, std::vector<cv::Point2f>& row_out) {
          const uint8_t* m = mask.ptr<uint8_t>(y);
          for (int x = 0; x < w; ++x) {
            if (!m[x]) continue;
            const bool edge = x == 0 || y == 0 || x == w - 1 || y == h - 1 || !m[x - 1] ||
                              !m[x + 1] || !mask.ptr<uint8_t>(y - 1)[x] ||
                              !mask.ptr<uint8_t>(y + 1)[x];
            if (!edge) continue;
            const Eigen::Vector2d q = plane_of(x, y);
            if (q.allFinite())
              row_out.emplace_back(static_cast<float>(q.x()), static_cast<float>(q.y()));
          }
        },
        per_row);
    for (const auto& row : per_row) boundary.insert(boundary.end(), row.begin(), row.end());
  }
  return boundary;
}

// First guess: the minimum-area rectangle of the boundary.
struct FirstGuess {
  double angle0 = 0;  // first axis in (u, v), radians
  Eigen::Vector2d centre{0, 0};
  double half0[2] = {0, 0};       // half sizes along the first and the second axis
  std::array<double, 4> edge0{};  // outward offsets of the sides, as Outline::edge
};

FirstGuess GuessRectangle(const std::vector<cv::Point2f>& boundary) {
  const cv::RotatedRect guess = cv::minAreaRect(boundary);
  cv::Point2f corner[4];
  guess.points(corner);
  const cv::Point2f e0 = corner[1] - corner[0], e1 = corner[2] - corner[1];
  FirstGuess out;
  out.angle0 = std::atan2(e0.y, e0.x);
  out.centre = Eigen::Vector2d(guess.center.x, guess.center.y);
  out.half0[0] = 0.5 * cv::norm(e0);
  out.half0[1] = 0.5 * cv::norm(e1);
  out.edge0 = {out.half0[0], out.half0[0], out.half0[1], out.half0[1]};
  return out;
}

// A pixel in the band around the first guess, on its nearest side (32 bytes: millions of them
// on a large scan's band).
struct Cand {
  float t, o;    // along the side, outwards (first-guess frame)
  float u, v;    // where the pixel's ray meets the plane
  float uo, vo;  // the sample projected on the plane (valid only)
  float height;  // above the plane (valid only)
  uint8_t side, in_mask, usable, scan_border;
};

// The samples in the band (mm either side of the first guess), each on its nearest side, handed
// out a side at a time in row order: one pass over the scan counts each row's candidates per side
// and where they lie, and a side's are then read from those spans alone. All four sides at once
// were ~250 MB on a 12288 x 9216 scan (the preprocess's peak, beside the scan).
class SideBand {
 public:
  SideBand(const Grid<Vec3f>& xyz, const cv::Mat& mask, const cv::Mat& valid,
           const LocalFrame& frame, const PlaneMap& plane_of, const FirstGuess& guess, double band)
      : xyz_(xyz),
        mask_(mask),
        valid_(valid),
        frame_(frame),
        plane_of_(plane_of),
        guess_(guess),
        band_(band),
        rows_(static_cast<size_t>(xyz.height)) {
    for (int s = 0; s < 4; ++s) n0_[s] = SideNormal(s, guess.angle0);
    const int w = xyz.width;
    tbb::parallel_for(tbb::blocked_range<int>(0, xyz.height, 16),
                      [&](const tbb::blocked_range<int>& r) {
                        for (int y = r.begin(); y < r.end(); ++y) {
                          std::array<Span, 4>& row = rows_[static_cast<size_t>(y)];
                          for (int x = 0; x < w; ++x) {
                            const int s = Candidate(x, y, nullptr);
                            if (s < 0) continue;
                            Span& span = row[static_cast<size_t>(s)];
                            span.x0 = std::min(span.x0, x), span.x1 = x;
                            ++span.count;
                          }
                        }
                      });
  }

  std::vector<Cand> Gather(int side) const {
    const size_t h = rows_.size(), s = static_cast<size_t>(side);
    std::vector<size_t> start(h + 1, 0);
    for (size_t y = 0; y < h; ++y) start[y + 1] = start[y] + rows_[y][s].count;
    std::vector<Cand> cands(start[h]);
    tbb::parallel_for(tbb::blocked_range<int>(0, static_cast<int>(h), 16),
                      [&](const tbb::blocked_range<int>& r) {
                        Cand c;
                        for (int y = r.begin(); y < r.end(); ++y) {
                          const Span& span = rows_[static_cast<size_t>(y)][s];
                          size_t next = start[static_cast<size_t>(y)];
                          for (int x = span.x0; x <= span.x1; ++x)
                            if (Candidate(x, y, &c) == side) cands[next++] = c;
                        }
                      });
    return cands;
  }

 private:
  struct Span {
    int x0 = std::numeric_limits<int>::max(), x1 = -1;
    size_t count = 0;
  };

  // The candidate at (x, y) into *c (its side; -1: none); only the side when c is null.
  int Candidate(int x, int y, Cand* c) const {
    const std::array<double, 4>& edge0 = guess_.edge0;
    const Eigen::Vector2d q = plane_of_(x, y), d = q - guess_.centre;
    int best = -1;
    double best_dist = band_;
    for (int s = 0; s < 4; ++s) {
      const double dist = std::fabs(n0_[s].dot(d) - edge0[static_cast<size_t>(s)]);
      if (dist < best_dist) best = s, best_dist = dist;
    }
    if (best < 0) return -1;
    const double o = n0_[best].dot(d);
    // The band's inner half only gives the local canvas height: one sample in four will do.
    if (o < edge0[static_cast<size_t>(best)] - 0.5 * band_ && ((x | y) & 1)) return -1;
    if (!c) return best;
    const int w = xyz_.width, h = xyz_.height;
    *c = Cand{};
    c->side = static_cast<uint8_t>(best);
    c->o = static_cast<float>(o);
    c->t = static_cast<float>(n0_[best < 2 ? 2 : 0].dot(d));
    c->u = static_cast<float>(q.x()), c->v = static_cast<float>(q.y());
    c->in_mask = mask_.ptr<uint8_t>(y)[x] != 0;
    c->usable = valid_.ptr<uint8_t>(y)[x] != 0;
    c->scan_border = x == 0 || y == 0 || x == w - 1 || y == h - 1;
    if (c->usable) {
      const Eigen::Vector2f qo = frame_.UV(xyz_(x, y));
      c->uo = qo.x(), c->vo = qo.y();
      c->height = frame_.H(xyz_(x, y));
    }
    return best;
  }

  const Grid<Vec3f>& xyz_;
  const cv::Mat &mask_, &valid_;
  const LocalFrame& frame_;
  const PlaneMap& plane_of_;
  const FirstGuess& guess_;
  const double band_;
  Eigen::Vector2d n0_[4];
  std::vector<std::array<Span, 4>> rows_;
};

// Per side: the local canvas height (a line along the side, from the band's inner half),
// canvas-like samples (within `tol` of it: CanvasLike), open or closed, and the side's angle.
struct SideFits {
  std::array<Eigen::Vector2d, 4> height_line;  // height = [0] + [1] t
  std::array<double, 4> delta{}, weight{};     // angle against the guess; its weight
  std::array<double, 4> half_len{};            // half length of the side
  double tol = 0;                              // canvas-like: within this of the height line
};

bool CanvasLike(const Cand& c, const SideFits& fits) {
  return c.in_mask && c.usable &&
         c.height <= fits.height_line[c.side].dot(Eigen::Vector2d(1, c.t)) + fits.tol;
}

// Side s of `fits` from its candidates (and whether it is closed).
void FitSide(int s, const std::vector<Cand>& cands, const FirstGuess& guess, double band,
             double spacing, bool* closed_out, SideFits* fits_out) {
  const double(&half0)[2] = guess.half0;
  const std::array<double, 4>& edge0 = guess.edge0;
  SideFits& fits = *fits_out;
  bool& closed_s = *closed_out;
  std::array<Eigen::Vector2d, 4>& height_line = fits.height_line;
  std::array<double, 4>& delta = fits.delta;
  std::array<double, 4>& weight = fits.weight;
  std::array<double, 4>& half_len = fits.half_len;
  {
    const double e = edge0[static_cast<size_t>(s)];
    half_len[static_cast<size_t>(s)] = s < 2 ? half0[1] : half0[0];
    const double corner_cut =
        half_len[static_cast<size_t>(s)] -
        std::max(kOutlineCornerMm, kOutlineCornerShare * 2 * half_len[static_cast<size_t>(s)]);
    // Height line by trimmed least squares.
    std::vector<const Cand*> inner;
    for (const Cand& c : cands) {
      if (c.in_mask && c.usable && c.o < e - 0.5 * band && std::fabs(c.t) < corner_cut)
        inner.push_back(&c);
    }
    Eigen::Vector2d line(0, 0);
    for (int pass = 0; pass < 3 && inner.size() >= 3; ++pass) {
      Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
      Eigen::Vector2d atb = Eigen::Vector2d::Zero();
      for (const Cand* c : inner) {
        const Eigen::Vector2d a(1, c->t);
        ata += a * a.transpose();
        atb += a * c->height;
      }
      if (std::fabs(ata.determinant()) < 1e-12) break;
      line = ata.ldlt().solve(atb);
      std::vector<double> r;
      for (const Cand* c : inner) r.push_back(c->height - line.dot(Eigen::Vector2d(1, c->t)));
      std::vector<double> tmp = r;
      const double med = Median(tmp);
      const double lim = 3 * kMadToSigma * std::max(Mad(r, med), 1e-4);
      std::vector<const Cand*> kept;
      for (size_t i = 0; i < inner.size(); ++i)
        if (std::fabs(r[i] - med) <= lim) kept.push_back(inner[i]);
      inner.swap(kept);
    }
    height_line[static_cast<size_t>(s)] = line;
    // Bins of one spacing along the side: the outermost canvas-like sample of each, unless it
    // lies on the scan's border (the canvas goes on beyond the view there).
    const int nbins = std::max(1, static_cast<int>(2 * corner_cut / spacing));
    std::vector<int> bin_best(static_cast<size_t>(nbins), -1);
    for (size_t i = 0; i < cands.size(); ++i) {
      const Cand& c = cands[i];
      if (!CanvasLike(c, fits) || std::fabs(c.t) >= corner_cut) continue;
      const int b = std::clamp(static_cast<int>((c.t + corner_cut) / spacing), 0, nbins - 1);
      int& best = bin_best[static_cast<size_t>(b)];
      if (best < 0 || c.o > cands[static_cast<size_t>(best)].o) best = static_cast<int>(i);
    }
    std::vector<Eigen::Vector2d> pts;  // (t, o)
    for (int b = 0; b < nbins; ++b) {
      const int best = bin_best[static_cast<size_t>(b)];
      if (best >= 0 && !cands[static_cast<size_t>(best)].scan_border)
        pts.emplace_back(-corner_cut + (b + 0.5) * spacing, cands[static_cast<size_t>(best)].o);
    }
    // Open: too little of the side's edge is in view to place it.
    closed_s = static_cast<int>(pts.size()) >= kOutlineMinBins &&
               pts.back().x() - pts.front().x() >=
                   kOutlineMinSpanShare * 2 * half_len[static_cast<size_t>(s)];
    if (!closed_s) return;
    double beta = 0;
    bool fitted = false;
    for (int pass = 0; pass < 4 && pts.size() >= 3; ++pass) {
      Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
      Eigen::Vector2d atb = Eigen::Vector2d::Zero();
      for (const auto& p : pts) {
        const Eigen::Vector2d a(1, p.x());
        ata += a * a.transpose();
        atb += a * p.y();
      }
      if (std::fabs(ata.determinant()) < 1e-12) break;
      const Eigen::Vector2d ab = ata.ldlt().solve(atb);
      beta = ab(1);
      fitted = true;
      std::vector<double> r;
      for (const auto& p : pts) r.push_back(p.y() - ab(0) - ab(1) * p.x());
      std::vector<double> tmp = r;
      const double med = Median(tmp);
      const double lim = std::max(3 * kMadToSigma * Mad(r, med), 0.5 * spacing);
      std::vector<Eigen::Vector2d> kept;
      for (size_t i = 0; i < pts.size(); ++i)
        if (std::fabs(r[i] - med) <= lim) kept.push_back(pts[i]);
      if (kept.size() == pts.size()) break;
      pts.swap(kept);
    }
    if (!fitted || static_cast<int>(pts.size()) < kOutlineMinBins) return;
    const double span = pts.back().x() - pts.front().x();
    if (span < kOutlineMinSpanShare * 2 * half_len[static_cast<size_t>(s)]) return;
    static constexpr double kSign[4] = {-1, 1, 1, -1};
    delta[static_cast<size_t>(s)] = std::atan(kSign[s] * beta);
    weight[static_cast<size_t>(s)] = static_cast<double>(pts.size()) * span * span;
  }
}

// Side positions in the refined frame: the threshold that best separates canvas-like samples
// (inside) from the others (outside); open sides reach the mask's extent. Frame samples lying
// over the visible canvas mark the side as overhung.
void PlaceSide(int s, const std::vector<Cand>& cands, const SideFits& fits, const FirstGuess& guess,
               double spacing, Outline* out_ptr) {
  Outline& out = *out_ptr;
  const std::array<Eigen::Vector2d, 4>& height_line = fits.height_line;
  const std::array<double, 4>& half_len = fits.half_len;
  const std::array<double, 4>& edge0 = guess.edge0;
  {
    const Eigen::Vector2d n = SideNormal(s, out.angle);
    const double corner_cut =
        half_len[static_cast<size_t>(s)] -
        std::max(kOutlineCornerMm, kOutlineCornerShare * 2 * half_len[static_cast<size_t>(s)]);
    std::vector<std::pair<float, int>> samples;  // (offset, +1 inside / -1 outside)
    double mask_extent = -std::numeric_limits<double>::max();
    for (size_t i = 0; i < cands.size(); ++i) {
      const Cand& c = cands[i];
      const double o = n.dot(Eigen::Vector2d(c.u, c.v) - out.centre);
      if (c.in_mask) mask_extent = std::max(mask_extent, o);
      if (!c.usable || std::fabs(c.t) >= corner_cut) continue;
      samples.emplace_back(static_cast<float>(o), CanvasLike(c, fits) ? 1 : -1);
    }
    if (!out.closed[static_cast<size_t>(s)] || samples.empty()) {
      out.closed[static_cast<size_t>(s)] = false;
      out.edge[static_cast<size_t>(s)] = mask_extent > -std::numeric_limits<double>::max()
                                             ? mask_extent + spacing
                                             : edge0[static_cast<size_t>(s)];
      return;
    }
    std::sort(samples.begin(), samples.end());
    long cost = 0;
    for (const auto& p : samples) cost += p.second > 0;
    long best = cost;
    size_t best_k = 0;  // edge before samples[best_k]
    for (size_t k = 0; k < samples.size(); ++k) {
      cost += samples[k].second > 0 ? -1 : 1;
      if (cost < best) best = cost, best_k = k + 1;
    }
    // The edge at the outermost canvas-like sample of the best split: pixels beyond it up to
    // the first other sample may be missing samples of a steep wall seen edge-on.
    const double e = best_k == 0 ? samples.front().first : samples[best_k - 1].first;
    out.edge[static_cast<size_t>(s)] = e;
    // Overhang: frame samples over the visible canvas.
    const double reach = std::max(kOverhangMm, kOverhangSpacings * spacing);
    size_t over = 0;
    for (size_t i = 0; i < cands.size(); ++i) {
      const Cand& c = cands[i];
      // A frame sample: outside the grown region, its ray past the edge.
      if (!c.usable || c.in_mask || std::fabs(c.t) >= corner_cut ||
          !(n.dot(Eigen::Vector2d(c.u, c.v) - out.centre) > e))
        continue;
      const double rise =
          c.height - height_line[static_cast<size_t>(s)].dot(Eigen::Vector2d(1, c.t));
      const double o = n.dot(Eigen::Vector2d(c.uo, c.vo) - out.centre);
      if (rise > kOverhangRiseMm && o < e - reach) ++over;
    }
    out.overhang[static_cast<size_t>(s)] = over > kOverhangShare * 2 * corner_cut / spacing;
  }
}

// The mask: every pixel whose ray meets the plane inside the rectangle, but for samples the
// grown region left out: those stay out unless they lie a sample spacing inside it, within
// the canvas's height band (a frame sample grazed at the very edge is no canvas).
// Not ok (why in the note) when it disagrees with the grown region.
void RectangleMask(const Grid<Vec3f>& xyz, const cv::Mat& mask, const cv::Mat& valid,
                   const LocalFrame& frame, const PlaneMap& plane_of, const SideFits& fits,
                   double tol, double spacing, Outline* out_ptr) {
  Outline& out = *out_ptr;
  const int w = xyz.width, h = xyz.height;
  const std::array<Eigen::Vector2d, 4>& height_line = fits.height_line;
  const std::array<double, 4>& half_len = fits.half_len;
  double band_mm = tol;
  for (int s = 0; s < 4; ++s)
    for (double t : {-half_len[static_cast<size_t>(s)], half_len[static_cast<size_t>(s)]})
      band_mm = std::max(
          band_mm, tol + std::fabs(height_line[static_cast<size_t>(s)].dot(Eigen::Vector2d(1, t))));
  out.mask = cv::Mat::zeros(h, w, CV_8U);
  std::array<Eigen::Vector2d, 4> normals;
  for (int s = 0; s < 4; ++s) normals[static_cast<size_t>(s)] = SideNormal(s, out.angle);
  std::atomic<size_t> differ{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 32), [&](const tbb::blocked_range<int>& r) {
    size_t local = 0;
    for (int y = r.begin(); y < r.end(); ++y) {
      uint8_t* o = out.mask.ptr<uint8_t>(y);
      const uint8_t* m = mask.ptr<uint8_t>(y);
      const uint8_t* ok = valid.ptr<uint8_t>(y);
      for (int x = 0; x < w; ++x) {
        const Eigen::Vector2d dq = plane_of(x, y) - out.centre;
        double inside = std::numeric_limits<double>::max();
        for (int s = 0; s < 4; ++s)
          inside = std::min(
              inside, out.edge[static_cast<size_t>(s)] - normals[static_cast<size_t>(s)].dot(dq));
        bool in = inside >= 0 && std::isfinite(dq.x());
        local += ok[x] && (in != (m[x] != 0));
        if (in && ok[x] && !m[x]) in = inside > spacing && std::fabs(frame.H(xyz(x, y))) <= band_mm;
        o[x] = in ? 255 : 0;
      }
    }
    differ += local;
  });
  const double mask_px = std::max(1.0, static_cast<double>(cv::countNonZero(mask)));
  if (static_cast<double>(differ.load()) > kOutlineMaxDisagreement * mask_px) {
    out.note = "the canvas outline is not a rectangle (it differs from the grown region by " +
               std::to_string(static_cast<int>(100.0 * differ.load() / mask_px)) + " %)";
    out.mask.release();
    return;
  }
  out.ok = true;
}

}  // namespace

// Outward normal of side s in (u, v) for a rectangle at `angle`.
Eigen::Vector2d SideNormal(int s, double angle) {
  const Eigen::Vector2d e0(std::cos(angle), std::sin(angle)), e1(-std::sin(angle), std::cos(angle));
  return s == 0 ? e0 : s == 1 ? Eigen::Vector2d(-e0) : s == 2 ? e1 : Eigen::Vector2d(-e1);
}

Outline FitOutline(const Grid<Vec3f>& xyz, const cv::Mat& mask, const cv::Mat& valid,
                   cv::Mat fit_mask, const LocalFrame& frame, double noise_sigma, double spacing) {
  Outline out;
  const std::optional<PlaneMap> plane_of = FitPlaneMap(xyz, fit_mask, frame, &out.note);
  fit_mask.release();
  if (!plane_of) return out;
  const std::vector<cv::Point2f> boundary = MaskBoundaryOnPlane(mask, *plane_of);
  if (boundary.size() < 8) {
    out.note = "mask too small for an outline";
    return out;
  }
  const FirstGuess guess = GuessRectangle(boundary);
  const double angle0 = guess.angle0;
  out.centre = guess.centre;
  const double band = std::max(kOutlineBandMm, kOutlineBandSpacings * spacing);
  const SideBand side_band(xyz, mask, valid, frame, *plane_of, guess, band);
  const double tol = std::max(kOutlineHeightSigmas * noise_sigma, kOutlineHeightFloorMm);
  SideFits fits;
  fits.tol = tol;
  for (int s = 0; s < 4; ++s)
    FitSide(s, side_band.Gather(s), guess, band, spacing, &out.closed[static_cast<size_t>(s)],
            &fits);
  const std::array<double, 4>& delta = fits.delta;
  const std::array<double, 4>& weight = fits.weight;
  double wsum = 0, dsum = 0;
  for (int s = 0; s < 4; ++s)
    wsum += weight[static_cast<size_t>(s)],
        dsum += weight[static_cast<size_t>(s)] * delta[static_cast<size_t>(s)];
  if (!(wsum > 0)) {
    out.note = "no side of the canvas outline could be fitted";
    return out;
  }
  const double d = dsum / wsum;
  for (int s = 0; s < 4; ++s)
    if (weight[static_cast<size_t>(s)] > 0 &&
        std::fabs(delta[static_cast<size_t>(s)] - d) > kOutlineMaxSideDisagreeDeg * kPi / 180) {
      out.note = "the outline's sides are not those of a rectangle";
      return out;
    }
  out.angle = angle0 + d;
  // The candidates are gathered again, a side at a time, rather than held (SideBand says why).
  for (int s = 0; s < 4; ++s) PlaceSide(s, side_band.Gather(s), fits, guess, spacing, &out);
  RectangleMask(xyz, mask, valid, frame, *plane_of, fits, tol, spacing, &out);
  return out;
}

}  // namespace digitize::canvas_detail
