// Viewer benchmark: the paper's (seed 001) Tables 1 and 2 on this machine (Mesa llvmpipe, a CPU
// rasteriser, 2 cores) with the image error of every rendering against the Embree reference.
//   Table 1: frame time by technique x view (close / framed / far x face / grazing, view.h):
//            mesh (full resolution and OpenMesh-simplified), relief everywhere, bump (paper's
//            plain bump, "px4" = 4 fixed-point parallax steps only, and the default with the slab
//            search), hybrid, hybrid+adaptive (also "adaptive-px4": without the slab search, the
//            renderer before it), screen-space error. delta0 = 30 % of H (the paper's range and
//            ReliefOptions' default); --delta0=0.10 for the smaller slab.
//   Table 2: hybrid+adaptive frame time by box size n (5, 10, 20, 50, 100) x angle (framed).
//   Tables 1 and 2 are point-sampled (filter_reflectance off), as the paper's renderer.
//   Table 3: prefiltered reflectance (renderer.h): hybrid+adaptive point-sampled, filtered, and
//            point-sampled at 4 x 4 the pixels (supersampling, 16x the shading), frame time and
//            PSNR against the reference antialiased with 8 x 8 rays per pixel (the truth of what
//            a pixel shows; 4 x 4 is itself a coarse estimate), radiance clipped to white.
// Timing: Draw + glFinish measured with a steady clock (GL timer queries are meaningless on
// llvmpipe), over --frames frames after one warm-up: the minimum (the frame least disturbed by
// other processes on a shared 2-core machine; ratios use it) and the median; every ratio comes
// from this one run.
// Writes docs/bench_viewer_table{1,2,3}.csv (bench/plot_viewer.gp plots the first two).
//
//   viewer_bench [--long-side=768] [--width=512] [--height=384] [--frames=7] [--delta0=0.30]
//                [--mesh-triangles=100000] [--csv-dir=docs] [--shots=DIR] [--tables=1,2,3]
// --shots writes every Table 1 image, its reference and a x4 difference image as PNGs.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_support.h"
#include "digitize/image_io.h"
#include "digitize/relight.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/truth_pack.h"
#include "digitize_viewer/gl_context.h"
#include "digitize_viewer/renderer.h"
#include "digitize_viewer/scene_setup.h"

