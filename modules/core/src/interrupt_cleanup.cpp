#include <paps/core/interrupt_cleanup.h>

#include <atomic>
#include <csignal>
#include <cstring>

#include <unistd.h>

namespace paps {

namespace {

constexpr int kSlots = 16;
constexpr std::size_t kPathBytes = 4096;
// Paths are copied into static storage: the handler may only call async-signal-safe
// functions (unlink, signal, raise) and read memory that is never freed.
char g_paths[kSlots][kPathBytes];
std::atomic<int> g_state[kSlots];  // 0 free, 1 being filled, 2 armed

extern "C" void removeTemporariesAndDie(int sig) {
  for (int i = 0; i < kSlots; ++i)
    if (g_state[i].load() == 2) ::unlink(g_paths[i]);
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

}  // namespace

void installInterruptCleanup() {
  for (const int sig : {SIGINT, SIGTERM, SIGHUP}) {
    struct sigaction old {};
    if (::sigaction(sig, nullptr, &old) != 0) continue;
    if (old.sa_handler != SIG_DFL || (old.sa_flags & SA_SIGINFO)) continue;  // the program's own
    struct sigaction sa {};
    sa.sa_handler = removeTemporariesAndDie;
    sigemptyset(&sa.sa_mask);
    ::sigaction(sig, &sa, nullptr);
  }
}

TemporaryFileGuard::TemporaryFileGuard(const std::string& path) {
  if (path.size() + 1 > kPathBytes) return;
  for (int i = 0; i < kSlots; ++i) {
    int expected = 0;
    if (g_state[i].compare_exchange_strong(expected, 1)) {
      std::memcpy(g_paths[i], path.c_str(), path.size() + 1);
      g_state[i].store(2);
      slot_ = i;
      return;
    }
  }
}

TemporaryFileGuard::~TemporaryFileGuard() {
  if (slot_ >= 0) g_state[slot_].store(0);
}

}  // namespace paps
