#include <paps/surface/lpf_resampling.h>
#include <paps/surface/impl/lpf_resampling.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <unordered_map>

#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/spatial_order.h>
#include <paps/core/tiling.h>
#include <paps/filters/lpf_denoising.h>

namespace paps {

void LpfResamplingParameters::validate() const {
  probing.validate();
  requireInRange("factor", factor, 1.f, 100.f);
  if (!(tau_p >= 0) || !std::isfinite(tau_p))
    throw InvalidParameter("tau_p", detail::toString(tau_p), "0 (0.7 x the pattern step) or a finite value > 0");
  if (max_tile_points != 0 && (max_tile_points < 1000 || max_tile_points >= (std::size_t(1) << 31)))
    throw InvalidParameter("max_tile_points", std::to_string(max_tile_points),
                           "0 (one piece) or a count from 1000 to below 2^31");
  requireInRange("denoise_ratio", denoise_ratio, 0.01f, 100.f);
  requireInRange("denoise_passes", denoise_passes, 0, 50);
  if (!(tile_margin >= 2.5f && tile_margin <= 10.f))
    throw InvalidParameter("tile_margin", detail::toString(tile_margin), "2.5 to 10 pattern radii");
}

namespace {

// Cell of a position on a grid of cell `size`, packed in 64 bits (21 bits an axis, offset so
// that the cloud's box fits; callers check the extent).
struct CellKey {
  Eigen::Vector3f origin;
  float inv;
  std::uint64_t operator()(const Eigen::Vector3f& p, int dx = 0, int dy = 0, int dz = 0) const {
    const Eigen::Vector3f g = (p - origin) * inv;
    const std::uint64_t x = static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(g.x())) + 1 + dx);
    const std::uint64_t y = static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(g.y())) + 1 + dy);
    const std::uint64_t z = static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(g.z())) + 1 + dz);
    return (x << 42) | (y << 21) | z;
  }
};

// The proposals of eq. 3.7 of the fields of `points` (in spatial order), field by field; the
// report gets the analysis's radius, step, pattern and fields, and `tau` the consensus radius.
Positions proposeInSpatialOrder(const Positions& points, const LpfResamplingParameters& params,
                                LpfResamplingReport& report, float& tau, const ProgressCallback& progress,
                                bool check_extent) {
  // The analysis resolves the radius (from the neighbour count; no noise rule here: the
  // proposals are filtered at the input spacing that count implies) and the step (`factor`
  // nodes a point).
  LocalProbingParameters probing = params.probing;
  probing.noise_sigmas = 0.f;
  probing.nodes_per_point = params.factor;
  LocalProbingAnalysis analysis(points, probing, progress, check_extent);
  analysis.analyse(points, probing.rounds, progress);
  const ProbingPattern& pattern = analysis.pattern();
  const float r = analysis.radius();
  const float spacing = r * std::sqrt(3.14159265f / probing.neighbours);  // the 1:1 step
  report.radius = r;
  report.step = pattern.step();
  report.pattern_nodes = pattern.size();
  report.fields = analysis.fieldCount();
  tau = params.tau_p > 0 ? params.tau_p : 0.7f * pattern.step();
  const float target_r = probing.target_factor * r;

  // Proposals (eq. 3.7), field by field: the consolidated points s + R (u + D a). (Proposing
  // only the consolidated height above each node's own place did worse: 6.3e-4 against
  // 2.3e-4 on the plate of the bench, and on the wires crossings, whose fields are planar,
  // scattered points beside the wires, 7.1e-3 against 2.5e-3.)
  const std::int64_t nf = static_cast<std::int64_t>(analysis.fieldCount());
  std::vector<Positions> per_field(nf);
  const int m = pattern.size();
#pragma omp parallel for schedule(dynamic, 64)
  for (std::int64_t j = 0; j < nf; ++j) {
    const int dim = analysis.targetDimension(j);
    if (dim == 0) continue;
    const ProbingPose& pose = analysis.pose(j);
    const Eigen::VectorXf rec = analysis.reconstructed(j);
    for (int i = 0; i < m; ++i) {
      if (analysis.probedPoint(j, i) < 0) continue;
      const Eigen::Vector3f v = analysis.fields().col(j).segment<3>(3 * i);
      const Eigen::Vector3f d = rec.segment<3>(3 * i);
      const Eigen::Vector2f& u = pattern.node(i);
      // Off a wire every node probes the wire, past a border every node the border: only
      // the nodes near their probed point propose (the others' consolidated values would
      // scatter points across the wire or the border).
      if ((dim == 2 ? v.head<2>().norm() : v.norm()) > spacing) continue;
      const Eigen::Vector3f local = Eigen::Vector3f(u.x(), u.y(), 0.f) + d;
      const Eigen::Vector3f p = pose.seed + pose.frame * local;
      if (isFinite(p) && (p - analysis.targetCentre(j)).norm() <= target_r) per_field[j].push_back(p);
    }
  }
  Positions proposals;
  for (auto& f : per_field) {
    proposals.insert(proposals.end(), f.begin(), f.end());
    Positions().swap(f);
  }
  report.proposals = proposals.size();
  return proposals;
}

