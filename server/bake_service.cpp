#include "server/bake_service.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <vector>

#include "common/printable.h"
#include "core/error.h"
#include "core/methods/registry.h"
#include "server/convert.h"
#include "server/status_mapping.h"

namespace cloudbake::server {
namespace {
constexpr uint32_t kDefaultChunk = 256 * 1024;
constexpr uint32_t kMinChunk = 64 * 1024;
constexpr uint32_t kMaxChunk = 1024 * 1024;
// How long WatchJob waits for an event before looking at the call again: bounds how long a
// stream outlives its client's deadline or cancellation.
constexpr std::chrono::milliseconds kWatchPoll(200);

/// The status of a call its client gave up on: DEADLINE_EXCEEDED once its deadline passed here,
/// else CANCELLED (the client never sees it; it is for the log and interceptors). A client whose
/// deadline passes first cancels the call itself, so either can mean a client deadline.
grpc::Status abandoned(const grpc::ServerContext* ctx, const char* rpc) {
  const bool expired = ctx->deadline() <= std::chrono::system_clock::now();
  spdlog::debug("{}: stream stopped: the client gave up ({})", rpc,
                expired ? "deadline exceeded" : "cancelled");
  return expired ? grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED, "deadline exceeded")
                 : grpc::Status(grpc::StatusCode::CANCELLED, "cancelled by the client");
}
}  // namespace

grpc::Status BakeServiceImpl::GetServerInfo(Ctx* ctx, const v1::GetServerInfoRequest*,
                                            v1::ServerInfo* reply) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("GetServerInfo", [&] {
    const JobManagerOptions& o = jobs_.options();
    reply->set_version(CLOUDBAKE_VERSION);
    for (const std::string& m : methodNames(/*runnable_only=*/true)) reply->add_methods(m);
    reply->set_worker_threads(o.worker_threads);
    reply->set_max_concurrent_jobs(o.max_concurrent_jobs);
    reply->set_queue_bound(uint32_t(o.queue_bound));
    reply->set_max_upload_bytes(o.max_upload_bytes);
    reply->set_max_image_pixels(uint64_t(o.limits.max_image_pixels));
    reply->set_max_views(uint32_t(o.limits.max_views));
    reply->set_max_samples(uint64_t(o.limits.max_samples));
    reply->set_max_voxels(o.limits.max_voxels);
    reply->set_max_frames(uint64_t(o.limits.max_frames));
    reply->set_max_points(uint64_t(o.limits.max_points));
    toProto(jobs_.stats(), reply->mutable_stats());
    return grpc::Status::OK;
  });
}

grpc::Status BakeServiceImpl::UploadAsset(Ctx* ctx,
                                          grpc::ServerReader<v1::UploadAssetRequest>* reader,
                                          v1::UploadAssetResponse* reply) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("UploadAsset", [&] {
    const StreamSlot slot(*this);
    v1::UploadAssetRequest msg;
    if (!reader->Read(&msg)) throw InputError("upload: no messages (expected a header first)");
    if (!msg.has_header()) throw InputError("upload: the first message must be a header");
    const v1::AssetHeader header = msg.header();
    reply->set_sha256(header.sha256());
    reply->set_size(header.size());
    if (!jobs_.assets().find(header.sha256()).empty()) {
      reply->set_already_present(true);  // the client may stop sending
      return grpc::Status::OK;
    }
    AssetStore::Writer writer(jobs_.assets(), header.sha256(), header.size());
    while (reader->Read(&msg)) {
      if (ctx->IsCancelled()) return abandoned(ctx, "UploadAsset");
      if (!msg.has_data() && msg.has_header()) {
        throw InputError("upload: only the first message may be a header");
      }
      if (msg.data().size() > kMaxChunk) {
        throw InputError("upload: data messages must be at most 1 MiB, got " +
                         std::to_string(msg.data().size()) + " bytes");
      }
      writer.write(msg.data().data(), msg.data().size());
      upload_bytes_ += msg.data().size();
    }
    // The stream also ends when the client gives up: that is no truncated upload to report.
    if (ctx->IsCancelled()) return abandoned(ctx, "UploadAsset");
    writer.finish();
    spdlog::info("asset {} stored ({} bytes, '{}')", header.sha256(), header.size(),
                 printable(header.name().substr(0, 256)));
    return grpc::Status::OK;
  });
}

