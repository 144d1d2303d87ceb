// cloudctl: command-line client of cloudbake-server (docs/cli.md, docs/api.md).
// Usage: cloudctl [--server HOST:PORT] [--timeout S] [--json] COMMAND ...
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "client/shot_paths.h"
#include "cloudbake/v1/bake_service.grpc.pb.h"
#include "common/cli_number.h"
#include "common/cli_suggest.h"
#include "common/exit_codes.h"
#include "common/grpc_status.h"
#include "common/json_limits.h"
#include "common/printable.h"
#include "common/stdout_check.h"
#include "core/io/exr_io.h"
#include "core/io/png_writer.h"
#include "core/job/asset_limits.h"
#include "core/job/sha256.h"

namespace {
namespace fs = std::filesystem;
namespace v1 = cloudbake::v1;
using Json = nlohmann::json;
using cloudbake::ExitCode;

constexpr size_t kUploadChunk = 1 << 20;
/// gRPC's default limit on a received message, which the server keeps.
constexpr size_t kMaxRequestBytes = size_t(4) << 20;

/// An error with the exit code it maps to; main() prints it once.
struct CliError {
  int code;
  std::string message;
};

const char* statusName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::INVALID_ARGUMENT:
      return "invalid argument";
    case grpc::StatusCode::NOT_FOUND:
      return "not found";
    case grpc::StatusCode::UNAVAILABLE:
      return "server unavailable";
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return "deadline exceeded";
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return "server busy";
    case grpc::StatusCode::FAILED_PRECONDITION:
      return "failed precondition";
    case grpc::StatusCode::CANCELLED:
      return "cancelled";
    case grpc::StatusCode::OUT_OF_RANGE:
      return "out of range";
    default:
      return "error";
  }
}

/// A request gRPC would refuse as RESOURCE_EXHAUSTED, which reads as "server busy, retry".
CliError tooLarge(const std::string& what, size_t bytes) {
  return CliError{ExitCode::kBadInput, what + " too large (" + std::to_string(bytes) +
                                           " bytes; a request may have at most " +
                                           std::to_string(kMaxRequestBytes) + " bytes)"};
}

void check(const grpc::Status& s, const std::string& what) {
  if (!s.ok()) {
    throw CliError{cloudbake::exitCodeFor(cloudbake::errorKindFor(s.error_code())),
                   what + ": " + statusName(s.error_code()) + ": " + s.error_message()};
  }
}

/// As check, for the server's verdict on a shot: its messages name the shot "shot.json" (the
/// name the server gives every shot), which the user never used; the user's file is named instead.
void checkShot(const grpc::Status& s, const std::string& shot_file) {
  if (s.ok()) return;
  std::string message = s.error_message();
  if (message.rfind("shot.json: ", 0) == 0) message.erase(0, 11);
  check(grpc::Status(s.error_code(), message), shot_file);
}

/// A job's error with the server's name of the shot ("shot.json: ...") replaced by the user's
/// file, when the client knows it (submit): an asset found bad while the job ran is named so.
std::string userNamedError(const std::string& error, const std::string& shot_file) {
  const std::string server_name = "shot.json: ";
  if (shot_file.empty() || error.rfind(server_name, 0) != 0) return error;
  return shot_file + ": " + error.substr(server_name.size());
}

// Protobuf's own names of the enum values ("QUEUED", "RUNNING", ...); they live for the program.
const char* stateName(v1::JobState s) { return v1::JobState_Name(s).c_str(); }

bool terminal(v1::JobState s) {
  return s == v1::SUCCEEDED || s == v1::FAILED || s == v1::CANCELLED;
}

Json jobJson(const v1::Job& j) {
  Json outputs = Json::array();
  for (const auto& o : j.outputs()) {
    outputs.push_back({{"name", o.name()}, {"size", o.size()}, {"sha256", o.sha256()}});
  }
  return {{"id", j.id()},
          {"state", stateName(j.state())},
          {"shot_name", j.shot_name()},
          {"method", j.method()},
          {"views", std::vector<std::string>(j.views().begin(), j.views().end())},
          {"stage", j.stage()},
          {"fraction", j.fraction()},
          {"error", j.error()},
          {"error_is_input", j.error_is_input()},
          {"error_no_space", j.error_no_space()},
          {"created_unix", j.created_unix()},
          {"started_unix", j.started_unix()},
          {"finished_unix", j.finished_unix()},
          {"views_rendered", j.views_rendered()},
          {"views_cached", j.views_cached()},
          {"bakes_computed", j.bakes_computed()},
          {"bakes_cached", j.bakes_cached()},
          {"views_from_bake", j.views_from_bake()},
          {"outputs", outputs}};
}

/// Exit code of a finished job: bad input in the shot's assets (found while running) is 2.
int jobExitCode(const v1::Job& j) {
  switch (j.state()) {
    case v1::SUCCEEDED:
      return ExitCode::kOk;
    case v1::CANCELLED:
      return ExitCode::kCancelled;
    case v1::FAILED:
      if (j.error_no_space()) return ExitCode::kUnavailable;  // a full server: retry later
      return j.error_is_input() ? ExitCode::kBadInput : ExitCode::kJobFailed;
    default:
      return ExitCode::kFailure;
  }
}

/// A small text file an option names; CliError naming the option when it cannot be read.
std::string readTextFile(const std::string& path, const std::string& option) {
  // A folder opens as a stream and fails at the first read, with the library's own words.
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    throw CliError{ExitCode::kBadInput, option + " " + path + ": is a folder, not a file"};
  }
  // A missing file is exit 3 as for every command (it was 2, "cannot open").
  if (!std::filesystem::exists(path, ec)) {
    throw CliError{ExitCode::kNotFound, option + " " + path + ": file not found"};
  }
  std::ifstream in(path, std::ios::binary);
  if (!in.is_open()) throw CliError{ExitCode::kBadInput, option + " " + path + ": cannot open"};
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw CliError{ExitCode::kBadInput, option + " " + path + ": cannot read"};
  return text;
}

/// The bearer token: from --token-file (CLOUDBAKE_TOKEN_FILE), else CLOUDBAKE_TOKEN, else none.
std::string readToken(const std::string& file) {
  const char* env = std::getenv("CLOUDBAKE_TOKEN");
  std::string token = !file.empty() ? readTextFile(file, "--token-file") : env ? env : "";
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; };
  while (!token.empty() && blank(token.back())) token.pop_back();
  while (!token.empty() && blank(token.front())) token.erase(token.begin());
  if (!file.empty() && token.empty()) {
    // Not "this server requires a token", as if none had been given.
    throw CliError{ExitCode::kBadInput, "--token-file " + file + ": holds no token"};
  }
  for (const char c : token) {
    if (static_cast<unsigned char>(c) <= ' ' || c == 0x7f) {
      throw CliError{ExitCode::kBadInput,
                     "token: must be one word of printable characters (--token-file or "
                     "CLOUDBAKE_TOKEN)"};
    }
  }
  return token;
}

