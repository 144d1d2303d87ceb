// Internal to core/shot: strict, path-aware reading of JSON values. Every error names the JSON
// pointer (RFC 6901) of the offending value, so a user can find it in a long shot file.
#pragma once

#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/math/vec3.h"

namespace cloudbake::shotjson {

/// World coordinates the shot may hold (camera positions, the centres of analytic volumes):
/// far beyond any scene's scale, and small enough that distances between points stay finite
/// and keep their digits.
constexpr double kMaxCoordinate = 1e15;
/// An analytic volume's centre lies within this many times its size of the origin: beyond,
/// the lattices' voxels lose their precision in world coordinates (a sphere of radius 1 at 1e40
/// had a zero extent along x).
constexpr double kMaxOffsetOverSize = 1e6;

using Json = nlohmann::json;

/// Escapes one reference token of a JSON pointer ("~" -> "~0", "/" -> "~1").
std::string escapePointerToken(const std::string& token);

/// Parses JSON text, rejecting duplicate object keys (which nlohmann would silently collapse).
/// Errors are "<source>: <pointer>: message".
Json parseStrict(const std::string& text, const std::string& source);

/// How files named by the document are resolved and checked.
struct PathPolicy {
  std::filesystem::path base_dir;                    ///< absolute
  std::vector<std::filesystem::path> allowed_roots;  ///< canonical; empty: anything
  bool check_exists = true;
};

/// Reading context: error prefix and path policy.
class Reader {
 public:
  Reader(std::string source, PathPolicy policy);

  [[noreturn]] void fail(const std::string& pointer, const std::string& message) const;
  [[noreturn]] void failMissingFile(const std::string& pointer, const std::string& message) const;

  double number(const Json& v, const std::string& ptr) const;  ///< finite number
  /// Finite number in [lo, hi]; `open_lo`/`open_hi` exclude the bound.
  double numberIn(const Json& v, const std::string& ptr, double lo, double hi, bool open_lo = false,
                  bool open_hi = false) const;
  int64_t integer(const Json& v, const std::string& ptr, int64_t lo, int64_t hi) const;
  uint64_t unsignedInteger(const Json& v, const std::string& ptr) const;
  bool boolean(const Json& v, const std::string& ptr) const;
  std::string string(const Json& v, const std::string& ptr) const;
  Vec3 vec3(const Json& v, const std::string& ptr) const;  ///< [x, y, z], finite
  /// A point in world units: vec3 with every coordinate within +-kMaxCoordinate.
  Vec3 point(const Json& v, const std::string& ptr) const;
  /// RGB triple with each channel in [lo, hi]; a single number when `allow_scalar`.
  Rgb rgb(const Json& v, const std::string& ptr, double lo, double hi,
          bool allow_scalar = false) const;
  /// A file path: resolved against base_dir, canonicalised, checked against the allowed roots
  /// and (optionally) for existence. Returns the absolute path.
  std::string filePath(const Json& v, const std::string& ptr) const;

  const std::string& source() const { return source_; }

 private:
  std::string source_;
  PathPolicy policy_;
};

/// A JSON object being read: checks its keys against an allowed set and gives child pointers.
class Object {
 public:
  /// Fails unless `v` is an object. With `allowed` non-empty, fails on the first key not in it.
  Object(const Reader& reader, const Json& v, std::string ptr,
         std::initializer_list<const char*> allowed = {});

  /// Fails on the first key not in `allowed` (for objects whose keys depend on a type field).
  void allowOnly(std::initializer_list<const char*> allowed, const std::string& context = "") const;
  void allowOnly(const std::vector<std::string>& allowed, const std::string& context = "") const;

  bool has(const char* key) const { return value_.contains(key); }
  const Json* find(const char* key) const;
  const Json& required(const char* key) const;  ///< fails "<ptr>/<key>: missing (required)"
  std::string path(const std::string& key) const { return ptr_ + "/" + escapePointerToken(key); }
  const std::string& ptr() const { return ptr_; }
  const Json& json() const { return value_; }
  const Reader& reader() const { return reader_; }

 private:
  const Reader& reader_;
  const Json& value_;
  std::string ptr_;
};

/// Human-readable type of a JSON value ("object", "array", "string", "number", ...).
std::string typeName(const Json& v);

}  // namespace cloudbake::shotjson
