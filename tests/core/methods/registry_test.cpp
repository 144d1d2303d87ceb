// The method registry: every method is well described, its knob table is consistent, its
// version is in every cache key of what it computes, and the docs agree with it.
#include "core/methods/registry.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include "core/job/cache_key.h"
#include "core/methods/method_docs.h"
#include "core/shot/shot_parser.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;
using Json = nlohmann::json;

std::string readText(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(MethodRegistry, EveryMethodIsDescribedAndFoundByName) {
  std::set<std::string> names;
  for (const BakeMethod* m : bakeMethods()) {
    const MethodInfo& i = m->info();
    SCOPED_TRACE(i.name);
    EXPECT_TRUE(names.insert(i.name).second) << "duplicate name";
    EXPECT_EQ(findMethod(i.name), m);
    EXPECT_FALSE(i.summary.empty());
    EXPECT_GE(i.version, 1);
    EXPECT_GE(i.default_samples, 1);
    // Cited by author and year, never by an internal seed number.
    if (i.runnable) {
      EXPECT_TRUE(std::regex_search(i.citation, std::regex("\\b(19|20)[0-9][0-9]\\b")))
          << i.citation;
    }
    EXPECT_EQ(i.summary.find("seed 0"), std::string::npos);
    EXPECT_EQ(i.citation.find("seed 0"), std::string::npos);
  }
  EXPECT_EQ(findMethod("nonesuch"), nullptr);
  EXPECT_EQ(methodNames(true), (std::vector<std::string>{"pathtrace", "single", "pointcloud",
                                                         "precomputed", "photon", "auto"}));
}

TEST(MethodRegistry, KnobTablesAreConsistent) {
  std::map<std::string, const Knob*> first;  // a key shared by methods has one type and range
  for (const BakeMethod* m : bakeMethods()) {
    std::set<std::string> keys;
    for (const Knob& k : m->info().knobs) {
      SCOPED_TRACE(m->info().name + "/" + k.key);
      EXPECT_TRUE(keys.insert(k.key).second) << "duplicate knob";
      EXPECT_NE(k.key, "method");
      EXPECT_NE(k.key, "samples");
      EXPECT_NE(k.key, "seed");
      EXPECT_FALSE(k.doc.empty());
      if (k.type == Knob::Type::kInteger || k.type == Knob::Type::kNumber) {
        EXPECT_LT(k.min, k.max);
      }
      const bool has_default = !std::holds_alternative<std::monostate>(k.default_value);
      EXPECT_TRUE(has_default || k.required || !k.default_doc.empty())
          << "a knob without a fixed default says what it is";
      if (has_default) {
        // The default lies in the knob's own range.
        const KnobValue& d = k.default_value;
        if (auto* i = std::get_if<int64_t>(&d)) {
          EXPECT_EQ(k.type, Knob::Type::kInteger);
          EXPECT_GE(double(*i), k.min);
          EXPECT_LE(double(*i), k.max);
        } else if (auto* x = std::get_if<double>(&d)) {
          EXPECT_EQ(k.type, Knob::Type::kNumber);
          EXPECT_TRUE(k.exclusive_min ? *x > k.min : *x >= k.min);
          EXPECT_LE(*x, k.max);
        } else if (auto* s = std::get_if<std::string>(&d)) {
          EXPECT_EQ(k.type, Knob::Type::kChoice);
          EXPECT_NE(std::find(k.choices.begin(), k.choices.end(), *s), k.choices.end());
        } else {
          EXPECT_EQ(k.type, Knob::Type::kBoolean);
        }
      }
      auto [it, inserted] = first.emplace(k.key, &k);
      if (!inserted) {
        EXPECT_EQ(int(it->second->type), int(k.type));
        EXPECT_EQ(it->second->min, k.min);
        EXPECT_EQ(it->second->max, k.max);
      }
    }
  }
}

std::string shotOf(const std::string& method, const std::string& knobs = "") {
  return R"({"version": 1, "name": "k",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 2, "albedo": 0.9, "phase": {"type": "hg", "g": 0.5}},
    "lighting": {"sun": {"direction": [0, 0, 1], "irradiance": [1, 1, 1]}},
    "bake": {"method": ")" +
         method + "\"" + knobs + R"(},
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 0],
               "look_at": [0, 0, 0], "width": 2.5}, "resolution": [8, 8]}]})";
}

