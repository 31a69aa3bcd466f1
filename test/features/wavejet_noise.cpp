// The noise-aware order policy of the Wavejets (wavejet_noise.h): the pilot's decision on
// clean and noisy surfaces of known curvature, the error of the default against the fixed
// order, explicit settings kept, determinism.
#include <cmath>
#include <cstdio>
#include <cstring>

#include <gtest/gtest.h>
#include <omp.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>
#include <paps/features/wavejet_estimation.h>
#include <paps/features/wavejet_noise.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace features_wavejet_noise_test {

using paps::Normals;
using paps::Positions;
using Policy = paps::WavejetParameters::OrderPolicy;

// `count` points uniform on the unit sphere with outward normals (true k1 = k2 = -1).
Positions unitSphere(std::size_t count, std::uint64_t seed, Normals& out) {
  paps::Random rng(seed);
  Positions p;
  out.clear();
  while (p.size() < count) {
    const Eigen::Vector3d v = rng.gaussian3().normalized();
    p.push_back(v.cast<float>());
    out.push_back(v.cast<float>());
  }
  return p;
}

// `count` points of the height field z = f(x, y) over [-1, 1]^2, normals hint +z.
template <typename F>
Positions heightField(std::size_t count, std::uint64_t seed, Normals& up, F f) {
  paps::Random rng(seed);
  Positions p;
  up.assign(count, Eigen::Vector3f::UnitZ());
  while (p.size() < count) {
    const double x = rng.uniform(-1, 1), y = rng.uniform(-1, 1);
    p.emplace_back(float(x), float(y), float(f(x, y)));
  }
  return p;
}

// z = 0.5 x^2 + 0.25 y^2 (true k at the apex: 1, 0.5).
Positions paraboloid(std::size_t count, std::uint64_t seed, Normals& up) {
  return heightField(count, seed, up, [](double x, double y) { return 0.5 * x * x + 0.25 * y * y; });
}

// z = x^3 - 3 x y^2 (monkey saddle, scaled by 0.3): cubic terms a quadric cannot follow.
Positions monkeySaddle(std::size_t count, std::uint64_t seed, Normals& up) {
  return heightField(count, seed, up, [](double x, double y) { return 0.3 * (x * x * x - 3 * x * y * y); });
}

// Isotropic Gaussian noise of `sigma` (metres).
Positions noisy(Positions p, double sigma, std::uint64_t seed) {
  paps::Random rng(seed);
  for (auto& x : p) x += rng.gaussian3().cast<float>() * float(sigma);
  return p;
}

// The radius of the default run (50 neighbours over the clean points).
float defaultRadius(const Positions& p) {
  paps::SpatialIndex index(p);
  return paps::radiusForNeighbourCount(p, index, 50);
}

// Relative curvature error on the unit sphere (outward normals: k1 = k2 = -1), points with a
// valid fit.
double sphereError(const std::vector<paps::WavejetResult>& r) {
  double se = 0;
  std::size_t n = 0;
  for (const auto& x : r) {
    if (!x.valid()) continue;
    se += (x.k1 + 1.0) * (x.k1 + 1.0) + (x.k2 + 1.0) * (x.k2 + 1.0);
    n += 2;
  }
  return std::sqrt(se / std::max<std::size_t>(n, 1));
}

TEST(WavejetNoise, CleanSurfacesKeepTheFixedOrder) {
  // Measured pilot residuals (residual / R_phi) on these clean clouds: sphere 1.6e-7,
  // paraboloid 1.4e-7, monkey saddle 1.6e-7 (float rounding), against the threshold 2e-5.
  // The core's quadric estimate reads the cubic and quartic terms of clean surfaces as
  // noise (bench: 1.1e-4 on the monkey saddle, 2.7e-4 on x^4 + y^4); the order-4 residual
  // does not.
  Normals hints;
  for (int s = 0; s < 3; ++s) {
    const Positions p = s == 0 ? unitSphere(20000, 1, hints) : s == 1 ? paraboloid(20000, 2, hints)
                                                                      : monkeySaddle(20000, 3, hints);
    paps::WavejetReport r;
    paps::estimateWavejets(p, 0.f, paps::WavejetParameters(), &r, nullptr, nullptr, &hints);
    std::printf("clean surface %d: pilot residual / R_phi %.3g\n", s, r.noise_relative);
    EXPECT_TRUE(r.noise_measured) << s;
    EXPECT_FALSE(r.select_order) << s;
    EXPECT_LT(r.noise_relative, 0.1f * paps::kWavejetCleanResidual) << s;
    EXPECT_FLOAT_EQ(r.beta, 1.1f) << s;
    EXPECT_EQ(r.support_scale, 1.f) << s;
    EXPECT_EQ(r.fitted, p.size()) << s;
  }
}

