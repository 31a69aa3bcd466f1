// paps denoise IN OUT [options]
#include <cstdio>

#include <paps/core/cloud_io.h>
#include <paps/core/view_point_option.h>
#include <paps/core/error.h>
#include <paps/filters/lpf_denoising.h>
#include <paps/filters/point_bilateral_filter.h>
#include <paps/filters/similarity_denoising.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

const char* kDenoiseUsage =
    "usage: paps denoise IN OUT [options]\n"
    "  IN, OUT                .pcd or .ply; every field of IN is kept, x y z move, and normals\n"
    "                         (normal_x/y/z, curvature) are estimated again on OUT\n"
    "  --keep-normals         keep IN's normals as they were (they describe the noisy surface)\n"
    "  --method M             similarity (default), bilateral, or lpf (Local Probing Fields:\n"
    "                         surfaces and wires alike, slower; its options below)\n"
    "  --radius R             neighbourhood radius in metres (default: from --neighbours, grown\n"
    "                         with the measured noise; see --no-adapt)\n"
    "  --neighbours N         neighbour count of a typical point (median) that sets the base radius (default 30)\n"
    "  --noise S              noise standard deviation of IN in metres (default: measured)\n"
    "  --no-adapt             keep the base radius and the given passes/own weight whatever the\n"
    "                         noise (default: radius, passes and own weight follow the noise;\n"
    "                         --passes, --refilter, --own-weight given explicitly are kept)\n"
    "  --grid N               descriptor grid N x N (default 4)\n"
    "  --sigma S              similarity scale in metres (default: from the descriptors)\n"
    "  --sigma-scale F        multiplier of the automatic sigma^2 (default 2)\n"
    "  --smoothing N          mean-curvature-motion iterations (default 10)\n"
    "  --guide N              smoothing iterations of the points descriptors are built from (default 3)\n"
    "  --passes N             times the filter is applied (default: from the noise, 1 to 4,\n"
    "                         refiltering; 1 with --radius or --no-adapt)\n"
    "  --refilter             later passes filter the previous output (default: they average the\n"
    "                         input again, guided by the previous output)\n"
    "  --aggregate A          patch (default: fit over the union of the similar patches) or\n"
    "                         centre (manuscript: average of the similar points' residuals)\n"
    "  --own-weight W         weight of the point's own patch, times the similar patches' total\n"
    "                         (default 0: the largest of their weights)\n"
    "  --patches K            similar patches averaged (default 32)\n"
    "  --checks N             descriptors compared per similarity query (default 48, 0 = exact)\n"
    "  --tile-points N        a cloud of more finite points is denoised in tiles of at most N\n"
    "                         points, one at a time (every method; memory: about 1 KB a\n"
    "                         point of a tile; default 2000000; 0: one piece whatever the size)\n"
    "  --max-noise-ratio Q    dense scans under heavy noise: when the noise exceeds Q x the base\n"
    "                         radius, the cloud is denoised as interleaved subsets, each a\n"
    "                         sparser sampling of the surface with noise at most Q x its own base\n"
    "                         radius, each by the whole noise rule (default 1.15; 0: never; off with\n"
    "                         --radius, --no-adapt, --passes, --refilter or --own-weight)\n"
    "  --iterations N         bilateral passes (default 1)\n"
    "LPF options (--method lpf; --radius is the pattern radius, --neighbours defaults to 100,\n"
    "--passes from the relief: 5 where the surface is smooth at the pattern scale, 2 where it\n"
    "has relief, by the noise growth from balls of r to 2r; give --passes to set them):\n"
    "  --step S               pattern step in metres (default: as many nodes as points in the ball)\n"
    "  --atoms D              dictionary atoms (default 16)\n"
    "  --lambda L             L1 weight of the codes in metres (default: 0.5 x the step)\n"
    "  --rounds N             rounds of the first joint analysis (default 4)\n"
    "  --seed-spacing S       one field per S metres (default: a third of the pattern radius;\n"
    "                         the manuscript's one field per point: --seed-spacing 1e-9)\n"
    "  --free-motion          points on surfaces may also move along them (the manuscript's\n"
    "                         rule; draws borders in)\n"
    "  --bend-threshold T     points near creases (where a quarter of the covering fields are\n"
    "                         bent farther than T x the radius from a plane or scattered, and\n"
    "                         fewer are wires; tested after every analysis) stop moving after\n"
    "                         that pass (default 0.08; 0: every pass moves every point, the\n"
    "                         manuscript's rule, which rounds creases more each pass)\n"
    "  --free-curvature       keep each field's curvature out of the L1 penalty: better on\n"
    "                         curved surfaces, worse on flat ones (see docs/lpf.md)\n"
    "  --quiet                no progress bar\n"
    "  --timings              print the wall time of each stage\n";

