#include "digitize_viewer/gallery.h"

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "digitize/image_io.h"
#include "digitize/output_dir.h"
#include "digitize_viewer/gl_context.h"
#include "digitize_viewer/painting_setup.h"

namespace digitize::viewer {

// MakeGallery and LoadPackForViewer: gallery_layout.cpp (no GL, so the fuzz target links them).

Result<std::vector<ViewCamera>> ReadCameraPath(const std::filesystem::path& path) {
  const std::string name = path.string();
  // The viewer's own words ("cannot open") whatever ReadTextFile found.
  auto text = ReadTextFile(path, "camera path");
  if (!text) return Error{name + ": cannot open"};
  nlohmann::json j;
  try {
    std::istringstream in(*text);  // operator>>: trailing text after the object is ignored
    in >> j;
  } catch (const std::exception& e) {
    return Error{name + ": not JSON (" + e.what() + ")"};
  }
  try {
    if (j.value("format", "") != "digitize.camera_path")
      return Error{name + ": \"format\" must be \"digitize.camera_path\""};
    if (j.value("version", 0) != 1) return Error{name + ": unsupported version (1 expected)"};
    const int w = j.value("width", 640), h = j.value("height", 480);
    const double fov = j.value("fov_y_deg", 50.0);
    if (!j.contains("frames") || !j["frames"].is_array() || j["frames"].empty())
      return Error{name + ": \"frames\" must be a non-empty array"};
    std::vector<ViewCamera> out;
    auto vec = [](const nlohmann::json& a) {
      if (!a.is_array() || a.size() != 3) throw std::runtime_error("3 numbers expected");
      return Vec3d(a[0].get<double>(), a[1].get<double>(), a[2].get<double>());
    };
    for (size_t i = 0; i < j["frames"].size(); ++i) {
      const auto& f = j["frames"][i];
      const std::string where = name + ": frames[" + std::to_string(i) + "]";
      ViewCamera c;
      c.width = w;
      c.height = h;
      c.fov_y_deg = fov;
      c.near_mm = 10;
      c.far_mm = 1e6;
      try {
        c.eye_mm = vec(f.at("eye"));
        c.target_mm = vec(f.at("target"));
        c.up = f.contains("up") ? vec(f["up"]) : Vec3d::UnitZ();
      } catch (const std::exception& e) {
        return Error{where + ": " + e.what()};
      }
      if (Status s = c.Validate(); !s.ok()) return Error{where + ": " + s.message()};
      out.push_back(c);
    }
    return out;
  } catch (const std::exception& e) {
    return Error{name + ": " + e.what()};
  }
}

std::filesystem::path ScreenshotPath(const std::filesystem::path& out_png, size_t index,
                                     size_t count) {
  if (count <= 1) return out_png;
  char suffix[24];  // "_" + up to 20 digits of a size_t + NUL
  std::snprintf(suffix, sizeof(suffix), "_%03zu", index);
  return out_png.parent_path() / (out_png.stem().string() + suffix + out_png.extension().string());
}

GalleryScene HangInRenderer(Renderer& renderer,
                            const std::vector<std::pair<std::string, Pack>>& packs,
                            const std::vector<std::filesystem::path>& streamed,
                            const StreamOptions& stream_options,
                            std::vector<std::string>& refused) {
  std::vector<std::unique_ptr<PyramidStream>> streams;
  std::vector<std::string> names;
  std::vector<Eigen::Vector2d> sizes;
  for (const std::filesystem::path& p : streamed) {
    auto stream = PyramidStream::Open(p, stream_options);
    if (!stream) {
      refused.push_back(stream.error().message);
      continue;
    }
    sizes.emplace_back((*stream)->width_mm(), (*stream)->height_mm());
    names.push_back(p.string());
    streams.push_back(std::move(stream).value());
  }
  GalleryScene scene = HangPaintings(packs, {}, sizes);
  const Gallery& g = scene.gallery;
  refused.insert(refused.end(), scene.failed.begin(), scene.failed.end());
  for (size_t k = 0; k < scene.hung.size(); ++k) {
    const auto& [name, pack] = packs[scene.hung[k]];
    auto added = renderer.AddPainting(pack, name, g.world_from_canvas[k]);
    if (!added) refused.push_back(added.error().message);
  }
  for (size_t j = 0; j < streams.size(); ++j) {
    auto added = renderer.AddStreamedPainting(std::move(streams[j]), names[j],
                                              g.world_from_canvas[scene.hung.size() + j]);
    if (!added) refused.push_back(added.error().message);
  }
  return scene;
}

Status RenderGalleryScreenshots(const std::vector<std::pair<std::string, Pack>>& packs,
                                const std::filesystem::path& out_png,
                                const std::vector<ViewCamera>& path,
                                const GalleryShotOptions& options,
                                std::vector<std::string>* failed) {
  const size_t shots = std::max<size_t>(path.size(), 1);
  std::vector<std::filesystem::path> outs;
  for (size_t i = 0; i < shots; ++i) {
    std::filesystem::path out = ScreenshotPath(out_png, i, shots);
    if (auto format = OutputFormatFor(out); !format.ok()) return Status(format.error());
    if (Status s = CheckOutputPath(out, options.inputs); !s.ok()) return s;
    outs.push_back(std::move(out));
  }
  const bool close_up = path.empty() && !options.close_up.empty();
  if (close_up) {
    if (auto format = OutputFormatFor(options.close_up); !format.ok())
      return Status(format.error());
    if (Status s = CheckOutputPath(options.close_up, options.inputs); !s.ok()) return s;
    outs.push_back(options.close_up);
  }
  auto context = HeadlessContext::Create();
  if (!context) return context.error();
  auto renderer = Renderer::Create();
  if (!renderer) return renderer.error();
  std::vector<std::string> refused;
  const GalleryScene scene =
      HangInRenderer(**renderer, packs, options.streamed, options.stream, refused);
  const Gallery& g = scene.gallery;
  const bool streaming = !options.streamed.empty();
  if (!refused.empty()) {
    if (failed == nullptr) return Error{refused.front()};
    failed->insert(failed->end(), refused.begin(), refused.end());
    // An empty room would hide that nothing could be shown.
    if (refused.size() == packs.size() + options.streamed.size())
      return Error{"none of the " + std::to_string(packs.size() + options.streamed.size()) +
                   " painting(s) could be hung; nothing written"};
  }
  (*renderer)->SetRoom(g.room);
  // As every other command: a missing output folder is made (only now, when all is ready).
  for (const std::filesystem::path& out : outs) {
    const std::filesystem::path dir = out.parent_path();
    if (dir.empty()) continue;
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return Error{dir.string() + ": cannot create the screenshot folder: " + ec.message()};
  }
  std::vector<ViewCamera> cameras = path;
  if (cameras.empty()) {
    ViewCamera c = g.start;
    c.width = options.width;
    c.height = options.height;
    cameras.push_back(c);
    if (close_up && !g.centres_mm.empty()) {
      ViewCamera near = CloseUpView(g, 0);
      near.width = options.width;
      near.height = options.height;
      cameras.push_back(near);
    }
  }
  // Before anything is drawn: an image this GL cannot hold is an error, not an abort.
  for (const ViewCamera& c : cameras)
    if (Status s = (*renderer)->CheckImageSize(c.width, c.height); !s.ok()) return s;
  RenderOptions render = options.render;
  render.exposure = options.exposure;  // the styles' tone is the screenshot's
  for (size_t i = 0; i < cameras.size(); ++i) {
    if (streaming) (void)(*renderer)->SettleStreams(cameras[i], options.settle_seconds);
    const RenderedImage img = (*renderer)->Render(cameras[i], g.lights, render);
    if (Status s = WriteRgb8(outs[i], ToneMap(img.rgb, options.exposure)); !s.ok()) return s;
  }
  return Status::Ok();
}

Status WriteVideo(const std::filesystem::path& first_png, size_t count,
                  const std::filesystem::path& video, double fps) {
  if (count < 2) return Error{video.string() + ": a video needs at least 2 images"};
  if (!(fps > 0 && fps <= 240)) return Error{video.string() + ": fps must be in (0, 240]"};
  std::error_code ec;
  if (std::filesystem::exists(video, ec))
    return Error{video.string() + ": already exists (a video is never written over a file)"};
  // The images' names as ffmpeg's pattern: stem_%03d.ext (ScreenshotPath's numbering).
  const std::string pattern = (first_png.parent_path() / (first_png.stem().string() + "_%03d" +
                                                          first_png.extension().string()))
                                  .string();
  const std::string rate = FormatNumber(fps);
  std::vector<std::string> args = {
      "ffmpeg",      "-nostdin", "-n",      "-loglevel", "error",
      "-framerate",  rate,       "-i",      pattern,     "-c:v",
      "libx264",     "-pix_fmt", "yuv420p", "-vf",       "pad=ceil(iw/2)*2:ceil(ih/2)*2",
      video.string()};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  // No shell: file names reach ffmpeg as they are.
  if (posix_spawnp(&pid, "ffmpeg", nullptr, nullptr, argv.data(), environ) != 0)
    return Error{video.string() +
                 ": ffmpeg is not installed (Debian: apt install ffmpeg); the images are written"};
  int status = 0;
  if (waitpid(pid, &status, 0) < 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::filesystem::remove(video, ec);  // ffmpeg's own partial file (-n: nothing was there)
    return Error{video.string() + ": ffmpeg failed (exit " +
                 std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + ")"};
  }
  return Status::Ok();
}

}  // namespace digitize::viewer
