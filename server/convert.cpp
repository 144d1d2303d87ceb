#include "server/convert.h"

#include "core/error.h"

namespace cloudbake::server {

v1::JobState toProto(JobState state) {
  switch (state) {
    case JobState::kQueued:
      return v1::QUEUED;
    case JobState::kRunning:
      return v1::RUNNING;
    case JobState::kSucceeded:
      return v1::SUCCEEDED;
    case JobState::kFailed:
      return v1::FAILED;
    case JobState::kCancelled:
      return v1::CANCELLED;
  }
  return v1::JOB_STATE_UNSPECIFIED;
}

std::optional<JobState> fromProto(v1::JobState state) {
  switch (state) {
    case v1::JOB_STATE_UNSPECIFIED:
      return std::nullopt;
    case v1::QUEUED:
      return JobState::kQueued;
    case v1::RUNNING:
      return JobState::kRunning;
    case v1::SUCCEEDED:
      return JobState::kSucceeded;
    case v1::FAILED:
      return JobState::kFailed;
    case v1::CANCELLED:
      return JobState::kCancelled;
    default:
      break;
  }
  throw InputError("state: " + std::to_string(int(state)) + " is not a job state");
}

void toProto(const JobRecord& r, v1::Job* out) {
  out->set_id(r.id);
  out->set_state(toProto(r.state));
  out->set_shot_name(r.shot_name);
  out->set_method(r.method);
  for (const std::string& v : r.views) out->add_views(v);
  out->set_created_unix(r.created);
  out->set_started_unix(r.started);
  out->set_finished_unix(r.finished);
  out->set_stage(r.stage);
  out->set_fraction(r.fraction);
  out->set_error(r.error);
  out->set_error_is_input(r.error_is_input);
  out->set_error_no_space(r.error_no_space);
  for (const OutputFile& f : r.outputs) {
    v1::OutputFile* o = out->add_outputs();
    o->set_name(f.name);
    o->set_size(f.size);
    o->set_sha256(f.sha256);
  }
  out->set_views_rendered(uint32_t(r.views_rendered));
  out->set_views_cached(uint32_t(r.views_cached));
  out->set_bakes_computed(uint32_t(r.bakes_computed));
  out->set_bakes_cached(uint32_t(r.bakes_cached));
  out->set_views_from_bake(uint32_t(r.views_from_bake));
}

void toProto(const JobEvent& e, v1::JobEvent* out) {
  out->set_seq(e.seq);
  out->set_time_unix(e.time);
  out->set_state(toProto(e.state));
  out->set_stage(e.stage);
  out->set_fraction(e.fraction);
  out->set_eta_seconds(e.eta_s);
  out->set_message(e.message);
}

void toProto(const JobPlan& p, v1::JobPlan* out) {
  out->set_shot_name(p.shot_name);
  out->set_method(p.method);
  for (size_t i = 0; i < p.views.size(); ++i) {
    auto* v = out->add_views();
    v->set_name(p.views[i]);
    v->set_cached(p.view_cached[i]);
  }
  out->set_vdb(p.vdb);
  out->set_pixel_samples(p.pixel_samples);
  out->set_bake_key(p.bake_key);
  for (const std::string& c : p.components) out->add_components(c);
  out->set_bake_cached(p.bake_cached);
}

void toProto(const JobManagerStats& s, v1::ServerStats* out) {
  out->set_scatter_computations(s.scatter_computations);
  out->set_views_from_cache(s.views_from_cache);
  out->set_bakes_from_cache(s.bakes_from_cache);
  out->set_volume_builds(s.volume_builds);
  out->set_jobs_submitted(s.jobs_submitted);
  out->set_jobs_queued(uint32_t(s.queued));
  out->set_jobs_running(uint32_t(s.running));
  out->set_cache_hits(s.cache.hits);
  out->set_cache_misses(s.cache.misses);
  out->set_cache_shared(s.cache.shared);
  out->set_cache_shared_across_processes(s.cache.shared_across_processes);
  out->set_cache_leases_taken_over(s.cache.leases_taken_over);
  out->set_cache_corrupt_dropped(s.cache.corrupt);
  out->set_cache_evicted(s.cache.evicted);
  out->set_cache_entries(s.cache.entries);
  out->set_cache_bytes(s.cache.bytes);
}

SubmitInput fromProto(const v1::SubmitJobRequest& request) {
  SubmitInput in;
  if (request.shot_json().empty()) throw InputError("shot_json: must not be empty");
  in.shot_json = request.shot_json();
  if (request.assets_size() > 10000) throw InputError("assets: more than 10000 entries");
  for (const v1::AssetRef& a : request.assets()) in.assets.emplace_back(a.path(), a.sha256());
  if (request.has_samples()) {
    if (request.samples() < 1 || request.samples() > 1000000) {
      throw InputError("samples: must be in [1, 1000000], got " +
                       std::to_string(request.samples()));
    }
    in.samples = request.samples();
  }
  in.sun_tolerance_deg = request.sun_tolerance_deg();  // range checked by the JobManager
  return in;
}

void checkJobId(const std::string& id, const char* field) {
  if (!isJobId(id)) {
    throw InputError(std::string(field) + ": '" + id.substr(0, 64) +
                     "' is not a job id (expected 'j' and 16 hex digits)");
  }
}

}  // namespace cloudbake::server
