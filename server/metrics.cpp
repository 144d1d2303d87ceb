#include "server/metrics.h"

#include <prometheus/collectable.h>
#include <prometheus/exposer.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <mutex>
#include <stdexcept>
#include <utility>
#include <vector>

namespace cloudbake::server {

namespace {

using prometheus::ClientMetric;
using prometheus::MetricFamily;
using prometheus::MetricType;

// Seconds from a quick cached view to a long bake: roughly x2.5 apart, 10 ms to about 3 h.
const prometheus::Histogram::BucketBoundaries& secondsBuckets() {
  static const prometheus::Histogram::BucketBoundaries kBuckets = {
      0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 25, 50, 100, 250, 500, 1000, 2500, 10000};
  return kBuckets;
}

MetricFamily family(const std::string& name, const std::string& help, MetricType type) {
  MetricFamily f;
  f.name = name;
  f.help = help;
  f.type = type;
  return f;
}

void addValue(MetricFamily* f, double value, std::vector<ClientMetric::Label> labels = {}) {
  ClientMetric m;
  m.label = std::move(labels);
  if (f->type == MetricType::Counter) {
    m.counter.value = value;
  } else {
    m.gauge.value = value;
  }
  f->metric.push_back(std::move(m));
}

MetricFamily single(const std::string& name, const std::string& help, MetricType type,
                    double value) {
  MetricFamily f = family(name, help, type);
  addValue(&f, value);
  return f;
}

}  // namespace

/// Per-method histograms, fed as jobs end.
class ServerMetrics::Histograms {
 public:
  explicit Histograms(prometheus::Registry& registry)
      : job_(prometheus::BuildHistogram()
                 .Name("cloudbake_job_seconds")
                 .Help("Wall-clock seconds of finished jobs, by method and outcome")
                 .Register(registry)),
        bake_(prometheus::BuildHistogram()
                  .Name("cloudbake_bake_seconds")
                  .Help("Seconds of light bakes computed (not from cache), by method")
                  .Register(registry)),
        view_(prometheus::BuildHistogram()
                  .Name("cloudbake_view_seconds")
                  .Help("Seconds per view rendered (not from cache), by method")
                  .Register(registry)) {}

  void observe(const JobFinished& job) {
    job_.Add({{"method", job.method}, {"outcome", jobStateName(job.state)}}, secondsBuckets())
        .Observe(job.seconds);
    for (const StepTime& step : job.steps) {
      const auto cached = step.values.find("cached");
      if (cached != step.values.end() && cached->second != 0) continue;
      if (step.step == "bake" || step.step == "precompute") {
        bake_.Add({{"method", job.method}}, secondsBuckets()).Observe(step.seconds);
      } else if (step.step == "view") {
        view_.Add({{"method", job.method}}, secondsBuckets()).Observe(step.seconds);
      }
    }
  }

 private:
  prometheus::Family<prometheus::Histogram>& job_;
  prometheus::Family<prometheus::Histogram>& bake_;
  prometheus::Family<prometheus::Histogram>& view_;
};

/// Counters and gauges read from the job manager and the service at each scrape, so they can
/// never drift from what ServerInfo reports.
class ServerMetrics::Snapshot : public prometheus::Collectable {
 public:
  explicit Snapshot(MetricsSources sources) : sources_(std::move(sources)) {}
  std::vector<MetricFamily> Collect() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    return attached_ ? collectLocked() : std::vector<MetricFamily>{};
  }
  void detach() {
    std::lock_guard<std::mutex> lock(mutex_);
    attached_ = false;
  }

 private:
  std::vector<MetricFamily> collectLocked() const;
  MetricsSources sources_;
  mutable std::mutex mutex_;
  bool attached_ = true;
};

