// The patch list `digitize preprocess --patches` reads and the registration report it writes
// (preprocess.h, docs/formats.md).
#include <Eigen/Geometry>
#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>

#include "digitize/image_io.h"
#include "digitize/preprocess.h"
#include "json_fields.h"
#include "options_json.h"

namespace digitize {

Result<std::vector<PatchListEntry>> ReadPatchList(const std::filesystem::path& path) {
  Result<std::string> text = ReadTextFile(path, "patch list");
  if (!text.ok()) return text.error();
  const std::string where = path.string();
  return CatchBadInput([&] {
    const nlohmann::json doc = ParseJson(*text, where);
    const Fields top(doc, where);
    top.OnlyKeys({"format", "version", "frame", "units", "patches"});
    if (top.String("format") != "digitize.scan_patches")
      Fail(top.At("format") + " must be \"digitize.scan_patches\", got \"" + top.String("format") +
           "\"");
    top.Integer("version", 1, 1);
    if (top.Has("units") && top.String("units") != "mm")
      Fail(top.At("units") + " must be \"mm\", got \"" + top.String("units") + "\"");
    const nlohmann::json& list = top.Array("patches");
    std::vector<PatchListEntry> out;
    for (size_t i = 0; i < list.size(); ++i) {
      const std::string at = top.At("patches") + "[" + std::to_string(i) + "]";
      const Fields f(list[i], at);
      f.OnlyKeys({"scan", "rig_from_scan"});
      PatchListEntry e;
      const std::string scan = f.String("scan");
      if (scan.empty()) Fail(f.At("scan") + " must name a scan file");
      e.scan = std::filesystem::path(scan).is_absolute() ? std::filesystem::path(scan)
                                                         : path.parent_path() / scan;
      e.rig_from_scan = TransformFrom(f.Object("rig_from_scan"));
      const Mat3d& r = e.rig_from_scan.rotation;
      if (!(r.transpose() * r).isApprox(Mat3d::Identity(), 1e-6) || !(r.determinant() > 0))
        Fail(f.At("rig_from_scan") + ".rotation is not a rotation (R^T R != I or det <= 0)");
      out.push_back(std::move(e));
    }
    return out;
  });
}

std::string PatchRegistrationJson(const PatchRegistrationResult& r,
                                  const std::vector<std::string>& sources) {
  using nlohmann::json;
  auto name = [&](size_t i) { return i < sources.size() ? sources[i] : r.patches[i].source; };
  json patches = json::array();
  for (size_t i = 0; i < r.patches.size(); ++i) {
    const PatchReport& p = r.patches[i];
    patches.push_back({{"scan", name(i)},
                       {"rig_from_scan", ToJson(p.rig_from_scan)},
                       {"correction_deg", p.correction_deg},
                       {"correction_mm", p.correction_mm},
                       {"max_correction_mm", p.max_correction_mm},
                       {"correlation_pieces", p.correlation_pieces},
                       {"correlation_peak", p.correlation_peak},
                       {"icp_rounds", p.icp_rounds},
                       {"canvas_points", p.canvas_points},
                       {"outline_fitted", p.outline_fitted}});
  }
  json overlaps = json::array();
  for (const OverlapResidual& o : r.overlaps)
    overlaps.push_back(
        {{"patches", {o.patch_a, o.patch_b}},
         {"scans", {name(static_cast<size_t>(o.patch_a)), name(static_cast<size_t>(o.patch_b))}},
         {"texels", o.texels},
         {"rms_mm", o.rms_mm},
         {"max_mm", o.max_mm},
         {"mean_mm", o.mean_mm}});
  const json doc = {{"format", "digitize.patch_registration"},
                    {"version", 1},
                    {"units", "mm, degrees; texels counted on the canvas grid"},
                    {"frame", "rig (the patch list's frame); patch 0 keeps its nominal pose"},
                    {"canvas_from_rig", ToJson(r.canvas.canvas_from_scan)},
                    {"pitch_mm", r.field.pitch_mm},
                    {"uncovered_texels", r.uncovered_texels},
                    {"brief", r.brief},
                    {"patches", patches},
                    {"overlaps", overlaps}};
  return doc.dump(2) + "\n";
}

}  // namespace digitize
