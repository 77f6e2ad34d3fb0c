// Photo sets, as users have them (docs/formats.md): registered photographs of the painting under
// known lights, read from a calibration JSON or from an RTI capture (.lp), with their pixels
// loaded as linear RGB. Formats, units and frames: docs/formats.md, "Photo sets".
//
// Layer: io (core + image_io). No OpenImageIO or JSON type appears here.
//
// Frames. Cameras and lights live in the SCAN frame (mm), the frame the canvas was extracted in,
// so a PhotoSet is tied to a preprocessed canvas through its `canvas_from_scan`. An RTI capture
// has no scan: its scan frame IS the canvas frame of a flat canvas whose texel grid is the image
// grid (canvas_from_scan = identity; see ReadRtiCapture).
//
// Camera frame: OpenCV convention, x right, y down (image rows), z along the viewing direction.
// Pixel (u, v) = (column, row) with the CENTRE of pixel (0, 0) at (0, 0), as in OpenCV.
//
// Pixels. Loading is eager by default (PhotoSetOptions::load_pixels): every image is decoded,
// linearised and checked in parallel (TBB, one task per image). With load_pixels = false the
// readers check everything but the pixels (files exist, open, have the camera's size) and
// LoadPhotoPixels / LoadPhoto decode later, e.g. one photo at a time to bound memory
// (a 2048x2048 photo takes 48 MiB as float RGB).
//
// NaN / Inf policy: a pixel with a non-finite channel is never propagated. Its colour is set to
// (0, 0, 0) and it is flagged kPixelNonFinite in Photo::flags; the count is reported per photo and
// per set. A photo with more than max_non_finite_fraction of such pixels is refused (an error
// naming the file): it is corrupt, not a photo with a few bad pixels.
//
// Saturation: a pixel with a channel at the top of its encoding (integer images: the encoded value
// >= saturation_encoded, by default the maximum code 255 / 65535; float images: a linear value
// >= float_saturation_level, by default never) is flagged kPixelSaturated and counted; its colour
// is kept (it is a lower bound of the true radiance) and the fit must reject it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "digitize/core.h"
#include "digitize/height_field.h"

namespace digitize {

class ImageRegionReader;  // image_io.h

// ---------------------------------------------------------------------------------------------
// Camera.

// Projection of a camera-frame point (x, y, z) in mm to pixel (u, v):
//   pinhole:       u = fx x / z + cx,              v = fy y / z + cy
//   orthographic:  u = x / pixel_pitch_mm + cx,    v = y / pixel_pitch_mm + cy  (rays along +z)
enum class CameraModel { kPinhole, kOrthographic };

// Bounds beyond which a camera is a typo or a unit mix-up (fx in mm, a pitch in metres), not a
// camera: `fx: 1e-300` (a 180-degree view) fitted "76.9 % converged" with every texel sampling
// one pixel. Camera::Validate checks the first two, CheckCanvasFootprint the others
// (docs/formats.md, "Bounds on cameras").
inline constexpr double kMinFieldOfViewDeg = 0.1;    // pinhole, horizontal and vertical: a 600 mm
                                                     // lens on a full-frame sensor sees 3.4 deg
inline constexpr double kMaxFieldOfViewDeg = 170.0;  // fisheyes need undistorting first anyway
inline constexpr double kMaxPrincipalPointOffset = 1.0;  // image widths / heights the principal
                                                         // point may lie beyond the image's edge
inline constexpr double kMinCanvasFootprintPx = 4.0;  // the canvas in a photo, px along each axis
inline constexpr double kMaxTexelsPerPixel = 64.0;    // canvas texels one photo pixel may span
inline constexpr double kMaxPixelsPerTexel = 1024.0;  // photo pixels one canvas texel may span

struct Camera {
  CameraModel model = CameraModel::kPinhole;
  int width = 0, height = 0;        // image size, px
  double fx = 0, fy = 0;            // focal lengths, px (pinhole)
  double cx = 0, cy = 0;            // principal point, px (pixel centres at integers)
  double pixel_pitch_mm = 0;        // orthographic only: mm per pixel on the object
  RigidTransform camera_from_scan;  // p_camera = R p_scan + t, mm; rotation det +1
  // This image is the part of a larger one (LoadPhotoRegion) whose pixel (origin_x, origin_y) is
  // its pixel (0, 0): projections are the whole image's less the origin, subtracted last, so a
  // part's pixel coordinates are the whole's exactly (an integer off a double of larger
  // magnitude), and its rays are the whole's rays, bit for bit. 0 for a whole image.
  int origin_x = 0, origin_y = 0;

