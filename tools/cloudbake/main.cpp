// Entry point of the `cloudbake` tool: parses the command line and dispatches to a subcommand.
#include <CLI/CLI.hpp>
#include <iostream>

#include "core/error.h"
#include "tools/cloudbake/commands.h"

int main(int argc, char** argv) {
  using namespace cloudbake::tool;
  CLI::App app{"cloudbake: bake light scattering through clouds (in-process tool)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("cloudbake ") + CLOUDBAKE_VERSION);
  int exit_code = kOk;
  addMieCommand(app, &exit_code);
  addPhaseCommand(app, &exit_code);
  addRenderCommand(app, &exit_code);
  addCompareCommand(app, &exit_code);
  addBakeSliceCommand(app, &exit_code);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kOk : kBadInput;
  } catch (const cloudbake::InputError& e) {
    std::cerr << "cloudbake: error: " << e.what() << "\n";
    return kBadInput;
  } catch (const std::exception& e) {
    std::cerr << "cloudbake: internal error: " << e.what() << "\n";
    return kFailure;
  }
  return exit_code;
}
