// Property tests of the Lafortune BRDF (STYLE rule 10): non-negativity and reciprocity on random
// directions, analytic and autodiff derivatives against numeric ones, the gauge conversion, the
// numerical contract at extreme k and grazing angles; and the measured-fits parser, on the real
// file and on hostile inputs.
#include "digitize/lafortune.h"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>

#include "test_paths.h"

namespace digitize {
namespace {

// Uniform direction on the upper hemisphere, optionally down to a grazing elevation.
Vec3f RandomHemisphere(std::mt19937& rng, float min_z = 0.0f) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const float z = min_z + (1.0f - min_z) * u(rng);
  const float phi = 2.0f * 3.14159265f * u(rng);
  const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  return {r * std::cos(phi), r * std::sin(phi), z};
}

// Any lobe the evaluator may meet, including ones outside the fitted family (|c| > 1, c > 0) and
// the extreme exponents.
LafortuneParams RandomParams(std::mt19937& rng) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  LafortuneParams p;
  p.rho_d = Vec3f(u(rng), u(rng), u(rng)) * 0.3f;
  p.rho_s = Vec3f(u(rng), u(rng), u(rng)) * 5.0f;
  p.cx = -2.0f + 3.0f * u(rng);
  p.cy = -2.0f + 3.0f * u(rng);
  p.k = std::pow(10.0f, -1.0f + 5.0f * u(rng));  // 0.1 .. 1e4
  return p;
}

TEST(Lafortune, NonNegativeFiniteAndReciprocalOnRandomDirections) {
  std::mt19937 rng(1);
  for (int i = 0; i < 20000; ++i) {
    const LafortuneParams p = RandomParams(rng);
    const Vec3f v = RandomHemisphere(rng), l = RandomHemisphere(rng);
    const Vec3f f = EvaluateLafortune(p, v, l);
    const Vec3f b = EvaluateLafortune(p, l, v);
    ASSERT_TRUE(f.allFinite());
    ASSERT_TRUE((f.array() >= 0.0f).all());
    ASSERT_TRUE((f.array() >= p.rho_d.array()).all());  // the lobe only adds
    // Exactly reciprocal: the lobe only sees the products v_i l_i, which commute.
    ASSERT_EQ(f, b);
  }
}

TEST(Lafortune, FittedFamilyLobeNeverExceedsRhoS) {
  // |cx|, |cy| <= 1 and cz = 1 bound the base by |v||l| = 1: rho_s is the peak specular value.
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int i = 0; i < 20000; ++i) {
    LafortuneParams p;
    p.rho_s = Vec3f::Ones();
    p.cx = u(rng);
    p.cy = u(rng);
    p.k = 0.5f + 10.0f * std::abs(u(rng));
    const Vec3f f = EvaluateLafortune(p, RandomHemisphere(rng), RandomHemisphere(rng));
    ASSERT_LE(f.maxCoeff(), 1.0f + 1e-5f);
  }
}

TEST(Lafortune, MirrorLobePeaksAtTheMirrorDirection) {
  LafortuneParams p;
  p.rho_s = Vec3f::Ones();
  p.k = 50;
  const Vec3f l = Vec3f(0.3f, -0.2f, 0.9f).normalized();
  const Vec3f mirror(-l.x(), -l.y(), l.z());
  EXPECT_NEAR(EvaluateLafortune(p, mirror, l).x(), 1.0f, 1e-5f);
  // 22 degrees off the mirror direction: cos(22 deg)^50 ~ 0.02.
  EXPECT_LT(EvaluateLafortune(p, Vec3f(0, 0, 1), l).x(), 0.05f);
}

// Numeric central differences of the lobe in double, for every parameter.
double NumericLobe(const LafortuneParams& p, const Vec3f& v, const Vec3f& l, int param, double h) {
  double c[4] = {p.cx, p.cy, p.cz, p.k};
  const double vd[3] = {v.x(), v.y(), v.z()}, ld[3] = {l.x(), l.y(), l.z()};
  c[param] += h;
  const double plus = LafortuneLobe(c[0], c[1], c[2], c[3], vd, ld);
  c[param] -= 2 * h;
  const double minus = LafortuneLobe(c[0], c[1], c[2], c[3], vd, ld);
  return (plus - minus) / (2 * h);
}

