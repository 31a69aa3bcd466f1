#include <paps/core/cell_grid.h>

#include <algorithm>
#include <memory>
#include <numeric>

#include <cstring>

#include <paps/core/error.h>
#include <paps/core/key_sort.h>

namespace paps {

namespace {

// Sort key of a neighbour: the bits of d2 (ordered as integers for d2 >= 0), then the index.
std::uint64_t distanceIndexKey(float d2, int index) {
  std::uint32_t bits;
  std::memcpy(&bits, &d2, sizeof bits);
  return (static_cast<std::uint64_t>(bits) << 32) | static_cast<std::uint32_t>(index);
}

// The capped list of slot t from the kd-tree over the grid's points: the max_count + kTreeExtra
// nearest, keyed and sorted as the scan keys them (self first, then distance and index), kept
// in buf (max_count keys) when the ball is over the cap and the max_count-th is nearer than
// the farthest returned by a relative 1e-5 (so neither a tie nor another rounding of the
// distances in the tree can change the list); false otherwise.
constexpr int kTreeExtra = 16;
__attribute__((noinline)) bool cappedListFromTree(const SpatialIndex& tree, const Positions& sorted,
                                                  const std::vector<int>& original, std::int64_t t, int max_count,
                                                  float max_d2, std::vector<int>& knn, std::vector<float>& kd2,
                                                  std::vector<std::uint64_t>& buf) {
  const Eigen::Vector3f& q = sorted[t];
  const int n = tree.nearestK(q, max_count + kTreeExtra, knn, kd2);
  if (n < max_count + kTreeExtra) return false;
  // (Filled by index, not push_back: a second call site of buf's push_back made the compiler
  // move it out of the scan's loop.)
  buf.resize(static_cast<std::size_t>(n));
  float farthest = 0.f;
  for (int j = 0; j < n; ++j) {
    const int s = knn[j];
    const float d2 = (sorted[s] - q).squaredNorm();
    farthest = std::max(farthest, d2);
    buf[static_cast<std::size_t>(j)] = s == t ? static_cast<std::uint32_t>(original[s])
                                              : distanceIndexKey(d2, original[s]) + (std::uint64_t(1) << 32);
  }
  std::sort(buf.begin(), buf.end());
  auto distanceOf = [](std::uint64_t key) {
    if ((key >> 32) == 0) return 0.f;
    const std::uint32_t bits = static_cast<std::uint32_t>((key >> 32) - 1);
    float d2;
    std::memcpy(&d2, &bits, sizeof d2);
    return d2;
  };
  if ((buf.front() >> 32) != 0) return false;  // self not among them: copies beyond the cap
  const float over = distanceOf(buf[static_cast<std::size_t>(max_count)]);
  const float last = distanceOf(buf[static_cast<std::size_t>(max_count) - 1]);
  if (!(over <= max_d2) || !(last < (1.f - 1e-5f) * farthest)) return false;
  buf.resize(static_cast<std::size_t>(max_count));
  return true;
}
}  // namespace

bool CellGrid::build(const Positions& points, float cell, bool anchored) {
  requirePositive("cell", cell);
  *this = CellGrid();
  cell_ = cell;
  inv_ = 1.0 / double(cell);
  anchored_ = anchored;
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  for (const auto& p : points)
    if (isFinite(p)) { lo = lo.cwiseMin(p); hi = hi.cwiseMax(p); }
  if (!(lo.x() <= hi.x())) return true;  // no finite point: an empty grid
  // Two cells of margin: every occupied coordinate is >= 1 even after rounding.
  origin_ = lo.cast<double>() - Eigen::Vector3d::Constant(2 * cell_);
  if (anchored_)
    for (int a = 0; a < 3; ++a) base_[a] = std::floor(double(lo[a]) * inv_) - 2;
  if (coordinates(hi).maxCoeff() > kMaxCell && !buildWindow(points)) return false;
  const Eigen::Vector3d top = coordinates(hi);
  for (int a = 0; a < 3; ++a) top_[a] = static_cast<std::int64_t>(std::clamp(top[a], 0.0, kMaxCell));
  std::vector<std::pair<std::uint64_t, int>> keyed;
  keyed.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i)
    if (isFinite(points[i])) keyed.emplace_back(keyOf(points[i]), static_cast<int>(i));
  sortByKey(keyed);  // indices in order: points of a cell stay in index order
  original_.resize(keyed.size());
  sorted_.resize(keyed.size());
  for (std::size_t s = 0; s < keyed.size(); ++s) {
    original_[s] = keyed[s].second;
    sorted_[s] = points[keyed[s].second];
    if (s == 0 || keyed[s].first != keyed[s - 1].first) {
      keys_.push_back(keyed[s].first);
      start_.push_back(static_cast<int>(s));
    }
  }
  start_.push_back(static_cast<int>(keyed.size()));
  return true;
}

