// Core types shared by every stage: grids, rigid transforms, results and progress.
//
// Layer: core (depends on nothing but Eigen and the standard library).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace digitize {

inline constexpr double kPi = 3.14159265358979323846;

// ---------------------------------------------------------------------------------------------
// Failure handling (STYLE.md rule 4): bad input or I/O -> a returned Error naming the file and
// the problem; a broken invariant -> DIGITIZE_CHECK throws; a fit that does not converge -> data.

struct Error {
  std::string message;  // "scan.exr: 3 channels expected (X, Y, Z in mm), got 4"
};

// A value or an Error. No exception crosses a stage boundary for bad input.
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : state_(std::move(value)) {}      // NOLINT: implicit by design
  Result(Error error) : state_(std::move(error)) {}  // NOLINT

  bool ok() const { return std::holds_alternative<T>(state_); }
  explicit operator bool() const { return ok(); }
  const T& value() const& { return Get(); }
  T& value() & { return Get(); }
  T&& value() && { return std::move(Get()); }
  const T& operator*() const& { return Get(); }
  T& operator*() & { return Get(); }
  const T* operator->() const { return &Get(); }
  T* operator->() { return &Get(); }
  const Error& error() const { return std::get<Error>(state_); }

 private:
  T& Get() {
    if (!ok()) throw std::logic_error("Result::value() on an error: " + error().message);
    return std::get<T>(state_);
  }
  const T& Get() const {
    if (!ok()) throw std::logic_error("Result::value() on an error: " + error().message);
    return std::get<T>(state_);
  }
  std::variant<T, Error> state_;
};

// Result of an operation that returns nothing but may fail.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(Error error) : error_(std::move(error.message)), failed_(true) {}  // NOLINT
  static Status Ok() { return {}; }
  bool ok() const { return !failed_; }
  explicit operator bool() const { return ok(); }
  const std::string& message() const { return error_; }

 private:
  std::string error_;
  bool failed_ = false;
};

// Broken invariant (a bug, not bad input).
class InvariantError : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};

#define DIGITIZE_CHECK(cond, msg)                                                               \
  do {                                                                                          \
    if (!(cond))                                                                                \
      throw ::digitize::InvariantError(std::string(__FILE__) + ":" + std::to_string(__LINE__) + \
                                       ": " + (msg));                                           \
  } while (0)

// ---------------------------------------------------------------------------------------------
// Grids. Row-major, row 0 first; (x, y) = (column, row). Contiguous so OpenCV and OpenImageIO can
// wrap the storage without a copy.

template <class T>
struct Grid {
  int width = 0;
  int height = 0;
  std::vector<T> data;

  Grid() = default;
  // Without a fill value cells are zero: Eigen's T{} would leave vectors uninitialised.
  Grid(int w, int h) : Grid(w, h, Zero()) {}
  Grid(int w, int h, const T& fill) : width(w), height(h) {
    DIGITIZE_CHECK(w >= 0 && h >= 0, "negative grid size");
    data.assign(static_cast<size_t>(w) * static_cast<size_t>(h), fill);
  }
  bool empty() const { return data.empty(); }
  size_t size() const { return data.size(); }
  bool Contains(int x, int y) const { return x >= 0 && y >= 0 && x < width && y < height; }
  size_t Index(int x, int y) const {
    return static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x);
  }
  T& operator()(int x, int y) { return data[Index(x, y)]; }
  const T& operator()(int x, int y) const { return data[Index(x, y)]; }
  T* Row(int y) { return data.data() + Index(0, y); }
  static T Zero() {
    if constexpr (requires { T::Zero(); }) {
      return T::Zero();
    } else {
      return T{};
    }
  }
  const T* Row(int y) const { return data.data() + Index(0, y); }
};

using Vec3f = Eigen::Vector3f;
using Vec3d = Eigen::Vector3d;
using Mat3d = Eigen::Matrix3d;

inline constexpr float kMissing = std::numeric_limits<float>::quiet_NaN();

inline bool IsValid(const Vec3f& p) {
  return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
}

// ---------------------------------------------------------------------------------------------
// Rigid transforms. Names say the frames: `canvas_from_scan.Apply(p_scan)` gives p in the canvas
// frame. Rotation is orthonormal with det +1 (checked where constructed from input).

struct RigidTransform {
  Mat3d rotation = Mat3d::Identity();
  Vec3d translation = Vec3d::Zero();

  Vec3d Apply(const Vec3d& p) const { return rotation * p + translation; }
  Vec3d ApplyToDirection(const Vec3d& d) const { return rotation * d; }
  RigidTransform Inverse() const {
    RigidTransform inv;
    inv.rotation = rotation.transpose();
    inv.translation = -(inv.rotation * translation);
    return inv;
  }
  // (a * b).Apply(p) == a.Apply(b.Apply(p))
  friend RigidTransform operator*(const RigidTransform& a, const RigidTransform& b) {
    RigidTransform c;
    c.rotation = a.rotation * b.rotation;
    c.translation = a.rotation * b.translation + a.translation;
    return c;
  }
};

// Angle in degrees between two directions (unsigned, robust near 0 and 180).
inline double AngleDeg(const Vec3d& a, const Vec3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / 3.14159265358979323846;
}

// The toolkit's one number format, for messages and metadata: printf's %g with
// `significant_digits` digits ("0.25", "1e+30", "nan"; 6 is what std::ostream prints), or, with
// kRoundTripDigits, the shortest text that reads back as the same double (std::to_chars), for a
// value a reader parses again.
inline constexpr int kRoundTripDigits = -1;
inline std::string FormatNumber(double v, int significant_digits = 6) {
  char buf[40];
  if (significant_digits == kRoundTripDigits) {
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
  }
  const int n = std::snprintf(buf, sizeof buf, "%.*g", significant_digits, v);
  return std::string(buf, std::min(static_cast<size_t>(n), sizeof buf - 1));
}

// ---------------------------------------------------------------------------------------------
// Progress. Stages report a fraction in [0, 1] for a named step; the CLI draws a bar, tests
// pass nothing. Called from one thread at a time, at most a few hundred times per step.
using ProgressCallback = std::function<void(std::string_view step, double fraction)>;

inline void ReportProgress(const ProgressCallback& progress, std::string_view step,
                           double fraction) {
  if (progress) progress(step, fraction);
}

}  // namespace digitize
