// APSS and RIMLS upsampling: points projected on a sphere land on it; output count; bad input.
#include <gtest/gtest.h>

#include <cmath>

#include <pcl/point_types.h>

#include <paps/core/random.h>
#include <paps/surface/mls_upsampling.h>

using namespace paps;

namespace {
Positions spherePoints(std::size_t n, float r, std::uint64_t seed) {
  Random rng(seed);
  Positions p;
  while (p.size() < n) {
    Eigen::Vector3f v(rng.gaussian(), rng.gaussian(), rng.gaussian());
    if (v.norm() > 1e-3f) p.push_back(r * v.normalized());
  }
  return p;
}
double maxRadiusError(const Positions& p, float r) {
  double e = 0;
  for (const auto& x : p) e = std::max(e, static_cast<double>(std::abs(x.norm() - r)));
  return e;
}
}  // namespace

TEST(MlsUpsampling, ApssLandsOnSphere) {
  const Positions in = spherePoints(3000, 1.f, 1);
  MlsUpsamplingParameters p;
  p.factor = 4;
  MlsUpsamplingReport r;
  const Positions out = upsampleMls(in, MlsSurface::Apss, p, &r);
  EXPECT_EQ(out.size(), 12000u);
  EXPECT_EQ(r.unprojected, 0u);
  EXPECT_LT(maxRadiusError(out, 1.f), 2e-3);  // exact with exact normals; PCA normals bias it slightly
}

TEST(MlsUpsampling, RimlsLandsNearSphere) {
  const Positions in = spherePoints(3000, 1.f, 2);
  MlsUpsamplingParameters p;
  p.output_count = 7777;
  const Positions out = upsampleMls(in, MlsSurface::Rimls, p);
  EXPECT_EQ(out.size(), 7777u);
  EXPECT_LT(maxRadiusError(out, 1.f), 1e-2);
}

TEST(MlsUpsampling, PclStageAndBadInput) {
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  writePositions(spherePoints(2000, 0.5f, 3), *cloud);
  APSSUpsampling<pcl::PointXYZ> apss;
  apss.setInputCloud(cloud);
  apss.setUpsamplingFactor(2);
  pcl::PointCloud<pcl::PointXYZ> out;
  apss.process(out);
  EXPECT_EQ(out.size(), 4000u);
  EXPECT_TRUE(out.is_dense);
  EXPECT_THROW(apss.setUpsamplingFactor(0), InvalidParameter);
  EXPECT_THROW(apss.setRadius(NAN), InvalidParameter);
  EXPECT_THROW(upsampleMls({}, MlsSurface::Rimls, {}), InvalidInput);
  EXPECT_THROW(upsampleMls(Positions(10, Eigen::Vector3f::Constant(NAN)), MlsSurface::Apss, {}), InvalidInput);
}
