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
// and the decoded pixels of every part; the reader recomputes it.
std::string PackChecksum(const OIIO::ImageSpec& meta, const void* const data[kParts],
                         const size_t bytes[kParts]);

// digitize:provenance as JSON (provenance.cpp): what the writer stores and `inspect --json`
// shows; and its parse, whose errors name the file and the key.
nlohmann::json ProvenanceToJson(const PackProvenance& provenance);
Result<PackProvenance> ParseProvenance(const std::string& file, const std::string& text);

}  // namespace digitize::pack_exr
