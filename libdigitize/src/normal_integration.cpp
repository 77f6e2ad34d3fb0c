// Height from normals (normal_integration.h): Poisson least squares with Eigen's SimplicialLDLT,
// or Frankot-Chellappa with OpenCV's DFT on the mirror-padded grid.
#include "digitize/normal_integration.h"

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>
#include <vector>

namespace digitize {
namespace {

// Gradients in pixel steps: gx = dz / d(column), gy = dz / d(row) = -q pitch (rows run down the
// canvas, Y up), in mm per pixel.
void Gradients(const Grid<Vec3f>& normals, double pitch_mm, double min_nz, std::vector<double>* gx,
               std::vector<double>* gy) {
  gx->resize(normals.size());
  gy->resize(normals.size());
  for (size_t i = 0; i < normals.size(); ++i) {
    const Vec3f n = normals.data[i];
    const double nz = std::max(static_cast<double>(n.z()), min_nz);
    (*gx)[i] = -n.x() / nz * pitch_mm;
    (*gy)[i] = n.y() / nz * pitch_mm;
  }
}

bool InMask(const Grid<uint8_t>* mask, size_t i) {
  return !mask || mask->empty() || mask->data[i] != 0;
}

void RemoveMean(Grid<float>& z, const Grid<uint8_t>* mask) {
  double sum = 0;
  size_t n = 0;
  for (size_t i = 0; i < z.size(); ++i) {
    if (!InMask(mask, i)) continue;
    sum += z.data[i];
    ++n;
  }
  const float mean = n ? static_cast<float>(sum / static_cast<double>(n)) : 0.0f;
  for (float& v : z.data) v -= mean;
}

double GradientResidual(const Grid<float>& z, const std::vector<double>& gx,
                        const std::vector<double>& gy, const Grid<uint8_t>* mask, double pitch) {
  double sse = 0;
  size_t n = 0;
  for (int y = 0; y < z.height; ++y) {
    for (int x = 0; x < z.width; ++x) {
      const size_t a = z.Index(x, y);
      if (!InMask(mask, a)) continue;
      if (x + 1 < z.width && InMask(mask, a + 1)) {
        const double r = (z.data[a + 1] - z.data[a] - 0.5 * (gx[a] + gx[a + 1])) / pitch;
        sse += r * r;
        ++n;
      }
      if (y + 1 < z.height) {
        const size_t b = z.Index(x, y + 1);
        if (!InMask(mask, b)) continue;
        const double r = (z.data[b] - z.data[a] - 0.5 * (gy[a] + gy[b])) / pitch;
        sse += r * r;
        ++n;
      }
    }
  }
  return n ? std::sqrt(sse / static_cast<double>(n)) : 0.0;
}

Grid<float> SolveFrankotChellappa(int w, int h, const std::vector<double>& gx,
                                  const std::vector<double>& gy);

Result<Grid<float>> SolvePoisson(int w, int h, const std::vector<double>& gx,
                                 const std::vector<double>& gy, const Grid<uint8_t>* mask,
                                 const Grid<float>* weights,
                                 const NormalIntegrationOptions& options,
                                 const std::vector<float>& initial, int* iterations,
                                 bool* converged) {
  const size_t n = static_cast<size_t>(w) * static_cast<size_t>(h);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(n * 5);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(n));
  Eigen::VectorXd diag = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(n));
  auto weight_of = [&](size_t i) {
    return weights && !weights->empty() ? static_cast<double>(weights->data[i]) : 1.0;
  };
  // One pair (a, b) with target step t = z_b - z_a and weight c: adds c (z_b - z_a - t)^2.
  auto add_pair = [&](size_t a, size_t b, double ga, double gb) {
    const bool data = InMask(mask, a) && InMask(mask, b);
    double c = data ? std::min(weight_of(a), weight_of(b)) : 0.0;
    double t = 0.5 * (ga + gb);
    if (!(c > 0)) {
      c = options.membrane_weight;
      t = 0;
    }
    diag[static_cast<Eigen::Index>(a)] += c;
    diag[static_cast<Eigen::Index>(b)] += c;
    triplets.emplace_back(static_cast<int>(a), static_cast<int>(b), -c);
    triplets.emplace_back(static_cast<int>(b), static_cast<int>(a), -c);
    rhs[static_cast<Eigen::Index>(a)] -= c * t;
    rhs[static_cast<Eigen::Index>(b)] += c * t;
  };
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t a = static_cast<size_t>(y) * w + x;
      if (x + 1 < w) add_pair(a, a + 1, gx[a], gx[a + 1]);
      if (y + 1 < h) add_pair(a, a + w, gy[a], gy[a + w]);
    }
  }
  // The constant is free: a penalty on one pixel picks, among the minimisers, the one with z_0 = 0
  // (exactly: no other mode is biased); the mean is removed afterwards.
  diag[0] += 1.0;
  for (size_t i = 0; i < n; ++i)
    triplets.emplace_back(static_cast<int>(i), static_cast<int>(i),
                          diag[static_cast<Eigen::Index>(i)]);
  Eigen::SparseMatrix<double> a(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  a.setFromTriplets(triplets.begin(), triplets.end());
  triplets = {};
  Eigen::VectorXd z;
  if (n <= options.max_direct_pixels) {
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver;
    solver.compute(a);
    if (solver.info() != Eigen::Success)
      return Error{"normal integration: the Poisson system could not be factorised (" +
                   std::to_string(w) + "x" + std::to_string(h) + ")"};
    z = solver.solve(rhs);
    if (solver.info() != Eigen::Success || !z.allFinite())
      return Error{"normal integration: the Poisson solve failed"};
  } else {
    // Too large to factorise (the fill-in of a 2D Laplacian grows as n log n): preconditioned
    // conjugate gradients from the Frankot-Chellappa heights, which are close everywhere but at
    // the mask's edges.
    Eigen::ConjugateGradient<Eigen::SparseMatrix<double>, Eigen::Lower | Eigen::Upper,
                             Eigen::IncompleteCholesky<double>>
        cg;
    cg.setTolerance(options.cg_tolerance);
    cg.setMaxIterations(options.cg_max_iterations);
    cg.compute(a);
    if (cg.info() != Eigen::Success)
      return Error{"normal integration: the Poisson preconditioner failed (" + std::to_string(w) +
                   "x" + std::to_string(h) + ")"};
    Eigen::VectorXd guess(static_cast<Eigen::Index>(n));
    for (size_t i = 0; i < n; ++i) guess[static_cast<Eigen::Index>(i)] = initial[i];
    guess.array() -= guess[0];  // the pinned gauge z_0 = 0
    z = cg.solveWithGuess(rhs, guess);
    *iterations = static_cast<int>(cg.iterations());
    *converged = cg.info() == Eigen::Success;
    if (!z.allFinite()) return Error{"normal integration: the Poisson solve diverged"};
  }
  Grid<float> out(w, h);
  for (size_t i = 0; i < n; ++i) out.data[i] = static_cast<float>(z[static_cast<Eigen::Index>(i)]);
  return out;
}

