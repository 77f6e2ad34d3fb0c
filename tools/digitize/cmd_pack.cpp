// `digitize pack`, `digitize inspect`, `digitize verify`: texture packs (docs/formats.md).
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "digitize/image_io.h"
#include "digitize/output_dir.h"
#include "digitize/pack.h"
#include "digitize/reflectance_fit.h"

namespace digitize::cli {

std::string PackOptionsJson(const PackWriteOptions& o) {
  nlohmann::json j = {{"encoding", ToString(o.encoding)}};
  if (o.encoding == PackEncoding::kQuantised)
    j["mantissa_bits"] = {{"height", o.quantisation.height_bits},
                          {"normal", o.quantisation.normal_bits},
                          {"rho", o.quantisation.rho_bits},
                          {"lobe", o.quantisation.lobe_bits}};
  return j.dump();
}

void PrintPackSummaryLine(const std::string& path, const PackSummary& s) {
  std::printf("%s: %dx%d texels (%.1f x %.1f mm), %zu boxes, %s, %.2f bytes/texel (%llu bytes)\n",
              EscapeForTerminal(path).c_str(), s.width, s.height, s.width * s.pitch_mm,
              s.height * s.pitch_mm, s.box_count, ToString(s.encoding), s.BytesPerTexel(),
              static_cast<unsigned long long>(s.file_bytes));
}

void AddPackWriteFlags(CLI::App* c, PackWriteOptions& o, bool& quantised) {
  c->add_flag("--quantised", quantised,
              "Drop low mantissa bits per channel group (smaller; stated error, docs/formats.md)")
      ->group("Pack");
  c->add_option("--height-bits", o.quantisation.height_bits, "Quantised: mantissa bits of height (0-10)")
      ->capture_default_str()->group("Pack");
  c->add_option("--normal-bits", o.quantisation.normal_bits, "Quantised: mantissa bits of nx, ny")
      ->capture_default_str()->group("Pack");
  c->add_option("--rho-bits", o.quantisation.rho_bits, "Quantised: mantissa bits of rho_d, rho_s")
      ->capture_default_str()->group("Pack");
  c->add_option("--lobe-bits", o.quantisation.lobe_bits, "Quantised: mantissa bits of cx, cy, k")
      ->capture_default_str()->group("Pack");
}

int PackFromFolders(const std::string& cmd, const std::string& canvas_dir, const std::string& fit_dir,
                    const std::string& out, PackWriteOptions options) {
  if (Status s = options.Validate(); !s.ok()) return Fail(cmd, s.message());
  if (Status s = CheckOutputPath(out, {canvas_dir, fit_dir}); !s.ok())
    return Fail(cmd, s.message());
  auto maps = ReadReflectanceMaps(fit_dir);
  if (!maps.ok()) return Fail(cmd, maps.error().message);
  PreprocessedCanvas canvas;
  if (!canvas_dir.empty()) {
    auto c = ReadPreprocessOutputs(canvas_dir);
    if (!c.ok()) return Fail(cmd, c.error().message);
    canvas = std::move(c).value();
  } else {
    // An RTI fit without a canvas folder: the flat canvas of its texel grid, pitch from the fit.
    return Fail(cmd, "--canvas is required (for an RTI capture, preprocess a height map or use "
                     "`digitize run --photos capture.lp`)");
  }
  auto provenance = ProvenanceFromOutputs(canvas_dir, fit_dir, PackOptionsJson(options));
  if (!provenance.ok()) return Fail(cmd, provenance.error().message);
  auto pack = AssemblePack(std::move(canvas), std::move(maps).value(), std::move(provenance).value());
  if (!pack.ok()) return Fail(cmd, fit_dir + ": " + pack.error().message);
  if (Status s = WritePack(out, *pack, options); !s.ok()) return Fail(cmd, s.message());
  auto summary = InspectPack(out);
  if (!summary.ok()) return Fail(cmd, summary.error().message);
  PrintPackSummaryLine(out, *summary);
  return 0;
}

void AddPackCommand(CLI::App& app, int& exit_code) {
  struct Args {
    std::string canvas, fit, out;
    PackWriteOptions options;
    bool quantised = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand(
      "pack",
      "Canvas (a `digitize preprocess` folder) + reflectance maps (a `digitize fit` folder) -> one "
      "texture pack: a multi-part half-float OpenEXR file with everything the viewer needs "
      "(docs/formats.md, \"Texture packs\").");
  c->add_option("--canvas", args->canvas, "Folder written by `digitize preprocess`")
      ->required()->check(CLI::ExistingDirectory);
  c->add_option("--fit", args->fit, "Folder written by `digitize fit` on that canvas")
      ->required()->check(CLI::ExistingDirectory);
  c->add_option("-o,--out", args->out, "Pack file to write (e.g. painting.pack.exr; replaced only on success)")
      ->required();
  AddPackWriteFlags(c, args->options, args->quantised);
  c->callback([args, &exit_code] {
    PackWriteOptions o = args->options;
    o.encoding = args->quantised ? PackEncoding::kQuantised : PackEncoding::kHalf;
    exit_code = PackFromFolders("pack", args->canvas, args->fit, args->out, o);
  });
}

void AddInspectCommand(CLI::App& app, int& exit_code) {
  struct Args {
    std::string pack;
    bool json = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand(
      "inspect", "Summary of a texture pack from its header: size, resolution, boxes, fit brief, "
                 "provenance (no pixel is decoded; `digitize verify` checks them)");
  c->add_option("pack", args->pack, "Pack file")->required();
  c->add_flag("--json", args->json, "Print the summary as JSON");
  c->callback([args, &exit_code] {
    auto s = InspectPack(args->pack);
    if (!s.ok()) {
      exit_code = Fail("inspect", s.error().message);
      return;
    }
    const PackProvenance& p = s->provenance;
    if (args->json) {
      nlohmann::json inputs = nlohmann::json::array();
      for (const PackInput& in : p.inputs)
        inputs.push_back({{"name", in.name}, {"sha1", in.sha1}, {"bytes", in.bytes}});
      nlohmann::json j = {
          {"file", args->pack},
          {"format", kPackFormatName},
          {"version", s->version},
          {"size_texels", {s->width, s->height}},
          {"pitch_mm", s->pitch_mm},
          {"size_mm", {s->width * s->pitch_mm, s->height * s->pitch_mm}},
          {"delta0_mm", s->delta0_mm},
          {"max_height_mm", s->max_height_mm},
          {"cell_px", s->cell_px},
          {"boxes", s->box_count},
          {"encoding", ToString(s->encoding)},
          {"file_bytes", s->file_bytes},
          {"bytes_per_texel", s->BytesPerTexel()},
          {"raw_bytes_per_texel", s->raw_bytes_per_texel},
          {"gauge", s->gauge},
          {"provenance",
           {{"tool_version", p.tool_version},
            {"created_utc", p.created_utc},
            {"fit_brief", p.fit_brief},
            {"options", nlohmann::json::parse(p.options_json.empty() ? "{}" : p.options_json,
                                              nullptr, false)},
            {"inputs", inputs}}}};
      if (s->encoding == PackEncoding::kQuantised)
        j["mantissa_bits"] = {{"height", s->quantisation.height_bits},
                              {"normal", s->quantisation.normal_bits},
                              {"rho", s->quantisation.rho_bits},
                              {"lobe", s->quantisation.lobe_bits}};
      // ASCII only (\uXXXX for the rest, so no control character reaches the terminal), and
      // bytes that are not UTF-8 (a file name) replaced rather than thrown on.
      std::printf(
          "%s\n",
          j.dump(2, ' ', /*ensure_ascii=*/true, nlohmann::json::error_handler_t::replace).c_str());
    } else {
      PrintPackSummaryLine(args->pack, *s);
      std::printf("  format      digitize.pack v%d, %s encoding, %d bytes/texel before compression\n",
                  s->version, ToString(s->encoding), s->raw_bytes_per_texel);
      if (s->encoding == PackEncoding::kQuantised)
        std::printf("  mantissa    height %d, normal %d, rho %d, lobe %d bits (of 10)\n",
                    s->quantisation.height_bits, s->quantisation.normal_bits,
                    s->quantisation.rho_bits, s->quantisation.lobe_bits);
      std::printf("  pitch       %.4g mm\n", s->pitch_mm);
      std::printf("  relief      delta0 %.4g mm, H %.4g mm, %zu boxes of %d texels\n", s->delta0_mm,
                  s->max_height_mm, s->box_count, s->cell_px);
      // Every string from the file is escaped: a pack is shared, and its provenance could
      // otherwise clear the screen, retitle the terminal or forge lines of this listing.
      std::printf("  fit         %s\n",
                  p.fit_brief.empty() ? "(none recorded)" : EscapeForTerminal(p.fit_brief).c_str());
      std::printf("  made by     %s on %s\n", EscapeForTerminal(p.tool_version).c_str(),
                  EscapeForTerminal(p.created_utc).c_str());
      std::printf("  inputs      %zu files\n", p.inputs.size());
      for (const PackInput& in : p.inputs)
        std::printf("    %-28s %10llu bytes  sha1 %s\n", EscapeForTerminal(in.name).c_str(),
                    static_cast<unsigned long long>(in.bytes), EscapeForTerminal(in.sha1).c_str());
    }
    exit_code = 0;
  });
}

void AddVerifyCommand(CLI::App& app, int& exit_code) {
  auto path = std::make_shared<std::string>();
  CLI::App* c = app.add_subcommand(
      "verify", "Full validation of a texture pack: header, every value, checksum, boxes against "
                "the heights. Exit 0 when valid, 1 with the first problem otherwise.");
  c->add_option("pack", *path, "Pack file")->required();
  c->callback([path, &exit_code] {
    auto v = VerifyPack(*path);
    if (!v.ok()) {
      exit_code = Fail("verify", v.error().message);
      return;
    }
    for (const std::string& line : v->checks) std::printf("ok  %s\n", line.c_str());
    std::printf("%s: valid\n", EscapeForTerminal(*path).c_str());
    exit_code = 0;
  });
}

}  // namespace digitize::cli
