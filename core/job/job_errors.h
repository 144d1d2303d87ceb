// Errors of the job layer beyond InputError/Cancelled (core/error.h). The service maps each to
// one gRPC status in one place (server/status_mapping.cpp).
#pragma once

#include <stdexcept>
#include <string>

namespace cloudbake {

/// A job id or an asset hash that does not exist (gRPC NOT_FOUND).
class NotFoundError : public std::runtime_error {
 public:
  explicit NotFoundError(const std::string& what) : std::runtime_error(what) {}
};

/// The queue or another bounded resource is full; retry later (gRPC RESOURCE_EXHAUSTED).
class ResourceExhaustedError : public std::runtime_error {
 public:
  explicit ResourceExhaustedError(const std::string& what) : std::runtime_error(what) {}
};

/// The request is valid but the job is not in a state that allows it, e.g. fetching the result
/// of a job that has not succeeded (gRPC FAILED_PRECONDITION).
class FailedPreconditionError : public std::runtime_error {
 public:
  explicit FailedPreconditionError(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace cloudbake
