// Wavejets on analytic surfaces with known answers (manuscript 2.4).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>

#include <gtest/gtest.h>
#include <omp.h>
#include <pcl/common/io.h>
#include <pcl/features/normal_3d.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/core/kd_tree_search.h>
#include <paps/features/wavejet_estimation.h>

#include "../common/peak_allocation.h"

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace features_wavejet_estimation_test {

using paps::Positions;
using HeightFn = std::function<double(double, double)>;
constexpr double kPi = 3.14159265358979323846;

// Irregular samples of z = f(x, y) over the disk of radius `extent`; point 0 is the apex.
Positions heightFieldSamples(const HeightFn& f, int count, double extent, std::uint64_t seed) {
  paps::Random rng(seed);
  Positions p;
  p.emplace_back(0.f, 0.f, static_cast<float>(f(0, 0)));
  while (static_cast<int>(p.size()) < count) {
    const double x = rng.uniform(-extent, extent), y = rng.uniform(-extent, extent);
    if (x * x + y * y > extent * extent) continue;
    p.emplace_back(static_cast<float>(x), static_cast<float>(y), static_cast<float>(f(x, y)));
  }
  return p;
}

std::vector<int> iota(std::size_t n) {
  std::vector<int> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<int>(i);
  return v;
}

paps::WavejetResult fitAtApex(const Positions& p, const paps::WavejetParameters& params, float radius,
                              const Eigen::Vector3f& initial = Eigen::Vector3f::Constant(NAN),
                              paps::WavejetCoefficients* c = nullptr) {
  std::vector<int> nb;
  for (std::size_t i = 0; i < p.size(); ++i)
    if ((p[i] - p[0]).head<2>().norm() <= radius) nb.push_back(static_cast<int>(i));
  auto ws = paps::makeWavejetWorkspace();
  return paps::fitWavejet(p, nb.data(), static_cast<int>(nb.size()), p[0], radius, params, *ws, initial,
                          Eigen::Vector3f::UnitZ(), c);
}

Eigen::Vector3f tilted(double degrees, double azimuth) {
  const double g = degrees * kPi / 180;
  return Eigen::Vector3f(static_cast<float>(std::sin(g) * std::cos(azimuth)),
                         static_cast<float>(std::sin(g) * std::sin(azimuth)), static_cast<float>(std::cos(g)));
}

double angleDeg(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return std::acos(std::min(1.0, std::abs(static_cast<double>(a.normalized().dot(b.normalized()))))) * 180 / kPi;
}

TEST(Wavejet, ParaboloidAndSaddlePrincipalCurvaturesAtApex) {
  struct Case { double a, b; };
  for (const Case c : {Case{0.5, 0.2}, Case{0.8, -0.3}, Case{-0.4, -0.1}}) {
    const Positions p = heightFieldSamples([&](double x, double y) { return c.a * x * x + c.b * y * y; }, 400, 0.5, 7);
    paps::WavejetParameters params;
    const auto r = fitAtApex(p, params, 0.5f);
    ASSERT_TRUE(r.valid());
    EXPECT_EQ(r.order, 4);
    EXPECT_NEAR(r.k1, 2 * std::max(c.a, c.b), 1e-3);
    EXPECT_NEAR(r.k2, 2 * std::min(c.a, c.b), 1e-3);
    EXPECT_NEAR(r.mean_curvature, c.a + c.b, 1e-3);
    EXPECT_NEAR(r.gaussian_curvature, 4 * c.a * c.b, 1e-3);
    EXPECT_LT(angleDeg(r.normal, Eigen::Vector3f::UnitZ()), 0.01);
    // k1 direction: x when a > b, else y.
    const Eigen::Vector3f d1 = c.a > c.b ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY();
    EXPECT_GT(std::abs(r.direction1.dot(d1)), 0.999f);
    EXPECT_NEAR(r.offset, 0.f, 1e-5);
  }
}

TEST(Wavejet, SphereCurvatureIsOneOverRadius) {
  // 4000 points on a sphere of radius 2, outward orientation hints: k1 = k2 = -1/2.
  paps::Random rng(3);
  Positions p;
  paps::Normals out;
  while (p.size() < 4000) {
    Eigen::Vector3d v = rng.gaussian3();
    v.normalize();
    p.push_back((2.0 * v).cast<float>());
    out.push_back(v.cast<float>());
  }
  paps::WavejetParameters params;
  paps::WavejetReport report;
  const auto res = paps::estimateWavejets(p, 0.45f, params, &report, nullptr, nullptr, &out);
  EXPECT_EQ(report.fitted, p.size());
  double worst = 0, worst_normal = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    worst = std::max({worst, std::abs(res[i].k1 + 0.5), std::abs(res[i].k2 + 0.5)});
    worst_normal = std::max(worst_normal, angleDeg(res[i].normal, out[i]));
    EXPECT_GT(res[i].normal.dot(out[i]), 0.f);
  }
  EXPECT_LT(worst, 0.005);  // 1% of 1/r
  EXPECT_LT(worst_normal, 0.05);
}

// The surfaces of the bench, each with its exact normal at the apex (all +z).
std::vector<std::pair<const char*, HeightFn>> analyticSurfaces() {
  return {{"paraboloid", [](double x, double y) { return 0.5 * x * x + 0.3 * y * y; }},
          {"saddle", [](double x, double y) { return 0.5 * x * x - 0.4 * y * y; }},
          {"monkey saddle", [](double x, double y) { return x * x * x - 3 * x * y * y; }},
          {"x4+y4", [](double x, double y) { return x * x * x * x + y * y * y * y; }},
          {"sphere cap", [](double x, double y) { return 1.0 - std::sqrt(1.0 - x * x - y * y); }},
          {"cylinder", [](double x, double) { return 1.0 - std::sqrt(1.0 - x * x); }}};
}

TEST(Wavejet, TiltedPlaneCorrectedWithinHalfDegree) {
  for (const auto& s : analyticSurfaces()) {
    const Positions p = heightFieldSamples(s.second, 300, 0.4, 11);
    paps::WavejetParameters params;
    for (double tilt : {5.0, 10.0, 20.0})
      for (double az : {0.0, 1.0, 2.5}) {
        const auto r = fitAtApex(p, params, 0.4f, tilted(tilt, az));
        ASSERT_TRUE(r.valid()) << s.first;
        EXPECT_LT(angleDeg(r.normal, Eigen::Vector3f::UnitZ()), 0.5) << s.first << " tilt " << tilt;
      }
  }
}

// The plane is refitted for a real tilt (clean data: the tilt is many standard errors from
// zero), not for one the noise made: on small noisy neighbourhoods (18 to 24 points for the
// 15 unknowns of order 4, the case where a refit changed curvatures at random), every point
// whose tilt was judged within the noise has exactly the no-refit result.
TEST(Wavejet, RefitOnlyForTiltsAboveTheNoise) {
  const HeightFn f = [](double x, double y) { return 0.3 * x * x - 0.2 * y * y; };
  {
    const Positions p = heightFieldSamples(f, 300, 0.4, 5);
    paps::WavejetParameters params;
    params.refit_angle = 10;
    const auto r = fitAtApex(p, params, 0.4f, tilted(20, 0.7));
    ASSERT_TRUE(r.valid());
    EXPECT_GE(r.fits, 2);
    EXPECT_FALSE(r.tilt_within_noise);
    EXPECT_LT(angleDeg(r.normal, Eigen::Vector3f::UnitZ()), 0.1);
  }
  int gated = 0;
  for (std::uint64_t seed = 1; seed <= 400; ++seed) {
    Positions p = heightFieldSamples(f, 18 + static_cast<int>(seed % 7), 0.4, seed);
    paps::Random rng(1000 + seed);
    for (auto& q : p) q += rng.gaussian3().cast<float>() * 0.02f;
    paps::WavejetParameters params, no_refit;
    params.refit_angle = 10;
    no_refit.max_refits = 0;
    const auto r = fitAtApex(p, params, 0.4f, tilted(12, 0.3 * seed));
    const auto r0 = fitAtApex(p, no_refit, 0.4f, tilted(12, 0.3 * seed));
    ASSERT_TRUE(r.valid() && r0.valid());
    if (!r.tilt_within_noise) continue;
    ++gated;
    EXPECT_EQ(r.fits, 1);
    EXPECT_FLOAT_EQ(r.k1, r0.k1);
    EXPECT_FLOAT_EQ(r.k2, r0.k2);
    EXPECT_LT(angleDeg(r.normal, r0.normal), 1e-4);
  }
  EXPECT_GT(gated, 20);  // the case occurs: tilts above 10 degrees judged within the noise
}

