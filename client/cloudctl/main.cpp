// cloudctl: command-line client of cloudbake-server. Usage: cloudctl [--server HOST:PORT] COMMAND.
#include <grpcpp/grpcpp.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdlib>
#include <iostream>

#include "cloudbake/v1/bake_service.grpc.pb.h"
#include "tools/cloudbake/commands.h"

namespace {

using cloudbake::tool::ExitCode;

int exitCodeFor(const grpc::Status& s) {
  switch (s.error_code()) {
    case grpc::StatusCode::OK: return ExitCode::kOk;
    case grpc::StatusCode::INVALID_ARGUMENT: return ExitCode::kBadInput;
    case grpc::StatusCode::NOT_FOUND: return ExitCode::kNotFound;
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED: return ExitCode::kUnavailable;
    case grpc::StatusCode::CANCELLED: return ExitCode::kCancelled;
    default: return ExitCode::kFailure;
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"cloudctl: client of cloudbake-server"};
  const char* env_server = std::getenv("CLOUDBAKE_SERVER");
  std::string server = env_server && *env_server ? env_server : "127.0.0.1:50051";
  double timeout_s = 10;
  bool json = false;
  app.add_option("--server", server, "HOST:PORT of cloudbake-server (env CLOUDBAKE_SERVER)");
  app.add_option("--timeout", timeout_s, "deadline in seconds for short calls")->check(
      CLI::PositiveNumber);
  app.add_flag("--json", json, "machine-readable output on stdout");
  app.set_version_flag("--version", std::string("cloudctl ") + CLOUDBAKE_VERSION);
  app.require_subcommand(1);
  auto* health = app.add_subcommand("health", "check that the server is serving");
  auto* info = app.add_subcommand("info", "print the server's version and bake methods");
  CLI11_PARSE(app, argc, argv);

  auto channel = grpc::CreateChannel(server, grpc::InsecureChannelCredentials());
  auto deadline = std::chrono::system_clock::now() +
                  std::chrono::milliseconds(static_cast<long>(timeout_s * 1000));
  if (health->parsed() || info->parsed()) {
    auto stub = cloudbake::v1::BakeService::NewStub(channel);
    grpc::ClientContext ctx;
    ctx.set_deadline(deadline);
    cloudbake::v1::ServerInfo reply;
    const grpc::Status s = stub->GetServerInfo(&ctx, {}, &reply);
    if (!s.ok()) {
      std::cerr << "cloudctl: " << server << ": " << s.error_message() << "\n";
      return exitCodeFor(s);
    }
    if (json) {
      std::cout << "{\"server\":\"" << server << "\",\"serving\":true,\"version\":\""
                << reply.version() << "\"}\n";
    } else if (health->parsed()) {
      std::cout << server << ": SERVING (cloudbake " << reply.version() << ")\n";
    } else {
      std::cout << "version: " << reply.version() << "\nworker threads: "
                << reply.worker_threads() << "\nmethods:";
      for (const auto& m : reply.methods()) std::cout << " " << m;
      std::cout << "\n";
    }
  }
  return ExitCode::kOk;
}
