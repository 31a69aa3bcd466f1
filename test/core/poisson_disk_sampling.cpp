// Tests of paps/core/poisson_disk_sampling.h: the subset is a maximal Poisson-disk set.
#include <cmath>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/poisson_disk_sampling.h>
#include <paps/core/random.h>

namespace {
paps::Positions unitSquare(int n, std::uint64_t seed) {
  paps::Random rng(seed);
  paps::Positions p(n);
  for (auto& x : p) x = Eigen::Vector3f(rng.uniform(), rng.uniform(), 0.f);
  return p;
}
}  // namespace

TEST(PoissonDiskSubset, IsSeparatedAndCovering) {
  const paps::Positions pts = unitSquare(20000, 1);
  const float r = 0.05f;
  const auto kept = paps::poissonDiskSubset(pts, r, 7);
  ASSERT_FALSE(kept.empty());
  for (std::size_t a = 0; a < kept.size(); ++a)
    for (std::size_t b = a + 1; b < kept.size(); ++b)
      ASSERT_GE((pts[kept[a]] - pts[kept[b]]).norm(), r);
  for (const auto& p : pts) {
    float best = INFINITY;
    for (const int k : kept) best = std::min(best, (pts[k] - p).norm());
    ASSERT_LT(best, r);
  }
  // Maximal disk packings of a unit square at r = 0.05 hold between 1/(pi r^2) ~ 127
  // (disks of radius r cover) and 4/(pi r^2) ~ 509 (disks of radius r/2 disjoint) points.
  EXPECT_GT(kept.size(), 127u);
  EXPECT_LT(kept.size(), 509u);
  EXPECT_EQ(kept, paps::poissonDiskSubset(pts, r, 7));  // deterministic
}

TEST(PoissonDiskSubset, HandlesDegenerateInput) {
  EXPECT_TRUE(paps::poissonDiskSubset({}, 1.f).empty());
  paps::Positions same(100, Eigen::Vector3f(1, 2, 3));
  same.push_back(Eigen::Vector3f(NAN, 0, 0));
  const auto k = paps::poissonDiskSubset(same, 0.1f);
  ASSERT_EQ(k.size(), 1u);
  EXPECT_LT(k[0], 100);
  EXPECT_THROW(paps::poissonDiskSubset(same, 0.f), paps::InvalidParameter);
  EXPECT_THROW(paps::poissonDiskSubset(same, NAN), paps::InvalidParameter);
  paps::Positions wide{Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(1e6f, 0, 0)};
  EXPECT_THROW(paps::poissonDiskSubset(wide, 1e-6f), paps::InvalidParameter);
}

TEST(PoissonDiskSubsetOrdered, KeepsPreferredPointsFirst) {
  paps::Positions pts{Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(0.01f, 0, 0), Eigen::Vector3f(1, 0, 0)};
  const auto k = paps::poissonDiskSubsetOrdered(pts, 0.1f, {1.f, 0.f, 0.f});
  EXPECT_EQ(k, (std::vector<int>{1, 2}));
}
