#include <paps/core/normal_refresh.h>

#include <cmath>

#include <paps/core/cell_grid.h>
#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/spatial_order.h>

namespace paps {

namespace {
bool usable(const Eigen::Vector3f& n) { return isFinite(n) && n.squaredNorm() > 0.25f; }
}  // namespace

NormalRefresh refreshNormals(const Positions& points, float radius, const Normals& previous,
                             const std::vector<std::uint8_t>& moved,
                             const std::optional<Eigen::Vector3f>& viewpoint) {
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "a finite value >= 0 (0: no neighbourhood)");
  if (previous.size() != points.size())
    throw InvalidParameter("previous normals", detail::toString(previous.size()), "one per point");
  if (!moved.empty() && moved.size() != points.size())
    throw InvalidParameter("moved", detail::toString(moved.size()), "one flag per point");
  if (viewpoint && !isFinite(*viewpoint)) throw InvalidParameter("viewpoint", "not finite", "finite coordinates");
  NormalRefresh r;
  r.normals = previous;
  r.variation.assign(points.size(), NAN);
  if (points.empty()) return r;
  auto is_moved = [&](std::size_t i) { return moved.empty() || moved[i] != 0; };

  // In spatial order, so that the propagation's blocks (and so the signs) do not depend on
  // the order of the input.
  const std::vector<int> order = spatialOrderAll(points);
  const Positions sorted = gathered(points, order);
  const std::size_t n = sorted.size();
  Normals fresh(n, Eigen::Vector3f::Constant(NAN));
  std::vector<float> variation(n, NAN);
  // The side each normal takes: the sum of the previous normals over its ball. A noisy
  // previous normal can stand near 90 degrees from the new one, and its sign alone then flips
  // a few percent of them (rs1 at 0.5% noise: 3.8%); the ball's sum is far steadier.
  Normals hint(n, Eigen::Vector3f::Zero());
  bool all_hinted = true;
  // PCA normal and hint of the points at `rows` (indices into sorted) from their lists in `graph`.
  auto estimate = [&](const NeighbourGraph& graph, const int* rows, std::size_t count) {
    bool hinted = true;
#pragma omp parallel for schedule(dynamic, 512) reduction(&& : hinted)
    for (std::int64_t r = 0; r < static_cast<std::int64_t>(count); ++r) {
      const int k = rows[r];
      fresh[k] = pcaNormal(sorted, graph.begin(k), graph.count(k), nullptr, &variation[k]);
      if (!is_moved(order[k]) || !isFinite(fresh[k])) continue;
      for (const int* j = graph.begin(k); j != graph.end(k); ++j) {
        const Eigen::Vector3f& q = previous[order[*j]];
        if (usable(q)) hint[k] += q.normalized();
      }
      hinted = hinted && hint[k].squaredNorm() > 0;
    }
    all_hinted = all_hinted && hinted;
  };
  // Radius 0 (a filter that found no neighbourhood, e.g. one point, or every point at one
  // position): no new estimate anywhere.
  CellGrid grid;
  if (radius > 0 && grid.build(sorted, radius)) {
    // The lists of up to kRefreshNormalNeighbours points are built a block of cells at a time
    // (the same lists as in one go): at 64 a point they weighed about 0.26 KB a point, more
    // than a tiled denoiser (docs/denoising.md, item 8). Propagation reads the nearest
    // kPropagationNeighbours of each list only: those are built for every point.
    constexpr std::size_t kBlock = 1 << 20;
    for (std::size_t b = 0; b < grid.size(); b += kBlock) {
      const std::size_t e = std::min(grid.size(), b + kBlock);
      const NeighbourGraph block = grid.radiusGraph(n, radius, true, {}, kRefreshNormalNeighbours, {}, b, e);
      estimate(block, grid.original().data() + b, e - b);
    }
    if (!all_hinted) {
      if (viewpoint) orientNormalsTowards(sorted, fresh, *viewpoint);
      else orientNormalsByPropagation(sorted, fresh, grid.radiusGraph(n, radius, true, {}, kPropagationNeighbours));
    }
  } else {
    const NeighbourGraph graph =
        radius > 0 ? NeighbourGraph::byRadius(sorted, SpatialIndex(sorted), radius, kRefreshNormalNeighbours)
                   : NeighbourGraph::fromRows(std::vector<std::int64_t>(n + 1, 0), {});
    std::vector<int> all(n);
    for (std::size_t k = 0; k < n; ++k) all[k] = static_cast<int>(k);
    estimate(graph, all.data(), n);
    if (!all_hinted) {
      if (viewpoint) orientNormalsTowards(sorted, fresh, *viewpoint);
      else orientNormalsByPropagation(sorted, fresh, graph);
    }
  }
  for (std::size_t k = 0; k < order.size(); ++k) {
    const auto i = static_cast<std::size_t>(order[k]);
    if (!is_moved(i)) continue;
    Eigen::Vector3f n = fresh[k];
    if (!isFinite(n)) {
      // No estimate (too few neighbours, collinear or coincident ones): the input's normal,
      // when it had one, is still the best there is; otherwise NaN, as PCL's.
      if (!isFinite(points[i])) continue;  // not a point: passed through as it was
      if (usable(previous[i])) ++r.kept_previous;
      else r.normals[i] = n, ++r.without_normal;
      continue;
    }
    if (n.dot(hint[k]) < 0) n = -n;
    r.normals[i] = n;
    r.variation[i] = variation[k];
    ++r.refreshed;
  }
  return r;
}

bool anyUsableNormal(const Normals& normals) {
  for (const auto& n : normals)
    if (usable(n)) return true;
  return false;
}

std::size_t orientNormalsByNearbyHints(const Positions& points, Normals& normals, const Positions& hint_points,
                                       const Normals& hint_normals) {
  if (normals.size() != points.size())
    throw InvalidParameter("normals", detail::toString(normals.size()), "one per point");
  if (hint_normals.size() != hint_points.size())
    throw InvalidParameter("hint normals", detail::toString(hint_normals.size()), "one per hint point");
  if (!anyUsableNormal(hint_normals)) return 0;
  const SpatialIndex index(hint_points);
  std::size_t turned = 0;
#pragma omp parallel reduction(+ : turned)
  {
    std::vector<int> nn;
    std::vector<float> d2;
#pragma omp for schedule(static)
    for (std::int64_t i = 0; i < static_cast<std::int64_t>(points.size()); ++i) {
      Eigen::Vector3f& n = normals[static_cast<std::size_t>(i)];
      if (!isFinite(n) || !isFinite(points[static_cast<std::size_t>(i)])) continue;
      index.nearestK(points[static_cast<std::size_t>(i)], 16, nn, d2);
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      for (const int j : nn)
        if (usable(hint_normals[static_cast<std::size_t>(j)])) sum += hint_normals[static_cast<std::size_t>(j)].normalized();
      if (n.dot(sum) < 0) {
        n = -n;
        ++turned;
      }
    }
  }
  return turned;
}

}  // namespace paps
