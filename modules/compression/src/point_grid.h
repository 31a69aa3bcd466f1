#pragma once
// Internal to the codec: light spatial structures that keep the encoder and decoder within a
// small multiple of the cloud's own size.
//
// PointGrid: a static uniform grid over the finite points of a Positions array (borrowed,
// not copied). 4 bytes per point (indices sorted by cell) plus a hash table of the occupied
// cells; built in O(n) by counting. Queries are const and thread-safe; results come in a
// fixed order (cells in a fixed order, points by index inside a cell), so everything built
// on them is deterministic whatever the thread count.
//
// ThinningGrid: an incremental hash grid for Poisson-disk thinning (keep a point when no kept
// point lies within r), 4 bytes per kept point plus the occupied cells (side 6r: a query
// visits 1 to 8 cells, 2.4 on average).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <paps/core/error.h>
#include <paps/core/positions.h>
#include <paps/core/spatial_order.h>

namespace paps::compression::detail {

class CellHash {
 public:
  void reset(std::size_t expected) {
    std::size_t cap = 16;
    while (cap < 2 * expected + 16) cap <<= 1;
    keys_.assign(cap, kEmpty);
    ids_.assign(cap, -1);
    mask_ = cap - 1;
    size_ = 0;
  }
  /// Id of the cell `key`, or -1.
  int find(std::uint64_t key) const {
    std::size_t h = slot(key);
    while (keys_[h] != kEmpty) {
      if (keys_[h] == key) return ids_[h];
      h = (h + 1) & mask_;
    }
    return -1;
  }
  /// Id of the cell `key`, inserting it with id = size() when absent (grows as needed).
  int insert(std::uint64_t key, bool* inserted = nullptr) {
    if (2 * (size_ + 1) > keys_.size()) grow();
    std::size_t h = slot(key);
    while (keys_[h] != kEmpty) {
      if (keys_[h] == key) { if (inserted) *inserted = false; return ids_[h]; }
      h = (h + 1) & mask_;
    }
    keys_[h] = key;
    ids_[h] = int(size_);
    if (inserted) *inserted = true;
    return int(size_++);
  }
  std::size_t size() const { return size_; }
  std::size_t bytes() const { return keys_.capacity() * 8 + ids_.capacity() * 4; }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
  std::size_t slot(std::uint64_t k) const { return std::size_t((k * 0x9E3779B97F4A7C15ULL) >> 17) & mask_; }
  void grow() {
    std::vector<std::uint64_t> k = std::move(keys_);
    std::vector<int> id = std::move(ids_);
    std::size_t cap = std::max<std::size_t>(16, k.size() * 2);
    keys_.assign(cap, kEmpty);
    ids_.assign(cap, -1);
    mask_ = cap - 1;
    for (std::size_t i = 0; i < k.size(); ++i)
      if (k[i] != kEmpty) {
        std::size_t h = slot(k[i]);
        while (keys_[h] != kEmpty) h = (h + 1) & mask_;
        keys_[h] = k[i];
        ids_[h] = id[i];
      }
  }
  std::vector<std::uint64_t> keys_;
  std::vector<int> ids_;
  std::size_t mask_ = 0, size_ = 0;
};

// 21 bits per axis, offset so that neighbours of border cells stay representable.
inline std::uint64_t packCell(std::int64_t x, std::int64_t y, std::int64_t z) {
  return (std::uint64_t(x & 0x1FFFFF) << 42) | (std::uint64_t(y & 0x1FFFFF) << 21) | std::uint64_t(z & 0x1FFFFF);
}

class PointGrid {
 public:
  /// Grid of side `cell` over the finite points of `pts` (kept by reference).
  /// Throws InvalidParameter when the cell is so small that an axis would need > 2^20 cells.
  PointGrid(const Positions& pts, float cell) : pts_(pts), cell_(cell), inv_(1.f / cell) {
    lo_ = Eigen::Vector3f::Constant(INFINITY);
    Eigen::Vector3f hi = -lo_;
    std::size_t finite = 0;
    for (const auto& p : pts)
      if (isFinite(p)) { lo_ = lo_.cwiseMin(p); hi = hi.cwiseMax(p); ++finite; }
    if (finite == 0) { start_.assign(1, 0); cells_.reset(1); return; }
    for (int a = 0; a < 3; ++a)
      if (!(double(hi[a] - lo_[a]) * inv_ < 1048000.0))
        throw InvalidParameter("patch_radius", paps::detail::toString(cell), "at least extent / 2^20 of the points");
    // Pass 1: cell of every point (4 bytes each, freed at the end) and the count per cell.
    std::vector<int> cell_of(pts.size(), -1);
    cells_.reset(std::max<std::size_t>(64, finite / 32));
    std::vector<std::uint32_t> count;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (!isFinite(pts[i])) continue;
      bool fresh = false;
      const int id = cells_.insert(keyOf(pts[i]), &fresh);
      if (fresh) count.push_back(0);
      ++count[id];
      cell_of[i] = id;
    }
    start_.assign(count.size() + 1, 0);
    for (std::size_t c = 0; c < count.size(); ++c) start_[c + 1] = start_[c] + count[c];
    order_.resize(finite);
    for (std::size_t i = 0; i < pts.size(); ++i)
      if (cell_of[i] >= 0) order_[start_[cell_of[i]] + --count[cell_of[i]]] = int(i);
    // Points of a cell by their coordinates (x, y, z; copies of a position by index), so that
    // what is built on the grid does not depend on the order of the input.
    for (std::size_t c = 0; c + 1 < start_.size(); ++c)
      std::sort(order_.begin() + start_[c], order_.begin() + start_[c + 1], [&pts](int a, int b) { return before(pts, a, b); });
  }

