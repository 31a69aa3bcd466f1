// Every PCL-style class of PAPS with point types of the user's own, through PAPS_NO_PRECOMPILE
// (and PCL_NO_PRECOMPILE, which PCL needs for them), as the README tells users to do. The
// explicit instantiations below compile every member of every class for those types: a
// header whose template bodies cannot be reached that way (a missing #include of its impl, a
// body that names a PCL type) fails this build. The tests then run the stages that keep
// fields on a small sphere.
#define PCL_NO_PRECOMPILE
#define PAPS_NO_PRECOMPILE
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>

#include <pcl/point_types.h>
#include <pcl/register_point_struct.h>

#include <paps/core/random.h>
#include <paps/features/wavejet_estimation.h>
#include <paps/filters/lpf_denoising.h>
#include <paps/filters/point_bilateral_filter.h>
#include <paps/filters/similarity_denoising.h>
#include <paps/filters/wavejet_enhancement.h>
#include <paps/fusion/image_registration.h>
#include <paps/fusion/point_colorization.h>
#include <paps/fusion/shadow_correction.h>
#include <paps/fusion/shadow_detection.h>
#include <paps/surface/lpf_resampling.h>
#include <paps/surface/mls_upsampling.h>
#include <paps/surface/quadric_super_resolution.h>
#include <paps/surface/transport_feature_recovery.h>
#include <paps/surface/transport_reconstruction.h>

namespace test_types {
// A spinning LiDAR's point: no normal, no colour.
struct EIGEN_ALIGN16 LidarPoint {
  PCL_ADD_POINT4D;
  float intensity;
  std::uint16_t ring;
  float time;
  PCL_MAKE_ALIGNED_OPERATOR_NEW
};
// A coloured point with a normal and a label of its own (for the fusion stages).
struct EIGEN_ALIGN16 SurveyPoint {
  PCL_ADD_POINT4D;
  PCL_ADD_NORMAL4D;
  PCL_ADD_RGB;
  float curvature;
  std::uint32_t segment;
  PCL_MAKE_ALIGNED_OPERATOR_NEW
};
}  // namespace test_types

POINT_CLOUD_REGISTER_POINT_STRUCT(test_types::LidarPoint, (float, x, x)(float, y, y)(float, z, z)(
                                                              float, intensity, intensity)(std::uint16_t, ring, ring)(
                                                              float, time, time))
POINT_CLOUD_REGISTER_POINT_STRUCT(test_types::SurveyPoint,
                                  (float, x, x)(float, y, y)(float, z, z)(float, normal_x, normal_x)(
                                      float, normal_y, normal_y)(float, normal_z, normal_z)(std::uint32_t, rgba, rgba)(
                                      float, curvature, curvature)(std::uint32_t, segment, segment))

using test_types::LidarPoint;
using test_types::SurveyPoint;

// Every member of every class, for the custom types.
template class paps::SimilarityDenoising<LidarPoint>;
template class paps::PointBilateralFilter<LidarPoint>;
template class paps::LpfDenoising<LidarPoint>;
template class paps::WavejetEnhancement<LidarPoint>;
template class paps::WavejetEnhancement<SurveyPoint>;
template class paps::WavejetEstimation<LidarPoint>;
template class paps::WavejetEstimation<SurveyPoint, SurveyPoint>;
template class paps::QuadricSuperResolution<LidarPoint, LidarPoint>;
template class paps::QuadricSuperResolution<SurveyPoint, SurveyPoint>;
template class paps::MlsUpsampling<LidarPoint, LidarPoint, paps::MlsSurface::Apss>;
template class paps::MlsUpsampling<SurveyPoint, SurveyPoint, paps::MlsSurface::Rimls>;
template class paps::LpfResampling<LidarPoint, LidarPoint>;
template class paps::TransportReconstruction<LidarPoint>;
template class paps::TransportFeatureRecovery<SurveyPoint>;
template class paps::PointColorization<SurveyPoint>;
template class paps::ShadowDetection<SurveyPoint>;
template class paps::ShadowCorrection<SurveyPoint>;
template class paps::ImageToCloudRegistration<SurveyPoint>;

