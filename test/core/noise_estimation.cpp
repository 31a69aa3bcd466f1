// Tests of paps/core/noise_estimation.h: the noise of a plane and of a sphere with known
// Gaussian noise is recovered, curvature is not taken for noise, a noise slab thicker than the
// ball is handled by growing the ball (on a thinned cloud where the ball holds more points than
// a fit takes), errors, determinism across thread counts.
#include <cmath>
#include <limits>

#include <omp.h>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/random.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_noise_estimation_test {

using paps::Positions;

/// `count` points uniform on the unit square at z = 0, with Gaussian noise of `sigma`
/// (metres) on every axis.
Positions noisyPlane(int count, float sigma, std::uint64_t seed) {
  paps::Random rng(seed);
  Positions p;
  for (int i = 0; i < count; ++i) {
    const double gz = rng.gaussian();
    const double uy = rng.uniform(), gy = rng.gaussian();
    const double ux = rng.uniform(), gx = rng.gaussian();
    p.emplace_back(ux + sigma * gx, uy + sigma * gy, sigma * gz);
  }
  return p;
}

/// `count` points uniform on the sphere of `radius`, Gaussian noise of `sigma` on every axis.
Positions noisySphere(int count, float radius, float sigma, std::uint64_t seed) {
  paps::Random rng(seed);
  Positions p;
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3f d = rng.gaussian3().cast<float>();
    d.normalize();
    p.push_back(radius * d + sigma * rng.gaussian3().cast<float>());
  }
  return p;
}

TEST(EstimateNoiseLevel, RecoversTheNoiseOfAPlane) {
  for (float sigma : {0.001f, 0.003f}) {
    const Positions p = noisyPlane(50000, sigma, 3);
    const paps::SpatialIndex index(p);
    const float r = paps::radiusForNeighbourCount(p, index, 30);
    const paps::NoiseEstimate e = paps::estimateNoiseLevel(p, index, r);
    EXPECT_NEAR(e.sigma, sigma, 0.08f * sigma) << "radius " << r;
    EXPECT_GT(e.fits, 1000u);
  }
}

TEST(NoiseGrowth, NearOneOnSmoothSurfacesAboveWithReliefFinerThanTheBalls) {
  // A noisy plane and sphere: what the fits leave is the noise at both scales. The plane
  // with bumps of a wavelength of twice the ball radius: the wider fits leave the bumps too.
  const Positions plane = noisyPlane(20000, 0.003f, 5);
  const paps::SpatialIndex pi(plane);
  const float r = paps::radiusForNeighbourCount(plane, pi, 100);
  EXPECT_NEAR(paps::noiseGrowth(plane, pi, r), 1.f, 0.08f);
  const Positions sphere = noisySphere(20000, 1.f, 0.01f, 6);
  const paps::SpatialIndex si(sphere);
  EXPECT_NEAR(paps::noiseGrowth(sphere, si, paps::radiusForNeighbourCount(sphere, si, 100)), 1.f, 0.08f);
  Positions bumpy = plane;
  const float k = 3.14159265f / r;  // wavelength 2r
  for (auto& q : bumpy) q.z() += 0.02f * std::sin(k * q.x()) * std::sin(k * q.y());
  const paps::SpatialIndex bi(bumpy);
  const float growth = paps::noiseGrowth(bumpy, bi, r);
  EXPECT_GT(growth, 1.3f) << "radius " << r;
  // The sigma at r handed in is used as it is.
  const float at_r = paps::estimateNoiseLevel(bumpy, bi, r).sigma;
  EXPECT_FLOAT_EQ(paps::noiseGrowth(bumpy, bi, r, at_r), growth);
  EXPECT_FLOAT_EQ(paps::noiseGrowth(bumpy, bi, r, 2 * at_r), 0.5f * growth);
}

TEST(EstimateNoiseLevel, CleanSurfacesHaveNoNoiseWhateverTheirCurvature) {
  // A sphere of radius 0.5 sampled with about 30 neighbours a ball: the quadric absorbs the
  // curvature, so the estimate stays far below the sag of the ball (r^2 / 2R ~ 1e-3).
  const Positions p = noisySphere(50000, 0.5f, 0.f, 5);
  const paps::SpatialIndex index(p);
  const float r = paps::radiusForNeighbourCount(p, index, 30);
  const paps::NoiseEstimate e = paps::estimateNoiseLevel(p, index, r);
  EXPECT_LT(e.sigma, 0.02f * r * r / (2 * 0.5f));
  EXPECT_FLOAT_EQ(e.radius, r);
}

