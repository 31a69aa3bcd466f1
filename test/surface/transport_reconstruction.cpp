// Tests of paps/surface/transport_reconstruction.h: a sampled cube is reconstructed with the
// vertex budget asked, close to the cube and covering it, closer than with the manuscript's
// coarser quadrature; outliers do not take the mesh with them; the same mesh with one or two
// threads, through the pcl stage, and with or without reused simulations; facets hanging
// from points that are not there go; bad input.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <omp.h>

#include <gtest/gtest.h>
#include <pcl/PolygonMesh.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/metrics.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>
#include <paps/core/synthetic.h>
#include <paps/surface/transport_reconstruction.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace surface_transport_reconstruction_test {

using paps::TriangleMesh;

paps::TransportReconstructionParameters smallRun() {
  paps::TransportReconstructionParameters p;
  p.target_vertices = 20;
  p.candidates = 10;
  return p;
}

struct Fit { double to_truth_rms, to_truth_p95, coverage_rms; };
Fit fit(const TriangleMesh& out, const TriangleMesh& truth) {
  const paps::PointToMeshDistance t(truth), o(out);
  const float diag = truth.boundingBoxDiagonal();
  const auto a = paps::pointToMeshError(paps::synthetic::sampleMesh(out, 5000, 1), t);
  const auto b = paps::pointToMeshError(paps::synthetic::sampleMesh(truth, 5000, 2), o);
  return {a.rmse / diag, a.p95 / diag, b.rmse / diag};
}

TEST(TransportReconstruction, ReconstructsACubeWithTheVerticesAskedCloserThanWithCoarseBins) {
  const TriangleMesh cube = paps::synthetic::cube(0.5f, 4);
  const paps::Positions points = paps::synthetic::sampleMesh(cube, 600, 3);
  paps::TransportReconstructionReport r;
  const TriangleMesh out = paps::transportReconstruct(points, smallRun(), &r);
  EXPECT_EQ(r.points, 600u);
  EXPECT_EQ(r.initial_vertices, 120);  // 20% of the points
  EXPECT_EQ(r.collapses, 100);
  EXPECT_LE(r.output_vertices, 20);
  EXPECT_GE(r.output_facets, 12);  // a closed cube needs at least 12 triangles
  EXPECT_LT(r.rms_transport, 0.1 * cube.boundingBoxDiagonal());
  const Fit f = fit(out, cube);
  std::printf("cube, 600 points, 20 vertices: rms %.4f p95 %.4f coverage %.4f of the diagonal\n", f.to_truth_rms,
              f.to_truth_p95, f.coverage_rms);
  // Measured 0.0075, 0.0157, 0.0127 (a 120-vertex Delaunay start, no noise; 0.0096, 0.0173,
  // 0.0145 with the manuscript's quadrature).
  EXPECT_LT(f.to_truth_rms, 0.011);
  EXPECT_LT(f.to_truth_p95, 0.025);
  EXPECT_LT(f.coverage_rms, 0.02);

  // Against the manuscript's quadrature (200 bins per area, up to 16 a facet) on the same
  // points and seed: coarse bins add a tangential cost that hides the cube's edges from the
  // collapse choice. Both with the collapses that turn a facet over allowed, as when this was
  // measured (session 66: with them refused, this seed's mesh RMS is 0.0097 with either
  // quadrature, coverage 0.0118 against 0.0126).
  auto fine = smallRun();
  fine.transport.refuse_flips = false;
  auto manuscript = fine;
  manuscript.transport = paps::TransportParameters();
  manuscript.transport.refuse_flips = false;
  ASSERT_EQ(manuscript.transport.bins_per_area, 200);
  ASSERT_EQ(fine.transport.bins_per_area, 800);
  const Fit sharp = fit(paps::transportReconstruct(points, fine), cube);
  const Fit coarse = fit(paps::transportReconstruct(points, manuscript), cube);
  std::printf("flips allowed: rms %.4f coverage %.4f; with the manuscript's quadrature: rms %.4f coverage %.4f\n",
              sharp.to_truth_rms, sharp.coverage_rms, coarse.to_truth_rms, coarse.coverage_rms);
  EXPECT_LT(sharp.to_truth_rms, 0.9 * coarse.to_truth_rms);
  EXPECT_LT(sharp.coverage_rms, 0.95 * coarse.coverage_rms);
}

// The advancing-front start: the same subset, only the facets of a surface over it. On a
// sample of the fandisk block the Delaunay start's output keeps layers of facets (edges with
// 3 or more); this one is nearly a manifold, and closer to the block. The same mesh twice in
// one process: CGAL's surface depended on its random generator (seeded for the call) and on
// heap addresses where priorities tied (broken by point indices).
TEST(TransportReconstruction, AdvancingFrontStartGivesANearManifoldMesh) {
  const TriangleMesh block = paps::synthetic::fandiskBlock(32);
  const paps::Positions points = paps::synthetic::sampleMesh(block, 1000, 7);
  auto p = smallRun();
  p.target_vertices = 40;
  EXPECT_EQ(p.initial_complex, paps::InitialComplex::AdvancingFront);  // the default
  p.stacked_threshold = 0;  // the starts themselves (the stacked-facet deletion takes most layers of either)
  paps::TransportReconstructionReport rd, ra;
  p.initial_complex = paps::InitialComplex::Delaunay;
  const TriangleMesh delaunay = paps::transportReconstruct(points, p, &rd);
  p.initial_complex = paps::InitialComplex::AdvancingFront;
  const TriangleMesh front = paps::transportReconstruct(points, p, &ra);
  EXPECT_FALSE(ra.advancing_front_fallback);
  EXPECT_EQ(ra.initial_vertices, rd.initial_vertices);
  EXPECT_LT(ra.initial_facets, rd.initial_facets / 3);  // a surface has about 2 facets a vertex
  const Fit fd = fit(delaunay, block), fa = fit(front, block);
  std::printf("fandisk block, 1000 points, 40 vertices: Delaunay start %zu facets, %d non-manifold edges, rms %.4f "
              "coverage %.4f; advancing front %zu facets, %d non-manifold edges, rms %.4f coverage %.4f\n",
              delaunay.triangles.size(), delaunay.nonManifoldEdgeCount(), fd.to_truth_rms, fd.coverage_rms,
              front.triangles.size(), front.nonManifoldEdgeCount(), fa.to_truth_rms, fa.coverage_rms);
  // Measured: Delaunay start 76 facets, 24 non-manifold edges, RMS 0.0085 of the diagonal
  // from the block, coverage 0.0081; advancing front 68, 1, 0.0051, 0.0068 (70, 1, 0.0059,
  // 0.0073 in some runs before CGAL's ties were broken by point indices).
  EXPECT_LE(front.nonManifoldEdgeCount(), 2);
  EXPECT_GT(delaunay.nonManifoldEdgeCount(), 10);
  EXPECT_LT(fa.to_truth_rms, fd.to_truth_rms);
  EXPECT_LT(fa.coverage_rms, 1.5 * fd.coverage_rms);
  const TriangleMesh again = paps::transportReconstruct(points, p);
  EXPECT_EQ(again.vertices, front.vertices);
  EXPECT_EQ(again.triangles, front.triangles);
}