namespace {
std::string adaptedNote(float noise, bool measured, float scale) {
  char b[160];
  std::snprintf(b, sizeof b, " (chosen: noise %.3g m%s, %.2f x the base radius)", noise, measured ? " measured" : "",
                scale);
  return b;
}
}  // namespace

int runDenoise(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"quiet", "help", "timings", "refilter", "no-adapt", "free-motion", "free-curvature", "keep-normals"});
  if (a.has("help")) { std::fputs(kDenoiseUsage, stdout); return 0; }
  a.allowOnly({"method", "radius", "neighbours", "grid", "sigma", "sigma-scale", "smoothing",
               "patches", "iterations", "quiet", "timings", "checks", "guide", "passes",
               "refilter", "aggregate", "own-weight", "noise", "no-adapt", "step", "atoms", "lambda",
               "rounds", "seed-spacing", "free-motion", "bend-threshold", "free-curvature", "keep-normals", "tile-points",
               "max-noise-ratio"});
  if (a.positional.size() != 2) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "IN and OUT");
  a.requireCloudOutput();
  const std::string& in_path = a.positional[0];
  const std::string& out_path = a.positional[1];
  const std::string method = a.text("method", "similarity");
  if (method != "similarity" && method != "bilateral" && method != "lpf")
    throw InvalidParameter("method", method, "similarity, bilateral or lpf");
  // An option of another method would be silently ignored: refused instead.
  std::vector<std::string> applies = {"method", "radius", "neighbours", "quiet", "timings", "keep-normals"};
  if (method == "similarity")
    applies.insert(applies.end(), {"grid", "sigma", "sigma-scale", "smoothing", "patches", "checks", "guide", "passes",
                                   "refilter", "aggregate", "own-weight", "noise", "no-adapt", "tile-points",
                                   "max-noise-ratio"});
  else if (method == "lpf")
    applies.insert(applies.end(), {"step", "atoms", "lambda", "rounds", "seed-spacing", "passes", "free-motion",
                                   "free-curvature", "bend-threshold", "tile-points"});
  else
    applies.insert(applies.end(), {"iterations", "tile-points"});
  requireOptionsOf(a, applies, "--method " + method);

  Eigen::Vector3f origin;
  pcl::PCLPointCloud2 cloud = loadCloud(in_path, &origin);
  const Positions in = positionsOf(cloud);
  printRead(in_path, in);
  const ProgressCallback progress = progressBar(a.has("quiet"), a.has("timings"));
  Positions out;
  float radius = 0;  // the filter's, for the normals
  if (method == "similarity") {
    SimilarityDenoisingParameters p;
    p.radius = a.real("radius", 0);
    p.target_neighbours = a.integer("neighbours", p.target_neighbours);
    p.grid_size = a.integer("grid", p.grid_size);
    p.sigma = a.real("sigma", 0);
    p.sigma_scale = a.real("sigma-scale", p.sigma_scale);
    p.smoothing_iterations = a.integer("smoothing", p.smoothing_iterations);
    p.similar_patches = a.integer("patches", p.similar_patches);
    p.search_checks = a.integer("checks", p.search_checks);
    p.descriptor_smoothing = a.integer("guide", p.descriptor_smoothing);
    p.passes = a.integer("passes", p.passes);
    p.guided_passes = !a.has("refilter");
    p.own_weight = a.real("own-weight", p.own_weight);
    const std::string aggregate = a.text("aggregate", "patch");
    if (aggregate == "centre") p.aggregation = SimilarityDenoisingParameters::Aggregation::Centre;
    else if (aggregate != "patch") throw InvalidParameter("aggregate", aggregate, "patch or centre");
    if (const auto known = knownSensorOrigin(origin)) {
      p.use_viewpoint = true;
      p.viewpoint = *known;
    }
    p.noise_sigma = a.real("noise", 0);
    p.adapt_to_noise = !a.has("no-adapt");
    p.max_tile_points = a.count("tile-points", p.max_tile_points);
    p.max_noise_ratio = a.real("max-noise-ratio", p.max_noise_ratio);
    validateAsOptions({{"target_neighbours", "neighbours"}, {"grid_size", "grid"}, {"sigma_scale", "sigma-scale"},
                       {"smoothing_iterations", "smoothing"}, {"descriptor_smoothing", "guide"},
                       {"similar_patches", "patches"}, {"search_checks", "checks"}, {"own_weight", "own-weight"},
                       {"noise_sigma", "noise"}, {"max_tile_points", "tile-points"},
                       {"max_noise_ratio", "max-noise-ratio"}},
                      [&] { p.validate(); });
    // Schedule options given on the command line go over the noise rule's choice.
    SimilarityDenoisingReport choice, r;
    SimilarityDenoisingParameters run = p;
    if (a.has("passes") || a.has("refilter") || a.has("own-weight")) {
      run = noiseResolvedParameters(in, p, &choice);
      if (a.has("passes") || a.has("refilter")) {
        run.passes = p.passes;
        run.guided_passes = p.guided_passes;
      }
      if (a.has("own-weight")) run.own_weight = p.own_weight;
    }
    out = denoiseBySimilarity(in, run, &r, {}, progress);
    if (run.adapt_to_noise) choice = r;  // resolved inside the run
    const std::string adapted =
        p.radius > 0 ? "" : !p.adapt_to_noise ? " (chosen from the neighbour count)"
                                               : adaptedNote(choice.noise_sigma, choice.noise_estimated, choice.radius_scale);
    std::printf("similarity denoising: radius %g m%s (mean %.1f neighbours), grid %dx%d, sigma %g m%s, "
                "%d smoothing iterations, %d similar patches, %d pass%s%s, own weight %g\n",
                r.radius, adapted.c_str(), r.mean_neighbours, p.grid_size, p.grid_size,
                r.sigma, p.sigma > 0 ? "" : " (chosen)", p.smoothing_iterations, p.similar_patches,
                r.passes, r.passes > 1 ? "es" : "", r.passes > 1 ? (r.guided_passes ? " (guided)" : " (refiltered)") : "",
                r.own_weight);
    if (r.subsets > 1)
      std::printf("in %zu interleaved subsets (noise %.3g x the base radius on the whole cloud; radius, noise "
                  "and sigma above are their means)\n", r.subsets, r.split_noise_ratio);
    if (r.tiles > r.subsets)
      std::printf("in %zu tiles (at most %zu points each, %zu with the halo of %g radii)\n", r.tiles,
                  p.max_tile_points, r.largest_tile, p.tile_margin);
    std::printf("normals oriented %s; moved %zu points; %zu NaN or Inf points passed through\n",
                p.use_viewpoint ? "towards the file's sensor origin" : "by propagation", r.moved, r.non_finite);
    if (r.isolated) std::fprintf(stderr, "warning: %zu points have too few neighbours (or only collinear ones: no normal) and were left in place\n", r.isolated);
    radius = r.radius;
  } else if (method == "lpf") {
    LpfDenoisingParameters p;
    p.probing.radius = a.real("radius", 0);
    p.probing.neighbours = a.integer("neighbours", p.probing.neighbours);
    p.probing.step = a.real("step", 0);
    p.probing.atoms = a.integer("atoms", p.probing.atoms);
    p.probing.lambda = a.real("lambda", p.probing.lambda);
    p.probing.rounds = a.integer("rounds", p.probing.rounds);
    p.probing.seed_spacing = a.real("seed-spacing", 0);
    p.iterations = a.integer("passes", p.iterations);
    p.normal_motion_on_surfaces = !a.has("free-motion");
    p.probing.free_curvature = a.has("free-curvature");
    p.bend_threshold = a.real("bend-threshold", p.bend_threshold);
    p.max_tile_points = a.count("tile-points", p.max_tile_points);
    validateAsOptions({{"seed_spacing", "seed-spacing"}, {"iterations", "passes"}, {"bend_threshold", "bend-threshold"},
                       {"max_tile_points", "tile-points"}},
                      [&] { p.validate(); });
    LpfDenoisingReport r;
    out = lpfDenoisePositions(in, p, &r, {}, progress);
    char chosen[96] = " (chosen)";
    if (r.noise_sigma > 0)
      std::snprintf(chosen, sizeof chosen, " (chosen: noise %.3g m measured, at least %g sigma)", r.noise_sigma,
                    p.probing.noise_sigmas);
    std::printf("LPF denoising: pattern radius %g m%s, step %g m (%d nodes), %zu fields, %d atoms, lambda %g m, "
                "%d pass%s%s%s; moved %zu points\n",
                r.radius, p.probing.radius > 0 ? "" : chosen, r.step, r.pattern_nodes, r.fields, p.probing.atoms,
                r.lambda, r.passes, r.passes == 1 ? "" : "es",
                p.iterations > 0 ? ""
                : r.noise_growth >= p.relief_growth
                    ? fmt(" (chosen: relief, noise growth %.3g)", r.noise_growth).c_str()
                    : fmt(" (chosen: smooth, noise growth %.3g)", r.noise_growth).c_str(),
                p.probing.free_curvature ? ", free curvature" : "", r.moved);
    if (r.tiles > 1)
      std::printf("in %zu tiles (at most %zu points each, %zu with the halo of %g radii; fields and dictionaries per tile)\n",
                  r.tiles, p.max_tile_points, r.largest_tile, p.tile_margin);
    if (p.bend_threshold > 0 && r.passes > 1) {
      std::string by_pass;
      for (std::size_t k = 0; k < r.held_after_pass.size(); ++k)
        by_pass += (k ? ", " : "") + std::to_string(r.held_after_pass[k]) + " after pass " + std::to_string(k + 1);
      std::printf("bent fields (creases): %zu; points held: %zu (%s)\n", r.bent_fields, r.held_points, by_pass.c_str());
    }
    if (!r.round_errors.empty())
      std::printf("representation error per field: %.3g after the first round, %.3g after the last\n",
                  r.round_errors.front(), r.round_errors.back());
    if (r.isolated) std::fprintf(stderr, "warning: %zu points had no field to move them and were left in place\n", r.isolated);
    radius = r.radius;
  } else {
    PointBilateralParameters p;
    p.radius = a.real("radius", 0);
    p.target_neighbours = a.integer("neighbours", p.target_neighbours);
    p.iterations = a.integer("iterations", p.iterations);
    p.max_tile_points = a.count("tile-points", p.max_tile_points);
    validateAsOptions({{"target_neighbours", "neighbours"}, {"max_tile_points", "tile-points"}}, [&] { p.validate(); });
    PointBilateralReport r;
    out = bilateralFilterPositions(in, p, &r, {}, progress);
    std::printf("bilateral filter: radius %g m%s, %d passes; moved %zu points\n", r.radius,
                p.radius > 0 ? "" : " (chosen)", p.iterations, r.moved);
    if (r.tiles > 1)
      std::printf("in %zu tiles (at most %zu points each, %zu with the halo of %d radii)\n", r.tiles,
                  p.max_tile_points, r.largest_tile, p.iterations);
    if (r.isolated) std::fprintf(stderr, "warning: %zu points have too few neighbours (or only collinear ones: no normal) and were left in place\n", r.isolated);
    radius = r.radius;
  }
  writePositions(out, cloud);
  refreshBlobNormals(cloud, out, radius, origin, a.has("keep-normals"));
  saveCloudAtomic(out_path, cloud, origin);
  std::printf("wrote %s\n", out_path.c_str());
  return 0;
}

}  // namespace paps::cli
