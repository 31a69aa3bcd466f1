// Uses paps::filters from an installed PAPS: denoises a few hundred noisy points of a plane
// and checks that the filter ran and lowered the noise. Exit 0 on success.
#include <cmath>
#include <cstdio>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/filters/similarity_denoising.h>

int main() {
  // 20 x 20 grid on z = 0 with a deterministic pseudo-random height noise.
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  unsigned state = 12345u;
  auto noise = [&state] {
    state = state * 1664525u + 1013904223u;
    return (static_cast<float>(state >> 8) / 16777216.f - 0.5f) * 0.01f;
  };
  for (int j = 0; j < 20; ++j)
    for (int i = 0; i < 20; ++i) cloud->push_back(pcl::PointXYZ(0.05f * i, 0.05f * j, noise()));

  paps::SimilarityDenoising<pcl::PointXYZ> filter;
  filter.setInputCloud(cloud);
  filter.setTargetNeighbours(20);
  pcl::PointCloud<pcl::PointXYZ> out;
  try {
    filter.filter(out);
  } catch (const paps::Error& e) {
    std::fprintf(stderr, "paps_consumer: %s\n", e.what());
    return 1;
  }
  double before = 0, after = 0;
  for (std::size_t i = 0; i < cloud->size(); ++i) {
    before += (*cloud)[i].z * (*cloud)[i].z;
    after += out[i].z * out[i].z;
    if (!std::isfinite(out[i].x) || !std::isfinite(out[i].y) || !std::isfinite(out[i].z)) {
      std::fprintf(stderr, "paps_consumer: point %zu is not finite\n", i);
      return 1;
    }
  }
  before = std::sqrt(before / cloud->size());
  after = std::sqrt(after / out.size());
  std::printf("paps_consumer: %zu points, radius %g, moved %zu, height RMS %.4g -> %.4g\n", out.size(),
              filter.getReport().radius, filter.getReport().moved, before, after);
  if (out.size() != cloud->size() || filter.getReport().moved == 0 || !(after < before)) {
    std::fprintf(stderr, "paps_consumer: the filter did not denoise\n");
    return 1;
  }
  return 0;
}
