#include "core/methods/knob.h"

#include <cmath>
#include <cstdio>

#include "core/error.h"

namespace cloudbake {

Knob Knob::integer(std::string key, int64_t lo, int64_t hi, std::optional<int64_t> def,
                   std::string doc) {
  Knob k;
  k.key = std::move(key);
  k.type = Type::kInteger;
  k.min = double(lo);
  k.max = double(hi);
  if (def) k.default_value = *def;
  k.doc = std::move(doc);
  return k;
}

Knob Knob::number(std::string key, double lo, double hi, std::optional<double> def,
                  std::string units, std::string doc, bool exclusive_min) {
  Knob k;
  k.key = std::move(key);
  k.type = Type::kNumber;
  k.min = lo;
  k.max = hi;
  k.exclusive_min = exclusive_min;
  if (def) k.default_value = *def;
  k.units = std::move(units);
  k.doc = std::move(doc);
  return k;
}

Knob Knob::boolean(std::string key, bool def, std::string doc) {
  Knob k;
  k.key = std::move(key);
  k.type = Type::kBoolean;
  k.default_value = def;
  k.doc = std::move(doc);
  return k;
}

Knob Knob::choice(std::string key, std::vector<std::string> choices, std::string def,
                  std::string doc) {
  Knob k;
  k.key = std::move(key);
  k.type = Type::kChoice;
  k.choices = std::move(choices);
  k.default_value = std::move(def);
  k.doc = std::move(doc);
  return k;
}

Knob& Knob::derivedDefault(std::string words) {
  default_value = std::monostate{};
  default_doc = std::move(words);
  return *this;
}

Knob& Knob::isRequired() {
  required = true;
  default_value = std::monostate{};
  return *this;
}

Knob& Knob::viewOnly() {
  view_only = true;
  return *this;
}

Knob& Knob::exclusiveMax() {
  exclusive_max = true;
  return *this;
}

Knob& Knob::withUnits(std::string u) {
  units = std::move(u);
  return *this;
}

KnobValues::KnobValues(const std::vector<Knob>& table) {
  for (const Knob& k : table) {
    if (!std::holds_alternative<std::monostate>(k.default_value))
      defaults_[k.key] = k.default_value;
  }
}

const KnobValue* KnobValues::find(const std::string& key) const {
  if (auto it = set_.find(key); it != set_.end()) return &it->second;
  if (auto it = defaults_.find(key); it != defaults_.end()) return &it->second;
  return nullptr;
}

const KnobValue& KnobValues::at(const std::string& key) const {
  const KnobValue* v = find(key);
  if (!v) throw InternalError("knob '" + key + "' read but neither set nor defaulted");
  return *v;
}

int64_t KnobValues::integer(const std::string& key) const {
  const auto* v = std::get_if<int64_t>(&at(key));
  if (!v) throw InternalError("knob '" + key + "' is not an integer");
  return *v;
}

double KnobValues::number(const std::string& key) const {
  const auto* v = std::get_if<double>(&at(key));
  if (!v) throw InternalError("knob '" + key + "' is not a number");
  return *v;
}

bool KnobValues::boolean(const std::string& key) const {
  const auto* v = std::get_if<bool>(&at(key));
  if (!v) throw InternalError("knob '" + key + "' is not a boolean");
  return *v;
}

const std::string& KnobValues::choice(const std::string& key) const {
  const auto* v = std::get_if<std::string>(&at(key));
  if (!v) throw InternalError("knob '" + key + "' is not a choice");
  return *v;
}

std::optional<int64_t> KnobValues::optionalInteger(const std::string& key) const {
  if (!find(key)) return std::nullopt;
  return integer(key);
}

std::optional<double> KnobValues::optionalNumber(const std::string& key) const {
  if (!find(key)) return std::nullopt;
  return number(key);
}

std::map<std::string, KnobValue> KnobValues::resolved() const {
  std::map<std::string, KnobValue> all = defaults_;
  for (const auto& [k, v] : set_) all[k] = v;
  return all;
}

std::string knobValueText(const KnobValue& value) {
  struct Visit {
    std::string operator()(std::monostate) const { return "unset"; }
    std::string operator()(int64_t v) const { return std::to_string(v); }
    std::string operator()(bool v) const { return v ? "true" : "false"; }
    std::string operator()(const std::string& v) const { return v; }
    std::string operator()(double v) const {
      char buf[32];
      for (int digits = 6; digits <= 17; ++digits) {
        std::snprintf(buf, sizeof buf, "%.*g", digits, v);
        if (std::strtod(buf, nullptr) == v) break;
      }
      return buf;
    }
  };
  return std::visit(Visit{}, value);
}

namespace {

// Powers of two read better as 2^n in docs ("integer 64..2^24").
std::string boundText(double v, bool integer) {
  const int64_t i = int64_t(v);
  if (integer && i >= 1024 && (i & (i - 1)) == 0) {
    int n = 0;
    while ((int64_t(1) << n) < i) ++n;
    return "2^" + std::to_string(n);
  }
  return integer ? std::to_string(i) : knobValueText(KnobValue(v));
}

}  // namespace

std::string knobTypeDoc(const Knob& k) {
  switch (k.type) {
    case Knob::Type::kInteger:
      return "integer " + boundText(k.min, true) + ".." + boundText(k.max, true);
    case Knob::Type::kNumber:
      return std::string("number ") + (k.exclusive_min ? "(" : "[") + boundText(k.min, false) +
             ", " + boundText(k.max, false) + (k.exclusive_max ? ")" : "]");
    case Knob::Type::kBoolean:
      return "boolean";
    case Knob::Type::kChoice: {
      std::string s;
      for (const std::string& c : k.choices) s += (s.empty() ? "`" : ", `") + c + "`";
      return s;
    }
  }
  return "";
}

std::string knobDefaultDoc(const Knob& k) {
  if (k.required) return "required";
  if (std::holds_alternative<std::monostate>(k.default_value)) return k.default_doc;
  return knobValueText(k.default_value);
}

}  // namespace cloudbake
