// Tests of paps/core/neighbourhood.h: the spatial index against brute force, the neighbour
// graphs, the automatic radius, errors and determinism across thread counts.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <limits>
#include <set>
#include <vector>

#include <omp.h>

#include <gtest/gtest.h>

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>

#include "../common/peak_allocation.h"

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_neighbourhood_test {

using paps::NeighbourGraph;
using paps::Positions;
using paps::SpatialIndex;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// `count` points uniform in the unit cube; every `nan_every`-th one (0: none) is NaN in
/// one coordinate (the coordinate cycles), so the index must skip them.
Positions randomPoints(int count, std::uint64_t seed, int nan_every) {
  paps::Random rng(seed);
  Positions p;
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3f x = rng.uniform3(0, 1).cast<float>();
    if (nan_every > 0 && i % nan_every == nan_every - 1) x[(i / nan_every) % 3] = kNaN;
    p.push_back(x);
  }
  return p;
}

/// `count` points uniform on the square [0, 1]^2 at z = 0.
Positions randomPlane(int count, std::uint64_t seed) {
  paps::Random rng(seed);
  Positions p;
  for (int i = 0; i < count; ++i) {
    const double y = rng.uniform();
    p.emplace_back(rng.uniform(), y, 0.f);
  }
  return p;
}

float squaredDistance(const Eigen::Vector3f& a, const Eigen::Vector3f& b) { return (a - b).squaredNorm(); }

/// Brute force: (squared distance, index) of every finite point, sorted.
std::vector<std::pair<float, int>> bruteForce(const Positions& p, const Eigen::Vector3f& q) {
  std::vector<std::pair<float, int>> all;
  for (std::size_t i = 0; i < p.size(); ++i)
    if (paps::isFinite(p[i])) all.emplace_back(squaredDistance(p[i], q), static_cast<int>(i));
  std::sort(all.begin(), all.end());
  return all;
}

std::vector<int> listOf(const NeighbourGraph& g, std::size_t i) { return {g.begin(i), g.end(i)}; }

// ----------------------------------------------------------------------- SpatialIndex

TEST(SpatialIndex, CoordinatesBeyondFloatSafetyAreRefused) {
  // Random float bit patterns (what a misaligned binary file reads as): finite values up to
  // 3.4e38, where the tree's float arithmetic overflowed and FLANN aborted the process. The
  // index names the first such point instead; up to kMaxCoordinate it is built.
  paps::Random rng(21);
  Positions p;
  for (int i = 0; i < 400; ++i) {
    Eigen::Vector3f v;
    for (int a = 0; a < 3; ++a) {
      std::uint32_t bits = static_cast<std::uint32_t>(rng.next());
      std::memcpy(&v[a], &bits, 4);
    }
    p.push_back(v);
  }
  try {
    const SpatialIndex index(p);
    ADD_FAILURE() << "built";
  } catch (const paps::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("beyond"), std::string::npos) << e.what();
  }
  const Positions edge = {{0, 0, 0}, {paps::kMaxCoordinate, 0, 0}, {0, -paps::kMaxCoordinate, 1}};
  const SpatialIndex ok(edge);
  EXPECT_EQ(ok.size(), 3u);
}

TEST(SpatialIndex, SizeCountsFinitePointsOnly) {
  const Positions p = randomPoints(1000, 1, 7);
  const SpatialIndex index(p);
  EXPECT_EQ(index.size(), paps::countFinite(p));
  EXPECT_EQ(index.size(), 1000u - 1000u / 7u);
}

TEST(SpatialIndex, RadiusSearchMatchesBruteForce) {
  const Positions p = randomPoints(3000, 2, 5);
  const SpatialIndex index(p);
  paps::Random rng(20);
  std::vector<int> idx;
  std::vector<float> d2;
  for (int t = 0; t < 200; ++t) {
    const Eigen::Vector3f q = rng.uniform3(-0.1, 1.1).cast<float>();
    const float r = static_cast<float>(rng.uniform(0.02, 0.2));
    const float r2 = r * r;
    const int n = index.radiusSearch(q, r, idx, d2);
    ASSERT_EQ(n, static_cast<int>(idx.size()));
    ASSERT_EQ(idx.size(), d2.size());
    // Every returned point is finite, within the radius, its distance is right, sorted.
    std::set<int> got;
    for (int k = 0; k < n; ++k) {
      ASSERT_GE(idx[k], 0);
      ASSERT_LT(idx[k], static_cast<int>(p.size()));
      ASSERT_TRUE(paps::isFinite(p[idx[k]])) << "NaN point " << idx[k] << " returned";
      EXPECT_NEAR(d2[k], squaredDistance(p[idx[k]], q), 1e-6f);
      EXPECT_LE(d2[k], r2 * (1 + 1e-5f));
      if (k > 0) EXPECT_LE(d2[k - 1], d2[k]);
      got.insert(idx[k]);
    }
    EXPECT_EQ(got.size(), idx.size()) << "duplicate indices";
    // Every point clearly inside is returned; nothing clearly outside is.
    std::size_t inside = 0;
    for (const auto& [dist2, i] : bruteForce(p, q)) {
      if (dist2 < r2 * (1 - 1e-5f)) {
        ++inside;
        EXPECT_TRUE(got.count(i)) << "point " << i << " at distance " << std::sqrt(dist2)
                                  << " missing for radius " << r;
      }
    }
    EXPECT_GE(got.size(), inside);
    EXPECT_LE(got.size(), inside + 1);  // at most a point exactly on the sphere
  }
}

