// Tests of paps/core/cell_grid.h: exact balls against brute force (NaNs, duplicates, empty
// cloud, tiny and huge radii), the orders documented, errors, determinism across threads.
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <omp.h>

#include <gtest/gtest.h>

#include <paps/core/cell_grid.h>
#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_cell_grid_test {

using paps::CellGrid;
using paps::NeighbourGraph;
using paps::Positions;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Uniform points in a box, with NaNs and exact duplicates mixed in.
Positions randomCloud(int count, std::uint64_t seed, float extent = 1.f) {
  paps::Random rng(seed);
  Positions p;
  for (int i = 0; i < count; ++i) {
    if (i % 17 == 5) {
      p.emplace_back(kNaN, 0.f, 0.f);
    } else if (i % 13 == 7 && !p.empty() && paps::isFinite(p.back())) {
      p.push_back(p.back());  // duplicate
    } else {
      p.emplace_back(rng.uniform3(0, extent).cast<float>());
    }
  }
  return p;
}

// Brute force: indices j with (p[j] - q)^2 <= r^2, sorted by squared distance then index.
std::vector<int> bruteBall(const Positions& p, const Eigen::Vector3f& q, float r) {
  std::vector<std::pair<float, int>> v;
  for (std::size_t j = 0; j < p.size(); ++j) {
    if (!paps::isFinite(p[j])) continue;
    const float d2 = (p[j] - q).squaredNorm();
    if (d2 <= r * r) v.emplace_back(d2, static_cast<int>(j));
  }
  std::sort(v.begin(), v.end());
  std::vector<int> out;
  for (const auto& e : v) out.push_back(e.second);
  return out;
}

TEST(CellGrid, RadiusSearchEqualsBruteForce) {
  const Positions p = randomCloud(1500, 1);
  for (const float cell : {0.05f, 0.1f, 0.37f}) {
    CellGrid grid;
    ASSERT_TRUE(grid.build(p, cell));
    EXPECT_EQ(grid.size(), paps::countFinite(p));
    // Radii below, at and above the cell side (several cells per axis).
    for (const float r : {0.5f * cell, cell, 2.5f * cell}) {
      std::vector<int> idx;
      std::vector<float> d2;
      for (std::size_t i = 0; i < p.size(); i += 7) {
        const Eigen::Vector3f q = paps::isFinite(p[i]) ? p[i] : Eigen::Vector3f(0.5f, 0.5f, 0.5f);
        grid.radiusSearch(q, r, idx, &d2);
        ASSERT_EQ(idx, bruteBall(p, q, r)) << "cell " << cell << " r " << r << " i " << i;
        for (std::size_t k = 0; k < idx.size(); ++k) EXPECT_EQ(d2[k], (p[idx[k]] - q).squaredNorm());
      }
    }
  }
}

// forEachInReach hands over the cells' points without measuring them: every point of the
// ball, each once, and nothing farther than the cells around it can hold.
TEST(CellGrid, PointsInReachHoldTheBallOnce) {
  const Positions p = randomCloud(1500, 3);
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, 0.1f));
  CellGrid::Cursor cursor;
  std::size_t extra = 0;
  for (const float r : {0.05f, 0.1f, 0.25f})
    for (std::size_t i = 0; i < p.size(); i += 11) {
      if (!paps::isFinite(p[i])) continue;
      std::vector<int> seen;
      grid.forEachInReach(p[i], r, cursor, [&](int slot) { seen.push_back(grid.original()[slot]); });
      std::sort(seen.begin(), seen.end());
      ASSERT_EQ(std::adjacent_find(seen.begin(), seen.end()), seen.end());  // each point once
      std::vector<int> ball = bruteBall(p, p[i], r);
      std::sort(ball.begin(), ball.end());
      ASSERT_TRUE(std::includes(seen.begin(), seen.end(), ball.begin(), ball.end())) << r << " " << i;
      for (int j : seen) ASSERT_LE((p[j] - p[i]).cwiseAbs().maxCoeff(), r + 2 * grid.cell()) << r << " " << i;
      extra += seen.size() - ball.size();
    }
  EXPECT_GT(extra, 0u);  // the cells' corners: not a ball
}

