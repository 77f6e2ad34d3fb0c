// The classical RTI bases -- PTM and hemispherical harmonics -- fitted per pixel to an RTI
// capture: what RTIBuilder, CNR-ISTI relight and RTIViewer / OpenLIME users open, and the
// baselines our per-texel BRDF fit is measured against (bench/rti_bench.cpp).
//
// Layer: photos (core, photo_set.h).
//
// A fit is, per pixel and per RGB channel, value(l) = sum_k c_k b_k(l) for the light direction l
// (unit, canvas frame = the .lp frame: x towards the image's right, y towards its top, z towards
// the camera; photo_set.h). The bases, with lu = l.x, lv = l.y:
//   PTM (Malzbender, Gelb, Wolters 2001), 6 terms, in the order of the .ptm file format:
//       b = (lu^2, lv^2, lu lv, lu, lv, 1)
//   HSH (Gautron, Krivanek, Pattanaik, Bouatouch 2004) as CNR-ISTI relight and OpenLIME evaluate
//   them (relight src/rti.cpp, lightWeightsHsh): theta = min(acos(lz), pi/2 - 0.01),
//   phi = atan2(lv, lu), t = cos(theta), s = sqrt(t - t^2):
//       b0 = 1 / sqrt(2 pi)
//       b1 = sqrt(6 / pi) cos(phi) s          b2 = sqrt(3 / (2 pi)) (2t - 1)
//       b3 = sqrt(6 / pi) sin(phi) s
//       b4 = sqrt(30 / pi) cos(2 phi) (t^2 - t)
//       b5 = sqrt(30 / pi) cos(phi) (2t - 1) s
//       b6 = sqrt(5 / (2 pi)) (6t^2 - 6t + 1)
//       b7 = sqrt(30 / pi) sin(phi) (2t - 1) s
//       b8 = sqrt(30 / pi) sin(2 phi) (t^2 - t)
//   "HSH order 2" is b0..b3 (4 coefficients, relight's 12 RGB planes), "order 3" b0..b8
//   (9 coefficients, 27 planes): the number of bands, as RTIBuilder and relight count them.
//
// The fit is linear least squares: all pixels share the light directions, so one pseudo-inverse
// P = (B^T B + lambda I)^-1 B^T (B: images x coefficients) is computed once and applied to every
// pixel as a matrix product. Values are fitted as 8-bit-derived fractions in [0, 1]: the sRGB
// codes / 255 (fit_in_srgb, what RTI tools do) or the linear values the photos load as.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "digitize/core.h"
#include "digitize/photo_set.h"

namespace digitize {

enum class RtiBasis { kPtm, kHsh2, kHsh3 };
const char* ToString(RtiBasis basis);  // "ptm", "hsh2", "hsh3"
// "ptm", "hsh2", "hsh3" (case-insensitive); the error lists them.
Result<RtiBasis> ParseRtiBasis(std::string_view name);

inline constexpr int kMaxRtiCoefficients = 9;
int RtiCoefficientCount(RtiBasis basis);  // 6, 4, 9

// The basis functions at a light direction (normalised here; the first RtiCoefficientCount
// entries are used, the rest are 0). Directions at or below the horizon are the caller's to
// refuse: HSH clamps theta as above, PTM takes (lu, lv) as they are.
std::array<double, kMaxRtiCoefficients> RtiBasisWeights(RtiBasis basis, const Vec3d& light);

struct RtiFitOptions {
  RtiBasis basis = RtiBasis::kHsh3;
  bool fit_in_srgb = true;  // fit the sRGB codes / 255 (RTI tools); false: linear values
  // Tikhonov weight lambda, relative to the mean diagonal of B^T B (unitless): keeps the solve
  // finite for a badly spread set of lights; 1e-9 moves a well-posed fit by ~1e-9 of a code.
  double ridge = 1e-9;
  int num_threads = 0;  // 0 = all cores

  Status Validate() const;  // ridge finite and >= 0, num_threads >= 0
};

// Coefficients per pixel, channel and basis function, in the fit's encoding (fractions of the
// 8-bit range: a value of 1 is code 255 in sRGB, or linear 1).
struct RtiFit {
  RtiBasis basis = RtiBasis::kHsh3;
  int width = 0, height = 0;
  bool srgb = true;  // coefficients fit sRGB codes / 255 (else linear values)
  // [pixel][channel][coefficient], pixel = y * width + x (row 0 = the image's top row).
  std::vector<float> coefficients;
  std::vector<Vec3d> lights;  // the fitted images' light directions, unit, in set order
  double seconds = 0;         // wall time of the fit (the solve and the products)

  int count() const { return RtiCoefficientCount(basis); }
  const float* At(int x, int y, int channel) const {
    return coefficients.data() +
           ((static_cast<size_t>(y) * width + x) * 3 + channel) * static_cast<size_t>(count());
  }
  float* At(int x, int y, int channel) {
    return coefficients.data() +
           ((static_cast<size_t>(y) * width + x) * 3 + channel) * static_cast<size_t>(count());
  }
};

// Fits `photos` (pixels loaded; directional lights, as ReadRtiCapture gives them). Every pixel
// of every photo is used: an RTI fit has no notion of a flagged sample (NaN/Inf pixels were set
// to 0 by the loader). Errors (naming the photo's entry and file where it is one photo): invalid
// options; no photos, or fewer than the basis's coefficients; a photo not loaded, of another
// size, with a point light, or with its light at or below the horizon (z <= 0); a singular
// system. Never NaN/Inf in the coefficients (a non-finite result is an error).
Result<RtiFit> FitRti(const PhotoSet& photos, const RtiFitOptions& options = {});

// The fit evaluated under `light` (normalised here; must have z > 0, else all black), clamped
// to [0, 1], IN THE FIT'S ENCODING (sRGB codes / 255 when fit.srgb, else linear).
Grid<Vec3f> RelightRti(const RtiFit& fit, const Vec3d& light, int num_threads = 0);

// ---------------------------------------------------------------------------------------------
// PSNR over 8-bit sRGB codes, pooled: every image is turned into codes round(255 * sRGB(clamp(v,
// 0, 1))) (its own encoding says whether v is sRGB already or linear: a photo loaded as linear
// gives back its file's codes exactly), the squared code differences of all compared pixels and
// channels of all images are summed into ONE mean, and PSNR = 10 log10(255^2 / MSE). This is how
// RTI tools report held-out relighting (relight's evaluateError), and how `digitize` is compared
// with them.
struct Srgb8Score {
  double psnr_db = 0;  // +inf for identical codes; 0 when nothing was compared
  double mse = 0;      // mean squared code difference
  size_t pixels = 0;   // compared (each counts 3 channels)
  int images = 0;
};

class Srgb8PsnrAccumulator {
 public:
  // Adds one image pair over the pixels where `mask` (optional; same size) is non-zero.
  // Error: sizes differ (names `what`).
  Status Add(const Grid<Vec3f>& test, ColourEncoding test_encoding, const Grid<Vec3f>& reference,
             ColourEncoding reference_encoding, const Grid<uint8_t>& mask = {},
             const std::string& what = "image");
  Srgb8Score Score() const;

 private:
  double sum_squared_ = 0;
  size_t pixels_ = 0;
  int images_ = 0;
};

// The 8-bit code of one channel value in `encoding` (kSrgb: v is sRGB already; kLinear: encoded
// first). kAuto is taken as linear.
uint8_t ToSrgb8(float value, ColourEncoding encoding);

}  // namespace digitize