TEST(Wavejet, Corollary2CorrectionIsSecondOrder) {
  // Third-order content; fit from a plane tilted by gamma without refitting. The corrected
  // |phi_3,n| must differ from the tangent-plane ones by O(gamma^2), not O(gamma).
  const HeightFn f = [](double x, double y) { return 0.5 * x * x + 0.2 * y * y + 0.3 * x * x * x + 0.4 * x * y * y; };
  const Positions p = heightFieldSamples(f, 500, 0.5, 5);
  paps::WavejetParameters params;
  params.order = 5;
  paps::WavejetCoefficients ref, c1, c2;
  ASSERT_TRUE(fitAtApex(p, params, 0.5f, Eigen::Vector3f::UnitZ(), &ref).valid());
  params.max_refits = 0;
  params.refit_angle = 90;
  ASSERT_TRUE(fitAtApex(p, params, 0.5f, tilted(2, 0.7), &c1).valid());
  ASSERT_TRUE(fitAtApex(p, params, 0.5f, tilted(4, 0.7), &c2).valid());
  double e1 = 0, e2 = 0, mag = 0;
  for (int n : {1, 3}) {
    e1 += std::abs(std::abs(c1.at(3, n)) - std::abs(ref.at(3, n)));
    e2 += std::abs(std::abs(c2.at(3, n)) - std::abs(ref.at(3, n)));
    mag += std::abs(ref.at(3, n));
  }
  // Measured: 1.7e-5, 6.6e-5, 2.6e-4, 1.0e-3 at 1, 2, 4, 8 degrees (|phi_3| sum 0.044):
  // quadratic in gamma, while the uncorrected first-order change is ~ gamma |phi_2| ~ 2e-3.
  EXPECT_LT(e2, 0.01 * mag);
  EXPECT_GT(e2, 2.5 * e1);  // error grows like gamma^2
}

TEST(Wavejet, OrderLoweredWhenFewNeighbours) {
  const Positions p = heightFieldSamples([](double x, double y) { return 0.3 * x * x + 0.1 * y * y; }, 12, 0.5, 9);
  paps::WavejetParameters params;  // K = 4 needs 1.1 * 15 = 16.5; K = 3 needs 11
  const auto idx = iota(p.size());
  auto ws = paps::makeWavejetWorkspace();
  const Eigen::Vector3f nan3 = Eigen::Vector3f::Constant(NAN), up = Eigen::Vector3f::UnitZ();
  auto r = paps::fitWavejet(p, idx.data(), 12, p[0], 0.5f, params, *ws, nan3, up);
  ASSERT_TRUE(r.valid());
  EXPECT_EQ(r.order, 3);
  r = paps::fitWavejet(p, idx.data(), 7, p[0], 0.5f, params, *ws, nan3, up);  // K = 2 needs 6.6
  ASSERT_TRUE(r.valid());
  EXPECT_EQ(r.order, 2);
  // 7 points: the PCA plane is a few degrees off, below the refit angle; an order-2 fit
  // over a tilted plane is then only o(gamma)-exact.
  EXPECT_NEAR(r.k1, 0.6, 1e-2);
  params.beta = 2;  // K = 3 needs 20, K = 2 needs 12
  r = paps::fitWavejet(p, idx.data(), 12, p[0], 0.5f, params, *ws, nan3, up);
  EXPECT_EQ(r.order, 2);
}

TEST(Wavejet, TooFewNeighboursGiveNaN) {
  const Positions p = heightFieldSamples([](double x, double y) { return x * y; }, 6, 0.5, 1);
  const auto idx = iota(p.size());
  auto ws = paps::makeWavejetWorkspace();
  const auto r = paps::fitWavejet(p, idx.data(), 6, p[0], 0.5f, paps::WavejetParameters(), *ws);
  EXPECT_FALSE(r.valid());
  EXPECT_TRUE(std::isnan(r.k1) && std::isnan(r.normal.x()) && std::isnan(r.mean_curvature));
}

TEST(Wavejet, DegenerateFitsAreNotCountedAsTooFewNeighbours) {
  // Points along a line: every ball holds plenty of neighbours, yet no surface fits. The
  // report tells them from the sparse points (it counted both as "too few neighbours").
  Positions p;
  for (int i = 0; i < 300; ++i) p.emplace_back(0.01f * i, 0.f, 0.f);
  p.emplace_back(50.f, 50.f, 50.f);  // isolated: too few
  paps::WavejetReport r;
  paps::WavejetParameters params;
  params.widening = paps::WavejetParameters::Widening::never;
  const auto res = paps::estimateWavejets(p, 0.2f, params, &r);
  ASSERT_EQ(res.size(), p.size());
  for (const auto& x : res) EXPECT_FALSE(x.valid());
  EXPECT_EQ(r.failed_fits, 300u);
  EXPECT_EQ(r.too_few_neighbours, 1u);
  EXPECT_EQ(r.fitted, 0u);
}

pcl::PointCloud<pcl::PointXYZ>::Ptr toCloud(const Positions& p) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr c(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& x : p) c->push_back(pcl::PointXYZ(x.x(), x.y(), x.z()));
  return c;
}

TEST(WavejetEstimation, NormalsFaceTheSensorOriginUnlessAViewPointIsGiven) {
  // pcl::NormalEstimation's convention: without setViewPoint, the input's sensor_origin_.
  const Positions p = heightFieldSamples([](double x, double y) { return 0.25 * (x * x + y * y); }, 2000, 1.0, 3);
  auto cloud = toCloud(p);
  cloud->sensor_origin_ = Eigen::Vector4f(0.f, 0.f, -10.f, 0.f);
  paps::WavejetEstimation<pcl::PointXYZ> wj;
  wj.setInputCloud(cloud);
  wj.setRadiusSearch(0.15);
  pcl::PointCloud<paps::PointWavejet> out;
  wj.compute(out);
  ASSERT_EQ(out.size(), p.size());
  std::size_t fitted = 0;
  for (const auto& q : out)
    if (std::isfinite(q.normal_z)) {
      ++fitted;
      ASSERT_LT(q.normal_z, 0.f);
    }
  EXPECT_GT(fitted, p.size() * 9 / 10);
  wj.setViewPoint(0, 0, 10);  // an explicit viewpoint wins
  wj.compute(out);
  for (const auto& q : out)
    if (std::isfinite(q.normal_z)) ASSERT_GT(q.normal_z, 0.f);
}

TEST(WavejetEstimation, FeatureOnHeightFieldWithIsolatedAndNaNPoints) {
  Positions p = heightFieldSamples([](double x, double y) { return 0.25 * (x * x + y * y); }, 3000, 1.0, 2);
  p.emplace_back(50.f, 50.f, 50.f);  // isolated: too few neighbours
  p.emplace_back(NAN, 0.f, 0.f);     // NaN input
  auto cloud = toCloud(p);
  cloud->is_dense = false;
  paps::WavejetEstimation<pcl::PointXYZ> wj;
  wj.setInputCloud(cloud);
  wj.setRadiusSearch(0.15);
  wj.setViewPoint(0, 0, 10);
  wj.setKeepCoefficients(true);
  pcl::PointCloud<paps::PointWavejet> out;
  wj.compute(out);
  ASSERT_EQ(out.size(), p.size());
  EXPECT_FALSE(out.is_dense);
  EXPECT_EQ(wj.getReport().too_few_neighbours, 1u);
  EXPECT_EQ(wj.getReport().non_finite, 1u);
  EXPECT_TRUE(std::isnan(out[p.size() - 2].k1));
  EXPECT_EQ(out[p.size() - 2].order, -1);
  EXPECT_TRUE(std::isnan(out[p.size() - 1].normal_x));
  // Apex: k1 = k2 = 0.5, normal +z (towards the viewpoint).
  EXPECT_NEAR(out[0].k1, 0.5, 2e-3);
  EXPECT_NEAR(out[0].k2, 0.5, 2e-3);
  EXPECT_GT(out[0].normal_z, 0.9999f);
  ASSERT_EQ(wj.getCoefficients().size(), p.size());
  EXPECT_NEAR(wj.getCoefficients()[0].at(2, 0).real(), 0.25 * 0.15, 1e-4);  // unit-disk units
  // The point type is registered: its normal copies into pcl::Normal.
  pcl::PointCloud<pcl::Normal> normals;
  pcl::copyPointCloud(out, normals);
  EXPECT_EQ(normals[0].normal_z, out[0].normal_z);
}

TEST(WavejetEstimation, KSearchAndOtherPointTypes) {
  const Positions p = heightFieldSamples([](double x, double y) { return 0.5 * x * x - 0.5 * y * y; }, 2000, 1.0, 4);
  pcl::PointCloud<pcl::PointNormal>::Ptr cloud(new pcl::PointCloud<pcl::PointNormal>);
  for (const auto& x : p) { pcl::PointNormal q; q.getVector3fMap() = x; cloud->push_back(q); }
  paps::WavejetEstimation<pcl::PointNormal> wj;
  wj.setInputCloud(cloud);
  wj.setKSearch(40);
  pcl::PointCloud<paps::PointWavejet> out;
  wj.compute(out);
  EXPECT_TRUE(out.is_dense);
  EXPECT_NEAR(out[0].k1, 1.0, 0.01);
  EXPECT_NEAR(out[0].k2, -1.0, 0.01);
  // An RGB-D camera's type (compiled in the library): the same positions give the same bits.
  pcl::PointCloud<pcl::PointXYZRGBA>::Ptr rgba(new pcl::PointCloud<pcl::PointXYZRGBA>);
  for (const auto& x : p) { pcl::PointXYZRGBA q; q.getVector3fMap() = x; q.rgba = 0x80ff0000u; rgba->push_back(q); }
  paps::WavejetEstimation<pcl::PointXYZRGBA> wj_rgba;
  wj_rgba.setInputCloud(rgba);
  wj_rgba.setKSearch(40);
  pcl::PointCloud<paps::PointWavejet> out_rgba;
  wj_rgba.compute(out_rgba);
  ASSERT_EQ(out_rgba.size(), out.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_EQ(std::memcmp(&out_rgba[i].k1, &out[i].k1, sizeof(float)), 0) << i;
    ASSERT_EQ(out_rgba[i].getNormalVector3fMap(), out[i].getNormalVector3fMap()) << i;
  }
}

