// Texture packs (paper 001 section 6): one self-describing file per
// painting holding everything the viewer needs -- height, normals, reflectance maps, relief boxes,
// physical size, gauge and provenance. What a museum keeps and ships.
//
// Layer: pack (core, io, relief, brdf). Format: docs/formats.md, "Texture packs".
//
// Container: a multi-part OpenEXR file (OpenImageIO), half-float channels, metadata in the header
// of part 0 as `digitize:*` string attributes, so `oiiotool --info -v`, `exrheader` or any EXR
// viewer can look inside. Parts:
//   "surface"      : H (height, mm), NX, NY (unit normal's x, y; nz = sqrt(1 - nx^2 - ny^2)),
//                    M (texel state + 4 x fit status + 64 x reflectance model, small integers:
//                    exact in half; version 1 packs have no model term: every texel Lafortune)
//   "reflectance"  : rho_d.R/G/B, rho_s.R/G/B, lobe.cx, lobe.cy, lobe.k (cz = 1 by the gauge);
//                    a GGX texel (reflectance_maps.h) stores F0 in rho_s, alpha in lobe.k and
//                    cx = cy = 0
//   "boxes"        : one pixel per n x n relief cell (float): present (0/1), h_max (mm),
//                    u_max, v_max (texel of the highest point, relative to the cell's corner);
//                    boxes are the present cells, so no box list can claim more than the grid
// 13 half channels = 26 bytes per texel before compression (the paper's budget), ZIP compressed.
// The per-texel fit error (fit_error.exr) is not stored: the fit brief in the provenance says how
// well the fit went.
//
// Encodings. kHalf: every value is rounded to the nearest half once; reading returns exactly
// those values (bit-exact round trip). kQuantised: additionally drops low mantissa bits per
// channel group (PackQuantisation), a stated relative error bound per group, so the lossless
// compressor has less to store; the read-back values are exactly the quantised ones.
#pragma once
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "digitize/core.h"
#include "digitize/height_field.h"
#include "digitize/preprocess.h"
#include "digitize/provenance.h"
#include "digitize/reflectance_maps.h"
#include "digitize/relief.h"

namespace digitize {

// 2: the reflectance model per texel (M's model term, digitize:models). Version 1 packs still read
// (every texel Lafortune). Version 3 (pack_tiled.h, kTiledPackVersion) is the tiled,
// multi-resolution form, written when PackWriteOptions::tile_size > 0; every reader reads all
// three.
inline constexpr int kPackVersion = 2;
inline constexpr const char* kPackFormatName = "digitize.pack";

// Physical bounds on what a pack may state (docs/formats.md, "What the reader checks"). A pack is
// shared between institutions, so its header is untrusted input: a pitch of 1e308 mm survives
// every finiteness check and then makes the gallery infinitely wide. Pack::Validate, the writer,
// ReadPack, InspectPack and VerifyPack all refuse a pack outside these bounds.
inline constexpr double kMinPackPitchMm = 1e-3;            // 1 um: finer than any scanner
inline constexpr double kMaxPackExtentMm = 100000.0;       // pitch x texels on either side: 100 m
inline constexpr double kMaxPackHeightMm = 1000.0;         // |height|, |h_max|, |H| and delta0: 1 m
inline constexpr double kMaxPackTranslationMm = 100000.0;  // |canvas_from_scan translation|
// |R R^T - I| (Frobenius) and det R > 0 of canvas_from_scan: 6-decimal JSON stays well inside.
inline constexpr double kPackRotationTolerance = 1e-4;
// digitize:size_mm against pitch x texels, relative (the writer stores both in shortest
// round-trip form, so a pack it wrote agrees exactly).
inline constexpr double kPackSizeTolerance = 1e-9;

// A painting, ready for the viewer. Same grid for every map (the HeightField's).
struct Pack {
  HeightField field;         // height_mm (never NaN), state, pitch_mm
  Grid<Vec3f> normals;       // unit, canvas frame, nz > 0
  ReflectanceMaps maps;      // rho_d, rho_s, lobe (cz = 1), status; fit_error all 0 when read
  double delta0_mm = 0;      // bump plane (bottom of every box)
  double max_height_mm = 0;  // H (top of every box)
  int cell_px = 0;           // box cell size, texels
  std::vector<ReliefBox> boxes;
  RigidTransform canvas_from_scan;  // where the canvas sits in the scan / photo frame
  PackProvenance provenance;

