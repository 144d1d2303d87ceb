#include "core/volume/vdb_header_check.h"

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>

#include "core/error.h"

namespace cloudbake {
namespace {

// A little-endian reader that knows how many bytes remain and refuses to go past them.
class Bytes {
 public:
  explicit Bytes(const std::string& path) : path_(path), in_(path, std::ios::binary) {
    // Why the open failed (a file of mode 600 read by another user: "Permission denied").
    const int open_error = in_ ? 0 : errno;
    in_.seekg(0, std::ios::end);
    size_ = left_ = in_ ? static_cast<long long>(in_.tellg()) : -1;
    in_.seekg(0);
    if (left_ < 0) {
      throw InputError(path + ": cannot read the VDB file" +
                       (open_error ? std::string(": ") + std::strerror(open_error) : ""));
    }
  }
  long long position() const { return size_ - left_; }
  long long size() const { return size_; }
  void seek(long long to) {
    in_.seekg(to);
    left_ = size_ - to;
  }
  uint64_t integer(int bytes, const char* what) {
    need(bytes, what);
    unsigned char b[8] = {};
    in_.read(reinterpret_cast<char*>(b), bytes);
    uint64_t v = 0;
    for (int i = bytes - 1; i >= 0; --i) v = v << 8 | b[i];
    return v;
  }
  void skip(long long n, const char* what) {
    need(n, what);
    in_.seekg(n, std::ios::cur);
  }
  /// A length-prefixed string (uint32 length, then the characters), skipped.
  void string(const char* what) { skip(static_cast<long long>(integer(4, what)), what); }
  [[noreturn]] void fail(const std::string& why) const {
    throw InputError(path_ + ": not a readable OpenVDB file (" + why + ")");
  }
  /// Refuses `n` bytes more than the file has left, without reading them.
  void require(long long n, const char* what) const {
    if (n < 0 || n > left_) {
      fail(std::string(what) + " declares " + std::to_string(n) +
           " bytes, more than the file holds");
    }
  }
  /// The same, read, when it is at most `longest` characters (a type name); skipped otherwise.
  std::string shortString(const char* what, uint64_t longest) {
    const uint64_t n = integer(4, what);
    if (n > longest) {
      skip(static_cast<long long>(n), what);
      return {};
    }
    need(static_cast<long long>(n), what);
    std::string text(n, '\0');
    in_.read(text.data(), static_cast<std::streamsize>(n));
    return text;
  }

 private:
  void need(long long n, const char* what) {
    require(n, what);
    left_ -= n;
  }
  std::string path_;
  std::ifstream in_;
  long long size_ = 0, left_ = 0;
};

// One buffer of io::DelayedLoadMetadata's value: a uint32 byte count, then a blosc-compressed
// buffer of that many bytes (whose 16-byte header declares its uncompressed size at byte 4), or,
// where the count is 0, `count` raw entries of `entry` bytes. OpenVDB allocates each at the size
// declared before reading it; a leaf's entry is bounded by the file's own size (every leaf takes
// at least a byte of it).
void skipDelayedLoadBuffer(Bytes& b, uint64_t count, int entry, long long* left) {
  const char* what = "a delayed-load metadata buffer";
  const uint64_t bytes = b.integer(4, what);
  *left -= 4;
  if (bytes == 0xFFFFFFFFu && entry == 8) return;  // "no compressed sizes stored"
  const uint64_t raw = bytes > 0 ? bytes : count * uint64_t(entry);
  if (*left < 0 || raw > uint64_t(*left) || (bytes > 0 && bytes < 16)) {
    b.fail(std::string(what) + " declares " + std::to_string(raw) +
           " bytes, not what its metadata value holds");
  }
  if (bytes > 0) {
    b.skip(4, what);
    const uint64_t uncompressed = b.integer(4, what);
    if (uncompressed > uint64_t(entry) * uint64_t(b.size())) {
      b.fail(std::string(what) + " declares " + std::to_string(uncompressed) +
             " uncompressed bytes, more than the file's leaves can need");
    }
    b.skip(static_cast<long long>(raw) - 8, what);
  } else {
    b.skip(static_cast<long long>(raw), what);
  }
  *left -= static_cast<long long>(raw);
}

// io::DelayedLoadMetadata's value (`bytes` declared): a leaf count, the leaves' masks (a byte
// each) and their compressed sizes (8 bytes each), checked within the declared size.
void skipDelayedLoad(Bytes& b, long long bytes) {
  if (bytes == 0) return;
  long long left = bytes - 4;
  const uint64_t count = b.integer(4, "a delayed-load leaf count");
  if (left < 0 || count > uint64_t(b.size())) {
    b.fail("a delayed-load metadata value declares " + std::to_string(count) +
           " leaves, more than the file holds");
  }
  skipDelayedLoadBuffer(b, count, 1, &left);
  skipDelayedLoadBuffer(b, count, 8, &left);
  if (left > 0) b.skip(left, "a delayed-load metadata value");
}

// A MetaMap as OpenVDB writes it (count, then name, type and sized value per entry): checked
// before MetaMap::readMeta allocates each string at its declared length, and each delayed-load
// value before it allocates its buffers.
void skipMetadata(Bytes& b) {
  const uint64_t entries = b.integer(4, "the metadata count");
  for (uint64_t i = 0; i < entries; ++i) {
    b.string("a metadata name");
    const std::string type = b.shortString("a metadata type", 64);
    const auto bytes = static_cast<long long>(b.integer(4, "a metadata value"));
    if (type == "__delayedload") {
      b.require(bytes, "a metadata value");
      skipDelayedLoad(b, bytes);
    } else {
      b.skip(bytes, "a metadata value");
    }
  }
}

}  // namespace

void checkVdbHeader(const std::string& path) {
  Bytes b(path);
  if (b.integer(8, "the magic number") != 0x56444220) {
    throw InputError(path + ": not an OpenVDB file (wrong magic number)");
  }
  const uint64_t version = b.integer(4, "the file version");
  if (version < 211) return;  // older layouts are left to OpenVDB
  b.skip(8, "the library version");
  if (version >= 212) b.skip(1, "the grid-offsets flag");
  if (version >= 220 && version < 222) b.skip(1, "the compression flag");
  b.skip(version >= 218 ? 36 : 16, "the UUID");
  skipMetadata(b);
  // Each grid's descriptor: name, type, instance parent (file version 216 on), then the
  // offsets of its data and of its end, where the next descriptor starts (files written with
  // offsets, as ours and io::File's are). A file without usable offsets is checked up to its
  // first grid.
  const uint64_t grids = b.integer(4, "the grid count");
  for (uint64_t g = 0; g < grids; ++g) {
    b.string("a grid name");
    b.string("a grid type");
    if (version >= 216) b.string("a grid's instance parent name");
    b.skip(16, "a grid's data and block offsets");
    const auto end = static_cast<long long>(b.integer(8, "a grid's end offset"));
    // The grid's own metadata follows: OpenVDB's stream reader reads it from here, whatever
    // the offsets say, before the tree (after the per-grid compression flags from file
    // version 222 on).
    if (version >= 222) b.skip(4, "a grid's compression flags");
    skipMetadata(b);
    if (end <= b.position() || end > b.size()) return;
    b.seek(end);
  }
}

}  // namespace cloudbake