  // True when the point is in front of the camera (camera-frame z > 0). Orthographic cameras see
  // along their whole axis, but a point behind their nominal origin is still reported "behind",
  // so that a camera placed under the canvas is caught.
  bool InFront(const Vec3d& p_scan) const { return camera_from_scan.Apply(p_scan).z() > 0.0; }

  // Pixel coordinates of a scan-frame point (no distortion). Precondition for pinhole: InFront.
  Eigen::Vector2d Project(const Vec3d& p_scan) const {
    const Vec3d p = camera_from_scan.Apply(p_scan);
    if (model == CameraModel::kOrthographic) {
      return {p.x() / pixel_pitch_mm + cx - origin_x, p.y() / pixel_pitch_mm + cy - origin_y};
    }
    return {fx * p.x() / p.z() + cx - origin_x, fy * p.y() / p.z() + cy - origin_y};
  }

  // Whether pixel coordinates fall on the image (pixel centres at 0 .. width-1, edges at -0.5).
  bool InImage(const Eigen::Vector2d& px) const {
    return px.x() >= -0.5 && px.y() >= -0.5 && px.x() <= width - 0.5 && px.y() <= height - 0.5;
  }

  // Centre of projection in the scan frame (mm). Orthographic: the camera frame's origin (only
  // where it is nominal: the rays are parallel).
  Vec3d CentreInScan() const {
    return -(camera_from_scan.rotation.transpose() * camera_from_scan.translation);
  }

  // The ray through the centre of pixel (u, v), scan frame: origin and unit direction (into the
  // scene). Orthographic: from the pixel's place on the camera's plane, along its axis.
  void Ray(double u, double v, Vec3d& origin, Vec3d& direction) const {
    u += origin_x;  // exact: pixel centres are integers
    v += origin_y;
    const Mat3d scan_from_camera = camera_from_scan.rotation.transpose();
    if (model == CameraModel::kOrthographic) {
      const Vec3d p((u - cx) * pixel_pitch_mm, (v - cy) * pixel_pitch_mm, 0.0);
      origin = scan_from_camera * (p - camera_from_scan.translation);
      direction = scan_from_camera.col(2);
      return;
    }
    origin = CentreInScan();
    direction = scan_from_camera * Vec3d((u - cx) / fx, (v - cy) / fy, 1.0).normalized();
  }
  // Same intrinsics and pose, exactly (photos of one camera position share what depends on it).
  bool SameView(const Camera& o) const {
    return model == o.model && width == o.width && height == o.height && fx == o.fx && fy == o.fy &&
           cx == o.cx && cy == o.cy && pixel_pitch_mm == o.pixel_pitch_mm &&
           origin_x == o.origin_x && origin_y == o.origin_y &&
           camera_from_scan.rotation == o.camera_from_scan.rotation &&
           camera_from_scan.translation == o.camera_from_scan.translation;
  }

  // Unit direction from a scan-frame point towards the camera (the view direction v of the BRDF).
  Vec3d DirectionToCamera(const Vec3d& p_scan) const {
    if (model == CameraModel::kOrthographic) return -camera_from_scan.rotation.row(2).transpose();
    return (CentreInScan() - p_scan).normalized();
  }

  // Checks the intrinsics (sizes; pinhole field of view within [kMinFieldOfViewDeg,
  // kMaxFieldOfViewDeg] both ways; principal point within kMaxPrincipalPointOffset image sizes of
  // the image) and the rotation; messages start with `what` ("calib.json: cameras[0]").
  Status Validate(const std::string& what) const;
};

// ---------------------------------------------------------------------------------------------
// Light. The measured linear pixel value of a surface point x with normal n, lit by this light and
// seen along v, is  f_r(v, l) * max(0, n.l) * E(x)  where l = DirectionTo(x) and
//   point light:        E(x) = intensity / |position_mm - x|^2   (d in mm)
//   directional light:  E(x) = irradiance
// so, with f_r in 1/sr, `intensity` is in linear pixel units x mm^2 x sr and `irradiance` in
// linear pixel units x sr. Both are RGB (a coloured or unbalanced source is modelled per channel).

enum class LightType { kPoint, kDirectional };

struct Light {
  LightType type = LightType::kDirectional;
  Vec3d position_mm = Vec3d::Zero();  // point: position, scan frame
  Vec3d direction = Vec3d::UnitZ();   // directional: unit vector TOWARDS the light, scan frame
  Vec3f intensity = Vec3f::Ones();    // point: RGB intensity (E = I / d^2)
  Vec3f irradiance = Vec3f::Ones();   // directional: RGB irradiance

