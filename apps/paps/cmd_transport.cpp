// paps reconstruct IN OUT.ply [options]: surface reconstruction by optimal transport.
// paps recover-features MESH IN OUT.ply [options]: crease recovery of a smooth mesh by
// optimal transport to the points it was made from.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <utility>

#include <unistd.h>

#include <pcl/console/print.h>
#include <pcl/io/ply_io.h>

#include <paps/core/cloud_file_layout.h>
#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/interrupt_cleanup.h>
#include <paps/core/triangle_mesh.h>
#include <paps/surface/transport_feature_recovery.h>
#include <paps/surface/transport_reconstruction.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

namespace {

const char* kReconstructUsage =
    "usage: paps reconstruct IN OUT.ply [options]\n"
    "  IN                       the points (.pcd, .ply, or .xyz: one 'x y z' a line)\n"
    "  OUT.ply                  the mesh (binary PLY: x y z vertices, triangles); a simplicial\n"
    "                           complex, possibly non-manifold, with creases and borders kept\n"
    "  --vertices N             decimation stops at N vertices (default 50, at least 3)\n"
    "  --initial-fraction F     share of the points in the initial Delaunay triangulation,\n"
    "                           in (0, 1] (default 0.2)\n"
    "  --candidates K           half-edge collapses simulated per step, drawn at random\n"
    "                           (default 40; 0: every half-edge, slow; 120 fits clean\n"
    "                           points closer in 2.2x-2.6x the time, but kept more facets\n"
    "                           hanging from outliers in the bench: docs/transport.md)\n"
    "  --seed S                 seed of the random draws (default 1); same seed, same mesh\n"
    "  --density-threshold T    facets whose mass density is below T x the mean are dropped,\n"
    "                           in [0, 1) (default 0.1)\n"
    "  --deletion-threshold D   after the decimation, a facet goes when passing its mass to\n"
    "                           its neighbours costs at most D x its mass x the median facet's\n"
    "                           mean squared transport distance (default 0.2; 0: keep all)\n"
    "  --stacked-threshold T    then a facet lying over near-parallel facets (a layer or a\n"
    "                           fold, within the reach below) goes when passing its mass to\n"
    "                           them costs at most T x its mass x that unit (default 4; 0:\n"
    "                           keep layers)\n"
    "  --stacked-reach R        how far above or below a facet another one counts as\n"
    "                           stacked on it, in RMS transport distances of the median facet\n"
    "                           (default 3)\n"
    "  --dangling-support S     at the end, a facet with a corner no other facet uses goes when\n"
    "                           fewer than 2 points lie within S mean point spacings of that\n"
    "                           corner (a facet held up by outliers); in [0, 1000] (default 0:\n"
    "                           keep them; 2 with --density-threshold 0.5 for points with\n"
    "                           outliers, as the bench does)\n"
    "  --outlier-neighbours K   points with outliers: a point whose distance to its K-th\n"
    "                           nearest exceeds 1.5 x the median weighs (1.5 median / d)^4\n"
    "                           (stray points pull the facets little); 0 (default): all\n"
    "                           weigh 1; 8 for the bench's cube with 10% outliers. Not for\n"
    "                           scans whose density varies: their sparse parts weigh less\n"
    "  --max-points N           more distinct points than N are first merged by a voxel\n"
    "                           grid into at most N points (cell centroids, summed masses);\n"
    "                           0: never (default 20000: rs1 50,000 points to 100 vertices\n"
    "                           in 30-38 s instead of 129-135 s, about as close; on a sharp\n"
    "                           cube 1.5x the facets of a plain sample: docs/transport.md)\n"
    "  --merge-points-per-vertex P\n"
    "                           the merge keeps at least P points a vertex: at most\n"
    "                           max(N, P x vertices) cells; in [0, 1000] (default 10; 0: N\n"
    "                           alone). Fewer points a vertex leave holes in the mesh\n"
    "  --merge-crease-angle A   merging splits a cell whose points' normals fall in two groups\n"
    "                           more than A degrees apart (a crease), each side at its own\n"
    "                           centroid, when they are further apart than their noise; in\n"
    "                           [0, 90] (default 30; 0: never split; a sharp cube merged\n"
    "                           10:1: its coverage error 0.68x: docs/transport.md)\n"
    "  --initial-complex C      advancing-front (default: the facets of CGAL's advancing-front\n"
    "                           surface over the subset; a near-manifold mesh) or delaunay (the\n"
    "                           manuscript: every facet of the subset's 3D Delaunay\n"
    "                           triangulation; its meshes stack layers of facets over the\n"
    "                           surface, 1.2x-2x its area in the bench; docs/transport.md)\n"
    "  --allow-volume           run on points that fill a volume too (refused by default:\n"
    "                           the method is for surfaces: 5,000 points in a cube took\n"
    "                           258 s, 200,000 did not end in 400 s; docs/transport.md)\n"
    "  --allow-flips            let the decimation make collapses that turn a facet over (by\n"
    "                           default they are refused: they fold the mesh back over itself)\n"
    "  --bins-per-area B        facet bins per unit area, the points scaled into a box of side\n"
    "                           0.5 (default 800; the manuscript's 200 is faster, less sharp)\n"
    "  --max-bins M             at most M bins a facet, 1 to 256 (default 64)\n"
    "  --bins-per-point K       a point's mass may go to its K nearest bins (and its nearest\n"
    "                           vertex); 0: to every bin of the local program (default 16;\n"
    "                           8 is faster and as good when the points outnumber the bins)\n"
    "  --quiet, --timings       no progress bar / wall time of each stage\n"
    "Costly: meant for tens to hundreds of vertices. 2 cores: 3,000 points to 100 vertices in\n"
    "about 3 s; 50,000 in about 35 s merged into 20,000 (2 min with --max-points 0); 112,586\n"
    "(bun0.pcd) to 50 vertices in 48 s merged (not finished in 28 min unmerged). --timings\n"
    "shows where the time goes.\n";

const char* kRecoverUsage =
    "usage: paps recover-features MESH IN OUT.ply [options]\n"
    "  MESH                     a smooth mesh made from IN (.ply or .obj; Poisson, MLS...)\n"
    "  IN                       the points (.pcd, .ply, or .xyz: one 'x y z' a line)\n"
    "  OUT.ply                  MESH with its vertices moved onto the creases and corners the\n"
    "                           points describe (binary PLY)\n"
    "  --sweeps N               relocation sweeps over all vertices, 1 to 1000 (default 1)\n"
    "  --density-threshold T    facets whose mass density is below T x the mean are dropped,\n"
    "                           in [0, 1) (default 0: every facet kept, a closed mesh stays closed)\n"
    "  --quiet, --timings       no progress bar / wall time of each stage\n";

// An ASCII point list: one point a line, x y z first (separated by spaces, tabs or commas),
// further columns ignored; empty lines and lines starting with '#' skipped.
Positions loadXyz(const std::string& path) {
  checkInputPath(path);
  std::ifstream f(path);
  if (!f) throw IoError("cannot read '" + path + "': not readable");
  Positions out;
  std::string line;
  std::size_t number = 0;
  while (std::getline(f, line)) {
    ++number;
    for (auto& c : line)
      if (c == ',' || c == '\t' || c == '\r') c = ' ';
    const auto first = line.find_first_not_of(' ');
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream s(line);
    float x, y, z;
    if (!(s >> x >> y >> z))
      throw IoError("cannot read '" + path + "': line " + std::to_string(number) + " does not start with three numbers");
    out.emplace_back(x, y, z);
  }
  if (out.empty()) throw IoError("cannot read '" + path + "': no points");
  return out;
}

Positions loadPoints(const std::string& path) {
  Positions p = lowerExtension(path) == ".xyz" ? loadXyz(path) : loadPositions(path);
  printRead(path, p);
  return p;
}

// Writes the mesh as binary PLY to a temporary file beside `path`, then renames it: the target
// is complete or untouched, and no temporary is left behind (not even on Ctrl-C).
void saveMeshAtomic(const std::string& path, const TriangleMesh& mesh) {
  checkFileOutput(path, ".ply");  // the mesh is written as binary PLY
  const std::filesystem::path target(path);
  const std::filesystem::path dir = target.has_parent_path() ? target.parent_path() : ".";
  const std::string tmp = (dir / ("." + target.stem().string() + ".tmp" + std::to_string(::getpid()) + ".ply")).string();
  const TemporaryFileGuard guard(tmp);
  std::error_code ec;
  const pcl::PolygonMesh pm = toPolygonMesh(mesh);
  const auto level = pcl::console::getVerbosityLevel();
  pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS);
  const int rc = pcl::io::savePLYFileBinary(tmp, pm);
  pcl::console::setVerbosityLevel(level);
  if (rc < 0) {
    std::filesystem::remove(tmp, ec);
    throw IoError("cannot write '" + path + "': the PLY writer failed");
  }
  commitTemporaryFile(tmp, path);
}

}  // namespace

