// The framed painting as a scene (canvas height field + frame + wall, ray-traced with Embree) and
// the simulated structured-light scan of it, with its ground truth.
#pragma once

#include <memory>
#include <vector>

#include "digitize/core.h"
#include "digitize/scan.h"
#include "digitize_synth/painting.h"

namespace digitize::synth {

struct FrameOptions {
  bool enabled = true;
  double raise_mm = 25;  // frame top above the canvas plane (15-40 typical), sharp step inwards
  double width_mm = 45;  // frame moulding width (30-60 typical)
  double wall_depth_mm = 20;  // wall plane below the canvas plane (behind the painting)
  // Asymmetric moulding: per-side widths (canvas frame: left = X 0, right = X W, bottom = Y 0,
  // top = Y H, i.e. the top of the scan image when upright); 0 = width_mm.
  double left_mm = 0, right_mm = 0, top_mm = 0, bottom_mm = 0;
  // Bevel at the sight edge: the moulding starts at the canvas outline at the canvas plane and
  // rises outwards by bevel_height_mm over bevel_width_mm, then steps up to the profile (which
  // keeps its outer edge). 0 = the plain vertical step at the outline.
  double bevel_width_mm = 0, bevel_height_mm = 0;
  // Lip: the frame's top overhangs the canvas by lip_mm on every side (hiding that strip of the
  // canvas edge from a scanner looking straight on), as a plate from lip_gap_mm above the
  // canvas plane up to raise_mm. 0 = no lip.
  double lip_mm = 0, lip_gap_mm = 8;
  double Width(int side) const;  // side: 0 left, 1 right, 2 bottom, 3 top
  // The frame as the library's ray tests model it (height_field.h): the truth a canvas measured
  // from a scan of this frame should carry. None when disabled.
  FrameBoxes Boxes() const;
  Status Validate() const;
  // Validate() and, for a canvas of this size, a lip that leaves some of it in view.
  Status ValidateFor(double canvas_width_mm, double canvas_height_mm) const;
};

// Canvas-frame scene: the painting's grid surface, the frame (boxes around it) and the wall. Kept
// alive for ray queries (the photo-set renderer, photo_sim.h, reuses it).
//
// Geometry (canvas frame, mm; W x H = painting.width_mm x painting.height_mm):
//   - canvas: an Embree grid through the texel centres (two triangles per quad), extended by a
//     ring of vertices on the canvas outline [0, W] x [0, H] that repeat the border heights;
//   - frame (enabled): a moulding swept around the canvas, inner face a vertical step at the
//     canvas outline from the wall up to raise_mm (or a bevel from the canvas plane first), top
//     profile peaking at raise_mm, outer face a vertical drop to the wall at the side's width
//     from the canvas; a lip (lip_mm > 0) is a plate over the canvas's outer strip;
//   - frame disabled: the canvas's own sides (stretcher) drop vertically to the wall; they are
//     reported as Hit::kFrame (not canvas, not wall);
//   - wall: the plane Z = -wall_depth_mm, large enough to fill any view.
// The painting must outlive the scene. Invalid frame options throw (validate them first).
class Scene {
 public:
  Scene(const Painting& painting, const FrameOptions& frame);
  ~Scene();
  Scene(const Scene&) = delete;
  Scene& operator=(const Scene&) = delete;

  enum class Hit : uint8_t { kNone = 0, kCanvas = 1, kFrame = 2, kWall = 3 };
  struct RayHit {
    Hit what = Hit::kNone;
    double t = 0;           // distance along the unit direction
    Vec3d normal{0, 0, 1};  // geometric normal, canvas frame, unit, facing the ray origin
  };
  // Rays in the canvas frame (mm). Thread-safe. direction need not be unit.
  void Intersect(const std::vector<Vec3d>& origins, const std::vector<Vec3d>& directions,
                 std::vector<RayHit>& hits) const;
  // The same, each ray ending at distance max_t_mm[i] along its direction (a segment: hits
  // beyond are not reported). Shadow rays that must say WHAT blocks the light use this.
  void Intersect(const std::vector<Vec3d>& origins, const std::vector<Vec3d>& directions,
                 const std::vector<float>& max_t_mm, std::vector<RayHit>& hits) const;
  // Shadow rays: blocked[i] = 1 when anything lies on the segment from origins[i] along
  // directions[i] (need not be unit) up to distance max_t_mm[i], else 0. An any-hit query, about
  // twice as fast as Intersect. Thread-safe. A zero or non-finite direction is never blocked.
  void Occluded(const std::vector<Vec3d>& origins, const std::vector<Vec3d>& directions,
                const std::vector<float>& max_t_mm, std::vector<uint8_t>& blocked) const;
  const Painting& painting() const { return painting_; }
  const FrameOptions& frame() const { return frame_; }

