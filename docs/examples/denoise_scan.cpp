// Denoising a scan inside a PCL pipeline: paps::SimilarityDenoising, PAPS's point bilateral
// filter beside it, then PCL's voxel grid.
//
//   example_denoise_scan [scan.pcd]
//
// Without a file it makes 40,000 points on the unit sphere with Gaussian noise of 0.01 per axis
// and exits 1 unless both filters bring the points closer to the sphere (distance | |p| - 1 |).
// The part between the "readme" marks is the README's example (a test keeps them equal).
#include <cmath>
#include <iostream>
#include <random>
#include <string>

#include <pcl/io/pcd_io.h>

#include <paps/core/error.h>
#include <paps/filters/point_bilateral_filter.h>
// [readme]
#include <pcl/conversions.h>
#include <pcl/filters/voxel_grid.h>
#include <paps/core/cloud_io.h>
#include <paps/filters/similarity_denoising.h>
// [readme]

using Cloud = pcl::PointCloud<pcl::PointXYZ>;

double rmsToUnitSphere(const Cloud& cloud) {
  double sum = 0;
  for (const auto& p : cloud) sum += std::pow(p.getVector3fMap().norm() - 1.0, 2);
  return std::sqrt(sum / cloud.size());
}

int main(int argc, char** argv) try {
  std::string path = argc > 1 ? argv[1] : "example_noisy_sphere.pcd";
  if (argc == 1) {  // 40,000 points on the unit sphere, Gaussian noise of 0.01 per axis
    Cloud sphere;
    std::mt19937 rng(7);
    std::normal_distribution<float> gauss(0.f, 1.f);
    for (int i = 0; i < 40000; ++i) {
      const Eigen::Vector3f d = Eigen::Vector3f(gauss(rng), gauss(rng), gauss(rng)).normalized();
      const Eigen::Vector3f p = d + 0.01f * Eigen::Vector3f(gauss(rng), gauss(rng), gauss(rng));
      sphere.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    }
    pcl::io::savePCDFileBinary(path, sphere);
  }
  // [readme]
  pcl::PointCloud<pcl::PointXYZ>::Ptr scan(new pcl::PointCloud<pcl::PointXYZ>), clean(new pcl::PointCloud<pcl::PointXYZ>);
  pcl::fromPCLPointCloud2(paps::loadCloud(path), *scan);   // PCD or PLY; paps::IoError if unreadable

  paps::SimilarityDenoising<pcl::PointXYZ> denoise;   // a pcl::Filter
  denoise.setInputCloud(scan);
  denoise.setTargetNeighbours(30);   // radius from the data, grown with the measured noise; or setRadius(metres)
  denoise.setSimilarPatches(32);
  denoise.setNumberOfThreads(2);     // as PCL's OMP classes; 0 (default): OMP_NUM_THREADS or every core
  denoise.filter(*clean);            // same size and fields as the input; NaNs pass through
  std::cout << "noise " << denoise.getReport().noise_sigma << " m, radius " << denoise.getReport().radius << " m\n";

  pcl::VoxelGrid<pcl::PointXYZ> grid; // ...and on with the rest of the PCL pipeline
  grid.setInputCloud(clean);
  // [readme]
  Cloud sparse, smooth;
  grid.setLeafSize(0.02f, 0.02f, 0.02f);
  grid.filter(sparse);

  // The baseline of the manuscript (Fleishman et al. 2003) at the same radius.
  paps::PointBilateralFilter<pcl::PointXYZ> bilateral;
  bilateral.setInputCloud(scan);
  bilateral.setRadius(denoise.getReport().radius);
  bilateral.filter(smooth);

  std::cout << scan->size() << " points -> " << sparse.size() << " after the voxel grid\n";
  if (argc > 1) return 0;
  const double before = rmsToUnitSphere(*scan), ours = rmsToUnitSphere(*clean), theirs = rmsToUnitSphere(smooth);
  std::cout << "RMS distance to the sphere: input " << before << ", SimilarityDenoising " << ours
            << ", PointBilateralFilter " << theirs << "\n";
  return ours < 0.5 * before && theirs < before ? 0 : 1;
} catch (const paps::Error& e) {  // bad parameters or input: one clear line
  std::cerr << "example_denoise_scan: " << e.what() << "\n";
  return 1;
}