TEST(TransportReconstruction, OutliersStayOffTheMesh) {
  const TriangleMesh cube = paps::synthetic::cube(0.5f, 4);
  paps::Positions points = paps::synthetic::sampleMesh(cube, 600, 3);
  paps::synthetic::addOutliers(points, 0.05f, 4);
  auto p = smallRun();
  p.density_threshold = 0.3f;
  const TriangleMesh out = paps::transportReconstruct(points, p);
  const Fit f = fit(out, cube);
  EXPECT_LT(f.to_truth_rms, 0.06);
  EXPECT_LT(f.coverage_rms, 0.06);
  // Weighted (outlier_neighbours): the report counts the light points as outlierWeights
  // weighs them, and the masses reach the plan (another mesh). At 600 points the surface's
  // own spacing is about the outliers' distance to it, so few are light here (5, none
  // below 0.1); the bench's 3,000 points separate them (OutlierWeights above).
  p.outlier_neighbours = 8;
  paps::TransportReconstructionReport r;
  const TriangleMesh weighted = paps::transportReconstruct(points, p, &r);
  const std::vector<double> w = paps::outlierWeights(points, 8);
  EXPECT_EQ(r.light_points, static_cast<std::size_t>(std::count_if(w.begin(), w.end(), [](double x) { return x < 1; })));
  EXPECT_EQ(r.outlier_points, static_cast<std::size_t>(std::count_if(w.begin(), w.end(), [](double x) { return x < 0.1; })));
  EXPECT_GT(r.light_points, 0u);
  EXPECT_NE(weighted.vertices, out.vertices);
  const Fit fw = fit(weighted, cube);
  std::printf("600 points + 5%% outliers, weighted (%zu light points): rms %.4f -> %.4f, coverage %.4f -> %.4f\n",
              r.light_points, f.to_truth_rms, fw.to_truth_rms, f.coverage_rms, fw.coverage_rms);
  EXPECT_LT(fw.to_truth_rms, 0.06);
  EXPECT_LT(fw.coverage_rms, 0.06);
}

// Outlier weights: 1 on a surface sampled at random, small for points far from it; NaN
// points weigh 0.
TEST(OutlierWeights, OneOnTheSurfaceAndSmallFarFromIt) {
  const TriangleMesh cube = paps::synthetic::cube(0.5f, 4);
  paps::Positions points = paps::synthetic::sampleMesh(cube, 3000, 7);
  const std::vector<int> outliers = paps::synthetic::addOutliers(points, 0.1f, 9);
  points.push_back(Eigen::Vector3f::Constant(NAN));
  const std::vector<double> w = paps::outlierWeights(points, 8);
  ASSERT_EQ(w.size(), points.size());
  EXPECT_EQ(w.back(), 0.0);
  std::vector<char> is_outlier(points.size(), 0);
  for (const int i : outliers) is_outlier[i] = 1;
  const paps::PointToMeshDistance to_cube(cube);
  std::size_t surface = 0, surface_full = 0, far = 0, far_light = 0;
  for (std::size_t i = 0; i + 1 < points.size(); ++i) {
    EXPECT_GT(w[i], 0.0);
    EXPECT_LE(w[i], 1.0);
    if (!is_outlier[i]) {
      ++surface;
      surface_full += w[i] == 1.0;
    } else if (to_cube.distance(points[i]) > 0.1) {  // 0.1 m from a 0.5 m cube
      ++far;
      far_light += w[i] < 0.2;
    }
  }
  std::printf("surface points of weight 1: %zu of %zu; outliers over 0.1 m off below 0.2: %zu of %zu\n", surface_full,
              surface, far_light, far);
  EXPECT_GT(surface_full, surface * 97 / 100);
  EXPECT_GT(far, 50u);
  EXPECT_GT(far_light, far * 9 / 10);
  EXPECT_THROW(paps::outlierWeights(points, 0), paps::InvalidParameter);
  // Copies: 20 positions stored 10 times each, and one point far off. The median reach is
  // taken over the points not piled on K others, so the far point alone is light.
  paps::Positions piles;
  for (int c = 0; c < 10; ++c)
    for (int i = 0; i < 20; ++i) piles.emplace_back(0.01f * i, 0.f, 0.f);
  piles.emplace_back(5.f, 5.f, 5.f);
  const std::vector<double> pw = paps::outlierWeights(piles, 12);
  for (std::size_t i = 0; i + 1 < piles.size(); ++i) ASSERT_EQ(pw[i], 1.0) << i;
  EXPECT_LT(pw.back(), 1e-6);
  EXPECT_GT(pw.back(), 0.0);
  const std::vector<double> one_pile = paps::outlierWeights(paps::Positions(30, Eigen::Vector3f::Ones()), 8);
  for (const double x : one_pile) EXPECT_EQ(x, 1.0);
  EXPECT_THROW(paps::outlierWeights(paps::Positions(1, Eigen::Vector3f::Zero()), 8), paps::InvalidInput);
}

TEST(TransportReconstruction, SameMeshWithOneOrTwoThreadsAndThroughThePclStage) {
  const TriangleMesh cube = paps::synthetic::cube(0.5f, 4);
  const paps::Positions points = paps::synthetic::sampleMesh(cube, 400, 5);
  auto p = smallRun();
  p.target_vertices = 30;
  p.initial_fraction = 0.1f;  // fewer collapses: the property does not depend on it
  for (const auto start : {paps::InitialComplex::Delaunay, paps::InitialComplex::AdvancingFront}) {
    auto q = p;
    q.initial_complex = start;
    omp_set_num_threads(1);
    const TriangleMesh one = paps::transportReconstruct(points, q);
    omp_set_num_threads(2);
    const TriangleMesh two = paps::transportReconstruct(points, q);
    ASSERT_EQ(one.vertices.size(), two.vertices.size());
    ASSERT_EQ(one.triangles, two.triangles);
    for (std::size_t v = 0; v < one.vertices.size(); ++v) ASSERT_EQ(one.vertices[v], two.vertices[v]);
  }
  const TriangleMesh one = paps::transportReconstruct(points, p);  // the default start

  auto cloud = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const auto& q : points) cloud->push_back(pcl::PointXYZ(q.x(), q.y(), q.z()));
  if (!std::getenv("NONAN")) cloud->push_back(pcl::PointXYZ(NAN, NAN, NAN));  // skipped
  cloud->header.frame_id = "scan_frame";
  cloud->header.stamp = 777;
  paps::TransportReconstruction<pcl::PointXYZ> stage;
  stage.setParameters(p);
  stage.setInputCloud(cloud);
  pcl::PolygonMesh mesh;
  stage.reconstruct(mesh);
  // The input's header, as pcl::SurfaceReconstruction gives it (it was overwritten).
  EXPECT_EQ(mesh.header.frame_id, "scan_frame");
  EXPECT_EQ(mesh.header.stamp, 777u);
  EXPECT_EQ(mesh.cloud.header.frame_id, "scan_frame");
  const TriangleMesh back = paps::toTriangleMesh(mesh);
  ASSERT_EQ(back.vertices.size(), one.vertices.size());
  for (std::size_t v = 0; v < one.vertices.size(); ++v) ASSERT_EQ(back.vertices[v], one.vertices[v]);
  EXPECT_EQ(stage.getReport().output_facets, static_cast<int>(one.triangles.size()));

  // With outlier weights (setOutlierNeighbours), still the function's mesh and report.
  p.outlier_neighbours = 4;
  paps::TransportReconstructionReport r;
  const TriangleMesh weighted = paps::transportReconstruct(points, p, &r);
  stage.setOutlierNeighbours(4);
  EXPECT_EQ(stage.getParameters().outlier_neighbours, 4);
  EXPECT_THROW(stage.setOutlierNeighbours(-1), paps::InvalidParameter);
  stage.reconstruct(mesh);
  const TriangleMesh weighted_back = paps::toTriangleMesh(mesh);
  ASSERT_EQ(weighted_back.vertices.size(), weighted.vertices.size());
  for (std::size_t v = 0; v < weighted.vertices.size(); ++v) ASSERT_EQ(weighted_back.vertices[v], weighted.vertices[v]);
  EXPECT_EQ(stage.getReport().light_points, r.light_points);
  EXPECT_EQ(stage.getReport().outlier_points, r.outlier_points);
}

