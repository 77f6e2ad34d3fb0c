// A synthetic photo set on disk (photo_sim.h, WriteSyntheticPhotoSet): the calibration JSON that
// digitize::ReadCalibration reads, the encoded images, the held-out renders and masks, the truth.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>
#include <string>
#include <system_error>
#include <vector>

#include "digitize/image_io.h"
#include "digitize_synth/photo_sim.h"

namespace digitize::synth {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr int kMaterialsFormatVersion = 1;

json Vec(const Vec3d& v) { return {v.x(), v.y(), v.z()}; }
json Vec(const Vec3f& v) { return {v.x(), v.y(), v.z()}; }

json TransformJson(const RigidTransform& t) {
  json rows = json::array();
  for (int r = 0; r < 3; ++r)
    rows.push_back({t.rotation(r, 0), t.rotation(r, 1), t.rotation(r, 2)});
  return {{"rotation", rows}, {"translation_mm", Vec(t.translation)}};
}

// docs/formats.md, "Calibration JSON": numbers printed to round trip (nlohmann writes the
// shortest text that reads back to the same double).
json CameraJson(const Camera& c) {
  DIGITIZE_CHECK(c.model == CameraModel::kPinhole, "synthetic photo sets use pinhole cameras");
  return {{"model", "pinhole"}, {"width", c.width},
          {"height", c.height}, {"fx", c.fx},
          {"fy", c.fy},         {"cx", c.cx},
          {"cy", c.cy},         {"camera_from_scan", TransformJson(c.camera_from_scan)}};
}

json LightJson(const Light& l) {
  DIGITIZE_CHECK(l.type == LightType::kPoint, "synthetic photo sets use point lights");
  return {{"type", "point"}, {"position_mm", Vec(l.position_mm)}, {"intensity", Vec(l.intensity)}};
}

bool SameCamera(const Camera& a, const Camera& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy &&
         a.camera_from_scan.rotation == b.camera_from_scan.rotation &&
         a.camera_from_scan.translation == b.camera_from_scan.translation;
}
bool SameLight(const Light& a, const Light& b) {
  return a.position_mm == b.position_mm && a.intensity == b.intensity;
}

// Calibration of a photo set with shared camera and light lists (each distinct one listed once).
json CalibrationJson(const PhotoSet& set, const std::vector<std::string>& paths,
                     const char* encoding) {
  std::vector<const Camera*> cameras;
  std::vector<const Light*> lights;
  json images = json::array();
  for (size_t i = 0; i < set.photos.size(); ++i) {
    const Photo& p = set.photos[i];
    auto c = std::find_if(cameras.begin(), cameras.end(),
                          [&](const Camera* x) { return SameCamera(*x, p.camera); });
    if (c == cameras.end()) c = cameras.insert(cameras.end(), &p.camera);
    auto l = std::find_if(lights.begin(), lights.end(),
                          [&](const Light* x) { return SameLight(*x, p.light); });
    if (l == lights.end()) l = lights.insert(lights.end(), &p.light);
    images.push_back({{"path", paths[i]},
                      {"camera", c - cameras.begin()},
                      {"light", l - lights.begin()},
                      {"encoding", encoding}});
  }
  json cams = json::array(), ls = json::array();
  for (const Camera* c : cameras) cams.push_back(CameraJson(*c));
  for (const Light* l : lights) ls.push_back(LightJson(*l));
  return {{"format", "digitize.calibration"},
          {"version", 1},
          {"units", "mm"},
          {"cameras", cams},
          {"lights", ls},
          {"images", images}};
}

json OptionsJson(const PhotoSimOptions& o) {
  return {{"cameras", o.cameras},
          {"camera_arc_deg", o.camera_arc_deg},
          {"camera_distance_mm", o.camera_distance_mm},
          {"pixels_per_texel", o.pixels_per_texel},
          {"view_margin", o.view_margin},
          {"lights", o.lights},
          {"light_min_elevation_deg", o.light_min_elevation_deg},
          {"light_max_elevation_deg", o.light_max_elevation_deg},
          {"light_distance_mm", o.light_distance_mm},
          {"white_level", o.white_level},
          {"held_out_lights", o.held_out_lights},
          {"held_out_camera_deg", o.held_out_camera_deg},
          {"noise_sigma", o.noise_sigma},
          {"encoding", ToString(o.encoding)},
          {"jpeg_quality", o.jpeg_quality},
          {"grid_cols", o.grid_cols},
          {"grid_rows", o.grid_rows},
          {"grid_overlap", o.grid_overlap},
          {"shadows", o.shadows},
          {"frame_albedo", o.frame_albedo},
          {"seed", o.seed}};
}

json MaterialsJson(const SyntheticPhotoSet& set) {
  json list = json::array();
  for (size_t i = 0; i < set.materials.size(); ++i) {
    const PaintMaterial& m = set.materials[i];
    json j = {{"index", i}, {"name", m.name}};
    if (m.is_measured) {
      json lobes = json::array();
      for (const MeasuredLafortuneLobe& lobe : m.measured.lobes)
        lobes.push_back({{"cxy", Vec(lobe.cxy)}, {"cz", Vec(lobe.cz)}, {"n", Vec(lobe.n)}});
      j["model"] = "lafortune-measured";
      j["measured_name"] = m.measured.name;
      j["diffuse_albedo"] = Vec(m.measured.diffuse_albedo);
      j["lobes"] = lobes;
    } else if (m.is_ggx) {
      j["model"] = "ggx";
      j["rho_d"] = Vec(m.ggx.rho_d);
      j["f0"] = Vec(m.ggx.f0);
      j["alpha"] = m.ggx.alpha;
    } else {
      const LafortuneParams& p = m.lafortune;
      j["model"] = "lafortune-1";
      j["rho_d"] = Vec(p.rho_d);
      j["rho_s"] = Vec(p.rho_s);
      j["cx"] = p.cx;
      j["cy"] = p.cy;
      j["cz"] = p.cz;
      j["k"] = p.k;
    }
    list.push_back(j);
  }
  return {
      {"format", "digitize.synthetic_materials"},
      {"version", kMaterialsFormatVersion},
      {"units", "rho_d, rho_s: BRDF values (1/sr); diffuse_albedo: albedo (BRDF = albedo / pi)"},
      {"models",
       {{"lafortune-1",
         "f = rho_d + rho_s max(0, cx vx lx + cy vy ly + cz vz lz)^k, tangent frame "
         "(tangent_frame.h), cz = 1"},
        {"ggx",
         "f = rho_d + F(v.h) D(n.h) G1(n.v) G1(n.l) / (4 n.v n.l): GGX, Schlick F0, Smith "
         "(ggx.h), tangent frame"},
        {"lafortune-measured",
         "f = diffuse_albedo / pi + sum_i max(0, cxy_i (vx lx + vy ly) + cz_i vz lz)^n_i"}}},
      {"region_rule", "texel material = paint region % material count (material.png)"},
      {"materials", list}};
}

std::string Numbered(const char* stem, size_t i, const char* ext) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%s%03zu.%s", stem, i, ext);
  return buf;
}