  // Unit direction from a scan-frame point towards the light.
  Vec3d DirectionTo(const Vec3d& p_scan) const {
    return type == LightType::kDirectional ? direction : (position_mm - p_scan).normalized();
  }
  // Irradiance at normal incidence at a scan-frame point (E(x) above).
  Vec3f IrradianceAt(const Vec3d& p_scan) const {
    if (type == LightType::kDirectional) return irradiance;
    return intensity / static_cast<float>((position_mm - p_scan).squaredNorm());
  }
  Status Validate(const std::string& what) const;
};

// ---------------------------------------------------------------------------------------------
// Photo.

// kAuto is decided from the file: integer samples (8/16-bit PNG/JPEG/TIFF) are sRGB, float
// samples (EXR, float TIFF) linear.
enum class ColourEncoding {
  kAuto,
  kSrgb,    // the sRGB transfer curve (IEC 61966-2-1), linearised on load with the exact EOTF
  kLinear,  // values are linear already
};
const char* ToString(ColourEncoding encoding);  // "auto", "srgb", "linear"

// Bits of Photo::flags.
enum PixelFlag : uint8_t {
  kPixelNonFinite = 1,  // NaN/Inf in the file: colour set to 0, never use
  kPixelSaturated = 2,  // a channel at the top of the encoding: a lower bound only
};

struct Photo {
  std::filesystem::path path;  // the image file, resolved (relative to the JSON / .lp folder)
  std::string entry;  // where it was declared, for errors: "calib.json: images[3]", "dirs.lp:5"
  Camera camera;
  Light light;
  ColourEncoding encoding =
      ColourEncoding::kAuto;  // resolved (never kAuto) once the header is read

  // Filled by loading (empty before): linear RGB, width x height of the camera; a 1-channel image
  // becomes grey RGB. Never NaN/Inf (see the policy above).
  Grid<Vec3f> rgb;
  // Per-pixel PixelFlag bits, same size as rgb; EMPTY when no pixel is flagged (the common case).
  Grid<uint8_t> flags;
  size_t non_finite_pixels = 0;  // pixels flagged kPixelNonFinite
  size_t saturated_pixels = 0;   // pixels flagged kPixelSaturated

  bool loaded() const { return !rgb.empty(); }
  uint8_t Flags(int x, int y) const { return flags.empty() ? uint8_t{0} : flags(x, y); }
  bool Usable(int x, int y) const { return Flags(x, y) == 0; }
};

// What loading found, over the whole set.
struct PhotoLoadSummary {
  int photos_loaded = 0;
  size_t pixels = 0;             // over all loaded photos
  size_t non_finite_pixels = 0;  // NaN/Inf, set to 0 and flagged
  size_t saturated_pixels = 0;   // flagged
  int srgb_photos = 0, linear_photos = 0;
  double seconds = 0;
  // "72 photos 402x395 (72 sRGB), 11.4 Mpx, 0 NaN/Inf px, 1234 saturated px (0.01 %); 0.35 s"
  std::string Brief() const;
};

struct PhotoSet {
  std::filesystem::path source;  // the calibration JSON or the .lp file
  std::vector<Photo> photos;     // in file order; never empty for a successful read

  // RTI captures (ReadRtiCapture): the images are the texel grid of a flat canvas whose frame is
  // the scan frame (canvas_from_scan = identity), with this pitch. 0 / false otherwise.
  bool is_rti = false;
  double rti_pitch_mm = 0;
  // Where rti_pitch_mm came from, in words for the user and the provenance: given, read from
  // the first image's resolution tag, or assumed (rti_pitch_assumed: the physical size is then
  // made up, and the tools say so).
  std::string rti_pitch_source;
  bool rti_pitch_assumed = false;

  PhotoLoadSummary summary;  // filled when the pixels are loaded
};

// ---------------------------------------------------------------------------------------------
// Reading.

struct PhotoSetOptions {
  bool load_pixels = true;          // decode every image now (parallel); false: headers only
  float saturation_encoded = 1.0f;  // integer images: encoded value in [0, 1] at or above which
                                    // a channel is saturated (1 = the maximum code only; JPEG
                                    // ringing around clipped highlights may want ~0.98)
  float float_saturation_level =
      std::numeric_limits<float>::infinity();  // float images: linear
                                               // value at or above which a channel is saturated
  double max_non_finite_fraction = 0.5;        // refuse a photo with more NaN/Inf pixels than this
  size_t max_pixels_per_image = size_t{1} << 28;  // refuse larger images (a corrupt header)
  // RTI only (ReadRtiCapture).
  // Canvas mm per image pixel. 0: from the first image's resolution tag (ImageHeader::
  // mm_per_pixel), else kRtiAssumedPitchMm, said in PhotoSet::rti_pitch_source.
  double rti_pixel_pitch_mm = 0;
  double rti_camera_distance_mm = 1000.0;  // nominal height of the orthographic camera
  // Image paths of a calibration or .lp file must stay inside that file's folder, after resolving
  // "..", absolute paths and symbolic links: a shared capture must not make the reader open (and a
  // pack then carry, hashed and named) files from elsewhere on this machine. true: any path.
  bool allow_outside_paths = false;

