// Text from outside (messages quoting a shot, upload names, paths) made safe to print and to send:
// valid UTF-8 kept, control characters and bytes that are not UTF-8 escaped, so a message is
// never dropped for bad encoding (a gRPC status is a protobuf string, which must be UTF-8) and a
// newline in a name cannot forge a log line. Header-only, beside exit_codes.h.
#pragma once

#include <cstdio>
#include <string>

namespace cloudbake {

/// The length of the valid UTF-8 sequence starting at s[i] (1-4), or 0 when it is not one.
inline size_t utf8SequenceLength(const std::string& s, size_t i) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = byte(i);
  size_t n = 0;
  unsigned min = 0;
  if (c < 0x80) return 1;
  if ((c & 0xE0) == 0xC0) n = 2, min = 0x80;
  if ((c & 0xF0) == 0xE0) n = 3, min = 0x800;
  if ((c & 0xF8) == 0xF0) n = 4, min = 0x10000;
  if (n == 0 || i + n > s.size()) return 0;
  unsigned cp = c & (0xFF >> (n + 1));
  for (size_t k = 1; k < n; ++k) {
    if ((byte(i + k) & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (byte(i + k) & 0x3F);
  }
  // Overlong forms, UTF-16 surrogates and code points beyond Unicode are not UTF-8.
  if (cp < min || (cp >= 0xD800 && cp <= 0xDFFF) || cp > 0x10FFFF) return 0;
  return n;
}

/// The offset of the first byte of `text` that is not part of valid UTF-8, or npos.
inline size_t firstInvalidUtf8(const std::string& text) {
  for (size_t i = 0; i < text.size();) {
    const size_t n = utf8SequenceLength(text, i);
    if (n == 0) return i;
    i += n;
  }
  return std::string::npos;
}

/// `text` with \n, \r, \t as such escapes and every other control character or non-UTF-8 byte
/// as \xNN.
inline std::string printable(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (size_t i = 0; i < text.size();) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    const size_t n = utf8SequenceLength(text, i);
    if (n > 1 || (n == 1 && c >= 0x20 && c != 0x7F)) {
      out.append(text, i, n);
      i += n;
      continue;
    }
    if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c == '\t') {
      out += "\\t";
    } else {
      char buf[5];
      std::snprintf(buf, sizeof buf, "\\x%02X", c);
      out += buf;
    }
    ++i;
  }
  return out;
}

}  // namespace cloudbake
