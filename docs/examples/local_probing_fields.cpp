// Local Probing Fields on a scan with wires: paps::LpfDenoising (a pcl::Filter) denoises
// surfaces and wires alike, then paps::LpfResampling (a pcl::CloudSurfaceProcessing) makes
// it denser. Height-field filters (MLS, bilateral) cannot denoise a wire: it has no normal.
//
//   example_local_probing_fields [scan.pcd]   (writes lpf_denoised.pcd and lpf_resampled.pcd)
//
// Without a file it makes a 2 x 2 m plate with a wire 0.3 m above it (20,000 points, noise
// of 4 mm) and exits 1 unless the wire's RMS error falls below half of the input's and the
// resampled cloud is denser and still within that error of the wire.
#include <cmath>
#include <iostream>
#include <random>

#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/filters/lpf_denoising.h>
#include <paps/surface/lpf_resampling.h>

// RMS distance to the wire (the line y = 0, z = 0.3) of the points above z = 0.15.
template <typename Cloud>
double wireRms(const Cloud& cloud) {
  double sum = 0;
  int n = 0;
  for (const auto& p : cloud)
    if (p.z > 0.15f) { sum += p.y * p.y + (p.z - 0.3) * (p.z - 0.3); ++n; }
  return std::sqrt(sum / n);
}

int main(int argc, char** argv) try {
  pcl::PointCloud<pcl::PointXYZ>::Ptr scan(new pcl::PointCloud<pcl::PointXYZ>);
  if (argc > 1) {
    pcl::fromPCLPointCloud2(paps::loadCloud(argv[1]), *scan);  // PCD or PLY; paps::IoError if unreadable
  } else {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    std::normal_distribution<float> noise(0.f, 0.004f);
    for (int i = 0; i < 20000; ++i) {
      const bool wire = i % 10 == 0;  // 2,000 points on the wire
      scan->push_back(pcl::PointXYZ(u(rng) + noise(rng), (wire ? 0.f : u(rng)) + noise(rng), (wire ? 0.3f : 0.f) + noise(rng)));
    }
  }
  paps::LpfDenoising<pcl::PointXYZ> denoise;
  denoise.setInputCloud(scan);       // pattern radius: 100 neighbours; or setRadius(metres)
  pcl::PointCloud<pcl::PointXYZ>::Ptr clean(new pcl::PointCloud<pcl::PointXYZ>);
  denoise.filter(*clean);            // same size and fields as the input

  paps::LpfResampling<pcl::PointXYZ> resample;
  resample.setInputCloud(clean);
  resample.setUpsamplingFactor(4);   // density x4 on surfaces, x2 along wires
  pcl::PointCloud<pcl::PointXYZ> dense;
  resample.process(dense);

  std::cout << scan->size() << " points -> denoised (pattern radius " << denoise.getReport().radius << " m) -> "
            << dense.size() << " resampled\n";
  if (argc > 1)
    return pcl::io::savePCDFileBinary("lpf_denoised.pcd", *clean) < 0 || pcl::io::savePCDFileBinary("lpf_resampled.pcd", dense) < 0;
  const double before = wireRms(*scan), after = wireRms(*clean), resampled = wireRms(dense);
  std::cout << "wire RMS error: input " << before << ", denoised " << after << ", resampled " << resampled << "\n";
  return after < 0.5 * before && resampled < 0.5 * before && dense.size() > 2 * scan->size() ? 0 : 1;
} catch (const paps::Error& e) {
  std::cerr << "example_local_probing_fields: " << e.what() << "\n";
  return 1;
}
