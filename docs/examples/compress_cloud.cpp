// Self-similarity compression with paps::compression::PointCloudCompression, in the shape of
// pcl::io::OctreePointCloudCompression: encode to a stream, decode from it.
//
//   example_compress_cloud [scan.pcd]   (writes scan.paps and decoded.pcd)
//
// Without a file it samples 100,000 points on a unit sphere and exits 1 unless the stream
// takes under 2 bits per point (the raw floats take 96) and the decoded points lie within a
// tenth of the input spacing of the sphere (RMS).
#include <cmath>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>

#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>

#include <paps/core/cloud_io.h>
#include <paps/compression/point_cloud_compression.h>
#include <paps/core/error.h>

using Cloud = pcl::PointCloud<pcl::PointXYZ>;

int main(int argc, char** argv) try {
  Cloud::Ptr cloud(new Cloud), decoded(new Cloud);
  if (argc > 1) {
    pcl::fromPCLPointCloud2(paps::loadCloud(argv[1]), *cloud);  // PCD or PLY; paps::IoError if unreadable
  } else {
    std::mt19937 rng(17);
    std::normal_distribution<float> gauss(0.f, 1.f);
    for (int i = 0; i < 100000; ++i) {
      const Eigen::Vector3f d = Eigen::Vector3f(gauss(rng), gauss(rng), gauss(rng)).normalized();
      cloud->push_back(pcl::PointXYZ(d.x(), d.y(), d.z()));
    }
  }
  // Presets: compact, balanced (the manuscript's settings), fine.
  paps::compression::PointCloudCompression<pcl::PointXYZ> codec(paps::compression::compressionPreset("balanced"));
  std::stringstream stream;
  codec.encodePointCloud(cloud, stream);  // only x y z are coded; NaN points are dropped (counted)
  const std::string bytes = stream.str();
  codec.decodePointCloud(stream, decoded);  // throws paps::CorruptStream on truncated or foreign data
  const double bpp = 8.0 * bytes.size() / cloud->size();
  std::cout << cloud->size() << " points -> " << bytes.size() << " bytes (" << bpp << " bits per point) -> "
            << decoded->size() << " decoded points, " << codec.encodeReport().seeds << " patches\n";
  if (argc > 1) {
    std::ofstream("scan.paps", std::ios::binary) << bytes;
    return pcl::io::savePCDFileBinary("decoded.pcd", *decoded) < 0 ? 1 : 0;
  }
  double sum = 0;
  for (const auto& p : *decoded) sum += std::pow(p.getVector3fMap().norm() - 1.0, 2);
  const double rms = std::sqrt(sum / decoded->size()), spacing = std::sqrt(4 * M_PI / cloud->size());
  std::cout << "RMS distance of the decoded points to the sphere " << rms << " (spacing " << spacing << ")\n";
  return bpp < 2 && !decoded->empty() && rms < 0.1 * spacing ? 0 : 1;
} catch (const paps::Error& e) {
  std::cerr << "example_compress_cloud: " << e.what() << "\n";
  return 1;
}
