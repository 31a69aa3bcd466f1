// Tests of paps/surface/transport_feature_recovery.h: a cube whose corners and edges were
// rounded off (as a smooth reconstruction does) gets them back from the cube's points; the
// pcl stage gives the same mesh; thread count and bad input.
#include <cmath>
#include <memory>

#include <omp.h>

#include <gtest/gtest.h>
#include <pcl/PolygonMesh.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/metrics.h>
#include <paps/core/random.h>
#include <paps/core/synthetic.h>
#include <paps/surface/transport_feature_recovery.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace surface_transport_feature_recovery_test {

using paps::TriangleMesh;

// The cube's mesh blended towards a sphere: corners pulled in, faces bulged.
TriangleMesh roundedCube() {
  TriangleMesh m = paps::synthetic::cube(0.5f, 8);
  for (auto& v : m.vertices) v = 0.6f * v + 0.4f * 0.3f * v.normalized();
  return m;
}

TEST(TransportFeatureRecovery, RecoversTheCornersOfACube) {
  const TriangleMesh truth = paps::synthetic::cube(0.5f, 8);
  const paps::Positions points = paps::synthetic::sampleMesh(truth, 20000, 3);
  const TriangleMesh rounded = roundedCube();
  paps::TransportFeatureRecoveryReport report;
  paps::TransportFeatureRecoveryParameters p;
  p.sweeps = 5;  // clean points
  const TriangleMesh out = paps::transportRecoverFeatures(rounded, points, p, &report);
  ASSERT_EQ(out.vertices.size(), rounded.vertices.size());
  ASSERT_EQ(out.triangles.size(), rounded.triangles.size());
  const paps::PointToMeshDistance cube(truth);
  const paps::ErrorStats before = paps::pointToMeshError(rounded.vertices, cube);
  const paps::ErrorStats after = paps::pointToMeshError(out.vertices, cube);
  EXPECT_LT(after.rmse, 0.25 * before.rmse) << before.rmse << " -> " << after.rmse;
  EXPECT_LT(after.max, 0.5 * before.max) << before.max << " -> " << after.max;
  EXPECT_LT(report.final_cost, report.relaxed_cost);
  EXPECT_LE(report.relaxed_cost, report.initial_cost);
  EXPECT_GT(report.max_move, 0.0);
  ASSERT_EQ(report.sweep_moves.size(), 5u);
  EXPECT_LT(report.sweep_moves[4], report.sweep_moves[0]);  // converging
}

TEST(TransportFeatureRecovery, SameMeshWithOneOrTwoThreadsAndThroughThePclStage) {
  const TriangleMesh truth = paps::synthetic::cube(0.5f, 4);
  const paps::Positions points = paps::synthetic::sampleMesh(truth, 3000, 5);
  TriangleMesh rounded = truth;
  for (auto& v : rounded.vertices) v = 0.7f * v + 0.3f * 0.3f * v.normalized();
  paps::TransportFeatureRecoveryParameters p;
  p.sweeps = 3;
  omp_set_num_threads(1);
  const TriangleMesh one = paps::transportRecoverFeatures(rounded, points, p);
  omp_set_num_threads(2);
  const TriangleMesh two = paps::transportRecoverFeatures(rounded, points, p);
  ASSERT_EQ(one.vertices.size(), two.vertices.size());
  for (std::size_t v = 0; v < one.vertices.size(); ++v) ASSERT_EQ(one.vertices[v], two.vertices[v]) << v;

  auto cloud = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const auto& q : points) cloud->push_back(pcl::PointXYZ(q.x(), q.y(), q.z()));
  auto mesh = std::make_shared<pcl::PolygonMesh>(paps::toPolygonMesh(rounded));
  mesh->header.frame_id = mesh->cloud.header.frame_id = "mesh_frame";
  mesh->header.stamp = 778;
  paps::TransportFeatureRecovery<pcl::PointXYZ> stage;
  stage.setParameters(p);
  stage.setInputMesh(mesh);
  stage.setInputCloud(cloud);
  pcl::PolygonMesh result;
  stage.process(result);
  // The input mesh's header, as pcl::MeshProcessing::process gives it (it was overwritten).
  EXPECT_EQ(result.header.frame_id, "mesh_frame");
  EXPECT_EQ(result.header.stamp, 778u);
  EXPECT_EQ(result.cloud.header.frame_id, "mesh_frame");
  const TriangleMesh back = paps::toTriangleMesh(result);
  ASSERT_EQ(back.vertices.size(), one.vertices.size());
  for (std::size_t v = 0; v < one.vertices.size(); ++v) ASSERT_EQ(back.vertices[v], one.vertices[v]) << v;
  EXPECT_EQ(stage.getReport().vertices, static_cast<int>(one.vertices.size()));
}

