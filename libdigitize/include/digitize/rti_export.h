// Exports of an RTI fit (rti_basis.h) in the formats RTI users open, and readers of what they
// write (for the round-trip tests and for inspecting a file):
//   - .ptm, PTM_1.2 PTM_FORMAT_LRGB, for RTIViewer (Malzbender, Gelb, Wolters, "Polynomial
//     texture map (.ptm) file format", HP Labs 2001): a text header
//         PTM_1.2\nPTM_FORMAT_LRGB\n<width>\n<height>\n<6 scales>\n<6 biases>\n
//     then, uncompressed, 6 luminance coefficient bytes per pixel for every pixel, then 3 RGB
//     bytes per pixel for every pixel, both in reversed scanline order (the image's BOTTOM row
//     first). Coefficient i = scale_i (byte - bias_i), in the order a0..a5 of
//     L = a0 lu^2 + a1 lv^2 + a2 lu lv + a3 lu + a4 lv + a5 (the PTM order of rti_basis.h), and
//     a viewer shows code = clamp(L x RGB byte, 0, 255) per channel.
//   - CNR-ISTI relight's folder, which relight and OpenLIME (the web viewer) open: info.json
//     {"width", "height", "format": "jpg", "type": "ptm" | "hsh", "colorspace": "rgb",
//     "nplanes": 3 x coefficients, "quality", "lights": [x, y, z, ...] (the fitted lights),
//     "materials": [{"scale": [...], "bias": [...]}]} and plane_0.jpg, plane_1.jpg, ...: plane p
//     (coefficient p / 3, channel p % 3) is channel p % 3 of plane_<p / 3>.jpg; a coefficient in
//     8-bit units is 255 (byte / 255 - bias_p) scale_p (relight's Material::Plane::dequantize),
//     so in the fit's fractions (rti_basis.h) it is (byte / 255 - bias_p) scale_p. Coefficients
//     are in relight's order: PTM 1, lu, lv, lu^2, lu lv, lv^2; HSH as rti_basis.h.
// Both are fitted on sRGB codes (relight and RTIViewer show what is stored): a linear fit is
// refused. Quantisation: every coefficient (plane) is mapped onto its full range over the image
// (no clipping of outliers, unlike relight's quantiles), so the error of one coefficient is at
// most half a step, (max - min) / 510, plus, in the JPEG planes, the JPEG error.
//
// Layer: photos (rti_basis.h; files through image_io.h / output_dir.h).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/photo_set.h"
#include "digitize/rti_basis.h"

namespace digitize {

// The content of an LRGB .ptm file. Pixels here are in image order (row 0 = the image's top);
// the file's reversed scanline order is the writer's and reader's business.
struct PtmLrgb {
  int width = 0, height = 0;
  std::array<float, 6> scale{};
  std::array<int, 6> bias{};
  std::vector<uint8_t> coefficients;  // 6 per pixel, a0..a5
  std::vector<uint8_t> rgb;           // 3 per pixel
};

// LRGB from an RGB PTM fit: per pixel, the luminance polynomial is the mean of the channels'
// and the RGB bytes are the channels' least-squares ratios to it over the fitted lights, scaled
// so the largest is 255 (the luminance takes the factor): exact when a pixel's colour does not
// change with the light (a matte pixel), an approximation otherwise (what LRGB is). Errors: the
// fit is not a PTM, or not fitted on sRGB.
Result<PtmLrgb> EncodePtmLrgb(const RtiFit& fit);
// What RTIViewer shows under `light` (z > 0; else black): codes / 255 as sRGB fractions.
Grid<Vec3f> RelightPtm(const PtmLrgb& ptm, const Vec3d& light);

// EncodePtmLrgb, then the file, atomically (image_io.h), never onto or above an input
// (CheckOutputPath against `inputs`).
Status WritePtm(const std::filesystem::path& path, const RtiFit& fit,
                const std::vector<std::filesystem::path>& inputs = {});
// Reads an LRGB .ptm (PTM_1.2 or PTM_1.1 header, PTM_FORMAT_LRGB only). Errors name the file:
// another format, a bad header field, a truncated file.
Result<PtmLrgb> ReadPtm(const std::filesystem::path& path);

// ---------------------------------------------------------------------------------------------
// relight / OpenLIME folder.

struct RelightFolderOptions {
  int jpeg_quality = 95;                      // 1-100, of the plane JPEGs (4:4:4 chroma)
  std::vector<std::filesystem::path> inputs;  // the run's inputs: never written onto or above
  Status Validate() const;
};

// Writes info.json and the plane JPEGs into `dir` as one output folder (output_dir.h: command
// "rti", content "relight-rti"; replaced only when new, empty or an earlier such output). Errors:
// a linear fit, options, the folder rules, I/O.
Status WriteRelightFolder(const std::filesystem::path& dir, const RtiFit& fit,
                          const RelightFolderOptions& options = {});

// Reads a folder WriteRelightFolder wrote (type ptm or hsh, colorspace rgb, 12 / 18 / 27
// planes) back into an RtiFit (srgb, coefficients dequantised into rti_basis.h's order; lights
// from "lights" when present). Errors name the file and the field.
Result<RtiFit> ReadRelightFolder(const std::filesystem::path& dir);

// ---------------------------------------------------------------------------------------------
// `digitize rti`: an RTI capture -> a classical RTI fit, its held-out score, its exports.

struct RtiRunOptions {
  std::string photos;       // the .lp file fitted
  std::string held_out;     // optional .lp: relit from the fit and scored (Srgb8PsnrAccumulator)
  std::string ptm;          // optional .ptm to write (the PTM basis only)
  std::string relight_dir;  // optional relight / OpenLIME folder to write
  PhotoSetOptions photo;
  RtiFitOptions fit;
  RelightFolderOptions relight;  // its inputs are set here (every input of the run)
  Status Validate() const;       // photos given; .ptm only with the PTM basis and sRGB; options
};

struct RtiHeldOutImage {
  std::string entry;
  Srgb8Score score;
};
struct RtiRunResult {
  RtiFit fit;
  int photos = 0;
  std::vector<RtiHeldOutImage> held_out_images;  // per image (empty without held_out)
  std::optional<Srgb8Score> held_out;            // pooled
  double seconds_held_out = 0;                   // relighting + scoring
};

// Order: options checked; the photos and the held-out photos read (a bad file fails before any
// work); every output checked against every input (the .lp files and their images) and the
// relight folder against the folder rules; the fit; the held-out score; the .ptm; the folder.
// Errors name the file or option.
Result<RtiRunResult> RunRti(const RtiRunOptions& options);

}  // namespace digitize
