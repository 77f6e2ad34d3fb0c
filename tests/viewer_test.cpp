// Viewer (seed 001, section 5): headless renders of a synthetic painting against the Embree
// reference (RenderRelit on the full height field, same camera, light and shading), per technique
// and per paper view; relief vs bump at grazing impasto; a flat-height lookup; no popping along a
// slow path across the adaptive thresholds; packs that fail to load.
//
// Images are 256 x 192 so the suite stays fast on 2 cores (and under ASan). PSNR peak: radiance
// 1 = paper white under the standard light (scene_setup.h).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>

#include "checker_pack.h"
#include "digitize/image_io.h"
#include "digitize/normals.h"
#include "digitize/relight.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/truth_pack.h"
#include "digitize_viewer/gallery.h"
#include "digitize_viewer/gl_context.h"
#include "digitize_viewer/painting_setup.h"
#include "digitize_viewer/renderer.h"
#include "digitize_viewer/scene_setup.h"
#include "digitize_viewer/view.h"
#include "pack_forge.h"
#include "test_support.h"

namespace digitize::viewer {
namespace {

constexpr int kW = 256, kH = 192;

struct Shared {
  std::unique_ptr<HeadlessContext> context;
  std::unique_ptr<Renderer> renderer;
  synth::Painting painting;
  Pack pack;
  std::unique_ptr<HeightFieldTracer> tracer;
  Light light;
  std::string skip_reason;
};

Shared& Get() {
  static Shared* s = [] {
    auto* s = new Shared();
    synth::PaintingOptions po;
    po.width_mm = 160;
    po.height_mm = 120;
    po.resolution_px = 256;
    po.seed = 3;
    po.impasto_count = 6;
    s->painting = synth::MakePainting(po);
    // delta0 at 30 % of H, the paper's range (20-40 %) and ReliefOptions' default: the relief
    // between the true canvas and the bump plane (stroke ridges, impasto flanks) is the bump
    // plane's, found by its slab search at grazing views (renderer.h).
    synth::TruthPackOptions tpo;
    tpo.relief.delta0_fraction = 0.30;
    s->pack = synth::MakeTruthPack(s->painting, tpo);
    auto tracer = HeightFieldTracer::Build(s->pack.field);
    if (!tracer) {
      s->skip_reason = tracer.error().message;
      return s;
    }
    s->tracer = std::make_unique<HeightFieldTracer>(std::move(*tracer));
    s->light = StandardLight(s->pack);
    auto context = HeadlessContext::Create();
    if (!context) {
      s->skip_reason = context.error().message;
      return s;
    }
    s->context = std::move(*context);
    auto renderer = Renderer::Create();
    if (!renderer) {
      s->skip_reason = renderer.error().message;
      return s;
    }
    s->renderer = std::move(*renderer);
    auto index = s->renderer->AddPainting(s->pack, "synthetic");
    if (!index) s->skip_reason = index.error().message;
    return s;
  }();
  return *s;
}

#define REQUIRE_GL()                                             \
  do {                                                           \
    if (!Get().skip_reason.empty()) FAIL() << Get().skip_reason; \
  } while (0)

RenderOptions Options(Technique t) {
  RenderOptions o;
  o.technique = t;
  return o;
}

ViewCamera View(ViewDistance d, ViewAngle a) {
  const Pack& p = Get().pack;
  return MakePaperView(p.width_mm(), p.height_mm(), {d, a}, kW, kH);
}

Grid<Vec3f> Render(const ViewCamera& view, const RenderOptions& options) {
  return Get().renderer->Render(view, {Get().light}, options).rgb;
}

double Psnr(const Grid<Vec3f>& test, const RelitImage& ref) {
  const ImageComparison c = CompareImages(test, ref.rgb, ref.mask, kPsnrPeak);
  // The far views cover few pixels (762 at far-grazing): still enough to judge.
  EXPECT_GT(c.pixels, size_t(500)) << "too few canvas pixels compared";
  return c.psnr_db;
}

// Mean absolute difference over all pixels and channels.
double MeanAbsDiff(const Grid<Vec3f>& a, const Grid<Vec3f>& b) {
  double sum = 0;
  for (size_t i = 0; i < a.data.size(); ++i) sum += (a.data[i] - b.data[i]).cwiseAbs().sum();
  return sum / (3.0 * a.data.size());
}

// Not blank: at least min_lit of the pixels lit (> 0.01) and a mean above 0.02 x min_lit / 0.1.
void ExpectPlausible(const Grid<Vec3f>& img, const std::string& what, double min_lit = 0.1) {
  size_t lit = 0;
  double sum = 0;
  for (const Vec3f& c : img.data) {
    ASSERT_TRUE(c.allFinite()) << what;
    ASSERT_GE(c.minCoeff(), 0.0f) << what;
    lit += c.maxCoeff() > 0.01f;
    sum += c.sum();
  }
  EXPECT_GT(double(lit), min_lit * img.data.size()) << what << ": blank image";
  EXPECT_GT(sum / (3.0 * img.data.size()), 0.2 * min_lit) << what << ": nearly black";
}

// Writes a screenshot when DIGITIZE_VIEWER_SHOTS names a folder (to look at them).
void MaybeSave(const Grid<Vec3f>& img, const std::string& name) {
  const char* dir = std::getenv("DIGITIZE_VIEWER_SHOTS");
  if (!dir) return;
  std::filesystem::create_directories(dir);
  (void)WritePngRgb8(std::filesystem::path(dir) / (name + ".png"), ToneMap(img));
}

TEST(ViewerTest, CameraMatchesReferenceConvention) {
  const ViewCamera v = View(ViewDistance::kFramed, ViewAngle::kFace);
  const Camera c = ToCamera(v);
  // The target projects to the image centre.
  const Eigen::Vector2d px = c.Project(v.target_mm);
  EXPECT_NEAR(px.x(), (kW - 1) / 2.0, 1e-9);
  EXPECT_NEAR(px.y(), (kH - 1) / 2.0, 1e-9);
  EXPECT_TRUE(v.Validate().ok());
  ViewCamera bad = v;
  bad.target_mm = bad.eye_mm;
  EXPECT_FALSE(bad.Validate().ok());
}

TEST(ViewerTest, OptionsValidate) {
  RenderOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.eps_max = o.eps_min;
  EXPECT_FALSE(o.Validate().ok());
  o = RenderOptions{};
  o.k = std::nan("");
  EXPECT_FALSE(o.Validate().ok());
  o = RenderOptions{};
  o.bump_min_steps = 0;
  EXPECT_FALSE(o.Validate().ok());
  o = RenderOptions{};
  o.bump_search_min_texels = -1;
  EXPECT_FALSE(o.Validate().ok());
  o = RenderOptions{};
  o.bump_binary_steps = 33;
  EXPECT_FALSE(o.Validate().ok());
  EXPECT_FALSE(ParseTechnique("nope").ok());
  for (Technique t : kAllTechniques) EXPECT_EQ(*ParseTechnique(ToString(t)), t);
}

TEST(ViewerTest, EveryTechniqueRendersAPlausibleImage) {
  REQUIRE_GL();
  const ViewCamera v = View(ViewDistance::kFramed, ViewAngle::kGrazing);
  for (Technique t : kAllTechniques) {
    const Grid<Vec3f> img = Render(v, Options(t));
    ExpectPlausible(img, ToString(t));
    MaybeSave(img, std::string("framed-grazing-") + ToString(t));
  }
}

// Image error of every mode against the Embree reference at the paper's six views, on 4 x 4
// box-filtered images (scene_setup.h: point samples at grazing views measure aliasing, not the
// renderer); the point-sampled PSNR is printed too. Thresholds: hybrid+adaptive >= 35 dB (the
// issue's bar), and so must be every mode that draws the relief (mesh, relief everywhere,
// hybrid, screen-space error); bump only may fail it at grazing views (its parallax error is what
// the boxes are for) but stays an image of the painting (>= 20 dB).
TEST(ViewerTest, MatchesEmbreeReferenceAtPaperViews) {
  REQUIRE_GL();
  const int ss = kCompareSupersampling;
  for (const PaperView& pv : AllPaperViews()) {
    const ViewCamera v = View(pv.distance, pv.angle);
    const RelitImage ref = RenderReference(*Get().tracer, Get().pack, v, Get().light, false);
    const RelitImage ref_ss =
        RenderReference(*Get().tracer, Get().pack, Supersampled(v, ss), Get().light, false);
    const Grid<Vec3f> ref_aa = Downsample(ref_ss.rgb, ss);
    const Grid<uint8_t> mask_aa = DownsampleMask(ref_ss.mask, ss);
    MaybeSave(ref.rgb, pv.Name() + "-reference");
    for (Technique t : kAllTechniques) {
      const Grid<Vec3f> img = Render(v, Options(t));
      // Half the pixels that see the canvas in the reference must be lit.
      const double canvas_share =
          double(std::count(ref.mask.data.begin(), ref.mask.data.end(), 1)) / ref.mask.size();
      ExpectPlausible(img, pv.Name() + " " + ToString(t), 0.5 * canvas_share);
      const double psnr_point = Psnr(img, ref);
      const Grid<Vec3f> aa = Downsample(Render(Supersampled(v, ss), Options(t)), ss);
      const ImageComparison c = CompareImages(aa, ref_aa, mask_aa, kPsnrPeak);
      EXPECT_GT(c.pixels, size_t(500)) << "too few canvas pixels compared";
      MaybeSave(img, pv.Name() + "-" + ToString(t));
      Grid<Vec3f> diff(kW, kH);
      for (size_t i = 0; i < diff.data.size(); ++i)
        diff.data[i] = (img.data[i] - ref.rgb.data[i]).cwiseAbs() * 4.0f;
      MaybeSave(diff, pv.Name() + "-" + ToString(t) + "-diff4");
      std::printf("%-15s %-13s point %6.2f dB, 4x4 box-filtered %6.2f dB\n", pv.Name().c_str(),
                  ToString(t), psnr_point, c.psnr_db);
      const bool bump_only = t == Technique::kBump;
      EXPECT_GE(c.psnr_db, bump_only ? 20.0 : 35.0) << pv.Name() << " " << ToString(t);
    }
  }
}

// The bump plane's slab search (renderer.h) is what carries hybrid+adaptive over the 35 dB bar
// at grazing views with delta0 = 30 % of H: the fixed-point parallax steps it replaces fall short
// there (the relief under the plane hides and shows texels they cannot follow), and it must gain
// >= 3 dB over them; at face views it leaves the image as it was (the search is skipped where the
// ray crosses the slab within a texel): the two images within 60 dB of each other.
TEST(ViewerTest, SlabSearchCarriesGrazingViews) {
  REQUIRE_GL();
  const int ss = kCompareSupersampling;
  RenderOptions fixed_point = Options(Technique::kHybridAdaptive);
  fixed_point.bump_slab_search = false;
  for (const PaperView& pv : AllPaperViews()) {
    const ViewCamera v = View(pv.distance, pv.angle);
    const RelitImage ref_ss =
        RenderReference(*Get().tracer, Get().pack, Supersampled(v, ss), Get().light, false);
    const Grid<Vec3f> ref_aa = Downsample(ref_ss.rgb, ss);
    const Grid<uint8_t> mask_aa = DownsampleMask(ref_ss.mask, ss);
    auto psnr = [&](const RenderOptions& o) {
      const Grid<Vec3f> aa = Downsample(Render(Supersampled(v, ss), o), ss);
      return CompareImages(aa, ref_aa, mask_aa, kPsnrPeak).psnr_db;
    };
    const double searched = psnr(Options(Technique::kHybridAdaptive)), fixed = psnr(fixed_point);
    std::printf("%-15s adaptive 4x4: slab search %6.2f dB, fixed-point steps %6.2f dB\n",
                pv.Name().c_str(), searched, fixed);
    EXPECT_GE(searched, 35.0) << pv.Name();
    // Measured on this painting: 31.1 -> 47.8 (close), 32.4 -> 52.7 (framed), 37.0 -> 48.5 (far).
    if (pv.angle == ViewAngle::kGrazing) {
      EXPECT_GT(searched, fixed + 3.0) << pv.Name();
    }
    if (pv.angle == ViewAngle::kFace) {
      const Grid<Vec3f> a = Render(v, Options(Technique::kHybridAdaptive)),
                        b = Render(v, fixed_point);
      Grid<uint8_t> all(kW, kH);
      std::fill(all.data.begin(), all.data.end(), uint8_t(1));
      EXPECT_GT(CompareImages(a, b, all, kPsnrPeak).psnr_db, 60.0) << pv.Name();
    }
  }
}

// Relief mapping shows what bump mapping cannot: at a grazing close view of impasto the two
// differ over a visible share of the image (measured: 4.7 % of pixels by more than 0.05,
// bound 3 %), and relief is the one that matches the reference.
TEST(ViewerTest, ReliefDiffersFromBumpAtGrazingImpasto) {
  REQUIRE_GL();
  const ViewCamera v = View(ViewDistance::kClose, ViewAngle::kGrazing);
  RenderOptions bump = Options(Technique::kBump);
  bump.bump_slab_search = false;
  bump.bump_parallax_iterations = 0;  // the paper's bump mapping
  const Grid<Vec3f> b = Render(v, bump);
  const Grid<Vec3f> r = Render(v, Options(Technique::kReliefEverywhere));
  size_t differ = 0;
  for (size_t i = 0; i < b.data.size(); ++i)
    differ += (b.data[i] - r.data[i]).cwiseAbs().maxCoeff() > 0.05f;
  const double share = double(differ) / b.data.size();
  std::printf("close-grazing: relief vs bump differ on %.1f %% of pixels\n", 100 * share);
  EXPECT_GT(share, 0.03);
  const RelitImage ref = RenderReference(*Get().tracer, Get().pack, v, Get().light, false);
  EXPECT_GT(Psnr(r, ref), Psnr(b, ref) + 5.0);
}

// A mis-bound height texture can look plausible: the same maps with a flat height field must
// give a clearly different relief image, and a worse one against the reference.
TEST(ViewerTest, ReliefDiffersFromFlatHeightLookup) {
  REQUIRE_GL();
  Pack flat = Get().pack;
  std::fill(flat.field.height_mm.data.begin(), flat.field.height_mm.data.end(), 0.0f);
  auto renderer = Renderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  ASSERT_TRUE((*renderer)->AddPainting(flat, "flat").ok());
  const ViewCamera v = View(ViewDistance::kClose, ViewAngle::kGrazing);
  const RenderOptions o = Options(Technique::kReliefEverywhere);
  const Grid<Vec3f> real = Render(v, o);
  const Grid<Vec3f> flat_img = (*renderer)->Render(v, {Get().light}, o).rgb;
  ExpectPlausible(flat_img, "flat");
  const double diff = MeanAbsDiff(real, flat_img);
  std::printf("close-grazing: relief vs flat lookup mean |diff| %.4f\n", diff);
  EXPECT_GT(diff, 0.004);  // measured 0.008
  const RelitImage ref = RenderReference(*Get().tracer, Get().pack, v, Get().light, false);
  EXPECT_GT(Psnr(real, ref), Psnr(flat_img, ref) + 10.0);
}

// No popping: dollying in at 30 deg from the normal from 10x to 1x the framed distance, boxes
// switch on (the adaptive rule's thresholds are crossed: counted), yet consecutive frames of
// hybrid+adaptive differ no more than those of hybrid with every box always on (the motion
// itself) plus a stated bound: 0.002 mean radiance (paper white = 1) per step.
TEST(ViewerTest, NoPoppingAlongASlowPath) {
  REQUIRE_GL();
  const Pack& p = Get().pack;
  const ViewCamera framed = View(ViewDistance::kFramed, ViewAngle::kFace);
  const double d_framed = (framed.eye_mm - framed.target_mm).norm();
  const int steps = 40;
  const double a = 30.0 * 3.14159265358979323846 / 180.0;
  Grid<Vec3f> prev_adaptive, prev_hybrid;
  int min_drawn = 1 << 30, max_drawn = 0, blended_frames = 0;
  double worst_excess = -1e9;
  for (int i = 0; i <= steps; ++i) {
    const double d = d_framed * std::pow(10.0, 1.0 - double(i) / steps);
    ViewCamera v = framed;
    v.eye_mm = v.target_mm + d * Vec3d(0, -std::sin(a), std::cos(a));
    v.up = Vec3d::UnitY();
    const RenderedImage ad =
        Get().renderer->Render(v, {Get().light}, Options(Technique::kHybridAdaptive));
    const Grid<Vec3f> hy = Render(v, Options(Technique::kHybrid));
    min_drawn = std::min(min_drawn, ad.stats.boxes_drawn);
    max_drawn = std::max(max_drawn, ad.stats.boxes_drawn);
    blended_frames += ad.stats.boxes_blended > 0;
    if (i > 0) {
      const double da = MeanAbsDiff(ad.rgb, prev_adaptive), dh = MeanAbsDiff(hy, prev_hybrid);
      worst_excess = std::max(worst_excess, da - dh);
    }
    prev_adaptive = ad.rgb;
    prev_hybrid = hy;
  }
  std::printf("dolly: boxes drawn %d .. %d of %zu, %d frames blend, worst excess %.5f\n", min_drawn,
              max_drawn, p.boxes.size(), blended_frames, worst_excess);
  EXPECT_EQ(min_drawn, 0);
  EXPECT_GE(max_drawn, int(p.boxes.size()) / 2);  // measured 12 of 24 (delta0 = 30 % of H)
  EXPECT_GT(blended_frames, 2);
  EXPECT_LT(worst_excess, 0.002);
}

// A pack the renderer cannot use is an error naming it, not a crash.
// The smallest grids through the filtered programs: an 8 x 6 texel canvas of 5 mm texels (its
// pyramid 8 x 6, 4 x 3, 2 x 1, 1 x 1) seen from 700 mm at 64 x 48 px, a pixel ~10.6 mm (2.1
// texels) across, face-on and at 60 deg: finite, lit, drawn with the filter (FrameStats says so)
// or without it; and filtered, the checker of radiance 0.1 and 0.3 averages towards 0.2 in every
// pixel: the spread of the pixels about 0.2 under half the point-sampled one's (measured 0.011
// face-on, 0.014 at 60 deg, against 0.100: its pixels each pick one texel).
TEST(ViewerTest, TinyPackThroughThePrefilteredPrograms) {
  REQUIRE_GL();
  const Pack tiny = FlatCheckerPack(8, 6, 5.0, 0.3f, 0.1f);
  auto renderer = Renderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  ASSERT_TRUE((*renderer)->AddPainting(tiny, "tiny").ok());
  Light light;
  light.type = LightType::kDirectional;
  light.direction = Vec3d(0, 0, 1);
  light.irradiance = Vec3f::Constant(1.0f);
  for (double angle_deg : {0.0, 60.0}) {
    ViewCamera v;
    v.target_mm = Vec3d(20, 15, 0);
    const double a = angle_deg * kPi / 180;
    v.eye_mm = v.target_mm + 700.0 * Vec3d(0, -std::sin(a), std::cos(a));
    v.width = 64;
    v.height = 48;
    double spread[2] = {0, 0};
    for (bool filter : {true, false}) {
      RenderOptions o = Options(Technique::kHybridAdaptive);
      o.filter_reflectance = filter;
      const RenderedImage img = (*renderer)->Render(v, {light}, o);
      EXPECT_EQ(img.stats.filtered_paintings, filter ? 1 : 0) << angle_deg;
      size_t lit = 0;
      double sum = 0;
      for (const Vec3f& c : img.rgb.data) {
        ASSERT_TRUE(c.allFinite());
        if (c.maxCoeff() > 0.01f) {
          ++lit;
          sum += (c.x() - 0.2) * (c.x() - 0.2);
        }
      }
      EXPECT_GE(lit, size_t(3)) << angle_deg << (filter ? " filtered" : " point");
      spread[filter ? 1 : 0] = std::sqrt(sum / std::max<size_t>(lit, 1));
    }
    std::printf("tiny pack at %.0f deg: RMS of pixels about 0.2: filtered %.4f, point %.4f\n",
                angle_deg, spread[1], spread[0]);
    EXPECT_LT(spread[1], 0.5 * spread[0]) << angle_deg;
  }
}

TEST(ViewerTest, InconsistentPackIsReported) {
  REQUIRE_GL();
  Pack bad = Get().pack;
  bad.normals = Grid<Vec3f>(3, 3);
  auto index = Get().renderer->AddPainting(bad, "broken.pack.exr");
  ASSERT_FALSE(index.ok());
  EXPECT_NE(index.error().message.find("broken.pack.exr"), std::string::npos);
  Pack tiny;
  tiny.field.height_mm = Grid<float>(1, 1);
  EXPECT_FALSE(Get().renderer->AddPainting(tiny, "tiny").ok());
  EXPECT_EQ(Get().renderer->painting_count(), 1);
}

// A scanned canvas's mask has a jagged outline inside the pack's grid rectangle (texels outside
// the canvas), and edge texels fitted from too few samples hold zero maps. The bump plane and the
// mesh cover the whole rectangle: those texels must not be relit black (the black outline once
// seen round every painting in the gallery). A uniformly bright flat painting, face on and close:
// no near-black pixel anywhere inside its rectangle, in every technique.
TEST(ViewerTest, NoBlackOutlineWhereTheMaskOrTheFitEnds) {
  REQUIRE_GL();
  constexpr int w = 64, h = 48;
  Pack p;
  p.field.height_mm = Grid<float>(w, h, 0.0f);
  p.field.state = Grid<TexelState>(w, h, TexelState::kMeasured);
  p.field.pitch_mm = 1.0;
  p.normals = Grid<Vec3f>(w, h, Vec3f::UnitZ());
  p.maps = ReflectanceMaps::Zeros(w, h);
  p.delta0_mm = 0.01;
  p.max_height_mm = 0.02;
  p.cell_px = 16;
  size_t outside = 0, unfitted = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      // A notched border 0-3 texels deep (as a dropout-ridden scan's mask), and a second ring of
      // texels the fit could not constrain: both keep the zero maps a fit leaves there.
      const int depth = std::min(std::min(x, w - 1 - x), std::min(y, h - 1 - y));
      const int notch = (x * 7 + y * 3) % 4;
      if (depth < notch) {
        p.field.state(x, y) = TexelState::kOutside;
        ++outside;
      } else if (depth == notch && (x + y) % 2 == 0) {
        ++unfitted;  // status stays kTooFewSamples
      } else {
        p.maps.rho_d(x, y) = Vec3f::Constant(0.8f / 3.14159265f);
        p.maps.status(x, y) = TexelFitStatus::kDiffuseOnly;
      }
    }
  }
  ASSERT_GT(outside, 50u);
  ASSERT_GT(unfitted, 20u);
  auto renderer = Renderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  ASSERT_TRUE((*renderer)->AddPainting(p, "notched").ok());
  ViewCamera view;
  view.eye_mm = Vec3d(w / 2.0, h / 2.0, 80);
  view.target_mm = Vec3d(w / 2.0, h / 2.0, 0);
  view.up = Vec3d::UnitY();
  view.width = 160;
  view.height = 120;
  const Camera cam = ToCamera(view);
  const Eigen::Vector2d a = cam.Project(Vec3d(0, h, 0)), b = cam.Project(Vec3d(w, 0, 0));
  const double u0 = std::min(a.x(), b.x()) + 1.5, u1 = std::max(a.x(), b.x()) - 1.5;
  const double v0 = std::min(a.y(), b.y()) + 1.5, v1 = std::max(a.y(), b.y()) - 1.5;
  ASSERT_GT(u1 - u0, 100);  // the canvas fills most of the image: 2+ pixels per texel
  for (Technique t : {Technique::kMesh, Technique::kBump, Technique::kHybridAdaptive}) {
    const Grid<Vec3f> img = (*renderer)->Render(view, {StandardLight(p)}, Options(t)).rgb;
    MaybeSave(img, std::string("notched_") + ToString(t));
    size_t inside = 0, black = 0;
    for (int v = int(std::ceil(v0)); v <= int(v1); ++v) {
      for (int u = int(std::ceil(u0)); u <= int(u1); ++u) {
        ++inside;
        black += img(u, v).maxCoeff() < 0.1f;  // the painting reads ~0.6-0.8 here
      }
    }
    EXPECT_GT(inside, 10000u);
    EXPECT_EQ(black, 0u) << ToString(t) << ": " << black << " near-black pixels of " << inside
                         << " inside the canvas rectangle";
  }
}