Grid<float> SolveFrankotChellappa(int w, int h, const std::vector<double>& gx,
                                  const std::vector<double>& gy) {
  // Even extension of z to 2w x 2h: mirroring the columns flips dz/dx, mirroring the rows dz/dy.
  const int W = 2 * w, H = 2 * h;
  cv::Mat px(H, W, CV_64F), py(H, W, CV_64F);
  for (int y = 0; y < H; ++y) {
    const bool my = y >= h;
    const int sy = my ? H - 1 - y : y;
    for (int x = 0; x < W; ++x) {
      const bool mx = x >= w;
      const int sx = mx ? W - 1 - x : x;
      const size_t i = static_cast<size_t>(sy) * w + sx;
      px.at<double>(y, x) = mx ? -gx[i] : gx[i];
      py.at<double>(y, x) = my ? -gy[i] : gy[i];
    }
  }
  cv::Mat fx, fy;
  cv::dft(px, fx, cv::DFT_COMPLEX_OUTPUT);
  cv::dft(py, fy, cv::DFT_COMPLEX_OUTPUT);
  cv::Mat fz(H, W, CV_64FC2);
  for (int v = 0; v < H; ++v) {
    const double wy = 2 * kPi * (v < H / 2 ? v : v - H) / H;
    for (int u = 0; u < W; ++u) {
      const double wx = 2 * kPi * (u < W / 2 ? u : u - W) / W;
      const double d = wx * wx + wy * wy;
      const cv::Vec2d a = fx.at<cv::Vec2d>(v, u), b = fy.at<cv::Vec2d>(v, u);
      // Z = -j (wx Gx + wy Gy) / (wx^2 + wy^2); -j (re + j im) = im - j re.
      const double re = wx * a[0] + wy * b[0], im = wx * a[1] + wy * b[1];
      fz.at<cv::Vec2d>(v, u) = d > 0 ? cv::Vec2d(im / d, -re / d) : cv::Vec2d(0, 0);
    }
  }
  cv::Mat z;
  cv::dft(fz, z, cv::DFT_INVERSE | cv::DFT_SCALE | cv::DFT_REAL_OUTPUT);
  Grid<float> out(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) out(x, y) = static_cast<float>(z.at<double>(y, x));
  return out;
}

}  // namespace