// Linear value of every code, as SimulatePhotoSet and the reader (photo_set.cpp) compute it.
std::vector<float> SrgbTable(int max_code) {
  std::vector<float> table(static_cast<size_t>(max_code) + 1);
  for (int i = 0; i <= max_code; ++i) {
    const double c = double(i) / max_code;
    table[i] = static_cast<float>(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
  }
  return table;
}

// The sRGB codes of linear values that SimulatePhotoSet took from the code table: each is found
// in the (increasing) table exactly; a value between entries gets the nearer code.
template <class T>
std::vector<T> SrgbCodes(const Grid<Vec3f>& rgb, int max_code) {
  static const std::vector<float> table8 = SrgbTable(255), table16 = SrgbTable(65535);
  const std::vector<float>& table = max_code == 255 ? table8 : table16;
  std::vector<T> codes(rgb.size() * 3);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, rgb.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t i = r.begin(); i != r.end(); ++i) {
                        for (int k = 0; k < 3; ++k) {
                          const float x = rgb.data[i][k];
                          auto it = std::lower_bound(table.begin(), table.end(), x);
                          if (it == table.end()) {
                            --it;
                          } else if (it != table.begin() && x - *(it - 1) < *it - x) {
                            --it;
                          }
                          codes[3 * i + k] = static_cast<T>(it - table.begin());
                        }
                      }
                    });
  return codes;
}

