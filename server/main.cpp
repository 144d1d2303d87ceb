// cloudbake-server: serves cloudbake.v1.BakeService, the standard health service and reflection.
// Flags and environment variables are documented in docs/api.md ("Server").
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <cctype>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <string_view>
#include <thread>

#include "common/cli_number.h"
#include "common/exit_codes.h"
#include "core/error.h"
#include "core/io/exr_io.h"
#include "core/job/file_util.h"
#include "core/job/job_record.h"
#include "core/volume/vdb_transcode.h"
#include "server/auth.h"
#include "server/bake_service.h"
#include "server/metrics.h"

namespace {

grpc::Server* g_server = nullptr;

void onSignal(int) {
  // Shutdown() is not async-signal-safe, so hand it to a detached thread.
  // With a deadline: open WatchJob streams are cancelled after it instead of blocking exit.
  if (g_server) {
    std::thread([] {
      g_server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
    }).detach();
  }
}

// `%*` in the JSON log pattern: the message as a JSON string body (quotes, backslashes and
// control characters escaped), so every line parses whatever a message contains.
class JsonMessageFlag : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    static const char* kHex = "0123456789abcdef";
    for (char ch : std::string_view(msg.payload.data(), msg.payload.size())) {
      const auto c = static_cast<unsigned char>(ch);
      if (c == '"' || c == '\\') {
        dest.push_back('\\');
        dest.push_back(ch);
      } else if (c < 0x20) {
        const char esc[] = {'\\', 'u', '0', '0', kHex[c >> 4], kHex[c & 15]};
        dest.append(esc, esc + 6);
      } else {
        dest.push_back(ch);
      }
    }
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return spdlog::details::make_unique<JsonMessageFlag>();
  }
};

// `%J` in the JSON log pattern: `,"job":"<id>"` when the message is about one job (it starts
// "job <id>: ", the convention of every job's log line), else nothing.
class JsonJobFlag : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    const std::string_view text(msg.payload.data(), msg.payload.size());
    if (text.rfind("job ", 0) != 0) return;
    const size_t colon = text.find(':', 4);
    if (colon == std::string_view::npos) return;
    const std::string id(text.substr(4, colon - 4));
    if (!cloudbake::isJobId(id)) return;
    const std::string field = R"(,"job":")" + id + "\"";
    dest.append(field.data(), field.data() + field.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return spdlog::details::make_unique<JsonJobFlag>();
  }
};

std::string defaultStateDir() {
  const char* xdg = std::getenv("XDG_STATE_HOME");
  if (xdg && *xdg) return std::string(xdg) + "/cloudbake";
  const char* home = std::getenv("HOME");
  return std::string(home && *home ? home : "/tmp") + "/.local/state/cloudbake";
}

// HOST:PORT for --listen and --metrics-listen, the port 0 (any free port) to 65535: gRPC
// wrapped a port past it silently (70000 listened on 4464) and took an empty one as 443.
CLI::Validator listenAddress(bool empty_is_off = false) {
  return CLI::Validator(
      [empty_is_off](std::string& text) -> std::string {
        if (empty_is_off && text.empty()) return "";
        const size_t colon = text.rfind(':');
        const std::string host = colon == std::string::npos ? "" : text.substr(0, colon);
        const std::string port = colon == std::string::npos ? "" : text.substr(colon + 1);
        bool ok = !host.empty() && !port.empty() && port.size() <= 5;
        for (char ch : port) ok = ok && ch >= '0' && ch <= '9';
        if (ok && std::stoi(port) <= 65535) return "";
        return "expected HOST:PORT with a port in 0..65535 (0: any free port), got '" + text + "'";
      },
      "HOST:PORT");
}

