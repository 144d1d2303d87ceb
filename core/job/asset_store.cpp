#include "core/job/asset_store.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <filesystem>

#include "core/error.h"
#include "core/job/file_util.h"

namespace cloudbake {
namespace fs = std::filesystem;

AssetStore::AssetStore(std::string root, uint64_t max_asset_bytes)
    : root_(std::move(root)), max_asset_bytes_(max_asset_bytes) {
  fs::create_directories(root_);
  // Leftovers of uploads interrupted by a crash.
  for (const auto& f : fs::directory_iterator(root_)) {
    if (f.path().filename().string().rfind("upload-", 0) == 0) {
      std::error_code ec;
      fs::remove(f.path(), ec);
    }
  }
}

std::string AssetStore::find(const std::string& sha256) const {
  if (!isSha256Hex(sha256)) return {};
  const fs::path p = fs::path(root_) / sha256;
  std::error_code ec;
  if (!fs::is_regular_file(p, ec)) return {};
  if (verified_.check(p.string(), sha256)) return p.string();
  // Two callers may find it corrupt at once: only the one whose removal succeeds reports it.
  if (fs::remove(p, ec)) {
    ++corrupt_;
    spdlog::warn("asset store: asset {} no longer hashes to its name; dropped (upload it again)",
                 sha256);
  }
  return {};
}

std::pair<size_t, size_t> AssetStore::scrub() const {
  size_t checked = 0;
  const uint64_t before = corrupt_;
  std::error_code ec;
  for (const auto& f : fs::directory_iterator(root_, ec)) {
    const std::string name = f.path().filename().string();
    if (!isSha256Hex(name)) continue;
    verified_.forget(f.path().string());
    find(name);
    ++checked;
  }
  return {checked, size_t(corrupt_ - before)};
}

AssetStore::Writer::Writer(const AssetStore& store, std::string sha256, uint64_t declared_size)
    : store_(store),
      sha256_(std::move(sha256)),
      declared_size_(declared_size),
      file_(nullptr, &std::fclose) {
  if (!isSha256Hex(sha256_)) {
    throw InputError("sha256: must be 64 lowercase hex digits, got '" + sha256_.substr(0, 80) +
                     "'");
  }
  if (store_.max_asset_bytes_ > 0 && declared_size_ > store_.max_asset_bytes_) {
    throw InputError("size: " + std::to_string(declared_size_) + " bytes exceeds the server's " +
                     "upload limit of " + std::to_string(store_.max_asset_bytes_) + " bytes");
  }
  tmp_ = (fs::path(store_.root_) / ("upload-" + uniqueSuffix())).string();
  // The store's folder is made again if something removed it while the server runs.
  std::error_code made;
  fs::create_directories(store_.root_, made);
  file_.reset(std::fopen(tmp_.c_str(), "wb"));
  if (!file_) {
    throwIfNoSpace(errno, "asset store: cannot create " + tmp_);
    throw std::runtime_error("asset store: cannot create " + tmp_);
  }
}

AssetStore::Writer::~Writer() {
  if (!finished_) {
    file_.reset();
    std::error_code ec;
    fs::remove(tmp_, ec);
  }
}

void AssetStore::Writer::write(const void* data, size_t size) {
  written_ += size;
  if (written_ > declared_size_) {
    throw InputError("data: more bytes than the declared size " + std::to_string(declared_size_));
  }
  hash_.update(data, size);
  if (size > 0 && std::fwrite(data, 1, size, file_.get()) != size) {
    throwIfNoSpace(errno, "asset store: write failed for " + tmp_);
    throw std::runtime_error("asset store: write failed for " + tmp_);
  }
}

std::string AssetStore::Writer::finish() {
  if (written_ != declared_size_) {
    throw InputError("data: upload truncated: got " + std::to_string(written_) + " of " +
                     std::to_string(declared_size_) + " bytes");
  }
  const std::string got = hash_.hexDigest();
  if (got != sha256_) {
    throw InputError("sha256: content hashes to " + got + ", not the declared " + sha256_);
  }
  if (std::fflush(file_.get()) != 0 || ::fsync(fileno(file_.get())) != 0 ||
      std::fclose(file_.release()) != 0) {
    throwIfNoSpace(errno, "asset store: sync failed for " + tmp_);
    throw std::runtime_error("asset store: sync failed for " + tmp_);
  }
  const fs::path dest = fs::path(store_.root_) / sha256_;
  fs::rename(tmp_, dest);
  store_.verified_.remember(dest.string());  // hashed while written
  finished_ = true;
  return dest.string();
}

}  // namespace cloudbake
