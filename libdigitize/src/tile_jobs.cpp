#include "digitize/tile_jobs.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <memory>
#include <nlohmann/json.hpp>

#include "digitize/image_io.h"
#include "digitize/output_dir.h"
#include "digitize/pack_tiled.h"
#include "digitize/pipeline.h"
#include "digitize/preprocess.h"
#include "digitize/provenance.h"
#include "json_fields.h"

namespace digitize {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

using Clock = std::chrono::steady_clock;
double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::string Format(const char* fmt, auto... args) {
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer), fmt, args...);
  return buffer;
}

constexpr const char* kTileResultFormat = "digitize.tile_result";
constexpr const char* kTileResultFile = "tile.json";

std::string IndexList(const std::vector<size_t>& indices, size_t at_most = 12) {
  std::string s;
  for (size_t i = 0; i < indices.size() && i < at_most; ++i)
    s += (i ? ", " : "") + std::to_string(indices[i]);
  if (indices.size() > at_most) s += ", ...";
  return s;
}

json TileResultJson(const TilePlan& plan, size_t index) {
  const TexelRect& t = plan.tiles[index];
  return {{"format", kTileResultFormat},
          {"version", 1},
          {"plan", plan.id},
          {"index", index},
          {"rect", {t.x, t.y, t.width, t.height}}};
}

// Whether tile `index`'s folder is a complete result of this plan (see the header).
bool TileDone(const TilePlan& plan, size_t index) {
  const fs::path dir = plan.TileFolder(index);
  std::error_code ec;
  if (!fs::is_regular_file(dir / kOutputMarkerName, ec)) return false;
  auto text = ReadTextFile(dir / kTileResultFile, "tile result", 1 << 16);
  if (!text.ok()) return false;
  const json doc = json::parse(*text, nullptr, false);
  return !doc.is_discarded() && doc == TileResultJson(plan, index);
}

// The work folder, created with its marker, or an existing one that is a tile plan's.
Status UseWorkFolder(const TilePlan& plan) {
  if (Status s = CheckOutputPath(plan.work, {plan.canvas, plan.photos}); !s.ok()) return s;
  std::error_code ec;
  const fs::path marker = plan.work / kTileWorkMarker;
  if (fs::is_regular_file(marker, ec)) return Status::Ok();
  if (fs::exists(plan.work, ec)) {
    if (!fs::is_directory(plan.work, ec))
      return Error{plan.work.string() + ": the plan's work folder is a file"};
    if (!fs::is_empty(plan.work, ec))
      return Error{plan.work.string() +
                   ": exists, is not empty and is not a tile plan's work "
                   "folder (no " +
                   std::string(kTileWorkMarker) + "): not used; make the plan with another --work"};
  }
  fs::create_directories(plan.work, ec);
  if (ec) return Error{plan.work.string() + ": cannot create the work folder: " + ec.message()};
  return WriteTextFile(marker, "digitize tile plan work folder: " + plan.file.string() + "\n");
}

void AppendLog(const TilePlan& plan, const std::string& line) {
  FILE* log = std::fopen((plan.work / "run.log").c_str(), "a");
  if (log == nullptr) return;  // the log is for people; the results say what was done
  const std::time_t now = std::time(nullptr);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  std::fprintf(log, "%s %s\n", stamp, line.c_str());
  std::fclose(log);
}

std::vector<std::string> PlanInputs(const TilePlan& plan) {
  return {plan.canvas.string(), plan.photos.string()};
}