// PCL's output types, as drop-ins for pcl::PrincipalCurvaturesEstimation: magnitudes of the
// principal curvatures in 1/m, largest first, and the direction of the largest.
TEST(WavejetEstimation, PclPrincipalCurvaturesOnASphereAndACylinder) {
  paps::Random rng(8);
  Positions sphere, cylinder;
  while (sphere.size() < 6000) {
    Eigen::Vector3d v = rng.gaussian3();
    sphere.push_back((0.5 * v.normalized()).cast<float>());  // radius 0.5: |k| = 2
  }
  while (cylinder.size() < 8000) {  // radius 0.25 (|k1| = 4, k2 = 0), axis z, height 1
    const double a = rng.uniform(0, 2 * kPi), z = rng.uniform(-0.5, 0.5);
    cylinder.emplace_back(float(0.25 * std::cos(a)), float(0.25 * std::sin(a)), float(z));
  }
  auto run = [](const Positions& p) {
    paps::WavejetEstimation<pcl::PointXYZ, pcl::PrincipalCurvatures> wj;
    wj.setInputCloud(toCloud(p));
    wj.setRadiusSearch(0.1);
    pcl::PointCloud<pcl::PrincipalCurvatures> out;
    wj.compute(out);
    EXPECT_EQ(out.size(), p.size());
    EXPECT_EQ(wj.getReport().fitted, p.size());
    return out;
  };
  const auto s = run(sphere);
  for (const auto& q : s) {
    ASSERT_NEAR(q.pc1, 2.f, 0.04f);
    ASSERT_NEAR(q.pc2, 2.f, 0.04f);
    ASSERT_GE(q.pc1, q.pc2);
  }
  const auto c = run(cylinder);
  std::size_t checked = 0;
  for (std::size_t i = 0; i < cylinder.size(); ++i) {
    if (std::abs(cylinder[i].z()) > 0.35f) continue;  // away from the open ends
    ++checked;
    ASSERT_NEAR(c[i].pc1, 4.f, 0.08f) << i;
    ASSERT_LT(c[i].pc2, 0.08f) << i;
    const Eigen::Vector3f d(c[i].principal_curvature_x, c[i].principal_curvature_y, c[i].principal_curvature_z);
    ASSERT_NEAR(d.norm(), 1.f, 1e-4f);
    ASSERT_LT(std::abs(d.z()), 0.03f) << "the curved direction is around the axis";
  }
  EXPECT_GT(checked, 5000u);

  // The same fit as the PointWavejet output, only written the PCL way.
  paps::WavejetEstimation<pcl::PointXYZ> wj;
  wj.setInputCloud(toCloud(cylinder));
  wj.setRadiusSearch(0.1);
  pcl::PointCloud<paps::PointWavejet> full;
  wj.compute(full);
  for (std::size_t i = 0; i < cylinder.size(); ++i) {
    ASSERT_EQ(c[i].pc1, std::max(std::abs(full[i].k1), std::abs(full[i].k2)));
    ASSERT_EQ(c[i].pc2, std::min(std::abs(full[i].k1), std::abs(full[i].k2)));
  }
}

// As a drop-in for pcl::NormalEstimation: the corrected normal, and PCL's own `curvature`
// (the surface variation of the same ball) so that PCL stages reading it (region growing,
// keypoints) see what they expect; with PointNormal output, x y z are left as they are.
TEST(WavejetEstimation, PclNormalOutputCarriesPclsCurvature) {
  Positions p = heightFieldSamples([](double x, double y) { return 0.25 * (x * x + y * y); }, 3000, 1.0, 5);
  p.emplace_back(50.f, 50.f, 50.f);  // isolated: NaN, as PCL's
  auto cloud = toCloud(p);
  paps::WavejetEstimation<pcl::PointXYZ, pcl::Normal> wj;
  wj.setInputCloud(cloud);
  wj.setRadiusSearch(0.15);
  wj.setViewPoint(0, 0, 10);
  pcl::PointCloud<pcl::Normal> ours;
  wj.compute(ours);
  pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
  ne.setInputCloud(cloud);
  ne.setRadiusSearch(0.15);
  ne.setViewPoint(0, 0, 10);
  pcl::PointCloud<pcl::Normal> pcl_normals;
  ne.compute(pcl_normals);
  ASSERT_EQ(ours.size(), p.size());
  EXPECT_FALSE(ours.is_dense);
  EXPECT_TRUE(std::isnan(ours.back().normal_x));
  EXPECT_TRUE(std::isnan(ours.back().curvature));
  std::size_t compared = 0;
  for (std::size_t i = 0; i + 1 < p.size(); ++i) {
    if (!std::isfinite(pcl_normals[i].curvature)) continue;
    ++compared;
    ASSERT_NEAR(ours[i].curvature, pcl_normals[i].curvature, 2e-5f + 1e-3f * pcl_normals[i].curvature) << i;
    const Eigen::Vector3f n = ours[i].getNormalVector3fMap();
    ASSERT_NEAR(n.norm(), 1.f, 1e-4f);
    ASSERT_GT(n.z(), 0.f) << "towards the viewpoint";
    // The exact normal of z = (x^2 + y^2) / 4.
    const Eigen::Vector3f exact = Eigen::Vector3f(-p[i].x() / 2, -p[i].y() / 2, 1.f).normalized();
    ASSERT_LT(angleDeg(n, exact), 0.5) << i;
  }
  EXPECT_GT(compared, 2900u);

  paps::WavejetEstimation<pcl::PointXYZ, pcl::PointNormal> with_xyz;
  with_xyz.setInputCloud(cloud);
  with_xyz.setRadiusSearch(0.15);
  with_xyz.setViewPoint(0, 0, 10);
  pcl::PointCloud<pcl::PointNormal> pn;
  pcl::copyPointCloud(*cloud, pn);
  with_xyz.compute(pn);
  for (std::size_t i = 0; i + 1 < p.size(); ++i) {
    ASSERT_EQ(pn[i].getVector3fMap(), p[i]);
    ASSERT_EQ(pn[i].getNormalVector3fMap(), ours[i].getNormalVector3fMap());
    ASSERT_EQ(pn[i].curvature, ours[i].curvature);
  }
}

TEST(WavejetEstimation, BadParametersThrow) {
  paps::WavejetEstimation<pcl::PointXYZ> wj;
  EXPECT_THROW(wj.setOrder(0), paps::InvalidParameter);
  EXPECT_THROW(wj.setOrder(50), paps::InvalidParameter);
  EXPECT_THROW(wj.setBeta(0.5f), paps::InvalidParameter);
  EXPECT_THROW(wj.setBeta(NAN), paps::InvalidParameter);
  EXPECT_THROW(wj.setIrlsIterations(-1), paps::InvalidParameter);
  EXPECT_THROW(wj.setPlaneCorrection(-1, 1.f), paps::InvalidParameter);
  {
    paps::WavejetParameters p;
    p.max_tile_points = std::size_t(1) << 31;
    EXPECT_THROW(wj.setParameters(p), paps::InvalidParameter);
  }
  pcl::PointCloud<paps::PointWavejet> out;
  auto empty = pcl::PointCloud<pcl::PointXYZ>::Ptr(new pcl::PointCloud<pcl::PointXYZ>);
  wj.setInputCloud(empty);
  wj.setRadiusSearch(0.1);
  EXPECT_THROW(wj.compute(out), paps::InvalidInput);
  {
    // A search surface with no finite point: PCL's kd-tree, built on nothing, crashed.
    paps::WavejetEstimation<pcl::PointXYZ> s;
    s.setInputCloud(toCloud(heightFieldSamples([](double, double) { return 0.0; }, 100, 1.0, 1)));
    s.setRadiusSearch(0.1);
    s.setSearchSurface(empty);
    EXPECT_THROW(s.compute(out), paps::InvalidInput);
    auto nan = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
    nan->push_back(pcl::PointXYZ(NAN, 0, 0));
    s.setSearchSurface(nan);
    EXPECT_THROW(s.compute(out), paps::InvalidInput);
  }
  wj.setInputCloud(toCloud(heightFieldSamples([](double, double) { return 0.0; }, 100, 1.0, 1)));
  wj.setRadiusSearch(0);
  EXPECT_THROW(wj.compute(out), paps::InvalidParameter);  // neither radius nor k
  wj.setRadiusSearch(-1);
  EXPECT_THROW(wj.compute(out), paps::InvalidParameter);
  wj.setRadiusSearch(0.3);
  wj.setKSearch(10);
  EXPECT_THROW(wj.compute(out), paps::InvalidParameter);  // both
  wj.setKSearch(0);
  wj.setIndices(pcl::IndicesPtr(new pcl::Indices{0, 5, 100}));  // 100 points: 100 is past the end
  try {
    wj.compute(out);
    ADD_FAILURE() << "an index past the cloud was accepted";
  } catch (const paps::InvalidParameter& e) {
    EXPECT_EQ(e.parameter(), "indices");
  }
  Positions p(10, Eigen::Vector3f::Zero());
  EXPECT_THROW(paps::estimateWavejets(p, NAN, paps::WavejetParameters()), paps::InvalidParameter);
  EXPECT_THROW(paps::estimateWavejets(Positions(3, Eigen::Vector3f::Constant(NAN)), 0.1f, paps::WavejetParameters()),
               paps::InvalidInput);
  // Copies of one position are one position: said so (it said "fewer than 2 finite points").
  for (const std::size_t copies : {std::size_t(2), std::size_t(1000)}) {
    try {
      paps::estimateWavejets(Positions(copies, Eigen::Vector3f(1, 2, 3)), 0.f, paps::WavejetParameters());
      ADD_FAILURE() << copies << " copies accepted";
    } catch (const paps::InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("all " + std::to_string(copies) + " finite points are at one position"),
                std::string::npos) << e.what();
    }
  }
  // A k beyond any neighbourhood is named as k (it was named after an internal parameter).
  paps::WavejetEstimation<pcl::PointXYZ> big_k;
  big_k.setInputCloud(toCloud(heightFieldSamples([](double, double) { return 0.0; }, 100, 1.0, 1)));
  big_k.setKSearch(1000000);
  try {
    big_k.compute(out);
    ADD_FAILURE() << "k = 1e6 accepted";
  } catch (const paps::InvalidParameter& e) {
    EXPECT_EQ(e.parameter(), "k");
  }
}

