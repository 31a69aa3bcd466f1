// paps::KdTreeSearch against pcl::search::KdTree: every list and distance the same, in the
// same order, among many ties, with non-finite points and indices, and at a radius whose
// square rounds differently in float and in double; a PCL feature gives the same output
// with either; the tree is built at the first query only.
#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>
#include <pcl/features/normal_3d.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <paps/core/error.h>
#include <paps/core/kd_tree_search.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_kd_tree_search_test {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// A lattice of step 0.1 with every other point stored twice (equal distances everywhere)
// and a few NaN points; not dense.
pcl::PointCloud<pcl::PointXYZ>::Ptr latticeWithTies() {
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (int x = 0; x < 12; ++x)
    for (int y = 0; y < 12; ++y)
      for (int z = 0; z < 5; ++z) cloud->push_back(pcl::PointXYZ(0.1f * float(x), 0.1f * float(y), 0.1f * float(z)));
  const std::size_t lattice = cloud->size();
  for (std::size_t i = 0; i < lattice; i += 2) {
    cloud->push_back((*cloud)[i]);
    if (i % 50 == 0) cloud->push_back(pcl::PointXYZ(kNaN, kNaN, kNaN));
  }
  cloud->is_dense = false;
  return cloud;
}

void expectSameAnswers(pcl::search::Search<pcl::PointXYZ>& ours, pcl::search::Search<pcl::PointXYZ>& pcl_search,
                       const pcl::PointCloud<pcl::PointXYZ>& cloud, std::size_t& compared) {
  pcl::Indices a, b;
  std::vector<float> da, db;
  for (std::size_t i = 0; i < cloud.size(); i += 5) {
    if (!std::isfinite(cloud[i].x)) continue;
    pcl::PointXYZ q = cloud[i];
    if (i % 3 == 0) q.z += 0.05f;  // between lattice planes too
    for (const int k : {1, 6, 26, 300, 6}) {
      ASSERT_EQ(ours.nearestKSearch(q, k, a, da), pcl_search.nearestKSearch(q, k, b, db)) << i;
      ASSERT_EQ(a, b) << "k " << k << " at " << i;
      ASSERT_EQ(da, db) << "k " << k << " at " << i;
      ++compared;
    }
    // 0.1 and 0.3: lattice distances (points on the ball's edge); caps that bind or not.
    for (const auto& [radius, cap] : {std::pair<double, unsigned>{0.1, 0}, {0.1, 3}, {0.3, 0}, {0.3, 20}, {0.25, 0},
                                      {0.3, 100000}}) {
      ASSERT_EQ(ours.radiusSearch(q, radius, a, da, cap), pcl_search.radiusSearch(q, radius, b, db, cap)) << i;
      ASSERT_EQ(a, b) << "radius " << radius << ", cap " << cap << " at " << i;
      ASSERT_EQ(da, db) << "radius " << radius << ", cap " << cap << " at " << i;
      ++compared;
    }
    // Search's query by index goes through the same virtual calls.
    ASSERT_EQ(ours.nearestKSearch(cloud, static_cast<pcl::index_t>(i), 9, a, da),
              pcl_search.nearestKSearch(cloud, static_cast<pcl::index_t>(i), 9, b, db));
    ASSERT_EQ(a, b);
  }
}

TEST(KdTreeSearch, SameListsAsPclSearchKdTreeAmongTies) {
  const auto cloud = latticeWithTies();
  paps::KdTreeSearch<pcl::PointXYZ> ours;
  pcl::search::KdTree<pcl::PointXYZ> theirs;
  ours.setInputCloud(cloud);
  theirs.setInputCloud(cloud);
  std::size_t compared = 0;
  expectSameAnswers(ours, theirs, *cloud, compared);

  // On a subset of the cloud (indices, NaN points among them): indices of the whole cloud.
  auto subset = pcl::make_shared<pcl::Indices>();
  for (std::size_t i = 0; i < cloud->size(); i += 3) subset->push_back(static_cast<pcl::index_t>(i));
  ours.setInputCloud(cloud, subset);
  theirs.setInputCloud(cloud, subset);
  expectSameAnswers(ours, theirs, *cloud, compared);
  EXPECT_GT(compared, 1000u);
}