// A server with an old --cache-dir must never serve results of other code: every key of what a
// method computes carries its name, its algorithm version and the shared pieces' versions.
TEST(MethodRegistry, AlgorithmVersionsAreInEveryKeyOfWhatAMethodComputes) {
  for (const char* name : {"pathtrace", "single", "pointcloud", "precomputed"}) {
    SCOPED_TRACE(name);
    const ShotSpec shot = parseShot(shotOf(name), "");
    const ShotCacheKeys keys = computeCacheKeys(shot);
    const std::string salt = algorithmSalt(findMethod(name)->info());
    EXPECT_NE(salt.find(std::string(name) + "/" + std::to_string(findMethod(name)->info().version)),
              std::string::npos);
    EXPECT_NE(salt.find("render_from_bake/"), std::string::npos);
    EXPECT_NE(keys.bake_material.find(salt), std::string::npos);
    if (std::string(name) == "single" || std::string(name) == "pointcloud") {
      EXPECT_NE(keys.light_material.find(salt), std::string::npos);
      EXPECT_EQ(keys.light, lightKeyAt(keys, shot.lighting.sun.direction));
    }
    if (std::string(name) == "precomputed") {
      EXPECT_FALSE(keys.precompute.empty());
    }
    EXPECT_EQ(keys.views[0], viewKeyAt(keys, 0, shot.lighting.sun.direction));
  }
  // Two methods never share a light key, even with the same knobs.
  EXPECT_NE(computeCacheKeys(parseShot(shotOf("single"), "")).bake,
            computeCacheKeys(parseShot(shotOf("pointcloud"), "")).bake);
}

TEST(MethodRegistry, ADefaultKnobGivesTheSameKeysAsSettingItToItsDefault) {
  const ShotCacheKeys a = computeCacheKeys(parseShot(shotOf("pointcloud"), ""));
  const ShotCacheKeys b =
      computeCacheKeys(parseShot(shotOf("pointcloud", R"(, "points": 65536)"), ""));
  const ShotCacheKeys c =
      computeCacheKeys(parseShot(shotOf("pointcloud", R"(, "points": 4096)"), ""));
  EXPECT_EQ(a.light, b.light);
  EXPECT_NE(a.light, c.light);
  // A view-only knob leaves the bake alone.
  const ShotCacheKeys d =
      computeCacheKeys(parseShot(shotOf("pointcloud", R"(, "step": 0.01)"), ""));
  EXPECT_EQ(a.light, d.light);
}

// Photon bakes a uniform sky per unit radiance, so any colour of it reuses the bake; a
// gradient or map sky is baked by its shape, so another shape is another bake.
TEST(MethodRegistry, PhotonsLightKeyHoldsTheSkysShapeOnlyWhenItHasOne) {
  auto keyWith = [](const std::string& sky) {
    std::string text = shotOf("photon");
    const std::string sun = R"("irradiance": [1, 1, 1]})";
    text.replace(text.find(sun), sun.size(), sun + ", \"sky\": " + sky);
    return computeCacheKeys(parseShot(text, "")).light;
  };
  EXPECT_EQ(keyWith(R"({"radiance": [0.1, 0.2, 0.3]})"), keyWith(R"({"radiance": [1, 1, 1]})"));
  const std::string g1 = R"({"zenith": [0.1, 0.2, 0.4], "horizon": [0.3, 0.3, 0.3]})";
  const std::string g2 = R"({"zenith": [0.4, 0.2, 0.1], "horizon": [0.3, 0.3, 0.3]})";
  EXPECT_EQ(keyWith(g1), keyWith(g1));
  EXPECT_NE(keyWith(g1), keyWith(g2));
  EXPECT_NE(keyWith(g1), keyWith(R"({"radiance": [1, 1, 1]})"));
}

