// paps bench transport: the optimal-transport stages of the manuscript's chapter 5 against
// PCL, in one run, each method in its own process (time, peak memory):
//  (a) feature recovery: PCL Poisson on a sampled fandisk block (creases and corners
//      rounded off), then TransportFeatureRecovery on that same Poisson mesh with the same
//      points (one relocation sweep, the default, and five); errors of the vertices and of
//      the meshes against the true shape;
//  (b) reconstruction: TransportReconstruction against PCL Poisson, the same Poisson mesh
//      decimated (VTK's quadric decimation through PCL) to as many vertices as ours, and PCL's
//      greedy projection triangulation on a sampled cube (noise 0 and 0.5%, and 10% outliers).
// Errors are in thousandths of the ground truth's bounding-box diagonal.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <pcl/common/io.h>
#include <pcl/features/normal_3d_omp.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/surface/gp3.h>
#include <pcl/surface/poisson.h>
#include <pcl/surface/vtk_smoothing/vtk_mesh_quadric_decimation.h>

#include <paps/core/error.h>
#include <paps/core/metrics.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/synthetic.h>
#include <paps/core/triangle_mesh.h>
#include <paps/surface/transport_feature_recovery.h>
#include <paps/surface/transport_reconstruction.h>

#include "bench_worker.h"
#include "cli_common.h"
#include "commands.h"
#include "render.h"

