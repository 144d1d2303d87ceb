// Entry point of the `cloudbake` tool: parses the command line and dispatches to a subcommand.
#include <CLI/CLI.hpp>
#include <csignal>
#include <exception>
#include <iostream>
#include <string>
#include <vector>

#include "common/cli_suggest.h"
#include "common/exit_codes.h"
#include "common/stdout_check.h"
#include "core/io/exr_io.h"
#include "tools/cloudbake/commands.h"
#include "tools/cloudbake/interrupt.h"

namespace {

// Every failure that reaches main is reported here: the exit code every program shares, and a
// word telling the user whether to fix their input ("error") or report a bug ("internal error").
int reportError(std::exception_ptr error) {
  using cloudbake::ErrorKind;
  cloudbake::ClassifiedError e = cloudbake::classifyException(error);
  // The server keeps a full disk's path to its log; here the user's own file is worth naming.
  try {
    std::rethrow_exception(error);
  } catch (const cloudbake::StorageFullError& full) {
    e.message = "no space left on the device: " + full.detail();
  } catch (...) {
  }
  // A signal's cancel says which signal, not the bare "cancelled: cancelled" it printed.
  if (e.kind == ErrorKind::kCancelled && cloudbake::tool::interruptSignal() != 0) {
    e.message = std::string("interrupted by ") +
                (cloudbake::tool::interruptSignal() == SIGINT ? "SIGINT (Ctrl-C)" : "SIGTERM") +
                "; the run's outputs were not kept";
  }
  const char* label = e.kind == ErrorKind::kInternal    ? "internal error"
                      : e.kind == ErrorKind::kCancelled ? "cancelled"
                                                        : "error";
  std::cerr << "cloudbake: " << label << ": " << e.message << "\n";
  return cloudbake::exitCodeFor(e.kind);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace cloudbake::tool;
  using cloudbake::kBadInput;
  using cloudbake::kOk;
  CLI::App app{"cloudbake: bake light scattering through clouds (in-process tool)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("cloudbake ") + CLOUDBAKE_VERSION);
  int exit_code = kOk;
  addMieCommand(app, &exit_code);
  addPhaseCommand(app, &exit_code);
  addRenderCommand(app, &exit_code);
  addFarmCommands(app, &exit_code);
  addCompareCommand(app, &exit_code);
  addPreviewCommand(app, &exit_code);
  addBakeSliceCommand(app, &exit_code);
  addMethodsCommand(app, &exit_code);
  addTranscodeCommand(app, &exit_code);

  // The commands that run a shot take SIGINT and SIGTERM (Slurm's scancel and time limit) as a
  // cancel from the start, before their options and the shot are even read: a signal there
  // killed the process (an outside probe).
  if (argc > 1 && (std::string(argv[1]) == "render" || std::string(argv[1]) == "run-task")) {
    installInterruptHandler();
  }
  try {
    // Every command that writes or reads an EXR compresses its line blocks on all cores;
    // `render` and `farm run-task` narrow this to their --threads.
    cloudbake::setExrThreads(0);
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    std::vector<std::string> commands;
    for (const CLI::App* sub : app.get_subcommands({})) commands.push_back(sub->get_name());
    const std::string typo = cloudbake::unknownCommand(argc, argv, commands, {});
    if (!typo.empty()) {
      std::cerr << "cloudbake: " << cloudbake::unknownCommandMessage(typo, commands) << "\n";
      return kBadInput;
    }
    return app.exit(e) == 0 ? kOk : kBadInput;
  } catch (...) {
    return cloudbake::checkStdout(reportError(std::current_exception()), "cloudbake");
  }
  return cloudbake::checkStdout(exit_code, "cloudbake");
}
