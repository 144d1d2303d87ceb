// ErrorKind (common/exit_codes.h) to gRPC status codes and back: the server answers with
// statusCodeFor, cloudctl reads a status with errorKindFor, so a remote failure exits with the
// code the same failure has in-process. Needs gRPC's headers (cloudbake-server, cloudctl).
#pragma once

#include <grpcpp/support/status_code_enum.h>

#include "common/exit_codes.h"

namespace cloudbake {

inline grpc::StatusCode statusCodeFor(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::kBadInput:
      return grpc::StatusCode::INVALID_ARGUMENT;
    case ErrorKind::kNotFound:
      return grpc::StatusCode::NOT_FOUND;
    case ErrorKind::kUnavailable:
      return grpc::StatusCode::UNAVAILABLE;
    case ErrorKind::kResourceExhausted:
      return grpc::StatusCode::RESOURCE_EXHAUSTED;
    case ErrorKind::kFailedPrecondition:
      return grpc::StatusCode::FAILED_PRECONDITION;
    case ErrorKind::kCancelled:
      return grpc::StatusCode::CANCELLED;
    case ErrorKind::kInternal:
      break;
  }
  return grpc::StatusCode::INTERNAL;
}

/// The inverse of statusCodeFor, plus the codes gRPC itself produces (a passed deadline is
/// "retry later" like an unreachable server). For a failed status only.
inline ErrorKind errorKindFor(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::OUT_OF_RANGE:
    case grpc::StatusCode::UNAUTHENTICATED:  // a missing or unknown token: the caller's to fix
    case grpc::StatusCode::PERMISSION_DENIED:
      return ErrorKind::kBadInput;
    case grpc::StatusCode::NOT_FOUND:
      return ErrorKind::kNotFound;
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return ErrorKind::kUnavailable;
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return ErrorKind::kResourceExhausted;
    case grpc::StatusCode::FAILED_PRECONDITION:
      return ErrorKind::kFailedPrecondition;
    case grpc::StatusCode::CANCELLED:
      return ErrorKind::kCancelled;
    default:
      return ErrorKind::kInternal;
  }
}

}  // namespace cloudbake
