// What the photo-set sources share (private to the library): the calibration reader
// (photo_calibration.cpp), the RTI reader (rti_lp.cpp), pixel loading (photo_pixels.cpp) and the
// camera, light and path checks (photo_checks.cpp). The contract is digitize/photo_set.h.
#pragma once

#include <filesystem>
#include <string>

#include "digitize/core.h"
#include "digitize/image_io.h"
#include "digitize/photo_set.h"

namespace digitize::photo_detail {

// Photo-set messages show numbers to 4 significant digits (FormatNumber).
inline constexpr int kShownDigits = 4;
// Images larger than this per side are refused in a camera (a corrupt value, not a sensor).
inline constexpr int kMaxImageSide = 1 << 16;
// Below this length a light direction is a zero vector, not a direction.
inline constexpr double kMinDirectionNorm = 1e-9;

inline std::string Size(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// photo_pixels.cpp

// The header only (cheap), so that a missing, unreadable or wrongly sized image is reported
// before seconds are spent decoding the others. Errors name the file.
Result<ImageHeader> ReadHeader(const std::filesystem::path& path);
// kAuto: sRGB for integer samples, linear for float ones.
ColourEncoding Resolve(ColourEncoding declared, bool integer_samples);
// Every photo's image header checked against its camera, its encoding resolved.
Status ProbeAll(PhotoSet& set);

// photo_checks.cpp

// PhotoSetOptions::allow_outside_paths: `image` (what `entry` of the file in `dir` names, as
// `written`) must resolve, symbolic links and ".." included, to a path inside dir's.
Status CheckImageInsideFolder(const std::filesystem::path& image, const std::filesystem::path& dir,
                              const std::string& entry, const std::string& written,
                              const PhotoSetOptions& options);
// No image listed twice.
Status CheckDistinctImages(const PhotoSet& set);

}  // namespace digitize::photo_detail
