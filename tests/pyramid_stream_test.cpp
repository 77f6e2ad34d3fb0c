// The streamed pyramid (pyramid_stream.h, issue 14 part 4): which tiles a view needs (the
// screen-space error; every visible canvas point in exactly one of them), the frames' bounds
// (GPU budget, uploads per frame), loads that converge, and renders of a tiled pack streamed
// against the same pack uploaded whole and against the Embree reference.
//
// The painting: the synthetic one of viewer_test (160 x 120 mm at 0.3125 mm a texel, 512 x 384
// texels), written as a version 3 pack in 64-texel tiles: 8 x 6 tiles at level 0, the root (one
// tile) at level 3.
#include "digitize_viewer/pyramid_stream.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>

#include "digitize/height_field_tracer.h"
#include "digitize/image_io.h"
#include "digitize/pack_tiled.h"
#include "digitize/relight.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/truth_pack.h"
#include "digitize_viewer/gallery.h"
#include "digitize_viewer/gl_context.h"
#include "digitize_viewer/renderer.h"
#include "digitize_viewer/scene_setup.h"
#include "digitize_viewer/view.h"
#include "test_support.h"

namespace digitize::viewer {
namespace {

namespace fs = std::filesystem;
constexpr int kW = 256, kH = 192, kTile = 64;

struct Shared {
  fs::path dir, file;
  Pack pack;
};

Shared& Get() {
  static Shared* s = [] {
    auto* s = new Shared();
    synth::PaintingOptions po;
    po.width_mm = 160;
    po.height_mm = 120;
    po.resolution_px = 512;
    po.seed = 3;
    po.impasto_count = 6;
    synth::TruthPackOptions tpo;
    tpo.relief.delta0_fraction = 0.30;
    s->pack = synth::MakeTruthPack(synth::MakePainting(po), tpo);
    s->dir = test::FreshScratchDir("digitize_pyramid_stream");
    static const test::RemoveOnExit remove(s->dir);  // at the process's exit
    s->file = s->dir / "painting.pack.exr";
    PackWriteOptions o;
    o.tile_size = kTile;
    const Status written = WritePack(s->file, s->pack, o);
    EXPECT_TRUE(written.ok()) << written.message();
    const Status single = WritePack(s->dir / "single.pack.exr", s->pack);
    EXPECT_TRUE(single.ok()) << single.message();
    return s;
  }();
  return *s;
}

std::unique_ptr<PyramidStream> Open(const StreamOptions& options = {}) {
  auto stream = PyramidStream::Open(Get().file, options);
  EXPECT_TRUE(stream.ok()) << stream.error().message;
  return stream.ok() ? std::move(stream).value() : nullptr;
}

ViewCamera View(ViewDistance d, ViewAngle a) {
  const Pack& p = Get().pack;
  return MakePaperView(p.width_mm(), p.height_mm(), {d, a}, kW, kH);
}

// A tile's level-0 texel rectangle [x0, x1) x [y0, y1).
std::array<int, 4> Level0Rect(const PyramidStream& s, const TileKey& k) {
  const int scale = 1 << k.level, t = kTile;
  const auto [w, h] = s.LevelSize(k.level);
  return {k.tx * t * scale, k.ty * t * scale, std::min(k.tx * t + t, w) * scale,
          std::min(k.ty * t + t, h) * scale};
}

// The canvas texels some pixel's ray meets (the Embree reference's hit points): what a view sees.
std::vector<std::array<int, 2>> VisibleTexels(const ViewCamera& view) {
  const Pack& p = Get().pack;
  static std::unique_ptr<HeightFieldTracer> tracer = [&] {
    auto t = HeightFieldTracer::Build(p.field);
    EXPECT_TRUE(t.ok());
    return std::make_unique<HeightFieldTracer>(std::move(*t));
  }();
  const Camera camera = ToCamera(view);
  const RigidTransform scan_from_camera = camera.camera_from_scan.Inverse();
  std::vector<Vec3f> origins, dirs;
  for (int y = 0; y < view.height; y += 3)
    for (int x = 0; x < view.width; x += 3) {
      origins.push_back(view.eye_mm.cast<float>());
      dirs.push_back(
          scan_from_camera
              .ApplyToDirection(
                  Vec3d((x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy, 1).normalized())
              .cast<float>());
    }
  std::vector<SurfaceHit> hits(origins.size());
  tracer->Intersect(origins, dirs, hits);
  std::vector<std::array<int, 2>> seen;
  for (const SurfaceHit& h : hits) {
    if (!h.hit) continue;
    const int tx = int(std::lround(h.texel_x)), ty = int(std::lround(h.texel_y));
    if (tx >= 0 && ty >= 0 && tx < p.width() && ty < p.height()) seen.push_back({tx, ty});
  }
  return seen;
}

// Every seen texel lies in exactly one of `tiles`, and no two tiles overlap.
void ExpectCoversOnce(const PyramidStream& s, const std::vector<TileKey>& tiles,
                      const std::vector<std::array<int, 2>>& seen, const std::string& what) {
  ASSERT_FALSE(seen.empty()) << what;
  size_t wrong = 0;
  for (const auto& [x, y] : seen) {
    int n = 0;
    for (const TileKey& k : tiles) {
      const auto r = Level0Rect(s, k);
      n += x >= r[0] && x < r[2] && y >= r[1] && y < r[3];
    }
    wrong += n != 1;
  }
  EXPECT_EQ(wrong, 0u) << what << ": of " << seen.size() << " texels seen";
  for (size_t i = 0; i < tiles.size(); ++i)
    for (size_t j = i + 1; j < tiles.size(); ++j) {
      const auto a = Level0Rect(s, tiles[i]), b = Level0Rect(s, tiles[j]);
      EXPECT_FALSE(a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3])
          << what << ": tiles overlap";
    }
}

TEST(PyramidStream, OpensATiledPackAndRefusesOthers) {
  auto s = Open();
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->summary().tile_size, kTile);
  EXPECT_EQ(s->root_level(), 3);  // 512 x 384 -> 64 x 48 at level 3: one tile
  EXPECT_EQ(s->LevelTiles(0), (std::array<int, 2>{8, 6}));
  EXPECT_EQ(s->LevelTiles(2), (std::array<int, 2>{2, 2}));
  auto refused = PyramidStream::Open(Get().dir / "single.pack.exr");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("single.pack.exr"), std::string::npos)
      << refused.error().message;
  StreamOptions bad;
  bad.max_texel_px = 0;
  EXPECT_FALSE(PyramidStream::Open(Get().file, bad).ok());
}

