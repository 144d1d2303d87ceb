// The one JSON parser entry of every program (server, tools, clients): JSON from outside (shots,
// views, irradiances sent over RPC) and our own state files alike, parsed with bounds on size
// and nesting, so hostile or corrupt text is an InputError naming what it was, never a stack
// overflow or gigabytes of memory. Header-only, beside exit_codes.h.
#pragma once

#include <algorithm>
#include <cstddef>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "core/error.h"

namespace cloudbake {

/// Bounds of parseJsonLimited. A shot is a few levels deep and a few kilobytes long.
struct JsonLimits {
  size_t max_depth = 32;                ///< nested arrays and objects
  size_t max_bytes = size_t(64) << 20;  ///< text length
};

/// Parses `text`; InputError "<what>: ..." when it is longer than max_bytes, nested deeper than
/// max_depth (found while parsing, before anything deeper is built) or not JSON. `on_event`
/// sees every event after the depth check, as nlohmann's parser callback does (for example to
/// find duplicate keys); it may be empty.
template <class Json = nlohmann::json>
Json parseJsonLimited(
    const std::string& text, const std::string& what, const JsonLimits& limits = {},
    const std::function<void(int, typename Json::parse_event_t, Json&)>& on_event = {});

/// Where in `text` the token a position-less parse error quotes ("number overflow parsing
/// '1e999'") lies, as " (key "k", line L, column C)"; empty where the message has a position or
/// quotes nothing.
inline std::string whereInJson(const std::string& text, const std::string& message,
                               const std::string& last_key) {
  if (message.find(" at line ") != std::string::npos) return "";
  const size_t open = message.find('\''), close = message.rfind('\'');
  if (open == std::string::npos || close <= open + 1) return "";
  const size_t at = text.find(message.substr(open + 1, close - open - 1));
  if (at == std::string::npos) return "";
  const size_t line_start = text.rfind('\n', at);
  const size_t line = size_t(std::count(text.begin(), text.begin() + int64_t(at), '\n')) + 1;
  const size_t column = at - (line_start == std::string::npos ? 0 : line_start + 1) + 1;
  return std::string(" (") + (last_key.empty() ? "" : "after key \"" + last_key + "\", ") +
         "line " + std::to_string(line) + ", column " + std::to_string(column) + ")";
}

template <class Json>
Json parseJsonLimited(
    const std::string& text, const std::string& what, const JsonLimits& limits,
    const std::function<void(int, typename Json::parse_event_t, Json&)>& on_event) {
  if (text.size() > limits.max_bytes) {
    throw InputError(what + ": " + std::to_string(text.size()) + " bytes of JSON, more than the " +
                     std::to_string(limits.max_bytes) + " allowed");
  }
  // nlohmann's lexer takes a NUL byte for the end of the input and would ignore what follows.
  if (const size_t nul = text.find('\0'); nul != std::string::npos) {
    throw InputError(what + ": invalid JSON: a NUL byte at offset " + std::to_string(nul));
  }
  size_t depth = 0;
  std::string last_key;  // for errors nlohmann reports without a position (number overflow)
  auto callback = [&](int level, typename Json::parse_event_t event, Json& parsed) {
    using E = typename Json::parse_event_t;
    if (event == E::key && parsed.is_string()) last_key = parsed.template get<std::string>();
    if (event == E::object_start || event == E::array_start) {
      if (++depth > limits.max_depth) {
        throw InputError(what + ": nested deeper than " + std::to_string(limits.max_depth) +
                         " levels");
      }
    } else if (event == E::object_end || event == E::array_end) {
      --depth;
    }
    if (on_event) on_event(level, event, parsed);
    return true;
  };
  try {
    return Json::parse(text, callback);
  } catch (const typename Json::exception& e) {
    std::string message = e.what();
    const size_t tag = message.find("] ");  // "[json.exception.parse_error.101] ..."
    if (message.rfind("[json.exception", 0) == 0 && tag != std::string::npos) {
      message = message.substr(tag + 2);
    }
    throw InputError(what + ": invalid JSON: " + message + whereInJson(text, message, last_key));
  }
}

}  // namespace cloudbake
