// cloudctl uploads the files a shot names from one list of keys (client/shot_paths.h): it must
// be the set of properties that docs/shot.schema.json types as paths, or a new path property
// would silently not be uploaded.
#include "client/shot_paths.h"

#include <gtest/gtest.h>

#include <fstream>
#include <set>
#include <string>

namespace {
using Json = nlohmann::json;

constexpr const char* kPathRef = "#/$defs/path";

// Pointers (with "*" for array elements) of every place below `node` whose schema is kPathRef.
void pathPointers(const Json& schema, const Json& node, const std::string& pointer, int depth,
                  std::set<std::string>* out) {
  ASSERT_LT(depth, 64) << "schema recursion at " << pointer;
  if (!node.is_object()) return;  // `true`/`false` schemas name no type
  if (node.contains("$ref")) {
    const std::string ref = node["$ref"].get<std::string>();
    if (ref == kPathRef) {
      out->insert(pointer);
      return;
    }
    ASSERT_EQ(ref.rfind("#/", 0), 0u) << "unexpected $ref " << ref;
    pathPointers(schema, schema.at(Json::json_pointer(ref.substr(1))), pointer, depth + 1, out);
  }
  for (const char* alternatives : {"allOf", "anyOf", "oneOf"}) {
    if (!node.contains(alternatives)) continue;
    for (const Json& alt : node[alternatives]) pathPointers(schema, alt, pointer, depth + 1, out);
  }
  for (const char* branch : {"if", "then", "else"}) {
    if (node.contains(branch)) pathPointers(schema, node[branch], pointer, depth + 1, out);
  }
  if (node.contains("properties")) {
    for (const auto& [key, sub] : node["properties"].items()) {
      pathPointers(schema, sub, pointer + "/" + key, depth + 1, out);
    }
  }
  if (node.contains("items")) pathPointers(schema, node["items"], pointer + "/*", depth + 1, out);
}

Json readSchema() {
  std::ifstream in(std::string(CLOUDBAKE_SOURCE_DIR) + "/docs/shot.schema.json");
  EXPECT_TRUE(in) << "docs/shot.schema.json not found";
  return Json::parse(in);
}

TEST(CloudctlShotPaths, EqualTheSchemasPathProperties) {
  const Json schema = readSchema();
  ASSERT_EQ(schema.at("/$defs/path/type"_json_pointer), "string")
      << "the schema no longer marks paths with " << kPathRef;
  std::set<std::string> from_schema;
  pathPointers(schema, schema, "", 0, &from_schema);
  const std::set<std::string> listed(std::begin(cloudbake::client::kShotPathPointers),
                                     std::end(cloudbake::client::kShotPathPointers));
  EXPECT_EQ(listed, from_schema);
  EXPECT_EQ(listed.size(), std::size(cloudbake::client::kShotPathPointers)) << "duplicates";
}

TEST(CloudctlShotPaths, FindsEveryPathInListOrder) {
  Json shot = Json::parse(R"({
    "volume": {"sequence": {"paths": ["f0.vdb", 7, "f1.vdb"]}, "vdb": {"path": "a.vdb"},
               "mesh": {"path": "m.ply"}},
    "lighting": {"sky": {"map": "sky.exr"}, "sun": {"irradiance": [1, 1, 1]}},
    "name": "not/a/path.vdb"
  })");
  std::vector<std::string> got;
  for (Json* node : cloudbake::client::shotPathNodes(shot)) got.push_back(node->get<std::string>());
  EXPECT_EQ(got, (std::vector<std::string>{"a.vdb", "m.ply", "f0.vdb", "f1.vdb", "sky.exr"}));

  // With the JSON pointer of each, which cloudctl's errors name (an outside probe found them
  // naming the file alone).
  std::vector<std::string> pointers;
  for (const auto& p : cloudbake::client::shotPaths(shot)) pointers.push_back(p.pointer);
  EXPECT_EQ(pointers, (std::vector<std::string>{"/volume/vdb/path", "/volume/mesh/path",
                                                "/volume/sequence/paths/0",
                                                "/volume/sequence/paths/2", "/lighting/sky/map"}));

  // The nodes are the shot's own: a client rewrites them in place.
  *cloudbake::client::shotPathNodes(shot).front() = "outside/x/a.vdb";
  EXPECT_EQ(shot["volume"]["vdb"]["path"], "outside/x/a.vdb");
}

TEST(CloudctlShotPaths, SkipsWhatIsNotAShotOfPaths) {
  for (const char* text : {R"([1, 2])", R"("shot")", R"({"volume": []})",
                           R"({"volume": {"vdb": {"path": 3}, "sequence": {"paths": "x"}}})",
                           R"({"lighting": {"sky": "blue"}})"}) {
    Json shot = Json::parse(text);
    EXPECT_TRUE(cloudbake::client::shotPathNodes(shot).empty()) << text;
  }
}

}  // namespace
