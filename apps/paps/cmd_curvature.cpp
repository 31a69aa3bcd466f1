// paps curvature IN OUT [options]   and   paps enhance IN OUT --alpha0 A | --alpha1 RE[,IM]
#include <chrono>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstring>
#include <sstream>

#include <pcl/common/io.h>
#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/normal_refresh.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/spatial_order.h>
#include <paps/features/point_types.h>
#include <paps/features/wavejet.h>
#include <paps/features/wavejet_estimation.h>
#include <paps/features/wavejet_noise.h>
#include <paps/filters/wavejet_enhancement.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

const char* kCurvatureUsage =
    "usage: paps curvature IN OUT [options]\n"
    "  Wavejet curvatures and corrected normals (manuscript 2.4). OUT (.pcd or .ply) holds x y z,\n"
    "  normal_x/y/z, k1 k2 (1/m, signed w.r.t. the normal, k1 >= k2), mean_curvature,\n"
    "  gaussian_curvature, principal_x/y/z (direction of k1), offset (m), a0 a1_real a1_imag\n"
    "  (unit-disk units) and order (-1: too few neighbours, outputs NaN). Exact duplicate\n"
    "  positions are fitted once and counted once; every input point gets an output.\n"
    "  --radius R             R_phi in metres, the same at every point (NaN outputs where the ball\n"
    "                         holds fewer than beta (K+1)(K+2)/2 points, 17 for K = 4). Default:\n"
    "                         chosen from --neighbours over the distinct positions, and a point\n"
    "                         whose ball holds fewer than N distinct positions is fitted on its N\n"
    "                         nearest, rescaled to their disk (scans of varying density); one\n"
    "                         whose ball holds more than 4 N is fitted on its 4 N nearest\n"
    "  --neighbours N         neighbour count that sets the automatic R_phi and the minimum per\n"
    "                         point (default 50)\n"
    "  --max-neighbours M     the maximum per point with the automatic R_phi (default 4 N)\n"
    "  --fixed-radius         automatic R_phi without the per-point widening or narrowing\n"
    "  --order K              Wavejet order, 1 to 20 (default 4); given, the order is fixed\n"
    "                         (no noise-aware choice; with --select-order: the highest order)\n"
    "  --beta B               order lowered until neighbours >= B (K+1)(K+2)/2 (default 1.1);\n"
    "                         given, no noise-aware choice\n"
    "  --irls N               IRLS passes against noise/outliers (default 0)\n"
    "  --select-order         per point, lower the order where higher orders fit noise (BIC);\n"
    "                         under noise use it with --beta 3 and a radius holding ~200\n"
    "                         neighbours (docs/wavejets.md: 2 R_phi, the support PCL's\n"
    "                         curvature estimator sees)\n"
    "  --order-policy P       auto (default unless --order, --beta or --select-order is given):\n"
    "                         a pilot of order-K fits measures the noise; clean data keep the\n"
    "                         fixed order, noisy data get --select-order and, with the automatic\n"
    "                         radius, beta 3 and (no --neighbours) twice the radius (about 4x\n"
    "                         the neighbours) when the residual is noise (no larger at 2 R_phi),\n"
    "                         not relief; fixed: the manuscript's fixed order; select: as\n"
    "                         --select-order\n"
    "  --refits N             plane corrections with refit, at most (default 4)\n"
    "  --refit-angle D        refit while the tilt exceeds D degrees (default 45)\n"
    "  --orient M             normal orientation: input (input normals, default when present),\n"
    "                         propagate (default otherwise), or viewpoint (towards the sensor\n"
    "                         origin of a .pcd, VIEWPOINT; the origin when it has none)\n"
    "  --tile-points N        fit a cloud of more distinct positions in tiles of at most N, one\n"
    "                         at a time: the same outputs, the working memory of a tile\n"
    "                         (default 2000000; 0: one piece whatever the size)\n"
    "  --quiet                no progress bar\n"
    "  --timings              print the wall time of each stage\n";

