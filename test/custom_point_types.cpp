// Every PCL-style class of PAPS with point types of the user's own, through PAPS_NO_PRECOMPILE
// (and PCL_NO_PRECOMPILE, which PCL needs for them), as the README tells users to do. The
// explicit instantiations below compile every member of every class for those types: a
// header whose template bodies cannot be reached that way (a missing #include of its impl, a
// body that names a PCL type) fails this build. The tests then run every stage on the custom
// types: the filters and upsamplers on a small sphere, the fusion stages on a short synthetic
// street, the transport stages on a cube. Each gives what the same stage gives for a type the
// library compiles in (the same positions, colours, labels, poses or meshes) and keeps the
// user's own fields.
#define PCL_NO_PRECOMPILE
#define PAPS_NO_PRECOMPILE
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <vector>

#include <pcl/PolygonMesh.h>

#include <pcl/point_types.h>
#include <pcl/register_point_struct.h>

#include <paps/core/metrics.h>
#include <paps/core/random.h>
#include <paps/core/synthetic.h>
#include <paps/core/triangle_mesh.h>
#include <paps/fusion/camera_model.h>
#include <paps/fusion/colour_space.h>
#include <paps/fusion/synthetic_street.h>
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

namespace {

// ring = i % 64, time = i * 1e-5 and intensity = i % 13 of one input point i of noisySphere().
bool fieldsOfAnInputPoint(const LidarPoint& p) {
  const long i = std::lround(p.time / 1e-5f);
  return i >= 0 && i < 3000 && p.ring == i % 64 && p.intensity == static_cast<float>(i % 13);
}

pcl::PointCloud<pcl::PointXYZ>::Ptr xyzOf(const pcl::PointCloud<LidarPoint>& in) {
  auto xyz = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const auto& p : in) xyz->push_back(pcl::PointXYZ(p.x, p.y, p.z));
  return xyz;
}

// The user's segment and curvature fields hold values made from the index, for the stages to keep.
std::uint32_t segmentOf(std::size_t i) { return static_cast<std::uint32_t>(7 * i + 3); }
float curvatureOf(std::size_t i) { return 0.25f * static_cast<float>(i); }

pcl::PointCloud<SurveyPoint>::Ptr surveyCloudOf(const pcl::PointCloud<pcl::PointXYZRGBNormal>& in) {
  auto out = pcl::make_shared<pcl::PointCloud<SurveyPoint>>();
  for (std::size_t i = 0; i < in.size(); ++i) {
    SurveyPoint p;
    p.getVector3fMap() = in[i].getVector3fMap();
    p.getNormalVector3fMap() = in[i].getNormalVector3fMap();
    p.rgba = in[i].rgba;
    p.curvature = curvatureOf(i);
    p.segment = segmentOf(i);
    out->push_back(p);
  }
  return out;
}

// Same positions, normals and colours as the listed type's output, and the user's fields kept.
void expectSameAsListed(const pcl::PointCloud<SurveyPoint>& custom, const pcl::PointCloud<pcl::PointXYZRGBNormal>& listed,
                        const char* what) {
  ASSERT_EQ(custom.size(), listed.size()) << what;
  for (std::size_t i = 0; i < custom.size(); ++i) {
    ASSERT_EQ(custom[i].getVector3fMap(), listed[i].getVector3fMap()) << what << " " << i;
    ASSERT_EQ(custom[i].getNormalVector3fMap(), listed[i].getNormalVector3fMap()) << what << " " << i;
    ASSERT_EQ(custom[i].rgba, listed[i].rgba) << what << " " << i;
    ASSERT_EQ(custom[i].segment, segmentOf(i)) << what << " " << i;
    ASSERT_EQ(custom[i].curvature, curvatureOf(i)) << what << " " << i;
  }
}

double meanLuminance(const pcl::PointCloud<SurveyPoint>& cloud, const std::vector<std::uint8_t>& mask) {
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i)
    if (mask[i]) {
      const Eigen::Vector3f c(paps::colour::fromByte(cloud[i].r), paps::colour::fromByte(cloud[i].g),
                              paps::colour::fromByte(cloud[i].b));
      sum += paps::colour::luminance(c);
      ++n;
    }
  return sum / static_cast<double>(std::max<std::size_t>(n, 1));
}

}  // namespace