// A tile's report.json (WriteReflectanceOutputs) back into the counts the merge sums.
Result<ReflectanceFitReport> ReadTileReport(const fs::path& file) {
  auto text = ReadTextFile(file, "fit report");
  if (!text.ok()) return text.error();
  return CatchBadInput([&]() {
    const json doc = ParseJson(*text, file.string());
    const Fields f(doc, file.string());
    ReflectanceFitReport r;
    const Fields photos = f.Object("photos");
    r.photos = static_cast<size_t>(photos.Integer("count", 0, int64_t{1} << 40));
    r.distinct_directions =
        static_cast<int>(photos.Integer("distinct_directions", 0, int64_t{1} << 30));
    for (const json& e : photos.Array("light_below_canvas_entries")) {
      if (!e.is_string()) Fail(photos.At("light_below_canvas_entries") + ": not a string");
      r.light_below_canvas.push_back(e.get<std::string>());
    }
    constexpr int64_t kMany = int64_t{1} << 50;
    r.fit.texels = static_cast<size_t>(f.Integer("texels_fitted", 0, kMany));
    r.samples.texels = r.fit.texels;
    r.texels_outside = static_cast<size_t>(f.Integer("texels_outside", 0, kMany));
    const Fields status = f.Object("status");
    for (int i = 0; i < kTexelFitStatusCount; ++i)
      r.fit.count_by_status[i] =
          static_cast<size_t>(status.Integer(ToString(static_cast<TexelFitStatus>(i)), 0, kMany));
    const Fields lobes = f.Object("lobes_by_model");
    for (int m = 0; m < kReflectanceModelCount; ++m)
      r.fit.lobes_by_model[m] =
          static_cast<size_t>(lobes.Integer(ToString(static_cast<ReflectanceModel>(m)), 0, kMany));
    const Fields q = f.Object("photo_quantisation");
    r.quantisation = {static_cast<int>(q.Integer("code_max", 0, 65535)), q.Boolean("srgb"),
                      q.Boolean("lossy")};
    const Fields s = f.Object("samples");
    SampleStats& st = r.samples;
    st.candidates = static_cast<size_t>(s.Integer("candidates", 0, kMany));
    st.kept = static_cast<size_t>(s.Integer("kept", 0, kMany));
    const Fields rej = s.Object("rejected");
    const auto count = [&](const char* key) {
      return static_cast<size_t>(rej.Integer(key, 0, kMany));
    };
    st.behind_camera = count("behind_camera");
    st.outside_image = count("outside_image");
    st.facing_away = count("facing_away");
    st.light_below_horizon = count("light_below_horizon");
    st.non_finite = count("non_finite");
    st.saturated = count("saturated");
    st.black = count("black");
    st.hidden = count("hidden");
    st.shadowed = count("shadowed");
    r.dark_outliers = count("dark_outliers");
    const auto rays = [&](const char* key) {
      const Fields o = s.Object(key);
      TraceStats t;
      t.rays = static_cast<size_t>(o.Integer("rays", 0, kMany));
      t.skipped = static_cast<size_t>(o.Integer("skipped", 0, kMany));
      t.traced = static_cast<size_t>(o.Integer("traced", 0, kMany));
      t.blocked = static_cast<size_t>(o.Integer("blocked", 0, kMany));
      return t;
    };
    st.view_rays = rays("view_rays");
    st.light_rays = rays("light_rays");
    r.texels_refitted = static_cast<size_t>(f.Integer("texels_refitted", 0, kMany));
    r.fit.mean_rms_error = f.Number("mean_rms_error");
    r.fit.mean_iterations = f.Number("mean_iterations");
    const Fields sec = f.Object("seconds");
    r.seconds_tracer = sec.Number("tracer");
    r.seconds_samples = sec.Number("samples");
    r.seconds_fit = sec.Number("fit");
    r.seconds_total = sec.Number("total");
    return r;
  });
}

// `total` += `part` for the counts a fit report sums over tiles.
void AddTileReport(ReflectanceFitReport& total, const ReflectanceFitReport& part) {
  const size_t lobes_total = total.fit.texels - total.fit.count(TexelFitStatus::kDiffuseOnly) -
                             total.fit.count(TexelFitStatus::kTooFewSamples);
  const size_t lobes_part = part.fit.texels - part.fit.count(TexelFitStatus::kDiffuseOnly) -
                            part.fit.count(TexelFitStatus::kTooFewSamples);
  const double texels = static_cast<double>(total.fit.texels + part.fit.texels);
  if (texels > 0)
    total.fit.mean_rms_error = (total.fit.mean_rms_error * static_cast<double>(total.fit.texels) +
                                part.fit.mean_rms_error * static_cast<double>(part.fit.texels)) /
                               texels;
  if (lobes_total + lobes_part > 0)
    total.fit.mean_iterations = (total.fit.mean_iterations * static_cast<double>(lobes_total) +
                                 part.fit.mean_iterations * static_cast<double>(lobes_part)) /
                                static_cast<double>(lobes_total + lobes_part);
  total.fit.texels += part.fit.texels;
  for (int i = 0; i < kTexelFitStatusCount; ++i)
    total.fit.count_by_status[i] += part.fit.count_by_status[i];
  for (int m = 0; m < kReflectanceModelCount; ++m)
    total.fit.lobes_by_model[m] += part.fit.lobes_by_model[m];
  total.samples += part.samples;
  total.texels_outside += part.texels_outside;
  total.dark_outliers += part.dark_outliers;
  total.texels_refitted += part.texels_refitted;
  total.seconds_tracer += part.seconds_tracer;
  total.seconds_samples += part.seconds_samples;
  total.seconds_fit += part.seconds_fit;
  total.seconds_total += part.seconds_total;
}

// The shell's single quotes around `text` (' as '\'').
std::string ShellQuote(const std::string& text) {
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

}  // namespace

std::string TilesStatus::Brief() const {
  std::string s = Format("%zu of %zu tiles done", done.size(), tiles);
  if (!pending.empty()) s += "; pending: " + IndexList(pending);
  if (merged) s += "; merged";
  return s;
}

Result<TilesStatus> StatusOfTiles(const TilePlan& plan) {
  TilesStatus status;
  status.tiles = plan.tiles.size();
  for (size_t i = 0; i < plan.tiles.size(); ++i)
    (TileDone(plan, i) ? status.done : status.pending).push_back(i);
  std::error_code ec;
  status.merged = status.pending.empty() &&
                  fs::is_regular_file(plan.FitFolder() / kOutputMarkerName, ec) &&
                  fs::is_regular_file(plan.out, ec);
  return status;
}