TEST(TransportFeatureRecovery, SameMeshForShuffledPoints) {
  const TriangleMesh truth = paps::synthetic::cube(0.5f, 4);
  const paps::Positions points = paps::synthetic::sampleMesh(truth, 3000, 8);
  paps::Positions shuffled = points;
  paps::Random rng(3);
  for (std::size_t k = shuffled.size(); k > 1; --k) std::swap(shuffled[k - 1], shuffled[rng.below(k)]);
  TriangleMesh rounded = truth;
  for (auto& v : rounded.vertices) v = 0.7f * v + 0.3f * 0.3f * v.normalized();
  const TriangleMesh a = paps::transportRecoverFeatures(rounded, points, {});
  const TriangleMesh b = paps::transportRecoverFeatures(rounded, shuffled, {});
  for (std::size_t v = 0; v < a.vertices.size(); ++v) ASSERT_EQ(a.vertices[v], b.vertices[v]) << v;
}

TEST(TransportFeatureRecovery, DensityFilterOpensWhatNoPointSupports) {
  // Points on the cube minus its top face: a closed mesh loses the top facets.
  const TriangleMesh truth = paps::synthetic::cube(0.5f, 4);
  paps::Positions points;
  for (const auto& q : paps::synthetic::sampleMesh(truth, 6000, 9))
    if (q.z() < 0.24f) points.push_back(q);
  paps::TransportFeatureRecoveryParameters p;
  p.sweeps = 2;
  p.density_threshold = 0.2f;
  const TriangleMesh out = paps::transportRecoverFeatures(truth, points, p);
  int top = 0;
  for (const auto& t : out.triangles)
    top += out.vertices[t[0]].z() > 0.24f && out.vertices[t[1]].z() > 0.24f && out.vertices[t[2]].z() > 0.24f;
  EXPECT_EQ(top, 0);
  EXPECT_GT(out.triangles.size(), truth.triangles.size() * 3 / 4);  // the rest stays
}

TEST(TransportFeatureRecovery, RejectsBadInput) {
  const TriangleMesh truth = paps::synthetic::cube(0.5f, 2);
  const paps::Positions points = paps::synthetic::sampleMesh(truth, 200, 1);
  EXPECT_THROW(paps::transportRecoverFeatures(TriangleMesh{}, points, {}), paps::InvalidInput);
  EXPECT_THROW(paps::transportRecoverFeatures(truth, {}, {}), paps::InvalidInput);
  EXPECT_THROW(paps::transportRecoverFeatures(truth, paps::Positions(5, Eigen::Vector3f::Constant(NAN)), {}),
               paps::InvalidInput);
  TriangleMesh broken = truth;
  broken.triangles[0][1] = 999;
  EXPECT_THROW(paps::transportRecoverFeatures(broken, points, {}), paps::InvalidInput);
  paps::TransportFeatureRecoveryParameters p;
  p.sweeps = 0;
  EXPECT_THROW(paps::transportRecoverFeatures(truth, points, p), paps::InvalidParameter);
  p = {};
  p.density_threshold = 1.5f;
  EXPECT_THROW(paps::transportRecoverFeatures(truth, points, p), paps::InvalidParameter);
  paps::TransportFeatureRecovery<pcl::PointXYZ> stage;
  pcl::PolygonMesh out;
  EXPECT_THROW(stage.process(out), paps::InvalidInput);  // no mesh, no cloud
}

}  // namespace surface_transport_feature_recovery_test
