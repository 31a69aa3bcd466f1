// Tests of paps/core/spatial_order.h: a Z-order over the finite points, ties by coordinates;
// a sample of points chosen by position.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/core/spatial_order.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_spatial_order_test {

using paps::Positions;

TEST(SpatialOrder, FiniteIndicesOnceEach) {
  Positions p;
  paps::Random rng(3);
  for (int i = 0; i < 1000; ++i) p.emplace_back(rng.uniform3(0, 1).cast<float>());
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

Positions shuffledCopy(const Positions& p, std::uint64_t seed) {
  Positions q = p;
  paps::Random rng(seed);
  for (std::size_t i = q.size(); i > 1; --i) std::swap(q[i - 1], q[rng.below(i)]);
  return q;
}

// With one step per axis nearly every point shares its cell with hundreds of others: the
// order among them comes from their coordinates, so a shuffled copy gives the same sequence
// of positions.
TEST(SpatialOrder, PointsOfOneCellAreOrderedByCoordinates) {
  Positions p;
  paps::Random rng(6);
  for (int i = 0; i < 500; ++i) p.emplace_back(rng.uniform3(0, 1).cast<float>());
  p.push_back(p[3]);  // a copy
  const Positions q = shuffledCopy(p, 8);
  ASSERT_NE(p, q);
  EXPECT_EQ(paps::gathered(p, paps::spatialOrder(p, 1)), paps::gathered(q, paps::spatialOrder(q, 1)));
  EXPECT_EQ(paps::gathered(p, paps::spatialOrder(p)), paps::gathered(q, paps::spatialOrder(q)));
}

TEST(PositionSample, DependsOnThePositionsOnly) {
  Positions p;
  paps::Random rng(7);
  for (int i = 0; i < 5000; ++i) p.emplace_back(rng.uniform3(0, 1).cast<float>());
  for (int i = 0; i < 500; ++i) p.push_back(p[static_cast<std::size_t>(i) * 3]);  // copies
  p[10] = Eigen::Vector3f(NAN, 0, 0);
  const Positions q = shuffledCopy(p, 9);
  const std::vector<int> a = paps::positionSample(p, 200), b = paps::positionSample(q, 200);
  ASSERT_EQ(a.size(), 200u);
  EXPECT_EQ(paps::gathered(p, a), paps::gathered(q, b));
  std::vector<int> sorted = a;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_TRUE(std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end());
  EXPECT_EQ(std::count(a.begin(), a.end(), 10), 0);
  // Spread over the cloud: each octant of the unit cube holds about an eighth of the sample.
  int octant[8] = {};
  for (const int i : a) ++octant[(p[i].x() > 0.5f) + 2 * (p[i].y() > 0.5f) + 4 * (p[i].z() > 0.5f)];
  for (const int c : octant) EXPECT_GT(c, 10);
  // More samples than finite points: every finite point, once.
  EXPECT_EQ(paps::positionSample(p, 100000).size(), p.size() - 1);
  EXPECT_TRUE(paps::positionSample(p, 0).empty());
  // Copies of a position share its hash, whatever their index: a copy of every tenth point
  // appended, the sample of the larger cloud holds a copy exactly when it holds its original
  // (but at the sample's last hash, where the cut may fall between the two).
  EXPECT_NE(paps::positionHash(p[3]), paps::positionHash(p[4]));
  Positions with_copies = p;
  for (std::size_t i = 0; i < p.size(); i += 10) with_copies.push_back(p[i]);
  const std::vector<int> c = paps::positionSample(with_copies, 300);
  std::vector<std::uint8_t> in_sample(with_copies.size(), 0);
  for (const int i : c) in_sample[i] = 1;
  std::size_t copies_in = 0;
  const std::uint64_t last = paps::positionHash(with_copies[c.back()]);
  for (std::size_t i = 0, k = p.size(); i < p.size(); i += 10, ++k) {
    if (!paps::isFinite(p[i]) || paps::positionHash(p[i]) == last) continue;
    EXPECT_EQ(in_sample[k], in_sample[i]) << i;
    copies_in += in_sample[k];
  }
  EXPECT_GT(copies_in, 5u);
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

}  // namespace core_spatial_order_test
