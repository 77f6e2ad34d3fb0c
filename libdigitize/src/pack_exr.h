// Private to the texture pack files: what the pack model (pack.cpp), the writer
// (pack_write.cpp), the bounded reader (pack_read.cpp), `digitize verify` (pack_verify.cpp) and
// provenance (provenance.cpp) share -- the container layout, the half encoding, the physical
// bounds, the checksum and the provenance's JSON form. Format: docs/formats.md, "Texture packs".
#pragma once

#include <OpenImageIO/imageio.h>

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "digitize/pack.h"
#include "digitize/pack_tiled.h"

namespace digitize::pack_exr {

inline constexpr int kParts = 3;
inline constexpr float kHalfMax = 65504.0f;

// Channel layout of each part, in the order the Pack is filled. EXR stores channels sorted by
// name, so the reader looks them up by name, never by position.
inline const std::vector<std::string> kSurfaceChannels = {"H", "NX", "NY", "M"};
inline const std::vector<std::string> kReflectanceChannels = {"rho_d.R", "rho_d.G", "rho_d.B",
                                                              "rho_s.R", "rho_s.G", "rho_s.B",
                                                              "lobe.cx", "lobe.cy", "lobe.k"};
inline const std::vector<std::string> kBoxChannels = {"present", "h_max", "u_max", "v_max"};
inline const char* const kPartNames[kParts] = {"surface", "reflectance", "boxes"};
// Version 3 (pack_tiled.h): parts 0 and 1 tiled and mip-mapped, part 2 the boxes as above, and a
// fourth part of SHA-1 digests, one row per tile (level by level, row-major) and a last row for
// the boxes part: the digest's 20 bytes in order, 4 to a UINT channel (little-endian).
inline constexpr int kTiledParts = 4;
inline const char* const kChecksumPartName = "checksums";
inline const std::vector<std::string> kChecksumChannels = {"sha1.0", "sha1.1", "sha1.2", "sha1.3",
                                                           "sha1.4"};
// OpenEXR's tile description mode byte for MIPMAP_LEVELS with ROUND_UP: level sizes ceil(w / 2^l).
inline constexpr int kTileModeMipmapRoundUp = 0x11;

// Part 0's M channel: state + 4 x fit status + kModelStride x model (version 2; version 1 has no
// model term). The stride leaves room for 16 fit statuses; every code is an integer below 2048,
// exact in half.
inline constexpr int kModelStride = 64;
inline constexpr int kStatesPerStatus = 4;
int TexelCode(TexelState state, TexelFitStatus status, ReflectanceModel model);

// digitize:models, "lafortune=N,ggx=M": texels per model, in ReflectanceModel order.
std::string ModelCountsText(const std::array<int64_t, kReflectanceModelCount>& counts);
std::array<int64_t, kReflectanceModelCount> CountModels(const ReflectanceMaps& maps);

// "x, y" of a texel in messages.
std::string TexelName(int x, int y);

uint16_t ToHalfBits(float v);
float FromHalfBits(uint16_t bits);
// Normal from its stored (nx, ny): nz >= 0 recomputed, renormalised when rounding pushed
// nx^2 + ny^2 past 1. The single definition both the writer's preview and the reader use.
Vec3f NormalFromXY(float nx, float ny);

// The physical bounds of pack.h on what a pack states about its geometry. Each message starts
// with the value's name (pitch_mm, delta0_mm, max_height_mm, canvas_from_scan) for the caller to
// prefix: "pack: " in memory, "FILE: digitize:" for a header.
Status CheckPhysicalBounds(double pitch_mm, int w, int h, double delta0_mm, double max_height_mm,
                           const RigidTransform& canvas_from_scan);

// Integrity: EXR has no checksum, and a flipped bit in ZIP data can decode to other valid-looking
// values. The writer hashes every digitize:* attribute (sorted by name, the checksum excluded)
// and the decoded pixels of every part (version 3: none; each tile has its own digest); the
// reader recomputes it.
using Attributes = std::vector<std::pair<std::string, std::string>>;
std::string PackChecksum(Attributes attributes, const void* const data[], const size_t bytes[],
                         int parts);
Attributes DigitizeAttributes(const OIIO::ImageSpec& spec);  // its digitize:* string attributes

// Part 0's digitize:* attributes but the checksum, as both writers store them.
Attributes PackAttributes(const PackHeader& header, const PackWriteOptions& options);

// The header's bounds and boxes as Pack::Validate checks them ("pack: ..." messages).
Status CheckHeader(const PackHeader& header);
// Every value of `pack` within half's range (|v| <= 65504), else an error naming the map and the
// texel (offset by y0 rows in the message).
Status CheckHalfRange(const Pack& pack, int y0 = 0);

// The boxes part: 4 floats (present, h_max, u_max, v_max) per cell, row-major.
std::vector<float> BoxCells(const std::vector<ReliefBox>& boxes, int w, int h, int cell_px);
// Its reading: every value checked (ReadPack's rules); errors name the file and the cell.
Result<std::vector<ReliefBox>> DecodeBoxCells(const std::string& file, const float* cells, int w,
                                              int h, int cell_px, size_t box_count);

// One encoded texel (EncodePackValues' values) into the file's channels, canonical order: surface
// H, NX, NY, M; reflectance rho_d.RGB, rho_s.RGB, lobe.cx, lobe.cy, lobe.k.
void EncodeTexel(const HeightField& field, const Grid<Vec3f>& normals, const ReflectanceMaps& maps,
                 size_t i, uint16_t surface[4], uint16_t reflectance[9]);
// The inverse over a w x h block (canonical channel order) into out (grids sized w x h), each
// texel checked as ReadPack checks it; messages name texel (x0 + x, y0 + y) and `where` (e.g.
// " of level 2").
Status DecodeTexels(const std::string& file, int version, const uint16_t* surface,
                    const uint16_t* reflectance, int w, int h, int x0, int y0,
                    const std::string& where, PackLevel& out);

// digitize:provenance as JSON (provenance.cpp): what the writer stores and `inspect --json`
// shows; and its parse, whose errors name the file and the key.
nlohmann::json ProvenanceToJson(const PackProvenance& provenance);
Result<PackProvenance> ParseProvenance(const std::string& file, const std::string& text);

}  // namespace digitize::pack_exr
