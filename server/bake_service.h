// gRPC handlers of cloudbake.v1.BakeService: validate, convert, call core, map status.
#pragma once

#include "cloudbake/v1/bake_service.grpc.pb.h"

namespace cloudbake::server {

/// Dependencies and settings of the service, passed in rather than read from globals.
struct BakeServiceOptions {
  unsigned worker_threads = 0;  ///< 0: one per hardware thread
};

class BakeServiceImpl final : public cloudbake::v1::BakeService::Service {
 public:
  explicit BakeServiceImpl(BakeServiceOptions options) : options_(options) {}
  grpc::Status GetServerInfo(grpc::ServerContext* context,
                             const cloudbake::v1::GetServerInfoRequest* request,
                             cloudbake::v1::ServerInfo* reply) override;

 private:
  BakeServiceOptions options_;
};

}  // namespace cloudbake::server