TEST(SpatialIndex, RadiusSearchMaxCountKeepsTheNearest) {
  const Positions p = randomPoints(2000, 3, 4);
  const SpatialIndex index(p);
  std::vector<int> idx;
  std::vector<float> d2;
  for (int t = 0; t < 50; ++t) {
    const Eigen::Vector3f q = p[t * 13 % 1500].allFinite() ? p[t * 13 % 1500] : Eigen::Vector3f(0.5f, 0.5f, 0.5f);
    const int all = index.radiusSearch(q, 0.3f, idx, d2);
    ASSERT_GT(all, 10);
    const int n = index.radiusSearch(q, 0.3f, idx, d2, 10);
    ASSERT_EQ(n, 10);
    const auto brute = bruteForce(p, q);
    for (int k = 0; k < n; ++k) EXPECT_NEAR(d2[k], brute[k].first, 1e-6f) << "rank " << k;
  }
}

TEST(SpatialIndex, NearestKMatchesBruteForce) {
  const Positions p = randomPoints(3000, 4, 6);
  const SpatialIndex index(p);
  paps::Random rng(40);
  std::vector<int> idx;
  std::vector<float> d2;
  for (int t = 0; t < 200; ++t) {
    const Eigen::Vector3f q = rng.uniform3(-0.1, 1.1).cast<float>();
    const int k = 1 + static_cast<int>(rng.below(40));
    const int n = index.nearestK(q, k, idx, d2);
    ASSERT_EQ(n, k);
    ASSERT_EQ(idx.size(), static_cast<std::size_t>(k));
    const auto brute = bruteForce(p, q);
    std::set<int> expected, got(idx.begin(), idx.end());
    for (int j = 0; j < k; ++j) expected.insert(brute[j].second);
    for (int j = 0; j < k; ++j) {
      ASSERT_TRUE(paps::isFinite(p[idx[j]]));
      EXPECT_NEAR(d2[j], squaredDistance(p[idx[j]], q), 1e-6f);
      EXPECT_NEAR(d2[j], brute[j].first, 1e-6f) << "rank " << j;
    }
    // Random data: ties at the k-th distance have probability zero.
    EXPECT_EQ(got, expected);
  }
}

TEST(SpatialIndex, SameResultsAsPclKdTreeFlannAmongTies) {
  // The index runs FLANN's tree itself (without PCL's copies): every list, in its order,
  // must be what pcl::KdTreeFLANN gives. A lattice with every point stored twice makes many
  // equal distances, where only the same tree and search break ties alike.
  Positions p;
  for (int x = 0; x < 12; ++x)
    for (int y = 0; y < 12; ++y)
      for (int z = 0; z < 6; ++z) p.emplace_back(0.1f * float(x), 0.1f * float(y), 0.1f * float(z));
  const std::size_t lattice = p.size();
  for (std::size_t i = 0; i < lattice; i += 2) p.push_back(p[i]);
  p.emplace_back(kNaN, 0.f, 0.f);
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  std::vector<int> finite;
  for (std::size_t i = 0; i < p.size(); ++i)
    if (paps::isFinite(p[i])) {
      cloud->push_back(pcl::PointXYZ(p[i].x(), p[i].y(), p[i].z()));
      finite.push_back(static_cast<int>(i));
    }
  pcl::KdTreeFLANN<pcl::PointXYZ> pcl_tree(/*sorted=*/true);
  pcl_tree.setInputCloud(cloud);
  const SpatialIndex index(p);
  std::vector<int> ours, theirs;
  std::vector<float> d_ours, d_theirs;
  pcl::Indices idx;
  std::size_t compared = 0;
  for (std::size_t i = 0; i < lattice; i += 7) {
    const Eigen::Vector3f q = p[i] + Eigen::Vector3f(0.f, 0.f, i % 2 ? 0.f : 0.05f);
    const pcl::PointXYZ pq(q.x(), q.y(), q.z());
    // k past FLANN's heap threshold (250) too; the index keeps a result set per thread
    // between queries, so the bounds change from query to query.
    for (const int k : {1, 7, 27, 60, 300, 7}) {
      index.nearestK(q, k, ours, d_ours);
      pcl_tree.nearestKSearch(pq, k, idx, d_theirs);
      theirs.clear();
      for (const auto j : idx) theirs.push_back(finite[j]);
      ASSERT_EQ(ours, theirs) << "k " << k << " at " << i;
      ASSERT_EQ(d_ours, d_theirs);
      ++compared;
    }
    for (const auto& [radius, cap] : {std::pair<float, int>{0.2f, 0}, {0.2f, 5}, {0.2f, 40}, {0.35f, 0}, {0.35f, 40},
                                      {0.2f, 0}}) {
      index.radiusSearch(q, radius, ours, d_ours, cap);
      pcl_tree.radiusSearch(pq, radius, idx, d_theirs, cap);
      theirs.clear();
      for (const auto j : idx) theirs.push_back(finite[j]);
      ASSERT_EQ(ours, theirs) << "radius " << radius << ", cap " << cap << " at " << i;
      ASSERT_EQ(d_ours, d_theirs);
      ++compared;
    }
  }
  EXPECT_GT(compared, 500u);
}

