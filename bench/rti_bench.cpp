// The classical RTI bases against `digitize` on a real capture (results: docs/bench_rti.txt): the
// hand-held RTI capture in shared/data/rti_icon (72 JPEGs + dirs.lp), split as the project
// evaluates RTI -- every 4th image from index 3 (0-based: 3, 7, 11, ...) held out, the rest
// fitted -- and each held-out light relit from the fit. Per row: fit time, relight time (all
// held-out lights) and the held-out PSNR over 8-bit sRGB codes pooled over every held-out image
// (Srgb8PsnrAccumulator: one MSE over all pixels and channels, peak 255). Rows: PTM, HSH order 2
// and 3 fitted on the sRGB codes (what RTI tools do) and on linear values; the sRGB fits as
// written to their exports and read back (.ptm, relight folder: the cost of 8-bit storage and
// JPEG); and `digitize`: the
// project's own per-texel BRDF fit of the same split, run as `digitize fit --photos fit.lp
// --held-out held.lp` runs it (FitToFolder on .lp subsets written to a temporary folder), its
// maps read back and each held-out view rendered (RenderRelit) and scored by the same PSNR.
// Reference (CNR-ISTI relight on this split, fitted in sRGB): HSH3 23.45 dB, PTM 21.22 dB.
//
//   rti_bench [--data=../shared/data/rti_icon] [--csv-dir=docs] [--no-digitize]
// The data path is relative to the current directory; the default is right when run from the
// repository root (bench/run.sh does).
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_support.h"
#include "digitize/height_field_tracer.h"
#include "digitize/photo_set.h"
#include "digitize/pipeline.h"
#include "digitize/reflectance_fit.h"
#include "digitize/relight.h"
#include "digitize/rti_basis.h"
#include "digitize/rti_export.h"

