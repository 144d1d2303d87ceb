// The one classification of our exceptions (common/exit_codes.h) behind the exit codes of
// cloudbake and cloudctl and the statuses of cloudbake-server (server/status_mapping.cpp).
#include "common/exit_codes.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <new>
#include <stdexcept>
#include <string>

#include "common/grpc_status.h"
#include "server/status_mapping.h"

namespace cloudbake {
namespace {

template <typename E>
ClassifiedError classify(const E& error) {
  return classifyException(std::make_exception_ptr(error));
}

TEST(StatusExitCodes, AreTheDocumentedNumbers) {
  // docs/cli.md: scripts test these values.
  EXPECT_EQ(kOk, 0);
  EXPECT_EQ(kFailure, 1);
  EXPECT_EQ(kBadInput, 2);
  EXPECT_EQ(kNotFound, 3);
  EXPECT_EQ(kUnavailable, 4);
  EXPECT_EQ(kJobFailed, 5);
  EXPECT_EQ(kCancelled, 6);
}

TEST(StatusExitCodes, EachExceptionHasOneKindAndExitCode) {
  struct Case {
    ClassifiedError got;
    ErrorKind kind;
    ExitCode code;
  };
  const Case cases[] = {
      {classify(InputError("shot.json: /a: bad")), ErrorKind::kBadInput, kBadInput},
      {classify(MissingFileError("a.vdb: file not found")), ErrorKind::kNotFound, kNotFound},
      {classify(NotFoundError("job 'x' not found")), ErrorKind::kNotFound, kNotFound},
      {classify(ResourceExhaustedError("queue full")), ErrorKind::kResourceExhausted, kUnavailable},
      {classify(FailedPreconditionError("not done")), ErrorKind::kFailedPrecondition, kJobFailed},
      {classify(Cancelled()), ErrorKind::kCancelled, kCancelled},
      {classify(std::bad_alloc()), ErrorKind::kResourceExhausted, kUnavailable},
      {classify(InternalError("bug")), ErrorKind::kInternal, kFailure},
      {classify(std::runtime_error("other")), ErrorKind::kInternal, kFailure},
      {classify(42), ErrorKind::kInternal, kFailure},
  };
  for (const Case& c : cases) {
    EXPECT_EQ(c.got.kind, c.kind) << c.got.message;
    EXPECT_EQ(exitCodeFor(c.got.kind), c.code) << c.got.message;
  }
  EXPECT_EQ(classify(InputError("shot.json: /a: bad")).message, "shot.json: /a: bad");
  EXPECT_EQ(classify(42).message, "unknown exception");
  EXPECT_EQ(classify(std::bad_alloc()).message.rfind("out of memory: ", 0), 0u);
}

TEST(StatusExitCodes, RemoteFailuresExitLikeLocalOnes) {
  // cloudctl reads the server's status back into the kind the server mapped it from.
  for (ErrorKind kind : {ErrorKind::kBadInput, ErrorKind::kNotFound, ErrorKind::kUnavailable,
                         ErrorKind::kResourceExhausted, ErrorKind::kFailedPrecondition,
                         ErrorKind::kCancelled, ErrorKind::kInternal}) {
    EXPECT_EQ(errorKindFor(statusCodeFor(kind)), kind) << int(kind);
  }
  EXPECT_EQ(exitCodeFor(errorKindFor(grpc::StatusCode::OUT_OF_RANGE)), kBadInput);
  EXPECT_EQ(exitCodeFor(errorKindFor(grpc::StatusCode::DEADLINE_EXCEEDED)), kUnavailable);
  EXPECT_EQ(exitCodeFor(errorKindFor(grpc::StatusCode::UNIMPLEMENTED)), kFailure);
}

grpc::Status statusOf(std::exception_ptr error) {
  return server::statusFromException(error, "Test");
}

class StatusMapping : public ::testing::Test {
 protected:
  // The mapping logs every error; here that is only noise.
  void SetUp() override { spdlog::set_level(spdlog::level::off); }
  void TearDown() override { spdlog::set_level(spdlog::level::info); }
};

TEST_F(StatusMapping, ClientErrorsKeepTheirMessage) {
  const grpc::Status missing = statusOf(std::make_exception_ptr(MissingFileError("a.vdb: nope")));
  EXPECT_EQ(missing.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(missing.error_message(), "a.vdb: nope");
  EXPECT_EQ(statusOf(std::make_exception_ptr(InputError("x"))).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(statusOf(std::make_exception_ptr(ResourceExhaustedError("x"))).error_code(),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(statusOf(std::make_exception_ptr(FailedPreconditionError("x"))).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(statusOf(std::make_exception_ptr(Cancelled())).error_code(),
            grpc::StatusCode::CANCELLED);
  EXPECT_EQ(
      statusOf(std::make_exception_ptr(InputError(std::string(5000, 'x')))).error_message().size(),
      2003u);  // clipped, with "..."
}

// A message quoting a shot's bytes reaches the client readable: invalid UTF-8 and control
// characters escaped (an invalid byte made the whole message empty; a newline forged log lines).
TEST_F(StatusMapping, MessagesAreValidUtf8WithControlsEscaped) {
  const grpc::Status s =
      statusOf(std::make_exception_ptr(InputError("shot.json: /name: bad \xFF\xFE"
                                                  "byte\nforged: line \u00e9")));
  EXPECT_EQ(s.error_message(), "shot.json: /name: bad \\xFF\\xFEbyte\\nforged: line \u00e9");
}

TEST_F(StatusMapping, InternalErrorsHideTheirDetails) {
  for (const std::exception_ptr& error :
       {std::make_exception_ptr(InternalError("/srv/state/cache/ab: unreadable")),
        std::make_exception_ptr(std::runtime_error("/srv/state: boom")),
        std::make_exception_ptr(7)}) {
    const grpc::Status s = statusOf(error);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INTERNAL);
    EXPECT_EQ(s.error_message(), "internal server error (details in the server log)");
  }
}

}  // namespace
}  // namespace cloudbake