namespace paps::cli {

namespace {

const char* kUsage =
    "usage: paps bench transport [options]\n"
    "  --out DIR   where the table (CSV) and the scratch files go (default bench_out)\n"
    "  --quick     fewer points, Poisson depth 5, one noise level per part (a smoke run)\n"
    "  --samples DIR  sample data from scripts/fetch_samples.sh (default $PAPS_SAMPLES or\n"
    "              ~/.cache/paps/samples); its rs1_normals.ply is the real-scan shape of (b)\n"
    "  --candidates K  half-edge collapses our reconstruction simulates per step (default 40,\n"
    "              the library's; 0 = all)\n"
    "  --outlier-seeds N  seeds 1..N for each of our variants on the cube with outliers (default\n"
    "              3, at most 100; one seed's run takes a minute or two)\n"
    "  --only-outliers  only the cube with outliers: not (a) nor the other shapes and cases\n"
    "  --scan-points N  points sampled on rs1 (default 3000, 1000 to 1000000); past the\n"
    "              --max-points ours also runs unmerged (max_points 0)\n"
    "  --only-scan  only the real scan rs1: not (a) nor the cube and fandisk\n"
    "  --shape-points N  points sampled on the cube and the fandisk block of (b) (default\n"
    "              3000, 1000 to 1000000)\n"
    "  --max-points N  ours merges inputs of more than N distinct points into cells (default\n"
    "              the library's 20000; 0: never); past it ours also runs without the crease\n"
    "              splits (merge_crease_angle 0)\n"
    "  --only-shapes  only the cube and the fandisk block of (b): not (a) nor the scan\n"
    "(a) feature recovery on a fandisk block: PCL Poisson (normals by PCL's NormalEstimationOMP,\n"
    "    k = 20, pointing away from the centroid), then our transport feature recovery on that\n"
    "    Poisson mesh with the same points, with 1 relocation sweep (the default) and with 5\n"
    "    (its time: the recovery alone, and Poisson + recovery)\n"
    "(b) reconstruction of a cube (3000 points, noise 0 and 0.5%, and 10% outliers, where ours drops facets\n"
    "    below 0.5 of the mean density and dangling facets (support 2), then the same with the\n"
    "    outlier weights (outlier_neighbours 8); --quick: 800 points, noise 0)\n"
    "    and of a fandisk block (3000 points, 60 vertices, no noise; not in --quick) and of the\n"
    "    real range-scan mesh rs1_normals.ply (3000 points, or --scan-points; 100 vertices, no\n"
    "    noise; PCL's normals turned towards the scanner at the origin; not in --quick):\n"
    "    ours (30 vertices on the cube; seeds 1, 2, 3 and their mean; --quick: seed 1) vs\n"
    "    PCL Poisson (depth 5), that Poisson mesh decimated by VTK's quadric\n"
    "    decimation (pcl::MeshQuadricDecimationVTK) to seed 1's vertex count (reduction factor\n"
    "    1 - ours/Poisson vertices; its time: Poisson + decimation), and PCL's greedy projection\n"
    "    triangulation (radius 3x the mean spacing, mu 2.5, 100 neighbours); ours also starts\n"
    "    from every facet of the subset's Delaunay triangulation (initial_complex Delaunay, the\n"
    "    manuscript's start; ours' default is the advancing-front surface of the same subset)\n"
    "Errors in thousandths of the bounding-box diagonal: vertices to the true mesh (RMS),\n"
    "50000 samples of the output to the true mesh (mesh->gt) and of the true mesh to the output\n"
    "(gt->mesh, whose max measures rounded creases and corners and holes). (b) also: area/gt, the\n"
    "output's area over the true mesh's (layers of facets stacked over one surface push it above 1,\n"
    "holes below), and e>2, the edges shared by three facets or more (0 on a manifold).\n";

// Triangles travel through the raw scratch files as float triples (indices are exact in
// float below 2^24).
void writeMeshRaw(const std::string& path, const TriangleMesh& m) {
  writeRaw(path, m.vertices);
  Positions t(m.triangles.size());
  for (std::size_t i = 0; i < t.size(); ++i) t[i] = m.triangles[i].cast<float>();
  writeRaw(path + ".tri", t);
}

TriangleMesh readMeshRaw(const std::string& path) {
  TriangleMesh m;
  m.vertices = readRaw(path);
  for (const auto& t : readRaw(path + ".tri")) m.triangles.push_back(t.cast<int>());
  return m;
}

// Normals for PCL's mesh builders, as a user would make them: NormalEstimationOMP on the k
// nearest neighbours, each flipped to point away from the centroid (the shapes are convex
// enough for that), or towards the origin for a range scan taken from there.
pcl::PointCloud<pcl::PointNormal>::Ptr withNormals(const Positions& points, int k, bool towards_origin = false) {
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  Eigen::Vector3f centroid = Eigen::Vector3f::Zero();
  for (const auto& p : points) {
    cloud->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    centroid += p;
  }
  centroid /= static_cast<float>(std::max<std::size_t>(points.size(), 1));
  pcl::NormalEstimationOMP<pcl::PointXYZ, pcl::Normal> ne;
  ne.setInputCloud(cloud);
  ne.setKSearch(k);
  pcl::PointCloud<pcl::Normal> normals;
  ne.compute(normals);
  auto out = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  pcl::concatenateFields(*cloud, normals, *out);
  for (auto& p : *out) {
    const Eigen::Vector3f outward = towards_origin ? Eigen::Vector3f(-p.getVector3fMap()) : Eigen::Vector3f(p.getVector3fMap() - centroid);
    if (outward.dot(p.getNormalVector3fMap()) < 0) p.getNormalVector3fMap() *= -1.f;
  }
  return out;
}

// The distances see neither holes' area nor layers of facets stacked within the noise (each
// layer is near the surface): the area ratio (output / true mesh; layers push it above 1,
// holes below) and the edges of three facets or more show them.
struct MeshScore {
  double vertex_rms = NAN, to_gt_rms = NAN, to_gt_max = NAN, from_gt_rms = NAN, from_gt_max = NAN;
  double area_ratio = NAN, nonmanifold_edges = NAN;
};

MeshScore score(const TriangleMesh& m, const PointToMeshDistance& gt_distance, const Positions& gt_samples,
                double diagonal, double gt_area) {
  MeshScore s;
  const double k = 1e3 / diagonal;
  if (!m.vertices.empty()) s.vertex_rms = k * pointToMeshError(m.vertices, gt_distance).rmse;
  if (m.triangles.empty()) return s;
  s.area_ratio = m.area() / gt_area;
  s.nonmanifold_edges = m.nonManifoldEdgeCount();
  const ErrorStats to_gt = pointToMeshError(synthetic::sampleMesh(m, 50000, 3), gt_distance);
  const ErrorStats from_gt = pointToMeshError(gt_samples, PointToMeshDistance(m));
  s.to_gt_rms = k * to_gt.rmse;
  s.to_gt_max = k * to_gt.max;
  s.from_gt_rms = k * from_gt.rmse;
  s.from_gt_max = k * from_gt.max;
  return s;
}

// Runs `paps bench-worker-ot METHOD` on `input` (and, for the recovery, the mesh in
// DIR/ot_mesh.bin); the output mesh comes back in `mesh`.
WorkerResult runMeshWorker(const std::string& dir, const std::string& method, const Positions& input,
                           const std::map<std::string, double>& params, TriangleMesh& mesh) {
  const std::string in = dir + "/ot_in.bin", out = dir + "/ot_out.bin", log = dir + "/ot_log.txt";
  writeRaw(in, input);
  std::remove((out + ".tri").c_str());
  WorkerResult w = spawnWorker({"bench-worker-ot", method, in, out, log}, params, out, log);
  mesh = TriangleMesh();
  if (w.ok) mesh = readMeshRaw(out);
  return w;
}

std::string cell(const char* format, double v) { return std::isfinite(v) ? fmt(format, v) : "-"; }

}  // namespace

int runTransportWorker(int argc, char** argv) {
  if (argc < 6) return 2;
  const std::string out_path = argv[4];
  const std::string dir = std::filesystem::path(argv[3]).parent_path().string();
  return runWorkerFrame(argc, argv, [&](const std::string& method, const Positions& input, const WorkerParameters& params,
                                        std::ostream& lf, double& seconds) {
    const auto t0 = std::chrono::steady_clock::now();
    auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
    TriangleMesh mesh;
    if (method == "poisson" || method == "poisson-decimated" || method == "gp3") {
      const auto cloud = withNormals(input, 20, params.get("viewpoint", 0) > 0);
      pcl::PolygonMesh pm;
      if (method == "poisson" || method == "poisson-decimated") {
        pcl::Poisson<pcl::PointNormal> poisson;
        poisson.setDepth(static_cast<int>(params.get("depth", 6)));
        poisson.setInputCloud(cloud);
        poisson.reconstruct(pm);
        if (method == "poisson-decimated") {
          // To as many vertices as ours: VTK's target reduction is a fraction of the
          // triangles, which on a closed mesh is near the fraction of the vertices.
          const double target = params.get("vertices", 0);
          const double poisson_vertices = static_cast<double>(pm.cloud.width * pm.cloud.height);
          if (!(target > 0) || poisson_vertices <= 0)
            throw InvalidParameter("vertices", std::to_string(target), "a positive vertex count (ours)");
          const double factor = std::clamp(1.0 - target / poisson_vertices, 0.0, 1.0);
          const double poisson_seconds = elapsed();
          pcl::MeshQuadricDecimationVTK decimation;
          decimation.setInputMesh(pcl::make_shared<pcl::PolygonMesh>(pm));
          decimation.setTargetReductionFactor(static_cast<float>(factor));
          pcl::PolygonMesh decimated;
          decimation.process(decimated);
          lf << "chosen " << fmt("from Poisson's %.0f vertices", poisson_vertices) << " and " << pm.polygons.size()
             << fmt(" facets, target reduction factor %.4f", factor) << fmt(" (Poisson %.2f s", poisson_seconds)
             << fmt(", decimation %.2f s)", elapsed() - poisson_seconds) << "\n";
          pm = std::move(decimated);
        }
      } else {
        pcl::GreedyProjectionTriangulation<pcl::PointNormal> gp3;
        gp3.setSearchRadius(params.get("radius", 0));
        gp3.setMu(params.get("mu", 2.5));
        gp3.setMaximumNearestNeighbors(static_cast<int>(params.get("neighbours", 100)));
        gp3.setMaximumSurfaceAngle(M_PI / 4);
        gp3.setMinimumAngle(M_PI / 18);
        gp3.setMaximumAngle(2 * M_PI / 3);
        gp3.setNormalConsistency(false);
        gp3.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointNormal>>());
        gp3.setInputCloud(cloud);
        gp3.reconstruct(pm);
      }
      seconds = elapsed();
      mesh = toTriangleMesh(pm);
      if (method == "poisson-decimated") {
        // Count only the vertices the facets use.
        std::vector<int> id(mesh.vertices.size(), -1);
        Positions used;
        for (auto& t : mesh.triangles)
          for (int c = 0; c < 3; ++c) {
            int& k = id[static_cast<std::size_t>(t[c])];
            if (k < 0) {
              k = static_cast<int>(used.size());
              used.push_back(mesh.vertices[static_cast<std::size_t>(t[c])]);
            }
            t[c] = k;
          }
        mesh.vertices = std::move(used);
      }
    } else if (method == "ot-recovery") {
      const TriangleMesh smooth = readMeshRaw(dir + "/ot_mesh.bin");
      TransportFeatureRecoveryParameters p;
      p.sweeps = static_cast<int>(params.get("sweeps", p.sweeps));
      TransportFeatureRecoveryReport r;
      const auto t1 = std::chrono::steady_clock::now();
      mesh = transportRecoverFeatures(smooth, input, p, &r);
      seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
      lf << "chosen cost " << r.initial_cost << " -> " << r.final_cost << ", mean move " << r.mean_move << "\n";
    } else if (method == "ot-reconstruction") {
      TransportReconstructionParameters p;
      p.target_vertices = static_cast<int>(params.get("vertices", p.target_vertices));
      p.density_threshold = static_cast<float>(params.get("density", p.density_threshold));
      p.seed = static_cast<std::uint64_t>(params.get("seed", 1));
      p.candidates = static_cast<int>(params.get("candidates", p.candidates));
      p.dangling_support = static_cast<float>(params.get("dangling", p.dangling_support));
      p.outlier_neighbours = static_cast<int>(params.get("outlier_neighbours", p.outlier_neighbours));
      p.max_points = static_cast<int>(params.get("max_points", p.max_points));
      p.merge_crease_angle = params.get("crease", p.merge_crease_angle);
      if (params.get("delaunay_start", 0) != 0) p.initial_complex = InitialComplex::Delaunay;
      p.stacked_threshold = static_cast<float>(params.get("stacked", p.stacked_threshold));
      p.transport.refuse_flips = params.get("allow_flips", 0) == 0;
      TransportReconstructionReport r;
      mesh = transportReconstruct(input, p, &r);
      seconds = elapsed();
      lf << "chosen " << r.collapses << " collapses, " << r.simulations << " simulations, " << r.refused_collapses
         << " refused (they turned a facet over), " << r.restored_facets << " empty facets kept (they close a hole)\n";
    } else {
      throw InvalidParameter("method", method, "poisson, poisson-decimated, gp3, ot-recovery or ot-reconstruction");
    }
    Positions tri(mesh.triangles.size());
    for (std::size_t i = 0; i < tri.size(); ++i) tri[i] = mesh.triangles[i].cast<float>();
    writeRaw(out_path + ".tri", tri);
    return mesh.vertices;
  });
}