// A byte count, bare or with a unit (b, k/kb/kib, m/mb/mib, g/gb/gib, t/tb/tib: powers of 1024,
// any case), rewritten as the bare count. CLI::AsSizeValue wrapped a negative count to 2^64 - 1
// and let 2^64 through.
CLI::Validator byteCount() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        size_t digits = 0;
        while (digits < text.size() && text[digits] >= '0' && text[digits] <= '9') ++digits;
        std::string unit = text.substr(digits);
        for (char& ch : unit) ch = char(std::tolower(static_cast<unsigned char>(ch)));
        static const std::pair<const char*, int> kUnits[] = {
            {"", 0},    {"b", 0}, {"k", 1},  {"kb", 1},  {"kib", 1}, {"m", 2},  {"mb", 2},
            {"mib", 2}, {"g", 3}, {"gb", 3}, {"gib", 3}, {"t", 4},   {"tb", 4}, {"tib", 4}};
        int power = -1;
        for (const auto& [name, p] : kUnits) {
          if (unit == name) power = p;
        }
        if (digits == 0 || digits > 19 || power < 0) {
          return "expected a byte count such as 1048576, 512MB or 2GB, got '" + text + "'";
        }
        const unsigned long long count = std::stoull(text.substr(0, digits));
        if (count > (std::numeric_limits<uint64_t>::max() >> 1 >> (10 * power))) {
          return "more bytes than the server counts (2^63): '" + text + "'";
        }
        text = std::to_string(uint64_t(count) << (10 * power));
        return "";
      },
      "BYTES");
}

struct ServerFlags {
  ServerFlags() { jobs.state_dir = defaultStateDir(); }

  std::string listen = "127.0.0.1:50051";
  std::string metrics_listen;     // empty: no metrics endpoint
  std::string tls_cert, tls_key;  // PEM files; both or neither
  std::string auth_tokens;        // file of 'NAME TOKEN' lines; empty: no authentication
  std::string reflection = "auto";
  std::string log_level = "info";
  bool log_json = false;
  cloudbake::JobManagerOptions jobs;
  // Flag types that CLI11 range-checks; applyLimitFlags copies them into jobs.limits.
  uint64_t max_image_pixels = uint64_t(jobs.limits.max_image_pixels);
  uint64_t max_samples = uint64_t(jobs.limits.max_samples);
  unsigned max_views = unsigned(jobs.limits.max_views);
  size_t max_streams = 256;
  double keep_jobs_hours = jobs.keep_finished_seconds / 3600.0;
  double scrub_hours = jobs.scrub_interval_seconds / 3600.0;
  bool vdb_in_process = false;
};

// The farm executor's flags (docs/deployment.md, "Farm").
void addExecutorOptions(CLI::App& app, ServerFlags* f) {
  cloudbake::JobManagerOptions& o = f->jobs;
  app.add_option("--executor", o.executor,
                 "where jobs run: local (this process) or slurm (farm tasks on the cluster of "
                 "sbatch; needs --shared-dir; docs/deployment.md)")
      ->envname("CLOUDBAKE_EXECUTOR")
      ->check(CLI::IsMember({"local", "slurm"}))
      ->capture_default_str();
  app.add_option("--slurm-cloudbake", o.slurm.cloudbake,
                 "the cloudbake binary as the Slurm nodes run it (default: the one installed "
                 "beside this server)")
      ->envname("CLOUDBAKE_SLURM_CLOUDBAKE");
  app.add_option("--slurm-tasks", o.slurm.tasks, "most farm tasks per stage of a job")
      ->envname("CLOUDBAKE_SLURM_TASKS")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  app.add_option("--slurm-cpus-per-task", o.slurm.cpus_per_task, "CPUs each farm task asks")
      ->envname("CLOUDBAKE_SLURM_CPUS_PER_TASK")
      ->check(CLI::Range(1, 4096))
      ->capture_default_str();
  app.add_option("--slurm-partition", o.slurm.partition, "Slurm partition (default: the default)")
      ->envname("CLOUDBAKE_SLURM_PARTITION");
  app.add_option("--slurm-retries", o.slurm.retries, "extra attempts of a failed farm task")
      ->envname("CLOUDBAKE_SLURM_RETRIES")
      ->check(CLI::Range(0, 10))
      ->capture_default_str();
}