// Points are fitted in spatial order (a shuffled cloud waited on memory): the output of every
// point is the same whatever the order of the input, at the defaults (noise pilot, widening)
// and with copies of points and a NaN in the cloud.
TEST(WavejetEstimation, OutputDoesNotDependOnTheInputOrder) {
  Positions p = heightFieldSamples([](double x, double y) { return std::sin(3 * x) * std::cos(2 * y) * 0.2; }, 4000, 1.0, 8);
  paps::Random rng(2);
  for (auto& x : p) x.z() += static_cast<float>(0.004 * rng.gaussian());
  for (int i = 0; i < 100; ++i) p.push_back(p[i * 7]);
  p[5] = Eigen::Vector3f::Constant(NAN);
  std::vector<int> perm = iota(p.size());
  for (std::size_t i = perm.size() - 1; i > 0; --i) std::swap(perm[i], perm[rng.below(i + 1)]);
  Positions shuffled(p.size());
  for (std::size_t k = 0; k < p.size(); ++k) shuffled[k] = p[perm[k]];
  paps::WavejetReport ra, rb;
  const auto a = paps::estimateWavejets(p, 0.f, paps::WavejetParameters(), &ra);
  const auto b = paps::estimateWavejets(shuffled, 0.f, paps::WavejetParameters(), &rb);
  EXPECT_EQ(ra.radius, rb.radius);
  EXPECT_EQ(ra.noise_sigma, rb.noise_sigma);
  EXPECT_EQ(ra.duplicates, 100u);
  std::size_t valid = 0;
  for (std::size_t k = 0; k < p.size(); ++k) {
    const auto& x = a[perm[k]];
    const auto& y = b[k];
    ASSERT_EQ(x.valid(), y.valid()) << k;
    if (!x.valid()) continue;
    ++valid;
    ASSERT_EQ(x.k1, y.k1) << k;
    ASSERT_EQ(x.k2, y.k2) << k;
    ASSERT_EQ(x.normal, y.normal) << k;
    ASSERT_EQ(x.radius, y.radius) << k;
  }
  EXPECT_EQ(valid, p.size() - 1);
}

// The same balls returned sorted by distance or not (pcl::search::KdTree's option): the same
// estimates, bit for bit. On this range image's border, where the fits are ill-conditioned,
// 89 mean curvatures differed (0.105 against 0.65) before the fit put its list in order.
TEST(WavejetEstimation, SameResultWhateverOrderTheSearchReturns) {
  const int w = 64, h = 48;
  const float f = 60.f;
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>(w, h));
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const float dx = (u - w / 2 + 0.5f) / f, dy = (v - h / 2 + 0.5f) / f;
      const float z = 1.f + 0.01f * std::sin(8 * dx);
      (*cloud)(u, v) = pcl::PointXYZ(dx * z, dy * z, z);
    }
  pcl::PointCloud<paps::PointWavejet> out[2];
  for (int sorted = 0; sorted < 2; ++sorted) {
    paps::WavejetEstimation<pcl::PointXYZ> est;
    est.setInputCloud(cloud);
    est.setRadiusSearch(0.06);
    est.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>(sorted == 1));
    est.compute(out[sorted]);
  }
  ASSERT_EQ(out[0].size(), out[1].size());
  std::size_t fitted = 0;
  for (std::size_t i = 0; i < out[0].size(); ++i) {
    ASSERT_EQ(std::memcmp(&out[0][i], &out[1][i], sizeof(paps::PointWavejet)), 0) << i;
    fitted += std::isfinite(out[0][i].mean_curvature);
  }
  EXPECT_GT(fitted, out[0].size() * 9 / 10);
}

// Large index sets are visited in space order (cache locality on shuffled clouds); each
// output must still be its own point's: the same bits as that point estimated alone (one
// index, visited as given), by k and by radius, on a shuffled cloud with indices out of order.
TEST(WavejetEstimation, EachOutputIsItsPointsWhateverOrderThePointsAreVisitedIn) {
  Positions p = heightFieldSamples([](double x, double y) { return 0.3 * x * x - 0.2 * y * y + 0.1 * x * y; }, 9000, 1.0, 4);
  paps::Random rng(6);
  for (auto& x : p) x.z() += static_cast<float>(0.002 * rng.gaussian());
  std::vector<int> perm = iota(p.size());
  for (std::size_t i = perm.size() - 1; i > 0; --i) std::swap(perm[i], perm[rng.below(i + 1)]);
  Positions shuffled(p.size());
  for (std::size_t k = 0; k < p.size(); ++k) shuffled[k] = p[perm[k]];
  const auto cloud = toCloud(shuffled);
  // Every other point, last first: 4,500 indices (the space order starts at 4,096).
  auto indices = pcl::make_shared<pcl::Indices>();
  for (int i = static_cast<int>(p.size()) - 1; i >= 0; i -= 2) indices->push_back(i);
  for (int by_k = 0; by_k < 2; ++by_k) {
    auto estimate = [&](const pcl::IndicesPtr& idx, pcl::PointCloud<paps::PointWavejet>& out) {
      paps::WavejetEstimation<pcl::PointXYZ> est;
      est.setInputCloud(cloud);
      est.setIndices(idx);
      if (by_k)
        est.setKSearch(30);
      else
        est.setRadiusSearch(0.05);
      est.compute(out);
    };
    pcl::PointCloud<paps::PointWavejet> all;
    estimate(indices, all);
    ASSERT_EQ(all.size(), indices->size());
    std::size_t fitted = 0;
    for (std::size_t j = 0; j < all.size(); ++j) fitted += std::isfinite(all[j].k1);
    EXPECT_GT(fitted, all.size() * 99 / 100) << by_k;
    for (std::size_t j = 0; j < all.size(); j += 450) {
      pcl::PointCloud<paps::PointWavejet> one;
      estimate(pcl::make_shared<pcl::Indices>(1, (*indices)[j]), one);
      ASSERT_EQ(one.size(), 1u);
      EXPECT_EQ(std::memcmp(&one[0], &all[j], sizeof(paps::PointWavejet)), 0) << by_k << " " << j;
      EXPECT_NE(std::memcmp(&one[0], &all[j == 0 ? 1 : j - 1], sizeof(paps::PointWavejet)), 0) << by_k << " " << j;
    }
  }
}

// Without a search method the class gives PCL's Feature a paps::KdTreeSearch, which builds at
// its first query: radius balls from the grid never build it; a k search on the same object
// does, and gives the outputs of an explicit pcl::search::KdTree, bit for bit; the tree
// answers a user's queries.
TEST(WavejetEstimation, DefaultKdTreeIsBuiltOnlyWhenQueried) {
  const Positions p = heightFieldSamples([](double x, double y) { return 0.2 * x * y; }, 6000, 1.0, 12);
  const auto cloud = toCloud(p);
  paps::WavejetEstimation<pcl::PointXYZ> est;
  est.setInputCloud(cloud);
  est.setRadiusSearch(0.06);
  pcl::PointCloud<paps::PointWavejet> out;
  est.compute(out);
  const auto lazy = std::dynamic_pointer_cast<paps::KdTreeSearch<pcl::PointXYZ>>(est.getSearchMethod());
  ASSERT_TRUE(lazy);
  EXPECT_FALSE(lazy->built());
  EXPECT_GT(est.getReport().fitted, p.size() * 9 / 10);
  est.setRadiusSearch(0);
  est.setKSearch(25);
  pcl::PointCloud<paps::PointWavejet> by_k, by_kd;
  est.compute(by_k);
  EXPECT_TRUE(lazy->built());
  EXPECT_EQ(est.getSearchMethod(), lazy);
  paps::WavejetEstimation<pcl::PointXYZ> kd;
  kd.setInputCloud(cloud);
  kd.setKSearch(25);
  kd.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  kd.compute(by_kd);
  ASSERT_EQ(by_k.size(), by_kd.size());
  for (std::size_t i = 0; i < by_k.size(); ++i)
    ASSERT_EQ(std::memcmp(&by_k[i], &by_kd[i], sizeof(paps::PointWavejet)), 0) << i;
  // A user's own query on the tree the class made: the nearest points by brute force.
  pcl::Indices nn;
  std::vector<float> d2;
  ASSERT_EQ(lazy->nearestKSearch(pcl::PointXYZ(0.1f, -0.2f, 0.f), 3, nn, d2), 3);
  std::vector<std::pair<float, int>> all;
  for (std::size_t i = 0; i < p.size(); ++i)
    all.emplace_back((p[i] - Eigen::Vector3f(0.1f, -0.2f, 0.f)).squaredNorm(), static_cast<int>(i));
  std::sort(all.begin(), all.end());
  for (int j = 0; j < 3; ++j) EXPECT_EQ(nn[j], all[j].second);
  // A new cloud resets it: not built again until queried.
  est.setInputCloud(toCloud(Positions(p.begin(), p.begin() + 5000)));
  est.setKSearch(0);
  est.setRadiusSearch(0.06);
  est.compute(out);
  EXPECT_EQ(out.size(), 5000u);
  EXPECT_FALSE(lazy->built());
}

