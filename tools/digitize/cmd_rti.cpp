// `digitize rti`: a classical RTI fit (PTM, HSH) of an RTI capture, its held-out score and its
// exports for RTIViewer (.ptm) and relight / OpenLIME (a folder) -- RunRti (rti_export.h).
#include <cstdio>
#include <memory>

#include "commands.h"
#include "digitize/image_io.h"
#include "digitize/rti_export.h"

namespace digitize::cli {

void AddRtiCommand(CLI::App& app, int& exit_code) {
  struct Args {
    RtiRunOptions options;
    std::string basis = "hsh3";
    bool linear = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* c = app.add_subcommand(
      "rti",
      "RTI capture (.lp) -> a classical RTI fit per pixel (PTM, or hemispherical harmonics of "
      "order 2 / 3), its held-out PSNR over 8-bit sRGB codes, and files RTI viewers open: a .ptm "
      "(RTIViewer) and a relight folder (info.json + plane JPEGs: relight, OpenLIME).");
  c->add_option("--photos", args->options.photos, "RTI .lp file to fit")->required();
  c->add_option("--basis", args->basis, "ptm, hsh2 (4 coefficients) or hsh3 (9)")
      ->capture_default_str();
  c->add_option("--held-out", args->options.held_out,
                ".lp file of photos not fitted: relit from the fit and scored");
  c->add_option("--ptm", args->options.ptm, ".ptm file to write (PTM_1.2 LRGB; --basis ptm)");
  c->add_option("--relight-dir", args->options.relight_dir,
                "Folder to write for relight / OpenLIME (info.json + plane_N.jpg)")
      ->transform(FolderPath());
  c->add_option("--jpeg-quality", args->options.relight.jpeg_quality,
                "Quality of the relight folder's plane JPEGs (1-100)")
      ->capture_default_str();
  c->add_flag("--linear", args->linear,
              "Fit linear values instead of the sRGB codes (no exports; for comparison)");
  c->add_option("--threads", args->options.fit.num_threads, "Threads (0 = all cores)")
      ->capture_default_str();
  AddPhotoSetFlags(c, args->options.photo);
  c->callback([args, &exit_code] {
    auto basis = ParseRtiBasis(args->basis);
    if (!basis.ok()) {
      exit_code = Fail("rti", "--basis: " + basis.error().message);
      return;
    }
    RtiRunOptions o = args->options;
    o.fit.basis = *basis;
    o.fit.fit_in_srgb = !args->linear;
    auto r = RunRti(o);
    if (!r.ok()) {
      exit_code = Fail("rti", r.error().message);
      return;
    }
    std::printf("fit: %s (%d coefficients), %d photos %dx%d, %s; %.2f s\n", ToString(r->fit.basis),
                r->fit.count(), r->photos, r->fit.width, r->fit.height,
                r->fit.srgb ? "sRGB codes" : "linear", r->fit.seconds);
    if (r->held_out) {
      for (const RtiHeldOutImage& i : r->held_out_images)
        std::printf("  %-32s %6.2f dB\n", EscapeForTerminal(i.entry).c_str(), i.score.psnr_db);
      std::printf(
          "held-out PSNR %.2f dB (8-bit sRGB, pooled; MSE %.2f codes^2) over %d photos, "
          "%.2f M px; %.2f s\n",
          r->held_out->psnr_db, r->held_out->mse, r->held_out->images, r->held_out->pixels / 1e6,
          r->seconds_held_out);
    }
    if (!o.ptm.empty()) std::printf("wrote %s\n", o.ptm.c_str());
    if (!o.relight_dir.empty()) std::printf("wrote %s/info.json\n", o.relight_dir.c_str());
    exit_code = 0;
  });
}

}  // namespace digitize::cli
