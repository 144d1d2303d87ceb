#include "server/bake_service.h"

namespace cloudbake::server {

grpc::Status BakeServiceImpl::GetServerInfo(grpc::ServerContext* /*context*/,
                                            const cloudbake::v1::GetServerInfoRequest* /*request*/,
                                            cloudbake::v1::ServerInfo* reply) {
  reply->set_version(CLOUDBAKE_VERSION);
  reply->add_methods("pathtrace");
  reply->set_worker_threads(options_.worker_threads);
  return grpc::Status::OK;
}

}  // namespace cloudbake::server
