// Upsampling with the moving-least-squares peers of the manuscript's Table 2.2:
// paps::APSSUpsampling (algebraic spheres) and paps::RIMLSUpsampling (robust implicit MLS),
// both pcl::CloudSurfaceProcessing stages, as fast as PCL's MovingLeastSquares upsampling.
//
//   example_mls_upsampling [scan.pcd]   (writes apss.pcd and rimls.pcd)
//
// Without a file it samples 10,000 points on the unit sphere and exits 1 unless both outputs
// have 4x the points and lie on the sphere (RMS radial error below a tenth of the spacing).
#include <cmath>
#include <iostream>
#include <random>

#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/surface/mls_upsampling.h>

double rmsToUnitSphere(const pcl::PointCloud<pcl::PointNormal>& cloud) {
  double sum = 0;
  for (const auto& p : cloud) sum += std::pow(p.getVector3fMap().norm() - 1.0, 2);
  return std::sqrt(sum / cloud.size());
}

int main(int argc, char** argv) try {
  pcl::PointCloud<pcl::PointXYZ>::Ptr scan(new pcl::PointCloud<pcl::PointXYZ>);
  if (argc > 1) {
    pcl::fromPCLPointCloud2(paps::loadCloud(argv[1]), *scan);  // PCD or PLY; paps::IoError if unreadable
  } else {
    std::mt19937 rng(13);
    std::normal_distribution<float> gauss(0.f, 1.f);
    for (int i = 0; i < 10000; ++i) {
      const Eigen::Vector3f d = Eigen::Vector3f(gauss(rng), gauss(rng), gauss(rng)).normalized();
      scan->push_back(pcl::PointXYZ(d.x(), d.y(), d.z()));
    }
  }
  paps::APSSUpsampling<pcl::PointXYZ, pcl::PointNormal> apss;
  apss.setInputCloud(scan);
  apss.setUpsamplingFactor(4);   // kernel support: from 30 neighbours, or setRadius(metres)
  pcl::PointCloud<pcl::PointNormal> spheres;
  apss.process(spheres);

  paps::RIMLSUpsampling<pcl::PointXYZ, pcl::PointNormal> rimls;
  rimls.setInputCloud(scan);
  rimls.setUpsamplingFactor(4);
  pcl::PointCloud<pcl::PointNormal> robust;
  rimls.process(robust);

  std::cout << scan->size() << " -> APSS " << spheres.size() << ", RIMLS " << robust.size()
            << " points; kernel support " << apss.getReport().radius << " m\n";
  if (argc > 1)
    return pcl::io::savePCDFileBinary("apss.pcd", spheres) < 0 || pcl::io::savePCDFileBinary("rimls.pcd", robust) < 0;
  const double spacing = std::sqrt(4 * M_PI / scan->size());
  const double e_apss = rmsToUnitSphere(spheres), e_rimls = rmsToUnitSphere(robust);
  std::cout << "RMS distance to the sphere: APSS " << e_apss << ", RIMLS " << e_rimls << " (spacing " << spacing << ")\n";
  return spheres.size() == 4 * scan->size() && robust.size() == 4 * scan->size() && e_apss < 0.1 * spacing &&
                 e_rimls < 0.1 * spacing
             ? 0
             : 1;
} catch (const paps::Error& e) {
  std::cerr << "example_mls_upsampling: " << e.what() << "\n";
  return 1;
}