TEST(CustomPointTypes, MoreUpsamplersAndTheWavejetEnhancementOnTheUsersTypes) {
  const auto in = noisySphere();
  // LPF resampling: the listed PointXYZ gives the same positions; new points take a source's fields.
  paps::LpfResampling<LidarPoint, LidarPoint> lpf;
  paps::LpfResampling<pcl::PointXYZ, pcl::PointXYZ> lpf_listed;
  lpf.setInputCloud(in);
  lpf_listed.setInputCloud(xyzOf(*in));
  lpf.setUpsamplingFactor(2);
  lpf_listed.setUpsamplingFactor(2);
  pcl::PointCloud<LidarPoint> out;
  pcl::PointCloud<pcl::PointXYZ> out_listed;
  lpf.process(out);
  lpf_listed.process(out_listed);
  ASSERT_GT(out.size(), in->size());
  ASSERT_EQ(out.size(), out_listed.size());
  std::size_t from_input = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_EQ(out[i].getVector3fMap(), out_listed[i].getVector3fMap()) << "lpf " << i;
    from_input += fieldsOfAnInputPoint(out[i]);
  }
  EXPECT_EQ(from_input, out.size());
  EXPECT_LT(rmsToUnitSphere(out), rmsToUnitSphere(*in));

  // RIMLS on a type with a normal, colour and label: positions of the listed PointNormal run
  // (given the same normals), and each new point carries one input point's segment.
  const auto rgbn = pcl::make_shared<pcl::PointCloud<pcl::PointXYZRGBNormal>>();
  auto with_normals = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  for (const auto& p : *in) {
    pcl::PointXYZRGBNormal q;
    q.getVector3fMap() = p.getVector3fMap();
    q.getNormalVector3fMap() = p.getVector3fMap().normalized();
    q.r = 10;
    q.g = 20;
    q.b = static_cast<std::uint8_t>(p.ring);
    rgbn->push_back(q);
    pcl::PointNormal n;
    n.getVector3fMap() = q.getVector3fMap();
    n.getNormalVector3fMap() = q.getNormalVector3fMap();
    with_normals->push_back(n);
  }
  const auto survey = surveyCloudOf(*rgbn);
  paps::RIMLSUpsampling<SurveyPoint, SurveyPoint> rimls;
  paps::RIMLSUpsampling<pcl::PointNormal, pcl::PointNormal> rimls_listed;
  rimls.setInputCloud(survey);
  rimls_listed.setInputCloud(with_normals);
  rimls.setUpsamplingFactor(2);
  rimls_listed.setUpsamplingFactor(2);
  pcl::PointCloud<SurveyPoint> up;
  pcl::PointCloud<pcl::PointNormal> up_listed;
  rimls.process(up);
  rimls_listed.process(up_listed);
  ASSERT_GT(up.size(), survey->size());
  ASSERT_EQ(up.size(), up_listed.size());
  for (std::size_t i = 0; i < up.size(); ++i) {
    // The fitted surface's normal and curvature, as in the listed type.
    ASSERT_EQ(up[i].getVector3fMap(), up_listed[i].getVector3fMap()) << "rimls " << i;
    ASSERT_EQ(up[i].getNormalVector3fMap(), up_listed[i].getNormalVector3fMap()) << "rimls " << i;
    ASSERT_EQ(up[i].curvature, up_listed[i].curvature) << "rimls " << i;
    ASSERT_EQ(up[i].segment % 7, 3u) << i;
    const std::size_t source = up[i].segment / 7;
    ASSERT_LT(source, survey->size()) << i;
    EXPECT_EQ(up[i].rgba, (*survey)[source].rgba) << i;
  }

  // Wavejet enhancement with alpha0 = 1 projects on the fitted surface: closer to the sphere,
  // and the positions of the listed type.
  paps::WavejetEnhancement<LidarPoint> project;
  project.setRadius(0.2f);
  project.setPositionGain(1.f);
  expectFieldsKeptAndCloser(project, "wavejet projection");
  paps::WavejetEnhancement<pcl::PointXYZ> project_listed;
  project_listed.setRadius(0.2f);
  project_listed.setPositionGain(1.f);
  pcl::PointCloud<LidarPoint> a;
  pcl::PointCloud<pcl::PointXYZ> b;
  project.setInputCloud(in);
  project.filter(a);
  project_listed.setInputCloud(xyzOf(*in));
  project_listed.filter(b);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i].getVector3fMap(), b[i].getVector3fMap()) << i;

  // Wavejet estimation into the user's own type: the corrected normals of the listed
  // PointNormal input, along the sphere's radius.
  paps::WavejetEstimation<SurveyPoint, SurveyPoint> estimate;
  paps::WavejetEstimation<pcl::PointNormal> estimate_listed;
  estimate.setInputCloud(survey);
  estimate_listed.setInputCloud(with_normals);
  estimate.setRadiusSearch(0.2);
  estimate_listed.setRadiusSearch(0.2);
  pcl::PointCloud<SurveyPoint> e;
  pcl::PointCloud<paps::PointWavejet> e_listed;
  estimate.compute(e);
  estimate_listed.compute(e_listed);
  ASSERT_EQ(e.size(), e_listed.size());
  double along_radius = 0;
  for (std::size_t i = 0; i < e.size(); ++i) {
    ASSERT_EQ(e[i].getNormalVector3fMap(), e_listed[i].getNormalVector3fMap()) << i;
    ASSERT_TRUE(std::isfinite(e[i].curvature)) << i;
    along_radius += std::abs(e[i].getNormalVector3fMap().dot((*in)[i].getVector3fMap().normalized()));
  }
  EXPECT_GT(along_radius / static_cast<double>(e.size()), 0.98);
}

