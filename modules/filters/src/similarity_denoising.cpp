#include <paps/filters/similarity_denoising.h>
#include <paps/filters/impl/similarity_denoising.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <pcl/point_types.h>

#include <paps/core/descriptor_index.h>
#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/plane_height_patch.h>
#include <paps/core/spatial_order.h>
#include <paps/core/tiling.h>

namespace paps {

void SimilarityDenoisingParameters::validate() const {
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "0 (automatic) or a finite value > 0");
  requireInRange("target_neighbours", target_neighbours, 3, 1000);
  requireNonNegative("noise_sigma", noise_sigma, "estimated");
  requireInRange("grid_size", grid_size, 1, 16);
  // Its square is taken in float: beyond 1e18 it overflows (a weight of 1 for every patch).
  if (!(sigma >= 0) || !(sigma <= 1e18f))
    throw InvalidParameter("sigma", detail::toString(sigma), "0 (automatic) or a value in (0, 1e18]");
  requirePositive("sigma_scale", sigma_scale);
  requireInRange("smoothing_iterations", smoothing_iterations, 1, 1000);
  requireInRange("descriptor_smoothing", descriptor_smoothing, 0, 1000);
  requireInRange("passes", passes, 1, 100);
  requireInRange("similar_patches", similar_patches, 1, 1000);
  if (!(own_weight >= 0) || !std::isfinite(own_weight))
    throw InvalidParameter("own_weight", detail::toString(own_weight), "0 (automatic) or a finite value > 0");
  requireInRange("search_checks", search_checks, 0, 1000000);
  if (max_tile_points >= (std::size_t(1) << 31))
    throw InvalidParameter("max_tile_points", std::to_string(max_tile_points), "0 (one piece) or a count below 2^31");
  if (!(tile_margin >= 1) || !std::isfinite(tile_margin))
    throw InvalidParameter("tile_margin", detail::toString(tile_margin), "a finite number of radii >= 1");
  if (!(max_noise_ratio >= 0) || !(max_noise_ratio <= 1e3f))
    throw InvalidParameter("max_noise_ratio", detail::toString(max_noise_ratio), "0 (never split) or a value in (0, 1000]");
  if (use_viewpoint && !isFinite(viewpoint))
    throw InvalidParameter("viewpoint", "non-finite", "finite coordinates");
}

namespace {

// Fewer neighbours than this (self included) and a point has no usable frame.
constexpr int kMinNeighbours = 4;
// What the last pass did to a point (denoiseOnce's status): the counts of the report, per point.
constexpr std::uint8_t kUpdated = 1, kIsolated = 2;

// Iterated mean-curvature motion: each point moves along its normal to the plane through
// the centroid of its neighbours. Moving along the normal only keeps the one-to-one
// correspondence p <-> p_S that the residual V = p - p_S needs. Normals are refitted on the
// moving surface and kept on the side they started on.
Positions meanCurvatureMotion(const Positions& points, const NeighbourGraph& graph,
                              Normals& normals, const std::vector<std::uint8_t>& usable,
                              int iterations, const ProgressCallback& progress,
                              const char* stage = "smoothing") {
  Positions cur = points, next = points;
  const std::int64_t n = static_cast<std::int64_t>(points.size());
  ProgressReporter report(progress, stage, static_cast<std::size_t>(iterations));
  for (int it = 0; it < iterations; ++it) {
#pragma omp parallel for schedule(dynamic, 1024)
    for (std::int64_t i = 0; i < n; ++i) {
      if (!usable[i]) continue;
      // The point itself is left out of the centroid: p_S then keeps almost no trace of p's
      // own noise, which would otherwise leak into p's descriptor through its origin.
      Eigen::Vector3f c = Eigen::Vector3f::Zero();
      for (const int* j = graph.begin(i) + 1; j != graph.end(i); ++j) c += cur[*j] - cur[i];
      c /= static_cast<float>(graph.count(i) - 1);
      next[i] = cur[i] + c.dot(normals[i]) * normals[i];
    }
    std::swap(cur, next);
    // Normals turn slowly: refitting every third step (and after the last) is enough and
    // saves most of the PCA cost.
    if (it % 3 != 2 && it + 1 != iterations) {
      report.advance();
      continue;
    }
    Normals refit = estimateNormals(cur, graph);
#pragma omp parallel for schedule(static)
    for (std::int64_t i = 0; i < n; ++i) {
      if (!usable[i] || !isFinite(refit[i])) continue;
      normals[i] = refit[i].dot(normals[i]) < 0 ? Eigen::Vector3f(-refit[i]) : refit[i];
    }
    report.advance();
    report.throwIfCancelled();
  }
  report.finish();
  return cur;
}

// Permutation of the pattern samples under a half-turn (u, v) -> (-u, -v); empty when the
// pattern is not symmetric, in which case the second orientation is described again.
std::vector<int> halfTurnPermutation(const SamplingPattern& pattern) {
  std::vector<int> perm(pattern.size());
  for (std::size_t s = 0; s < pattern.size(); ++s) {
    int best = -1;
    for (std::size_t t = 0; t < pattern.size(); ++t)
      if ((pattern.samples[t] + pattern.samples[s]).norm() < 1e-4f) best = static_cast<int>(t);
    if (best < 0) return {};
    perm[s] = best;
  }
  return perm;
}

// Weighted least-squares normal equations of h = c0 + c1 u + c2 v + c3 u^2 + c4 uv + c5 v^2
// over one patch: the heights of a point's neighbours above its smoothed position, in its
// frame, in units of the radius, with Gaussian weights exp(-(u^2 + v^2)). A half turn of the
// frame (u, v) -> (-u, -v) flips the sign of the linear monomials only.
// Stored per point in float (half the memory; the sums are of ~30 terms of order 1), summed
// across patches in double.
template <typename Scalar>
struct PatchMoments {
  static constexpr int kTerms = 6;
  // Upper triangle of the 6 x 6 matrix (21 values), then the right-hand side (6).
  std::array<Scalar, 27> m{};