  /// Order by coordinates (x, then y, then z), copies of a position by index.
  static bool before(const Positions& pts, int a, int b) {
    return pts[a] != pts[b] ? coordinatesBefore(pts[a], pts[b]) : a < b;
  }

  float cell() const { return cell_; }
  std::size_t size() const { return order_.size(); }
  std::size_t cellCount() const { return start_.size() - 1; }
  /// Points of cell id c (ids in order of first appearance in the array).
  const int* cellBegin(std::size_t c) const { return order_.data() + start_[c]; }
  const int* cellEnd(std::size_t c) const { return order_.data() + start_[c + 1]; }
  std::uint64_t keyOf(const Eigen::Vector3f& p) const {
    return packCell(coord(p, 0), coord(p, 1), coord(p, 2));
  }
  std::int64_t coord(const Eigen::Vector3f& p, int a) const {
    return std::int64_t(std::floor((p[a] - lo_[a]) * inv_)) + 2;
  }
  int cellId(std::int64_t x, std::int64_t y, std::int64_t z) const { return cells_.find(packCell(x, y, z)); }

  /// Calls f(index, squared distance) for every point within r of q.
  template <typename F>
  void forEachWithin(const Eigen::Vector3f& q, float r, F&& f) const {
    if (order_.empty() || !isFinite(q)) return;
    const float r2 = r * r;
    std::int64_t a[3], b[3];
    for (int d = 0; d < 3; ++d) {
      a[d] = std::int64_t(std::floor((q[d] - r - lo_[d]) * inv_)) + 2;
      b[d] = std::int64_t(std::floor((q[d] + r - lo_[d]) * inv_)) + 2;
      a[d] = std::max<std::int64_t>(a[d], 0);
      b[d] = std::min<std::int64_t>(b[d], 0x1FFFFF);
    }
    for (std::int64_t z = a[2]; z <= b[2]; ++z)
      for (std::int64_t y = a[1]; y <= b[1]; ++y)
        for (std::int64_t x = a[0]; x <= b[0]; ++x) {
          const int c = cellId(x, y, z);
          if (c < 0) continue;
          for (std::uint32_t j = start_[c]; j < start_[c + 1]; ++j) {
            const int i = order_[j];
            const float d2 = (pts_[i] - q).squaredNorm();
            if (d2 <= r2) f(i, d2);
          }
        }
  }
  int countWithin(const Eigen::Vector3f& q, float r) const {
    int n = 0;
    forEachWithin(q, r, [&](int, float) { ++n; });
    return n;
  }
  /// Points within r of q; when there are more than max_count (> 0), the max_count nearest
  /// (ties by coordinates). Order: fixed (grid order, or by distance when capped).
  int radiusSearch(const Eigen::Vector3f& q, float r, std::vector<int>& idx, std::vector<float>& d2,
                   int max_count = 0) const {
    idx.clear();
    d2.clear();
    forEachWithin(q, r, [&](int i, float d) { idx.push_back(i); d2.push_back(d); });
    if (max_count > 0 && int(idx.size()) > max_count) {
      thread_local std::vector<std::pair<float, int>> tmp;
      tmp.resize(idx.size());
      for (std::size_t j = 0; j < idx.size(); ++j) tmp[j] = {d2[j], idx[j]};
      auto nearer = [this](const std::pair<float, int>& a, const std::pair<float, int>& b) {
        return a.first != b.first ? a.first < b.first : before(pts_, a.second, b.second);
      };
      std::nth_element(tmp.begin(), tmp.begin() + max_count, tmp.end(), nearer);
      tmp.resize(max_count);
      std::sort(tmp.begin(), tmp.end(), nearer);
      idx.resize(max_count);
      d2.resize(max_count);
      for (int j = 0; j < max_count; ++j) { d2[j] = tmp[j].first; idx[j] = tmp[j].second; }
    }
    return int(idx.size());
  }
  std::size_t bytes() const { return order_.capacity() * 4 + start_.capacity() * 4 + cells_.bytes(); }