TEST(CellGrid, QueryGivesTheBallInCellOrder) {
  const Positions p = randomCloud(2000, 2);
  const float r = 0.08f;
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, r));
  const Positions& sorted = grid.sorted();
  for (std::size_t s = 0; s < sorted.size(); ++s)  // cell order keeps input order inside a cell
    EXPECT_EQ(sorted[s], p[grid.original()[s]]);
  CellGrid::Cursor cursor;
  std::vector<int> slots;
  for (std::size_t s = 0; s < sorted.size(); ++s) {
    grid.query(sorted[s], r, slots, cursor);
    ASSERT_TRUE(std::is_sorted(slots.begin(), slots.end()));
    std::vector<int> got;
    for (const int t : slots) got.push_back(grid.original()[t]);
    std::sort(got.begin(), got.end());
    std::vector<int> want = bruteBall(p, sorted[s], r);
    std::sort(want.begin(), want.end());
    ASSERT_EQ(got, want) << "slot " << s;
  }
  // Queries away from the cloud, from a fresh cursor each time and from a shared one.
  for (const Eigen::Vector3f q : {Eigen::Vector3f(5, 5, 5), Eigen::Vector3f(-0.05f, 0.5f, 0.5f),
                                  Eigen::Vector3f(1.07f, 1.07f, -0.07f)}) {
    CellGrid::Cursor fresh;
    grid.query(q, r, slots, fresh);
    std::vector<int> got;
    for (const int t : slots) got.push_back(grid.original()[t]);
    std::sort(got.begin(), got.end());
    std::vector<int> want = bruteBall(p, q, r);
    std::sort(want.begin(), want.end());
    EXPECT_EQ(got, want);
  }
  EXPECT_EQ(grid.query(Eigen::Vector3f(kNaN, 0, 0), r, slots, cursor), 0);
}

// Anchored grids (build(..., true)) of one cell size order the points two clouds share alike:
// a part of a cloud (every third point of a box, away from the origin, indices kept in order)
// lists them in the whole grid's relative order, and so do its queries. An unanchored grid
// keys its cells from the bounding box, so the part's order differs.
TEST(CellGrid, AnchoredGridsOrderSharedPointsAlike) {
  Positions whole = randomCloud(20000, 9, 3.f);
  for (auto& p : whole) p += Eigen::Vector3f(1000.3f, -250.7f, 12.1f);
  std::vector<int> part_ids;  // whole indices of the part, increasing
  for (std::size_t i = 0; i < whole.size(); ++i)
    if (whole[i].x() < 1001.f && i % 3 != 1) part_ids.push_back(static_cast<int>(i));
  Positions part;
  for (const int i : part_ids) part.push_back(whole[i]);
  const float cell = 0.13f;
  auto relativeOrderMatches = [&](bool anchored) {
    CellGrid a, b;
    EXPECT_TRUE(a.build(whole, cell, anchored));
    EXPECT_TRUE(b.build(part, cell, anchored));
    std::vector<int> in_whole;  // the part's points in the whole grid's order
    std::vector<char> member(whole.size(), 0);
    for (const int i : part_ids) member[i] = 1;
    for (const int i : a.original())
      if (member[i]) in_whole.push_back(i);
    std::vector<int> in_part;
    for (const int j : b.original()) in_part.push_back(part_ids[j]);
    return in_whole == in_part;
  };
  EXPECT_TRUE(relativeOrderMatches(true));
  EXPECT_FALSE(relativeOrderMatches(false));
  // Queries: the part's ball, mapped to whole indices, is the whole ball restricted to the
  // part, in the same order; and the anchored grid finds the brute-force ball.
  CellGrid a, b;
  a.build(whole, cell, true);
  b.build(part, cell, true);
  CellGrid::Cursor ca, cb;
  std::vector<int> sa, sb;
  for (std::size_t k = 0; k < part.size(); k += 97) {
    const float r = 0.21f;
    a.query(part[k], r, sa, ca);
    b.query(part[k], r, sb, cb);
    std::vector<int> from_whole, from_part;
    std::vector<char> member(whole.size(), 0);
    for (const int i : part_ids) member[i] = 1;
    for (const int s : sa)
      if (member[a.original()[s]]) from_whole.push_back(a.original()[s]);
    for (const int s : sb) from_part.push_back(part_ids[b.original()[s]]);
    ASSERT_EQ(from_whole, from_part) << k;
    std::size_t brute = 0;
    for (const auto& p : whole) brute += (p - part[k]).squaredNorm() <= r * r;
    ASSERT_EQ(sa.size(), brute) << k;
  }
}