void addServiceOptions(CLI::App& app, ServerFlags* f) {
  cloudbake::JobManagerOptions& o = f->jobs;
  app.add_option("--listen", f->listen, "HOST:PORT to listen on (port 0: any free port)")
      ->envname("CLOUDBAKE_LISTEN")
      ->check(listenAddress())
      ->capture_default_str();
  app.add_option("--cache-dir", o.state_dir,
                 "folder for the job store, result cache and uploaded assets")
      ->envname("CLOUDBAKE_CACHE_DIR")
      ->capture_default_str();
  app.add_option("--shared-dir", o.shared_dir,
                 "folder shared with other replicas and farm tasks (may be NFS): the result "
                 "cache lives there, so one replica's bake is a hit on the others "
                 "(docs/deployment.md)")
      ->envname("CLOUDBAKE_SHARED_DIR");
  app.add_option("--cache-size", o.cache_max_bytes,
                 "bound of the result cache (bytes, or with a unit: 512MB, 2GB; 0: unbounded)")
      ->envname("CLOUDBAKE_CACHE_SIZE")
      ->transform(byteCount())
      ->capture_default_str();
  app.add_option("--threads", o.worker_threads,
                 "threads of each job's TBB arena, and of OpenEXR's compression (0: all cores)")
      ->envname("CLOUDBAKE_THREADS")
      ->check(CLI::Range(0u, 4096u))
      ->capture_default_str();
  app.add_option("--max-concurrent-jobs", o.max_concurrent_jobs, "jobs running at once")
      ->envname("CLOUDBAKE_MAX_CONCURRENT_JOBS")
      ->check(CLI::Range(1u, 256u))
      ->capture_default_str();
  app.add_option("--queue-bound", o.queue_bound,
                 "queued jobs plus submits and dry runs being prepared, beyond which they fail "
                 "with RESOURCE_EXHAUSTED")
      ->envname("CLOUDBAKE_QUEUE_BOUND")
      ->check(CLI::Range(size_t(1), size_t(100000)))
      ->capture_default_str();
  app.add_option("--max-streams", f->max_streams,
                 "streaming calls (uploads, watches, fetches) open at once; more get "
                 "RESOURCE_EXHAUSTED")
      ->envname("CLOUDBAKE_MAX_STREAMS")
      ->check(CLI::Range(size_t(1), size_t(100000)))
      ->capture_default_str();
  app.add_option("--max-job-seconds", o.max_job_seconds,
                 "wall-clock seconds a job may run before it is stopped and FAILED (0: no limit)")
      ->envname("CLOUDBAKE_MAX_JOB_SECONDS")
      ->check(cloudbake::numberIn(0, 1e9))
      ->capture_default_str();
  app.add_option("--keep-jobs-hours", f->keep_jobs_hours,
                 "finished jobs (records, inputs, outputs) older than this are pruned, unless a "
                 "client touched them in the last 10 minutes (0: kept forever)")
      ->envname("CLOUDBAKE_KEEP_JOBS_HOURS")
      ->check(cloudbake::numberIn(0, 1e6))
      ->capture_default_str();
  app.add_option("--scrub-hours", f->scrub_hours,
                 "every stored output and asset is hashed again this often: corrupt assets are "
                 "dropped, corrupt outputs rebuilt from the cache when they can be (0: never)")
      ->envname("CLOUDBAKE_SCRUB_HOURS")
      ->check(cloudbake::numberIn(0, 1e6))
      ->capture_default_str();
  app.add_option("--max-finished-jobs", o.max_finished_jobs,
                 "finished jobs kept at most; the oldest beyond it are pruned (0: no limit)")
      ->envname("CLOUDBAKE_MAX_FINISHED_JOBS")
      ->check(CLI::Range(size_t(0), size_t(100000000)))
      ->capture_default_str();
  app.add_option("--max-upload-bytes", o.max_upload_bytes, "largest asset upload")
      ->envname("CLOUDBAKE_MAX_UPLOAD_BYTES")
      ->transform(byteCount())
      ->capture_default_str();
}

void addLimitOptions(CLI::App& app, ServerFlags* f) {
  cloudbake::JobLimits& limits = f->jobs.limits;
  app.add_option("--max-image-pixels", f->max_image_pixels, "largest view (width x height)")
      ->envname("CLOUDBAKE_MAX_IMAGE_PIXELS")
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 26))
      ->capture_default_str();
  app.add_option("--max-views", f->max_views, "most views per shot")
      ->envname("CLOUDBAKE_MAX_VIEWS")
      ->check(CLI::Range(1u, 256u))
      ->capture_default_str();
  app.add_flag("--vdb-in-process", f->vdb_in_process,
               "read users' VDB files in the server process (default: each is rewritten first "
               "by a child process, so a file that crashes OpenVDB fails its job only)")
      ->envname("CLOUDBAKE_VDB_IN_PROCESS");
  app.add_option("--max-samples", f->max_samples, "most samples per pixel")
      ->envname("CLOUDBAKE_MAX_SAMPLES")
      ->check(CLI::Range(uint64_t(1), uint64_t(1000000)))
      ->capture_default_str();
  app.add_option("--max-voxels", limits.max_voxels,
                 "most voxels of a shot's volume (mesh resolution^3 or box, procedural grid, VDB "
                 "active voxels, bake.vdb grid of a box or sphere; 0: no limit)")
      ->envname("CLOUDBAKE_MAX_VOXELS")
      ->check(CLI::Range(uint64_t(0), uint64_t(1) << 40))
      ->capture_default_str();
  app.add_option("--max-frames", limits.max_frames,
                 "most frames of an animated volume (volume.sequence; 0: no limit)")
      ->envname("CLOUDBAKE_MAX_FRAMES")
      ->check(CLI::Range(int64_t(0), int64_t(100000)))
      ->capture_default_str();
  app.add_option("--max-points", limits.max_points,
                 "most points of a point-based bake (bake.points of pointcloud, bake.sample_points "
                 "of precomputed; 0: no limit)")
      ->envname("CLOUDBAKE_MAX_POINTS")
      ->check(CLI::Range(int64_t(0), int64_t(1) << 32))
      ->capture_default_str();
}

