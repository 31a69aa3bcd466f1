// Tests of paps/core/normal_refresh.h: the normals of a moved cloud, on shapes with known
// normals (a sphere: radial; a plane: its axis), oriented as the rule says.
#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>
#include <omp.h>

#include <paps/core/error.h>
#include <paps/core/normal_refresh.h>
#include <paps/core/random.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_normal_refresh_test {

using paps::Normals;
using paps::Positions;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

double angleDeg(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  const double c = std::max(-1.0, std::min(1.0, double(a.normalized().dot(b.normalized()))));
  return std::acos(c) * 180.0 / M_PI;
}

/// `count` nearly uniform points on the unit sphere (Fibonacci lattice): spacing about
/// sqrt(4 pi / count).
Positions unitSphere(int count) {
  Positions p;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < count; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / count, r = std::sqrt(1.0 - z * z), a = golden * i;
    p.emplace_back(float(r * std::cos(a)), float(r * std::sin(a)), float(z));
  }
  return p;
}

/// A 40 x 40 grid on z = 0, spacing 1 cm.
Positions flatGrid() {
  Positions p;
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j) p.emplace_back(0.01f * i, 0.01f * j, 0.f);
  return p;
}

constexpr float kSphereRadius = 0.2f;  // about 36 of 4000 points: spacing 0.056

TEST(NormalRefresh, SphereNormalsAreRadialAndFollowThePreviousOrientation) {
  const Positions p = unitSphere(4000);
  Normals inward(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) inward[i] = -p[i];
  const paps::NormalRefresh r = paps::refreshNormals(p, kSphereRadius, inward, {});
  ASSERT_EQ(r.normals.size(), p.size());
  EXPECT_EQ(r.refreshed, p.size());
  EXPECT_EQ(r.without_normal, 0u);
  double worst = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_NEAR(r.normals[i].norm(), 1.f, 1e-5f);
    worst = std::max(worst, angleDeg(r.normals[i], -p[i]));
    // Surface variation of a cap of half-angle 0.2 rad: small, not zero.
    EXPECT_GT(r.variation[i], 0.f);
    EXPECT_LT(r.variation[i], 0.01f);
  }
  EXPECT_LT(worst, 1.0);  // every one inward, along the radius
}

TEST(NormalRefresh, WithoutPreviousNormalsAClosedSurfaceIsOrientedOneWay) {
  // PCL's default-constructed normal, 0 0 0, is no orientation: propagation decides, and on a
  // closed surface it turns the normals outward (the highest point's normal up).
  const Positions p = unitSphere(4000);
  const Normals zero(p.size(), Eigen::Vector3f::Zero());
  const paps::NormalRefresh r = paps::refreshNormals(p, kSphereRadius, zero, {});
  for (std::size_t i = 0; i < p.size(); ++i) ASSERT_LT(angleDeg(r.normals[i], p[i]), 1.0) << "point " << i;
}

TEST(NormalRefresh, WithoutPreviousNormalsTheViewpointOrients) {
  const Positions p = flatGrid();
  const Normals none(p.size(), Eigen::Vector3f::Constant(kNaN));
  const paps::NormalRefresh below = paps::refreshNormals(p, 0.025f, none, {}, Eigen::Vector3f(0.2f, 0.2f, -3.f));
  const paps::NormalRefresh above = paps::refreshNormals(p, 0.025f, none, {}, Eigen::Vector3f(0.2f, 0.2f, 3.f));
  for (std::size_t i = 0; i < p.size(); ++i) {
    ASSERT_LT(angleDeg(below.normals[i], -Eigen::Vector3f::UnitZ()), 1e-3);
    ASSERT_LT(angleDeg(above.normals[i], Eigen::Vector3f::UnitZ()), 1e-3);
    ASSERT_NEAR(below.variation[i], 0.f, 1e-6f);  // flat
  }
}

TEST(NormalRefresh, OnlyMovedPointsChangeAndTheRestKeepTheirNormalsBitForBit) {
  const Positions p = flatGrid();
  Normals previous(p.size());
  paps::Random rng(5);
  for (auto& n : previous) {
    const float y = float(rng.gaussian());
    n = Eigen::Vector3f(float(rng.gaussian()), y, 1.f).normalized();
  }
  std::vector<std::uint8_t> moved(p.size(), 0);
  for (std::size_t i = 0; i < p.size(); i += 3) moved[i] = 1;
  const paps::NormalRefresh r = paps::refreshNormals(p, 0.025f, previous, moved);
  std::size_t changed = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (moved[i]) {
      ASSERT_LT(angleDeg(r.normals[i], Eigen::Vector3f::UnitZ()), 1e-3) << "up, as the previous normal";
      ++changed;
    } else {
      ASSERT_EQ(r.normals[i], previous[i]);
      ASSERT_TRUE(std::isnan(r.variation[i]));
    }
  }
  EXPECT_EQ(r.refreshed, changed);
}