// An empty cloud is no answer (the PCL stage would hand it on as one).
InvalidInput noProposal(const Positions& points) {
  return InvalidInput("LPF resampling proposed no point: no field holds enough points (" +
                      std::to_string(countFinite(points)) + " finite points)");
}

// Consensus (eq. 3.8): in proposal order, a proposal that no kept point conflicts with (one
// within tau) gathers the proposals within tau of it; their mean is kept unless a kept point
// conflicts with it. Proposals on a grid of cells of tau, sorted by cell. `kept_before`
// (tiles: the points the tiles before kept near this one's proposals) conflict as kept
// points do, and are not returned.
Positions consensus(const Positions& proposals, float tau, const Positions& kept_before,
                    const ProgressCallback& progress) {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  for (const auto& p : proposals) { lo = lo.cwiseMin(p); hi = hi.cwiseMax(p); }
  for (const auto& p : kept_before) { lo = lo.cwiseMin(p); hi = hi.cwiseMax(p); }
  if (((hi - lo) / tau).maxCoeff() > 2e6f)
    throw InvalidParameter("tau_p", detail::toString(tau), "at least 1e-6 of the extent of the output (2 million cells an axis)");
  const CellKey key{lo - Eigen::Vector3f::Constant(tau), 1.f / tau};
  std::vector<std::uint64_t> keys(proposals.size());
  for (std::size_t k = 0; k < proposals.size(); ++k) keys[k] = key(proposals[k]);
  std::vector<std::uint32_t> order(proposals.size());
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return keys[a] != keys[b] ? keys[a] < keys[b] : a < b;
  });
  std::vector<std::uint64_t> sorted_keys(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) sorted_keys[k] = keys[order[k]];
  std::unordered_map<std::uint64_t, std::vector<int>> kept_cells;
  Positions kept = kept_before;
  for (std::size_t k = 0; k < kept.size(); ++k) kept_cells[key(kept[k])].push_back(static_cast<int>(k));
  const float tau2 = tau * tau;
  auto conflicts = [&](const Eigen::Vector3f& q) {
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = kept_cells.find(key(q, dx, dy, dz));
          if (it == kept_cells.end()) continue;
          for (int k : it->second)
            if ((kept[k] - q).squaredNorm() <= tau2) return true;
        }
    return false;
  };
  ProgressReporter rep(progress, "LPF consensus", proposals.size());
  for (std::size_t k = 0; k < proposals.size(); ++k) {
    rep.advance();
    const Eigen::Vector3f& q = proposals[k];
    if (conflicts(q)) continue;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int count = 0;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const std::uint64_t c = key(q, dx, dy, dz);
          auto range = std::equal_range(sorted_keys.begin(), sorted_keys.end(), c);
          for (auto it = range.first; it != range.second; ++it) {
            const Eigen::Vector3f& o = proposals[order[it - sorted_keys.begin()]];
            if ((o - q).squaredNorm() <= tau2) { sum += o.cast<double>(); ++count; }
          }
        }
    const Eigen::Vector3f mean = (sum / count).cast<float>();
    if (conflicts(mean)) continue;
    kept_cells[key(mean)].push_back(static_cast<int>(kept.size()));
    kept.push_back(mean);
    if (rep.cancelled()) break;
  }
  rep.throwIfCancelled();
  rep.finish();
  kept.erase(kept.begin(), kept.begin() + static_cast<std::ptrdiff_t>(kept_before.size()));
  return kept;
}