  static std::array<double, kTerms> monomials(double u, double v) { return {1, u, v, u * u, u * v, v * v}; }
  static bool odd(int t) { return t == 1 || t == 2; }

  void addSample(double u, double v, double h, double w) {
    const auto phi = monomials(u, v);
    int e = 0;
    for (int a = 0; a < kTerms; ++a)
      for (int b = a; b < kTerms; ++b) m[e++] += static_cast<Scalar>(w * phi[a] * phi[b]);
    for (int a = 0; a < kTerms; ++a) m[e++] += static_cast<Scalar>(w * phi[a] * h);
  }
  template <typename Other>
  void add(const PatchMoments<Other>& o, double w, bool turned) {
    const std::array<double, 27>& sign = turned ? halfTurnSigns() : kOnes;
    for (int e = 0; e < 27; ++e) m[e] += sign[e] * w * o.m[e];  // branch-free: vectorises
  }
  static constexpr std::array<double, 27> kOnes = {1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1,
                                                   1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1};
  // Signs of the 27 sums under a half turn: products of one odd (linear) monomial flip.
  static const std::array<double, 27>& halfTurnSigns() {
    static const std::array<double, 27> signs = [] {
      std::array<double, 27> s{};
      int e = 0;
      for (int a = 0; a < kTerms; ++a)
        for (int b = a; b < kTerms; ++b) s[e++] = odd(a) != odd(b) ? -1 : 1;
      for (int a = 0; a < kTerms; ++a) s[e++] = odd(a) ? -1 : 1;
      return s;
    }();
    return signs;
  }
  // c0 of the fit; the quadratic terms are dropped (then the linear ones) when the samples do
  // not determine them, and NaN when there is nothing at all.
  double heightAtCentre() const {
    Eigen::Matrix<double, kTerms, kTerms> A;
    Eigen::Matrix<double, kTerms, 1> b;
    int e = 0;
    for (int a = 0; a < kTerms; ++a)
      for (int c = a; c < kTerms; ++c, ++e) A(a, c) = A(c, a) = m[e];
    for (int a = 0; a < kTerms; ++a, ++e) b(a) = m[e];
    // Fixed sizes: no allocation per point (dynamic LDLT was half the aggregation time).
    double c0;
    if (solveFirst<kTerms>(A, b, c0) || solveFirst<3>(A, b, c0)) return c0;
    return A(0, 0) > 0 ? b(0) / A(0, 0) : std::numeric_limits<double>::quiet_NaN();
  }
  template <int N>
  static bool solveFirst(const Eigen::Matrix<double, kTerms, kTerms>& A, const Eigen::Matrix<double, kTerms, 1>& b,
                         double& c0) {
    const Eigen::LDLT<Eigen::Matrix<double, N, N>> ldlt(A.template topLeftCorner<N, N>());
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return false;
    const Eigen::Matrix<double, N, 1> d = ldlt.vectorD();
    if (d.minCoeff() <= 1e-9 * std::max(d.maxCoeff(), 1e-300)) return false;
    c0 = ldlt.solve(b.template head<N>())(0);
    return true;
  }
};

std::vector<PatchMoments<float>> patchMoments(const Positions& points, const Positions& smooth, const LocalFrames& frames,
                                       const NeighbourGraph& graph, const std::vector<std::uint8_t>& usable,
                                       float radius) {
  std::vector<PatchMoments<float>> out(points.size());
  const double inv_r = 1.0 / radius;
  const std::int64_t n = static_cast<std::int64_t>(points.size());
#pragma omp parallel for schedule(dynamic, 1024)
  for (std::int64_t i = 0; i < n; ++i) {
    if (!usable[i]) continue;
    // Summed in a local double patch and stored once (adding into the stored float patch
    // cost 27 loads and stores per sample).
    PatchMoments<double> sums;
    for (const int* j = graph.begin(i); j != graph.end(i); ++j) {
      const Eigen::Vector3d l = frames[i].toLocal(points[*j] - smooth[i]).cast<double>() * inv_r;
      sums.addSample(l.x(), l.y(), l.z(), std::exp(-(l.x() * l.x() + l.y() * l.y())));
    }
    for (int e = 0; e < 27; ++e) out[i].m[e] = static_cast<float>(sums.m[e]);
  }
  return out;
}

}  // namespace