bool CellGrid::buildWindow(const Positions& points) {
  // A few far points (a stray LiDAR return kilometres away) would make the grid too wide to
  // key. The grid is then a window of kMaxCell cells centred on the median point, and points
  // outside it are filed in its border cells: clamping is monotone, so every point within
  // reach of a query still lies in the (clamped) box of cells the query scans, and the exact
  // distance test keeps the results those of the full grid. Only the time grows with the
  // points outside, hence the limit.
  constexpr std::size_t kMaxOutside = 4096;
  // No lower than the full grid's origin.
  const Eigen::Vector3d median = medianPoint(points);
  origin_ = origin_.cwiseMax(median - Eigen::Vector3d::Constant(0.5 * kMaxCell * cell_));
  if (anchored_)
    for (int a = 0; a < 3; ++a) base_[a] = std::max(base_[a], std::floor(median[a] * inv_ - 0.5 * kMaxCell));
  std::size_t outside = 0;
  for (const auto& p : points) {
    if (!isFinite(p)) continue;
    const Eigen::Vector3d c = coordinates(p);
    outside += c.minCoeff() < 0 || c.maxCoeff() > kMaxCell;
    if (outside > kMaxOutside) return false;
  }
  windowed_ = true;
  return true;
}

double CellGrid::coordinate(int axis, double v) const {
  // Anchored: v / cell less a whole number is exact in double (|v / cell| < 2^52), so a point
  // falls in the same lattice cell whatever the base.
  return anchored_ ? v * inv_ - base_[axis] : (v - origin_[axis]) * inv_;
}

Eigen::Vector3d CellGrid::coordinates(const Eigen::Vector3f& p) const {
  return {coordinate(0, p.x()), coordinate(1, p.y()), coordinate(2, p.z())};
}

std::uint64_t CellGrid::keyOf(const Eigen::Vector3f& p) const {
  Eigen::Vector3d c = coordinates(p);
  if (windowed_) c = c.cwiseMax(0.0).cwiseMin(kMaxCell);
  return pack(std::uint64_t(c.x()), std::uint64_t(c.y()), std::uint64_t(c.z()));
}

void CellGrid::prepare(const Eigen::Vector3f& q, float reach, Cursor& cursor) const {
  // The box of cells within reach; the slack covers float rounding of the distance test, so
  // every point that passes it lies inside the box.
  const double slack = double(reach) * (1 + 1e-5);
  std::int64_t box[6];
  for (int a = 0; a < 3; ++a) {
    const double lo = std::floor(coordinate(a, double(q[a]) - slack));
    const double hi = std::floor(coordinate(a, double(q[a]) + slack));
    // Windowed: the box is clamped like the keys (a query outside scans the border cells).
    const double floor_at = windowed_ ? 0.0 : -1.0, ceil_at = double(top_[a]) + (windowed_ ? 0 : 1);
    box[2 * a] = static_cast<std::int64_t>(std::clamp(lo, floor_at, ceil_at));
    box[2 * a + 1] = static_cast<std::int64_t>(std::clamp(hi, floor_at, ceil_at));
    box[2 * a] = std::max<std::int64_t>(box[2 * a], 0);
    box[2 * a + 1] = std::min<std::int64_t>(box[2 * a + 1], top_[a]);
  }
  if (std::equal(box, box + 6, cursor.box)) return;
  std::copy(box, box + 6, cursor.box);
  cursor.ranges.clear();
  if (box[0] > box[1] || box[2] > box[3] || box[4] > box[5]) return;
  const std::int64_t width = box[1] - box[0] + 1;
  // A row of cells (fixed y, z) is one run of consecutive keys; rows come in ascending key
  // order, so each search starts where the previous one ended.
  auto from = keys_.begin();
  for (std::int64_t z = box[4]; z <= box[5]; ++z)
    for (std::int64_t y = box[2]; y <= box[3]; ++y) {
      const std::uint64_t first = pack(box[0], y, z), last = pack(box[1], y, z);
      const auto lo = std::lower_bound(from, keys_.end(), first);
      const auto cap = keys_.end() - lo > width ? lo + width : keys_.end();
      const auto hi = std::upper_bound(lo, cap, last);
      from = hi;
      if (lo == hi) continue;
      cursor.ranges.emplace_back(start_[static_cast<std::size_t>(lo - keys_.begin())],
                                 start_[static_cast<std::size_t>(hi - keys_.begin())]);
    }
}