  Status Validate() const;
};

// Reads a calibration file (docs/formats.md: {"format": "digitize.calibration", "version": 1,
// "images": [{"path", "camera", "light", "encoding"}], optional shared "cameras" / "lights"}).
// Every field is checked; errors name the JSON file and the entry
// ("calib.json: images[3].camera.camera_from_scan.rotation is not a rotation (det 0.71, ...)"),
// and for image problems also the image file (missing, unreadable, size differs from the
// camera's). Rotations within 1e-4 of orthonormal are snapped to the nearest rotation (JSON
// written with 6 decimals); beyond that, or with det < 0, they are refused. Two entries naming
// the same image (same path once resolved and lexically normalised) are refused, naming both.
// Does NOT check that the cameras see the canvas: that needs the canvas (CheckCamerasSeeCanvas).
Result<PhotoSet> ReadCalibration(const std::filesystem::path& json_path,
                                 const PhotoSetOptions& options = {},
                                 const ProgressCallback& progress = nullptr);

// Reads an RTI capture: a .lp file (first non-comment line: the image count; then one line per
// image, `filename x y z`, the direction towards the light, unit or not: normalised) and its
// images. Tolerated: blank lines, CRLF, '#' comments, tabs, file names with spaces, Windows
// paths (backslashes; an absolute path that does not exist is looked up by its file name in the
// .lp's folder). Errors name the .lp file and line: bad count, count mismatch, non-numeric or
// non-finite value, zero direction, more than 3 numbers after the name (extra columns; so a name
// whose last word is a number, "scan 2" without an extension, cannot be read); missing /
// unreadable images, images whose size differs from the first one, and an image listed twice
// (same resolved path; both lines named) name the image file too.
//
// Direction frame (checked on the real capture in shared/data/rti_icon: lights with x > 0
// brighten the right of the images, lights with y > 0 the top): x towards the image's right
// (increasing column), y towards the image's TOP (decreasing row), z out of the canvas towards the
// camera. This is the canvas frame (height_field.h), so directions are used as they are. Lights
// with z <= 0 (at or below the canvas plane) are kept: the fit rejects their samples (n.l <= 0).
//
// The photo set: directional lights with unit irradiance (RGB 1, 1, 1); one orthographic camera
// looking straight down (-z) from rti_camera_distance_mm above the canvas centre, pitch
// rti_pitch_mm, so that image pixel (x, y) sees texel (x, y) of the flat canvas
// (HeightField::TexelCentreMm). is_rti = true; rti_pitch_mm = rti_pixel_pitch_mm when given (> 0),
// else the first image's resolution tag (300 dpi -> 25.4 / 300 mm), else kRtiAssumedPitchMm with
// rti_pitch_assumed set; rti_pitch_source says which.
inline constexpr double kRtiAssumedPitchMm = 1.0;  // RTI has no scale: 1 mm per pixel
// A pixel of an RTI capture spans 1 um to 100 mm of canvas: outside that a pitch (given or tagged)
// is a typo or a software default, not the canvas's scale.
inline constexpr double kMinRtiPitchMm = 1e-3;
inline constexpr double kMaxRtiPitchMm = 100.0;
Result<PhotoSet> ReadRtiCapture(const std::filesystem::path& lp_path,
                                const PhotoSetOptions& options = {},
                                const ProgressCallback& progress = nullptr);

// ---------------------------------------------------------------------------------------------
// Parsing only: the text of a calibration or .lp file, without the filesystem. The readers above
// are these plus the file read and the image checks; the fuzz targets (tests/fuzz/) and the
// corpus test call them directly. `source` is the file the text came from: errors and entries
// name it and relative image paths are resolved against its folder, but it is never opened, and
// neither is any image. Errors are the readers' parsing errors, word for word.

// The calibration's photos, unprobed and unloaded: each photo's encoding is as declared (kAuto
// when not given), its path resolved but not checked. Cameras and lights are validated as in
// ReadCalibration (rotations snapped, directions normalised).
Result<PhotoSet> ParseCalibrationText(std::string_view text, const std::filesystem::path& source);

// One image line of a .lp file.
struct RtiLightEntry {
  std::string image;  // the file name as written (ReadRtiCapture resolves it; may hold spaces)
  Vec3d direction = Vec3d::UnitZ();  // towards the light, canvas frame, unit length
  int line = 0;                      // 1-based line in the .lp file
};
// The entries of a .lp file in file order; never empty on success (the count is >= 1 and matches).
Result<std::vector<RtiLightEntry>> ParseRtiLightsText(std::string_view text,
                                                      const std::filesystem::path& source);

// Decodes (or re-decodes) the pixels of every photo in parallel, fills photo.rgb / flags /
// counts and set.summary. On error (the first failing photo in set order is reported) the set is
// left with its photos unloaded (no partial state).
Status LoadPhotoPixels(PhotoSet& set, const PhotoSetOptions& options = {},
                       const ProgressCallback& progress = nullptr);
// One photo. Errors name the entry and the image file.
Status LoadPhoto(Photo& photo, const PhotoSetOptions& options = {});

// A rectangle of a photo's pixels: columns [x, x + width), rows [y, y + height).
struct PixelRect {
  int x = 0, y = 0, width = 0, height = 0;
};
// The part `region` of a photo (header read, pixels not needed) as a photo of its own: the same
// light and pose, the camera's image cut to the rectangle (Camera::origin_x/y += (x, y), so a
// pixel's ray is the whole photo's ray through the same pixel, bit for bit), its pixels read
// through `reader` (a bounded cache: photos far larger than memory are read a part at a time)
// and converted as LoadPhoto converts them. Errors name the entry and the file; a region not
// inside the image. `tiled_copy`, when given, is read instead of the photo's file: a tiled copy
// of its samples (WriteTiledCopy, photo_tile_cache.h); the photo is still the photo (its file's
// name says whether it is lossy).
Result<Photo> LoadPhotoRegion(const Photo& photo, const PixelRect& region,
                              ImageRegionReader& reader, const PhotoSetOptions& options = {},
                              const std::filesystem::path& tiled_copy = {});

// sRGB EOTF (IEC 61966-2-1), exact piecewise form: c <= 0.04045 ? c / 12.92
// : ((c + 0.055) / 1.055)^2.4; odd-symmetric for negative values (extended sRGB).
float SrgbToLinear(float encoded);
// Its inverse (the sRGB OETF), same symmetry: what a display shows of a linear value.
float LinearToSrgb(float linear);

// ---------------------------------------------------------------------------------------------
// Geometry checks that need the canvas.

// Whether the camera sees the canvas whose frame is `canvas_from_scan` and whose rectangle spans
// [0, extent_mm.x] x [0, extent_mm.y] at Z = 0: the canvas centre must be in front of the camera,
// the camera on the canvas's front side (Z > 0 in the canvas frame: it is not looking at the back
// of the canvas), and some of the canvas (a 9x9 lattice of points) must project into the image,
// or the ray through the image centre meet the canvas rectangle (a camera close to the canvas).
// The error starts with `what` ("calib.json: images[3]") and says which of these fails.
Status CheckCameraSeesCanvas(const Camera& camera, const RigidTransform& canvas_from_scan,
                             const Eigen::Vector2d& extent_mm, const std::string& what);
// Whether the canvas appears in the photo at a scale the fit can use, measured by the local scale
// of the projection at the canvas centre along the canvas's X and Y (px per mm): the canvas must
// span at least kMinCanvasFootprintPx pixels along each axis, one pixel at most
// kMaxTexelsPerPixel texels of `pitch_mm` and one texel at most kMaxPixelsPerTexel pixels.
// Precondition: CheckCameraSeesCanvas passed. The error starts with `what` and gives the numbers.
Status CheckCanvasFootprint(const Camera& camera, const RigidTransform& canvas_from_scan,
                            const Eigen::Vector2d& extent_mm, double pitch_mm,
                            const std::string& what);
// Every photo of the set against a canvas height field (extent = size x pitch): both checks above.
Status CheckCamerasSeeCanvas(const PhotoSet& set, const RigidTransform& canvas_from_scan,
                             const HeightField& canvas);

// The flat canvas an RTI capture is fitted on when no height field is given: the image grid,
// pitch rti_pitch_mm, height 0, every texel kMeasured. Error when `set` is not an RTI capture.
Result<HeightField> FlatCanvasForRti(const PhotoSet& set);

}  // namespace digitize
