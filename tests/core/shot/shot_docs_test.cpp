// The shipped examples, docs/shot.schema.json and docs/shot-format.md agree with the parser.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "core/shot/shot_parser.h"
#include "tests/core/shot/shot_test_util.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;
using testing::readText;

const fs::path kRoot = CLOUDBAKE_SOURCE_DIR;

json loadSchema() { return json::parse(readText(kRoot / "docs/shot.schema.json")); }

// Follows "$ref": "#/$defs/name" within the schema.
const json& resolve(const json& schema, const json& node) {
  if (node.is_object() && node.contains("$ref")) {
    const std::string ref = node["$ref"];
    const std::string prefix = "#/$defs/";
    EXPECT_EQ(ref.rfind(prefix, 0), 0u) << ref;
    return resolve(schema, schema["$defs"].at(ref.substr(prefix.size())));
  }
  return node;
}

// Every subschema that `node` combines with (allOf/oneOf/anyOf/then branches, refs resolved).
void branches(const json& schema, const json& node, std::vector<const json*>* out) {
  const json& n = resolve(schema, node);
  if (!n.is_object()) return;
  out->push_back(&n);
  for (const char* k : {"allOf", "oneOf", "anyOf"}) {
    if (n.contains(k)) {
      for (const json& b : n[k]) branches(schema, b, out);
    }
  }
  if (n.contains("then")) branches(schema, n["then"], out);
}

// Checks that every key of `instance` is declared (with a schema other than `false`) at the
// matching place of the schema, recursively. Returns the first undeclared pointer or "".
std::string undeclaredKey(const json& schema, const json& node, const json& instance,
                          const std::string& ptr) {
  std::vector<const json*> parts;
  branches(schema, node, &parts);
  if (instance.is_object()) {
    for (auto it = instance.begin(); it != instance.end(); ++it) {
      const json* sub = nullptr;
      for (const json* p : parts) {
        if (p->contains("properties") && (*p)["properties"].contains(it.key()) &&
            !(*p)["properties"][it.key()].is_boolean()) {
          sub = &(*p)["properties"][it.key()];
        }
      }
      if (!sub) return ptr + "/" + it.key();
      const std::string bad = undeclaredKey(schema, *sub, it.value(), ptr + "/" + it.key());
      if (!bad.empty()) return bad;
    }
  } else if (instance.is_array()) {
    for (const json* p : parts) {
      if (!p->contains("items")) continue;
      for (size_t i = 0; i < instance.size(); ++i) {
        const std::string bad =
            undeclaredKey(schema, (*p)["items"], instance[i], ptr + "/" + std::to_string(i));
        if (!bad.empty()) return bad;
      }
    }
  }
  return "";
}

std::vector<fs::path> examples() {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(kRoot / "examples")) {
    if (e.path().extension() == ".json") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

TEST(ShotExamples, EveryExampleParses) {
  const auto files = examples();
  ASSERT_GE(files.size(), 4u);
  int skipped = 0;
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    try {
      const ShotSpec s = parseShotFile(f.string());
      EXPECT_FALSE(s.views.empty());
      EXPECT_EQ(s.name, f.stem().string()) << "an example's name matches its file name";
    } catch (const MissingFileError& e) {
      // Examples that use the shared assets need ../shared beside the repository.
      if (fs::exists(fs::path(CLOUDBAKE_SHARED_DIR) / "data")) {
        ADD_FAILURE() << e.what();
      } else {
        ++skipped;
      }
    } catch (const InputError& e) {
      ADD_FAILURE() << e.what();
    }
  }
  if (skipped > 0) {
    GTEST_SKIP() << skipped << " example(s) need " << CLOUDBAKE_SHARED_DIR
                 << "/data, which is absent";
  }
}

TEST(ShotExamples, SlabIsTheDesignContractExample) {
  const ShotSpec slab = parseShotFile((kRoot / "examples/slab.json").string());
  EXPECT_EQ(serializeShot(slab), serializeShot(parseShot(testing::kDesignSlab, "")));
}

TEST(ShotSchema, IsDraft2020WithTheParsersTopLevelKeys) {
  const json schema = loadSchema();
  EXPECT_EQ(schema.at("$schema"), "https://json-schema.org/draft/2020-12/schema");
  std::set<std::string> schema_keys;
  for (auto it = schema.at("properties").begin(); it != schema.at("properties").end(); ++it) {
    schema_keys.insert(it.key());
  }
  const auto keys = shotTopLevelKeys();
  EXPECT_EQ(schema_keys, std::set<std::string>(keys.begin(), keys.end()));
  EXPECT_EQ(schema.at("additionalProperties"), false);
}

TEST(ShotSchema, ClosesEveryObject) {
  const json schema = loadSchema();
  // Any subschema that declares properties of an object must also forbid undeclared ones,
  // except the if/then clauses that only narrow a closed parent.
  std::function<void(const json&, const std::string&, bool)> walk =
      [&](const json& n, const std::string& ptr, bool in_condition) {
        if (n.is_object()) {
          if (n.contains("properties") && !in_condition) {
            EXPECT_EQ(n.value("additionalProperties", json(true)), false) << ptr;
          }
          for (auto it = n.begin(); it != n.end(); ++it) {
            const bool cond =
                in_condition || it.key() == "if" || it.key() == "then" || it.key() == "not";
            walk(it.value(), ptr + "/" + it.key(), cond);
          }
        } else if (n.is_array()) {
          for (size_t i = 0; i < n.size(); ++i)
            walk(n[i], ptr + "/" + std::to_string(i), in_condition);
        }
      };
  walk(schema, "", false);
}

TEST(ShotSchema, DeclaresEveryKeyTheExamplesUse) {
  const json schema = loadSchema();
  for (const fs::path& f : examples()) {
    const json example = json::parse(readText(f));
    EXPECT_EQ(undeclaredKey(schema, schema, example, ""), "") << f;
  }
  // And the check can fail: an unknown key is reported.
  json j = json::parse(testing::kDesignSlab);
  j["medium"]["phase"]["gg"] = 1;
  EXPECT_EQ(undeclaredKey(schema, schema, j, ""), "/medium/phase/gg");
}

TEST(ShotFormatDoc, MentionsEveryKeyOfTheSchema) {
  const json schema = loadSchema();
  const std::string doc = readText(kRoot / "docs/shot-format.md");
  ASSERT_FALSE(doc.empty());
  std::set<std::string> keys;
  std::function<void(const json&)> collect = [&](const json& n) {
    if (n.is_object()) {
      if (n.contains("properties") && n["properties"].is_object()) {
        for (auto it = n["properties"].begin(); it != n["properties"].end(); ++it) {
          keys.insert(it.key());
        }
      }
      for (const auto& v : n) collect(v);
    } else if (n.is_array()) {
      for (const auto& v : n) collect(v);
    }
  };
  collect(schema);
  EXPECT_GT(keys.size(), 50u);
  for (const std::string& k : keys) {
    // Either `key` or a dotted form such as `sky.map`.
    const bool found = doc.find("`" + k + "`") != std::string::npos ||
                       doc.find("." + k + "`") != std::string::npos;
    EXPECT_TRUE(found) << "docs/shot-format.md lacks `" << k << "`";
  }
}

}  // namespace
}  // namespace cloudbake