std::string TileRunReport::Brief() const {
  std::string s = Format("fitted %zu tile%s", fitted.size(), fitted.size() == 1 ? "" : "s");
  if (!fitted.empty()) s += " (" + IndexList(fitted) + ")";
  if (!skipped.empty()) s += Format(", %zu done already", skipped.size());
  return s + Format("; %.1f s", seconds);
}

namespace {

// The inputs of one tile job: the tile, a halo around it wide enough to hold everything that can
// shadow or hide the tile's texels, and of each photo the pixels the tile's texels project to.
struct TileInputs {
  PreprocessedCanvas canvas;  // the window: tile + halo (field.window)
  PhotoSet photos;            // parts of the photos that see the tile
  TexelRect region;           // the tile, in the window's texels
  int halo = 0;               // texels
  size_t from_copies = 0;     // photo parts read from tiled copies (photo_tile_cache.h)
};

constexpr int kHaloSlackTexels = 2;  // bilinear quads and the tracer's whole-texel footprints
// Rays flatter than this (light or camera within 1 degree of the canvas plane) may cross the whole
// canvas under the relief's top: such a tile reads the whole canvas.
const double kMinSinElevation = std::sin(1.0 * M_PI / 180.0);

// Canvas-frame corners of the box over a tile's texels (one texel wider each side, so pixel
// footprints and bilinear neighbours are in) from z0 to z1.
std::array<Vec3d, 8> TileBox(const TilePlan& plan, const TexelRect& t, double pitch, double z0,
                             double z1) {
  const double X0 = (t.x - 1.0) * pitch, X1 = (t.x + t.width + 1.0) * pitch;
  const double Y0 = (plan.canvas_height - t.y - t.height - 1.0) * pitch;
  const double Y1 = (plan.canvas_height - t.y + 1.0) * pitch;
  std::array<Vec3d, 8> c;
  for (int i = 0; i < 8; ++i) c[i] = Vec3d(i & 1 ? X1 : X0, i & 2 ? Y1 : Y0, i & 4 ? z1 : z0);
  return c;
}

// The smallest sine of the elevation (above the canvas plane) of any light or camera of `set`
// seen from the tile's corners at height z: a ray leaving a tile texel towards it climbs at least
// this steeply. Over a rectangle the farthest point from a light's foot is a corner, so the
// corners bound every texel.
double MinSinElevation(const PhotoSet& set, const RigidTransform& canvas_from_scan,
                       const std::array<Vec3d, 8>& box) {
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  double least = 1.0;
  for (const Photo& photo : set.photos) {
    // A perspective camera's rays start at its centre; an orthographic one's share a direction.
    Vec3d o, d;
    photo.camera.Ray(photo.camera.cx - photo.camera.origin_x,
                     photo.camera.cy - photo.camera.origin_y, o, d);
    for (int i = 0; i < 4; ++i) {  // the bottom corners
      const Vec3d p_scan = scan_from_canvas.Apply(box[i]);
      const Vec3d to_light = canvas_from_scan.rotation * photo.light.DirectionTo(p_scan);
      const Vec3d to_camera = photo.camera.model == CameraModel::kOrthographic
                                  ? Vec3d(canvas_from_scan.rotation * -d)
                                  : Vec3d(canvas_from_scan.rotation * (o - p_scan).normalized());
      least = std::min({least, to_light.z(), to_camera.z()});
    }
  }
  return least;
}

// The pixel rectangle of `camera` that holds the projection of `box` and the footprints of its
// texels; empty (width 0) when the box projects off the image. A box partly behind the camera
// takes the whole image.
PixelRect BoxPixels(const Camera& camera, const RigidTransform& canvas_from_scan,
                    const std::array<Vec3d, 8>& box, double pitch) {
  const RigidTransform scan_from_canvas = canvas_from_scan.Inverse();
  double u0 = std::numeric_limits<double>::infinity(), v0 = u0, u1 = -u0, v1 = -u0;
  double texel_px = 1.0;  // the largest texel footprint, pixels
  for (const Vec3d& corner : box) {
    const Vec3d p = scan_from_canvas.Apply(corner);
    const Vec3d q = scan_from_canvas.Apply(corner + Vec3d(pitch, 0, 0));
    if (!camera.InFront(p) || !camera.InFront(q)) return {0, 0, camera.width, camera.height};
    const Eigen::Vector2d a = camera.Project(p), b = camera.Project(q);
    u0 = std::min(u0, a.x()), u1 = std::max(u1, a.x());
    v0 = std::min(v0, a.y()), v1 = std::max(v1, a.y());
    texel_px = std::max(texel_px, (b - a).norm());
  }
  const double margin = std::ceil(2.0 * texel_px) + 3.0;
  const double x0 = std::max(0.0, std::floor(u0 - margin));
  const double y0 = std::max(0.0, std::floor(v0 - margin));
  const double x1 = std::min<double>(camera.width, std::ceil(u1 + margin) + 1.0);
  const double y1 = std::min<double>(camera.height, std::ceil(v1 + margin) + 1.0);
  if (!(x1 > x0 && y1 > y0)) return {};
  return {static_cast<int>(x0), static_cast<int>(y0), static_cast<int>(x1 - x0),
          static_cast<int>(y1 - y0)};
}

}  // namespace