TEST(CellGrid, HugeAndTinyRadius) {
  const Positions p = randomCloud(400, 3);
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, 0.05f));
  std::vector<int> idx;
  grid.radiusSearch(Eigen::Vector3f(0.2f, 0.3f, 0.4f), 1e6f, idx);
  EXPECT_EQ(idx.size(), paps::countFinite(p));
  EXPECT_EQ(idx, bruteBall(p, Eigen::Vector3f(0.2f, 0.3f, 0.4f), 1e6f));
  // A tiny radius finds a point and its exact duplicates only.
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!paps::isFinite(p[i])) continue;
    grid.radiusSearch(p[i], 1e-7f, idx);
    EXPECT_EQ(idx, bruteBall(p, p[i], 1e-7f));
  }
  // A cell far too small for the extent of many points: build refuses, the graph helper
  // throws (two clusters of 5,000 points a million cells apart).
  Positions wide = randomCloud(5000, 4);
  for (int i = 0; i < 5000; ++i) wide.push_back(wide[std::size_t(i)] + Eigen::Vector3f(1e6f, 0, 0));
  EXPECT_FALSE(grid.build(wide, 1e-3f));
  EXPECT_THROW(paps::gridRadiusGraph(wide, 1e-3f), paps::InvalidParameter);
}

TEST(CellGrid, FarOutliersShareTheBorderCellsAndBallsStayExact) {
  // A scan with a few stray points far beyond 2^21 cells, on every side (one at 1e30, two
  // 3e5 m away and 0.031 m apart, which must still find each other).
  Positions p = randomCloud(1500, 9);
  const float far = 3e5f;
  for (const Eigen::Vector3f& q :
       {Eigen::Vector3f(far, 0.5f, 0.5f), Eigen::Vector3f(std::nextafter(far, 1e6f), 0.5f, 0.5f),
        Eigen::Vector3f(-2e5f, 0.5f, 0.5f), Eigen::Vector3f(0.5f, -1e7f, 0.5f), Eigen::Vector3f(1e30f, 1e30f, 1e30f),
        Eigen::Vector3f(-1e30f, 0.f, 0.f), Eigen::Vector3f(0.5f, 0.5f, 4e6f)})
    p.push_back(q);
  const float r = 0.05f;
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, r));
  std::vector<int> idx;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!paps::isFinite(p[i])) continue;
    grid.radiusSearch(p[i], r, idx);
    ASSERT_EQ(idx, bruteBall(p, p[i], r)) << "point " << i;
  }
  grid.radiusSearch(p[1500], r, idx);
  EXPECT_EQ(idx.size(), 2u);  // the two stray points 3e5 m away see each other
  // Queries that are not points of the grid, far outside it too.
  for (const Eigen::Vector3f& q : {Eigen::Vector3f(far, 0.5f, 0.52f), Eigen::Vector3f(-5e29f, 1, 1)}) {
    grid.radiusSearch(q, r, idx);
    EXPECT_EQ(idx, bruteBall(p, q, r));
  }
  const NeighbourGraph g = paps::gridRadiusGraph(p, r);
  const paps::SpatialIndex index(p);
  const NeighbourGraph by_radius = NeighbourGraph::byRadius(p, index, r);
  std::vector<int> kd;
  std::vector<float> d2;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!paps::isFinite(p[i])) continue;
    std::vector<int> want = bruteBall(p, p[i], r);
    std::rotate(want.begin(), std::find(want.begin(), want.end(), int(i)), std::find(want.begin(), want.end(), int(i)) + 1);
    ASSERT_EQ(std::vector<int>(g.begin(i), g.end(i)), want) << "point " << i;
    index.radiusSearch(p[i], r, kd, d2);
    std::rotate(kd.begin(), std::find(kd.begin(), kd.end(), int(i)), std::find(kd.begin(), kd.end(), int(i)) + 1);
    ASSERT_EQ(std::vector<int>(by_radius.begin(i), by_radius.end(i)), kd) << "point " << i;
  }
}