int CellGrid::query(const Eigen::Vector3f& q, float radius, std::vector<int>& slots, Cursor& cursor) const {
  requirePositive("radius", radius);
  slots.clear();
  forEachWithin(q, radius, radius * radius, cursor, [&](int s, float) { slots.push_back(s); });
  return static_cast<int>(slots.size());
}

int CellGrid::radiusSearch(const Eigen::Vector3f& q, float radius, std::vector<int>& indices,
                           std::vector<float>* sq_distances) const {
  requirePositive("radius", radius);
  thread_local Cursor cursor;
  thread_local std::vector<std::uint64_t> keyed;
  keyed.clear();
  forEachWithin(q, radius, radius * radius, cursor,
                [&](int s, float d2) { keyed.push_back(distanceIndexKey(d2, original_[s])); });
  std::sort(keyed.begin(), keyed.end());
  indices.resize(keyed.size());
  if (sq_distances) sq_distances->resize(keyed.size());
  for (std::size_t k = 0; k < keyed.size(); ++k) {
    indices[k] = static_cast<int>(keyed[k] & 0xFFFFFFFFu);
    if (sq_distances) {
      const std::uint32_t bits = static_cast<std::uint32_t>(keyed[k] >> 32);
      std::memcpy(&(*sq_distances)[k], &bits, sizeof bits);
    }
  }
  return static_cast<int>(indices.size());
}

NeighbourGraph CellGrid::radiusGraph(std::size_t total, float radius, bool open_ball,
                                     const ProgressCallback& progress, int max_count,
                                     const Overflow& overflow) const {
  return radiusGraph(total, radius, open_ball, progress, max_count, overflow, 0, sorted_.size());
}

