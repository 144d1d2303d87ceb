#include "tools/cloudbake/interrupt.h"

#include <atomic>
#include <csignal>
#include <cstring>

namespace cloudbake::tool {
namespace {

std::atomic<int> g_signal{0};  // the first SIGINT or SIGTERM; 0 before it
static_assert(std::atomic<int>::is_always_lock_free, "set from a signal handler");
// The signals whose handler was installed, written before any is: after the first signal
// both go back to their default action, so a second one of either kind ends the process
// (SA_RESETHAND resets only the one that arrived).
bool g_installed[2] = {false, false};
constexpr int kSignals[2] = {SIGINT, SIGTERM};

extern "C" void onInterrupt(int signal) {
  int none = 0;
  g_signal.compare_exchange_strong(none, signal, std::memory_order_relaxed);
  for (int i = 0; i < 2; ++i) {
    if (g_installed[i]) std::signal(kSignals[i], SIG_DFL);  // async-signal-safe
  }
}

}  // namespace

void installInterruptHandler() {
  struct sigaction sa;
  std::memset(&sa, 0, sizeof sa);
  sa.sa_handler = onInterrupt;
  sigemptyset(&sa.sa_mask);
  // The handler runs once: the next signal takes its default action and ends the process.
  sa.sa_flags = SA_RESETHAND | SA_RESTART;
  for (int i = 0; i < 2; ++i) {
    // A signal the parent set to be ignored stays ignored (nohup, a shell's background job).
    struct sigaction old;
    if (sigaction(kSignals[i], nullptr, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    g_installed[i] = true;
    sigaction(kSignals[i], &sa, nullptr);
  }
}

bool interrupted() { return interruptSignal() != 0; }

int interruptSignal() { return g_signal.load(std::memory_order_relaxed); }

}  // namespace cloudbake::tool