int runBenchTransport(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 3, {"quick", "help", "only-outliers", "only-scan", "only-shapes"});
  if (a.has("help")) { std::fputs(kUsage, stdout); return 0; }
  a.allowOnly({"out", "quick", "samples", "candidates", "outlier-seeds", "only-outliers", "scan-points", "only-scan", "shape-points",
               "max-points", "only-shapes"});
  const int outlier_seeds = a.integer("outlier-seeds", 3);
  if (outlier_seeds < 1 || outlier_seeds > 100)
    throw InvalidParameter("outlier-seeds", std::to_string(outlier_seeds), "1 to 100");
  const bool only_outliers = a.has("only-outliers");
  if (only_outliers && a.has("quick")) throw InvalidParameter("only-outliers", "with --quick", "one or the other");
  const int candidates = a.integer("candidates", TransportReconstructionParameters().candidates);
  // The real scan's sample size; past the library's max_points, ours also runs unmerged.
  const int scan_points = a.integer("scan-points", 3000);
  if (scan_points < 1000 || scan_points > 1000000)
    throw InvalidParameter("scan-points", std::to_string(scan_points), "1000 to 1000000");
  const int shape_points = a.integer("shape-points", 3000);
  if (shape_points < 1000 || shape_points > 1000000)
    throw InvalidParameter("shape-points", std::to_string(shape_points), "1000 to 1000000");
  const int max_points = a.integer("max-points", TransportReconstructionParameters().max_points);
  if (max_points < 0 || max_points > 1000000000)
    throw InvalidParameter("max-points", std::to_string(max_points), "0 (never merge) to 1000000000");
  const bool only_scan = a.has("only-scan"), only_shapes = a.has("only-shapes");
  if (only_scan && (a.has("quick") || a.has("only-outliers")))
    throw InvalidParameter("only-scan", "with --quick or --only-outliers", "one of them");
  if (only_shapes && (a.has("quick") || a.has("only-outliers") || only_scan))
    throw InvalidParameter("only-shapes", "with --quick, --only-outliers or --only-scan", "one of them");
  if (candidates < 0) throw InvalidParameter("candidates", std::to_string(candidates), "0 (all half-edges) or more");
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  const bool quick = a.has("quick");
  const std::string out_dir = a.text("out", "bench_out");
  std::filesystem::create_directories(out_dir);
  std::ofstream csv(out_dir + "/transport.csv");
  csv << "part,noise,method,ok,vertices,facets,seconds,total_seconds,peak_mb,vertex_rms,mesh_gt_rms,mesh_gt_max,"
         "gt_mesh_rms,gt_mesh_max,area_ratio,nonmanifold_edges\n";
  auto csvRow = [&](const char* part, double noise, const std::string& method, const WorkerResult& w,
                    const TriangleMesh& m, double total, const MeshScore& s) {
    csv << part << "," << noise << ",\"" << method << "\"," << w.ok << "," << m.vertices.size() << ","
        << m.triangles.size() << "," << w.seconds << "," << total << "," << w.peak_mb << "," << s.vertex_rms << ","
        << s.to_gt_rms << "," << s.to_gt_max << "," << s.from_gt_rms << "," << s.from_gt_max << "," << s.area_ratio
        << "," << s.nonmanifold_edges << "\n";
  };

  // (a) Feature recovery.
  if (!only_outliers && !only_scan && !only_shapes) {
    const std::size_t n = quick ? 20000 : 60000;
    const int depth = quick ? 5 : 6;
    const TriangleMesh gt = synthetic::fandiskBlock(64);
    const Positions clean = synthetic::sampleMesh(gt, n, 7);
    const double diagonal = gt.boundingBoxDiagonal();
    const PointToMeshDistance gt_distance(gt);
    const Positions gt_samples = synthetic::sampleMesh(gt, 50000, 4);
    std::printf("bench transport (a): feature recovery on fandiskBlock(64) (%zu triangles), %zu points, PCL Poisson "
                "depth %d;\nerrors in 1e-3 of the bounding-box diagonal (%.3f m); mesh->gt: 50000 samples of the "
                "output, gt->mesh: 50000 samples of the true mesh\n",
                gt.triangles.size(), n, depth, diagonal);
    std::printf("%-6s %-34s %7s %7s %8s %8s %8s %8s %9s %9s %9s %9s\n", "noise", "method", "verts", "facets", "time(s)",
                "total(s)", "peak MB", "vert.rms", "m>gt.rms", "m>gt.max", "gt>m.rms", "gt>m.max");
    for (const double noise : quick ? std::vector<double>{0.0005} : std::vector<double>{0, 0.0005, 0.002}) {
      Positions points = clean;
      if (noise > 0) synthetic::addGaussianNoise(points, static_cast<float>(noise), 8);
      const std::string noise_s = fmt("%.2f%%", noise * 100);
      auto print = [&](const std::string& name, const WorkerResult& w, const TriangleMesh& m, double total) {
        if (!w.ok) {
          std::printf("%-6s %-34s failed: %s\n", noise_s.c_str(), name.c_str(), w.message.c_str());
          csvRow("recovery", noise, name, w, m, total, MeshScore());
          return;
        }
        const MeshScore s = score(m, gt_distance, gt_samples, diagonal, gt.area());
        std::printf("%-6s %-34s %7zu %7zu %8.2f %8.2f %8.0f %8s %9s %9s %9s %9s\n", noise_s.c_str(), name.c_str(),
                    m.vertices.size(), m.triangles.size(), w.seconds, total, w.peak_mb, cell("%.3f", s.vertex_rms).c_str(),
                    cell("%.3f", s.to_gt_rms).c_str(), cell("%.2f", s.to_gt_max).c_str(),
                    cell("%.3f", s.from_gt_rms).c_str(), cell("%.2f", s.from_gt_max).c_str());
        csvRow("recovery", noise, name, w, m, total, s);
      };
      TriangleMesh poisson;
      const WorkerResult wp = runMeshWorker(out_dir, "poisson", points, {{"depth", depth}}, poisson);
      print("PCL Poisson", wp, poisson, wp.seconds);
      if (!wp.ok || poisson.triangles.empty()) continue;
      writeMeshRaw(out_dir + "/ot_mesh.bin", poisson);
      std::vector<TriangleMesh> panels{gt, poisson};
      for (const int sweeps : {1, 5}) {
        TriangleMesh recovered;
        const WorkerResult wr = runMeshWorker(out_dir, "ot-recovery", points, {{"sweeps", sweeps}}, recovered);
        print("Poisson + OT recovery (" + std::to_string(sweeps) + (sweeps == 1 ? " sweep)" : " sweeps)"), wr, recovered,
              wp.seconds + wr.seconds);
        panels.push_back(wr.ok ? recovered : TriangleMesh());
      }
      const std::string png = out_dir + "/recovery_noise" + fmt("%.2f", noise * 100) + ".png";
      try {
        renderMeshPanels(panels, View::looking(gt.vertices, {1.f, 0.6f, 0.8f}), 400, png);
        std::printf("%-6s   picture: %s (true mesh | Poisson | + recovery, 1 sweep | 5 sweeps)\n", "", png.c_str());
      } catch (const Error& e) {
        std::fprintf(stderr, "warning: no picture: %s\n", e.what());
      }
    }
  }

  // (b) Reconstruction: the cube (planar faces, sharp edges), then the fandisk block (curved
  // faces and creases) and the real scan rs1 (not in --quick).
  struct Shape {
    std::string name, part;
    TriangleMesh gt;
    int vertices;
    bool viewpoint = false;  // normals for Poisson and GP3 towards the origin (a range scan)
    // (noise, outliers): a share of the points replaced by points uniform in the box enlarged
    // by 10% (the manuscript's Fig. 5.5 uses 20%).
    std::vector<std::pair<double, double>> cases;
    View view{};  // of the picture
  };
  std::vector<Shape> shapes;
  if (!only_scan) shapes = {{"cube(0.5, 4)", "reconstruction", synthetic::cube(0.5f, 4), 30, false,
                                quick ? std::vector<std::pair<double, double>>{{0, 0}}
                                      : only_outliers ? std::vector<std::pair<double, double>>{{0, 0.1}}
                                      : std::vector<std::pair<double, double>>{{0, 0}, {0.005, 0}, {0, 0.1}}}};
  if (!quick && !only_outliers && !only_scan) shapes.push_back({"fandiskBlock(32)", "reconstruction-fandisk", synthetic::fandiskBlock(32), 60, false, {{0, 0}}});
  // A real shape: the range-scan mesh of opencv-doc (an open, cluttered scene with borders,
  // which the transport keeps and Poisson closes).
  const std::string rs1 = a.text("samples", samplesDir()) + "/rs1_normals.ply";
  const bool all_shapes = !quick && !only_outliers && !only_shapes;
  if (all_shapes && std::filesystem::exists(rs1))
    shapes.push_back({"rs1_normals.ply (real range scan)", "reconstruction-rs1", loadTriangleMesh(rs1), 100, true, {{0, 0}}});
  else if (all_shapes)
    std::fprintf(stderr, "warning: %s missing (run scripts/fetch_samples.sh): the real-scan rows are skipped\n", rs1.c_str());
  // The synthetic shapes seen from above a corner; the scan from the scanner (at the origin,
  // image rows along -y).
  for (Shape& shape : shapes) {
    Eigen::Vector3f centroid = Eigen::Vector3f::Zero();
    for (const auto& v : shape.gt.vertices) centroid += v / static_cast<float>(shape.gt.vertices.size());
    shape.view = shape.viewpoint ? View::looking(shape.gt.vertices, -centroid, -Eigen::Vector3f::UnitY())
                                 : View::looking(shape.gt.vertices, {1.f, 0.6f, 0.8f});
  }
  for (const Shape& shape : shapes) {
    const bool scan = shape.part == "reconstruction-rs1";
    const std::size_t n = quick ? 800 : scan ? static_cast<std::size_t>(scan_points) : static_cast<std::size_t>(shape_points);
    const TriangleMesh& gt = shape.gt;
    const Positions clean = synthetic::sampleMesh(gt, n, 7);
    const double diagonal = gt.boundingBoxDiagonal();
    const PointToMeshDistance gt_distance(gt);
    const Positions gt_samples = synthetic::sampleMesh(gt, 50000, 4);
    const double gt_area = gt.area();
    std::printf("\nbench transport (b): reconstruction of %s, %zu points; ours with %d vertices and %d candidates a step, PCL Poisson "
                "depth 5, the same Poisson mesh\nquadric-decimated (VTK through PCL) to ours' vertex count (time: Poisson + decimation), PCL "
                "GreedyProjectionTriangulation (radius 3x the mean spacing, mu 2.5, 100 neighbours);\n"
                "errors in 1e-3 of the bounding-box diagonal (%.3f m)\n",
                shape.name.c_str(), n, shape.vertices, candidates, diagonal);
    std::printf("%-6s %-34s %7s %7s %9s %9s %9s %9s %7s %5s %8s %8s\n", "noise", "method", "verts", "facets", "m>gt.rms",
                "m>gt.max", "gt>m.rms", "gt>m.max", "area/gt", "e>2", "time(s)", "peak MB");
    for (const auto& [noise, outliers] : shape.cases) {
      Positions points = clean;
      if (noise > 0) synthetic::addGaussianNoise(points, static_cast<float>(noise), 8);
      if (outliers > 0) synthetic::addOutliers(points, static_cast<float>(outliers), 9);
      const std::string noise_s = outliers > 0 ? fmt("+%.0f%%o", outliers * 100) : fmt("%.2f%%", noise * 100);
      // GP3's radius: 3x the mean distance of a point to its nearest neighbour.
      const double spacing = meanNearestNeighbourDistance(points, SpatialIndex(points));
      struct Row {
        std::string name, method;
        std::map<std::string, double> params;
        int group = 0;  // ours: rows of one variant, averaged together
      };
      // Ours first, with seeds 1 to 3 (the initial subset and the candidates are random;
      // --quick: one): the decimated Poisson row takes seed 1's vertex count.
      std::vector<Row> rows;
      const int seeds = quick ? 1 : outliers > 0 ? outlier_seeds : 3;
      for (int seed = 1; seed <= seeds; ++seed)
        rows.push_back(outliers > 0 ? Row{fmt("ours (OT, 0.5, dangling 2), seed %.0f", seed), "ot-reconstruction",
                                          {{"vertices", shape.vertices}, {"density", 0.5}, {"dangling", 2}, {"seed", seed},
                                           {"candidates", candidates}, {"max_points", max_points}}}
                                    : Row{fmt("ours (OT reconstruction), seed %.0f", seed), "ot-reconstruction",
                                          {{"vertices", shape.vertices}, {"seed", seed}, {"candidates", candidates},
                                           {"max_points", max_points}}});
      // A variant of ours' first rows: the same seeds with one parameter changed.
      const auto addVariant = [&](const char* label, const char* key, double value, int group) {
        for (Row r : std::vector<Row>(rows.begin(), rows.begin() + seeds)) {
          r.name = std::string("ours (") + label + fmt("), seed %.0f", r.params["seed"]);
          r.params[key] = value;
          r.group = group;
          rows.push_back(r);
        }
      };
      // Merged: also without the crease splits (merge_crease_angle 0), what they change.
      const bool merged = max_points > 0 && n > static_cast<std::size_t>(max_points);
      if (merged) addVariant("no crease split", "crease", 0, 3);
      // Also from every facet of the subset's Delaunay triangulation (initial_complex), the
      // manuscript's start (ours starts from the advancing-front surface of the same subset).
      addVariant("Delaunay start", "delaunay_start", 1, 4);
      // Without the stacked-facet deletion (stacked_threshold 0), what it changes.
      addVariant("no stacked deletion", "stacked", 0, 5);
      // With the collapses that turn a facet over allowed (refuse_flips false), what refusing changes.
      addVariant("flips allowed", "allow_flips", 1, 6);
      // A scan sample larger than max_points: also unmerged (max_points 0), the cost the merge saves.
      if (scan && merged)
        for (int seed = 1; seed <= seeds; ++seed)
          rows.push_back(Row{fmt("ours (unmerged), seed %.0f", seed), "ot-reconstruction",
                             {{"vertices", shape.vertices}, {"seed", seed}, {"candidates", candidates}, {"max_points", 0}},
                             1});
      // With outliers, also with the outlier weights (outlier_neighbours 8).
      if (outliers > 0)
        for (int seed = 1; seed <= seeds; ++seed)
          rows.push_back(Row{fmt("ours (as above, weights 8), seed %.0f", seed), "ot-reconstruction",
                             {{"vertices", shape.vertices}, {"density", 0.5}, {"dangling", 2}, {"outlier_neighbours", 8},
                              {"seed", seed}, {"candidates", candidates}},
                             1});
      const double viewpoint = shape.viewpoint ? 1 : 0;
      rows.push_back({"PCL Poisson", "poisson", {{"depth", 5}, {"viewpoint", viewpoint}}});
      rows.push_back({"PCL Poisson + quadric decimation", "poisson-decimated", {{"depth", 5}, {"viewpoint", viewpoint}}});
      rows.push_back({"PCL GreedyProjectionTriangulation", "gp3",
                      {{"radius", 3 * spacing}, {"mu", 2.5}, {"neighbours", 100}, {"viewpoint", viewpoint}}});
      std::size_t ours_vertices = 0;
      // The picture: the true mesh, then ours (seed 1) and each peer, in the rows' order.
      std::vector<TriangleMesh> panels{gt};
      MeshScore ours_sum{0, 0, 0, 0, 0, 0, 0};
      double ours_seconds = 0;
      int ours_runs = 0, ours_group = 0;
      // The mean of the seeds of one variant of ours, printed after its rows.
      auto printMean = [&] {
        if (ours_runs > 1)
          std::printf("%-6s %-34s %7s %7s %9.3f %9.2f %9.3f %9.2f %7.3f %5.1f %8.2f\n", noise_s.c_str(), "ours, mean of the seeds",
                      "", "", ours_sum.to_gt_rms / ours_runs, ours_sum.to_gt_max / ours_runs, ours_sum.from_gt_rms / ours_runs,
                      ours_sum.from_gt_max / ours_runs, ours_sum.area_ratio / ours_runs, ours_sum.nonmanifold_edges / ours_runs,
                      ours_seconds / ours_runs);
        ours_sum = MeshScore{0, 0, 0, 0, 0, 0, 0};
        ours_seconds = 0;
        ours_runs = 0;
      };
      for (Row r : rows) {
        if ((r.method == "ot-reconstruction" && r.group != ours_group) || r.method == "poisson") {
          printMean();
          ours_group = r.group;
        }
        TriangleMesh m;
        WorkerResult w;
        if (r.method == "poisson-decimated" && ours_vertices == 0) {
          w.message = "no vertex count to decimate to (ours failed or gave no vertices)";
        } else {
          if (r.method == "poisson-decimated") r.params["vertices"] = static_cast<double>(ours_vertices);
          w = runMeshWorker(out_dir, r.method, points, r.params, m);
        }
        if (r.method == "ot-reconstruction" && w.ok && ours_vertices == 0) ours_vertices = m.vertices.size();
        if (r.method != "ot-reconstruction" || (r.params["seed"] == 1 && r.group == 0))
          panels.push_back(w.ok ? m : TriangleMesh());
        if (!w.ok) {
          std::printf("%-6s %-34s failed: %s\n", noise_s.c_str(), r.name.c_str(), w.message.c_str());
          csvRow(outliers > 0 ? "reconstruction-outliers" : shape.part.c_str(), noise, r.name, w, m, w.seconds, MeshScore());
          continue;
        }
        const MeshScore s = score(m, gt_distance, gt_samples, diagonal, gt_area);
        if (r.method == "ot-reconstruction") {
          ours_sum.area_ratio += s.area_ratio;
          ours_sum.nonmanifold_edges += s.nonmanifold_edges;
          ours_sum.to_gt_rms += s.to_gt_rms;
          ours_sum.to_gt_max += s.to_gt_max;
          ours_sum.from_gt_rms += s.from_gt_rms;
          ours_sum.from_gt_max += s.from_gt_max;
          ours_seconds += w.seconds;
          ++ours_runs;
        }
        std::printf("%-6s %-34s %7zu %7zu %9s %9s %9s %9s %7s %5s %8.2f %8.0f\n", noise_s.c_str(), r.name.c_str(),
                    m.vertices.size(), m.triangles.size(), cell("%.3f", s.to_gt_rms).c_str(),
                    cell("%.2f", s.to_gt_max).c_str(), cell("%.3f", s.from_gt_rms).c_str(),
                    cell("%.2f", s.from_gt_max).c_str(), cell("%.3f", s.area_ratio).c_str(),
                    cell("%.0f", s.nonmanifold_edges).c_str(), w.seconds, w.peak_mb);
        if (r.method == "poisson-decimated" && !w.chosen.empty()) std::printf("%-6s   %s\n", "", w.chosen.c_str());
        csvRow(outliers > 0 ? "reconstruction-outliers" : shape.part.c_str(), noise, r.name, w, m, w.seconds, s);
      }
      const std::string png = out_dir + "/" + shape.part + "_" + (outliers > 0 ? fmt("outliers%.0f", outliers * 100) : fmt("noise%.2f", noise * 100)) + ".png";
      try {
        renderMeshPanels(panels, shape.view, 320, png);
        std::printf("%-6s   picture: %s (true mesh | ours, seed 1 | Poisson | Poisson decimated | GP3)\n", "", png.c_str());
      } catch (const Error& e) {
        std::fprintf(stderr, "warning: no picture: %s\n", e.what());
      }
    }
  }
  for (const char* scratch : {"ot_in.bin", "ot_out.bin", "ot_out.bin.tri", "ot_log.txt", "ot_mesh.bin", "ot_mesh.bin.tri"})
    std::remove((out_dir + "/" + scratch).c_str());
  std::printf("\nwrote %s/transport.csv\n", out_dir.c_str());
  return 0;
}

}  // namespace paps::cli