namespace {
Positions denoiseOnce(const Positions& points, const std::vector<std::uint8_t>& side,
                      const SimilarityDenoisingParameters& params,
                      SimilarityDenoisingReport* report_out, const std::vector<std::uint8_t>& movable,
                      const ProgressCallback& progress, const Positions* estimate = nullptr,
                      std::unique_ptr<SpatialIndex> spatial_index = nullptr,
                      std::vector<std::uint8_t>* status = nullptr) {
  SimilarityDenoisingReport report;
  const std::size_t n = points.size();
  // Per point, when asked: kUpdated (counted in `moved`), kIsolated (in `isolated`), else 0.
  if (status) status->assign(n, 0);
  const std::size_t finite = checkMovableInput(points, movable);
  report.non_finite = n - finite;
  if (finite == 1) {
    report.isolated = 1;
    if (status)
      for (std::size_t i = 0; i < n; ++i) (*status)[i] = isFinite(points[i]) ? kIsolated : 0;
    if (report_out) *report_out = report;
    return points;
  }

  // 1. Neighbourhoods, capped so that a too large radius cannot explode the cost.
  const int cap = std::max(64, 4 * params.target_neighbours);
  RadiusNeighbourhood nb =
      buildRadiusNeighbourhood(points, params.radius, params.target_neighbours, cap, progress, std::move(spatial_index),
                               /*check_extent=*/false);  // checked on the whole cloud (denoiseBySimilarity)
  report.radius = nb.radius;
  report.mean_neighbours = nb.graph.meanCount();
  const NeighbourGraph& graph = nb.graph;

  // 2. Normals of S, oriented, then S = S_smooth + V.
  ProgressReporter normals_rep(progress, "normals", 1);
  Normals normals = estimateNormals(points, graph);
  if (params.use_viewpoint) orientNormalsTowards(points, normals, params.viewpoint);
  else orientNormalsByPropagation(points, normals, graph);
  normals_rep.finish();
  normals_rep.throwIfCancelled();
  std::vector<std::uint8_t> usable(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    usable[i] = isFinite(points[i]) && graph.count(i) >= kMinNeighbours && isFinite(normals[i]);
    if (isFinite(points[i]) && !usable[i]) {
      ++report.isolated;
      if (status) (*status)[i] = kIsolated;
    }
  }
  Normals smooth_normals = normals;
  const Positions smooth = meanCurvatureMotion(points, graph, smooth_normals, usable,
                                               params.smoothing_iterations, progress);

  // The guide the descriptors are built from: the points split in two halves, each half
  // lightly smoothed on its own. A point is described from the other half only, so no trace of
  // its own noise enters its descriptor (otherwise the most similar patches are those that
  // share that noise, and averaging them keeps it). `side` says which half (halvesOf).
  auto half = [&](int i) { return side[i]; };
  Positions guide = points;
  if (estimate) {
    // A first estimate guides (as in two-stage non-local means, e.g. BM3D): it is far less
    // noisy, and each point's own noise is diluted in it over many samples.
    guide = *estimate;
  } else if (params.descriptor_smoothing > 0) {
    const NeighbourGraph half_graph = graph.filtered([&](int i, int j) { return half(i) == half(j); });
    std::vector<std::uint8_t> half_usable(usable);
    for (std::size_t i = 0; i < n; ++i) half_usable[i] = usable[i] && half_graph.count(i) >= kMinNeighbours;
    Normals half_normals = normals;
    guide = meanCurvatureMotion(points, half_graph, half_normals, half_usable, params.descriptor_smoothing,
                                progress, "guide");
  }
  normals = smooth_normals;
  // Heights are read above this base, in descriptors and in the patch fits alike.
  const bool patch_mode = params.aggregation == SimilarityDenoisingParameters::Aggregation::Patch;
  const Positions& base = patch_mode && estimate ? *estimate : smooth;
  // 3. Principal frames on S_smooth and plane+height descriptors of S in them.
  // The principal directions come from the guide, which still carries the detail that S_smooth
  // has lost (on S_smooth they would be noise); the normal and the height plane are S_smooth's.
  LocalFrames frames;
  {
    ProgressReporter frames_rep(progress, "frames", 1);
    Normals guide_normals = estimateNormals(guide, graph);
    for (std::size_t i = 0; i < n; ++i)
      if (isFinite(guide_normals[i]) && isFinite(normals[i]) && guide_normals[i].dot(normals[i]) < 0)
        guide_normals[i] = -guide_normals[i];
    if (estimate)  // the estimate's normals are far less noisy than S_smooth's
      for (std::size_t i = 0; i < n; ++i)
        if (isFinite(guide_normals[i])) normals[i] = guide_normals[i];
    frames = estimatePrincipalFrames(guide_normals, graph);
    for (std::size_t i = 0; i < n; ++i) {
      LocalFrame& f = frames[i];
      if (!usable[i] || !f.valid()) continue;
      Eigen::Vector3f t1 = f.t1 - f.t1.dot(normals[i]) * normals[i];
      if (t1.norm() < 1e-6f) t1 = f.t2 - f.t2.dot(normals[i]) * normals[i];
      f.n = normals[i];
      f.t1 = t1.normalized();
      f.t2 = f.n.cross(f.t1);
    }
    frames_rep.finish();
    frames_rep.throwIfCancelled();
  }
  const PlaneHeightPatch patch(SamplingPattern::grid(params.grid_size), nb.radius);
  const std::size_t dims = patch.size();
  const std::vector<int> perm = halfTurnPermutation(patch.pattern());
  const int orientations = params.both_orientations ? 2 : 1;
  std::vector<int> rows_of_point(n, -1), point_of_row;
  for (std::size_t i = 0; i < n; ++i)
    if (usable[i]) {
      rows_of_point[i] = static_cast<int>(point_of_row.size());
      for (int o = 0; o < orientations; ++o) point_of_row.push_back(static_cast<int>(i));
    }
  const std::size_t rows = point_of_row.size();
  std::vector<float> desc(rows * dims);
  {
    ProgressReporter rep(progress, "descriptors", n);
    const std::int64_t sn = static_cast<std::int64_t>(n);
#pragma omp parallel
    {
      std::vector<std::uint8_t> valid(dims);
      std::vector<int> row;
#pragma omp for schedule(dynamic, 1024)
      for (std::int64_t i = 0; i < sn; ++i) {
        rep.advance();
        if (!usable[i] || rep.cancelled()) continue;
        float* d0 = &desc[rows_of_point[i] * dims];
        // The point itself is left out of its descriptor: otherwise patches that share its
        // own noise would look most similar and the average would keep that noise. Without
        // an estimate, only the other half is read (see the guide above); the row is
        // filtered here rather than kept as a second graph (memory).
        row.clear();
        for (const int* j = graph.begin(i) + 1; j != graph.end(i); ++j)
          if (estimate || half(static_cast<int>(i)) != half(*j)) row.push_back(*j);
        const int count = static_cast<int>(row.size());
        patch.describe(frames[i], base[i], guide, row.data(), count, d0, valid.data());
        if (orientations == 2) {
          float* d1 = d0 + dims;
          if (!perm.empty()) for (std::size_t s = 0; s < dims; ++s) d1[s] = d0[perm[s]];
          else patch.describe(frames[i].rotatedHalfTurn(), base[i], guide, row.data(), count, d1, valid.data());
        }
      }
    }
    rep.throwIfCancelled();
    rep.finish();
  }

  // sigma^2 from the data: two adjacent points see almost the same geometry, so the distance
  // between their descriptors is what noise alone does to a descriptor. Its median over the
  // points (times sigma_scale) is the scale at which patches count as alike. (The distance to
  // the k most similar patches would not do: those were picked for sharing the noise.)
  float sigma2 = params.sigma * params.sigma;
  if (!(sigma2 > 0)) {
    std::vector<float> adjacent;
    adjacent.reserve(n);
    for (std::size_t i = 0; i < n; ++i) {
      if (!usable[i]) continue;
      // The nearest distinct point: a duplicate (scans are often stored with each point
      // twice) has the same descriptor and would set sigma to nothing.
      int j = -1;
      for (const int* q = graph.begin(i) + 1; q != graph.begin(i) + graph.count(i); ++q)
        if (points[*q] != points[i]) { j = *q; break; }
      if (j < 0 || !usable[j]) continue;
      const float* di = &desc[rows_of_point[i] * dims];
      float best = std::numeric_limits<float>::max();
      for (int o = 0; o < orientations; ++o) {
        const float* dj = &desc[(rows_of_point[j] + o) * dims];
        float d2 = 0;
        for (std::size_t s = 0; s < dims; ++s) d2 += (di[s] - dj[s]) * (di[s] - dj[s]);
        best = std::min(best, d2);
      }
      adjacent.push_back(best);
    }
    if (!adjacent.empty()) {
      std::nth_element(adjacent.begin(), adjacent.begin() + adjacent.size() / 2, adjacent.end());
      sigma2 = adjacent[adjacent.size() / 2] * params.sigma_scale;
    }
    if (!(sigma2 > 0)) sigma2 = 1e-12f * nb.radius * nb.radius + 1e-30f;
  }
  report.sigma = std::sqrt(sigma2);

  // 4. The k most similar patches of every movable point (its own rows excluded: the point
  //    itself enters with the largest weight of the others, as in non-local means), and
  // 5. the update, in one of two ways (see Aggregation):
  //  - Patch, a non-local MLS: the weighted normal equations of every patch (its points'
  //    heights over its own tangent plane, in units of the radius, Gaussian weights) are
  //    computed once; a point's fit sums those of its similar patches, so the union of about
  //    k x neighbours samples costs k small additions.
  //  - Centre, the three sums of 2.2.2: V of the similar points, read in their own frames
  //    (turned by half a turn for the second orientation), averaged and re-expressed in p's
  //    frame.
  // Each point's matches are used as soon as they are found: keeping all of them (k ints and
  // floats per point) was the largest array of the filter after the neighbour graph.
  const int k = params.similar_patches - 1;
  const DescriptorIndex index(desc.data(), rows, dims, params.search_checks);
  // The queries are the rows themselves, read from the index's copy (below): ours goes back
  // for the search and the update (59 MB on table_scene).
  std::vector<float>().swap(desc);
  auto isMoving = [&](std::size_t i) { return usable[i] && (movable.empty() || movable[i]); };
  std::vector<PatchMoments<float>> moments;
  if (patch_mode) moments = patchMoments(points, base, frames, graph, usable, nb.radius);
  Positions out = points;
  std::size_t moved = 0;
  // Points in the descriptor tree's storage order: consecutive queries are alike and walk the
  // same branches, and consecutive points share most of their similar patches, so both the
  // search and the data the update reads stay in cache (3x faster than point order).
  const std::vector<int>& tree_order = index.storageOrder();
  const std::int64_t srows = static_cast<std::int64_t>(rows);
  ProgressReporter search_rep(progress, "similarity search", rows);
#pragma omp parallel reduction(+ : moved)
  {
    std::vector<int> idx, match;
    std::vector<float> d2, match_d2;
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t t = 0; t < srows; ++t) {
      search_rep.advance();
      const int own_row = tree_order[t];
      const std::int64_t i = point_of_row[own_row];
      if (rows_of_point[i] != own_row || !isMoving(i) || search_rep.cancelled()) continue;
      match.clear();
      match_d2.clear();
      if (k > 0) {
        index.nearestKOfStored(t, k + orientations, idx, d2);  // row own_row
        for (std::size_t c = 0; c < idx.size() && static_cast<int>(match.size()) < k; ++c) {
          if (point_of_row[idx[c]] == static_cast<int>(i)) continue;
          match.push_back(idx[c]);
          match_d2.push_back(d2[c]);
        }
      }
      PatchMoments<double> fit;
      Eigen::Vector3d residual = Eigen::Vector3d::Zero();
      double w_max = 0, w_sum = 0;
      for (std::size_t m = 0; m < match.size(); ++m) {
        const int row = match[m];
        const int q = point_of_row[row];
        const bool turned = orientations == 2 && (row & 1);
        const double w = std::exp(-static_cast<double>(match_d2[m]) / sigma2);
        if (patch_mode) {
          fit.add(moments[q], w, turned);
        } else {
          const LocalFrame fq = turned ? frames[q].rotatedHalfTurn() : frames[q];
          residual += w * fq.toLocal(points[q] - smooth[q]).cast<double>();
        }
        w_max = std::max(w_max, w);
        w_sum += w;
      }
      if (patch_mode) {
        const double w_own = params.own_weight > 0 ? params.own_weight * w_sum : w_max;
        fit.add(moments[i], w_own > 0 ? w_own : 1.0, false);
        const double h = fit.heightAtCentre() * nb.radius;
        if (!std::isfinite(h)) continue;
        out[i] = base[i] + static_cast<float>(h) * frames[i].n;
      } else {
        // The point itself enters with the largest weight of the others, as in non-local means.
        const double w_self = w_sum > 0 ? w_max : 1.0;
        residual += w_self * frames[i].toLocal(points[i] - smooth[i]).cast<double>();
        out[i] = smooth[i] + frames[i].toWorld((residual / (w_sum + w_self)).cast<float>());
      }
      ++moved;
      if (status) (*status)[i] = kUpdated;
    }
  }
  search_rep.throwIfCancelled();
  search_rep.finish();
  report.moved = moved;
  if (report_out) *report_out = report;
  return out;
}

}  // namespace

