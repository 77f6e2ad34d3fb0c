// Robust photometric stereo (photometric_stereo.h): rank trimming, residual reselection, and the
// alternation with the per-image intensities.
//
// Work plan: per row, the samples of every pixel are gathered from the images into a small local
// buffer (one row of every image is streamed, so the images are read in order), then each pixel
// is solved alone (3x3 normal equations). Rows are independent tasks.
#include "digitize/photometric_stereo.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>

namespace digitize {
namespace {

// 1.4826 MAD is the standard deviation of a normal distribution.
constexpr double kMadToSigma = 1.4826;
// The mean tilt is taken over normals within ~73 deg of the camera axis: steeper ones (impasto
// walls) are few, least certain and would dominate a mean of n_x / n_z.
constexpr double kMinTiltNz = 0.3;

// Per-pixel working buffers (one per task: no allocation per pixel).
struct PixelScratch {
  std::vector<double> g;        // grey / (e_i s_i)
  std::vector<double> scale;    // e_i s_i
  std::vector<Vec3f> rgb;       // the pixel's colour in each image
  std::vector<Vec3d> l;         // unit light direction at the pixel
  std::vector<uint8_t> usable;  // not excluded
  std::vector<uint8_t> inlier;
  std::vector<uint8_t> next;  // the reselection's candidate inliers
  std::vector<int> order;
  std::vector<double> tmp;
  void Resize(size_t n) {
    g.resize(n);
    scale.resize(n);
    rgb.resize(n);
    l.resize(n);
    usable.resize(n);
    inlier.resize(n);
    next.resize(n);
    order.resize(n);
    tmp.resize(n);
  }
};

struct PixelFit {
  Vec3d b = Vec3d::Zero();  // grey albedo x normal
  Vec3d n = Vec3d::UnitZ();
  int inliers = 0;
  double residual = 0;  // RMS / grey albedo
  PhotometricStatus status = PhotometricStatus::kOk;
};

// Least squares b over the samples marked in `use` (false when fewer than 3 or singular); `a` gets
// the normal matrix sum l l^T / count for the spread test.
bool SolveLs(const PixelScratch& s, const std::vector<uint8_t>& use, Vec3d* b, int* count,
             Mat3d* a_mean) {
  double xx = 0, xy = 0, xz = 0, yy = 0, yz = 0, zz = 0;
  Vec3d r = Vec3d::Zero();
  int k = 0;
  for (size_t i = 0; i < s.g.size(); ++i) {
    if (!use[i]) continue;
    const Vec3d& l = s.l[i];
    xx += l.x() * l.x(), xy += l.x() * l.y(), xz += l.x() * l.z();
    yy += l.y() * l.y(), yz += l.y() * l.z(), zz += l.z() * l.z();
    r += s.g[i] * l;
    ++k;
  }
  *count = k;
  if (k < 3) return false;
  Mat3d a;
  a << xx, xy, xz, xy, yy, yz, xz, yz, zz;
  *a_mean = a / k;
  Eigen::LDLT<Mat3d> ldlt(a);
  if (ldlt.info() != Eigen::Success) return false;
  *b = ldlt.solve(r);
  return b->allFinite();
}

// Whether the lights of a normal matrix constrain a normal: its smallest eigenvalue.
bool Spread(const Mat3d& a_mean, double min_spread) {
  // Fast path: lambda_min = det / (lambda_1 lambda_2) >= det / (trace / 2)^2, so a large enough
  // determinant proves the spread without the eigenvalues (nearly every pixel of a capture).
  const double tr = a_mean.trace();
  if (tr > 0 && a_mean.determinant() / (0.25 * tr * tr) >= min_spread) return true;
  Eigen::SelfAdjointEigenSolver<Mat3d> eig;
  eig.computeDirect(a_mean, Eigen::EigenvaluesOnly);
  return eig.eigenvalues()(0) >= min_spread;
}

double Median(std::vector<double>& v, size_t n) {
  if (n == 0) return 0;
  auto mid = v.begin() + static_cast<std::ptrdiff_t>(n / 2);
  std::nth_element(v.begin(), mid, v.begin() + static_cast<std::ptrdiff_t>(n));
  return *mid;
}

// n_z >= min_nz: flipped towards the camera, then tilted up.
Vec3d ClampNormal(Vec3d n, double min_nz) {
  if (n.z() < 0) n.z() = -n.z();
  if (n.z() < min_nz) {
    const double xy = std::hypot(n.x(), n.y());
    const double scale = xy > 0 ? std::sqrt(1 - min_nz * min_nz) / xy : 0;
    n = xy > 0 ? Vec3d(n.x() * scale, n.y() * scale, min_nz) : Vec3d::UnitZ();
  }
  return n.normalized();
}

PixelFit FitPixel(PixelScratch& s, const PhotometricStereoOptions& o) {
  PixelFit fit;
  const size_t m = s.g.size();
  size_t n_usable = 0;
  double max_g = 0;
  for (size_t i = 0; i < m; ++i) {
    s.inlier[i] = 0;
    if (!s.usable[i]) continue;
    s.order[n_usable++] = static_cast<int>(i);
    max_g = std::max(max_g, s.g[i]);
  }
  if (n_usable == 0 || !(max_g >= o.black_level)) {
    fit.status = PhotometricStatus::kBlack;
    return fit;
  }
  // Step 1: rank trimming, by the order statistics of a copy of the usable values.
  for (size_t r = 0; r < n_usable; ++r) s.tmp[r] = s.g[s.order[r]];
  auto begin = s.tmp.begin();
  // The median first; the low and high ranks then lie in its two halves (nth_element leaves the
  // smaller values before it), so each later search covers half the samples.
  const size_t mid = n_usable / 2;
  auto at = [&](size_t rank, size_t from, size_t to) {
    std::nth_element(begin + static_cast<std::ptrdiff_t>(from),
                     begin + static_cast<std::ptrdiff_t>(rank),
                     begin + static_cast<std::ptrdiff_t>(to));
    return s.tmp[rank];
  };
  const size_t lo = std::min(static_cast<size_t>(std::floor(o.low_quantile * n_usable)), mid);
  const size_t hi = std::max(lo + 1, static_cast<size_t>(std::ceil(o.high_quantile * n_usable)));
  const double median = at(mid, 0, n_usable);
  const double floor_g = std::max(lo < mid ? at(lo, 0, mid) : median, o.shadow_ratio * median);
  // Samples from rank hi up are dropped: every value above the hi-th (ties kept, as ranks are).
  const double ceil_g = hi < n_usable ? (hi > mid ? at(hi, mid + 1, n_usable) : median)
                                      : std::numeric_limits<double>::infinity();
  for (size_t r = 0; r < n_usable; ++r) {
    const int i = s.order[r];
    if (s.g[i] >= floor_g && s.g[i] < ceil_g) s.inlier[i] = 1;
  }
  Vec3d b;
  Mat3d a_mean;
  int count = 0;
  if (!SolveLs(s, s.inlier, &b, &count, &a_mean) || !Spread(a_mean, o.min_light_spread)) {
    fit.status = count < o.min_inliers && n_usable >= 3 ? PhotometricStatus::kTooFewInliers
                                                        : PhotometricStatus::kDegenerate;
    // Two images, or lights that are all equal, are degenerate whatever the trimming left.
    int all = 0;
    Vec3d unused;
    Mat3d a_all;
    if (!SolveLs(s, s.usable, &unused, &all, &a_all) || !Spread(a_all, o.min_light_spread)) {
      fit.status = PhotometricStatus::kDegenerate;
    }
    fit.inliers = count;
    return fit;
  }
  // Step 2: reselection by shading and residual, until the inliers stop changing. The robust
  // sigma: 1.4826 MAD of the trimmed set's residuals in the first round (it may still hold
  // outliers), then the RMS of the inliers' residuals (they passed the cut; a median per round
  // cost more than the solves).
  for (int it = 0; it < o.reselect_iterations; ++it) {
    const double albedo = b.norm();
    if (!(albedo > 0)) break;
    const Vec3d n = b / albedo;
    size_t k = 0;
    double sum2 = 0;
    for (size_t i = 0; i < m; ++i) {
      if (!s.inlier[i]) continue;
      const double r = s.g[i] - b.dot(s.l[i]);
      s.tmp[k++] = std::abs(r);
      sum2 += r * r;
    }
    const double scale = it == 0 ? kMadToSigma * Median(s.tmp, k)
                                 : std::sqrt(sum2 / static_cast<double>(std::max<size_t>(k, 1)));
    const double sigma = std::max(scale, o.noise_floor * albedo);
    const double limit = o.outlier_sigmas * sigma;
    bool changed = false;
    for (size_t i = 0; i < m; ++i) {
      s.next[i] = s.usable[i] && n.dot(s.l[i]) >= o.min_shading &&
                  std::abs(s.g[i] - b.dot(s.l[i])) <= limit;
      changed |= s.next[i] != s.inlier[i];
    }
    if (!changed) break;
    Vec3d nb;
    Mat3d na;
    if (!SolveLs(s, s.next, &nb, &count, &na) || !Spread(na, o.min_light_spread)) break;
    b = nb;
    s.inlier.swap(s.next);
  }
  // Final inlier set of b (the last reselection may have failed to solve).
  int k = 0;
  double sse = 0;
  for (size_t i = 0; i < m; ++i) {
    if (!s.inlier[i]) continue;
    const double r = s.g[i] - b.dot(s.l[i]);
    sse += r * r;
    ++k;
  }
  fit.inliers = k;
  const double albedo = b.norm();
  if (k < o.min_inliers || !(albedo > 0)) {
    fit.status = PhotometricStatus::kTooFewInliers;
    return fit;
  }
  fit.b = b;
  fit.n = ClampNormal(b / albedo, o.min_nz);
  fit.residual = std::sqrt(sse / k) / albedo;
  return fit;
}

struct Setup {
  int width = 0, height = 0;
  std::vector<double> e;  // current intensities
  const std::vector<PhotometricImage>* images = nullptr;
  const PhotometricStereoOptions* options = nullptr;
  std::vector<double> centre_distance;  // point lights: distance to the canvas centre
  Vec3d centre = Vec3d::Zero();         // canvas centre, mm
};

// Fills the scratch with pixel (x, y)'s samples under intensities `e`.
void Gather(const Setup& st, int x, int y, PixelScratch& s) {
  const auto& images = *st.images;
  const double pitch = st.options->pitch_mm;
  const Vec3d p((x + 0.5) * pitch, (st.height - y - 0.5) * pitch, 0.0);
  for (size_t i = 0; i < images.size(); ++i) {
    const PhotometricImage& im = images[i];
    const Vec3f c = (*im.rgb)(x, y);
    double scale = st.e[i];
    if (im.point_light) {
      const Vec3d d = im.light - p;
      const double dist = d.norm();
      s.l[i] = d / dist;
      const double ratio = st.centre_distance[i] / dist;
      scale *= ratio * ratio;
    } else {
      s.l[i] = im.light;
    }
    s.g[i] = (static_cast<double>(c.x()) + c.y() + c.z()) / 3.0 / scale;
    s.scale[i] = scale;
    s.rgb[i] = c;
    s.usable[i] = !(im.exclude && !im.exclude->empty() && (*im.exclude)(x, y) != 0);
  }
}

// One alternation round on the subsample: new intensities (mean 1). Returns false when no image
// got a ratio (the previous e are kept).
bool UpdateIntensities(Setup& st) {
  const auto& o = *st.options;
  const size_t m = st.images->size();
  const int stride = o.intensity_stride;
  const int rows = (st.height + stride - 1) / stride;
  // Per subsampled row, per image: the ratios (kept per row so the result is independent of the
  // scheduling).
  std::vector<std::vector<std::vector<float>>> ratios(rows);
  // Per subsampled row: the sum of n_x / n_z, n_y / n_z and the count (the mean tilt, below).
  std::vector<Eigen::Vector3d> tilt(rows, Eigen::Vector3d::Zero());
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    PixelScratch s;
    s.Resize(m);
    for (int r = range.begin(); r < range.end(); ++r) {
      const int y = r * stride;
      auto& out = ratios[r];
      out.assign(m, {});
      for (int x = 0; x < st.width; x += stride) {
        Gather(st, x, y, s);
        const PixelFit fit = FitPixel(s, o);
        if (fit.status != PhotometricStatus::kOk) continue;
        if (fit.n.z() >= kMinTiltNz)
          tilt[r] += Eigen::Vector3d(fit.n.x() / fit.n.z(), fit.n.y() / fit.n.z(), 1);
        for (size_t i = 0; i < m; ++i) {
          if (!s.inlier[i]) continue;
          const double shading = fit.n.dot(s.l[i]);
          if (shading < o.min_intensity_shading) continue;
          // g_i was divided by e_i s_i; the raw grey over the model's shading without e.
          const double raw = s.g[i] * s.scale[i];
          const double model = fit.b.dot(s.l[i]) * s.scale[i] / st.e[i];
          if (model > 0) out[i].push_back(static_cast<float>(raw / model));
        }
      }
    }
  });
  std::vector<double> e(m, 0.0);
  double sum = 0;
  int have = 0;
  for (size_t i = 0; i < m; ++i) {
    std::vector<double> all;
    for (const auto& row : ratios) all.insert(all.end(), row[i].begin(), row[i].end());
    if (all.empty()) continue;
    e[i] = Median(all, all.size());
    if (!(e[i] > 0) || !std::isfinite(e[i])) {
      e[i] = 0;
      continue;
    }
    sum += e[i];
    ++have;
  }
  if (have == 0) return false;
  const double mean = sum / have;
  for (size_t i = 0; i < m; ++i) st.e[i] = e[i] > 0 ? e[i] / mean : 1.0;
  // The gauge of the tilt (header, INTENSITIES): normals tilted by tau on average are what
  // intensities e_i l_z / (l_z + tau . l_xy) would give a flat canvas; undo that mode.
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  for (const auto& v : tilt) t += v;
  if (o.zero_mean_tilt && t.z() > 0) {
    const double tx = t.x() / t.z(), ty = t.y() / t.z();
    for (size_t i = 0; i < m; ++i) {
      // A point light's mode is, to first order, that of its direction from the canvas centre.
      const auto& im = (*st.images)[i];
      const Vec3d l = im.point_light ? Vec3d((im.light - st.centre).normalized()) : im.light;
      if (!(l.z() > 0)) continue;
      const double factor = 1 + (tx * l.x() + ty * l.y()) / l.z();
      if (factor > 0.1) st.e[i] *= factor;
    }
  }
  // Normalise the whole vector to mean 1 (images without a ratio were set to the mean).
  const double total = std::accumulate(st.e.begin(), st.e.end(), 0.0) / static_cast<double>(m);
  for (double& v : st.e) v /= total;
  return true;
}

}  // namespace

