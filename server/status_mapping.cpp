#include "server/status_mapping.h"

#include <spdlog/spdlog.h>

#include "common/exit_codes.h"
#include "common/grpc_status.h"
#include "common/printable.h"

namespace cloudbake::server {
namespace {

// Messages go back to clients verbatim: keep them to one readable size.
std::string clip(const std::string& message) {
  constexpr size_t kMax = 2000;
  return message.size() <= kMax ? message : message.substr(0, kMax) + "...";
}

// The names clients see, for log lines an operator can grep next to client reports.
const char* codeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::INVALID_ARGUMENT:
      return "INVALID_ARGUMENT";
    case grpc::StatusCode::NOT_FOUND:
      return "NOT_FOUND";
    case grpc::StatusCode::UNAVAILABLE:
      return "UNAVAILABLE";
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::FAILED_PRECONDITION:
      return "FAILED_PRECONDITION";
    default:
      return "ERROR";
  }
}

}  // namespace

grpc::Status statusFromException(std::exception_ptr error, const char* rpc) {
  ClassifiedError e = classifyException(error);
  // Messages may quote a shot's bytes: escaped, so the status is never dropped for not being
  // UTF-8 (invalid UTF-8 in a shot used to reach the client as an empty message) and the log
  // line never split.
  e.message = printable(e.message);
  const grpc::StatusCode code = statusCodeFor(e.kind);
  switch (e.kind) {
    case ErrorKind::kCancelled:
      break;  // the client asked for it
    case ErrorKind::kResourceExhausted:
      // A warning: the server is too small for its load.
      spdlog::warn("{}: {}: {}", rpc, codeName(code), e.message);
      break;
    case ErrorKind::kBadInput:
    case ErrorKind::kNotFound:
    case ErrorKind::kUnavailable:
    case ErrorKind::kFailedPrecondition:
      spdlog::info("{}: {}: {}", rpc, codeName(code), e.message);
      break;
    case ErrorKind::kInternal:
      // The details may name server-side paths and state: they stay in the log.
      spdlog::error("{}: internal error: {}", rpc, e.message);
      return {grpc::StatusCode::INTERNAL, "internal server error (details in the server log)"};
  }
  return {code, clip(e.message)};
}

}  // namespace cloudbake::server
