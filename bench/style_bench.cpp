// Style benchmark: frame time of every look (stylise.h) on this machine (Mesa llvmpipe, a CPU
// rasteriser, 2 cores) beside the realistic mode, with each style's coherence error side by
// side: the gallery of two synthetic paintings (400 x 300 and 300 x 400 mm) from its start view
// and the first painting's close-up, 1280 x 720; coherence as MeasureCoherence (scene_setup.h) on
// the first painting's slow path (256 x 192, 3 steps): the display-luminance residual after
// warping each frame into the next, and without the warp.
// Timing: Draw + glFinish with a steady clock over --frames frames after a warm-up (which
// also builds the style's textures): minimum and median; the ratio to realistic uses minima
// from this one run. Writes docs/bench_style.csv.
//
//   style_bench [--frames=5] [--width=1280] [--height=720] [--csv-dir=docs] [--shots=DIR]

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "bench_support.h"
#include "digitize/image_io.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/truth_pack.h"
#include "digitize_viewer/gallery.h"
#include "digitize_viewer/gl_context.h"
#include "digitize_viewer/renderer.h"
#include "digitize_viewer/scene_setup.h"

using namespace digitize;
using namespace digitize::viewer;

int main(int argc, char** argv) {
  const int frames = std::stoi(bench::Arg(argc, argv, "frames", "5"));
  const int width = std::stoi(bench::Arg(argc, argv, "width", "1280"));
  const int height = std::stoi(bench::Arg(argc, argv, "height", "720"));
  const std::filesystem::path csv_dir = bench::Arg(argc, argv, "csv-dir", "docs");
  const std::string shots = bench::Arg(argc, argv, "shots", "");

  std::vector<Pack> packs;
  for (const auto& [w, h, seed] : {std::tuple{400.0, 300.0, 7}, std::tuple{300.0, 400.0, 8}}) {
    synth::PaintingOptions po;
    po.width_mm = w;
    po.height_mm = h;
    po.resolution_px = 512;
    po.seed = uint64_t(seed);
    po.impasto_count = 16;
    packs.push_back(synth::MakeTruthPack(synth::MakePainting(po)));
  }
  auto context = HeadlessContext::Create();
  if (!context) {
    std::fprintf(stderr, "style_bench: %s\n", context.error().message.c_str());
    return 1;
  }
  std::printf("# %s\n", (*context)->Description().c_str());
  auto made = Renderer::Create();
  if (!made) {
    std::fprintf(stderr, "style_bench: %s\n", made.error().message.c_str());
    return 1;
  }
  Renderer& r = **made;
  const Gallery g = MakeGallery({Eigen::Vector2d(400, 300), Eigen::Vector2d(300, 400)});
  for (size_t i = 0; i < packs.size(); ++i)
    if (auto added = r.AddPainting(packs[i], "synthetic", g.world_from_canvas[i]); !added) {
      std::fprintf(stderr, "style_bench: %s\n", added.error().message.c_str());
      return 1;
    }
  r.SetRoom(g.room);
  // The coherence scene: the first painting alone in its canvas frame.
  auto single_made = Renderer::Create();
  if (!single_made) return 1;
  Renderer& single = **single_made;
  (void)single.AddPainting(packs[0], "synthetic");
  const std::vector<ViewCamera> path = SlowPath(packs[0], 256, 192, 3);

  ViewCamera start = g.start, close = CloseUpView(g, 0);
  for (ViewCamera* c : {&start, &close}) {
    c->width = width;
    c->height = height;
  }
  std::filesystem::create_directories(csv_dir);
  std::ofstream csv(csv_dir / "bench_style.csv");
  csv << "style,view,min_ms,median_ms,ratio_to_realistic,strokes,coherence_warped,"
         "coherence_unwarped\n";
  std::printf("%-15s %-8s %9s %9s %8s %8s %10s %10s\n", "style", "view", "min ms", "median",
              "x real", "strokes", "residual", "unwarped");
  double realistic_min[2] = {0, 0};
  // Every style, then the realistic mode point-sampled (filter_reflectance off): the cost of the
  // prefiltered reflectance in the gallery.
  std::vector<std::pair<Style, bool>> runs;
  for (Style style : kAllStyles) runs.push_back({style, true});
  runs.push_back({Style::kRealistic, false});
  for (const auto& [style, filtered] : runs) {
    const std::string label = std::string(ToString(style)) + (filtered ? "" : "-point");
    RenderOptions o;
    o.ambient = 0.05;
    o.style = style;
    o.filter_reflectance = filtered;
    const CoherenceResidual coh =
        MeasureCoherence(single, packs[0], StandardLight(packs[0]), path, o);
    int view_index = 0;
    for (const auto& [name, cam] : {std::pair{"gallery", start}, std::pair{"close-up", close}}) {
      RenderedImage img = r.Render(cam, g.lights, o);  // warm-up
      std::vector<double> ms;
      for (int i = 0; i < frames; ++i) {
        img = r.Render(cam, g.lights, o);
        ms.push_back(img.ms);
      }
      std::sort(ms.begin(), ms.end());
      if (style == Style::kRealistic && filtered) realistic_min[view_index] = ms.front();
      const double ratio = ms.front() / realistic_min[view_index];
      std::printf("%-15s %-8s %9.1f %9.1f %8.2f %8zu %10.4f %10.4f\n", label.c_str(), name,
                  ms.front(), ms[ms.size() / 2], ratio, img.stats.strokes, coh.warped,
                  coh.unwarped);
      csv << label << "," << name << "," << ms.front() << "," << ms[ms.size() / 2] << "," << ratio
          << "," << img.stats.strokes << "," << coh.warped << "," << coh.unwarped << "\n";
      if (!shots.empty()) {
        std::filesystem::create_directories(shots);
        (void)WriteRgb8(std::filesystem::path(shots) / (label + "_" + name + ".png"),
                        ToneMap(img.rgb));
      }
      ++view_index;
    }
  }
  std::printf("\nwrote %s\n", (csv_dir / "bench_style.csv").c_str());
  return 0;
}