// Self-shadowing: with shadows on, the viewer's relief modes match the reference with shadows on
// (same 35 dB bar on 4 x 4 box-filtered images) and are darker than without (shadows appear).
TEST(ViewerTest, ShadowsMatchReferenceWithShadows) {
  REQUIRE_GL();
  const int ss = kCompareSupersampling;
  // A low light (20 deg above the canvas, from -X) so that the impasto casts long shadows.
  const Pack& p = Get().pack;
  Light light;
  light.type = LightType::kPoint;
  const double d = 300, e = 20 * 3.14159265358979323846 / 180;
  light.position_mm =
      Vec3d(p.width_mm() / 2, p.height_mm() / 2, 0) + d * Vec3d(-std::cos(e), 0, std::sin(e));
  light.intensity = Vec3f::Constant(float(3.14159265358979323846 * d * d));
  for (ViewAngle a : {ViewAngle::kFace, ViewAngle::kGrazing}) {
    const ViewCamera v = View(ViewDistance::kClose, a);
    const RelitImage ref_ss =
        RenderReference(*Get().tracer, Get().pack, Supersampled(v, ss), light, true);
    ASSERT_GT(ref_ss.shadowed_pixels, 0u);
    const Grid<Vec3f> ref_aa = Downsample(ref_ss.rgb, ss);
    const Grid<uint8_t> mask_aa = DownsampleMask(ref_ss.mask, ss);
    for (Technique t : {Technique::kReliefEverywhere, Technique::kHybridAdaptive}) {
      RenderOptions o = Options(t);
      o.shadows = true;
      const Grid<Vec3f> lit = Get().renderer->Render(Supersampled(v, ss), {light}, o).rgb;
      const Grid<Vec3f> aa = Downsample(lit, ss);
      const double psnr = CompareImages(aa, ref_aa, mask_aa, kPsnrPeak).psnr_db;
      const Grid<Vec3f> unlit =
          Get().renderer->Render(Supersampled(v, ss), {light}, Options(t)).rgb;
      const double psnr_off =
          CompareImages(Downsample(unlit, ss), ref_aa, mask_aa, kPsnrPeak).psnr_db;
      std::printf("close-%s %-9s vs reference with shadows: on %6.2f dB, off %6.2f dB (4x4)\n",
                  a == ViewAngle::kFace ? "face" : "grazing", ToString(t), psnr, psnr_off);
      EXPECT_GE(psnr, 35.0);
      EXPECT_GT(psnr, psnr_off + 3.0);  // the shadows are there, and in the right places
    }
  }
}