TEST(CellGrid, EmptyAndAllNaN) {
  CellGrid grid;
  std::vector<int> idx;
  for (const Positions& p : {Positions(), Positions(5, Eigen::Vector3f(kNaN, kNaN, kNaN))}) {
    ASSERT_TRUE(grid.build(p, 0.1f));
    EXPECT_EQ(grid.size(), 0u);
    EXPECT_EQ(grid.radiusSearch(Eigen::Vector3f::Zero(), 1.f, idx), 0);
    const NeighbourGraph g = paps::gridRadiusGraph(p, 0.1f);
    EXPECT_EQ(g.size(), p.size());
    for (std::size_t i = 0; i < g.size(); ++i) EXPECT_EQ(g.count(i), 0);
  }
}

TEST(CellGrid, InvalidRadiusThrows) {
  const Positions p = randomCloud(50, 4);
  CellGrid grid;
  std::vector<int> idx;
  CellGrid::Cursor cursor;
  for (const float bad : {0.f, -1.f, kNaN, std::numeric_limits<float>::infinity()}) {
    EXPECT_THROW(grid.build(p, bad), paps::InvalidParameter);
    EXPECT_THROW(paps::gridRadiusGraph(p, bad), paps::InvalidParameter);
  }
  ASSERT_TRUE(grid.build(p, 0.1f));
  for (const float bad : {0.f, -1.f, kNaN, std::numeric_limits<float>::infinity()}) {
    EXPECT_THROW(grid.radiusSearch(p[0], bad, idx), paps::InvalidParameter);
    EXPECT_THROW(grid.query(p[0], bad, idx, cursor), paps::InvalidParameter);
  }
}

TEST(CellGrid, GraphMatchesBruteForceAndKdTree) {
  const Positions p = randomCloud(1200, 5);
  const float r = 0.11f;
  const NeighbourGraph g = paps::gridRadiusGraph(p, r);
  ASSERT_EQ(g.size(), p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    std::vector<int> got(g.begin(i), g.end(i));
    if (!paps::isFinite(p[i])) { EXPECT_TRUE(got.empty()); continue; }
    std::vector<int> want = bruteBall(p, p[i], r);
    std::rotate(want.begin(), std::find(want.begin(), want.end(), int(i)), std::find(want.begin(), want.end(), int(i)) + 1);
    ASSERT_EQ(got, want) << "point " << i;
  }
  // The open-ball graph gives the kd-tree lists (self moved first), list for list, and so
  // does NeighbourGraph::byRadius; with a cap, byRadius keeps the head of that list.
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, r));
  const NeighbourGraph open = grid.radiusGraph(p.size(), r, /*open_ball=*/true);
  const paps::SpatialIndex index(p);
  const NeighbourGraph by_radius = NeighbourGraph::byRadius(p, index, r);
  const NeighbourGraph capped = NeighbourGraph::byRadius(p, index, r, 6);
  std::vector<int> kd;
  std::vector<float> d2;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!paps::isFinite(p[i])) continue;
    index.radiusSearch(p[i], r, kd, d2);
    std::rotate(kd.begin(), std::find(kd.begin(), kd.end(), int(i)), std::find(kd.begin(), kd.end(), int(i)) + 1);
    ASSERT_EQ(std::vector<int>(open.begin(i), open.end(i)), kd) << i;
    ASSERT_EQ(std::vector<int>(by_radius.begin(i), by_radius.end(i)), kd) << i;
    // Capped: the 6 nearest, self first, exact ties (the duplicates) by index: the head of
    // the full list.
    kd.resize(std::min<std::size_t>(kd.size(), 6));
    ASSERT_EQ(std::vector<int>(capped.begin(i), capped.end(i)), kd) << i;
  }
}