void addSecurityOptions(CLI::App& app, ServerFlags* f) {
  app.add_option("--tls-cert", f->tls_cert, "PEM certificate chain: serve TLS (with --tls-key)")
      ->envname("CLOUDBAKE_TLS_CERT")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-key", f->tls_key, "PEM private key of --tls-cert")
      ->envname("CLOUDBAKE_TLS_KEY")
      ->check(CLI::ExistingFile);
  app.add_option("--auth-tokens", f->auth_tokens,
                 "file of 'NAME TOKEN' lines: every call needs 'authorization: Bearer TOKEN', and "
                 "each client sees and acts on its own jobs only (health stays open)")
      ->envname("CLOUDBAKE_AUTH_TOKENS")
      ->check(CLI::ExistingFile);
  app.add_option("--reflection", f->reflection,
                 "gRPC server reflection: on, off, or auto (on only when listening on loopback)")
      ->envname("CLOUDBAKE_REFLECTION")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
}

void addLogOptions(CLI::App& app, ServerFlags* f) {
  app.add_option("--log-level", f->log_level, "trace|debug|info|warn|error")
      ->envname("CLOUDBAKE_LOG_LEVEL")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}))
      ->capture_default_str();
  app.add_flag("--log-json", f->log_json,
               "log one JSON object per line (with a \"job\" field on a job's lines)")
      ->envname("CLOUDBAKE_LOG_JSON");
  app.add_option("--metrics-listen", f->metrics_listen,
                 "HOST:PORT to serve Prometheus metrics on at /metrics (plain HTTP; empty: off)")
      ->envname("CLOUDBAKE_METRICS_LISTEN")
      ->check(listenAddress(/*empty_is_off=*/true))
      ->capture_default_str();
}

void applyLimitFlags(ServerFlags* f) {
  f->jobs.keep_finished_seconds = f->keep_jobs_hours * 3600.0;
  f->jobs.scrub_interval_seconds = f->scrub_hours * 3600.0;
  f->jobs.limits.max_image_pixels = int64_t(f->max_image_pixels);
  f->jobs.limits.max_samples = int64_t(f->max_samples);
  f->jobs.limits.max_views = int(f->max_views);
}

void setUpLogging(const ServerFlags& f) {
  // Logs go to stderr; stdout stays free for tools that wrap the server.
  spdlog::set_default_logger(spdlog::stderr_color_mt("cloudbake-server"));
  spdlog::set_level(spdlog::level::from_str(f.log_level));
  if (f.log_json) {
    auto formatter = std::make_unique<spdlog::pattern_formatter>(spdlog::pattern_time_type::utc);
    formatter->add_flag<JsonMessageFlag>('*').add_flag<JsonJobFlag>('J').set_pattern(
        R"({"time":"%Y-%m-%dT%H:%M:%S.%fZ","level":"%l","thread":%t%J,"message":"%*"})");
    spdlog::set_formatter(std::move(formatter));
  }
}

bool loopbackHost(const std::string& listen) {
  const std::string host = listen.substr(0, listen.rfind(':'));
  return host == "127.0.0.1" || host == "localhost" || host == "[::1]" || host == "::1";
}