SimilarityDenoisingParameters noiseAdaptedParameters(const SimilarityDenoisingParameters& params,
                                                     float base_radius, float noise_sigma) {
  requirePositive("base_radius", base_radius);
  requireNonNegative("noise_sigma", noise_sigma);
  // Measured (docs/denoising.md, "Noise-adaptive defaults"): below q = 0.2 the detail costs
  // more than the noise and the target-count radius is best; the best radius then grows with
  // the noise until the neighbour cap (4 x target) makes a larger ball pointless (x2.5). The
  // own patch at half the weight wins at every noise level measured; from q = 0.6 the first
  // output is still noisy enough that filtering it once more wins.
  const float q = noise_sigma / base_radius;
  SimilarityDenoisingParameters p = params;
  const float scale = std::clamp(1.f + (q - 0.2f) * (1.5f / 0.45f), 1.f, 2.5f);
  p.radius = base_radius * scale;
  p.own_weight = 1.f;
  p.passes = noiseAdaptedPasses(q);
  p.guided_passes = false;
  return p;
}

int noiseAdaptedPasses(float q) {
  // Below 0.6 one pass wins; from there the first output is noisy enough that filtering it
  // again wins. Dense scans under heavy noise go further (the ball is capped at 4 x target
  // neighbours, so its reach shrinks with the density while the noise stays), and each pass
  // widens the support again (RMS to the surface, 2 / 3 / 4 / 5 passes): rs1 2M points at
  // q 1.08: 0.237 / 0.215 / 0.210; engraved plane 1M at q 1.12: 1.92e-3 / 1.51e-3 / 1.49e-3;
  // rs1 1M at q 1.22: 0.849 / 0.643 / 0.593 / 0.579. A third pass loses 2-3% on rs1 at
  // q 0.71 and 0.84. Four at most: the fifth gained 2.4% for 22% more time.
  if (!(q >= 0.6f)) return 1;
  if (q < 0.95f) return 2;
  return q < 1.2f ? 3 : 4;
}