Positions resampleInSpatialOrder(const Positions& points, const LpfResamplingParameters& params,
                                 LpfResamplingReport* report_out, const ProgressCallback& progress) {
  LpfResamplingReport report;
  float tau = 0.f;
  Positions proposals = proposeInSpatialOrder(points, params, report, tau, progress, true);
  if (report_out) *report_out = report;
  if (proposals.empty()) throw noProposal(points);
  Positions kept = consensus(proposals, tau, {}, progress);
  report.output = kept.size();
  report.largest_tile = points.size();
  if (report_out) *report_out = report;
  return kept;
}

// The tiled run (max_tile_points): the pattern radius is chosen once, on the whole cloud in
// spatial order as one piece chooses it (so the same step and consensus radius); each tile's
// fields are analysed on its core and halo, and it keeps the proposals nearer its core's box
// than any other core's box (ties to the first tile), so that every proposal is made by the
// tile whose fields see all around it. The consensus runs tile after tile, the points the
// tiles before kept near this tile's proposals counting as kept: no two output points closer
// than tau, across the seams too.
// `radius` > 0: the pattern radius one piece would choose, already resolved on `points`.
Positions resampleInTiles(const Positions& points, const LpfResamplingParameters& params, float radius,
                          LpfResamplingReport* report_out, const ProgressCallback& progress) {
  LpfResamplingParameters run = params;
  run.max_tile_points = 0;
  run.probing.radius = radius;
  if (!(radius > 0)) {
    LocalProbingParameters probing = params.probing;
    probing.noise_sigmas = 0.f;  // as the one-piece analysis resolves it
    const Positions sorted = gathered(points, spatialOrderAll(points));
    const SpatialIndex index(sorted);
    run.probing.radius = LocalProbingAnalysis::chooseRadius(sorted, index, probing, nullptr);
  }
  const float r = run.probing.radius;
  const std::vector<Tile> tiles = splitIntoTiles(points, params.max_tile_points, params.tile_margin * r);
  std::vector<BoundingBox> boxes;
  for (const Tile& tile : tiles) boxes.push_back(boundingBox(points, tile.core));
  auto owner = [&](const Eigen::Vector3f& p, std::size_t t) {
    const float own = boxes[t].distance(p);
    for (std::size_t u = 0; u < tiles.size(); ++u)
      if (u != t) {
        const float other = boxes[u].distance(p);
        if (other < own || (other == own && u < t)) return false;
      }
    return true;
  };
  LpfResamplingReport report;
  report.tiles = tiles.size();
  Positions out;
  for (std::size_t t = 0; t < tiles.size(); ++t) {
    std::vector<int> members(tiles[t].core);
    members.insert(members.end(), tiles[t].halo.begin(), tiles[t].halo.end());
    report.largest_tile = std::max(report.largest_tile, members.size());
    const ProgressCallback sub = tileProgress(progress, t, tiles.size());
    Positions local = gathered(points, members);
    std::vector<int>().swap(members);
    local = gathered(local, spatialOrderAll(local));
    LpfResamplingReport r_t;
    float tau = 0.f;
    Positions proposals = proposeInSpatialOrder(local, run, r_t, tau, sub, false);
    Positions().swap(local);
    proposals.erase(std::remove_if(proposals.begin(), proposals.end(),
                                   [&](const Eigen::Vector3f& p) { return !owner(p, t); }),
                    proposals.end());
    report.radius = r_t.radius;
    report.step = r_t.step;
    report.pattern_nodes = r_t.pattern_nodes;
    report.fields += r_t.fields;
    report.proposals += proposals.size();
    if (proposals.empty()) continue;
    // The points the tiles before kept within tau of this tile's proposals' box.
    BoundingBox around;
    for (const auto& p : proposals) around.add(p);
    const Positions kept = consensus(proposals, tau, pointsNearBox(out, around, tau), sub);
    out.insert(out.end(), kept.begin(), kept.end());
  }
  if (out.empty()) throw noProposal(points);
  report.output = out.size();
  if (report_out) *report_out = report;
  return out;
}

