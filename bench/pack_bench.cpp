// Pack size against relighting error (docs/benchmarks.md, "Texture packs"): a synthetic painting
// photographed under 64 point lights and fitted on its true canvas, then packed in half mode and in
// quantised modes of fewer and fewer mantissa bits. For each: the file's bytes per texel (after
// ZIP), the write and read times, and the held-out relighting PSNR computed from the pack READ BACK
// (height, normals and maps as stored) against the noise-free truth renders, next to the PSNR of
// the in-memory float maps. Writes docs/bench_pack.csv for bench/plot_pack.gp.
//
//   pack_bench [--long-side=820] [--lights=64] [--pixels-per-texel=2.07] [--csv-dir=docs]
#include <cctype>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_support.h"
#include "digitize/pack.h"
#include "digitize/reflectance_fit.h"
#include "digitize/relief.h"
#include "digitize_synth/painting.h"
#include "digitize_synth/photo_sim.h"

namespace {

using namespace digitize;
using bench::Arg;
using bench::Clock;
using bench::Since;

struct Row {
  std::string config, series;
  int height_bits = 10, normal_bits = 10, rho_bits = 10, lobe_bits = 10;
  double bytes_per_texel = 0, write_s = 0, read_s = 0, psnr_db = 0, loss_db = 0;
};

}  // namespace

int main(int argc, char** argv) {
  const int long_side = std::stoi(Arg(argc, argv, "long-side", "820"));
  const int lights = std::stoi(Arg(argc, argv, "lights", "64"));
  const double ppt = std::stod(Arg(argc, argv, "pixels-per-texel", "2.07"));
  const std::filesystem::path csv_dir = Arg(argc, argv, "csv-dir", "");

  const bench::Photographed photographed = bench::PhotographPainting(long_side, lights, ppt);
  const synth::Painting& painting = photographed.painting;
  const synth::SyntheticPhotoSet& truth = photographed.photos;
  const synth::PhotoSimOptions& so = photographed.options;
  const HeightField& canvas = painting.truth;
  const size_t texels = canvas.height_mm.size();
  ReflectanceFitOptions options;
  options.fit.noise_sigma = std::max(so.noise_sigma, 0.001);
  auto fit = FitReflectance(canvas, painting.normals, {}, truth.fit, options);
  if (!fit.ok()) {
    std::fprintf(stderr, "%s\n", fit.error().message.c_str());
    return 1;
  }
  auto base =
      EvaluateHeldOut(canvas, painting.normals, fit->maps, {}, truth.held_out, truth.held_out_mask);
  std::printf("painting %dx%d = %.2f M texels, %zu photos (%s, noise %.4f); fit: %s\n",
              canvas.width(), canvas.height(), texels / 1e6, truth.fit.photos.size(),
              synth::ToString(so.encoding), so.noise_sigma, fit->report.Brief().c_str());
  std::printf("float maps in memory: %s\n\n", base->Brief().c_str());

  ReliefOptions ro;
  const ReliefResult relief = ClassifyRelief(canvas, ro);
  Pack pack;
  pack.field = canvas;
  pack.normals = painting.normals;
  pack.maps = fit->maps;
  pack.delta0_mm = relief.delta0_mm;
  pack.max_height_mm = relief.max_height_mm;
  pack.cell_px = relief.cell_px;
  pack.boxes = relief.boxes;
  pack.provenance = NewProvenance();
  pack.provenance.fit_brief = fit->report.Brief();

  struct Config {
    const char* name;
    PackEncoding encoding;
    PackQuantisation q;
  };
  const PackQuantisation defaults;
  const std::vector<Config> configs = {
      {"half", PackEncoding::kHalf, {}},
      {"q 10/8/8/8", PackEncoding::kQuantised, {10, 8, 8, 8}},
      {"q 10/7/6/7", PackEncoding::kQuantised, {10, 7, 6, 7}},
      {"q height 8", PackEncoding::kQuantised, {8, 10, 10, 10}},
      {"q normal 5", PackEncoding::kQuantised, {10, 5, 10, 10}},
      {"q rho 4", PackEncoding::kQuantised, {10, 10, 4, 10}},
      {"q lobe 5", PackEncoding::kQuantised, {10, 10, 10, 5}},
      {"q default", PackEncoding::kQuantised, defaults},
      {"q 8/5/4/5", PackEncoding::kQuantised, {8, 5, 4, 5}},
      {"q 10/4/3/4", PackEncoding::kQuantised, {10, 4, 3, 4}},
      {"q 8/3/2/3", PackEncoding::kQuantised, {8, 3, 2, 3}},
      {"q 6/2/1/2", PackEncoding::kQuantised, {6, 2, 1, 2}},
  };
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "digitize_pack_bench";
  std::filesystem::create_directories(dir);
  std::vector<Row> rows;
  for (const Config& c : configs) {
    PackWriteOptions o;
    o.encoding = c.encoding;
    o.quantisation = c.q;
    const auto path = dir / "p.pack.exr";
    auto t0 = Clock::now();
    if (Status s = WritePack(path, pack, o); !s.ok()) {
      std::fprintf(stderr, "%s\n", s.message().c_str());
      return 1;
    }
    Row r;
    r.config = c.name;
    // One group quantised alone shows which group costs the PSNR; the others sweep all at once.
    r.series = std::string(c.name).find("q ") == 0 &&
                       !std::isdigit(static_cast<unsigned char>(c.name[2])) &&
                       std::string(c.name) != "q default"
                   ? "one group"
                   : "sweep";
    if (c.encoding == PackEncoding::kQuantised) {
      r.height_bits = c.q.height_bits;
      r.normal_bits = c.q.normal_bits;
      r.rho_bits = c.q.rho_bits;
      r.lobe_bits = c.q.lobe_bits;
    }
    r.write_s = Since(t0);
    t0 = Clock::now();
    auto read = ReadPack(path);
    r.read_s = Since(t0);
    if (!read.ok()) {
      std::fprintf(stderr, "%s\n", read.error().message.c_str());
      return 1;
    }
    r.bytes_per_texel =
        static_cast<double>(std::filesystem::file_size(path)) / static_cast<double>(texels);
    auto score = EvaluateHeldOut(read->field, read->normals, read->maps, read->canvas_from_scan,
                                 truth.held_out, truth.held_out_mask);
    r.psnr_db = score->psnr_db;
    r.loss_db = base->psnr_db - score->psnr_db;
    rows.push_back(r);
    std::printf(
        "%-12s %6.2f bytes/texel  write %5.2f s  read %5.2f s  PSNR %6.2f dB  loss %5.2f dB\n",
        r.config.c_str(), r.bytes_per_texel, r.write_s, r.read_s, r.psnr_db, r.loss_db);
    std::fflush(stdout);
  }
  std::filesystem::remove_all(dir);
  if (!csv_dir.empty()) {
    std::ofstream csv(csv_dir / "bench_pack.csv");
    csv << "config,series,height_bits,normal_bits,rho_bits,lobe_bits,bytes_per_texel,write_s,read_"
           "s,"
           "psnr_db,loss_db,float_psnr_db,texels\n";
    for (const Row& r : rows)
      csv << r.config << "," << r.series << "," << r.height_bits << "," << r.normal_bits << ","
          << r.rho_bits << "," << r.lobe_bits << "," << r.bytes_per_texel << "," << r.write_s << ","
          << r.read_s << "," << r.psnr_db << "," << r.loss_db << "," << base->psnr_db << ","
          << texels << "\n";
    std::printf("wrote %s\n", (csv_dir / "bench_pack.csv").string().c_str());
  }
  return 0;
}
