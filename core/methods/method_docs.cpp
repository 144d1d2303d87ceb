#include "core/methods/method_docs.h"

#include <cctype>
#include <map>
#include <set>

#include "core/error.h"
#include "core/methods/registry.h"

namespace cloudbake {
namespace {
using Json = nlohmann::json;

Json valueJson(const KnobValue& v) {
  return std::visit(
      [](const auto& x) -> Json {
        if constexpr (std::is_same_v<std::decay_t<decltype(x)>, std::monostate>) {
          return nullptr;
        } else {
          return x;
        }
      },
      v);
}

// The knob's type and range, without its default (shared between methods).
Json knobTypeSchema(const Knob& k) {
  switch (k.type) {
    case Knob::Type::kInteger:
      return {{"type", "integer"}, {"minimum", int64_t(k.min)}, {"maximum", int64_t(k.max)}};
    case Knob::Type::kNumber: {
      Json j = {{"type", "number"}};
      j[k.exclusive_min ? "exclusiveMinimum" : "minimum"] = k.min;
      j[k.exclusive_max ? "exclusiveMaximum" : "maximum"] = k.max;
      return j;
    }
    case Knob::Type::kBoolean:
      return {{"type", "boolean"}};
    case Knob::Type::kChoice:
      return {{"enum", k.choices}};
  }
  return Json::object();
}

std::string cell(std::string s) {
  for (size_t i = 0; (i = s.find('|', i)) != std::string::npos; i += 2) s.replace(i, 1, "\\|");
  return s;
}

}  // namespace

std::string methodsMarkdown() {
  std::string md;
  for (const BakeMethod* m : bakeMethods()) {
    const MethodInfo& info = m->info();
    std::string summary = info.summary;
    if (!summary.empty()) summary[0] = char(std::toupper(static_cast<unsigned char>(summary[0])));
    md += "\n### `" + info.name + "`\n\n" + summary + ".";
    if (!info.citation.empty()) md += " Reference: " + info.citation + ".";
    md += " Algorithm version " + std::to_string(info.version) + "; `samples` defaults to " +
          std::to_string(info.default_samples) + (info.runnable ? "" : "; not runnable yet") +
          ".\n\n";
    if (info.knobs.empty()) continue;
    md += "| key | type | default | units | meaning |\n|---|---|---|---|---|\n";
    for (const Knob& k : info.knobs) {
      md += "| `" + k.key + "` | " + cell(knobTypeDoc(k)) + " | " + cell(knobDefaultDoc(k)) +
            " | " + cell(k.units) + " | " + cell(k.doc) + " |\n";
    }
  }
  return md + "\n";
}

Json bakeSchema() {
  Json props = {{"method", {{"enum", methodNames()}, {"default", BakeSpec{}.method}}},
                {"samples",
                 {{"type", "integer"},
                  {"minimum", 1},
                  {"maximum", 1000000},
                  {"description", "paths (pathtrace) or rays (views from a bake) per pixel"}}},
                {"seed", {{"default", 1}}}};
  props["seed"]["allOf"] = Json::array({Json{{"$ref", "#/$defs/seed"}}});
  std::set<std::string> all;
  for (const BakeMethod* m : bakeMethods()) {
    for (const Knob& k : m->info().knobs) {
      all.insert(k.key);
      if (!props.contains(k.key)) props[k.key] = knobTypeSchema(k);
    }
  }
  Json branches = Json::array();
  for (const BakeMethod* m : bakeMethods()) {
    const MethodInfo& info = m->info();
    Json own = Json::object();
    std::set<std::string> mine;
    for (const Knob& k : info.knobs) {
      Json s = knobTypeSchema(k);
      if (!std::holds_alternative<std::monostate>(k.default_value)) {
        s["default"] = valueJson(k.default_value);
      }
      s["description"] = k.doc;
      own[k.key] = s;
      mine.insert(k.key);
    }
    for (const std::string& key : all) {
      if (!mine.count(key)) own[key] = false;
    }
    Json then = {{"properties", own}};
    for (const Knob& k : info.knobs) {
      if (k.required) then["required"].push_back(k.key);
    }
    Json condition = Json::object();
    condition["properties"]["method"]["const"] = info.name;
    condition["required"] = Json::array({"method"});
    Json branch = Json::object();
    branch["if"] = condition;
    branch["then"] = then;
    branches.push_back(branch);
    if (info.name == BakeSpec{}.method) {
      // A shot without `method` is a pathtrace shot: the same knobs apply.
      Json absent = Json::object();
      absent["if"]["not"]["required"] = Json::array({"method"});
      absent["then"] = then;
      branches.push_back(absent);
    }
  }
  return {{"type", "object"},
          {"additionalProperties", false},
          {"properties", props},
          {"allOf", branches}};
}

std::string replaceMarkedSection(const std::string& doc, const std::string& section,
                                 const std::string& what) {
  const size_t b = doc.find(kMethodDocsBegin);
  const size_t e = doc.find(kMethodDocsEnd);
  if (b == std::string::npos || e == std::string::npos || e < b) {
    throw InputError(what + ": lacks the markers '" + kMethodDocsBegin + "' ... '" +
                     kMethodDocsEnd + "'");
  }
  const size_t start = b + std::string(kMethodDocsBegin).size();
  return doc.substr(0, start) + "\n" + section + doc.substr(e);
}

}  // namespace cloudbake
