// Private: each stage's options (and the canvas transform) as JSON, written by the stage that owns them and used both in its
// report.json and in a pack's provenance (docs/formats.md), so the two never disagree.
#pragma once

#include <nlohmann/json.hpp>

#include "digitize/core.h"

namespace digitize {

struct PreprocessOptions;
struct ReflectanceFitOptions;
struct PackWriteOptions;

nlohmann::json ToJson(const PreprocessOptions& options);      // preprocess.cpp
nlohmann::json ToJson(const ReflectanceFitOptions& options);  // reflectance_fit.cpp
nlohmann::json ToJson(const PackWriteOptions& options);       // pack.cpp
// {"rotation": 3 rows, "translation_mm": 3 numbers}: transform.json and the pack header.
nlohmann::json ToJson(const RigidTransform& transform);       // preprocess.cpp
// Its inverse. The message names the member and what it must be ("rotation must be 3 rows of 3
// numbers"), for the caller to prefix with the file. Checks the shape, not that R is a rotation.
Result<RigidTransform> TransformFromJson(const nlohmann::json& json);  // preprocess.cpp

}  // namespace digitize