// For the Auto rule of denoise_input and the automatic passes: the noise measured on the
// whole cloud (in spatial order, as the analysis reads it) at the pattern radius the
// analysis would choose without a noise rule, against the consensus radius that radius
// implies (report.noise_sigma, noise_ratio). Returns that radius.
float measureNoise(const Positions& sorted, const LpfResamplingParameters& params, LpfResamplingReport& report) {
  LocalProbingParameters probing = params.probing;
  probing.noise_sigmas = 0.f;
  probing.nodes_per_point = params.factor;
  const SpatialIndex index(sorted);
  const float r = LocalProbingAnalysis::chooseRadius(sorted, index, probing, nullptr);
  const float step = probing.step > 0 ? probing.step : r * std::sqrt(3.14159265f / (probing.neighbours * params.factor));
  const float tau = params.tau_p > 0 ? params.tau_p : 0.7f * step;
  try {
    report.noise_sigma = estimateNoiseLevel(sorted, index, r).sigma;
  } catch (const InvalidInput&) {
    report.noise_sigma = 0.f;  // no ball to fit a surface in (wires only, or a few points)
  }
  report.noise_ratio = report.noise_sigma / tau;
  return r;
}

}  // namespace

Positions lpfResample(const Positions& points, const LpfResamplingParameters& params, LpfResamplingReport* report,
                      const ProgressCallback& progress) {
  params.validate();
  if (points.empty()) throw InvalidInput("no point to resample (the cloud, or its indices, are empty)");
  const std::size_t finite = countFinite(points);
  if (finite < 3) throw InvalidInput("LPF resampling needs at least 3 finite points, got " + std::to_string(finite));
  requireRadiusWithinExtent("radius", params.probing.radius, points);
  // In spatial order: the output does not depend on the input order.
  Positions sorted = gathered(points, spatialOrderAll(points));
  LpfResamplingReport noise;
  using Denoise = LpfResamplingParameters::Denoise;
  float radius = 0.f;  // the pattern radius of `sorted`, once measured
  if (params.denoise_input == Denoise::Auto || (params.denoise_input == Denoise::On && params.denoise_passes == 0))
    radius = measureNoise(sorted, params, noise);
  if (params.denoise_input == Denoise::On ||
      (params.denoise_input == Denoise::Auto && noise.noise_ratio >= params.denoise_ratio)) {
    LpfDenoisingParameters d;
    d.probing.neighbours = params.probing.neighbours;
    d.probing.seed = params.probing.seed;
    d.max_tile_points = params.max_tile_points;
    d.iterations = params.denoise_passes > 0
                       ? params.denoise_passes
                       : std::clamp(static_cast<int>(std::floor(2.f * noise.noise_ratio)), 1, 5);
    sorted = lpfDenoisePositions(sorted, d, nullptr, {}, progress);
    noise.denoised = true;
    noise.denoise_passes = d.iterations;
    radius = 0.f;  // the points moved
  }
  Positions out = params.max_tile_points > 0 && finite > params.max_tile_points
                      ? resampleInTiles(sorted, params, radius, report, progress)
                      : resampleInSpatialOrder(sorted, params, report, progress);
  if (report) {
    report->noise_sigma = noise.noise_sigma;
    report->noise_ratio = noise.noise_ratio;
    report->denoised = noise.denoised;
    report->denoise_passes = noise.denoise_passes;
  }
  return out;
}

template class LpfResampling<pcl::PointXYZ, pcl::PointXYZ>;
template class LpfResampling<pcl::PointXYZI, pcl::PointXYZ>;
template class LpfResampling<pcl::PointXYZRGB, pcl::PointXYZ>;
template class LpfResampling<pcl::PointXYZRGBA, pcl::PointXYZ>;
template class LpfResampling<pcl::PointNormal, pcl::PointXYZ>;

}  // namespace paps
