// PAPS stages inside a PCL pipeline: a noisy scan of a box corner is denoised by
// paps::SimilarityDenoising, which also writes the normals and curvature of the denoised
// surface into the PointNormal cloud; PCL's own region growing then segments it with them,
// its neighbours found by paps::KdTreeSearch (the lists of pcl::search::KdTree, faster).
//
//   example_pcl_pipeline
//
// The corner's three faces (0.5 m squares, 1 mm noise) must come out as three segments, each
// holding most of one face and little of the others; exits 1 otherwise.
#include <algorithm>
#include <iostream>
#include <random>
#include <vector>

#include <pcl/common/io.h>
#include <pcl/point_types.h>
#include <pcl/segmentation/region_growing.h>

#include <paps/core/error.h>
#include <paps/core/kd_tree_search.h>
#include <paps/filters/similarity_denoising.h>

int main() try {
  // Three faces of a box, meeting at the origin: face f is the plane where coordinate f is 0.
  pcl::PointCloud<pcl::PointNormal>::Ptr scan(new pcl::PointCloud<pcl::PointNormal>);
  std::vector<int> face;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> side(0.f, 0.5f);
  std::normal_distribution<float> noise(0.f, 0.001f);
  for (int f = 0; f < 3; ++f)
    for (int i = 0; i < 12000; ++i) {
      pcl::PointNormal p;  // normals 0 0 0: none yet, as a scan comes
      Eigen::Vector3f q(side(rng), side(rng), side(rng));
      q[f] = 0.f;
      p.getVector3fMap() = q + Eigen::Vector3f(noise(rng), noise(rng), noise(rng));
      p.normal_x = p.normal_y = p.normal_z = p.curvature = 0.f;
      scan->push_back(p);
      face.push_back(f);
    }
  scan->sensor_origin_ = Eigen::Vector4f(1.f, 1.f, 1.f, 0.f);  // the scanner looked into the corner

  // PAPS: denoise; the moved points get the normals (facing the sensor) and PCL's curvature
  // of the denoised surface.
  paps::SimilarityDenoising<pcl::PointNormal> denoise;
  denoise.setInputCloud(scan);
  pcl::PointCloud<pcl::PointNormal>::Ptr clean(new pcl::PointCloud<pcl::PointNormal>);
  denoise.filter(*clean);
  std::cout << "denoised: radius " << denoise.getReport().radius << " m, " << denoise.getRefreshedNormals()
            << " normals estimated on the output\n";

  // PCL: region growing on those normals and curvatures (its usual point and normal types).
  pcl::PointCloud<pcl::PointXYZ>::Ptr points(new pcl::PointCloud<pcl::PointXYZ>);
  pcl::PointCloud<pcl::Normal>::Ptr normals(new pcl::PointCloud<pcl::Normal>);
  pcl::copyPointCloud(*clean, *points);
  pcl::copyPointCloud(*clean, *normals);
  pcl::RegionGrowing<pcl::PointXYZ, pcl::Normal> grow;
  grow.setInputCloud(points);
  grow.setInputNormals(normals);
  grow.setSearchMethod(pcl::make_shared<paps::KdTreeSearch<pcl::PointXYZ>>());  // for pcl::search::KdTree
  grow.setNumberOfNeighbours(20);
  grow.setSmoothnessThreshold(static_cast<float>(8.0 / 180.0 * M_PI));
  grow.setCurvatureThreshold(0.01f);
  grow.setMinClusterSize(500);
  std::vector<pcl::PointIndices> segments;
  grow.extract(segments);
  std::sort(segments.begin(), segments.end(),
            [](const pcl::PointIndices& a, const pcl::PointIndices& b) { return a.indices.size() > b.indices.size(); });

  // Each of the three largest segments: mostly one face, and most of that face.
  bool ok = segments.size() >= 3;
  std::vector<bool> taken(3, false);
  for (std::size_t s = 0; s < std::min<std::size_t>(3, segments.size()); ++s) {
    int count[3] = {0, 0, 0};
    for (const int i : segments[s].indices) ++count[face[i]];
    const int f = static_cast<int>(std::max_element(count, count + 3) - count);
    const double purity = double(count[f]) / segments[s].indices.size(), cover = count[f] / 12000.0;
    std::cout << "segment " << s << ": " << segments[s].indices.size() << " points, face " << f << ", purity "
              << purity << ", covers " << cover << " of the face\n";
    ok = ok && !taken[f] && purity > 0.99 && cover > 0.85;
    taken[f] = true;
  }
  std::cout << segments.size() << " segments; " << (ok ? "the three faces found" : "FAILED") << "\n";
  return ok ? 0 : 1;
} catch (const paps::Error& e) {
  std::cerr << "example_pcl_pipeline: " << e.what() << "\n";
  return 1;
}
