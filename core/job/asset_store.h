// Uploaded assets (VDBs, meshes, sky maps), content-addressed by SHA-256 so each is sent once.
#pragma once

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <utility>

#include "core/job/sha256.h"
#include "core/job/verified_files.h"

namespace cloudbake {

/// ROOT/<sha256>: one file per distinct content. Writes go through AssetWriter: a temporary
/// file hashed while written, renamed into place only when the hash matches what the client
/// declared, so a truncated or corrupted upload is never stored. Thread safe.
class AssetStore {
 public:
  AssetStore(std::string root, uint64_t max_asset_bytes);

  /// Path of asset `sha256` if it is held and its content still hashes to it (checked on first
  /// use in this process and whenever the file changed), else empty. A corrupt asset is removed
  /// and counted, so the next upload of the right bytes stores it again.
  std::string find(const std::string& sha256) const;
  /// Hashes every stored asset again, whatever its size and time say (bit rot leaves both),
  /// dropping and counting the corrupt ones. Returns {assets checked, assets dropped}.
  std::pair<size_t, size_t> scrub() const;
  /// Assets found corrupt and removed since the store was opened.
  uint64_t corruptDropped() const { return corrupt_; }

  /// Streams one upload. Throws InputError for a bad declared hash or when the data exceeds
  /// max_asset_bytes; finish() throws InputError when the hash or size does not match.
  class Writer {
   public:
    Writer(const AssetStore& store, std::string sha256, uint64_t declared_size);
    ~Writer();
    void write(const void* data, size_t size);
    /// Returns the stored path.
    std::string finish();

   private:
    const AssetStore& store_;
    std::string sha256_, tmp_;
    uint64_t declared_size_, written_ = 0;
    Sha256 hash_;
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file_;
    bool finished_ = false;
  };

  uint64_t maxAssetBytes() const { return max_asset_bytes_; }

 private:
  std::string root_;
  uint64_t max_asset_bytes_;
  mutable VerifiedFiles verified_;
  mutable std::atomic<uint64_t> corrupt_{0};
};

}  // namespace cloudbake
