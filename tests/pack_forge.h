// Test helper: a pack rewritten with some digitize:* header attributes replaced and its checksum
// recomputed from docs/formats.md's definition alone (SHA-1 of the other digitize:* attributes as
// "name=value\n" sorted by name, then the decoded pixels of parts 0, 1, 2 in the documented
// channel order). What anyone with an EXR library and SHA-1 can do to a shared pack -- the
// checksum is an integrity check, not authentication -- so the reader's other checks must hold on
// their own. That such a forgery reads back at all (pack_test) also checks the definition.
#pragma once

#include <OpenImageIO/half.h>
#include <OpenImageIO/hash.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace digitize::forge {

// Sets channel `channel` of pixel (x, y) in a half part's pixels as the file stores them
// (channels in the file's order). False when the part has no such channel or pixel.
inline bool SetHalf(const OIIO::ImageSpec& spec, std::vector<char>& pixels,
                    const std::string& channel, int x, int y, float value) {
  const auto it = std::find(spec.channelnames.begin(), spec.channelnames.end(), channel);
  if (it == spec.channelnames.end() || spec.format != OIIO::TypeDesc::HALF || x < 0 || y < 0 ||
      x >= spec.width || y >= spec.height)
    return false;
  const size_t c = static_cast<size_t>(it - spec.channelnames.begin());
  const uint16_t bits = half(value).bits();
  std::memcpy(&pixels[((static_cast<size_t>(y) * spec.width + x) * spec.nchannels + c) * 2], &bits,
              2);
  return true;
}

// Pixels of one part as the file stores them (channels in the file's order, native type).
using PixelEdit = std::function<void(int part, const OIIO::ImageSpec& spec, std::vector<char>&)>;

// Returns "" on success, else what failed. `erase`: attributes removed (an older writer's header);
// `edit`: called on every part's pixels before the checksum is recomputed.
inline std::string ForgePack(const std::filesystem::path& from, const std::filesystem::path& to,
                             const std::map<std::string, std::string>& attributes,
                             const std::vector<std::string>& erase = {},
                             const PixelEdit& edit = nullptr) {
  const std::vector<std::vector<std::string>> order = {
      {"H", "NX", "NY", "M"},
      {"rho_d.R", "rho_d.G", "rho_d.B", "rho_s.R", "rho_s.G", "rho_s.B", "lobe.cx", "lobe.cy",
       "lobe.k"},
      {"present", "h_max", "u_max", "v_max"}};
  auto in = OIIO::ImageInput::open(from.string());
  if (!in) return "cannot open " + from.string() + ": " + OIIO::geterror();
  std::vector<OIIO::ImageSpec> specs;
  std::vector<std::vector<char>> pixels;
  for (int part = 0; in->seek_subimage(part, 0); ++part) {
    specs.push_back(in->spec());
    pixels.emplace_back(specs.back().image_bytes(/*native=*/true));
    if (!in->read_image(part, 0, 0, specs.back().nchannels, OIIO::TypeDesc::UNKNOWN,
                        pixels.back().data()))
      return "cannot read part " + std::to_string(part) + ": " + in->geterror();
  }
  in->close();
  if (specs.size() != order.size()) return "not a 3-part pack";
  if (edit)
    for (size_t part = 0; part < specs.size(); ++part)
      edit(static_cast<int>(part), specs[part], pixels[part]);
  for (const auto& [name, value] : attributes) specs[0].attribute(name, value);
  for (const std::string& name : erase) specs[0].erase_attribute(name);

  std::vector<std::pair<std::string, std::string>> attrs;
  for (const OIIO::ParamValue& p : specs[0].extra_attribs) {
    const std::string name = p.name().string();
    if (name.rfind("digitize:", 0) == 0 && name != "digitize:checksum")
      attrs.emplace_back(name, specs[0].get_string_attribute(name));
  }
  std::sort(attrs.begin(), attrs.end());
  OIIO::SHA1 sha;
  for (const auto& [k, v] : attrs) sha.append(k + "=" + v + "\n");
  for (size_t part = 0; part < specs.size(); ++part) {
    const OIIO::ImageSpec& spec = specs[part];
    const size_t bytes = part == 2 ? 4 : 2;  // float boxes, half maps
    std::vector<size_t> index;
    for (const std::string& c : order[part]) {
      const auto it = std::find(spec.channelnames.begin(), spec.channelnames.end(), c);
      if (it == spec.channelnames.end()) return "part " + std::to_string(part) + " lacks " + c;
      index.push_back(static_cast<size_t>(it - spec.channelnames.begin()));
    }
    const size_t n = static_cast<size_t>(spec.width) * spec.height, nc = index.size();
    std::vector<char> canonical(n * nc * bytes);
    for (size_t i = 0; i < n; ++i)
      for (size_t k = 0; k < nc; ++k)
        std::memcpy(&canonical[(i * nc + k) * bytes], &pixels[part][(i * nc + index[k]) * bytes],
                    bytes);
    sha.append(canonical.data(), canonical.size());
  }
  specs[0].attribute("digitize:checksum", sha.digest());

  auto out = OIIO::ImageOutput::create(to.string());
  if (!out) return "no writer for " + to.string();
  if (!out->open(to.string(), static_cast<int>(specs.size()), specs.data()))
    return "cannot write " + to.string() + ": " + out->geterror();
  for (size_t part = 0; part < specs.size(); ++part) {
    if (part > 0 && !out->open(to.string(), specs[part], OIIO::ImageOutput::AppendSubimage))
      return "cannot append part " + std::to_string(part);
    if (!out->write_image(OIIO::TypeDesc::UNKNOWN, pixels[part].data()))
      return "cannot write part " + std::to_string(part) + ": " + out->geterror();
  }
  if (!out->close()) return "cannot close " + to.string();
  return "";
}

}  // namespace digitize::forge