Status PhotometricStereoOptions::Validate() const {
  auto in01 = [](double v) { return std::isfinite(v) && v >= 0 && v <= 1; };
  if (!in01(low_quantile))
    return Error{"low_quantile must be in [0, 1], got " + FormatNumber(low_quantile)};
  if (!in01(high_quantile) || !(high_quantile > low_quantile))
    return Error{"high_quantile must be in (low_quantile, 1], got " + FormatNumber(high_quantile)};
  if (!(std::isfinite(shadow_ratio) && shadow_ratio >= 0 && shadow_ratio < 1))
    return Error{"shadow_ratio must be in [0, 1) (share of the median), got " +
                 FormatNumber(shadow_ratio)};
  if (reselect_iterations < 0)
    return Error{"reselect_iterations must be >= 0, got " + std::to_string(reselect_iterations)};
  if (!(std::isfinite(min_shading) && min_shading >= 0 && min_shading < 1))
    return Error{"min_shading must be in [0, 1) (n.l), got " + FormatNumber(min_shading)};
  if (!(std::isfinite(outlier_sigmas) && outlier_sigmas > 0))
    return Error{"outlier_sigmas must be > 0, got " + FormatNumber(outlier_sigmas)};
  if (!(std::isfinite(noise_floor) && noise_floor >= 0))
    return Error{"noise_floor must be >= 0 (share of the albedo), got " +
                 FormatNumber(noise_floor)};
  if (min_inliers < 3) return Error{"min_inliers must be >= 3, got " + std::to_string(min_inliers)};
  if (!(std::isfinite(min_light_spread) && min_light_spread >= 0))
    return Error{"min_light_spread must be >= 0, got " + FormatNumber(min_light_spread)};
  if (!(std::isfinite(min_nz) && min_nz > 0 && min_nz <= 1))
    return Error{"min_nz must be in (0, 1], got " + FormatNumber(min_nz)};
  if (!(std::isfinite(black_level) && black_level >= 0))
    return Error{"black_level must be >= 0 (linear), got " + FormatNumber(black_level)};
  if (intensity_iterations < 0)
    return Error{"intensity_iterations must be >= 0, got " + std::to_string(intensity_iterations)};
  if (intensity_stride < 1)
    return Error{"intensity_stride must be >= 1 px, got " + std::to_string(intensity_stride)};
  if (!(std::isfinite(min_intensity_shading) && min_intensity_shading >= 0 &&
        min_intensity_shading < 1))
    return Error{"min_intensity_shading must be in [0, 1) (n.l), got " +
                 FormatNumber(min_intensity_shading)};
  for (size_t i = 0; i < intensities.size(); ++i) {
    if (!(std::isfinite(intensities[i]) && intensities[i] > 0))
      return Error{"intensities[" + std::to_string(i) + "] must be > 0, got " +
                   FormatNumber(intensities[i])};
  }
  if (!(std::isfinite(pitch_mm) && pitch_mm > 0))
    return Error{"pitch_mm must be > 0 mm, got " + FormatNumber(pitch_mm)};
  if (num_threads < 0) return Error{"num_threads must be >= 0, got " + std::to_string(num_threads)};
  return Status::Ok();
}

