// Exit codes of cloudbake, cloudctl and cloudbake-server (docs/cli.md) and the one
// classification of our exceptions behind them, which the service's gRPC statuses share
// (common/grpc_status.h), so a failure reads the same whichever program reports it.
#pragma once

#include <exception>
#include <new>
#include <string>

#include "core/error.h"
// For MissingFileError only, until it moves to core/error.h.

namespace cloudbake {

/// Process exit codes (docs/cli.md).
enum ExitCode : int {
  kOk = 0,
  kFailure = 1,      ///< internal error
  kBadInput = 2,     ///< invalid shot, asset or argument
  kNotFound = 3,     ///< a file or job does not exist
  kUnavailable = 4,  ///< server unreachable or busy: retry later
  kJobFailed = 5,
  kCancelled = 6,
};

/// What went wrong, whoever reports it.
enum class ErrorKind {
  kBadInput,            ///< InputError
  kNotFound,            ///< MissingFileError, NotFoundError
  kUnavailable,         ///< the server cannot be reached (no exception of ours)
  kResourceExhausted,   ///< ResourceExhaustedError
  kFailedPrecondition,  ///< FailedPreconditionError
  kCancelled,           ///< Cancelled
  kInternal,            ///< InternalError and anything else: a bug, never the user's input
};

struct ClassifiedError {
  ErrorKind kind;
  std::string message;  ///< what(); "unknown exception" for a non-std::exception
};

/// Classifies a caught exception (std::current_exception() in a catch block).
inline ClassifiedError classifyException(std::exception_ptr error) {
  try {
    std::rethrow_exception(error);
  } catch (const MissingFileError& e) {  // before InputError, which it derives from
    return {ErrorKind::kNotFound, e.what()};
  } catch (const InputError& e) {
    return {ErrorKind::kBadInput, e.what()};
  } catch (const NotFoundError& e) {
    return {ErrorKind::kNotFound, e.what()};
  } catch (const ResourceExhaustedError& e) {
    return {ErrorKind::kResourceExhausted, e.what()};
  } catch (const FailedPreconditionError& e) {
    return {ErrorKind::kFailedPrecondition, e.what()};
  } catch (const Cancelled& e) {
    return {ErrorKind::kCancelled, e.what()};
  } catch (const std::bad_alloc&) {
    // Not a bug but a machine too small for the work (the limits are checked before a run, as
    // an upper bound; other processes hold memory too): retry with less or elsewhere.
    return {ErrorKind::kResourceExhausted,
            "out of memory: the work needs more memory than is free (lower the shot's "
            "resolutions, photons or orders, or run it on a larger machine)"};
  } catch (const std::exception& e) {
    return {ErrorKind::kInternal, e.what()};
  } catch (...) {
    return {ErrorKind::kInternal, "unknown exception"};
  }
}

inline ExitCode exitCodeFor(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::kBadInput:
      return kBadInput;
    case ErrorKind::kNotFound:
      return kNotFound;
    case ErrorKind::kUnavailable:
    case ErrorKind::kResourceExhausted:
      return kUnavailable;
    case ErrorKind::kFailedPrecondition:
      return kJobFailed;
    case ErrorKind::kCancelled:
      return kCancelled;
    case ErrorKind::kInternal:
      break;
  }
  return kFailure;
}

}  // namespace cloudbake
