// paps superres IN [IN2 ...] OUT --factor F [options]
#include <cstdio>

#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include <paps/core/cloud_io.h>
#include <paps/core/normal_refresh.h>
#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/surface/lpf_resampling.h>
#include <paps/surface/mls_upsampling.h>
#include <paps/surface/quadric_super_resolution.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

namespace {
// --denoise auto|on|off (QSR and LPF).
DenoiseFirst denoiseFirstOption(const Arguments& a) {
  const std::string denoise = a.text("denoise", "auto");
  if (denoise == "auto") return DenoiseFirst::Auto;
  if (denoise == "on") return DenoiseFirst::On;
  if (denoise == "off") return DenoiseFirst::Off;
  throw InvalidParameter("denoise", denoise, "auto, on or off");
}

const char* kSuperresUsage =
    "usage: paps superres IN [IN2 ...] OUT --factor F [options]\n"
    "  IN                     the scan to super-resolve (.pcd or .ply)\n"
    "  IN2 ...                other scans of the same object, registered (sources of similar patches)\n"
    "  OUT                    .pcd or .ply, x y z (and normal_x/y/z with --normals), factor x the\n"
    "                         finite points of IN\n"
    "  --normals              also write the normal of the fitted surface at each output point\n"
    "                         (QSR: the SR surface's; APSS/RIMLS: the gradient of their fit),\n"
    "                         on the side of IN's own normals nearby when it has some, else\n"
    "                         oriented by propagation over the scan, and\n"
    "                         PCL's curvature field (the surface variation of the input ball\n"
    "                         each point was made from, as PCL's MLS); on by default when IN\n"
    "                         has normal fields (they are then replaced, curvature too)\n"
    "  --keep-normals         IN has normals: each new point carries its source point's instead\n"
    "  --orient M             with --normals: propagate (default) or viewpoint (each normal\n"
    "                         towards IN's sensor origin, a .pcd's VIEWPOINT, else the origin,\n"
    "                         where a range scan in its own frame has its sensor: right where\n"
    "                         propagation fails, across folds between scan pieces)\n"
    "  --factor F             output count / input count (default 4, 1 to 1000)\n"
    "  --count N              exact output count (overrides --factor)\n"
    "  --method M             qsr (default), apss, rimls, or lpf (Local Probing Fields\n"
    "                         resampling: wires as well as surfaces; --factor is the density\n"
    "                         ratio on surfaces, --radius the pattern radius, --neighbours its\n"
    "                         count (default 100); no --count, no --normals; --denoise: auto\n"
    "                         denoises first with paps denoise --method lpf when the measured\n"
    "                         noise is at least half the consensus radius, 0.7 x the output\n"
    "                         spacing, in twice that ratio passes, 1 to 5)\n"
    "  --radius R             patch radius (QSR) or kernel support (APSS/RIMLS) in metres\n"
    "                         (default: from --neighbours)\n"
    "  --neighbours N         neighbour count of a typical point (median) that sets the radius (default 36 QSR, 30 others)\n"
    "  --similarity S         QSR similarity radius in metres (RMS height difference; default: the\n"
    "                         median distance of patches to their most similar patch)\n"
    "  --grid-lr N, --grid-sr N  QSR bins per side (default: from the data)\n"
    "  --patches K            QSR similar patches kept per patch (default 16; 0: none, a local\n"
    "                         interpolation of the scan alone)\n"
    "  --kernel F             QSR aggregation kernel scale (default 0.7; from the noise, 0.7 to\n"
    "                         1.4, with --adapt)\n"
    "  --similarity-scale F   QSR multiplier of the automatic similarity radius (default 1)\n"
    "  --irls N               QSR IRLS passes, 0 to 10 (default 2)\n"
    "  --noise S              QSR noise standard deviation of IN in metres (default: measured)\n"
    "  --adapt                QSR: widen the kernel with the measured noise (2-4% closer to the\n"
    "                         surface at 0.5% noise, about 3x the time); acts on scans that are\n"
    "                         not denoised first (a denoised scan gets the quiet kernel)\n"
    "  --denoise WHEN         QSR and LPF: denoise the scans first (paps denoise's default): auto (default:\n"
    "                         when the measured noise is at least 5% of the patch radius), on, off;\n"
    "                         auto also denoises from 0.5% when the surface is smooth at the patch\n"
    "                         scale (scan-line bench: 17% closer to the ground); on denoises always,\n"
    "                         which costs detailed, quiet surfaces their detail\n"
    "  --tile-points N        a first scan of more finite points is super-resolved in tiles of at\n"
    "                         most N points, one at a time (memory: QSR about 1.2 KB a point of a\n"
    "                         tile at x2, LPF 1.5 KB; default 2000000; 0: one piece whatever the\n"
    "                         size)\n"
    "  --refit                APSS/RIMLS: refit at every output point instead of once per input\n"
    "                         point (slower, slightly more accurate)\n"
    "  --seed-disc S          radius of the tangent discs the output seeds are spread over, in mean\n"
    "                         input spacings (default 1.2 QSR, 0.68 APSS/RIMLS; 0.1 to 10); a\n"
    "                         smaller disc keeps seeds nearer the returns (closer to the surface,\n"
    "                         fewer gaps filled)\n"
    "  --thin-disc F          QSR: scale of the seed disc of points whose ball is too thin for a\n"
    "                         quadric (along scan lines, strips, sparse parts), in (0, 1] (default\n"
    "                         0.5; 1: the same disc everywhere)\n"
    "  --max-neighbours N     APSS/RIMLS: most neighbours a kernel holds, the nearest within the\n"
    "                         radius (default 16 x --neighbours; bounds memory on clustered input)\n"
    "  --quiet, --timings     no progress bar / wall time of each stage\n";
}  // namespace

