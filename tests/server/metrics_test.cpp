// server/metrics: a live server's Prometheus endpoint scraped over HTTP as jobs run, and its JSON
// log lines (a "job" field on a job's lines, one summary line per finished job).
#include <map>
#include <nlohmann/json.hpp>
#include <regex>

#include "tests/server/server_fixture.h"

namespace cloudbake::testing {
namespace {

using Json = nlohmann::json;

/// GET http://127.0.0.1:port/path; the body, or "" when the connection fails.
std::string httpGet(int port, const std::string& path) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(uint16_t(port));
  if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    close(fd);
    return "";
  }
  const std::string request =
      "GET " + path + " HTTP/1.0\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
  if (write(fd, request.data(), request.size()) != ssize_t(request.size())) {
    close(fd);
    return "";
  }
  std::string response;
  char buf[4096];
  ssize_t n;
  while ((n = read(fd, buf, sizeof buf)) > 0) response.append(buf, size_t(n));
  close(fd);
  const size_t body = response.find("\r\n\r\n");
  return body == std::string::npos ? "" : response.substr(body + 4);
}

/// Samples of the text format: "name{labels}" -> value (comments skipped).
std::map<std::string, double> parseMetrics(const std::string& text) {
  std::map<std::string, double> out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const size_t space = line.rfind(' ');
    out[line.substr(0, space)] = std::stod(line.substr(space + 1));
  }
  return out;
}

class MetricsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    metrics_port_ = freePort();
    server_.logTo(ws_.path("server.log"));
    ASSERT_TRUE(server_.start({"--metrics-listen=127.0.0.1:" + std::to_string(metrics_port_),
                               "--log-json", "--log-level=info"}));
  }
  void TearDown() override { EXPECT_TRUE(server_.stop()); }
  std::map<std::string, double> scrape() {
    const std::string body = httpGet(metrics_port_, "/metrics");
    EXPECT_FALSE(body.empty()) << "no answer from the metrics endpoint";
    return parseMetrics(body);
  }
  /// Submits the shot, waits and downloads; returns the bytes downloaded.
  uintmax_t submit(const std::string& shot, const std::string& out) {
    const CmdResult r = run(server_.cloudctl(30) + " submit " + shot + " --out " + out);
    EXPECT_EQ(r.code, 0) << r.err;
    uintmax_t bytes = 0;
    for (const auto& e : std::filesystem::directory_iterator(out)) bytes += e.file_size();
    return bytes;
  }
  Workspace ws_;
  ServerProc server_{ws_.path("state")};
  int metrics_port_ = 0;
};

