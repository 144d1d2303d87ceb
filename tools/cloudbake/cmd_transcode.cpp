// `cloudbake transcode-vdb IN OUT`: a user's VDB file rewritten by cloudbake (no blosc or zip
// blocks), as the server's child reader does before a run reads it (core/job/vdb_gate.h). A crash
// inside OpenVDB on a corrupt file ends this process only.
#include <sys/resource.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/volume/vdb_transcode.h"
#include "tools/cloudbake/commands.h"

namespace cloudbake::tool {

std::vector<std::string> vdbReaderCommand() {
  std::error_code ec;
  const std::string self = std::filesystem::read_symlink("/proc/self/exe", ec).string();
  if (ec || self.empty()) return {};  // no /proc: read in-process
  return {self, "transcode-vdb"};
}

void addTranscodeCommand(CLI::App& app, int* exit_code) {
  struct Options {
    std::string in, out;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("transcode-vdb",
                                     "Read every grid of an OpenVDB file and write them again "
                                     "without blosc or zip blocks (what a server "
                                     "does in a child process before it reads a user's file)");
  cmd->add_option("in", opt->in, "the .vdb file to read")->required();
  cmd->add_option("out", opt->out, "the .vdb file to write (through OUT.tmp and a rename)")
      ->required();
  cmd->callback([opt, exit_code] {
    const rlimit no_core{0, 0};
    setrlimit(RLIMIT_CORE, &no_core);  // a crash on a corrupt file leaves no core file
    transcodeVdb(opt->in, opt->out);
    std::printf("%s\n", opt->out.c_str());
    *exit_code = kOk;
  });
}

}  // namespace cloudbake::tool