TEST(MeanNearestNeighbourDistance, IsTheGridStepAndSkipsNonFinitePoints) {
  Positions grid;
  for (int j = 0; j < 10; ++j)
    for (int i = 0; i < 10; ++i) grid.emplace_back(0.05f * i, 0.05f * j, 0.f);
  grid.emplace_back(NAN, 0.f, 0.f);
  EXPECT_NEAR(paps::meanNearestNeighbourDistance(grid, SpatialIndex(grid)), 0.05, 1e-6);
  // A copy of one point: that pair counts 0, the mean drops by 2 x 0.05 / 101.
  grid.push_back(grid[0]);
  EXPECT_NEAR(paps::meanNearestNeighbourDistance(grid, SpatialIndex(grid)), 0.05 * 99 / 101, 1e-6);
  const Positions one{Eigen::Vector3f::Zero(), Eigen::Vector3f::Constant(NAN)};
  EXPECT_THROW(paps::meanNearestNeighbourDistance(one, SpatialIndex(one)), paps::InvalidInput);
}

TEST(SpatialIndex, NearestKReturnsAtMostTheFinitePoints) {
  Positions p = {{0, 0, 0}, {kNaN, 0, 0}, {1, 0, 0}, {0, kNaN, kNaN}, {0, 2, 0}};
  const SpatialIndex index(p);
  std::vector<int> idx;
  std::vector<float> d2;
  EXPECT_EQ(index.nearestK(Eigen::Vector3f(0.1f, 0, 0), 10, idx, d2), 3);
  EXPECT_EQ(idx, (std::vector<int>{0, 2, 4}));
  EXPECT_NEAR(d2[2], 0.01f + 4.f, 1e-6f);
  EXPECT_EQ(index.nearestK(Eigen::Vector3f(0.1f, 0, 0), 0, idx, d2), 0);
  EXPECT_TRUE(idx.empty());
  // A non-finite query finds nothing.
  EXPECT_EQ(index.nearestK(Eigen::Vector3f(kNaN, 0, 0), 2, idx, d2), 0);
  EXPECT_EQ(index.radiusSearch(Eigen::Vector3f(kNaN, 0, 0), 5.f, idx, d2), 0);
}

TEST(SpatialIndex, EmptyAndAllNaNIndexFindNothing) {
  std::vector<int> idx{7};
  std::vector<float> d2{1.f};
  const SpatialIndex empty(Positions{});
  EXPECT_EQ(empty.size(), 0u);
  EXPECT_EQ(empty.radiusSearch(Eigen::Vector3f::Zero(), 1.f, idx, d2), 0);
  EXPECT_TRUE(idx.empty());
  const SpatialIndex nan(Positions(5, Eigen::Vector3f::Constant(kNaN)));
  EXPECT_EQ(nan.size(), 0u);
  EXPECT_EQ(nan.nearestK(Eigen::Vector3f::Zero(), 3, idx, d2), 0);
}

// --------------------------------------------------------------------- NeighbourGraph

TEST(NeighbourGraph, ByRadiusSelfFirstSymmetricAndNaNEmpty) {
  const Positions p = randomPoints(3000, 5, 9);
  const SpatialIndex index(p);
  const float r = 0.08f;
  const NeighbourGraph g = NeighbourGraph::byRadius(p, index, r);
  ASSERT_EQ(g.size(), p.size());
  std::vector<std::set<int>> sets(p.size());
  std::vector<int> idx;
  std::vector<float> d2;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!paps::isFinite(p[i])) {
      EXPECT_EQ(g.count(i), 0) << "NaN point " << i;
      continue;
    }
    ASSERT_GE(g.count(i), 1);
    EXPECT_EQ(*g.begin(i), static_cast<int>(i)) << "self must come first";
    sets[i] = std::set<int>(g.begin(i), g.end(i));
    EXPECT_EQ(sets[i].size(), static_cast<std::size_t>(g.count(i)));
    // The same set as a direct search.
    index.radiusSearch(p[i], r, idx, d2);
    EXPECT_EQ(sets[i], std::set<int>(idx.begin(), idx.end()));
    for (int j : sets[i]) EXPECT_TRUE(paps::isFinite(p[j]));
  }
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < p.size(); ++i)
    for (int j : sets[i]) {
      EXPECT_TRUE(sets[j].count(static_cast<int>(i))) << i << " -> " << j << " but not back";
      ++pairs;
    }
  EXPECT_GT(pairs, 3 * p.size());  // the test is not vacuous: points have neighbours
}