TEST(WavejetNoise, NoisySurfacesSelectTheOrderAndMeasureTheNoise) {
  // Noise of 0.1%, 0.5% and 2% of R_phi: the pilot reads it within 15% (measured 0.098,
  // 0.491, 1.965% on the sphere, 0.097, 0.486, 1.939% on the paraboloid) and the policy
  // selects the order with beta 3 at twice the automatic radius (the residual at 2 R_phi
  // over the one at R_phi measured 1.000 to 1.002: noise, not relief; ~190 neighbours).
  Normals hints;
  for (int s = 0; s < 2; ++s) {
    const Positions clean = s == 0 ? unitSphere(20000, 4, hints) : paraboloid(20000, 5, hints);
    const float r0 = defaultRadius(clean);
    for (const double q : {0.001, 0.005, 0.02}) {
      const Positions p = noisy(clean, q * r0, 77);
      paps::WavejetReport r;
      paps::estimateWavejets(p, 0.f, paps::WavejetParameters(), &r, nullptr, nullptr, &hints);
      std::printf("surface %d, noise %.2f%% of R_phi: pilot %.4f%%, scale ratio %.3f, mean neighbours %.1f\n", s, 100 * q,
                  100 * r.noise_relative, r.noise_scale_ratio, r.mean_neighbours);
      EXPECT_TRUE(r.select_order) << s << " " << q;
      EXPECT_LE(r.noise_scale_ratio, paps::kWavejetNoiseScaleRatio);
      EXPECT_FLOAT_EQ(r.beta, 3.f);
      EXPECT_NEAR(r.noise_relative, q, 0.15 * q) << s << " " << q;
      EXPECT_EQ(r.support_scale, 2.f);
      EXPECT_GT(r.mean_neighbours, 180);
      EXPECT_EQ(r.fitted, p.size());
    }
  }
}

TEST(WavejetNoise, DefaultBeatsTheFixedOrderUnderNoiseAndMatchesItWhenClean) {
  // Unit sphere, 20,000 points, R_phi ~0.1 (50 neighbours). Measured curvature RMSE (true
  // 1): 0.1% noise: fixed order 4 0.0614, default 0.0099 (ratio 0.16); 0.5%: fixed 0.308,
  // default 0.0134 (0.04). Asserted with margin: < 0.5x and < 0.2x. Clean: the default is
  // the fixed order, output identical (RMSE 1.25e-5).
  Normals hints;
  const Positions clean = unitSphere(20000, 6, hints);
  const float r0 = defaultRadius(clean);
  paps::WavejetParameters fixed;
  fixed.order_policy = Policy::fixed;
  for (const double q : {0.001, 0.005}) {
    const Positions p = noisy(clean, q * r0, 99);
    const double e_fixed = sphereError(paps::estimateWavejets(p, 0.f, fixed, nullptr, nullptr, nullptr, &hints));
    const double e_def = sphereError(paps::estimateWavejets(p, 0.f, paps::WavejetParameters(), nullptr, nullptr, nullptr, &hints));
    std::printf("sphere, noise %.2f%% of R_phi: curvature RMSE fixed order %.4f, default %.4f\n", 100 * q, e_fixed, e_def);
    EXPECT_LT(e_def, (q < 0.002 ? 0.5 : 0.2) * e_fixed) << q << ": default " << e_def << ", fixed " << e_fixed;
  }
  const auto a = paps::estimateWavejets(clean, 0.f, fixed, nullptr, nullptr, nullptr, &hints);
  const auto b = paps::estimateWavejets(clean, 0.f, paps::WavejetParameters(), nullptr, nullptr, nullptr, &hints);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].k1, b[i].k1) << i;
    ASSERT_EQ(a[i].k2, b[i].k2) << i;
    ASSERT_EQ(a[i].order, 4) << i;
  }
  std::printf("clean sphere: curvature RMSE of the default %.2e\n", sphereError(b));
  EXPECT_LT(sphereError(b), 1e-3);
}