// A black sun's photon bake traces no sun photons, so its key differs from a lit one's; every
// lit sun's colour still shares one bake.
TEST(MethodRegistry, PhotonsLightKeySaysWhenTheSunIsBlack) {
  auto keyWith = [](const std::string& irradiance) {
    std::string text = shotOf("photon");
    const std::string sun = R"("irradiance": [1, 1, 1])";
    text.replace(text.find(sun), sun.size(), "\"irradiance\": " + irradiance);
    return computeCacheKeys(parseShot(text, "")).light;
  };
  EXPECT_EQ(keyWith("[1, 1, 1]"), keyWith("[3, 2, 1]"));
  EXPECT_EQ(keyWith("[0, 0, 0]"), keyWith("[0, 0, 0]"));
  EXPECT_NE(keyWith("[0, 0, 0]"), keyWith("[1, 1, 1]"));
}

// photon's plan names the zonal terms of the sunlight only where there is sunlight to tally.
TEST(MethodRegistry, PhotonsPlanTalliesZonalTermsOnlyUnderASun) {
  auto planOf = [](const std::string& irradiance) {
    std::string text = shotOf("photon");
    const std::string sun = R"("irradiance": [1, 1, 1]})";
    text.replace(text.find(sun), sun.size(),
                 "\"irradiance\": " + irradiance + R"(}, "sky": {"radiance": [1, 1, 1]})");
    const ShotSpec shot = parseShot(text, "");
    std::string all;
    for (const std::string& line :
         findMethod("photon")
             ->plan(shot, ShotCacheKeys{}, [](const std::string&) { return false; })
             .components) {
      all += line + "\n";
    }
    return all;
  };
  EXPECT_NE(planOf("[1, 1, 1]").find("zonal terms about the sun's axis"), std::string::npos);
  const std::string dark = planOf("[0, 0, 0]");
  EXPECT_EQ(dark.find("zonal"), std::string::npos) << dark;
  EXPECT_NE(dark.find("no sun photons (a black sun)"), std::string::npos) << dark;
}

TEST(MethodDocs, ShotFormatDocHasTheRegistrysKnobTables) {
  const std::string doc = readText(fs::path(CLOUDBAKE_SOURCE_DIR) / "docs/shot-format.md");
  ASSERT_FALSE(doc.empty());
  EXPECT_EQ(doc, replaceMarkedSection(doc, methodsMarkdown(), "docs/shot-format.md"))
      << "docs/shot-format.md's method tables differ from the registry: run "
         "`build/tools/cloudbake/cloudbake methods --update-docs .` and commit the result";
}

TEST(MethodDocs, ShotSchemaHasTheRegistrysBakeDefinition) {
  const Json schema =
      Json::parse(readText(fs::path(CLOUDBAKE_SOURCE_DIR) / "docs/shot.schema.json"));
  EXPECT_EQ(schema.at("$defs").at("bake"), bakeSchema())
      << "docs/shot.schema.json's $defs/bake differs from the registry: run "
         "`build/tools/cloudbake/cloudbake methods --update-docs .` and commit the result";
}

TEST(MethodDocs, TheDocChecksCanFail) {
  EXPECT_THROW(replaceMarkedSection("no markers here", "x", "doc"), InputError);
  const std::string doc = std::string("a ") + kMethodDocsBegin + "\nstale\n" + kMethodDocsEnd;
  EXPECT_NE(doc, replaceMarkedSection(doc, methodsMarkdown(), "doc"));
}

}  // namespace
}  // namespace cloudbake