// Copies of every point (overlapping scans) are the same measure at twice the mass (a power
// of two: every mass and cost scales exactly): the mesh of the distinct points. It once came
// out with 4 or 6 vertices for the 10 asked, or with no facet at all, when the initial subset
// drew the same position several times.
TEST(TransportReconstruction, CopiesOfThePointsGiveTheMeshOfTheDistinctPoints) {
  const TriangleMesh truth = paps::synthetic::cube(0.5f, 4);
  const paps::Positions points = paps::synthetic::sampleMesh(truth, 300, 4);
  paps::Positions copies;
  for (int c = 0; c < 2; ++c) copies.insert(copies.end(), points.begin(), points.end());
  auto p = smallRun();
  p.target_vertices = 10;
  p.seed = 3;
  paps::TransportReconstructionReport r1, r2;
  const TriangleMesh one = paps::transportReconstruct(points, p, &r1);
  const TriangleMesh two = paps::transportReconstruct(copies, p, &r2);
  EXPECT_EQ(r2.points, 600u);
  ASSERT_EQ(two.vertices.size(), one.vertices.size());
  ASSERT_EQ(two.triangles.size(), one.triangles.size());
  for (std::size_t v = 0; v < one.vertices.size(); ++v) EXPECT_EQ(two.vertices[v], one.vertices[v]) << v;
  for (std::size_t f = 0; f < one.triangles.size(); ++f) EXPECT_EQ(two.triangles[f], one.triangles[f]) << f;
  EXPECT_NEAR(r2.rms_transport, r1.rms_transport, 1e-9);
}

// The exactness tests: a 400-point cube to 30 vertices, with the manuscript's quadrature
// (faster, the same property).
paps::TransportReconstructionParameters exactnessRun(int candidates) {
  auto p = smallRun();
  p.candidates = candidates;
  p.initial_fraction = 0.1f;
  p.target_vertices = 30;
  p.transport = paps::TransportParameters();
  return p;
}

void expectSameMesh(const TriangleMesh& a, const TriangleMesh& b) {
  ASSERT_EQ(a.vertices.size(), b.vertices.size());
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (std::size_t v = 0; v < a.vertices.size(); ++v) ASSERT_EQ(a.vertices[v], b.vertices[v]);
  for (std::size_t f = 0; f < a.triangles.size(); ++f) ASSERT_EQ(a.triangles[f], b.triangles[f]);
}

TEST(TransportReconstruction, ReusedSimulationsGiveTheSameMesh) {
  // A simulation is reused only while nothing in its stencil changed: the mesh must be the one
  // every draw re-simulated gives, bit for bit, with fewer programs solved.
  const paps::Positions points = paps::synthetic::sampleMesh(paps::synthetic::cube(0.5f, 4), 400, 8);
  auto p = exactnessRun(40);  // more draws of the same half-edges: more reuse to check
  paps::TransportReconstructionReport with, without;
  const TriangleMesh a = paps::transportReconstruct(points, p, &with);
  p.reuse_simulations = false;
  const TriangleMesh b = paps::transportReconstruct(points, p, &without);
  EXPECT_GT(with.reused_simulations, 0);
  EXPECT_EQ(without.reused_simulations, 0);
  // The same draws (the same collapses chosen): each simulated, reused or skipped by its
  // bound; a reused simulation can settle a step's bound sooner, so never more programs.
  EXPECT_EQ(with.simulations + with.reused_simulations + with.bounded_simulations,
            without.simulations + without.bounded_simulations);
  EXPECT_LT(with.simulations, without.simulations);
  EXPECT_EQ(with.final_cost, without.final_cost);
  expectSameMesh(a, b);
}

// The two bounds' tests compare one run at the defaults (made once a process, as both need it) with a
// run that has one of the bounds switched off.
struct BoundRun {
  TriangleMesh mesh;
  paps::TransportReconstructionReport report;
};

BoundRun boundRun(bool paps::TransportReconstructionParameters::*off) {
  const paps::Positions points = paps::synthetic::sampleMesh(paps::synthetic::cube(0.5f, 4), 400, 9);
  auto p = exactnessRun(20);
  if (off) p.*off = false;
  BoundRun r;
  r.mesh = paps::transportReconstruct(points, p, &r.report);
  return r;
}

const BoundRun& defaultBoundRun() {
  static const BoundRun r = boundRun(nullptr);
  return r;
}

TEST(TransportReconstruction, BoundedSimulationsGiveTheSameMeshWithFewerPrograms) {
  // The collapses skipped by their lower bound could not have been chosen: the mesh is the
  // one simulating every draw gives, bit for bit.
  const BoundRun& with = defaultBoundRun();
  const BoundRun every = boundRun(&paps::TransportReconstructionParameters::bound_simulations);
  const auto& bounded = with.report;
  EXPECT_EQ(every.report.bounded_simulations, 0);
  EXPECT_GT(bounded.bounded_simulations, 0);
  EXPECT_LT(bounded.simulations, every.report.simulations);
  // The same draws (the same collapses chosen): each simulated, reused or skipped.
  EXPECT_EQ(bounded.simulations + bounded.reused_simulations + bounded.bounded_simulations,
            every.report.simulations + every.report.reused_simulations);
  EXPECT_EQ(bounded.collapses, every.report.collapses);
  EXPECT_EQ(bounded.final_cost, every.report.final_cost);
  expectSameMesh(with.mesh, every.mesh);
}

TEST(TransportReconstruction, DualBoundGivesTheSameMeshWithFewerPrograms) {
  // A collapse left out by its dual bound could not have been chosen either: the same mesh,
  // bit for bit, as with the nearest-bin bound alone.
  const BoundRun& with = defaultBoundRun();
  const BoundRun nearest = boundRun(&paps::TransportReconstructionParameters::dual_bound);
  const auto& dual = with.report;
  EXPECT_LT(dual.simulations, nearest.report.simulations);
  EXPECT_EQ(dual.simulations + dual.reused_simulations + dual.bounded_simulations,
            nearest.report.simulations + nearest.report.reused_simulations + nearest.report.bounded_simulations);
  EXPECT_EQ(dual.collapses, nearest.report.collapses);
  EXPECT_EQ(dual.final_cost, nearest.report.final_cost);
  expectSameMesh(with.mesh, nearest.mesh);
}