TEST(KdTreeSearch, BallIsPclsWhereTheSquaredRadiusRoundsDifferently) {
  // A point at float distance d of the query, with d^2 below float(r * r) (double product,
  // as pcl::KdTreeFLANN) but equal to float(r) * float(r): inside PCL's ball only.
  const double r = 0.22455983311725247;
  const float d = 0.224559829f;
  ASSERT_LT(d * d, static_cast<float>(r * r));
  ASSERT_FALSE(d * d < static_cast<float>(r) * static_cast<float>(r));
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  cloud->push_back(pcl::PointXYZ(0, 0, 0));
  cloud->push_back(pcl::PointXYZ(d, 0, 0));
  cloud->push_back(pcl::PointXYZ(1, 0, 0));
  paps::KdTreeSearch<pcl::PointXYZ> ours;
  pcl::search::KdTree<pcl::PointXYZ> theirs;
  ours.setInputCloud(cloud);
  theirs.setInputCloud(cloud);
  pcl::Indices a, b;
  std::vector<float> da, db;
  EXPECT_EQ(theirs.radiusSearch(pcl::PointXYZ(0, 0, 0), r, b, db), 2);
  EXPECT_EQ(ours.radiusSearch(pcl::PointXYZ(0, 0, 0), r, a, da), 2);
  EXPECT_EQ(a, b);
  EXPECT_EQ(da, db);
}

TEST(KdTreeSearch, PclNormalEstimationGivesTheSameNormals) {
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (int i = 0; i < 4000; ++i) {
    // A wavy sheet sampled along a spiral: no ties, uneven spacing.
    const float t = 0.05f * float(i), r = 0.002f * float(i);
    const float x = r * std::cos(t), y = r * std::sin(t);
    cloud->push_back(pcl::PointXYZ(x, y, 0.2f * std::sin(3 * x) * std::cos(2 * y)));
  }
  for (const bool by_radius : {false, true}) {
    pcl::PointCloud<pcl::Normal> a, b;
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    ne.setInputCloud(cloud);
    if (by_radius) ne.setRadiusSearch(0.6);
    else ne.setKSearch(20);
    ne.setSearchMethod(pcl::make_shared<paps::KdTreeSearch<pcl::PointXYZ>>());
    ne.compute(a);
    ne.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
    ne.compute(b);
    ASSERT_EQ(a.size(), b.size());
    std::size_t finite = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
      ASSERT_EQ(a[i].getNormalVector3fMap(), b[i].getNormalVector3fMap()) << i;
      ASSERT_EQ(a[i].curvature, b[i].curvature) << i;
      finite += std::isfinite(a[i].normal_x);
    }
    EXPECT_EQ(finite, a.size());
  }
}

TEST(KdTreeSearch, BuiltAtTheFirstQueryAndAgainAfterANewCloud) {
  auto cloud = latticeWithTies();
  paps::KdTreeSearch<pcl::PointXYZ> search;
  pcl::Indices idx;
  std::vector<float> d2;
  EXPECT_THROW(search.nearestKSearch(pcl::PointXYZ(0, 0, 0), 3, idx, d2), paps::InvalidInput);
  search.setInputCloud(cloud);
  EXPECT_FALSE(search.built());
  ASSERT_EQ(search.nearestKSearch(pcl::PointXYZ(0.01f, 0, 0), 1, idx, d2), 1);
  EXPECT_TRUE(search.built());
  EXPECT_EQ(idx[0], 0);
  // A non-finite query finds nothing (pcl::search::KdTree asserts).
  EXPECT_EQ(search.nearestKSearch(pcl::PointXYZ(kNaN, 0, 0), 3, idx, d2), 0);
  EXPECT_TRUE(idx.empty());
  auto moved = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  moved->push_back(pcl::PointXYZ(5, 5, 5));
  moved->push_back(pcl::PointXYZ(0.02f, 0, 0));
  search.setInputCloud(moved);
  EXPECT_FALSE(search.built());
  ASSERT_EQ(search.nearestKSearch(pcl::PointXYZ(0, 0, 0), 5, idx, d2), 2);  // at most the points held
  EXPECT_EQ(idx, (pcl::Indices{1, 0}));
  EXPECT_EQ(search.getName(), "paps::KdTreeSearch");
}

TEST(KdTreeSearch, CorruptCoordinatesAreAnErrorOutOfThePclStage) {
  // A coordinate of 1e35 (misread bytes): FLANN's tree would abort the process. The search
  // refuses the cloud when the stage hands it over, before any parallel region.
  auto cloud = latticeWithTies();
  (*cloud)[7].y = 1e35f;
  pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
  ne.setInputCloud(cloud);
  ne.setKSearch(8);
  ne.setSearchMethod(pcl::make_shared<paps::KdTreeSearch<pcl::PointXYZ>>());
  pcl::PointCloud<pcl::Normal> out;
  try {
    ne.compute(out);
    ADD_FAILURE() << "computed";
  } catch (const paps::InvalidInput& e) {
    // The one core check (requireCoordinatesInRange), named for the search and the value.
    const std::string what = e.what();
    EXPECT_NE(what.find("paps::KdTreeSearch: a point has a coordinate of magnitude 1e+35"), std::string::npos) << what;
  }
  // At the limit itself the cloud is taken.
  (*cloud)[7].y = -paps::kMaxCoordinate;
  paps::KdTreeSearch<pcl::PointXYZ> search;
  EXPECT_NO_THROW(search.setInputCloud(cloud));
}

}  // namespace core_kd_tree_search_test
