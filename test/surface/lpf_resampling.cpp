// Tests of paps/surface/lpf_resampling.h: a clean plate and a clean wire are resampled
// denser without leaving them; on the plate and wires with noise the output is closer to
// the true shape than APSS's at the same count; determinism, order, the pcl stage, errors.
#include <algorithm>
#include <cmath>
#include <vector>

#include <omp.h>

#include <gtest/gtest.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>
#include <paps/core/spatial_order.h>
#include <paps/core/synthetic.h>
#include <paps/surface/lpf_resampling.h>
#include <paps/surface/mls_upsampling.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace surface_lpf_resampling_test {

using paps::LpfResamplingParameters;
using paps::LpfResamplingReport;
using paps::Positions;

Positions plate(int count, std::uint64_t seed) {
  paps::Random rng(seed);
  Positions p;
  for (int i = 0; i < count; ++i) {
    const double y = rng.uniform();
    p.emplace_back(rng.uniform(), y, 0.f);
  }
  return p;
}

TEST(LpfResampling, PlateGetsDenserAndStaysOnIt) {
  const Positions in = plate(5000, 1);
  LpfResamplingReport r;
  const Positions out = paps::lpfResample(in, {}, &r);
  // Factor 4 on a surface: about four times the points (measured 3.4x on the plate and wires).
  EXPECT_GT(out.size(), 2.5 * in.size());
  EXPECT_LT(out.size(), 6.0 * in.size());
  double worst_z = 0;
  for (const auto& p : out) {
    worst_z = std::max(worst_z, static_cast<double>(std::abs(p.z())));
    EXPECT_GT(p.x(), -0.02f);
    EXPECT_LT(p.x(), 1.02f);
  }
  EXPECT_LT(worst_z, 1e-5);
  // Coverage of the inner square, on a grid of spots: the mean distance to the nearest point
  // falls well below the input's, and no hole is wider than the input's widest (a node with
  // no input point within a spacing proposes nothing).
  auto coverage = [](const Positions& pts, double* worst) {
    const paps::SpatialIndex index(pts);
    std::vector<int> k;
    std::vector<float> d2;
    double sum = 0;
    *worst = 0;
    for (int i = 0; i <= 40; ++i)
      for (int j = 0; j <= 40; ++j) {
        index.nearestK(Eigen::Vector3f(0.1f + 0.02f * i, 0.1f + 0.02f * j, 0.f), 1, k, d2);
        sum += std::sqrt(static_cast<double>(d2[0]));
        *worst = std::max(*worst, std::sqrt(static_cast<double>(d2[0])));
      }
    return sum / (41 * 41);
  };
  double worst_in, worst_out;
  const double mean_in = coverage(in, &worst_in), mean_out = coverage(out, &worst_out);
  EXPECT_LT(mean_out, 0.7 * mean_in);
  EXPECT_LE(worst_out, worst_in);
  EXPECT_EQ(r.output, out.size());
}