Status WritePhoto(const fs::path& path, const Photo& photo, const PhotoSimOptions& options) {
  const Grid<Vec3f>& rgb = photo.rgb;
  const PhotoEncoding encoding = options.encoding;
  if (encoding == PhotoEncoding::kLinearExr) {
    return WriteFloatExr(path, rgb, {"R", "G", "B"}, {{"digitize:quantity", "linear radiance"}});
  }
  if (encoding == PhotoEncoding::kJpeg) {
    const auto codes = SrgbCodes<uint8_t>(rgb, 255);
    Grid<std::array<uint8_t, 3>> image(rgb.width, rgb.height);
    std::memcpy(image.data.data(), codes.data(), codes.size());
    return WriteJpegRgb8(path, image, options.jpeg_quality);
  }
  // zlib level 3 instead of OIIO's 6: 3x faster (0.09 s a megapixel instead of 0.27 s) for
  // files 4 % larger; 64 such images are most of what `digitize synth --photos` spends writing.
  constexpr int kZlibLevel = 3;
  if (encoding == PhotoEncoding::kSrgb8) {
    const auto codes = SrgbCodes<uint8_t>(rgb, 255);
    return WriteSrgbPng(path, rgb.width, rgb.height, 8, codes.data(), kZlibLevel);
  }
  const auto codes = SrgbCodes<uint16_t>(rgb, 65535);
  return WriteSrgbPng(path, rgb.width, rgb.height, 16, codes.data(), kZlibLevel);
}

Status CreateDir(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error{dir.string() + ": cannot create the folder: " + ec.message()};
  return Status::Ok();
}

// Writes n files in parallel (TBB); returns the first error in file order.
template <class Write>
Status WriteAll(size_t n, Write write) {
  std::vector<Status> status(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) status[i] = write(i);
  });
  for (const Status& s : status) {
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

const char* FitExtension(PhotoEncoding e) {
  return e == PhotoEncoding::kLinearExr ? "exr" : e == PhotoEncoding::kJpeg ? "jpg" : "png";
}
std::string FitPath(const PhotoSimOptions& o, size_t i) {
  return "images/" + Numbered("img_", i, FitExtension(o.encoding));
}
std::string HeldPath(size_t i) { return Numbered("img_", i, "exr"); }
std::string MaskPath(size_t i) { return Numbered("mask_", i, "png"); }

Status CreateFolders(const fs::path& dir) {
  for (const fs::path& d : {dir, dir / "images", dir / "held_out", dir / "truth"}) {
    if (Status s = CreateDir(d); !s.ok()) return s;
  }
  return Status::Ok();
}

// One image of the set where WriteSyntheticPhotoSet puts it (a held-out one with its mask).
Status WriteImage(const fs::path& dir, const PhotoSimOptions& options, const Photo& photo,
                  const Grid<uint8_t>* held_out_mask, size_t index) {
  if (!held_out_mask) return WritePhoto(dir / FitPath(options, index), photo, options);
  PhotoSimOptions linear = options;
  linear.encoding = PhotoEncoding::kLinearExr;
  if (Status w = WritePhoto(dir / "held_out" / HeldPath(index), photo, linear); !w.ok()) return w;
  Grid<uint8_t> mask = *held_out_mask;
  for (uint8_t& m : mask.data) m = m ? 255 : 0;
  return WritePng8(dir / "held_out" / MaskPath(index), mask);
}

// Everything but the images: the truth, then the calibrations (last: their presence says the
// images beside them are complete).
Status WriteTruthAndCalibration(const fs::path& dir, const SyntheticPhotoSet& set);

}  // namespace

Status WriteSyntheticPhotoSet(const fs::path& dir, const SyntheticPhotoSet& set) {
  if (set.pixels_released)
    return Error{dir.string() + ": the photo set's pixels were handed to a sink; nothing to write"};
  if (Status s = CreateFolders(dir); !s.ok()) return s;
  if (Status s = WriteAll(
          set.fit.photos.size(),
          [&](size_t i) { return WriteImage(dir, set.options, set.fit.photos[i], nullptr, i); });
      !s.ok())
    return s;
  if (Status s = WriteAll(set.held_out.photos.size(),
                          [&](size_t i) {
                            return WriteImage(dir, set.options, set.held_out.photos[i],
                                              &set.held_out_mask[i], i);
                          });
      !s.ok())
    return s;
  return WriteTruthAndCalibration(dir, set);
}