TEST(CellGrid, CappedListsAreTheNearestWhereverTheDensityJumps) {
  // The capped search first looks at a reach guessed from the previous query; where the
  // density drops (a dense square beside a sparse one, copies mixed in) the guess falls short
  // and the full ball is searched. Either way each list is the cap's nearest of the ball.
  paps::Random rng(11);
  Positions p;
  for (int i = 0; i < 3000; ++i) {
    const bool dense = i % 3 != 0;
    const float x = static_cast<float>(rng.uniform(0, 1)), y = static_cast<float>(rng.uniform(0, 1));
    p.emplace_back(dense ? 0.25f * x : 0.25f + x, dense ? 0.25f * y : y, 0.001f * static_cast<float>(rng.uniform(0, 1)));
    if (i % 29 == 3) p.push_back(p.back());
  }
  const float r = 0.08f;  // sparse balls hold about 20 points, dense ones about 640
  const int cap = 25;
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, r));
  const NeighbourGraph g = grid.radiusGraph(p.size(), r, false, {}, cap);
  int full = 0, short_balls = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    std::vector<int> want = bruteBall(p, p[i], r);
    std::rotate(want.begin(), std::find(want.begin(), want.end(), int(i)), std::find(want.begin(), want.end(), int(i)) + 1);
    (want.size() > static_cast<std::size_t>(cap) ? full : short_balls)++;
    want.resize(std::min<std::size_t>(want.size(), cap));
    ASSERT_EQ(std::vector<int>(g.begin(i), g.end(i)), want) << "point " << i;
  }
  EXPECT_GT(full, 1000);       // crowded balls, capped
  EXPECT_GT(short_balls, 50);  // sparse balls, under the cap
}

TEST(CellGrid, CappedListsInACrowdedCellComeFromTheTreeUnchanged) {
  // A 1 mm cluster of 20,000 points (some stored 40 times) inside one cell of side 0.1 beside
  // a sparse square: far more than 64 x the cap in one cell, so the capped lists there come
  // from a kd-tree, checked against the scan's order; they must be the brute-force lists,
  // copies (ties at distance 0) included.
  paps::Random rng(12);
  Positions p;
  for (int i = 0; i < 20000; ++i) {
    p.emplace_back(0.001f * rng.uniform3(0, 1).cast<float>());
    if (i % 997 == 5)
      for (int c = 0; c < 39; ++c) p.push_back(p.back());
  }
  for (int i = 0; i < 2000; ++i) {
    const float y = static_cast<float>(rng.uniform(0, 1));
    p.emplace_back(0.2f + static_cast<float>(rng.uniform(0, 1)), y, 0.f);
  }
  const float r = 0.1f;
  const int cap = 25;
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, r));
  const NeighbourGraph g = grid.radiusGraph(p.size(), r, false, {}, cap);
  int checked = 0, copies_checked = 0;
  for (std::size_t i = 0; i < p.size(); i += (i < 20800 ? 13 : 1)) {
    std::vector<int> want = bruteBall(p, p[i], r);
    std::rotate(want.begin(), std::find(want.begin(), want.end(), int(i)), std::find(want.begin(), want.end(), int(i)) + 1);
    want.resize(std::min<std::size_t>(want.size(), cap));
    ASSERT_EQ(std::vector<int>(g.begin(i), g.end(i)), want) << "point " << i;
    ++checked;
    copies_checked += i > 0 && p[i] == p[i - 1];
  }
  EXPECT_GT(checked, 3000);
  EXPECT_GT(copies_checked, 5);
}

TEST(CellGrid, CappedListsOfPilesOfCopiesAreTheBruteForceLists) {
  // Positions stored many times, their copies scattered through the indices (as a merged or
  // quantised scan has them), beside ordinary points in the same cells: a pile at least as
  // large as the cap takes its list without a scan (itself, then its lowest-index copies),
  // which must be the brute-force list. Piles of exactly the cap, one less, one more, and a
  // pile whose copies are +0 and -0 (the same position) are all there.
  paps::Random rng(21);
  const int cap = 30;
  const std::vector<Eigen::Vector3f> piles = {{0.01f, 0.02f, 0.03f}, {0.02f, 0.01f, 0.f}, {0.05f, 0.05f, 0.05f},
                                              {0.3f, 0.3f, 0.3f}, {0.f, 0.07f, 0.01f}};
  const std::vector<int> sizes = {cap, cap - 1, cap + 1, 500, 3 * cap};
  Positions p;
  std::vector<int> left(sizes);
  for (int i = 0; i < 3000; ++i) {
    const float z = 0.1f * static_cast<float>(rng.uniform(0, 1)), y = 0.4f * static_cast<float>(rng.uniform(0, 1));
    p.emplace_back(0.4f * static_cast<float>(rng.uniform(0, 1)), y, z);
    const int k = static_cast<int>(rng.uniform(0, 5));
    if (left[k] > 0) {
      --left[k];
      Eigen::Vector3f q = piles[k];
      if (k == 4 && left[k] % 2) q.x() = -0.f;  // -0 and +0: one position
      p.push_back(q);
    }
  }
  for (int k = 0; k < 5; ++k) ASSERT_EQ(left[k], 0) << k;
  const float r = 0.05f;
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, r));
  const NeighbourGraph g = grid.radiusGraph(p.size(), r, false, {}, cap);
  int in_piles = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    std::vector<int> want = bruteBall(p, p[i], r);
    std::rotate(want.begin(), std::find(want.begin(), want.end(), int(i)), std::find(want.begin(), want.end(), int(i)) + 1);
    want.resize(std::min<std::size_t>(want.size(), cap));
    ASSERT_EQ(std::vector<int>(g.begin(i), g.end(i)), want) << "point " << i;
    in_piles += std::find(piles.begin(), piles.end(), p[i]) != piles.end();
  }
  EXPECT_EQ(in_piles, cap + cap - 1 + cap + 1 + 500 + 3 * cap);
}

