#include <paps/core/tiling.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include <paps/core/error.h>
#include <paps/core/spatial_order.h>

namespace paps {

namespace {
using Box = BoundingBox;

// Halves `ids` at the median of the longest side until each part holds at most max_core
// points. The order key is the coordinate along that side, then the position (x, y, z), and
// every point whose key equals the median's goes left: copies of a position stay together and
// the parts depend on the positions only.
void split(const Positions& points, std::vector<int> ids, std::size_t max_core, std::vector<std::vector<int>>& out) {
  if (ids.size() <= max_core) {
    out.push_back(std::move(ids));
    return;
  }
  const Box b = boundingBox(points, ids);
  int axis = 0;
  (b.hi - b.lo).maxCoeff(&axis);
  auto before = [&](int i, int j) {
    const Eigen::Vector3f &p = points[i], &q = points[j];
    if (p[axis] != q[axis]) return p[axis] < q[axis];
    return coordinatesBefore(p, q);
  };
  const auto mid = ids.begin() + static_cast<std::ptrdiff_t>((ids.size() - 1) / 2);  // left: ceil(n / 2)
  std::nth_element(ids.begin(), mid, ids.end(), before);
  const int median = *mid;
  std::vector<int> left, right;
  for (const int i : ids) (before(median, i) ? right : left).push_back(i);
  if (right.empty()) {
    // The median is the last position and has copies: the cut goes before them instead (a
    // pile of copies at the end of the axis used to stop the split, and stay with up to half
    // the points). When nothing lies before them, all are copies of one position: one tile.
    left.clear();
    for (const int i : ids) (before(i, median) ? left : right).push_back(i);
    if (left.empty()) {
      out.push_back(std::move(right));
      return;
    }
  }
  std::vector<int>().swap(ids);
  split(points, std::move(left), max_core, out);
  split(points, std::move(right), max_core, out);
}
}  // namespace

std::vector<Tile> splitIntoTiles(const Positions& points, std::size_t max_core, float margin) {
  if (max_core == 0) throw InvalidParameter("max_core", "0", "at least 1");
  if (!(margin >= 0) || !std::isfinite(margin))
    throw InvalidParameter("margin", std::to_string(margin), "a finite distance >= 0");
  std::vector<int> finite;
  for (std::size_t i = 0; i < points.size(); ++i)
    if (isFinite(points[i])) finite.push_back(static_cast<int>(i));
  std::vector<std::vector<int>> cores;
  if (!finite.empty()) split(points, std::move(finite), max_core, cores);
  // The tiles come in split order (left before right), which depends on the positions only.
  std::vector<Tile> tiles(cores.size());
  std::vector<int> owner(points.size(), -1);
  for (std::size_t t = 0; t < cores.size(); ++t) {
    std::sort(cores[t].begin(), cores[t].end());
    for (const int i : cores[t]) owner[i] = static_cast<int>(t);
    tiles[t].core = std::move(cores[t]);
  }
  for (std::size_t t = 0; t < tiles.size(); ++t) {
    Box b = boundingBox(points, tiles[t].core);
    b.lo.array() -= margin;
    b.hi.array() += margin;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (owner[i] < 0 || owner[i] == static_cast<int>(t)) continue;
      const Eigen::Vector3f& p = points[i];
      if ((p.array() >= b.lo.array()).all() && (p.array() <= b.hi.array()).all())
        tiles[t].halo.push_back(static_cast<int>(i));
    }
  }
  return tiles;
}

Positions runInTiles(const Positions& points, const std::vector<std::uint8_t>& movable,
                     const std::vector<Tile>& tiles, const TileStage& stage) {
  if (!movable.empty() && movable.size() != points.size())
    throw InvalidParameter("movable", std::to_string(movable.size()) + " flags",
                           "one per point (" + std::to_string(points.size()) + ")");
  Positions out = points;
  for (std::size_t t = 0; t < tiles.size(); ++t) {
    const Tile& tile = tiles[t];
    Positions local;
    std::vector<std::uint8_t> local_movable;
    local.reserve(tile.core.size() + tile.halo.size());
    for (const auto* list : {&tile.core, &tile.halo})
      for (const int i : *list) {
        local.push_back(points[i]);
        if (!movable.empty()) local_movable.push_back(movable[i]);
      }
    const Positions moved = stage(local, local_movable, t);
    if (moved.size() != local.size())
      throw InvalidInput("tile " + std::to_string(t) + ": the stage returned " + std::to_string(moved.size()) +
                         " positions for " + std::to_string(local.size()) + " points");
    for (std::size_t k = 0; k < tile.core.size(); ++k) out[tile.core[k]] = moved[k];
  }
  return out;
}

std::vector<int> pointsAroundTile(const Positions& cloud, const Tile& tile, const Positions& other, float margin) {
  Box b = boundingBox(cloud, tile.core);
  b.lo.array() -= margin;
  b.hi.array() += margin;
  std::vector<int> inside;
  for (std::size_t i = 0; i < other.size(); ++i)
    if (isFinite(other[i]) && (other[i].array() >= b.lo.array()).all() && (other[i].array() <= b.hi.array()).all())
      inside.push_back(static_cast<int>(i));
  return inside;
}

