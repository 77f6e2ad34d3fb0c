// Private: each stage's options (and the canvas transform) as JSON, written by the stage that
// owns them and used both in its report.json and in a pack's provenance (docs/formats.md), so the
// two never disagree.
#pragma once

#include <nlohmann/json.hpp>

#include "digitize/core.h"
#include "json_fields.h"

namespace digitize {

struct PreprocessOptions;
struct ReflectanceFitOptions;
struct PackWriteOptions;

nlohmann::json ToJson(const PreprocessOptions& options);      // preprocess.cpp
nlohmann::json ToJson(const ReflectanceFitOptions& options);  // reflectance_fit.cpp
nlohmann::json ToJson(const PackWriteOptions& options);       // pack.cpp
// {"rotation": 3 rows, "translation_mm": 3 numbers}: transform.json and the pack header.
nlohmann::json ToJson(const RigidTransform& transform);  // transform_json.cpp
// Its inverse (a member of a JSON file read with json_fields.h): Fails naming the key path when
// a member is missing or not 3 x 3 / 3 finite numbers. Checks the shape, not that R is a rotation.
RigidTransform TransformFrom(const Fields& fields);  // transform_json.cpp

}  // namespace digitize