TEST(NeighbourGraph, ByRadiusMaxCount) {
  const Positions p = randomPoints(2000, 6, 0);
  const SpatialIndex index(p);
  const NeighbourGraph all = NeighbourGraph::byRadius(p, index, 0.15f);
  const NeighbourGraph capped = NeighbourGraph::byRadius(p, index, 0.15f, 8);
  std::size_t capped_points = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_EQ(capped.count(i), std::min(all.count(i), 8));
    EXPECT_EQ(*capped.begin(i), static_cast<int>(i));
    capped_points += all.count(i) > 8;
  }
  EXPECT_GT(capped_points, p.size() / 2);
}

TEST(NeighbourGraph, ByCountSelfFirstAndExactCount) {
  const Positions p = randomPoints(2000, 7, 11);
  const SpatialIndex index(p);
  const NeighbourGraph g = NeighbourGraph::byCount(p, index, 12);
  ASSERT_EQ(g.size(), p.size());
  std::vector<int> idx;
  std::vector<float> d2;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!paps::isFinite(p[i])) {
      EXPECT_EQ(g.count(i), 0);
      continue;
    }
    ASSERT_EQ(g.count(i), 12);
    EXPECT_EQ(*g.begin(i), static_cast<int>(i));
    const auto brute = bruteForce(p, p[i]);
    std::set<int> expected;
    for (int k = 0; k < 12; ++k) expected.insert(brute[k].second);
    EXPECT_EQ(std::set<int>(g.begin(i), g.end(i)), expected);
  }
  EXPECT_DOUBLE_EQ(g.meanCount(), 12.0);
}

// The k-nearest graph holds 4 bytes a neighbour and 8 a point; building it should not hold
// much more. Lists per point held 88 bytes a point more at k = 12 (at 20M points, 1.8 GB
// beside the graph's 1.1 GB, the peak of `paps curvature`).
TEST(NeighbourGraph, ByCountHoldsLittleMoreThanTheGraph) {
  if (!paps::test::allocationCounted()) GTEST_SKIP() << "operator new not counted in this build";
  const Positions p = randomPoints(100000, 7, 23);
  const SpatialIndex index(p);
  paps::test::resetAllocationPeak();
  const NeighbourGraph g = NeighbourGraph::byCount(p, index, 12);
  const std::size_t peak = paps::test::allocationPeakSinceReset();
  const double graph_bytes = 12.0 * 4 * index.size() + 8.0 * (p.size() + 1);
  std::printf("byCount, 100K points, k = 12: peak %.1f MB for a graph of %.1f MB (%.2fx)\n", peak / 1e6,
              graph_bytes / 1e6, peak / graph_bytes);
  EXPECT_LT(peak, 1.5 * graph_bytes);
  EXPECT_DOUBLE_EQ(g.meanCount(), 12.0);
}

TEST(NeighbourGraph, ByCountWithFewerPointsThanK) {
  const Positions p = {{0, 0, 0}, {1, 0, 0}, {kNaN, kNaN, kNaN}, {0, 1, 0}};
  const SpatialIndex index(p);
  const NeighbourGraph g = NeighbourGraph::byCount(p, index, 10);
  EXPECT_EQ(g.count(0), 3);
  EXPECT_EQ(g.count(2), 0);
  EXPECT_EQ(listOf(g, 3).front(), 3);
  EXPECT_DOUBLE_EQ(g.meanCount(), 3.0);
}

TEST(NeighbourGraph, SelfFirstAmongExactDuplicates) {
  // Five copies of the same point and one apart: each copy must list itself first.
  Positions p(5, Eigen::Vector3f(0.25f, 0.5f, 0.75f));
  p.emplace_back(0.3f, 0.5f, 0.75f);
  const SpatialIndex index(p);
  for (const NeighbourGraph& g :
       {NeighbourGraph::byRadius(p, index, 0.01f), NeighbourGraph::byCount(p, index, 6)}) {
    for (std::size_t i = 0; i < 5; ++i) {
      EXPECT_EQ(*g.begin(i), static_cast<int>(i));
      EXPECT_EQ(std::set<int>(g.begin(i), g.end(i)).size(), static_cast<std::size_t>(g.count(i)));
    }
  }
  EXPECT_EQ(NeighbourGraph::byRadius(p, index, 0.01f).count(5), 1);
}

