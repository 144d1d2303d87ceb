#include "core/methods/method.h"

namespace cloudbake {

void BakeMethod::validate(const ShotSpec&, const std::string&) const {}

nlohmann::json BakeMethod::keyMaterial(const ShotSpec&, const nlohmann::json&) const {
  return nlohmann::json::object();
}

void BakeMethod::checkLimits(const ShotSpec&, const MethodLimits&, const std::string&) const {}

}  // namespace cloudbake