namespace {
// The choices read from the whole cloud: the parameters to run with (radius, passes and weight
// resolved from the noise, adapt_to_noise off), the report fields of the choice (noise_sigma,
// noise_estimated, radius_scale), and the kd-tree built on the points to make it (null when
// none was built), which the first pass reuses.
struct NoiseChoice {
  SimilarityDenoisingParameters run;
  SimilarityDenoisingReport report;
  std::unique_ptr<SpatialIndex> index;
};

// noiseResolvedParameters, keeping the kd-tree it built.
NoiseChoice resolveNoise(const Positions& points, const SimilarityDenoisingParameters& params,
                         const ProgressCallback& progress = {}) {
  params.validate();
  NoiseChoice choice;
  choice.run = params;
  if (params.radius > 0 || !params.adapt_to_noise || countFinite(points) < 10) return choice;
  ProgressReporter rep(progress, "noise", 1);
  choice.index = std::make_unique<SpatialIndex>(points);
  const float r0 = radiusForNeighbourCount(points, *choice.index, params.target_neighbours);
  float noise = params.noise_sigma;
  bool estimated = false;
  if (noise == 0) {
    try {
      noise = estimateNoiseLevel(points, *choice.index, r0).sigma;
      estimated = true;
    } catch (const InvalidInput&) {
      noise = 0;  // no ball holds enough points for a fit: nothing to adapt to
    }
  }
  choice.run = noiseAdaptedParameters(params, r0, noise);
  choice.run.adapt_to_noise = false;
  choice.report.noise_sigma = noise;
  choice.report.noise_estimated = estimated;
  choice.report.radius_scale = choice.run.radius / r0;
  rep.finish();
  rep.throwIfCancelled();
  return choice;
}

// q of the noise rule (noise / base radius) of a choice; 0 where the rule did not apply.
float noiseRatioOf(const NoiseChoice& choice) {
  if (!(choice.run.radius > 0) || !(choice.report.radius_scale > 0)) return 0.f;
  return choice.report.noise_sigma / (choice.run.radius / choice.report.radius_scale);
}
}  // namespace