TEST(CellGrid, OpenBallExcludesTheBoundary) {
  // Points exactly at distance 1 on a lattice: the closed ball has them, the open one not.
  Positions p;
  for (int x = 0; x < 4; ++x)
    for (int y = 0; y < 4; ++y) p.emplace_back(float(x), float(y), 0.f);
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, 1.f));
  const NeighbourGraph closed = grid.radiusGraph(p.size(), 1.f);
  const NeighbourGraph open = grid.radiusGraph(p.size(), 1.f, true);
  EXPECT_EQ(closed.count(5), 5);  // (1, 1) and its 4 lattice neighbours
  EXPECT_EQ(open.count(5), 1);
}

TEST(CellGrid, DeterministicAcrossThreadCounts) {
  const Positions p = randomCloud(5000, 6);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const NeighbourGraph one = paps::gridRadiusGraph(p, 0.06f);
  omp_set_num_threads(4);
  const NeighbourGraph four = paps::gridRadiusGraph(p, 0.06f);
  omp_set_num_threads(saved);
  ASSERT_EQ(one.size(), four.size());
  for (std::size_t i = 0; i < one.size(); ++i)
    ASSERT_EQ(std::vector<int>(one.begin(i), one.end(i)), std::vector<int>(four.begin(i), four.end(i)));
  // Rebuilding gives the same cell order.
  CellGrid a, b;
  ASSERT_TRUE(a.build(p, 0.06f));
  ASSERT_TRUE(b.build(p, 0.06f));
  EXPECT_EQ(a.original(), b.original());
}

// A graph built a block of slots at a time (the normal refresh of a large cloud): each block's
// rows are exactly those of the whole graph, capped or not, piles included; the other rows are
// empty; blocks that cover every slot give every row.
TEST(CellGrid, BlocksOfSlotsGiveTheRowsOfTheWholeGraph) {
  Positions p = randomCloud(6000, 31);
  // A pile above the cap, in a cell crowded enough (over 64 x 10 points) for the kd-tree path.
  p.insert(p.end(), 700, Eigen::Vector3f(0.5f, 0.5f, 0.5f));
  const float r = 0.08f;
  CellGrid grid;
  ASSERT_TRUE(grid.build(p, r));
  for (const int cap : {0, 10, 64}) {
    const NeighbourGraph whole = grid.radiusGraph(p.size(), r, true, {}, cap);
    std::vector<int> seen(p.size(), 0);
    for (std::size_t b = 0; b < grid.size(); b += 1000) {
      const std::size_t e = std::min(grid.size(), b + 1000);
      const NeighbourGraph block = grid.radiusGraph(p.size(), r, true, {}, cap, {}, b, e);
      std::vector<int> in_block(p.size(), 0);
      for (std::size_t s = b; s < e; ++s) in_block[grid.original()[s]] = 1;
      for (std::size_t i = 0; i < p.size(); ++i) {
        if (in_block[i]) {
          ++seen[i];
          ASSERT_EQ(std::vector<int>(block.begin(i), block.end(i)), std::vector<int>(whole.begin(i), whole.end(i)))
              << "cap " << cap << ", point " << i;
        } else {
          ASSERT_EQ(block.count(i), 0) << "cap " << cap << ", point " << i << " outside the block";
        }
      }
    }
    for (std::size_t i = 0; i < p.size(); ++i) EXPECT_EQ(seen[i], paps::isFinite(p[i]) ? 1 : 0) << i;
  }
}

}  // namespace core_cell_grid_test