TEST(TransportReconstruction, DualBoundGivesTheSameMeshAtTheReconstructionsQuadrature) {
  // The fine quadrature (up to 64 bins a facet) makes the uniform measure bind, where the
  // dual bound's steps grow large: the first version of the bound let rounding lift it above
  // the program, and this run's mesh changed (checked). The 400-point runs above did not show it.
  const paps::Positions points = paps::synthetic::sampleMesh(paps::synthetic::cube(0.5f, 4), 1000, 7);
  paps::TransportReconstructionParameters p;  // the reconstruction's own quadrature
  p.target_vertices = 100;
  p.seed = 2;
  paps::TransportReconstructionReport dual, nearest;
  const TriangleMesh a = paps::transportReconstruct(points, p, &dual);
  p.dual_bound = false;
  const TriangleMesh b = paps::transportReconstruct(points, p, &nearest);
  EXPECT_LT(dual.simulations, nearest.simulations);
  EXPECT_EQ(dual.final_cost, nearest.final_cost);
  expectSameMesh(a, b);
}

TEST(TransportReconstruction, SameMeshForShuffledPoints) {
  const paps::Positions points = paps::synthetic::sampleMesh(paps::synthetic::cube(0.5f, 4), 400, 6);
  paps::Positions shuffled = points;
  paps::Random rng(2);
  for (std::size_t k = shuffled.size(); k > 1; --k) std::swap(shuffled[k - 1], shuffled[rng.below(k)]);
  auto p = smallRun();
  p.initial_fraction = 0.1f;
  p.transport = paps::TransportParameters();  // the manuscript's quadrature: faster, same property
  const TriangleMesh a = paps::transportReconstruct(points, p);
  const TriangleMesh b = paps::transportReconstruct(shuffled, p);
  ASSERT_EQ(a.vertices.size(), b.vertices.size());
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (std::size_t v = 0; v < a.vertices.size(); ++v) ASSERT_EQ(a.vertices[v], b.vertices[v]);
  for (std::size_t f = 0; f < a.triangles.size(); ++f) ASSERT_EQ(a.triangles[f], b.triangles[f]);
}

TEST(TransportReconstruction, ProgressIsReportedAndCancels) {
  const paps::Positions points = paps::synthetic::sampleMesh(paps::synthetic::cube(0.5f, 4), 400, 7);
  std::vector<std::string> stages;
  auto p = smallRun();
  p.initial_fraction = 0.1f;
  p.transport = paps::TransportParameters();  // faster; progress does not depend on it
  paps::transportReconstruct(points, p, nullptr, [&](const std::string& stage, float) {
    if (stages.empty() || stages.back() != stage) stages.push_back(stage);
    return true;
  });
  // Every stage that takes time reports (--timings accounts for the whole run).
  const std::vector<std::string> expected{"transport Delaunay", "transport relaxation", "transport decimation",
                                          "transport relocation", "transport facet deletion",
                                          "transport stacked facets"};
  EXPECT_EQ(stages, expected);
  // A cancel in any stage stops the run.
  for (const std::string& stop : expected)
    EXPECT_THROW(paps::transportReconstruct(points, p, nullptr,
                                            [&](const std::string& stage, float) { return stage != stop; }),
                 paps::Cancelled)
        << stop;
  // Merging (more points than max_points) is a stage of its own, first, and cancels too.
  p.max_points = 300;
  stages.clear();
  paps::transportReconstruct(points, p, nullptr, [&](const std::string& stage, float) {
    if (stages.empty() || stages.back() != stage) stages.push_back(stage);
    return true;
  });
  ASSERT_FALSE(stages.empty());
  EXPECT_EQ(stages.front(), "transport merge");
  EXPECT_EQ(std::vector<std::string>(stages.begin() + 1, stages.end()), expected);
  EXPECT_THROW(paps::transportReconstruct(points, p, nullptr,
                                          [&](const std::string& stage, float) { return stage != "transport merge"; }),
               paps::Cancelled);
}

// Points on a grid of [0, 1]^2 (spacing 0.05), and the square as two facets.
paps::Positions squarePoints() {
  paps::Positions p;
  for (int j = 0; j <= 20; ++j)
    for (int i = 0; i <= 20; ++i) p.emplace_back(0.05f * i, 0.05f * j, 0.f);
  return p;
}
TriangleMesh square() {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}
// The square and a fin on its edge y = 0, the fin's free corner (vertex 4) 0.4 above it.
TriangleMesh squareWithFin() {
  TriangleMesh m = square();
  m.vertices.emplace_back(0.5f, 0.f, 0.4f);
  m.triangles.emplace_back(0, 1, 4);
  return m;
}
int dropDangling(TriangleMesh& m, const paps::Positions& points) {
  return paps::dropDanglingFacets(m, paps::SpatialIndex(points), 0.1f);
}

TEST(DanglingFacets, AFacetHangingFromNoPointsGoesAndTheSurfaceStays) {
  const paps::Positions points = squarePoints();
  TriangleMesh m = squareWithFin();
  EXPECT_EQ(dropDangling(m, points), 1);
  EXPECT_EQ(m.triangles.size(), 2u);
  ASSERT_EQ(m.vertices.size(), 4u);  // the fin's corner is gone, the rest renumbered
  EXPECT_EQ(m.triangles, square().triangles);
  // The square's own free corners, (1, 0) and (0, 1), have points around them: kept.
  TriangleMesh s = square();
  EXPECT_EQ(dropDangling(s, points), 0);
  EXPECT_EQ(s.triangles.size(), 2u);
}

TEST(DanglingFacets, OnePointIsNotSupportTwoAre) {
  const TriangleMesh fin = squareWithFin();
  paps::Positions points = squarePoints();
  points.emplace_back(0.5f, 0.f, 0.45f);  // one outlier by the corner
  TriangleMesh m = fin;
  EXPECT_EQ(dropDangling(m, points), 1);
  points.emplace_back(0.55f, 0.f, 0.4f);  // and a second
  m = fin;
  EXPECT_EQ(dropDangling(m, points), 0);
  EXPECT_EQ(m.triangles.size(), 3u);
}

TEST(DanglingFacets, AChainGoesFacetByFacet) {
  // A second fin hanging from the first one's corner: that corner is not free until the
  // second goes.
  TriangleMesh m = squareWithFin();
  m.vertices.emplace_back(0.5f, 0.f, 0.8f);
  m.vertices.emplace_back(0.6f, 0.f, 0.8f);
  m.triangles.emplace_back(4, 5, 6);
  EXPECT_EQ(dropDangling(m, squarePoints()), 2);
  EXPECT_EQ(m.triangles, square().triangles);
}

