#include <paps/filters/point_bilateral_filter.h>
#include <paps/filters/impl/point_bilateral_filter.hpp>

#include <cmath>

#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/spatial_order.h>
#include <paps/core/tiling.h>

namespace paps {

void PointBilateralParameters::validate() const {
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "0 (automatic) or a finite value > 0");
  requireInRange("target_neighbours", target_neighbours, 3, 1000);
  requirePositive("sigma_c_fraction", sigma_c_fraction);
  if (!(sigma_s >= 0) || !std::isfinite(sigma_s))
    throw InvalidParameter("sigma_s", detail::toString(sigma_s), "0 (automatic) or a finite value > 0");
  requireInRange("iterations", iterations, 1, 100);
  if (max_tile_points >= (std::size_t(1) << 31))
    throw InvalidParameter("max_tile_points", std::to_string(max_tile_points), "0 (one piece) or a count below 2^31");
}

namespace {
constexpr std::uint8_t kMoved = 1, kIsolated = 2;

// `status`, when given, gets what the last pass did to each point: kMoved, kIsolated or 0.
Positions bilateralInSpatialOrder(const Positions& points, const PointBilateralParameters& params,
                                  PointBilateralReport* report_out, const std::vector<std::uint8_t>& movable,
                                  const ProgressCallback& progress, std::vector<std::uint8_t>* status = nullptr) {
  PointBilateralReport report;
  const std::size_t n = points.size();
  if (status) status->assign(n, 0);
  const std::size_t finite = checkMovableInput(points, movable);
  report.non_finite = n - finite;
  if (finite == 1) {
    report.isolated = 1;
    if (status)
      for (std::size_t i = 0; i < n; ++i)
        if (isFinite(points[i])) (*status)[i] = kIsolated;
    if (report_out) *report_out = report;
    return points;
  }
  const int cap = std::max(64, 4 * params.target_neighbours);
  RadiusNeighbourhood nb =
      buildRadiusNeighbourhood(points, params.radius, params.target_neighbours, cap, progress, nullptr,
                               /*check_extent=*/false);  // checked on the whole cloud (bilateralFilterPositions)
  report.radius = nb.radius;
  const float inv2c = 1.f / (2.f * std::pow(params.sigma_c_fraction * nb.radius, 2.f));
  Positions cur = points, next = points;
  const std::int64_t sn = static_cast<std::int64_t>(n);
  ProgressReporter rep(progress, "bilateral", static_cast<std::size_t>(params.iterations) * n);
  for (int it = 0; it < params.iterations; ++it) {
    const bool last = it + 1 == params.iterations;
    // Neighbour lists stay those of the input; normals follow the filtered surface.
    const Normals normals = estimateNormals(cur, nb.graph);
    std::size_t moved = 0, isolated = 0;
#pragma omp parallel for schedule(dynamic, 1024) reduction(+ : moved, isolated)
    for (std::int64_t i = 0; i < sn; ++i) {
      rep.advance();
      if (!isFinite(cur[i]) || (!movable.empty() && !movable[i])) continue;
      if (!isFinite(normals[i]) || nb.graph.count(i) < 4) {
        ++isolated;
        if (status && last) (*status)[i] = kIsolated;
        continue;
      }
      const Eigen::Vector3f& p = cur[i];
      const Eigen::Vector3f& nrm = normals[i];
      float inv2s;
      if (params.sigma_s > 0) {
        inv2s = 1.f / (2.f * params.sigma_s * params.sigma_s);
      } else {
        double s2 = 0;
        for (const int* j = nb.graph.begin(i); j != nb.graph.end(i); ++j) s2 += std::pow(nrm.dot(cur[*j] - p), 2.f);
        s2 /= nb.graph.count(i);
        inv2s = s2 > 0 ? static_cast<float>(1.0 / (2.0 * s2)) : 0.f;
      }
      float num = 0, den = 0;
      for (const int* j = nb.graph.begin(i); j != nb.graph.end(i); ++j) {
        const Eigen::Vector3f d = cur[*j] - p;
        const float h = nrm.dot(d);
        const float w = std::exp(-d.squaredNorm() * inv2c - h * h * inv2s);
        num += w * h;
        den += w;
      }
      next[i] = den > 0 ? Eigen::Vector3f(p + (num / den) * nrm) : p;
      moved += next[i] != p;  // weights that all underflow (a tiny sigma) leave it in place
      if (status && last && next[i] != p) (*status)[i] = kMoved;
    }
    rep.throwIfCancelled();
    std::swap(cur, next);
    next = cur;
    report.moved = moved;
    report.isolated = isolated;
  }
  rep.finish();
  if (report_out) *report_out = report;
  return cur;
}

// The tiled run (PointBilateralParameters::max_tile_points). The radius is chosen once, on the
// whole cloud in spatial order as the one-piece run chooses it. A point's output after k
// passes reads the points within k radii of it (each pass reads the neighbours within the
// radius), so halos of `iterations` radii give every core point what the one-piece run gives it.
Positions filterInTiles(const Positions& points, const PointBilateralParameters& params,
                        PointBilateralReport* report_out, const std::vector<std::uint8_t>& movable,
                        const ProgressCallback& progress) {
  PointBilateralParameters run = params;
  run.max_tile_points = 0;
  if (!(run.radius > 0)) {
    const Positions sorted = gathered(points, spatialOrderAll(points));
    const SpatialIndex index(sorted);
    run.radius = radiusForNeighbourCount(sorted, index, run.target_neighbours);
  }
  PointBilateralReport report;
  const std::vector<Tile> tiles = splitIntoTiles(points, params.max_tile_points, run.iterations * run.radius);
  report.tiles = tiles.size();
  std::vector<std::uint8_t> status;
  const Positions out = runSortedInTiles(
      points, movable, tiles,
      [&](const Positions& p, const std::vector<std::uint8_t>& m, std::vector<std::uint8_t>& st, std::size_t,
          const ProgressCallback& sub) {
        return bilateralInSpatialOrder(p, run, nullptr, m, sub, &st);
      },
      progress, &status, kIsolated, &report.largest_tile);
  for (const std::uint8_t s : status) {
    report.moved += s == kMoved;
    report.isolated += s == kIsolated;
  }
  report.radius = run.radius;
  report.non_finite = points.size() - countFinite(points);
  if (report_out) *report_out = report;
  return out;
}
}  // namespace

