#pragma once
// Temporary outputs removed on Ctrl-C. Outputs are written to a temporary file and renamed
// when complete; an interrupt during the write would otherwise leave the temporary behind.
// A TemporaryFileGuard marks such a file while it is written; a program that calls
// installInterruptCleanup() (the `paps` command line does; a library never installs signal
// handlers on its own) then removes every marked file on SIGINT, SIGTERM or SIGHUP and dies
// of that signal as it would have.
#include <string>

namespace paps {

/// Installs the handlers for SIGINT, SIGTERM and SIGHUP, except where the program already
/// set one of its own. Idempotent.
void installInterruptCleanup();

/// While alive, `path` is removed if the process is interrupted (see above). At most 16
/// files are marked at once; further guards do nothing.
class TemporaryFileGuard {
 public:
  explicit TemporaryFileGuard(const std::string& path);
  ~TemporaryFileGuard();
  TemporaryFileGuard(const TemporaryFileGuard&) = delete;
  TemporaryFileGuard& operator=(const TemporaryFileGuard&) = delete;

 private:
  int slot_ = -1;
};

}  // namespace paps