int runReconstruct(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"quiet", "help", "timings", "allow-volume", "allow-flips"});
  if (a.has("help")) { std::fputs(kReconstructUsage, stdout); return 0; }
  a.allowOnly({"vertices", "initial-fraction", "candidates", "seed", "density-threshold", "deletion-threshold",
               "stacked-threshold", "stacked-reach", "dangling-support", "outlier-neighbours", "max-points", "merge-points-per-vertex", "merge-crease-angle", "initial-complex", "bins-per-area", "max-bins", "bins-per-point", "quiet",
               "timings", "allow-volume", "allow-flips"});
  if (a.positional.size() != 2) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "IN OUT.ply");
  a.requireFileOutput(".ply");  // checked before any work
  const std::string in_path = a.positional[0], out_path = a.positional[1];
  // Parameters and the output path are checked before the points are read.
  TransportReconstructionParameters p;
  p.target_vertices = a.integer("vertices", p.target_vertices);
  p.initial_fraction = a.real("initial-fraction", p.initial_fraction);
  p.candidates = a.integer("candidates", p.candidates);
  p.seed = a.count("seed", p.seed);
  p.density_threshold = a.real("density-threshold", p.density_threshold);
  p.deletion_threshold = a.real("deletion-threshold", p.deletion_threshold);
  p.stacked_threshold = a.real("stacked-threshold", p.stacked_threshold);
  p.stacked_reach = a.real("stacked-reach", p.stacked_reach);
  p.dangling_support = a.real("dangling-support", p.dangling_support);
  p.outlier_neighbours = a.integer("outlier-neighbours", p.outlier_neighbours);
  p.max_points = a.integer("max-points", p.max_points);
  p.merge_points_per_vertex = a.integer("merge-points-per-vertex", p.merge_points_per_vertex);
  p.merge_crease_angle = a.real("merge-crease-angle", p.merge_crease_angle);
  const std::string initial = a.text("initial-complex", "advancing-front");
  if (initial == "delaunay")
    p.initial_complex = InitialComplex::Delaunay;
  else if (initial == "advancing-front")
    p.initial_complex = InitialComplex::AdvancingFront;
  else
    throw InvalidParameter("initial-complex", initial, "delaunay or advancing-front");
  p.allow_volume = a.has("allow-volume");
  p.transport.refuse_flips = !a.has("allow-flips");
  p.transport.bins_per_area = a.number("bins-per-area", p.transport.bins_per_area);
  p.transport.max_bins_per_facet = a.integer("max-bins", p.transport.max_bins_per_facet);
  p.transport.bins_per_point = a.integer("bins-per-point", p.transport.bins_per_point);
  validateAsOptions({{"target_vertices", "vertices"}, {"initial_fraction", "initial-fraction"},
                     {"density_threshold", "density-threshold"}, {"deletion_threshold", "deletion-threshold"},
                     {"stacked_threshold", "stacked-threshold"}, {"stacked_reach", "stacked-reach"},
                     {"dangling_support", "dangling-support"}, {"outlier_neighbours", "outlier-neighbours"}, {"max_points", "max-points"},
                     {"merge_points_per_vertex", "merge-points-per-vertex"}, {"merge_crease_angle", "merge-crease-angle"},
                     {"bins_per_area", "bins-per-area"},
                     {"max_bins_per_facet", "max-bins"}, {"bins_per_point", "bins-per-point"}},
                    [&] { p.validate(); });
  const Positions points = loadPoints(in_path);
  TransportReconstructionReport r;
  const TriangleMesh mesh = transportReconstruct(points, p, &r, progressBar(a.has("quiet"), a.has("timings")));
  const bool front = p.initial_complex == InitialComplex::AdvancingFront && !r.advancing_front_fallback;
  std::printf("reconstruct: %s of %d points (%d facets), %d facets %s; %d collapses (%d simulated, "
              "%d simulations reused, %d skipped by their bound, %d refused: they turned a facet over)\n",
              front ? "advancing front" : "Delaunay", r.initial_vertices, r.initial_facets, r.complex_facets,
              front ? "kept (all)" : "with mass", r.collapses, r.simulations, r.reused_simulations,
              r.bounded_simulations, r.refused_collapses);
  if (r.merge_cell > 0)
    std::printf("reconstruct: %zu points merged into %zu (at most %zu asked; cells of %g m, %zu more for creases, "
                "spread %.4g in the costs)\n",
                r.points, r.transported_points, r.merge_target, r.merge_cell, r.crease_points, r.merge_spread);
  if (p.outlier_neighbours > 0)
    std::printf("reconstruct: outlier weights (%d neighbours): %zu points weigh less than 1, %zu less than 0.1\n",
                p.outlier_neighbours, r.light_points, r.outlier_points);
  std::printf("reconstruct: %d facets deleted, %d stacked facets deleted, %d dangling facets dropped, %d empty facets "
              "kept (they close a hole); transport cost %.4g -> %.4g, RMS transport distance %g m\n",
              r.deleted_facets, r.stacked_facets, r.dangling_facets, r.restored_facets, r.initial_cost, r.final_cost,
              r.rms_transport);
  // rs1 to 10,000 vertices merged into 20,000 points kept 8,986 border edges; from all its
  // 114,373 points, 1,547 (docs/transport.md, session 66). The merge keeps kPointsPerVertex
  // by default (merge_points_per_vertex), up to the grid's steps: the warning is for inputs
  // that have too few, or a merge asked for fewer.
  const std::size_t wanted = kPointsPerVertex * static_cast<std::size_t>(p.target_vertices);
  if (r.transported_points < wanted && !(r.merge_cell > 0 && r.merge_target >= wanted))
    std::fprintf(stderr,
                 "reconstruct: warning: %zu points for %d vertices (fewer than %d a vertex): many small facets get no "
                 "point and the mesh has holes; give more points or ask for fewer vertices\n",
                 r.transported_points, p.target_vertices, kPointsPerVertex);
  std::printf("reconstruct: volume variation %.3g (a volume is refused above %g without --allow-volume)\n",
              r.volume_variation, kVolumeVariation);
  saveMeshAtomic(out_path, mesh);
  std::printf("wrote %s: %zu vertices, %zu facets\n", out_path.c_str(), mesh.vertices.size(), mesh.triangles.size());
  return 0;
}