std::vector<MetricFamily> ServerMetrics::Snapshot::collectLocked() const {
  const JobManagerStats s = sources_.stats();
  const auto kC = MetricType::Counter;
  const auto kG = MetricType::Gauge;
  std::vector<MetricFamily> out;
  MetricFamily info = family("cloudbake_build_info", "Version of this server (value 1)", kG);
  addValue(&info, 1, {{"version", CLOUDBAKE_VERSION}});
  out.push_back(std::move(info));
  MetricFamily jobs = family("cloudbake_jobs", "Jobs the server holds, by state", kG);
  const std::pair<const char*, size_t> states[] = {{"QUEUED", s.queued},
                                                   {"RUNNING", s.running},
                                                   {"SUCCEEDED", s.succeeded},
                                                   {"FAILED", s.failed},
                                                   {"CANCELLED", s.cancelled}};
  for (const auto& [state, n] : states) addValue(&jobs, double(n), {{"state", state}});
  out.push_back(std::move(jobs));
  out.push_back(single("cloudbake_queue_depth", "Jobs queued, not yet running", kG, s.queued));
  out.push_back(single("cloudbake_jobs_running", "Jobs running now", kG, s.running));
  out.push_back(
      single("cloudbake_jobs_submitted_total", "Jobs accepted since start", kC, s.jobs_submitted));
  out.push_back(single("cloudbake_scatter_computations_total",
                       "Views path-traced plus lights baked, not from cache", kC,
                       s.scatter_computations));
  out.push_back(single("cloudbake_views_from_cache_total", "Views served from the cache", kC,
                       s.views_from_cache));
  out.push_back(single("cloudbake_bakes_from_cache_total", "Light bakes reused from the cache", kC,
                       s.bakes_from_cache));
  out.push_back(
      single("cloudbake_volume_builds_total", "Density volumes built", kC, s.volume_builds));
  out.push_back(single("cloudbake_cache_hits_total", "Cache lookups served", kC, s.cache.hits));
  out.push_back(
      single("cloudbake_cache_misses_total", "Cache lookups computed", kC, s.cache.misses));
  out.push_back(single("cloudbake_cache_shared_total",
                       "Requests that waited for an identical computation", kC, s.cache.shared));
  out.push_back(single("cloudbake_cache_shared_across_processes_total",
                       "Of them, waits on another process's lease (a replica, a farm task)", kC,
                       s.cache.shared_across_processes));
  out.push_back(single("cloudbake_cache_leases_taken_over_total",
                       "Computations of a key whose lease holder died or stalled", kC,
                       s.cache.leases_taken_over));
  out.push_back(single("cloudbake_cache_evictions_total", "Entries removed by --cache-size", kC,
                       s.cache.evicted));
  out.push_back(single("cloudbake_cache_corrupt_dropped_total",
                       "Entries dropped because a checksum was wrong", kC, s.cache.corrupt));
  out.push_back(single("cloudbake_cache_entries", "Entries held", kG, s.cache.entries));
  out.push_back(single("cloudbake_cache_bytes", "Bytes held by the cache", kG, s.cache.bytes));
  out.push_back(single("cloudbake_outputs_corrupt_total",
                       "Job outputs refused because they no longer match their SHA-256", kC,
                       double(s.outputs_corrupt)));
  out.push_back(single("cloudbake_assets_corrupt_dropped_total",
                       "Stored assets dropped because they no longer hash to their name", kC,
                       double(s.assets_corrupt)));
  out.push_back(single("cloudbake_upload_bytes_total", "Asset bytes received", kC,
                       double(sources_.upload_bytes())));
  out.push_back(single("cloudbake_fetch_bytes_total", "Result bytes sent", kC,
                       double(sources_.fetch_bytes())));
  out.push_back(single("cloudbake_open_streams", "Streaming calls open now", kG,
                       double(sources_.open_streams())));
  return out;
}

ServerMetrics::ServerMetrics()
    : registry_(std::make_shared<prometheus::Registry>()),
      histograms_(std::make_unique<Histograms>(*registry_)) {}

ServerMetrics::~ServerMetrics() = default;

void ServerMetrics::observe(const JobFinished& job) { histograms_->observe(job); }

void ServerMetrics::serve(const std::string& listen, MetricsSources sources) {
  snapshot_ = std::make_shared<Snapshot>(std::move(sources));
  try {
    exposer_ = std::make_unique<prometheus::Exposer>(listen, 1);
  } catch (const std::exception& e) {
    throw std::runtime_error("--metrics-listen " + listen + ": cannot listen (" + e.what() + ")");
  }
  exposer_->RegisterCollectable(registry_);
  exposer_->RegisterCollectable(snapshot_);
}

void ServerMetrics::detach() {
  if (snapshot_) snapshot_->detach();
}

void ServerMetrics::stop() { exposer_.reset(); }

int ServerMetrics::port() const {
  if (!exposer_) return 0;
  const std::vector<int> ports = exposer_->GetListeningPorts();
  return ports.empty() ? 0 : ports.front();
}

}  // namespace cloudbake::server
