// An RTI capture (photos + light directions, camera straight down, no scan) becomes a canvas the
// fit can use like a scan's: per-image light intensities estimated from the capture itself,
// per-texel normals by robust photometric stereo (photometric_stereo.h) and a height field by
// integrating them (normal_integration.h), with relief boxes as preprocess makes them.
//
// Layer: pipeline (photo_set.h, photometric_stereo.h, normal_integration.h, relief.h).
//
// WHY. On the flat canvas (normals straight up) a relit texel depends only on the light's
// elevation: the lit and the shadowed side of a stroke look alike, and a raking light gives a
// flat picture. Photometric-stereo normals give the fit the azimuth, the height field gives cast
// shadows and the gallery a surface.
//
// INTENSITIES. A hand-held light's distance varies from image to image (rti_icon: the
// estimated intensities span 0.5 .. 2.6), which the fit would otherwise read as reflectance.
// The estimate (mean 1) multiplies each fitted photo's light. A photo the fit did not see (a
// held-out one) gets the intensity its light direction predicts from the fitted lights
// (PredictRtiIntensity): on rti_icon the intensities follow the direction (how the light was
// held), which predicts a held-out image's intensity to ~13 % RMS where a constant is off by
// ~33 %.
#pragma once

#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/normal_integration.h"
#include "digitize/photo_set.h"
#include "digitize/photometric_stereo.h"
#include "digitize/preprocess.h"

namespace digitize {

struct RtiCanvasOptions {
  bool normals = true;    // photometric stereo; false: the flat canvas, normals straight up
  bool height = true;     // integrate the normals into a height field (needs normals)
  PhotometricStereoOptions stereo;  // estimate_intensities on by default
  NormalIntegrationOptions integration;
  ReliefOptions relief;
  // Intensity of a light the fit did not see: the intensities of the fitted lights within
  // about this angle (Gaussian kernel in degrees, geometric mean) of its direction.
  double intensity_kernel_deg = 8.0;
  // After the first fit, each photo's intensity is corrected by its gain against the fit
  // (CheckPhotoResiduals: the full reflectance model, where photometric stereo saw a Lambertian
  // one) and the fit is run again, this many times. rti_icon: 25.7 -> see docs/bench_rti.txt.
  int refine_intensity_rounds = 1;
  Status Validate() const;  // names the option
};

struct RtiCanvas {
  PreprocessedCanvas canvas;        // the capture's grid at its pitch; normals and heights
  std::vector<double> intensities;  // per photo of the set, mean 1 (all 1 without estimation)
  std::string stereo_brief;         // PhotometricStereoResult::Brief(), empty without normals
  std::string integration_brief;    // NormalIntegrationResult::Brief(), empty without height
  double seconds = 0;
  // "normals: 99.2 % ok ...; intensities 0.52 .. 2.63; height: poisson ...; relief 3 boxes"
  std::string Brief() const;
};

// The canvas of an RTI capture whose pixels are loaded, and each photo's light multiplied by its
// estimated intensity (irradiance for directional lights, intensity for point lights). Errors:
// not an RTI capture, pixels not loaded, images of different sizes, invalid options, the stages'
// own errors (named).
Result<RtiCanvas> RtiCanvasFor(PhotoSet& rti, const RtiCanvasOptions& options = {},
                               const ProgressCallback& progress = nullptr);

// Multiplies photo i's light and intensities[i] by factors[i] (> 0 and finite; others are left
// as they are). Sizes must agree (checked: throws InvariantError otherwise).
void ScaleRtiIntensities(PhotoSet& rti, std::vector<double>& intensities,
                         const std::vector<double>& factors);

// The intensity a light towards `direction` (unit, canvas frame) has in the capture whose
// lights are `fitted` with `intensities` (RtiCanvas::intensities; fitted lights as read, before
// RtiCanvasFor scaled them): the kernel-weighted geometric mean of the fitted intensities; 1
// without any fitted light. Point lights use their direction from the canvas origin.
double PredictRtiIntensity(const PhotoSet& fitted, const std::vector<double>& intensities,
                           const Vec3d& direction, double kernel_deg);

// Multiplies each light of `other` (e.g. the held-out photos of the same capture) by its
// PredictRtiIntensity. `fitted` as read (before RtiCanvasFor scaled its lights).
void ApplyPredictedIntensities(const PhotoSet& fitted, const std::vector<double>& intensities,
                               double kernel_deg, PhotoSet& other);

}  // namespace digitize
