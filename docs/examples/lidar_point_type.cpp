// A point type of your own (here a spinning LiDAR's: intensity, ring, time) through PAPS:
// the library is compiled for a short list of PCL types, and for any other type the template
// bodies are included by defining PAPS_NO_PRECOMPILE (and PCL_NO_PRECOMPILE, which PCL
// itself needs for a custom type) before the first include. Every stage keeps the extra
// fields: the filters move x, y, z only; the upsamplers give each new point the fields of the
// input point it was made from, as PCL's MLS does.
//
//   example_lidar_point_type
//
// It scans a sphere of radius 2 m with 48 rings (1 cm noise) and exits 1 unless the denoiser
// brings the points closer to the sphere and keeps every ring and time, the Wavejet mean
// curvature of the scan is within 10% of 1/2 1/m, and the 2x super-resolved points lie on
// the sphere with the ring of an input point near them.
#define PCL_NO_PRECOMPILE
#define PAPS_NO_PRECOMPILE
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_types.h>
#include <pcl/register_point_struct.h>

#include <paps/core/error.h>
#include <paps/features/wavejet_estimation.h>
#include <paps/filters/similarity_denoising.h>
#include <paps/surface/quadric_super_resolution.h>

struct EIGEN_ALIGN16 LidarPoint {
  PCL_ADD_POINT4D;  // x, y, z and padding
  float intensity;
  std::uint16_t ring;
  float time;
  PCL_MAKE_ALIGNED_OPERATOR_NEW
};
POINT_CLOUD_REGISTER_POINT_STRUCT(LidarPoint, (float, x, x)(float, y, y)(float, z, z)(float, intensity, intensity)(
                                                  std::uint16_t, ring, ring)(float, time, time))

namespace {
constexpr double kRadius = 2.0;

double rmsToSphere(const pcl::PointCloud<LidarPoint>& cloud) {
  double sum = 0;
  for (const auto& p : cloud) sum += std::pow(p.getVector3fMap().norm() - kRadius, 2);
  return std::sqrt(sum / static_cast<double>(cloud.size()));
}
}  // namespace

int main() try {
  // 48 rings from -60 to +60 degrees of elevation, 360 azimuth steps; 1 cm range noise.
  pcl::PointCloud<LidarPoint>::Ptr scan(new pcl::PointCloud<LidarPoint>);
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.01);
  for (int ring = 0; ring < 48; ++ring)
    for (int step = 0; step < 360; ++step) {
      const double elevation = (-60.0 + 120.0 * ring / 47) * M_PI / 180, azimuth = step * M_PI / 180;
      const double r = kRadius + noise(rng);
      LidarPoint p;
      p.x = static_cast<float>(r * std::cos(elevation) * std::cos(azimuth));
      p.y = static_cast<float>(r * std::cos(elevation) * std::sin(azimuth));
      p.z = static_cast<float>(r * std::sin(elevation));
      p.intensity = static_cast<float>(step % 7);
      p.ring = static_cast<std::uint16_t>(ring);
      p.time = static_cast<float>(step * 1e-4);
      scan->push_back(p);
    }

  // 1. Similarity denoising: a pcl::Filter on the custom type; fields other than x, y, z kept.
  paps::SimilarityDenoising<LidarPoint> denoise;
  denoise.setInputCloud(scan);
  denoise.setNumberOfThreads(2);
  pcl::PointCloud<LidarPoint>::Ptr clean(new pcl::PointCloud<LidarPoint>);
  denoise.filter(*clean);
  std::size_t fields_kept = 0;
  for (std::size_t i = 0; i < scan->size(); ++i)
    fields_kept += (*clean)[i].ring == (*scan)[i].ring && (*clean)[i].time == (*scan)[i].time &&
                   (*clean)[i].intensity == (*scan)[i].intensity;
  const double before = rmsToSphere(*scan), after = rmsToSphere(*clean);
  std::printf("denoised %zu points: RMS to the sphere %.4f m -> %.4f m; ring, time, intensity kept on %zu\n",
              clean->size(), before, after, fields_kept);

  // 2. Wavejet curvatures (a pcl::Feature), on the raw scan: their noise pilot measures white
  //    noise and lowers the order against it. What a denoiser leaves is smooth ripple, which
  //    the pilot cannot tell from relief: on the denoised copy of this scan the mean |H| comes
  //    out 0.68 instead of 0.51 (docs/wavejets.md, "After a denoiser").
  paps::WavejetEstimation<LidarPoint> wavejets;
  wavejets.setInputCloud(scan);
  wavejets.setRadiusSearch(0.25);  // metres: about 5 rings, 70 neighbours
  wavejets.setNumberOfThreads(2);
  pcl::PointCloud<paps::PointWavejet> features;
  wavejets.compute(features);
  double mean_h = 0;
  std::size_t fitted = 0;
  for (const auto& f : features)
    if (std::isfinite(f.k1)) mean_h += std::abs(0.5 * (f.k1 + f.k2)), ++fitted;
  mean_h /= static_cast<double>(std::max<std::size_t>(fitted, 1));
  std::printf("Wavejets: %zu points fitted, mean |H| %.4f 1/m (true %.4f)\n", fitted, mean_h, 1 / kRadius);

  // 3. Quadric super-resolution into the same type: each new point takes its source's fields.
  paps::QuadricSuperResolution<LidarPoint, LidarPoint> qsr;
  qsr.setInputCloud(clean);
  qsr.setUpsamplingFactor(2);
  qsr.setNumberOfThreads(2);
  pcl::PointCloud<LidarPoint> dense;
  qsr.process(dense);
  // The source is a nearby input point: its ring is within 2 of the nearest input's.
  pcl::KdTreeFLANN<LidarPoint> tree;
  tree.setInputCloud(clean);
  std::size_t near_ring = 0;
  pcl::Indices k(1);
  std::vector<float> d2(1);
  for (const auto& p : dense)
    if (tree.nearestKSearch(p, 1, k, d2) == 1) near_ring += std::abs(int(p.ring) - int((*clean)[k[0]].ring)) <= 2;
  std::printf("super-resolved: %zu -> %zu points, RMS to the sphere %.4f m, ring of a nearby input point on %zu\n",
              clean->size(), dense.size(), rmsToSphere(dense), near_ring);

  const bool ok = fields_kept == scan->size() && after < 0.8 * before && fitted == clean->size() &&
                  std::abs(mean_h - 1 / kRadius) < 0.1 / kRadius && dense.size() > 1.9 * clean->size() &&
                  rmsToSphere(dense) < before && near_ring == dense.size();
  return ok ? 0 : 1;
} catch (const paps::Error& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
