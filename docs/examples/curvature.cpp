// Curvatures and corrected normals with paps::WavejetEstimation, a pcl::Feature.
//
//   example_curvature [scan.pcd]        (writes curvature.pcd: the scalar outputs per point)
//
// Without a file it samples a cylinder of radius 0.5 (30,000 points; k1 = 2, k2 = 0, mean
// curvature 1 when the normal points inward) and exits 1 unless the median estimates are
// within 2% of these values.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <vector>

#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/features/wavejet_estimation.h>

float median(std::vector<float> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

int main(int argc, char** argv) try {
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  if (argc > 1) {
    pcl::fromPCLPointCloud2(paps::loadCloud(argv[1]), *cloud);  // PCD or PLY; paps::IoError if unreadable
  } else {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> angle(0.f, 6.2831853f), height(-1.f, 1.f);
    for (int i = 0; i < 30000; ++i) {
      const float a = angle(rng);
      cloud->push_back(pcl::PointXYZ(0.5f * std::cos(a), 0.5f * std::sin(a), height(rng)));
    }
  }
  paps::WavejetEstimation<pcl::PointXYZ> wavejets;  // output type paps::PointWavejet
  wavejets.setInputCloud(cloud);
  wavejets.setKSearch(50);          // or setRadiusSearch(metres), as any pcl::Feature
  wavejets.setOrder(4);             // phi_{k,n} up to k = 4 (the manuscript's default)
  if (argc == 1) wavejets.setViewPoint(0, 0, 0);  // normals towards the axis: the synthetic check's convention
  pcl::PointCloud<paps::PointWavejet> out;
  wavejets.compute(out);            // NaN outputs (order -1) where a point could not be fitted

  std::vector<float> k1, k2, h;
  for (const auto& q : out)
    if (q.order >= 0) { k1.push_back(q.k1); k2.push_back(q.k2); h.push_back(q.mean_curvature); }
  if (k1.empty()) return 1;
  std::cout << k1.size() << " of " << out.size() << " points fitted; median k1 " << median(k1) << ", k2 "
            << median(k2) << ", mean curvature " << median(h) << " (1/m)\n";
  if (argc > 1) return pcl::io::savePCDFileBinary("curvature.pcd", out) < 0 ? 1 : 0;
  return std::abs(median(k1) - 2) < 0.04 && std::abs(median(k2)) < 0.04 && std::abs(median(h) - 1) < 0.02 ? 0 : 1;
} catch (const paps::Error& e) {
  std::cerr << "example_curvature: " << e.what() << "\n";
  return 1;
}
