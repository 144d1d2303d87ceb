// Earlier files a run writes over, kept aside until the run ends. A run that fails or is
// cancelled puts them back, so a re-render into the folder of an earlier complete run leaves
// that run as it was (its frames and the animation.json that lists them agree); a run that
// succeeds deletes them.
#pragma once

#include <mutex>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace cloudbake {

class ReplacedOutputs {
 public:
  ReplacedOutputs() = default;
  ReplacedOutputs(const ReplacedOutputs&) = delete;
  ReplacedOutputs& operator=(const ReplacedOutputs&) = delete;
  /// Puts back what is still kept: a run that neither committed nor restored ended abnormally.
  ~ReplacedOutputs();

  /// Call before the run writes `path`. The first time this run writes it, moves a file already
  /// there aside, to a hidden name in the same folder (a rename: no copy). Throws
  /// std::runtime_error naming the path when the move fails.
  void keep(const std::string& path);

  /// The run failed and has removed its own files: moves every kept file back. Never throws;
  /// returns the hidden names of those that could not be put back (for the error message).
  std::vector<std::string> restore() noexcept;

  /// The run succeeded: deletes the kept files.
  void commit() noexcept;

  /// How many files are kept aside now.
  size_t kept() const;

  /// The hidden name a kept file of `path` gets: ".<name>.replaced.<unique>" beside it.
  static std::string hiddenName(const std::string& path);

 private:
  mutable std::mutex mutex_;
  std::set<std::string> seen_;
  std::vector<std::pair<std::string, std::string>> kept_;  // (path, hidden copy)
};

}  // namespace cloudbake
