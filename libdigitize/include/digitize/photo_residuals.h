// After a fit: which photos disagree with it, and how. Each photo is re-rendered from the canvas
// and the fitted maps (RenderRelit, shadows by the relief on) and compared with the photo over the
// pixels that see a canvas texel and are not flagged (NaN, saturated) in the photo:
//   - gain: the photo's brightness relative to the fit, observed / predicted luminance -- the
//     median of the per-pixel ratios over well-exposed pixels, refined by a least-squares scale
//     over the pixels whose ratio is within gain_inlier_band of that median (a shadow or a
//     highlight the fit misses does not pull it). An uncalibrated light intensity (RTI flashes,
//     a light's power that drifted) shows here;
//   - misregistration: the shift of the photo's content relative to its relit image, by phase
//     correlation of the two luminance images (cv::phaseCorrelate, Hanning window) over the
//     bounding box of the canvas in the relit image; pixels inside the box that do not see the
//     canvas or are flagged take the image's mean there, so the canvas outline (the same in
//     both: it comes from the relit mask) carries no weight. A camera pose that is off shows here.
//     Beyond max_shift_px, the relit image is moved by the shift onto the photo (bilinear): the
//     shift is reported only when the moved image matches the photo better (residual RMS after
//     the gain, min_shift_improvement), and the gain is then measured again on it: misregistered
//     pixels compare neighbouring texels, which biased the ratio by 2 % at a 4-texel shift;
//   - residual RMS (linear, all channels, unclipped) before and after applying the gain.
// A shift is given in photo pixels (x right, y down: the photo's content sits at relit + shift),
// and in mm and texels on the canvas from the camera's local scale at the canvas centre.
//
// Layer: samples (relight.h, photo_set.h, reflectance_maps.h).
//
// Degenerate photos: a photo with fewer than min_pixels well-exposed canvas pixels (a black
// photo, a camera that misses the canvas, everything saturated) gets gain 1, shift 0 and the flag
// kResidualTooFewPixels, and is named in Warnings(); nothing NaN/Inf ever leaves (checked).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/photo_set.h"
#include "digitize/reflectance_maps.h"

namespace digitize {

struct PhotoResidualOptions {
  // Pixels whose relit luminance is below this (linear; 1 = the white of an 8-bit photo) do not
  // enter the gain: at 0.01 an 8-bit sRGB code step is ~4 % of the value, and darker pixels are
  // mostly quantisation and noise.
  double min_luminance = 0.01;
  double gain_inlier_band = 0.2;  // relative band around the median ratio kept for the refinement
  size_t min_pixels = 256;        // well-exposed canvas pixels below which a photo is not judged
  // Warn when |ln gain| exceeds this: ln 1.1 (10 %). Flash-to-flash variation of a studio or RTI
  // light is a few per cent, and a 10 % gain already costs ~20 dB on a mid-grey (0.3 x 0.1 error
  // vs 1 peak), so beyond it the light's intensity is wrong, not the fit.
  double max_abs_log_gain = 0.0953101798;
  // Warn when the shift exceeds this, px: phase correlation is accurate to ~0.1 px on a textured
  // painting, but on a real capture the model's own mismatch (glints, shadows it renders a little
  // off) moves the correlation peak too: rti_icon, a fixed camera, shows up to 0.6 px on half its
  // photos. A misregistration that costs what is measured here (4 texels: 1.8 dB held-out) is
  // several pixels.
  double max_shift_px = 1.0;
  // Below this phase-correlation peak (0..1) the shift is not trusted (flag kResidualShiftWeak,
  // no shift warning): a flat, textureless image correlates with anything.
  double min_shift_response = 0.02;
  // A shift beyond max_shift_px is reported only when the relit image moved by it matches the
  // photo better: its residual RMS (after the gain) at most (1 - this) of the unmoved one's. A
  // real misregistration of a few pixels more than halves it (photo_residuals_test); a spurious
  // peak does not lower it at all (a grid camera's photo of a canvas corner under a grazing light
  // correlated at a 129 px "shift" that made the RMS worse).
  double min_shift_improvement = 0.1;
  // Images (the canvas's bounding box) larger than this along either side are averaged down by
  // an integer factor for the correlation (the shift is scaled back): bounds the FFT.
  int max_correlation_side_px = 1024;
  bool shadows = true;  // relight with relief shadows (as the fit's samples were)
  int num_threads = 0;  // RenderRelit's; 0 = all cores

  Status Validate() const;
};

// Bits of PhotoResidual::flags.
enum PhotoResidualFlag : uint8_t {
  kResidualTooFewPixels = 1,  // fewer than min_pixels well-exposed canvas pixels: not judged
  kResidualGainOff = 2,       // |ln gain| > max_abs_log_gain
  kResidualShifted = 4,       // shift > max_shift_px (and the correlation is trusted)
  kResidualShiftWeak = 8,     // correlation peak below min_shift_response, or moving the relit
                              // image by the shift does not match the photo better: not trusted
};

struct PhotoResidual {
  std::string entry;  // the photo's calibration entry ("calib.json: images[12]")
  std::string path;   // the photo's image file
  double gain = 1.0;  // observed / predicted brightness (1 = as the fit predicts)
  double shift_x_px = 0, shift_y_px = 0;  // photo content relative to the relit image
  double shift_px = 0;                    // magnitude
  double shift_mm = 0;                    // on the canvas (0 when the scale is unknown)
  double shift_texels = 0;                // shift_mm / canvas pitch
  double shift_response = 0;              // phase-correlation peak, 0..1
  double rms = 0;                         // linear, all channels, over the compared pixels
  double rms_after_gain = 0;              // with the relit image multiplied by gain
  size_t pixels = 0;                      // compared (canvas, unflagged)
  size_t gain_pixels = 0;                 // well-exposed ones the gain was measured on
  uint8_t flags = 0;                      // PhotoResidualFlag bits
};

struct PhotoResidualReport {
  std::vector<PhotoResidual> photos;  // in set order
  PhotoResidualOptions options;
  double seconds = 0;
  // "12 photos checked: 1 with its gain off (max 1.30), 1 shifted (max 3.8 px), 0 not judged;
  // 2.1 s"
  std::string Brief() const;
  // One line per photo that is off or was not judged, naming its file and entry, e.g.
  // "photos/img_12.png (calib.json: images[12]): the photo is shifted by (3.8, 0.2) px (1.9
  // texels, 0.95 mm) from its relit image: its camera pose is off (misregistration)".
  std::vector<std::string> Warnings() const;
};

// Errors: invalid options, sizes that differ, photos not loaded (naming the entry and file), a
// tracer build failure. Renders each photo once.
Result<PhotoResidualReport> CheckPhotoResiduals(const HeightField& canvas,
                                                const Grid<Vec3f>& normals,
                                                const ReflectanceMaps& maps,
                                                const RigidTransform& canvas_from_scan,
                                                const PhotoSet& photos,
                                                const PhotoResidualOptions& options = {});

}  // namespace digitize
