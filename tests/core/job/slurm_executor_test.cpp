// The Slurm executor's parts that need no cluster (core/job/slurm_executor.h): commands run
// without a shell, and bad options are clear errors naming the flag. Runs on a real Slurm are in
// tests/farm/slurm_test.sh.
#include "core/job/slurm_executor.h"

#include <gtest/gtest.h>

#include <string>

#include "core/error.h"
#include "core/job/job_manager.h"
#include "core/shot/shot_parser.h"
#include "tests/core/job/job_test_util.h"

namespace cloudbake {
namespace {

TEST(SlurmExecutor, CommandsRunWithoutAShellAndReportStatusAndOutput) {
  const CommandResult echo = runCommand({"echo", "a b", "$HOME;"});
  EXPECT_EQ(echo.status, 0);
  EXPECT_EQ(echo.output, "a b $HOME;\n");
  const CommandResult fails = runCommand({"sh", "-c", "echo oops >&2; exit 3"});
  EXPECT_EQ(fails.status, 3);
  EXPECT_EQ(fails.output, "oops\n");
  EXPECT_THROW(runCommand({"no-such-command-cloudbake"}), std::runtime_error);
}

TEST(SlurmExecutor, BadOptionsNameTheirFlag) {
  const ShotSpec shot = parseShot(R"({"version": 1, "name": "s",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1}},
    "medium": {"extinction": 1, "albedo": 0.9, "phase": {"type": "isotropic"}},
    "lighting": {"sun": {"direction": [0, 0, 1], "irradiance": [1, 1, 1]}},
    "bake": {"method": "pathtrace", "samples": 1},
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 0],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 3}, "resolution": [4, 4]}]})",
                                  "");
  RunOptions ro;
  ro.out_dir = freshDir("slurm_options").string();
  auto refused = [&](SlurmOptions so, const std::string& flag) {
    try {
      runShotOnSlurm(shot, ro, so);
      ADD_FAILURE() << "accepted: " << flag;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(flag), std::string::npos) << e.what();
    }
  };
  SlurmOptions ok;
  ok.shared_dir = ro.out_dir;
  ok.cloudbake = "cloudbake";
  refused(SlurmOptions{}, "--shared-dir");
  SlurmOptions o = ok;
  o.tasks = 0;
  refused(o, "--slurm-tasks");
  o = ok;
  o.cpus_per_task = 5000;
  refused(o, "--slurm-cpus-per-task");
  o = ok;
  o.retries = -1;
  refused(o, "--slurm-retries");
  o = ok;
  o.cloudbake.clear();
  refused(o, "--slurm-cloudbake");
}

TEST(SlurmExecutor, TheServerNeedsASharedFolderForIt) {
  JobManagerOptions o;
  o.state_dir = freshDir("slurm_manager").string();
  o.executor = "slurm";
  EXPECT_THROW(JobManager{o}, InputError);
  o.executor = "lsf";
  EXPECT_THROW(JobManager{o}, InputError);
}

}  // namespace
}  // namespace cloudbake