namespace {

// A short street of the fusion tests: the scan as the listed type and as the user's type, and
// photos of the y > 0 side (PointColorization, ShadowDetection, ImageToCloudRegistration).
struct SurveyStreet {
  paps::synthetic::StreetScene scene;
  paps::synthetic::StreetScan scan;
  std::vector<paps::RegisteredPhoto> photos;
  static paps::synthetic::StreetOptions options() {
    paps::synthetic::StreetOptions o;
    o.length = 16;
    o.scan_step = 0.15;
    o.scan_angle_step_deg = 0.6;
    return o;
  }
  SurveyStreet() : scene(options()), scan(scene.scan()) {
    const auto camera = paps::CameraIntrinsics::fromFieldOfView(240, 180, 75);
    const auto poses = scene.cameraPoses(3, -4, 4, 1, 0, -5);
    for (std::size_t v = 0; v < poses.size(); ++v) {
      paps::synthetic::PhotoOptions po;
      po.seed = 30 + v;
      photos.push_back({scene.photo(camera, poses[v], po).image, camera, poses[v]});
    }
  }
};

template <typename PointT>
void colorize(const SurveyStreet& s, const typename pcl::PointCloud<PointT>::Ptr& in, pcl::PointCloud<PointT>& out) {
  paps::PointColorization<PointT> c;
  c.setInputCloud(in);
  for (const auto& p : s.photos) c.addView(p.image, p.camera, p.pose);
  c.filter(out);
}

template <typename PointT>
paps::ShadowDetectionResult detectShadows(const SurveyStreet& s, const typename pcl::PointCloud<PointT>::Ptr& in) {
  paps::ShadowDetection<PointT> d;
  d.setInputCloud(in);
  d.setReflectance(s.scan.reflectance);
  for (const auto& p : s.photos) d.addView(p.image, p.camera, p.pose);
  paps::ShadowDetectionResult r;
  d.detect(r);
  return r;
}

template <typename PointT>
void correctShadows(const SurveyStreet& s, const typename pcl::PointCloud<PointT>::Ptr& in, pcl::PointCloud<PointT>& out) {
  paps::ShadowCorrection<PointT> c;
  paps::ShadowCorrectionParameters p;
  p.target = paps::RelightTarget::AllLit;
  p.sun_direction = s.scene.sunDirection().cast<float>();
  c.setParameters(p);
  c.setInputCloud(in);
  c.setShadowLabels(s.scan.in_shadow);
  c.filter(out);
}

template <typename PointT>
paps::CameraPose registerPhoto(const typename pcl::PointCloud<PointT>::Ptr& in, const cv::Mat& photo,
                               const paps::CameraIntrinsics& camera, const paps::CameraPose& initial) {
  paps::ImageToCloudRegistration<PointT> r;
  r.setInputCloud(in);
  r.setPhoto(photo, camera);
  r.setInitialPose(initial);
  return r.align();
}

}  // namespace

