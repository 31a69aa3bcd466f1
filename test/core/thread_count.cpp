// Tests of paps/core/thread_count.h: a scoped count bounds the parallel regions started in
// its scope and is restored after; the option rejects absurd counts.
#include <omp.h>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/thread_count.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_thread_count_test {

int threadsOfARegion() {
  int n = 0;
#pragma omp parallel
  {
#pragma omp single
    n = omp_get_num_threads();
  }
  return n;
}

TEST(ThreadCount, ScopedCountBoundsRegionsAndIsRestored) {
  omp_set_dynamic(0);
  const int before = omp_get_max_threads();
  {
    const paps::ScopedThreadCount one(1);
    EXPECT_EQ(omp_get_max_threads(), 1);
    EXPECT_EQ(threadsOfARegion(), 1);
    {
      const paps::ScopedThreadCount three(3);
      EXPECT_EQ(threadsOfARegion(), 3);
    }
    EXPECT_EQ(omp_get_max_threads(), 1);
  }
  EXPECT_EQ(omp_get_max_threads(), before);
  {
    const paps::ScopedThreadCount keep(0);  // 0 keeps the current count
    EXPECT_EQ(omp_get_max_threads(), before);
  }
  EXPECT_EQ(omp_get_max_threads(), before);
}

TEST(ThreadCount, OptionRejectsAbsurdCounts) {
  paps::ThreadCountOption o;
  EXPECT_EQ(o.getNumberOfThreads(), 0u);
  o.setNumberOfThreads(2);
  EXPECT_EQ(o.getNumberOfThreads(), 2u);
  EXPECT_THROW(o.setNumberOfThreads(100000), paps::InvalidParameter);
  EXPECT_EQ(o.getNumberOfThreads(), 2u);
}

}  // namespace core_thread_count_test
