// A bake method's quality knobs: the table each method declares (key, type, range, default,
// units, doc) and the validated values a shot carries. The shot parser checks a shot's `bake`
// keys against the table; docs/shot-format.md and docs/shot.schema.json are generated from it
// and tested against it; a method reads its typed options from the values.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace cloudbake {

/// One value of a knob; monostate: not set (a knob without a fixed default that the shot omits).
using KnobValue = std::variant<std::monostate, int64_t, double, bool, std::string>;

/// One entry of a method's knob table.
struct Knob {
  enum class Type { kInteger, kNumber, kBoolean, kChoice };

  std::string key;
  Type type = Type::kNumber;
  double min = 0, max = 0;           ///< kInteger, kNumber: the closed range (but see below)
  bool exclusive_min = false;        ///< kNumber: `min` itself is not allowed
  bool exclusive_max = false;        ///< kNumber: `max` itself is not allowed
  std::vector<std::string> choices;  ///< kChoice: the allowed strings
  KnobValue default_value;           ///< monostate: no fixed default; `default_doc` says what
  std::string default_doc;           ///< the default in words where it is derived
  bool required = false;
  std::string units;  ///< "world units", "" for counts and flags
  std::string doc;    ///< one sentence for docs/shot-format.md
  /// The knob changes how views are rendered from a bake, not the bake: it is left out of the
  /// bake's cache key.
  bool view_only = false;

  // Builders, so tables read as one line per knob.
  static Knob integer(std::string key, int64_t lo, int64_t hi, std::optional<int64_t> def,
                      std::string doc);
  static Knob number(std::string key, double lo, double hi, std::optional<double> def,
                     std::string units, std::string doc, bool exclusive_min = true);
  static Knob boolean(std::string key, bool def, std::string doc);
  static Knob choice(std::string key, std::vector<std::string> choices, std::string def,
                     std::string doc);
  Knob& derivedDefault(std::string words);
  Knob& isRequired();
  Knob& viewOnly();
  Knob& exclusiveMax();
  Knob& withUnits(std::string u);
};

/// The validated knobs of one shot: the values the shot sets, over the fixed defaults of the
/// method's table. Typed getters throw InternalError on a key the method did not declare or a
/// type it did not declare, since that is a bug in the method, not bad input.
class KnobValues {
 public:
  KnobValues() = default;
  /// No knob set yet: getters return the table's fixed defaults.
  explicit KnobValues(const std::vector<Knob>& table);

  void set(const std::string& key, KnobValue value) { set_[key] = std::move(value); }
  /// True when the shot sets the knob (not when only its default exists).
  bool has(const std::string& key) const { return set_.count(key) > 0; }

  int64_t integer(const std::string& key) const;
  double number(const std::string& key) const;
  bool boolean(const std::string& key) const;
  const std::string& choice(const std::string& key) const;
  /// The value the shot sets, else the fixed default, else nullopt (a derived default).
  std::optional<int64_t> optionalInteger(const std::string& key) const;
  std::optional<double> optionalNumber(const std::string& key) const;

  /// What the shot sets, sorted by key: its canonical form.
  const std::map<std::string, KnobValue>& explicitValues() const { return set_; }
  /// Every value a getter returns: what the shot sets over the defaults, sorted by key.
  std::map<std::string, KnobValue> resolved() const;

  bool operator==(const KnobValues& o) const { return set_ == o.set_ && defaults_ == o.defaults_; }

 private:
  const KnobValue* find(const std::string& key) const;
  const KnobValue& at(const std::string& key) const;
  std::map<std::string, KnobValue> set_, defaults_;
};

/// The knobs of a shot that sets none: KnobValues(table).
inline KnobValues defaultKnobValues(const std::vector<Knob>& table) { return KnobValues(table); }

/// The knob's range and type in the words of docs/shot-format.md ("integer 8..1024",
/// "number (0, 1]", "`normalized`, `paper`", "boolean").
std::string knobTypeDoc(const Knob& knob);

/// The knob's default in the words of docs/shot-format.md ("65536", "true", "required", or
/// default_doc).
std::string knobDefaultDoc(const Knob& knob);

/// A value as it appears in docs and messages: shortest round-trip form for numbers.
std::string knobValueText(const KnobValue& value);

}  // namespace cloudbake
