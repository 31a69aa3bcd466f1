// Tests of paps/core/spatial_order.h: a Z-order over the finite points, ties by index.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/core/spatial_order.h>

namespace {

using paps::Positions;

TEST(SpatialOrder, FiniteIndicesOnceEach) {
  Positions p;
  paps::Random rng(3);
  for (int i = 0; i < 1000; ++i) p.emplace_back(rng.uniform(), rng.uniform(), rng.uniform());
  p[7] = Eigen::Vector3f(NAN, 0, 0);
  p[8] = Eigen::Vector3f(0, INFINITY, 0);
  std::vector<int> order = paps::spatialOrder(p);
  ASSERT_EQ(order.size(), 998u);
  std::sort(order.begin(), order.end());
  EXPECT_TRUE(std::adjacent_find(order.begin(), order.end()) == order.end());
  EXPECT_EQ(std::count(order.begin(), order.end(), 7), 0);
  EXPECT_EQ(std::count(order.begin(), order.end(), 8), 0);
}

// On an 8 x 8 x 8 lattice with three bits per axis (7 steps across the extent) the order is
// the Morton code itself: the k-th point is the code k decoded.
TEST(SpatialOrder, IsTheMortonOrderOfALattice) {
  Positions p;
  for (int z = 0; z < 8; ++z)
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x) p.emplace_back(x, y, z);
  std::reverse(p.begin(), p.end());  // not the input order
  const std::vector<int> order = paps::spatialOrder(p, 3);
  ASSERT_EQ(order.size(), 512u);
  for (int code = 0; code < 512; ++code) {
    int c[3] = {0, 0, 0};
    for (int bit = 0; bit < 3; ++bit)
      for (int a = 0; a < 3; ++a) c[a] |= ((code >> (3 * bit + a)) & 1) << bit;
    EXPECT_EQ(p[order[code]], Eigen::Vector3f(c[0], c[1], c[2])) << code;
  }
}

TEST(SpatialOrder, ConsecutivePointsAreCloseOnAShuffledSurface) {
  Positions p;
  paps::Random rng(4);
  for (int i = 0; i < 20000; ++i) {
    const double u = rng.uniform(), v = rng.uniform();
    p.emplace_back(u, v, 0.1 * std::sin(6 * u));
  }
  auto meanStep = [&](const std::vector<int>& o) {
    double s = 0;
    for (std::size_t k = 1; k < o.size(); ++k) s += (p[o[k]] - p[o[k - 1]]).norm();
    return s / (o.size() - 1);
  };
  std::vector<int> input(p.size());
  std::iota(input.begin(), input.end(), 0);
  // Input order: about 0.5 apart; Z order: a few spacings (1 / sqrt(20000) = 0.007).
  EXPECT_GT(meanStep(input), 0.4);
  EXPECT_LT(meanStep(paps::spatialOrder(p)), 0.03);
}

TEST(SpatialOrder, EdgeCases) {
  EXPECT_TRUE(paps::spatialOrder({}).empty());
  EXPECT_TRUE(paps::spatialOrder({Eigen::Vector3f(NAN, NAN, NAN)}).empty());
  const Positions same(5, Eigen::Vector3f(1, 2, 3));  // zero extent: ties by index
  EXPECT_EQ(paps::spatialOrder(same), (std::vector<int>{0, 1, 2, 3, 4}));
  EXPECT_THROW(paps::spatialOrder(same, 0), paps::InvalidParameter);
  EXPECT_THROW(paps::spatialOrder(same, 22), paps::InvalidParameter);
  EXPECT_EQ(paps::gathered(std::vector<int>{10, 20, 30}, {2, 0}), (std::vector<int>{30, 10}));
}

}  // namespace