// The level each needed tile is at is the coarsest whose texel covers at most max_texel_px at
// the tile's nearest point (its parent's would cover more), and the tiles cover what is seen once.
TEST(PyramidStream, NeedsTheLevelTheScreenSpaceErrorAsksForAndCoversTheViewOnce) {
  StreamOptions o;
  o.max_texel_px = 1.0;  // a texel a pixel: the paper views then need every level but the top
  auto s = Open(o);
  ASSERT_NE(s, nullptr);
  const double pitch = Get().pack.field.pitch_mm;
  std::map<std::string, std::vector<TileKey>> needed;
  for (ViewDistance d : {ViewDistance::kClose, ViewDistance::kFramed, ViewDistance::kFar})
    for (ViewAngle a : {ViewAngle::kFace, ViewAngle::kGrazing}) {
      const ViewCamera view = View(d, a);
      const std::string name = PaperView{d, a}.Name();
      const std::vector<TileKey> tiles = s->Needed(view, {});
      needed[name] = tiles;
      ExpectCoversOnce(*s, tiles, VisibleTexels(view), name);
      const double f = ToCamera(view).fy;
      // The stream's boxes reach from below the lowest texel to H; a box inside them (the true
      // heights) is no nearer, one around them (+-20 mm) no farther: one-sided bounds each.
      const auto texel_px = [&](const TileKey& k, double z0, double z1) {
        const auto r = Level0Rect(*s, k);
        const Vec3d lo(r[0] * pitch, Get().pack.height_mm() - r[3] * pitch, z0);
        const Vec3d hi(r[2] * pitch, Get().pack.height_mm() - r[1] * pitch, z1);
        const double dist = (view.eye_mm.cwiseMax(lo).cwiseMin(hi) - view.eye_mm).norm();
        return pitch * std::ldexp(1.0, k.level) * f / dist;
      };
      const float z0 = Get().pack.field.height_mm.data[0];
      float lo = z0, hi = z0;
      for (float z : Get().pack.field.height_mm.data) lo = std::min(lo, z), hi = std::max(hi, z);
      for (const TileKey& k : tiles) {
        if (k.level > 0) {
          EXPECT_LE(texel_px(k, lo, hi), 1.0) << name;
        }
        if (k.level < int(s->summary().levels.size()) - 1) {
          EXPECT_GT(texel_px({k.level + 1, k.tx / 2, k.ty / 2}, -20, 20), 1.0) << name;
        }
      }
    }
  // Close up: level 0, and only the tiles in view (of 48); far: one coarse tile.
  for (const TileKey& k : needed["close-face"]) EXPECT_EQ(k.level, 0);
  EXPECT_LT(needed["close-face"].size(), 48u);
  EXPECT_GE(needed["close-face"].size(), 4u);
  EXPECT_EQ(needed["far-face"].size(), 1u);
  EXPECT_GE(needed["far-face"][0].level, 2);
  // Grazing: finer near the eye than far from it.
  std::set<int> levels;
  for (const TileKey& k : needed["framed-grazing"]) levels.insert(k.level);
  EXPECT_GE(levels.size(), 2u);
}