TEST(Lafortune, AnalyticDerivativesMatchNumericOnes) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int checked = 0;
  for (int i = 0; i < 5000; ++i) {
    LafortuneParams p;
    p.cx = u(rng);
    p.cy = u(rng);
    p.k = std::pow(10.0f, 0.5f * (u(rng) + 1.0f) * 3.0f);  // 1 .. 1000
    const Vec3f v = RandomHemisphere(rng), l = RandomHemisphere(rng);
    const LobeDerivatives d = LafortuneLobeDerivatives(p, v, l);
    const double base = p.cx * v.x() * l.x() + p.cy * v.y() * l.y() + v.z() * l.z();
    if (base < 1e-2 || d.value < 1e-12)
      continue;  // the kink at 0 and underflow: nothing to compare
    // Step ~1e-6 of the scale each parameter varies on; central differences err by O(h^2 f''').
    const double hc = 1e-6 * base;
    const double num[4] = {NumericLobe(p, v, l, 0, hc), NumericLobe(p, v, l, 1, hc),
                           NumericLobe(p, v, l, 2, hc), NumericLobe(p, v, l, 3, 1e-6 * p.k)};
    const double ana[4] = {d.d_cx, d.d_cy, d.d_cz, d.d_k};
    // Scale of a derivative: the value times the sensitivity k/base (for c) or |log base| (for k).
    const double scale[4] = {d.value * p.k / base, d.value * p.k / base, d.value * p.k / base,
                             d.value * (std::abs(std::log(base)) + 1e-3)};
    for (int j = 0; j < 4; ++j)
      ASSERT_NEAR(ana[j], num[j], 1e-5 * scale[j]) << "param " << j << " k " << p.k;
    ++checked;
  }
  EXPECT_GT(checked, 1000);
}

TEST(Lafortune, AutodiffJetsMatchAnalyticDerivatives) {
  // The reference fit differentiates LafortuneLobe with ceres::Jet: check it at the same points.
  using J = ceres::Jet<double, 4>;
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int i = 0; i < 2000; ++i) {
    LafortuneParams p;
    p.cx = u(rng);
    p.cy = u(rng);
    p.k = 1.0f + 500.0f * std::abs(u(rng));
    const Vec3f v = RandomHemisphere(rng), l = RandomHemisphere(rng);
    const double vd[3] = {v.x(), v.y(), v.z()}, ld[3] = {l.x(), l.y(), l.z()};
    const J g = LafortuneLobe(J(p.cx, 0), J(p.cy, 1), J(p.cz, 2), J(p.k, 3), vd, ld);
    const LobeDerivatives d = LafortuneLobeDerivatives(p, v, l);
    const double tol = 1e-9 + 1e-9 * std::abs(d.value) * p.k;
    ASSERT_NEAR(g.a, d.value, 1e-12 + 1e-9 * d.value);
    ASSERT_NEAR(g.v[0], d.d_cx, tol);
    ASSERT_NEAR(g.v[1], d.d_cy, tol);
    ASSERT_NEAR(g.v[2], d.d_cz, tol);
    ASSERT_NEAR(g.v[3], d.d_k, tol);
  }
}

TEST(Lafortune, GaugeConversionPreservesTheFunction) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int i = 0; i < 2000; ++i) {
    const double cz = 0.3 + 1.5 * u(rng);
    const double cx = -cz * (0.5 + 0.5 * u(rng)), cy = -cz * (0.5 + 0.5 * u(rng));
    const double k = 1.0 + 200.0 * u(rng);
    const Vec3f rho_d(0.1f, 0.2f, 0.05f);
    const Vec3f rho_s = Vec3f(0.5f, 1.0f, 2.0f) * static_cast<float>(u(rng) + 0.1);
    Result<LafortuneParams> p = LafortuneFromGeneral(rho_d, rho_s, cx, cy, cz, k);
    if (!p.ok()) {
      // Only rho_s cz^k beyond float's range may refuse; the function is then not storable.
      ASSERT_GT(k * std::log(cz), 80.0) << p.error().message;
      continue;
    }
    ASSERT_TRUE(p->Validate().ok());
    EXPECT_EQ(p->cz, 1.0f);
    for (int j = 0; j < 20; ++j) {
      const Vec3f v = RandomHemisphere(rng), l = RandomHemisphere(rng);
      const double base = cx * v.x() * l.x() + cy * v.y() * l.y() + cz * v.z() * l.z();
      const double lobe = base > 0 ? std::pow(base, k) : 0.0;
      const Vec3f f = EvaluateLafortune(*p, v, l);
      for (int c = 0; c < 3; ++c) {
        const double want = rho_d[c] + rho_s[c] * lobe;
        if (want > kMaxBrdf) {  // the contract's cap (cz > 1 with a large k gives huge peaks)
          ASSERT_EQ(f[c], kMaxBrdf);
          continue;
        }
        // float evaluation of base^k: relative error ~ k * 1e-7.
        ASSERT_NEAR(f[c], want, 1e-6 + want * (2e-6 + 3e-7 * k));
      }
    }
  }
}

