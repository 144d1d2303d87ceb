#include "tools/cloudbake/interrupt.h"

#include <time.h>

#include <atomic>
#include <csignal>
#include <cstdint>
#include <cstring>

namespace cloudbake::tool {
namespace {

std::atomic<int> g_signal{0};        // the first SIGINT or SIGTERM; 0 before it
std::atomic<int64_t> g_first_ns{0};  // when it arrived (CLOCK_MONOTONIC)
static_assert(std::atomic<int>::is_always_lock_free, "set from a signal handler");
static_assert(std::atomic<int64_t>::is_always_lock_free, "set from a signal handler");
constexpr int kSignals[2] = {SIGINT, SIGTERM};
// A second signal this soon after the first is the same stop delivered twice: coreutils'
// `timeout` signals its child and then the child's process group, and a scheduler may signal
// every process of a job. Ending at once on it (an outside probe's `timeout 3`) left a
// cancelled render's files behind.
constexpr int64_t kRepeatNs = 1'000'000'000;

int64_t monotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);  // async-signal-safe
  return int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

extern "C" void onInterrupt(int signal) {
  const int64_t now = monotonicNs();
  int none = 0;
  if (g_signal.compare_exchange_strong(none, signal, std::memory_order_relaxed)) {
    g_first_ns.store(now, std::memory_order_relaxed);
    return;
  }
  if (now - g_first_ns.load(std::memory_order_relaxed) < kRepeatNs) return;
  // A later one ends the process as the signal would have: the default action, raised again
  // (blocked in this handler, it is delivered as it returns).
  std::signal(signal, SIG_DFL);  // async-signal-safe
  std::raise(signal);
}

}  // namespace

void installInterruptHandler() {
  struct sigaction sa;
  std::memset(&sa, 0, sizeof sa);
  sa.sa_handler = onInterrupt;
  sigemptyset(&sa.sa_mask);
  for (int signal : kSignals) sigaddset(&sa.sa_mask, signal);  // one handler at a time
  sa.sa_flags = SA_RESTART;
  for (int signal : kSignals) {
    // A signal the parent set to be ignored stays ignored (nohup, a shell's background job).
    struct sigaction old;
    if (sigaction(signal, nullptr, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    sigaction(signal, &sa, nullptr);
  }
}

bool interrupted() { return interruptSignal() != 0; }

int interruptSignal() { return g_signal.load(std::memory_order_relaxed); }

}  // namespace cloudbake::tool
