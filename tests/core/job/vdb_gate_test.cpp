// The child reader of users' VDB files (core/job/vdb_gate.h): what its exit says, and that a
// child that hangs is stopped by a cancel or the timeout. Real rewrites are tested end to end by
// ServerTest.BadInputsAreAnsweredClearlyAndTheServerKeepsServing (a file that aborts OpenVDB).
#include "core/job/vdb_gate.h"

#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "core/error.h"

namespace cloudbake {
namespace {

// A reader that runs `script` with IN as $1 and OUT as $2.
VdbReaderOptions shell(const std::string& script, double timeout = 600) {
  VdbReaderOptions o;
  o.command = {"/bin/sh", "-c", script, "reader"};
  o.timeout_seconds = timeout;
  return o;
}

std::string messageOf(const VdbReaderOptions& o) {
  try {
    rewriteVdbInChild(o, "in.vdb", "out.vdb", {});
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(VdbGate, ASuccessfulChildIsQuiet) {
  EXPECT_NO_THROW(rewriteVdbInChild(shell("test \"$1\" = in.vdb && test \"$2\" = out.vdb"),
                                    "in.vdb", "out.vdb", {}));
}

TEST(VdbGate, BadInputFromTheChildKeepsItsMessage) {
  const std::string m =
      messageOf(shell("echo 'reader: error: in.vdb: not a readable OpenVDB file' >&2; exit 2"));
  EXPECT_EQ(m, "in.vdb: not a readable OpenVDB file");
}

TEST(VdbGate, ACrashOfTheChildIsTheFilesFault) {
  const std::string m = messageOf(shell("kill -ABRT $$"));
  EXPECT_NE(m.find("in.vdb: not a readable OpenVDB file"), std::string::npos) << m;
  EXPECT_NE(m.find("signal 6"), std::string::npos) << m;
  EXPECT_NE(messageOf(shell("exit 1")).find("exit 1"), std::string::npos);
}

TEST(VdbGate, AHangingChildEndsAtTheTimeoutOrACancel) {
  auto t0 = std::chrono::steady_clock::now();
  EXPECT_NE(messageOf(shell("sleep 30", 0.3)).find("took more than"), std::string::npos);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5);
  t0 = std::chrono::steady_clock::now();
  int polls = 0;
  EXPECT_THROW(
      rewriteVdbInChild(shell("sleep 30"), "in.vdb", "out.vdb", [&] { return ++polls < 3; }),
      Cancelled);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5);
}

TEST(VdbGate, AMissingReaderIsOurFault) {
  VdbReaderOptions o;
  o.command = {"/nonexistent/cloudbake-reader"};
  EXPECT_THROW(rewriteVdbInChild(o, "in.vdb", "out.vdb", {}), InternalError);
  o.command.clear();
  EXPECT_THROW(rewriteVdbInChild(o, "in.vdb", "out.vdb", {}), InternalError);
}

}  // namespace
}  // namespace cloudbake