// Walking from far to close: every frame draws resident tiles that cover the view once, uploads
// at most max_uploads_per_frame, stays within the budget, and the loads finish.
TEST(PyramidStream, FramesStayWithinTheirBoundsAndLoadsFinish) {
  StreamOptions o;
  o.max_uploads_per_frame = 2;
  const int64_t tile_bytes = int64_t{kTile} * kTile * 32;
  o.budget_bytes = 24 * tile_bytes;  // fewer than the 48 of level 0
  auto s = Open(o);
  ASSERT_NE(s, nullptr);
  const ViewCamera far = View(ViewDistance::kFar, ViewAngle::kFace);
  const ViewCamera close = View(ViewDistance::kClose, ViewAngle::kFace);
  std::set<TileKey> resident;
  int completed_at = -1;
  for (int frame = 0; frame < 2000 && completed_at < 0; ++frame) {
    const double t = std::min(1.0, frame / 40.0);
    ViewCamera view = far;
    view.eye_mm = far.eye_mm + t * (close.eye_mm - far.eye_mm);
    StreamFrame f = s->Frame(view, {});
    EXPECT_LE(int(f.upload.size()), frame == 0 ? 1 : o.max_uploads_per_frame);
    EXPECT_LE(f.resident_bytes, o.budget_bytes);
    for (const TileKey& k : f.evict) EXPECT_EQ(resident.erase(k), 1u) << "evicted twice";
    for (const GpuTile& g : f.upload) {
      EXPECT_TRUE(resident.insert(g.key).second) << "uploaded twice";
      EXPECT_EQ(g.rgba[0].size(), size_t(4) * g.width * g.height);
      for (const auto& channel : g.rgba)
        for (float v : channel) ASSERT_TRUE(std::isfinite(v));
    }
    for (const TileKey& k : f.draw) EXPECT_TRUE(resident.count(k)) << "drew a tile not uploaded";
    if (frame % 10 == 0 || t == 1.0) ExpectCoversOnce(*s, f.draw, VisibleTexels(view), "frame");
    EXPECT_TRUE(f.errors.empty());
    if (t == 1.0 && f.missing == 0) completed_at = frame;
    s->WaitForLoads(0.02);
  }
  ASSERT_GE(completed_at, 0) << "the close-up's tiles never all arrived";
  const StreamFrame last = s->Frame(close, {});
  for (const TileKey& k : last.draw) EXPECT_EQ(k.level, 0);
}

