#include <paps/core/poisson_disk_sampling.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include <paps/core/error.h>
#include <paps/core/random.h>

namespace paps {
namespace {

// Grid of cell side = radius over the candidate points. A cube of side r holds at most 8
// points at mutual distance >= r, so each cell keeps a fixed array of 8 slots. Cells are found
// through an open-addressing hash table built once over the candidates' cells.
class KeptGrid {
 public:
  KeptGrid(const Positions& pts, float radius, const std::vector<int>& candidates)
      : pts_(pts), r_(radius), r2_(radius * radius) {
    Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
    for (const int i : candidates) { lo = lo.cwiseMin(pts[i]); hi = hi.cwiseMax(pts[i]); }
    lo_ = lo;
    for (int a = 0; a < 3; ++a) {
      const double cells = std::floor((double(hi[a]) - lo[a]) / radius) + 3;
      if (!(cells < 1048576.0)) throw InvalidParameter("radius", detail::toString(radius),
                                                       "at least extent / 2^20 of the points");
      dims_[a] = static_cast<std::int64_t>(cells);
    }
    std::size_t cap = 16;
    while (cap < 2 * candidates.size() + 16) cap <<= 1;
    keys_.assign(cap, -1);
    ids_.assign(cap, -1);
    mask_ = cap - 1;
    for (const int i : candidates) {
      const std::int64_t k = keyOf(pts[i]);
      std::size_t h = slot(k);
      while (keys_[h] != -1 && keys_[h] != k) h = (h + 1) & mask_;
      if (keys_[h] == -1) { keys_[h] = k; ids_[h] = static_cast<int>(count_.size()); count_.push_back(0); }
    }
    kept_.resize(count_.size() * 8);
  }
  bool free(const Eigen::Vector3f& p) const {
    const std::int64_t cx = cell(p, 0), cy = cell(p, 1), cz = cell(p, 2);
    for (std::int64_t z = cz - 1; z <= cz + 1; ++z)
      for (std::int64_t y = cy - 1; y <= cy + 1; ++y)
        for (std::int64_t x = cx - 1; x <= cx + 1; ++x) {
          const int id = find(key(x, y, z));
          if (id < 0) continue;
          for (int s = 0; s < count_[id]; ++s)
            if ((pts_[kept_[std::size_t(id) * 8 + s]] - p).squaredNorm() < r2_) return false;
        }
    return true;
  }
  void add(int i) {
    const int id = find(keyOf(pts_[i]));
    if (id >= 0 && count_[id] < 8) kept_[std::size_t(id) * 8 + count_[id]++] = i;
  }

 private:
  std::int64_t cell(const Eigen::Vector3f& p, int a) const {
    return static_cast<std::int64_t>(std::floor((p[a] - lo_[a]) / r_)) + 1;
  }
  std::int64_t key(std::int64_t x, std::int64_t y, std::int64_t z) const { return (z * dims_[1] + y) * dims_[0] + x; }
  std::int64_t keyOf(const Eigen::Vector3f& p) const { return key(cell(p, 0), cell(p, 1), cell(p, 2)); }
  std::size_t slot(std::int64_t k) const {
    std::uint64_t h = static_cast<std::uint64_t>(k) * 0x9E3779B97F4A7C15ULL;
    return static_cast<std::size_t>(h >> 20) & mask_;
  }
  int find(std::int64_t k) const {
    std::size_t h = slot(k);
    while (keys_[h] != -1) {
      if (keys_[h] == k) return ids_[h];
      h = (h + 1) & mask_;
    }
    return -1;
  }
  const Positions& pts_;
  float r_, r2_;
  Eigen::Vector3f lo_;
  std::int64_t dims_[3];
  std::vector<std::int64_t> keys_;
  std::vector<int> ids_;
  std::size_t mask_ = 0;
  std::vector<std::uint8_t> count_;
  std::vector<int> kept_;
};

std::vector<int> throwDarts(const Positions& points, float radius, const std::vector<int>& order,
                            const ProgressCallback& progress) {
  KeptGrid grid(points, radius, order);
  std::vector<int> kept;
  ProgressReporter rep(progress, "Poisson-disk sampling", order.size());
  std::size_t done = 0;
  for (const int i : order) {
    if (grid.free(points[i])) { grid.add(i); kept.push_back(i); }
    if (++done % 65536 == 0) { rep.advance(65536); rep.throwIfCancelled(); }
  }
  rep.finish();
  std::sort(kept.begin(), kept.end());
  return kept;
}

}  // namespace

std::vector<int> poissonDiskSubset(const Positions& points, float radius, std::uint64_t seed,
                                   const ProgressCallback& progress) {
  requirePositive("radius", radius);
  std::vector<int> order;
  order.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i)
    if (isFinite(points[i])) order.push_back(static_cast<int>(i));
  if (order.empty()) return {};
  // Random order inside blocks of 8 x 8 x 8 cells visited one after the other: the darts are
  // as random locally, and the memory traffic stays local (several times faster on millions
  // of points than one global shuffle).
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY);
  for (const int i : order) lo = lo.cwiseMin(points[i]);
  const double block = 8.0 * radius;
  Random rng(seed);
  std::vector<std::pair<std::uint64_t, int>> keyed(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) {
    const Eigen::Vector3f& p = points[order[k]];
    std::uint64_t key = 0;
    for (int a = 0; a < 3; ++a) {
      const auto c = static_cast<std::uint64_t>(std::min(2047.0, std::floor((double(p[a]) - lo[a]) / block)));
      key = (key << 11) | c;
    }
    keyed[k] = {(key << 31) | (rng.next() & 0x7FFFFFFFu), order[k]};
  }
  std::sort(keyed.begin(), keyed.end());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = keyed[k].second;
  return throwDarts(points, radius, order, progress);
}

std::vector<int> poissonDiskSubsetOrdered(const Positions& points, float radius,
                                          const std::vector<float>& priority) {
  requirePositive("radius", radius);
  if (!priority.empty() && priority.size() != points.size())
    throw InvalidParameter("priority", std::to_string(priority.size()) + " values",
                           std::to_string(points.size()) + " values, one per point");
  std::vector<int> order;
  for (std::size_t i = 0; i < points.size(); ++i)
    if (isFinite(points[i])) order.push_back(static_cast<int>(i));
  if (order.empty()) return {};
  if (!priority.empty())
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return priority[a] < priority[b]; });
  return throwDarts(points, radius, order, {});
}

}  // namespace paps
