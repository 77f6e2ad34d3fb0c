// A rigid transform as JSON (options_json.h): transform.json and the pack header store it so.
#include "digitize/core.h"
#include "json_fields.h"
#include "options_json.h"

namespace digitize {

nlohmann::json ToJson(const RigidTransform& t) {
  nlohmann::json rotation = nlohmann::json::array();
  for (int r = 0; r < 3; ++r)
    rotation.push_back({t.rotation(r, 0), t.rotation(r, 1), t.rotation(r, 2)});
  return {{"rotation", rotation},
          {"translation_mm", {t.translation.x(), t.translation.y(), t.translation.z()}}};
}

RigidTransform TransformFrom(const Fields& fields) {
  RigidTransform t;
  t.rotation = fields.Matrix3("rotation");
  t.translation = fields.Vector3("translation_mm");
  return t;
}

}  // namespace digitize