struct Client {
  std::string server;
  double timeout_s = 10;
  double retry_s = 30;  // how long a submit retries a full queue or an unavailable server
  bool json = false;
  bool wait_for_server = false;
  bool png = false;  // --png: a preview beside each downloaded EXR
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<v1::BakeService::Stub> stub;
  bool tls = false;    // --tls: TLS with the system's CA certificates
  std::string tls_ca;  // --tls-ca: TLS trusting this PEM file instead
  std::string token;   // sent as 'authorization: Bearer TOKEN' on every call

  std::shared_ptr<grpc::ChannelCredentials> credentials() const {
    if (!tls && tls_ca.empty()) return grpc::InsecureChannelCredentials();
    grpc::SslCredentialsOptions ssl;
    if (!tls_ca.empty()) {
      ssl.pem_root_certs = readTextFile(tls_ca, "--tls-ca");
      if (ssl.pem_root_certs.find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
        throw CliError{ExitCode::kBadInput, "--tls-ca " + tls_ca + ": not a PEM certificate"};
      }
    }
    return grpc::SslCredentials(ssl);
  }

  /// Fails at once when the connection is refused or the host unreachable (the channel's
  /// first attempt fails), unless --wait-for-server asks to keep trying until --timeout.
  void connect() {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(4 << 20);
    channel = grpc::CreateCustomChannel(server, credentials(), args);
    const auto start = std::chrono::system_clock::now();
    const auto until = deadline();
    grpc_connectivity_state state = channel->GetState(/*try_to_connect=*/true);
    while (state != GRPC_CHANNEL_READY) {
      if (state == GRPC_CHANNEL_TRANSIENT_FAILURE && !wait_for_server) {
        throw CliError{ExitCode::kUnavailable,
                       server +
                           ": server unavailable (connection refused or unreachable; "
                           "--wait-for-server keeps trying for --timeout seconds)"};
      }
      if (!channel->WaitForStateChange(state, until)) {
        // The wait ends at --timeout or at --deadline, whichever is first: say which, in the
        // seconds it waited (a --deadline 3 said "within 10 s", a --timeout 1e-6 "within 1 s").
        const double waited = std::chrono::duration<double>(until - start).count();
        const bool by_deadline =
            command_deadline &&
            *command_deadline <
                start + std::chrono::milliseconds(static_cast<long>(timeout_s * 1000));
        char seconds[32];
        std::snprintf(seconds, sizeof seconds, "%.2g", std::max(0.0, waited));
        throw CliError{ExitCode::kUnavailable,
                       server + ": server unavailable (no connection within " + seconds + " s, " +
                           (by_deadline ? "--deadline" : "--timeout") + ")"};
      }
      state = channel->GetState(/*try_to_connect=*/true);
    }
    stub = v1::BakeService::NewStub(channel);
  }
  /// --deadline: when set, every call of this command (uploads, submit, watch, fetch) ends by
  /// then with DEADLINE_EXCEEDED (exit code 4); the server stops streaming when it passes.
  std::optional<std::chrono::system_clock::time_point> command_deadline;

  std::chrono::system_clock::time_point deadline() const {
    const auto t = std::chrono::system_clock::now() +
                   std::chrono::milliseconds(static_cast<long>(timeout_s * 1000));
    return command_deadline ? std::min(t, *command_deadline) : t;
  }
  void shortCall(grpc::ClientContext* ctx) const {
    ctx->set_deadline(deadline());
    authorize(ctx);
  }
  /// Streams have no per-call bound (a bake may take hours), only the command's deadline.
  void streamCall(grpc::ClientContext* ctx) const {
    if (command_deadline) ctx->set_deadline(*command_deadline);
    authorize(ctx);
  }
  void authorize(grpc::ClientContext* ctx) const {
    if (!token.empty()) ctx->AddMetadata("authorization", "Bearer " + token);
  }
};

// ---- health ------------------------------------------------------------------------------

/// grpc.health.v1.HealthCheckResponse.ServingStatus values.
const char* servingStatusName(uint64_t s) {
  switch (s) {
    case 0:
      return "UNKNOWN";
    case 1:
      return "SERVING";
    case 2:
      return "NOT_SERVING";
    case 3:
      return "SERVICE_UNKNOWN";
    default:
      return "UNRECOGNISED";
  }
}

/// Reads a protobuf base-128 varint at `*at`; false when truncated or longer than 10 bytes.
bool readVarint(const std::string& b, size_t* at, uint64_t* value) {
  *value = 0;
  for (int shift = 0; shift < 70 && *at < b.size(); shift += 7) {
    const auto byte = static_cast<unsigned char>(b[(*at)++]);
    *value |= uint64_t(byte & 0x7f) << shift;
    if (!(byte & 0x80)) return true;
  }
  return false;
}

/// The `status` (field 1, varint) of an encoded HealthCheckResponse; unknown fields are skipped
/// as protobuf requires. Absent: 0 (UNKNOWN), proto3's default. Throws CliError when malformed.
uint64_t parseHealthStatus(const std::string& b) {
  uint64_t status = 0;
  size_t at = 0;
  auto bad = [] { return CliError{ExitCode::kFailure, "health: malformed HealthCheckResponse"}; };
  while (at < b.size()) {
    uint64_t tag = 0, v = 0;
    if (!readVarint(b, &at, &tag)) throw bad();
    switch (tag & 7) {
      case 0:  // varint
        if (!readVarint(b, &at, &v)) throw bad();
        if ((tag >> 3) == 1) status = v;
        break;
      case 1:  // 64-bit
        if (b.size() - at < 8) throw bad();
        at += 8;
        break;
      case 2:  // length-delimited
        if (!readVarint(b, &at, &v) || v > b.size() - at) throw bad();
        at += size_t(v);
        break;
      case 5:  // 32-bit
        if (b.size() - at < 4) throw bad();
        at += 4;
        break;
      default:
        throw bad();
    }
  }
  return status;
}

/// Calls the standard grpc.health.v1.Health/Check for the whole server (empty `service`, which
/// encodes to zero bytes) without generated stubs; returns the ServingStatus.
uint64_t healthCheck(Client& c) {
  grpc::GenericStub stub(c.channel);
  grpc::ClientContext ctx;
  c.shortCall(&ctx);
  grpc::CompletionQueue cq;
  grpc::Slice empty;
  grpc::ByteBuffer request(&empty, 1);
  auto call = stub.PrepareUnaryCall(&ctx, "/grpc.health.v1.Health/Check", request, &cq);
  call->StartCall();
  grpc::ByteBuffer response;
  grpc::Status status;
  call->Finish(&response, &status, reinterpret_cast<void*>(1));
  void* tag = nullptr;
  bool ok = false;
  if (!cq.Next(&tag, &ok)) throw CliError{ExitCode::kFailure, "health: no completion"};
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
  check(status, c.server + ": health");
  std::vector<grpc::Slice> slices;
  if (!response.Dump(&slices).ok()) throw CliError{ExitCode::kFailure, "health: bad response"};
  std::string bytes;
  for (const grpc::Slice& s : slices) {
    bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  }
  return parseHealthStatus(bytes);
}