TEST(EstimateNoiseLevel, RecoversTheNoiseOfASphere) {
  const float sigma = 0.002f;
  const Positions p = noisySphere(50000, 0.5f, sigma, 7);
  const paps::SpatialIndex index(p);
  const float r = paps::radiusForNeighbourCount(p, index, 30);
  EXPECT_NEAR(paps::estimateNoiseLevel(p, index, r).sigma, sigma, 0.08f * sigma);
}

TEST(EstimateNoiseLevel, NoiseThickerThanTheBallGrowsTheBall) {
  // sigma = 0.6 r: at r a PCA plane is noise; the ball must grow to about 6 sigma.
  const Positions p = noisyPlane(50000, 0.006f, 9);
  const paps::SpatialIndex index(p);
  const float r = 0.01f;
  const paps::NoiseEstimate e = paps::estimateNoiseLevel(p, index, r);
  EXPECT_GT(e.radius, 5 * 0.006f);
  EXPECT_NEAR(e.sigma, 0.006f, 0.1f * 0.006f);
}

TEST(EstimateNoiseLevel, DenseCloudsUnderThickNoiseReadTheSameNoise) {
  // The previous test's noise on 20x the points: the grown ball (about 6 sigma) holds some
  // 4,500 points, more than a fit takes. Fitting on its 1,500 nearest (a ball of 0.6x the
  // radius, about 3.5 sigma, whose cap cuts the slab) read 0.0054 for 0.006; an even
  // thinning of the cloud keeps the ball's width.
  const Positions p = noisyPlane(1000000, 0.006f, 9);
  const paps::SpatialIndex index(p);
  const paps::NoiseEstimate e = paps::estimateNoiseLevel(p, index, 0.01f);
  EXPECT_GT(e.radius, 5 * 0.006f);
  EXPECT_NEAR(e.sigma, 0.006f, 0.05f * 0.006f);
}

TEST(EstimateNoiseLevel, SameResultWithAnyThreadCount) {
  const Positions p = noisySphere(20000, 0.5f, 0.003f, 11);
  const paps::SpatialIndex index(p);
  omp_set_num_threads(1);
  const paps::NoiseEstimate a = paps::estimateNoiseLevel(p, index, 0.03f);
  omp_set_num_threads(2);
  const paps::NoiseEstimate b = paps::estimateNoiseLevel(p, index, 0.03f);
  EXPECT_EQ(a.sigma, b.sigma);
  EXPECT_EQ(a.radius, b.radius);
  EXPECT_EQ(a.fits, b.fits);
}

TEST(EstimateNoiseLevel, BadInputGivesClearErrors) {
  const Positions p = noisyPlane(1000, 0.001f, 13);
  const paps::SpatialIndex index(p);
  EXPECT_THROW(paps::estimateNoiseLevel(p, index, 0.f), paps::InvalidParameter);
  EXPECT_THROW(paps::estimateNoiseLevel(p, index, std::numeric_limits<float>::quiet_NaN()),
               paps::InvalidParameter);
  EXPECT_THROW(paps::estimateNoiseLevel(p, index, 0.1f, 0), paps::InvalidParameter);
  // No ball of 1e-6 m holds 10 points.
  EXPECT_THROW(paps::estimateNoiseLevel(p, index, 1e-6f), paps::InvalidInput);
  // Fewer than 10 finite points.
  Positions few(p.begin(), p.begin() + 9);
  few.push_back(Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN()));
  const paps::SpatialIndex few_index(few);
  EXPECT_THROW(paps::estimateNoiseLevel(few, few_index, 1.f), paps::InvalidInput);
  // A pile of near-copies fills every ball within a hair's width: the thinning it asks for is
  // capped (no overflow), and the estimate still comes out.
  paps::Random rng(15);
  Positions pile = noisyPlane(500, 0.f, 17);
  for (int i = 0; i < 3000; ++i) {
    const auto z = 1e-7f * rng.gaussian(), y = 0.5f + 1e-7f * rng.gaussian();
    pile.emplace_back(0.5f + 1e-7f * rng.gaussian(), y, z);
  }
  const paps::SpatialIndex pile_index(pile);
  const paps::NoiseEstimate e = paps::estimateNoiseLevel(pile, pile_index, 0.2f);
  EXPECT_TRUE(std::isfinite(e.sigma));
  EXPECT_GE(e.sigma, 0.f);
}

}  // namespace core_noise_estimation_test
