// The stop-signal handlers: async-signal-safe (a lock-free atomic store, _exit).
#include "app/signals.h"

#include <csignal>
#include <unistd.h>

namespace tuile {

namespace {

std::atomic<bool> g_stop{false};
volatile std::sig_atomic_t g_signal = 0;
static_assert(std::atomic<bool>::is_always_lock_free, "the handler stores to it");

extern "C" void on_stop_signal(int sig) {
  if (g_stop.load()) _exit(128 + sig);  // a second request: abort at once
  g_signal = sig;
  g_stop.store(true);
}

}  // namespace

const std::atomic<bool>& install_stop_signals() {
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  return g_stop;
}

int stop_signal() { return static_cast<int>(g_signal); }

}  // namespace tuile