 private:
  void IntersectImpl(const std::vector<Vec3d>& origins, const std::vector<Vec3d>& directions,
                     const std::vector<float>* max_t_mm, std::vector<RayHit>& hits) const;
  struct Impl;
  const Painting& painting_;
  FrameOptions frame_;
  std::unique_ptr<Impl> impl_;
};

enum class ScannerModel { kOrthographic, kPinhole };

struct ScanSimOptions {
  ScannerModel model = ScannerModel::kOrthographic;
  int width_px = 1024, height_px = 1024;  // scan grid (about 0.6 mm samples on the default canvas)
  double field_margin = 0.25;  // the field of view spans the canvas plus frame plus this share
                               // (negative: crops into it; see SimulateScan)
  double tilt_deg = 8;         // canvas plane tilt against the scanner's image plane
  double tilt_axis_deg = 30;   // in-plane direction of the tilt axis
  double roll_deg = 3;         // in-plane rotation of the canvas in the scan image
  Vec3d offset_mm{5, -3, 0};   // canvas centre off the optical axis (X, Y) and extra distance (Z)
  double distance_mm = 1000;   // scanner to canvas centre
  double noise_mm = 0.02;      // Gaussian sigma along the viewing ray
  double dropout = 0.01;       // share of samples lost at random
  int hole_blobs = 4;          // blob-shaped holes
  int border_hole_blobs = 0;   // blob-shaped holes centred on the visible canvas's outline
  double hole_blob_radius_px = 6;
  double outliers = 1e-4;  // share of samples displaced by +-(2..50) mm
  int exposures = 1;       // same pose, independent noise and dropouts
  uint64_t seed = 1;
  // A patch of a larger painting (patch_sim.h): the canvas point aim_mm (canvas frame, on the
  // plane Z = 0) takes the canvas centre's place in the pose (NaN: the canvas centre), and the
  // field of view spans field_mm at distance_mm (square pixels, the tighter axis decides; 0: the
  // footprint and field_margin as above). pose_error (canvas frame, applied to the canvas side
  // of the pose: true canvas_from_scan = pose_error * nominal canvas_from_scan) moves the head
  // away from the pose the options describe, without changing its camera.
  Eigen::Vector2d aim_mm{kMissing, kMissing};
  Eigen::Vector2d field_mm{0, 0};
  RigidTransform pose_error;
  Status Validate() const;
};

struct SyntheticScan {
  std::vector<Scan> exposures;      // same pose; independent noise, dropouts, holes, outliers
  RigidTransform canvas_from_scan;  // ground truth
  Grid<uint8_t> canvas_mask_scan;   // 1 where the scan ray hits the canvas (before dropouts)
  Grid<uint8_t> hit_scan;           // Scene::Hit per scan pixel
  // Bounding box (canvas frame, mm) of the canvas the scanner sees (the noise-free hits): the
  // canvas [0, W] x [0, H] less what the frame hides.
  Eigen::Vector2d visible_min_mm{0, 0}, visible_max_mm{0, 0};
  // What produced it (written to truth.json by WriteSyntheticScan).
  ScanSimOptions options;
  FrameOptions frame;
  double pixel_pitch_mm = 0;  // orthographic: ray spacing in the scan frame (0 for pinhole)
  double focal_px = 0;        // pinhole: focal length in pixels, principal point at the image
                              // centre (0 for orthographic)
};

// Pose (scan_from_canvas): the canvas centre goes to (offset.x, offset.y, distance + offset.z);
// with zero tilt and roll the canvas is upright in the scan image (canvas +X = scan +X, canvas +Y
// = scan -Y, i.e. canvas top at row 0, canvas +Z = scan -Z, towards the scanner); then roll_deg
// turns it about the scan Z axis and tilt_deg about the in-plane axis at tilt_axis_deg from scan
// +X. The field of view is centred on the optical axis; its extent is the canvas-plus-frame
// footprint (around the canvas centre, axis-aligned box in the image) times (1 + field_margin):
// with a margin >= 0 the view contains that box along both axes, with a negative margin it lies
// inside it along both axes (crop into the canvas; mind the offset).
// Pixel (i, j): orthographic ray from ((i + 0.5 - width/2) p, (j + 0.5 - height/2) p, 0) along +Z;
// pinhole ray from the origin through ((i + 0.5 - width/2) / f, (j + 0.5 - height/2) / f, 1).
// A ray's sample is its hit moved along the ray by the noise (and, for outliers, by +-2..50 mm).
// Deterministic for options.seed, independent of thread scheduling. Invalid options, or a pinhole
// pose that puts the scene behind the scanner, throw (validate first).
SyntheticScan SimulateScan(const Scene& scene, const ScanSimOptions& options);

// Painting resolution (texels on the long side, 64..8192) whose texel pitch is about 1.1x the
// scan's sample spacing on the canvas, so the truth holds no detail the scanner cannot resolve
// (ground truth for normals is then meaningful). Ignores tilt, which only stretches the sampling.
int MatchedResolution(const PaintingOptions& painting, const FrameOptions& frame,
                      const ScanSimOptions& scan);

}  // namespace digitize::synth