// ---- progress ----------------------------------------------------------------------------

class Progress {
 public:
  /// `json`: one JSON object per line on stderr (stdout keeps the one result document).
  Progress(bool quiet, bool json)
      : quiet_(quiet), json_(json), tty_(!json && isatty(fileno(stderr)) != 0) {}
  void event(const v1::JobEvent& e) {
    if (quiet_) return;
    const int percent = int(std::floor(std::clamp(e.fraction(), 0.0, 1.0) * 100));
    if (json_) {
      if (!e.message().empty() || percent > last_percent_ || terminal(e.state())) {
        Json line = {{"state", stateName(e.state())},
                     {"stage", e.stage()},
                     {"fraction", e.fraction()},
                     {"message", e.message()}};
        if (e.eta_seconds() >= 0 && !terminal(e.state())) line["eta_seconds"] = e.eta_seconds();
        std::fprintf(stderr, "%s\n", line.dump().c_str());
        std::fflush(stderr);
        last_percent_ = std::max(last_percent_, percent);
      }
      return;
    }
    std::string eta = e.eta_seconds() >= 0 && !terminal(e.state())
                          ? " ETA " + std::to_string(int(std::ceil(e.eta_seconds()))) + " s"
                          : "";
    if (tty_) {
      const int filled = percent / 5;
      std::fprintf(stderr, "\r[%s%s] %3d%% %-9s %-8s%s\033[K",
                   std::string(size_t(filled), '#').c_str(),
                   std::string(size_t(20 - filled), '.').c_str(), percent, stateName(e.state()),
                   e.stage().c_str(), eta.c_str());
      if (!e.message().empty() || terminal(e.state())) {
        std::fprintf(stderr, "\r\033[K%s\n", line(e, percent).c_str());
      }
    } else if (!e.message().empty() || percent / 10 > last_decile_ || terminal(e.state())) {
      std::fprintf(stderr, "%s%s\n", line(e, percent).c_str(), eta.c_str());
      last_decile_ = std::max(last_decile_, percent / 10);
    }
    std::fflush(stderr);
  }

 private:
  static std::string line(const v1::JobEvent& e, int percent) {
    return std::to_string(percent) + "% " + stateName(e.state()) + " " + e.stage() +
           (e.message().empty() ? "" : ": " + e.message());
  }
  bool quiet_, json_, tty_;
  int last_decile_ = -1, last_percent_ = -1;
};

// ---- uploads -----------------------------------------------------------------------------

std::string upload(Client& c, const std::string& path, bool quiet) {
  const std::string sha = cloudbake::sha256File(path);
  const uint64_t size = fs::file_size(path);
  grpc::ClientContext ctx;
  c.streamCall(&ctx);
  v1::UploadAssetResponse reply;
  auto writer = c.stub->UploadAsset(&ctx, &reply);
  v1::UploadAssetRequest msg;
  msg.mutable_header()->set_sha256(sha);
  msg.mutable_header()->set_size(size);
  msg.mutable_header()->set_name(fs::path(path).filename().string());
  bool open = writer->Write(msg);
  std::ifstream in(path, std::ios::binary);
  std::string buf(kUploadChunk, '\0');
  while (open && in) {
    in.read(buf.data(), std::streamsize(buf.size()));
    const auto n = size_t(in.gcount());
    if (n == 0) break;
    msg.set_data(buf.data(), n);
    open = writer->Write(msg);  // false: the server answered early (content already held)
  }
  writer->WritesDone();
  check(writer->Finish(), "upload " + path);
  if (!c.json && !quiet) {
    std::fprintf(stderr, "%s: %s (%llu bytes)\n", path.c_str(),
                 reply.already_present() ? "already on the server" : "uploaded",
                 static_cast<unsigned long long>(size));
  }
  return sha;
}

// ---- fetch -------------------------------------------------------------------------------

/// Appends `file` from `offset` on to `part`. A stream that fails before a byte arrived (an
/// output gone from the server) leaves no empty .part behind.
void downloadPart(Client& c, const std::string& job, const v1::OutputFile& file,
                  const fs::path& part, uint64_t offset) {
  const uint64_t start = offset;
  grpc::ClientContext ctx;
  c.streamCall(&ctx);
  v1::FetchResultRequest req;
  req.set_job_id(job);
  req.set_name(file.name());
  req.set_offset(offset);
  auto reader = c.stub->FetchResult(&ctx, req);
  std::ofstream out(part, std::ios::binary | std::ios::app);
  v1::ResultChunk chunk;
  while (reader->Read(&chunk)) {
    if (chunk.offset() != offset) {
      throw CliError{ExitCode::kFailure, "fetch " + file.name() + ": chunk out of order"};
    }
    out.write(chunk.data().data(), std::streamsize(chunk.data().size()));
    offset += chunk.data().size();
  }
  out.close();
  if (!out) {
    throw CliError{ExitCode::kFailure,
                   "fetch " + file.name() + ": cannot write " + part.string() +
                       " (disk full or not writable); the partial file is kept for a resume"};
  }
  const grpc::Status status = reader->Finish();
  std::error_code ec;
  if (!status.ok() && start == 0 && fs::file_size(part, ec) == 0) fs::remove(part, ec);
  check(status, "fetch " + file.name());
}

/// Downloads one output to DIR/<name>, resuming DIR/<name>.part, verifying size and SHA-256. A
/// file already there with the same size and SHA-256 (the unchanged bake.vdb of a RenderView of
/// the same job) is kept as it is, without a download.
std::string fetchOne(Client& c, const std::string& job, const v1::OutputFile& file,
                     const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (!fs::is_directory(dir)) {
    throw CliError{ExitCode::kBadInput, "--out: cannot create folder '" + dir + "'"};
  }
  if (file.name().find('/') != std::string::npos || file.name().empty() || file.name() == "." ||
      file.name() == "..") {
    throw CliError{ExitCode::kFailure, "server sent an unsafe output name '" + file.name() + "'"};
  }
  const fs::path final_path = fs::path(dir) / file.name();
  // Checked before the download: the rename at its end failed ("filesystem error", exit 1)
  // with the whole file left beside it.
  if (fs::is_directory(final_path, ec)) {
    throw CliError{ExitCode::kBadInput, "--out: " + final_path.string() +
                                            " is a folder; the output '" + file.name() +
                                            "' cannot be written there"};
  }
  if (fs::is_regular_file(final_path, ec) && fs::file_size(final_path, ec) == file.size() &&
      cloudbake::sha256File(final_path.string()) == file.sha256()) {
    return final_path.string();
  }
  const fs::path part = final_path.string() + ".part";
  uint64_t offset = fs::exists(part) ? fs::file_size(part) : 0;
  if (offset > file.size()) {
    fs::remove(part);
    offset = 0;
  }
  const bool resumed = offset > 0;
  if (offset < file.size() || file.size() == 0) downloadPart(c, job, file, part, offset);
  const std::string got = cloudbake::sha256File(part.string());
  if (fs::file_size(part) != file.size() || got != file.sha256()) {
    fs::remove(part);
    // A .part that was not a prefix of this output (a stale one, another version of the file)
    // spoils only the resume: the whole file is fetched again once, not left for a second run.
    if (resumed) return fetchOne(c, job, file, dir);
    throw CliError{ExitCode::kFailure, "fetch " + file.name() + ": checksum mismatch (expected " +
                                           file.sha256() + ", got " + got +
                                           "); the partial file was removed"};
  }
  fs::rename(part, final_path);
  return final_path.string();
}

