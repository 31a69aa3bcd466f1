// Tests of paps/core/interrupt_cleanup.h, in child processes: a marked temporary file is
// removed when the process is interrupted, and the process still dies of the signal; a file
// no longer marked is left alone; a handler the program set itself is not replaced.
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <paps/core/interrupt_cleanup.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_interrupt_cleanup_test {

namespace fs = std::filesystem;

std::string scratchFile(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / "paps_interrupt_cleanup";
  fs::create_directories(dir);
  const fs::path p = dir / name;
  std::ofstream(p) << "partial output";
  return p.string();
}

// Runs `child` in a forked process and returns its wait status.
template <typename F>
int inChild(F child) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    child();
    ::_exit(0);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return status;
}

TEST(InterruptCleanup, MarkedTemporaryIsRemovedAndTheSignalStillKills) {
  for (const int sig : {SIGINT, SIGTERM}) {
    const std::string tmp = scratchFile("marked.tmp");
    const int status = inChild([&] {
      paps::installInterruptCleanup();
      const paps::TemporaryFileGuard guard(tmp);
      std::raise(sig);
    });
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == sig) << "status " << status;
    EXPECT_FALSE(fs::exists(tmp)) << "signal " << sig;
  }
}

TEST(InterruptCleanup, UnmarkedFilesAndForeignHandlersAreLeftAlone) {
  const std::string kept = scratchFile("released.tmp");
  int status = inChild([&] {
    paps::installInterruptCleanup();
    { const paps::TemporaryFileGuard guard(kept); }  // released: the write finished
    std::raise(SIGINT);
  });
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGINT);
  EXPECT_TRUE(fs::exists(kept));
  // A program with its own SIGINT handler keeps it (and its file).
  const std::string own = scratchFile("own_handler.tmp");
  status = inChild([&] {
    std::signal(SIGINT, [](int) { ::_exit(42); });
    paps::installInterruptCleanup();
    const paps::TemporaryFileGuard guard(own);
    std::raise(SIGINT);
  });
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 42) << "status " << status;
  EXPECT_TRUE(fs::exists(own));
}

}  // namespace core_interrupt_cleanup_test
