#include "digitize/tile_plan.h"

#include <OpenImageIO/hash.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <nlohmann/json.hpp>

#include "digitize/image_io.h"
#include "digitize/output_dir.h"
#include "digitize/pack_tiled.h"
#include "digitize/pipeline.h"
#include "digitize/preprocess.h"
#include "json_fields.h"

namespace digitize {
namespace fs = std::filesystem;
using nlohmann::json;

// Every option of the fit travels in the plan, so a field added to one of these structs must be
// added to the plan's JSON below (and to docs/formats.md) or tiles would be fitted with its
// default: these sizes make that a compile error, not a silent difference.
static_assert(sizeof(TraceOptions) == 24, "carry the new TraceOptions field in the tile plan");
static_assert(sizeof(SampleOptions) == 56, "carry the new SampleOptions field in the tile plan");
static_assert(sizeof(BrdfFitOptions) == 128, "carry the new BrdfFitOptions field in the plan");
static_assert(sizeof(ReflectanceFitOptions) == 232, "carry the new fit option in the tile plan");
static_assert(sizeof(PackWriteOptions) == 24, "carry the new pack option in the tile plan");

fs::path TilePlan::TileFolder(size_t index) const {
  char name[32];
  std::snprintf(name, sizeof name, "tile_%05zu", index);
  return work / name;
}

std::vector<TexelRect> TileGrid(int width, int height, int tile_size) {
  std::vector<TexelRect> tiles;
  if (width <= 0 || height <= 0 || tile_size <= 0) return tiles;
  for (int y = 0; y < height; y += tile_size)
    for (int x = 0; x < width; x += tile_size)
      tiles.push_back({x, y, std::min(tile_size, width - x), std::min(tile_size, height - y)});
  return tiles;
}

namespace {

// JSON has no infinity: an unbounded level is written as null.
json NumberOrNull(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
double NumberOrInfinity(const Fields& f, const std::string& key) {
  return f.Get(key).is_null() ? std::numeric_limits<double>::infinity() : f.Number(key);
}

json OptionsJson(const TilePlan& p) {
  const SampleOptions& s = p.fit.samples;
  const BrdfFitOptions& b = p.fit.fit;
  const ReflectanceFitOptions& r = p.fit;
  return {{"photo",
           {{"saturation_encoded", p.photo.saturation_encoded},
            {"float_saturation_level", NumberOrNull(p.photo.float_saturation_level)},
            {"max_non_finite_fraction", p.photo.max_non_finite_fraction},
            {"max_pixels_per_image", p.photo.max_pixels_per_image},
            {"allow_outside_paths", p.photo.allow_outside_paths}}},
          {"samples",
           {{"min_cos", s.min_cos},
            {"black_level", s.black_level},
            {"reject_black", s.reject_black},
            {"visibility_rays", s.visibility_rays},
            {"shadow_rays", s.shadow_rays},
            {"min_direct_samples", s.min_direct_samples},
            {"share_view_rays", s.share_view_rays},
            {"horizon_sectors", s.horizon_sectors},
            {"skip_unblockable", s.trace.skip_unblockable},
            {"origin_offset_mm", s.trace.origin_offset_mm}}},
          {"brdf",
           {{"method", b.method == BrdfFitMethod::kFast ? "fast" : "ceres"},
            {"min_samples", b.min_samples},
            {"noise_sigma", b.noise_sigma},
            {"diffuse_chi2_sigmas", b.diffuse_chi2_sigmas},
            {"saturation_radiance", NumberOrNull(b.saturation_radiance)},
            {"k_min", b.k_min},
            {"k_max", b.k_max},
            {"max_specular_albedo", b.max_specular_albedo},
            {"lobe_prior_weight", b.lobe_prior_weight},
            {"specular_prior_weight", b.specular_prior_weight},
            {"max_iterations", b.max_iterations},
            {"fit_lafortune", b.fit_lafortune},
            {"fit_ggx", b.fit_ggx},
            {"ggx_alpha_min", b.ggx_alpha_min},
            {"ggx_alpha_max", b.ggx_alpha_max},
            {"model_penalty_per_parameter", b.model_penalty_per_parameter},
            {"photo_code_max", b.photo_code_max},
            {"photo_codes_srgb", b.photo_codes_srgb},
            {"photo_compression_sigma_codes", b.photo_compression_sigma_codes}}},
          {"fit",
           {{"tile_texels", r.tile_texels},
            {"pixel_texel_maps", r.pixel_texel_maps},
            {"dark_outlier_ratio", r.dark_outlier_ratio},
            {"dark_outlier_fit_ratio", r.dark_outlier_fit_ratio},
            {"dark_outlier_sigmas", r.dark_outlier_sigmas},
            {"dark_outlier_rounds", r.dark_outlier_rounds},
            {"quantisation_from_photos", r.quantisation_from_photos},
            {"jpeg_sigma_codes", r.jpeg_sigma_codes}}},
          {"pack",
           {{"encoding", ToString(p.pack.encoding)},
            {"height_bits", p.pack.quantisation.height_bits},
            {"normal_bits", p.pack.quantisation.normal_bits},
            {"rho_bits", p.pack.quantisation.rho_bits},
            {"lobe_bits", p.pack.quantisation.lobe_bits},
            {"tile_size", p.pack.tile_size}}}};
}

void ReadOptions(const Fields& o, TilePlan& p) {
  o.OnlyKeys({"photo", "samples", "brdf", "fit", "pack"});
  const Fields photo = o.Object("photo");
  photo.OnlyKeys({"saturation_encoded", "float_saturation_level", "max_non_finite_fraction",
                  "max_pixels_per_image", "allow_outside_paths"});
  p.photo.saturation_encoded = static_cast<float>(photo.Number("saturation_encoded"));
  p.photo.float_saturation_level =
      static_cast<float>(NumberOrInfinity(photo, "float_saturation_level"));
  p.photo.max_non_finite_fraction = photo.Number("max_non_finite_fraction");
  p.photo.max_pixels_per_image =
      static_cast<size_t>(photo.Integer("max_pixels_per_image", 1, int64_t{1} << 40));
  p.photo.allow_outside_paths = photo.Boolean("allow_outside_paths");

  const Fields s = o.Object("samples");
  s.OnlyKeys({"min_cos", "black_level", "reject_black", "visibility_rays", "shadow_rays",
              "min_direct_samples", "share_view_rays", "horizon_sectors", "skip_unblockable",
              "origin_offset_mm"});
  SampleOptions& so = p.fit.samples;
  so.min_cos = s.Number("min_cos");
  so.black_level = static_cast<float>(s.Number("black_level"));
  so.reject_black = s.Boolean("reject_black");
  so.visibility_rays = s.Boolean("visibility_rays");
  so.shadow_rays = s.Boolean("shadow_rays");
  so.min_direct_samples = static_cast<int>(s.Integer("min_direct_samples", 0, 1 << 20));
  so.share_view_rays = s.Boolean("share_view_rays");
  so.horizon_sectors = static_cast<int>(s.Integer("horizon_sectors", 0, 32));
  so.trace.skip_unblockable = s.Boolean("skip_unblockable");
  so.trace.origin_offset_mm = s.Number("origin_offset_mm");

  const Fields b = o.Object("brdf");
  b.OnlyKeys({"method", "min_samples", "noise_sigma", "diffuse_chi2_sigmas", "saturation_radiance",
              "k_min", "k_max", "max_specular_albedo", "lobe_prior_weight", "specular_prior_weight",
              "max_iterations", "fit_lafortune", "fit_ggx", "ggx_alpha_min", "ggx_alpha_max",
              "model_penalty_per_parameter", "photo_code_max", "photo_codes_srgb",
              "photo_compression_sigma_codes"});
  BrdfFitOptions& bo = p.fit.fit;
  const std::string method = b.String("method");
  if (method != "fast" && method != "ceres")
    Fail(b.At("method") + " must be \"fast\" or \"ceres\", got " + Show(method));
  bo.method = method == "fast" ? BrdfFitMethod::kFast : BrdfFitMethod::kCeresReference;
  bo.min_samples = static_cast<int>(b.Integer("min_samples", 0, 1 << 20));
  bo.noise_sigma = b.Number("noise_sigma");
  bo.diffuse_chi2_sigmas = b.Number("diffuse_chi2_sigmas");
  bo.saturation_radiance = NumberOrInfinity(b, "saturation_radiance");
  bo.k_min = b.Number("k_min");
  bo.k_max = b.Number("k_max");
  bo.max_specular_albedo = b.Number("max_specular_albedo");
  bo.lobe_prior_weight = b.Number("lobe_prior_weight");
  bo.specular_prior_weight = b.Number("specular_prior_weight");
  bo.max_iterations = static_cast<int>(b.Integer("max_iterations", 0, 1 << 20));
  bo.fit_lafortune = b.Boolean("fit_lafortune");
  bo.fit_ggx = b.Boolean("fit_ggx");
  bo.ggx_alpha_min = b.Number("ggx_alpha_min");
  bo.ggx_alpha_max = b.Number("ggx_alpha_max");
  bo.model_penalty_per_parameter = b.Number("model_penalty_per_parameter");
  bo.photo_code_max = static_cast<int>(b.Integer("photo_code_max", 0, 65535));
  bo.photo_codes_srgb = b.Boolean("photo_codes_srgb");
  bo.photo_compression_sigma_codes = b.Number("photo_compression_sigma_codes");

  const Fields f = o.Object("fit");
  f.OnlyKeys({"tile_texels", "pixel_texel_maps", "dark_outlier_ratio", "dark_outlier_fit_ratio",
              "dark_outlier_sigmas", "dark_outlier_rounds", "quantisation_from_photos",
              "jpeg_sigma_codes"});
  ReflectanceFitOptions& r = p.fit;
  r.tile_texels = static_cast<int>(f.Integer("tile_texels", 1, 1 << 30));
  r.pixel_texel_maps = f.Boolean("pixel_texel_maps");
  r.dark_outlier_ratio = f.Number("dark_outlier_ratio");
  r.dark_outlier_fit_ratio = f.Number("dark_outlier_fit_ratio");
  r.dark_outlier_sigmas = f.Number("dark_outlier_sigmas");
  r.dark_outlier_rounds = static_cast<int>(f.Integer("dark_outlier_rounds", 0, 10));
  r.quantisation_from_photos = f.Boolean("quantisation_from_photos");
  r.jpeg_sigma_codes = f.Number("jpeg_sigma_codes");

  const Fields k = o.Object("pack");
  k.OnlyKeys({"encoding", "height_bits", "normal_bits", "rho_bits", "lobe_bits", "tile_size"});
  const std::string encoding = k.String("encoding");
  if (encoding != ToString(PackEncoding::kHalf) && encoding != ToString(PackEncoding::kQuantised))
    Fail(k.At("encoding") + " must be \"half\" or \"quantised\", got " + Show(encoding));
  p.pack.encoding =
      encoding == ToString(PackEncoding::kHalf) ? PackEncoding::kHalf : PackEncoding::kQuantised;
  p.pack.quantisation.height_bits = static_cast<int>(k.Integer("height_bits", 0, 10));
  p.pack.quantisation.normal_bits = static_cast<int>(k.Integer("normal_bits", 0, 10));
  p.pack.quantisation.rho_bits = static_cast<int>(k.Integer("rho_bits", 0, 10));
  p.pack.quantisation.lobe_bits = static_cast<int>(k.Integer("lobe_bits", 0, 10));
  // Plans written before tiled packs: a single-grid pack.
  p.pack.tile_size = k.Has("tile_size") ? static_cast<int>(k.Integer("tile_size", 0, 4096)) : 0;
  if (p.pack.tile_size != 0)
    if (Status s = CheckPackTileSize(p.pack.tile_size); !s.ok())
      Fail(k.At("tile_size") + ": " + s.message());
}

// The plan without its id: what the id is the digest of.
json PlanContent(const TilePlan& p) {
  json tiles = json::array();
  for (const TexelRect& t : p.tiles) tiles.push_back({t.x, t.y, t.width, t.height});
  return {{"format", kTilePlanFormat},
          {"version", kTilePlanVersion},
          {"canvas", p.canvas.string()},
          {"photos", p.photos.string()},
          {"out", p.out.string()},
          {"work", p.work.string()},
          {"canvas_size", {p.canvas_width, p.canvas_height}},
          {"tile_size", p.tile_size},
          {"height_range_mm", {p.min_height_mm, p.max_height_mm}},
          {"options", OptionsJson(p)},
          {"tiles", tiles}};
}

std::string Digest(const json& content) {
  const std::string text = content.dump();
  OIIO::SHA1 sha(text.data(), text.size());
  return sha.digest();
}

fs::path AbsolutePath(const Fields& f, const std::string& key) {
  const std::string path = f.String(key);
  if (path.empty() || !fs::path(path).is_absolute())
    Fail(f.At(key) + " must be an absolute path, got " + Show(path));
  return path;
}

}  // namespace

std::string TilePlanJson(const TilePlan& plan) {
  json doc = PlanContent(plan);
  doc["id"] = Digest(doc);
  return doc.dump(2) + "\n";
}

Result<TilePlan> ReadTilePlan(const fs::path& file) {
  auto text = ReadTextFile(file, "tile plan");
  if (!text.ok()) return text.error();
  const std::string where = file.string();
  auto plan = CatchBadInput([&]() {
    const json doc = ParseJson(*text, where);
    const Fields f(doc, where);
    if (!f.Has("format") || !f.Get("format").is_string() || f.String("format") != kTilePlanFormat)
      Fail(where + ": not a tile plan (\"format\" must be \"" + kTilePlanFormat +
           "\"; write one with `digitize tiles plan`)");
    const int64_t version = f.Integer("version", 0, 1 << 20);
    if (version != kTilePlanVersion)
      Fail(where + ": tile plan version " + std::to_string(version) + "; this build reads " +
           std::to_string(kTilePlanVersion));
    f.OnlyKeys({"format", "version", "canvas", "photos", "out", "work", "canvas_size", "tile_size",
                "height_range_mm", "options", "tiles", "id"});
    TilePlan p;
    p.file = ResolvePath(file);
    p.canvas = AbsolutePath(f, "canvas");
    p.photos = AbsolutePath(f, "photos");
    p.out = AbsolutePath(f, "out");
    p.work = AbsolutePath(f, "work");
    const json& size = f.Array("canvas_size");
    if (size.size() != 2 || !size[0].is_number_integer() || !size[1].is_number_integer())
      Fail(f.At("canvas_size") + " must be [width, height], got " + Show(size));
    p.canvas_width = size[0].get<int>();
    p.canvas_height = size[1].get<int>();
    const json& range = f.Array("height_range_mm");
    if (range.size() != 2 || !range[0].is_number() || !range[1].is_number())
      Fail(f.At("height_range_mm") + " must be [lowest, highest], got " + Show(range));
    p.min_height_mm = range[0].get<double>();
    p.max_height_mm = range[1].get<double>();
    if (!(p.min_height_mm <= p.max_height_mm && p.min_height_mm >= -kMaxPackHeightMm &&
          p.max_height_mm <= kMaxPackHeightMm))
      Fail(f.At("height_range_mm") + " must be [lowest, highest] within +-" +
           FormatNumber(kMaxPackHeightMm) + " mm, got " + Show(range));
    constexpr int kMaxSide = 1 << 20;
    if (p.canvas_width < 1 || p.canvas_height < 1 || p.canvas_width > kMaxSide ||
        p.canvas_height > kMaxSide)
      Fail(f.At("canvas_size") + " out of bounds [1, " + std::to_string(kMaxSide) +
           "]: " + Show(size));
    p.tile_size = static_cast<int>(f.Integer("tile_size", kMinTileSize, kMaxTileSize));
    const size_t count = static_cast<size_t>((p.canvas_width + p.tile_size - 1) / p.tile_size) *
                         static_cast<size_t>((p.canvas_height + p.tile_size - 1) / p.tile_size);
    if (count > kMaxPlanTiles)
      Fail(where + ": " + std::to_string(count) + " tiles, more than the " +
           std::to_string(kMaxPlanTiles) + " a plan may have");
    ReadOptions(f.Object("options"), p);
    p.tiles = TileGrid(p.canvas_width, p.canvas_height, p.tile_size);
    const json& tiles = f.Array("tiles");
    if (tiles.size() != p.tiles.size())
      Fail(f.At("tiles") + ": " + std::to_string(tiles.size()) + " tiles; a " +
           std::to_string(p.canvas_width) + " x " + std::to_string(p.canvas_height) +
           " canvas in tiles of " + std::to_string(p.tile_size) + " has " +
           std::to_string(p.tiles.size()));
    for (size_t i = 0; i < tiles.size(); ++i) {
      const TexelRect& t = p.tiles[i];
      if (tiles[i] != json{t.x, t.y, t.width, t.height})
        Fail(f.At("tiles") + "[" + std::to_string(i) + "] is " + Show(tiles[i]) + ", expected " +
             Show(json{t.x, t.y, t.width, t.height}) + " (tiles are the canvas cut row by row)");
    }
    for (const Status& s : {p.photo.Validate(), p.fit.Validate(), p.pack.Validate()})
      if (!s.ok()) Fail(where + ": options: " + s.message());
    p.id = f.String("id");
    if (p.id != Digest(PlanContent(p)))
      Fail(where +
           ": \"id\" does not match the plan's content (edited by hand?): make a new "
           "plan with `digitize tiles plan`");
    return p;
  });
  if (!plan.ok()) return plan.error();
  return plan;
}

Result<TilePlan> MakeTilePlan(const TilePlanOptions& options) {
  if (options.tile_size < kMinTileSize || options.tile_size > kMaxTileSize)
    return Error{"tile size must be in [" + std::to_string(kMinTileSize) + ", " +
                 std::to_string(kMaxTileSize) + "] texels, got " +
                 std::to_string(options.tile_size)};
  if (Status s = options.photo.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = options.fit.Validate(); !s.ok()) return Error{s.message()};
  if (Status s = options.pack.Validate(); !s.ok()) return Error{s.message()};
  if (options.canvas.empty()) return Error{"a tile plan needs a canvas folder (--canvas)"};
  if (options.plan.empty() || options.out.empty())
    return Error{"a tile plan needs its file (--plan) and the pack to merge into (--out)"};
  const fs::path photos_ext = fs::path(options.photos).extension();
  if (photos_ext == ".lp" || photos_ext == ".LP")
    return Error{options.photos +
                 ": an RTI capture is one image grid: fit it untiled (`digitize fit`)"};

  TilePlan p;
  p.canvas = ResolvePath(options.canvas);
  p.photos = ResolvePath(options.photos);
  p.out = ResolvePath(options.out);
  p.file = ResolvePath(options.plan);
  std::string work = options.work;
  if (work.empty()) {
    fs::path stem = p.file;
    if (stem.extension() == ".json") stem.replace_extension();
    work = stem.string() + ".tiles";
  }
  p.work = ResolvePath(work);
  p.tile_size = options.tile_size;
  p.photo = options.photo;
  p.fit = options.fit;
  p.fit.fit.num_threads = 0;
  p.fit.samples.trace.num_threads = 0;
  p.pack = options.pack;

  if (Status s = CheckCanvasFolder(p.canvas); !s.ok()) return Error{s.message()};
  auto header = ReadImageHeader(p.canvas / "height.exr");
  if (!header.ok()) return header.error();
  p.canvas_width = header->width;
  p.canvas_height = header->height;
  // The height range in strips of rows through a bounded cache: the plan of a canvas larger than
  // memory is made in bounded memory too.
  {
    ImageRegionReader reader(256);
    constexpr int kStripRows = 256;
    p.min_height_mm = std::numeric_limits<double>::infinity();
    p.max_height_mm = -std::numeric_limits<double>::infinity();
    for (int y = 0; y < p.canvas_height; y += kStripRows) {
      const int rows = std::min(kStripRows, p.canvas_height - y);
      auto strip = reader.Read(p.canvas / "height.exr", 0, y, p.canvas_width, rows);
      if (!strip.ok()) return strip.error();
      for (float z : strip->pixels) {
        if (!std::isfinite(z))
          return Error{(p.canvas / "height.exr").string() + ": a non-finite height (row " +
                       std::to_string(y) + " or below)"};
        p.min_height_mm = std::min(p.min_height_mm, static_cast<double>(z));
        p.max_height_mm = std::max(p.max_height_mm, static_cast<double>(z));
      }
    }
  }
  PhotoSetOptions headers_only = p.photo;
  headers_only.load_pixels = false;
  auto set = ReadPhotoSetFile(p.photos, headers_only);
  if (!set.ok()) return set.error();
  if (set->is_rti)
    return Error{p.photos.string() +
                 ": an RTI capture is one image grid: fit it untiled (`digitize fit`)"};
  const std::vector<fs::path> inputs = {p.canvas, p.photos};
  for (const fs::path& out : {p.file, p.work, p.out})
    if (Status s = CheckOutputPath(out, inputs); !s.ok()) return Error{s.message()};
  if (IsWithinFolder(p.file, p.work) || IsWithinFolder(p.out, p.work))
    return Error{p.work.string() + ": the work folder must not hold the plan or the pack"};
  if (fs::exists(p.file)) {
    auto old = ReadTextFile(p.file, "tile plan");
    if (!old.ok()) return old.error();
    if (old->find(std::string("\"") + kTilePlanFormat + "\"") == std::string::npos)
      return Error{p.file.string() +
                   ": exists and is not a tile plan: not replaced (choose another --plan)"};
  }
  p.tiles = TileGrid(p.canvas_width, p.canvas_height, p.tile_size);
  if (p.tiles.size() > kMaxPlanTiles)
    return Error{std::to_string(p.tiles.size()) + " tiles, more than " +
                 std::to_string(kMaxPlanTiles) + ": choose a larger --tile-size"};
  const json content = PlanContent(p);
  p.id = Digest(content);
  if (Status s = WriteTextFile(p.file, TilePlanJson(p)); !s.ok()) return Error{s.message()};
  return p;
}

}  // namespace digitize