TEST(DanglingFacets, RejectsBadInput) {
  TriangleMesh m = square();
  const paps::SpatialIndex points(squarePoints());
  EXPECT_THROW(paps::dropDanglingFacets(m, points, 0.f), paps::InvalidParameter);
  EXPECT_THROW(paps::dropDanglingFacets(m, points, NAN), paps::InvalidParameter);
  m.triangles.emplace_back(0, 1, 7);
  EXPECT_THROW(paps::dropDanglingFacets(m, points, 0.1f), paps::InvalidInput);
  EXPECT_EQ(m.triangles.size(), 3u);  // untouched
}

// Merging large inputs (max_points): the merged points keep the mass and its centroid, and
// for any bin b, sum m |p - b|^2 over the input = sum M |c - b|^2 over the cells + spread, so
// a plan's cost on the merged points plus the spread is the cost of a plan on the input.
std::vector<Eigen::Vector3d> spherePoints(int n, std::uint64_t seed, std::vector<double>* masses) {
  paps::Random rng(seed);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p = rng.gaussian3();
    points.push_back(3.0 * p.normalized() + Eigen::Vector3d(100, -20, 5));
    masses->push_back(0.5 + 1.5 * rng.uniform());
  }
  return points;
}

TEST(MergeIntoCells, KeepsTheMassAndItsCentroidAndTheSpreadIsTheCostDifference) {
  std::vector<double> masses;
  const std::vector<Eigen::Vector3d> points = spherePoints(3000, 11, &masses);
  const paps::MergedPoints m = paps::mergeIntoCells(points, masses, 400);
  ASSERT_LE(m.points.size(), 400u);
  EXPECT_GT(m.points.size(), 200u);  // the finest grid that fits, not any grid
  ASSERT_EQ(m.masses.size(), m.points.size());
  EXPECT_GT(m.cell, 0);
  EXPECT_GT(m.spread, 0);
  double mass = 0, merged_mass = 0;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero(), merged_centre = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < points.size(); ++i) { mass += masses[i]; centre += masses[i] * points[i]; }
  for (std::size_t i = 0; i < m.points.size(); ++i) {
    EXPECT_GT(m.masses[i], 0);
    merged_mass += m.masses[i];
    merged_centre += m.masses[i] * m.points[i];
  }
  EXPECT_NEAR(merged_mass, mass, 1e-9 * mass);
  EXPECT_LT((merged_centre / merged_mass - centre / mass).norm(), 1e-9);
  paps::Random rng(5);
  for (int t = 0; t < 6; ++t) {
    const Eigen::Vector3d b = Eigen::Vector3d(100, -20, 5) + 2 * rng.gaussian3();
    double direct = 0, merged = m.spread;
    for (std::size_t i = 0; i < points.size(); ++i) direct += masses[i] * (points[i] - b).squaredNorm();
    for (std::size_t i = 0; i < m.points.size(); ++i) merged += m.masses[i] * (m.points[i] - b).squaredNorm();
    EXPECT_NEAR(merged, direct, 1e-9 * direct) << t;
  }
  // A centroid lies within its cell: at most a cell's diagonal from some input point.
  for (const auto& c : m.points) {
    double nearest = INFINITY;
    for (const auto& p : points) nearest = std::min(nearest, (p - c).norm());
    EXPECT_LE(nearest, std::sqrt(3.0) * m.cell);
  }
}

