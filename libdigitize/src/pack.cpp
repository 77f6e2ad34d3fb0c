// Texture packs: the model, its checks and its encodings (pack.h); the container is written by
// pack_write.cpp and read by pack_read.cpp (pack_exr.h: what they share).
#include "digitize/pack.h"

#include <OpenImageIO/half.h>
#include <OpenImageIO/hash.h>

#include <algorithm>
#include <charconv>
#include <cmath>

#include "digitize/image_io.h"
#include "options_json.h"
#include "pack_exr.h"

namespace digitize {
namespace pack_exr {

int TexelCode(TexelState state, TexelFitStatus status, ReflectanceModel model) {
  return static_cast<int>(state) + kStatesPerStatus * static_cast<int>(status) +
         kModelStride * static_cast<int>(model);
}

std::string ModelCountsText(const std::array<int64_t, kReflectanceModelCount>& counts) {
  std::string text;
  for (int m = 0; m < kReflectanceModelCount; ++m)
    text += std::string(m > 0 ? "," : "") + ToString(static_cast<ReflectanceModel>(m)) + "=" +
            std::to_string(counts[m]);
  return text;
}

std::array<int64_t, kReflectanceModelCount> CountModels(const ReflectanceMaps& maps) {
  std::array<int64_t, kReflectanceModelCount> counts{};
  for (const ReflectanceModel m : maps.model.data) ++counts[static_cast<size_t>(m)];
  return counts;
}

std::string TexelName(int x, int y) { return std::to_string(x) + ", " + std::to_string(y); }

uint16_t ToHalfBits(float v) { return half(v).bits(); }
float FromHalfBits(uint16_t bits) {
  half h;
  h.setBits(bits);
  return static_cast<float>(h);
}

// Normal from its stored (nx, ny): nz >= 0 recomputed, renormalised when rounding pushed
// nx^2 + ny^2 past 1. The single definition both the writer's preview and the reader use.
Vec3f NormalFromXY(float nx, float ny) {
  const float s = nx * nx + ny * ny;
  if (s >= 1.0f) {
    const float inv = 1.0f / std::sqrt(s);
    return {nx * inv, ny * inv, 0.0f};
  }
  return {nx, ny, std::sqrt(1.0f - s)};
}

Status CheckPhysicalBounds(double pitch_mm, int w, int h, double delta0_mm, double max_height_mm,
                           const RigidTransform& canvas_from_scan) {
  if (!(std::isfinite(pitch_mm) && pitch_mm >= kMinPackPitchMm))
    return Error{"pitch_mm " + FormatNumber(pitch_mm, kRoundTripDigits) +
                 " is not a texel pitch (at least " +
                 FormatNumber(kMinPackPitchMm, kRoundTripDigits) + " mm, finite)"};
  const int texels = std::max(w, h);
  const double extent_mm = pitch_mm * texels;
  if (!(extent_mm <= kMaxPackExtentMm))
    return Error{"pitch_mm " + FormatNumber(pitch_mm, kRoundTripDigits) + " x " +
                 std::to_string(texels) + " texels = " + FormatNumber(extent_mm, kRoundTripDigits) +
                 " mm, beyond the " + FormatNumber(kMaxPackExtentMm / 1000, kRoundTripDigits) +
                 " m a painting may measure"};
  if (!(std::isfinite(max_height_mm) && std::abs(max_height_mm) <= kMaxPackHeightMm))
    return Error{"max_height_mm " + FormatNumber(max_height_mm, kRoundTripDigits) +
                 " is outside [-" + FormatNumber(kMaxPackHeightMm, kRoundTripDigits) + ", " +
                 FormatNumber(kMaxPackHeightMm, kRoundTripDigits) + "] mm"};
  if (!(std::isfinite(delta0_mm) && delta0_mm >= 0 &&
        (delta0_mm <= max_height_mm + 1e-9 || delta0_mm == 0)))
    return Error{"delta0_mm " + FormatNumber(delta0_mm, kRoundTripDigits) +
                 " is not in [0, max_height_mm " + FormatNumber(max_height_mm, kRoundTripDigits) +
                 "]"};
  const Mat3d& r = canvas_from_scan.rotation;
  if (!r.allFinite() ||
      !((r * r.transpose() - Mat3d::Identity()).norm() <= kPackRotationTolerance) ||
      !(r.determinant() > 0))
    return Error{"canvas_from_scan rotation is not a rotation (|R R^T - I| above " +
                 FormatNumber(kPackRotationTolerance, kRoundTripDigits) + ", or det <= 0)"};
  const Vec3d& t = canvas_from_scan.translation;
  if (!t.allFinite() || !(t.norm() <= kMaxPackTranslationMm))
    return Error{"canvas_from_scan translation (" + FormatNumber(t.x(), kRoundTripDigits) + ", " +
                 FormatNumber(t.y(), kRoundTripDigits) + ", " +
                 FormatNumber(t.z(), kRoundTripDigits) + ") mm is farther than " +
                 FormatNumber(kMaxPackTranslationMm / 1000, kRoundTripDigits) +
                 " m from the scanner"};
  return Status::Ok();
}

std::string PackChecksum(Attributes attributes, const void* const data[], const size_t bytes[],
                         int parts) {
  std::erase_if(attributes, [](const auto& a) { return a.first == "digitize:checksum"; });
  std::sort(attributes.begin(), attributes.end());
  OIIO::SHA1 sha;
  for (const auto& [k, v] : attributes) {
    sha.append(k);
    sha.append("=", 1);
    sha.append(v);
    sha.append("\n", 1);
  }
  for (int p = 0; p < parts; ++p) sha.append(data[p], bytes[p]);
  return sha.digest();
}

Attributes DigitizeAttributes(const OIIO::ImageSpec& spec) {
  Attributes attributes;
  for (const OIIO::ParamValue& p : spec.extra_attribs) {
    const std::string name = p.name().string();
    if (name.rfind("digitize:", 0) == 0)
      attributes.emplace_back(name, spec.get_string_attribute(name));
  }
  return attributes;
}

Status CheckHeader(const PackHeader& header) {
  const int w = header.width, h = header.height;
  if (w <= 0 || h <= 0) return Error{"pack: empty grid"};
  if (Status s = CheckPhysicalBounds(header.pitch_mm, w, h, header.delta0_mm, header.max_height_mm,
                                     header.canvas_from_scan);
      !s.ok())
    return Error{"pack: " + s.message()};
  const int cell_px = header.cell_px;
  if (cell_px < 1) return Error{"pack: cell_px must be >= 1, got " + std::to_string(cell_px)};
  const std::vector<ReliefBox>& boxes = header.boxes;
  if (!boxes.empty() && !(header.delta0_mm > 0))
    return Error{"pack: boxes need a bump plane above the canvas (delta0_mm > 0)"};
  for (size_t i = 0; i < boxes.size(); ++i) {
    const ReliefBox& b = boxes[i];
    const std::string name = "pack: box " + std::to_string(i);
    if (b.x0 < 0 || b.y0 < 0 || b.width < 1 || b.height < 1 || b.x0 + int64_t{b.width} > w ||
        b.y0 + int64_t{b.height} > h)
      return Error{name + " is not inside the " + std::to_string(w) + "x" + std::to_string(h) +
                   " grid"};
    if (b.x0 % cell_px != 0 || b.y0 % cell_px != 0 || b.width != std::min(cell_px, w - b.x0) ||
        b.height != std::min(cell_px, h - b.y0))
      return Error{name + " is not a cell of the " + std::to_string(cell_px) + "-texel grid"};
    if (b.u_max < b.x0 || b.u_max >= b.x0 + b.width || b.v_max < b.y0 || b.v_max >= b.y0 + b.height)
      return Error{name + ": its highest texel (u_max, v_max) lies outside the box"};
    if (!(b.h_max_mm >= -kMaxPackHeightMm) ||
        b.h_max_mm > header.max_height_mm + 1e-6 * (1 + std::abs(header.max_height_mm)))
      return Error{name + ": h_max_mm " + FormatNumber(b.h_max_mm) + " is not finite or above H"};
    if (i > 0) {
      const ReliefBox& a = boxes[i - 1];
      if (std::make_pair(b.y0, b.x0) <= std::make_pair(a.y0, a.x0))
        return Error{name + ": boxes must be distinct cells in row-major order"};
    }
  }
  return Status::Ok();
}

Status CheckHalfRange(const Pack& pack, int y0) {
  const int w = pack.width();
  auto check = [&](const char* map, size_t i, float v) -> Status {
    if (std::abs(v) > kHalfMax)
      return Error{std::string(map) + " at texel " + TexelName(int(i % w), y0 + int(i / w)) +
                   " = " + FormatNumber(v) + " exceeds the half-float range (65504)"};
    return Status::Ok();
  };
  for (size_t i = 0; i < pack.field.height_mm.size(); ++i) {
    Status s = check("height", i, pack.field.height_mm.data[i]);
    for (int c = 0; c < 3 && s.ok(); ++c) s = check("rho_d", i, pack.maps.rho_d.data[i][c]);
    for (int c = 0; c < 3 && s.ok(); ++c) s = check("rho_s", i, pack.maps.rho_s.data[i][c]);
    for (int c : {0, 1, 3})
      if (s.ok()) s = check("lobe", i, pack.maps.lobe.data[i][c]);
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

std::vector<float> BoxCells(const std::vector<ReliefBox>& boxes, int w, int h, int cell_px) {
  const int cells_x = (w + cell_px - 1) / cell_px, cells_y = (h + cell_px - 1) / cell_px;
  std::vector<float> cells(static_cast<size_t>(cells_x) * cells_y * 4, 0.0f);
  for (const ReliefBox& b : boxes) {
    float* c = &cells[4 * (static_cast<size_t>(b.y0 / cell_px) * cells_x + b.x0 / cell_px)];
    c[0] = 1.0f;
    c[1] = b.h_max_mm;
    c[2] = static_cast<float>(b.u_max - b.x0);
    c[3] = static_cast<float>(b.v_max - b.y0);
  }
  return cells;
}

void EncodeTexel(const HeightField& field, const Grid<Vec3f>& normals, const ReflectanceMaps& maps,
                 size_t i, uint16_t surface[4], uint16_t reflectance[9]) {
  surface[0] = ToHalfBits(field.height_mm.data[i]);
  surface[1] = ToHalfBits(normals.data[i].x());
  surface[2] = ToHalfBits(normals.data[i].y());
  surface[3] = ToHalfBits(
      static_cast<float>(TexelCode(field.state.data[i], maps.status.data[i], maps.model.data[i])));
  for (int c = 0; c < 3; ++c) {
    reflectance[c] = ToHalfBits(maps.rho_d.data[i][c]);
    reflectance[3 + c] = ToHalfBits(maps.rho_s.data[i][c]);
  }
  reflectance[6] = ToHalfBits(maps.lobe.data[i][0]);
  reflectance[7] = ToHalfBits(maps.lobe.data[i][1]);
  reflectance[8] = ToHalfBits(maps.lobe.data[i][3]);
}

}  // namespace pack_exr

namespace {

using namespace pack_exr;

// Rounds a finite half to `bits` mantissa bits (of 10), to nearest; a value that would round up
// into infinity is truncated instead.
uint16_t QuantiseHalfBits(uint16_t h, int bits) {
  if (bits >= 10) return h;
  const uint16_t sign = h & 0x8000u;
  const uint16_t magnitude = h & 0x7fffu;
  const int drop = 10 - bits;
  const uint16_t mask = static_cast<uint16_t>(~((1u << drop) - 1u)) & 0x7fffu;
  uint32_t rounded = (static_cast<uint32_t>(magnitude) + (1u << (drop - 1))) & mask;
  if (rounded >= 0x7c00u) rounded = magnitude & mask;  // would be Inf
  return static_cast<uint16_t>(sign | rounded);
}

float Encode(float v, int bits) { return FromHalfBits(QuantiseHalfBits(ToHalfBits(v), bits)); }

}  // namespace

const char* ToString(PackEncoding encoding) {
  return encoding == PackEncoding::kHalf ? "half" : "quantised";
}

Status PackQuantisation::Validate() const {
  for (auto [name, v] : {std::pair<const char*, int>{"height_bits", height_bits},
                         {"normal_bits", normal_bits},
                         {"rho_bits", rho_bits},
                         {"lobe_bits", lobe_bits}})
    if (v < 0 || v > 10)
      return Error{std::string(name) + " must be in [0, 10] (half mantissa bits), got " +
                   std::to_string(v)};
  return Status::Ok();
}

Status PackWriteOptions::Validate() const {
  if (tile_size != 0)
    if (Status s = CheckPackTileSize(tile_size); !s.ok()) return s;
  return quantisation.Validate();
}

nlohmann::json ToJson(const PackWriteOptions& o) {
  nlohmann::json j = {{"encoding", ToString(o.encoding)}};
  if (o.encoding == PackEncoding::kQuantised)
    j["mantissa_bits"] = {{"height", o.quantisation.height_bits},
                          {"normal", o.quantisation.normal_bits},
                          {"rho", o.quantisation.rho_bits},
                          {"lobe", o.quantisation.lobe_bits}};
  if (o.tile_size > 0) j["tile_size"] = o.tile_size;
  return j;
}

Status Pack::Validate() const {
  const int w = width(), h = height();
  if (w <= 0 || h <= 0) return Error{"pack: empty grid"};
  if (field.state.width != w || field.state.height != h || normals.width != w ||
      normals.height != h || maps.width() != w || maps.height() != h)
    return Error{"pack: the height field, normals and reflectance maps differ in size"};
  if (Status s = CheckHeader(HeaderOf(*this)); !s.ok()) return s;
  if (Status s = maps.Validate(); !s.ok()) return Error{"pack: " + s.message()};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!(std::abs(field.height_mm(x, y)) <= kMaxPackHeightMm))
        return Error{"pack: height at texel " + TexelName(x, y) + " = " +
                     FormatNumber(field.height_mm(x, y)) + " mm is not finite or beyond " +
                     FormatNumber(kMaxPackHeightMm, kRoundTripDigits) + " mm"};
      if (static_cast<int>(field.state(x, y)) > 3)
        return Error{"pack: texel state at " + TexelName(x, y) + " is not a TexelState"};
      const Vec3f& n = normals(x, y);
      if (!IsValid(n) || std::abs(n.norm() - 1.0f) > 1e-3f || n.z() < 0)
        return Error{"pack: normal at texel " + TexelName(x, y) +
                     " is not a unit vector with nz >= 0"};
    }
  return Status::Ok();
}

PackHeader HeaderOf(const Pack& pack) {
  PackHeader h;
  h.width = pack.width();
  h.height = pack.height();
  h.pitch_mm = pack.field.pitch_mm;
  h.delta0_mm = pack.delta0_mm;
  h.max_height_mm = pack.max_height_mm;
  h.cell_px = pack.cell_px;
  h.boxes = pack.boxes;
  h.canvas_from_scan = pack.canvas_from_scan;
  h.provenance = pack.provenance;
  if (pack.maps.model.size() == static_cast<size_t>(h.width) * h.height)
    h.texels_by_model = CountModels(pack.maps);
  return h;
}

Pack EncodePackValues(const Pack& pack, const PackWriteOptions& options) {
  const bool q = options.encoding == PackEncoding::kQuantised;
  const PackQuantisation bits = q ? options.quantisation : PackQuantisation{10, 10, 10, 10};
  Pack out = pack;
  out.maps.fit_error = Grid<float>(pack.width(), pack.height(), 0.0f);
  for (size_t i = 0; i < pack.field.height_mm.size(); ++i) {
    out.field.height_mm.data[i] = Encode(pack.field.height_mm.data[i], bits.height_bits);
    const Vec3f& n = pack.normals.data[i];
    out.normals.data[i] =
        NormalFromXY(Encode(n.x(), bits.normal_bits), Encode(n.y(), bits.normal_bits));
    for (int c = 0; c < 3; ++c) {
      out.maps.rho_d.data[i][c] = Encode(pack.maps.rho_d.data[i][c], bits.rho_bits);
      out.maps.rho_s.data[i][c] = Encode(pack.maps.rho_s.data[i][c], bits.rho_bits);
    }
    auto& lobe = out.maps.lobe.data[i];
    lobe = {Encode(lobe[0], bits.lobe_bits), Encode(lobe[1], bits.lobe_bits), 1.0f,
            Encode(lobe[3], bits.lobe_bits)};
    if (pack.maps.model.data[i] == ReflectanceModel::kGgx) {
      // Rounding to nearest keeps F0 <= 1 and alpha <= 1 (1 is kept exactly), but may take alpha
      // below kGgxMinAlpha (with few lobe bits): then the next kept value up.
      uint16_t alpha = QuantiseHalfBits(ToHalfBits(pack.maps.lobe.data[i][3]), bits.lobe_bits);
      const uint16_t step = static_cast<uint16_t>(1u << (10 - std::min(bits.lobe_bits, 10)));
      while (FromHalfBits(alpha) < kGgxMinAlpha) alpha = static_cast<uint16_t>(alpha + step);
      lobe = {0.0f, 0.0f, 1.0f, FromHalfBits(alpha)};
      for (int c = 0; c < 3; ++c)
        out.maps.rho_s.data[i][c] = std::min(out.maps.rho_s.data[i][c], 1.0f);
    }
  }
  return out;
}

Result<Pack> AssemblePack(PreprocessedCanvas canvas, ReflectanceMaps maps,
                          PackProvenance provenance) {
  if (maps.width() != canvas.field.width() || maps.height() != canvas.field.height())
    return Error{"reflectance maps are " + std::to_string(maps.width()) + "x" +
                 std::to_string(maps.height()) + " texels, the canvas " +
                 std::to_string(canvas.field.width()) + "x" +
                 std::to_string(canvas.field.height()) + ": fitted on another canvas?"};
  Pack pack;
  pack.field = std::move(canvas.field);
  pack.normals = std::move(canvas.normals);
  pack.maps = std::move(maps);
  pack.delta0_mm = canvas.delta0_mm;
  pack.max_height_mm = canvas.max_height_mm;
  pack.cell_px = canvas.cell_px;
  pack.boxes = std::move(canvas.boxes);
  pack.canvas_from_scan = canvas.canvas_from_scan;
  pack.provenance = std::move(provenance);
  if (Status s = pack.Validate(); !s.ok()) return Error{s.message()};
  return pack;
}

}  // namespace digitize