TEST(LpfResampling, NoisyPlateIsDenoisedFirstAndKeepsItsDensity) {
  // Noise thicker than the consensus radius: one analysis leaves the proposals in layers
  // (more points than asked, farther from the plate); denoised first, the output keeps the
  // density asked for and comes closer. A clean plate is not denoised.
  Positions in = plate(5000, 11);
  paps::synthetic::addGaussianNoise(in, 0.005f, 12);
  auto rms_z = [](const Positions& p) {
    double s = 0;
    for (const auto& x : p) s += static_cast<double>(x.z()) * x.z();
    return std::sqrt(s / static_cast<double>(p.size()));
  };
  LpfResamplingParameters p;
  LpfResamplingReport automatic, off, clean;
  const Positions a = paps::lpfResample(in, p, &automatic);
  p.denoise_input = LpfResamplingParameters::Denoise::Off;
  const Positions b = paps::lpfResample(in, p, &off);
  std::printf("noise %.4g = %.2f tau_p; auto: %zu points, RMS z %.4g; off: %zu points, RMS z %.4g; input RMS z %.4g\n",
              automatic.noise_sigma, automatic.noise_ratio, a.size(), rms_z(a), b.size(), rms_z(b), rms_z(in));
  EXPECT_TRUE(automatic.denoised);
  EXPECT_FALSE(off.denoised);
  EXPECT_GT(automatic.noise_ratio, LpfResamplingParameters().denoise_ratio);
  EXPECT_NEAR(automatic.noise_sigma, 0.005 * std::sqrt(2.0), 0.3 * 0.005 * std::sqrt(2.0));
  EXPECT_GT(a.size(), 2.5 * in.size());
  EXPECT_LT(a.size(), 5.0 * in.size());
  // Measured: 18,046 points at RMS z 8.9e-4 (2 passes, the ratio 1.37) against 20,907 at
  // 2.6e-3 (input 7.0e-3).
  EXPECT_EQ(automatic.denoise_passes, 2);
  EXPECT_EQ(off.denoise_passes, 0);
  EXPECT_GT(b.size(), 1.1 * a.size());
  EXPECT_LT(rms_z(a), 0.5 * rms_z(b));
  p.denoise_input = LpfResamplingParameters::Denoise::On;
  EXPECT_TRUE(paps::lpfResample(in, p) == a);
  p.denoise_passes = 2;
  EXPECT_TRUE(paps::lpfResample(in, p) == a);
  // In tiles (the denoiser's and the resampler's): denoised as well, as dense, as close.
  p.denoise_input = LpfResamplingParameters::Denoise::Auto;
  p.denoise_passes = 0;
  p.max_tile_points = 2000;
  LpfResamplingReport tiled;
  const Positions c = paps::lpfResample(in, p, &tiled);
  EXPECT_TRUE(tiled.denoised);
  EXPECT_GE(tiled.tiles, 3u);
  EXPECT_NEAR(static_cast<double>(c.size()), static_cast<double>(a.size()), 0.05 * static_cast<double>(a.size()));
  EXPECT_LT(rms_z(c), 1.2 * rms_z(a));
  p.max_tile_points = LpfResamplingParameters().max_tile_points;
  paps::lpfResample(plate(5000, 11), p, &clean);
  EXPECT_FALSE(clean.denoised);
  EXPECT_LT(clean.noise_ratio, 0.01f);
  p.denoise_ratio = 0.f;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.denoise_ratio = NAN;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.denoise_ratio = 0.5f;
  p.denoise_passes = 51;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.denoise_passes = -1;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  paps::LpfResampling<pcl::PointXYZ> stage;
  stage.setDenoiseInput(LpfResamplingParameters::Denoise::Off);
  EXPECT_EQ(stage.getParameters().denoise_input, LpfResamplingParameters::Denoise::Off);
}

TEST(LpfResampling, WireGetsDenserAndStaysOnIt) {
  // A clean straight wire (spacing 2 mm), a pattern step of 1 mm: the output lies on the
  // wire and is denser. (The automatic step assumes a surface's density: a cloud of wires
  // alone gets a coarser one, see docs/lpf.md.)
  paps::Random rng(2);
  Positions in;
  for (int i = 0; i < 1500; ++i) in.emplace_back(static_cast<float>(rng.uniform(0, 3)), 0.5f, 0.25f);
  LpfResamplingParameters p;
  p.probing.radius = 0.02f;
  p.probing.step = 0.001f;
  const Positions out = paps::lpfResample(in, p);
  ASSERT_FALSE(out.empty());
  double worst = 0;
  for (const auto& p : out) worst = std::max(worst, static_cast<double>((p - Eigen::Vector3f(p.x(), 0.5f, 0.25f)).norm()));
  EXPECT_LT(worst, 1e-4);
  EXPECT_GT(out.size(), 1.25 * in.size());  // measured 1.35x
}