// Without a search method the radius balls come from our grid, with one from PCL's kd-tree:
// the same balls, so the same outputs, bit for bit. A lattice whose spacing divides the
// radius puts many neighbours at a squared distance within rounding of R^2 (the open ball
// must be FLANN's); a second case searches another surface.
TEST(WavejetEstimation, GridBallsAreTheKdTreesBalls) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr lattice(new pcl::PointCloud<pcl::PointXYZ>);
  for (int i = 0; i < 60; ++i)
    for (int j = 0; j < 60; ++j) {
      const float x = 0.01f * static_cast<float>(i), y = 0.01f * static_cast<float>(j);
      lattice->push_back(pcl::PointXYZ(x, y, 0.3f * x * x - 0.2f * y * y));
    }
  lattice->push_back(pcl::PointXYZ(NAN, 0.f, 0.f));
  lattice->is_dense = false;
  const Positions noisy_p = heightFieldSamples([](double x, double y) { return std::sin(3 * x) * std::cos(2 * y) * 0.2; }, 6000, 1.0, 21);
  auto noisy = toCloud(noisy_p);
  auto half = toCloud(Positions(noisy_p.begin(), noisy_p.begin() + 3000));
  // A neighbour whose squared distance FLANN sums as (dx^2 + dy^2) + dz^2 just below R^2,
  // while dx^2 + (dy^2 + dz^2) (Eigen's squaredNorm) rounds to R^2 itself: FLANN keeps it.
  pcl::PointCloud<pcl::PointXYZ>::Ptr edge(new pcl::PointCloud<pcl::PointXYZ>);
  double edge_radius = 0;
  {
    paps::Random rng(4);
    for (int tries = 0; tries < 1000000 && edge_radius == 0; ++tries) {
      const float dz = static_cast<float>(rng.uniform(0.0, 0.02)), dy = static_cast<float>(rng.uniform(0.6, 0.72)),
                  dx = static_cast<float>(rng.uniform(0.6, 0.72));
      float flann = dx * dx;
      flann += dy * dy;
      flann += dz * dz;
      float other = dy * dy + dz * dz;
      other = dx * dx + other;
      const double r = std::sqrt(static_cast<double>(other));
      if (flann < other && static_cast<float>(r * r) == other) {
        edge_radius = r;
        edge->push_back(pcl::PointXYZ(0.f, 0.f, 0.f));
        edge->push_back(pcl::PointXYZ(dx, dy, dz));
      }
    }
    ASSERT_GT(edge_radius, 0);
    for (int i = -6; i <= 6; ++i)  // a patch to fit around the first point
      for (int j = -6; j <= 6; ++j)
        if (i != 0 || j != 0) {
          const float x = 0.1f * static_cast<float>(i), y = 0.1f * static_cast<float>(j);
          edge->push_back(pcl::PointXYZ(x, y, 0.01f * x * y));
        }
  }
  struct Case { pcl::PointCloud<pcl::PointXYZ>::Ptr input, surface; double radius; };
  for (const Case& c : {Case{lattice, nullptr, 0.03}, Case{lattice, nullptr, 0.05}, Case{half, noisy, 0.08},
                        Case{edge, nullptr, edge_radius}}) {
    pcl::PointCloud<paps::PointWavejet> out[2];
    paps::WavejetReport report[2];
    for (int tree = 0; tree < 2; ++tree) {
      paps::WavejetEstimation<pcl::PointXYZ> est;
      est.setInputCloud(c.input);
      if (c.surface) est.setSearchSurface(c.surface);
      est.setRadiusSearch(c.radius);
      est.setViewPoint(0, 0, 10);
      if (tree == 1) est.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
      est.compute(out[tree]);
      report[tree] = est.getReport();
    }
    ASSERT_EQ(out[0].size(), out[1].size());
    for (std::size_t i = 0; i < out[0].size(); ++i)
      ASSERT_EQ(std::memcmp(&out[0][i], &out[1][i], sizeof(paps::PointWavejet)), 0) << c.radius << " " << i;
    EXPECT_EQ(report[0].mean_neighbours, report[1].mean_neighbours) << c.radius;
    EXPECT_GT(report[0].fitted, c.input->size() * 7 / 10) << c.radius;
  }
}

TEST(WavejetEstimation, DeterministicAcrossThreadCounts) {
  Positions p = heightFieldSamples([](double x, double y) { return std::sin(3 * x) * std::cos(2 * y) * 0.2; }, 4000, 1.0, 8);
  paps::Random rng(2);
  for (auto& x : p) x.z() += static_cast<float>(0.002 * rng.gaussian());
  // Both solvers: normal equations (default) and QR (IRLS), with order selection.
  for (const int irls : {0, 3}) {
    paps::WavejetParameters params;
    params.irls_iterations = irls;
    params.select_order = irls == 0;
    params.order_policy = irls == 0 ? paps::WavejetParameters::OrderPolicy::select
                                    : paps::WavejetParameters::OrderPolicy::fixed;  // the fixed order on QR
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const auto a = paps::estimateWavejets(p, 0.12f, params);
    omp_set_num_threads(std::max(2, threads));
    const auto b = paps::estimateWavejets(p, 0.12f, params);
    omp_set_num_threads(threads);
    for (std::size_t i = 0; i < p.size(); ++i) {
      ASSERT_EQ(a[i].k1, b[i].k1);
      ASSERT_EQ(a[i].normal, b[i].normal);
      ASSERT_EQ(a[i].a0, b[i].a0);
    }
  }
}

// The pcl::Feature writes each fit into the output and counts it in the report as it goes:
// no per-point copy of the results (76 bytes a point before session 49), and the same
// outputs and report whatever the thread count.
TEST(WavejetEstimation, ThreadsGiveTheSameOutputAndReportWithoutACopyOfTheResults) {
  Positions p = heightFieldSamples([](double x, double y) { return std::sin(3 * x) * std::cos(2 * y) * 0.2; }, 60000, 1.0, 12);
  paps::Random rng(5);
  for (auto& x : p) x.z() += static_cast<float>(0.004 * rng.gaussian());  // the pilot selects orders
  p.emplace_back(50.f, 50.f, 50.f);  // too few neighbours
  p.emplace_back(NAN, 0.f, 0.f);
  auto cloud = toCloud(p);
  cloud->is_dense = false;
  std::vector<pcl::PointCloud<paps::PointWavejet>> out(2);
  std::vector<paps::WavejetReport> report(2);
  std::size_t peak = 0;
  for (int threads : {1, 2}) {
    paps::WavejetEstimation<pcl::PointXYZ> wj;
    wj.setInputCloud(cloud);
    wj.setRadiusSearch(0.03);
    wj.setViewPoint(0, 0, 10);
    wj.setNumberOfThreads(threads);
    paps::test::resetAllocationPeak();
    wj.compute(out[threads - 1]);
    if (threads == 2) peak = paps::test::allocationPeakSinceReset();
    report[threads - 1] = wj.getReport();
  }
  const auto& r = report[0];
  EXPECT_GT(r.fitted, p.size() * 9 / 10);
  EXPECT_GT(r.lowered, 0u);
  EXPECT_EQ(r.too_few_neighbours, 1u);
  EXPECT_EQ(r.non_finite, 1u);
  for (std::size_t paps::WavejetReport::*field : {&paps::WavejetReport::fitted, &paps::WavejetReport::lowered, &paps::WavejetReport::widened,
                            &paps::WavejetReport::narrowed, &paps::WavejetReport::too_few_neighbours,
                            &paps::WavejetReport::failed_fits, &paps::WavejetReport::not_converged,
                            &paps::WavejetReport::tilt_within_noise, &paps::WavejetReport::non_finite})
    EXPECT_EQ(r.*field, report[1].*field);
  EXPECT_EQ(r.mean_neighbours, report[1].mean_neighbours);
  EXPECT_EQ(r.max_radius, report[1].max_radius);
  EXPECT_EQ(r.select_order, report[1].select_order);
  EXPECT_TRUE(r.select_order);
  const auto same = [](float a, float b) { return a == b || (std::isnan(a) && std::isnan(b)); };
  for (std::size_t i = 0; i < p.size(); ++i) {
    const auto &a = out[0][i], &b = out[1][i];
    ASSERT_TRUE(same(a.normal_x, b.normal_x) && same(a.normal_y, b.normal_y) && same(a.normal_z, b.normal_z)) << i;
    ASSERT_TRUE(same(a.k1, b.k1) && same(a.k2, b.k2) && same(a.principal_x, b.principal_x) && same(a.a0, b.a0) &&
                same(a.offset, b.offset) && a.order == b.order)
        << i;
  }
  // What operator new holds at most during compute(): PCL's kd-tree, the positions, the
  // pilot's index and the fits' scratch, 106 bytes a point when measured (the output cloud
  // is allocated by Eigen's aligned allocator, outside operator new). The per-point copy of
  // the results and its side arrays held 86 more.
  if (paps::test::allocationCounted()) {
    std::printf("peak held through operator new during compute: %.1f bytes a point\n",
                static_cast<double>(peak) / static_cast<double>(p.size()));
    EXPECT_LT(peak, p.size() * 140);
  }
}

