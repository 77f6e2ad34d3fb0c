#include "json_fields.h"

#include <cmath>

#include "digitize/image_io.h"

namespace digitize {

using nlohmann::json;

void Fail(std::string message) { throw BadInput{std::move(message)}; }

json ParseJson(std::string_view text, const std::string& where) {
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    // parse_error, and also out_of_range for a number beyond double ("1e400"): both bad input.
    // The text after nlohmann's "[json.exception.parse_error.101] " says where and why; the id
    // means nothing to a user. It quotes the file ("last read: '...'"), so it is escaped.
    std::string_view why = e.what();
    if (why.starts_with("[json.exception.")) {
      if (const size_t end = why.find("] "); end != std::string_view::npos)
        why.remove_prefix(end + 2);
    }
    Fail(where + ": not valid JSON (" + EscapeForTerminal(why) + ")");
  }
}

namespace {

constexpr int kShownDepth = 2;
constexpr size_t kShownChars = 80;

void ShowInto(const json& v, int depth, std::string& out) {
  if (out.size() > kShownChars) return;
  if (!v.is_structured()) {
    out += v.dump();  // a scalar: no recursion (a long string is cut below)
    return;
  }
  const bool array = v.is_array();
  if (v.empty() || depth == 0) {
    out += v.empty() ? (array ? "[]" : "{}") : (array ? "[...]" : "{...}");
    return;
  }
  out += array ? '[' : '{';
  bool first = true;
  for (auto it = v.begin(); it != v.end() && out.size() <= kShownChars; ++it) {
    if (!first) out += ", ";
    first = false;
    if (!array) out += json(it.key()).dump() + ": ";
    ShowInto(*it, depth - 1, out);
  }
  out += array ? ']' : '}';
}

}  // namespace

std::string Show(const json& v) {
  std::string out;
  ShowInto(v, kShownDepth, out);
  if (out.size() > kShownChars) {
    size_t cut = kShownChars;
    while (cut > 0 && (static_cast<unsigned char>(out[cut]) & 0xC0) == 0x80) --cut;  // UTF-8
    out.resize(cut);
    out += "...";
  }
  return out;
}

Fields::Fields(const json& object, std::string where) : object_(object), where_(std::move(where)) {
  if (!object_.is_object()) Fail(where_ + " must be an object, got " + TypeName(object_));
}

const json& Fields::Get(const std::string& key) const {
  if (!object_.contains(key)) Fail(where_ + ": missing \"" + key + "\"");
  return object_.at(key);
}

const json& Fields::Array(const std::string& key) const {
  const json& v = Get(key);
  if (!v.is_array()) Fail(At(key) + " must be an array, got " + Show(v));
  return v;
}

int64_t Fields::Integer(const std::string& key, int64_t min, int64_t max) const {
  const json& v = Get(key);
  if (!v.is_number_integer()) Fail(At(key) + " must be an integer, got " + Show(v));
  const auto i = v.get<int64_t>();
  if (i < min || i > max) Fail(At(key) + " is out of range: " + Show(v));
  return i;
}

std::string Fields::String(const std::string& key) const {
  const json& v = Get(key);
  if (!v.is_string()) Fail(At(key) + " must be a string, got " + Show(v));
  return v.get<std::string>();
}

bool Fields::Boolean(const std::string& key) const {
  const json& v = Get(key);
  if (!v.is_boolean()) Fail(At(key) + " must be true or false, got " + Show(v));
  return v.get<bool>();
}

Vec3d Fields::Vector3(const std::string& key) const {
  const json& v = Get(key);
  if (!v.is_array() || v.size() != 3)
    Fail(At(key) + " must be an array of 3 numbers, got " + Show(v));
  Vec3d out;
  for (int i = 0; i < 3; ++i) out[i] = NumberOf(v[i], At(key) + "[" + std::to_string(i) + "]");
  return out;
}

Vec3f Fields::Rgb(const std::string& key) const {
  const json& v = Get(key);
  if (v.is_number()) {
    const double g = NumberOf(v, At(key));
    return Vec3f::Constant(static_cast<float>(g));
  }
  return Vector3(key).cast<float>();
}

Mat3d Fields::Matrix3(const std::string& key) const {
  const std::string where = At(key);
  const json& r = Get(key);
  if (!r.is_array() || r.size() != 3) Fail(where + " must be 3 rows of 3 numbers, got " + Show(r));
  Mat3d m;
  for (int i = 0; i < 3; ++i) {
    if (!r[i].is_array() || r[i].size() != 3) {
      Fail(where + " must be 3 rows of 3 numbers, row " + std::to_string(i) + " is " + Show(r[i]));
    }
    for (int j = 0; j < 3; ++j) {
      m(i, j) = NumberOf(r[i][j], where + "[" + std::to_string(i) + "][" + std::to_string(j) + "]");
    }
  }
  return m;
}

void Fields::OnlyKeys(std::initializer_list<const char*> allowed) const {
  for (const auto& [key, value] : object_.items()) {
    if (key == "comment" || key.starts_with("_")) continue;
    bool known = false;
    for (const char* a : allowed) known = known || key == a;
    if (!known) {
      std::string list;
      for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
      Fail(where_ + ": unknown key \"" + key + "\" (expected: " + list + ")");
    }
  }
}

double Fields::NumberOf(const json& v, const std::string& where) {
  if (!v.is_number()) Fail(where + " must be a number, got " + Show(v));
  const double d = v.get<double>();
  if (!std::isfinite(d)) Fail(where + " is not finite");
  return d;
}

}  // namespace digitize
