#pragma once
// CellGrid: the shared fixed-radius neighbour search on a uniform grid of cubic cells.
//
// The finite points of a Positions array are sorted once by cell (x fastest, then y, then z)
// and copied in that order, so that a row of cells is one contiguous range of sorted() and
// points visited one after the other are close in memory. NaN/Inf points are ignored.
//
// Ball convention: "within r" means a squared distance <= r * r (closed ball), computed in
// float as (p - q).squaredNorm(), so results equal a brute-force loop with that test.
// Queries are const and thread-safe (each thread keeps its own Cursor).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include <paps/core/neighbourhood.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

class CellGrid {
 public:
  CellGrid() = default;

  /// Grids the finite points of `points` in cells of side `cell`. Throws InvalidParameter
  /// when `cell` is not finite and > 0. When the extent needs more than 2^21 - 4 cells along
  /// an axis, the grid is a window of that many cells around the median point and at most
  /// 4096 points outside it share its border cells (queries return the same points);
  /// returns false (grid left empty) when more lie outside. An empty cloud is a valid grid.
  /// `anchored`: the cells are those of the lattice of multiples of `cell` (a point's cell is
  /// floor(x / cell) on each axis), not of the points' bounding box, so grids of one cell size
  /// built on overlapping point sets order their common points alike (a tile and its cloud).
  bool build(const Positions& points, float cell, bool anchored = false);

  float cell() const { return static_cast<float>(cell_); }
  /// Number of finite points.
  std::size_t size() const { return sorted_.size(); }
  /// Finite points in cell order ("slots"), and the input index of each slot.
  const Positions& sorted() const { return sorted_; }
  const std::vector<int>& original() const { return original_; }

  /// Per-thread cache of the slot ranges scanned by the last query; consecutive queries in
  /// the same cell (the case when iterating sorted()) reuse them.
  struct Cursor {
    std::int64_t box[6] = {-1, -1, -1, -1, -1, -1};
    std::vector<std::pair<int, int>> ranges;
  };

  /// Calls f(slot, squared distance) for every point p with (p - q)^2 <= max_d2, searching
  /// the cells within `reach` of q (reach >= sqrt(max_d2)). Order: cell order, then slot.
  template <typename F>
  void forEachWithin(const Eigen::Vector3f& q, float reach, float max_d2, Cursor& cursor, F&& f) const {
    forEachInReach(q, reach, cursor, [&](int s) {
      const float d2 = (sorted_[s] - q).squaredNorm();
      if (d2 <= max_d2) f(s, d2);
    });
  }

  /// Calls f(slot) for every point of the cells within `reach` of q: every point within
  /// reach, and others. For a caller that measures distances by its own convention (a
  /// kd-tree's ball to reproduce). Order: cell order, then slot.
  template <typename F>
  void forEachInReach(const Eigen::Vector3f& q, float reach, Cursor& cursor, F&& f) const {
    if (sorted_.empty() || !isFinite(q)) return;
    prepare(q, reach, cursor);
    for (const auto& r : cursor.ranges)
      for (int s = r.first; s < r.second; ++s) f(s);
  }

  /// Slots of the points within `radius` of q, in cell order then slot order. Throws
  /// InvalidParameter unless radius is finite and > 0.
  int query(const Eigen::Vector3f& q, float radius, std::vector<int>& slots, Cursor& cursor) const;

  /// Input indices of the points within `radius` of q, sorted by squared distance then by
  /// index; `sq_distances` (optional) gets the matching squared distances.
  int radiusSearch(const Eigen::Vector3f& q, float radius, std::vector<int>& indices,
                   std::vector<float>* sq_distances = nullptr) const;

  /// Fills the list of input point `index` (self first) when its ball is over the cap.
  using Overflow = std::function<void(int index, std::vector<int>& list)>;

  /// Neighbour lists of every input point (NeighbourGraph conventions: self first, then by
  /// squared distance, ties by index; empty for non-finite points). open_ball keeps only
  /// squared distances < radius^2, the kd-tree (FLANN) convention. A ball of more than
  /// max_count (> 0) points keeps its first max_count, or is filled by `overflow` when set.
  /// Queries run in cell order; the result does not depend on the thread count. `total` is
  /// the size of the input array the grid was built on.
  NeighbourGraph radiusGraph(std::size_t total, float radius, bool open_ball = false,
                             const ProgressCallback& progress = {}, int max_count = 0,
                             const Overflow& overflow = {}) const;
  /// The same lists, for the points in slots [slot_begin, slot_end) only (the others get
  /// empty lists): a graph too large to hold at once, built a block of cells at a time.
  NeighbourGraph radiusGraph(std::size_t total, float radius, bool open_ball, const ProgressCallback& progress,
                             int max_count, const Overflow& overflow, std::size_t slot_begin,
                             std::size_t slot_end) const;

 private:
  static constexpr double kMaxCell = double((1 << 21) - 4);  // largest cell coordinate
  static std::uint64_t pack(std::uint64_t x, std::uint64_t y, std::uint64_t z) { return x | (y << 21) | (z << 42); }
  bool buildWindow(const Positions& points);
  std::uint64_t keyOf(const Eigen::Vector3f& p) const;
  /// Cell coordinate of v along `axis`, and of p (before the window's clamp), as doubles.
  double coordinate(int axis, double v) const;
  Eigen::Vector3d coordinates(const Eigen::Vector3f& p) const;
  void prepare(const Eigen::Vector3f& q, float reach, Cursor& cursor) const;

  double cell_ = 0, inv_ = 0;
  bool windowed_ = false;  // far points clamped into the border cells (see build)
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  bool anchored_ = false;
  Eigen::Vector3d base_ = Eigen::Vector3d::Zero();  // anchored: the lattice cell of coordinate 0
  std::int64_t top_[3] = {0, 0, 0};  // largest occupied cell coordinate per axis
  std::vector<std::uint64_t> keys_;   // occupied cells, ascending
  std::vector<int> start_;            // first slot of each occupied cell, then size()
  std::vector<int> original_;
  Positions sorted_;
};

/// Neighbour lists within `radius` (closed ball) of every point through a CellGrid of side
/// `radius`: self first, then by squared distance, ties by index; a list over max_count (> 0)
/// keeps its first (nearest) max_count. Throws InvalidParameter on a radius that is not finite
/// and > 0, or smaller than extent / 2^21 of the points.
NeighbourGraph gridRadiusGraph(const Positions& points, float radius, const ProgressCallback& progress = {},
                               int max_count = 0);

}  // namespace paps