TEST(LpfResampling, CloserToPlateAndWiresThanApss) {
  // Measured (20,000 points, noise 0.05% of the diagonal): accuracy 6.4e-4 against APSS 2.1e-3.
  const auto shape = paps::synthetic::plateAndWires(20000, 3);
  Positions in = shape.points;
  paps::synthetic::addGaussianNoise(in, 0.0005f, 5);
  const Positions ours = paps::lpfResample(in, {});
  paps::MlsUpsamplingParameters q;
  q.output_count = ours.size();
  const Positions apss = paps::upsampleMls(in, paps::MlsSurface::Apss, q);
  auto rms = [](const Positions& p) {
    double s = 0;
    for (const auto& x : p) s += std::pow(paps::synthetic::distanceToPlateAndWires(x), 2);
    return std::sqrt(s / p.size());
  };
  EXPECT_LT(rms(ours), 0.5 * rms(apss)) << rms(ours) << " vs APSS " << rms(apss);
}

TEST(LpfResampling, SameWithOneOrTwoThreadsAndAnyInputOrder) {
  Positions in = plate(3000, 4);
  paps::synthetic::addGaussianNoise(in, 0.002f, 5);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const Positions a = paps::lpfResample(in, {});
  omp_set_num_threads(2);
  const Positions b = paps::lpfResample(in, {});
  Positions shuffled = in;
  paps::Random rng(6);
  for (std::size_t i = shuffled.size(); i > 1; --i) std::swap(shuffled[i - 1], shuffled[rng.below(i)]);
  const Positions c = paps::lpfResample(shuffled, {});
  omp_set_num_threads(saved);
  EXPECT_TRUE(a == b);
  EXPECT_TRUE(a == c);
}

TEST(LpfResampling, PclStageMatchesFunction) {
  const Positions in = plate(2000, 7);
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  paps::writePositions(in, *cloud);
  paps::LpfResampling<pcl::PointXYZ> stage;
  pcl::PointCloud<pcl::PointXYZ> out;
  EXPECT_THROW(stage.process(out), paps::InvalidInput);
  stage.setInputCloud(cloud);
  stage.process(out);
  const Positions expected = paps::lpfResample(in, {});
  ASSERT_EQ(out.size(), expected.size());
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_EQ(out[i].getVector3fMap(), expected[i]);
  EXPECT_EQ(stage.getReport().output, expected.size());
  // An RGB-D camera's type in (compiled in the library): the same points out.
  auto rgba = pcl::make_shared<pcl::PointCloud<pcl::PointXYZRGBA>>();
  paps::writePositions(in, *rgba);
  paps::LpfResampling<pcl::PointXYZRGBA, pcl::PointXYZ> from_rgba;
  from_rgba.setInputCloud(rgba);
  pcl::PointCloud<pcl::PointXYZ> out_rgba;
  from_rgba.process(out_rgba);
  ASSERT_EQ(out_rgba.size(), expected.size());
  for (std::size_t i = 0; i < out_rgba.size(); ++i) ASSERT_EQ(out_rgba[i].getVector3fMap(), expected[i]);
}

