// The one place where exceptions from core/ become gRPC statuses (docs/api.md, "Errors").
#pragma once

#include <grpcpp/grpcpp.h>

#include <exception>
#include <string>

namespace cloudbake::server {

/// Maps the exception being handled to a status through the classification the exit codes share
/// (common/exit_codes.h, common/grpc_status.h): InputError -> INVALID_ARGUMENT (its message,
/// which names the field), MissingFileError/NotFoundError -> NOT_FOUND,
/// ResourceExhaustedError -> RESOURCE_EXHAUSTED, FailedPreconditionError ->
/// FAILED_PRECONDITION, Cancelled -> CANCELLED; InternalError and anything else -> INTERNAL with
/// a generic message, the details going to the log only. `rpc` names the call in the log.
grpc::Status statusFromException(std::exception_ptr error, const char* rpc);

/// Runs `handler` (returning grpc::Status) and maps any exception it throws.
template <typename Fn>
grpc::Status guarded(const char* rpc, Fn&& handler) {
  try {
    return handler();
  } catch (...) {
    return statusFromException(std::current_exception(), rpc);
  }
}

}  // namespace cloudbake::server
