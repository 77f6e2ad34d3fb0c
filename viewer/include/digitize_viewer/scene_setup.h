// The standard single-painting scene of the viewer's tests, benchmark and screenshots: the
// painting in its own canvas frame (world = canvas), one white point light, and the Embree
// reference of any view of it (relight.h) -- so every rendering mode has a measurable error.
//
// Layer: viewer (libdigitize only).
#pragma once

#include <vector>

#include "digitize/core.h"
#include "digitize/height_field_tracer.h"
#include "digitize/pack.h"
#include "digitize/photo_set.h"
#include "digitize/relight.h"
#include "digitize_viewer/renderer.h"
#include "digitize_viewer/view.h"

namespace digitize::viewer {

// The light of the comparisons: a point light up and to the upper left of the canvas centre,
// (-0.35 W, +0.25 H, 0.9 max(W, H)) from it, at 45-ish deg elevation, white, with intensity
// such that a white Lambertian surface (albedo 1, rho = 1 / pi) at the centre, facing it, reads
// radiance 1: I = pi d^2. Radiance 1 is therefore "paper white" and the PSNR peak we use.
Light StandardLight(const Pack& pack);
inline constexpr double kPsnrPeak = 1.0;

// The Embree reference of a view: RenderRelit on the pack's full height field, same camera
// (canvas_from_scan = identity), same light, shadows as asked.
RelitImage RenderReference(const HeightFieldTracer& tracer, const Pack& pack,
                           const ViewCamera& view, const Light& light, bool shadows);

// The reference mask without its outline: pixels whose 8 neighbours also see the canvas. On a
// silhouette pixel both renderers point-sample a step edge, and a sub-pixel difference in where
// the edge falls (the rasteriser snaps vertices to 1/256 px; the bump plane's outline is the
// slab's, not the height field's) flips the whole pixel: at the far grazing view the canvas is a
// strip a few pixels high and its outline alone sets the PSNR. Comparisons report both masks.
Grid<uint8_t> InteriorMask(const Grid<uint8_t>& mask);

// Antialiased comparison. Both renderers point-sample one ray per pixel; at grazing views a
// pixel spans tens of texels along the canvas, so a sub-pixel difference picks another texel and
// the per-pixel error is aliasing noise, not a rendering error. The comparison that matters for
// a display is between box-filtered images: render both at s x the size (Supersampled: same eye,
// target and fov, s x the pixels) and average s x s blocks (Downsample); compare the pixels whose
// s x s reference samples all see the canvas (DownsampleMask).
ViewCamera Supersampled(const ViewCamera& view, int s);
Grid<Vec3f> Downsample(const Grid<Vec3f>& image, int s);
Grid<uint8_t> DownsampleMask(const Grid<uint8_t>& mask, int s);
inline constexpr int kCompareSupersampling = 4;

// Temporal coherence of a look (the styles' test and benchmark): the painting rendered (world =
// canvas frame, technique kBump so the depth buffer holds the bump plane z = delta0) along
// `path`; each frame warped into the next through that plane and the two cameras, sampled
// bilinearly. Mean absolute display-luminance residual over the canvas pixels seen in both
// frames (8 px from the image border, 2 mm inside the canvas), warped and unwarped: marks that
// move with the surface make the first small and far below the second.
struct CoherenceResidual {
  double warped = 0, unwarped = 0;
  size_t pixels = 0;  // summed over the path's steps
};
CoherenceResidual MeasureCoherence(Renderer& renderer, const Pack& pack, const Light& light,
                                   const std::vector<ViewCamera>& path,
                                   const RenderOptions& options);
// A slow path over the painting from its framed face view: `steps` steps, each 0.5 % of the
// distance sideways, 0.2 % up and 1 % closer.
std::vector<ViewCamera> SlowPath(const Pack& pack, int width, int height, int steps);

}  // namespace digitize::viewer
