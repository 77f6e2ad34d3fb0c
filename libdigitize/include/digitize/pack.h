// Texture packs (issue 4; SPEC step 7, paper 001 section 6): one self-describing file per
// painting holding everything the viewer needs -- height, normals, reflectance maps, relief boxes,
// physical size, gauge and provenance. What a museum keeps and ships.
//
// Layer: pack (core, io, relief, brdf). Format: docs/formats.md, "Texture packs".
//
// Container: a multi-part OpenEXR file (OpenImageIO), half-float channels, metadata in the header
// of part 0 as `digitize:*` string attributes, so `oiiotool --info -v`, `exrheader` or any EXR
// viewer can look inside. Parts:
//   "surface"      : H (height, mm), NX, NY (unit normal's x, y; nz = sqrt(1 - nx^2 - ny^2)),
//                    M (texel state + 4 x fit status, small integers: exact in half)
//   "reflectance"  : rho_d.R/G/B, rho_s.R/G/B, lobe.cx, lobe.cy, lobe.k (cz = 1 by the gauge)
// 13 half channels = 26 bytes per texel before compression (the paper's budget), ZIP compressed.
// The per-texel fit error (fit_error.exr) is not stored: the fit brief in the provenance says how
// well the fit went.
//
// Encodings. kHalf: every value is rounded to the nearest half once; reading returns exactly
// those values (bit-exact round trip). kQuantised: additionally drops low mantissa bits per
// channel group (PackQuantisation), a stated relative error bound per group, so the lossless
// compressor has less to store; the read-back values are exactly the quantised ones.
#pragma once
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>
#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/reflectance_maps.h"
#include "digitize/relief.h"

namespace digitize {

inline constexpr int kPackVersion = 1;
inline constexpr const char* kPackFormatName = "digitize.pack";

struct PackInput {
  std::string name;    // file name as given on the command line
  std::string sha256;  // hex digest of the file's bytes ("" when not hashed, e.g. in memory)
  uint64_t bytes = 0;
};

struct PackProvenance {
  std::string tool_version;       // "digitize 0.4.0"
  std::string created_utc;        // ISO 8601, "2026-11-30T09:30:00Z"
  std::string fit_brief;          // the fit's one-line brief
  std::string options_json;       // JSON object: the options of the stages that made the pack
  std::vector<PackInput> inputs;  // scan(s), calibration, photos, canvas and fit folders' files
};

// A painting, ready for the viewer. Same grid for every map (the HeightField's).
struct Pack {
  HeightField field;          // height_mm (never NaN), state, pitch_mm
  Grid<Vec3f> normals;        // unit, canvas frame, nz > 0
  ReflectanceMaps maps;       // rho_d, rho_s, lobe (cz = 1), status; fit_error all 0 when read
  double delta0_mm = 0;       // bump plane (bottom of every box)
  double max_height_mm = 0;   // H (top of every box)
  int cell_px = 0;            // box cell size, texels
  std::vector<ReliefBox> boxes;
  RigidTransform canvas_from_scan;  // where the canvas sits in the scan / photo frame
  PackProvenance provenance;

  int width() const { return field.width(); }
  int height() const { return field.height(); }
  double width_mm() const { return field.width() * field.pitch_mm; }
  double height_mm() const { return field.height() * field.pitch_mm; }
  // Everything consistent: sizes, finite values, rho >= 0, cz = 1, k >= 0, normals unit with
  // nz > 0, boxes inside the grid with h_max in [delta0, H] and (u_max, v_max) inside the box,
  // delta0 <= H. Message names the map and texel (or box index).
  Status Validate() const;
};

// Mantissa bits kept per channel group in kQuantised mode (half has 10). Relative error of a
// kept value: at most 2^-(bits+1) (round to nearest). The state/status channel is never quantised.
struct PackQuantisation {
  int height_bits = 10;  // keep height exact: relief mapping magnifies height errors at grazing views
  int normal_bits = 6;
  int rho_bits = 5;
  int lobe_bits = 6;     // cx, cy, k
  Status Validate() const;  // each in [0, 10]
};

enum class PackEncoding { kHalf, kQuantised };
const char* ToString(PackEncoding encoding);  // "half", "quantised"

struct PackWriteOptions {
  PackEncoding encoding = PackEncoding::kHalf;
  PackQuantisation quantisation;  // kQuantised only
  Status Validate() const;
};

// Bounds the reader applies before allocating anything a header claims.
struct PackReadOptions {
  int64_t max_texels = int64_t{1} << 28;  // 16384 x 16384
  int64_t max_boxes = int64_t{1} << 22;
};

// What `digitize inspect` shows; from the header alone (no pixel is decoded).
struct PackSummary {
  int version = 0;
  int width = 0, height = 0;
  double pitch_mm = 0;
  double delta0_mm = 0, max_height_mm = 0;
  int cell_px = 0;
  size_t box_count = 0;
  PackEncoding encoding = PackEncoding::kHalf;
  PackQuantisation quantisation;
  std::string gauge;        // "lafortune1:cz=1,tangent"
  PackProvenance provenance;
  uint64_t file_bytes = 0;
  double BytesPerTexel() const {
    return width > 0 && height > 0 ? double(file_bytes) / (double(width) * height) : 0.0;
  }
};

// Writes atomically (temporary file beside `path`, then rename). Refuses a pack that does not
// Validate() or whose values do not fit in half (|v| > 65504), naming the map and texel.
Status WritePack(const std::filesystem::path& path, const Pack& pack,
                 const PackWriteOptions& options = {});

// Reads and validates everything: format name, version, parts, channel sets, sizes (bounded by
// options before any allocation), NaN/Inf, boxes, metadata. Errors name the file and the problem.
Result<Pack> ReadPack(const std::filesystem::path& path, const PackReadOptions& options = {});

// Header only.
Result<PackSummary> InspectPack(const std::filesystem::path& path,
                                const PackReadOptions& options = {});

// The values a pack written with `options` reads back as (half rounding, then quantisation):
// what the relighting error of an encoding is measured with, without writing a file.
Pack EncodePackValues(const Pack& pack, const PackWriteOptions& options);

}  // namespace digitize