TEST(NeighbourGraph, SelfFirstAmongDuplicatesBeyondTheCap) {
  // Regression: self was once moved to the front only when the capped query returned it;
  // with more exact duplicates than max_count (byRadius) or k (byCount) the query may return
  // other copies only, and 8 of these 12 lists did not start with their point. Fixed: the
  // kd-tree path puts self first (putSelfFirst, neighbourhood.cpp) and so do the cell grid's
  // lists that byRadius uses (cell_grid.cpp).
  // More exact copies than the list may hold: the list must still start with the point
  // itself (the header promises self first; the denoiser drops element 0 as "self").
  const Positions p(12, Eigen::Vector3f(0.25f, 0.5f, 0.75f));
  const SpatialIndex index(p);
  const NeighbourGraph by_radius = NeighbourGraph::byRadius(p, index, 0.01f, 4);
  const NeighbourGraph by_count = NeighbourGraph::byCount(p, index, 4);
  std::size_t radius_bad = 0, count_bad = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    ASSERT_EQ(by_radius.count(i), 4);
    ASSERT_EQ(by_count.count(i), 4);
    radius_bad += *by_radius.begin(i) != static_cast<int>(i);
    count_bad += *by_count.begin(i) != static_cast<int>(i);
  }
  EXPECT_EQ(radius_bad, 0u) << "points whose capped radius list does not start with themselves";
  EXPECT_EQ(count_bad, 0u) << "points whose k-nearest list does not start with themselves";
}

TEST(NeighbourGraph, MeanCountIgnoresEmptyLists) {
  const Positions p = {{0, 0, 0}, {0.1f, 0, 0}, {kNaN, 0, 0}, {5, 5, 5}};
  const SpatialIndex index(p);
  const NeighbourGraph g = NeighbourGraph::byRadius(p, index, 0.5f);
  EXPECT_EQ(g.count(0), 2);
  EXPECT_EQ(g.count(1), 2);
  EXPECT_EQ(g.count(2), 0);
  EXPECT_EQ(g.count(3), 1);
  EXPECT_DOUBLE_EQ(g.meanCount(), 5.0 / 3.0);
  EXPECT_DOUBLE_EQ(NeighbourGraph().meanCount(), 0.0);
  EXPECT_EQ(NeighbourGraph().size(), 0u);
}

TEST(RadiusNeighbourhood, AnExplicitRadiusWiderThanTheCloudIsRefused) {
  // A ball wider than the cloud's diagonal holds all of it, at quadratic cost: refused with
  // the extent in the message; up to the diagonal itself it is used as given; NaN points and
  // a one-position cloud (extent 0) are left to the other checks.
  Positions p = randomPoints(200, 9, 0);
  p.emplace_back(kNaN, 0.f, 0.f);
  const float diagonal = paps::boundingBoxDiagonal(p);
  try {
    paps::buildRadiusNeighbourhood(p, 1.01f * diagonal, 30);
    ADD_FAILURE() << "accepted";
  } catch (const paps::InvalidParameter& e) {
    EXPECT_EQ(e.parameter(), "radius");
    EXPECT_NE(std::string(e.what()).find("at most the extent of the cloud"), std::string::npos) << e.what();
  }
  EXPECT_EQ(paps::buildRadiusNeighbourhood(p, diagonal, 30).graph.count(0), 200);
  EXPECT_NO_THROW(paps::requireRadiusWithinExtent("radius", 5.f, Positions(3, Eigen::Vector3f(1, 2, 3))));
}

TEST(NeighbourGraph, InvalidRadiusAndCount) {
  const Positions p = randomPoints(50, 8, 0);
  const SpatialIndex index(p);
  for (float r : {0.f, -1.f, kNaN, std::numeric_limits<float>::infinity()}) {
    try {
      NeighbourGraph::byRadius(p, index, r);
      ADD_FAILURE() << "radius " << r << " accepted";
    } catch (const paps::InvalidParameter& e) {
      EXPECT_EQ(e.parameter(), "radius");
    }
  }
  for (int k : {0, -3}) {
    try {
      NeighbourGraph::byCount(p, index, k);
      ADD_FAILURE() << "k " << k << " accepted";
    } catch (const paps::InvalidParameter& e) {
      EXPECT_EQ(e.parameter(), "k");
    }
  }
}