SimilarityDenoisingParameters noiseResolvedParameters(const Positions& points,
                                                      const SimilarityDenoisingParameters& params,
                                                      SimilarityDenoisingReport* report) {
  NoiseChoice choice = resolveNoise(points, params);
  if (report) {
    report->noise_sigma = choice.report.noise_sigma;
    report->noise_estimated = choice.report.noise_estimated;
    report->radius_scale = choice.report.radius_scale;
  }
  return choice.run;
}

namespace {
// The two halves of the guide (denoiseOnce), drawn from the bits of the input coordinates:
// copies of a point (scans stored twice) fall in the same half, the split depends on neither
// the input order nor the spatial order the filter runs in (index parity there would put a
// point and its copy, adjacent, in opposite halves), and every pass keeps the same split.
std::vector<std::uint8_t> halvesOf(const Positions& points) {
  std::vector<std::uint8_t> side(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) side[i] = positionHash(points[i]) & 1;
  return side;
}

// The one-piece run on points in spatial order, with the choice made on those very points (its
// kd-tree, if any, serves the first pass).
Positions denoiseInSpatialOrder(const Positions& points, NoiseChoice choice, SimilarityDenoisingReport* report_out,
                                const std::vector<std::uint8_t>& movable, const ProgressCallback& progress,
                                std::vector<std::uint8_t>* status = nullptr) {
  const SimilarityDenoisingParameters& run = choice.run;
  Positions cur = points;
  const std::vector<std::uint8_t> side = halvesOf(points);
  SimilarityDenoisingReport report;
  for (int pass = 0; pass < run.passes; ++pass) {
    // Later passes keep the radius of the first, so the scale does not drift.
    SimilarityDenoisingParameters p = run;
    if (pass > 0) p.radius = report.radius;
    if (pass > 0 && run.guided_passes) cur = denoiseOnce(points, side, p, &report, movable, progress, &cur, nullptr, status);
    else cur = denoiseOnce(cur, side, p, &report, movable, progress, nullptr, pass == 0 ? std::move(choice.index) : nullptr, status);
  }
  report.noise_sigma = choice.report.noise_sigma;
  report.noise_estimated = choice.report.noise_estimated;
  report.radius_scale = choice.report.radius_scale;
  report.passes = run.passes;
  report.guided_passes = run.guided_passes;
  report.own_weight = run.own_weight;
  if (report_out) *report_out = report;
  return cur;
}
}  // namespace