TEST(CustomPointTypes, FusionStagesOnTheUsersTypeGiveTheListedTypesResults) {
  const SurveyStreet s;
  const auto listed = s.scan.cloud.makeShared();
  const auto custom = surveyCloudOf(s.scan.cloud);

  // Colours from the photos.
  auto coloured_listed = pcl::make_shared<pcl::PointCloud<pcl::PointXYZRGBNormal>>();
  auto coloured = pcl::make_shared<pcl::PointCloud<SurveyPoint>>();
  colorize<pcl::PointXYZRGBNormal>(s, listed, *coloured_listed);
  colorize<SurveyPoint>(s, custom, *coloured);
  expectSameAsListed(*coloured, *coloured_listed, "colorization");
  std::size_t with_colour = 0;  // the scan came black
  for (const auto& p : *coloured) with_colour += (p.rgba & 0xffffffu) != 0;
  std::printf("colorization: %zu of %zu points coloured\n", with_colour, coloured->size());
  EXPECT_GT(with_colour, coloured->size() / 10);  // the photos see the y > 0 side, in part

  // Shadows detected on the coloured clouds: the same labels, and shadows found.
  const auto d_listed = detectShadows<pcl::PointXYZRGBNormal>(s, coloured_listed);
  const auto d = detectShadows<SurveyPoint>(s, coloured);
  EXPECT_EQ(d.in_shadow, d_listed.in_shadow);
  EXPECT_EQ(d.decided, d_listed.decided);
  const auto shadow = static_cast<std::size_t>(std::count(d.in_shadow.begin(), d.in_shadow.end(), 1));
  std::printf("shadow detection: %zu of %zu points in shadow\n", shadow, d.in_shadow.size());
  EXPECT_GT(shadow, 0u);
  EXPECT_LT(shadow, d.in_shadow.size());

  // Shadows relit from the true labels: the same colours, and the shadowed points brighter.
  pcl::PointCloud<pcl::PointXYZRGBNormal> relit_listed;
  pcl::PointCloud<SurveyPoint> relit;
  correctShadows<pcl::PointXYZRGBNormal>(s, coloured_listed, relit_listed);
  correctShadows<SurveyPoint>(s, coloured, relit);
  expectSameAsListed(relit, relit_listed, "shadow correction");
  std::vector<std::uint8_t> seen_in_shadow(coloured->size());
  for (std::size_t i = 0; i < seen_in_shadow.size(); ++i)
    seen_in_shadow[i] = s.scan.in_shadow[i] && ((*coloured)[i].rgba & 0xffffffu) != 0;
  const double before = meanLuminance(*coloured, seen_in_shadow), after = meanLuminance(relit, seen_in_shadow);
  std::printf("shadow correction: mean luminance in shadow %.3f -> %.3f\n", before, after);
  EXPECT_GT(after, 1.3 * before);
}

// A photo registered from a wrong orientation on the street of the registration tests (the
// case of ImageRegistration.PclFrontEndWithShadingFromNormals): the same pose for the user's
// type and the listed one (shading from the normals, which both carry), nearer the truth.
TEST(CustomPointTypes, PhotoRegisteredOnTheUsersTypeGivesTheListedTypesPose) {
  paps::synthetic::StreetOptions o;
  o.length = 36;
  const paps::synthetic::StreetScene scene(o);
  const paps::synthetic::StreetScan scan = scene.scan();
  const auto listed = scan.cloud.makeShared();
  const auto custom = surveyCloudOf(scan.cloud);
  auto camera = paps::CameraIntrinsics::fromFieldOfView(320, 240, 80);
  camera.k1 = -0.08;
  camera.k2 = 0.01;
  const auto truth = scene.cameraPoses(1, -6, -6, 1, 15, 10)[0];
  const cv::Mat photo = scene.photo(camera, truth).image;
  paps::PoseDelta delta;
  delta.yaw = 3.0 * M_PI / 180;
  delta.pitch = -2.0 * M_PI / 180;
  delta.roll = 1.0 * M_PI / 180;
  const auto initial = paps::applyPoseDelta(truth, delta);
  const paps::CameraPose pose = registerPhoto<SurveyPoint>(custom, photo, camera, initial);
  const paps::CameraPose pose_listed = registerPhoto<pcl::PointXYZRGBNormal>(listed, photo, camera, initial);
  EXPECT_EQ(pose.matrix(), pose_listed.matrix());
  std::vector<Eigen::Vector3d> probe;
  for (std::size_t i = 0; i < custom->size(); i += 17) probe.push_back((*custom)[i].getVector3fMap().cast<double>());
  const double error_before = paps::meanReprojectionError(camera, truth, initial, probe);
  const double error_after = paps::meanReprojectionError(camera, truth, pose, probe);
  std::printf("registration: reprojection error %.2f -> %.2f px\n", error_before, error_after);
  EXPECT_LT(error_after, 0.5 * error_before);
}