const char* kEnhanceUsage =
    "usage: paps enhance IN OUT (--alpha0 A | --alpha1 RE[,IM]) [options]\n"
    "  Wavejet detail enhancement (manuscript 2.4.3). Every field of IN is kept.\n"
    "  --alpha0 A             position filter (eq. 2.21): 1 projects on the Wavejet surface,\n"
    "                         >1 enhances details, 0..1 smooths, <0 inverts them\n"
    "  --alpha1 RE[,IM]       normal filter (eq. 2.22), complex gain: 2 sharpens the shading,\n"
    "                         0 flattens it, imaginary parts skew the normals; positions stay\n"
    "  --radius R             R_phi = s in metres, fixed (default: automatic, widened where\n"
    "                         sparse, as for paps curvature)\n"
    "  --neighbours N         neighbour count that sets the automatic R_phi (default 50)\n"
    "  --max-neighbours M     the maximum per point with the automatic R_phi (default 4 N)\n"
    "  --fixed-radius         automatic R_phi without the per-point widening or narrowing\n"
    "  --order K              Wavejet order (default 4; the manuscript uses 6 to 9)\n"
    "  --beta B, --irls N, --select-order   as for paps curvature\n"
    "  --order-policy P       fixed (default here: the filters scale the higher orders, which the\n"
    "                         order selection drops under noise), auto or select (paps curvature)\n"
    "  --max-motion F         motion clamp as a fraction of R_phi (default 0.5)\n"
    "  --orient M             input, propagate or viewpoint (as for paps curvature)\n"
    "  --tile-points N        as for paps curvature (default 2000000)\n"
    "  --quiet, --timings\n"
    "  Normals are written to normal_x/y/z (added when IN has none); with --alpha0 they are\n"
    "  the corrected Wavejet normals of the enhanced surface (a second fit, on OUT).\n";