int TileHaloTexels(const TilePlan& plan, const TexelRect& tile, const PhotoSet& set,
                   const RigidTransform& canvas_from_scan, double pitch) {
  // A ray from a tile texel (at >= the canvas's lowest height) climbing at least at the set's
  // flattest elevation is above the highest relief within `reach` mm.
  const double sin_e = MinSinElevation(
      set, canvas_from_scan, TileBox(plan, tile, pitch, plan.min_height_mm, plan.max_height_mm));
  const int whole_canvas = std::max(plan.canvas_width, plan.canvas_height);
  if (sin_e < kMinSinElevation) return whole_canvas;
  const double tan_e = sin_e / std::sqrt(1.0 - sin_e * sin_e);
  const double reach_mm = (plan.max_height_mm - plan.min_height_mm) / tan_e;
  return static_cast<int>(
      std::min<double>(whole_canvas, std::ceil(reach_mm / pitch) + kHaloSlackTexels));
}

Result<int> LargestTileHalo(const TilePlan& plan) {
  PhotoSetOptions headers_only = plan.photo;
  headers_only.load_pixels = false;
  auto photos = ReadPhotoSetFile(plan.photos, headers_only);
  if (!photos.ok()) return photos.error();
  ImageRegionReader reader(64);
  auto frame = ReadPreprocessWindow(plan.canvas, 0, 0, 1, 1, reader);
  if (!frame.ok()) return frame.error();
  int largest = 0;
  for (const TexelRect& tile : plan.tiles)
    largest = std::max(largest, TileHaloTexels(plan, tile, *photos, frame->canvas_from_scan,
                                               frame->field.pitch_mm));
  return largest;
}

namespace {

Result<TileInputs> ReadTileInputs(const TilePlan& plan, size_t index, const PhotoSet& whole,
                                  const std::vector<fs::path>& copies,
                                  const RigidTransform& canvas_from_scan, double pitch,
                                  ImageRegionReader& reader) {
  const TexelRect& tile = plan.tiles[index];
  TileInputs in;
  in.halo = TileHaloTexels(plan, tile, whole, canvas_from_scan, pitch);
  const int x0 = std::max(0, tile.x - in.halo), y0 = std::max(0, tile.y - in.halo);
  const int x1 = std::min(plan.canvas_width, tile.x + tile.width + in.halo);
  const int y1 = std::min(plan.canvas_height, tile.y + tile.height + in.halo);
  auto canvas = ReadPreprocessWindow(plan.canvas, x0, y0, x1 - x0, y1 - y0, reader);
  if (!canvas.ok()) return canvas.error();
  in.canvas = std::move(canvas).value();
  in.canvas.field.window.full_max_height_mm = static_cast<float>(plan.max_height_mm);
  in.region = {tile.x - x0, tile.y - y0, tile.width, tile.height};

  in.photos.source = whole.source;
  const auto box =
      TileBox(plan, tile, pitch, plan.min_height_mm - pitch, plan.max_height_mm + pitch);
  for (size_t i = 0; i < whole.photos.size(); ++i) {
    const Photo& photo = whole.photos[i];
    const PixelRect rect = BoxPixels(photo.camera, canvas_from_scan, box, pitch);
    if (rect.width == 0) continue;  // sees none of the tile
    auto part = LoadPhotoRegion(photo, rect, reader, plan.photo, copies[i]);
    if (!part.ok()) return part.error();
    in.from_copies += !copies[i].empty();
    in.photos.photos.push_back(std::move(part).value());
  }
  if (in.photos.photos.empty()) {
    // No photo sees the tile: its texels get no sample (kTooFewSamples), as in the whole fit. The
    // fit still needs a photo set; one pixel of the first photo, far from the tile, adds nothing.
    auto part = LoadPhotoRegion(whole.photos.front(), {0, 0, 1, 1}, reader, plan.photo);
    if (!part.ok()) return part.error();
    in.photos.photos.push_back(std::move(part).value());
  }
  return in;
}

}  // namespace

Result<PhotoTileCacheSummary> CachePlanPhotos(const TilePlan& plan,
                                              const ProgressCallback& progress) {
  if (Status s = UseWorkFolder(plan); !s.ok()) return Error{s.message()};
  PhotoSetOptions headers_only = plan.photo;
  headers_only.load_pixels = false;
  auto photos = ReadPhotoSetFile(plan.photos, headers_only);
  if (!photos.ok()) return photos.error();
  if (photos->is_rti) return PhotoTileCacheSummary{};  // fitted untiled, never by tile jobs
  auto summary = WritePhotoTileCache(*photos, plan.PhotoCacheFolder(), progress);
  if (summary.ok()) AppendLog(plan, "photo cache: " + summary->Brief());
  return summary;
}

