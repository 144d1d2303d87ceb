// SHA-256 (FIPS 180-4) of byte strings and files, via OpenSSL's EVP interface.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

namespace cloudbake {

/// Incremental SHA-256: update() any number of times, then hexDigest() once (64 lowercase hex
/// characters). Used for content addressing (uploads, cache entries) and transfer checksums.
class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;
  void update(const void* data, size_t size);
  void update(const std::string& data) { update(data.data(), data.size()); }
  std::string hexDigest();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Hex SHA-256 of a byte string.
std::string sha256Hex(const std::string& data);

/// Hex SHA-256 of a file's content, read in 1 MiB blocks (constant memory). Throws InputError
/// naming `path` when it cannot be read.
std::string sha256File(const std::string& path);

/// True for a 64-character lowercase hex string (the form sha256Hex gives).
bool isSha256Hex(const std::string& text);

}  // namespace cloudbake
