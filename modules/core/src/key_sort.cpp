#include <paps/core/key_sort.h>

#include <algorithm>
#include <array>

namespace paps {

namespace {

constexpr int kDigitBits = 11;  // 2048 counters: fit in L1, 6 passes at most for 64 bits
constexpr std::size_t kSmall = 256;  // below this std::sort wins

std::uint64_t keyOf(std::uint64_t k) { return k; }
std::uint64_t keyOf(const std::pair<std::uint64_t, int>& p) { return p.first; }

template <typename T>
void radixSort(std::vector<T>& items, std::vector<T>* scratch) {
  if (items.size() < kSmall) {
    std::stable_sort(items.begin(), items.end(), [](const T& a, const T& b) { return keyOf(a) < keyOf(b); });
    return;
  }
  // Only the bits some key sets need a pass; their digits are counted in one sweep.
  std::uint64_t used = 0;
  for (const T& t : items) used |= keyOf(t);
  int bits = 0;
  while (bits < 64 && (used >> bits) != 0) ++bits;
  const int passes = (bits + kDigitBits - 1) / kDigitBits;
  if (passes == 0) return;  // every key is 0
  std::vector<std::array<std::size_t, 1 << kDigitBits>> counts(passes);
  for (auto& c : counts) c.fill(0);
  constexpr std::uint64_t mask = (1u << kDigitBits) - 1;
  for (const T& t : items)
    for (int p = 0; p < passes; ++p) ++counts[p][(keyOf(t) >> (p * kDigitBits)) & mask];
  std::vector<T> local;
  std::vector<T>& other = scratch ? *scratch : local;
  other.resize(items.size());
  std::vector<T>* from = &items;
  std::vector<T>* to = &other;
  for (int p = 0; p < passes; ++p) {
    auto& c = counts[p];
    // A digit every key shares moves nothing: skip its pass.
    if (std::any_of(c.begin(), c.end(), [&](std::size_t n) { return n == items.size(); })) continue;
    std::size_t sum = 0;
    for (auto& n : c) {
      const std::size_t here = n;
      n = sum;
      sum += here;
    }
    const int shift = p * kDigitBits;
    for (const T& t : *from) (*to)[c[(keyOf(t) >> shift) & mask]++] = t;
    std::swap(from, to);
  }
  if (from != &items) items.swap(*from);  // the sorted data now lives in `items`
}

}  // namespace

void sortByKey(std::vector<std::pair<std::uint64_t, int>>& pairs, std::vector<std::pair<std::uint64_t, int>>* scratch) {
  radixSort(pairs, scratch);
}

void sortKeys(std::vector<std::uint64_t>& keys, std::vector<std::uint64_t>* scratch) { radixSort(keys, scratch); }

}  // namespace paps