 private:
  const Positions& pts_;
  float cell_, inv_;
  Eigen::Vector3f lo_;
  CellHash cells_;
  std::vector<std::uint32_t> start_;
  std::vector<int> order_;
};

/// Poisson-disk thinning, streaming: offer points one by one; a point is kept when no kept
/// point lies closer than r. Kept points are appended to `out`.
class ThinningGrid {
 public:
  /// `expected`: about how many points will be kept (sizes the table once).
  ThinningGrid(float r, std::size_t expected) : r2_(r * r), inv_(1.f / (8 * r)), r_(r) {
    // Cells of side 8r hold about 11 kept points on a surface sampled at 2r (measured on rs1,
    // 1M points: 11.4); sized for 12 a cell, the table is 3 MB where 6r cells took 6 MB.
    cells_.reset(expected / 12 + 16);
  }
  bool offer(const Eigen::Vector3f& p, Positions& out) {
    std::int64_t a[3], b[3], own[3];
    for (int d = 0; d < 3; ++d) {
      a[d] = std::int64_t(std::floor((p[d] - r_) * inv_));
      b[d] = std::int64_t(std::floor((p[d] + r_) * inv_));
      own[d] = std::int64_t(std::floor(p[d] * inv_));
    }
    auto blocked = [&](int c) {
      if (c < 0) return false;
      for (int j = head_[c]; j >= 0; j = next_[j])
        if ((out[j] - p).squaredNorm() < r2_) return true;
      return false;
    };
    // The point's own cell first: it holds the blocking point most of the time.
    const std::uint64_t own_key = packCell(own[0], own[1], own[2]);
    if (blocked(cells_.find(own_key))) return false;
    for (std::int64_t z = a[2]; z <= b[2]; ++z)
      for (std::int64_t y = a[1]; y <= b[1]; ++y)
        for (std::int64_t x = a[0]; x <= b[0]; ++x) {
          if (x == own[0] && y == own[1] && z == own[2]) continue;
          if (blocked(cells_.find(packCell(x, y, z)))) return false;
        }
    bool fresh = false;
    const int c = cells_.insert(own_key, &fresh);
    if (fresh) head_.push_back(-1);
    next_.push_back(head_[c]);
    head_[c] = int(out.size());
    out.push_back(p);
    return true;
  }
  void reserve(std::size_t n) { next_.reserve(n); }
  std::size_t cells() const { return cells_.size(); }
  std::size_t bytes() const { return cells_.bytes() + head_.capacity() * 4 + next_.capacity() * 4; }

 private:
  float r2_, inv_, r_;
  CellHash cells_;
  std::vector<int> head_, next_;
};

}  // namespace paps::compression::detail
