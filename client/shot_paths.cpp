#include "client/shot_paths.h"

#include <string>
#include <string_view>

namespace cloudbake::client {
namespace {

// `pointer` is what is left of one of kShotPathPointers below `node` ("" at the value itself),
// `at` the concrete pointer of `node`.
void collect(nlohmann::json& node, std::string_view pointer, const std::string& at,
             std::vector<ShotPath>* out) {
  if (pointer.empty()) {
    if (node.is_string()) out->push_back({at, &node});
    return;
  }
  const size_t end = pointer.find('/', 1);
  const std::string_view token = pointer.substr(1, end == std::string_view::npos ? end : end - 1);
  const std::string_view rest = end == std::string_view::npos ? "" : pointer.substr(end);
  if (token == "*") {
    if (!node.is_array()) return;
    for (size_t i = 0; i < node.size(); ++i) {
      collect(node[i], rest, at + "/" + std::to_string(i), out);
    }
  } else if (node.is_object()) {
    const auto it = node.find(std::string(token));
    if (it != node.end()) collect(*it, rest, at + "/" + std::string(token), out);
  }
}

}  // namespace

std::vector<ShotPath> shotPaths(nlohmann::json& shot) {
  std::vector<ShotPath> out;
  for (const char* pointer : kShotPathPointers) collect(shot, pointer, "", &out);
  return out;
}

std::vector<nlohmann::json*> shotPathNodes(nlohmann::json& shot) {
  std::vector<nlohmann::json*> out;
  for (const ShotPath& p : shotPaths(shot)) out.push_back(p.node);
  return out;
}

}  // namespace cloudbake::client