grpc::Status BakeServiceImpl::SubmitJob(Ctx* ctx, const v1::SubmitJobRequest* request,
                                        v1::SubmitJobResponse* reply) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("SubmitJob", [&] {
    // A client that gave up while the request was queued gets no job it cannot learn about.
    if (ctx->IsCancelled()) return abandoned(ctx, "SubmitJob");
    SubmitInput input = fromProto(*request);
    input.owner = who;
    // Staging many assets or planning a big shot can outlast the client's deadline: stop then.
    input.abandoned = [ctx] {
      return ctx->IsCancelled() || ctx->deadline() <= std::chrono::system_clock::now();
    };
    if (request->dry_run()) {
      toProto(jobs_.plan(input), reply->mutable_plan());
    } else {
      const JobRecord record = jobs_.submit(input);
      spdlog::info("job {}: submitted ('{}')", record.id, printable(record.shot_name));
      toProto(record, reply->mutable_job());
    }
    return grpc::Status::OK;
  });
}

void BakeServiceImpl::checkOwner(const std::string& caller, const std::string& id) const {
  // Another client's job answers exactly as a job that does not exist: ids reveal nothing.
  if (auth_.enabled() && jobs_.ownerOf(id) != caller) {
    throw NotFoundError("job '" + id.substr(0, 64) + "' not found");
  }
}

BakeServiceImpl::StreamSlot::StreamSlot(BakeServiceImpl& service) : service_(service) {
  if (++service_.streams_ > service_.max_streams_) {
    --service_.streams_;
    throw ResourceExhaustedError("too many streams open on this server (limit " +
                                 std::to_string(service_.max_streams_) +
                                 ", --max-streams); retry later");
  }
}

grpc::Status BakeServiceImpl::WatchJob(Ctx* ctx, const v1::WatchJobRequest* request,
                                       grpc::ServerWriter<v1::JobEvent>* writer) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("WatchJob", [&] {
    const StreamSlot slot(*this);
    checkJobId(request->job_id());
    checkOwner(who, request->job_id());
    uint64_t after = request->after_seq();
    for (;;) {
      if (ctx->IsCancelled()) return abandoned(ctx, "WatchJob");
      JobRecord record;
      const std::vector<JobEvent> events =
          jobs_.events(request->job_id(), after, kWatchPoll, &record);
      for (size_t i = 0; i < events.size(); ++i) {
        v1::JobEvent e;
        toProto(events[i], &e);
        const bool last = i + 1 == events.size() && record.terminal();
        if (last) toProto(record, e.mutable_job());
        if (!writer->Write(e)) return abandoned(ctx, "WatchJob");
        after = events[i].seq;
      }
      if (record.terminal()) {
        if (events.empty()) {  // resumed after the end: repeat the final state
          v1::JobEvent e;
          e.set_seq(after);
          e.set_state(toProto(record.state));
          e.set_stage(record.stage);
          e.set_fraction(record.fraction);
          e.set_message(record.error);
          toProto(record, e.mutable_job());
          writer->Write(e);
        }
        return grpc::Status::OK;
      }
    }
  });
}

grpc::Status BakeServiceImpl::GetJob(Ctx* ctx, const v1::GetJobRequest* request, v1::Job* reply) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("GetJob", [&] {
    checkJobId(request->job_id());
    checkOwner(who, request->job_id());
    toProto(jobs_.get(request->job_id()), reply);
    return grpc::Status::OK;
  });
}

grpc::Status BakeServiceImpl::ListJobs(Ctx* ctx, const v1::ListJobsRequest* request,
                                       v1::ListJobsResponse* reply) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("ListJobs", [&] {
    // With tokens a client lists only its own jobs: filter first, then apply the limit.
    const size_t limit = request->limit();
    for (const JobRecord& r :
         jobs_.list(fromProto(request->state()), auth_.enabled() ? 0 : limit)) {
      if (auth_.enabled() && r.owner != who) continue;
      if (limit != 0 && size_t(reply->jobs_size()) >= limit) break;
      toProto(r, reply->add_jobs());
    }
    return grpc::Status::OK;
  });
}