int runRecoverFeatures(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"quiet", "help", "timings"});
  if (a.has("help")) { std::fputs(kRecoverUsage, stdout); return 0; }
  a.allowOnly({"sweeps", "density-threshold", "quiet", "timings"});
  if (a.positional.size() != 3)
    throw InvalidParameter("arguments", std::to_string(a.positional.size()), "MESH IN OUT.ply");
  a.requireFileOutput(".ply");  // checked before any work
  const std::string mesh_path = a.positional[0], in_path = a.positional[1], out_path = a.positional[2];
  TransportFeatureRecoveryParameters p;
  p.sweeps = a.integer("sweeps", p.sweeps);
  p.density_threshold = a.real("density-threshold", p.density_threshold);
  validateAsOptions({{"density_threshold", "density-threshold"}}, [&] { p.validate(); });
  const TriangleMesh smooth = loadTriangleMesh(mesh_path);
  std::printf("read %s: %zu vertices, %zu facets\n", mesh_path.c_str(), smooth.vertices.size(), smooth.triangles.size());
  const Positions points = loadPoints(in_path);
  TransportFeatureRecoveryReport r;
  const TriangleMesh mesh = transportRecoverFeatures(smooth, points, p, &r, progressBar(a.has("quiet"), a.has("timings")));
  std::printf("recover-features: transport cost %.4g -> %.4g (relaxed) -> %.4g after %d sweeps; vertices moved "
              "%g m on average, at most %g m\n",
              r.initial_cost, r.relaxed_cost, r.final_cost, p.sweeps, r.mean_move, r.max_move);
  if (mesh.triangles.empty())
    throw InvalidInput("no facet kept (try a lower --density-threshold)");
  saveMeshAtomic(out_path, mesh);
  std::printf("wrote %s: %zu vertices, %zu facets\n", out_path.c_str(), mesh.vertices.size(), mesh.triangles.size());
  return 0;
}

}  // namespace paps::cli
