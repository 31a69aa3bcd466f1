// Tests of paps/core/tiling.h: every finite point in exactly one core, halos exactly the
// points of the grown box, copies of a position kept together, tiles that depend on the
// positions only, and a local stage run in tiles equal to the same stage on the whole cloud
// when the halo covers its reach (and not when it does not).
#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/core/tiling.h>

namespace {

using paps::Positions;

Positions randomSlab(std::size_t n, std::uint64_t seed) {
  paps::Random rng(seed);
  Positions p;
  for (std::size_t i = 0; i < n; ++i)
    p.emplace_back(static_cast<float>(rng.uniform(0, 4)), static_cast<float>(rng.uniform(0, 1)),
                   static_cast<float>(rng.uniform(0, 0.1)));
  return p;
}

bool inGrownBox(const Positions& p, const std::vector<int>& core, const Eigen::Vector3f& q, float margin) {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  for (const int i : core) { lo = lo.cwiseMin(p[i]); hi = hi.cwiseMax(p[i]); }
  return (q.array() >= lo.array() - margin).all() && (q.array() <= hi.array() + margin).all();
}

// Each point moved to the mean of the points within `reach` (itself included): a local stage.
Positions meanOfBall(const Positions& p, float reach) {
  Positions out(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    int n = 0;
    for (const auto& q : p)
      if ((q - p[i]).norm() <= reach) { s += q.cast<double>(); ++n; }
    out[i] = (s / n).cast<float>();
  }
  return out;
}

TEST(Tiling, CoresPartitionTheFinitePointsAndHalosAreTheGrownBoxes) {
  Positions p = randomSlab(5000, 3);
  p[17] = Eigen::Vector3f::Constant(NAN);
  p[99].x() = INFINITY;
  const float margin = 0.05f;
  const auto tiles = paps::splitIntoTiles(p, 700, margin);
  EXPECT_EQ(tiles.size(), 8u);  // 4998 finite points halved until <= 700: 8 tiles of 624-625
  std::vector<int> owner(p.size(), -1);
  for (std::size_t t = 0; t < tiles.size(); ++t) {
    EXPECT_LE(tiles[t].core.size(), 700u);
    EXPECT_TRUE(std::is_sorted(tiles[t].core.begin(), tiles[t].core.end()));
    EXPECT_TRUE(std::is_sorted(tiles[t].halo.begin(), tiles[t].halo.end()));
    for (const int i : tiles[t].core) {
      EXPECT_EQ(owner[i], -1) << "point " << i << " in two cores";
      owner[i] = static_cast<int>(t);
    }
  }
  for (std::size_t i = 0; i < p.size(); ++i) EXPECT_EQ(owner[i] >= 0, paps::isFinite(p[i])) << i;
  for (std::size_t t = 0; t < tiles.size(); ++t) {
    const std::set<int> halo(tiles[t].halo.begin(), tiles[t].halo.end());
    std::size_t expected = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      const bool in = owner[i] >= 0 && owner[i] != static_cast<int>(t) && inGrownBox(p, tiles[t].core, p[i], margin);
      expected += in;
      EXPECT_EQ(halo.count(static_cast<int>(i)) == 1, in) << "tile " << t << " point " << i;
    }
    EXPECT_EQ(halo.size(), expected);
    EXPECT_GT(halo.size(), 0u);
  }
}

TEST(Tiling, CopiesOfAPositionStayTogetherAndTheSplitFollowsThePositionsOnly) {
  // 300 positions stored 5 times each, in a shuffled order, cut into tiles of at most 12.
  const Positions base = randomSlab(300, 8);
  Positions p;
  for (int c = 0; c < 5; ++c) p.insert(p.end(), base.begin(), base.end());
  paps::Random rng(2);
  std::vector<int> perm(p.size());
  for (std::size_t i = 0; i < perm.size(); ++i) perm[i] = static_cast<int>(i);
  for (std::size_t i = perm.size(); i > 1; --i) std::swap(perm[i - 1], perm[rng.below(i)]);
  Positions shuffled;
  for (const int i : perm) shuffled.push_back(p[i]);
  auto byPosition = [](const Positions& q, const std::vector<paps::Tile>& tiles) {
    std::map<std::tuple<float, float, float>, std::set<std::size_t>> where;
    for (std::size_t t = 0; t < tiles.size(); ++t)
      for (const int i : tiles[t].core) where[{q[i].x(), q[i].y(), q[i].z()}].insert(t);
    return where;
  };
  const auto a = paps::splitIntoTiles(p, 12, 0.f), b = paps::splitIntoTiles(shuffled, 12, 0.f);
  ASSERT_EQ(a.size(), b.size());
  const auto wa = byPosition(p, a), wb = byPosition(shuffled, b);
  ASSERT_EQ(wa.size(), 300u);
  for (const auto& [pos, t] : wa) {
    EXPECT_EQ(t.size(), 1u) << "copies of one position in several tiles";
    EXPECT_EQ(wb.at(pos), t) << "the tile of a position changed with the input order";
  }
}

