#pragma once
// Progress reporting and cancellation for long runs.
#include <atomic>
#include <cstddef>
#include <functional>
#include <string>

#include <paps/core/error.h>

namespace paps {

/// Called with the stage name and the fraction done in [0, 1]. Return false to
/// cancel: the running algorithm then throws paps::Cancelled.
using ProgressCallback = std::function<bool(const std::string& stage, float fraction)>;

/// `progress` with "<part> <index + 1>/<count>: " before every stage name (e.g. "tile 2/5: "),
/// for a run cut into parts; empty when `progress` is.
ProgressCallback partProgress(const ProgressCallback& progress, const std::string& part, std::size_t index,
                              std::size_t count);

/// Thread-safe helper that calls a ProgressCallback about a hundred times per
/// stage, from whichever thread crosses the next step. Safe to call from OpenMP loops;
/// the call itself is serialised.
class ProgressReporter {
 public:
  ProgressReporter(const ProgressCallback& cb, std::string stage, std::size_t total);
  /// Count `n` more items done. Cheap when no callback is set.
  void advance(std::size_t n = 1);
  /// Report the end of the stage.
  void finish();
  /// True once the callback asked to stop; loops check it and break out.
  bool cancelled() const { return cancelled_.load(std::memory_order_relaxed); }
  /// Throws paps::Cancelled if the callback asked to stop.
  void throwIfCancelled() const {
    if (cancelled()) throw Cancelled();
  }

 private:
  const ProgressCallback* cb_;
  std::string stage_;
  std::size_t total_;
  std::size_t step_;
  std::atomic<std::size_t> done_{0};
  std::atomic<std::size_t> next_report_{0};
  std::atomic<bool> cancelled_{false};
};

}  // namespace paps