Result<TileRunReport> RunTiles(const TilePlan& plan, const TileRunOptions& options,
                               const ProgressCallback& progress) {
  const auto start = Clock::now();
  if (options.threads < 0) return Error{"threads must be >= 0"};
  if (options.cache_mb < 64) return Error{"cache_mb must be >= 64"};
  for (size_t index : options.indices)
    if (index >= plan.tiles.size())
      return Error{plan.file.string() + ": no tile " + std::to_string(index) + " (the plan has " +
                   std::to_string(plan.tiles.size()) + ", 0 to " +
                   std::to_string(plan.tiles.size() - 1) + ")"};
  TileRunReport report;
  std::vector<size_t> todo;
  std::vector<size_t> chosen = options.indices;
  if (chosen.empty())
    for (size_t i = 0; i < plan.tiles.size(); ++i) chosen.push_back(i);
  std::sort(chosen.begin(), chosen.end());
  chosen.erase(std::unique(chosen.begin(), chosen.end()), chosen.end());
  for (size_t index : chosen)
    (!options.redo && TileDone(plan, index) ? report.skipped : todo).push_back(index);
  if (todo.empty()) {
    report.seconds = Since(start);
    return report;
  }
  if (Status s = UseWorkFolder(plan); !s.ok()) return Error{s.message()};

  // The photos' headers only: each tile reads the parts it needs.
  ReportProgress(progress, "photos", 0.0);
  PhotoSetOptions headers_only = plan.photo;
  headers_only.load_pixels = false;
  auto photos = ReadPhotoSetFile(plan.photos, headers_only, progress);
  if (!photos.ok()) return photos.error();
  if (photos->is_rti)
    return Error{plan.photos.string() + ": an RTI capture: fit it untiled (`digitize fit`)"};
  auto header = ReadImageHeader(plan.canvas / "height.exr");
  if (!header.ok()) return header.error();
  if (header->width != plan.canvas_width || header->height != plan.canvas_height)
    return Error{plan.canvas.string() + ": the canvas is " + std::to_string(header->width) + " x " +
                 std::to_string(header->height) + " texels, the plan " + plan.file.string() +
                 " was cut for " + std::to_string(plan.canvas_width) + " x " +
                 std::to_string(plan.canvas_height) + ": make a new plan"};
  std::string cache_note;
  const std::vector<fs::path> copies =
      FindPhotoTileCopies(*photos, plan.PhotoCacheFolder(), &cache_note);
  if (!cache_note.empty()) AppendLog(plan, "photo cache: " + cache_note);
  ImageRegionReader reader(options.cache_mb);
  // One texel of the canvas: its frame and pitch, which every tile's window shares.
  auto frame = ReadPreprocessWindow(plan.canvas, 0, 0, 1, 1, reader);
  if (!frame.ok()) return frame.error();
  ReflectanceFitOptions fit = plan.fit;
  fit.fit.num_threads = options.threads;
  fit.samples.trace.num_threads = options.threads;
  const FolderOutput output{"tiles run", "fit-tile", {plan.canvas, plan.photos}};
  const std::vector<std::string> inputs = PlanInputs(plan);
  for (size_t k = 0; k < todo.size(); ++k) {
    const size_t index = todo[k];
    const auto tile_start = Clock::now();
    auto in = ReadTileInputs(plan, index, *photos, copies, frame->canvas_from_scan,
                             frame->field.pitch_mm, reader);
    if (!in.ok()) return Error{"tile " + std::to_string(index) + ": " + in.error().message};
    const Status fitted = FitReflectanceRegions(
        in->canvas.field, in->canvas.normals, in->canvas.canvas_from_scan, in->photos, fit,
        std::span<const TexelRect>(&in->region, 1),
        [&](size_t, ReflectanceFitResult&& result) -> Status {
          const Status written =
              WriteDirectoryAtomically(plan.TileFolder(index), output, [&](const fs::path& dir) {
                if (Status s = WriteReflectanceOutputs(dir, result, plan.fit, inputs); !s.ok())
                  return s;
                return WriteTextFile(dir / kTileResultFile,
                                     TileResultJson(plan, index).dump(2) + "\n");
              });
          if (!written.ok())
            return Error{"tile " + std::to_string(index) + ": " + written.message()};
          report.fitted.push_back(index);
          AppendLog(plan,
                    Format("tile %zu of %zu fitted in %.1f s (window %d x %d, halo %d, %zu of %zu "
                           "photos, %zu read from tiled copies): ",
                           index, plan.tiles.size(), Since(tile_start), in->canvas.field.width(),
                           in->canvas.field.height(), in->halo, in->photos.photos.size(),
                           photos->photos.size(), in->from_copies) +
                        result.report.Brief());
          return Status::Ok();
        },
        nullptr, &*photos);
    if (!fitted.ok())
      return Error{plan.file.string() + ": tile " + std::to_string(index) + ": " +
                   fitted.message()};
    report.peak_cache_bytes = reader.peak_cache_bytes();
    ReportProgress(progress, "tiles", static_cast<double>(k + 1) / todo.size());
  }
  report.seconds = Since(start);
  return report;
}

