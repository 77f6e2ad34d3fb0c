// Streamed pyramid benchmark (pyramid_stream.h, issue 14 part 4): a tiled pack walked up to on a
// camera path -- from the whole painting in view to a close-up, then along it -- with the frame
// time (Render: Draw + glFinish, Mesa llvmpipe on this machine's cores), the tiles drawn, needed,
// missing and uploaded each frame, the resident texture memory, and the process's peak RSS; and,
// where the pack's level 0 fits a whole read (ReadPack's 2^26 texels), the same path with the
// pack uploaded whole, for the time to the first frame and the memory against the stream's.
// Writes one CSV row per frame (--csv) and prints a summary line per form.
//
//   viewer_stream_bench --pack=FILE.pack.exr [--frames=120] [--width=640] [--height=360]
//                       [--budget-mb=512] [--uploads=4] [--csv=docs/bench_viewer_stream.csv]
//                       [--whole=1] [--shots=DIR]
// The pack: bench/pack_tiled_bench --size N --tile 256 --out FILE --keep 1 writes one.
#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_support.h"
#include "digitize/image_io.h"
#include "digitize/pack.h"
#include "digitize_viewer/gl_context.h"
#include "digitize_viewer/pyramid_stream.h"
#include "digitize_viewer/renderer.h"
#include "digitize_viewer/view.h"

