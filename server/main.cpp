// cloudbake-server: serves cloudbake.v1.BakeService, the standard health service and reflection.
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdlib>
#include <thread>

#include "server/bake_service.h"

namespace {

std::string envOr(const char* name, const std::string& fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::string(v) : fallback;
}

grpc::Server* g_server = nullptr;

void onSignal(int) {
  // Shutdown() is not async-signal-safe, so hand it to a detached thread.
  if (g_server) std::thread([] { g_server->Shutdown(); }).detach();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"cloudbake-server: cloud-lighting bake service (gRPC)"};
  std::string listen = envOr("CLOUDBAKE_LISTEN", "127.0.0.1:50051");
  unsigned threads = 0;
  std::string log_level = envOr("CLOUDBAKE_LOG_LEVEL", "info");
  app.add_option("--listen", listen, "HOST:PORT to listen on (env CLOUDBAKE_LISTEN)");
  app.add_option("--threads", threads, "worker threads (0: all hardware threads)");
  app.add_option("--log-level", log_level, "trace|debug|info|warn|error (env CLOUDBAKE_LOG_LEVEL)");
  app.set_version_flag("--version", std::string("cloudbake-server ") + CLOUDBAKE_VERSION);
  CLI11_PARSE(app, argc, argv);
  spdlog::set_level(spdlog::level::from_str(log_level));
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  cloudbake::server::BakeServiceImpl service({threads});
  grpc::ServerBuilder builder;
  int bound_port = 0;
  builder.AddListeningPort(listen, grpc::InsecureServerCredentials(), &bound_port);
  builder.RegisterService(&service);
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  if (!server || bound_port == 0) {
    spdlog::error("cannot listen on {}", listen);
    return 4;
  }
  g_server = server.get();
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  // Report the bound port (useful with port 0, which lets the OS pick one).
  const std::string host = listen.substr(0, listen.rfind(':'));
  spdlog::info("cloudbake-server {} listening on {}:{} ({} worker threads)", CLOUDBAKE_VERSION,
               host, bound_port, threads);
  server->Wait();
  spdlog::info("cloudbake-server stopped");
  return 0;
}