const char* ToString(PhotometricStatus s) {
  switch (s) {
    case PhotometricStatus::kOk:
      return "ok";
    case PhotometricStatus::kTooFewInliers:
      return "too few inliers";
    case PhotometricStatus::kDegenerate:
      return "degenerate";
    case PhotometricStatus::kBlack:
      return "black";
  }
  return "?";
}

std::string PhotometricStereoResult::Brief() const {
  const double total = static_cast<double>(normals.size());
  auto pct = [&](size_t n) {
    char b[32];
    std::snprintf(b, sizeof b, "%.1f %%", total > 0 ? 100.0 * n / total : 0.0);
    return std::string(b);
  };
  double lo = 0, hi = 0;
  if (!intensities.empty()) {
    lo = *std::min_element(intensities.begin(), intensities.end());
    hi = *std::max_element(intensities.begin(), intensities.end());
  }
  char tail[128];
  std::snprintf(tail, sizeof tail, "intensities %.3f .. %.3f (%d rounds); %.2f s", lo, hi,
                intensity_rounds, seconds);
  return std::to_string(normals.size()) + " px x " + std::to_string(intensities.size()) +
         " images: " + pct(ok_pixels) + " ok, " + pct(too_few_pixels) + " too few inliers, " +
         pct(degenerate_pixels) + " degenerate, " + pct(black_pixels) + " black; " + tail;
}