NeighbourGraph CellGrid::radiusGraph(std::size_t total, float radius, bool open_ball,
                                     const ProgressCallback& progress, int max_count,
                                     const Overflow& overflow, std::size_t slot_begin,
                                     std::size_t slot_end) const {
  requirePositive("radius", radius);
  slot_end = std::min(slot_end, sorted_.size());
  slot_begin = std::min(slot_begin, slot_end);
  // Largest float below r^2 for the open ball; never below 0, so a point always finds itself.
  float max_d2 = radius * radius;
  if (open_ball) max_d2 = std::max(0.f, std::nextafter(max_d2, -1.f));
  // Slots [first, m) are queried: all of them, or a block.
  const std::int64_t first = static_cast<std::int64_t>(slot_begin), m = static_cast<std::int64_t>(slot_end);
  // Queries in cell order (memory locality), by chunks whose lists are then put in place.
  const std::int64_t chunk = 256, chunks = (m - first + chunk - 1) / chunk;
  std::vector<std::vector<int>> found(static_cast<std::size_t>(chunks));
  std::vector<int> cnt(total, 0);
  ProgressReporter report(progress, "neighbours", total);
  // A capped ball keeps its max_count nearest. When the ball at a smaller reach already holds
  // max_count points, those are the max_count nearest of the whole ball (every point left out
  // is farther than all of them), so a crowded ball is first searched at a reach guessed from
  // the previous query's (its max_count-th distance, with a margin): fewer cells scanned and
  // fewer points to select from. A guess too short costs a second, full search; the lists are
  // exactly those of the full search either way.
  const bool guess_reach = max_count > 0 && !overflow;
  constexpr float kReachMargin = 1.15f;
  // Cells far more crowded than the cap (a 1 cm cluster beside a 1 km plane: 500K points in
  // one cell) cost every query of theirs a scan of the whole cell, whatever the reach: 159 s
  // for the denoiser on 1M such points. There a kd-tree gives the cap + kTreeExtra nearest,
  // keyed and sorted as the scan would; they are kept when the ball is over the cap and the
  // cap-th is nearer than the farthest returned by a relative 1e-5 (so neither a tie nor
  // another rounding of the distances in the tree can change the list), else the scan runs.
  constexpr int kCrowdedCell = 64;  // x max_count: a thread that scanned that many tries the tree
  constexpr int kTreeRest = 64;
  // The cells that hold queried slots: a block of slots prepares only those (a block-wise
  // caller would otherwise build the tree and sort the piles of the whole grid for every block).
  auto queried = [&](std::size_t k) { return start_[k] < m && start_[k + 1] > first; };
  int largest_cell = 0;
  for (std::size_t k = 0; k + 1 < start_.size(); ++k)
    if (queried(k)) largest_cell = std::max(largest_cell, start_[k + 1] - start_[k]);
  std::unique_ptr<SpatialIndex> tree;
  if (guess_reach && largest_cell > kCrowdedCell * max_count) tree = std::make_unique<SpatialIndex>(sorted_);
  // Piles: a point stored at least max_count times (itself included) has as its capped list
  // itself, then the max_count - 1 lowest indices among its other copies, all at distance 0:
  // what the scan would keep, without the scan (1M points on 10 positions: every query scanned
  // a cell of 100,000 points, and the denoiser took minutes). A pile lies in one cell.
  std::vector<int> pile_of;               // per slot: its pile, or -1
  std::vector<std::vector<int>> pile_low;  // per pile: its max_count lowest indices, ascending
  if (max_count > 0 && !overflow && largest_cell >= max_count) {
    pile_of.assign(sorted_.size(), -1);
    // A cell's slots by position (compared by value, as exactDuplicateRepresentatives: -0
    // equals +0), then by index: each pile is a run, its lowest indices first. Only the cells
    // that can hold a pile are sorted.
    auto less = [&](int a, int b) {
      const Eigen::Vector3f& p = sorted_[static_cast<std::size_t>(a)];
      const Eigen::Vector3f& q = sorted_[static_cast<std::size_t>(b)];
      if (p.x() != q.x()) return p.x() < q.x();
      if (p.y() != q.y()) return p.y() < q.y();
      if (p.z() != q.z()) return p.z() < q.z();
      return original_[a] < original_[b];
    };
    std::vector<int> cell;
    for (std::size_t k = 0; k + 1 < start_.size(); ++k) {
      if (start_[k + 1] - start_[k] < max_count || !queried(k)) continue;
      cell.resize(static_cast<std::size_t>(start_[k + 1] - start_[k]));
      std::iota(cell.begin(), cell.end(), start_[k]);
      std::sort(cell.begin(), cell.end(), less);
      for (std::size_t a = 0, b; a < cell.size(); a = b) {
        const Eigen::Vector3f& at = sorted_[static_cast<std::size_t>(cell[a])];
        for (b = a + 1; b < cell.size() && sorted_[static_cast<std::size_t>(cell[b])] == at; ++b) {
        }
        if (b - a < static_cast<std::size_t>(max_count)) continue;
        std::vector<int> low;
        for (std::size_t j = a; j < a + static_cast<std::size_t>(max_count); ++j) low.push_back(original_[cell[j]]);
        for (std::size_t j = a; j < b; ++j) pile_of[static_cast<std::size_t>(cell[j])] = static_cast<int>(pile_low.size());
        pile_low.push_back(std::move(low));
      }
    }
  }
#pragma omp parallel
  {
    Cursor cursor;
    std::vector<std::uint64_t> buf;
    std::vector<int> list, knn;
    std::vector<float> kd2;
    float guess = radius;  // per thread: the next query's reach
    bool crowded = false;  // per thread: the last scan visited more than kCrowdedCell x max_count
    int tree_rest = 0;     // per thread: queries left before the tree is tried again
#pragma omp for schedule(dynamic, 1)
    for (std::int64_t c = 0; c < chunks; ++c) {
      if (report.cancelled()) continue;
      const std::int64_t begin = first + c * chunk, end = std::min<std::int64_t>(m, begin + chunk);
      for (std::int64_t t = begin; t < end; ++t) {
        auto collect = [&](float reach, float reach_d2) {
          buf.clear();
          forEachWithin(sorted_[t], reach, reach_d2, cursor, [&](int s, float d2) {
            // Self first, even among exact duplicates.
            buf.push_back(s == t ? static_cast<std::uint32_t>(original_[s])
                                 : distanceIndexKey(d2, original_[s]) + (std::uint64_t(1) << 32));
          });
        };
        // Whether the last scan visited more than kCrowdedCell x max_count points.
        auto noteCrowding = [&]() {
          std::size_t scanned = 0;
          for (const auto& r : cursor.ranges) scanned += static_cast<std::size_t>(r.second - r.first);
          crowded = scanned > static_cast<std::size_t>(kCrowdedCell) * max_count;
        };
        // A tree answer that cannot be kept (copies beyond the cap, ties at the boundary) costs
        // a query for nothing: after one, the next kTreeRest queries of the thread scan (20
        // positions stored 10,000 times each: 3.3 s without the tree, 8.3 s trying it at
        // every query).
        bool listed = false;  // the capped list came without a scan (a pile, or the tree)
        const int pile = pile_of.empty() ? -1 : pile_of[static_cast<std::size_t>(t)];
        if (pile >= 0) {
          buf.assign(1, static_cast<std::uint32_t>(original_[t]));
          for (const int i : pile_low[static_cast<std::size_t>(pile)])
            if (i != original_[t] && buf.size() < static_cast<std::size_t>(max_count))
              buf.push_back(distanceIndexKey(0.f, i) + (std::uint64_t(1) << 32));
          listed = true;
        } else if (tree && crowded) {
          if (tree_rest > 0)
            --tree_rest;
          else if (!(listed = cappedListFromTree(*tree, sorted_, original_, t, max_count, max_d2, knn, kd2, buf)))
            tree_rest = kTreeRest;
        }
        if (listed) {
          // buf holds the capped list
        } else if (guess_reach && guess < radius) {
          collect(guess, std::min(max_d2, guess * guess));
          if (buf.size() < static_cast<std::size_t>(max_count)) collect(radius, max_d2);
        } else {
          collect(radius, max_d2);
        }
        if (tree && !listed) noteCrowding();
        if (max_count > 0 && buf.size() > static_cast<std::size_t>(max_count)) {
          if (overflow) {
            list.clear();
            overflow(original_[t], list);
            cnt[original_[t]] = static_cast<int>(list.size());
            found[c].insert(found[c].end(), list.begin(), list.end());
            continue;
          }
          // The keys are distinct (they hold the index): selecting the max_count smallest and
          // sorting only those gives the lists a full sort would, without sorting the rest of
          // a crowded ball (bun0: thousands of points in the balls of its dense parts).
          std::nth_element(buf.begin(), buf.begin() + max_count, buf.end());
          buf.resize(static_cast<std::size_t>(max_count));
        }
        std::sort(buf.begin(), buf.end());
        if (guess_reach) {
          // The max_count-th distance (the key's high word is its bits + 1; self is at 0).
          float kth = radius;
          if (buf.size() == static_cast<std::size_t>(max_count) && (buf.back() >> 32) > 0) {
            const std::uint32_t bits = static_cast<std::uint32_t>((buf.back() >> 32) - 1);
            float d2;
            std::memcpy(&d2, &bits, sizeof d2);
            kth = std::sqrt(d2);
          }
          guess = std::min(radius, kReachMargin * kth);
        }
        cnt[original_[t]] = static_cast<int>(buf.size());
        for (const std::uint64_t e : buf) found[c].push_back(static_cast<int>(e & 0xFFFFFFFFu));
      }
      report.advance(static_cast<std::size_t>(end - begin));
    }
  }
  report.throwIfCancelled();
  std::vector<std::int64_t> offsets(total + 1, 0);
  for (std::size_t i = 0; i < total; ++i) offsets[i + 1] = offsets[i] + cnt[i];
  std::vector<int> indices(static_cast<std::size_t>(offsets.back()));
#pragma omp parallel for schedule(dynamic, 1)
  for (std::int64_t c = 0; c < chunks; ++c) {
    std::size_t pos = 0;
    const std::int64_t begin = first + c * chunk, end = std::min<std::int64_t>(m, begin + chunk);
    for (std::int64_t t = begin; t < end; ++t) {
      const int i = original_[t];
      std::copy(found[c].begin() + pos, found[c].begin() + pos + cnt[i], indices.begin() + offsets[i]);
      pos += cnt[i];
    }
    std::vector<int>().swap(found[c]);
  }
  report.advance(total - static_cast<std::size_t>(m - first));
  report.finish();
  return NeighbourGraph::fromRows(std::move(offsets), std::move(indices));
}

NeighbourGraph gridRadiusGraph(const Positions& points, float radius, const ProgressCallback& progress,
                               int max_count) {
  requirePositive("radius", radius);
  CellGrid grid;
  if (!grid.build(points, radius))
    throw InvalidParameter("radius", detail::toString(radius),
                           "at least extent / 2^21 of the points, or fewer than 4096 points that far from the "
                           "median point; remove far outliers first");
  return grid.radiusGraph(points.size(), radius, false, progress, max_count);
}

}  // namespace paps
