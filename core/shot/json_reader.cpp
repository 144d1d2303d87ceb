#include "core/shot/json_reader.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <set>
#include <sstream>
#include <system_error>

#include "common/json_limits.h"
#include "core/format.h"
#include "core/shot/shot_parser.h"

namespace cloudbake::shotjson {
namespace fs = std::filesystem;

std::string escapePointerToken(const std::string& token) {
  std::string out;
  out.reserve(token.size());
  for (char c : token) {
    if (c == '~') {
      out += "~0";
    } else if (c == '/') {
      out += "~1";
    } else {
      out += c;
    }
  }
  return out;
}

std::string typeName(const Json& v) {
  if (v.is_boolean()) return "a boolean";
  if (v.is_number()) return "a number";
  if (v.is_string()) return "a string";
  if (v.is_array()) return "an array";
  if (v.is_object()) return "an object";
  if (v.is_null()) return "null";
  return v.type_name();
}

namespace {

// Quotes a user string for a message, cut short so a huge value cannot flood a log.
std::string quoted(const std::string& s) {
  std::string out = "'";
  for (size_t i = 0; i < s.size() && i < 64; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    out += std::isprint(c) ? static_cast<char>(c) : '?';
  }
  if (s.size() > 64) out += "...";
  return out + "'";
}

// One open object/array while parsing: where the parser is inside it.
struct Frame {
  bool object = false;
  std::string key;
  size_t index = 0;
  std::set<std::string> keys;
};

std::string pointerOf(const std::vector<Frame>& stack) {
  std::string p;
  for (const Frame& f : stack) {
    p += "/" + (f.object ? escapePointerToken(f.key) : std::to_string(f.index));
  }
  return p;
}

bool isNonFiniteSpelling(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (!s.empty() && (s[0] == '-' || s[0] == '+')) s.erase(0, 1);
  return s == "nan" || s == "inf" || s == "infinity";
}

std::string formatNumber(double v) { return exactNumber(v); }

// True when `path` (canonical) is `root` (canonical) or lies below it.
bool isWithin(const fs::path& path, const fs::path& root) {
  auto p = path.begin();
  for (auto r = root.begin(); r != root.end(); ++r, ++p) {
    if (r->empty()) continue;  // trailing separator
    if (p == path.end() || *p != *r) return false;
  }
  return true;
}

}  // namespace

Json parseStrict(const std::string& text, const std::string& source) {
  constexpr size_t kMaxDepth = 32;
  std::vector<Frame> stack;
  std::string duplicate;  // pointer of the first repeated key
  auto on_event = [&](int /*depth*/, Json::parse_event_t event, Json& parsed) {
    switch (event) {
      case Json::parse_event_t::object_start:
      case Json::parse_event_t::array_start:
        // A shot is a few levels deep; a bound keeps hostile input from costing gigabytes.
        if (stack.size() >= kMaxDepth) {
          throw InputError(source + ": " + pointerOf(stack) + ": nested deeper than " +
                           std::to_string(kMaxDepth) + " levels");
        }
        stack.push_back(Frame{event == Json::parse_event_t::object_start, {}, 0, {}});
        break;
      case Json::parse_event_t::key:
        if (!stack.empty()) {
          Frame& top = stack.back();
          top.key = parsed.get<std::string>();
          if (!top.keys.insert(top.key).second && duplicate.empty()) {
            duplicate = pointerOf(stack);
          }
        }
        break;
      case Json::parse_event_t::value:
        if (!stack.empty() && !stack.back().object) ++stack.back().index;
        break;
      case Json::parse_event_t::object_end:
      case Json::parse_event_t::array_end:
        if (!stack.empty()) stack.pop_back();
        if (!stack.empty() && !stack.back().object) ++stack.back().index;
        break;
    }
  };
  // The common parser's own depth bound sits one level deeper, so the error above, which names
  // the pointer, is the one a user sees.
  JsonLimits limits;
  limits.max_depth = kMaxDepth + 1;
  const Json doc = parseJsonLimited<Json>(text, source + ": /", limits, on_event);
  if (!duplicate.empty()) {
    throw InputError(source + ": " + duplicate + ": duplicate key (each key may appear once)");
  }
  return doc;
}

Reader::Reader(std::string source, PathPolicy policy)
    : source_(std::move(source)), policy_(std::move(policy)) {}

void Reader::fail(const std::string& pointer, const std::string& message) const {
  throw InputError(source_ + ": " + (pointer.empty() ? "/" : pointer) + ": " + message);
}

void Reader::failMissingFile(const std::string& pointer, const std::string& message) const {
  throw MissingFileError(source_ + ": " + (pointer.empty() ? "/" : pointer) + ": " + message);
}

double Reader::number(const Json& v, const std::string& ptr) const {
  if (v.is_string() && isNonFiniteSpelling(v.get<std::string>())) {
    fail(ptr, "must be a finite number; got the string " + quoted(v.get<std::string>()) +
                  " (NaN and infinity are not allowed)");
  }
  if (!v.is_number()) fail(ptr, "must be a number, got " + typeName(v));
  const double x = v.get<double>();
  if (!std::isfinite(x)) fail(ptr, "must be a finite number (value out of double range)");
  return x;
}

double Reader::numberIn(const Json& v, const std::string& ptr, double lo, double hi, bool open_lo,
                        bool open_hi) const {
  const double x = number(v, ptr);
  const bool below = open_lo ? !(x > lo) : !(x >= lo);
  const bool above = open_hi ? !(x < hi) : !(x <= hi);
  if (below || above) {
    fail(ptr, std::string("must be in ") + (open_lo ? "(" : "[") + formatNumber(lo) + ", " +
                  formatNumber(hi) + (open_hi ? ")" : "]") + ", got " + formatNumber(x));
  }
  return x;
}

int64_t Reader::integer(const Json& v, const std::string& ptr, int64_t lo, int64_t hi) const {
  const std::string range = "[" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  if (v.is_number_unsigned()) {
    const uint64_t u = v.get<uint64_t>();
    if (u > static_cast<uint64_t>(hi) || (lo > 0 && u < static_cast<uint64_t>(lo))) {
      fail(ptr, "must be an integer in " + range + ", got " + std::to_string(u));
    }
    return static_cast<int64_t>(u);
  }
  if (v.is_number_integer()) {
    const int64_t i = v.get<int64_t>();
    if (i < lo || i > hi) {
      fail(ptr, "must be an integer in " + range + ", got " + std::to_string(i));
    }
    return i;
  }
  const double x = number(v, ptr);  // rejects non-numbers and NaN spellings
  if (x != std::floor(x)) fail(ptr, "must be an integer, got " + formatNumber(x));
  if (x < static_cast<double>(lo) || x > static_cast<double>(hi)) {
    fail(ptr, "must be an integer in " + range + ", got " + formatNumber(x));
  }
  return static_cast<int64_t>(x);
}

uint64_t Reader::unsignedInteger(const Json& v, const std::string& ptr) const {
  if (v.is_number_unsigned()) return v.get<uint64_t>();
  if (v.is_number_integer()) fail(ptr, "must be a non-negative integer");
  const double x = number(v, ptr);
  if (x != std::floor(x) || x < 0 || x >= 18446744073709551616.0) {
    fail(ptr, "must be a non-negative integer below 2^64, got " + formatNumber(x));
  }
  return static_cast<uint64_t>(x);
}

bool Reader::boolean(const Json& v, const std::string& ptr) const {
  if (!v.is_boolean()) fail(ptr, "must be true or false, got " + typeName(v));
  return v.get<bool>();
}

std::string Reader::string(const Json& v, const std::string& ptr) const {
  if (!v.is_string()) fail(ptr, "must be a string, got " + typeName(v));
  return v.get<std::string>();
}

Vec3 Reader::vec3(const Json& v, const std::string& ptr) const {
  if (!v.is_array() || v.size() != 3) {
    fail(ptr, "must be an array of 3 numbers [x, y, z], got " +
                  (v.is_array() ? "an array of " + std::to_string(v.size()) : typeName(v)));
  }
  return {number(v[0], ptr + "/0"), number(v[1], ptr + "/1"), number(v[2], ptr + "/2")};
}

Vec3 Reader::point(const Json& v, const std::string& ptr) const {
  const Vec3 p = vec3(v, ptr);
  for (int a = 0; a < 3; ++a) {
    if (!(std::abs(p[a]) <= kMaxCoordinate)) {
      fail(ptr + "/" + std::to_string(a),
           "must be within +-" + exactNumber(kMaxCoordinate) + " world units, got " +
               exactNumber(p[a]) + " (distances between such points overflow or lose every digit)");
    }
  }
  return p;
}

Rgb Reader::rgb(const Json& v, const std::string& ptr, double lo, double hi,
                bool allow_scalar) const {
  if (allow_scalar && !v.is_array()) {
    const double x = numberIn(v, ptr, lo, hi);
    return {x, x, x};
  }
  if (!v.is_array() || v.size() != 3) {
    fail(ptr, std::string("must be ") + (allow_scalar ? "a number or " : "") +
                  "an RGB triple [r, g, b], got " +
                  (v.is_array() ? "an array of " + std::to_string(v.size()) : typeName(v)));
  }
  return {numberIn(v[0], ptr + "/0", lo, hi), numberIn(v[1], ptr + "/1", lo, hi),
          numberIn(v[2], ptr + "/2", lo, hi)};
}

std::string Reader::filePath(const Json& v, const std::string& ptr) const {
  const std::string text = string(v, ptr);
  if (text.empty()) fail(ptr, "must be a non-empty path");
  for (unsigned char c : text) {
    if (c < 0x20 || c == 0x7f) fail(ptr, "path must not contain control characters");
  }
  fs::path p(text);
  if (p.is_relative()) p = policy_.base_dir / p;
  std::error_code ec;
  fs::path canonical = fs::weakly_canonical(p, ec);
  if (ec) fail(ptr, "cannot resolve path " + quoted(text) + ": " + ec.message());
  if (!policy_.allowed_roots.empty()) {
    const bool ok = std::any_of(policy_.allowed_roots.begin(), policy_.allowed_roots.end(),
                                [&](const fs::path& root) { return isWithin(canonical, root); });
    if (!ok) fail(ptr, "path " + quoted(text) + " is outside the allowed folders");
  }
  if (policy_.check_exists) {
    const fs::file_status st = fs::status(canonical, ec);
    if (!fs::exists(st)) failMissingFile(ptr, "file not found: " + canonical.string());
    if (!fs::is_regular_file(st)) fail(ptr, "not a regular file: " + canonical.string());
  }
  return canonical.string();
}

Object::Object(const Reader& reader, const Json& v, std::string ptr,
               std::initializer_list<const char*> allowed)
    : reader_(reader), value_(v), ptr_(std::move(ptr)) {
  if (!v.is_object()) reader.fail(ptr_, "must be an object, got " + typeName(v));
  if (allowed.size() > 0) allowOnly(allowed);
}

void Object::allowOnly(std::initializer_list<const char*> allowed,
                       const std::string& context) const {
  allowOnly(std::vector<std::string>(allowed.begin(), allowed.end()), context);
}

void Object::allowOnly(const std::vector<std::string>& allowed, const std::string& context) const {
  for (auto it = value_.begin(); it != value_.end(); ++it) {
    const bool known = std::find(allowed.begin(), allowed.end(), it.key()) != allowed.end();
    if (known) continue;
    std::string list;
    for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
    reader_.fail(path(it.key()), "unknown key" + (context.empty() ? "" : " " + context) +
                                     " (allowed: " + list + ")");
  }
}

const Json* Object::find(const char* key) const {
  auto it = value_.find(key);
  return it == value_.end() ? nullptr : &*it;
}

const Json& Object::required(const char* key) const {
  const Json* v = find(key);
  if (!v) reader_.fail(path(key), "missing (required)");
  return *v;
}

}  // namespace cloudbake::shotjson
