// Prometheus metrics of cloudbake-server over HTTP (--metrics-listen): the counters ServerInfo
// reports, jobs by state, queue depth, stream and transfer counters, and per-method histograms of
// job, bake and view seconds. Names follow Prometheus conventions (docs/deployment.md,
// "Metrics").
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "core/job/job_manager.h"

namespace prometheus {
class Exposer;
class Registry;
}  // namespace prometheus

namespace cloudbake::server {

/// What the metrics read at each scrape (dependencies passed in, TF Serving style).
struct MetricsSources {
  std::function<JobManagerStats()> stats;
  std::function<uint64_t()> upload_bytes;
  std::function<uint64_t()> fetch_bytes;
  std::function<size_t()> open_streams;
};

class ServerMetrics {
 public:
  ServerMetrics();
  ~ServerMetrics();
  ServerMetrics(const ServerMetrics&) = delete;
  ServerMetrics& operator=(const ServerMetrics&) = delete;

  /// Records a finished job into the histograms (JobManagerOptions::on_job_finished).
  void observe(const JobFinished& job);
  /// Serves GET /metrics on `listen` (HOST:PORT; port 0: any free port). Throws
  /// std::runtime_error naming the address when it cannot be bound.
  void serve(const std::string& listen, MetricsSources sources);
  /// From now on scrapes read nothing from the sources (which may then be destroyed).
  void detach();
  /// Closes the endpoint (waiting for a scrape in progress); observe() still works.
  void stop();
  /// The bound port, once serving; 0 before.
  int port() const;

 private:
  class Histograms;
  class Snapshot;
  std::shared_ptr<prometheus::Registry> registry_;
  std::unique_ptr<Histograms> histograms_;
  std::shared_ptr<Snapshot> snapshot_;
  std::unique_ptr<prometheus::Exposer> exposer_;
};

}  // namespace cloudbake::server