namespace {
// The tiled run (SimilarityDenoisingParameters::max_tile_points) of `run`, the parameters
// resolved once on the whole cloud (its radius set), whose choice `choice` reports: each tile
// runs with them.
Positions denoiseInTiles(const Positions& points, SimilarityDenoisingParameters run, std::size_t max_tile_points,
                         const SimilarityDenoisingReport& choice, SimilarityDenoisingReport* report_out,
                         const std::vector<std::uint8_t>& movable, const ProgressCallback& progress) {
  SimilarityDenoisingReport report;
  report.noise_sigma = choice.noise_sigma;
  report.noise_estimated = choice.noise_estimated;
  report.radius_scale = choice.radius_scale;
  run.max_tile_points = 0;
  const std::vector<Tile> tiles = splitIntoTiles(points, max_tile_points, run.tile_margin * run.radius);
  double sigma = 0, neighbours = 0;
  std::size_t weighed = 0;  // core points of the tiles that ran the filter
  report.tiles = tiles.size();
  std::vector<std::uint8_t> status;
  const SortedTileStage stage = [&](const Positions& p, const std::vector<std::uint8_t>& m,
                                    std::vector<std::uint8_t>& st, std::size_t t, const ProgressCallback& sub) {
    SimilarityDenoisingReport r;
    const Positions o = denoiseInSpatialOrder(p, NoiseChoice{run, {}, nullptr}, &r, m, sub, &st);
    const std::size_t core = tiles[t].core.size();
    sigma += static_cast<double>(core) * r.sigma;
    neighbours += static_cast<double>(core) * r.mean_neighbours;
    weighed += core;
    return o;
  };
  // A pile of copies larger than a tile is left as it is and counted isolated, as in one piece.
  const Positions out = runSortedInTiles(points, movable, tiles, stage, progress, &status, kIsolated, &report.largest_tile);
  for (const std::uint8_t s : status) {
    report.moved += s == kUpdated;
    report.isolated += s == kIsolated;
  }
  report.radius = run.radius;
  report.passes = run.passes;
  report.guided_passes = run.guided_passes;
  report.own_weight = run.own_weight;
  report.sigma = weighed ? static_cast<float>(sigma / weighed) : 0.f;
  report.mean_neighbours = weighed ? neighbours / weighed : 0.0;
  report.non_finite = points.size() - countFinite(points);
  if (report_out) *report_out = report;
  return out;
}
}  // namespace

namespace {
// Interleaved subsets (SimilarityDenoisingParameters::max_noise_ratio). A subset under this
// many finite points is not made: the split stops growing there.
constexpr std::size_t kMinSubsetPoints = 10000;
// The subset growth stops after this many measurements (each builds a kd-tree on a subset).
constexpr int kSubsetMeasurements = 8;

// A point's subset among `count`: from the high half of its position hash (the low bit splits
// the guide into halves, halvesOf), so copies of a position share a subset and the split
// depends on neither the input order nor the thread count.
std::size_t subsetOf(const Eigen::Vector3f& p, std::size_t count) {
  return static_cast<std::size_t>((positionHash(p) >> 32) % count);
}

// q of the noise rule (noise / base radius) on `sorted` (points in spatial order, as the runs
// measure them); 0 where the rule does not apply.
float measuredNoiseRatio(const Positions& sorted, const SimilarityDenoisingParameters& params) {
  return noiseRatioOf(resolveNoise(sorted, params));
}

// Whether a cloud of `finite` finite points may be cut into interleaved subsets.
bool splitRuleApplies(const SimilarityDenoisingParameters& params, std::size_t finite) {
  return params.max_noise_ratio > 0 && !(params.radius > 0) && params.adapt_to_noise && finite >= 2 * kMinSubsetPoints;
}

// The number of interleaved subsets for `points` (1: no split), whose whole cloud measured q
// (points in `order`, spatialOrderAll). q grows as the square root of the density: J starts
// from that law and grows until the first subset measures q at most the ratio (the law is
// not exact: the estimate also reads some relief as noise).
std::size_t interleavedSubsetCount(const Positions& points, const std::vector<int>& order, std::size_t finite,
                                   const SimilarityDenoisingParameters& params, float q) {
  const float ratio = params.max_noise_ratio;
  if (!splitRuleApplies(params, finite) || !(q > ratio)) return 1;
  const auto grown = [&](std::size_t count, float measured) {
    const double r = static_cast<double>(measured) / ratio;
    const double wanted = std::ceil(static_cast<double>(count) * r * r);
    return std::max(count + 1, static_cast<std::size_t>(std::min(wanted, 1e9)));
  };
  // In double, capped: a tiny ratio must not overflow the count (the subset floor ends it).
  const double start = std::ceil(static_cast<double>(q) / ratio * (static_cast<double>(q) / ratio));
  std::size_t count = std::max<std::size_t>(2, static_cast<std::size_t>(std::min(start, 1e9)));
  for (int m = 0; m < kSubsetMeasurements; ++m) {
    if (finite / count < kMinSubsetPoints) return std::max<std::size_t>(1, finite / kMinSubsetPoints);
    Positions first;  // the first subset, in spatial order
    first.reserve(finite / count + 1);
    for (const int i : order)
      if (isFinite(points[i]) && subsetOf(points[i], count) == 0) first.push_back(points[i]);
    const float qs = measuredNoiseRatio(first, params);
    if (!(qs > ratio)) break;
    count = grown(count, qs);
  }
  return std::min(count, std::max<std::size_t>(1, finite / kMinSubsetPoints));
}

// The split run: each subset denoised on its own by denoiseBySimilarity (which resolves its
// noise, radius, passes and tiles), the report merged.
Positions denoiseInInterleavedSubsets(const Positions& points, const SimilarityDenoisingParameters& params,
                                      std::size_t count, float q, SimilarityDenoisingReport* report_out,
                                      const std::vector<std::uint8_t>& movable, const ProgressCallback& progress) {
  std::vector<std::vector<int>> members(count);
  for (std::size_t i = 0; i < points.size(); ++i)
    if (isFinite(points[i])) members[subsetOf(points[i], count)].push_back(static_cast<int>(i));
  SimilarityDenoisingParameters sub_params = params;
  sub_params.max_noise_ratio = 0;
  Positions out = points;
  SimilarityDenoisingReport report;
  report.tiles = 0;
  double radius = 0, noise = 0, scale = 0, sigma = 0, neighbours = 0, weighed = 0;
  bool estimated = false;
  for (std::size_t j = 0; j < count; ++j) {
    const std::vector<int>& idx = members[j];
    if (idx.empty()) continue;
    Positions sub(idx.size());
    std::vector<std::uint8_t> sub_movable(movable.empty() ? 0 : idx.size());
    for (std::size_t k = 0; k < idx.size(); ++k) {
      sub[k] = points[idx[k]];
      if (!movable.empty()) sub_movable[k] = movable[idx[k]];
    }
    const ProgressCallback sub_progress = partProgress(progress, "subset", j, count);
    SimilarityDenoisingReport r;
    const Positions o = denoiseBySimilarity(sub, sub_params, &r, sub_movable, sub_progress);
    for (std::size_t k = 0; k < idx.size(); ++k) out[idx[k]] = o[k];
    const double w = static_cast<double>(idx.size());
    radius += w * r.radius;
    noise += w * r.noise_sigma;
    scale += w * r.radius_scale;
    sigma += w * r.sigma;
    neighbours += w * r.mean_neighbours;
    weighed += w;
    estimated = estimated || r.noise_estimated;
    report.passes = std::max(report.passes, r.passes);
    report.guided_passes = r.guided_passes;
    report.own_weight = r.own_weight;
    report.moved += r.moved;
    report.isolated += r.isolated;
    report.tiles += r.tiles;
    report.largest_tile = std::max(report.largest_tile, r.largest_tile);
  }
  report.radius = static_cast<float>(radius / weighed);
  report.noise_sigma = static_cast<float>(noise / weighed);
  report.noise_estimated = estimated;
  report.radius_scale = static_cast<float>(scale / weighed);
  report.sigma = static_cast<float>(sigma / weighed);
  report.mean_neighbours = neighbours / weighed;
  report.non_finite = points.size() - countFinite(points);
  report.subsets = count;
  report.split_noise_ratio = q;
  if (report_out) *report_out = report;
  return out;
}
}  // namespace