grpc::Status BakeServiceImpl::CancelJob(Ctx* ctx, const v1::CancelJobRequest* request,
                                        v1::Job* reply) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("CancelJob", [&] {
    checkJobId(request->job_id());
    checkOwner(who, request->job_id());
    toProto(jobs_.cancel(request->job_id()), reply);
    spdlog::info("job {}: cancel requested", request->job_id());
    return grpc::Status::OK;
  });
}

grpc::Status BakeServiceImpl::FetchResult(Ctx* ctx, const v1::FetchResultRequest* request,
                                          grpc::ServerWriter<v1::ResultChunk>* writer) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("FetchResult", [&] {
    const StreamSlot slot(*this);
    checkJobId(request->job_id());
    checkOwner(who, request->job_id());
    uint32_t chunk = request->chunk_size() == 0 ? kDefaultChunk : request->chunk_size();
    if (chunk < kMinChunk || chunk > kMaxChunk) {
      throw InputError("chunk_size: must be 0 (default 262144) or in [65536, 1048576], got " +
                       std::to_string(request->chunk_size()));
    }
    const OutputFile file = jobs_.output(request->job_id(), request->name());
    std::ifstream in(file.path, std::ios::binary);
    in.seekg(0, std::ios::end);
    if (!in || uint64_t(in.tellg()) != file.size) {
      throw std::runtime_error(file.path + ": missing or not of the recorded size " +
                               std::to_string(file.size));
    }
    if (request->offset() > file.size) {
      return grpc::Status(grpc::StatusCode::OUT_OF_RANGE,
                          "offset: " + std::to_string(request->offset()) + " is past the end (" +
                              std::to_string(file.size) + " bytes)");
    }
    in.seekg(std::streamoff(request->offset()));
    std::vector<char> buffer(chunk);  // constant memory whatever the file size
    uint64_t offset = request->offset();
    do {
      if (ctx->IsCancelled()) return abandoned(ctx, "FetchResult");
      const uint64_t n = std::min<uint64_t>(chunk, file.size - offset);
      in.read(buffer.data(), std::streamsize(n));
      if (uint64_t(in.gcount()) != n) throw std::runtime_error(file.path + ": short read");
      v1::ResultChunk c;
      c.set_name(file.name);
      c.set_offset(offset);
      c.set_total_size(file.size);
      c.set_sha256(file.sha256);
      c.set_data(buffer.data(), n);
      if (!writer->Write(c)) return abandoned(ctx, "FetchResult");
      fetch_bytes_ += n;
      offset += n;
    } while (offset < file.size);
    return grpc::Status::OK;
  });
}

grpc::Status BakeServiceImpl::RenderView(Ctx* ctx, const v1::RenderViewRequest* request,
                                         v1::SubmitJobResponse* reply) {
  std::string who;
  if (grpc::Status st = auth_.authenticate(*ctx, &who); !st.ok()) return st;
  return guarded("RenderView", [&] {
    checkJobId(request->job_id());
    checkOwner(who, request->job_id());
    std::string sun;
    if (request->sun_irradiance_size() != 0) {
      if (request->sun_irradiance_size() != 3) {
        throw InputError("sun_irradiance: must be empty or [r, g, b], got " +
                         std::to_string(request->sun_irradiance_size()) + " values");
      }
      std::ostringstream text;
      text.precision(17);
      for (int i = 0; i < 3; ++i) {
        const double v = request->sun_irradiance(i);
        if (!std::isfinite(v)) {
          throw InputError("sun_irradiance[" + std::to_string(i) + "]: must be finite");
        }
        text << (i == 0 ? "[" : ",") << v;
      }
      text << "]";
      sun = text.str();
    }
    const JobRecord record = jobs_.render(request->job_id(), request->views_json(), sun, who);
    toProto(record, reply->mutable_job());
    return grpc::Status::OK;
  });
}

}  // namespace cloudbake::server