std::filesystem::path TempDir() {
  const auto dir = test::ScratchPath("digitize_viewer_test");
  std::filesystem::create_directories(dir);
  return dir;
}

TEST(ViewerTest, CameraPathReadsAndRejectsBadFiles) {
  const auto dir = TempDir();
  const auto good = dir / "path.json";
  ASSERT_TRUE(WriteTextFile(good, R"({"format": "digitize.camera_path", "version": 1,
    "width": 64, "height": 48, "frames": [
      {"eye": [0, 0, 1600], "target": [0, 1000, 1500]},
      {"eye": [100, 0, 1600], "target": [0, 1000, 1500], "up": [0, 0, 1]}]})")
                  .ok());
  auto path = ReadCameraPath(good);
  ASSERT_TRUE(path.ok()) << path.error().message;
  ASSERT_EQ(path->size(), 2u);
  EXPECT_EQ((*path)[1].width, 64);
  const auto bad = dir / "bad.json";
  ASSERT_TRUE(WriteTextFile(bad, R"({"format": "digitize.camera_path", "version": 1,
    "frames": [{"eye": [0, 0, 0], "target": [0, 0, 0]}]})")
                  .ok());
  auto e = ReadCameraPath(bad);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("bad.json: frames[0]"), std::string::npos) << e.error().message;
  EXPECT_FALSE(ReadCameraPath(dir / "missing.json").ok());
  ASSERT_TRUE(WriteTextFile(bad, "{not json").ok());
  EXPECT_FALSE(ReadCameraPath(bad).ok());
  std::filesystem::remove_all(dir);
}

// A pack file that does not exist or is not a pack: an error naming it, nothing thrown.
TEST(ViewerTest, PackThatFailsToLoadIsReported) {
  const auto dir = TempDir();
  const auto junk = dir / "junk.pack.exr";
  ASSERT_TRUE(WriteTextFile(junk, "not an EXR").ok());
  for (const auto& p : {dir / "missing.pack.exr", junk}) {
    auto pack = LoadPackForViewer(p);
    ASSERT_FALSE(pack.ok());
    EXPECT_NE(pack.error().message.find(p.filename().string()), std::string::npos)
        << pack.error().message;
  }
  std::filesystem::remove_all(dir);
}

// A pack file written by WritePack and read by the viewer renders like the pack in memory (up to
// the half-float rounding of the file: measured 89 dB, bound 40 dB).
TEST(ViewerTest, PackFileRendersLikeThePackInMemory) {
  REQUIRE_GL();
  const auto dir = TempDir();
  const auto path = dir / "synthetic.pack.exr";
  ASSERT_TRUE(WritePack(path, Get().pack).ok());
  auto pack = LoadPackForViewer(path);
  ASSERT_TRUE(pack.ok()) << pack.error().message;
  auto renderer = Renderer::Create();
  ASSERT_TRUE(renderer.ok());
  ASSERT_TRUE((*renderer)->AddPainting(*pack, path.string()).ok());
  const ViewCamera v = View(ViewDistance::kClose, ViewAngle::kGrazing);
  const RenderOptions o = Options(Technique::kHybridAdaptive);
  const Grid<Vec3f> from_file = (*renderer)->Render(v, {Get().light}, o).rgb;
  const Grid<Vec3f> in_memory = Render(v, o);
  Grid<uint8_t> all(kW, kH, 1);
  const double psnr = CompareImages(from_file, in_memory, all, kPsnrPeak).psnr_db;
  std::printf("pack file vs in memory: %.2f dB\n", psnr);
  EXPECT_GT(psnr, 40.0);
  std::filesystem::remove_all(dir);
}

