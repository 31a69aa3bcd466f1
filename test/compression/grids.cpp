// The codec's internal spatial structures (modules/compression/src/point_grid.h) against brute
// force, and the codec's output against the thread count.
#include <algorithm>
#include <cmath>
#include <vector>

#include <omp.h>
#include <gtest/gtest.h>

#include <paps/compression/rate_distortion.h>
#include <paps/compression/self_similarity_codec.h>
#include <paps/core/random.h>
#include <paps/core/synthetic.h>

#include "point_grid.h"

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace compression_grids_test {

using namespace paps;
using namespace paps::compression;

Positions randomPoints(std::size_t n, std::uint64_t seed) {
  Random rng(seed);
  Positions p(n);
  for (auto& q : p) {
    const float z = 0.2f * float(rng.uniform()), y = float(rng.uniform());
    q = Eigen::Vector3f(float(rng.uniform()), y, z);
  }
  return p;
}

TEST(PointGrid, RadiusSearchFindsExactlyThePointsWithinTheRadius) {
  Positions p = randomPoints(5000, 3);
  p[17] = Eigen::Vector3f(NAN, 0, 0);  // skipped, never returned
  for (const float cell : {0.03f, 0.1f, 0.4f}) {
    const compression::detail::PointGrid grid(p, cell);
    EXPECT_EQ(grid.size(), p.size() - 1);
    std::vector<int> idx;
    std::vector<float> d2;
    for (int q = 0; q < 200; q += 7) {
      const float r = 0.02f + 0.01f * float(q % 11);
      grid.radiusSearch(p[q == 17 ? 18 : q], r, idx, d2);
      std::vector<int> got = idx, want;
      for (std::size_t i = 0; i < p.size(); ++i)
        if (isFinite(p[i]) && (p[i] - p[q == 17 ? 18 : q]).squaredNorm() <= r * r) want.push_back(int(i));
      std::sort(got.begin(), got.end());
      EXPECT_EQ(got, want) << "cell " << cell << " radius " << r;
      // Capped: the nearest ones, by increasing distance.
      if (want.size() > 4) {
        grid.radiusSearch(p[q == 17 ? 18 : q], r, idx, d2, 4);
        ASSERT_EQ(idx.size(), 4u);
        EXPECT_TRUE(std::is_sorted(d2.begin(), d2.end()));
        std::vector<float> all;
        for (const int i : want) all.push_back((p[i] - p[q == 17 ? 18 : q]).squaredNorm());
        std::sort(all.begin(), all.end());
        EXPECT_FLOAT_EQ(d2[3], all[3]);
      }
    }
  }
}

TEST(ThinningGrid, KeepsWhatSequentialPoissonDiskThinningKeeps) {
  const Positions p = randomPoints(4000, 5);
  const float r = 0.03f;
  compression::detail::ThinningGrid thin(r, 100);  // deliberately undersized: the table grows
  Positions kept;
  for (const auto& q : p) thin.offer(q, kept);
  // Brute force, same order.
  Positions want;
  for (const auto& q : p) {
    bool free = true;
    for (const auto& k : want) free = free && (k - q).squaredNorm() >= r * r;
    if (free) want.push_back(q);
  }
  ASSERT_EQ(kept.size(), want.size());
  for (std::size_t i = 0; i < kept.size(); ++i) EXPECT_EQ(kept[i], want[i]);
  EXPECT_LT(kept.size(), p.size());
}

TEST(SelfSimilarityCodec, OutputDoesNotDependOnTheThreadCount) {
  const TriangleMesh mesh = synthetic::engravedPlane(1.f, 0.25f, 0.02f, 120);
  const Positions pts = synthetic::sampleMesh(mesh, 30000, 4);
  CompressionParameters prm;
  prm.max_training_patches = 64;  // exercises the training subset and the block pass
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto b1 = compressPositions(pts, prm);
  const Positions d1 = decompressPositions(b1.data(), b1.size());
  omp_set_num_threads(std::max(2, saved));
  const auto b2 = compressPositions(pts, prm);
  const Positions d2 = decompressPositions(b2.data(), b2.size());
  omp_set_num_threads(saved);
  EXPECT_EQ(b1, b2);
  ASSERT_EQ(d1.size(), d2.size());
  EXPECT_TRUE(std::equal(d1.begin(), d1.end(), d2.begin()));
  EXPECT_GT(d1.size(), pts.size() / 2);
}

TEST(PreparedReference, KnownAnswerOnAShiftedPlaneAndSameAsCompareClouds) {
  // A plane z = 0 and the same points lifted by 0.01: D1 = D2 = 0.01 both ways.
  Positions ref;
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < 60; ++x) ref.emplace_back(0.05f * x, 0.05f * y, 0.f);
  Positions dec = ref;
  for (auto& p : dec) p.z() += 0.01f;
  const PreparedReference prepared(ref);
  const CloudErrors e = prepared.compare(dec, 0.005);
  EXPECT_NEAR(e.d1_rmse, 0.01, 1e-5);
  EXPECT_NEAR(e.d2_rmse, 0.01, 1e-5);
  EXPECT_DOUBLE_EQ(e.share_above_tolerance, 1.0);
  const CloudErrors f = compareClouds(ref, dec, 0.005);
  EXPECT_EQ(e.d2_rmse, f.d2_rmse);
  EXPECT_EQ(e.d1_rmse, f.d1_rmse);
  EXPECT_EQ(prepared.compare(dec, 0.02).share_above_tolerance, 0.0);
}

}  // namespace compression_grids_test
