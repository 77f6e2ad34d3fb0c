// The size an OpenEXR attribute value must have for OpenEXR to read exactly the bytes its header
// gives it. OpenEXR reads a fixed-size type (v2f, box2i, ...) as sizeof(type), whatever size the
// header states, and a preview or string vector as its own inner counts say; where the two
// disagree, the header parser drifts out of step and takes value bytes for the next attribute's
// size, then allocates it (a 3 KB pack asked for 2 GB through a v2f stated as 248 bytes; found by
// tests/fuzz/fuzz_viewer_load). Checked on the raw header before OpenEXR sees the file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace digitize::exr {

// The fixed size of an OpenEXR attribute type (OpenEXR's file layout), or 0 for the types whose
// size is their own (string, chlist, floatvector, stringvector, preview, opaque types).
inline size_t FixedAttributeSize(std::string_view type) {
  struct Entry {
    std::string_view type;
    size_t bytes;
  };
  static constexpr Entry kFixed[] = {
      {"int", 4},
      {"float", 4},
      {"double", 8},
      {"compression", 1},
      {"lineOrder", 1},
      {"envmap", 1},
      {"deepImageState", 1},
      {"box2i", 16},
      {"box2f", 16},
      {"v2i", 8},
      {"v2f", 8},
      {"v2d", 16},
      {"v3i", 12},
      {"v3f", 12},
      {"v3d", 24},
      {"m33f", 36},
      {"m33d", 72},
      {"m44f", 64},
      {"m44d", 128},
      {"rational", 8},
      {"timecode", 8},
      {"keycode", 28},
      {"chromaticities", 32},
      {"tiledesc", 9},
  };
  for (const Entry& e : kFixed)
    if (e.type == type) return e.bytes;
  return 0;
}

inline uint32_t LittleEndianU32(const char* p) {
  uint32_t u = 0;
  for (int i = 3; i >= 0; --i) u = (u << 8) | static_cast<uint8_t>(p[i]);
  return u;
}

// "" when OpenEXR reads exactly `size` bytes for a value of `type` starting at `value`, else why
// not (a phrase to follow the attribute's name).
inline std::string AttributeSizeProblem(std::string_view type, const char* value, size_t size) {
  if (const size_t fixed = FixedAttributeSize(type); fixed != 0) {
    if (size == fixed) return "";
    return "is " + std::to_string(size) + " bytes, a " + std::string(type) + " is " +
           std::to_string(fixed);
  }
  if (type == "preview") {  // width, height, then 4 bytes a pixel
    if (size < 8) return "is too short for a preview";
    const uint64_t pixels = uint64_t{LittleEndianU32(value)} * LittleEndianU32(value + 4);
    if (pixels > (size - 8) / 4 || 8 + 4 * pixels != size)
      return "holds a preview whose size disagrees with the attribute's";
    return "";
  }
  if (type == "stringvector") {  // each string: int32 length, then its bytes
    size_t pos = 0;
    while (pos < size) {
      if (size - pos < 4) return "holds a truncated string vector";
      const uint32_t n = LittleEndianU32(value + pos);
      pos += 4;
      if (n > size - pos) return "holds a string longer than the attribute";
      pos += n;
    }
    return "";
  }
  return "";
}

}  // namespace digitize::exr