v1::Job getJob(Client& c, const std::string& id) {
  grpc::ClientContext ctx;
  c.shortCall(&ctx);
  v1::GetJobRequest req;
  req.set_job_id(id);
  v1::Job job;
  check(c.stub->GetJob(&ctx, req, &job), "job " + id);
  return job;
}

/// DIR/<stem>.png beside a downloaded EXR: its beauty (or, in other files, the unprefixed RGB)
/// auto-exposed as `cloudbake preview` does. The EXR is the product; the PNG is for looking.
std::string writePreview(const std::string& exr_path) {
  try {
    const cloudbake::ExrContents exr = cloudbake::readExr(exr_path);
    auto it = exr.layers.find("beauty");
    if (it == exr.layers.end()) it = exr.layers.find("");
    if (it == exr.layers.end() || it->second.channels < 3) {
      throw CliError{ExitCode::kFailure, exr_path + ": --png: no RGB layer to preview"};
    }
    const std::string png = fs::path(exr_path).replace_extension(".png").string();
    cloudbake::writePreviewPng(png, it->second);
    return png;
  } catch (const std::exception& e) {  // unreadable EXR, unwritable PNG
    throw CliError{ExitCode::kFailure, std::string("--png: ") + e.what()};
  }
}

bool isExr(const std::string& name) {
  return name.size() > 4 && name.compare(name.size() - 4, 4, ".exr") == 0;
}

/// Fetches every output of a job; prints paths (or a JSON object with --json).
int fetchAll(Client& c, const v1::Job& job, const std::string& dir, const std::string& only) {
  if (job.state() != v1::SUCCEEDED) {
    // A job still queued or running has no results yet: like one that did not succeed (exit
    // 5, docs/cli.md), not an internal error.
    const bool finished = job.state() == v1::FAILED || job.state() == v1::CANCELLED;
    throw CliError{finished ? jobExitCode(job) : int(ExitCode::kJobFailed),
                   "job " + job.id() + " is " + stateName(job.state()) +
                       (finished ? "" : " (no outputs yet: `cloudctl watch` waits for it)") +
                       (job.error().empty() ? "" : ": " + job.error())};
  }
  Json files = Json::array();
  bool any = false;
  for (const auto& f : job.outputs()) {
    if (!only.empty() && f.name() != only) continue;
    any = true;
    const std::string path = fetchOne(c, job.id(), f, dir);
    files.push_back(
        {{"name", f.name()}, {"path", path}, {"size", f.size()}, {"sha256", f.sha256()}});
    if (!c.json) std::cout << path << "\n";
    if (c.png && isExr(f.name())) {
      const std::string png = writePreview(path);
      files.back()["preview"] = png;
      if (!c.json) std::cout << png << "\n";
    }
  }
  if (!any && !only.empty()) {
    throw CliError{ExitCode::kNotFound, "job " + job.id() + " has no output '" + only + "'"};
  }
  if (c.json) {
    Json j = jobJson(job);
    j["files"] = files;
    std::cout << j.dump() << "\n";
  }
  return ExitCode::kOk;
}

/// Streams events until the job finishes; returns its final record. Reconnects (resuming
/// after the last event) when the stream breaks while the server is still reachable.
v1::Job watch(Client& c, const std::string& id, bool quiet) {
  Progress progress(quiet, c.json);
  uint64_t after = 0;
  for (int attempt = 0;; ++attempt) {
    grpc::ClientContext ctx;
    c.streamCall(&ctx);
    v1::WatchJobRequest req;
    req.set_job_id(id);
    req.set_after_seq(after);
    auto reader = c.stub->WatchJob(&ctx, req);
    v1::JobEvent e;
    while (reader->Read(&e)) {
      progress.event(e);
      after = std::max(after, e.seq());
      if (e.has_job() && terminal(e.job().state())) {
        ctx.TryCancel();
        reader->Finish();
        return e.job();
      }
    }
    const grpc::Status s = reader->Finish();
    if (s.error_code() != grpc::StatusCode::UNAVAILABLE || attempt >= 3) {
      check(s, "watch " + id);
      return getJob(c, id);
    }
    std::this_thread::sleep_for(std::chrono::seconds(1));
  }
}

int finishJob(Client& c, const v1::Job& job_in, const std::string& out_dir,
              const std::string& shot_file = "") {
  v1::Job job = job_in;
  job.set_error(userNamedError(job.error(), shot_file));
  if (job.state() == v1::SUCCEEDED && !out_dir.empty()) return fetchAll(c, job, out_dir, "");
  if (c.json)
    std::cout << jobJson(job).dump() << "\n";
  else if (job.state() == v1::SUCCEEDED) {
    std::cout << job.id() << " SUCCEEDED";
    for (const auto& f : job.outputs()) std::cout << " " << f.name();
    std::cout << "\n";
  }
  if (job.state() != v1::SUCCEEDED) {
    throw CliError{jobExitCode(job), "job " + job.id() + " " + stateName(job.state()) +
                                         (job.error().empty() ? "" : ": " + job.error())};
  }
  return ExitCode::kOk;
}

// ---- submit ------------------------------------------------------------------------------

struct SubmitArgs {
  std::string shot;
  std::string out;
  bool wait = false, detach = false, dry_run = false, quiet = false;
  int samples = 0;
  bool samples_given = false;  // sent to the server, which checks its range
  double sun_tolerance_deg = 0;
  bool allow_outside = false;
  bool png = false;
};

/// The shot file's text; CliError (exit 3 or 2) when it is missing or cannot be read.
std::string readShotFile(const std::string& path) {
  if (!fs::exists(path)) throw CliError{ExitCode::kNotFound, path + ": file not found"};
  if (!fs::is_regular_file(path)) throw CliError{ExitCode::kBadInput, path + ": not a file"};
  try {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  } catch (const std::exception& e) {
    throw CliError{ExitCode::kBadInput, path + ": cannot read: " + e.what()};
  }
}

/// JSON text must be UTF-8, and a request's strings must be (protobuf refuses to send others,
/// with no message of ours): bad input naming the file and the byte.
void checkUtf8(const std::string& text, const std::string& what) {
  const size_t at = cloudbake::firstInvalidUtf8(text);
  if (at == std::string::npos) return;
  throw CliError{ExitCode::kBadInput, what + ": invalid JSON: the byte at offset " +
                                          std::to_string(at) + " is not UTF-8"};
}