TEST(Wavejet, CloudRunUsesExactlyTheBallNeighbours) {
  // A sphere: points on the extreme planes of the bounding box sit on cell borders of the
  // neighbour grid. Every point must see exactly its ball (mean count equal to brute force)
  // and give the same fit as with brute-force neighbour lists.
  paps::Random rng(5);
  Positions p;
  p.emplace_back(2.f, 0.f, 0.f);
  p.emplace_back(-2.f, 0.f, 0.f);
  p.emplace_back(0.f, 0.f, -2.f);
  while (p.size() < 3000) {
    Eigen::Vector3d v = rng.gaussian3();
    p.push_back((2.0 * v.normalized()).cast<float>());
  }
  paps::Normals out(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) out[i] = p[i].normalized();
  paps::WavejetParameters params;
  for (const float r : {0.45f, 0.3f, 0.7f, 0.61f}) {  // cell borders fall differently
    paps::WavejetReport report;
    paps::estimateWavejets(p, r, params, &report, nullptr, nullptr, &out);
    EXPECT_EQ(report.fitted, p.size()) << "radius " << r;
  }
  const float radius = 0.5f;
  paps::WavejetReport report;
  const auto res = paps::estimateWavejets(p, radius, params, &report, nullptr, nullptr, &out);
  EXPECT_EQ(report.fitted, p.size());
  double brute_sum = 0;
  auto ws = paps::makeWavejetWorkspace();
  for (std::size_t i = 0; i < p.size(); ++i) {
    std::vector<int> nb;
    for (std::size_t j = 0; j < p.size(); ++j)
      if ((p[j] - p[i]).squaredNorm() <= radius * radius) nb.push_back(static_cast<int>(j));
    brute_sum += static_cast<double>(nb.size());
    if (i % 100 != 0 && i > 2) continue;
    const auto r = paps::fitWavejet(p, nb.data(), static_cast<int>(nb.size()), p[i], radius, params, *ws,
                                    Eigen::Vector3f::Constant(NAN), out[i]);
    ASSERT_TRUE(r.valid());
    EXPECT_NEAR(res[i].k1, r.k1, 1e-4);
    EXPECT_NEAR(res[i].k2, r.k2, 1e-4);
    EXPECT_LT(angleDeg(res[i].normal, r.normal), 1e-3);
  }
  EXPECT_DOUBLE_EQ(report.mean_neighbours, brute_sum / static_cast<double>(p.size()));
}

TEST(Wavejet, IrlsResistsOutliers) {
  Positions p = heightFieldSamples([](double x, double y) { return 0.5 * x * x + 0.1 * y * y; }, 400, 0.5, 6);
  paps::Random rng(4);
  for (std::size_t i = 1; i < p.size(); i += 10) p[i].z() += static_cast<float>(rng.uniform(0.05, 0.2));
  paps::WavejetParameters params;
  const auto plain = fitAtApex(p, params, 0.5f);
  params.irls_iterations = 10;
  const auto robust = fitAtApex(p, params, 0.5f);
  EXPECT_LT(std::abs(robust.k1 - 1.0), 0.02);
  EXPECT_LT(std::abs(robust.k1 - 1.0), 0.5 * std::abs(plain.k1 - 1.0));
}

TEST(Wavejet, IntegralInvariantOfParaboloid) {
  // z = c r^2 (unit disk): phi_20 = c, a_0(1) = c / 4, a_1 = 0.
  const Positions p = heightFieldSamples([](double x, double y) { return 0.2 * (x * x + y * y); }, 300, 1.0, 3);
  paps::WavejetCoefficients c;
  const auto r = fitAtApex(p, paps::WavejetParameters(), 1.f, Eigen::Vector3f::Constant(NAN), &c);
  EXPECT_NEAR(r.a0, 0.05, 1e-4);
  EXPECT_NEAR(std::abs(r.a1), 0.0, 1e-4);
  EXPECT_NEAR(c.integralInvariant(0, 0.5f).real(), 0.2 * std::pow(0.5, 4) / 4, 1e-5);
}

TEST(Wavejet, OrderSelectionUnderNoise) {
  // Noisy paraboloid: GCV picks order 2 and the curvature error drops; on clean data with
  // quartic content the full order stays.
  const HeightFn f = [](double x, double y) { return 0.5 * x * x + 0.25 * y * y; };
  double err_fixed = 0, err_sel = 0;
  int order2 = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    Positions p = heightFieldSamples(f, 60, 0.12, seed);
    paps::Random rng(seed + 100);
    for (auto& x : p) x.z() += static_cast<float>(0.0012 * rng.gaussian());  // 1% of R
    paps::WavejetParameters params;
    const auto a = fitAtApex(p, params, 0.12f);
    params.select_order = true;
    const auto b = fitAtApex(p, params, 0.12f);
    err_fixed += std::pow(a.k1 - 1.0, 2) + std::pow(a.k2 - 0.5, 2);
    err_sel += std::pow(b.k1 - 1.0, 2) + std::pow(b.k2 - 0.5, 2);
    order2 += b.order == 2;
  }
  EXPECT_GE(order2, 15);
  EXPECT_LT(err_sel, 0.25 * err_fixed);
  const Positions clean = heightFieldSamples([](double x, double y) { return x * x * x * x + 2 * y * y * y * y + 0.3 * x * y; }, 200, 0.5, 3);
  paps::WavejetParameters params;
  params.select_order = true;
  EXPECT_EQ(fitAtApex(clean, params, 0.5f).order, 4);
}

// A unit sphere sampled like a real scan of uneven density: `uniform` points over the whole
// sphere, then `cap` more in the cap of angular radius `cap_angle` around +z, every point
// written twice when `copies` (exact duplicates, as in bun0.pcd).
Positions sphereWithDenseCap(std::uint64_t seed, std::size_t uniform, std::size_t cap, float cap_angle, bool copies) {
  paps::Random rng(seed);
  Positions p;
  auto onSphere = [&]() {
    const Eigen::Vector3d v = rng.gaussian3();
    return Eigen::Vector3f(v.normalized().cast<float>());
  };
  while (p.size() < uniform) p.push_back(onSphere());
  while (p.size() < uniform + cap) {
    const Eigen::Vector3f v = onSphere();
    if (v.z() > std::cos(cap_angle)) p.push_back(v);
  }
  if (copies) {
    const std::size_t base = p.size();
    for (std::size_t i = 0; i < base; ++i) p.push_back(p[i]);
  }
  return p;
}

// Varying density: 3000 points over the sphere and 6000 in the cap of 0.15 rad (about 350x
// denser), every point twice; `base` gets the count before the copies.
Positions varyingDensitySphere(std::size_t& base) {
  base = 9000;
  return sphereWithDenseCap(7, 3000, 6000, 0.15f, true);
}

TEST(WavejetEstimation, VaryingDensityAndDuplicatesFittedEverywhereAtDefaults) {
  // The bug of bun0.pcd: the automatic radius aims at a mean count, which the dense cap
  // dominates, so the sparse part had fewer than 7 points per ball and NaN outputs. With
  // the defaults (duplicates counted once, balls holding fewer than 50 distinct positions
  // widened to the 50 nearest) every point is fitted and the curvature stays accurate
  // (truth k1 = k2 = -1 with outward normals).
  std::size_t base = 0;
  const Positions p = varyingDensitySphere(base);
  paps::Normals out(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) out[i] = p[i].normalized();
  paps::WavejetParameters fixed;
  fixed.widening = paps::WavejetParameters::Widening::never;
  paps::WavejetReport before;
  paps::estimateWavejets(p, 0.f, fixed, &before, nullptr, nullptr, &out);
  EXPECT_GT(before.too_few_neighbours, 5000u);  // most of the sparse part (2 x ~3000 copies)

  paps::WavejetReport report;
  const auto res = paps::estimateWavejets(p, 0.f, paps::WavejetParameters(), &report, nullptr, nullptr, &out);
  ASSERT_EQ(res.size(), p.size());
  EXPECT_EQ(report.too_few_neighbours, 0u);
  EXPECT_EQ(report.fitted, p.size());
  EXPECT_EQ(report.duplicates, base);
  EXPECT_GT(report.widened, 5000u);
  EXPECT_GT(report.widened_radius_median, 5 * report.radius);
  double se_sparse = 0, se_dense = 0;
  std::size_t n_sparse = 0, n_dense = 0;
  for (std::size_t i = 0; i < base; ++i) {
    ASSERT_TRUE(res[i].valid()) << i;
    // Every copy gets its position's output.
    ASSERT_EQ(res[i + base].k1, res[i].k1);
    ASSERT_EQ(res[i + base].normal, res[i].normal);
    const double e = std::pow(res[i].k1 + 1.0, 2) + std::pow(res[i].k2 + 1.0, 2);
    if (res[i].radius > report.radius) { se_sparse += e; n_sparse += 2; }
    else { se_dense += e; n_dense += 2; }
    EXPECT_LT(angleDeg(res[i].normal, out[i]), 0.5);
  }
  ASSERT_GT(n_sparse, 0u);
  ASSERT_GT(n_dense, 0u);
  // Measured 0.0031 (widened points, 50 neighbours each) and 0.0005 (the others, ball of
  // R_phi).
  EXPECT_LT(std::sqrt(se_sparse / n_sparse), 0.01);
  EXPECT_LT(std::sqrt(se_dense / n_dense), 0.003);
}