namespace {

// The merge reads the canvas a band of rows of the whole width at a time: its cache holds a few
// bands of height, normals and mask (17 bytes a texel), not more (a cache fills to its bound:
// 512 MB was a third of the merge's peak at 8192 wide). The tiles' maps go through it too, a
// band of a tile at a time, each piece copied out as soon as it is read: they need no room of
// their own beyond a strip of a tile.
size_t MergeCacheMb(int width, int band_rows) {
  const size_t band = static_cast<size_t>(width) * static_cast<size_t>(band_rows) * 17;
  return std::max<size_t>(64, (3 * band) >> 20);
}

// Tile `index`'s maps, checked against the plan's rectangle.
Result<ReflectanceMaps> ReadTileMaps(const TilePlan& plan, size_t index) {
  const fs::path dir = plan.TileFolder(index);
  auto maps = ReadReflectanceMaps(dir);
  if (!maps.ok()) return maps.error();
  const TexelRect& t = plan.tiles[index];
  if (maps->width() != t.width || maps->height() != t.height)
    return Error{dir.string() + ": maps are " + std::to_string(maps->width()) + " x " +
                 std::to_string(maps->height()) + ", the tile " + std::to_string(t.width) + " x " +
                 std::to_string(t.height)};
  return maps;
}

// Tile `index`'s texels by model, its maps read a band of rows at a time (every value checked as
// ReadTileMaps does, every file's size against the plan's rectangle) so that the tile is never
// held whole: the streamed merge's header needs the counts before its first band.
Result<std::array<int64_t, kReflectanceModelCount>> CountTileModels(const TilePlan& plan,
                                                                    size_t index,
                                                                    ImageRegionReader& reader) {
  const fs::path dir = plan.TileFolder(index);
  const TexelRect& t = plan.tiles[index];
  std::vector<std::string> names = {"rho_d.exr", "rho_s.exr", "lobe.exr", "fit_error.exr",
                                    "fit_status.png"};
  std::error_code ec;
  if (fs::exists(dir / "model.png", ec)) names.push_back("model.png");  // optional (before GGX)
  for (const std::string& name : names) {
    auto header = ReadImageHeader(dir / name);
    if (!header.ok()) return header.error();
    if (header->width != t.width || header->height != t.height)
      return Error{(dir / name).string() + ": " + std::to_string(header->width) + " x " +
                   std::to_string(header->height) + ", the tile " + std::to_string(t.width) +
                   " x " + std::to_string(t.height)};
  }
  std::array<int64_t, kReflectanceModelCount> models{};
  constexpr int kBandRows = 256;
  for (int y = 0; y < t.height; y += kBandRows) {
    auto band =
        ReadReflectanceMapsWindow(dir, 0, y, t.width, std::min(kBandRows, t.height - y), reader);
    if (!band.ok()) return band.error();
    for (const ReflectanceModel m : band->model.data) ++models[static_cast<size_t>(m)];
  }
  return models;
}

// Texel (x, y) of `from` into (tx, ty) of `to`.
void CopyTexel(const ReflectanceMaps& from, int x, int y, ReflectanceMaps& to, int tx, int ty) {
  to.rho_d(tx, ty) = from.rho_d(x, y);
  to.rho_s(tx, ty) = from.rho_s(x, y);
  to.lobe(tx, ty) = from.lobe(x, y);
  to.fit_error(tx, ty) = from.fit_error(x, y);
  to.status(tx, ty) = from.status(x, y);
  to.model(tx, ty) = from.model(x, y);
}

// The tiled pack of a plan, its level 0 streamed from the canvas folder and the tile folders a
// band of rows at a time (WriteTiledPack): the canvas is read by window through a bounded cache,
// and only the tiles a band crosses are held, so the merge's memory follows the canvas's width,
// not its texels. The provenance hashes the tile folders' files (there is no whole-canvas map).
Result<PackSummary> StreamTilesToPack(const TilePlan& plan,
                                      const std::array<int64_t, kReflectanceModelCount>& models,
                                      const ProgressCallback& progress) {
  const std::string file = plan.out.string();
  if (Status s = plan.pack.Validate(); !s.ok()) return Error{file + ": " + s.message()};
  if (Status s = CheckOutputPath(plan.out, {plan.canvas, plan.work}); !s.ok())
    return Error{s.message()};
  ImageRegionReader reader(MergeCacheMb(plan.canvas_width, plan.pack.tile_size));
  auto frame = ReadPreprocessWindow(plan.canvas, 0, 0, 1, 1, reader);
  if (!frame.ok()) return frame.error();
  PackHeader header;
  header.width = plan.canvas_width;
  header.height = plan.canvas_height;
  header.pitch_mm = frame->field.pitch_mm;
  header.delta0_mm = frame->delta0_mm;
  header.max_height_mm = frame->max_height_mm;
  header.cell_px = frame->cell_px;
  header.boxes = std::move(frame->boxes);
  header.canvas_from_scan = frame->canvas_from_scan;
  header.texels_by_model = models;
  auto provenance = ProvenanceFromOutputs(plan.canvas, plan.FitFolder(), plan.pack);
  if (!provenance.ok()) return provenance.error();
  for (size_t i = 0; i < plan.tiles.size(); ++i) {
    std::vector<fs::path> files;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(plan.TileFolder(i), ec))
      if (e.is_regular_file() && e.path().filename().string().front() != '.')
        files.push_back(e.path());
    if (ec) return Error{plan.TileFolder(i).string() + ": cannot list: " + ec.message()};
    std::sort(files.begin(), files.end());
    if (Status s = AddProvenanceInputs(*provenance, files, plan.work); !s.ok())
      return Error{s.message()};
  }
  header.provenance = std::move(provenance).value();