namespace {

// Orientation hints per --orient: input normals, propagated PCA normals, or none (viewpoint).
bool orientationHints(const pcl::PCLPointCloud2& cloud, const Positions& p, const std::string& mode,
                      Normals& hints) {
  if (mode != "input" && mode != "propagate" && mode != "viewpoint" && mode != "auto")
    throw InvalidParameter("orient", mode, "input, propagate or viewpoint");
  if (mode == "viewpoint") return false;
  if (mode == "input" || mode == "auto") {
    if (blobNormals(cloud, hints) && anyUsableNormal(hints)) { std::printf("orientation: input normals\n"); return true; }
    if (mode == "input") throw InvalidParameter("orient", "input", "an input with normal_x/y/z fields");
  }
  // On the distinct positions, as the Wavejet stage fits them: in a pile of copies every
  // nearest-neighbour query reads the whole pile (1M points on 10 positions: minutes). In Z
  // order, as the Wavejet stage: on a shuffled cloud the normals' loop waits on memory (1M
  // shuffled points: about 1.3 s of 8 s in input order), and the propagation's blocks would
  // depend on the input order.
  std::vector<int> slot;
  const Positions distinct = distinctPositions(p, exactDuplicateRepresentatives(p), &slot);
  const Normals dn = runInSpatialOrder(distinct, {}, [](const Positions& ps, const std::vector<std::uint8_t>&) {
    const NeighbourGraph g = NeighbourGraph::byCount(ps, SpatialIndex(ps), 12);
    Normals n = estimateNormals(ps, g);
    orientNormalsByPropagation(ps, n, g);
    return n;
  });
  hints.assign(p.size(), Eigen::Vector3f::Constant(NAN));
  for (std::size_t i = 0; i < p.size(); ++i)
    if (slot[i] >= 0) hints[i] = dn[static_cast<std::size_t>(slot[i])];
  std::printf("orientation: propagated over the graph of the 12 nearest distinct positions\n");
  return true;
}

// The Wavejet fields by the options that set them (for error messages).
const std::map<std::string, std::string> kWavejetOptions = {
    {"irls_iterations", "irls"}, {"max_refits", "refits"}, {"refit_angle", "refit-angle"},
    {"narrowed_neighbours", "max-neighbours"}};

WavejetParameters wavejetParameters(const Arguments& a, const char* default_policy) {
  WavejetParameters w;
  w.order = a.integer("order", w.order);
  w.beta = a.real("beta", w.beta);
  w.irls_iterations = a.integer("irls", w.irls_iterations);
  w.max_refits = a.integer("refits", w.max_refits);
  w.refit_angle = a.real("refit-angle", w.refit_angle);
  w.select_order = a.has("select-order");
  // The noise-aware policy decides unless the user set the order, beta or the policy.
  const std::string policy =
      a.text("order-policy", a.has("select-order") ? "select" : a.has("order") || a.has("beta") ? "fixed" : default_policy);
  if (policy == "auto") w.order_policy = WavejetParameters::OrderPolicy::automatic;
  else if (policy == "fixed") w.order_policy = WavejetParameters::OrderPolicy::fixed;
  else if (policy == "select") w.order_policy = WavejetParameters::OrderPolicy::select;
  else throw InvalidParameter("order-policy", policy, "auto, fixed or select");
  if (policy == "fixed" && w.select_order)
    throw InvalidParameter("order-policy", policy, "auto or select with --select-order");
  // An explicit --neighbours is kept as given (no growth with the noise).
  w.adapt_support = !a.has("neighbours");
  // Widening with the automatic radius (the library's default: an explicit --radius is kept
  // as given); --fixed-radius turns it off (docs/wavejets.md, "Real scans").
  w.widening = a.has("fixed-radius") ? WavejetParameters::Widening::never : WavejetParameters::Widening::automatic;
  // The cap of narrowing (0: 4 x --neighbours).
  w.narrowed_neighbours = a.integer("max-neighbours", w.narrowed_neighbours);
  w.max_tile_points = a.count("tile-points", w.max_tile_points);
  validateAsOptions(kWavejetOptions, [&] { w.validate(); });
  // A cap below the count every ball is widened to would be raised to it without a word.
  const int count = a.integer("neighbours", 50);
  if (w.narrowed_neighbours > 0 && w.narrowed_neighbours < count)
    throw InvalidParameter("max-neighbours", std::to_string(w.narrowed_neighbours),
                           "at least the neighbour count (--neighbours, " + std::to_string(count) + "), or 0: 4 x it");
  return w;
}

// One line on what the neighbourhoods were: duplicates fitted once, sparse balls widened,
// crowded balls narrowed.
void printNeighbourhoodChoice(std::size_t duplicates, std::size_t widened, float widened_median, int widen_to,
                              std::size_t narrowed, float narrowed_median, int narrow_to, bool fixed) {
  if (duplicates)
    std::printf("exact duplicates: %zu points share the position of an earlier one: fitted and counted once\n",
                duplicates);
  if (fixed) return;
  if (widened)
    std::printf("widened: %zu points had fewer than %d distinct positions in the ball of R_phi: fitted on their %d "
                "nearest, R_phi = distance of the farthest (median %g m)\n", widened, widen_to, widen_to, widened_median);
  else
    std::printf("widened: none (every ball holds at least %d distinct positions)\n", widen_to);
  if (narrowed)
    std::printf("narrowed: %zu points had more than %d distinct positions in the ball of R_phi: fitted on their %d "
                "nearest, R_phi = distance of the farthest (median %g m)\n", narrowed, narrow_to, narrow_to,
                narrowed_median);
  else
    std::printf("narrowed: none (no ball holds more than %d distinct positions)\n", narrow_to);
}

// One line on the tiles, when there were several.
void printTiles(const WavejetReport& r) {
  if (r.tiles > 1)
    std::printf("in %zu tiles (the largest held %zu distinct positions with its halo; %zu halos grown for widened "
                "balls)\n", r.tiles, r.largest_tile, r.grown_halos);
}

// One line on the order policy: what the pilot measured and what was chosen.
void printOrderPolicy(const WavejetParameters& asked, const WavejetReport& r, int neighbours, float radius) {
  if (!r.noise_measured) {
    std::printf("order policy: %s (as given): %s, beta %g\n",
                asked.order_policy == WavejetParameters::OrderPolicy::automatic ? "automatic" : "explicit",
                r.select_order ? "order selected per point in [2, K] (BIC)" : "fixed order", r.beta);
    return;
  }
  std::printf("order policy: automatic: residual of order-%d fits %.3g%% of R_phi (sigma %g m) -> %s, beta %g", asked.order,
              100 * r.noise_relative, r.noise_sigma,
              r.select_order ? "noisy: order selected per point in [2, K] (BIC)" : "clean: fixed order", r.beta);
  if (radius > 0) std::printf(", radius as given\n");
  else if (r.support_scale > 1)
    std::printf(", automatic R_phi x%g (about %gx the neighbours; residual at 2 R_phi / at R_phi %.2f: noise)\n",
                r.support_scale, r.support_scale * r.support_scale, r.noise_scale_ratio);
  else if (!std::isnan(r.noise_scale_ratio))
    std::printf(", automatic R_phi kept (residual at 2 R_phi / at R_phi %.2f > %.2f: relief, not only noise)\n",
                r.noise_scale_ratio, kWavejetNoiseScaleRatio);
  else std::printf("\n");
}

}  // namespace