TEST(NeighbourGraph, ProgressCallbackCancels) {
  const Positions p = randomPoints(5000, 9, 0);
  const SpatialIndex index(p);
  int calls = 0;
  auto stop = [&](const std::string&, float) { return ++calls < 2; };
  EXPECT_THROW(NeighbourGraph::byRadius(p, index, 0.05f, 0, stop), paps::Cancelled);
  EXPECT_GE(calls, 2);
  float last = -1.f;
  bool monotone = true;
  auto watch = [&](const std::string&, float f) {
    monotone = monotone && f >= last;
    last = f;
    return true;
  };
  NeighbourGraph::byCount(p, index, 5, watch);
  EXPECT_TRUE(monotone);
  EXPECT_FLOAT_EQ(last, 1.f);
}

TEST(NeighbourGraph, SameResultWithOneOrTwoThreads) {
  const Positions p = randomPoints(20000, 10, 13);
  const SpatialIndex index(p);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const NeighbourGraph r1 = NeighbourGraph::byRadius(p, index, 0.04f, 40);
  const NeighbourGraph k1 = NeighbourGraph::byCount(p, index, 9);
  omp_set_num_threads(2);
  const NeighbourGraph r2 = NeighbourGraph::byRadius(p, index, 0.04f, 40);
  const NeighbourGraph k2 = NeighbourGraph::byCount(p, index, 9);
  omp_set_num_threads(saved);
  ASSERT_EQ(r1.size(), r2.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    ASSERT_EQ(listOf(r1, i), listOf(r2, i)) << "radius graph differs at point " << i;
    ASSERT_EQ(listOf(k1, i), listOf(k2, i)) << "k graph differs at point " << i;
  }
}

// --------------------------------------------------------------- automatic radius

TEST(RadiusForNeighbourCount, UniformPlaneHitsTheTarget) {
  const Positions p = randomPlane(20000, 11);
  const SpatialIndex index(p);
  for (int target : {10, 30, 80}) {
    const float r = paps::radiusForNeighbourCount(p, index, target);
    // Density 20000 per unit area: count ~ 20000 pi r^2 away from the border.
    const double expected_r = std::sqrt(target / (20000 * M_PI));
    EXPECT_NEAR(r, expected_r, 0.15 * expected_r) << "target " << target;
    const NeighbourGraph g = NeighbourGraph::byRadius(p, index, r);
    EXPECT_NEAR(g.meanCount(), target, 0.15 * target) << "target " << target << ", radius " << r;
    const float rm = paps::radiusForNeighbourCount(p, index, target, paps::NeighbourCountStatistic::Mean);
    EXPECT_NEAR(NeighbourGraph::byRadius(p, index, rm).meanCount(), target, 0.05 * target) << "target " << target;
  }
}

// A real scan's density varies: here 30% of the points crowd 0.25% of the plane (like the
// returns next to a sensor) and every point is stored twice (bun0.pcd). A typical point must
// still get the target count; a mean count made by the dense spot gave 2 (its duplicate).
TEST(RadiusForNeighbourCount, TypicalPointHitsTheTargetOnVeryUnevenDensity) {
  Positions p = randomPlane(14000, 21);
  paps::Random rng(22);
  for (int i = 0; i < 6000; ++i) {
    const auto y = 0.5f + 0.05f * rng.uniform();
    p.emplace_back(0.5f + 0.05f * rng.uniform(), y, 0.f);
  }
  const std::size_t unique = p.size();
  for (std::size_t i = 0; i < unique; ++i) p.push_back(p[i]);
  const SpatialIndex index(p);
  const float r = paps::radiusForNeighbourCount(p, index, 30);
  const NeighbourGraph g = NeighbourGraph::byRadius(p, index, r);
  std::vector<int> counts;
  for (std::size_t i = 0; i < p.size(); ++i) counts.push_back(g.count(i));
  std::sort(counts.begin(), counts.end());
  EXPECT_NEAR(counts[counts.size() / 2], 30, 4.5) << "radius " << r;
  // Sparse part: 28000 stored points per unit area, count ~ 28000 pi r^2.
  EXPECT_NEAR(r, std::sqrt(30 / (28000 * M_PI)), 0.15 * std::sqrt(30 / (28000 * M_PI)));
  EXPECT_LT(std::count_if(counts.begin(), counts.end(), [](int c) { return c < 6; }), 0.01 * p.size());
  // The Mean statistic does what it says, and shows why it is not the default here.
  const float r_mean = paps::radiusForNeighbourCount(p, index, 30, paps::NeighbourCountStatistic::Mean);
  EXPECT_NEAR(NeighbourGraph::byRadius(p, index, r_mean).meanCount(), 30, 4.5);
  EXPECT_LT(r_mean, 0.25f * r);
}

TEST(RadiusForNeighbourCount, ScalesWithTheData) {
  Positions p = randomPlane(5000, 12);
  const float r1 = paps::radiusForNeighbourCount(p, SpatialIndex(p), 20);
  for (auto& x : p) x = 1000.f * x + Eigen::Vector3f(5e3f, -2e3f, 7.f);
  const float r2 = paps::radiusForNeighbourCount(p, SpatialIndex(p), 20);
  EXPECT_NEAR(r2 / r1, 1000.f, 10.f);
}

