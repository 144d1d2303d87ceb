// gRPC handlers of cloudbake.v1.BakeService: validate, convert, call core/job, map status.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>

#include "cloudbake/v1/bake_service.grpc.pb.h"
#include "core/job/job_manager.h"
#include "server/auth.h"

namespace cloudbake::server {

/// The handlers; the JobManager (queue, caches, store) is owned by the caller.
class BakeServiceImpl final : public cloudbake::v1::BakeService::Service {
 public:
  /// `max_streams`: streaming calls (uploads, watches, fetches) open at once; more are answered
  /// RESOURCE_EXHAUSTED, so a flood of watchers cannot take a thread each without bound.
  /// `auth`: who may call (default: anyone, anonymously); with tokens each client sees and acts
  /// on its own jobs only.
  explicit BakeServiceImpl(JobManager& jobs, size_t max_streams = 256, Authenticator auth = {})
      : jobs_(jobs), max_streams_(max_streams), auth_(std::move(auth)) {}
  using Ctx = grpc::ServerContext;
  grpc::Status GetServerInfo(Ctx*, const v1::GetServerInfoRequest*, v1::ServerInfo*) override;
  grpc::Status UploadAsset(Ctx*, grpc::ServerReader<v1::UploadAssetRequest>*,
                           v1::UploadAssetResponse*) override;
  grpc::Status SubmitJob(Ctx*, const v1::SubmitJobRequest*, v1::SubmitJobResponse*) override;
  grpc::Status WatchJob(Ctx*, const v1::WatchJobRequest*,
                        grpc::ServerWriter<v1::JobEvent>*) override;
  grpc::Status GetJob(Ctx*, const v1::GetJobRequest*, v1::Job*) override;
  grpc::Status ListJobs(Ctx*, const v1::ListJobsRequest*, v1::ListJobsResponse*) override;
  grpc::Status CancelJob(Ctx*, const v1::CancelJobRequest*, v1::Job*) override;
  grpc::Status FetchResult(Ctx*, const v1::FetchResultRequest*,
                           grpc::ServerWriter<v1::ResultChunk>*) override;
  grpc::Status RenderView(Ctx*, const v1::RenderViewRequest*, v1::SubmitJobResponse*) override;

  /// Bytes received by UploadAsset and sent by FetchResult since the server started.
  uint64_t uploadBytes() const { return upload_bytes_; }
  uint64_t fetchBytes() const { return fetch_bytes_; }
  /// Streaming calls open now.
  size_t openStreams() const { return streams_; }

 private:
  /// NotFoundError unless job `id` belongs to `caller` (any job when tokens are off).
  void checkOwner(const std::string& caller, const std::string& id) const;
  /// Holds one of the max_streams slots while a streaming call runs.
  class StreamSlot {
   public:
    explicit StreamSlot(BakeServiceImpl& service);
    ~StreamSlot() { --service_.streams_; }
    StreamSlot(const StreamSlot&) = delete;
    StreamSlot& operator=(const StreamSlot&) = delete;

   private:
    BakeServiceImpl& service_;
  };

  JobManager& jobs_;
  size_t max_streams_;
  Authenticator auth_;
  std::atomic<size_t> streams_{0};
  std::atomic<uint64_t> upload_bytes_{0}, fetch_bytes_{0};
};

}  // namespace cloudbake::server