// A tile whose bytes were damaged (untrusted files): its read fails its checksum, the error
// names the file and comes once, its coarser ancestor is drawn in its place, and the loads still
// end (what can come, came).
TEST(PyramidStream, ADamagedTileIsReportedOnceAndItsAncestorDrawn) {
  const fs::path damaged = Get().dir / "damaged.pack.exr";
  fs::copy_file(Get().file, damaged, fs::copy_options::overwrite_existing);
  std::string bytes = test::ReadFileBytes(damaged);
  for (size_t i = bytes.size() * 3 / 10; i < bytes.size() * 3 / 10 + 64; ++i) bytes[i] ^= 0x5a;
  {
    std::ofstream out(damaged, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), std::streamsize(bytes.size()));
  }
  auto s = PyramidStream::Open(damaged);
  ASSERT_TRUE(s.ok()) << s.error().message;  // the header and the root are intact
  const ViewCamera view = View(ViewDistance::kFramed, ViewAngle::kFace);  // needs all 48
  std::vector<std::string> errors;
  StreamFrame f;
  for (int frame = 0; frame < 2000; ++frame) {
    f = (*s)->Frame(view, {});
    errors.insert(errors.end(), f.errors.begin(), f.errors.end());
    if (f.loading == 0 && frame > 0) break;
    (*s)->WaitForLoads(0.02);
  }
  EXPECT_EQ(f.loading, 0);
  ASSERT_GE(errors.size(), 1u);
  EXPECT_LT(errors.size(), 48u);
  for (const std::string& e : errors) EXPECT_NE(e.find("damaged.pack.exr"), std::string::npos) << e;
  EXPECT_EQ(f.missing, int(errors.size())) << "a failed tile is asked for again";
  ExpectCoversOnce(**s, f.draw, VisibleTexels(view), "with a damaged tile");
  int coarser = 0;
  for (const TileKey& k : f.draw) coarser += k.level > 0;
  EXPECT_GE(coarser, 1);
}

// --- rendered --------------------------------------------------------------------------------

struct Gl {
  std::unique_ptr<HeadlessContext> context;
  std::unique_ptr<Renderer> whole, streamed;
  std::unique_ptr<HeightFieldTracer> tracer;
  std::string skip;
};

Gl& GetGl() {
  static Gl* g = [] {
    auto* g = new Gl();
    auto context = HeadlessContext::Create();
    if (!context) {
      g->skip = context.error().message;
      return g;
    }
    g->context = std::move(*context);
    auto whole = Renderer::Create();
    auto streamed = Renderer::Create();
    if (!whole || !streamed) {
      g->skip = "renderer";
      return g;
    }
    g->whole = std::move(*whole);
    g->streamed = std::move(*streamed);
    if (auto i = g->whole->AddPainting(Get().pack, "whole"); !i) g->skip = i.error().message;
    if (auto i = g->streamed->AddStreamedPainting(Open(), "streamed"); !i)
      g->skip = i.error().message;
    auto tracer = HeightFieldTracer::Build(Get().pack.field);
    if (tracer) g->tracer = std::make_unique<HeightFieldTracer>(std::move(*tracer));
    return g;
  }();
  return *g;
}

Grid<Vec3f> Clip01(Grid<Vec3f> image) {
  for (Vec3f& c : image.data) c = c.cwiseMax(0.0f).cwiseMin(1.0f);
  return image;
}