/// Uploads the files `req`'s shot names and lists them in `req`. A file outside the shot's
/// folder goes (with --allow-outside only) under a name inside it, which the shot text then uses.
void addAssets(Client& c, const SubmitArgs& a, v1::SubmitJobRequest* req) {
  // The server validates the shot; here we only find the files to send. Text that is not JSON
  // goes as it is, for the server's parser to report where it breaks.
  Json shot;
  try {
    shot = cloudbake::parseJsonLimited(req->shot_json(), a.shot);
  } catch (const cloudbake::InputError&) {
    return;
  }
  const fs::path base = fs::absolute(a.shot).parent_path();
  bool rewritten = false;
  const std::vector<cloudbake::client::ShotPath> paths = cloudbake::client::shotPaths(shot);
  if (paths.size() > cloudbake::kMaxJobAssets) {
    throw CliError{ExitCode::kBadInput,
                   a.shot + ": names " + std::to_string(paths.size()) + " files (" +
                       paths.back().pointer + " the last), more than the " +
                       std::to_string(cloudbake::kMaxJobAssets) + " a job may name"};
  }
  for (const cloudbake::client::ShotPath& path : paths) {
    Json* node = path.node;
    const std::string p = node->get<std::string>();
    const std::string field = a.shot + ": " + path.pointer + ": ";
    fs::path rel = fs::path(p).lexically_normal();
    const bool outside = rel.is_absolute() || (!rel.empty() && *rel.begin() == "..");
    // Absolute or escaping paths are not sent unless asked for: the server rejects them,
    // naming the field.
    if (p.empty() || (outside && !a.allow_outside)) continue;
    // Control characters: not sent either; the server's parser names the field for them.
    if (std::any_of(p.begin(), p.end(), [](unsigned char ch) { return ch < 0x20 || ch == 0x7f; })) {
      continue;
    }
    const fs::path local = outside && rel.is_absolute() ? rel : base / rel;
    // A path inside the folder may still lead out of it through a symbolic link: what would be
    // sent is the file outside, which needs --allow-outside as any other (it sent /etc/passwd).
    std::error_code ec;
    const fs::path real = fs::weakly_canonical(local, ec);
    const fs::path real_base = fs::weakly_canonical(base, ec);
    const auto [end, unused] =
        std::mismatch(real_base.begin(), real_base.end(), real.begin(), real.end());
    if (!outside && !a.allow_outside && end != real_base.end()) {
      throw CliError{ExitCode::kBadInput,
                     field + "'" + p + "' leads outside the shot's folder (to " + real.string() +
                         "); cloudctl submit --allow-outside uploads it"};
    }
    if (!fs::exists(local)) {
      throw CliError{ExitCode::kNotFound,
                     field + "'" + p + "' (" + local.string() + "): file not found"};
    }
    if (!fs::is_regular_file(local)) {
      throw CliError{ExitCode::kBadInput, field + "'" + p + "': not a regular file"};
    }
    const std::string sha = upload(c, local.string(), a.quiet);
    if (outside) {
      rel = fs::path("outside") / sha.substr(0, 16) / local.filename();
      *node = rel.string();
      rewritten = true;
    }
    v1::AssetRef* ref = req->add_assets();
    ref->set_path(rel.string());
    ref->set_sha256(sha);
  }
  if (rewritten) req->set_shot_json(shot.dump(2));
}

/// SubmitJob, tried again with exponential backoff and jitter while the server's queue is full
/// (RESOURCE_EXHAUSTED) or the server is briefly away (UNAVAILABLE), for --retry-seconds and
/// never past --deadline; then the last answer stands.
void submitWithRetries(Client& c, const SubmitArgs& a, const v1::SubmitJobRequest& req,
                       v1::SubmitJobResponse* reply) {
  using Clock = std::chrono::system_clock;
  Clock::time_point give_up = Clock::now() + std::chrono::milliseconds(long(c.retry_s * 1000));
  if (c.command_deadline) give_up = std::min(give_up, *c.command_deadline);
  std::mt19937_64 rng(std::random_device{}());
  for (double wait_s = 0.25;; wait_s = std::min(wait_s * 2, 8.0)) {
    grpc::ClientContext ctx;
    c.shortCall(&ctx);
    grpc::Status st = c.stub->SubmitJob(&ctx, req, reply);
    if (st.error_code() == grpc::StatusCode::CANCELLED) {
      // This client cancels no submit: the server ended the call (a graceful stop) before any
      // job existed. Retried as a server away, not "cancelled" (exit 6), which names a job.
      st = grpc::Status(grpc::StatusCode::UNAVAILABLE,
                        "the server ended the call before a job was created (stopping?); "
                        "nothing was submitted");
    }
    const bool busy = st.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED ||
                      st.error_code() == grpc::StatusCode::UNAVAILABLE;
    const double sleep_s = wait_s * std::uniform_real_distribution<double>(0.5, 1.0)(rng);
    const Clock::time_point next = Clock::now() + std::chrono::milliseconds(long(sleep_s * 1000));
    if (!busy || next > give_up) {
      checkShot(st, a.shot);
      return;
    }
    std::this_thread::sleep_until(next);
  }
}

v1::SubmitJobResponse sendSubmit(Client& c, const SubmitArgs& a, const v1::SubmitJobRequest& req) {
  // gRPC refuses a larger request as RESOURCE_EXHAUSTED, which reads as "server busy, retry":
  // said here for what it is.
  if (req.ByteSizeLong() > kMaxRequestBytes) {
    throw tooLarge(a.shot + ": shot", req.ByteSizeLong());
  }
  v1::SubmitJobResponse reply;
  try {
    submitWithRetries(c, a, req, &reply);
  } catch (CliError& e) {
    if (!a.allow_outside && e.message.find("is outside the allowed") != std::string::npos) {
      e.message += " (cloudctl submit --allow-outside uploads such files)";
    }
    throw;
  }
  return reply;
}

void printPlan(const Client& c, const v1::JobPlan& p) {
  if (c.json) {
    Json views = Json::array();
    for (const auto& v : p.views()) views.push_back({{"name", v.name()}, {"cached", v.cached()}});
    std::cout << Json{{"shot_name", p.shot_name()},
                      {"method", p.method()},
                      {"views", views},
                      {"vdb", p.vdb()},
                      {"pixel_samples", p.pixel_samples()},
                      {"bake_key", p.bake_key()},
                      {"bake_cached", p.bake_cached()},
                      {"components", Json(std::vector<std::string>(p.components().begin(),
                                                                   p.components().end()))}}
                     .dump()
              << "\n";
    return;
  }
  std::cout << "shot '" << p.shot_name() << "', method " << p.method() << "\n";
  for (const auto& line : p.components()) std::cout << "  " << line << "\n";
  std::cout << "  estimated cost: " << p.pixel_samples()
            << (p.method() == "pathtrace"
                    ? " paths\n"
                    : " view rays at most (a sparse film traces fewer), after the bake\n");
  std::cout << "  bake key: " << p.bake_key() << "\n";
}

