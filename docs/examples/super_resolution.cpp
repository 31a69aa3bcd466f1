// Point set super-resolution with paps::QuadricSuperResolution (QSR), a
// pcl::CloudSurfaceProcessing: 4x the points, each with the normal of the fitted surface.
//
//   example_super_resolution [scan.pcd]   (writes super_resolved.pcd)
//
// Without a file it samples 10,000 points on the unit sphere and exits 1 unless the output
// has 4x the points, lies on the sphere (RMS radial error below a tenth of the input spacing)
// and its normals point outward (propagated over the closed surface: no viewpoint is set).
#include <cmath>
#include <iostream>
#include <random>

#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/surface/quadric_super_resolution.h>

int main(int argc, char** argv) try {
  pcl::PointCloud<pcl::PointXYZ>::Ptr scan(new pcl::PointCloud<pcl::PointXYZ>);
  if (argc > 1) {
    pcl::fromPCLPointCloud2(paps::loadCloud(argv[1]), *scan);  // PCD or PLY; paps::IoError if unreadable
  } else {
    std::mt19937 rng(11);
    std::normal_distribution<float> gauss(0.f, 1.f);
    for (int i = 0; i < 10000; ++i) {
      const Eigen::Vector3f d = Eigen::Vector3f(gauss(rng), gauss(rng), gauss(rng)).normalized();
      scan->push_back(pcl::PointXYZ(d.x(), d.y(), d.z()));
    }
  }
  paps::QuadricSuperResolution<pcl::PointXYZ, pcl::PointNormal> qsr;
  qsr.setInputCloud(scan);
  qsr.setUpsamplingFactor(4);     // output count = 4 x the finite input points
  qsr.setNumberOfThreads(2);      // the output does not depend on it
  // qsr.addScan(other);          // other registered scans of the object: more similar patches
  // qsr.setViewPoint(x, y, z);   // normals towards the sensor instead of propagated
  pcl::PointCloud<pcl::PointNormal> out;
  qsr.process(out);
  const auto& r = qsr.getReport();
  std::cout << scan->size() << " -> " << out.size() << " points; patch radius " << r.patch_radius
            << " m, spacing " << r.spacing << " m, " << r.patches << " patches, denoised first: "
            << (r.denoised ? "yes" : "no") << "\n";
  if (argc > 1) return pcl::io::savePCDFileBinary("super_resolved.pcd", out) < 0 ? 1 : 0;

  double sum = 0;
  std::size_t outward = 0;
  for (const auto& p : out) {
    sum += std::pow(p.getVector3fMap().norm() - 1.0, 2);
    outward += p.getNormalVector3fMap().dot(p.getVector3fMap()) > 0;
  }
  const double rms = std::sqrt(sum / out.size());
  std::cout << "RMS distance to the sphere " << rms << " m; " << outward << " normals outward\n";
  return out.size() == 4 * scan->size() && rms < 0.1 * r.spacing && outward == out.size() ? 0 : 1;
} catch (const paps::Error& e) {
  std::cerr << "example_super_resolution: " << e.what() << "\n";
  return 1;
}