namespace {

// 3,000 points on the unit sphere with 2% noise; ring, time and intensity from the index.
pcl::PointCloud<LidarPoint>::Ptr noisySphere() {
  auto cloud = pcl::make_shared<pcl::PointCloud<LidarPoint>>();
  paps::Random rng(21);
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d direction = rng.gaussian3().normalized();
    const double radius = 1.0 + 0.02 * rng.gaussian();
    const Eigen::Vector3d d = direction * radius;
    LidarPoint p;
    p.getVector3fMap() = d.cast<float>();
    p.intensity = static_cast<float>(i % 13);
    p.ring = static_cast<std::uint16_t>(i % 64);
    p.time = static_cast<float>(i) * 1e-5f;
    cloud->push_back(p);
  }
  return cloud;
}

double rmsToUnitSphere(const pcl::PointCloud<LidarPoint>& cloud) {
  double sum = 0;
  for (const auto& p : cloud) sum += std::pow(p.getVector3fMap().norm() - 1.0, 2);
  return std::sqrt(sum / static_cast<double>(cloud.size()));
}

// A filter on the custom type moves x, y, z closer to the sphere and keeps every other field.
template <typename Filter>
void expectFieldsKeptAndCloser(Filter&& f, const char* what) {
  const auto in = noisySphere();
  pcl::PointCloud<LidarPoint> out;
  f.setInputCloud(in);
  f.filter(out);
  ASSERT_EQ(out.size(), in->size()) << what;
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_EQ(out[i].ring, (*in)[i].ring) << what << " " << i;
    ASSERT_EQ(out[i].time, (*in)[i].time) << what << " " << i;
    ASSERT_EQ(out[i].intensity, (*in)[i].intensity) << what << " " << i;
  }
  std::printf("%s: RMS to the sphere %.5f -> %.5f\n", what, rmsToUnitSphere(*in), rmsToUnitSphere(out));
  EXPECT_LT(rmsToUnitSphere(out), 0.8 * rmsToUnitSphere(*in)) << what;
}

}  // namespace

TEST(CustomPointTypes, FiltersKeepTheUsersFields) {
  expectFieldsKeptAndCloser(paps::SimilarityDenoising<LidarPoint>(), "similarity");
  expectFieldsKeptAndCloser(paps::PointBilateralFilter<LidarPoint>(), "bilateral");
  expectFieldsKeptAndCloser(paps::LpfDenoising<LidarPoint>(), "lpf");
}

TEST(CustomPointTypes, UpsamplersGiveNewPointsTheirSourcesFields) {
  const auto in = noisySphere();
  auto check = [&](auto&& stage, const char* what) {
    stage.setInputCloud(in);
    stage.setUpsamplingFactor(2);
    pcl::PointCloud<LidarPoint> out;
    stage.process(out);
    ASSERT_GT(out.size(), in->size()) << what;
    std::size_t from_input = 0;
    for (const auto& p : out) {
      // ring = i % 64, time = i * 1e-5 and intensity = i % 13 of one input point i.
      const long i = std::lround(p.time / 1e-5f);
      from_input += i >= 0 && i < 3000 && p.ring == i % 64 && p.intensity == static_cast<float>(i % 13);
    }
    EXPECT_EQ(from_input, out.size()) << what;
    EXPECT_LT(rmsToUnitSphere(out), rmsToUnitSphere(*in)) << what;
  };
  check(paps::QuadricSuperResolution<LidarPoint, LidarPoint>(), "qsr");
  check(paps::APSSUpsampling<LidarPoint, LidarPoint>(), "apss");
}

TEST(CustomPointTypes, WavejetsOfACustomTypeAreThoseOfItsPositions) {
  const auto in = noisySphere();
  auto xyz = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const auto& p : *in) xyz->push_back(pcl::PointXYZ(p.x, p.y, p.z));
  paps::WavejetEstimation<LidarPoint> custom;
  paps::WavejetEstimation<pcl::PointXYZ> listed;  // compiled in the library
  custom.setInputCloud(in);
  listed.setInputCloud(xyz);
  custom.setRadiusSearch(0.2);
  listed.setRadiusSearch(0.2);
  pcl::PointCloud<paps::PointWavejet> a, b;
  custom.compute(a);
  listed.compute(b);
  ASSERT_EQ(a.size(), b.size());
  std::size_t fitted = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].getNormalVector3fMap(), b[i].getNormalVector3fMap()) << i;
    fitted += std::isfinite(a[i].k1);
  }
  EXPECT_EQ(fitted, a.size());
}
