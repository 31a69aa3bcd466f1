#include <paps/surface/quadric_super_resolution.h>
#include <paps/core/spatial_order.h>
#include <paps/surface/impl/quadric_super_resolution.hpp>

#include <algorithm>
#include <array>
#include <map>
#include <cmath>
#include <memory>
#include <numeric>
#include <tuple>

#include <pcl/point_types.h>

#include <paps/core/descriptor_index.h>
#include <paps/core/error.h>
#include <paps/core/irls.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/quadric_height_patch.h>
#include <paps/core/tiling.h>
#include <paps/filters/similarity_denoising.h>
#include <paps/surface/mls_upsampling.h>

namespace paps {

void QuadricSuperResolutionParameters::validate() const {
  if (!(patch_radius >= 0) || !std::isfinite(patch_radius))
    throw InvalidParameter("patch_radius", detail::toString(patch_radius), "0 (automatic) or a finite value > 0");
  requireInRange("target_neighbours", target_neighbours, 9, 1000);
  if (!(similarity_radius >= 0) || !std::isfinite(similarity_radius))
    throw InvalidParameter("similarity_radius", detail::toString(similarity_radius), "0 (automatic) or a finite value > 0");
  requirePositive("similarity_scale", similarity_scale);
  requireInRange("factor", factor, 1.f, 1000.f);
  if (grid_lr != 0) requireInRange("grid_lr", grid_lr, 2, 16);
  if (grid_sr != 0) requireInRange("grid_sr", grid_sr, 2, 64);
  requireInRange("similar_patches", similar_patches, 0, 256);
  requireInRange("candidates", candidates, 1, 1024);
  requireInRange("search_checks", search_checks, 0, 1000000);
  requireInRange("irls_iterations", irls_iterations, 0, 10);
  requireInRange("seed_disc", seed_disc, 0.1f, 10.f);
  if (!(thin_disc > 0.f && thin_disc <= 1.f))
    throw InvalidParameter("thin_disc", detail::toString(thin_disc), "a value in (0, 1]");
  if (!(kernel_scale >= 0) || !std::isfinite(kernel_scale))
    throw InvalidParameter("kernel_scale", detail::toString(kernel_scale), "0 (automatic) or a finite value > 0");
  requireNonNegative("noise_sigma", noise_sigma, "estimated");
  if (max_tile_points != 0 && (max_tile_points < 1000 || max_tile_points >= (std::size_t(1) << 31)))
    throw InvalidParameter("max_tile_points", std::to_string(max_tile_points),
                           "0 (one piece) or a count from 1000 to below 2^31");
  requireInRange("tile_margin", tile_margin, 1.f, 10.f);
}

namespace {
// Noise / patch radius below which the fixed kernel is kept, and from which it is widest.
constexpr float kQuietNoise = 0.05f, kLoudNoise = 0.25f;
// Quieter scans are denoised first too when their noise is at least kSmoothNoise x R and the
// surface is smooth at the patch scale: the noise measured over balls of 2R is less than
// kSmoothGrowth x that over balls of R. Measured (session 12): the scan-line ground 1.18 (q
// 0.011), the bench's 0.01% rows 2.9 (engraved plane, q 0.026) and 2.3 (rs1, q 0.022), where
// denoising would flatten the relief (to the surface 1.7e-4 -> 5.0e-4 and 1.07e-1 -> 1.72e-1).
constexpr float kSmoothNoise = 0.005f, kSmoothGrowth = 1.3f;
}  // namespace

QuadricSuperResolutionParameters noiseAdaptedParameters(const QuadricSuperResolutionParameters& params,
                                                        float patch_radius, float noise_sigma) {
  requirePositive("patch_radius", patch_radius);
  requireNonNegative("noise_sigma", noise_sigma);
  QuadricSuperResolutionParameters p = params;
  // Measured (docs/superresolution.md, "Noise-adaptive kernel: measurements"), on the distance from the
  // output to the true surface: under light noise the kernel of 0.7 keeps the detail; as the
  // noise grows a wider kernel averages it better (q 0.22: 1.4 is 10% closer to the surface
  // than 0.7, q 0.04: 6% farther). Capped at 1.4: the aggregation costs the square of the
  // kernel. A larger similarity scale, more IRLS passes or a narrower kernel lower the bench's
  // one-sided error but move the output off the surface (rs1 0.25%: +3% to +33%): not used.
  float kernel = 0.7f;
  if (params.adapt_to_noise) {
    const float q = noise_sigma / patch_radius;
    kernel = 0.7f + 0.7f * std::clamp((q - kQuietNoise) / (kLoudNoise - kQuietNoise), 0.f, 1.f);
  }
  if (p.kernel_scale == 0) p.kernel_scale = kernel;
  return p;
}

namespace {

// Arc length of y = a x^2 from 0 to x (signed).
inline float arcLength(float a, float x) {
  const float aa = std::abs(a);
  if (aa * std::abs(x) < 1e-6f) return x;
  const float q = std::sqrt(1.f + 4.f * aa * aa * x * x);
  return 0.5f * x * q + std::asinh(2.f * aa * x) / (4.f * aa);
}

struct Scan {
  const Positions* points;
  RadiusNeighbourhood nh;
  std::size_t offset;  // global index of its first point
};

// Nearest distinct positions (exact duplicates counted once). Without duplicates it searches
// the scan's own index; with them, an index of the distinct positions built once: the search on
// the full index had to double k through every copy, which on a scan made of a few positions
// repeated thousands of times (UTM coordinates in float, merged scans) took minutes.
class DistinctSearch {
 public:
  DistinctSearch(const Positions& points, const SpatialIndex& full, const std::vector<int>& first) : full_(full) {
    for (std::size_t i = 0; i < first.size(); ++i)
      if (first[i] >= 0 && first[i] != static_cast<int>(i)) { has_copies_ = true; break; }
    if (!has_copies_) return;
    for (std::size_t i = 0; i < first.size(); ++i)
      if (first[i] == static_cast<int>(i)) {
        distinct_.push_back(points[i]);
        original_.push_back(static_cast<int>(i));
      }
    own_ = std::make_unique<SpatialIndex>(distinct_);
  }

  // The `want` nearest distinct positions to q, as indices into the scan, in `kept`; returns
  // the distance of the farthest kept (metres), or 0 when the scan holds fewer.
  float nearest(const Eigen::Vector3f& q, int want, std::vector<int>& idx, std::vector<float>& d2,
                std::vector<int>& kept) const {
    kept.clear();
    // Without copies: the `want` first of 2 x want, as before the distinct index (ties at the
    // boundary of a lattice then resolve as they always did).
    const int found = has_copies_ ? own_->nearestK(q, want, idx, d2) : full_.nearestK(q, 2 * want, idx, d2);
    if (found < want) return 0.f;
    for (int j = 0; j < want; ++j) kept.push_back(has_copies_ ? original_[idx[j]] : idx[j]);
    return std::sqrt(d2[want - 1]) * 1.0001f;
  }