  const int w = plan.canvas_width, h = plan.canvas_height;
  const PackBandSource band = [&](int y0, int rows) -> Result<PackLevel> {
    auto canvas = ReadPreprocessWindow(plan.canvas, 0, y0, w, rows, reader);
    if (!canvas.ok()) return canvas.error();
    ReflectanceMaps maps = ReflectanceMaps::Zeros(w, rows);
    // Only the band's rows of each tile it crosses (a row of tiles whole was 46 bytes a texel
    // of the canvas's width times the tiles' height). MergeTiles checked every tile's files
    // against the plan first (CountTileModels).
    for (size_t i = 0; i < plan.tiles.size(); ++i) {
      const TexelRect& t = plan.tiles[i];
      const int top = std::max(t.y, y0), bottom = std::min(t.y + t.height, y0 + rows);
      if (top >= bottom) continue;
      auto part = ReadReflectanceMapsWindow(plan.TileFolder(i), 0, top - t.y, t.width, bottom - top,
                                            reader);
      if (!part.ok()) return part.error();
      for (int y = top; y < bottom; ++y)
        for (int x = 0; x < t.width; ++x) CopyTexel(*part, x, y - top, maps, t.x + x, y - y0);
    }
    ReportProgress(progress, "merge", 0.3 + 0.7 * static_cast<double>(y0 + rows) / h);
    PackLevel level;  // taken, not copied (BaseLevel copies): a band is the canvas's width
    level.max_height_mm = canvas->field.height_mm;
    level.field = std::move(canvas->field);
    level.normals = std::move(canvas->normals);
    level.maps = std::move(maps);
    return level;
  };
  if (Status s = WriteTiledPack(plan.out, header, plan.pack, band); !s.ok())
    return Error{s.message()};
  return InspectPack(plan.out);
}

}  // namespace

Result<TileMergeReport> MergeTiles(const TilePlan& plan, const ProgressCallback& progress) {
  auto status = StatusOfTiles(plan);
  if (!status.ok()) return status.error();
  if (!status->pending.empty())
    return Error{plan.file.string() + ": " + std::to_string(status->pending.size()) + " of " +
                 std::to_string(plan.tiles.size()) +
                 " tiles are not done (tiles: " + IndexList(status->pending) +
                 "); run them first (`digitize tiles run PLAN --all`)"};
  if (Status s = UseWorkFolder(plan); !s.ok()) return Error{s.message()};
  // A tiled pack streams from the tile folders; a single-grid one is written from whole maps.
  const bool streamed = plan.pack.tile_size > 0;
  TileMergeReport merged;
  ReflectanceFitResult whole;
  if (!streamed) whole.maps = ReflectanceMaps::Zeros(plan.canvas_width, plan.canvas_height);
  std::array<int64_t, kReflectanceModelCount> models{};
  auto count_reader = std::make_unique<ImageRegionReader>(64);  // gone before the pack's bands
  ReportProgress(progress, "merge", 0.0);
  for (size_t i = 0; i < plan.tiles.size(); ++i) {
    const TexelRect& t = plan.tiles[i];
    if (streamed) {
      auto counts = CountTileModels(plan, i, *count_reader);
      if (!counts.ok()) return counts.error();
      for (size_t m = 0; m < models.size(); ++m) models[m] += (*counts)[m];
    } else {
      auto maps = ReadTileMaps(plan, i);
      if (!maps.ok()) return maps.error();
      for (int y = 0; y < t.height; ++y)
        for (int x = 0; x < t.width; ++x) CopyTexel(*maps, x, y, whole.maps, t.x + x, t.y + y);
    }
    auto part = ReadTileReport(plan.TileFolder(i) / "report.json");
    if (!part.ok()) return part.error();
    if (i == 0) {
      whole.report.photos = part->photos;
      whole.report.distinct_directions = part->distinct_directions;
      whole.report.light_below_canvas = part->light_below_canvas;
      whole.report.quantisation = part->quantisation;
    }
    AddTileReport(whole.report, *part);
    ReportProgress(progress, "merge",
                   (streamed ? 0.3 : 0.8) * static_cast<double>(i + 1) /
                       static_cast<double>(plan.tiles.size()));
  }
  count_reader.reset();
  whole.report.fit.method = plan.fit.fit.method;
  whole.report.fit.seconds = whole.report.seconds_fit;
  const FolderOutput output{"tiles merge", "fit", {plan.canvas, plan.photos}};
  const std::vector<std::string> inputs = PlanInputs(plan);
  if (Status s = WriteDirectoryAtomically(
          plan.FitFolder(), output,
          [&](const fs::path& dir) {
            if (!streamed) return WriteReflectanceOutputs(dir, whole, plan.fit, inputs);
            return WriteTextFile(dir / "report.json",
                                 ReflectanceReportJson(whole, plan.fit, inputs));
          });
      !s.ok())
    return Error{s.message()};
  ReportProgress(progress, "merge", streamed ? 0.3 : 0.9);
  auto pack = streamed ? StreamTilesToPack(plan, models, progress)
                       : PackFromFolders(plan.canvas, plan.FitFolder(), plan.out, plan.pack);
  if (!pack.ok()) return pack.error();
  merged.fit = std::move(whole.report);
  merged.pack = *pack;
  AppendLog(plan, "merged " + std::to_string(plan.tiles.size()) + " tiles into " +
                      plan.out.string() + ": " + merged.fit.Brief());
  ReportProgress(progress, "merge", 1.0);
  return merged;
}

