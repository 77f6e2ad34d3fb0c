// Light directions of an RTI capture from a reflective sphere in the frame: the highlight of each
// image on a sphere of known (or detected) outline, under an orthographic camera looking along -z.
//
// Layer: relief (core only; OpenCV stays in the .cpp).
//
// Frames: pixel (u, v) = (column, row), pixel centres at integers; directions in the canvas frame
// of an RTI capture (x right, y towards row 0, z towards the camera), as a .lp stores them.
// A highlight at (u, v) on the circle (cx, cy, r) has the sphere normal
// n = ((u - cx) / r, -(v - cy) / r, sqrt(1 - ...)); the view is v = (0, 0, 1), so the light is the
// mirror direction l = 2 (n.v) n - v.
#pragma once

#include <string>
#include <vector>

#include "digitize/core.h"

namespace digitize {

struct SphereCircle {
  double cx = 0, cy = 0;  // centre, pixels
  double radius_px = 0;
};

struct SphereDetectOptions {
  double min_radius_px = 8, max_radius_px = 0;  // 0: half the image's shorter side
  Status Validate() const;
};

// The sphere's outline in `image` (any grey image where the sphere differs from its
// surroundings: e.g. the per-pixel mean or max over the capture), by OpenCV's HoughCircles on the
// image scaled to 8 bits; the strongest circle. Error when none is found (names the radii tried)
// or on an empty / non-finite image.
Result<SphereCircle> DetectSphere(const Grid<float>& image,
                                  const SphereDetectOptions& options = {});

struct SphereLightOptions {
  double highlight_fraction = 0.9;  // the highlight: pixels within the circle at >= this x the
                                    // image's brightest value there; their brightness-weighted
                                    // centroid is its position
  double rim_margin = 0.03;         // pixels beyond (1 - this) x radius are ignored: the rim's edge
                                    // pixels mix sphere and background
  double min_peak = 1e-4;           // a brightest value below this: no highlight (light behind)
  Status Validate() const;
};

struct SphereLight {
  bool found = false;                // false: no highlight (direction left at (0, 0, 1))
  Vec3d direction = Vec3d::UnitZ();  // unit, towards the light
  Eigen::Vector2d highlight_px = Eigen::Vector2d::Zero();
};

// One light per image (grey images, linear). Errors: an empty or wrongly sized image, a circle
// that does not fit the image or has radius < 2 px, invalid options.
Result<std::vector<SphereLight>> LightsFromSphere(const std::vector<const Grid<float>*>& images,
                                                  const SphereCircle& circle,
                                                  const SphereLightOptions& options = {});

}  // namespace digitize