/// TLS credentials from the flags, or insecure ones without them. Throws std::runtime_error.
std::shared_ptr<grpc::ServerCredentials> serverCredentials(const ServerFlags& f) {
  if (f.tls_cert.empty() && f.tls_key.empty()) return grpc::InsecureServerCredentials();
  if (f.tls_cert.empty() || f.tls_key.empty()) {
    throw std::runtime_error("--tls-cert and --tls-key go together");
  }
  // gRPC refuses a file that is not PEM only when it binds, which read as "cannot listen on"
  // (exit 4) with the cause in its own log lines: the files are checked here, by name.
  const std::string cert = cloudbake::readWholeFile(f.tls_cert);
  const std::string key = cloudbake::readWholeFile(f.tls_key);
  if (cert.find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
    throw std::runtime_error("--tls-cert " + f.tls_cert + ": not a PEM certificate chain");
  }
  if (key.find("-----BEGIN") == std::string::npos ||
      key.find("PRIVATE KEY-----") == std::string::npos) {
    throw std::runtime_error("--tls-key " + f.tls_key + ": not a PEM private key");
  }
  grpc::SslServerCredentialsOptions ssl;
  ssl.pem_key_cert_pairs.push_back({key, cert});
  return grpc::SslServerCredentials(ssl);
}

/// Null, or *bound_port 0, when `listen` cannot be bound.
std::unique_ptr<grpc::Server> startServer(const ServerFlags& f, grpc::Service* service,
                                          int* bound_port) {
  const std::string& listen = f.listen;
  grpc::EnableDefaultHealthCheckService(true);
  // Reflection describes the whole API to anyone who connects: by default only on loopback.
  if (f.reflection == "on" || (f.reflection == "auto" && loopbackHost(listen))) {
    grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  }
  grpc::ServerBuilder builder;
  // Without this gRPC sets SO_REUSEPORT and a second server on the same port starts silently,
  // sharing connections with the first.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // A fixed 4 MiB receive window per stream instead of BDP auto-tuning: uploads of hundreds of
  // MB then buffer at most a few MiB in the server (auto-tuning let a fast client grow it by
  // tens of MiB, docs/api.md "Large files"), and 4 MiB still fills a 100 ms link at 40 MB/s.
  builder.AddChannelArgument(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, 4 << 20);
  builder.AddListeningPort(listen, serverCredentials(f), bound_port);
  builder.RegisterService(service);
  return builder.BuildAndStart();
}

constexpr const char* kTranscodeVdbFlag = "--transcode-vdb";

// The child's work: read IN with OpenVDB and write OUT (exit 0), or say why not (exit 2; 4 when
// the rewrite's volume is full). A crash
// inside OpenVDB ends this process, which the parent reports as the file's fault.
int transcodeVdbChild(const char* in, const char* out) {
  const rlimit no_core{0, 0};
  setrlimit(RLIMIT_CORE, &no_core);
  try {
    cloudbake::transcodeVdb(in, out);
    return cloudbake::kOk;
  } catch (const cloudbake::InputError& e) {
    std::fprintf(stderr, "cloudbake-server: error: %s\n", e.what());
    return cloudbake::kBadInput;
  } catch (const cloudbake::StorageFullError& e) {
    // The rewrite's volume is full: the file is not at fault, and a retry may succeed.
    std::fprintf(stderr, "cloudbake-server: error: %s\n", e.detail().c_str());
    return cloudbake::kUnavailable;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cloudbake-server: failed: %s\n", e.what());
    return cloudbake::kFailure;
  }
}

// Jobs write their EXRs after rendering, so OpenEXR's compression threads take the cores the
// job's arena has finished with.
bool startExrThreads(unsigned worker_threads) {
  try {
    cloudbake::setExrThreads(static_cast<int>(worker_threads));
    return true;
  } catch (const std::exception& e) {
    spdlog::error("cannot start OpenEXR's threads: {}", e.what());
    return false;
  }
}

// The job manager's options from the flags, with the paths of this executable's own helpers.
cloudbake::JobManagerOptions jobOptionsFor(const ServerFlags& f) {
  cloudbake::JobManagerOptions o = f.jobs;
  if (!f.vdb_in_process) {
    std::error_code ec;
    o.vdb_reader.command = {std::filesystem::read_symlink("/proc/self/exe", ec).string(),
                            kTranscodeVdbFlag};
  }
  if (o.slurm.cloudbake.empty()) {
    // Installed together (bin/cloudbake beside bin/cloudbake-server), as the nodes run it.
    std::error_code ec;
    o.slurm.cloudbake =
        (std::filesystem::read_symlink("/proc/self/exe", ec).parent_path() / "cloudbake").string();
  }
  return o;
}