// The gallery: paintings at their physical size on the back wall, facing into the room.
TEST(ViewerTest, GalleryHangsPaintingsFacingTheRoom) {
  const Gallery g = MakeGallery({Eigen::Vector2d(400, 300), Eigen::Vector2d(600, 800)});
  ASSERT_EQ(g.world_from_canvas.size(), 2u);
  ASSERT_EQ(g.lights.size(), 2u);
  for (const RigidTransform& t : g.world_from_canvas) {
    EXPECT_NEAR(t.rotation.determinant(), 1.0, 1e-12);
    const Vec3d normal = t.ApplyToDirection(Vec3d::UnitZ());
    EXPECT_NEAR(normal.y(), -1.0, 1e-12);  // into the room
    const Vec3d corner = t.Apply(Vec3d(0, 0, 0));
    EXPECT_GT(corner.x(), 0);
    EXPECT_LT(corner.x(), g.width_mm);
    EXPECT_GT(corner.z(), 0);
  }
  // Side by side, not overlapping.
  EXPECT_GT(g.world_from_canvas[1].translation.x(), g.world_from_canvas[0].translation.x() + 400);
}

// The start view is a visitor's: ~2.5 m from the first painting at eye height, both paintings
// (hung with their centres at 1.55 m) well inside the image, the floor in view; every painting
// lies inside its picture light's full-strength cone, frame included.
TEST(ViewerTest, GalleryStartViewShowsTheRoomAndTwoPaintings) {
  const Gallery g = MakeGallery({Eigen::Vector2d(400, 300), Eigen::Vector2d(600, 800)});
  ASSERT_EQ(g.centres_mm.size(), 2u);
  ViewCamera c = g.start;
  c.width = 1280;
  c.height = 720;
  const Camera cam = ToCamera(c);
  EXPECT_NEAR((g.start.eye_mm - g.centres_mm[0]).norm(), 2500, 300);
  EXPECT_NEAR(g.start.eye_mm.z(), 1600, 100);
  for (const Vec3d& centre : g.centres_mm) {
    EXPECT_NEAR(centre.z(), 1550, 1e-9);
    ASSERT_TRUE(cam.InFront(centre));
    const Eigen::Vector2d px = cam.Project(centre);
    EXPECT_GT(px.x(), 0.1 * c.width);
    EXPECT_LT(px.x(), 0.9 * c.width);
    EXPECT_GT(px.y(), 0.1 * c.height);
    EXPECT_LT(px.y(), 0.9 * c.height);
  }
  // The floor where it meets the back wall, somewhere across the image's lower edge.
  bool floor_seen = false;
  for (double x = 0; x <= g.width_mm && !floor_seen; x += 100) {
    const Vec3d p(x, g.depth_mm - 20, 0);
    if (!cam.InFront(p)) continue;
    const Eigen::Vector2d px = cam.Project(p);
    floor_seen = px.x() >= 0 && px.x() < c.width && px.y() >= 0 && px.y() < c.height;
  }
  EXPECT_TRUE(floor_seen) << "the start view shows no floor";
  ASSERT_EQ(g.room.spots.size(), g.lights.size());
  const double frame = GalleryOptions().frame_mm;
  for (size_t i = 0; i < g.lights.size(); ++i) {
    const RigidTransform& t = g.world_from_canvas[i];
    const Eigen::Vector2d size = i == 0 ? Eigen::Vector2d(400, 300) : Eigen::Vector2d(600, 800);
    for (double u : {-frame, size.x() + frame})
      for (double v : {-frame, size.y() + frame}) {
        const Vec3d corner = t.Apply(Vec3d(u, v, 0));
        const Vec3d l = (corner - g.lights[i].position_mm).normalized();
        const double deg = std::acos(std::clamp(l.dot(g.room.spots[i].axis), -1.0, 1.0)) * 180 /
                           3.14159265358979323846;
        EXPECT_LT(deg, g.room.spots[i].inner_deg) << "painting " << i << " corner outside its cone";
      }
  }
  const ViewCamera near = CloseUpView(g, 0);
  EXPECT_NEAR((near.eye_mm - g.centres_mm[0]).norm(), 350, 1);
  EXPECT_TRUE(near.Validate().ok());
}

// The tour walks from the start view past every painting, inside the room, without jumps, and
// stands in front of each painting facing it.
TEST(ViewerTest, GalleryTourVisitsEveryPaintingSmoothly) {
  const Gallery g = MakeGallery({Eigen::Vector2d(400, 300), Eigen::Vector2d(64, 48)});
  const std::vector<ViewCamera> tour = GalleryTour(g, 120, 320, 180);
  ASSERT_EQ(tour.size(), 120u);
  EXPECT_LT((tour.front().eye_mm - g.start.eye_mm).norm(), 1e-6);
  double longest = 0, total = 0;
  for (size_t i = 0; i < tour.size(); ++i) {
    EXPECT_TRUE(tour[i].Validate().ok()) << i;
    EXPECT_EQ(tour[i].width, 320);
    for (int k = 0; k < 3; ++k) {
      EXPECT_GT(tour[i].eye_mm[k], 0) << i;
      EXPECT_LT(tour[i].eye_mm[k], Vec3d(g.width_mm, g.depth_mm, g.height_mm)[k]) << i;
    }
    if (i > 0) {
      const double step = (tour[i].eye_mm - tour[i - 1].eye_mm).norm();
      longest = std::max(longest, step);
      total += step;
    }
  }
  EXPECT_LT(longest, 4 * total / (tour.size() - 1)) << "a jump in the walk";
  for (size_t p = 0; p < g.centres_mm.size(); ++p) {
    double nearest = 1e300;
    bool facing = false;
    for (const ViewCamera& c : tour) {
      const double d = (c.eye_mm - g.centres_mm[p]).norm();
      if (d < nearest) {
        nearest = d;
        facing =
            (c.target_mm - c.eye_mm).normalized().dot((g.centres_mm[p] - c.eye_mm).normalized()) >
            0.99;
      }
    }
    EXPECT_LT(nearest, 1.05 * std::clamp(3 * g.sizes_mm[p].maxCoeff(), 400.0, 1200.0)) << p;
    EXPECT_TRUE(facing) << "painting " << p;
  }
}

// A video of a tour: refused without images or over an existing file; without ffmpeg an error
// that says so; with it, a file.
TEST(ViewerTest, TourVideoIsRefusedOrWritten) {
  const auto dir = TempDir();
  std::filesystem::create_directories(dir);
  EXPECT_FALSE(WriteVideo(dir / "t.png", 1, dir / "t.mp4").ok());
  { std::ofstream(dir / "there.mp4") << "not ours"; }
  const Status over = WriteVideo(dir / "t.png", 4, dir / "there.mp4");
  EXPECT_FALSE(over.ok());
  EXPECT_NE(over.message().find("already exists"), std::string::npos) << over.message();
  std::ifstream kept(dir / "there.mp4");
  std::string text;
  std::getline(kept, text);
  EXPECT_EQ(text, "not ours");
  Grid<std::array<uint8_t, 3>> img(64, 48);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = {uint8_t(i), uint8_t(i / 64), 90};
  for (size_t i = 0; i < 4; ++i)
    ASSERT_TRUE(WritePngRgb8(ScreenshotPath(dir / "t.png", i, 4), img).ok());
  const Status made = WriteVideo(dir / "t.png", 4, dir / "t.mp4");
  const bool has_ffmpeg = std::system("command -v ffmpeg > /dev/null 2>&1") == 0;
  if (has_ffmpeg) {
    EXPECT_TRUE(made.ok()) << made.message();
    EXPECT_GT(std::filesystem::file_size(dir / "t.mp4"), 100u);
  } else {
    EXPECT_FALSE(made.ok());
    EXPECT_NE(made.message().find("ffmpeg is not installed"), std::string::npos) << made.message();
    EXPECT_FALSE(std::filesystem::exists(dir / "t.mp4"));
  }
  std::filesystem::remove_all(dir);
}

// The display transform: midtones (up to the knee) pass unchanged, highlights roll off below 1
// monotonically and keep their hue; a gold highlight 4x paper white stays gold, not white.
// The window's output (display_output, an sRGB framebuffer) is the screenshots' tone curve of
// the same frame: every pixel DisplayColour(radiance, exposure) of the linear render, within
// 1e-4 (the shader's float arithmetic: measured 1e-5; a display step is 4e-3), at two exposures;
// and the frame is not the linear one (the curve shoulders the highlights: > 1 % of pixels differ).
TEST(ViewerTest, DisplayOutputIsTheToneCurveOfTheRadiance) {
  REQUIRE_GL();
  const ViewCamera v = View(ViewDistance::kFramed, ViewAngle::kFace);
  for (double exposure : {1.0, 2.5}) {
    RenderOptions o = Options(Technique::kHybridAdaptive);
    o.exposure = exposure;
    const Grid<Vec3f> linear = Render(v, o);
    o.display_output = true;
    const Grid<Vec3f> shown = Render(v, o);
    double worst = 0;
    size_t differ = 0;
    for (size_t i = 0; i < linear.data.size(); ++i) {
      const Vec3f want = DisplayColour(linear.data[i], exposure);
      worst = std::max<double>(worst, (shown.data[i] - want).cwiseAbs().maxCoeff());
      if ((shown.data[i] - linear.data[i]).cwiseAbs().maxCoeff() > 0.01) ++differ;
    }
    std::printf("exposure %.1f: worst |display - DisplayColour(linear)| %.2e, %.1f %% changed\n",
                exposure, worst, 100.0 * differ / linear.data.size());
    EXPECT_LT(worst, 1e-4) << exposure;
    EXPECT_GT(differ, linear.data.size() / 100) << exposure;
  }
}

TEST(ViewerTest, DisplayColourKeepsMidtonesAndHueOfHighlights) {
  EXPECT_LT((DisplayColour(Vec3f(0.5f, 0.3f, 0.2f)) - Vec3f(0.5f, 0.3f, 0.2f)).norm(), 1e-6);
  EXPECT_LT((DisplayColour(Vec3f(0.25f, 0.15f, 0.1f), 2.0) - Vec3f(0.5f, 0.3f, 0.2f)).norm(), 1e-6);
  double last = 0;
  for (double v = 0.01; v < 100; v *= 1.1) {
    const Vec3f d = DisplayColour(Vec3f::Constant(float(v)));
    EXPECT_GE(d.x(), last - 1e-7) << v;
    EXPECT_LE(d.x(), 1.0f) << v;
    if (v < 2) {
      EXPECT_LT(d.x(), 0.96f) << v;  // headroom: 2x paper white is far from clipped
    }
    last = d.x();
  }
  EXPECT_GT(last, 0.99);
  EXPECT_NEAR(DisplayColour(Vec3f::Constant(1.0f)).x(), 0.875, 1e-6);  // paper white
  const Vec3f gold(1.0f, 0.78f, 0.34f);
  const Vec3f hi = DisplayColour(4.0f * gold);
  EXPECT_LT(hi.maxCoeff(), 1.0f + 1e-6f);
  EXPECT_NEAR(hi.z() / hi.x(), gold.z() / gold.x(), 1e-5) << "the highlight went white";
  const Vec3f soft = DisplayColour(1.2f * gold);
  EXPECT_NEAR(soft.y() / soft.x(), gold.y() / gold.x(), 1e-5);
  EXPECT_NEAR(soft.z() / soft.x(), gold.z() / gold.x(), 1e-5);
  for (float bad : {std::nanf(""), -1.0f, std::numeric_limits<float>::infinity()})
    EXPECT_TRUE(DisplayColour(Vec3f::Constant(bad)).allFinite());
}