namespace {

using namespace digitize;
using bench::Arg;
using bench::Clock;
using bench::Since;
namespace fs = std::filesystem;

struct Row {
  std::string method, encoding;
  int coefficients = 0;
  double fit_s = 0, relight_s = 0, psnr_db = 0, mse = 0;
  size_t pixels = 0;
};

bool IsHeldOut(size_t i) { return i % 4 == 3; }

PhotoSet Subset(const PhotoSet& all, bool held) {
  PhotoSet s;
  s.source = all.source;
  s.is_rti = all.is_rti;
  s.rti_pitch_mm = all.rti_pitch_mm;
  s.rti_pitch_source = all.rti_pitch_source;
  s.rti_pitch_assumed = all.rti_pitch_assumed;
  for (size_t i = 0; i < all.photos.size(); ++i)
    if (IsHeldOut(i) == held) s.photos.push_back(all.photos[i]);
  return s;
}

Status WriteLp(const fs::path& path, const PhotoSet& all, bool held) {
  std::string text;
  size_t count = 0;
  for (size_t i = 0; i < all.photos.size(); ++i) count += IsHeldOut(i) == held;
  text += std::to_string(count) + "\n";
  char buf[512];
  for (size_t i = 0; i < all.photos.size(); ++i) {
    if (IsHeldOut(i) != held) continue;
    const Vec3d& d = all.photos[i].light.direction;
    std::snprintf(buf, sizeof buf, "%s %.17g %.17g %.17g\n",
                  fs::absolute(all.photos[i].path).string().c_str(), d.x(), d.y(), d.z());
    text += buf;
  }
  std::ofstream out(path);
  out << text;
  return out ? Status::Ok() : Status(Error{path.string() + ": write failed"});
}

Result<Row> RtiRow(const PhotoSet& fit_set, const PhotoSet& held, RtiBasis basis, bool srgb) {
  RtiFitOptions options;
  options.basis = basis;
  options.fit_in_srgb = srgb;
  auto fit = FitRti(fit_set, options);
  if (!fit.ok()) return fit.error();
  Row row;
  row.method = ToString(basis);
  row.encoding = srgb ? "srgb" : "linear";
  row.coefficients = RtiCoefficientCount(basis);
  row.fit_s = fit->seconds;
  Srgb8PsnrAccumulator acc;
  for (const Photo& photo : held.photos) {
    const auto t0 = Clock::now();
    const Grid<Vec3f> relit = RelightRti(*fit, photo.light.direction);
    row.relight_s += Since(t0);
    Status s = acc.Add(relit, srgb ? ColourEncoding::kSrgb : ColourEncoding::kLinear, photo.rgb,
                       ColourEncoding::kLinear, {}, photo.entry);
    if (!s.ok()) return Error{s.message()};
  }
  const Srgb8Score score = acc.Score();
  row.psnr_db = score.psnr_db;
  row.mse = score.mse;
  row.pixels = score.pixels;
  return row;
}

// The same fit written as users get it and read back: the .ptm (LRGB, 8-bit coefficients) and
// the relight folder (8-bit coefficient planes in JPEGs of quality 95), relit and scored as above.
Result<std::vector<Row>> ExportRows(const PhotoSet& fit_set, const PhotoSet& held, RtiBasis basis,
                                    const fs::path& work) {
  RtiFitOptions options;
  options.basis = basis;
  auto fit = FitRti(fit_set, options);
  if (!fit.ok()) return fit.error();
  std::vector<Row> rows;
  auto score = [&](const std::string& method, auto relight) -> Status {
    Row row;
    row.method = method;
    row.encoding = "srgb";
    row.coefficients = RtiCoefficientCount(basis);
    row.fit_s = fit->seconds;
    Srgb8PsnrAccumulator acc;
    for (const Photo& photo : held.photos) {
      const auto t0 = Clock::now();
      const Grid<Vec3f> relit = relight(photo.light.direction);
      row.relight_s += Since(t0);
      if (Status s = acc.Add(relit, ColourEncoding::kSrgb, photo.rgb, ColourEncoding::kLinear);
          !s.ok())
        return s;
    }
    row.psnr_db = acc.Score().psnr_db;
    row.mse = acc.Score().mse;
    row.pixels = acc.Score().pixels;
    rows.push_back(row);
    return Status::Ok();
  };
  if (basis == RtiBasis::kPtm) {
    const fs::path file = work / "fit.ptm";
    if (Status s = WritePtm(file, *fit); !s.ok()) return Error{s.message()};
    auto ptm = ReadPtm(file);
    if (!ptm.ok()) return ptm.error();
    if (Status s = score("ptm.ptm", [&](const Vec3d& l) { return RelightPtm(*ptm, l); }); !s.ok())
      return Error{s.message()};
  }
  const fs::path dir = work / (std::string("relight_") + ToString(basis));
  if (Status s = WriteRelightFolder(dir, *fit); !s.ok()) return Error{s.message()};
  auto back = ReadRelightFolder(dir);
  if (!back.ok()) return back.error();
  if (Status s = score(std::string(ToString(basis)) + ".dir",
                       [&](const Vec3d& l) { return RelightRti(*back, l); });
      !s.ok())
    return Error{s.message()};
  return rows;
}

// digitize's own fit of the split, as `digitize fit --photos fit.lp --held-out held.lp` runs it
// (FitToFolder: the RTI canvas -- intensities, normals, height --, the fit with its intensity
// refinement, the held-out photos relit with the intensities their directions predict), scored by
// FitToFolder's own 8-bit sRGB PSNR (the same pooled definition). `flat`: the paper's RTI path,
// normals straight up and no intensity estimate.
Result<Row> DigitizeRow(const PhotoSet& all, const fs::path& work, bool flat) {
  const fs::path fit_lp = work / "fit.lp", held_lp = work / "held.lp";
  if (Status s = WriteLp(fit_lp, all, false); !s.ok()) return Error{s.message()};
  if (Status s = WriteLp(held_lp, all, true); !s.ok()) return Error{s.message()};
  FitFolderOptions o;
  o.photos = fit_lp.string();
  o.held_out = held_lp.string();
  o.photo.allow_outside_paths = true;  // the .lp subsets sit in a temporary folder
  o.check_photos = false;              // a report for the user, not part of the fit
  if (flat) {
    o.rti.normals = false;
    o.rti.height = false;
  }
  o.out = (work / (flat ? "fit_flat" : "fit")).string();
  const auto t0 = Clock::now();
  auto fitted = FitToFolder(o);
  if (!fitted.ok()) return fitted.error();
  const double wall = Since(t0);
  if (!fitted->held_out) return Error{"FitToFolder gave no held-out score"};
  Row row;
  row.method = flat ? "digitize-flat" : "digitize";
  row.encoding = "linear";
  row.relight_s = fitted->held_out->seconds;
  row.fit_s = wall - row.relight_s;  // photos decoded, canvas, fit(s), folder written
  row.psnr_db = fitted->held_out->psnr_srgb8_db;
  row.mse = 255.0 * 255.0 / std::pow(10.0, row.psnr_db / 10.0);
  row.pixels = fitted->held_out->pixels;
  std::printf("%s: %s\n  %s\n  %s (FitToFolder %.1f s)\n", row.method.c_str(),
              fitted->rti ? fitted->rti->Brief().c_str() : "-", fitted->fit.Brief().c_str(),
              fitted->held_out->Brief().c_str(), wall);
  return row;
}

}  // namespace