TEST(WavejetEstimation, WidenedRunDeterministicAcrossThreadCounts) {
  std::size_t base = 0;
  const Positions p = varyingDensitySphere(base);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto a = paps::estimateWavejets(p, 0.f, paps::WavejetParameters());
  omp_set_num_threads(std::max(2, threads));
  const auto b = paps::estimateWavejets(p, 0.f, paps::WavejetParameters());
  omp_set_num_threads(threads);
  for (std::size_t i = 0; i < p.size(); ++i) {
    ASSERT_EQ(a[i].k1, b[i].k1) << i;
    ASSERT_EQ(a[i].radius, b[i].radius) << i;
    ASSERT_EQ(a[i].normal, b[i].normal) << i;
  }
}

TEST(WavejetEstimation, DuplicatesGiveTheOutputOfTheCloudWithout) {
  // Counting each position once: a cloud with copies gives exactly the outputs of the
  // cloud without them (same radius, same neighbour lists), also when not widened.
  const Positions u = heightFieldSamples([](double x, double y) { return 0.3 * x * x - 0.2 * x * y; }, 3000, 1.0, 12);
  Positions p = u;
  for (std::size_t i = 0; i < u.size(); i += 3) p.push_back(u[i]);
  p.push_back(u[5]);
  for (const auto widening : {paps::WavejetParameters::Widening::never, paps::WavejetParameters::Widening::always}) {
    paps::WavejetParameters params;
    params.widening = widening;
    paps::WavejetReport ru, rp;
    const auto a = paps::estimateWavejets(u, 0.f, params, &ru);
    const auto b = paps::estimateWavejets(p, 0.f, params, &rp);
    EXPECT_EQ(ru.radius, rp.radius);
    EXPECT_EQ(rp.duplicates, p.size() - u.size());
    for (std::size_t i = 0; i < u.size(); ++i) {
      ASSERT_EQ(a[i].k1, b[i].k1) << i;
      ASSERT_EQ(a[i].normal, b[i].normal) << i;
    }
    std::size_t copies_widened = 0;
    for (std::size_t i = u.size(); i < p.size(); ++i) {
      const std::size_t j = i == p.size() - 1 ? 5 : 3 * (i - u.size());
      ASSERT_EQ(b[i].k1, a[j].k1) << i;
      copies_widened += a[j].radius > ru.radius;
    }
    EXPECT_EQ(rp.widened, ru.widened + copies_widened);  // counted per input point
  }
}

TEST(WavejetEstimation, WideningWithAnExplicitRadius) {
  // setRadiusSearch keeps PCL's semantics by default (NaN where too few); Widening::always
  // fits every point whose ball holds fewer than 50 on its 50 nearest instead.
  const Positions p = heightFieldSamples([](double x, double y) { return 0.25 * (x * x + y * y); }, 2000, 1.0, 2);
  auto cloud = toCloud(p);
  paps::WavejetEstimation<pcl::PointXYZ> wj;
  wj.setInputCloud(cloud);
  wj.setRadiusSearch(0.06);  // about 7 neighbours on average
  wj.setViewPoint(0, 0, 10);
  pcl::PointCloud<paps::PointWavejet> out;
  wj.compute(out);
  EXPECT_FALSE(out.is_dense);
  EXPECT_GT(wj.getReport().too_few_neighbours, 500u);
  paps::WavejetParameters params;
  params.widening = paps::WavejetParameters::Widening::always;
  wj.setParameters(params);
  wj.compute(out);
  EXPECT_TRUE(out.is_dense);
  EXPECT_EQ(wj.getReport().too_few_neighbours, 0u);
  EXPECT_GT(wj.getReport().widened, 500u);
  EXPECT_NEAR(out[0].k1, 0.5, 5e-3);
  EXPECT_NEAR(out[0].k2, 0.5, 5e-3);
  // The same through estimateWavejets with the explicit radius.
  paps::WavejetReport r;
  paps::estimateWavejets(p, 0.06f, params, &r);
  EXPECT_EQ(r.too_few_neighbours, 0u);
  EXPECT_EQ(r.widened, wj.getReport().widened);
  params.widened_neighbours = -1;
  EXPECT_THROW(params.validate(), paps::InvalidParameter);
}

// The converse of varyingDensitySphere: a unit sphere sampled evenly (6000 points, which
// set the automatic radius, about 50 per ball) plus a dense cluster of 4000 in a cap of
// angular radius 0.08, where every ball of R_phi holds thousands; every position twice when
// `copies`.
Positions denseClusterSphere(bool copies) { return sphereWithDenseCap(19, 6000, 4000, 0.08f, copies); }

TEST(WavejetEstimation, NarrowingBoundsCrowdedBalls) {
  // The cost of bun0.pcd: its dense parts held ~2,000 per ball of the automatic radius.
  // With the defaults a ball holding more than 4 N = 200 distinct positions is fitted on
  // its 200 nearest at their radius; the others keep the ball of R_phi exactly.
  const Positions u = denseClusterSphere(false);
  const Positions p = denseClusterSphere(true);
  paps::Normals out(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) out[i] = p[i].normalized();
  paps::WavejetParameters params;
  EXPECT_EQ(paps::wavejetWidenedNeighbours(params, 50), 50);
  EXPECT_EQ(paps::wavejetNarrowedNeighbours(params, 50), 200);
  paps::WavejetReport full, report;
  paps::WavejetParameters fixed;
  fixed.widening = paps::WavejetParameters::Widening::never;
  const auto ref = paps::estimateWavejets(p, 0.f, fixed, &full, nullptr, nullptr, &out);
  const auto res = paps::estimateWavejets(p, 0.f, params, &report, nullptr, nullptr, &out);
  EXPECT_EQ(report.radius, full.radius);
  EXPECT_GT(full.mean_neighbours, 1000.0);  // the cluster's balls dominate the mean
  EXPECT_EQ(report.fitted, p.size());
  // Every cluster position (both copies) narrowed, counted per input point.
  EXPECT_GE(report.narrowed, 2 * 4000u);
  EXPECT_LT(report.narrowed, 2 * 4300u);
  EXPECT_LT(report.narrowed_radius_median, 0.25f * report.radius);
  EXPECT_LT(report.mean_neighbours, 200.0);
  double se_narrow = 0, se_ball = 0, se_ref = 0;
  std::size_t n_narrow = 0, n_ball = 0, n_exact = 0, n_widened = 0, n_widened_checked = 0;
  const std::size_t base = u.size();
  // The distinct positions by distance to u[i] (brute force), for the fits checked below.
  auto byDistance = [&](std::size_t i) {
    std::vector<std::pair<float, int>> d;
    for (std::size_t j = 0; j < base; ++j) d.emplace_back((u[j] - u[i]).squaredNorm(), static_cast<int>(j));
    std::sort(d.begin(), d.end());
    return d;
  };
  auto ws = paps::makeWavejetWorkspace();
  for (std::size_t i = 0; i < base; ++i) {
    ASSERT_TRUE(res[i].valid()) << i;
    ASSERT_EQ(res[i + base].k1, res[i].k1);
    ASSERT_EQ(res[i + base].radius, res[i].radius);
    const double e = std::pow(res[i].k1 + 1.0, 2) + std::pow(res[i].k2 + 1.0, 2);
    if (res[i].radius < report.radius) {
      se_narrow += e;
      se_ref += std::pow(ref[i].k1 + 1.0, 2) + std::pow(ref[i].k2 + 1.0, 2);
      ++n_narrow;
      EXPECT_LT(angleDeg(res[i].normal, out[i]), 0.5);
      if (n_narrow % 500 != 1) continue;
      // Exactly the fit on the 200 nearest distinct positions at the 200th distance.
      const auto d = byDistance(i);
      std::vector<int> nb;
      for (int j = 0; j < 200; ++j) nb.push_back(d[j].second);
      const auto r = paps::fitWavejet(u, nb.data(), 200, u[i], std::sqrt(d[199].first), params, *ws,
                                      Eigen::Vector3f::Constant(NAN), out[i]);
      ASSERT_TRUE(r.valid());
      // (These balls hold thousands: the 200 come from the kd-tree, checked to be the same
      // points in the same order as the whole ball's; the tolerances only allow another
      // summation order.)
      EXPECT_FLOAT_EQ(res[i].radius, std::sqrt(d[199].first));
      EXPECT_NEAR(res[i].k1, r.k1, 1e-6);
      EXPECT_NEAR(res[i].k2, r.k2, 1e-6);
      EXPECT_LT((res[i].normal - r.normal).norm(), 1e-5f);
    } else if (res[i].radius == report.radius) {
      // The ball of R_phi exactly: the same output as with widening never.
      ASSERT_EQ(res[i].k1, ref[i].k1) << i;
      ASSERT_EQ(res[i].k2, ref[i].k2) << i;
      ASSERT_EQ(res[i].normal, ref[i].normal) << i;
      ++n_exact;
      se_ball += e;
      ++n_ball;
    } else {
      // Widened (fewer than N = 50 distinct positions in the ball of R_phi): the fit on the
      // 50 nearest distinct positions at the 50th distance.
      ++n_widened;
      se_ball += e;
      ++n_ball;
      if (n_widened % 10 != 1) continue;
      ++n_widened_checked;
      const auto d = byDistance(i);
      ASSERT_GE(d[49].first, report.radius * report.radius) << i << ": the ball held 50, nothing to widen";
      std::vector<int> nb;
      for (int j = 0; j < 50; ++j) nb.push_back(d[j].second);
      const auto r = paps::fitWavejet(u, nb.data(), 50, u[i], std::sqrt(d[49].first), params, *ws,
                                      Eigen::Vector3f::Constant(NAN), out[i]);
      ASSERT_TRUE(r.valid());
      // Measured identical (the same neighbours in the same order); the tolerances only
      // allow a different summation order.
      EXPECT_FLOAT_EQ(res[i].radius, std::sqrt(d[49].first)) << i;
      EXPECT_NEAR(res[i].k1, r.k1, 1e-6) << i;
      EXPECT_NEAR(res[i].k2, r.k2, 1e-6) << i;
      EXPECT_LT((res[i].normal - r.normal).norm(), 1e-5f) << i;
    }
  }
  ASSERT_GE(n_narrow, 4000u);
  ASSERT_GT(n_exact, 0u);
  ASSERT_GT(n_widened, 0u);
  // The report counts per input point: every distinct position is there twice.
  EXPECT_EQ(report.widened, 2 * n_widened);
  std::printf("ball of R_phi exactly: %zu points, widened: %zu (%zu checked against fitWavejet)\n", n_exact,
              n_widened, n_widened_checked);
  // Truth k1 = k2 = -1 (outward normals). Measured 0.00034 on the narrowed points (full
  // ball: 0.00005, no noise here) and 0.00011 on the others.
  const double rms_narrow = std::sqrt(se_narrow / n_narrow), rms_ref = std::sqrt(se_ref / n_narrow);
  EXPECT_LT(rms_narrow, 0.002) << "full ball " << rms_ref;
  EXPECT_LT(std::sqrt(se_ball / n_ball), 0.001);
  std::printf("narrowed: %zu points, curvature RMS error %.4g (full ball %.4g); others %.4g\n", n_narrow, rms_narrow,
              rms_ref, std::sqrt(se_ball / n_ball));

  // Deterministic whatever the thread count.
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto a = paps::estimateWavejets(p, 0.f, params, nullptr, nullptr, nullptr, &out);
  omp_set_num_threads(std::max(2, threads));
  const auto b = paps::estimateWavejets(p, 0.f, params, nullptr, nullptr, nullptr, &out);
  omp_set_num_threads(threads);
  for (std::size_t i = 0; i < p.size(); ++i) {
    ASSERT_EQ(a[i].k1, b[i].k1) << i;
    ASSERT_EQ(a[i].k2, b[i].k2) << i;
    ASSERT_EQ(a[i].radius, b[i].radius) << i;
    ASSERT_EQ(a[i].normal, b[i].normal) << i;
  }

  // Under the rule of widening: an explicit radius keeps the full ball (never narrowed),
  // Widening::always narrows it too; a cap below N is raised to N.
  paps::WavejetReport explicit_r;
  paps::estimateWavejets(p, report.radius, params, &explicit_r, nullptr, nullptr, &out);
  EXPECT_EQ(explicit_r.narrowed, 0u);
  EXPECT_EQ(explicit_r.mean_neighbours, full.mean_neighbours);
  params.widening = paps::WavejetParameters::Widening::always;
  paps::WavejetReport always_r;
  paps::estimateWavejets(p, report.radius, params, &always_r, nullptr, nullptr, &out);
  EXPECT_EQ(always_r.narrowed, report.narrowed);
  params.narrowed_neighbours = 10;
  EXPECT_EQ(paps::wavejetNarrowedNeighbours(params, 50), 50);
  params.narrowed_neighbours = -1;
  EXPECT_THROW(params.validate(), paps::InvalidParameter);
}

