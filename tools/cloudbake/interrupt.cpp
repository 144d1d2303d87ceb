#include "tools/cloudbake/interrupt.h"

#include <atomic>
#include <csignal>
#include <cstring>
#include <initializer_list>

namespace cloudbake::tool {
namespace {

std::atomic<int> g_signal{0};  // the first SIGINT or SIGTERM; 0 before it
static_assert(std::atomic<int>::is_always_lock_free, "set from a signal handler");

extern "C" void onInterrupt(int signal) { g_signal.store(signal, std::memory_order_relaxed); }

}  // namespace

void installInterruptHandler() {
  struct sigaction sa;
  std::memset(&sa, 0, sizeof sa);
  sa.sa_handler = onInterrupt;
  sigemptyset(&sa.sa_mask);
  // The handler runs once: the next signal takes its default action and ends the process.
  sa.sa_flags = SA_RESETHAND | SA_RESTART;
  for (const int signal : {SIGINT, SIGTERM}) {
    // A signal the parent set to be ignored stays ignored (nohup, a shell's background job).
    struct sigaction old;
    if (sigaction(signal, nullptr, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    sigaction(signal, &sa, nullptr);
  }
}

bool interrupted() { return interruptSignal() != 0; }

int interruptSignal() { return g_signal.load(std::memory_order_relaxed); }

}  // namespace cloudbake::tool