const char* ToString(NormalIntegrationMethod m) {
  return m == NormalIntegrationMethod::kPoisson ? "poisson" : "frankot-chellappa";
}

Status NormalIntegrationOptions::Validate() const {
  if (!(std::isfinite(min_nz) && min_nz > 0 && min_nz <= 1))
    return Error{"min_nz must be in (0, 1], got " + FormatNumber(min_nz)};
  if (!(std::isfinite(membrane_weight) && membrane_weight > 0))
    return Error{"membrane_weight must be > 0, got " + FormatNumber(membrane_weight)};
  if (!(std::isfinite(cg_tolerance) && cg_tolerance > 0))
    return Error{"cg_tolerance must be > 0, got " + FormatNumber(cg_tolerance)};
  if (cg_max_iterations < 1)
    return Error{"cg_max_iterations must be >= 1, got " + std::to_string(cg_max_iterations)};
  return Status::Ok();
}

std::string NormalIntegrationResult::Brief() const {
  char b[160];
  std::snprintf(b, sizeof b, "%s %dx%d: residual %.4g; %.2f s", ToString(method), height_mm.width,
                height_mm.height, rms_gradient_residual, seconds);
  std::string out = b;
  if (cg_iterations > 0)
    out += " (" + std::to_string(cg_iterations) + " CG iterations" +
           (converged ? ")" : ", not converged)");
  return out;
}

Result<NormalIntegrationResult> IntegrateNormals(const Grid<Vec3f>& normals, double pitch_mm,
                                                 const Grid<uint8_t>* mask,
                                                 const Grid<float>* weights,
                                                 const NormalIntegrationOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (Status s = options.Validate(); !s.ok()) return Error{"normal integration: " + s.message()};
  if (normals.empty()) return Error{"normal integration: no normals"};
  if (!(std::isfinite(pitch_mm) && pitch_mm > 0))
    return Error{"normal integration: pitch_mm must be > 0 mm, got " + FormatNumber(pitch_mm)};
  for (size_t i = 0; i < normals.size(); ++i) {
    if (!IsValid(normals.data[i]))
      return Error{"normal integration: normal at pixel (" + std::to_string(i % normals.width) +
                   ", " + std::to_string(i / normals.width) + ") is not finite"};
  }
  const int w = normals.width, h = normals.height;
  if (mask && !mask->empty() && (mask->width != w || mask->height != h))
    return Error{"normal integration: the mask's size differs from the normals'"};
  if (weights && !weights->empty()) {
    if (weights->width != w || weights->height != h)
      return Error{"normal integration: the weights' size differs from the normals'"};
    for (float v : weights->data)
      if (!(std::isfinite(v) && v >= 0))
        return Error{"normal integration: weights must be finite and >= 0, got " + FormatNumber(v)};
  }
  std::vector<double> gx, gy;
  Gradients(normals, pitch_mm, options.min_nz, &gx, &gy);
  NormalIntegrationResult result;
  result.method = options.method;
  if (options.method == NormalIntegrationMethod::kPoisson) {
    const size_t n = normals.size();
    std::vector<float> initial;
    if (n > options.max_direct_pixels) initial = SolveFrankotChellappa(w, h, gx, gy).data;
    auto z = SolvePoisson(w, h, gx, gy, mask, weights, options, initial, &result.cg_iterations,
                          &result.converged);
    if (!z.ok()) return z.error();
    result.height_mm = std::move(*z);
  } else {
    result.height_mm = SolveFrankotChellappa(w, h, gx, gy);
  }
  for (float& v : result.height_mm.data)
    if (!std::isfinite(v)) v = 0;
  RemoveMean(result.height_mm, mask);
  result.rms_gradient_residual = GradientResidual(result.height_mm, gx, gy, mask, pitch_mm);
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

HeightField HeightFieldFromIntegration(const NormalIntegrationResult& result, double pitch_mm,
                                       const Grid<uint8_t>* mask) {
  HeightField field;
  field.height_mm = result.height_mm;
  field.pitch_mm = pitch_mm;
  field.state =
      Grid<TexelState>(result.height_mm.width, result.height_mm.height, TexelState::kMeasured);
  if (mask && !mask->empty()) {
    DIGITIZE_CHECK(mask->size() == field.state.size(), "HeightFieldFromIntegration: mask size");
    for (size_t i = 0; i < mask->size(); ++i)
      if (mask->data[i] == 0) field.state.data[i] = TexelState::kFilled;
  }
  return field;
}

}  // namespace digitize