// The headless gallery screenshot (what `digitize demo` ends with) shows the painting.
TEST(ViewerTest, GalleryScreenshotIsWritten) {
  REQUIRE_GL();
  const auto dir = TempDir();
  GalleryShotOptions shot;
  shot.width = 160;
  shot.height = 90;
  const auto png = dir / "gallery.png";
  const Status s = RenderGalleryScreenshots({{"synthetic", Get().pack}}, png, {}, shot);
  ASSERT_TRUE(s.ok()) << s.message();
  auto img = ReadImage(png);
  ASSERT_TRUE(img.ok()) << img.error().message;
  EXPECT_EQ(img->width, 160);
  // Not blank: the painting and the room give a spread of values.
  const auto [lo, hi] = std::minmax_element(img->pixels.begin(), img->pixels.end());
  EXPECT_GT(*hi - *lo, 0.3f);
  // Its own context came and went: the suite's context is current again and still works.
  ExpectPlausible(
      Render(View(ViewDistance::kFramed, ViewAngle::kFace), Options(Technique::kHybrid)),
      "after the gallery screenshot");
  std::filesystem::remove_all(dir);
}

// Packs are shared: a pack the viewer refuses is listed and the others hang without a gap; the
// GL-free set-up (what the fuzz target runs) never yields a non-finite gallery.
TEST(ViewerTest, RefusedPackIsListedAndTheOthersHang) {
  Pack absurd = Get().pack;
  absurd.field.pitch_mm = 1e308;  // what a forged header said before the reader refused it
  Pack flat_line = Get().pack;
  flat_line.field.height_mm = Grid<float>(1, 1);
  const GalleryScene scene = HangPaintings(
      {{"absurd.pack.exr", absurd}, {"good.pack.exr", Get().pack}, {"line.pack.exr", flat_line}});
  ASSERT_EQ(scene.hung, std::vector<size_t>{1});
  ASSERT_EQ(scene.failed.size(), 2u);
  EXPECT_EQ(scene.failed[0].rfind("absurd.pack.exr: ", 0), 0u) << scene.failed[0];
  EXPECT_NE(scene.failed[0].find("pitch_mm 1e+308"), std::string::npos) << scene.failed[0];
  EXPECT_EQ(scene.failed[1].rfind("line.pack.exr: ", 0), 0u) << scene.failed[1];
  ASSERT_EQ(scene.gallery.world_from_canvas.size(), 1u);
  EXPECT_TRUE(scene.gallery.start.Validate().ok());
  EXPECT_LT(scene.gallery.width_mm, 1e4);  // one 160 mm painting: the minimum room
}

// The forged pack file (pitch_mm = 1e308 with a recomputed checksum) is refused at load,
// naming the file and the attribute; the viewer then hangs the good pack beside it.
TEST(ViewerTest, ForgedPackFailsToLoadAndTheGoodOneRenders) {
  REQUIRE_GL();
  const auto dir = TempDir();
  ASSERT_TRUE(WritePack(dir / "good.pack.exr", Get().pack).ok());
  ASSERT_EQ(forge::ForgePack(dir / "good.pack.exr", dir / "forged.pack.exr",
                             {{"digitize:pitch_mm", "1e308"}}),
            "");
  auto forged = LoadPackForViewer(dir / "forged.pack.exr");
  ASSERT_FALSE(forged.ok());
  EXPECT_NE(forged.error().message.find("forged.pack.exr: digitize:pitch_mm 1e+308"),
            std::string::npos)
      << forged.error().message;
  auto good = LoadPackForViewer(dir / "good.pack.exr");
  ASSERT_TRUE(good.ok()) << good.error().message;
  // A refused pack in the list: the others render, it is reported, nothing aborts.
  Pack absurd = *good;
  absurd.max_height_mm = 1e30;
  GalleryShotOptions shot;
  shot.width = 96;
  shot.height = 64;
  std::vector<std::string> failed;
  const auto png = dir / "gallery.png";
  const Status s = RenderGalleryScreenshots({{"bad.pack.exr", absurd}, {"good.pack.exr", *good}},
                                            png, {}, shot, &failed);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(failed.size(), 1u);
  EXPECT_EQ(failed[0].rfind("bad.pack.exr: ", 0), 0u) << failed[0];
  EXPECT_TRUE(std::filesystem::exists(png));
  // Without a list to report into, the refusal is the error.
  const Status strict = RenderGalleryScreenshots({{"bad.pack.exr", absurd}}, png, {}, shot);
  ASSERT_FALSE(strict.ok());
  EXPECT_NE(strict.message().find("bad.pack.exr"), std::string::npos) << strict.message();
  std::filesystem::remove_all(dir);
}

// Image sizes this GL cannot render are an error naming the size, not an abort on an incomplete
// framebuffer.
TEST(ViewerTest, ImpossibleScreenshotSizesAreRefused) {
  REQUIRE_GL();
  Renderer& r = *Get().renderer;
  EXPECT_TRUE(r.CheckImageSize(kW, kH).ok());
  for (const auto& [w, h] :
       {std::pair{100000, 100000}, std::pair{20000, 100}, std::pair{100, 20000}}) {
    const Status s = r.CheckImageSize(w, h);
    ASSERT_FALSE(s.ok()) << w << "x" << h;
    EXPECT_NE(s.message().find("a " + std::to_string(w) + "x" + std::to_string(h) +
                               " image is larger than this OpenGL's maximum render target size"),
              std::string::npos)
        << s.message();
  }
  EXPECT_FALSE(r.CheckImageSize(0, 10).ok());
  // Within the GL's limits (16384 on llvmpipe) but beyond the memory bound.
  const Status big = r.CheckImageSize(16384, 16384);
  ASSERT_FALSE(big.ok());
  const auto dir = TempDir();
  GalleryShotOptions shot;
  shot.width = 100000;
  shot.height = 100000;
  const Status s =
      RenderGalleryScreenshots({{"synthetic", Get().pack}}, dir / "huge.png", {}, shot);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("100000x100000"), std::string::npos) << s.message();
  EXPECT_FALSE(std::filesystem::exists(dir / "huge.png"));
  std::filesystem::remove_all(dir);
}

// Issue 10: --screenshot writes what its extension says (read back: the format OpenImageIO finds),
// refuses an unknown extension and an output onto an input, before rendering anything.
TEST(ViewerTest, ScreenshotFormatFollowsTheExtension) {
  REQUIRE_GL();
  const auto dir = TempDir();
  GalleryShotOptions shot;
  shot.width = 64;
  shot.height = 36;
  for (const auto& [name, format] :
       std::vector<std::pair<std::string, std::string>>{{"shot.jpg", "jpeg"},
                                                        {"shot.png", "png"},
                                                        {"shot.tif", "tiff"},
                                                        {"shot.exr", "openexr"}}) {
    const Status s = RenderGalleryScreenshots({{"synthetic", Get().pack}}, dir / name, {}, shot);
    ASSERT_TRUE(s.ok()) << s.message();
    auto header = ReadImageHeader(dir / name);
    ASSERT_TRUE(header.ok()) << header.error().message;
    EXPECT_EQ(header->format, format) << name;
    EXPECT_EQ(header->width, 64);
  }
  const Status bmp =
      RenderGalleryScreenshots({{"synthetic", Get().pack}}, dir / "shot.bmp", {}, shot);
  EXPECT_FALSE(bmp.ok());
  EXPECT_NE(bmp.message().find("shot.bmp: unknown image extension"), std::string::npos)
      << bmp.message();
  EXPECT_FALSE(std::filesystem::exists(dir / "shot.bmp"));

  // The screenshot aimed at an input (here the "pack" file) is refused; the input is intact.
  const auto pack_file = dir / "painting.pack.png";
  std::ofstream(pack_file) << "a pack";
  shot.inputs = {pack_file};
  const Status onto = RenderGalleryScreenshots({{"synthetic", Get().pack}}, pack_file, {}, shot);
  EXPECT_FALSE(onto.ok());
  EXPECT_NE(onto.message().find("is the input"), std::string::npos) << onto.message();
  std::ifstream in(pack_file);
  std::string content;
  std::getline(in, content);
  EXPECT_EQ(content, "a pack");
  std::filesystem::remove_all(dir);
}

// --- GGX texels -------------------------------------------------------------------------------

// The shared painting with its right half GGX (ggx.h): the upper rows a varnish over the painted
// colour (F0 0.04, alpha 0.05 .. 0.3 from left to right), the lower rows gilding (F0 (1, 0.78,
// 0.34), rho_d 0, alpha 0.1 .. 0.3). Texels outside the canvas stay as they are. (Gold at alpha
// 0.05 on the impasto glints: at the far grazing view, where the canvas is 762 pixels, a glint
// of ~10 pixels a pixel off in the relief techniques sets the PSNR, 31-33 dB clipped; the mesh,
// on the reference's own surface, stays at 85 dB.)
Pack MakeGgxPack(const Pack& base) {
  Pack p = base;
  const int w = p.width(), h = p.height();
  for (int y = 0; y < h; ++y)
    for (int x = w / 2; x < w; ++x) {
      if (p.field.state(x, y) == TexelState::kOutside) continue;
      GgxParams g;
      const float ramp = float(x - w / 2) / float(w - 1 - w / 2);
      if (y < h / 2) {
        g.rho_d = p.maps.rho_d(x, y);
        g.f0 = Vec3f::Constant(0.04f);
        g.alpha = 0.05f + 0.25f * ramp;
      } else {
        g.f0 = Vec3f(1.0f, 0.78f, 0.34f);
        g.alpha = 0.1f + 0.2f * ramp;
      }
      p.maps.SetGgx(x, y, g);
    }
  return p;
}

