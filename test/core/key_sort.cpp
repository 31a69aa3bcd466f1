// Tests of paps/core/key_sort.h: the radix sorts give std::sort's order, ties in input order.
#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <paps/core/key_sort.h>
#include <paps/core/random.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_key_sort_test {

using Pairs = std::vector<std::pair<std::uint64_t, int>>;

// n keys of `bits` random low bits (0 to 64), drawn among `distinct` values so ties abound.
std::vector<std::uint64_t> randomKeys(std::size_t n, int bits, std::uint64_t distinct, std::uint64_t seed) {
  paps::Random rng(seed);
  std::vector<std::uint64_t> pool(distinct);
  for (auto& k : pool) {
    const std::uint64_t r = rng.next();
    k = bits == 64 ? r : (bits == 0 ? 0 : r >> (64 - bits));
  }
  std::vector<std::uint64_t> keys(n);
  for (auto& k : keys) k = pool[rng.below(distinct)];
  return keys;
}

TEST(KeySort, PairsGetStdSortOrderWithTiesByIndex) {
  // Sizes below and above the small-input cut-off; bit widths that need 0, 1, 3 and 6 passes,
  // and keys whose high digits are all equal (a pass skipped).
  for (const std::size_t n : {0u, 1u, 5u, 255u, 256u, 257u, 10000u, 100000u})
    for (const int bits : {0, 1, 11, 23, 33, 64})
      for (const std::uint64_t distinct : {1u, 7u, 100000u}) {
        const std::vector<std::uint64_t> keys = randomKeys(n, bits, distinct, 17 * n + bits + distinct);
        Pairs pairs(n), expected(n), scratch;
        for (std::size_t i = 0; i < n; ++i) pairs[i] = expected[i] = {keys[i] | (bits == 0 ? 0 : 1ull << (bits - 1)), static_cast<int>(i)};
        std::sort(expected.begin(), expected.end());
        paps::sortByKey(pairs, &scratch);
        ASSERT_EQ(pairs, expected) << n << " pairs, " << bits << " bits, " << distinct << " distinct";
      }
}

TEST(KeySort, StableForAnyValues) {
  // Values not in order: equal keys keep their input order (what std::stable_sort does).
  std::vector<std::uint64_t> keys = randomKeys(50000, 40, 300, 5);
  paps::Random rng(9);
  Pairs pairs(keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i) pairs[i] = {keys[i], static_cast<int>(rng.below(1000))};
  Pairs expected = pairs;
  std::stable_sort(expected.begin(), expected.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  paps::sortByKey(pairs);
  EXPECT_EQ(pairs, expected);
}

TEST(KeySort, KeysSortAscendingAndScratchIsReusable) {
  std::vector<std::uint64_t> scratch;
  for (const int bits : {1, 20, 64}) {
    std::vector<std::uint64_t> keys = randomKeys(30000, bits, 30000, 100 + bits), expected = keys;
    std::sort(expected.begin(), expected.end());
    paps::sortKeys(keys, &scratch);
    EXPECT_EQ(keys, expected) << bits << " bits";
  }
}

}  // namespace core_key_sort_test