Positions bilateralFilterPositions(const Positions& points, const PointBilateralParameters& params,
                                   PointBilateralReport* report_out,
                                   const std::vector<std::uint8_t>& movable,
                                   const ProgressCallback& progress) {
  params.validate();
  checkMovableInput(points, movable);
  if (leaveOnePositionAsItIs(points, report_out)) return points;
  requireRadiusWithinExtent("radius", params.radius, points);
  if (params.max_tile_points > 0 && countFinite(points) > params.max_tile_points)
    return filterInTiles(points, params, report_out, movable, progress);
  // In Z order, as the similarity denoiser (1M shuffled points: 2.05 s in input order,
  // 1.40 s sorted); the output then does not depend on the input order.
  return runInSpatialOrder(points, movable, [&](const Positions& p, const std::vector<std::uint8_t>& m) {
    return bilateralInSpatialOrder(p, params, report_out, m, progress);
  });
}

template class PointBilateralFilter<pcl::PointXYZ>;
template class PointBilateralFilter<pcl::PointXYZI>;
template class PointBilateralFilter<pcl::PointNormal>;
template class PointBilateralFilter<pcl::PointXYZRGB>;
template class PointBilateralFilter<pcl::PointXYZRGBA>;  // RGB-D cameras (PCL's OpenNI2 and RealSense grabbers)
template class PointBilateralFilter<pcl::PointXYZRGBNormal>;

}  // namespace paps
