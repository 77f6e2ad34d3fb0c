// The virtual gallery: a room (floorboards, walls, ceiling, skirting, a lighting track), packs
// hung along the back wall at their physical size in moulded frames, a picture light (a spot on
// the track) per painting, a starting camera; scripted camera paths (JSON) for screenshots;
// loading packs for the viewer with errors reported, never thrown; the headless gallery
// screenshots `digitize demo` ends with.
//
// Layer: viewer (libdigitize only). Frames: the gallery's world frame is in mm with Z UP, the
// floor at Z = 0, the back wall at Y = room depth; a canvas hangs with its X along world +X, its
// Y along world +Z and its normal (canvas +Z) along world -Y, into the room.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/pack.h"
#include "digitize/photo_set.h"
#include "digitize_viewer/pyramid_stream.h"
#include "digitize_viewer/renderer.h"
#include "digitize_viewer/view.h"

namespace digitize::viewer {

struct GalleryOptions {
  double min_room_width_mm = 6000;  // grown to fit the paintings
  double room_depth_mm = 6000;
  double room_height_mm = 3200;
  double centre_height_mm = 1550;   // canvas centres hang at eye height (museum practice)
  double gap_mm = 1200;             // between frames, and from the side walls
  double frame_mm = 70;             // frame moulding width
  double light_distance_mm = 1500;  // each picture light: this far in front, 30 deg above
  double view_distance_mm = 2500;   // the start camera from the first painting
  Status Validate() const;          // every length > 0
};

struct Gallery {
  Room room;                                      // boxes, the picture lights' cones, ambient
  std::vector<RigidTransform> world_from_canvas;  // one per painting, in the given order
  std::vector<Vec3d> centres_mm;                  // each canvas centre, world frame
  std::vector<Eigen::Vector2d> sizes_mm;          // each canvas (width, height)
  std::vector<Light> lights;                      // one picture light per painting
  ViewCamera start;  // a visitor view_distance_mm from the first painting, the room and the next
                     // painting in view
  double width_mm = 0, depth_mm = 0, height_mm = 0;
};

// sizes_mm: each painting's (width, height). Light intensities make a white Lambertian canvas
// centre read radiance 1 (paper white, as scene_setup.h). An empty list gives the empty room.
Gallery MakeGallery(const std::vector<Eigen::Vector2d>& sizes_mm,
                    const GalleryOptions& options = {});

// A close view of painting `index` that shows its relief: from 35 cm, 35 deg off its normal
// towards the left and a little above, looking at the centre (the picture light then rakes
// across the relief towards the camera's side).
ViewCamera CloseUpView(const Gallery& gallery, size_t index);

// A scripted tour (`digitize-viewer --tour N`): from the start view to the front of the first
// painting (3x its longer side away, 0.4 to 1.2 m), up to its close-up and back, then to the
// front of each next painting in turn; `frames`
// (>= 2) cameras of width x height, eased in and out between those key views and spread by the
// distance walked, every eye inside the room. An empty gallery tours its start view only.
std::vector<ViewCamera> GalleryTour(const Gallery& gallery, int frames, int width, int height);

// Reads a pack for the viewer (ReadPack). The error names the file; nothing is thrown.
Result<Pack> LoadPackForViewer(const std::filesystem::path& path);
// Whether `path` holds a tiled pack (version 3, from its header alone): the viewer streams those
// (Renderer::AddStreamedPainting) instead of reading them whole.
bool IsTiledPack(const std::filesystem::path& path);

// Camera path, docs/formats.md "Camera paths":
//   {"format": "digitize.camera_path", "version": 1, "width": 640, "height": 480,
//    "fov_y_deg": 50, "frames": [{"eye": [x, y, z], "target": [x, y, z], "up": [0, 0, 1]}, ...]}
// width, height, fov_y_deg and up are optional (640, 480, 50, +Z); every frame is validated.
// Errors name the file and the frame.
Result<std::vector<ViewCamera>> ReadCameraPath(const std::filesystem::path& path);

struct GalleryShotOptions {
  int width = 1280, height = 720;
  RenderOptions render;  // technique etc.; ambient 0.05 by default for the room
  double exposure = 1.0;
  // The run's inputs (packs, camera path): no screenshot is written onto, into or above them.
  std::vector<std::filesystem::path> inputs;
  // Without a camera path: also the first painting's CloseUpView, written here (empty: not).
  std::filesystem::path close_up;
  // Tiled packs streamed (pyramid_stream.h), hung after the packs; before each image every tile
  // its view needs is loaded (Renderer::SettleStreams, at most settle_seconds).
  std::vector<std::filesystem::path> streamed;
  StreamOptions stream;
  double settle_seconds = 120;
  GalleryShotOptions() { render.ambient = 0.05; }
};

// The file image `index` of `count` is written to: out_png itself for a single image, else
// out_png with _NNN before the extension (walk/shot.png -> walk/shot_000.png, ...).
std::filesystem::path ScreenshotPath(const std::filesystem::path& out_png, size_t index,
                                     size_t count);

// Headless (EGL surfaceless): hangs the packs in a gallery, renders its start view (and the
// close-up when options.close_up is set), or each camera of `path` when given (written to
// ScreenshotPath(out_png, i, path.size())), and writes
// 8-bit sRGB images in the format the extension names (.png, .jpg, .tif; .exr holds their linear
// values), creating out_png's folder when missing. Errors, before anything is rendered: an
// unknown extension, an output onto, into or above an input or the current directory
// (CheckOutputPath), an image size this GL cannot render (Renderer::CheckImageSize), no GL
// context. A pack the viewer refuses (PreparePainting, AddPainting) is appended to `*failed`
// (naming it) and the others are hung and rendered; with failed = nullptr it is the error. A
// failed write leaves the previous file in place.
Status RenderGalleryScreenshots(const std::vector<std::pair<std::string, Pack>>& packs,
                                const std::filesystem::path& out_png,
                                const std::vector<ViewCamera>& path = {},
                                const GalleryShotOptions& options = {},
                                std::vector<std::string>* failed = nullptr);

// Hangs the packs (read whole) and then the tiled packs `streamed` (opened with
// `stream_options`) in one gallery, each added to `renderer` (AddPainting /
// AddStreamedPainting); every pack refused on the way is appended to `refused`, naming it. What
// the screenshots and the window both hang.
struct GalleryScene;  // painting_setup.h
GalleryScene HangInRenderer(Renderer& renderer,
                            const std::vector<std::pair<std::string, Pack>>& packs,
                            const std::vector<std::filesystem::path>& streamed,
                            const StreamOptions& stream_options, std::vector<std::string>& refused);

// Encodes the images ScreenshotPath(first_png, i, count), i = 0 .. count - 1, into `video`
// (H.264 in the container its extension names, `fps` frames a second) with ffmpeg, run without a
// shell. Errors: fewer than 2 images, ffmpeg not installed (the message says so: Debian's
// package `ffmpeg`), `video` already there (never overwritten), ffmpeg failing (its exit code).
Status WriteVideo(const std::filesystem::path& first_png, size_t count,
                  const std::filesystem::path& video, double fps = 24);

}  // namespace digitize::viewer