int runCurvature(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"quiet", "help", "timings", "select-order", "fixed-radius"});
  if (a.has("help")) { std::fputs(kCurvatureUsage, stdout); return 0; }
  a.allowOnly({"radius", "neighbours", "order", "beta", "irls", "refits", "refit-angle", "orient", "quiet",
               "timings", "select-order", "fixed-radius", "max-neighbours", "order-policy", "tile-points"});
  if (a.positional.size() != 2) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "IN and OUT");
  a.requireCloudOutput();
  WavejetParameters params = wavejetParameters(a, "auto");
  const float radius = a.real("radius", 0);
  const int neighbours = a.integer("neighbours", 50);
  const pcl::PCLPointCloud2 cloud = loadCloud(a.positional[0], &params.viewpoint);
  Positions p = positionsOf(cloud);
  printRead(a.positional[0], p);
  Normals hints;
  const bool have_hints = orientationHints(cloud, p, a.text("orient", "auto"), hints);
  const ProgressCallback progress = progressBar(a.has("quiet"), a.has("timings"));
  WavejetReport r;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<WavejetResult> res = estimateWavejets(p, radius, params, &r, nullptr, nullptr,
                                                   have_hints ? &hints : nullptr, progress, neighbours);
  Normals().swap(hints);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  printOrderPolicy(params, r, neighbours, radius);
  const int used = neighbours;
  std::printf("wavejets: order %d, R_phi %g m%s (mean %.1f neighbours), %.2f s\n", params.order, r.radius,
              radius > 0 ? "" : " (chosen from the neighbour count over the distinct positions)", r.mean_neighbours, secs);
  WavejetParameters run = params;
  run.beta = r.beta;
  if (r.support_scale > 1 && run.narrowed_neighbours == 0)
    run.narrowed_neighbours = static_cast<int>(r.support_scale * r.support_scale) * wavejetNarrowedNeighbours(params, neighbours);
  printNeighbourhoodChoice(r.duplicates, r.widened, r.widened_radius_median,
                           wavejetWidenedNeighbours(run, used), r.narrowed, r.narrowed_radius_median,
                           wavejetNarrowedNeighbours(run, used),
                           params.widening == WavejetParameters::Widening::never || radius > 0);
  printTiles(r);
  std::printf("fitted %zu points; order lowered at %zu; plane correction not converged at %zu; tilt within the "
              "noise (plane kept) at %zu\n", r.fitted, r.lowered, r.not_converged, r.tilt_within_noise);
  if (r.too_few_neighbours)
    std::fprintf(stderr, "warning: %zu points have too few neighbours for order 2: NaN outputs%s\n",
                 r.too_few_neighbours, radius > 0 ? " (--radius: without it, sparse balls are widened)"
                                       : params.widening == WavejetParameters::Widening::never
                                           ? " (--fixed-radius: without it, sparse balls are widened)" : "");
  if (r.failed_fits)
    std::fprintf(stderr, "warning: %zu points have enough neighbours but a degenerate fit (neighbours along a line, "
                 "or a radius far beyond the cloud): NaN outputs\n", r.failed_fits);
  if (r.non_finite) std::fprintf(stderr, "warning: %zu NaN input points: NaN outputs\n", r.non_finite);
  // The input's own fields (intensity, colour...) and its width x height are kept; the
  // Wavejet fields are added (input normals are replaced by the corrected ones). The rows are
  // made a block at a time as the file is written: neither the outputs as a blob nor the
  // combined cloud is ever held (a large scan's outputs are several times its input).
  Positions().swap(p);
  pcl::PCLPointCloud2 wavejet_fields;
  pcl::toPCLPointCloud2(pcl::PointCloud<PointWavejet>(1, 1), wavejet_fields);
  CloudRows rows = appendedRows(cloud, wavejet_fields.fields, sizeof(PointWavejet),
                                [&res](std::size_t i, std::uint8_t* row) {
                                  PointWavejet w;
                                  toPoint(res[i], w);
                                  std::memcpy(row, &w, sizeof(PointWavejet));
                                });
  rows.layout.is_dense = r.fitted == res.size();
  saveCloudAtomic(a.positional[1], rows, params.viewpoint);
  std::printf("wrote %s\n", a.positional[1].c_str());
  return 0;
}

