#include <paps/filters/lpf_denoising.h>
#include <paps/filters/impl/lpf_denoising.hpp>

#include <algorithm>
#include <cmath>

#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/spatial_order.h>
#include <paps/core/tiling.h>

namespace paps {

void LpfDenoisingParameters::validate() const {
  probing.validate();
  requireInRange("iterations", iterations, 0, 50);
  requireInRange("relief_growth", relief_growth, 1.f, 10.f);
  requireInRange("rounds_per_pass", rounds_per_pass, 0, 100);
  if (!(rate > 0 && rate <= 1)) throw InvalidParameter("rate", detail::toString(rate), "a value in (0, 1]");
  if (!(bend_threshold >= 0 && bend_threshold <= 10))
    throw InvalidParameter("bend_threshold", detail::toString(bend_threshold), "a value in [0, 10] (0: off)");
  if (!(bent_share > 0 && bent_share <= 1))
    throw InvalidParameter("bent_share", detail::toString(bent_share), "a value in (0, 1]");
  if (!(tau_p >= 0) || !std::isfinite(tau_p))
    throw InvalidParameter("tau_p", detail::toString(tau_p), "0 (the pattern step) or a finite value > 0");
  if (max_tile_points >= (std::size_t(1) << 31))
    throw InvalidParameter("max_tile_points", std::to_string(max_tile_points), "0 (one piece) or a count below 2^31");
  if (!(tile_margin >= 1) || !std::isfinite(tile_margin))
    throw InvalidParameter("tile_margin", detail::toString(tile_margin), "a finite number of radii >= 1");
}

namespace {

// For every point, the fields whose target ball holds it (within target_factor x r of the
// field's centre), in increasing field order. From the balls, not from the target lists:
// those keep an even subset where the cloud is dense (the cap), which left points of bun0's
// dense spots in no list (12.8% of the points unmoved, against 2.1% now).
NeighbourGraph coveringFields(const LocalProbingAnalysis& a, const Positions& points) {
  const std::size_t nf = a.fieldCount(), n = points.size();
  Positions centres(nf);
  for (std::size_t j = 0; j < nf; ++j) centres[j] = a.targetCentre(j);
  const SpatialIndex index(centres);
  const float ball = a.parameters().target_factor * a.radius();
  std::vector<std::vector<int>> lists(n);
#pragma omp parallel
  {
    std::vector<float> d2;
#pragma omp for schedule(dynamic, 1024)
    for (std::int64_t p = 0; p < static_cast<std::int64_t>(n); ++p) {
      if (!isFinite(points[p])) continue;
      index.radiusSearch(points[p], ball, lists[p], d2);
      std::sort(lists[p].begin(), lists[p].end());
    }
  }
  std::vector<std::int64_t> offsets(n + 1, 0);
  for (std::size_t p = 0; p < n; ++p) offsets[p + 1] = offsets[p] + static_cast<std::int64_t>(lists[p].size());
  std::vector<int> fields;
  fields.reserve(static_cast<std::size_t>(offsets[n]));
  for (auto& l : lists) {
    fields.insert(fields.end(), l.begin(), l.end());
    std::vector<int>().swap(l);
  }
  return NeighbourGraph::fromRows(std::move(offsets), std::move(fields));
}

// RMS distance of field j's consolidated pattern (nodes u_i plus their reconstruction: D a,
// and the free curvature if any; in its frame) to its least-squares plane
// z = c0 + c1 x + c2 y, over the pattern radius.
float fieldBend(const LocalProbingAnalysis& a, std::size_t j) {
  const ProbingPattern& pattern = a.pattern();
  const int m = pattern.size();
  std::vector<Eigen::Vector3d> at(static_cast<std::size_t>(m));
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (int i = 0; i < m; ++i) {
    const Eigen::Vector2f& u = pattern.node(i);
    at[i] = (Eigen::Vector3f(u.x(), u.y(), 0.f) + a.reconstructedNode(j, i)).cast<double>();
    const Eigen::Vector3d row(1, at[i].x(), at[i].y());
    A += row * row.transpose();
    b += row * at[i].z();
  }
  const Eigen::Vector3d c = A.ldlt().solve(b);
  double ss = 0;
  for (int i = 0; i < m; ++i) {
    const double e = at[i].z() - (c[0] + c[1] * at[i].x() + c[2] * at[i].y());
    ss += e * e;
  }
  return static_cast<float>(std::sqrt(ss / m) / pattern.radius());
}

bool holdsCreases(const LpfDenoisingParameters& params) { return params.bend_threshold > 0 && params.iterations > 1; }

// What happened to a point, when asked (the tiled run counts its core points): kMoved or
// kIsolated by the last pass, and the pass after which it was held (0: never) times kHeldUnit.
constexpr std::uint8_t kMoved = 1, kIsolated = 2, kHeldUnit = 4;  // passes <= 50 < 64

Positions denoiseInSpatialOrder(const Positions& points, const LpfDenoisingParameters& params,
                                LpfDenoisingReport* report_out, const std::vector<std::uint8_t>& movable,
                                const ProgressCallback& progress, std::vector<std::uint8_t>* status = nullptr,
                                bool check_extent = true) {
  LpfDenoisingReport report;
  const std::size_t n = points.size();
  const std::size_t finite = countFinite(points);
  report.non_finite = n - finite;
  if (status) status->assign(n, 0);
  if (finite < 3) {
    // No pattern can be placed on fewer than 3 points: they pass through.
    report.isolated = finite;
    if (status)
      for (std::size_t i = 0; i < n; ++i)
        if (isFinite(points[i])) (*status)[i] = kIsolated;
    if (report_out) *report_out = report;
    return points;
  }
  Positions cur = points;
  LocalProbingAnalysis analysis(cur, params.probing, progress, check_extent);
  const ProbingPattern& pattern = analysis.pattern();
  report.radius = pattern.radius();
  report.step = pattern.step();
  report.lambda = analysis.lambda();
  report.noise_sigma = analysis.noiseSigma();
  report.pattern_nodes = pattern.size();
  report.fields = analysis.fieldCount();
  const float tau = params.tau_p > 0 ? params.tau_p : pattern.step();
  const double inv2t = 1.0 / (2.0 * static_cast<double>(tau) * tau);  // double: tiny units stay finite
  const std::int64_t sn = static_cast<std::int64_t>(n);
  const NeighbourGraph cover = coveringFields(analysis, cur);
  ProgressReporter rep(progress, "LPF denoising", static_cast<std::size_t>(params.iterations) * n);
  // Creases (bend_threshold): the pass from which each point stays where it is. Tested after
  // every analysis, since the first pass lowers the noise that hides mild creases from the
  // first test.
  const bool hold_creases = holdsCreases(params);
  std::vector<int> held_from(hold_creases ? n : 0, params.iterations);
  std::vector<std::uint8_t> ever_bent(hold_creases ? analysis.fieldCount() : 0, 0);
  for (int pass = 0; pass < params.iterations; ++pass) {
    analysis.analyse(cur, pass == 0 ? params.probing.rounds : params.rounds_per_pass);
    if (hold_creases && pass + 1 < params.iterations) {
      const std::size_t nf = analysis.fieldCount();
      std::vector<std::uint8_t> bent(nf, 0);
      // Bent: a surface whose pattern leaves its plane, or a scattered target area, which is no
      // height field either (an edge or corner too sharp for the pattern, such as a
      // tetrahedron's 70.5-degree edges, or clutter).
#pragma omp parallel for schedule(dynamic, 256)
      for (std::int64_t j = 0; j < static_cast<std::int64_t>(nf); ++j) {
        const int dimension = analysis.targetDimension(j);
        bent[j] = dimension == 3 || (dimension == 2 && fieldBend(analysis, j) > params.bend_threshold);
      }
      std::size_t newly_held = 0;
      for (std::int64_t p = 0; p < sn; ++p) {
        if (held_from[p] < params.iterations) continue;
        // Held: enough bent or scattered fields, and not on a wire (wires need their passes).
        int known = 0, bent_here = 0, wires = 0;
        for (const int* jp = cover.begin(p); jp != cover.end(p); ++jp) {
          const int dimension = analysis.targetDimension(static_cast<std::size_t>(*jp));
          if (dimension == 0) continue;
          ++known;
          wires += dimension == 1;
          bent_here += bent[static_cast<std::size_t>(*jp)];
        }
        if (known > 0 && bent_here >= params.bent_share * known && wires < params.bent_share * known) {
          held_from[p] = pass + 1;  // this pass still moves it
          ++newly_held;
          if (status) (*status)[p] = static_cast<std::uint8_t>(kHeldUnit * (pass + 1));
        }
      }
      for (std::size_t j = 0; j < nf; ++j) ever_bent[j] |= bent[j];
      report.held_after_pass.push_back(newly_held);
      report.held_points += newly_held;
    }
    Positions next = cur;
    std::size_t moved = 0, isolated = 0;
    const bool last = pass + 1 == params.iterations;
#pragma omp parallel for schedule(dynamic, 1024) reduction(+ : moved, isolated)
    for (std::int64_t p = 0; p < sn; ++p) {
      rep.advance();
      if (!isFinite(cur[p]) || (!movable.empty() && !movable[p])) continue;
      if (hold_creases && pass >= held_from[p]) continue;
      // Every field whose target area holds the point projects it on its pattern plane and
      // proposes the consolidated pattern there: the bilinear blend of the consolidated
      // positions u + D a (plus any free curvature) of the four nodes around the projection
      // (3.3.2). On a surface that keeps the point's tangential place and takes the
      // consolidated height; on a wire it keeps the place along the wire and takes the
      // wire's consolidated axis.
      Eigen::Vector3d acc = Eigen::Vector3d::Zero();
      double wsum = 0;
      for (const int* jp = cover.begin(p); jp != cover.end(p); ++jp) {
        const std::size_t j = static_cast<std::size_t>(*jp);
        if (analysis.targetDimension(j) == 0) continue;  // too few points to be a witness
        const ProbingPose& pose = analysis.pose(j);
        const Eigen::Vector3f l = pose.frame.transpose() * (cur[p] - pose.seed);
        int corner[4];
        float weight[4];
        if (!pattern.cellCorners(l.x(), l.y(), corner, weight)) continue;  // beyond the pattern
        Eigen::Vector3f at[4], local = Eigen::Vector3f::Zero();
        for (int c = 0; c < 4; ++c) {
          const Eigen::Vector2f& u = pattern.node(corner[c]);
          at[c] = Eigen::Vector3f(u.x(), u.y(), 0.f) + analysis.reconstructedNode(j, corner[c]);
          local += weight[c] * at[c];
        }
        Eigen::Vector3f move = local - l;
        // On a surface the point moves along the pattern's normal only, so that
        // consolidation does not drag it along the surface (measured: borders drew in by
        // half a spacing otherwise). Across a wire it moves in every direction.
        if (params.normal_motion_on_surfaces && analysis.targetDimension(j) == 2) move.head<2>().setZero();
        const Eigen::Vector3f candidate = cur[p] + pose.frame * move;
        const double w = std::exp(-(candidate - cur[p]).cast<double>().squaredNorm() * inv2t);
        acc += w * candidate.cast<double>();
        wsum += w;
      }
      if (!(wsum > 0)) {
        ++isolated;
        if (status && last) (*status)[p] |= kIsolated;
        continue;
      }
      const Eigen::Vector3f consensus = (acc / wsum).cast<float>();
      next[p] = cur[p] + params.rate * (consensus - cur[p]);
      moved += next[p] != cur[p];
      if (status && last && next[p] != cur[p]) (*status)[p] |= kMoved;
    }
    rep.throwIfCancelled();
    cur.swap(next);
    analysis.probe(cur);
    report.moved = moved;
    report.isolated = isolated;
  }
  report.bent_fields = static_cast<std::size_t>(std::count(ever_bent.begin(), ever_bent.end(), 1));
  report.round_errors = analysis.roundErrors();
  rep.finish();
  if (report_out) *report_out = report;
  return cur;
}

// The tiled run (LpfDenoisingParameters::max_tile_points): the radius is chosen once, on the
// whole cloud in spatial order as the one-piece analysis chooses it; every tile then runs
// with that radius (so the same step and lambda).
Positions denoiseInTiles(const Positions& points, const LpfDenoisingParameters& params,
                         LpfDenoisingReport* report_out, const std::vector<std::uint8_t>& movable,
                         const ProgressCallback& progress) {
  LpfDenoisingReport report;
  LpfDenoisingParameters run = params;
  run.max_tile_points = 0;
  if (!(params.probing.radius > 0)) {  // the automatic passes resolve it first
    const Positions sorted = gathered(points, spatialOrderAll(points));
    const SpatialIndex index(sorted);
    run.probing.radius = LocalProbingAnalysis::chooseRadius(sorted, index, params.probing, &report.noise_sigma);
  }
  const std::vector<Tile> tiles = splitIntoTiles(points, params.max_tile_points, params.tile_margin * run.probing.radius);
  report.tiles = tiles.size();
  std::vector<double> error_sums;  // per round, over the fields of every tile
  std::size_t fields_with_errors = 0;
  std::vector<std::uint8_t> status;
  const Positions out = runSortedInTiles(
      points, movable, tiles,
      [&](const Positions& p, const std::vector<std::uint8_t>& m, std::vector<std::uint8_t>& st, std::size_t,
          const ProgressCallback& sub) {
        LpfDenoisingReport r;
        const Positions o = denoiseInSpatialOrder(p, run, &r, m, sub, &st, /*check_extent=*/false);
        report.radius = r.radius;
        report.step = r.step;
        report.lambda = r.lambda;
        report.pattern_nodes = r.pattern_nodes;
        report.fields += r.fields;
        report.bent_fields += r.bent_fields;
        if (error_sums.size() < r.round_errors.size()) error_sums.resize(r.round_errors.size(), 0.0);
        for (std::size_t k = 0; k < r.round_errors.size(); ++k) error_sums[k] += r.round_errors[k] * r.fields;
        fields_with_errors += r.fields;
        return o;
      },
      progress, &status, kIsolated, &report.largest_tile);
  if (holdsCreases(params)) report.held_after_pass.assign(static_cast<std::size_t>(params.iterations - 1), 0);
  for (const std::uint8_t s : status) {
    report.moved += (s & kMoved) != 0;
    report.isolated += (s & kIsolated) != 0;
    const int held = s / kHeldUnit;
    if (held > 0) {
      ++report.held_points;
      ++report.held_after_pass[static_cast<std::size_t>(held - 1)];
    }
  }
  for (const double e : error_sums) report.round_errors.push_back(fields_with_errors ? e / fields_with_errors : 0.0);
  if (report.radius == 0) report.radius = run.probing.radius;
  report.non_finite = points.size() - countFinite(points);
  if (report_out) *report_out = report;
  return out;
}

}  // namespace

Positions lpfDenoisePositions(const Positions& points, const LpfDenoisingParameters& params,
                              LpfDenoisingReport* report, const std::vector<std::uint8_t>& movable,
                              const ProgressCallback& progress) {
  params.validate();
  checkMovableInput(points, movable);
  if (leaveOnePositionAsItIs(points, report)) return points;
  const std::size_t finite = countFinite(points);
  if (finite >= 3) requireRadiusWithinExtent("radius", params.probing.radius, points);
  // The automatic passes: the radius is resolved on the whole cloud (in spatial order, as the
  // analysis reads it) and the noise growth measured at it.
  LpfDenoisingParameters run = params;
  float noise_sigma = 0.f, growth = 0.f;
  if (run.iterations == 0) {
    run.iterations = 5;
    if (finite >= 3) {
      const Positions sorted = gathered(points, spatialOrderAll(points));
      const SpatialIndex index(sorted);
      run.probing.radius = LocalProbingAnalysis::chooseRadius(sorted, index, params.probing, &noise_sigma);
      try {
        growth = noiseGrowth(sorted, index, run.probing.radius);
      } catch (const InvalidInput&) {
        growth = 0.f;  // no ball to fit a surface in (wires only): the full count
      }
      if (growth >= params.relief_growth) run.iterations = 2;
    }
  }
  Positions out = params.max_tile_points > 0 && finite > params.max_tile_points
                      ? denoiseInTiles(points, run, report, movable, progress)
                      : runInSpatialOrder(points, movable, [&](const Positions& p, const std::vector<std::uint8_t>& m) {
                          return denoiseInSpatialOrder(p, run, report, m, progress);
                        });
  if (report) {
    report->passes = run.iterations;
    report->noise_growth = growth;
    if (params.iterations == 0 && params.probing.radius == 0) report->noise_sigma = noise_sigma;
  }
  return out;
}

template class LpfDenoising<pcl::PointXYZ>;
template class LpfDenoising<pcl::PointXYZI>;
template class LpfDenoising<pcl::PointNormal>;
template class LpfDenoising<pcl::PointXYZRGB>;
template class LpfDenoising<pcl::PointXYZRGBA>;  // RGB-D cameras (PCL's OpenNI2 and RealSense grabbers)
template class LpfDenoising<pcl::PointXYZRGBNormal>;

}  // namespace paps
