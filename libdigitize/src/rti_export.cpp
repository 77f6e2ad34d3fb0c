// The .ptm and relight folder exports of an RTI fit (rti_export.h).
#include "digitize/rti_export.h"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "digitize/image_io.h"
#include "digitize/output_dir.h"
#include "json_fields.h"

namespace digitize {
namespace fs = std::filesystem;
namespace {

// relight's coefficient order for each of ours (rti_basis.h): relight stores PTM as
// 1, lu, lv, lu^2, lu lv, lv^2; ours (the .ptm order) is lu^2, lv^2, lu lv, lu, lv, 1.
constexpr std::array<int, 6> kRelightPtmToOurs = {5, 3, 4, 0, 2, 1};

int OursFromRelight(RtiBasis basis, int relight_index) {
  return basis == RtiBasis::kPtm ? kRelightPtmToOurs[relight_index] : relight_index;
}

// A range [lo, hi] onto bytes: value = (byte / 255 - bias) * scale, byte = round(255 (value /
// scale + bias)). A constant plane still gets a positive scale, so decoding stays finite.
struct PlaneQuant {
  float scale = 1, bias = 0;
};
PlaneQuant QuantFor(double lo, double hi) {
  PlaneQuant q;
  const double range = std::max(hi - lo, 1e-6);
  q.scale = static_cast<float>(range);
  q.bias = static_cast<float>(-lo / range);
  return q;
}
uint8_t Quantise(double value, const PlaneQuant& q) {
  const double v = std::round(255.0 * (value / q.scale + q.bias));
  return static_cast<uint8_t>(std::clamp(v, 0.0, 255.0));
}

std::string FormatFloat(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// .ptm

Result<PtmLrgb> EncodePtmLrgb(const RtiFit& fit) {
  if (fit.basis != RtiBasis::kPtm)
    return Error{std::string("a .ptm holds a PTM fit, this one is ") + ToString(fit.basis)};
  if (!fit.srgb)
    return Error{"a .ptm holds a fit of sRGB codes, this one was fitted on linear values"};
  DIGITIZE_CHECK(fit.coefficients.size() == static_cast<size_t>(fit.width) * fit.height * 18,
                 "RtiFit coefficients do not match its size");
  // The Gram matrix of the basis over the fitted lights: <a, b>_G = sum over lights of
  // p_a(l) p_b(l), the least-squares inner product of two polynomials on the data's lights.
  Eigen::Matrix<double, 6, 6> gram = Eigen::Matrix<double, 6, 6>::Zero();
  for (const Vec3d& l : fit.lights) {
    const auto w = RtiBasisWeights(RtiBasis::kPtm, l);
    const Eigen::Map<const Eigen::Matrix<double, 6, 1>> b(w.data());
    gram += b * b.transpose();
  }
  if (fit.lights.empty()) gram.setIdentity();

  const size_t pixels = static_cast<size_t>(fit.width) * fit.height;
  std::vector<std::array<float, 6>> lum(pixels);
  PtmLrgb ptm;
  ptm.width = fit.width;
  ptm.height = fit.height;
  ptm.rgb.assign(pixels * 3, 0);
  ptm.coefficients.assign(pixels * 6, 0);
  for (size_t i = 0; i < pixels; ++i) {
    Eigen::Matrix<double, 6, 3> a;
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < 6; ++k) a(k, c) = fit.coefficients[(i * 3 + c) * 6 + k];
    const Eigen::Matrix<double, 6, 1> y = a.rowwise().mean();
    const double yy = y.dot(gram * y);
    Eigen::Vector3d chroma = Eigen::Vector3d::Zero();
    if (yy > 1e-12) {
      for (int c = 0; c < 3; ++c) chroma[c] = std::max(0.0, a.col(c).dot(gram * y) / yy);
    }
    const double m = chroma.maxCoeff();
    const Eigen::Matrix<double, 6, 1> l =
        m > 0 ? Eigen::Matrix<double, 6, 1>(y * m) : Eigen::Matrix<double, 6, 1>::Zero();
    for (int k = 0; k < 6; ++k) lum[i][k] = static_cast<float>(l[k]);
    for (int c = 0; c < 3; ++c) {
      const double byte = m > 0 ? std::round(255.0 * chroma[c] / m) : 0.0;
      ptm.rgb[i * 3 + c] = static_cast<uint8_t>(std::clamp(byte, 0.0, 255.0));
    }
  }
  // The .ptm bias is an integer byte: the step is chosen so that 0 maps to a whole byte and the
  // range [lo, hi] (widened to hold 0) fits in 0..255 with that bias.
  for (int k = 0; k < 6; ++k) {
    double lo = 0, hi = 0;
    for (size_t i = 0; i < pixels; ++i) {
      lo = std::min(lo, static_cast<double>(lum[i][k]));
      hi = std::max(hi, static_cast<double>(lum[i][k]));
    }
    double scale = std::max((hi - lo) / 254.0, 1e-9);
    int bias = static_cast<int>(std::ceil(-lo / scale));
    bias = std::clamp(bias, 0, 255);
    if ((255 - bias) * scale < hi) scale = hi / std::max(1, 255 - bias);
    ptm.scale[k] = static_cast<float>(scale);
    ptm.bias[k] = bias;
    for (size_t i = 0; i < pixels; ++i) {
      const double byte = std::round(lum[i][k] / ptm.scale[k] + bias);
      ptm.coefficients[i * 6 + k] = static_cast<uint8_t>(std::clamp(byte, 0.0, 255.0));
    }
  }
  return ptm;
}

Grid<Vec3f> RelightPtm(const PtmLrgb& ptm, const Vec3d& light) {
  Grid<Vec3f> out(ptm.width, ptm.height);
  if (!(light.z() > 0) || !IsValid(light.cast<float>())) return out;
  const auto w = RtiBasisWeights(RtiBasis::kPtm, light);
  for (int y = 0; y < ptm.height; ++y) {
    for (int x = 0; x < ptm.width; ++x) {
      const size_t i = static_cast<size_t>(y) * ptm.width + x;
      double lum = 0;
      for (int k = 0; k < 6; ++k)
        lum += w[k] * ptm.scale[k] * (static_cast<int>(ptm.coefficients[i * 6 + k]) - ptm.bias[k]);
      for (int c = 0; c < 3; ++c)
        out(x, y)[c] = static_cast<float>(std::clamp(lum * ptm.rgb[i * 3 + c], 0.0, 255.0) / 255.0);
    }
  }
  return out;
}

Status WritePtm(const fs::path& path, const RtiFit& fit, const std::vector<fs::path>& inputs) {
  if (Status s = CheckOutputPath(path, inputs); !s.ok()) return s;
  auto ptm = EncodePtmLrgb(fit);
  if (!ptm.ok()) return Error{path.string() + ": " + ptm.error().message};
  std::string text = "PTM_1.2\nPTM_FORMAT_LRGB\n" + std::to_string(ptm->width) + "\n" +
                     std::to_string(ptm->height) + "\n";
  for (int k = 0; k < 6; ++k) text += FormatFloat(ptm->scale[k]) + (k < 5 ? " " : "\n");
  for (int k = 0; k < 6; ++k) text += std::to_string(ptm->bias[k]) + (k < 5 ? " " : "\n");
  const size_t header = text.size();
  const size_t pixels = static_cast<size_t>(ptm->width) * ptm->height;
  text.resize(header + pixels * 9);
  char* coef = text.data() + header;
  char* rgb = coef + pixels * 6;
  for (int y = 0; y < ptm->height; ++y) {
    const size_t src = static_cast<size_t>(y) * ptm->width;
    const size_t dst = static_cast<size_t>(ptm->height - 1 - y) * ptm->width;  // bottom row first
    std::memcpy(coef + dst * 6, ptm->coefficients.data() + src * 6, ptm->width * 6);
    std::memcpy(rgb + dst * 3, ptm->rgb.data() + src * 3, ptm->width * 3);
  }
  return WriteAtomically(path, [&](const fs::path& temp) { return WriteTextFile(temp, text); });
}

Result<PtmLrgb> ReadPtm(const fs::path& path) {
  const std::string name = path.string();
  auto bytes = ReadTextFile(path, ".ptm file", uintmax_t{1} << 32);
  if (!bytes.ok()) return bytes.error();
  const std::string& data = *bytes;
  size_t pos = 0;
  auto line = [&]() -> std::string {
    const size_t end = data.find('\n', pos);
    if (end == std::string::npos) {
      pos = data.size();
      return {};
    }
    std::string l = data.substr(pos, end - pos);
    pos = end + 1;
    if (!l.empty() && l.back() == '\r') l.pop_back();
    return l;
  };
  const std::string version = line();
  if (version != "PTM_1.2" && version != "PTM_1.1")
    return Error{name + ": not a PTM file (first line '" + version.substr(0, 40) + "')"};
  const std::string format = line();
  if (format != "PTM_FORMAT_LRGB")
    return Error{name + ": format '" + format.substr(0, 40) + "', only PTM_FORMAT_LRGB is read"};
  PtmLrgb ptm;
  {
    std::istringstream w(line()), h(line());
    if (!(w >> ptm.width) || !(h >> ptm.height) || ptm.width <= 0 || ptm.height <= 0 ||
        ptm.width > 65536 || ptm.height > 65536)
      return Error{name + ": bad width / height lines"};
  }
  {
    std::istringstream s(line());
    for (float& v : ptm.scale)
      if (!(s >> v) || !std::isfinite(v)) return Error{name + ": bad scale line (6 numbers)"};
    std::istringstream b(line());
    for (int& v : ptm.bias)
      if (!(b >> v) || v < 0 || v > 255) return Error{name + ": bad bias line (6 bytes)"};
  }
  const size_t pixels = static_cast<size_t>(ptm.width) * ptm.height;
  if (data.size() - pos < pixels * 9) {
    return Error{name + ": truncated: " + std::to_string(data.size() - pos) + " data bytes, " +
                 std::to_string(pixels * 9) + " expected"};
  }
  ptm.coefficients.resize(pixels * 6);
  ptm.rgb.resize(pixels * 3);
  const char* coef = data.data() + pos;
  const char* rgb = coef + pixels * 6;
  for (int y = 0; y < ptm.height; ++y) {
    const size_t dst = static_cast<size_t>(y) * ptm.width;
    const size_t src = static_cast<size_t>(ptm.height - 1 - y) * ptm.width;
    std::memcpy(ptm.coefficients.data() + dst * 6, coef + src * 6, ptm.width * 6);
    std::memcpy(ptm.rgb.data() + dst * 3, rgb + src * 3, ptm.width * 3);
  }
  return ptm;
}

// ---------------------------------------------------------------------------------------------
// relight / OpenLIME folder

Status RelightFolderOptions::Validate() const {
  if (jpeg_quality < 1 || jpeg_quality > 100)
    return Error{"jpeg_quality must be 1-100, got " + std::to_string(jpeg_quality)};
  return Status::Ok();
}

Status WriteRelightFolder(const fs::path& dir, const RtiFit& fit,
                          const RelightFolderOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{dir.string() + ": " + s.message()};
  if (!fit.srgb) {
    return Error{dir.string() +
                 ": relight folders hold fits of sRGB codes, this one was fitted on linear values"};
  }
  const int n = fit.count();
  DIGITIZE_CHECK(fit.coefficients.size() == static_cast<size_t>(fit.width) * fit.height * 3 * n,
                 "RtiFit coefficients do not match its size");
  const FolderOutput output{"rti", "relight-rti", options.inputs};
  if (Status s = CheckFolderOutput(dir, output); !s.ok()) return s;

  const size_t pixels = static_cast<size_t>(fit.width) * fit.height;
  const int nplanes = 3 * n;
  // Plane p: relight coefficient p / 3, channel p % 3.
  std::vector<PlaneQuant> quant(nplanes);
  for (int p = 0; p < nplanes; ++p) {
    const int k = OursFromRelight(fit.basis, p / 3), c = p % 3;
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (size_t i = 0; i < pixels; ++i) {
      const double v = fit.coefficients[(i * 3 + c) * n + k];
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
    quant[p] = QuantFor(lo, hi);
  }
  nlohmann::json info;
  info["width"] = fit.width;
  info["height"] = fit.height;
  info["format"] = "jpg";
  info["type"] = fit.basis == RtiBasis::kPtm ? "ptm" : "hsh";
  info["colorspace"] = "rgb";
  info["nplanes"] = nplanes;
  info["quality"] = options.jpeg_quality;
  nlohmann::json lights = nlohmann::json::array();
  for (const Vec3d& l : fit.lights)
    for (int a = 0; a < 3; ++a) lights.push_back(std::round(l[a] * 1e6) / 1e6);
  info["lights"] = lights;
  nlohmann::json scale = nlohmann::json::array(), bias = nlohmann::json::array();
  for (const PlaneQuant& q : quant) {
    scale.push_back(q.scale);
    bias.push_back(q.bias);
  }
  info["materials"] = nlohmann::json::array({{{"scale", scale}, {"bias", bias}}});

  return WriteDirectoryAtomically(dir, output, [&](const fs::path& temp) -> Status {
    if (Status s = WriteTextFile(temp / "info.json", info.dump(1) + "\n"); !s.ok()) return s;
    const int njpegs = (nplanes + 2) / 3;
    for (int j = 0; j < njpegs; ++j) {
      Grid<std::array<uint8_t, 3>> image(fit.width, fit.height, {0, 0, 0});
      for (int ch = 0; ch < 3; ++ch) {
        const int p = 3 * j + ch;
        if (p >= nplanes) break;
        const int k = OursFromRelight(fit.basis, p / 3), c = p % 3;
        for (size_t i = 0; i < pixels; ++i)
          image.data[i][ch] = Quantise(fit.coefficients[(i * 3 + c) * n + k], quant[p]);
      }
      const fs::path file = temp / ("plane_" + std::to_string(j) + ".jpg");
      if (Status s = WriteJpegRgb8(file, image, options.jpeg_quality); !s.ok()) return s;
    }
    return Status::Ok();
  });
}

Result<RtiFit> ReadRelightFolder(const fs::path& dir) {
  const fs::path info_path = dir / "info.json";
  const std::string name = info_path.string();
  auto text = ReadTextFile(info_path, "relight info.json");
  if (!text.ok()) return text.error();
  return CatchBadInput([&]() -> RtiFit {
    const nlohmann::json info = ParseJson(*text, name);
    auto get_int = [&](const char* key) {
      if (!info.contains(key) || !info[key].is_number_integer())
        Fail(name + ": '" + key + "' must be an integer");
      return info[key].get<int>();
    };
    auto get_string = [&](const char* key) {
      if (!info.contains(key) || !info[key].is_string())
        Fail(name + ": '" + key + "' must be a string");
      return info[key].get<std::string>();
    };
    RtiFit fit;
    fit.srgb = true;
    fit.width = get_int("width");
    fit.height = get_int("height");
    if (fit.width <= 0 || fit.height <= 0 || fit.width > 65536 || fit.height > 65536)
      Fail(name + ": width / height out of range");
    const std::string type = get_string("type"), colorspace = get_string("colorspace");
    if (colorspace != "rgb") Fail(name + ": colorspace '" + colorspace + "', only rgb is read");
    const int nplanes = get_int("nplanes");
    if (type == "ptm" && nplanes == 18) {
      fit.basis = RtiBasis::kPtm;
    } else if (type == "hsh" && nplanes == 12) {
      fit.basis = RtiBasis::kHsh2;
    } else if (type == "hsh" && nplanes == 27) {
      fit.basis = RtiBasis::kHsh3;
    } else {
      Fail(name + ": type '" + type + "' with " + std::to_string(nplanes) +
           " planes is not read (ptm: 18, hsh: 12 or 27)");
    }
    if (!info.contains("materials") || !info["materials"].is_array() ||
        info["materials"].size() != 1)
      Fail(name + ": 'materials' must be an array of one material");
    const nlohmann::json& m = info["materials"][0];
    std::vector<PlaneQuant> quant(nplanes);
    for (const char* key : {"scale", "bias"}) {
      if (!m.contains(key) || !m[key].is_array() || static_cast<int>(m[key].size()) != nplanes)
        Fail(name + ": materials[0]." + key + " must hold " + std::to_string(nplanes) + " numbers");
      for (int p = 0; p < nplanes; ++p) {
        if (!m[key][p].is_number() || !std::isfinite(m[key][p].get<double>()))
          Fail(name + ": materials[0]." + key + "[" + std::to_string(p) + "] is not a number");
        (std::string(key) == "scale" ? quant[p].scale : quant[p].bias) = m[key][p].get<float>();
      }
    }
    if (info.contains("lights") && info["lights"].is_array()) {
      const nlohmann::json& l = info["lights"];
      for (size_t i = 0; i + 2 < l.size(); i += 3)
        if (l[i].is_number() && l[i + 1].is_number() && l[i + 2].is_number())
          fit.lights.emplace_back(l[i].get<double>(), l[i + 1].get<double>(),
                                  l[i + 2].get<double>());
    }
    const int n = fit.count();
    const size_t pixels = static_cast<size_t>(fit.width) * fit.height;
    fit.coefficients.assign(pixels * 3 * n, 0.0f);
    for (int j = 0; j < (nplanes + 2) / 3; ++j) {
      const fs::path file = dir / ("plane_" + std::to_string(j) + ".jpg");
      auto image = ReadImage(file);
      if (!image.ok()) Fail(image.error().message);
      if (image->width != fit.width || image->height != fit.height || image->channels != 3)
        Fail(file.string() + ": " + std::to_string(image->width) + "x" +
             std::to_string(image->height) + "x" + std::to_string(image->channels) + ", " +
             std::to_string(fit.width) + "x" + std::to_string(fit.height) + "x3 expected");
      for (int ch = 0; ch < 3; ++ch) {
        const int p = 3 * j + ch;
        if (p >= nplanes) break;
        const int k = OursFromRelight(fit.basis, p / 3), c = p % 3;
        for (size_t i = 0; i < pixels; ++i) {
          const double byte = std::round(image->pixels[i * 3 + ch] * 255.0);
          fit.coefficients[(i * 3 + c) * n + k] =
              static_cast<float>((byte / 255.0 - quant[p].bias) * quant[p].scale);
        }
      }
    }
    return fit;
  });
}

// ---------------------------------------------------------------------------------------------
// `digitize rti`

Status RtiRunOptions::Validate() const {
  if (photos.empty()) return Error{"--photos: an RTI .lp file is required"};
  if (Status s = fit.Validate(); !s.ok()) return s;
  if (Status s = photo.Validate(); !s.ok()) return s;
  if (Status s = relight.Validate(); !s.ok()) return s;
  if (!ptm.empty() && fit.basis != RtiBasis::kPtm) {
    return Error{"--ptm " + ptm + ": a .ptm holds the PTM basis, the fit is " +
                 ToString(fit.basis) + " (use --basis ptm, or --relight-dir for HSH)"};
  }
  if ((!ptm.empty() || !relight_dir.empty()) && !fit.fit_in_srgb)
    return Error{"the .ptm and relight exports hold fits of sRGB codes: drop --linear"};
  return Status::Ok();
}

Result<RtiRunResult> RunRti(const RtiRunOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return Error{s.message()};
  auto photos = ReadRtiCapture(options.photos, options.photo);
  if (!photos.ok()) return photos.error();
  std::optional<PhotoSet> held;
  if (!options.held_out.empty()) {
    auto h = ReadRtiCapture(options.held_out, options.photo);
    if (!h.ok()) return h.error();
    held = std::move(*h);
  }
  std::vector<fs::path> inputs = {options.photos};
  for (const Photo& p : photos->photos) inputs.push_back(p.path);
  if (held) {
    inputs.emplace_back(options.held_out);
    for (const Photo& p : held->photos) inputs.push_back(p.path);
  }
  if (!options.ptm.empty())
    if (Status s = CheckOutputPath(options.ptm, inputs); !s.ok()) return Error{s.message()};
  RelightFolderOptions folder = options.relight;
  folder.inputs = inputs;
  if (!options.relight_dir.empty()) {
    if (Status s = CheckFolderOutput(options.relight_dir, {"rti", "relight-rti", inputs}); !s.ok())
      return Error{s.message()};
  }

  RtiRunResult result;
  result.photos = static_cast<int>(photos->photos.size());
  auto fit = FitRti(*photos, options.fit);
  if (!fit.ok()) return fit.error();
  result.fit = std::move(*fit);
  if (held) {
    const auto t0 = std::chrono::steady_clock::now();
    Srgb8PsnrAccumulator pooled;
    const ColourEncoding enc = result.fit.srgb ? ColourEncoding::kSrgb : ColourEncoding::kLinear;
    for (const Photo& p : held->photos) {
      const std::string what = p.entry + " (" + p.path.string() + ")";
      if (p.rgb.width != result.fit.width || p.rgb.height != result.fit.height) {
        return Error{what + ": " + std::to_string(p.rgb.width) + "x" +
                     std::to_string(p.rgb.height) + " pixels, the fitted photos have " +
                     std::to_string(result.fit.width) + "x" + std::to_string(result.fit.height)};
      }
      if (!(p.light.direction.z() > 0))
        return Error{what + ": held-out light at or below the horizon"};
      const Grid<Vec3f> relit = RelightRti(result.fit, p.light.direction, options.fit.num_threads);
      Srgb8PsnrAccumulator one;
      if (Status s = one.Add(relit, enc, p.rgb, ColourEncoding::kLinear, {}, what); !s.ok())
        return Error{s.message()};
      if (Status s = pooled.Add(relit, enc, p.rgb, ColourEncoding::kLinear, {}, what); !s.ok())
        return Error{s.message()};
      result.held_out_images.push_back({p.entry, one.Score()});
    }
    result.held_out = pooled.Score();
    result.seconds_held_out =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  if (!options.ptm.empty())
    if (Status s = WritePtm(options.ptm, result.fit, inputs); !s.ok()) return Error{s.message()};
  if (!options.relight_dir.empty()) {
    if (Status s = WriteRelightFolder(options.relight_dir, result.fit, folder); !s.ok())
      return Error{s.message()};
  }
  return result;
}

}  // namespace digitize