struct GgxShared {
  Pack pack;
  std::unique_ptr<Renderer> renderer;
  std::string error;
};

GgxShared& GetGgx() {
  static GgxShared* s = [] {
    auto* s = new GgxShared();
    s->pack = MakeGgxPack(Get().pack);
    auto renderer = Renderer::Create();
    if (!renderer) {
      s->error = renderer.error().message;
      return s;
    }
    s->renderer = std::move(*renderer);
    if (auto index = s->renderer->AddPainting(s->pack, "synthetic-ggx"); !index)
      s->error = index.error().message;
    return s;
  }();
  return *s;
}

// Radiance clipped to [0, 1], what a display shows (ToneMap) and what the held-out evaluation
// compares (photo white = 1).
Grid<Vec3f> Clip01(Grid<Vec3f> img) {
  for (Vec3f& c : img.data) c = c.cwiseMax(0.0f).cwiseMin(1.0f);
  return img;
}

// The viewer's GGX is ggx.h's: a pack with GGX texels (varnish and gold, alpha down to 0.05)
// matches the Embree reference (RenderRelit, which evaluates each texel's model) at the paper's
// six views in every technique.
// - The mesh shades the reference's own surface points, so it tests the shading alone: >= 60 dB
//   on the raw radiance (measured 76-105 dB, 4 x 4 box-filtered).
// - Every technique, with the Lafortune case's bars (35 dB on 4 x 4 box-filtered images, bump
//   only 20 dB; adaptive at far-grazing 30 dB, below), on the radiance clipped to paper white.
//   Unclipped, a gold highlight at alpha 0.05 reaches ~10^3 x paper white at grazing views (D ~ 1 /
//   (pi alpha^2), 1 / (4 n.v)), so a highlight edge a sub-texel step of the relief march away costs
//   10^6 per pixel and the PSNR measures where that edge falls, not the shading (framed-grazing: 23
//   dB raw for identical-looking images).
// And the GGX half is not shaded as Lafortune: the same pack with the GGX texels read as
// Lafortune lobes (cx = cy = 0, k = alpha: a flat lobe) is far from the reference.
TEST(ViewerTest, GgxPackMatchesEmbreeReferenceAtPaperViews) {
  REQUIRE_GL();
  ASSERT_EQ(GetGgx().error, "");
  const Pack& pack = GetGgx().pack;
  const int64_t ggx =
      std::count(pack.maps.model.data.begin(), pack.maps.model.data.end(), ReflectanceModel::kGgx);
  ASSERT_GT(ggx, int64_t(pack.width()) * pack.height() / 3);
  const int ss = kCompareSupersampling;
  for (const PaperView& pv : AllPaperViews()) {
    const ViewCamera v = View(pv.distance, pv.angle);
    const RelitImage ref = RenderReference(*Get().tracer, pack, v, Get().light, false);
    const RelitImage ref_ss =
        RenderReference(*Get().tracer, pack, Supersampled(v, ss), Get().light, false);
    const Grid<Vec3f> ref_aa = Downsample(ref_ss.rgb, ss);
    const Grid<uint8_t> mask_aa = DownsampleMask(ref_ss.mask, ss);
    MaybeSave(ref.rgb, "ggx-" + pv.Name() + "-reference");
    const double canvas_share =
        double(std::count(ref.mask.data.begin(), ref.mask.data.end(), 1)) / ref.mask.size();
    for (Technique t : kAllTechniques) {
      RenderOptions point_options = Options(t);
      point_options.filter_reflectance = false;
      const Grid<Vec3f> img = GetGgx().renderer->Render(v, {Get().light}, point_options).rgb;
      ExpectPlausible(img, "ggx " + pv.Name() + " " + ToString(t), 0.4 * canvas_share);
      const double psnr_point = Psnr(img, ref);
      // The shading formula against the reference's, texel for texel: the prefiltered path
      // (which acts at far-grazing even at 4x the pixels) is PrefilteredReflectance's test.
      RenderOptions o = Options(t);
      o.filter_reflectance = false;
      const Grid<Vec3f> aa =
          Downsample(GetGgx().renderer->Render(Supersampled(v, ss), {Get().light}, o).rgb, ss);
      const ImageComparison raw = CompareImages(aa, ref_aa, mask_aa, kPsnrPeak);
      const ImageComparison c = CompareImages(Clip01(aa), Clip01(ref_aa), mask_aa, kPsnrPeak);
      EXPECT_GT(c.pixels, size_t(500)) << "too few canvas pixels compared";
      MaybeSave(img, "ggx-" + pv.Name() + "-" + ToString(t));
      std::printf(
          "ggx %-15s %-13s point %6.2f dB, 4x4 box-filtered %6.2f dB, clipped to white %6.2f dB\n",
          pv.Name().c_str(), ToString(t), psnr_point, raw.psnr_db, c.psnr_db);
      if (t == Technique::kMesh) {
        EXPECT_GE(raw.psnr_db, 60.0) << pv.Name() << " mesh (raw radiance)";
      }
      // The adaptive rule draws almost no box at the far views (sub-pixel parallax), so there it
      // is nearly the bump plane, whose parallax shifts the glossy highlights by a pixel: 34.1
      // dB at far-grazing (bump alone 24.5), where Lafortune's broader lobes hide it (48 dB).
      const bool far_adaptive = t == Technique::kHybridAdaptive &&
                                pv.distance == ViewDistance::kFar &&
                                pv.angle == ViewAngle::kGrazing;
      const double bar = t == Technique::kBump ? 20.0 : far_adaptive ? 30.0 : 35.0;
      EXPECT_GE(c.psnr_db, bar) << pv.Name() << " " << ToString(t);
    }
  }
  // The model channel matters: the GGX texels shaded as Lafortune are another image.
  Pack as_lafortune = pack;
  std::fill(as_lafortune.maps.model.data.begin(), as_lafortune.maps.model.data.end(),
            ReflectanceModel::kLafortune);
  auto renderer = Renderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  ASSERT_TRUE((*renderer)->AddPainting(as_lafortune, "as-lafortune").ok());
  const ViewCamera v = View(ViewDistance::kFramed, ViewAngle::kFace);
  const RelitImage ref = RenderReference(*Get().tracer, pack, v, Get().light, false);
  const RenderOptions o = Options(Technique::kHybridAdaptive);
  const double right = Psnr(GetGgx().renderer->Render(v, {Get().light}, o).rgb, ref);
  const double wrong = Psnr((*renderer)->Render(v, {Get().light}, o).rgb, ref);
  std::printf("ggx framed-face: GGX shading %.2f dB, GGX texels as Lafortune %.2f dB\n", right,
              wrong);
  EXPECT_GT(right, wrong + 10.0);
}

// Prefiltered reflectance (renderer.h, shading_pyramid.h): where a pixel covers several texels
// one texel per pixel aliases -- the pixel shows the texel its ray happens to meet, not the
// surface it sees. What a pixel should show is the reference antialiased: 8 x 8 rays per pixel,
// averaged (4 x 4, the other tests' filter, is itself a 16-sample estimate whose error at paint
// edges is what the point-sampled renderer is measured against). Native resolution, hybrid +
// adaptive, radiance clipped to white (GGX glints, as above). Bars, from the measured values in
// brackets (Lafortune / GGX):
// - far-face, a pixel ~4.4 texels across: filtered >= point + 8 dB (25.7 -> 39.1 / 25.1 -> 37.2);
// - far-grazing, ~16 x 4.5 texels: >= point + 3 dB (25.1 -> 32.0 / 21.0 -> 26.3);
// - framed-grazing, ~3.5 x 1.1 texels: Lafortune >= point + 2 dB (30.1 -> 34.5); GGX within 2 dB
//   (28.0 -> 26.7): the samples lie on the plane through the pixel's surface point, and on the
//   gilded impasto a few of them meet glints (~30x white) that the pixel's rays, bent by the
//   relief, do not (renderer.h);
// - framed-face (~1.1 texels) no worse; close-face (a pixel under a texel) the same image.
// And a sub-pixel pan (8 steps of a quarter pixel) flickers less: the RMS frame-to-frame change
// inside the canvas below 0.6 x the point-sampled one's (measured 0.034 vs 0.071 far-face, 0.032
// vs 0.065 far-grazing; the rest is the paint's edges moving a quarter pixel).
TEST(ViewerTest, PrefilteredReflectanceMatchesTheAntialiasedReference) {
  REQUIRE_GL();
  ASSERT_EQ(GetGgx().error, "");
  const int ss = kCompareSupersampling, truth_ss = 8;
  for (int model = 0; model < 2; ++model) {
    const Pack& pack = model == 0 ? Get().pack : GetGgx().pack;
    Renderer& renderer = model == 0 ? *Get().renderer : *GetGgx().renderer;
    for (const PaperView& pv : AllPaperViews()) {
      const ViewCamera v = View(pv.distance, pv.angle);
      const RelitImage ref_ss =
          RenderReference(*Get().tracer, pack, Supersampled(v, truth_ss), Get().light, false);
      const Grid<Vec3f> ref_aa = Clip01(Downsample(ref_ss.rgb, truth_ss));
      const Grid<uint8_t> mask_aa = DownsampleMask(ref_ss.mask, truth_ss);
      RenderOptions o = Options(Technique::kHybridAdaptive);
      const Grid<Vec3f> filtered = Clip01(renderer.Render(v, {Get().light}, o).rgb);
      const Grid<Vec3f> supersampled =
          Clip01(Downsample(renderer.Render(Supersampled(v, ss), {Get().light}, o).rgb, ss));
      o.filter_reflectance = false;
      const Grid<Vec3f> point = Clip01(renderer.Render(v, {Get().light}, o).rgb);
      const double db_point = CompareImages(point, ref_aa, mask_aa, kPsnrPeak).psnr_db;
      const double db_filtered = CompareImages(filtered, ref_aa, mask_aa, kPsnrPeak).psnr_db;
      const double db_ss = CompareImages(supersampled, ref_aa, mask_aa, kPsnrPeak).psnr_db;
      const bool ggx = model == 1;
      const std::string what = std::string(ggx ? "ggx " : "lafortune ") + pv.Name();
      std::printf("%-24s point %6.2f dB, filtered %6.2f dB (renderer 4x4 supersampled %6.2f dB)\n",
                  what.c_str(), db_point, db_filtered, db_ss);
      MaybeSave(filtered, "filtered-" + what);
      MaybeSave(point, "point-" + what);
      MaybeSave(ref_aa, "antialiased-reference-" + what);
      const bool grazing = pv.angle == ViewAngle::kGrazing;
      switch (pv.distance) {
        case ViewDistance::kClose:
          if (grazing) {
            EXPECT_GE(db_filtered, db_point) << what;
          } else {
            EXPECT_LT(MeanAbsDiff(filtered, point), 1e-7) << what;
          }
          break;
        case ViewDistance::kFramed:
          if (grazing) {
            EXPECT_GE(db_filtered, ggx ? db_point - 2.0 : db_point + 2.0) << what;
          } else {
            EXPECT_GE(db_filtered, db_point) << what;
          }
          break;
        case ViewDistance::kFar:
          EXPECT_GE(db_filtered, db_point + (grazing ? 3.0 : 8.0)) << what;
          break;
      }
    }
  }
  // Flicker along a sub-pixel pan at the far views.
  for (ViewAngle angle : {ViewAngle::kFace, ViewAngle::kGrazing}) {
    const ViewCamera v = View(ViewDistance::kFar, angle);
    const Vec3d forward = (v.target_mm - v.eye_mm).normalized();
    const Vec3d right = forward.cross(v.up).normalized();
    const double px_mm =
        2 * std::tan(v.fov_y_deg * kPi / 360) / v.height * (v.target_mm - v.eye_mm).norm();
    // Compared over the canvas away from its outline (whose 0.25 px motion is the pan's, not
    // flicker): the reference's interior pixels eroded by 2 more.
    const Grid<uint8_t> inside = InteriorMask(InteriorMask(
        InteriorMask(RenderReference(*Get().tracer, Get().pack, v, Get().light, false).mask)));
    auto rms_change = [&](const Grid<Vec3f>& a, const Grid<Vec3f>& b) {
      double sum = 0;
      size_t n = 0;
      for (size_t i = 0; i < a.data.size(); ++i)
        if (inside.data[i]) {
          sum += (a.data[i] - b.data[i]).squaredNorm() / 3;
          ++n;
        }
      return std::sqrt(sum / std::max<size_t>(n, 1));
    };
    double change[2] = {0, 0};
    for (int filter = 0; filter < 2; ++filter) {
      RenderOptions o = Options(Technique::kHybridAdaptive);
      o.filter_reflectance = filter == 1;
      Grid<Vec3f> previous;
      for (int step = 0; step < 8; ++step) {
        ViewCamera c = v;
        c.eye_mm += right * (0.25 * px_mm * step);
        c.target_mm += right * (0.25 * px_mm * step);
        Grid<Vec3f> img = Clip01(Get().renderer->Render(c, {Get().light}, o).rgb);
        if (step > 0) change[filter] += rms_change(img, previous) / 7;
        previous = std::move(img);
      }
    }
    std::printf("far-%s pan: RMS frame-to-frame change point %.5f, filtered %.5f\n",
                angle == ViewAngle::kFace ? "face" : "grazing", change[0], change[1]);
    EXPECT_LT(change[1], 0.6 * change[0]);
  }
}

