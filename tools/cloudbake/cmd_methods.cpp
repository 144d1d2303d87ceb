// `cloudbake methods [--json | --markdown | --schema | --update-docs REPO]`: the bake methods of
// this build, from the registry (core/methods/registry.h): names, summaries, citations, versions
// and knob tables. --update-docs rewrites the generated parts of docs/shot-format.md and
// docs/shot.schema.json in a checkout, so the docs cannot drift from the code.
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "core/error.h"
#include "core/methods/method_docs.h"
#include "core/methods/registry.h"
#include "tools/cloudbake/commands.h"

namespace cloudbake::tool {
namespace {
namespace fs = std::filesystem;
using Json = nlohmann::json;

struct MethodsOptions {
  bool json = false;
  bool markdown = false;
  bool schema = false;
  std::string update_docs;
};

std::string readAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string() + ": cannot open for reading");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void writeAll(const fs::path& path, const std::string& text) {
  const fs::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.close();
    if (!out) throw InputError(tmp.string() + ": write failed");
  }
  fs::rename(tmp, path);
}

void updateDocs(const fs::path& repo) {
  const fs::path md = repo / "docs/shot-format.md";
  writeAll(md, replaceMarkedSection(readAll(md), methodsMarkdown(), md.string()));
  const fs::path schema_path = repo / "docs/shot.schema.json";
  // Ordered, so the hand-written rest of the schema keeps its reading order.
  nlohmann::ordered_json schema = nlohmann::ordered_json::parse(readAll(schema_path));
  schema["$defs"]["bake"] = nlohmann::ordered_json::parse(bakeSchema().dump());
  writeAll(schema_path, schema.dump(2) + "\n");
  std::cout << md.string() << "\n" << schema_path.string() << "\n";
}

Json methodsJson() {
  Json all = Json::array();
  for (const BakeMethod* m : bakeMethods()) {
    const MethodInfo& i = m->info();
    Json knobs = Json::array();
    for (const Knob& k : i.knobs) {
      knobs.push_back({{"key", k.key},
                       {"type", knobTypeDoc(k)},
                       {"default", knobDefaultDoc(k)},
                       {"units", k.units},
                       {"doc", k.doc}});
    }
    all.push_back({{"name", i.name},
                   {"summary", i.summary},
                   {"citation", i.citation},
                   {"version", i.version},
                   {"runnable", i.runnable},
                   {"knobs", knobs}});
  }
  return all;
}

void printMethods(const MethodsOptions& o) {
  if (o.json) {
    std::cout << methodsJson().dump(2) << "\n";
  } else if (o.markdown) {
    std::cout << methodsMarkdown();
  } else if (o.schema) {
    std::cout << bakeSchema().dump(2) << "\n";
  } else {
    for (const BakeMethod* m : bakeMethods()) {
      const MethodInfo& i = m->info();
      std::cout << i.name << " (v" << i.version << (i.runnable ? "" : ", not runnable")
                << "): " << i.summary << "\n";
    }
  }
}

}  // namespace

void addMethodsCommand(CLI::App& app, int* exit_code) {
  auto opt = std::make_shared<MethodsOptions>();
  CLI::App* cmd = app.add_subcommand("methods", "The bake methods of this build and their knobs");
  auto* json = cmd->add_flag("--json", opt->json, "as JSON");
  auto* md = cmd->add_flag("--markdown", opt->markdown, "the knob tables of docs/shot-format.md");
  auto* schema =
      cmd->add_flag("--schema", opt->schema, "the `bake` schema of docs/shot.schema.json");
  auto* update = cmd->add_option("--update-docs", opt->update_docs,
                                 "rewrite the generated parts of REPO/docs from the registry");
  json->excludes(md)->excludes(schema)->excludes(update);
  md->excludes(schema)->excludes(update);
  schema->excludes(update);
  cmd->callback([opt, exit_code] {
    try {
      if (!opt->update_docs.empty()) {
        updateDocs(opt->update_docs);
      } else {
        printMethods(*opt);
      }
      *exit_code = kOk;
    } catch (const InputError& e) {
      std::cerr << "cloudbake: error: " << e.what() << "\n";
      *exit_code = kBadInput;
    } catch (const std::exception& e) {
      std::cerr << "cloudbake: internal error: " << e.what() << "\n";
      *exit_code = kFailure;
    }
  });
}

}  // namespace cloudbake::tool