TEST_F(MetricsTest, CountersMoveAsJobsRunAndHitTheCache) {
  auto m = scrape();
  EXPECT_EQ(m.at(R"(cloudbake_jobs{state="SUCCEEDED"})"), 0);
  EXPECT_EQ(m.at("cloudbake_jobs_submitted_total"), 0);
  EXPECT_EQ(m.at("cloudbake_queue_depth"), 0);
  EXPECT_EQ(m.at("cloudbake_fetch_bytes_total"), 0);
  EXPECT_EQ(m.count(R"(cloudbake_build_info{version=")" CLOUDBAKE_VERSION "\"}"), 1u);

  const std::string shot = ws_.write("sphere.json", sphereShot(16, 4));
  const uintmax_t first = submit(shot, ws_.path("out1"));
  m = scrape();
  EXPECT_EQ(m.at(R"(cloudbake_jobs{state="SUCCEEDED"})"), 1);
  EXPECT_EQ(m.at(R"(cloudbake_jobs{state="RUNNING"})"), 0);
  EXPECT_EQ(m.at("cloudbake_jobs_submitted_total"), 1);
  EXPECT_EQ(m.at("cloudbake_scatter_computations_total"), 1);
  EXPECT_GE(m.at("cloudbake_cache_misses_total"), 1);
  EXPECT_GT(m.at("cloudbake_cache_bytes"), 0);
  EXPECT_EQ(m.at("cloudbake_fetch_bytes_total"), double(first)) << "every byte cloudctl received";
  EXPECT_EQ(m.at(R"(cloudbake_job_seconds_count{method="pathtrace",outcome="SUCCEEDED"})"), 1);
  EXPECT_EQ(m.at(R"(cloudbake_view_seconds_count{method="pathtrace"})"), 1);
  EXPECT_GT(m.at(R"(cloudbake_view_seconds_sum{method="pathtrace"})"), 0);
  const double hits = m.at("cloudbake_cache_hits_total");

  // The same shot again: served from the cache, so no new view is timed.
  const uintmax_t second = submit(shot, ws_.path("out2"));
  m = scrape();
  EXPECT_EQ(m.at(R"(cloudbake_jobs{state="SUCCEEDED"})"), 2);
  EXPECT_EQ(m.at("cloudbake_scatter_computations_total"), 1);
  EXPECT_GT(m.at("cloudbake_cache_hits_total"), hits);
  EXPECT_EQ(m.at("cloudbake_views_from_cache_total"), 1);
  EXPECT_EQ(m.at(R"(cloudbake_job_seconds_count{method="pathtrace",outcome="SUCCEEDED"})"), 2);
  EXPECT_EQ(m.at(R"(cloudbake_view_seconds_count{method="pathtrace"})"), 1);
  EXPECT_EQ(m.at("cloudbake_fetch_bytes_total"), double(first + second));

  // A cancelled job is counted under its outcome.
  const std::string slow = ws_.write("slow.json", sphereShot(256, 4096));
  const CmdResult sub = run(server_.cloudctl() + " submit --detach " + slow);
  ASSERT_EQ(sub.code, 0) << sub.err;
  const std::string id = sub.out.substr(0, sub.out.find('\n'));
  EXPECT_EQ(run(server_.cloudctl() + " cancel " + id).code, 0);
  run(server_.cloudctl(30) + " watch " + id);
  m = scrape();
  EXPECT_EQ(m.at(R"(cloudbake_jobs{state="CANCELLED"})"), 1);
  EXPECT_EQ(m.at(R"(cloudbake_job_seconds_count{method="pathtrace",outcome="CANCELLED"})"), 1);
  EXPECT_EQ(m.at("cloudbake_jobs_submitted_total"), 3);
}

TEST_F(MetricsTest, JsonLogLinesCarryTheJobAndOneSummaryPerJob) {
  const std::string shot = ws_.write("sphere.json", sphereShot(16, 4));
  submit(shot, ws_.path("out1"));
  submit(shot, ws_.path("out2"));
  ASSERT_TRUE(server_.stop());
  std::istringstream log(slurp(ws_.path("server.log")));
  std::string line;
  std::vector<Json> finished;
  int job_lines = 0;
  while (std::getline(log, line)) {
    const Json j = Json::parse(line);  // every line is one JSON object
    const std::string message = j.at("message");
    std::smatch id;
    if (std::regex_search(message, id, std::regex("^job (j[0-9a-f]{16}): "))) {
      ++job_lines;
      EXPECT_EQ(j.value("job", ""), id[1].str()) << line;
      if (message.find(": finished: ") != std::string::npos) finished.push_back(j);
    } else {
      EXPECT_FALSE(j.contains("job")) << line;
    }
  }
  EXPECT_GE(job_lines, 6) << "submitted, started and finished for each job";
  ASSERT_EQ(finished.size(), 2u);
  for (const Json& j : finished) {
    const std::string message = j.at("message");
    EXPECT_NE(message.find("SUCCEEDED, method pathtrace, "), std::string::npos) << message;
  }
  EXPECT_NE(finished[0].at("message").get<std::string>().find("cache miss"), std::string::npos);
  EXPECT_NE(finished[1].at("message").get<std::string>().find("cache hit"), std::string::npos);
}

TEST(MetricsListen, AnAddressInUseStopsTheServerWithAClearError) {
  Workspace ws;
  // Hold a port the way another process would.
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  ASSERT_EQ(listen(fd, 1), 0);
  socklen_t len = sizeof addr;
  getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  const std::string busy = "127.0.0.1:" + std::to_string(ntohs(addr.sin_port));
  ServerProc server(ws.path("state"));
  server.logTo(ws.path("server.log"));
  EXPECT_FALSE(server.start({"--metrics-listen=" + busy}));
  EXPECT_NE(slurp(ws.path("server.log")).find("--metrics-listen " + busy + ": cannot listen"),
            std::string::npos)
      << slurp(ws.path("server.log"));
  close(fd);
}

}  // namespace
}  // namespace cloudbake::testing