TEST(WavejetEstimation, NarrowingInThePclClassWithWideningAlways) {
  const Positions u = denseClusterSphere(false);
  auto cloud = toCloud(u);
  paps::WavejetEstimation<pcl::PointXYZ> wj;
  wj.setInputCloud(cloud);
  paps::WavejetReport r;
  paps::estimateWavejets(u, 0.f, paps::WavejetParameters(), &r);
  wj.setRadiusSearch(r.radius);
  pcl::PointCloud<paps::PointWavejet> out;
  wj.compute(out);
  EXPECT_EQ(wj.getReport().narrowed, 0u);  // PCL's semantics by default: the full ball
  EXPECT_GT(wj.getReport().mean_neighbours, 1000.0);
  paps::WavejetParameters params;
  params.widening = paps::WavejetParameters::Widening::always;
  wj.setParameters(params);
  wj.compute(out);
  EXPECT_EQ(wj.getReport().narrowed, r.narrowed);
  EXPECT_LT(wj.getReport().mean_neighbours, 200.0);
  EXPECT_TRUE(out.is_dense);
}

// The same floats (NaN equal to NaN), field by field: a tile must give the one-piece bits.
bool sameBits(const paps::WavejetResult& a, const paps::WavejetResult& b) {
  auto same = [](const auto& x, const auto& y) { return std::memcmp(&x, &y, sizeof(x)) == 0; };
  return same(a.normal, b.normal) && same(a.direction1, b.direction1) && same(a.k1, b.k1) && same(a.k2, b.k2) &&
         same(a.mean_curvature, b.mean_curvature) && same(a.gaussian_curvature, b.gaussian_curvature) &&
         same(a.offset, b.offset) && same(a.a0, b.a0) && same(a.a1, b.a1) && a.order == b.order &&
         same(a.radius, b.radius) && a.fits == b.fits && same(a.residual, b.residual) &&
         a.converged == b.converged && a.tilt_within_noise == b.tilt_within_noise;
}

// WavejetParameters::max_tile_points: a cloud fitted in tiles gets the one-piece outputs bit
// for bit, coefficients and report included: on a sphere of uneven density stored twice (the
// sparse part widened to balls several radii wide, which reach past a tile's first halo),
// with a NaN, orientation hints and initial normals; on a sphere with a dense cluster (its
// balls narrowed, most from the kd-tree); and on a noisy height field, where the noise pilot
// selects the order and doubles the automatic radius.
TEST(WavejetEstimation, TiledFitsAreTheOnePieceFits) {
  std::size_t base = 0;
  Positions sphere = varyingDensitySphere(base);
  sphere[17] = Eigen::Vector3f::Constant(NAN);
  Positions field = heightFieldSamples([](double x, double y) { return std::sin(3 * x) * std::cos(2 * y) * 0.2; },
                                       12000, 1.0, 8);
  paps::Random rng(4);
  for (auto& x : field) x.z() += static_cast<float>(0.01 * rng.gaussian());
  const Positions cluster = denseClusterSphere(true);
  const Positions* clouds[] = {&sphere, &cluster, &field};
  for (const Positions* cloud : clouds) {
    const Positions& p = *cloud;
    paps::Normals hints(p.size()), initial(p.size(), Eigen::Vector3f::Constant(NAN));
    for (std::size_t i = 0; i < p.size(); ++i) hints[i] = cloud == &field ? Eigen::Vector3f::UnitZ() : p[i];
    for (std::size_t i = 0; i < p.size(); i += 5) initial[i] = hints[i];
    paps::WavejetParameters one, tiled;
    one.max_tile_points = 0;
    tiled.max_tile_points = 1500;
    paps::WavejetReport ra, rb;
    std::vector<paps::WavejetCoefficients> ca, cb;
    const auto a = paps::estimateWavejets(p, 0.f, one, &ra, &ca, &initial, &hints);
    const auto b = paps::estimateWavejets(p, 0.f, tiled, &rb, &cb, &initial, &hints);
    EXPECT_EQ(ra.tiles, 1u);
    EXPECT_GE(rb.tiles, 5u);
    EXPECT_LT(rb.largest_tile, p.size());  // no tile held the whole cloud
    ASSERT_EQ(a.size(), b.size());
    std::size_t valid = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      ASSERT_TRUE(sameBits(a[i], b[i])) << i << ": k1 " << a[i].k1 << " / " << b[i].k1;
      ASSERT_EQ(ca[i].order, cb[i].order) << i;
      ASSERT_EQ(ca[i].phi, cb[i].phi) << i;
      valid += a[i].valid();
    }
    EXPECT_EQ(ra.radius, rb.radius);
    EXPECT_EQ(ra.support_scale, rb.support_scale);
    EXPECT_EQ(ra.select_order, rb.select_order);
    EXPECT_EQ(ra.fitted, rb.fitted);
    EXPECT_EQ(ra.widened, rb.widened);
    EXPECT_EQ(ra.narrowed, rb.narrowed);
    EXPECT_EQ(ra.duplicates, rb.duplicates);
    EXPECT_EQ(ra.mean_neighbours, rb.mean_neighbours);
    EXPECT_EQ(ra.widened_radius_median, rb.widened_radius_median);
    EXPECT_GT(valid, p.size() * 9 / 10);
    if (cloud == &sphere) {
      EXPECT_GT(rb.grown_halos, 0u);  // the widened balls reached past the first halos
      EXPECT_GT(ra.widened, 5000u);
      EXPECT_EQ(ra.non_finite, 1u);
    } else if (cloud == &cluster) {
      EXPECT_GE(ra.narrowed, 2 * 4000u);
      EXPECT_EQ(ra.narrowed_radius_median, rb.narrowed_radius_median);
    } else {
      EXPECT_TRUE(ra.select_order);
      EXPECT_GT(ra.support_scale, 1.f);
    }
  }
}

}  // namespace features_wavejet_estimation_test
