#pragma once
// How many threads a PAPS stage uses. PCL's own parallel classes take setNumberOfThreads();
// ours do too (ThreadCountOption), so a pipeline that shares the machine can bound each
// stage. The outputs do not depend on the count (every stage is tested for it), only the time.
#include <omp.h>

#include <paps/core/error.h>

namespace paps {

/// Sets OpenMP's thread count for the parallel regions the calling thread starts, for the
/// lifetime of the object, then restores the previous one. 0 keeps the current count.
class ScopedThreadCount {
 public:
  explicit ScopedThreadCount(unsigned threads) : previous_(omp_get_max_threads()), set_(threads > 0) {
    if (set_) omp_set_num_threads(static_cast<int>(threads));
  }
  ~ScopedThreadCount() {
    if (set_) omp_set_num_threads(previous_);
  }
  ScopedThreadCount(const ScopedThreadCount&) = delete;
  ScopedThreadCount& operator=(const ScopedThreadCount&) = delete;

 private:
  int previous_;
  bool set_;
};

/// The setNumberOfThreads() / getNumberOfThreads() pair of PCL's OMP classes, for a PAPS stage
/// to inherit beside its PCL base; the stage runs its work under
/// ScopedThreadCount(getNumberOfThreads()).
class ThreadCountOption {
 public:
  /// 0 (default): OpenMP's count (OMP_NUM_THREADS, else every core); n > 0: n threads.
  void setNumberOfThreads(unsigned threads) {
    if (threads > 4096) throw InvalidParameter("threads", detail::toString(threads), "0 (all) to 4096");
    threads_ = threads;
  }
  unsigned getNumberOfThreads() const { return threads_; }

 protected:
  unsigned threads_ = 0;
};

}  // namespace paps