TEST(CustomPointTypes, TransportStagesOnTheUsersTypesGiveTheListedTypesMeshes) {
  const paps::TriangleMesh cube = paps::synthetic::cube(0.5f, 4);
  const paps::Positions points = paps::synthetic::sampleMesh(cube, 400, 5);
  auto lidar = pcl::make_shared<pcl::PointCloud<LidarPoint>>();
  auto survey = pcl::make_shared<pcl::PointCloud<SurveyPoint>>();
  auto xyz = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (std::size_t i = 0; i < points.size(); ++i) {
    LidarPoint l;
    l.getVector3fMap() = points[i];
    l.intensity = 1;
    l.ring = 2;
    l.time = 3;
    lidar->push_back(l);
    SurveyPoint v;
    v.getVector3fMap() = points[i];
    v.getNormalVector3fMap() = Eigen::Vector3f::UnitZ();
    v.rgba = 0xff102030u;
    v.curvature = curvatureOf(i);
    v.segment = segmentOf(i);
    survey->push_back(v);
    xyz->push_back(pcl::PointXYZ(points[i].x(), points[i].y(), points[i].z()));
  }
  auto expectSameMesh = [](const pcl::PolygonMesh& a, const pcl::PolygonMesh& b, const char* what) {
    const paps::TriangleMesh ma = paps::toTriangleMesh(a), mb = paps::toTriangleMesh(b);
    ASSERT_GT(ma.triangles.size(), 0u) << what;
    ASSERT_EQ(ma.vertices.size(), mb.vertices.size()) << what;
    ASSERT_EQ(ma.triangles.size(), mb.triangles.size()) << what;
    for (std::size_t v = 0; v < ma.vertices.size(); ++v) ASSERT_EQ(ma.vertices[v], mb.vertices[v]) << what << " " << v;
    for (std::size_t t = 0; t < ma.triangles.size(); ++t) ASSERT_EQ(ma.triangles[t], mb.triangles[t]) << what << " " << t;
  };

  // Reconstruction by decimation, with the vertices asked, near the cube.
  paps::TransportReconstructionParameters p;
  p.target_vertices = 30;
  p.candidates = 10;
  p.initial_fraction = 0.1f;
  auto rebuildWith = [&p](auto&& stage, const auto& cloud) {
    stage.setParameters(p);
    stage.setInputCloud(cloud);
    pcl::PolygonMesh m;
    stage.reconstruct(m);
    return m;
  };
  const pcl::PolygonMesh mesh = rebuildWith(paps::TransportReconstruction<LidarPoint>(), lidar);
  const pcl::PolygonMesh mesh_listed = rebuildWith(paps::TransportReconstruction<pcl::PointXYZ>(), xyz);
  expectSameMesh(mesh, mesh_listed, "reconstruction");
  const paps::TriangleMesh rebuilt = paps::toTriangleMesh(mesh);
  EXPECT_LE(rebuilt.vertices.size(), 30u);
  EXPECT_GE(rebuilt.vertices.size(), 20u);
  const paps::PointToMeshDistance to_cube(cube);
  EXPECT_LT(paps::pointToMeshError(rebuilt.vertices, to_cube).max, 0.05 * cube.boundingBoxDiagonal());

  // Feature recovery: a rounded cube pulled back to its corners by the user's points.
  paps::TriangleMesh rounded = cube;
  for (auto& v : rounded.vertices) v = 0.7f * v + 0.3f * 0.3f * v.normalized();
  auto smooth = pcl::make_shared<pcl::PolygonMesh>(paps::toPolygonMesh(rounded));
  paps::TransportFeatureRecoveryParameters fp;
  fp.sweeps = 3;
  auto recoverWith = [&fp, &smooth](auto&& stage, const auto& cloud) {
    stage.setParameters(fp);
    stage.setInputMesh(smooth);
    stage.setInputCloud(cloud);
    pcl::PolygonMesh m;
    stage.process(m);
    return m;
  };
  const pcl::PolygonMesh sharp = recoverWith(paps::TransportFeatureRecovery<SurveyPoint>(), survey);
  const pcl::PolygonMesh sharp_listed = recoverWith(paps::TransportFeatureRecovery<pcl::PointXYZ>(), xyz);
  expectSameMesh(sharp, sharp_listed, "feature recovery");
  EXPECT_LT(paps::pointToMeshError(paps::toTriangleMesh(sharp).vertices, to_cube).rmse,
            0.5 * paps::pointToMeshError(rounded.vertices, to_cube).rmse);
}
