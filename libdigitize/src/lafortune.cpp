// The Lafortune BRDF: evaluation, gauge conversion, and the measured multi-lobe fits' parser.
#include "digitize/lafortune.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>
#include <vector>

#include "digitize/image_io.h"
#include "text_tokens.h"

namespace digitize {
namespace {

bool FiniteNonNegative(const Vec3f& x) { return x.allFinite() && (x.array() >= 0.0f).all(); }

bool AboveHorizon(const Vec3f& v, const Vec3f& l) { return v.z() > 0.0f && l.z() > 0.0f; }

// Final guard of the numerical contract: finite and capped (a NaN cannot get here from finite
// parameters, but a caller's non-finite parameters must not leak out as NaN either).
float Capped(float f) {
  if (!(f >= 0.0f)) return 0.0f;
  return std::min(f, kMaxBrdf);
}

}  // namespace

Status LafortuneParams::Validate() const {
  if (!FiniteNonNegative(rho_d))
    return Error{"rho_d must be finite and >= 0 (1/sr), got (" + FormatNumber(rho_d.x()) + ", " +
                 FormatNumber(rho_d.y()) + ", " + FormatNumber(rho_d.z()) + ")"};
  if (!FiniteNonNegative(rho_s))
    return Error{"rho_s must be finite and >= 0 (1/sr), got (" + FormatNumber(rho_s.x()) + ", " +
                 FormatNumber(rho_s.y()) + ", " + FormatNumber(rho_s.z()) + ")"};
  if (!std::isfinite(cx) || !std::isfinite(cy))
    return Error{"cx, cy must be finite, got " + FormatNumber(cx) + ", " + FormatNumber(cy)};
  if (cz != 1.0f) return Error{"cz must be 1 (the stored gauge), got " + FormatNumber(cz)};
  if (!(std::isfinite(k) && k >= 0.0f))
    return Error{"k must be finite and >= 0, got " + FormatNumber(k)};
  return Status::Ok();
}

Vec3f EvaluateLafortune(const LafortuneParams& p, const Vec3f& v, const Vec3f& l) {
  if (!AboveHorizon(v, l)) return Vec3f::Zero();
  const float lobe = LafortuneLobe(p.cx, p.cy, p.cz, p.k, v.data(), l.data());
  Vec3f f;
  for (int c = 0; c < 3; ++c) f[c] = Capped(p.rho_d[c] + p.rho_s[c] * lobe);
  return f;
}

LobeDerivatives LafortuneLobeDerivatives(const LafortuneParams& p, const Vec3f& v, const Vec3f& l) {
  LobeDerivatives d;
  if (!AboveHorizon(v, l)) return d;
  const double ax = double(v.x()) * l.x(), ay = double(v.y()) * l.y(), az = double(v.z()) * l.z();
  const double base = p.cx * ax + p.cy * ay + p.cz * az;
  if (!(base > kLobeBaseEps)) return d;
  const double log_base = std::log(base);
  const double e = p.k * log_base;
  if (e > kMaxLobeLog) {  // capped: flat in every parameter
    d.value = std::exp(double(kMaxLobeLog));
    return d;
  }
  d.value = std::exp(e);
  // d/dc base^k = k base^(k-1) dbase/dc = k value / base * dbase/dc.
  const double g = p.k * d.value / base;
  d.d_cx = g * ax;
  d.d_cy = g * ay;
  d.d_cz = g * az;
  d.d_k = d.value * log_base;
  return d;
}

Result<LafortuneParams> LafortuneFromGeneral(const Vec3f& rho_d, const Vec3f& rho_s, double cx,
                                             double cy, double cz, double k) {
  if (!FiniteNonNegative(rho_d))
    return Error{"general Lafortune lobe: rho_d must be finite and >= 0"};
  if (!FiniteNonNegative(rho_s))
    return Error{"general Lafortune lobe: rho_s must be finite and >= 0"};
  if (!(std::isfinite(cx) && std::isfinite(cy) && std::isfinite(cz)))
    return Error{"general Lafortune lobe: C must be finite, got (" + FormatNumber(cx) + ", " +
                 FormatNumber(cy) + ", " + FormatNumber(cz) + ")"};
  if (!(std::isfinite(k) && k >= 0.0))
    return Error{"general Lafortune lobe: k must be finite and >= 0, got " + FormatNumber(k)};
  if (!(cz > 0.0))
    return Error{
        "general Lafortune lobe: Cz = " + FormatNumber(cz) +
        " <= 0 has no cz = 1 form (a retro-reflective or grazing lobe; use the multi-lobe model)"};
  LafortuneParams p;
  p.rho_d = rho_d;
  p.cx = static_cast<float>(cx / cz);
  p.cy = static_cast<float>(cy / cz);
  p.cz = 1.0f;
  p.k = static_cast<float>(k);
  if (!std::isfinite(p.cx) || !std::isfinite(p.cy))
    return Error{"general Lafortune lobe: C / Cz overflows float (Cz = " + FormatNumber(cz) + ")"};
  // (s C . x)^k = s^k (C . x)^k with s = 1 / cz, so rho_s' = rho_s cz^k; in log space because
  // cz^k alone over- or underflows long before the product does.
  const double log_scale = k * std::log(cz);
  for (int c = 0; c < 3; ++c) {
    if (rho_s[c] == 0.0f) {
      p.rho_s[c] = 0.0f;
      continue;
    }
    const double log_value = std::log(double(rho_s[c])) + log_scale;
    if (log_value > std::log(double(std::numeric_limits<float>::max())))
      return Error{"general Lafortune lobe: rho_s * Cz^k = exp(" + FormatNumber(log_value) +
                   ") is beyond float's range"};
    // Below float's smallest normal the lobe contributes < 1e-38 / sr: 0 is the honest value.
    const double value = std::exp(log_value);
    p.rho_s[c] =
        value < double(std::numeric_limits<float>::min()) ? 0.0f : static_cast<float>(value);
  }
  return p;
}

// ---------------------------------------------------------------------------------------------
// Multi-lobe model.

Vec3f EvaluateMeasuredLafortune(const MeasuredLafortune& brdf, const Vec3f& v, const Vec3f& l) {
  if (!AboveHorizon(v, l)) return Vec3f::Zero();
  constexpr float kInvPi = 0.318309886183790671538f;
  Vec3f f = brdf.diffuse_albedo * kInvPi;
  const float axy = v.x() * l.x() + v.y() * l.y();
  const float az = v.z() * l.z();
  for (const MeasuredLafortuneLobe& lobe : brdf.lobes) {
    for (int c = 0; c < 3; ++c) f[c] += ClampedLobe(lobe.cxy[c] * axy + lobe.cz[c] * az, lobe.n[c]);
  }
  for (int c = 0; c < 3; ++c) f[c] = Capped(f[c]);
  return f;
}

namespace {

// A finite decimal number, the whole token (ParseWholeNumber alone accepts "nan" and "inf").
bool ParseNumber(std::string_view token, float* out) {
  float value = 0;
  if (!ParseWholeNumber(token, value) || !std::isfinite(value)) return false;
  *out = value;
  return true;
}

// "r,g,b" or one grey number. On failure returns a message naming the field.
std::string ParseRgb(std::string_view token, std::string_view field, Vec3f* out) {
  std::array<std::string_view, 3> parts;
  int count = 0;
  size_t start = 0;
  while (true) {
    const size_t comma = token.find(',', start);
    const std::string_view part =
        token.substr(start, comma == std::string_view::npos ? comma : comma - start);
    if (count == 3)
      return std::string(field) + ": '" + std::string(token) + "' has more than 3 values";
    parts[count++] = part;
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  if (count == 2)
    return std::string(field) + ": '" + std::string(token) +
           "' has 2 values; expected 1 (grey) or 3 (R,G,B)";
  for (int i = 0; i < count; ++i) {
    float value = 0;
    if (!ParseNumber(parts[i], &value))
      return std::string(field) + ": '" + std::string(parts[i].empty() ? token : parts[i]) +
             "' is not a finite number";
    (*out)[i] = value;
  }
  if (count == 1) out->setConstant((*out)[0]);
  return {};
}

}  // namespace

Result<std::vector<MeasuredLafortune>> ParseMeasuredLafortuneFits(std::string_view text,
                                                                  std::string_view source_name) {
  std::vector<MeasuredLafortune> materials;
  std::vector<bool> has_diffuse;
  const std::string source(source_name);
  int line_number = 0;
  size_t pos = 0;
  const auto fail = [&](const std::string& what) {
    return Error{source + ":" + std::to_string(line_number) + ": " + what};
  };
  while (pos <= text.size()) {
    const size_t newline = text.find('\n', pos);
    const std::string_view line = text.substr(
        pos, newline == std::string_view::npos ? std::string_view::npos : newline - pos);
    pos = newline == std::string_view::npos ? text.size() + 1 : newline + 1;
    ++line_number;
    std::vector<std::string_view> tokens;
    for (const TextToken& t : SplitTokens(line, kSpaceTabCr)) tokens.push_back(t.text);
    if (tokens.empty() || tokens[0].front() == '#') continue;
    if (tokens.size() != 5)
      return fail(
          "expected 5 columns ('<material> diffuse R G B' or '<material> <lobe> Cxy Cz n'), got " +
          std::to_string(tokens.size()));
    const std::string name(tokens[0]);
    auto it = std::find_if(materials.begin(), materials.end(),
                           [&](const MeasuredLafortune& m) { return m.name == name; });
    if (it == materials.end()) {
      materials.push_back(MeasuredLafortune{name, Vec3f::Zero(), {}});
      has_diffuse.push_back(false);
      it = materials.end() - 1;
    }
    const size_t index = static_cast<size_t>(it - materials.begin());
    if (tokens[1] == "diffuse") {
      if (has_diffuse[index]) return fail("second diffuse row for " + name);
      Vec3f albedo;
      for (int c = 0; c < 3; ++c) {
        float value = 0;
        if (!ParseNumber(tokens[2 + c], &value))
          return fail("diffuse of " + name + ": '" + std::string(tokens[2 + c]) +
                      "' is not a finite number");
        if (value < 0.0f)
          return fail("diffuse of " + name + ": albedo " + FormatNumber(value) + " < 0");
        albedo[c] = value;
      }
      it->diffuse_albedo = albedo;
      has_diffuse[index] = true;
      continue;
    }
    int lobe_index = -1;
    if (!ParseWholeNumber(tokens[1], lobe_index) || lobe_index < 0)
      return fail("second column must be 'diffuse' or a lobe index >= 0, got '" +
                  std::string(tokens[1]) + "'");
    if (static_cast<size_t>(lobe_index) != it->lobes.size())
      return fail("lobe " + std::to_string(lobe_index) + " of " + name + ": expected lobe " +
                  std::to_string(it->lobes.size()) + " (indices run 0, 1, 2, ... once each)");
    MeasuredLafortuneLobe lobe;
    const std::string prefix = "lobe " + std::to_string(lobe_index) + " of " + name + ": ";
    for (const auto& [token, field, target] :
         {std::tuple{tokens[2], "Cxy", &lobe.cxy}, std::tuple{tokens[3], "Cz", &lobe.cz},
          std::tuple{tokens[4], "n", &lobe.n}}) {
      const std::string problem = ParseRgb(token, field, target);
      if (!problem.empty()) return fail(prefix + problem);
    }
    if ((lobe.n.array() < 0.0f).any()) return fail(prefix + "exponent n must be >= 0");
    it->lobes.push_back(lobe);
  }
  for (size_t i = 0; i < materials.size(); ++i)
    if (!has_diffuse[i])
      return Error{source + ": material " + materials[i].name + " has no diffuse row"};
  if (materials.empty()) return Error{source + ": no material rows"};
  return materials;
}

Result<std::vector<MeasuredLafortune>> ReadMeasuredLafortuneFits(
    const std::filesystem::path& path) {
  // The reader's own words ("cannot open") whatever ReadTextFile found.
  auto text = ReadTextFile(path, "Lafortune fits file");
  if (!text) return Error{path.string() + ": cannot open"};
  return ParseMeasuredLafortuneFits(*text, path.string());
}

}  // namespace digitize