TEST(Lafortune, GaugeConversionRefusesWhatItCannotStore) {
  const Vec3f rd(0.1f, 0.1f, 0.1f), rs(1, 1, 1);
  EXPECT_FALSE(LafortuneFromGeneral(rd, rs, -1, -1, 0.0, 10).ok());   // no cz = 1 form
  EXPECT_FALSE(LafortuneFromGeneral(rd, rs, -1, -1, -0.5, 10).ok());  // retro lobe
  EXPECT_FALSE(LafortuneFromGeneral(rd, rs, std::nan(""), -1, 1, 10).ok());
  EXPECT_FALSE(LafortuneFromGeneral(rd, rs, -1, -1, 1, -1).ok());
  EXPECT_FALSE(LafortuneFromGeneral(rd, -rs, -1, -1, 1, 10).ok());
  EXPECT_FALSE(LafortuneFromGeneral(rd, rs, -1, -1, 2.0, 1000).ok());  // rho_s 2^1000: beyond float
  // Underflow of rho_s cz^k is an honest 0, not an error.
  Result<LafortuneParams> tiny = LafortuneFromGeneral(rd, rs, -0.5, -0.5, 0.5, 1000);
  ASSERT_TRUE(tiny.ok());
  EXPECT_EQ(tiny->rho_s, Vec3f::Zero());
  EXPECT_FLOAT_EQ(tiny->cx, -1.0f);
  const std::string message = LafortuneFromGeneral(rd, rs, -1, -1, -0.5, 10).error().message;
  EXPECT_NE(message.find("Cz"), std::string::npos) << message;
}

TEST(Lafortune, ExtremeExponentsStayFinite) {
  std::mt19937 rng(6);
  const float ks[] = {0.0f, 1e-30f, 1.0f, 1e4f, 1e6f, 3e38f};
  for (float k : ks) {
    for (float c : {-1.0f, -5.0f, 5.0f}) {  // |c| > 1 makes bases > 1: the exponent cap must hold
      LafortuneParams p;
      p.rho_d = Vec3f::Constant(0.1f);
      p.rho_s = Vec3f::Constant(1000.0f);
      p.cx = p.cy = c;
      p.k = k;
      for (int i = 0; i < 2000; ++i) {
        const Vec3f f = EvaluateLafortune(p, RandomHemisphere(rng), RandomHemisphere(rng));
        ASSERT_TRUE(f.allFinite()) << "k " << k << " c " << c;
        ASSERT_LE(f.maxCoeff(), kMaxBrdf);
      }
    }
  }
  // k = 0: the step 1 where the base is positive, 0 (not pow(0, 0) = 1) where it is clamped.
  LafortuneParams p;
  p.rho_s = Vec3f::Ones();
  p.k = 0.0f;
  const Vec3f l = Vec3f(0.6f, 0.0f, 0.8f);
  EXPECT_EQ(EvaluateLafortune(p, Vec3f(-0.6f, 0.0f, 0.8f), l).x(), 1.0f);    // base 1
  EXPECT_EQ(EvaluateLafortune(p, Vec3f(0.99f, 0.0f, 0.141f), l).x(), 0.0f);  // base < 0
  // k -> infinity: the lobe tends to 0 off the peak, stays 1 exactly at the mirror direction.
  p.k = 1e6f;
  EXPECT_EQ(EvaluateLafortune(p, Vec3f(-0.6f, 0.0f, 0.8f), l).x(), 1.0f);
  EXPECT_EQ(EvaluateLafortune(p, Vec3f(-0.5f, 0.0f, 0.866f), l).x(), 0.0f);
  const LobeDerivatives d = LafortuneLobeDerivatives(p, Vec3f(-0.5f, 0.0f, 0.866f), l);
  EXPECT_TRUE(std::isfinite(d.d_k) && std::isfinite(d.d_cx));
}