int cmdSubmit(Client& c, const SubmitArgs& a) {
  if (a.wait && a.detach)
    throw CliError{ExitCode::kBadInput, "--wait and --detach exclude each other"};
  const std::string text = readShotFile(a.shot);
  if (text.size() > kMaxRequestBytes) {
    throw tooLarge(a.shot + ": shot", text.size());
  }
  checkUtf8(text, a.shot);
  c.connect();
  v1::SubmitJobRequest req;
  req.set_shot_json(text);
  req.set_dry_run(a.dry_run);
  if (a.samples_given) req.set_samples(a.samples);
  req.set_sun_tolerance_deg(a.sun_tolerance_deg);
  addAssets(c, a, &req);
  const v1::SubmitJobResponse reply = sendSubmit(c, a, req);
  if (a.dry_run) {
    printPlan(c, reply.plan());
    return ExitCode::kOk;
  }
  const v1::Job& job = reply.job();
  if (a.detach) {
    if (c.json)
      std::cout << jobJson(job).dump() << "\n";
    else
      std::cout << job.id() << "\n";
    return ExitCode::kOk;
  }
  if (!c.json && !a.quiet) std::fprintf(stderr, "job %s submitted\n", job.id().c_str());
  return finishJob(c, watch(c, job.id(), a.quiet), a.out, a.shot);
}

// ---- health and info ---------------------------------------------------------------------

int cmdHealth(Client& c) {
  c.connect();
  const uint64_t st = healthCheck(c);
  const bool serving = st == 1;
  if (c.json) {
    std::cout << Json{{"server", c.server}, {"serving", serving}, {"status", servingStatusName(st)}}
                     .dump()
              << "\n";
  } else {
    std::cout << c.server << ": " << servingStatusName(st) << "\n";
  }
  if (!serving) {
    throw CliError{ExitCode::kUnavailable,
                   c.server + ": health: " + servingStatusName(st) + " (not SERVING)"};
  }
  return ExitCode::kOk;
}

void printInfoJson(const Client& c, const v1::ServerInfo& reply) {
  const v1::ServerStats& s = reply.stats();
  Json j = {{"server", c.server}, {"serving", true}, {"version", reply.version()}};
  j["methods"] = std::vector<std::string>(reply.methods().begin(), reply.methods().end());
  j["worker_threads"] = reply.worker_threads();
  j["limits"] = {{"max_concurrent_jobs", reply.max_concurrent_jobs()},
                 {"queue_bound", reply.queue_bound()},
                 {"max_upload_bytes", reply.max_upload_bytes()},
                 {"max_image_pixels", reply.max_image_pixels()},
                 {"max_views", reply.max_views()},
                 {"max_samples", reply.max_samples()},
                 {"max_voxels", reply.max_voxels()},
                 {"max_frames", reply.max_frames()},
                 {"max_points", reply.max_points()}};
  j["stats"] = {{"scatter_computations", s.scatter_computations()},
                {"views_from_cache", s.views_from_cache()},
                {"bakes_from_cache", s.bakes_from_cache()},
                {"volume_builds", s.volume_builds()},
                {"jobs_submitted", s.jobs_submitted()},
                {"jobs_queued", s.jobs_queued()},
                {"jobs_running", s.jobs_running()},
                {"cache_hits", s.cache_hits()},
                {"cache_misses", s.cache_misses()},
                {"cache_shared", s.cache_shared()},
                {"cache_shared_across_processes", s.cache_shared_across_processes()},
                {"cache_leases_taken_over", s.cache_leases_taken_over()},
                {"cache_corrupt_dropped", s.cache_corrupt_dropped()},
                {"cache_evicted", s.cache_evicted()},
                {"cache_entries", s.cache_entries()},
                {"cache_bytes", s.cache_bytes()}};
  std::cout << j.dump() << "\n";
}

void printInfoText(const v1::ServerInfo& reply) {
  const v1::ServerStats& s = reply.stats();
  std::cout << "version: " << reply.version() << "\nworker threads: " << reply.worker_threads()
            << "\nmethods:";
  for (const auto& m : reply.methods()) std::cout << " " << m;
  std::cout << "\njobs: " << s.jobs_submitted() << " submitted, " << s.jobs_queued() << " queued, "
            << s.jobs_running() << " running\nscattering computations: " << s.scatter_computations()
            << " (views from cache: " << s.views_from_cache()
            << ", bakes from cache: " << s.bakes_from_cache() << ")\ncache: " << s.cache_entries()
            << " entries, " << s.cache_bytes() << " bytes, " << s.cache_hits() << " hits, "
            << s.cache_misses() << " misses\n"
            << "limits: " << reply.max_concurrent_jobs() << " concurrent job(s), queue "
            << reply.queue_bound() << ", upload " << reply.max_upload_bytes() << " bytes, image "
            << reply.max_image_pixels() << " pixels, " << reply.max_views() << " views, "
            << reply.max_samples() << " spp, " << reply.max_voxels() << " voxels, "
            << reply.max_frames() << " frames, " << reply.max_points()
            << " points (0: unlimited)\n";
}

int cmdInfo(Client& c) {
  c.connect();
  grpc::ClientContext ctx;
  c.shortCall(&ctx);
  v1::ServerInfo reply;
  check(c.stub->GetServerInfo(&ctx, {}, &reply), c.server);
  if (c.json)
    printInfoJson(c, reply);
  else
    printInfoText(reply);
  return ExitCode::kOk;
}

// ---- job commands ------------------------------------------------------------------------

void printJob(const Client& c, const v1::Job& j) {
  if (c.json) {
    std::cout << jobJson(j).dump() << "\n";
    return;
  }
  std::cout << "id:       " << j.id() << "\nstate:    " << stateName(j.state())
            << "\nshot:     " << j.shot_name() << " (" << j.method() << ")\nstage:    " << j.stage()
            << " " << int(std::round(j.fraction() * 100)) << "%\n";
  if (!j.error().empty()) std::cout << "error:    " << j.error() << "\n";
  if (j.bakes_computed() + j.bakes_cached() > 0) {
    std::cout << "bake:     " << (j.bakes_computed() ? "computed" : "from cache") << ", "
              << j.views_from_bake() << " view(s) rendered from it\n";
  } else {
    std::cout << "views:    " << j.views_rendered() << " rendered, " << j.views_cached()
              << " from cache\n";
  }
  for (const auto& o : j.outputs()) {
    std::cout << "output:   " << o.name() << " " << o.size() << " bytes sha256 " << o.sha256()
              << "\n";
  }
}

/// Arguments of the commands that name a job (status, watch, list, cancel, fetch, render).
struct JobArgs {
  std::string job_id, out_dir, name, views_file, state_filter;
  unsigned limit = 0;
  std::vector<double> sun;
  bool quiet = false;
  bool png = false;
};

int cmdWatch(Client& c, const std::string& id) {
  const v1::Job job = watch(c, id, false);
  if (c.json)
    std::cout << jobJson(job).dump() << "\n";
  else
    std::cout << job.id() << " " << stateName(job.state()) << "\n";
  return jobExitCode(job);
}