Positions denoiseBySimilarity(const Positions& points, const SimilarityDenoisingParameters& params,
                              SimilarityDenoisingReport* report_out,
                              const std::vector<std::uint8_t>& movable,
                              const ProgressCallback& progress) {
  params.validate();
  checkMovableInput(points, movable);
  if (leaveOnePositionAsItIs(points, report_out)) return points;
  requireRadiusWithinExtent("radius", params.radius, points);
  // Every choice that reads the whole cloud (noise, radius, passes, the split) is made once, on
  // the points in spatial order: the samples of the noise and radius are drawn along the array,
  // and so do not depend on the input order. Every stage also loops over neighbourhoods, and on
  // a shuffled cloud those loops wait on memory (1M points: 60 s in input order, 33 s in Z
  // order): the filter runs in Z order, non-finite points last.
  const std::size_t finite = countFinite(points);
  float q = 0.f;
  std::size_t subsets = 1;
  Positions out;
  {
    const std::vector<int> order = spatialOrderAll(points);
    Positions sorted = gathered(points, order);
    NoiseChoice choice = resolveNoise(sorted, params, progress);
    if (splitRuleApplies(params, finite)) q = noiseRatioOf(choice);
    subsets = interleavedSubsetCount(points, order, finite, params, q);
    if (subsets == 1 && params.max_tile_points > 0 && finite > params.max_tile_points) {
      SimilarityDenoisingParameters run = choice.run;
      if (!(run.radius > 0)) {
        if (!choice.index) choice.index = std::make_unique<SpatialIndex>(sorted);
        run.radius = radiusForNeighbourCount(sorted, *choice.index, run.target_neighbours);
      }
      // The tiles are there to bound the memory: the whole cloud's copy and tree go first.
      choice.index.reset();
      Positions().swap(sorted);
      out = denoiseInTiles(points, run, params.max_tile_points, choice.report, report_out, movable, progress);
    } else if (subsets == 1) {
      const Positions sorted_out = denoiseInSpatialOrder(sorted, std::move(choice), report_out,
                                                         movable.empty() ? movable : gathered(movable, order), progress);
      out.resize(points.size());
      for (std::size_t k = 0; k < order.size(); ++k) out[order[k]] = sorted_out[k];
    }
  }
  if (subsets > 1) return denoiseInInterleavedSubsets(points, params, subsets, q, report_out, movable, progress);
  if (report_out) report_out->split_noise_ratio = q;
  return out;
}

template class SimilarityDenoising<pcl::PointXYZ>;
template class SimilarityDenoising<pcl::PointXYZI>;
template class SimilarityDenoising<pcl::PointNormal>;
template class SimilarityDenoising<pcl::PointXYZRGB>;
template class SimilarityDenoising<pcl::PointXYZRGBA>;  // RGB-D cameras (PCL's OpenNI2 and RealSense grabbers)
template class SimilarityDenoising<pcl::PointXYZRGBNormal>;

}  // namespace paps