Status SlurmScriptOptions::Validate() const {
  if (digitize.empty() || !fs::path(digitize).is_absolute())
    return Error{"the digitize executable must be an absolute path, got \"" + digitize + "\""};
  if (cpus_per_task < 1 || cpus_per_task > 4096)
    return Error{"cpus per task must be in [1, 4096], got " + std::to_string(cpus_per_task)};
  if (mem_mb < 0) return Error{"memory per job must be >= 0 MB"};
  if (max_running < 0) return Error{"max running tiles must be >= 0"};
  for (const std::string* s : {&partition, &time})
    for (char c : *s)
      if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == ':' ||
            c == '.' || c == ','))
        return Error{"partition and time may hold letters, digits and - _ : . , only, got \"" + *s +
                     "\""};
  return Status::Ok();
}

Result<SlurmScripts> WriteSlurmScripts(const TilePlan& plan, const SlurmScriptOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  for (const fs::path& p : {plan.file, plan.work, fs::path(options.digitize)})
    for (char c : p.string())
      if (c == '\n' || c == '\r' || c == '\0')
        return Error{p.string() + ": a path with a line break cannot go into a job script"};
  if (Status s = UseWorkFolder(plan); !s.ok()) return Error{s.message()};
  const fs::path slurm = plan.work / "slurm", logs = plan.work / "logs";
  std::error_code ec;
  for (const fs::path& dir : {slurm, logs}) {
    fs::create_directories(dir, ec);
    if (ec) return Error{dir.string() + ": cannot create: " + ec.message()};
  }
  std::string common;
  if (!options.partition.empty()) common += "#SBATCH --partition=" + options.partition + "\n";
  if (!options.time.empty()) common += "#SBATCH --time=" + options.time + "\n";
  if (options.mem_mb > 0) common += "#SBATCH --mem=" + std::to_string(options.mem_mb) + "M\n";
  const std::string exe = ShellQuote(options.digitize), file = ShellQuote(plan.file.string());
  const std::string header = "#!/bin/bash\n# Written by `digitize tiles sbatch` for the plan " +
                             plan.file.string() + " (id " + plan.id + ").\n";
  std::string array = Format("0-%zu", plan.tiles.size() - 1);
  if (options.max_running > 0) array += "%" + std::to_string(options.max_running);
  const std::string tiles =
      header + "#SBATCH --job-name=digitize-tiles\n#SBATCH --array=" + array +
      "\n#SBATCH --cpus-per-task=" + std::to_string(options.cpus_per_task) +
      "\n#SBATCH --output=" + (logs / "tile_%a.log").string() + "\n" + common +
      "set -euo pipefail\n"
      "# A tile already done (a requeued task, a rerun) is skipped.\n"
      "exec " +
      exe + " tiles run " + file + " --index \"$SLURM_ARRAY_TASK_ID\" --threads " +
      std::to_string(options.cpus_per_task) + "\n";
  const std::string merge = header + "#SBATCH --job-name=digitize-merge\n#SBATCH --cpus-per-task=" +
                            std::to_string(options.cpus_per_task) +
                            "\n#SBATCH --output=" + (logs / "merge.log").string() + "\n" + common +
                            "set -euo pipefail\nexec " + exe + " tiles merge " + file + "\n";
  const std::string submit =
      header +
      "# Submits the tiles as a job array, then the merge to run once every tile succeeded.\n"
      "set -euo pipefail\n"
      "tiles=$(sbatch --parsable " +
      ShellQuote((slurm / "tiles.sbatch").string()) +
      ")\n"
      "tiles=${tiles%%;*}\n"
      "merge=$(sbatch --parsable --dependency=afterok:\"$tiles\" " +
      ShellQuote((slurm / "merge.sbatch").string()) +
      ")\n"
      "merge=${merge%%;*}\n"
      "echo \"tiles: job $tiles (" +
      std::to_string(plan.tiles.size()) +
      " tasks); merge: job $merge, after every tile succeeded\"\n";
  SlurmScripts scripts{slurm / "tiles.sbatch", slurm / "merge.sbatch", slurm / "submit.sh"};
  for (const auto& [path, text] : {std::pair{scripts.tiles, tiles}, std::pair{scripts.merge, merge},
                                   std::pair{scripts.submit, submit}}) {
    if (Status s = WriteTextFile(path, text); !s.ok()) return Error{s.message()};
    fs::permissions(path, fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec,
                    fs::perm_options::add, ec);
  }
  return scripts;
}

}  // namespace digitize
