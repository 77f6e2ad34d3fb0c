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

}  // namespace digitize::viewer