TEST(WavejetNoise, ExplicitSettingsAreKept) {
  Normals hints;
  const Positions clean = unitSphere(20000, 8, hints);
  const float r0 = defaultRadius(clean);
  const Positions p = noisy(clean, 0.01 * r0, 5);
  paps::WavejetReport r;
  // Fixed policy: no pilot, fixed order, beta and neighbour count as given.
  paps::WavejetParameters fixed;
  fixed.order_policy = Policy::fixed;
  paps::estimateWavejets(p, 0.f, fixed, &r, nullptr, nullptr, &hints);
  EXPECT_FALSE(r.noise_measured);
  EXPECT_FALSE(r.select_order);
  EXPECT_FLOAT_EQ(r.beta, 1.1f);
  EXPECT_EQ(r.support_scale, 1.f);
  // select_order given with beta 1.1: kept (no beta 3, no growth).
  paps::WavejetParameters sel;
  sel.select_order = true;
  paps::estimateWavejets(p, 0.f, sel, &r, nullptr, nullptr, &hints);
  EXPECT_FALSE(r.noise_measured);
  EXPECT_TRUE(r.select_order);
  EXPECT_FLOAT_EQ(r.beta, 1.1f);
  EXPECT_EQ(r.support_scale, 1.f);
  // An explicit radius is kept (the policy still decides the order).
  paps::estimateWavejets(p, 0.1f, paps::WavejetParameters(), &r, nullptr, nullptr, &hints);
  EXPECT_TRUE(r.select_order);
  EXPECT_FLOAT_EQ(r.beta, 1.1f);  // no widening with a fixed ball: beta 3 would give NaN outputs
  EXPECT_FLOAT_EQ(r.radius, 0.1f);
  EXPECT_EQ(r.support_scale, 1.f);
  // No support growth when adapt_support is off (an explicit --neighbours).
  paps::WavejetParameters keep;
  keep.adapt_support = false;
  paps::estimateWavejets(p, 0.f, keep, &r, nullptr, nullptr, &hints);
  EXPECT_TRUE(r.select_order);
  EXPECT_EQ(r.support_scale, 1.f);
  // The PCL class: setOrder makes the order fixed; by default the pilot decides.
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& x : p) cloud->push_back(pcl::PointXYZ(x.x(), x.y(), x.z()));
  pcl::PointCloud<paps::PointWavejet> out;
  paps::WavejetEstimation<pcl::PointXYZ> wj;
  wj.setInputCloud(cloud);
  wj.setRadiusSearch(r0);
  wj.compute(out);
  EXPECT_TRUE(wj.getReport().noise_measured);
  EXPECT_TRUE(wj.getReport().select_order);
  wj.setOrder(4);
  wj.compute(out);
  EXPECT_FALSE(wj.getReport().noise_measured);
  EXPECT_FALSE(wj.getReport().select_order);
  wj.setSelectOrder(true);
  wj.compute(out);
  EXPECT_TRUE(wj.getReport().select_order);
  EXPECT_FLOAT_EQ(wj.getReport().beta, 1.1f);
}

TEST(WavejetNoise, DeterministicAcrossThreadCounts) {
  Normals hints;
  const Positions clean = unitSphere(20000, 9, hints);
  const Positions p = noisy(clean, 0.005 * defaultRadius(clean), 3);
  const int threads = omp_get_max_threads();
  paps::WavejetReport r1, r2;
  omp_set_num_threads(1);
  const auto a = paps::estimateWavejets(p, 0.f, paps::WavejetParameters(), &r1, nullptr, nullptr, &hints);
  omp_set_num_threads(std::max(2, threads));
  const auto b = paps::estimateWavejets(p, 0.f, paps::WavejetParameters(), &r2, nullptr, nullptr, &hints);
  omp_set_num_threads(threads);
  EXPECT_EQ(r1.noise_relative, r2.noise_relative);
  EXPECT_EQ(r1.noise_sigma, r2.noise_sigma);
  EXPECT_EQ(r1.support_scale, r2.support_scale);
  EXPECT_EQ(r1.radius, r2.radius);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(std::memcmp(a[i].normal.data(), b[i].normal.data(), sizeof(float) * 3), 0) << i;
    ASSERT_EQ(std::memcmp(&a[i].k1, &b[i].k1, sizeof(float)), 0) << i;
    ASSERT_EQ(std::memcmp(&a[i].k2, &b[i].k2, sizeof(float)), 0) << i;
    ASSERT_EQ(a[i].order, b[i].order) << i;
  }
}

TEST(WavejetNoise, BadInputThrows) {
  Normals hints;
  const Positions p = unitSphere(500, 10, hints);
  paps::SpatialIndex index(p);
  EXPECT_THROW(paps::wavejetResidualNoise(p, index, 0.f, paps::WavejetParameters(), 50), paps::InvalidParameter);
  EXPECT_THROW(paps::wavejetResidualNoise(p, index, NAN, paps::WavejetParameters(), 50), paps::InvalidParameter);
  EXPECT_THROW(paps::wavejetResidualNoise(p, index, 0.1f, paps::WavejetParameters(), 2), paps::InvalidParameter);
  EXPECT_THROW(paps::wavejetResidualNoise(p, index, 0.1f, paps::WavejetParameters(), 50, 0), paps::InvalidParameter);
  const Positions none(3, Eigen::Vector3f::Constant(NAN));
  paps::SpatialIndex empty(none);
  EXPECT_THROW(paps::wavejetResidualNoise(none, empty, 0.1f, paps::WavejetParameters(), 50), paps::InvalidInput);
}

}  // namespace features_wavejet_noise_test