// At every paper view the streamed painting, once its tiles are there, stands against the
// antialiased Embree reference (4 x 4 rays a pixel, box-filtered: what a display should show) as
// well as the whole pack does: level 0 where the view needs it, elsewhere the pyramid's
// prefiltered levels against the whole pack's per-pixel filter.
TEST(PyramidStream, RendersLikeTheWholePackOnceSettled) {
  Gl& g = GetGl();
  if (!g.skip.empty()) FAIL() << g.skip;
  const Light light = StandardLight(Get().pack);
  const int ss = 4;
  for (ViewDistance d : {ViewDistance::kClose, ViewDistance::kFramed, ViewDistance::kFar})
    for (ViewAngle a : {ViewAngle::kFace, ViewAngle::kGrazing}) {
      const ViewCamera view = View(d, a);
      const std::string name = PaperView{d, a}.Name();
      RenderOptions o;
      o.technique = Technique::kHybrid;
      ASSERT_TRUE(g.streamed->SettleStreams(view, 30)) << name;
      const RenderedImage s = g.streamed->Render(view, {light}, o);
      EXPECT_EQ(s.stats.tiles_missing, 0) << name;
      EXPECT_GT(s.stats.tiles_drawn, 0) << name;
      const RenderedImage w = g.whole->Render(view, {light}, o);
      const RelitImage ref_ss =
          RenderReference(*g.tracer, Get().pack, Supersampled(view, ss), light, false);
      const Grid<Vec3f> ref = Clip01(Downsample(ref_ss.rgb, ss));
      const Grid<uint8_t> mask = DownsampleMask(ref_ss.mask, ss);
      const double streamed_db = CompareImages(Clip01(s.rgb), ref, mask, kPsnrPeak).psnr_db;
      const double whole_db = CompareImages(Clip01(w.rgb), ref, mask, kPsnrPeak).psnr_db;
      const double apart_db = CompareImages(Clip01(s.rgb), Clip01(w.rgb), mask, kPsnrPeak).psnr_db;
      std::printf(
          "%-15s streamed %.2f dB, whole %.2f dB against the antialiased reference; "
          "%.2f dB apart; %d tiles\n",
          name.c_str(), streamed_db, whole_db, apart_db, s.stats.tiles_drawn);
      // Close and framed views get level 0 (a texel under half a pixel), and the same filter:
      // the whole pack's image. Far views get coarser levels, whose prefiltered lobes
      // (pack_pyramid.h) shade highlights brighter and wider than the whole pack's mean over the
      // footprint: measured 4.2 dB below it at far-face, 0.9 dB at far-grazing.
      const bool far = d == ViewDistance::kFar;
      EXPECT_GT(streamed_db, whole_db - (far ? 5.0 : 0.5)) << name;
      EXPECT_GT(apart_db, far ? 30.0 : 39.0) << name;
      if (const char* dir = std::getenv("DIGITIZE_VIEWER_SHOTS")) {
        fs::create_directories(dir);
        (void)WritePngRgb8(fs::path(dir) / ("stream_" + name + ".png"), ToneMap(s.rgb));
        (void)WritePngRgb8(fs::path(dir) / ("whole_" + name + ".png"), ToneMap(w.rgb));
      }
    }
}

// The gallery hangs a tiled pack streamed where it hangs the same pack read whole: same frame,
// same place, and (its tiles loaded before each shot) the same picture, from the room and close up.
TEST(PyramidStream, TheGalleryHangsATiledPackStreamed) {
  if (!GetGl().skip.empty()) FAIL() << GetGl().skip;
  EXPECT_TRUE(IsTiledPack(Get().file));
  EXPECT_FALSE(IsTiledPack(Get().dir / "single.pack.exr"));
  GalleryShotOptions o;
  o.width = 480;
  o.height = 270;
  o.close_up = Get().dir / "whole_close.png";
  ASSERT_TRUE(
      RenderGalleryScreenshots({{"whole", Get().pack}}, Get().dir / "whole.png", {}, o).ok());
  o.close_up = Get().dir / "streamed_close.png";
  o.streamed = {Get().file};
  ASSERT_TRUE(RenderGalleryScreenshots({}, Get().dir / "streamed.png", {}, o).ok());
  for (const std::string shot : {"", "_close"}) {
    auto a = ReadImage(Get().dir / ("streamed" + shot + ".png"));
    auto b = ReadImage(Get().dir / ("whole" + shot + ".png"));
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_EQ(a->pixels.size(), b->pixels.size());
    double sum = 0, painting = 0;
    for (size_t i = 0; i < a->pixels.size(); ++i) {
      sum += std::pow(a->pixels[i] - b->pixels[i], 2);
      painting += a->pixels[i];
    }
    const double psnr = 10 * std::log10(a->pixels.size() / std::max(sum, 1e-12));
    std::printf("gallery%s: streamed against whole %.1f dB (8-bit sRGB)\n", shot.c_str(), psnr);
    EXPECT_GT(psnr, 30.0) << shot;
    EXPECT_GT(painting / a->pixels.size(), 0.05) << shot << ": a dark image";
  }
}

}  // namespace
}  // namespace digitize::viewer