TEST(LpfResampling, BadInputAndParametersAreNamed) {
  EXPECT_THROW(paps::lpfResample(Positions{}, {}), paps::InvalidInput);
  EXPECT_THROW(paps::lpfResample(Positions{{0, 0, 0}, {1, 0, 0}}, {}), paps::InvalidInput);
  const float nan = std::nanf("");
  EXPECT_THROW(paps::lpfResample(Positions(10, Eigen::Vector3f::Constant(nan)), {}), paps::InvalidInput);
  // Three points: no field holds enough of them; an error, not an empty cloud.
  EXPECT_THROW(paps::lpfResample(Positions{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {}), paps::InvalidInput);
  LpfResamplingParameters p;
  p.factor = 0.5f;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.factor = 4.f;
  p.tau_p = -1.f;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.tau_p = 0.f;
  p.probing.atoms = 0;
  EXPECT_THROW(paps::lpfResample(plate(100, 8), p), paps::InvalidParameter);
  paps::LpfResampling<pcl::PointXYZ> stage;
  EXPECT_THROW(stage.setUpsamplingFactor(1000.f), paps::InvalidParameter);
}

// Distance of each point to its nearest other point, sorted.
std::vector<float> sortedNearestDistances(const Positions& a) {
  const paps::SpatialIndex index(a);
  std::vector<int> idx;
  std::vector<float> d2, d;
  for (const auto& p : a) {
    index.nearestK(p, 2, idx, d2);
    d.push_back(std::sqrt(d2[1]));
  }
  std::sort(d.begin(), d.end());
  return d;
}

// Tiles (max_tile_points): the pattern radius is the whole cloud's, the output as dense and as
// close to the plate and wires as in one piece, and the consensus runs on across the seams:
// no two output points closer than tau (0.7 x the step) in tiles either.
TEST(LpfResampling, TilesKeepTheDensityTheAccuracyAndTheConsensusAcrossSeams) {
  const auto shape = paps::synthetic::plateAndWires(16000, 3);
  Positions in = shape.points;
  paps::synthetic::addGaussianNoise(in, 0.0005f, 5);
  auto rms = [](const Positions& p) {
    double s = 0;
    for (const auto& x : p) s += std::pow(paps::synthetic::distanceToPlateAndWires(x), 2);
    return std::sqrt(s / static_cast<double>(p.size()));
  };
  LpfResamplingParameters p;
  LpfResamplingReport one, tiled;
  const Positions a = paps::lpfResample(in, p, &one);
  p.max_tile_points = 4000;
  const Positions b = paps::lpfResample(in, p, &tiled);
  const std::vector<float> na = sortedNearestDistances(a), nb = sortedNearestDistances(b);
  const float tau = 0.7f * one.step;
  std::printf("one piece: %zu points, RMS %.4e, closest pair %.4e; %zu tiles (largest %zu): %zu points, RMS %.4e, "
              "closest pair %.4e; tau %.4e; fields %zu / %zu\n",
              a.size(), rms(a), na.front(), tiled.tiles, tiled.largest_tile, b.size(), rms(b), nb.front(), tau,
              one.fields, tiled.fields);
  EXPECT_EQ(one.tiles, 1u);
  EXPECT_EQ(one.largest_tile, in.size());
  EXPECT_GE(tiled.tiles, 4u);
  EXPECT_GT(tiled.largest_tile, 4000u);
  EXPECT_EQ(tiled.radius, one.radius);
  EXPECT_EQ(tiled.step, one.step);
  EXPECT_EQ(tiled.output, b.size());
  EXPECT_NEAR(static_cast<double>(b.size()), static_cast<double>(a.size()), 0.03 * static_cast<double>(a.size()));
  EXPECT_LT(rms(b), 1.1 * rms(a));
  // Kept points are more than tau apart (to the rounding of the index's distances).
  EXPECT_GT(na.front(), 0.999f * tau);
  EXPECT_GT(nb.front(), 0.999f * tau);
  // The same in tiles whatever the thread count and the order of the points; the PCL stage
  // gives the function's output.
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const Positions c = paps::lpfResample(in, p);
  omp_set_num_threads(saved);
  EXPECT_TRUE(c == b);
  const Positions reversed(in.rbegin(), in.rend());
  EXPECT_TRUE(paps::lpfResample(reversed, p) == b);
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  paps::writePositions(in, *cloud);
  paps::LpfResampling<pcl::PointXYZ> stage;
  stage.setMaxTilePoints(p.max_tile_points);
  EXPECT_THROW(stage.setMaxTilePoints(999), paps::InvalidParameter);
  EXPECT_EQ(stage.getParameters().max_tile_points, p.max_tile_points);
  stage.setInputCloud(cloud);
  pcl::PointCloud<pcl::PointXYZ> out;
  stage.process(out);
  ASSERT_EQ(out.size(), b.size());
  for (std::size_t i = 0; i < out.size(); ++i) ASSERT_EQ(out[i].getVector3fMap(), b[i]) << i;
  EXPECT_EQ(stage.getReport().tiles, tiled.tiles);
}

TEST(LpfResampling, TileParametersAreChecked) {
  LpfResamplingParameters p;
  p.max_tile_points = 999;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.max_tile_points = std::size_t(1) << 31;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.max_tile_points = 0;
  p.validate();
  p.tile_margin = 2.f;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.tile_margin = NAN;
  EXPECT_THROW(p.validate(), paps::InvalidParameter);
  p.tile_margin = 10.f;
  p.validate();
}

}  // namespace surface_lpf_resampling_test