TEST(Tiling, ALocalStageInTilesEqualsTheWholeRunWhenTheHaloCoversItsReach) {
  const Positions p = randomSlab(1500, 4);
  const float reach = 0.12f;
  const Positions whole = meanOfBall(p, reach);
  auto stage = [&](const Positions& q, const std::vector<std::uint8_t>& m, std::size_t) {
    EXPECT_TRUE(m.empty());
    return meanOfBall(q, reach);
  };
  const Positions covered = paps::runInTiles(p, {}, paps::splitIntoTiles(p, 300, reach), stage);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < p.size(); ++i) differ += (covered[i] - whole[i]).norm() > 1e-6f;
  EXPECT_EQ(differ, 0u);
  // Without a halo the points near the cuts lose part of their ball: the check can fail.
  const Positions bare = paps::runInTiles(p, {}, paps::splitIntoTiles(p, 300, 0.f), stage);
  differ = 0;
  for (std::size_t i = 0; i < p.size(); ++i) differ += (bare[i] - whole[i]).norm() > 1e-6f;
  EXPECT_GT(differ, 50u);
}

TEST(Tiling, MovableFlagsFollowThePointsAndNonFinitePassThrough) {
  Positions p = randomSlab(400, 5);
  p[3] = Eigen::Vector3f::Constant(NAN);
  std::vector<std::uint8_t> movable(p.size(), 0);
  for (std::size_t i = 0; i < p.size(); i += 2) movable[i] = 1;
  const auto tiles = paps::splitIntoTiles(p, 100, 0.1f);
  std::vector<std::size_t> calls;
  const Positions out = paps::runInTiles(p, movable, tiles, [&](const Positions& q, const std::vector<std::uint8_t>& m, std::size_t t) {
    calls.push_back(t);
    EXPECT_EQ(m.size(), q.size());
    Positions o = q;
    for (std::size_t k = 0; k < q.size(); ++k)
      if (m[k]) o[k].z() += 1.f;
    return o;
  });
  EXPECT_EQ(calls, (std::vector<std::size_t>{0, 1, 2, 3}));
  EXPECT_TRUE(std::isnan(out[3].x()));
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (i == 3) continue;
    EXPECT_FLOAT_EQ(out[i].z(), p[i].z() + (movable[i] ? 1.f : 0.f)) << i;
  }
}

TEST(Tiling, EdgeCasesAndErrors) {
  // One position many times over: it cannot be cut, so it is one tile above the limit.
  const Positions same(50, Eigen::Vector3f(1, 2, 3));
  const auto one = paps::splitIntoTiles(same, 10, 0.f);
  ASSERT_EQ(one.size(), 1u);
  EXPECT_EQ(one[0].core.size(), 50u);
  EXPECT_TRUE(paps::splitIntoTiles(Positions(4, Eigen::Vector3f::Constant(NAN)), 10, 1.f).empty());
  EXPECT_TRUE(paps::splitIntoTiles(Positions{}, 10, 1.f).empty());
  const Positions p = randomSlab(20, 1);
  EXPECT_THROW(paps::splitIntoTiles(p, 0, 1.f), paps::InvalidParameter);
  EXPECT_THROW(paps::splitIntoTiles(p, 10, -1.f), paps::InvalidParameter);
  EXPECT_THROW(paps::splitIntoTiles(p, 10, NAN), paps::InvalidParameter);
  const auto tiles = paps::splitIntoTiles(p, 10, 0.f);
  EXPECT_THROW(paps::runInTiles(p, std::vector<std::uint8_t>(3, 1), tiles,
                                [](const Positions& q, const std::vector<std::uint8_t>&, std::size_t) { return q; }),
               paps::InvalidParameter);
  EXPECT_THROW(paps::runInTiles(p, {}, tiles,
                                [](const Positions& q, const std::vector<std::uint8_t>&, std::size_t) {
                                  return Positions(q.begin(), q.end() - 1);
                                }),
               paps::InvalidInput);
}

}  // namespace
