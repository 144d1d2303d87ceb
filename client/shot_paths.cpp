#include "client/shot_paths.h"

#include <string>
#include <string_view>

namespace cloudbake::client {
namespace {

// `pointer` is what is left of one of kShotPathPointers below `node` ("" at the value itself).
void collect(nlohmann::json& node, std::string_view pointer, std::vector<nlohmann::json*>* out) {
  if (pointer.empty()) {
    if (node.is_string()) out->push_back(&node);
    return;
  }
  const size_t end = pointer.find('/', 1);
  const std::string_view token = pointer.substr(1, end == std::string_view::npos ? end : end - 1);
  const std::string_view rest = end == std::string_view::npos ? "" : pointer.substr(end);
  if (token == "*") {
    if (!node.is_array()) return;
    for (nlohmann::json& element : node) collect(element, rest, out);
  } else if (node.is_object()) {
    const auto it = node.find(std::string(token));
    if (it != node.end()) collect(*it, rest, out);
  }
}

}  // namespace

std::vector<nlohmann::json*> shotPathNodes(nlohmann::json& shot) {
  std::vector<nlohmann::json*> out;
  for (const char* pointer : kShotPathPointers) collect(shot, pointer, &out);
  return out;
}

}  // namespace cloudbake::client
