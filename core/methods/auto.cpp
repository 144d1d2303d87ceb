#include "core/methods/auto.h"

#include "core/error.h"
#include "core/methods/registry.h"
#include "core/transport/path_tracer.h"

namespace cloudbake {
namespace {

class AutoMethod final : public BakeMethod {
 public:
  AutoMethod() {
    info_.name = "auto";
    info_.summary =
        "the cheapest method predicted to meet bake.tolerance (not runnable in this version)";
    info_.citation = "";
    info_.version = 1;
    info_.default_samples = 64;
    info_.runnable = false;
    info_.knobs = {
        Knob::integer("max_depth", 1, 1000000, PathTracerOptions{}.max_depth,
                      "scattering events per path, should the choice be `pathtrace`"),
        Knob::number("tolerance", 0, 1, std::nullopt, "",
                     "relative RMSE of the cloud's own light the choice must meet")
            .exclusiveMax()
            .isRequired(),
    };
  }
  const MethodInfo& info() const override { return info_; }

  MethodPlan plan(const ShotSpec&, const ShotCacheKeys&,
                  const std::function<bool(const std::string&)>&) const override {
    throw notRunnable();
  }
  void run(MethodRun&) const override { throw notRunnable(); }

 private:
  static InputError notRunnable() {
    return InputError("/bake/method: 'auto' is not implemented in this version (use " +
                      joinedMethodNames(true) + ")");
  }
  MethodInfo info_;
};

}  // namespace

const BakeMethod& autoMethod() {
  static const AutoMethod kMethod;
  return kMethod;
}

}  // namespace cloudbake