/// Opens the state folder, serves until SIGINT/SIGTERM; returns the exit code.
int serve(const ServerFlags& f) {
  cloudbake::JobManagerOptions o = jobOptionsFor(f);
  cloudbake::server::ServerMetrics metrics;
  o.on_job_finished = [&metrics](const cloudbake::JobFinished& job) { metrics.observe(job); };
  if (!startExrThreads(o.worker_threads)) return cloudbake::kFailure;
  std::unique_ptr<cloudbake::JobManager> jobs;
  try {
    jobs = std::make_unique<cloudbake::JobManager>(o);
  } catch (const std::exception& e) {
    spdlog::error("cannot open state folder {}: {}", o.state_dir, e.what());
    return cloudbake::kFailure;
  }
  cloudbake::server::Authenticator auth;
  std::unique_ptr<grpc::Server> server;
  int bound_port = 0;
  try {
    if (!f.auth_tokens.empty()) {
      auth = cloudbake::server::Authenticator(cloudbake::server::TokenTable::load(f.auth_tokens));
    }
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return cloudbake::kBadInput;
  }
  cloudbake::server::BakeServiceImpl service(*jobs, f.max_streams, std::move(auth));
  if (!f.metrics_listen.empty()) {
    try {
      cloudbake::JobManager* manager = jobs.get();
      metrics.serve(f.metrics_listen, {[manager] { return manager->stats(); },
                                       [&service] { return service.uploadBytes(); },
                                       [&service] { return service.fetchBytes(); },
                                       [&service] { return service.openStreams(); }});
    } catch (const std::exception& e) {
      spdlog::error("{}", e.what());
      return cloudbake::kUnavailable;
    }
    const std::string host = f.metrics_listen.substr(0, f.metrics_listen.rfind(':'));
    spdlog::info("metrics on http://{}:{}/metrics", host, metrics.port());
  }
  try {
    server = startServer(f, &service, &bound_port);
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return cloudbake::kBadInput;
  }
  if (!server || bound_port == 0) {
    spdlog::error("cannot listen on {}", f.listen);
    return cloudbake::kUnavailable;
  }
  g_server = server.get();
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  // Report the bound port (useful with port 0, which lets the OS pick one).
  const std::string host = f.listen.substr(0, f.listen.rfind(':'));
  spdlog::info(
      "cloudbake-server {} listening on {}:{} (state {}, {} runner(s), queue bound {}, max "
      "voxels {}, max frames {}, {}, {})",
      CLOUDBAKE_VERSION, host, bound_port, o.state_dir, o.max_concurrent_jobs, o.queue_bound,
      o.limits.max_voxels, o.limits.max_frames, f.tls_cert.empty() ? "plaintext" : "TLS",
      f.auth_tokens.empty() ? "no tokens" : "tokens required");
  server->Wait();
  // The metrics endpoint reads the job manager and the service: detach it before either goes.
  metrics.detach();
  // Streams (WatchJob) end when the job manager stops: stop it before the server is destroyed.
  jobs.reset();
  metrics.stop();
  spdlog::info("cloudbake-server stopped");
  // Not destroyed: gRPC's teardown is skipped on purpose (see main).
  (void)server.release();
  return cloudbake::kOk;
}

}  // namespace

int main(int argc, char** argv) {
  // The child that rewrites a user's VDB file for a job (core/job/vdb_gate.h): not a flag a
  // person types, so it stays out of --help.
  if (argc == 4 && std::string(argv[1]) == kTranscodeVdbFlag) {
    return transcodeVdbChild(argv[2], argv[3]);
  }
  CLI::App app{"cloudbake-server: cloud-lighting bake service (gRPC)"};
  ServerFlags flags;
  addServiceOptions(app, &flags);
  addExecutorOptions(app, &flags);
  addLimitOptions(app, &flags);
  addSecurityOptions(app, &flags);
  addLogOptions(app, &flags);
  app.set_version_flag("--version", std::string("cloudbake-server ") + CLOUDBAKE_VERSION);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? cloudbake::kOk : cloudbake::kBadInput;
  }
  applyLimitFlags(&flags);
  setUpLogging(flags);
  const int code = serve(flags);
  // Everything durable is written and logged by now. Returning would run gRPC's own teardown,
  // which waits for an internal timer: 0.1 s or 10 s at random (grpc 1.51, measured), too long
  // for a pod's grace period. So the process ends here.
  spdlog::shutdown();
  std::fflush(nullptr);
  std::_Exit(code);
}
