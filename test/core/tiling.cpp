// Tests of paps/core/tiling.h: every finite point in exactly one core, halos exactly the
// points of the grown box, copies of a position kept together, tiles that depend on the
// positions only, and a local stage run in tiles equal to the same stage on the whole cloud
// when the halo covers its reach (and not when it does not).
#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/core/spatial_order.h>
#include <paps/core/tiling.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_tiling_test {

using paps::Positions;

Positions randomSlab(std::size_t n, std::uint64_t seed) {
  paps::Random rng(seed);
  Positions p;
  for (std::size_t i = 0; i < n; ++i) {
    const float z = static_cast<float>(rng.uniform(0, 0.1)), y = static_cast<float>(rng.uniform(0, 1));
    p.emplace_back(static_cast<float>(rng.uniform(0, 4)), y, z);
  }
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

// tileHalo: the halo splitIntoTiles gives, for any margin; an infinite margin is every other
// finite point; a subset of a core gets the rest of the core in its halo.
TEST(Tiling, HaloOfACoreForAnotherMargin) {
  Positions p = randomSlab(3000, 5);
  p[7] = Eigen::Vector3f::Constant(NAN);
  const auto tiles = paps::splitIntoTiles(p, 500, 0.05f);
  for (const auto& tile : tiles) EXPECT_EQ(paps::tileHalo(p, tile.core, 0.05f), tile.halo);
  const std::vector<int>& core = tiles[2].core;
  const std::vector<int> all = paps::tileHalo(p, core, INFINITY);
  EXPECT_EQ(all.size() + core.size(), p.size() - 1);
  const std::vector<int> part(core.begin(), core.begin() + 10);
  const std::vector<int> wide = paps::tileHalo(p, part, 0.3f);
  EXPECT_TRUE(std::is_sorted(wide.begin(), wide.end()));
  std::size_t expected = 0;
  for (std::size_t i = 0; i < p.size(); ++i)
    expected += paps::isFinite(p[i]) && !std::binary_search(part.begin(), part.end(), static_cast<int>(i)) &&
                inGrownBox(p, part, p[i], 0.3f);
  EXPECT_EQ(wide.size(), expected);
  EXPECT_THROW(paps::tileHalo(p, core, -1.f), paps::InvalidParameter);
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

// runSortedInTiles: the stage gets each tile in spatial order, its progress prefixed with the
// tile, and its statuses come back to the core points of the cloud; a tile with no movable
// core point and a pile of copies larger than a tile are left as they are, without a call.
// The pile lies at the far end of the cut axis, where the median falls on it: it still gets a
// tile of its own (the split used to stop there and keep the pile with 125 other points).
TEST(Tiling, SortedTilesGiveEachCorePointItsStatus) {
  Positions p = randomSlab(400, 7);
  const Eigen::Vector3f pile(10.f, 0.f, 0.f);
  p.insert(p.end(), 150, pile);
  std::vector<std::uint8_t> movable(p.size(), 1);
  const auto tiles = paps::splitIntoTiles(p, 100, 0.1f);
  std::size_t pile_tile = tiles.size(), skipped = tiles.size();
  for (std::size_t t = 0; t < tiles.size(); ++t) {
    const bool all_pile = std::all_of(tiles[t].core.begin(), tiles[t].core.end(), [&](int i) { return p[i] == pile; });
    if (all_pile) pile_tile = t;
    else if (skipped == tiles.size()) skipped = t;  // the first tile of the slab may not move
    if (!all_pile) EXPECT_LE(tiles[t].core.size(), 100u);
  }
  ASSERT_LT(pile_tile, tiles.size());
  EXPECT_EQ(tiles[pile_tile].core.size(), 150u);
  ASSERT_LT(skipped, tiles.size());
  for (const int i : tiles[skipped].core) movable[i] = 0;
  std::vector<std::size_t> calls;
  std::vector<std::string> stages;
  const paps::SortedTileStage stage = [&](const Positions& q, const std::vector<std::uint8_t>& m,
                                          std::vector<std::uint8_t>& st, std::size_t t,
                                          const paps::ProgressCallback& progress) {
    calls.push_back(t);
    EXPECT_EQ(m.size(), q.size());
    // In spatial order: ordering it again changes nothing.
    const std::vector<int> again = paps::spatialOrderAll(q);
    for (std::size_t k = 0; k < again.size(); ++k) EXPECT_EQ(again[k], static_cast<int>(k));
    progress("work", 1.f);
    st.assign(q.size(), static_cast<std::uint8_t>(10 + t));
    Positions o = q;
    for (auto& x : o) x.z() += 1.f;
    return o;
  };
  std::vector<std::uint8_t> status;
  std::size_t largest = 0;
  const Positions out = paps::runSortedInTiles(
      p, movable, tiles, stage, [&](const std::string& name, float) { stages.push_back(name); return true; }, &status,
      7, &largest);
  EXPECT_EQ(calls.size(), tiles.size() - 2);  // less the pile and the tile that may not move
  ASSERT_FALSE(stages.empty());
  EXPECT_EQ(stages[0], "tile " + std::to_string(calls[0] + 1) + "/" + std::to_string(tiles.size()) + ": work");
  std::size_t most = 0;
  for (const auto& t : tiles) most = std::max(most, t.core.size() + t.halo.size());
  EXPECT_EQ(largest, most);
  for (std::size_t t = 0; t < tiles.size(); ++t)
    for (const int i : tiles[t].core) {
      if (t == pile_tile) {
        EXPECT_EQ(status[i], 7) << i;
        EXPECT_EQ(out[i], p[i]);
      } else if (t == skipped) {
        EXPECT_EQ(status[i], 0) << i;
        EXPECT_EQ(out[i], p[i]);
      } else {
        EXPECT_EQ(status[i], 10 + t) << i;
        EXPECT_FLOAT_EQ(out[i].z(), p[i].z() + 1.f);
      }
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

// pointsAroundTile: the finite points of another scan inside the tile's core box grown by the
// margin, in increasing order; tileProgress (partProgress) prefixes the stage names and passes
// the answer on.
TEST(Tiling, PointsAroundATileAndItsProgress) {
  const Positions cloud = randomSlab(2000, 3);
  const std::vector<paps::Tile> tiles = paps::splitIntoTiles(cloud, 600, 0.1f);
  ASSERT_EQ(tiles.size(), 4u);
  Positions other = randomSlab(3000, 4);
  other.emplace_back(NAN, 0.f, 0.f);
  std::size_t seen = 0;
  for (const paps::Tile& t : tiles) {
    const std::vector<int> around = paps::pointsAroundTile(cloud, t, other, 0.1f);
    EXPECT_TRUE(std::is_sorted(around.begin(), around.end()));
    std::set<int> inside(around.begin(), around.end());
    for (std::size_t i = 0; i < other.size(); ++i)
      EXPECT_EQ(inside.count(static_cast<int>(i)) == 1,
                std::isfinite(other[i].x()) && inGrownBox(cloud, t.core, other[i], 0.1f)) << i;
    seen += around.size();
  }
  EXPECT_GT(seen, 3000u);  // the boxes overlap by their margins
  std::vector<std::string> names;
  const paps::ProgressCallback cb = [&](const std::string& name, float) {
    names.push_back(name);
    return names.size() < 2;
  };
  const paps::ProgressCallback sub = paps::tileProgress(cb, 1, 4);
  EXPECT_TRUE(sub("fits", 0.5f));
  EXPECT_FALSE(sub("fits", 1.f));
  EXPECT_EQ(names.front(), "tile 2/4: fits");
  EXPECT_FALSE(static_cast<bool>(paps::tileProgress({}, 0, 4)));
  // The same prefix for any kind of part (the denoiser's interleaved subsets).
  names.clear();
  EXPECT_TRUE(paps::partProgress(cb, "subset", 2, 3)("noise", 0.f));
  EXPECT_EQ(names.front(), "subset 3/3: noise");
  EXPECT_FALSE(static_cast<bool>(paps::partProgress({}, "subset", 0, 3)));
}

// An upsampling stage's shares: largest remainders (ties to the first part), the exact total.
TEST(Tiling, SharesInProportionAddUpToTheTotal) {
  EXPECT_EQ(paps::splitInProportion(10, {1, 1, 1}), (std::vector<std::size_t>{4, 3, 3}));
  EXPECT_EQ(paps::splitInProportion(10, {0, 2, 3}), (std::vector<std::size_t>{0, 4, 6}));
  EXPECT_EQ(paps::splitInProportion(7, {0, 0}), (std::vector<std::size_t>{0, 0}));
  EXPECT_EQ(paps::splitInProportion(0, {5, 1}), (std::vector<std::size_t>{0, 0}));
  const std::vector<std::size_t> w{7, 11, 13, 17, 19};
  const std::vector<std::size_t> s = paps::splitInProportion(1000003, w);
  std::size_t sum = 0;
  for (std::size_t t = 0; t < s.size(); ++t) {
    sum += s[t];
    EXPECT_NEAR(static_cast<double>(s[t]), 1000003.0 * static_cast<double>(w[t]) / 67.0, 1.0);
  }
  EXPECT_EQ(sum, 1000003u);
}

// Occupied cells count the surface, not the points: a 10 x 10 patch of 0.1 m cells holds 100
// cells however densely it is sampled; cells sit on the lattice of multiples of their side.
TEST(Tiling, OccupiedCellsCountTheSurfaceNotThePoints) {
  paps::Positions p;
  std::vector<int> sparse, dense;
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j) {
      dense.push_back(static_cast<int>(p.size()));
      if (i % 4 == 0 && j % 4 == 0) sparse.push_back(static_cast<int>(p.size()));
      p.emplace_back(0.0125f + 0.025f * i, 0.0125f + 0.025f * j, 0.05f);
    }
  EXPECT_EQ(paps::occupiedCells(p, dense, 0.1f), 100u);
  EXPECT_EQ(paps::occupiedCells(p, sparse, 0.1f), 100u);
  EXPECT_EQ(paps::occupiedCells(p, {0}, 0.1f), 1u);
  EXPECT_EQ(paps::occupiedCells(p, {}, 0.1f), 0u);
  EXPECT_EQ(paps::occupiedCells(p, dense, 0.5f), 4u);
}

// Tiles without surface hand their shares on; when the last ones have none, the last tile
// that made points runs again with them; the total is kept; none anywhere: nothing made.
TEST(Tiling, TileSharesCarryOverTilesWithoutSurface) {
  struct Run {
    std::vector<bool> surface;
    std::vector<std::pair<std::size_t, std::size_t>> calls;  // (tile, count)
    std::vector<std::size_t> undone;
    std::size_t made = 0;
    std::vector<std::size_t> go(const std::vector<std::size_t>& shares) {
      std::vector<std::size_t> per(shares.size(), 0);
      const std::vector<std::size_t> tiles = paps::runTileShares(
          shares,
          [&](std::size_t t, std::size_t count) {
            calls.push_back({t, count});
            if (!surface[t]) return false;
            per[t] = count;
            made += count;
            return true;
          },
          [&](std::size_t t) {
            undone.push_back(t);
            made -= per[t];
          });
      return tiles;
    }
  };
  Run a{{true, false, true, false, false}};
  EXPECT_EQ(a.go({3, 4, 5, 6, 0}), (std::vector<std::size_t>{0, 2}));
  EXPECT_EQ(a.calls, (std::vector<std::pair<std::size_t, std::size_t>>{{0, 3}, {1, 4}, {2, 9}, {3, 6}, {4, 6}, {2, 15}}));
  EXPECT_EQ(a.undone, (std::vector<std::size_t>{2}));
  EXPECT_EQ(a.made, 18u);
  Run b{{false, true}};
  EXPECT_EQ(b.go({2, 0}), (std::vector<std::size_t>{1}));  // a zero share still takes the carried part
  EXPECT_EQ(b.made, 2u);
  Run c{{false, false}};
  EXPECT_TRUE(c.go({2, 3}).empty());
  EXPECT_TRUE(c.undone.empty());
  Run d{{true, true}};
  EXPECT_EQ(d.go({0, 5}), (std::vector<std::size_t>{1}));  // a tile with nothing to make is not run
  EXPECT_EQ(d.calls.size(), 1u);
}

}  // namespace core_tiling_test