int runSuperres(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"quiet", "help", "timings", "refit", "adapt", "normals", "keep-normals"});
  if (a.has("help")) { std::fputs(kSuperresUsage, stdout); return 0; }
  a.allowOnly({"factor", "count", "method", "radius", "neighbours", "similarity", "grid-lr", "grid-sr",
               "patches", "kernel", "similarity-scale", "irls", "noise", "adapt", "denoise", "quiet", "timings",
               "refit", "max-neighbours", "seed-disc", "thin-disc", "normals", "orient", "keep-normals",
               "tile-points"});
  if (a.positional.size() < 2)
    throw InvalidParameter("arguments", std::to_string(a.positional.size()), "IN [IN2 ...] OUT");
  a.requireCloudOutput();
  const std::string method = a.text("method", "qsr");
  if (method != "qsr" && method != "apss" && method != "rimls" && method != "lpf")
    throw InvalidParameter("method", method, "qsr, apss, rimls or lpf");
  // An option of another method would be silently ignored: refused instead (LPF sets its
  // density by --factor and gives no normals; APSS and RIMLS have no thin-ball test).
  std::vector<std::string> applies = {"factor", "method", "radius", "neighbours", "quiet", "timings", "tile-points"};
  if (method == "qsr")
    applies.insert(applies.end(), {"count", "similarity", "grid-lr", "grid-sr", "patches", "kernel", "similarity-scale",
                                   "irls", "noise", "adapt", "denoise", "seed-disc", "thin-disc", "normals", "orient",
                                   "keep-normals"});
  else if (method == "lpf")
    applies.push_back("denoise");
  else
    applies.insert(applies.end(), {"count", "refit", "max-neighbours", "seed-disc", "normals", "orient", "keep-normals"});
  requireOptionsOf(a, applies, "--method " + method);
  const std::string out_path = a.positional.back();
  // Parameters are checked before the scans are read, so a bad value fails at once.
  std::vector<Positions> scans;
  Eigen::Vector3f origin = Eigen::Vector3f::Zero();  // the first scan's sensor origin (.pcd VIEWPOINT)
  pcl::PCLPointCloud2 first;  // the first scan as read: its other fields go to the new points
  auto readScans = [&] {
    for (std::size_t i = 0; i + 1 < a.positional.size(); ++i) {
      if (i == 0) first = loadCloud(a.positional[i], &origin);
      scans.push_back(i == 0 ? positionsOf(first) : loadPositions(a.positional[i]));
      printRead(a.positional[i], scans.back());
    }
  };
  // Each new point's input point (of the first scan), when that scan has fields besides x y z
  // (colour, intensity): they are carried to the new points, as PCL's MLS does.
  std::vector<int> source;
  auto otherFields = [](const pcl::PCLPointCloud2& c) {
    std::string names;
    for (const auto& f : c.fields)
      if (f.name != "x" && f.name != "y" && f.name != "z" && f.name != "_") names += " " + f.name;
    return names;
  };
  auto carries = [&] { return !otherFields(first).empty(); };
  const std::size_t count = a.count("count", 0);
  if (count > 4000000000u) throw InvalidParameter("count", std::to_string(count), "a count in [0, 4e9]");
  const ProgressCallback progress = progressBar(a.has("quiet"), a.has("timings"));
  Positions out;
  Normals normals;
  std::vector<float> curvature;  // PCL's curvature field, with --normals
  // Normals of the fitted surface: asked for, or the input has normal fields, which a new
  // point's source point would otherwise lend it (the fit's are the surface's at the point).
  if (a.has("normals") && a.has("keep-normals"))
    throw InvalidParameter("keep-normals", "with --normals", "one of the two");
  Normals* normals_out = a.has("normals") ? &normals : nullptr;
  auto normalsFromInput = [&] {
    if (!normals_out && !a.has("keep-normals") && hasField(first, "normal_x")) {
      normals_out = &normals;
      std::printf("normals: IN has normal fields: each new point gets the fitted surface's (--keep-normals: its "
                  "source point's)\n");
    }
    if (a.has("orient") && !normals_out)
      throw InvalidParameter("orient", a.text("orient", ""), "with --normals (it orients them)");
  };
  // --orient needs output normals: asked for, or written because IN has normal fields (known
  // from its header, before any work).
  if (a.has("orient") && !a.has("normals") && (a.has("keep-normals") || !fileMayHaveNormals(a.positional[0])))
    throw InvalidParameter("orient", a.text("orient", ""), "with --normals (it orients them)");
  const std::string orient = a.text("orient", "propagate");
  if (orient != "propagate" && orient != "viewpoint") throw InvalidParameter("orient", orient, "propagate or viewpoint");

  if (method == "lpf") {
    LpfResamplingParameters p;
    p.factor = a.real("factor", p.factor);
    p.probing.radius = a.real("radius", 0);
    p.probing.neighbours = a.integer("neighbours", p.probing.neighbours);
    p.max_tile_points = a.count("tile-points", p.max_tile_points);
    p.denoise_input = denoiseFirstOption(a);
    validateAsOptions({{"max_tile_points", "tile-points"}}, [&] { p.validate(); });
    readScans();
    if (scans.size() > 1) std::fprintf(stderr, "warning: %s uses the first scan only\n", method.c_str());
    LpfResamplingReport r;
    out = lpfResample(scans[0], p, &r, progress);
    if (r.denoised)
      std::printf("lpf: the scan was denoised first (paps denoise --method lpf --passes %d): noise %g m measured, "
                  "%.2f x the consensus radius (%s)\n", r.denoise_passes, r.noise_sigma, r.noise_ratio,
                  p.denoise_input == LpfResamplingParameters::Denoise::On ? "--denoise on"
                                                                          : fmt("auto from %g", p.denoise_ratio).c_str());
    else if (p.denoise_input == LpfResamplingParameters::Denoise::Auto)
      std::printf("lpf: not denoised first: noise %g m measured, %.2f x the consensus radius (below %g)\n",
                  r.noise_sigma, r.noise_ratio, p.denoise_ratio);
    std::printf("lpf: pattern radius %g m%s, step %g m (%d nodes), %zu fields, %zu proposals\n", r.radius,
                p.probing.radius > 0 ? "" : " (chosen)", r.step, r.pattern_nodes, r.fields, r.proposals);
    if (r.tiles > 1)
      std::printf("lpf: in %zu tiles (at most %zu points each, %zu with the halo its fields read)\n", r.tiles,
                  p.max_tile_points, r.largest_tile);
  } else if (method == "qsr") {
    QuadricSuperResolutionParameters p;
    p.factor = a.real("factor", p.factor);
    p.output_count = count;
    p.patch_radius = a.real("radius", 0);
    p.target_neighbours = a.integer("neighbours", p.target_neighbours);
    p.similarity_radius = a.real("similarity", 0);
    p.grid_lr = a.integer("grid-lr", 0);
    p.grid_sr = a.integer("grid-sr", 0);
    p.similar_patches = a.integer("patches", p.similar_patches);
    p.kernel_scale = a.real("kernel", p.kernel_scale);
    p.similarity_scale = a.real("similarity-scale", p.similarity_scale);
    p.irls_iterations = a.integer("irls", p.irls_iterations);
    p.noise_sigma = a.real("noise", 0);
    p.seed_disc = a.real("seed-disc", p.seed_disc);
    p.thin_disc = a.real("thin-disc", p.thin_disc);
    p.max_tile_points = a.count("tile-points", p.max_tile_points);
    p.denoise_input = denoiseFirstOption(a);
    p.adapt_to_noise = a.has("adapt") || a.has("noise");
    validateAsOptions({{"target_neighbours", "neighbours"}, {"similarity_scale", "similarity-scale"},
                       {"grid_lr", "grid-lr"}, {"grid_sr", "grid-sr"}, {"similar_patches", "patches"},
                       {"irls_iterations", "irls"}, {"seed_disc", "seed-disc"}, {"noise_sigma", "noise"},
                       {"patch_radius", "radius"}, {"similarity_radius", "similarity"}, {"kernel_scale", "kernel"},
                       {"thin_disc", "thin-disc"}, {"max_tile_points", "tile-points"}},
                      [&] { p.validate(); });
    readScans();
    normalsFromInput();
    QuadricSuperResolutionReport r;
    out = superResolveQuadric(scans, p, &r, progress, normals_out, normals_out ? &curvature : nullptr,
                              carries() ? &source : nullptr);
    std::printf("QSR: patch radius %g m%s (mean %.1f neighbours), similarity radius %g m%s\n", r.patch_radius,
                p.patch_radius > 0 ? "" : " (chosen)", r.mean_neighbours, r.similarity_radius,
                p.similarity_radius > 0 ? "" : " (chosen)");
    if (r.tiles > 1)
      std::printf("QSR: in %zu tiles (at most %zu points each, %zu with the halo of %g patch radii); the choices "
                  "below are means over the tiles\n",
                  r.tiles, p.max_tile_points, r.largest_tile, p.tile_margin);
    std::printf("QSR: bins %dx%d low resolution%s, %dx%d super-resolution%s (mean similar weight K-1 = %.2f)\n",
                r.grid_lr, r.grid_lr, p.grid_lr ? "" : " (chosen)", r.grid_sr, r.grid_sr, p.grid_sr ? "" : " (chosen)",
                r.mean_similar_weight);
    if (r.noise_sigma > 0)
      std::printf("QSR: noise %.3g m%s, q = noise / patch radius = %.3f\n", r.noise_sigma,
                  r.noise_estimated ? " (measured)" : " (given)", r.noise_sigma / r.patch_radius);
    std::printf("QSR: kernel scale %.3g%s, similarity scale %.3g, %d IRLS passes\n", r.kernel_scale,
                p.kernel_scale > 0 ? "" : (p.adapt_to_noise ? " (chosen from the noise)" : " (fixed default)"),
                p.similarity_scale, p.irls_iterations);
    std::printf("QSR: %zu patches over %zu scan(s); %zu patches without a similar patch\n", r.patches, scans.size(),
                r.without_similar);
    std::printf("QSR: plane instead of quadric at %zu points: %zu flat (curvature below the patch's resolution), "
                "%zu ill-posed (fewer than 6 distinct neighbours, collinear, or bending more than the patch)\n",
                r.plane_fallbacks, r.flat_fits, r.ill_posed_fits);
    if (r.thin_balls)
      std::printf("QSR: %zu balls too thin for a quadric (along one or two scan lines): a wider support that reaches "
                  "across is tried\n",
                  r.thin_balls);
    if (r.widened_fits)
      std::printf("QSR: %zu fits of sparse or thin balls made on their %d (thin: up to %d) nearest distinct positions\n",
                  r.widened_fits, p.target_neighbours, kQsrThinWidening * p.target_neighbours);
    std::printf("QSR: seeds spread over tangent discs of radius %g m (%.2f mean spacings of %g m%s)\n", r.disc_radius,
                p.seed_disc, r.spacing, a.has("seed-disc") ? "" : "; --seed-disc");
    if (r.narrowed_discs)
      std::printf("QSR: %zu points whose ball is too thin for a quadric seed over discs %.2f times as wide%s\n",
                  r.narrowed_discs, p.thin_disc, a.has("thin-disc") ? "" : " (--thin-disc)");
    if (r.denoised)
      std::printf("QSR: the scan%s denoised first (paps denoise's default, %d pass%s%s)%s\n",
                  scans.size() > 1 ? "s were" : " was", r.denoise_passes, r.denoise_passes == 1 ? "" : "es",
                  r.denoise_subsets > 1 ? (", in " + std::to_string(r.denoise_subsets) + " interleaved subsets").c_str() : "",
                  p.denoise_input == QuadricSuperResolutionParameters::Denoise::On ? ""
                  : r.noise_growth > 0 ? ": the surface is smooth at the patch scale (noise over balls of 2R / R below 1.3)"
                                       : ": noise >= 5% of the patch radius");
    if (r.noise_growth > 0)
      std::printf("QSR: noise over balls of 2R / over balls of R = %.2f: %s\n", r.noise_growth,
                  r.denoised ? "smooth at the patch scale (below 1.3), denoised first"
                             : "relief at the patch scale (1.3 or more), not denoised");
    if (r.quadric_only)
      std::printf("QSR: %zu points without a comparable descriptor (rims, sparse parts) anchor the output by their quadric alone\n",
                  r.quadric_only);
    if (r.unprojected) std::fprintf(stderr, "warning: %zu output points had no patch nearby and were not projected\n", r.unprojected);
  } else {
    MlsUpsamplingParameters p;
    p.factor = a.real("factor", p.factor);
    p.output_count = count;
    p.radius = a.real("radius", 0);
    p.target_neighbours = a.integer("neighbours", p.target_neighbours);
    p.fit_per_input_point = !a.has("refit");
    p.max_neighbours = a.integer("max-neighbours", 0);
    p.max_tile_points = a.count("tile-points", p.max_tile_points);
    if (a.has("seed-disc")) {
      const double disc = a.number("seed-disc", 0);
      requireInRange("seed-disc", disc, 0.1, 10.0);
      p.disc_scale = static_cast<float>(disc / kMlsDiscSpacingsAtScaleOne);
    }
    validateAsOptions({{"target_neighbours", "neighbours"}, {"max_neighbours", "max-neighbours"},
                       {"max_tile_points", "tile-points"}},
                      [&] { p.validate(); });
    readScans();
    normalsFromInput();
    if (scans.size() > 1) std::fprintf(stderr, "warning: %s uses the first scan only\n", method.c_str());
    MlsUpsamplingReport r;
    out = upsampleMls(scans[0], method == "apss" ? MlsSurface::Apss : MlsSurface::Rimls, p, &r, progress, normals_out,
                      normals_out ? &curvature : nullptr, carries() ? &source : nullptr);
    std::printf("%s: radius %g m%s, seeds spread over tangent discs of radius %g m\n", method.c_str(), r.radius,
                p.radius > 0 ? "" : " (chosen)", r.disc_radius);
    if (r.tiles > 1)
      std::printf("%s: in %zu tiles (at most %zu points each, %zu with the halo its fits read)\n", method.c_str(), r.tiles,
                  p.max_tile_points, r.largest_tile);
    if (r.capped)
      std::printf("%s: %zu input points hold at least %d neighbours within the radius (much denser than typical); "
                  "their kernels keep the nearest %d (--max-neighbours)\n",
                  method.c_str(), r.capped, r.max_neighbours, r.max_neighbours);
    if (r.unprojected) std::fprintf(stderr, "warning: %zu output points could not be projected\n", r.unprojected);
  }
  pcl::PCLPointCloud2 cloud;
  if (!source.empty() && source.size() == out.size()) {
    cloud = gatherPoints(first, source);
    writePositions(out, cloud);
    std::printf("superres: kept from the input point each new point was made from:%s\n", otherFields(cloud).c_str());
  } else {
    pcl::PointCloud<pcl::PointXYZ> xyz;
    writePositions(out, xyz);
    pcl::toPCLPointCloud2(xyz, cloud);
  }
  if (normals_out) {
    Normals given;
    if (orient == "viewpoint") {
      orientNormalsTowards(out, normals, origin);
    } else if (blobNormals(first, given) && anyUsableNormal(given)) {
      // The side of the input's own normals nearby, over the propagated orientation.
      orientNormalsByNearbyHints(out, normals, scans[0], given);
      std::printf("normals: oriented as IN's normals nearby\n");
    }
    // PCL's `curvature` beside the normals, as its MLS writes it: the surface variation of
    // the input ball each output point was made from.
    if (hasField(cloud, "normal_x")) {  // carried from the source points: replaced, curvature too
      setNormals(cloud, normals);
      setCurvatureField(cloud, curvature);
    } else {
      setNormals(cloud, normals, &curvature);
    }
  }
  saveCloudAtomic(out_path, cloud, origin);
  std::printf("wrote %s: %zu points\n", out_path.c_str(), out.size());
  return 0;
}

}  // namespace paps::cli