// --- view modes -------------------------------------------------------------------------------

// A flat-topped test canvas 96 x 96 mm (1 mm texels) with one Gaussian bump (sigma 12 mm, 6 mm
// high) in the middle, grey Lambertian (albedo 0.8), no boxes: the mesh shows the exact surface.
Pack MakeBumpPack() {
  constexpr int n = 96;
  Pack p;
  p.field.pitch_mm = 1.0;
  p.field.height_mm = Grid<float>(n, n, 0.0f);
  p.field.state = Grid<TexelState>(n, n, TexelState::kMeasured);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const double dx = x + 0.5 - n / 2.0, dy = y + 0.5 - n / 2.0;
      p.field.height_mm(x, y) = float(6.0 * std::exp(-(dx * dx + dy * dy) / (2 * 12.0 * 12.0)));
    }
  p.normals = ComputeNormals(p.field);
  p.maps = ReflectanceMaps::Zeros(n, n);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      p.maps.rho_d(x, y) = Vec3f::Constant(float(0.8 / kPi));
      p.maps.status(x, y) = TexelFitStatus::kDiffuseOnly;
    }
  p.max_height_mm = 6.0;
  p.delta0_mm = 0.0;
  p.cell_px = 16;
  return p;
}

ViewCamera FaceView(const Pack& p, int w, int h) {
  ViewCamera v;
  v.eye_mm = Vec3d(p.width_mm() / 2, p.height_mm() / 2, 400);
  v.target_mm = Vec3d(p.width_mm() / 2, p.height_mm() / 2, 0);
  v.up = Vec3d::UnitY();
  v.fov_y_deg = 16;
  v.width = w;
  v.height = h;
  return v;
}

// Mean luminance of the pixels within r px of where canvas point (x, y, z) projects.
double MeanNear(const Grid<Vec3f>& img, const ViewCamera& view, const Vec3d& point, int r) {
  const Eigen::Vector2d px = ToCamera(view).Project(point);
  double sum = 0;
  int count = 0;
  for (int v = int(std::lround(px.y())) - r; v <= int(std::lround(px.y())) + r; ++v)
    for (int u = int(std::lround(px.x())) - r; u <= int(std::lround(px.x())) + r; ++u) {
      if (u < 0 || v < 0 || u >= img.width || v >= img.height) continue;
      sum += img(u, v).dot(Vec3f(0.2126f, 0.7152f, 0.0722f));
      ++count;
    }
  return count > 0 ? sum / count : 0.0;
}

double MeanLuminance(const Grid<Vec3f>& img) {
  double sum = 0;
  for (const Vec3f& c : img.data) sum += c.dot(Vec3f(0.2126f, 0.7152f, 0.0722f));
  return sum / img.data.size();
}

struct BumpScene {
  Pack pack = MakeBumpPack();
  std::unique_ptr<Renderer> renderer;
  ViewCamera view = FaceView(pack, 200, 200);
  // Surface points on the bump's flanks, where its slope is steepest (1 sigma from the top):
  // facing +x and facing -x.
  Vec3d east, west;
  Grid<Vec3f> Render(ViewMode mode, const std::function<void(RenderOptions&)>& set = {}) {
    RenderOptions o = Options(Technique::kMesh);
    o.mode = mode;
    if (set) set(o);
    return renderer->Render(view, {StandardLight(pack)}, o).rgb;
  }
};

BumpScene& GetBump() {
  static BumpScene* s = [] {
    auto* s = new BumpScene();
    const double c = s->pack.width_mm() / 2, h = 6.0 * std::exp(-0.5);
    s->east = Vec3d(c + 12, c, h);
    s->west = Vec3d(c - 12, c, h);
    auto renderer = Renderer::Create();
    if (renderer && (*renderer)->AddPainting(s->pack, "bump").ok())
      s->renderer = std::move(*renderer);
    return s;
  }();
  return *s;
}

TEST(ViewerTest, ViewModesParseAndValidate) {
  for (ViewMode m : kAllViewModes) EXPECT_EQ(*ParseViewMode(ToString(m)), m);
  EXPECT_FALSE(ParseViewMode("rti").ok());
  RenderOptions o;
  o.light_direction = Vec3d(1, 0, 0);  // in the canvas plane
  EXPECT_FALSE(o.Validate().ok());
  o = RenderOptions{};
  o.raking_elevation_deg = 0;
  EXPECT_FALSE(o.Validate().ok());
  o = RenderOptions{};
  o.specular_sharpen = 0.5;
  EXPECT_FALSE(o.Validate().ok());
  // The cursor's hemisphere: the centre is overhead, the right edge a light from +x near the
  // horizon, a corner (outside the disc) on the rim at the minimum elevation; always unit, z > 0.
  EXPECT_TRUE(HemisphereLightDirection(0, 0).isApprox(Vec3d::UnitZ()));
  const Vec3d right = HemisphereLightDirection(0.6, 0);
  EXPECT_NEAR(right.x(), 0.6, 1e-12);
  EXPECT_NEAR(right.z(), 0.8, 1e-12);
  const Vec3d corner = HemisphereLightDirection(-1, 1);
  EXPECT_NEAR(std::asin(corner.z()) * 180 / kPi, kMinLightElevationDeg, 1e-9);
  EXPECT_LT(corner.x(), 0);
  EXPECT_GT(corner.y(), 0);
  for (const auto& [x, y] : {std::pair{0.3, -0.9}, std::pair{5.0, 5.0}, std::pair{-1.0, 0.0}}) {
    const Vec3d d = HemisphereLightDirection(x, y);
    EXPECT_NEAR(d.norm(), 1.0, 1e-12);
    EXPECT_GT(d.z(), 0.0);
  }
  const Vec3d raking = LightDirectionFromAngles(180, 10);
  EXPECT_NEAR(raking.x(), -std::cos(10 * kPi / 180), 1e-12);
  EXPECT_NEAR(raking.z(), std::sin(10 * kPi / 180), 1e-12);
}

