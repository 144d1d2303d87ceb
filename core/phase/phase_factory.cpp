#include "core/phase/phase_factory.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <map>
#include <sstream>

#include "core/error.h"
#include "core/format.h"
#include "core/phase/henyey_greenstein.h"
#include "core/phase/isotropic.h"
#include "core/phase/mie_approx.h"
#include "core/phase/mie_isotropic_blend.h"
#include "core/phase/mie_table.h"

namespace cloudbake {
namespace {

double parseNumber(const std::string& key, const std::string& text) {
  const char* begin = text.c_str();
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(begin, &end);
  if (text.empty() || end != begin + text.size() || errno == ERANGE || !std::isfinite(v)) {
    throw InputError("phase." + key + ": expected a finite number, got '" + text + "'");
  }
  return v;
}

}  // namespace

std::shared_ptr<const PhaseFunction> makePhaseFunction(const PhaseSpec& spec,
                                                       const std::function<bool()>& keep_going) {
  // Validate the blend ratio first so a bad ratio is reported without building a Mie table.
  if (!std::isfinite(spec.mie_ratio) || spec.mie_ratio < 0.0 || spec.mie_ratio > 1.0) {
    std::ostringstream os;
    os << "phase.ratio: Mie/isotropic ratio must be in [0, 1], got " << exactNumber(spec.mie_ratio);
    throw InputError(os.str());
  }
  std::shared_ptr<const PhaseFunction> base;
  switch (spec.type) {
    case PhaseSpec::Type::kIsotropic:
      base = std::make_shared<IsotropicPhase>();
      break;
    case PhaseSpec::Type::kHenyeyGreenstein:
      base = std::make_shared<HenyeyGreensteinPhase>(spec.g);
      break;
    case PhaseSpec::Type::kMieApprox:
      base = std::make_shared<MieApproxPhase>(spec.diameter_um);
      break;
    case PhaseSpec::Type::kMie: {
      MieTableOptions options;
      options.effective_radius_um = spec.effective_radius_um;
      options.effective_variance = spec.effective_variance;
      base = std::make_shared<MieTablePhase>(options, keep_going);
      break;
    }
    default:
      throw InputError("phase.type: unknown phase function type");
  }
  if (spec.mie_ratio == 1.0) return base;
  return std::make_shared<MieIsotropicBlend>(base, spec.mie_ratio);
}

PhaseSpec parsePhaseSpec(const std::string& text) {
  PhaseSpec spec;
  const size_t colon = text.find(':');
  const std::string name = text.substr(0, colon);
  const std::string params = colon == std::string::npos ? "" : text.substr(colon + 1);
  std::map<std::string, std::vector<std::string>> allowed = {{"isotropic", {"ratio"}},
                                                             {"hg", {"g", "ratio"}},
                                                             {"mie_approx", {"d", "ratio"}},
                                                             {"mie", {"reff", "veff", "ratio"}}};
  const auto kind = allowed.find(name);
  if (kind == allowed.end()) {
    throw InputError("phase: unknown phase function '" + name +
                     "' (expected isotropic, hg, mie_approx or mie)");
  }
  if (colon != std::string::npos && params.empty()) {
    throw InputError("phase: '" + text + "' has an empty parameter list");
  }
  std::map<std::string, double> values;
  size_t pos = 0;
  while (pos < params.size()) {
    size_t comma = params.find(',', pos);
    if (comma == std::string::npos) comma = params.size();
    const std::string item = params.substr(pos, comma - pos);
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw InputError("phase: expected key=value in '" + text + "', got '" + item + "'");
    }
    const std::string key = item.substr(0, eq);
    bool known = false;
    std::string expected;
    for (const auto& k : kind->second) {
      known = known || k == key;
      expected += (expected.empty() ? "" : ", ") + k;
    }
    if (!known) {
      throw InputError("phase." + key + ": unknown parameter for " + name + " (expected " +
                       expected + ")");
    }
    if (values.count(key)) throw InputError("phase." + key + ": given more than once");
    values[key] = parseNumber(key, item.substr(eq + 1));
    pos = comma + 1;
    if (comma + 1 == params.size()) {
      throw InputError("phase: trailing ',' in '" + text + "'");
    }
  }
  if (name == "isotropic") {
    spec.type = PhaseSpec::Type::kIsotropic;
  } else if (name == "hg") {
    spec.type = PhaseSpec::Type::kHenyeyGreenstein;
    if (!values.count("g")) throw InputError("phase.g: required for hg (e.g. hg:g=0.75)");
    spec.g = values["g"];
  } else if (name == "mie_approx") {
    spec.type = PhaseSpec::Type::kMieApprox;
    if (values.count("d")) spec.diameter_um = values["d"];
  } else {
    spec.type = PhaseSpec::Type::kMie;
    if (values.count("reff")) spec.effective_radius_um = values["reff"];
    if (values.count("veff")) spec.effective_variance = values["veff"];
  }
  if (values.count("ratio")) spec.mie_ratio = values["ratio"];
  return spec;
}

}  // namespace cloudbake