TEST(Lafortune, GrazingAndBelowHorizon) {
  LafortuneParams p;
  p.rho_d = Vec3f::Constant(0.2f);
  p.rho_s = Vec3f::Constant(2.0f);
  p.k = 10.0f;
  const Vec3f grazing_l = Vec3f(std::sin(1.5706f), 0.0f, std::cos(1.5706f));  // 89.99 deg
  const Vec3f grazing_v = Vec3f(-std::sin(1.5706f), 0.0f, std::cos(1.5706f));
  const Vec3f f = EvaluateLafortune(p, grazing_v, grazing_l);
  EXPECT_TRUE(f.allFinite());
  EXPECT_NEAR(f.x(), 2.2f, 1e-4f);  // the mirror lobe still peaks at grazing: base = 1
  // Exactly at and below the horizon: reflection only, 0.
  EXPECT_EQ(EvaluateLafortune(p, Vec3f(1, 0, 0), grazing_l), Vec3f::Zero());
  EXPECT_EQ(EvaluateLafortune(p, Vec3f(0, 0.6f, -0.8f), grazing_l), Vec3f::Zero());
  // Non-finite directions: the lobe counts as 0, never NaN out.
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const Vec3f g = EvaluateLafortune(p, Vec3f(nan, 0.0f, 1.0f), Vec3f(0, 0, 1));
  EXPECT_TRUE(g.allFinite());
  EXPECT_TRUE(LafortuneLobeDerivatives(p, Vec3f(nan, 0, 1), Vec3f(0, 0, 1)).value == 0.0);
}