// Normals mode: each pixel is the encoded normal n * 0.5 + 0.5. A flat canvas whose normals are
// constant over 12 x 12-texel blocks (a different tilt per block, up to 60 deg): pixels over a
// block's interior (2 texels from its edges, where the bilinear normal is the block's) equal it
// to float rounding (1e-4), in every technique.
TEST(ViewerTest, NormalsModeShowsTheEncodedNormal) {
  REQUIRE_GL();
  Pack p = MakeBumpPack();
  std::fill(p.field.height_mm.data.begin(), p.field.height_mm.data.end(), 0.0f);
  p.max_height_mm = 0.0;
  auto block_normal = [](int bx, int by) {
    const double tilt = (5.0 + 7.0 * ((bx + 3 * by) % 8)) * kPi / 180;
    const double azimuth = (bx * 45.0 + by * 100.0) * kPi / 180;
    return Vec3f(float(std::sin(tilt) * std::cos(azimuth)),
                 float(std::sin(tilt) * std::sin(azimuth)), float(std::cos(tilt)));
  };
  for (int y = 0; y < p.height(); ++y)
    for (int x = 0; x < p.width(); ++x) p.normals(x, y) = block_normal(x / 12, y / 12);
  auto renderer = Renderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  ASSERT_TRUE((*renderer)->AddPainting(p, "blocks").ok());
  const ViewCamera view = FaceView(p, 240, 240);
  const Camera cam = ToCamera(view);
  for (Technique t : {Technique::kMesh, Technique::kBump, Technique::kHybridAdaptive}) {
    RenderOptions o = Options(t);
    o.mode = ViewMode::kNormals;
    const Grid<Vec3f> img = (*renderer)->Render(view, {StandardLight(p)}, o).rgb;
    MaybeSave(img, std::string("mode-normals-blocks-") + ToString(t));
    size_t checked = 0;
    float worst = 0;
    for (int v = 0; v < img.height; ++v)
      for (int u = 0; u < img.width; ++u) {
        // Where the pixel's ray meets the plane z = 0 (canvas frame = world here).
        Vec3d o_ray = view.eye_mm;
        const Vec3d d = (cam.camera_from_scan.rotation.transpose() *
                         Vec3d((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0))
                            .normalized();
        const Vec3d hit = o_ray + d * (-o_ray.z() / d.z());
        const double tx = hit.x() / p.field.pitch_mm, ty = p.height() - hit.y() / p.field.pitch_mm;
        if (tx < 0 || ty < 0 || tx >= p.width() || ty >= p.height()) continue;
        const double fx = std::fmod(tx, 12.0), fy = std::fmod(ty, 12.0);
        if (fx < 2 || fx > 10 || fy < 2 || fy > 10) continue;
        const Vec3f want = block_normal(int(tx) / 12, int(ty) / 12) * 0.5f + Vec3f::Constant(0.5f);
        worst = std::max(worst, (img(u, v) - want).cwiseAbs().maxCoeff());
        ++checked;
      }
    std::printf("normals mode %-9s: %zu pixels, worst |rgb - (n/2 + 1/2)| %.2e\n", ToString(t),
                checked, worst);
    EXPECT_GT(checked, 15000u);
    EXPECT_LT(worst, 1e-4f) << ToString(t);
  }
}

// Light mode: a directional light from +x brightens the bump's +x-facing flank over its -x-facing
// one, and from -x the other way round; and it is the reference's directional light (RenderRelit
// with the same direction and irradiance: 35 dB on the synthetic painting, 4 x 4 box-filtered).
TEST(ViewerTest, LightModeLightsTheSlopesFacingIt) {
  REQUIRE_GL();
  BumpScene& b = GetBump();
  ASSERT_TRUE(b.renderer);
  const Vec3d from_east = Vec3d(1, 0, 1).normalized(), from_west = Vec3d(-1, 0, 1).normalized();
  const Grid<Vec3f> east_lit =
      b.Render(ViewMode::kLight, [&](RenderOptions& o) { o.light_direction = from_east; });
  const Grid<Vec3f> west_lit =
      b.Render(ViewMode::kLight, [&](RenderOptions& o) { o.light_direction = from_west; });
  MaybeSave(east_lit, "mode-light-bump-from-east");
  ExpectPlausible(east_lit, "light from +x", 0.5);
  // Lambertian, E = pi: radiance = 0.8 cos(n, l). The flanks tilt by atan(6 e^-1/2 / 12) = 16.9
  // deg: 0.8 cos(45 -/+ 16.9 deg) = 0.71 and 0.45.
  const double e1 = MeanNear(east_lit, b.view, b.east, 2),
               w1 = MeanNear(east_lit, b.view, b.west, 2);
  const double e2 = MeanNear(west_lit, b.view, b.east, 2),
               w2 = MeanNear(west_lit, b.view, b.west, 2);
  std::printf("light mode: from +x: +x flank %.3f, -x flank %.3f; from -x: %.3f, %.3f\n", e1, w1,
              e2, w2);
  EXPECT_GT(e1, w1 + 0.15);
  EXPECT_GT(w2, e2 + 0.15);
  EXPECT_NEAR(e1, 0.8 * std::cos((45 - 16.9) * kPi / 180), 0.03);
  EXPECT_NEAR(w1, 0.8 * std::cos((45 + 16.9) * kPi / 180), 0.03);

  const int ss = kCompareSupersampling;
  const ViewCamera v = View(ViewDistance::kFramed, ViewAngle::kFace);
  RenderOptions o = Options(Technique::kHybridAdaptive);
  o.mode = ViewMode::kLight;
  o.light_direction = Vec3d(0.6, -0.3, 0.7).normalized();
  Light light;
  light.type = LightType::kDirectional;
  light.direction = o.light_direction;
  light.irradiance = Vec3f::Constant(float(o.light_irradiance));
  const RelitImage ref_ss =
      RenderReference(*Get().tracer, Get().pack, Supersampled(v, ss), light, false);
  const Grid<Vec3f> aa = Downsample(Get().renderer->Render(Supersampled(v, ss), {}, o).rgb, ss);
  const double psnr =
      CompareImages(aa, Downsample(ref_ss.rgb, ss), DownsampleMask(ref_ss.mask, ss), kPsnrPeak)
          .psnr_db;
  MaybeSave(Get().renderer->Render(v, {}, o).rgb, "mode-light-synthetic");
  std::printf("light mode vs reference with the directional light: %.2f dB (4x4)\n", psnr);
  EXPECT_GE(psnr, 35.0);
}

// Raking mode: at 10 deg elevation the canvas is darker on the whole than at 60 deg (flat part:
// 0.8 sin 10 = 0.14 against 0.8 sin 60 = 0.69), and the bump's flanks (tilted 16.9 deg) differ
// more: at 60 deg 0.8 sin(60 +/- 16.9 deg) = 0.78 / 0.55, Michelson contrast 0.18; at 10 deg the
// flank facing the light gets 0.8 sin 26.9 = 0.36 and the one facing away none (contrast 1).
TEST(ViewerTest, RakingModeDarkensAndRaisesReliefContrast) {
  REQUIRE_GL();
  BumpScene& b = GetBump();
  ASSERT_TRUE(b.renderer);
  auto at = [&](double elevation) {
    return b.Render(ViewMode::kRaking, [&](RenderOptions& o) {
      o.raking_azimuth_deg = 0;  // from +x
      o.raking_elevation_deg = elevation;
    });
  };
  const Grid<Vec3f> low = at(10), high = at(60);
  MaybeSave(low, "mode-raking-bump-10deg");
  MaybeSave(high, "mode-raking-bump-60deg");
  auto contrast = [&](const Grid<Vec3f>& img) {
    const double lit = MeanNear(img, b.view, b.east, 2), dark = MeanNear(img, b.view, b.west, 2);
    return (lit - dark) / (lit + dark);
  };
  const double mean_low = MeanLuminance(low), mean_high = MeanLuminance(high);
  const double c_low = contrast(low), c_high = contrast(high);
  std::printf("raking: mean %.3f at 10 deg, %.3f at 60 deg; flank contrast %.3f vs %.3f\n",
              mean_low, mean_high, c_low, c_high);
  EXPECT_LT(mean_low, 0.5 * mean_high);
  EXPECT_GT(c_low, c_high + 0.3);
  EXPECT_GT(c_low, 0.9);  // the flank facing away tilts past 10 deg: unlit
  ExpectPlausible(low, "raking 10 deg", 0.5);
}

// Specular enhancement: the diffuse term turns grey and dims by specular_diffuse (a Lambertian
// canvas: exactly 0.3 x the light mode's image under the same light), and the specular term is
// brightened and sharpened: on the GGX pack, lit from near the view direction, the brightest
// highlight rises above twice the light mode's (F0 x 2 and alpha / 2: the GGX peak x 8).
TEST(ViewerTest, SpecularModeDimsTheDiffuseAndRaisesHighlights) {
  REQUIRE_GL();
  BumpScene& b = GetBump();
  ASSERT_TRUE(b.renderer);
  const Grid<Vec3f> lit = b.Render(ViewMode::kLight);
  const Grid<Vec3f> spec = b.Render(ViewMode::kSpecular);
  double worst = 0;
  size_t compared = 0;
  for (size_t i = 0; i < lit.data.size(); ++i) {
    if (lit.data[i].maxCoeff() < 0.05f) continue;
    worst = std::max(worst, double((spec.data[i] - 0.3f * lit.data[i]).cwiseAbs().maxCoeff()));
    ++compared;
  }
  EXPECT_GT(compared, lit.data.size() / 2);
  EXPECT_LT(worst, 1e-4);

  ASSERT_EQ(GetGgx().error, "");
  const ViewCamera v = View(ViewDistance::kFramed, ViewAngle::kFace);
  RenderOptions o = Options(Technique::kHybridAdaptive);
  o.light_direction = (v.eye_mm - v.target_mm).normalized() + Vec3d(0.15, 0.1, 0);
  o.light_direction.normalize();
  o.mode = ViewMode::kLight;
  const Grid<Vec3f> plain = GetGgx().renderer->Render(v, {}, o).rgb;
  o.mode = ViewMode::kSpecular;
  const Grid<Vec3f> enhanced = GetGgx().renderer->Render(v, {}, o).rgb;
  MaybeSave(plain, "mode-light-ggx");
  MaybeSave(enhanced, "mode-specular-ggx");
  auto brightest = [](const Grid<Vec3f>& img) {
    float m = 0;
    for (const Vec3f& c : img.data) m = std::max(m, c.maxCoeff());
    return m;
  };
  std::printf("specular mode: brightest %.2f (light mode %.2f), mean %.3f (%.3f)\n",
              brightest(enhanced), brightest(plain), MeanLuminance(enhanced), MeanLuminance(plain));
  EXPECT_GT(brightest(enhanced), 2.0f * brightest(plain));
}

// Every mode in every technique on the synthetic painting: a plausible image (and screenshots
// to look at with DIGITIZE_VIEWER_SHOTS).
TEST(ViewerTest, EveryViewModeRendersAPlausibleImage) {
  REQUIRE_GL();
  const ViewCamera v = View(ViewDistance::kFramed, ViewAngle::kFace);
  for (ViewMode m : kAllViewModes) {
    for (Technique t : kAllTechniques) {
      RenderOptions o = Options(t);
      o.mode = m;
      const Grid<Vec3f> img = Get().renderer->Render(v, {Get().light}, o).rgb;
      ExpectPlausible(img, std::string(ToString(m)) + " " + ToString(t),
                      m == ViewMode::kRaking ? 0.1 : 0.3);
      if (t == Technique::kHybridAdaptive) MaybeSave(img, std::string("mode-") + ToString(m));
    }
  }
}

}  // namespace
}  // namespace digitize::viewer
