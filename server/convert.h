// Conversions between core/job records and cloudbake.v1 messages.
#pragma once

#include "cloudbake/v1/bake_service.pb.h"
#include "core/job/job_manager.h"

namespace cloudbake::server {

v1::JobState toProto(JobState state);
/// Throws InputError for a value that is not a job state.
std::optional<JobState> fromProto(v1::JobState state);
void toProto(const JobRecord& record, v1::Job* out);
void toProto(const JobEvent& event, v1::JobEvent* out);
void toProto(const JobPlan& plan, v1::JobPlan* out);
void toProto(const JobManagerStats& stats, v1::ServerStats* out);
/// Validates and converts a submit request (the shot itself is validated by the JobManager).
SubmitInput fromProto(const v1::SubmitJobRequest& request);
/// Throws InputError naming `field` unless `id` is a well-formed job id.
void checkJobId(const std::string& id, const char* field = "job_id");

}  // namespace cloudbake::server
