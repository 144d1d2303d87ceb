#include "core/methods/registry.h"

#include "core/error.h"
#include "core/methods/auto.h"
#include "core/methods/pathtrace.h"
#include "core/methods/photon.h"
#include "core/methods/pointcloud.h"
#include "core/methods/precomputed.h"
#include "core/methods/single.h"

namespace cloudbake {

const std::vector<const BakeMethod*>& bakeMethods() {
  // Constant data built once: the methods are stateless, so sharing them is safe.
  static const std::vector<const BakeMethod*> kMethods = {&pathtraceMethod(),  &singleMethod(),
                                                          &pointcloudMethod(), &precomputedMethod(),
                                                          &photonMethod(),     &autoMethod()};
  return kMethods;
}

const BakeMethod* findMethod(std::string_view name) {
  for (const BakeMethod* m : bakeMethods()) {
    if (m->info().name == name) return m;
  }
  return nullptr;
}

const BakeMethod& methodOf(const ShotSpec& shot) {
  const BakeMethod* m = findMethod(shot.bake.method);
  if (!m) throw InternalError("shot with unregistered method '" + shot.bake.method + "'");
  return *m;
}

std::vector<std::string> methodNames(bool runnable_only) {
  std::vector<std::string> names;
  for (const BakeMethod* m : bakeMethods()) {
    if (!runnable_only || m->info().runnable) names.push_back(m->info().name);
  }
  return names;
}

std::string joinedMethodNames(bool runnable_only) {
  const std::vector<std::string> names = methodNames(runnable_only);
  std::string s;
  for (size_t i = 0; i < names.size(); ++i) {
    if (i > 0) s += i + 1 == names.size() ? " or " : ", ";
    s += "'" + names[i] + "'";
  }
  return s;
}

}  // namespace cloudbake