TEST(MergeIntoCells, TheSameCellsForShuffledPointsAndNothingMergedWhenTheyFit) {
  std::vector<double> masses;
  const std::vector<Eigen::Vector3d> points = spherePoints(2000, 12, &masses);
  std::vector<int> order(points.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  paps::Random rng(3);
  for (std::size_t k = order.size(); k > 1; --k) std::swap(order[k - 1], order[rng.below(k)]);
  std::vector<Eigen::Vector3d> shuffled;
  std::vector<double> shuffled_masses;
  for (int i : order) { shuffled.push_back(points[i]); shuffled_masses.push_back(masses[i]); }
  const paps::MergedPoints a = paps::mergeIntoCells(points, masses, 250);
  const paps::MergedPoints b = paps::mergeIntoCells(shuffled, shuffled_masses, 250);
  ASSERT_EQ(a.points.size(), b.points.size());
  EXPECT_EQ(a.cell, b.cell);
  for (std::size_t i = 0; i < a.points.size(); ++i) {
    EXPECT_LT((a.points[i] - b.points[i]).norm(), 1e-9) << i;
    EXPECT_NEAR(a.masses[i], b.masses[i], 1e-9) << i;
  }
  for (const std::size_t fits : {std::size_t(0), points.size(), points.size() + 1}) {
    const paps::MergedPoints same = paps::mergeIntoCells(points, masses, fits);
    EXPECT_EQ(same.points, points);
    EXPECT_EQ(same.masses, masses);
    EXPECT_EQ(same.cell, 0);
    EXPECT_EQ(same.spread, 0);
  }
  // Fewer cells than the 8 of a grid at the box's side: still at most that many.
  for (const std::size_t few : {1, 2, 5}) EXPECT_LE(paps::mergeIntoCells(points, masses, few).points.size(), few);
  EXPECT_THROW(paps::mergeIntoCells(points, std::vector<double>(3, 1.0), 10), paps::InvalidInput);
  auto bad = points;
  bad[7].y() = NAN;
  EXPECT_THROW(paps::mergeIntoCells(bad, masses, 10), paps::InvalidInput);
}

// A cell across a crease merges at a centroid off the surface (inside a convex edge); split
// at the crease (the points' normals in two groups 90 degrees apart), each side's centroid
// lies on its own face. On a smooth sphere nothing is split at 30 degrees.
double depthInCube(const Eigen::Vector3d& p, double half) {
  const Eigen::Vector3d a = p.cwiseAbs();
  const Eigen::Vector3d out = (a.array() - half).max(0).matrix();
  return out.squaredNorm() > 0 ? out.norm() : half - a.maxCoeff();
}

TEST(MergeIntoCells, SplitsCellsAtCreasesSoTheirCentroidsLieOnTheFaces) {
  paps::Normals normals;
  const paps::Positions sample = paps::synthetic::sampleMesh(paps::synthetic::cube(1.f, 2), 20000, 9, &normals);
  std::vector<Eigen::Vector3d> points;
  for (const auto& p : sample) points.push_back(p.cast<double>());
  std::vector<double> masses(points.size(), 1.0);
  const paps::MergedPoints plain = paps::mergeIntoCells(points, masses, 1500);
  const paps::MergedPoints split = paps::mergeIntoCells(points, masses, 1500, &normals, 30);
  EXPECT_EQ(plain.crease_points, 0u);
  EXPECT_GT(split.crease_points, 100u);  // 12 edges of about 1 / cell cells, and 8 corners
  ASSERT_LE(split.points.size(), 1500u);
  EXPECT_GT(split.points.size(), 1000u);
  // Cells with fewer than 3 points on a side stay whole (kMinCreaseSide): some remain off.
  double plain_depth = 0, split_depth = 0;
  int plain_off = 0, split_off = 0;
  for (const auto& c : plain.points) {
    plain_depth = std::max(plain_depth, depthInCube(c, 0.5));
    plain_off += depthInCube(c, 0.5) > 1e-6;
  }
  for (const auto& c : split.points) {
    split_depth = std::max(split_depth, depthInCube(c, 0.5));
    split_off += depthInCube(c, 0.5) > 1e-6;
  }
  std::printf("cube, 20,000 points into at most 1,500: deepest centroid %.4f plain, %.4f split; off the faces %d "
              "plain, %d split (%zu more points, cell %.4f)\n",
              plain_depth, split_depth, plain_off, split_off, split.crease_points, split.cell);
  EXPECT_GT(plain_depth, 0.1 * plain.cell);
  EXPECT_LT(split_depth, 0.4 * plain_depth);
  EXPECT_LT(split_off, plain_off / 2);
  // Still a merge: the mass, and the cost identity with the spread.
  double mass = 0, direct = 0, merged = split.spread;
  const Eigen::Vector3d b(0.2, -0.7, 0.4);
  for (std::size_t i = 0; i < split.points.size(); ++i) {
    mass += split.masses[i];
    merged += split.masses[i] * (split.points[i] - b).squaredNorm();
  }
  for (const auto& p : points) direct += (p - b).squaredNorm();
  EXPECT_NEAR(mass, 20000.0, 1e-6);
  EXPECT_NEAR(merged, direct, 1e-9 * direct);
  EXPECT_GT(split.spread, 0);

  std::vector<double> sphere_masses;
  const std::vector<Eigen::Vector3d> sphere = spherePoints(3000, 13, &sphere_masses);
  paps::Normals radial;
  for (const auto& p : sphere) radial.push_back((p - Eigen::Vector3d(100, -20, 5)).normalized().cast<float>());
  const paps::MergedPoints smooth = paps::mergeIntoCells(sphere, sphere_masses, 400, &radial, 30);
  const paps::MergedPoints cells = paps::mergeIntoCells(sphere, sphere_masses, 400);
  EXPECT_EQ(smooth.crease_points, 0u);
  ASSERT_EQ(smooth.points.size(), cells.points.size());
  for (std::size_t i = 0; i < cells.points.size(); ++i) EXPECT_LT((smooth.points[i] - cells.points[i]).norm(), 1e-9);

  // A flat square with noise (0.3x the spacing) and PCA normals, as the reconstruction makes
  // them: the noise splits few cells (39 of about 1,500 when written).
  paps::Positions flat;
  paps::Random noise(21);
  for (int i = 0; i < 20000; ++i) {
    const double x = noise.uniform();
    const double y = noise.uniform();
    const double z = 0.002 * noise.gaussian();
    flat.emplace_back(x, y, z);
  }
  const paps::SpatialIndex flat_index(flat);
  const paps::Normals flat_normals =
      paps::estimateNormals(flat, paps::NeighbourGraph::byCount(flat, flat_index, paps::kMergeNormalNeighbours));
  std::vector<Eigen::Vector3d> flat_points;
  for (const auto& p : flat) flat_points.push_back(p.cast<double>());
  const paps::MergedPoints noisy = paps::mergeIntoCells(flat_points, masses, 1500, &flat_normals, 30);
  std::printf("noisy square: %zu of %zu points from crease splits\n", noisy.crease_points, noisy.points.size());
  EXPECT_LT(noisy.crease_points, noisy.points.size() / 20);

  // Never more than asked, even when one cell's crease splits are too many (a corner).
  for (const std::size_t few : {1, 2, 3, 5, 9})
    EXPECT_LE(paps::mergeIntoCells(points, masses, few, &normals, 30).points.size(), few) << few;
  EXPECT_THROW(paps::mergeIntoCells(points, masses, 1500, &radial, 30), paps::InvalidInput);  // sizes differ
  for (const double bad : {-1.0, 91.0, double(NAN)})
    EXPECT_THROW(paps::mergeIntoCells(points, masses, 1500, &normals, bad), paps::InvalidParameter);
}

// The merge keeps 10 points a vertex by default: asked for many vertices, it merges into more
// cells than max_points (rs1 at 2 points a vertex was left in shreds).
TEST(TransportReconstruction, MergeKeepsTenPointsAVertex) {
  paps::TransportReconstructionParameters d;
  EXPECT_EQ(d.mergeTarget(), 20000u);  // 50 vertices: max_points
  d.target_vertices = 3000;
  EXPECT_EQ(d.mergeTarget(), 30000u);
  d.merge_points_per_vertex = 0;
  EXPECT_EQ(d.mergeTarget(), 20000u);
  d.merge_points_per_vertex = 1000;
  d.target_vertices = 100000000;  // no overflow: 1e11 cells asked
  EXPECT_EQ(d.mergeTarget(), 100000000000u);
  d.max_points = 0;
  EXPECT_EQ(d.mergeTarget(), 0u);  // never merge
  d = paps::TransportReconstructionParameters();
  d.merge_points_per_vertex = 1001;
  EXPECT_THROW(d.validate(), paps::InvalidParameter);
  d.merge_points_per_vertex = -1;
  EXPECT_THROW(d.validate(), paps::InvalidParameter);

  const TriangleMesh cube = paps::synthetic::cube(0.5f, 4);
  const paps::Positions points = paps::synthetic::sampleMesh(cube, 6000, 3);
  auto p = smallRun();
  p.transport = paps::TransportParameters();  // faster; the merge does not depend on it
  p.max_points = 300;
  p.target_vertices = 40;  // 400 cells at most
  paps::TransportReconstructionReport r;
  paps::transportReconstruct(points, p, &r);
  EXPECT_EQ(r.merge_target, 400u);
  EXPECT_GT(r.transported_points, 300u);
  EXPECT_LE(r.transported_points, 400u);  // crease splits count towards it
  EXPECT_GT(r.merge_cell, 0);
  p.merge_points_per_vertex = 0;  // max_points alone
  paps::TransportReconstructionReport q;
  paps::transportReconstruct(points, p, &q);
  EXPECT_EQ(q.merge_target, 300u);
  EXPECT_LE(q.transported_points, 300u);
  EXPECT_GT(q.merge_cell, r.merge_cell);
}

// 6,000 points of the cube merged into at most 600 reconstruct it as closely as 600 points
// drawn from it do (the bounds of the first test); with max_points above the input, the mesh
// is the unmerged one, bit for bit.
TEST(TransportReconstruction, MergedLargeInputFitsTheCubeAsASampleOfThatSizeDoes) {
  const TriangleMesh cube = paps::synthetic::cube(0.5f, 4);
  const paps::Positions points = paps::synthetic::sampleMesh(cube, 6000, 3);
  auto p = smallRun();
  p.max_points = 600;
  paps::TransportReconstructionReport r;
  const TriangleMesh out = paps::transportReconstruct(points, p, &r);
  EXPECT_EQ(r.points, 6000u);
  EXPECT_LE(r.transported_points, 600u);
  EXPECT_GT(r.transported_points, 300u);
  EXPECT_GT(r.merge_cell, 0);
  EXPECT_GT(r.merge_spread, 0);
  EXPECT_GE(r.final_cost, r.merge_spread);
  EXPECT_LE(r.output_vertices, 20);
  const Fit f = fit(out, cube);
  std::printf("cube, 6,000 points merged into %zu, 20 vertices: rms %.4f p95 %.4f coverage %.4f of the diagonal\n",
              r.transported_points, f.to_truth_rms, f.to_truth_p95, f.coverage_rms);
  EXPECT_LT(f.to_truth_rms, 0.011);
  EXPECT_LT(f.to_truth_p95, 0.025);
  EXPECT_LT(f.coverage_rms, 0.02);

  const paps::Positions few = paps::synthetic::sampleMesh(cube, 300, 4);
  auto q = exactnessRun(10);  // the manuscript's quadrature: faster, the same property
  q.target_vertices = 10;
  q.max_points = 0;
  const TriangleMesh plain = paps::transportReconstruct(few, q);
  q.max_points = 300;
  paps::TransportReconstructionReport rq;
  const TriangleMesh unmerged = paps::transportReconstruct(few, q, &rq);
  EXPECT_EQ(rq.merge_cell, 0);
  EXPECT_EQ(rq.transported_points, 300u);
  ASSERT_EQ(unmerged.vertices.size(), plain.vertices.size());
  ASSERT_EQ(unmerged.triangles.size(), plain.triangles.size());
  for (std::size_t v = 0; v < plain.vertices.size(); ++v) EXPECT_EQ(unmerged.vertices[v], plain.vertices[v]) << v;
  for (std::size_t t = 0; t < plain.triangles.size(); ++t) EXPECT_EQ(unmerged.triangles[t], plain.triangles[t]) << t;
}

// Points exactly on a plane (a floor or wall scanned with quantised depth, a synthetic
// square) have a flat Delaunay triangulation: its triangles are the initial complex, and the
// mesh lies in the plane. Merged too.
TEST(TransportReconstruction, FlatInputGivesAFlatMeshOverIt) {
  paps::Positions flat;
  paps::Random rng(4);
  for (int i = 0; i < 600; ++i) {
    const double x = rng.uniform();
    flat.emplace_back(static_cast<float>(x), static_cast<float>(rng.uniform()), 0.f);
  }
  TriangleMesh square;
  square.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  square.triangles = {{0, 1, 2}, {0, 2, 3}};
  for (const int max_points : {0, 300}) {
    auto p = smallRun();
    p.max_points = max_points;
    paps::TransportReconstructionReport r;
    const TriangleMesh out = paps::transportReconstruct(flat, p, &r);
    EXPECT_EQ(r.merge_cell > 0, max_points > 0);
    // The filters at the end may take a few vertices with the facets they drop.
    EXPECT_LE(static_cast<int>(out.vertices.size()), p.target_vertices);
    EXPECT_GE(static_cast<int>(out.vertices.size()), p.target_vertices - 4);
    ASSERT_FALSE(out.triangles.empty());
    for (const auto& v : out.vertices) EXPECT_EQ(v.z(), 0.f);
    const Fit f = fit(out, square);
    // Measured (unmerged / merged): 18 / 20 vertices, 20 / 23 facets, RMS 0.0006 / 0.0000 of
    // the diagonal off the square (vertices a little past its border), coverage 0.0045 /
    // 0.0058 (a missing corner triangle of a tenth of the side would add about 0.01).
    EXPECT_LT(f.to_truth_rms, 0.005) << max_points;
    EXPECT_LT(f.coverage_rms, 0.012) << max_points;
  }
}

// A noisy wall: the default start (the advancing front) gives one sheet over the square; the
// manuscript's Delaunay start keeps layers of facets stacked within the noise (each near the
// points, so its distances look fine), the reason the default changed (session 64).
TEST(TransportReconstruction, NoisyPlaneGivesOneSheetNotStackedLayers) {
  paps::Positions wall;
  paps::Random rng(6);
  for (int i = 0; i < 1000; ++i) {
    const double x = rng.uniform(), y = rng.uniform();
    wall.emplace_back(static_cast<float>(x), static_cast<float>(y), static_cast<float>(0.01 * rng.gaussian()));
  }
  auto p = smallRun();
  p.target_vertices = 30;
  const TriangleMesh sheet = paps::transportReconstruct(wall, p);
  p.initial_complex = paps::InitialComplex::Delaunay;
  paps::TransportReconstructionReport r;
  const TriangleMesh delaunay = paps::transportReconstruct(wall, p, &r);
  p.stacked_threshold = 0;
  const TriangleMesh layers = paps::transportReconstruct(wall, p);
  std::printf("noisy unit square, 1000 points, noise 1%%, 30 vertices: advancing front %zu facets, area %.3f, %d "
              "non-manifold edges; Delaunay start %zu, %.3f, %d (%d stacked facets deleted); without that deletion "
              "%zu, %.3f, %d\n",
              sheet.triangles.size(), sheet.area(), sheet.nonManifoldEdgeCount(), delaunay.triangles.size(),
              delaunay.area(), delaunay.nonManifoldEdgeCount(), r.stacked_facets, layers.triangles.size(), layers.area(),
              layers.nonManifoldEdgeCount());
  // Measured: advancing front 30 facets, area 0.865, 0 non-manifold edges; Delaunay start 37,
  // 0.968, 3; without the stacked-facet deletion 69, 1.825, 29 (layers of facets within the
  // noise). Before the collapses that turn a facet over were refused (session 66): 25, 0.960,
  // 0; 35, 1.122, 4; 79, 3.161, 41.
  EXPECT_GT(sheet.area(), 0.85);
  EXPECT_LT(sheet.area(), 1.1);
  EXPECT_LE(sheet.nonManifoldEdgeCount(), 1);
  EXPECT_GT(delaunay.area(), 0.85);
  EXPECT_LT(delaunay.area(), 1.3);
  EXPECT_LE(delaunay.nonManifoldEdgeCount(), 8);
  EXPECT_GT(r.stacked_facets, 10);
  EXPECT_GT(layers.area(), 1.5 * delaunay.area());
  EXPECT_GT(layers.nonManifoldEdgeCount(), 20);
}

// Edges of one facet (borders), and edges of two facets folded onto each other: the second
// facet's free corner lies on the first facet's side of the edge (the sheet doubles back).
struct EdgeCounts { int edges = 0, border = 0, folded = 0; };
EdgeCounts edgeCounts(const TriangleMesh& m) {
  std::map<std::pair<int, int>, std::vector<int>> opposite;  // edge -> free corner of each facet
  for (const auto& t : m.triangles)
    for (int e = 0; e < 3; ++e)
      opposite[std::minmax(t[e], t[(e + 1) % 3])].push_back(t[(e + 2) % 3]);
  EdgeCounts c;
  for (const auto& [e, corners] : opposite) {
    ++c.edges;
    if (corners.size() == 1) ++c.border;
    if (corners.size() != 2) continue;
    const Eigen::Vector3f a = m.vertices[e.first], b = m.vertices[e.second];
    const Eigen::Vector3f side = (b - a).cross(m.vertices[corners[0]] - a).cross(b - a);
    if (side.dot(m.vertices[corners[0]] - a) * side.dot(m.vertices[corners[1]] - a) > 0) ++c.folded;
  }
  return c;
}

// A clean unit sphere with about 10 points a vertex (the most asked of the method): collapses
// that turn a facet over fold the sheet back, and the points near a corner go to the vertex,
// leaving small facets empty, which the density filter drops (holes). Refusing those collapses
// (refuse_flips) and keeping the empty facets that close a hole give a mesh with fewer folds
// and borders; a closed sphere should have none.
TEST(TransportReconstruction, ManyVerticesOnASphereGiveFewBordersAndFolds) {
  paps::Positions sphere;
  paps::Random rng(3);
  for (int i = 0; i < 2000; ++i) sphere.push_back(rng.gaussian3().normalized().cast<float>());
  paps::TransportReconstructionParameters p;
  p.target_vertices = 200;
  p.initial_fraction = 0.4f;
  paps::TransportReconstructionReport refused, allowed;
  const EdgeCounts on = edgeCounts(paps::transportReconstruct(sphere, p, &refused));
  p.transport.refuse_flips = false;
  const EdgeCounts off = edgeCounts(paps::transportReconstruct(sphere, p, &allowed));
  std::printf("unit sphere, 2000 points, 800 to 200 vertices: flips refused: %d edges, %d borders, %d folded "
              "(%d collapses refused, %d empty facets kept); allowed: %d, %d, %d (%d kept)\n",
              on.edges, on.border, on.folded, refused.refused_collapses, refused.restored_facets, off.edges, off.border,
              off.folded, allowed.restored_facets);
  EXPECT_GT(refused.refused_collapses, 0);
  EXPECT_EQ(allowed.refused_collapses, 0);
  EXPECT_GT(refused.restored_facets, 0);
  EXPECT_LT(on.border, off.border);
  EXPECT_LE(on.folded, off.folded);
}

TEST(TransportReconstruction, RefusesPointsFillingAVolumeUnlessAllowed) {
  // 300 points uniform in a cube: no surface. Refused (allow_volume false), with the measure
  // and the way out in the message; allowed, a mesh still comes out.
  paps::Positions volume;
  paps::Random rng(8);
  for (int i = 0; i < 300; ++i) {
    const double x = rng.uniform();
    const double y = rng.uniform();
    volume.emplace_back(static_cast<float>(x), static_cast<float>(y), static_cast<float>(rng.uniform()));
  }
  try {
    paps::transportReconstruct(volume, smallRun());
    ADD_FAILURE() << "a volume was reconstructed";
  } catch (const paps::InvalidInput& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("fill a volume"), std::string::npos) << what;
    EXPECT_NE(what.find("--allow-volume"), std::string::npos) << what;
  }
  auto allowed = smallRun();
  allowed.allow_volume = true;
  allowed.target_vertices = 45;  // few collapses from the 60 of the subset: a volume is slow
  paps::TransportReconstructionReport r;
  const TriangleMesh out = paps::transportReconstruct(volume, allowed, &r);
  EXPECT_FALSE(out.triangles.empty());
  EXPECT_GT(r.volume_variation, paps::kVolumeVariation);
  // The same points squeezed into a slab 1/50 as thick are a (noisy) surface.
  for (auto& p : volume) p.z() *= 0.02f;
  allowed.allow_volume = false;
  const TriangleMesh slab = paps::transportReconstruct(volume, allowed, &r);
  EXPECT_FALSE(slab.triangles.empty());
  EXPECT_LT(r.volume_variation, 0.05);
}