TEST(Lafortune, ValidateNamesTheField) {
  LafortuneParams p;
  EXPECT_TRUE(p.Validate().ok());
  p.k = -1;
  EXPECT_NE(p.Validate().message().find("k must be"), std::string::npos);
  p = {};
  p.cz = 2;
  EXPECT_NE(p.Validate().message().find("cz"), std::string::npos);
  p = {};
  p.rho_s = Vec3f(0, -1, 0);
  EXPECT_NE(p.Validate().message().find("rho_s"), std::string::npos);
  p = {};
  p.rho_d.x() = std::numeric_limits<float>::infinity();
  EXPECT_NE(p.Validate().message().find("rho_d"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Measured multi-lobe fits.

// <repo>/tests/lafortune_test.cpp -> <repo>/../shared/data (the project's shared data folder).
std::filesystem::path MeasuredFitsPath() {
  return std::filesystem::path(DIGITIZE_SOURCE_DIR).parent_path() / "shared" / "data" /
         "lafortune_measured_fits.txt";
}

TEST(MeasuredLafortune, ReadsThePublishedFits) {
  const std::filesystem::path path = MeasuredFitsPath();
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no " << path;
  Result<std::vector<MeasuredLafortune>> fits = ReadMeasuredLafortuneFits(path);
  ASSERT_TRUE(fits.ok()) << fits.error().message;
  ASSERT_EQ(fits->size(), 3u);
  const MeasuredLafortune& blue = (*fits)[0];
  EXPECT_EQ(blue.name, "bluepaint");
  EXPECT_FLOAT_EQ(blue.diffuse_albedo.z(), 0.70837f);
  ASSERT_EQ(blue.lobes.size(), 3u);
  EXPECT_FLOAT_EQ(blue.lobes[2].cxy.x(), -1.031545f);
  EXPECT_FLOAT_EQ(blue.lobes[0].n.y(), 18.597755f);
  const MeasuredLafortune& felt = (*fits)[2];
  EXPECT_EQ(felt.name, "felt");
  ASSERT_EQ(felt.lobes.size(), 3u);
  // Grey rows broadcast one value to the three channels.
  EXPECT_EQ(felt.lobes[2].cxy, Vec3f::Constant(1.004921f));
  EXPECT_EQ(felt.lobes[1].n, Vec3f::Constant(6.931827f));

  // The model on those numbers: finite, non-negative, reciprocal; diffuse/pi convention: at
  // normal incidence and view every lobe base is cz (or 0), so f = albedo/pi + sum max(0,cz)^n.
  std::mt19937 rng(7);
  for (const MeasuredLafortune& m : *fits) {
    for (int i = 0; i < 5000; ++i) {
      const Vec3f v = RandomHemisphere(rng), l = RandomHemisphere(rng);
      const Vec3f f = EvaluateMeasuredLafortune(m, v, l);
      ASSERT_TRUE(f.allFinite());
      ASSERT_TRUE((f.array() >= 0.0f).all());
      ASSERT_EQ(f, EvaluateMeasuredLafortune(m, l, v));
    }
    const Vec3f n(0, 0, 1);
    const Vec3f f = EvaluateMeasuredLafortune(m, n, n);
    for (int c = 0; c < 3; ++c) {
      double want = m.diffuse_albedo[c] / 3.14159265358979;
      for (const MeasuredLafortuneLobe& lobe : m.lobes)
        if (lobe.cz[c] > 0) want += std::pow(double(lobe.cz[c]), double(lobe.n[c]));
      EXPECT_NEAR(f[c], want, 1e-5 * (1 + want)) << m.name << " channel " << c;
    }
  }
}

// Parses `text` and returns the error message ("" when it parsed).
std::string ParseError(const std::string& text) {
  Result<std::vector<MeasuredLafortune>> r = ParseMeasuredLafortuneFits(text, "fits.txt");
  return r.ok() ? std::string() : r.error().message;
}

TEST(MeasuredLafortune, HostileInputsNameTheLine) {
  const std::string good = "# comment\n\nm diffuse 0.1 0.2 0.3\nm 0 -1,-1,-1 0.5 10\n";
  ASSERT_EQ(ParseError(good), "");
  ASSERT_EQ(ParseError("m diffuse 0.1 0.2 0.3\r\nm 0 -1 0.5 10\r\n"), "");  // CRLF
  struct Case {
    std::string text, expect;
  } cases[] = {
      {"m diffuse 0.1 0.2 0.3\nm 0 -1,-1,-1 abc 10\n",
       "fits.txt:2: lobe 0 of m: Cz: 'abc' is not a finite number"},
      {"m diffuse 0.1 0.2\n", "fits.txt:1: expected 5 columns"},
      {"m diffuse 0.1 0.2 0.3\n\nm 0 -1,-1,-1 0.5\n", "fits.txt:3: expected 5 columns"},
      {"m diffuse 0.1 0.2 0.3\nm 0 -1,-1 0.5 10\n",
       "fits.txt:2: lobe 0 of m: Cxy: '-1,-1' has 2 values"},
      {"m diffuse 0.1 0.2 0.3\nm 0 -1,-1,-1,-1 0.5 10\n", "more than 3 values"},
      {"m diffuse 0.1 0.2 0.3\nm 0 -1,,-1 0.5 10\n", "fits.txt:2: lobe 0 of m: Cxy"},
      {"m diffuse nan 0.2 0.3\n", "fits.txt:1: diffuse of m: 'nan' is not a finite number"},
      {"m diffuse 0.1 inf 0.3\n", "fits.txt:1: diffuse of m: 'inf'"},
      {"m diffuse 0.1 0.2 -0.3\n", "fits.txt:1: diffuse of m: albedo"},
      {"m diffuse 0.1 0.2 0.3x\n", "'0.3x' is not a finite number"},
      {"m diffuse 1e999 0.2 0.3\n", "fits.txt:1"},
      {"m diffuse 0.1 0.2 0.3\nm 1 -1 0.5 10\n", "fits.txt:2: lobe 1 of m: expected lobe 0"},
      {"m diffuse 0.1 0.2 0.3\nm 0 -1 0.5 10\nm 0 -1 0.5 10\n",
       "fits.txt:3: lobe 0 of m: expected lobe 1"},
      {"m diffuse 0.1 0.2 0.3\nm diffuse 0.1 0.2 0.3\n", "fits.txt:2: second diffuse row"},
      {"m diffuse 0.1 0.2 0.3\nm x -1 0.5 10\n",
       "fits.txt:2: second column must be 'diffuse' or a lobe index"},
      {"m diffuse 0.1 0.2 0.3\nm -1 -1 0.5 10\n", "fits.txt:2: second column"},
      {"m diffuse 0.1 0.2 0.3\nm 0 -1 0.5 -2\n",
       "fits.txt:2: lobe 0 of m: exponent n must be >= 0"},
      {"m 0 -1 0.5 10\n", "fits.txt: material m has no diffuse row"},
      {"# only comments\n\n", "fits.txt: no material rows"},
      {"", "fits.txt: no material rows"},
      {std::string("m diffuse 0.1\0 0.2 0.3\n", 23), "fits.txt:1"},
  };
  for (const Case& c : cases) {
    const std::string message = ParseError(c.text);
    EXPECT_NE(message.find(c.expect), std::string::npos)
        << "input: " << c.text << "\ngot: '" << message << "'";
  }
  // Garbage bytes never crash the parser.
  std::mt19937 rng(8);
  for (int i = 0; i < 2000; ++i) {
    std::string text = good;
    for (int j = 0; j < 4; ++j) text[rng() % text.size()] = static_cast<char>(rng() % 256);
    (void)ParseError(text);
  }
}

TEST(MeasuredLafortune, MissingFileIsAnError) {
  Result<std::vector<MeasuredLafortune>> r = ReadMeasuredLafortuneFits("/nonexistent/fits.txt");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("/nonexistent/fits.txt: cannot open"), std::string::npos);
}

}  // namespace
}  // namespace digitize
