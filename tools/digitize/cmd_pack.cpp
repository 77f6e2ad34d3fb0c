// `digitize pack`, `digitize inspect`, `digitize verify`: texture packs (docs/formats.md).
#include <cstdio>
#include <memory>

#include "commands.h"
#include "digitize/image_io.h"

namespace digitize::cli {

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
      ->required()
      ->check(CLI::ExistingDirectory);
  c->add_option("--fit", args->fit, "Folder written by `digitize fit` on that canvas")
      ->required()
      ->check(CLI::ExistingDirectory);
  c->add_option("-o,--out", args->out,
                "Pack file to write (e.g. painting.pack.exr; replaced only on success)")
      ->required();
  AddPackWriteFlags(c, args->options, args->quantised);
  c->callback([args, &exit_code] {
    PackWriteOptions o = args->options;
    o.encoding = args->quantised ? PackEncoding::kQuantised : PackEncoding::kHalf;
    auto summary = PackFromFolders(args->canvas, args->fit, args->out, o);
    if (!summary.ok()) {
      exit_code = Fail("pack", summary.error().message);
      return;
    }
    PrintPackSummaryLine(args->out, *summary);
    exit_code = 0;
  });
}

void AddInspectCommand(CLI::App& app, int& exit_code) {
  struct Args {
    std::string pack;
    bool json = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand(
      "inspect",
      "Summary of a texture pack from its header: size, resolution, boxes, fit brief, "
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
      std::printf("%s\n", PackSummaryJson(args->pack, *s).c_str());
    } else {
      PrintPackSummaryLine(args->pack, *s);
      std::printf(
          "  format      digitize.pack v%d, %s encoding, %d bytes/texel before compression\n",
          s->version, ToString(s->encoding), s->raw_bytes_per_texel);
      if (s->encoding == PackEncoding::kQuantised)
        std::printf("  mantissa    height %d, normal %d, rho %d, lobe %d bits (of 10)\n",
                    s->quantisation.height_bits, s->quantisation.normal_bits,
                    s->quantisation.rho_bits, s->quantisation.lobe_bits);
      if (s->tile_size > 0)
        std::printf(
            "  tiles       %d x %d texels, %zu levels (%d x %d down to 1 x 1, each "
            "prefiltered from the one above)\n",
            s->tile_size, s->tile_size, s->levels.size(), s->width, s->height);
      std::printf("  pitch       %.4g mm\n", s->pitch_mm);
      std::printf("  models     ");
      for (int m = 0; m < kReflectanceModelCount; ++m)
        std::printf(" %s %lld texels%s", ToString(static_cast<ReflectanceModel>(m)),
                    static_cast<long long>(s->texels_by_model[m]),
                    m + 1 < kReflectanceModelCount ? "," : "\n");
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
      "verify",
      "Full validation of a texture pack: header, every value, checksum, boxes against "
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