std::vector<int> tileHalo(const Positions& points, const std::vector<int>& core, float margin) {
  if (!(margin >= 0)) throw InvalidParameter("margin", std::to_string(margin), "a distance >= 0");
  // The grown box's points of the cloud itself, less the core.
  const std::vector<int> inside = pointsAroundTile(points, Tile{core, {}}, points, margin);
  std::vector<int> halo;
  std::set_difference(inside.begin(), inside.end(), core.begin(), core.end(), std::back_inserter(halo));
  return halo;
}

ProgressCallback tileProgress(const ProgressCallback& progress, std::size_t tile, std::size_t tiles) {
  return partProgress(progress, "tile", tile, tiles);
}

Positions runSortedInTiles(const Positions& points, const std::vector<std::uint8_t>& movable,
                           const std::vector<Tile>& tiles, const SortedTileStage& stage,
                           const ProgressCallback& progress, std::vector<std::uint8_t>* status,
                           std::uint8_t pile_status, std::size_t* largest_tile) {
  if (status) status->assign(points.size(), 0);
  if (largest_tile) *largest_tile = 0;
  return runInTiles(points, movable, tiles, [&](const Positions& p, const std::vector<std::uint8_t>& m, std::size_t t) {
    const std::size_t core = tiles[t].core.size();
    if (largest_tile) *largest_tile = std::max(*largest_tile, p.size());
    if (!m.empty() && std::none_of(m.begin(), m.begin() + static_cast<std::ptrdiff_t>(core),
                                   [](std::uint8_t v) { return v != 0; }))
      return p;
    if (finiteCountAtOnePosition(p) >= 2) {  // a pile of copies
      if (status)
        for (const int i : tiles[t].core) (*status)[i] = pile_status;
      return p;
    }
    const ProgressCallback sub = tileProgress(progress, t, tiles.size());
    const std::vector<int> order = spatialOrderAll(p);
    std::vector<std::uint8_t> sorted_status;
    const Positions sorted_out = stage(gathered(p, order), m.empty() ? m : gathered(m, order), sorted_status, t, sub);
    if (sorted_out.size() != p.size())
      throw InvalidInput("tile " + std::to_string(t) + ": the stage returned " + std::to_string(sorted_out.size()) +
                         " positions for " + std::to_string(p.size()) + " points");
    Positions o(p.size());
    for (std::size_t k = 0; k < order.size(); ++k) {
      o[order[k]] = sorted_out[k];
      const std::size_t local = static_cast<std::size_t>(order[k]);
      if (status && local < core && k < sorted_status.size()) (*status)[tiles[t].core[local]] = sorted_status[k];
    }
    return o;
  });
}

BoundingBox boundingBox(const Positions& points, const std::vector<int>& ids) {
  BoundingBox b;
  for (const int i : ids) b.add(points[i]);
  return b;
}

Positions pointsNearBox(const Positions& points, const BoundingBox& box, float margin) {
  Positions near;
  for (const Eigen::Vector3f& p : points)
    if (box.distance(p) <= margin) near.push_back(p);
  return near;
}

std::vector<std::size_t> splitInProportion(std::size_t total, const std::vector<std::size_t>& weights) {
  const double sum = static_cast<double>(std::accumulate(weights.begin(), weights.end(), std::size_t(0)));
  std::vector<std::size_t> share(weights.size(), 0);
  if (!(sum > 0)) return share;
  std::vector<std::pair<double, std::size_t>> rest;
  std::size_t given = 0;
  for (std::size_t t = 0; t < weights.size(); ++t) {
    const double exact = static_cast<double>(total) * static_cast<double>(weights[t]) / sum;
    share[t] = static_cast<std::size_t>(std::floor(exact));
    given += share[t];
    rest.push_back({exact - static_cast<double>(share[t]), t});
  }
  std::stable_sort(rest.begin(), rest.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  for (std::size_t k = 0; given < total && k < rest.size(); ++k, ++given) ++share[rest[k].second];
  return share;
}

std::size_t occupiedCells(const Positions& points, const std::vector<int>& ids, float cell) {
  std::vector<std::array<std::int64_t, 3>> keys;
  keys.reserve(ids.size());
  for (const int i : ids) {
    const Eigen::Vector3d c = (points[i].cast<double>() / cell).array().floor();
    keys.push_back({static_cast<std::int64_t>(c.x()), static_cast<std::int64_t>(c.y()), static_cast<std::int64_t>(c.z())});
  }
  std::sort(keys.begin(), keys.end());
  return static_cast<std::size_t>(std::unique(keys.begin(), keys.end()) - keys.begin());
}

std::vector<std::size_t> runTileShares(const std::vector<std::size_t>& shares,
                                       const std::function<bool(std::size_t, std::size_t)>& run,
                                       const std::function<void(std::size_t)>& undo) {
  std::vector<std::size_t> made;
  std::size_t carried = 0, last_count = 0;
  for (std::size_t t = 0; t < shares.size(); ++t) {
    if (shares[t] + carried == 0) continue;
    if (!run(t, shares[t] + carried)) {
      carried += shares[t];
      continue;
    }
    last_count = shares[t] + carried;
    carried = 0;
    made.push_back(t);
  }
  if (!made.empty() && carried > 0) {
    undo(made.back());
    run(made.back(), last_count + carried);
  }
  return made;
}

}  // namespace paps
