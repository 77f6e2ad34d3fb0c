// The contract of the parsers of user files (photo_set.h: ParseCalibrationText,
// ParseRtiLightsText; pack.h: ReadPack, InspectPack) on ANY input, checked on every input by the
// fuzz targets (tests/fuzz/fuzz_*.cpp) and on every corpus file by the normal test suite
// (tests/fuzz_corpus_test.cpp):
//   - no crash, no exception, no sanitizer report (the callers run under ASan+UBSan);
//   - bad input: an Error whose message names the source file;
//   - success: a result that holds the readers' promises (photos non-empty, cameras and lights
//     that validate, unit directions, entries naming the source, ...).
// Each Check* returns "" when the contract holds, else what is broken, for the caller to report.
#pragma once

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

#include "digitize/pack.h"
#include "digitize/photo_set.h"

namespace digitize::fuzz {

// The source name the fuzz targets pass: never opened (the parsers do not touch the filesystem).
inline const std::filesystem::path kCalibrationSource = "fuzz_dir/fuzz_calib.json";
inline const std::filesystem::path kLpSource = "fuzz_dir/fuzz_dirs.lp";

// A parsed rotation is snapped onto SO(3): orthonormal to rounding, far below the 1e-6 Validate
// accepts, so a snapping that silently degrades shows here first.
constexpr double kSnappedRotationTolerance = 1e-9;
// A direction normalised on read, normalised again: equal to rounding.
constexpr double kUnitTolerance = 1e-12;

inline std::string ErrorNamesSource(const std::string& message,
                                    const std::filesystem::path& source) {
  if (message.find(source.string()) != std::string::npos) return "";
  return "the error does not name " + source.string() + ": \"" + message + "\"";
}

inline std::string CheckCalibrationText(std::string_view text,
                                        const std::filesystem::path& source) {
  const Result<PhotoSet> set = ParseCalibrationText(text, source);
  if (!set.ok()) return ErrorNamesSource(set.error().message, source);
  if (set->photos.empty()) return "success with no photos";
  if (set->source != source) return "PhotoSet::source is " + set->source.string();
  if (set->is_rti) return "a calibration read as an RTI capture";
  for (const Photo& photo : set->photos) {
    const std::string what = photo.entry + ": ";
    if (photo.entry.find(source.string()) == std::string::npos) {
      return "entry \"" + photo.entry + "\" does not name the source";
    }
    if (photo.path.empty()) return what + "empty image path";
    if (photo.loaded()) return what + "pixels loaded by a parser";
    if (Status s = photo.camera.Validate(photo.entry); !s) return what + "camera: " + s.message();
    if (Status s = photo.light.Validate(photo.entry); !s) return what + "light: " + s.message();
    const Mat3d& r = photo.camera.camera_from_scan.rotation;
    const double off = (r.transpose() * r - Mat3d::Identity()).norm();
    if (!(off < kSnappedRotationTolerance &&
          std::abs(r.determinant() - 1) < kSnappedRotationTolerance)) {
      return what + "rotation not snapped onto SO(3): |R^T R - I| = " + std::to_string(off);
    }
    // The geometry helpers must be total on any camera the parser accepts.
    const Status sees = CheckCameraSeesCanvas(photo.camera, RigidTransform{},
                                              Eigen::Vector2d(200.0, 100.0), photo.entry);
    if (!sees.ok() && sees.message().rfind(photo.entry, 0) != 0) {
      return what + "CheckCameraSeesCanvas error does not start with the entry: " + sees.message();
    }
  }
  return "";
}

inline bool IsLpSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f' || c == '\n';
}

inline std::string CheckLpText(std::string_view text, const std::filesystem::path& source) {
  const auto entries = ParseRtiLightsText(text, source);
  if (!entries.ok()) return ErrorNamesSource(entries.error().message, source);
  if (entries->empty()) return "success with no entries";
  int previous_line = 0;
  std::string again = std::to_string(entries->size()) + "\n";
  for (const RtiLightEntry& e : *entries) {
    const std::string what = "line " + std::to_string(e.line) + ": ";
    if (e.line <= previous_line) return what + "line numbers not increasing";
    previous_line = e.line;
    if (e.image.empty()) return what + "empty image name";
    if (IsLpSpace(e.image.front()) || IsLpSpace(e.image.back())) {
      return what + "image name \"" + e.image + "\" starts or ends with white space";
    }
    if (e.image.find('#') != std::string::npos) return what + "a comment in the image name";
    if (!e.direction.allFinite() || std::abs(e.direction.norm() - 1) > kUnitTolerance) {
      return what + "direction not unit: |d| = " + std::to_string(e.direction.norm());
    }
    char numbers[96];
    std::snprintf(numbers, sizeof numbers, " %.17g %.17g %.17g\n", e.direction.x(), e.direction.y(),
                  e.direction.z());
    again += e.image + numbers;
  }
  // Round trip: the entries written back as a .lp file read as the same entries.
  const auto back = ParseRtiLightsText(again, source);
  if (!back.ok()) return "written back, the entries do not parse: " + back.error().message;
  if (back->size() != entries->size()) return "written back, the entry count changes";
  for (size_t i = 0; i < back->size(); ++i) {
    const RtiLightEntry& a = (*entries)[i];
    const RtiLightEntry& b = (*back)[i];
    if (a.image != b.image) return "written back, \"" + a.image + "\" reads as \"" + b.image + "\"";
    if ((a.direction - b.direction).norm() > kUnitTolerance) {
      return "written back, the direction of \"" + a.image + "\" changes";
    }
  }
  return "";
}

// A pack file: InspectPack reads the header only, ReadPack everything; a pack that reads must
// inspect too (the header is a subset), agree with the header, and Validate.
inline std::string CheckPackFile(const std::filesystem::path& path) {
  const Result<PackSummary> summary = InspectPack(path);
  if (!summary.ok()) {
    if (std::string broken = ErrorNamesSource(summary.error().message, path); !broken.empty()) {
      return "InspectPack: " + broken;
    }
  }
  const Result<Pack> pack = ReadPack(path);
  if (!pack.ok()) {
    if (std::string broken = ErrorNamesSource(pack.error().message, path); !broken.empty()) {
      return "ReadPack: " + broken;
    }
    return "";
  }
  if (!summary.ok()) return "ReadPack accepts what InspectPack refuses: " + summary.error().message;
  if (Status s = pack->Validate(); !s.ok())
    return "ReadPack returned a pack that does not Validate: " + s.message();
  if (pack->width() != summary->width || pack->height() != summary->height ||
      pack->boxes.size() != summary->box_count || pack->cell_px != summary->cell_px) {
    return "ReadPack and InspectPack disagree on the size, the cell size or the box count";
  }
  return "";
}

}  // namespace digitize::fuzz