TEST(TransportReconstruction, RejectsBadInput) {
  using paps::Positions;
  EXPECT_THROW(paps::transportReconstruct({}, smallRun()), paps::InvalidInput);
  EXPECT_THROW(paps::transportReconstruct(Positions(3, Eigen::Vector3f(1, 2, 3)), smallRun()), paps::InvalidInput);
  EXPECT_THROW(paps::transportReconstruct(Positions(50, Eigen::Vector3f::Constant(NAN)), smallRun()),
               paps::InvalidInput);
  Positions line;
  for (int i = 0; i < 200; ++i) line.emplace_back(i * 0.1f, i * 0.05f, 1.f);
  EXPECT_THROW(paps::transportReconstruct(line, smallRun()), paps::InvalidInput);  // collinear start
  {  // collinear after a merge: the error says so, and what to raise (a tiny cluster beside
     // a long line merges into one cell)
    Positions merging = line;
    for (int i = 0; i < 100; ++i) merging.emplace_back(5 + i % 5 * 1e-4f, 2.5f + i / 5 % 5 * 1e-4f, 1 + i / 25 * 1e-4f);
    auto merged = smallRun();
    merged.max_points = 100;
    merged.merge_points_per_vertex = 0;  // 100 cells, not 10 a vertex (200)
    try {
      paps::transportReconstruct(merging, merged);
      ADD_FAILURE() << "a line was reconstructed";
    } catch (const paps::InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("merged into"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("max_points"), std::string::npos) << e.what();
    }
  }
  const Positions few = paps::synthetic::sampleMesh(paps::synthetic::cube(0.5f, 2), 100, 1);
  EXPECT_THROW(paps::transportReconstruct(few, smallRun()), paps::InvalidParameter);  // 20 start vertices, not above 20
  // The message says what to change: the fraction while the points allow it, else the vertices.
  const auto message = [&](const paps::TransportReconstructionParameters& q) {
    try {
      paps::transportReconstruct(few, q);
    } catch (const paps::InvalidParameter& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(smallRun()).find("raise initial_fraction (--initial-fraction; now 0.2) to at least 0.21)"), std::string::npos)
      << message(smallRun());
  auto many = smallRun();
  many.target_vertices = 100;
  EXPECT_NE(message(many).find("the input has 100 distinct points: ask for fewer vertices"), std::string::npos)
      << message(many);
  auto p = smallRun();
  p.initial_fraction = 0;
  EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  p = smallRun();
  p.target_vertices = 2;
  EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  p = smallRun();
  p.density_threshold = -1;
  EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  for (const float bad : {-1.f, 1001.f, NAN}) {
    p = smallRun();
    p.dangling_support = bad;
    EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  }
  for (const float bad : {-1.f, 2e6f, NAN}) {
    p = smallRun();
    p.stacked_threshold = bad;
    EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  }
  for (const float bad : {0.f, -1.f, 1001.f, NAN}) {
    p = smallRun();
    p.stacked_reach = bad;
    EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  }
  for (const int bad : {-1, 1001}) {
    p = smallRun();
    p.outlier_neighbours = bad;
    EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  }
  for (const int bad : {-1, 1000000001}) {
    p = smallRun();
    p.max_points = bad;
    EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  }
  for (const double bad : {-1.0, 90.5, double(NAN)}) {
    p = smallRun();
    p.merge_crease_angle = bad;
    EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidParameter);
  }
  p = smallRun();
  p.max_points = 3;  // too few points left to triangulate
  p.merge_points_per_vertex = 0;
  EXPECT_THROW(paps::transportReconstruct(few, p), paps::InvalidInput);
  paps::TransportReconstruction<pcl::PointXYZ> stage;  // no input cloud
  pcl::PolygonMesh mesh;
  EXPECT_THROW(stage.reconstruct(mesh), paps::InvalidInput);
}

}  // namespace surface_transport_reconstruction_test