TEST(NormalRefresh, SameNormalsWhateverTheOrderOfThePoints) {
  // Without previous normals the signs come from the propagation, whose blocks must not
  // depend on the input order.
  const Positions p = unitSphere(9000);  // more than one block of 4096
  std::vector<int> perm(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) perm[i] = int(i);
  paps::Random rng(11);
  for (std::size_t i = p.size(); i > 1; --i) std::swap(perm[i - 1], perm[rng.below(i)]);
  Positions q(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) q[i] = p[perm[i]];
  const Normals zero(p.size(), Eigen::Vector3f::Zero());
  const paps::NormalRefresh a = paps::refreshNormals(p, 0.15f, zero, {});
  const paps::NormalRefresh b = paps::refreshNormals(q, 0.15f, zero, {});
  for (std::size_t i = 0; i < p.size(); ++i) ASSERT_EQ(b.normals[i], a.normals[perm[i]]) << "point " << i;
}

TEST(NormalRefresh, SameNormalsWithOneOrTwoThreads) {
  const Positions p = unitSphere(9000);
  const Normals zero(p.size(), Eigen::Vector3f::Zero());
  omp_set_num_threads(1);
  const paps::NormalRefresh one = paps::refreshNormals(p, 0.15f, zero, {});
  omp_set_num_threads(2);
  const paps::NormalRefresh two = paps::refreshNormals(p, 0.15f, zero, {});
  for (std::size_t i = 0; i < p.size(); ++i) {
    ASSERT_EQ(one.normals[i], two.normals[i]) << i;
    ASSERT_EQ(one.variation[i], two.variation[i]) << i;
  }
}

TEST(NormalRefresh, IsolatedPointsGetNaNAndNonFiniteOnesPassThrough) {
  Positions p = flatGrid();
  p.emplace_back(5.f, 5.f, 5.f);           // alone: no normal
  p.emplace_back(kNaN, kNaN, kNaN);        // not a point
  const Normals none(p.size(), Eigen::Vector3f::Zero());
  const paps::NormalRefresh r = paps::refreshNormals(p, 0.025f, none, {});
  EXPECT_TRUE(std::isnan(r.normals[p.size() - 2].x()));
  EXPECT_EQ(r.normals[p.size() - 1], Eigen::Vector3f::Zero());  // as it was, as the filters pass it
  EXPECT_EQ(r.without_normal, 1u);  // the NaN point is not counted: it has no position
  EXPECT_EQ(r.refreshed, p.size() - 2);
  // With an input normal, the isolated point keeps it (and NaN variation: nothing new).
  Normals given(p.size(), Eigen::Vector3f::UnitZ());
  given[p.size() - 2] = Eigen::Vector3f(0.6f, 0.f, 0.8f);
  const paps::NormalRefresh k = paps::refreshNormals(p, 0.025f, given, {});
  EXPECT_EQ(k.normals[p.size() - 2], given[p.size() - 2]);
  EXPECT_TRUE(std::isnan(k.variation[p.size() - 2]));
  EXPECT_EQ(k.kept_previous, 1u);
  EXPECT_EQ(k.without_normal, 0u);
}

TEST(NormalRefresh, RadiusZeroMeansNoNeighbourhood) {
  // What a filter reports when it found none (one point, every point at one position).
  const Positions p(5, Eigen::Vector3f(1.f, 2.f, 3.f));
  Normals previous(p.size(), Eigen::Vector3f::Zero());
  previous[2] = Eigen::Vector3f::UnitY();
  const paps::NormalRefresh r = paps::refreshNormals(p, 0.f, previous, {});
  EXPECT_EQ(r.normals[2], Eigen::Vector3f::UnitY());
  EXPECT_EQ(r.kept_previous, 1u);
  EXPECT_EQ(r.without_normal, 4u);
  EXPECT_EQ(r.refreshed, 0u);
}

TEST(NormalRefresh, BadParametersAreNamed) {
  const Positions p = flatGrid();
  const Normals n(p.size(), Eigen::Vector3f::UnitZ());
  EXPECT_THROW(paps::refreshNormals(p, -0.01f, n, {}), paps::InvalidParameter);
  EXPECT_THROW(paps::refreshNormals(p, kNaN, n, {}), paps::InvalidParameter);
  EXPECT_THROW(paps::refreshNormals(p, 0.02f, Normals(3), {}), paps::InvalidParameter);
  EXPECT_THROW(paps::refreshNormals(p, 0.02f, n, std::vector<std::uint8_t>(3, 1)), paps::InvalidParameter);
  EXPECT_EQ(paps::refreshNormals({}, 0.02f, {}, {}).refreshed, 0u);
}

}  // namespace core_normal_refresh_test