int cmdList(Client& c, const JobArgs& a) {
  grpc::ClientContext ctx;
  c.shortCall(&ctx);
  v1::ListJobsRequest req;
  if (!a.state_filter.empty()) {
    v1::JobState s = v1::JOB_STATE_UNSPECIFIED;
    v1::JobState_Parse(a.state_filter, &s);
    req.set_state(s);
  }
  req.set_limit(a.limit);
  v1::ListJobsResponse reply;
  check(c.stub->ListJobs(&ctx, req, &reply), "list");
  Json jobs = Json::array();
  for (const auto& j : reply.jobs()) {
    if (c.json)
      jobs.push_back(jobJson(j));
    else {
      std::printf("%s  %-9s %3d%%  %s\n", j.id().c_str(), stateName(j.state()),
                  int(std::round(j.fraction() * 100)), j.shot_name().c_str());
    }
  }
  if (c.json) std::cout << jobs.dump() << "\n";
  return ExitCode::kOk;
}

int cmdCancel(Client& c, const std::string& id) {
  grpc::ClientContext ctx;
  c.shortCall(&ctx);
  v1::CancelJobRequest req;
  req.set_job_id(id);
  v1::Job job;
  check(c.stub->CancelJob(&ctx, req, &job), "cancel " + id);
  if (c.json)
    std::cout << jobJson(job).dump() << "\n";
  else {
    std::cout << job.id() << " "
              << (job.state() == v1::RUNNING ? "cancelling" : stateName(job.state())) << "\n";
  }
  return ExitCode::kOk;
}

int cmdRender(Client& c, const JobArgs& a) {
  v1::RenderViewRequest req;
  req.set_job_id(a.job_id);
  if (!a.views_file.empty()) {
    std::ifstream in(a.views_file, std::ios::binary);
    if (!in) throw CliError{ExitCode::kNotFound, a.views_file + ": file not found"};
    req.set_views_json(std::string(std::istreambuf_iterator<char>(in), {}));
    if (req.views_json().size() > kMaxRequestBytes) {
      throw tooLarge(a.views_file + ": views file", req.views_json().size());
    }
    checkUtf8(req.views_json(), "--views " + a.views_file);
    // An empty views_json means "the shot's own views" to the server: an empty file given on
    // purpose must not silently render those again.
    if (req.views_json().empty()) {
      throw CliError{ExitCode::kBadInput, "--views " + a.views_file +
                                              ": the file is empty (expected a JSON array of "
                                              "views)"};
    }
  }
  for (double v : a.sun) req.add_sun_irradiance(v);
  grpc::ClientContext ctx;
  c.shortCall(&ctx);
  v1::SubmitJobResponse reply;
  check(c.stub->RenderView(&ctx, req, &reply), "render " + a.job_id);
  if (!c.json) std::fprintf(stderr, "job %s submitted\n", reply.job().id().c_str());
  return finishJob(c, watch(c, reply.job().id(), a.quiet), a.out_dir);
}

// ---- command line ------------------------------------------------------------------------

struct Commands {
  CLI::App *health, *info, *submit, *status, *watch, *list, *cancel, *fetch, *render;
};

/// Options of every command; `deadline_s` 0: no deadline.
void addGlobalOptions(CLI::App& app, Client* c, double* deadline_s, std::string* token_file) {
  const char* env_server = std::getenv("CLOUDBAKE_SERVER");
  c->server = env_server && *env_server ? env_server : "127.0.0.1:50051";
  app.add_option("--server", c->server, "HOST:PORT of cloudbake-server (env CLOUDBAKE_SERVER)");
  app.add_option("--timeout", c->timeout_s, "deadline in seconds for connecting and short calls")
      ->check(cloudbake::numberIn(0, 1e6, true));
  app.add_option("--deadline", *deadline_s,
                 "seconds the whole command may take (uploads, submit, watch, fetch); on expiry "
                 "exit 4 and the job goes on (default: none)")
      ->check(cloudbake::numberIn(0, 1e7, true));
  app.add_flag("--json", c->json, "machine-readable output on stdout (logs stay on stderr)");
  app.add_option("--retry-seconds", c->retry_s,
                 "how long submit retries when the server's queue is full or the server is "
                 "briefly unavailable (exponential backoff with jitter; 0: no retry)")
      ->check(cloudbake::numberIn(0, 86400))
      ->capture_default_str();
  app.add_flag("--tls", c->tls, "connect with TLS, trusting the system's CA certificates");
  app.add_option("--tls-ca", c->tls_ca,
                 "connect with TLS, trusting this PEM CA certificate (env CLOUDBAKE_TLS_CA)")
      ->envname("CLOUDBAKE_TLS_CA");
  app.add_option("--token-file", *token_file,
                 "file holding the bearer token to send (env CLOUDBAKE_TOKEN_FILE; or the token "
                 "itself in env CLOUDBAKE_TOKEN)")
      ->envname("CLOUDBAKE_TOKEN_FILE");
  app.add_flag("--wait-for-server", c->wait_for_server,
               "keep trying to connect until --timeout instead of failing at once when the "
               "connection is refused (e.g. while the server starts)");
  app.set_version_flag("--version", std::string("cloudctl ") + CLOUDBAKE_VERSION);
  app.require_subcommand(1);
  app.fallthrough();  // --json, --server, --timeout also after the command
}

CLI::App* addSubmitCommand(CLI::App& app, SubmitArgs* sa) {
  auto* submit = app.add_subcommand("submit", "submit a shot; by default wait and download");
  submit->add_option("shot", sa->shot, "shot file (JSON, format v1)")->required();
  submit->add_option(
      "--out", sa->out,
      "download the outputs here (DIR/<view>.exr, DIR/bake.vdb; frame sequences for precomputed)");
  submit->add_flag("--wait", sa->wait, "wait for the job, showing progress (default)");
  submit->add_flag("--detach", sa->detach, "print the job id and return at once");
  submit->add_flag("--dry-run", sa->dry_run, "print the server's plan; bake nothing");
  submit->add_flag("--quiet", sa->quiet, "no progress on stderr");
  submit->add_option("--samples", sa->samples, "override bake.samples (1..1000000)")
      ->each([sa](const std::string&) { sa->samples_given = true; });
  submit->add_flag("--allow-outside", sa->allow_outside,
                   "also upload files the shot names outside its folder (absolute or ../ paths)");
  submit->add_flag("--png", sa->png,
                   "also write an auto-exposed sRGB preview DIR/<view>.png beside each "
                   "downloaded EXR (display only: the EXR is the product)");
  submit->add_option("--sun-tolerance", sa->sun_tolerance_deg,
                     "reuse a cached bake whose sun direction is within DEG degrees (default 0)");
  return submit;
}

