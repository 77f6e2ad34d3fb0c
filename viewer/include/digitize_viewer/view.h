// Viewer cameras: a look-at pinhole camera for the real-time renderer that converts to the
// library's Camera, so RenderRelit (the Embree reference) renders exactly the same view.
//
// Layer: viewer (depends on libdigitize only). No GL type here.
//
// Frames. The viewer's world frame is the scan frame of digitize::Camera. For single-painting
// views (tests, benchmark, screenshots) the world IS the painting's canvas frame (canvas_from_scan
// = identity): X right, Y up the canvas, Z out of the canvas towards the viewer, mm. The gallery
// places canvases in a room whose Z axis points up (gallery.h).
#pragma once

#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/photo_set.h"

namespace digitize::viewer {

struct ViewCamera {
  Vec3d eye_mm = Vec3d(0, 0, 1000);  // centre of projection, world frame
  Vec3d target_mm = Vec3d::Zero();   // looked-at point
  Vec3d up = Vec3d::UnitY();         // world direction that appears upwards (not along the view)
  double fov_y_deg = 40;             // vertical field of view, degrees, (0, 180)
  int width = 256, height = 192;     // image size, px
  double near_mm = 1, far_mm = 1e5;  // depth range of the rasteriser (not used by the reference)

  // eye != target, up not parallel to the view, fov in (0, 180), sizes > 0, 0 < near < far.
  Status Validate() const;
};

// The pinhole Camera of the same view (OpenCV convention, photo_set.h): fx = fy = (height / 2) /
// tan(fov_y / 2), principal point at the image centre ((w - 1) / 2, (h - 1) / 2), camera_from_scan
// with z along the view, x to the right, y down. Both renderers then sample pixel centres.
Camera ToCamera(const ViewCamera& view);

// The paper's views (Table 1): distance close / framed / far x angle face / grazing. Definitions
// (for a canvas of W x H mm, image aspect a = width / height, vertical fov 40 deg):
//   framed distance D = 0.55 max(H, W / a) / tan(20 deg): the canvas fills the image with a
//   10 % margin; close = D / 4 (a quarter of the canvas across); far = 4 D.
//   face: eye on the canvas normal through the centre; grazing: eye at 72 deg from the normal,
//   towards canvas -Y (looking "up" the canvas), at the same distance from the centre.
// The target is always the canvas centre at height 0.
enum class ViewDistance { kClose, kFramed, kFar };
enum class ViewAngle { kFace, kGrazing };
struct PaperView {
  ViewDistance distance = ViewDistance::kFramed;
  ViewAngle angle = ViewAngle::kFace;
  std::string Name() const;  // "framed-face", "close-grazing", ...
};
inline constexpr double kGrazingDeg = 72.0;
std::vector<PaperView> AllPaperViews();  // the six, close first, face before grazing
ViewCamera MakePaperView(double canvas_width_mm, double canvas_height_mm, const PaperView& view,
                         int width, int height);

}  // namespace digitize::viewer