TEST(RadiusForNeighbourCount, IgnoresNaNAndIsDeterministic) {
  Positions p = randomPlane(10000, 13);
  const float clean = paps::radiusForNeighbourCount(p, SpatialIndex(p), 30);
  Positions with_nan = p;
  for (std::size_t i = 0; i < with_nan.size(); i += 3) with_nan.insert(with_nan.begin() + i, Eigen::Vector3f(kNaN, kNaN, kNaN));
  const SpatialIndex index(with_nan);
  const float r = paps::radiusForNeighbourCount(with_nan, index, 30);
  EXPECT_NEAR(r, clean, 0.1f * clean);
  EXPECT_EQ(r, paps::radiusForNeighbourCount(with_nan, index, 30));
  EXPECT_NEAR(paps::NeighbourGraph::byRadius(with_nan, index, r).meanCount(), 30, 4.5);
}

TEST(RadiusForNeighbourCount, Errors) {
  const Positions none;
  EXPECT_THROW(paps::radiusForNeighbourCount(none, SpatialIndex(none), 10), paps::InvalidInput);
  const Positions one = {{1, 2, 3}, {kNaN, 0, 0}};
  EXPECT_THROW(paps::radiusForNeighbourCount(one, SpatialIndex(one), 10), paps::InvalidInput);
  const Positions nan(4, Eigen::Vector3f::Constant(kNaN));
  EXPECT_THROW(paps::radiusForNeighbourCount(nan, SpatialIndex(nan), 10), paps::InvalidInput);
  const Positions same(10, Eigen::Vector3f(1, 1, 1));
  EXPECT_THROW(paps::radiusForNeighbourCount(same, SpatialIndex(same), 3), paps::InvalidInput);
  // Spacings whose squares overflow or underflow a float are named as such, not as a bad
  // radius or as identical points.
  auto message = [](const Positions& p) -> std::string {
    try {
      paps::radiusForNeighbourCount(p, SpatialIndex(p), 5);
    } catch (const paps::InvalidInput& e) {
      return e.what();
    }
    return "";
  };
  Positions huge, tiny;
  paps::Random rng(3);
  for (int i = 0; i < 200; ++i) {
    const float y = float(rng.uniform());
    const Eigen::Vector3f u(float(rng.uniform()), y, 0.f);
    huge.push_back(1e30f * u);
    tiny.push_back(1e-30f * u);
  }
  EXPECT_NE(message(huge).find("overflow"), std::string::npos) << message(huge);
  EXPECT_NE(message(tiny).find("underflow"), std::string::npos) << message(tiny);
  EXPECT_NE(message(same).find("identical"), std::string::npos) << message(same);
  const Positions two = {{0, 0, 0}, {1, 0, 0}};
  EXPECT_GT(paps::radiusForNeighbourCount(two, SpatialIndex(two), 2), 0.f);
  try {
    paps::radiusForNeighbourCount(two, SpatialIndex(two), 1);
    ADD_FAILURE() << "target_count 1 accepted";
  } catch (const paps::InvalidParameter& e) {
    EXPECT_EQ(e.parameter(), "target_count");
  }
  try {
    paps::radiusForNeighbourCount(two, SpatialIndex(two), 5, paps::NeighbourCountStatistic::Median, 0);
    ADD_FAILURE() << "samples 0 accepted";
  } catch (const paps::InvalidParameter& e) {
    EXPECT_EQ(e.parameter(), "samples");
  }
}

// ------------------------------------------------------------ buildRadiusNeighbourhood

TEST(BuildRadiusNeighbourhood, GivenOrAutomaticRadius) {
  const Positions p = randomPlane(5000, 14);
  const paps::RadiusNeighbourhood fixed = paps::buildRadiusNeighbourhood(p, 0.03f, 30);
  EXPECT_EQ(fixed.radius, 0.03f);
  ASSERT_TRUE(fixed.index);
  EXPECT_EQ(fixed.index->size(), p.size());
  ASSERT_EQ(fixed.graph.size(), p.size());
  // The lists at the given radius: those of byRadius on the same index (as sets), and, on a
  // sample, exactly the points of the open ball by brute force.
  const NeighbourGraph direct = NeighbourGraph::byRadius(p, *fixed.index, 0.03f);
  for (std::size_t i = 0; i < p.size(); ++i) {
    const std::vector<int> a = listOf(fixed.graph, i), b = listOf(direct, i);
    ASSERT_EQ(std::set<int>(a.begin(), a.end()), std::set<int>(b.begin(), b.end())) << i;
    ASSERT_EQ(a.size(), b.size()) << i;
  }
  for (std::size_t i = 0; i < p.size(); i += 97) {
    std::set<int> ball;
    for (const auto& [d2, j] : bruteForce(p, p[i]))
      if (d2 < 0.03f * 0.03f) ball.insert(j);
    const std::vector<int> a = listOf(fixed.graph, i);
    EXPECT_EQ(std::set<int>(a.begin(), a.end()), ball) << i;
  }
  const paps::RadiusNeighbourhood automatic = paps::buildRadiusNeighbourhood(p, 0.f, 25);
  EXPECT_NEAR(automatic.graph.meanCount(), 25, 0.15 * 25);
  const paps::RadiusNeighbourhood capped = paps::buildRadiusNeighbourhood(p, 0.1f, 25, 7);
  // Density 5000 per unit area: a ball of 0.1 holds about 157 points inside the square and
  // about 39 at a corner, always far more than 7, so every list is cut to exactly 7.
  for (std::size_t i = 0; i < p.size(); ++i) EXPECT_EQ(capped.graph.count(i), 7) << i;
}