Result<PhotometricStereoResult> SolvePhotometricStereo(const std::vector<PhotometricImage>& images,
                                                       const PhotometricStereoOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (Status s = options.Validate(); !s.ok()) return Error{"photometric stereo: " + s.message()};
  if (images.empty()) return Error{"photometric stereo: no image"};
  for (size_t i = 0; i < images.size(); ++i) {
    const auto& im = images[i];
    const std::string what = "photometric stereo: image " + std::to_string(i);
    if (!im.rgb || im.rgb->empty()) return Error{what + " has no pixels"};
    if (im.rgb->width != images[0].rgb->width || im.rgb->height != images[0].rgb->height)
      return Error{what + " is " + std::to_string(im.rgb->width) + "x" +
                   std::to_string(im.rgb->height) + ", image 0 is " +
                   std::to_string(images[0].rgb->width) + "x" +
                   std::to_string(images[0].rgb->height)};
    if (im.exclude && !im.exclude->empty() &&
        (im.exclude->width != im.rgb->width || im.exclude->height != im.rgb->height))
      return Error{what + ": the exclude mask's size differs from the image's"};
    if (!im.light.allFinite() || (!im.point_light && !(im.light.norm() > 0)))
      return Error{what + ": the light is zero or not finite"};
  }
  if (!options.intensities.empty() && options.intensities.size() != images.size())
    return Error{"photometric stereo: " + std::to_string(options.intensities.size()) +
                 " intensities given for " + std::to_string(images.size()) + " images"};

  // Directions normalised here so callers may pass .lp directions as they are.
  std::vector<PhotometricImage> lights = images;
  Setup st;
  st.width = images[0].rgb->width;
  st.height = images[0].rgb->height;
  st.images = &lights;
  st.options = &options;
  const Vec3d centre(st.width * options.pitch_mm / 2, st.height * options.pitch_mm / 2, 0);
  st.centre = centre;
  st.centre_distance.assign(images.size(), 1.0);
  for (size_t i = 0; i < lights.size(); ++i) {
    if (lights[i].point_light) {
      st.centre_distance[i] = (lights[i].light - centre).norm();
      if (!(st.centre_distance[i] > 0))
        return Error{"photometric stereo: image " + std::to_string(i) +
                     ": the point light sits on the canvas centre"};
    } else {
      lights[i].light.normalize();
    }
  }
  st.e =
      options.intensities.empty() ? std::vector<double>(images.size(), 1.0) : options.intensities;

  PhotometricStereoResult result;
  tbb::task_arena arena(options.num_threads > 0 ? options.num_threads : tbb::task_arena::automatic);
  arena.execute([&] {
    if (options.estimate_intensities && options.intensities.empty() && images.size() >= 3) {
      for (int round = 0; round < options.intensity_iterations; ++round) {
        const std::vector<double> before = st.e;
        if (!UpdateIntensities(st)) break;
        ++result.intensity_rounds;
        double change = 0;
        for (size_t i = 0; i < st.e.size(); ++i)
          change = std::max(change, std::abs(st.e[i] - before[i]));
        if (change < 1e-4) break;
      }
    }

    const int w = st.width, h = st.height;
    result.normals = Grid<Vec3f>(w, h, Vec3f(0, 0, 1));
    result.albedo = Grid<Vec3f>(w, h);
    result.inliers = Grid<uint8_t>(w, h, 0);
    result.residual = Grid<float>(w, h, 0.0f);
    result.status = Grid<PhotometricStatus>(w, h, PhotometricStatus::kOk);
    const size_t m = lights.size();
    tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& range) {
      PixelScratch s;
      s.Resize(m);
      for (int y = range.begin(); y < range.end(); ++y) {
        for (int x = 0; x < w; ++x) {
          Gather(st, x, y, s);
          const PixelFit fit = FitPixel(s, options);
          result.status(x, y) = fit.status;
          result.inliers(x, y) = static_cast<uint8_t>(std::min(fit.inliers, 255));
          result.residual(x, y) = static_cast<float>(fit.residual);
          const bool ok = fit.status == PhotometricStatus::kOk;
          const Vec3d n = ok ? fit.n : Vec3d::UnitZ();
          result.normals(x, y) = n.cast<float>();
          // RGB albedo: per-channel scale with n fixed; the inliers, or for a flagged pixel every
          // usable lit sample.
          Vec3d num = Vec3d::Zero();
          double den = 0;
          for (size_t i = 0; i < m; ++i) {
            if (ok ? !s.inlier[i] : !s.usable[i]) continue;
            const double shading = n.dot(s.l[i]);
            if (shading <= 0) continue;
            num += s.rgb[i].cast<double>() / s.scale[i] * shading;
            den += shading * shading;
          }
          const Vec3d a = den > 0 ? Vec3d((num / den).cwiseMax(0.0)) : Vec3d::Zero();
          result.albedo(x, y) = a.allFinite() ? Vec3f(a.cast<float>()) : Vec3f::Zero();
        }
      }
    });
  });
  for (const PhotometricStatus s : result.status.data) {
    switch (s) {
      case PhotometricStatus::kOk:
        ++result.ok_pixels;
        break;
      case PhotometricStatus::kTooFewInliers:
        ++result.too_few_pixels;
        break;
      case PhotometricStatus::kDegenerate:
        ++result.degenerate_pixels;
        break;
      case PhotometricStatus::kBlack:
        ++result.black_pixels;
        break;
    }
  }
  result.intensities = st.e;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace digitize