Commands addCommands(CLI::App& app, SubmitArgs* sa, JobArgs* ja) {
  Commands cmd;
  cmd.health = app.add_subcommand("health", "check that the server is serving");
  cmd.info = app.add_subcommand("info", "the server's version, methods, limits and counters");
  cmd.submit = addSubmitCommand(app, sa);
  cmd.status = app.add_subcommand("status", "show a job");
  cmd.status->add_option("job", ja->job_id, "job id")->required();
  cmd.watch = app.add_subcommand("watch", "follow a job's progress until it ends");
  cmd.watch->add_option("job", ja->job_id, "job id")->required();
  cmd.list = app.add_subcommand("list", "list jobs, newest first");
  cmd.list->add_option("--state", ja->state_filter, "QUEUED|RUNNING|SUCCEEDED|FAILED|CANCELLED")
      ->check(CLI::IsMember({"QUEUED", "RUNNING", "SUCCEEDED", "FAILED", "CANCELLED"}));
  cmd.list->add_option("--limit", ja->limit, "at most this many (0: all)");
  cmd.cancel = app.add_subcommand("cancel", "cancel a queued or running job");
  cmd.cancel->add_option("job", ja->job_id, "job id")->required();
  cmd.fetch = app.add_subcommand("fetch", "download a succeeded job's outputs");
  cmd.fetch->add_option("job", ja->job_id, "job id")->required();
  cmd.fetch->add_option("--out", ja->out_dir, "folder (default: current)");
  cmd.fetch->add_option("--name", ja->name, "only this output (e.g. nadir.exr)");
  cmd.fetch->add_flag("--png", ja->png, "also write a PNG preview beside each EXR");
  cmd.render = app.add_subcommand("render", "render new views of a job's shot from the cache");
  cmd.render->add_option("job", ja->job_id, "job id")->required();
  cmd.render->add_option("--views", ja->views_file, "JSON file with an array of shot-format views");
  cmd.render->add_option("--sun", ja->sun, "new sun irradiance R G B")->expected(3);
  cmd.render->add_option("--out", ja->out_dir, "download the new views here");
  cmd.render->add_flag("--quiet", ja->quiet, "no progress on stderr");
  cmd.render->add_flag("--png", ja->png, "also write a PNG preview beside each EXR");
  return cmd;
}

// A typo in --server read "server unavailable" (exit 4, inviting a retry) after gRPC failed to
// resolve it. Targets with a scheme gRPC knows are its to check; anything else must be
// HOST:PORT.
void checkServerAddress(const std::string& server) {
  for (const char* scheme : {"dns:", "unix:", "unix-abstract:", "ipv4:", "ipv6:", "vsock:"}) {
    if (server.rfind(scheme, 0) == 0 && server.size() > std::string(scheme).size()) return;
  }
  const size_t colon = server.rfind(':');
  const std::string host = colon == std::string::npos ? "" : server.substr(0, colon);
  const std::string port = colon == std::string::npos ? "" : server.substr(colon + 1);
  // An IPv6 address in brackets, or a name or IPv4 address with no brackets or colons.
  const bool bracketed = host.size() > 2 && host.front() == '[' && host.back() == ']';
  const std::string inner = bracketed ? host.substr(1, host.size() - 2) : host;
  bool host_ok =
      !inner.empty() && inner.find_first_of("[]") == std::string::npos &&
      (bracketed ? inner.find(':') != std::string::npos : inner.find(':') == std::string::npos);
  for (unsigned char ch : inner) host_ok = host_ok && ch > ' ' && ch != '/' && ch != 0x7f;
  bool port_ok = !port.empty() && port.size() <= 5;
  for (char ch : port) port_ok = port_ok && ch >= '0' && ch <= '9';
  if (port_ok) port_ok = std::stoi(port) >= 1 && std::stoi(port) <= 65535;
  if (host_ok && port_ok) return;
  throw CliError{ExitCode::kBadInput,
                 "--server (or CLOUDBAKE_SERVER): expected HOST:PORT with a port in 1..65535, "
                 "[IPV6]:PORT or a gRPC target such as unix:PATH, got '" +
                     cloudbake::printable(server) + "'"};
}

int runCommand(const Commands& cmd, Client& c, const SubmitArgs& sa, const JobArgs& ja) {
  checkServerAddress(c.server);
  c.png = sa.png || ja.png;
  // These connect themselves: submit only once the shot file has been read.
  if (cmd.health->parsed()) return cmdHealth(c);
  if (cmd.info->parsed()) return cmdInfo(c);
  if (cmd.submit->parsed()) return cmdSubmit(c, sa);
  c.connect();
  if (cmd.status->parsed()) {
    printJob(c, getJob(c, ja.job_id));
    return ExitCode::kOk;
  }
  if (cmd.watch->parsed()) return cmdWatch(c, ja.job_id);
  if (cmd.list->parsed()) return cmdList(c, ja);
  if (cmd.cancel->parsed()) return cmdCancel(c, ja.job_id);
  if (cmd.fetch->parsed()) {
    return fetchAll(c, getJob(c, ja.job_id), ja.out_dir.empty() ? "." : ja.out_dir, ja.name);
  }
  if (cmd.render->parsed()) return cmdRender(c, ja);
  return ExitCode::kOk;
}

// Failures other than CliError. Ours (sha256File's InputError) read like a CliError; anything
// else is cloudctl's own error.
int reportError(std::exception_ptr error) {
  const cloudbake::ClassifiedError e = cloudbake::classifyException(error);
  std::cerr << "cloudctl: " << (e.kind == cloudbake::ErrorKind::kInternal ? "error: " : "")
            << e.message << "\n";
  return cloudbake::exitCodeFor(e.kind);
}

// The global options that take a value, as "--name": the word after one is its value, not a
// mistyped command (a `--retry-seconds 1e9` out of range was called an unknown command '1e9').
std::vector<std::string> valueOptions(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::Option* o : app.get_options()) {
    if (o->get_items_expected_max() == 0) continue;  // a flag (CLI11 2.1 keeps its type size 1)
    for (const std::string& n : o->get_lnames()) names.push_back("--" + n);
  }
  return names;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"cloudctl: client of cloudbake-server"};
  Client c;
  double deadline_s = 0;
  std::string token_file;
  addGlobalOptions(app, &c, &deadline_s, &token_file);
  SubmitArgs sa;
  JobArgs ja;
  const Commands cmd = addCommands(app, &sa, &ja);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    std::vector<std::string> commands;
    for (const CLI::App* sub : app.get_subcommands({})) commands.push_back(sub->get_name());
    const std::string typo = cloudbake::unknownCommand(argc, argv, commands, valueOptions(app));
    if (!typo.empty()) {
      std::cerr << "cloudctl: " << cloudbake::unknownCommandMessage(typo, commands) << "\n";
      return ExitCode::kBadInput;
    }
    const int code = app.exit(e);
    return code == 0 ? ExitCode::kOk : ExitCode::kBadInput;
  }
  if (deadline_s > 0) {
    c.command_deadline = std::chrono::system_clock::now() +
                         std::chrono::microseconds(static_cast<long>(deadline_s * 1e6));
  }
  try {
    c.token = readToken(token_file);
    return cloudbake::checkStdout(runCommand(cmd, c, sa, ja), "cloudctl");
  } catch (const CliError& e) {
    std::cerr << "cloudctl: " << e.message << "\n";
    return cloudbake::checkStdout(e.code, "cloudctl");
  } catch (...) {
    return cloudbake::checkStdout(reportError(std::current_exception()), "cloudctl");
  }
}