TEST(BuildRadiusNeighbourhood, Errors) {
  const Positions p = randomPlane(100, 15);
  for (float r : {-1.f, kNaN}) {
    try {
      paps::buildRadiusNeighbourhood(p, r, 10);
      ADD_FAILURE() << "radius " << r << " accepted";
    } catch (const paps::InvalidParameter& e) {
      EXPECT_EQ(e.parameter(), "radius");
    }
  }
  EXPECT_THROW(paps::buildRadiusNeighbourhood(Positions{}, 0.1f, 10), paps::InvalidInput);
  EXPECT_THROW(paps::buildRadiusNeighbourhood(Positions(3, Eigen::Vector3f::Constant(kNaN)), 0.f, 10),
               paps::InvalidInput);
  EXPECT_THROW(paps::buildRadiusNeighbourhood(Positions{{0, 0, 0}, {kNaN, 0, 0}}, 0.1f, 10),
               paps::InvalidInput);
}

TEST(ExactDuplicateRepresentatives, FirstOccurrenceNaNAndSignedZero) {
  Positions p = {{1, 2, 3}, {0, 0, 0}, {1, 2, 3}, {kNaN, 0, 0}, {-0.f, 0, 0}, {1, 2, 3.0001f}, {1, 2, 3}};
  std::size_t dup = 99;
  const std::vector<int> rep = paps::exactDuplicateRepresentatives(p, &dup);
  const std::vector<int> expected = {0, 1, 0, -1, 1, 5, 0};
  EXPECT_EQ(rep, expected);
  EXPECT_EQ(dup, 3u);
  EXPECT_TRUE(paps::exactDuplicateRepresentatives(Positions()).empty());
}

TEST(ExactDuplicateRepresentatives, EveryPointTwiceInShuffledOrder) {
  const Positions base = randomPoints(500, 11, 0);
  Positions p;
  for (const auto& x : base) p.push_back(x);
  for (std::size_t i = base.size(); i-- > 0;) p.push_back(base[i]);  // reversed copies
  std::size_t dup = 0;
  const std::vector<int> rep = paps::exactDuplicateRepresentatives(p, &dup);
  EXPECT_EQ(dup, base.size());
  for (std::size_t i = 0; i < base.size(); ++i) {
    EXPECT_EQ(rep[i], static_cast<int>(i));
    EXPECT_EQ(rep[p.size() - 1 - i], static_cast<int>(i));
  }
}

// The mean count over a spread sample: on a regular grid every interior ball at 1.01 spacings
// holds 5 points (self and 4 neighbours), the corners 3 and the edges 4; the cap counts at most
// that many per ball; non-finite points are not sampled.
TEST(SampledMeanNeighbourCount, KnownCountsOnAGrid) {
  Positions grid;
  for (int j = 0; j < 50; ++j)
    for (int i = 0; i < 50; ++i) grid.emplace_back(0.1f * i, 0.1f * j, 0.f);
  grid.emplace_back(NAN, 0.f, 0.f);
  const SpatialIndex index(grid);
  // All 2,500 points sampled: 4 corners of 3, 192 edge points of 4, 2,304 interior of 5.
  const double all = (4 * 3 + 192 * 4 + 2304 * 5) / 2500.0;
  EXPECT_NEAR(paps::sampledMeanNeighbourCount(grid, index, 0.101f, 0, 5000), all, 1e-9);
  EXPECT_NEAR(paps::sampledMeanNeighbourCount(grid, index, 0.101f, 2, 5000), 2.0, 1e-9);
  const double sampled = paps::sampledMeanNeighbourCount(grid, index, 0.101f, 0, 100);
  EXPECT_GE(sampled, 3.0);
  EXPECT_LE(sampled, 5.0);
  const Positions none{Eigen::Vector3f::Constant(NAN)};
  EXPECT_EQ(paps::sampledMeanNeighbourCount(none, SpatialIndex(none), 1.f, 0), 0.0);
}

}  // namespace core_neighbourhood_test