namespace {

using namespace digitize;
using namespace digitize::viewer;
using bench::Arg;

double PeakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

// The path over a W x H mm painting (canvas frame, facing +z): the whole painting framed, eased
// down to 150 mm above a point a third of the way in, then 40 % of the width along it.
std::vector<ViewCamera> Path(double w, double h, int frames, int width, int height) {
  std::vector<ViewCamera> path;
  const double framed = 0.55 * std::max(h, w * height / double(width)) / std::tan(20 * M_PI / 180);
  const Vec3d centre(w / 2, h / 2, 0), near(w / 3, h / 2, 0);
  const int walk = frames * 2 / 3;
  for (int i = 0; i < frames; ++i) {
    ViewCamera c;
    c.width = width;
    c.height = height;
    c.fov_y_deg = 40;
    c.up = Vec3d::UnitY();
    c.near_mm = 1;
    c.far_mm = 10 * framed;
    if (i < walk) {
      const double t = double(i) / std::max(walk - 1, 1), s = t * t * (3 - 2 * t);
      const Vec3d target = centre + s * (near - centre);
      const double z = framed * std::pow(150.0 / framed, s);
      c.eye_mm = target + Vec3d(0, -0.3 * z * s, z);
      c.target_mm = target;
    } else {
      const double t = double(i - walk) / std::max(frames - walk - 1, 1);
      const Vec3d target = near + Vec3d(0.4 * w * t, 0, 0);
      c.eye_mm = target + Vec3d(0, -45, 150);
      c.target_mm = target;
    }
    path.push_back(c);
  }
  return path;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string pack = Arg(argc, argv, "pack", "");
  const int frames = std::stoi(Arg(argc, argv, "frames", "120"));
  const int width = std::stoi(Arg(argc, argv, "width", "640"));
  const int height = std::stoi(Arg(argc, argv, "height", "360"));
  const double budget_mb = std::stod(Arg(argc, argv, "budget-mb", "512"));
  const int uploads = std::stoi(Arg(argc, argv, "uploads", "4"));
  const std::string csv = Arg(argc, argv, "csv", "docs/bench_viewer_stream.csv");
  const bool whole = Arg(argc, argv, "whole", "1") == "1";
  const std::string shots = Arg(argc, argv, "shots", "");
  if (pack.empty()) {
    std::fprintf(stderr, "usage: viewer_stream_bench --pack=FILE.pack.exr [...]\n");
    return 2;
  }
  auto context = HeadlessContext::Create();
  if (!context) return std::fprintf(stderr, "%s\n", context.error().message.c_str()), 1;
  std::ofstream out(csv);
  out << "form,frame,ms,tiles_drawn,tiles_needed,tiles_missing,tiles_uploaded,resident_mb,"
         "peak_rss_mb\n";

  StreamOptions so;
  so.budget_bytes = int64_t(budget_mb * (1 << 20));
  so.max_uploads_per_frame = uploads;
  auto start = bench::Clock::now();
  auto stream = PyramidStream::Open(pack, so);
  if (!stream) return std::fprintf(stderr, "%s\n", stream.error().message.c_str()), 1;
  const PackSummary summary = (*stream)->summary();
  const double w = (*stream)->width_mm(), h = (*stream)->height_mm();
  const std::vector<ViewCamera> path = Path(w, h, frames, width, height);
  Light light;
  light.type = LightType::kPoint;
  light.position_mm = Vec3d(0.2 * w, 0.8 * h, 0.9 * std::max(w, h));
  const double d2 = (light.position_mm - Vec3d(w / 2, h / 2, 0)).squaredNorm();
  light.intensity = Vec3f::Constant(float(M_PI * d2));
  RenderOptions o;
  o.technique = Technique::kHybrid;

  std::printf("%s: %d x %d texels (%.2f Gtexel), %zu levels, tiles of %d; %d frames of %dx%d\n",
              pack.c_str(), summary.width, summary.height,
              double(summary.width) * summary.height / 1e9, summary.levels.size(),
              summary.tile_size, frames, width, height);
  for (const bool streamed : {true, false}) {
    if (!streamed && (!whole || int64_t(summary.width) * summary.height > (int64_t{1} << 26)))
      continue;
    auto renderer = Renderer::Create();
    if (!renderer) return std::fprintf(stderr, "%s\n", renderer.error().message.c_str()), 1;
    start = bench::Clock::now();
    if (streamed) {
      if (auto i = (*renderer)->AddStreamedPainting(std::move(*stream), pack); !i)
        return std::fprintf(stderr, "%s\n", i.error().message.c_str()), 1;
    } else {
      auto p = ReadPack(pack);
      if (!p) return std::fprintf(stderr, "%s\n", p.error().message.c_str()), 1;
      if (auto i = (*renderer)->AddPainting(*p, pack); !i)
        return std::fprintf(stderr, "%s\n", i.error().message.c_str()), 1;
    }
    double first_ms = 0, worst_ms = 0, sum_ms = 0, worst_mb = 0;
    int worst_uploads = 0, settled_frames = 0, missing_frames = 0;
    for (int i = 0; i < frames; ++i) {
      const RenderedImage r = (*renderer)->Render(path[i], {light}, o);
      if (i == 0) first_ms = bench::Since(start) * 1e3;
      worst_ms = std::max(worst_ms, r.ms);
      sum_ms += r.ms;
      const double mb = r.stats.stream_bytes / double(1 << 20);
      worst_mb = std::max(worst_mb, mb);
      worst_uploads = std::max(worst_uploads, r.stats.tiles_uploaded);
      settled_frames += r.stats.tiles_missing == 0;
      missing_frames += r.stats.tiles_missing > 0;
      char line[256];
      std::snprintf(line, sizeof line, "%s,%d,%.2f,%d,%d,%d,%d,%.1f,%.0f\n",
                    streamed ? "streamed" : "whole", i, r.ms, r.stats.tiles_drawn,
                    r.stats.tiles_needed, r.stats.tiles_missing, r.stats.tiles_uploaded, mb,
                    PeakRssMb());
      out << line;
      if (!shots.empty() && i % 20 == 0) {
        std::filesystem::create_directories(shots);
        (void)WritePngRgb8(std::filesystem::path(shots) /
                               ((streamed ? "stream_" : "whole_") + std::to_string(i) + ".png"),
                           ToneMap(r.rgb));
      }
    }
    std::printf(
        "%-8s first frame after %.0f ms; frame mean %.1f ms, worst %.1f ms; uploads <= %d a "
        "frame; resident <= %.0f MB (budget %.0f); %d frames with every tile there, %d with "
        "an ancestor in place; peak RSS %.0f MB\n",
        streamed ? "streamed" : "whole", first_ms, sum_ms / frames, worst_ms, worst_uploads,
        worst_mb, budget_mb, settled_frames, missing_frames, PeakRssMb());
  }
  std::printf("wrote %s\n", csv.c_str());
  return 0;
}
