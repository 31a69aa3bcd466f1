#include <paps/core/spatial_order.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <utility>

#include <paps/core/random.h>

namespace paps {

namespace {
/// Spreads the low 21 bits of v so that two zero bits separate each (Morton interleaving).
std::uint64_t spreadBits(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

/// Order of (key, index) pairs by key, then by the indexed point's coordinates, then (copies
/// of one position) by index: nothing in it depends on the input order but the last step.
struct KeyThenPosition {
  const Positions& points;
  bool operator()(const std::pair<std::uint64_t, int>& a, const std::pair<std::uint64_t, int>& b) const {
    if (a.first != b.first) return a.first < b.first;
    if (points[a.second] != points[b.second]) return coordinatesBefore(points[a.second], points[b.second]);
    return a.second < b.second;
  }
};
}  // namespace

std::vector<int> spatialOrder(const Positions& points, int bits_per_axis) {
  if (bits_per_axis < 1 || bits_per_axis > 21)
    throw InvalidParameter("bits_per_axis", std::to_string(bits_per_axis), "1 to 21");
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  for (const auto& p : points)
    if (isFinite(p)) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  const float top = static_cast<float>((1 << bits_per_axis) - 1);
  const float extent = std::max((hi - lo).maxCoeff(), 1e-30f);
  std::vector<std::pair<std::uint64_t, int>> keyed;
  keyed.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!isFinite(points[i])) continue;
    // Clamped: rounding may push the top corner a hair past the last cell.
    const Eigen::Vector3f q = (points[i] - lo) / extent * top;
    std::uint64_t key = 0;
    for (int a = 0; a < 3; ++a) key |= spreadBits(static_cast<std::uint64_t>(std::clamp(q[a], 0.f, top))) << a;
    keyed.emplace_back(key, static_cast<int>(i));
  }
  // Points of one cell by their coordinates (x, then y, then z), so that the order does not
  // depend on the input order; only copies of one position stay in index order.
  std::sort(keyed.begin(), keyed.end(), KeyThenPosition{points});
  std::vector<int> order(keyed.size());
  for (std::size_t k = 0; k < keyed.size(); ++k) order[k] = keyed[k].second;
  return order;
}

std::uint64_t positionHash(const Eigen::Vector3f& p) {
  std::uint32_t b[3];
  std::memcpy(b, p.data(), sizeof b);
  return Random((std::uint64_t{b[0]} << 32 | b[1]) ^ (b[2] * 0x9e3779b97f4a7c15ULL)).next();
}

std::vector<int> positionSample(const Positions& points, std::size_t samples) {
  // The `samples` smallest (hash, x, y, z, index), kept in a max-heap: one pass, no copy.
  if (samples == 0) return {};
  const KeyThenPosition before{points};
  std::vector<std::pair<std::uint64_t, int>> heap;
  heap.reserve(samples);
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!isFinite(points[i])) continue;
    const std::pair<std::uint64_t, int> e(positionHash(points[i]), static_cast<int>(i));
    if (heap.size() < samples) {
      heap.push_back(e);
      std::push_heap(heap.begin(), heap.end(), before);
    } else if (before(e, heap.front())) {
      std::pop_heap(heap.begin(), heap.end(), before);
      heap.back() = e;
      std::push_heap(heap.begin(), heap.end(), before);
    }
  }
  std::sort_heap(heap.begin(), heap.end(), before);
  std::vector<int> out(heap.size());
  for (std::size_t k = 0; k < heap.size(); ++k) out[k] = heap[k].second;
  return out;
}

std::vector<int> spatialOrderAll(const Positions& points) {
  std::vector<int> order = spatialOrder(points);
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!isFinite(points[i])) order.push_back(static_cast<int>(i));
  return order;
}

}  // namespace paps