 private:
  const SpatialIndex& full_;
  bool has_copies_ = false;
  Positions distinct_;
  std::vector<int> original_;
  std::unique_ptr<SpatialIndex> own_;
};

// A ball is sparse when it holds fewer distinct positions than the quadric has unknowns: the
// fit is then ill-posed for want of points, and a wider support is the cure. Elsewhere an
// ill-posed fit comes from noise or a crease, where the plane is the safer answer.
constexpr int kSparseBall = 6;
// Largest tangential offset of the centroid of a widened support from its point, in units of
// the wider radius: a half disc has 0.42, a quarter disc 0.60, a full uniform disc 0.
constexpr float kOneSided = 0.3f;
// Ridge on the slopes of the SR bins' local linear fit, in units of the weight sum (offsets in
// kernel widths). Measured on the bench (session 12) against session 11's fit (pivoted LDLT,
// the mean below a pivot of 1e-3): rs1 at 0.01% -3% (default disc) and -9% (narrow disc) to
// the surface, scan lines -8%, the engraved plane within 1.1%; the protocol error (nearest
// output) +0.3 to +0.5% on rs1. A plain first-order fit is 11% worse on scan lines, a
// zero-order one (infinite ridge) 1.5-4% worse on the plane at 0.01% noise.
constexpr double kSlopeRidge = 0.3;

// Whether nb[0..count) holds fewer than `limit` distinct positions (by `first`).
bool distinctFewerThan(const std::vector<int>& first, const int* nb, int count, int limit, std::vector<int>& seen) {
  seen.clear();
  for (int k = 0; k < count; ++k) {
    const int r = first[nb[k]];
    if (r < 0 || std::find(seen.begin(), seen.end(), r) != seen.end()) continue;
    seen.push_back(r);
    if (static_cast<int>(seen.size()) >= limit) return false;
  }
  return true;
}

// Below this a support counts as thin (lines, strips): between the half disc of a rim
// (2e-3, kept: the rim guard below handles it) and two scan lines (1e-5).
// On the scan-line test any threshold from 3e-4 to 3e-3 gives the output within 4%.
constexpr double kThinSupport = 1e-3;
// How close (RMS, in patch radii) the thin ball's own points must lie to the wider fit. On
// rs1 at 0.01% noise (bench) it turns down 28 of 53 wider fits (protocol error 1.992e-1
// without it, 1.989e-1 with it); on the scan-line test 0.05 and 0.1 change nothing.
constexpr float kThinOnWide = 0.05f;

struct Similar {
  int patch;  // global index
  bool flip;  // matched after a half turn
  float weight;
};

}  // namespace

namespace {
// The noise of the first scan and whether to denoise the scans first (denoise_input), from
// the first scan and its index at the patch radius R.
struct NoiseChoice {
  float noise = 0.f;       // 0: not measured (nothing follows it) or not measurable
  bool estimated = false;  // measured, not given
  float growth = 0.f;      // noise over balls of 2R / over balls of R (0: not measured)
  bool denoise = false;
};

NoiseChoice chooseNoiseAndDenoising(const Positions& scan0, const SpatialIndex& index, float R,
                                    const QuadricSuperResolutionParameters& params) {
  using Denoise = QuadricSuperResolutionParameters::Denoise;
  NoiseChoice c;
  // The noise, measured only when something follows it: the kernel (adapt_to_noise) and the
  // decision to denoise first.
  const bool kernel_follows = params.adapt_to_noise && params.kernel_scale == 0;
  if ((kernel_follows || params.denoise_input == Denoise::Auto) && R > 0) {
    c.noise = params.noise_sigma;
    if (c.noise == 0) {
      try {
        c.noise = estimateNoiseLevel(scan0, index, R).sigma;
        c.estimated = true;
      } catch (const InvalidInput&) {
        c.noise = 0;  // no ball holds enough points for a fit: nothing to adapt to
      }
    }
  }
  bool smooth_and_noisy = false;
  if (params.denoise_input == Denoise::Auto && R > 0 && c.noise >= kSmoothNoise * R && c.noise < kQuietNoise * R) {
    try {
      // The noise at R is the one measured above, unless the caller gave it.
      c.growth = noiseGrowth(scan0, index, R, c.estimated ? c.noise : 0.f);
      smooth_and_noisy = c.growth > 0 && c.growth < kSmoothGrowth;
    } catch (const InvalidInput&) {
      // no ball of 2R holds enough points: keep the input as it is
    }
  }
  c.denoise = params.denoise_input == Denoise::On || smooth_and_noisy ||
              (params.denoise_input == Denoise::Auto && R > 0 && c.noise >= kQuietNoise * R);
  return c;
}

// Below this q (noise / the denoiser's base radius) the first denoising is one pass; from it,
// the denoiser's own pass count.
constexpr float kDenoiseOnePassBelow = 0.75f;

// A scan denoised before its patches are built. The first scan's noise is the given or measured
// one (`noise`); the denoiser measures the other scans'. In tiles of max_tile_points, as the
// denoiser cuts them. `report` (optional) receives the pass and subset counts run
// (denoise_passes, denoise_subsets).
Positions denoisedFirst(const Positions& scan, bool first, const QuadricSuperResolutionParameters& params, float noise,
                        const ProgressCallback& progress, QuadricSuperResolutionReport* report = nullptr) {
  SimilarityDenoisingParameters dp;
  if (first) dp.noise_sigma = params.noise_sigma > 0 ? params.noise_sigma : noise;
  dp.max_tile_points = params.max_tile_points;
  // The denoiser's own rule, but one pass up to q = 0.75: its second pass (from q = 0.6) is
  // there because its first output is still noisy, and here the aggregation over similar
  // patches is that second filter. Measured on rs1 at 0.5% (q about 0.6): two passes round
  // the creases, 7.595e-1 / 7.851e-1 (protocol / to the surface) against 6.949e-1 / 7.365e-1.
  // Dense scans reach higher q (the denoiser's ball holds a fixed count, so it shrinks with
  // the density while the noise stays): there one pass leaves too much for the aggregation
  // (rs1 2M points x2 at q 1.08: 0.365 from the surface after one pass, 0.227 after two,
  // where the denoiser alone gives 0.237; at q 0.71, 500K points, 0.2727 against 0.2719).
  // Above its max_noise_ratio the denoiser cuts the scan into interleaved subsets: that choice
  // is its own too.
  SimilarityDenoisingReport choice;
  SimilarityDenoisingParameters one = noiseResolvedParameters(scan, dp, &choice);
  const float base_radius = choice.radius_scale > 0 ? one.radius / choice.radius_scale : 0.f;
  const float q = base_radius > 0 ? choice.noise_sigma / base_radius : 0.f;
  SimilarityDenoisingReport r;
  Positions out;
  if (!(q >= kDenoiseOnePassBelow)) {
    one.passes = 1;
    out = denoiseBySimilarity(scan, one, &r, {}, progress);
  } else {
    out = denoiseBySimilarity(scan, dp, &r, {}, progress);
  }
  if (report) {
    report->denoise_passes = r.passes;
    report->denoise_subsets = r.subsets;
  }
  return out;
}

// No surface anywhere: every ball, widened as far as it goes, is collinear or one position
// (points on lines, piles of copies). A plane through a line has no orientation; APSS and
// RIMLS refuse such clouds too.
InvalidInput noSurfaceAnywhere(float R) {
  return InvalidInput("every ball of the patch radius " + detail::toString(R) +
                       " m holds only collinear or coincident points (no surface anywhere): the cloud is points on "
                       "lines or piles of copies; give a larger patch radius (--radius) if it is a surface sampled in lines");
}

// What a tile of the first scan adds to a run (superResolveInTiles): in the scan's order,
// which points may seed the output (the core), the normals of the tiles before it where
// it meets them (NaN elsewhere), and, out, its own oriented normals.
struct TileRun {
  std::vector<std::uint8_t> seedable;
  Normals hints;
  Positions kept_before;  // what the tiles before made near it: its seeds keep their distance
  Normals oriented;
  bool no_surface = false;  // out: every ball is collinear or one position (nothing made)
};

Positions superResolveInSpatialOrder(const std::vector<Positions>& scans, const QuadricSuperResolutionParameters& params,
                                     QuadricSuperResolutionReport* report, const ProgressCallback& progress,
                                     Normals* normals_out, std::vector<float>* curvature_out,
                                     std::vector<int>* source_out, TileRun* tile = nullptr) {
  if (scans.empty()) throw InvalidInput("no scan to super-resolve");
  const std::size_t finite0 = countFinite(scans[0]);
  if (finite0 < 10)
    throw InvalidInput("the scan to super-resolve needs at least 10 finite points (got " + detail::toString(finite0) + ")");
  // A tile's share follows the surface it covers, not its points: the count was checked on the
  // whole scan.
  if (!tile) checkOutputCount(params.output_count, finite0);
  // A tile's radius was checked on the whole scan (a dense tile may be narrower).
  if (!tile) requireRadiusWithinExtent("patch_radius", params.patch_radius, scans[0]);
  QuadricSuperResolutionReport rep;

  // 1. Neighbourhoods at the patch radius, chosen on the first scan.
  std::vector<Scan> sc(scans.size());
  std::size_t total = 0;
  for (std::size_t s = 0; s < scans.size(); ++s) {
    sc[s].points = &scans[s];
    sc[s].offset = total;
    total += scans[s].size();
    if (s > 0 && countFinite(scans[s]) < 10) { sc[s].nh.radius = 0; continue; }
    sc[s].nh = buildRadiusNeighbourhood(scans[s], s == 0 ? params.patch_radius : sc[0].nh.radius,
                                        params.target_neighbours, 4 * params.target_neighbours, progress, nullptr,
                                        tile == nullptr);
  }
  const float R = sc[0].nh.radius;
  rep.patch_radius = R;
  const bool kernel_follows = params.adapt_to_noise && params.kernel_scale == 0;
  const NoiseChoice choice = chooseNoiseAndDenoising(scans[0], *sc[0].nh.index, R, params);
  const float noise = choice.noise;
  rep.noise_sigma = noise;
  rep.noise_estimated = choice.estimated;
  rep.noise_growth = choice.growth;
  // Denoising first (measured, docs/superresolution.md): the patches, the similarity and the
  // aggregation then work on points within a fraction of the noise of the surface. The
  // patches keep the radius chosen on the input.
  std::vector<Positions> denoised;
  std::vector<int> resorted0;  // denoised scans[0] position -> scans[0] position (it is sorted again)
  if (choice.denoise) {
    // The raw scans' lists and indices are rebuilt on the denoised scans: freed first, they
    // do not add to the denoiser's peak (rs1 1M points at 0.5%, four passes: 2.17 -> 2.11 GB).
    for (Scan& scan : sc) {
      scan.nh.graph = NeighbourGraph();
      scan.nh.index.reset();
    }
    denoised.resize(scans.size());
    for (std::size_t s = 0; s < scans.size(); ++s) {
      if (sc[s].nh.radius <= 0) { denoised[s] = scans[s]; continue; }
      const Positions d = denoisedFirst(scans[s], s == 0, params, noise, progress, s == 0 ? &rep : nullptr);
      // Sorted again on the denoised positions: the run is then the one on a denoised input.
      std::vector<int> resort = spatialOrderAll(d);
      denoised[s] = gathered(d, resort);
      if (s == 0) resorted0 = std::move(resort);
      sc[s].points = &denoised[s];
      sc[s].nh = buildRadiusNeighbourhood(denoised[s], R, params.target_neighbours, 4 * params.target_neighbours, progress,
                                          nullptr, tile == nullptr);
    }
    rep.denoised = true;
  }
  // After denoising the kernel is the quiet one: what noise is left is not the input's.
  const QuadricSuperResolutionParameters run = noiseAdaptedParameters(params, R > 0 ? R : 1.f,
                                                                      kernel_follows && !rep.denoised ? noise : 0.f);
  rep.kernel_scale = run.kernel_scale;
  rep.mean_neighbours = sc[0].nh.graph.meanCount();
  const int n_lr = params.grid_lr ? params.grid_lr
                                  : std::clamp(static_cast<int>(std::lround(std::sqrt(rep.mean_neighbours))), 2, 16);
  rep.grid_lr = n_lr;
  const QuadricHeightPatch lr(n_lr, R, 0.6f, 1);
  const int B = static_cast<int>(lr.size());
  // Mean input spacing (metres): one point per s0^2 of surface.
  const float s0 = R * std::sqrt(3.14159265f / static_cast<float>(std::max(1.0, rep.mean_neighbours)));

  // 2. Quadric fits and descriptors of every point of every scan.
  std::vector<QuadricFit> fits(total);
  std::vector<float> desc(total * B, 0.f);
  std::vector<std::uint8_t> valid(total * B, 0), usable(total, 0);
  std::vector<int> scan_of(total);
  std::vector<std::uint8_t> thin_ball(total, 0);
  std::size_t flat = 0, ill_posed = 0, widened = 0, thin_balls = 0, collinear = 0, fitted = 0;
  std::vector<float> variation0;  // the first scan's balls' surface variation (curvature_out)
  for (std::size_t s = 0; s < sc.size(); ++s) {
    const Positions& P = *sc[s].points;
    for (std::size_t i = 0; i < P.size(); ++i) scan_of[sc[s].offset + i] = static_cast<int>(s);
    if (sc[s].nh.radius <= 0) continue;
    const NeighbourGraph& g = sc[s].nh.graph;
    Normals normals = estimateNormals(P, g, s == 0 && curvature_out ? &variation0 : nullptr);
    orientNormalsByPropagation(P, normals, g);
    if (s == 0 && tile) {  // the orientation runs on from the tiles before
      turnComponentsToHints(normals, g, tile->hints);
      tile->oriented = normals;
    }
    const LocalFrames frames = estimatePrincipalFrames(normals, g);
    ProgressReporter pr(progress, "quadric patches", P.size());
    const std::int64_t n = static_cast<std::int64_t>(P.size());
    // Sparse parts: an ill-posed fit on a ball with few distinct positions is refitted on the
    // nearest target_neighbours distinct positions, as wide as they need.
    const std::vector<int> first = params.widen_sparse_fits ? exactDuplicateRepresentatives(P) : std::vector<int>();
    const DistinctSearch distinct(P, *sc[s].nh.index, params.widen_sparse_fits ? first : std::vector<int>());
    const int widen_to = params.target_neighbours;
#pragma omp parallel reduction(+ : flat, ill_posed, widened, thin_balls, collinear, fitted)
    {
      std::vector<int> idx, kept;
      std::vector<float> d2;
#pragma omp for schedule(dynamic, 256)
      for (std::int64_t i = 0; i < n; ++i) {
        if (pr.cancelled() || !isFinite(P[i])) continue;
        const std::size_t gi = sc[s].offset + i;
        const Eigen::Vector3f* nh = isFinite(normals[i]) ? &normals[i] : nullptr;
        const Eigen::Vector3f* th = frames[i].valid() ? &frames[i].t1 : nullptr;
        fits[gi] = fitQuadric(P, P[i], g.begin(i), g.count(i), R, nh, th);
        const bool ill = fits[gi].status == QuadricFit::Status::TooFewPoints || fits[gi].status == QuadricFit::Status::Degenerate;
        // Sparse balls, and thin ones (along one or two scan lines, whatever their count), are
        // refitted on a support that holds enough distinct positions spread in two directions.
        // A ball both sparse and thin is a sparse one (36 positions, as since session 10): sent
        // through the thin widening instead, such balls lost session 10's gain on rs1 at 0.01%
        // noise (bench protocol error 2.129e-1 to 2.142e-1 against 1.989e-1).
        thin_ball[gi] = fits[gi].conditioning < kThinSupport;
        const bool thin = params.widen_sparse_fits && thin_ball[gi];
        const bool sparse = (ill || thin) && params.widen_sparse_fits &&
                            distinctFewerThan(first, g.begin(i), g.count(i), kSparseBall, kept);
        if (thin && !sparse) ++thin_balls;
        if ((ill && sparse) || thin) {
          float wide_radius = 0;
          QuadricFit wide;
          for (int want = widen_to;; want *= 2) {
            wide_radius = distinct.nearest(P[i], want, idx, d2, kept);
            if (wide_radius == 0) break;
            wide = fitQuadric(P, P[i], kept.data(), static_cast<int>(kept.size()), wide_radius, nh, th);
            if (!thin || sparse || wide.conditioning >= kThinSupport) break;
            if (want >= kQsrThinWidening * widen_to) {  // thin however wide (a wire, a rim)
              wide_radius = 0;
              break;
            }
          }
          if (wide_radius > R) {
            // A point whose wider neighbours lie on one side of it is on a rim, where the
            // quadric would extrapolate past the scan (measured on the bench plane's corners at
            // 0.5% noise: outputs 16 mm off the mid-plane, 12 mm at most without); it keeps its
            // plane.
            Eigen::Vector3f centroid = Eigen::Vector3f::Zero();
            for (int k : kept) centroid += P[k] - P[i];
            centroid /= static_cast<float>(kept.size());
            const Eigen::Vector3f& wn = wide.frame.n;
            const bool surrounded = (centroid - centroid.dot(wn) * wn).norm() <= kOneSided * wide_radius;
            // A thin ball widened must lie on the wider surface: a strip of one surface (a
            // ridge, a thin part) whose wider support reaches another one does not.
            bool on_wide = true;
            if (thin && !sparse && wide.frame.valid()) {
              double ss = 0;
              int m = 0;
              for (const int* j = g.begin(i); j != g.end(i); ++j) {
                if (!isFinite(P[*j])) continue;
                const Eigen::Vector3f l = wide.frame.toLocal(P[*j] - wide.origin);
                const double e = l.z() - wide.height(l.x(), l.y());
                ss += e * e;
                ++m;
              }
              on_wide = m > 0 && std::sqrt(ss / m) <= kThinOnWide * R;
            }
            if (surrounded && on_wide &&
                (wide.status == QuadricFit::Status::Quadric || wide.status == QuadricFit::Status::FlatPlane)) {
              fits[gi] = wide;
              ++widened;
            }
          }
        }
        if (fits[gi].status == QuadricFit::Status::FlatPlane)
          ++flat;
        else if (fits[gi].isPlaneFallback())
          ++ill_posed;
        ++fitted;
        collinear += fits[gi].status == QuadricFit::Status::Degenerate;
        pr.advance();
      }
    }
    pr.throwIfCancelled();
    pr.finish();
  }
  if (fitted > 0 && collinear == fitted && tile) {  // no surface here; another tile may hold one
    tile->no_surface = true;
    if (report) *report = rep;
    return {};
  }
  if (fitted > 0 && collinear == fitted)
    throw noSurfaceAnywhere(R);
  // Descriptors, once the cloud is known to hold a surface somewhere: a cloud of piles of
  // copies is refused above without describing every patch first (1M points on 20 positions:
  // 75 s before the error).
  for (std::size_t s = 0; s < sc.size(); ++s) {
    if (sc[s].nh.radius <= 0) continue;
    const Positions& P = *sc[s].points;
    const NeighbourGraph& g = sc[s].nh.graph;
    ProgressReporter pr(progress, "patch descriptors", P.size());
    const std::int64_t n = static_cast<std::int64_t>(P.size());
#pragma omp parallel for schedule(dynamic, 256)
    for (std::int64_t i = 0; i < n; ++i) {
      if (pr.cancelled()) continue;
      const std::size_t gi = sc[s].offset + i;
      if (isFinite(P[i]) && fits[gi].frame.valid()) {
        const int nv = lr.describe(fits[gi], P, g.begin(i), g.count(i), &desc[gi * B], &valid[gi * B]);
        usable[gi] = nv * 2 >= B;
      }
      pr.advance();
    }
    pr.throwIfCancelled();
    pr.finish();
  }
  rep.widened_fits = widened;
  rep.thin_balls = thin_balls;
  rep.flat_fits = flat;
  rep.ill_posed_fits = ill_posed;
  rep.plane_fallbacks = flat + ill_posed;
  rep.patches = static_cast<std::size_t>(std::count(usable.begin(), usable.end(), 1));

  // 3. Similar patches of the first scan: kd-tree candidates, exact masked re-ranking (2.3).
  std::vector<int> rows;
  for (std::size_t g = 0; g < total; ++g)
    if (usable[g]) rows.push_back(static_cast<int>(g));
  const std::size_t n0 = scans[0].size();
  const Positions& P0 = *sc[0].points;
  auto positionOf = [&](int g) -> const Eigen::Vector3f& {
    const Scan& sg = sc[scan_of[g]];
    return (*sg.points)[static_cast<std::size_t>(g) - sg.offset];
  };
  std::vector<std::vector<std::pair<float, Similar>>> cand(n0);  // squared distance, patch
  if (params.similar_patches > 0 && rows.size() > 1) {
    // The comparable rows, moved to the front of desc and valid (rows ascend, so each moves
    // down or stays): row r below is patch rows[r], and the index is built on them without a
    // copy of its own (table_scene x2: 87 MB less at this stage's peak).
    for (std::size_t r = 0; r < rows.size(); ++r)
      if (static_cast<std::size_t>(rows[r]) != r) {
        std::copy_n(&desc[static_cast<std::size_t>(rows[r]) * B], B, &desc[r * B]);
        std::copy_n(&valid[static_cast<std::size_t>(rows[r]) * B], B, &valid[r * B]);
      }
    // On the principal axes: twice the recall of the given axes at the same checks
    // (docs/superresolution.md, session 23).
    const DescriptorIndex index(desc.data(), rows.size(), B, params.search_checks, DescriptorIndex::Axes::Principal);
    ProgressReporter pr(progress, "similar patches", n0);
    // The patches are queried in the order the tree stores them: consecutive queries then
    // walk the same branches and leaves, which stay in cache (each answer is the same in any
    // order).
    const std::vector<int>& tree_order = index.storageOrder();
    const std::int64_t n = static_cast<std::int64_t>(tree_order.size());
#pragma omp parallel
    {
      std::vector<int> idx;
      std::vector<float> d2;
      // The query's heights and validity (0 or 1) in both orientations: a half turn reverses
      // the bins. Masks as floats, so that the masked distance runs on SIMD lanes.
      std::vector<float> q[2] = {std::vector<float>(B), std::vector<float>(B)};
      std::vector<float> qm[2] = {std::vector<float>(B), std::vector<float>(B)};
      std::vector<std::pair<float, Similar>> out;
#pragma omp for schedule(dynamic, 256)
      for (std::int64_t t = 0; t < n; ++t) {
        const std::size_t row = static_cast<std::size_t>(tree_order[t]);
        const std::int64_t i = rows[row];
        if (pr.cancelled() || i >= static_cast<std::int64_t>(n0)) continue;  // other scans: sources only
        for (int b = 0; b < B; ++b) {
          q[0][b] = desc[row * B + b];
          q[1][B - 1 - b] = q[0][b];
          qm[0][b] = valid[row * B + b] ? 1.f : 0.f;
          qm[1][B - 1 - b] = qm[0][b];
        }
        out.clear();
        for (int flip = 0; flip < 2; ++flip) {
          const float* a = q[flip].data();
          const float* ma = qm[flip].data();
          index.nearestK(a, params.candidates, idx, d2);
          for (int c : idx) {
            const int g = rows[c];
            // An exact copy of the point (scans are often stored with every point twice) is
            // not a second measurement, and would set the similarity radius to nothing.
            if (g == i || positionOf(g) == P0[i]) continue;
            const float* o = &desc[static_cast<std::size_t>(c) * B];
            const std::uint8_t* vo = &valid[static_cast<std::size_t>(c) * B];
            float s = 0.f, shared = 0.f;
#pragma omp simd reduction(+ : s, shared)
            for (int b = 0; b < B; ++b) {
              const float both = vo[b] ? ma[b] : 0.f;
              const float d = a[b] - o[b];
              s += both * d * d;
              shared += both;
            }
            if (shared * 2 < B) continue;
            out.push_back({s / shared, {g, flip != 0, 0.f}});
          }
        }
        std::sort(out.begin(), out.end(), [](const auto& x, const auto& y) {
          return x.first < y.first || (x.first == y.first && x.second.patch < y.second.patch);
        });
        // One entry per patch (the better orientation), at most similar_patches.
        auto& kept = cand[i];
        for (const auto& e : out) {
          bool dup = false;
          for (const auto& k : kept) dup = dup || k.second.patch == e.second.patch;
          if (!dup) kept.push_back(e);
          if (static_cast<int>(kept.size()) >= params.similar_patches) break;
        }
        pr.advance();
      }
    }
    pr.throwIfCancelled();
    pr.finish();
  }
  // Similarity radius (2.4): automatic from the best matches.
  float rsim = params.similarity_radius;
  if (rsim <= 0) {
    std::vector<float> best;
    for (const auto& c : cand) if (!c.empty()) best.push_back(std::sqrt(c.front().first));
    if (best.empty()) rsim = 1e-3f * R;
    else {
      std::nth_element(best.begin(), best.begin() + best.size() / 2, best.end());
      rsim = std::max(best[best.size() / 2], 1e-6f * R) * params.similarity_scale;
    }
  }
  rep.similarity_radius = rsim;
  std::vector<std::vector<Similar>> similar(n0);
  double sum_w = 0;
  std::size_t counted = 0;
  for (std::size_t i = 0; i < n0; ++i) {
    if (!usable[i]) continue;
    double sw = 0;
    for (const auto& [d2, s] : cand[i]) {
      const float w = std::exp(-d2 / (2 * rsim * rsim));
      if (w < 1e-3f) continue;
      similar[i].push_back({s.patch, s.flip, w});
      sw += w;
    }
    rep.without_similar += similar[i].empty() && (!tile || tile->seedable[i]);
    sum_w += sw;
    ++counted;
    std::vector<std::pair<float, Similar>>().swap(cand[i]);
  }
  // The descriptors are not read again: their memory goes back before the SR heights take
  // theirs (table_scene x2: peak 958 -> 749 MB).
  std::vector<float>().swap(desc);
  std::vector<std::uint8_t>().swap(valid);
  std::vector<std::vector<std::pair<float, Similar>>>().swap(cand);
  std::vector<int>().swap(rows);
  rep.mean_similar_weight = counted ? sum_w / counted : 0;
  const int n_sr = params.grid_sr ? params.grid_sr
                                  : std::clamp(static_cast<int>(std::lround(n_lr * std::sqrt(1 + rep.mean_similar_weight))),
                                               n_lr, 4 * n_lr);
  rep.grid_sr = n_sr;

  // 4. Super-resolution patches (2.5), on the part of each patch the projection reads: an
  // inner square of half-width L around the centre, SR bins at geodesic spacing d_sr. The
  // Gaussian of 2.5 has width sigma_sr = kernel_scale x s0 / sqrt(1 + K): the aggregated
  // points are (1 + K) times denser than the input, so the kernel holds about the same number
  // of points whatever K (with K = 0 it is a plain interpolation at the input spacing).
  const float d_sr = std::sqrt(2.f) * R / static_cast<float>(n_sr);
  const float L = 1.1f * s0;
  const int half = static_cast<int>(std::ceil(L / d_sr));
  const int m = 2 * half + 1;
  const float sigma_sr = run.kernel_scale * s0 / std::sqrt(1.f + static_cast<float>(rep.mean_similar_weight));
  const float inv_2s2 = 1.f / (2.f * sigma_sr * sigma_sr), cut2 = 9.f * sigma_sr * sigma_sr;
  const float reach = L + 3.f * sigma_sr;
  // Columns of x half a cut wide over [-reach, reach]: a bin's cut meets 3 to 4 of them,
  // against the whole band without them. The test on cut2 decides within the window, which is
  // a hair wider than the cut so that rounding cannot leave out a point the test would keep.
  // At most kMaxColumns (a tiny kernel, --kernel 1e-6, would ask for millions): wider columns
  // only widen the windows.
  const float cut_x = 3.0003f * sigma_sr;
  constexpr int kMaxColumns = 1024;
  const float wanted = std::ceil(2.f * reach * 2.f / (3.f * sigma_sr));
  const bool capped = !(wanted < kMaxColumns);
  const int columns = capped ? kMaxColumns + 1 : std::max(1, static_cast<int>(wanted)) + 1;
  const float inv_column = capped ? kMaxColumns / (2.f * reach) : 2.f / (3.f * sigma_sr);
  // Column of x: -1 below (and for NaN, whose window is then empty), `columns` above.
  auto columnOf = [&](float x) {
    const float t = std::floor((x + reach) * inv_column);
    return t >= 0.f ? (t < static_cast<float>(columns) ? static_cast<int>(t) : columns) : -1;
  };
  const float inv_sigma_sr = 1.f / sigma_sr;
  const float inv_wide2 = 1.f / (2.f * s0 * s0);
  // Each patch's m x m SR heights are kept as 16-bit integers times a scale of its own (its
  // largest |height| / 32767): half the memory of floats (the largest array of the run: 223 MB
  // of floats on table_scene x2), and a rounding of at most 1/65534 of the patch's largest
  // height, far below any noise.
  std::vector<std::int16_t> srh(n0 * m * m, 0);
  std::vector<float> srh_scale(n0, 0.f);
  {
    ProgressReporter pr(progress, "super-resolution patches", n0);
    const std::int64_t n = static_cast<std::int64_t>(n0);
#pragma omp parallel
    {
      std::vector<Eigen::Vector3f> mapped, by_x;
      std::vector<float> mw, by_x_w;
      std::vector<int> column, column_start, by_x_column, rcol;
      std::vector<float> xs(m), ys(m), heights(static_cast<std::size_t>(m) * m);
      // The points within the kernel's cut band of the current bin row (structure of arrays,
      // so that the kernel weights, their exp and the fit's sums run on SIMD packets), and the
      // points within the cut of the current bin: height over the bin's tangent plane, weight,
      // offset in units of the kernel width, IRLS weight, squared distance to the bin centre.
      Eigen::ArrayXf rx, ry, rz, rwt;
      Eigen::ArrayXf hk, wk, uk, vk, rw, dist2;
#pragma omp for schedule(dynamic, 128)
      for (std::int64_t i = 0; i < n; ++i) {
        if (pr.cancelled() || !usable[i]) continue;
        const QuadricFit& f0 = fits[i];
        std::fill(heights.begin(), heights.end(), 0.f);
        mapped.clear();
        mw.clear();
        // Patch g's ball: its scan's points and g's neighbour list there.
        auto ballOf = [&](int g) {
          const Scan& s = sc[scan_of[g]];
          const std::size_t li = g - s.offset;
          return std::make_tuple(s.points, s.nh.graph.begin(li), s.nh.graph.end(li));
        };
        auto gather = [&](int g, bool flip, float w) {
          const auto [points, first, last] = ballOf(g);
          const QuadricFit& fg = fits[g];
          for (const int* j = first; j != last; ++j) {
            Eigen::Vector3f l = fg.frame.toLocal((*points)[*j] - fg.origin);
            if (flip) { l.x() = -l.x(); l.y() = -l.y(); }
            if (!(std::abs(l.x()) <= reach && std::abs(l.y()) <= reach)) continue;  // NaN too
            const float rho = l.z() - fg.height(l.x(), l.y());
            mapped.emplace_back(l.x(), l.y(), f0.height(l.x(), l.y()) + rho);
            mw.push_back(w);
          }
        };
        // The similar patches lie anywhere in the scan: their fits, lists and points are cache
        // misses, which made the gathering wait on memory. Their fits and lists are asked for
        // first, and each patch's points while the previous one is gathered.
        const std::vector<Similar>& sim = similar[i];
        auto prefetchPoints = [&](int g) {
          const auto [points, first, last] = ballOf(g);
          for (const int* j = first; j != last; ++j) __builtin_prefetch(&(*points)[*j]);
        };
        for (const auto& e : sim) {
          __builtin_prefetch(&fits[e.patch]);
          __builtin_prefetch(std::get<1>(ballOf(e.patch)));
        }
        gather(static_cast<int>(i), false, 1.f);
        if (!sim.empty()) prefetchPoints(sim[0].patch);
        for (std::size_t k = 0; k < sim.size(); ++k) {
          if (k + 1 < sim.size()) prefetchPoints(sim[k + 1].patch);
          gather(sim[k].patch, sim[k].flip, sim[k].weight);
        }
        // Grouped by columns of x, half a cut wide (a stable counting sort, linear): a band
        // then holds its points column by column, and the cut of each bin, which moves along
        // x with the bin, lies within a window of columns (below).
        column.resize(mapped.size());
        column_start.assign(columns + 1, 0);
        for (std::size_t k = 0; k < mapped.size(); ++k) {
          column[k] = std::clamp(columnOf(mapped[k].x()), 0, columns - 1);
          ++column_start[column[k] + 1];
        }
        for (int c = 0; c < columns; ++c) column_start[c + 1] += column_start[c];
        by_x.resize(mapped.size());
        by_x_w.resize(mapped.size());
        by_x_column.resize(mapped.size());
        for (std::size_t k = 0; k < mapped.size(); ++k) {
          const int at = column_start[column[k]]++;
          by_x[at] = mapped[k];
          by_x_w[at] = mw[k];
          by_x_column[at] = column[k];
        }
        mapped.swap(by_x);
        mw.swap(by_x_w);
        for (int k = 0; k < m; ++k) {
          xs[k] = parabolaAbscissaForArcLength(0.5f * f0.k1, (k - half) * d_sr);
          ys[k] = parabolaAbscissaForArcLength(0.5f * f0.k2, (k - half) * d_sr);
        }
        const Eigen::Index nm = static_cast<Eigen::Index>(mapped.size());
        if (rx.size() < nm) {
          for (Eigen::ArrayXf* a : {&rx, &ry, &rz, &rwt, &hk, &wk, &uk, &vk, &rw, &dist2}) a->resize(nm);
          rcol.resize(nm);
        }
        for (int by = 0; by < m; ++by) {
          // A point outside the cut's band of this row is outside the cut of all its bins.
          Eigen::Index nr = 0;
          for (Eigen::Index k = 0; k < nm; ++k) {  // branch-free, as the cut below
            const float dy = mapped[k].y() - ys[by];
            rx[nr] = mapped[k].x();
            ry[nr] = mapped[k].y();
            rz[nr] = mapped[k].z();
            rwt[nr] = mw[k];
            rcol[nr] = by_x_column[k];
            nr += (dy * dy <= cut2);
          }
          Eigen::Index lo = 0, hi = 0;  // the band's points in the columns the bin's cut meets
          for (int bx = 0; bx < m; ++bx) {
            const Eigen::Vector3f c(xs[bx], ys[by], f0.height(xs[bx], ys[by]));
            const Eigen::Vector3f nb = f0.normalAt(c.x(), c.y());
            // The points within the kernel's cut, in the band's order (branch-free: every
            // point of the x window is written, the count only moves past those inside), then
            // their height over the bin's tangent plane and kernel weight on SIMD packets. The
            // bins of a row go up in x, so the window only moves forward.
            const int first_col = columnOf(c.x() - cut_x), last_col = columnOf(c.x() + cut_x);
            while (lo < nr && rcol[lo] < first_col) ++lo;
            hi = std::max(hi, lo);
            while (hi < nr && rcol[hi] <= last_col) ++hi;
            Eigen::Index nk = 0;
            for (Eigen::Index k = lo; k < hi; ++k) {
              const float dx = rx[k] - c.x(), dy = ry[k] - c.y();
              uk[nk] = dx;
              vk[nk] = dy;
              hk[nk] = rz[k] - c.z();
              wk[nk] = rwt[k];
              nk += (dx * dx + dy * dy <= cut2);
            }
            {
              auto dx = uk.head(nk), dy = vk.head(nk), dz = hk.head(nk), w = wk.head(nk);
              dist2.head(nk) = dx.square() + dy.square() + dz.square();
              dz = dx * nb.x() + dy * nb.y() + dz * nb.z();  // now the height h
              w *= (-inv_2s2 * (dist2.head(nk) - dz.square()).max(0.f)).exp();
              dx *= inv_sigma_sr;
              dy *= inv_sigma_sr;
            }
            const double sw = wk.head(nk).sum();  // 0 when no point is within the cut
            if (!(sw > 1e-6)) {  // a hole: interpolate at the input spacing
              double hsw = 0, hsh = 0;
              for (std::size_t k = 0; k < mapped.size(); ++k) {
                const Eigen::Vector3f d = mapped[k] - c;
                const float h = d.dot(nb);
                const float w = mw[k] * std::exp(-std::max(0.f, d.squaredNorm() - h * h) * inv_wide2);
                hsw += w;
                hsh += w * h;
              }
              if (hsw > 1e-12) heights[by * m + bx] = static_cast<float>(hsh / hsw);
              continue;
            }
            // Local linear kernel regression h ~ c0 + c1 u + c2 v, l1 by IRLS. The slopes take
            // a ridge of kSlopeRidge x the weight sum: where the points spread little along u
            // or v (along a scan line, at a rim) the fit leans towards the weighted mean
            // instead of extrapolating a slope. The 3 x 3 normal equations are solved by LDL^T
            // (the ridge keeps every pivot at least kSlopeRidge x the weight sum).
            const auto h = hk.head(nk), u = uk.head(nk), v = vk.head(nk);
            float est = 0.f;
            rw.head(nk).setOnes();
            for (int pass = 0; pass <= params.irls_iterations; ++pass) {
              // The nine sums in one pass, on SIMD lanes (the lane order is fixed by the
              // build, so the result does not depend on the run or the thread count).
              float fs0 = 0, fsu = 0, fsv = 0, fsuu = 0, fsuv = 0, fsvv = 0, fb0 = 0, fbu = 0, fbv = 0;
              const float *pw = wk.data(), *pr = rw.data(), *ph = hk.data(), *pu = uk.data(), *pv = vk.data();
#pragma omp simd reduction(+ : fs0, fsu, fsv, fsuu, fsuv, fsvv, fb0, fbu, fbv)
              for (Eigen::Index k = 0; k < nk; ++k) {
                const float w = pw[k] * pr[k], wu = w * pu[k], wv = w * pv[k], wh = w * ph[k];
                fs0 += w;
                fsu += wu;
                fsv += wv;
                fsuu += wu * pu[k];
                fsuv += wu * pv[k];
                fsvv += wv * pv[k];
                fb0 += wh;
                fbu += wh * pu[k];
                fbv += wh * pv[k];
              }
              const double s0w = fs0, su = fsu, sv = fsv, suv = fsuv, b0 = fb0, bu = fbu, bv = fbv;
              double suu = fsuu, svv = fsvv;
              if (!(s0w > 1e-12)) break;
              suu += kSlopeRidge * s0w;
              svv += kSlopeRidge * s0w;
              const double l1 = su / s0w, l2 = sv / s0w;
              const double d1 = suu - l1 * su;
              const double l21 = (suv - l2 * su) / d1;
              const double d2 = svv - l2 * sv - l21 * l21 * d1;
              const double y1 = bu - l1 * b0, y2 = bv - l2 * b0 - l21 * y1;
              const double cv = y2 / d2, cu = y1 / d1 - l21 * cv, c0 = b0 / s0w - l1 * cu - l2 * cv;
              est = static_cast<float>(c0);
              if (pass == params.irls_iterations) break;
              // l1Weight (paps/core/irls.h) on packets.
              rw.head(nk) = (h - (static_cast<float>(c0) + static_cast<float>(cu) * u + static_cast<float>(cv) * v))
                                .abs()
                                .max(0.1f * sigma_sr)
                                .inverse();
            }
            heights[by * m + bx] = est;
          }
        }
        float largest = 0.f;
        for (float& h : heights) {
          if (!std::isfinite(h)) h = 0.f;  // not expected (the ridge keeps the solve regular)
          largest = std::max(largest, std::abs(h));
        }
        if (largest > 0.f) {
          const float scale = largest / 32767.f;
          srh_scale[i] = scale;
          for (std::size_t b = 0; b < heights.size(); ++b)
            srh[i * m * m + b] = static_cast<std::int16_t>(std::clamp(std::lround(heights[b] / scale), -32767L, 32767L));
        }
        pr.advance();
      }
    }
    pr.throwIfCancelled();
    pr.finish();
  }
  // The similar patches and the neighbour lists are not read again: their memory goes back
  // before the output is made.
  std::vector<std::vector<Similar>>().swap(similar);
  for (Scan& s : sc) s.nh.graph = NeighbourGraph();

  // 5. Output: Poisson-regularised seeds projected on the SR surface (2.6, robust). Every
  // point with a fitted frame seeds and anchors the output, also those whose descriptor has too
  // few valid bins to be compared (borders, sparse rims): their patch has no SR heights and
  // acts as its quadric alone (a local interpolation). Seeding only from comparable patches
  // left the rims of a scan uncovered.
  std::vector<std::uint8_t> anchor(n0, 0);
  Normals n0s(n0, Eigen::Vector3f::Constant(NAN));
  // In a tile only its core seeds (n0s NaN for the halo: upsamplingSeeds spawns nothing
  // there); the halo's patches anchor the projection of the core's seeds near the border.
  auto seeds = [&](std::size_t i) { return !tile || tile->seedable[i]; };
  for (std::size_t i = 0; i < n0; ++i)
    if (fits[i].frame.valid()) {
      anchor[i] = 1;
      if (!seeds(i)) continue;
      n0s[i] = fits[i].frame.n;
      rep.quadric_only += !usable[i];
    }
  const std::size_t count = params.output_count ? params.output_count
                                                : static_cast<std::size_t>(std::llround(params.factor * finite0));
  rep.spacing = s0;
  rep.disc_radius = params.seed_disc * s0;
  // Seeds of a point whose ball at R is thin stay nearer to it: across such a ball the
  // surface is an extrapolation (session 12: on the scan-line bench the default disc with 0.5
  // here lands as close to the ground as a global disc of 0.6, 1.534e-3 against 2.540e-3 m).
  std::vector<float> disc_scale(n0, 1.f);
  for (std::size_t i = 0; i < n0; ++i)
    if (thin_ball[i] && isFinite(P0[i])) {
      disc_scale[i] = params.thin_disc;
      rep.narrowed_discs += params.thin_disc < 1.f && seeds(i);
    }
  std::vector<int> origin;
  Positions out = upsamplingSeeds(P0, n0s, count, rep.disc_radius, params.seed,
                                  curvature_out || source_out ? &origin : nullptr,
                                  nullptr, 0.f, &disc_scale, tile ? &tile->kept_before : nullptr);
  if (normals_out) normals_out->assign(out.size(), Eigen::Vector3f::Constant(NAN));
  if (curvature_out) {  // PCL's MLS: the surface variation of the ball a point was made from
    curvature_out->assign(out.size(), NAN);
    if (variation0.size() == n0)
      for (std::size_t q = 0; q < out.size(); ++q) (*curvature_out)[q] = variation0[origin[q]];
  }
  if (source_out) {  // indices of scans[0] as given (the denoised scan was sorted again)
    *source_out = origin;
    if (!resorted0.empty())
      for (int& o : *source_out) o = resorted0[static_cast<std::size_t>(o)];
  }
  {
    const SpatialIndex& index0 = *sc[0].nh.index;
    const float inv_2sig2 = 1.f / (2.f * 0.5f * s0 * 0.5f * s0);
    ProgressReporter pr(progress, "projection", out.size());
    const std::int64_t n = static_cast<std::int64_t>(out.size());
    std::size_t unprojected = 0;
#pragma omp parallel reduction(+ : unprojected)
    {
      std::vector<int> idx;
      std::vector<float> d2;
      std::vector<Eigen::Vector3f> proj, pn;
      std::vector<float> pw, fw;
#pragma omp for schedule(dynamic, 512)
      for (std::int64_t q = 0; q < n; ++q) {
        if (pr.cancelled()) continue;
        Eigen::Vector3f x = out[q];
        Eigen::Vector3f est = x, est_n = Eigen::Vector3f::Constant(NAN);
        bool any = false;
        for (int round = 0; round < 2; ++round) {
        index0.nearestK(x, 8, idx, d2);
        proj.clear();
        pn.clear();
        pw.clear();
        for (std::size_t k = 0; k < idx.size(); ++k) {
          const int a = idx[k];
          if (!anchor[a]) continue;
          const QuadricFit& f = fits[a];
          const Eigen::Vector3f l = f.frame.toLocal(x - f.origin);
          const float u_raw = arcLength(0.5f * f.k1, l.x()) / d_sr + half;
          const float v_raw = arcLength(0.5f * f.k2, l.y()) / d_sr + half;
          // Far outside the inner grid the quadric extrapolation is not trusted: drop the
          // anchor. Just outside, read the border bins (constant extrapolation).
          if (u_raw < -0.5f * m || v_raw < -0.5f * m || u_raw > 1.5f * m || v_raw > 1.5f * m) continue;
          const float u = std::clamp(u_raw, 0.f, static_cast<float>(m - 1));
          const float v = std::clamp(v_raw, 0.f, static_cast<float>(m - 1));
          const int u0 = std::min(static_cast<int>(u), m - 2 < 0 ? 0 : m - 2), v0 = std::min(static_cast<int>(v), m - 2 < 0 ? 0 : m - 2);
          const float fu = m > 1 ? u - u0 : 0.f, fv = m > 1 ? v - v0 : 0.f;
          const std::int16_t* H = &srh[static_cast<std::size_t>(a) * m * m];
          const float scale = srh_scale[a];
          auto at = [&](int yy, int xx) { return scale * static_cast<float>(H[std::min(yy, m - 1) * m + std::min(xx, m - 1)]); };
          const float h = (1 - fv) * ((1 - fu) * at(v0, u0) + fu * at(v0, u0 + 1)) +
                          fv * ((1 - fu) * at(v0 + 1, u0) + fu * at(v0 + 1, u0 + 1));
          const Eigen::Vector3f onq(l.x(), l.y(), f.height(l.x(), l.y()));
          const Eigen::Vector3f pl = onq + h * f.normalAt(l.x(), l.y());
          const Eigen::Vector3f pw_ = f.origin + f.frame.toWorld(pl);
          if ((pw_ - x).squaredNorm() > 9.f * s0 * s0) continue;  // a patch that does not reach q
          proj.push_back(pw_);
          if (normals_out) {
            // Normal of the SR surface Q + h: the quadric's slopes plus those of the bilinear
            // SR heights (zero along an axis where the read is clamped to the border bins).
            const float dhu = u_raw > 0.f && u_raw < m - 1 ? (1 - fv) * (at(v0, u0 + 1) - at(v0, u0)) +
                                                                  fv * (at(v0 + 1, u0 + 1) - at(v0 + 1, u0))
                                                            : 0.f;
            const float dhv = v_raw > 0.f && v_raw < m - 1 ? (1 - fu) * (at(v0 + 1, u0) - at(v0, u0)) +
                                                                  fu * (at(v0 + 1, u0 + 1) - at(v0, u0 + 1))
                                                            : 0.f;
            const float kx = f.k1 * l.x(), ky = f.k2 * l.y();
            const float hx = dhu * std::sqrt(1.f + kx * kx) / d_sr;
            const float hy = dhv * std::sqrt(1.f + ky * ky) / d_sr;
            pn.push_back(f.frame.toWorld(Eigen::Vector3f(-(kx + hx), -(ky + hy), 1.f).normalized()));
          }
          pw.push_back(std::exp(-d2[k] * inv_2sig2) + 1e-12f);
        }
        if (proj.empty()) {  // no anchor close enough: the tangent plane of the nearest one
          if (round == 0 && !idx.empty() && anchor[idx[0]]) {
            const QuadricFit& f = fits[idx[0]];
            est = x - (x - f.origin).dot(f.frame.n) * f.frame.n;
            est_n = f.frame.n;
            any = true;
          }
          break;
        }
        any = true;
        est = Eigen::Vector3f::Zero();
        float sw = 0;
        for (std::size_t k = 0; k < proj.size(); ++k) { est += pw[k] * proj[k]; sw += pw[k]; }
        est /= sw;
        fw.assign(pw.begin(), pw.end());
        for (int pass = 0; pass < params.irls_iterations; ++pass) {
          Eigen::Vector3f e = Eigen::Vector3f::Zero();
          float s = 0;
          for (std::size_t k = 0; k < proj.size(); ++k) {
            fw[k] = pw[k] * l1Weight((proj[k] - est).norm(), 0.05f * d_sr);
            e += fw[k] * proj[k];
            s += fw[k];
          }
          if (s > 0) est = e / s;
        }
        if (normals_out) {  // the patches' normals, with the weights of the last position pass
          Eigen::Vector3f e = Eigen::Vector3f::Zero();
          for (std::size_t k = 0; k < pn.size(); ++k) e += fw[k] * pn[k];
          est_n = e.norm() > 0 ? Eigen::Vector3f(e.normalized()) : Eigen::Vector3f(pn[0]);
        }
        x = est;
        }
        if (!any) { ++unprojected; pr.advance(); continue; }
        out[q] = est;
        if (normals_out) (*normals_out)[q] = est_n;
        pr.advance();
      }
    }
    pr.throwIfCancelled();
    pr.finish();
    rep.unprojected = unprojected;
  }
  rep.output = out.size();
  if (report) *report = rep;
  return out;
}
}  // namespace

namespace {
// superResolveInSpatialOrder on scans in any order. Every stage loops over neighbourhoods: the
// scans run in Z order (in input order a shuffled scan waits on memory), which also makes the
// output independent of the input order. `source` comes back in scans[0]'s order, and so do a
// tile's flags, hints and oriented normals.
Positions superResolveSorted(const std::vector<Positions>& scans, const QuadricSuperResolutionParameters& params,
                             QuadricSuperResolutionReport* report, const ProgressCallback& progress, Normals* normals,
                             std::vector<float>* curvature, std::vector<int>* source, TileRun* tile = nullptr) {
  std::vector<Positions> sorted;
  sorted.reserve(scans.size());
  std::vector<int> order0;
  for (const Positions& scan : scans) {
    std::vector<int> order = spatialOrderAll(scan);
    sorted.push_back(gathered(scan, order));
    if (order0.empty()) order0 = std::move(order);
  }
  TileRun sorted_tile;
  if (tile) {
    sorted_tile.seedable = gathered(tile->seedable, order0);
    sorted_tile.hints = gathered(tile->hints, order0);
    sorted_tile.kept_before = std::move(tile->kept_before);
  }
  Positions out = superResolveInSpatialOrder(sorted, params, report, progress, normals, curvature, source,
                                             tile ? &sorted_tile : nullptr);
  if (source)
    for (int& s : *source) s = order0[static_cast<std::size_t>(s)];  // back to scans[0]'s order
  if (tile) {
    tile->no_surface = sorted_tile.no_surface;
    tile->oriented.assign(order0.size(), Eigen::Vector3f::Constant(NAN));
    if (sorted_tile.oriented.size() == order0.size())
      for (std::size_t k = 0; k < order0.size(); ++k) tile->oriented[order0[k]] = sorted_tile.oriented[k];
  }
  return out;
}

// The tiled run (max_tile_points): the patch radius, the noise and the decision to denoise are
// made on the whole first scan, as in one piece; each tile then runs QSR on its core and halo
// (and the other scans' points around it), seeds from its core only, and orients its normals
// as the tiles before it did where they meet.
Positions superResolveInTiles(const std::vector<Positions>& scans, const QuadricSuperResolutionParameters& params,
                              QuadricSuperResolutionReport* report, const ProgressCallback& progress,
                              Normals* normals_out, std::vector<float>* curvature_out, std::vector<int>* source_out) {
  const std::size_t finite0 = countFinite(scans[0]);
  checkOutputCount(params.output_count, finite0);
  requireRadiusWithinExtent("patch_radius", params.patch_radius, scans[0]);
  QuadricSuperResolutionReport rep;
  NoiseChoice choice;
  double mean_neighbours = 0;
  {
    // On the scan in spatial order, as the one-piece run measures it (the samples of the radius
    // and of the noise are drawn along the array).
    const Positions sorted = gathered(scans[0], spatialOrderAll(scans[0]));
    const SpatialIndex index(sorted);
    rep.patch_radius = params.patch_radius > 0 ? params.patch_radius
                                               : radiusForNeighbourCount(sorted, index, params.target_neighbours);
    choice = chooseNoiseAndDenoising(sorted, index, rep.patch_radius, params);
    // The low-resolution grid follows the mean count of the whole scan, as in one piece: tiles
    // of a scan whose density varies would each choose their own (table_scene_lms400 in 8
    // tiles: 6 x 6 for most points, 7 x 7 in one piece). Counted as the run's lists (4 x target).
    if (!choice.denoise) mean_neighbours = sampledMeanNeighbourCount(sorted, index, rep.patch_radius, 4 * params.target_neighbours);
  }
  if (!(rep.patch_radius > 0)) {  // no radius to cut by (a pile of copies): one piece says what it is
    QuadricSuperResolutionParameters one = params;
    one.max_tile_points = 0;
    return superResolveSorted(scans, one, report, progress, normals_out, curvature_out, source_out);
  }
  const float R = rep.patch_radius;
  rep.noise_sigma = choice.noise;
  rep.noise_estimated = choice.estimated;
  rep.noise_growth = choice.growth;
  std::vector<Positions> denoised;
  if (choice.denoise) {
    for (std::size_t s = 0; s < scans.size(); ++s)
      denoised.push_back(s == 0 || countFinite(scans[s]) >= 10
                             ? denoisedFirst(scans[s], s == 0, params, choice.noise, progress, s == 0 ? &rep : nullptr)
                             : scans[s]);
    rep.denoised = true;
    const Positions sorted = gathered(denoised[0], spatialOrderAll(denoised[0]));
    mean_neighbours = sampledMeanNeighbourCount(sorted, SpatialIndex(sorted), R, 4 * params.target_neighbours);
  }
  const std::vector<Positions>& in = choice.denoise ? denoised : scans;
  QuadricSuperResolutionParameters run = params;
  run.max_tile_points = 0;
  run.patch_radius = R;
  if (run.grid_lr == 0) run.grid_lr = std::clamp(static_cast<int>(std::lround(std::sqrt(mean_neighbours))), 2, 16);
  run.denoise_input = QuadricSuperResolutionParameters::Denoise::Off;
  // A denoised scan gets the quiet kernel; a raw one the noise measured on the whole scan.
  run.adapt_to_noise = params.adapt_to_noise && !choice.denoise;
  if (run.adapt_to_noise && choice.noise > 0) run.noise_sigma = choice.noise;

  const float margin = params.tile_margin * R;
  const std::vector<Tile> tiles = splitIntoTiles(in[0], params.max_tile_points, margin);
  rep.tiles = tiles.size();
  const std::size_t total = params.output_count ? params.output_count
                                                : static_cast<std::size_t>(std::llround(params.factor * finite0));
  // The oriented normals of the core points of the tiles done so far: the hints of the next.
  Normals oriented(in[0].size(), Eigen::Vector3f::Constant(NAN));
  Positions out;
  if (normals_out) normals_out->clear();
  if (curvature_out) curvature_out->clear();
  if (source_out) source_out->clear();
  const float typical_spacing = R * std::sqrt(3.14159265f / params.target_neighbours);  // a typical point's spacing
  // Runs tile t for `count` output points, appended to the outputs; false (nothing appended)
  // when the tile holds no surface.
  std::vector<QuadricSuperResolutionReport> reports(tiles.size());
  std::vector<std::size_t> starts(tiles.size(), 0);
  auto runTile = [&](std::size_t t, std::size_t count) {
    const Tile& tile = tiles[t];
    QuadricSuperResolutionReport& r = reports[t];
    r = QuadricSuperResolutionReport();
    starts[t] = out.size();
    std::vector<int> members(tile.core);
    members.insert(members.end(), tile.halo.begin(), tile.halo.end());
    rep.largest_tile = std::max(rep.largest_tile, members.size());
    std::vector<Positions> local(in.size());
    local[0] = gathered(in[0], members);
    for (std::size_t s = 1; s < in.size(); ++s) local[s] = gathered(in[s], pointsAroundTile(in[0], tile, in[s], margin));
    TileRun tr;
    tr.seedable.assign(members.size(), 0);
    std::fill_n(tr.seedable.begin(), tile.core.size(), 1);
    tr.hints = gathered(oriented, members);
    // Seeds lie within the seed disc of a core point and keep the Poisson-disk radius (about
    // the output spacing, below the input's) from what the tiles before made.
    tr.kept_before = pointsNearBox(out, boundingBox(in[0], tile.core), (params.seed_disc + 2.f) * typical_spacing);
    run.output_count = count;
    run.seed = params.seed + t;  // each tile draws its own seeds
    Normals n;
    std::vector<float> c;
    std::vector<int> src;
    const Positions o = superResolveSorted(local, run, &r, tileProgress(progress, t, tiles.size()), normals_out ? &n : nullptr,
                                           curvature_out ? &c : nullptr, &src, &tr);
    if (tr.no_surface) return false;
    for (std::size_t k = 0; k < tile.core.size(); ++k) oriented[tile.core[k]] = tr.oriented[k];
    out.insert(out.end(), o.begin(), o.end());
    if (normals_out) normals_out->insert(normals_out->end(), n.begin(), n.end());
    if (curvature_out) curvature_out->insert(curvature_out->end(), c.begin(), c.end());
    if (source_out)
      for (const int k : src) source_out->push_back(members[static_cast<std::size_t>(k)]);
    return true;
  };
  // Each tile's share of the output (runTileShares), by the surface its core covers, counted
  // in cells of about the seed disc.
  const float cell = std::max(params.seed_disc, 1.f) * typical_spacing;
  std::vector<std::size_t> cells;
  for (const Tile& t : tiles) cells.push_back(occupiedCells(in[0], t.core, cell));
  const std::vector<std::size_t> made = runTileShares(splitInProportion(total, cells), runTile, [&](std::size_t t) {
    out.resize(starts[t]);
    if (normals_out) normals_out->resize(starts[t]);
    if (curvature_out) curvature_out->resize(starts[t]);
    if (source_out) source_out->resize(starts[t]);
  });
  if (made.empty()) throw noSurfaceAnywhere(R);
  // The tiles' orientation runs on from the first tile, whose pieces were turned up on their
  // own; the whole is turned as one piece turns a connected scan (a closed surface out).
  if (normals_out && upwardSign(in[0], oriented) < 0)
    for (Eigen::Vector3f& n : *normals_out) n = -n;
  double weighed = 0, rsim = 0, neighbours = 0, similar = 0, spacing = 0, disc = 0, kernel = 0;
  std::map<std::pair<int, int>, std::size_t> grids;  // (grid_lr, grid_sr): core points of the tiles that chose them
  for (const std::size_t t : made) {
    const QuadricSuperResolutionReport& r = reports[t];
    const double w = static_cast<double>(tiles[t].core.size());
    weighed += w;
    rsim += w * r.similarity_radius;
    neighbours += w * r.mean_neighbours;
    similar += w * r.mean_similar_weight;
    spacing += w * r.spacing;
    disc += w * r.disc_radius;
    kernel += w * r.kernel_scale;
    grids[{r.grid_lr, r.grid_sr}] += tiles[t].core.size();
    rep.patches += r.patches;
    rep.plane_fallbacks += r.plane_fallbacks;
    rep.flat_fits += r.flat_fits;
    rep.ill_posed_fits += r.ill_posed_fits;
    rep.widened_fits += r.widened_fits;
    rep.thin_balls += r.thin_balls;
    rep.narrowed_discs += r.narrowed_discs;
    rep.without_similar += r.without_similar;
    rep.quadric_only += r.quadric_only;
    rep.unprojected += r.unprojected;
  }
  if (weighed > 0) {
    rep.similarity_radius = static_cast<float>(rsim / weighed);
    rep.mean_neighbours = neighbours / weighed;
    rep.mean_similar_weight = similar / weighed;
    rep.spacing = static_cast<float>(spacing / weighed);
    rep.disc_radius = static_cast<float>(disc / weighed);
    rep.kernel_scale = static_cast<float>(kernel / weighed);
    // The grids of the most core points.
    const auto best = std::max_element(grids.begin(), grids.end(),
                                       [](const auto& a, const auto& b) { return a.second < b.second; });
    rep.grid_lr = best->first.first;
    rep.grid_sr = best->first.second;
  }
  rep.output = out.size();
  if (report) *report = rep;
  return out;
}
}  // namespace

Positions superResolveQuadric(const std::vector<Positions>& scans, const QuadricSuperResolutionParameters& params,
                              QuadricSuperResolutionReport* report, const ProgressCallback& progress,
                              Normals* normals, std::vector<float>* curvature, std::vector<int>* source) {
  params.validate();
  if (scans.empty()) throw InvalidInput("no scan to super-resolve");
  if (params.max_tile_points > 0 && countFinite(scans[0]) > params.max_tile_points)
    return superResolveInTiles(scans, params, report, progress, normals, curvature, source);
  return superResolveSorted(scans, params, report, progress, normals, curvature, source);
}

template class QuadricSuperResolution<pcl::PointXYZ, pcl::PointXYZ>;
template class QuadricSuperResolution<pcl::PointNormal, pcl::PointNormal>;
template class QuadricSuperResolution<pcl::PointXYZRGB, pcl::PointXYZ>;
template class QuadricSuperResolution<pcl::PointXYZI, pcl::PointXYZ>;
template class QuadricSuperResolution<pcl::PointXYZ, pcl::PointNormal>;
// Coloured scans upsampled into their own type: each new point takes the colour (and the
// normal, for PointXYZRGBNormal) as PCL's MLS<PointT, PointT> gives them.
template class QuadricSuperResolution<pcl::PointXYZRGB, pcl::PointXYZRGB>;
template class QuadricSuperResolution<pcl::PointXYZRGBA, pcl::PointXYZRGBA>;
template class QuadricSuperResolution<pcl::PointXYZRGBNormal, pcl::PointXYZRGBNormal>;

}  // namespace paps
