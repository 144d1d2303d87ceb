#include "server/status_mapping.h"

#include <spdlog/spdlog.h>

#include "core/error.h"
#include "core/job/job_errors.h"
#include "core/shot/shot_parser.h"

namespace cloudbake::server {
namespace {

// Messages go back to clients verbatim: keep them to one readable size.
std::string clip(const std::string& message) {
  constexpr size_t kMax = 2000;
  return message.size() <= kMax ? message : message.substr(0, kMax) + "...";
}

}  // namespace

grpc::Status statusFromException(std::exception_ptr error, const char* rpc) {
  try {
    std::rethrow_exception(error);
  } catch (const MissingFileError& e) {
    spdlog::info("{}: NOT_FOUND: {}", rpc, e.what());
    return {grpc::StatusCode::NOT_FOUND, clip(e.what())};
  } catch (const InputError& e) {
    spdlog::info("{}: INVALID_ARGUMENT: {}", rpc, e.what());
    return {grpc::StatusCode::INVALID_ARGUMENT, clip(e.what())};
  } catch (const NotFoundError& e) {
    spdlog::info("{}: NOT_FOUND: {}", rpc, e.what());
    return {grpc::StatusCode::NOT_FOUND, clip(e.what())};
  } catch (const ResourceExhaustedError& e) {
    spdlog::warn("{}: RESOURCE_EXHAUSTED: {}", rpc, e.what());
    return {grpc::StatusCode::RESOURCE_EXHAUSTED, clip(e.what())};
  } catch (const FailedPreconditionError& e) {
    spdlog::info("{}: FAILED_PRECONDITION: {}", rpc, e.what());
    return {grpc::StatusCode::FAILED_PRECONDITION, clip(e.what())};
  } catch (const Cancelled& e) {
    return {grpc::StatusCode::CANCELLED, clip(e.what())};
  } catch (const std::exception& e) {
    spdlog::error("{}: internal error: {}", rpc, e.what());
  } catch (...) {
    spdlog::error("{}: internal error: unknown exception", rpc);
  }
  return {grpc::StatusCode::INTERNAL, "internal server error (details in the server log)"};
}

}  // namespace cloudbake::server