int main(int argc, char** argv) {
  const fs::path data = Arg(argc, argv, "data", "../shared/data/rti_icon");
  const fs::path csv_dir = Arg(argc, argv, "csv-dir", "");
  bool run_digitize = true;
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--no-digitize") run_digitize = false;

  const auto t0 = Clock::now();
  auto all = ReadRtiCapture(data / "dirs.lp");
  if (!all.ok()) {
    std::fprintf(stderr, "%s\n", all.error().message.c_str());
    return 1;
  }
  const PhotoSet fit_set = Subset(*all, false), held = Subset(*all, true);
  std::printf(
      "%s: %zu photos %dx%d, %zu fitted, %zu held out (every 4th from index 3); "
      "loaded in %.2f s\n\n",
      (data / "dirs.lp").string().c_str(), all->photos.size(), all->photos[0].rgb.width,
      all->photos[0].rgb.height, fit_set.photos.size(), held.photos.size(), Since(t0));

  std::vector<Row> rows;
  for (bool srgb : {true, false}) {
    for (RtiBasis basis : {RtiBasis::kPtm, RtiBasis::kHsh2, RtiBasis::kHsh3}) {
      auto row = RtiRow(fit_set, held, basis, srgb);
      if (!row.ok()) {
        std::fprintf(stderr, "%s\n", row.error().message.c_str());
        return 1;
      }
      rows.push_back(*row);
    }
  }
  const fs::path work =
      fs::temp_directory_path() / ("digitize_rti_bench_" + std::to_string(::getpid()));
  fs::create_directories(work);
  std::string failure;
  for (RtiBasis basis : {RtiBasis::kPtm, RtiBasis::kHsh2, RtiBasis::kHsh3}) {
    auto r = ExportRows(fit_set, held, basis, work);
    if (!r.ok()) {
      failure = r.error().message;
      break;
    }
    rows.insert(rows.end(), r->begin(), r->end());
  }
  if (failure.empty() && run_digitize) {
    for (bool flat : {true, false}) {
      auto row = DigitizeRow(*all, work, flat);
      if (!row.ok()) {
        failure = row.error().message;
        break;
      }
      rows.push_back(*row);
    }
  }
  std::error_code ec;
  fs::remove_all(work, ec);  // the folder this run made, nothing else
  if (!failure.empty()) {
    std::fprintf(stderr, "%s\n", failure.c_str());
    return 1;
  }

  std::string table;
  char buf[256];
  std::snprintf(buf, sizeof buf, "%-13s %-7s %6s %9s %10s %10s %9s\n", "method", "fit_in", "coefs",
                "fit_s", "relight_s", "psnr_db", "mse");
  table += buf;
  for (const Row& r : rows) {
    std::snprintf(buf, sizeof buf, "%-13s %-7s %6d %9.3f %10.3f %10.2f %9.2f\n", r.method.c_str(),
                  r.encoding.c_str(), r.coefficients, r.fit_s, r.relight_s, r.psnr_db, r.mse);
    table += buf;
  }
  table +=
      "\nheld-out PSNR over 8-bit sRGB codes, pooled over all held-out images and channels (peak "
      "255);\nrelight_s: all held-out lights. ptm.ptm: the PTM written as a .ptm (LRGB, 8-bit) and "
      "read back;\n*.dir: written as a relight / OpenLIME folder (8-bit planes, JPEG 95) and read "
      "back.\ndigitize: FitToFolder (photos decoded, intensities, photometric-stereo normals, "
      "height,\n"
      "fit + one intensity refinement + refit; per-texel diffuse / Lafortune / GGX);\n"
      "digitize-flat: the flat canvas, no normals or intensities (the paper's RTI path).\n"
      "Reference, CNR-ISTI relight on this split (sRGB): "
      "hsh3 23.45 dB, ptm 21.22 dB.\n";
  std::printf("%s", table.c_str());

  if (!csv_dir.empty()) {
    fs::create_directories(csv_dir);
    std::ofstream csv(csv_dir / "bench_rti.csv");
    csv << "method,fit_in,coefficients,fit_s,relight_s,psnr_db,mse,pixels\n";
    for (const Row& r : rows) {
      std::snprintf(buf, sizeof buf, "%s,%s,%d,%.4f,%.4f,%.3f,%.3f,%zu\n", r.method.c_str(),
                    r.encoding.c_str(), r.coefficients, r.fit_s, r.relight_s, r.psnr_db, r.mse,
                    r.pixels);
      csv << buf;
    }
    std::ofstream txt(csv_dir / "bench_rti.txt");
    txt << "rti_bench on " << (data / "dirs.lp").string() << ": " << fit_set.photos.size()
        << " fitted, " << held.photos.size() << " held out\n\n"
        << table;
    std::printf("wrote %s and bench_rti.txt\n", (csv_dir / "bench_rti.csv").string().c_str());
  }
  return 0;
}