int runEnhance(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"quiet", "help", "timings", "select-order", "fixed-radius"});
  if (a.has("help")) { std::fputs(kEnhanceUsage, stdout); return 0; }
  a.allowOnly({"alpha0", "alpha1", "radius", "neighbours", "order", "beta", "irls", "refits", "refit-angle",
               "max-motion", "orient", "quiet", "timings", "select-order", "fixed-radius", "max-neighbours",
               "order-policy", "tile-points"});
  if (a.positional.size() != 2) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "IN and OUT");
  a.requireCloudOutput();
  if (a.has("alpha0") == a.has("alpha1"))
    throw InvalidParameter("alpha0/alpha1", "both or neither", "exactly one of --alpha0 A or --alpha1 RE[,IM]");
  WavejetEnhancementParameters params;
  // Enhancement keeps the fixed order unless asked (WavejetEnhancementParameters::wavejet).
  params.wavejet = wavejetParameters(a, "fixed");
  params.radius = a.real("radius", 0);
  params.target_neighbours = a.integer("neighbours", params.target_neighbours);
  params.max_motion = a.real("max-motion", params.max_motion);
  if (a.has("alpha0")) params.alpha0 = a.real("alpha0", 1);
  if (a.has("alpha1")) {
    const std::string s = a.text("alpha1", "1");
    std::istringstream in(s);
    double re = 0, im = 0;
    char comma = 0;
    if (!(in >> re) || ((in >> comma) && (comma != ',' || !(in >> im))) || !in.eof())
      throw InvalidParameter("alpha1", s, "RE or RE,IM (numbers)");
    params.alpha1 = {static_cast<float>(re), static_cast<float>(im)};
  }
  std::map<std::string, std::string> names = kWavejetOptions;
  names.insert({{"target_neighbours", "neighbours"}, {"max_motion", "max-motion"}});
  validateAsOptions(names, [&] { params.validate(); });
  pcl::PCLPointCloud2 cloud = loadCloud(a.positional[0], &params.wavejet.viewpoint);
  const Positions p = positionsOf(cloud);
  printRead(a.positional[0], p);
  Normals hints;
  const bool have_hints = orientationHints(cloud, p, a.text("orient", "auto"), hints);
  const ProgressCallback progress = progressBar(a.has("quiet"), a.has("timings"));
  WavejetEnhancementReport r;
  if (a.has("alpha0")) {
    Normals normals;
    const Positions out = enhancePositions(p, params, &r, {}, progress, have_hints ? &hints : nullptr, &normals);
    writePositions(out, cloud);
    // The normals of the enhanced surface (the input's corrected ones describe it before).
    setNormals(cloud, enhancedSurfaceNormals(out, params, normals, progress));
    std::printf("position filter alpha0 = %g, order %d, R_phi %g m%s (mean %.1f neighbours): moved %zu points\n",
                params.alpha0, params.wavejet.order, r.radius, params.radius > 0 ? "" : " (chosen)",
                r.mean_neighbours, r.changed);
  } else {
    const Normals normals = enhanceNormals(p, params, &r, progress, have_hints ? &hints : nullptr);
    setNormals(cloud, normals);
    std::printf("normal filter alpha1 = %g%+gi, order %d, R_phi %g m%s (mean %.1f neighbours): %zu normals\n",
                params.alpha1.real(), params.alpha1.imag(), params.wavejet.order, r.radius,
                params.radius > 0 ? "" : " (chosen)", r.mean_neighbours, r.changed);
  }
  printOrderPolicy(params.wavejet, r.wavejet, params.target_neighbours, params.radius);
  WavejetParameters run = params.wavejet;
  run.beta = r.wavejet.beta;
  const int used = params.target_neighbours;
  if (r.wavejet.support_scale > 1 && run.narrowed_neighbours == 0)
    run.narrowed_neighbours =
        static_cast<int>(r.wavejet.support_scale * r.wavejet.support_scale) * wavejetNarrowedNeighbours(params.wavejet, used);
  printNeighbourhoodChoice(r.duplicates, r.widened, r.widened_radius_median,
                           wavejetWidenedNeighbours(run, used), r.narrowed,
                           r.narrowed_radius_median, wavejetNarrowedNeighbours(run, used),
                           params.wavejet.widening == WavejetParameters::Widening::never || params.radius > 0);
  printTiles(r.wavejet);
  if (r.clamped) std::fprintf(stderr, "warning: %zu motions clamped at %g R_phi (not a height field)\n", r.clamped, params.max_motion);
  if (r.unfitted) std::fprintf(stderr, "warning: %zu points have too few neighbours: left in place, normal NaN\n", r.unfitted);
  saveCloudAtomic(a.positional[1], cloud, params.wavejet.viewpoint);
  std::printf("wrote %s\n", a.positional[1].c_str());
  return 0;
}

}  // namespace paps::cli
