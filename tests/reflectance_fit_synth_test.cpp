// The fit judged end to end: synthetic paintings photographed by the generator (Embree,
// relief and frame shadows), fitted on their true canvas, and relit under held-out lights and
// views against the generator's noise-free renders (frame-shadowed pixels masked, images clipped
// to white = 1; reflectance_fit.h). Also the parameter errors by paint region, the exactness of
// ray skipping, and the stress materials (k = 1 and k = 1000, black paint, saturated highlights,
// a measured 3-lobe paint outside the fitted model).
//
// Sizes are small (120-240 texels on the long side, 24-64 lights) so the suite also runs under
// ASan; the benchmark (bench/fit_bench.cpp) runs the same at 1 megatexel.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "digitize/reflectance_fit.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"
#include "digitize_synth/reflectance_truth.h"
#include "digitize_synth/scan_sim.h"

namespace digitize {
namespace {

struct Case {
  synth::Painting painting;
  synth::SyntheticPhotoSet photos;
  ReflectanceFitResult fit;
  HeldOutScore score;
};

Case FitSynthetic(int long_side, bool noise, std::vector<synth::PaintMaterial> materials = {},
                  ReflectanceFitOptions options = {}, int lights = 64) {
  Case c;
  synth::PaintingOptions po;
  po.resolution_px = long_side;
  c.painting = synth::MakePainting(po);
  const synth::Scene scene(c.painting, synth::FrameOptions{});
  synth::PhotoSimOptions so;
  so.lights = lights;
  // Photos at ~2 pixels per texel, a ratio that is not a whole or half number: a texel's bilinear
  // sample then stays within the texel (at 1 pixel per texel it blends the neighbours', and a
  // paint boundary's texels get mixed colours), and pixel centres never line up exactly with
  // texel edges, where nearest-texel look-ups in two renderers could round apart.
  so.pixels_per_texel = 2.07;
  if (!noise) {
    so.noise_sigma = 0;
    so.encoding = synth::PhotoEncoding::kLinearExr;
  }
  c.photos = synth::SimulatePhotoSet(scene, RigidTransform{}, so, std::move(materials));
  // The fit's noise level: the photos' sigma, or float rounding for noise-free EXR.
  options.fit.noise_sigma = noise ? so.noise_sigma : 1e-3;
  auto fit = FitReflectance(c.painting.truth, c.painting.normals, {}, c.photos.fit, options);
  EXPECT_TRUE(fit.ok()) << fit.error().message;
  c.fit = std::move(fit).value();
  auto score = EvaluateHeldOut(c.painting.truth, c.painting.normals, c.fit.maps, {},
                               c.photos.held_out, c.photos.held_out_mask);
  EXPECT_TRUE(score.ok());
  c.score = *score;
  EXPECT_TRUE(c.fit.maps.Validate().ok());
  std::printf("  %s\n  %s\n", c.fit.report.Brief().c_str(), c.score.Brief().c_str());
  return c;
}

// Issue 3's accuracy target: >= 40 dB noise-free on held-out lights and views (measured 40.3 dB
// at 240 texels, 42.1 at 200). What is left is the narrow lobes (gloss k = 100, varnish k = 400)
// under held-out lights near their peaks, which 64 lights sample too sparsely.
TEST(ReflectanceFitSynth, NoiseFreeHeldOutPsnrAtLeast40dB) {
  const Case c = FitSynthetic(240, false);
  EXPECT_GE(c.score.psnr_db, 40.0);
  EXPECT_GT(c.score.pixels, 20000u);
  const auto regions =
      synth::MeasureReflectanceAccuracy(c.fit.maps, c.painting.truth, {}, c.photos, c.painting);
  std::printf("%s", synth::FormatReflectanceAccuracy(regions).c_str());
  ASSERT_GE(regions.size(), 5u);
  for (const auto& r : regions) {
    // Noise-free samples of the fitted family: rho_d within 1 % wherever the painting is.
    EXPECT_LT(r.rho_d_rel_median, 0.01) << r.name;
    if (r.name.find("satin") != std::string::npos ||
        r.name.find("semi-gloss") != std::string::npos ||
        r.name.find("gloss (") != std::string::npos) {
      // Lobes wider than the light spacing (k <= 100) are recovered: k within 12 %, albedo 0.005.
      EXPECT_LT(r.log10_k_abs_median, 0.05) << r.name;
      EXPECT_LT(r.spec_albedo_abs_median, 0.005) << r.name;
    }
  }
}

// At the default noise (sigma 0.002, 8-bit sRGB): reported, with a floor 3 dB under what it
// measures (42.6 dB at 200 texels) so that a regression shows.
TEST(ReflectanceFitSynth, DefaultNoiseHeldOutPsnr) {
  const Case c = FitSynthetic(200, true);
  EXPECT_GE(c.score.psnr_db, 39.0);
  EXPECT_GT(c.fit.report.samples.saturated, 0u);  // 8-bit highlights clip and are rejected
  EXPECT_GT(c.fit.report.dark_outliers, 0u);      // frame shadows removed as unmodelled
}

// Skipping rays that cannot be blocked is exact: the same samples, so the same maps, bit for bit.
TEST(ReflectanceFitSynth, RaySkippingChangesNothing) {
  ReflectanceFitOptions skip, trace;
  trace.samples.trace.skip_unblockable = false;
  const Case a = FitSynthetic(120, true, {}, skip, 24);
  const Case b = FitSynthetic(120, true, {}, trace, 24);
  EXPECT_GT(a.fit.report.samples.light_rays.skipped, a.fit.report.samples.light_rays.rays / 4);
  EXPECT_EQ(b.fit.report.samples.light_rays.skipped, 0u);
  EXPECT_EQ(a.fit.report.samples.shadowed, b.fit.report.samples.shadowed);
  EXPECT_EQ(a.fit.report.samples.hidden, b.fit.report.samples.hidden);
  EXPECT_EQ(a.fit.maps.rho_d.data, b.fit.maps.rho_d.data);
  EXPECT_EQ(a.fit.maps.lobe.data, b.fit.maps.lobe.data);
}

synth::PaintMaterial OneLobe(const char* name, Vec3f albedo, float spec_albedo, float k) {
  synth::PaintMaterial m;
  m.name = name;
  m.lafortune.rho_d = albedo / 3.14159265f;
  m.lafortune.rho_s = Vec3f::Constant(spec_albedo * (k + 2) / (2 * 3.14159265f));
  m.lafortune.k = k;
  return m;
}

// k = 1 (a lobe as wide as the hemisphere), k = 1000 (far narrower than the light spacing),
// black paint and a bright gloss whose highlights saturate the 8-bit photos: finite maps, a
// status per texel, and relighting that stays close.
TEST(ReflectanceFitSynth, StressMaterials) {
  const Case c = FitSynthetic(160, true,
                              {OneLobe("k = 1", {0.3f, 0.3f, 0.3f}, 0.2f, 1.0f),
                               OneLobe("k = 1000", {0.2f, 0.1f, 0.1f}, 0.05f, 1000.0f),
                               OneLobe("black", {0, 0, 0}, 0.0f, 1.0f),
                               OneLobe("saturating gloss", {0.7f, 0.7f, 0.7f}, 0.25f, 60.0f)});
  EXPECT_GT(c.fit.report.samples.saturated, 1000u);
  EXPECT_GT(c.fit.report.samples.black, 0u);
  // The k = 1000 lobe (0.3 degrees wide, peak 20x white) is narrower than the light spacing and
  // clips wherever a light meets it: its peak is never measured, so held-out highlights on it are
  // missed (its texels fit diffuse-only or a wide lobe). Measured 29.9 dB; floor 27 dB.
  EXPECT_GE(c.score.psnr_db, 27.0);
  const auto regions =
      synth::MeasureReflectanceAccuracy(c.fit.maps, c.painting.truth, {}, c.photos, c.painting);
  std::printf("%s", synth::FormatReflectanceAccuracy(regions).c_str());
  for (const auto& r : regions) {
    if (r.name == "k = 1") {
      EXPECT_LT(r.rho_d_rel_median, 0.1);
    }
  }
}

// A measured 3-lobe paint (bluepaint) is not in the fitted family: reported (measured 42.0 dB at
// 200 texels, noise-free), with a floor 4 dB under it.
TEST(ReflectanceFitSynth, MismatchedModelIsReported) {
  const Case c = FitSynthetic(200, false, synth::DefaultPaintMaterials(true));
  EXPECT_GE(c.score.psnr_db, 38.0);
}

}  // namespace
}  // namespace digitize