namespace {

using namespace digitize;
using namespace digitize::viewer;

using bench::Arg;

struct Timing {
  double median_ms = 0;
  double min_ms = 0;  // the least-disturbed frame: on a shared machine, the better estimate
  RenderedImage last;
};

Timing Time(Renderer& r, const ViewCamera& v, const Light& light, const RenderOptions& o,
            int frames) {
  Timing t;
  t.last = r.Render(v, {light}, o);  // warm-up (shader variants, mesh build, caches)
  std::vector<double> ms;
  for (int i = 0; i < frames; ++i) {
    t.last = r.Render(v, {light}, o);
    ms.push_back(t.last.ms);
  }
  std::sort(ms.begin(), ms.end());
  t.median_ms = ms[ms.size() / 2];
  t.min_ms = ms.front();
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  const int long_side = std::stoi(Arg(argc, argv, "long-side", "768"));
  const int width = std::stoi(Arg(argc, argv, "width", "512"));
  const int height = std::stoi(Arg(argc, argv, "height", "384"));
  const int frames = std::stoi(Arg(argc, argv, "frames", "7"));
  const double delta0 = std::stod(Arg(argc, argv, "delta0", "0.30"));
  const size_t mesh_budget = std::stoul(Arg(argc, argv, "mesh-triangles", "100000"));
  const std::filesystem::path csv_dir = Arg(argc, argv, "csv-dir", "docs");
  const std::string shots = Arg(argc, argv, "shots", "");
  const std::string tables = Arg(argc, argv, "tables", "1,2,3");  // which tables to run
  if (!shots.empty()) std::filesystem::create_directories(shots);
  auto save = [&](const Grid<Vec3f>& img, const std::string& name) {
    if (!shots.empty())
      (void)WritePngRgb8(std::filesystem::path(shots) / (name + ".png"), ToneMap(img));
  };

  synth::PaintingOptions po;  // 400 x 300 mm
  po.resolution_px = long_side;
  po.seed = 7;
  po.impasto_count = 24;
  const synth::Painting painting = synth::MakePainting(po);
  synth::TruthPackOptions tpo;
  tpo.relief.delta0_fraction = delta0;
  const Pack pack = synth::MakeTruthPack(painting, tpo);
  auto tracer = HeightFieldTracer::Build(pack.field);
  if (!tracer) {
    std::fprintf(stderr, "viewer_bench: %s\n", tracer.error().message.c_str());
    return 1;
  }
  auto context = HeadlessContext::Create();
  if (!context) {
    std::fprintf(stderr, "viewer_bench: %s\n", context.error().message.c_str());
    return 1;
  }
  std::printf("# %s\n", (*context)->Description().c_str());
  std::printf(
      "# painting %dx%d texels (%.0fx%.0f mm), %zu boxes of %d px, delta0 %.2f mm, H %.2f mm;"
      " image %dx%d; min and median of %d frames; Table 2 PSNR: point-sampled\n",
      pack.width(), pack.height(), pack.width_mm(), pack.height_mm(), pack.boxes.size(),
      pack.cell_px, pack.delta0_mm, pack.max_height_mm, width, height, frames);
  const Light light = StandardLight(pack);

  // Two renderers: full mesh and simplified mesh (each paints its own copy of the pack).
  auto full = Renderer::Create();
  auto simple = Renderer::Create();
  if (!full || !simple) {
    std::fprintf(stderr, "viewer_bench: %s\n",
                 (!full ? full.error() : simple.error()).message.c_str());
    return 1;
  }
  (void)(*full)->AddPainting(pack, "bench");
  MeshOptions mo;
  mo.max_triangles = mesh_budget;
  (void)(*simple)->AddPainting(pack, "bench", {}, mo);

  struct Mode {
    std::string name;
    Renderer* renderer;
    RenderOptions options;
  };
  std::vector<Mode> modes;
  // parallax < 0: the default slab search; >= 0: that many fixed-point parallax steps instead.
  auto add = [&](const std::string& name, Renderer* r, Technique t, int parallax = -1) {
    RenderOptions o;
    o.technique = t;
    o.filter_reflectance = false;
    o.bump_slab_search = parallax < 0;
    if (parallax >= 0) o.bump_parallax_iterations = parallax;
    modes.push_back({name, r, o});
  };
  add("mesh", full->get(), Technique::kMesh);
  add("mesh-" + std::to_string(mesh_budget / 1000) + "k", simple->get(), Technique::kMesh);
  add("relief", full->get(), Technique::kReliefEverywhere);
  add("bump-paper", full->get(), Technique::kBump, 0);
  add("bump-px4", full->get(), Technique::kBump, 4);
  add("bump", full->get(), Technique::kBump);
  add("hybrid", full->get(), Technique::kHybrid);
  add("adaptive-px4", full->get(), Technique::kHybridAdaptive, 4);
  add("adaptive", full->get(), Technique::kHybridAdaptive);
  add("screen-error", full->get(), Technique::kScreenSpaceError);

  std::filesystem::create_directories(csv_dir);
  if (tables.find('1') != std::string::npos) {
    std::ofstream t1(csv_dir / "bench_viewer_table1.csv");
    t1 << "view,technique,ms,hz,median_ms,psnr_db,psnr_interior_db,psnr_aa_db,boxes_drawn,boxes_"
          "blended,"
          "boxes_total,triangles\n";
    std::printf("\nTable 1: frame time (ms, Hz) and PSNR (dB) vs the Embree reference\n");
    std::printf("%-15s %-13s %9s %8s %9s %8s %9s %8s %7s\n", "view", "technique", "min ms", "Hz",
                "median ms", "PSNR", "interior", "AA 4x4", "boxes");
    for (const PaperView& pv : AllPaperViews()) {
      const ViewCamera v = MakePaperView(pack.width_mm(), pack.height_mm(), pv, width, height);
      const RelitImage ref = RenderReference(*tracer, pack, v, light, false);
      const Grid<uint8_t> interior = InteriorMask(ref.mask);
      const int ss = kCompareSupersampling;
      const ViewCamera v_ss = Supersampled(v, ss);
      const RelitImage ref_ss = RenderReference(*tracer, pack, v_ss, light, false);
      const Grid<Vec3f> ref_aa = Downsample(ref_ss.rgb, ss);
      const Grid<uint8_t> mask_aa = DownsampleMask(ref_ss.mask, ss);
      save(ref.rgb, pv.Name() + "-reference");
      double relief_ms = 0, adaptive_ms = 0, mesh_ms = 0;
      for (const Mode& m : modes) {
        const Timing t = Time(*m.renderer, v, light, m.options, frames);
        const ImageComparison c = CompareImages(t.last.rgb, ref.rgb, ref.mask, kPsnrPeak);
        const ImageComparison ci = CompareImages(t.last.rgb, ref.rgb, interior, kPsnrPeak);
        const Grid<Vec3f> aa = Downsample(m.renderer->Render(v_ss, {light}, m.options).rgb, ss);
        const ImageComparison ca = CompareImages(aa, ref_aa, mask_aa, kPsnrPeak);
        const FrameStats& s = t.last.stats;
        if (!shots.empty()) {
          save(t.last.rgb, pv.Name() + "-" + m.name);
          Grid<Vec3f> diff = t.last.rgb;
          for (size_t i = 0; i < diff.data.size(); ++i)
            diff.data[i] = (diff.data[i] - ref.rgb.data[i]).cwiseAbs() * 4.0f;
          save(diff, pv.Name() + "-" + m.name + "-diff4");
        }
        std::printf("%-15s %-13s %9.2f %8.1f %9.2f %8.2f %9.2f %8.2f %7d\n", pv.Name().c_str(),
                    m.name.c_str(), t.min_ms, 1000.0 / t.min_ms, t.median_ms, c.psnr_db, ci.psnr_db,
                    ca.psnr_db, s.boxes_drawn);
        t1 << pv.Name() << "," << m.name << "," << t.min_ms << "," << 1000.0 / t.min_ms << ","
           << t.median_ms << "," << c.psnr_db << "," << ci.psnr_db << "," << ca.psnr_db << ","
           << s.boxes_drawn << "," << s.boxes_blended << "," << s.boxes_total << ","
           << s.mesh_triangles << "\n";
        if (m.name == "relief") relief_ms = t.min_ms;
        if (m.name == "adaptive") adaptive_ms = t.min_ms;
        if (m.name == "mesh") mesh_ms = t.min_ms;
      }
      std::printf("%-15s adaptive is %.2fx faster than relief everywhere, %.2fx than the mesh\n",
                  pv.Name().c_str(), relief_ms / adaptive_ms, mesh_ms / adaptive_ms);
    }
  }
  if (tables.find('2') != std::string::npos) {
    std::ofstream t2(csv_dir / "bench_viewer_table2.csv");
    t2 << "n,angle,boxes_total,boxes_drawn,ms,hz,psnr_db,hybrid_ms,hybrid_psnr_db\n";
    std::printf("\nTable 2: hybrid+adaptive by box size n, framed view\n");
    std::printf("%5s %-8s %7s %7s %9s %8s %11s %8s\n", "n", "angle", "boxes", "drawn", "min ms",
                "PSNR", "hybrid ms", "PSNR");
    for (int n : {5, 10, 20, 50, 100}) {
      synth::TruthPackOptions o = tpo;
      o.relief.cell_px = n;
      const Pack pn = synth::MakeTruthPack(painting, o);
      auto r = Renderer::Create();
      if (!r || !(*r)->AddPainting(pn, "n" + std::to_string(n)).ok()) return 1;
      for (ViewAngle a : {ViewAngle::kFace, ViewAngle::kGrazing}) {
        const ViewCamera v =
            MakePaperView(pn.width_mm(), pn.height_mm(), {ViewDistance::kFramed, a}, width, height);
        const RelitImage ref = RenderReference(*tracer, pn, v, light, false);
        RenderOptions ad;
        ad.technique = Technique::kHybridAdaptive;
        ad.filter_reflectance = false;
        RenderOptions hy = ad;
        hy.technique = Technique::kHybrid;
        const Timing ta = Time(**r, v, light, ad, frames);
        const Timing th = Time(**r, v, light, hy, frames);
        const double pa = CompareImages(ta.last.rgb, ref.rgb, ref.mask, kPsnrPeak).psnr_db;
        const double ph = CompareImages(th.last.rgb, ref.rgb, ref.mask, kPsnrPeak).psnr_db;
        const char* angle = a == ViewAngle::kFace ? "face" : "grazing";
        std::printf("%5d %-8s %7d %7d %9.2f %8.2f %11.2f %8.2f\n", n, angle,
                    ta.last.stats.boxes_total, ta.last.stats.boxes_drawn, ta.min_ms, pa, th.min_ms,
                    ph);
        t2 << n << "," << angle << "," << ta.last.stats.boxes_total << ","
           << ta.last.stats.boxes_drawn << "," << ta.min_ms << "," << 1000.0 / ta.min_ms << ","
           << pa << "," << th.min_ms << "," << ph << "\n";
      }
    }
  }
  if (tables.find('3') != std::string::npos) {
    std::ofstream t3(csv_dir / "bench_viewer_table3.csv");
    t3 << "view,point_ms,point_psnr_db,filtered_ms,filtered_psnr_db,supersampled_ms,"
          "supersampled_psnr_db\n";
    std::printf(
        "\nTable 3: prefiltered reflectance, hybrid+adaptive; PSNR vs 8x8 rays per pixel\n");
    std::printf("%-15s %9s %8s %9s %8s %9s %8s %9s\n", "view", "point ms", "PSNR", "filt ms",
                "PSNR", "4x4 ss ms", "PSNR", "filt/pt");
    auto clip = [](Grid<Vec3f> img) {
      for (Vec3f& c : img.data) c = c.cwiseMax(0.0f).cwiseMin(1.0f);
      return img;
    };
    for (const PaperView& pv : AllPaperViews()) {
      const ViewCamera v = MakePaperView(pack.width_mm(), pack.height_mm(), pv, width, height);
      const int truth_ss = 8, ss = kCompareSupersampling;
      const RelitImage ref_ss =
          RenderReference(*tracer, pack, Supersampled(v, truth_ss), light, false);
      const Grid<Vec3f> truth = clip(Downsample(ref_ss.rgb, truth_ss));
      const Grid<uint8_t> mask = DownsampleMask(ref_ss.mask, truth_ss);
      RenderOptions o;
      o.technique = Technique::kHybridAdaptive;
      o.filter_reflectance = false;
      const Timing tp = Time(**full, v, light, o, frames);
      const Timing ts = Time(**full, Supersampled(v, ss), light, o, frames);
      o.filter_reflectance = true;
      const Timing tf = Time(**full, v, light, o, frames);
      auto db = [&](const Grid<Vec3f>& img) {
        return CompareImages(clip(img), truth, mask, kPsnrPeak).psnr_db;
      };
      const double dp = db(tp.last.rgb), df = db(tf.last.rgb), ds = db(Downsample(ts.last.rgb, ss));
      save(tf.last.rgb, pv.Name() + "-filtered");
      std::printf("%-15s %9.2f %8.2f %9.2f %8.2f %9.2f %8.2f %8.2fx\n", pv.Name().c_str(),
                  tp.min_ms, dp, tf.min_ms, df, ts.min_ms, ds, tf.min_ms / tp.min_ms);
      t3 << pv.Name() << "," << tp.min_ms << "," << dp << "," << tf.min_ms << "," << df << ","
         << ts.min_ms << "," << ds << "\n";
    }
  }
  std::printf("\nwrote the tables' CSV files to %s\n", csv_dir.c_str());
  return 0;
}
