// Reading JSON input files field by field (private to the library). Every message names the file,
// the key path and what was expected ("calib.json: images[2].camera.fx must be a number, got
// \"12\""), never nlohmann's own exception text, and quotes a bad value at most ~80 characters
// long whatever its size.
//
// The readers throw BadInput where they find a problem, so a parser reads as a list of fields;
// the public function that parses turns it into an Error (CatchBadInput), so no exception crosses
// the library's API.
#pragma once

#include <initializer_list>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <utility>

#include "digitize/core.h"

namespace digitize {

// Bad input found deep in a reader.
struct BadInput {
  std::string message;
};
[[noreturn]] void Fail(std::string message);

// read() as a Result: its value, or the message of the BadInput it threw.
template <class Read>
auto CatchBadInput(Read&& read) -> Result<decltype(read())> {
  try {
    return read();
  } catch (const BadInput& bad) {
    return Error{bad.message};
  }
}

// `text` as JSON; Fail(where + ": not valid JSON (...)") with the line and column when it is not,
// or when a number is beyond double ("1e400").
nlohmann::json ParseJson(std::string_view text, const std::string& where);

// A JSON value as an error message shows it: at most two levels deep and about 80 characters.
// Not json::dump: a hostile file can be huge, and dump recurses once per nesting level (a 400 KB
// file of nested arrays overflowed the stack).
std::string Show(const nlohmann::json& value);

// One JSON object, with the key path of every value for the error messages. Holds a reference:
// `object` must outlive it.
class Fields {
 public:
  // Fail(where + " must be an object, got TYPE") when `object` is not one.
  Fields(const nlohmann::json& object, std::string where);

  const std::string& where() const { return where_; }
  // The key path of `key` ("calib.json: images[2].camera").
  std::string At(const std::string& key) const { return where_ + "." + key; }
  bool Has(const std::string& key) const { return object_.contains(key); }

  // Each getter Fails naming At(key) when the key is missing or its value is not of the type.
  const nlohmann::json& Get(const std::string& key) const;
  Fields Object(const std::string& key) const { return Fields(Get(key), At(key)); }
  const nlohmann::json& Array(const std::string& key) const;
  double Number(const std::string& key) const { return NumberOf(Get(key), At(key)); }  // finite
  // An integer in [min, max].
  int64_t Integer(const std::string& key, int64_t min, int64_t max) const;
  std::string String(const std::string& key) const;
  bool Boolean(const std::string& key) const;
  Vec3d Vector3(const std::string& key) const;  // [x, y, z], finite
  Vec3f Rgb(const std::string& key) const;      // [r, g, b], or one number for grey
  Mat3d Matrix3(const std::string& key) const;  // 3 rows of 3 finite numbers

  // Unknown keys are typos ("encodng") until proven otherwise; "comment" and "_..." are free.
  void OnlyKeys(std::initializer_list<const char*> allowed) const;

  static std::string TypeName(const nlohmann::json& v) { return v.type_name(); }
  // `v` as a finite number; `where` names it in the message.
  static double NumberOf(const nlohmann::json& v, const std::string& where);

 private:
  const nlohmann::json& object_;
  std::string where_;
};

}  // namespace digitize