Status RenderSyntheticPhotoSet(const fs::path& dir, const Scene& scene,
                               const RigidTransform& canvas_from_scan,
                               const PhotoSimOptions& options, std::vector<PaintMaterial> materials,
                               const ProgressCallback& progress, SyntheticPhotoSet* summary) {
  if (Status s = CreateFolders(dir); !s.ok()) return s;
  SyntheticPhotoSet set =
      SimulatePhotoSet(scene, canvas_from_scan, options, std::move(materials), progress,
                       [&](const Photo& photo, const Grid<uint8_t>* mask, int index) {
                         return WriteImage(dir, options, photo, mask, static_cast<size_t>(index));
                       });
  if (!set.sink_status.ok()) return set.sink_status;
  if (Status s = WriteTruthAndCalibration(dir, set); !s.ok()) return s;
  if (summary) *summary = std::move(set);
  return Status::Ok();
}

namespace {

Status WriteTruthAndCalibration(const fs::path& dir, const SyntheticPhotoSet& set) {
  const bool exr = set.options.encoding == PhotoEncoding::kLinearExr;
  std::vector<std::string> paths, held_paths, mask_paths;
  for (size_t i = 0; i < set.fit.photos.size(); ++i) paths.push_back(FitPath(set.options, i));
  for (size_t i = 0; i < set.held_out.photos.size(); ++i) {
    held_paths.push_back(HeldPath(i));
    mask_paths.push_back(MaskPath(i));
  }

  // Truth on the painting's texel grid, a map at a time from each texel's material (a set
  // rendered into a sink keeps no truth maps; a set in memory holds the same values).
  const ReflectanceMaps of_material = MaterialTruth(set.materials);
  const Grid<uint8_t>& material = set.material_index;
  const auto map_of = [&](const auto& value) {
    Grid<Vec3f> g(material.width, material.height);
    for (size_t i = 0; i < g.size(); ++i) g.data[i] = value(material.data[i]);
    return g;
  };
  const ImageMetadata meta = {{"digitize:frame", "canvas texel grid (row 0 = top)"},
                              {"digitize:units", "1/sr"}};
  if (Status s = WriteFloatExr(dir / "truth" / "rho_d.exr",
                               map_of([&](int m) { return of_material.rho_d(m, 0); }),
                               {"R", "G", "B"}, meta);
      !s.ok())
    return s;
  if (Status s = WriteFloatExr(dir / "truth" / "rho_s.exr",
                               map_of([&](int m) { return of_material.rho_s(m, 0); }),
                               {"R", "G", "B"}, meta);
      !s.ok())
    return s;
  {
    // cz is 1 everywhere (the stored gauge): three channels, which every reader here opens.
    const Grid<Vec3f> lobe = map_of([&](int m) {
      const auto& c = of_material.lobe(m, 0);
      return Vec3f(c[0], c[1], c[3]);
    });
    const ImageMetadata lobe_meta = {
        {"digitize:frame", "canvas texel grid (row 0 = top)"},
        {"digitize:quantity",
         "Lafortune lobe cx, cy, k (cz = 1), tangent frame (tangent_frame.h)"}};
    if (Status s = WriteFloatExr(dir / "truth" / "lobe.exr", lobe, {"cx", "cy", "k"}, lobe_meta);
        !s.ok())
      return s;
  }
  if (Status s = WritePng8(dir / "truth" / "material.png", set.material_index); !s.ok()) return s;
  if (Status s = WriteTextFile(dir / "truth" / "materials.json", MaterialsJson(set).dump(2) + "\n");
      !s.ok())
    return s;

  // Calibrations last: their presence says the images beside them are complete.
  json held = CalibrationJson(set.held_out, held_paths, "linear");
  held["masks"] = mask_paths;
  held["comment"] =
      "held-out renders: noise-free linear radiance; masks: 255 where the pixel shows a canvas "
      "texel that no frame shadow darkens";
  if (!set.held_out.photos.empty()) {
    if (Status s = WriteTextFile(dir / "held_out" / "calib.json", held.dump(2) + "\n"); !s.ok())
      return s;
  }
  json fit = CalibrationJson(set.fit, paths, exr ? "linear" : "srgb");
  fit["generator"] = {{"name", "digitize synth (SimulatePhotoSet)"},
                      {"options", OptionsJson(set.options)},
                      {"canvas_from_scan", TransformJson(set.canvas_from_scan)},
                      {"held_out", set.held_out.photos.empty() ? "" : "held_out/calib.json"},
                      {"truth", "truth/"}};
  return WriteTextFile(dir / "calib.json", fit.dump(2) + "\n");
}

}  // namespace
}  // namespace digitize::synth