  int width() const { return field.width(); }
  int height() const { return field.height(); }
  double width_mm() const { return field.width() * field.pitch_mm; }
  double height_mm() const { return field.height() * field.pitch_mm; }
  // Everything consistent: sizes, finite values, rho >= 0, cz = 1, k >= 0, normals unit with
  // nz > 0, boxes inside the grid with h_max in [delta0, H] and (u_max, v_max) inside the box,
  // delta0 <= H; and physically plausible (the kMinPackPitchMm ... bounds above: pitch, extent,
  // heights, H, delta0, canvas_from_scan a rotation with a bounded translation). Message names
  // the map and texel (or box index, or the value).
  Status Validate() const;
};

// Mantissa bits kept per channel group in kQuantised mode (half has 10). Relative error of a
// kept value: at most 2^-(bits+1) (round to nearest). The state/status channel is never quantised.
struct PackQuantisation {
  // Defaults: <= 10 bytes per texel at <= 1 dB relighting loss (docs/benchmarks.md, "Packs").
  int height_bits = 8;      // 2^-9 relative: 5 um at 2.4 mm of relief, under any scanner's noise
  int normal_bits = 5;      // nx, ny
  int rho_bits = 4;         // rho_d, rho_s: 3 % relative
  int lobe_bits = 6;        // cx, cy, k: kept finer, a glossy lobe (k ~ 500) magnifies its errors
  Status Validate() const;  // each in [0, 10]
};

enum class PackEncoding { kHalf, kQuantised };
const char* ToString(PackEncoding encoding);  // "half", "quantised"

struct PackWriteOptions {
  PackEncoding encoding = PackEncoding::kHalf;
  PackQuantisation quantisation;  // kQuantised only
  // 0: one grid (version 2). Else a tiled, multi-resolution pack (version 3, pack_tiled.h) of
  // tile_size x tile_size tiles: a power of two in [64, 4096].
  int tile_size = 0;
  Status Validate() const;
};

// Bounds the reader applies before allocating anything a header claims.
struct PackReadOptions {
  int64_t max_texels = int64_t{1} << 26;        // 8192 x 8192 (~4 GiB in memory as a Pack)
  int64_t max_header_bytes = int64_t{1} << 22;  // all part headers together
  // A tiled pack (version 3) is read a tile at a time (TiledPackReader), so its level 0 may be
  // larger: 65536 x 65536. ReadPack, which holds it whole, still applies max_texels.
  int64_t max_tiled_texels = int64_t{1} << 32;
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
  std::string gauge;  // "lafortune1: f = ..."
  // Texels per reflectance model (indexed by ReflectanceModel), from digitize:models (version 1:
  // every texel Lafortune); ReadPack checks it against the pixels.
  std::array<int64_t, kReflectanceModelCount> texels_by_model{};
  PackProvenance provenance;
  uint64_t file_bytes = 0;
  int raw_bytes_per_texel = 0;  // uncompressed texel channels of the surface + reflectance parts
  // Version 3 (pack_tiled.h): the tile size and every level's size (level 0 first); else 0 and
  // empty.
  int tile_size = 0;
  std::vector<std::array<int, 2>> levels;
  double BytesPerTexel() const {
    return width > 0 && height > 0 ? double(file_bytes) / (double(width) * height) : 0.0;
  }
};

// A pack from a preprocessed canvas (ReadPreprocessOutputs: field, normals, boxes) and the
// reflectance maps fitted on it. Errors: different grid sizes, or a pack that does not Validate.
Result<Pack> AssemblePack(PreprocessedCanvas canvas, ReflectanceMaps maps,
                          PackProvenance provenance);

// Writes atomically (temporary file beside `path`, then rename). Refuses a pack that does not
// Validate() or whose values do not fit in half (|v| > 65504), naming the map and texel.
// options.tile_size > 0: a version 3 pack (WriteTiledPack, pack_tiled.h).
Status WritePack(const std::filesystem::path& path, const Pack& pack,
                 const PackWriteOptions& options = {});

// Reads and validates everything: format name, version, parts, channel sets, sizes (bounded by
// options before any allocation), NaN/Inf, boxes, metadata. Errors name the file and the problem.
// A version 3 pack: its level 0, every tile checked against its SHA-1.
Result<Pack> ReadPack(const std::filesystem::path& path, const PackReadOptions& options = {});

// Header only.
Result<PackSummary> InspectPack(const std::filesystem::path& path,
                                const PackReadOptions& options = {});

// The values a pack written with `options` reads back as (half rounding, then quantisation):
// what the relighting error of an encoding is measured with, without writing a file. GGX texels
// stay valid after rounding: alpha is rounded up to the first kept value >= kGgxMinAlpha when
// rounding to nearest fell below it, F0 stays <= 1, cx = cy = 0 exactly.
// Precondition: pack.Validate() is ok.
Pack EncodePackValues(const Pack& pack, const PackWriteOptions& options);

// `digitize verify`: ReadPack plus the consistency a reader does not need but a keeper wants:
// every box's h_max is the height at (u_max, v_max) and the highest in its cell, H bounds every
// height, the cells without a box hold no height above delta0 + tolerance... (within half
// rounding). One line per check in `checks`; the first failure is the error.
struct PackVerification {
  PackSummary summary;
  std::vector<std::string> checks;  // "boxes: 312 cells, h_max = cell maximum (half rounding)"
};
Result<PackVerification> VerifyPack(const std::filesystem::path& path,
                                    const PackReadOptions& options = {});

// `digitize inspect --json`: the summary of the pack file `file` as JSON text, ASCII only
// (\uXXXX for the rest, so no control character reaches a terminal; bytes that are not UTF-8,
// e.g. a file name, replaced).
std::string PackSummaryJson(const std::string& file, const PackSummary& summary);

}  // namespace digitize
