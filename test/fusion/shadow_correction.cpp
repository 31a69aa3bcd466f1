// ShadowCorrection (manuscript 4.5.3): relighting with the sun-sky ratio, eqs. 4.6 and 4.7.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include <pcl/common/io.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/fusion/colour_space.h>
#include <paps/fusion/shadow_correction.h>
#include <paps/fusion/synthetic_street.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace fusion_shadow_correction_test {

using Cloud = pcl::PointCloud<pcl::PointXYZRGBNormal>;

// The street's scan coloured by the synthetic lighting model itself (exposure 0.5: nothing
// saturates), with 1 grey level of noise, and the true shadow labels.
struct LitStreet {
  paps::synthetic::StreetScene scene;
  paps::synthetic::StreetScan scan;
  Cloud::Ptr cloud{new Cloud};
  static constexpr float kExposure = 0.5f;
  static paps::synthetic::StreetOptions options() {
    paps::synthetic::StreetOptions o;
    o.length = 24;
    o.scan_step = 0.15;
    o.scan_angle_step_deg = 0.6;
    return o;
  }
  static const LitStreet& get() {
    static const LitStreet street;
    return street;
  }
  LitStreet() : scene(options()), scan(scene.scan()) {
    paps::Random rng(5);
    *cloud = scan.cloud;
    for (std::size_t i = 0; i < cloud->size(); ++i) {
      auto& p = (*cloud)[i];
      const Eigen::Vector3f c = scan.albedo[i] * float(kExposure * scene.irradiance(p.getVector3fMap().cast<double>(),
                                                                                    p.getNormalVector3fMap().cast<double>()));
      p.r = paps::colour::toByte(c.x() + float(rng.gaussian()) / 255.f);
      p.g = paps::colour::toByte(c.y() + float(rng.gaussian()) / 255.f);
      p.b = paps::colour::toByte(c.z() + float(rng.gaussian()) / 255.f);
    }
  }
  paps::ShadowCorrectionParameters parameters(paps::RelightTarget target) const {
    paps::ShadowCorrectionParameters p;
    p.target = target;
    p.sun_direction = scene.sunDirection().cast<float>();
    return p;
  }
};

Eigen::Vector3f rgbOf(const pcl::PointXYZRGBNormal& p) {
  return {paps::colour::fromByte(p.r), paps::colour::fromByte(p.g), paps::colour::fromByte(p.b)};
}

// Mean over shadow points of Y / Y(albedo) over the same mean for lit points, on the points of
// one orientation (normal . axis > 0.9): 1 when shadow and lit surfaces of the same albedo look
// alike.
double shadowOverLit(const Cloud& cloud, const LitStreet& s, const Eigen::Vector3f& axis) {
  double sum[2] = {0, 0}, count[2] = {0, 0};
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (cloud[i].getNormalVector3fMap().dot(axis) < 0.9f) continue;
    const float albedo = paps::colour::luminance(s.scan.albedo[i]);
    if (albedo < 0.05f) continue;
    const int k = s.scan.in_shadow[i] ? 1 : 0;
    sum[k] += paps::colour::luminance(rgbOf(cloud[i])) / albedo;
    count[k] += 1;
  }
  return (sum[1] / count[1]) / (sum[0] / count[0]);
}

TEST(ShadowCorrection, RelitShadowsMatchTheLitSurfaces) {
  const LitStreet& s = LitStreet::get();
  paps::ShadowCorrection<pcl::PointXYZRGBNormal> correct;
  correct.setInputCloud(s.cloud);
  correct.setShadowLabels(s.scan.in_shadow);
  correct.setParameters(s.parameters(paps::RelightTarget::AllLit));
  Cloud lit;
  correct.filter(lit);
  const auto& report = correct.getReport();
  const Eigen::Vector3f ground = Eigen::Vector3f::UnitZ(), facade = -Eigen::Vector3f::UnitY();
  const double before_ground = shadowOverLit(*s.cloud, s, ground), after_ground = shadowOverLit(lit, s, ground);
  const double before_facade = shadowOverLit(*s.cloud, s, facade), after_facade = shadowOverLit(lit, s, facade);
  std::printf("SSR estimated %.3f (true %.1f) over %zu points; chroma ratios a %.3f b %.3f; filtered %zu\n",
              report.sun_sky_ratio, s.scene.options().sun_sky_ratio, report.estimation_points, report.a_ratio,
              report.b_ratio, report.filtered);
  std::printf("shadow/lit luminance of same albedo: ground %.3f -> %.3f, facades %.3f -> %.3f\n", before_ground,
              after_ground, before_facade, after_facade);
  EXPECT_NEAR(report.sun_sky_ratio, s.scene.options().sun_sky_ratio, 0.15);
  EXPECT_GT(report.local_pairs, 1000u);
  EXPECT_LT(before_ground, 0.5);
  EXPECT_NEAR(after_ground, 1.0, 0.06);
  EXPECT_LT(before_facade, 0.5);
  EXPECT_NEAR(after_facade, 1.0, 0.08);
  // Relit shadow points against the colour the model gives them in sunlight.
  double err_before = 0, err_after = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < lit.size(); ++i) {
    if (!s.scan.in_shadow[i] || lit[i].normal_z < 0.9f) continue;
    const auto& p = lit[i];
    const double light = s.scene.options().sun_sky_ratio * std::max(0.0, s.scene.sunDirection().z()) + 1;
    const Eigen::Vector3f truth = (s.scan.albedo[i] * float(LitStreet::kExposure * light)).cwiseMin(1.f);
    err_before += (rgbOf((*s.cloud)[i]) - truth).squaredNorm() / 3;
    err_after += (rgbOf(p) - truth).squaredNorm() / 3;
    ++n;
  }
  err_before = std::sqrt(err_before / n);
  err_after = std::sqrt(err_after / n);
  std::printf("ground shadow points %zu: RMS colour error against sunlit truth %.4f -> %.4f\n", n, err_before, err_after);
  EXPECT_LT(err_after, 0.1 * err_before);
  EXPECT_LT(err_after, 0.02);
}

TEST(ShadowCorrection, ManuscriptRatioOfMeansStillRelights) {
  // The equation before 4.6 on the boundary band's class means (local_pair_ratio off): on
  // these model colours close to the true ratio too (it assumes the same mean albedo on both
  // sides of the band, which the photo-coloured street of the bench breaks more).
  const LitStreet& s = LitStreet::get();
  auto p = s.parameters(paps::RelightTarget::AllLit);
  p.local_pair_ratio = false;
  paps::ShadowCorrectionReport report;
  std::vector<Eigen::Vector3f> colours;
  for (const auto& q : *s.cloud) colours.push_back(rgbOf(q));
  paps::Normals normals;
  for (const auto& q : *s.cloud) normals.push_back(q.getNormalVector3fMap());
  paps::correctShadows(paps::positionsOf(*s.cloud), normals, colours, s.scan.in_shadow, p, &report);
  std::printf("SSR from the class means: %.3f\n", report.sun_sky_ratio);
  EXPECT_EQ(report.local_pairs, 0u);
  EXPECT_NEAR(report.sun_sky_ratio, s.scene.options().sun_sky_ratio, 0.4);
}

TEST(ShadowCorrection, AllShadowEvensOutTheLight) {
  const LitStreet& s = LitStreet::get();
  paps::ShadowCorrection<pcl::PointXYZRGBNormal> correct;
  correct.setInputCloud(s.cloud);
  correct.setShadowLabels(s.scan.in_shadow);
  correct.setParameters(s.parameters(paps::RelightTarget::AllShadow));
  Cloud dark;
  correct.filter(dark);
  const double ground = shadowOverLit(dark, s, Eigen::Vector3f::UnitZ());
  const double facade = shadowOverLit(dark, s, -Eigen::Vector3f::UnitY());
  std::printf("all shadow: shadow/lit luminance ground %.3f, facades %.3f\n", ground, facade);
  EXPECT_NEAR(ground, 1.0, 0.06);
  EXPECT_NEAR(facade, 1.0, 0.08);
}

TEST(ShadowCorrection, SameOutputWithOneAndTwoThreads) {
  const LitStreet& s = LitStreet::get();
  Cloud out[2];
  for (int t = 0; t < 2; ++t) {
    paps::ShadowCorrection<pcl::PointXYZRGBNormal> correct;
    correct.setNumberOfThreads(t + 1);
    correct.setInputCloud(s.cloud);
    correct.setShadowLabels(s.scan.in_shadow);
    correct.setParameters(s.parameters(paps::RelightTarget::AllLit));
    correct.filter(out[t]);
  }
  ASSERT_EQ(out[0].size(), out[1].size());
  for (std::size_t i = 0; i < out[0].size(); ++i) ASSERT_EQ(out[0][i].rgba, out[1][i].rgba) << i;
}

TEST(ShadowCorrection, ProgressCallbackCancels) {
  const LitStreet& s = LitStreet::get();
  paps::ShadowCorrection<pcl::PointXYZRGBNormal> c;
  c.setInputCloud(s.cloud);
  c.setShadowLabels(s.scan.in_shadow);
  c.setParameters(s.parameters(paps::RelightTarget::AllLit));
  int calls = 0;
  c.setProgressCallback([&](const std::string&, float) { return ++calls < 3; });
  Cloud out;
  EXPECT_THROW(c.filter(out), paps::Cancelled);
  EXPECT_GE(calls, 3);
}

TEST(ShadowCorrection, BadInputThrows) {
  const LitStreet& s = LitStreet::get();
  paps::ShadowCorrection<pcl::PointXYZRGBNormal> c;
  Cloud out;
  EXPECT_THROW(c.filter(out), paps::InvalidInput);  // no cloud
  c.setInputCloud(s.cloud);
  EXPECT_THROW(c.filter(out), paps::InvalidInput);  // no labels
  c.setShadowLabels(std::vector<std::uint8_t>(3, 0));
  EXPECT_THROW(c.filter(out), paps::InvalidParameter);  // no sun direction (default NaN)
  c.setParameters(s.parameters(paps::RelightTarget::AllLit));
  EXPECT_THROW(c.filter(out), paps::InvalidParameter);  // 3 labels for many points
  c.setShadowLabels(std::vector<std::uint8_t>(s.cloud->size(), 0));
  EXPECT_THROW(c.filter(out), paps::InvalidInput);  // no shadow point: no SSR to estimate
  auto p = s.parameters(paps::RelightTarget::AllLit);
  p.sun_sky_ratio = 2;
  c.setParameters(p);
  c.filter(out);  // given SSR, everything lit: nothing changes but the penumbra (none)
  for (std::size_t i = 0; i < out.size(); i += 97) EXPECT_EQ(out[i].rgba, (*s.cloud)[i].rgba);
  Cloud::Ptr nans(new Cloud);
  pcl::PointXYZRGBNormal q;
  q.x = q.y = q.z = NAN;
  nans->push_back(q);
  c.setInputCloud(nans);
  c.setShadowLabels({1});
  EXPECT_THROW(c.filter(out), paps::InvalidInput);
  c.setInputCloud(Cloud::Ptr(new Cloud));
  EXPECT_THROW(c.filter(out), paps::InvalidInput);
  auto bad = [&](auto change) {
    auto q = s.parameters(paps::RelightTarget::AllLit);
    change(q);
    EXPECT_THROW(c.setParameters(q), paps::InvalidParameter);
  };
  bad([](auto& q) { q.sun_direction = Eigen::Vector3f::Zero(); });
  bad([](auto& q) { q.sun_direction = -q.ground_normal; });  // below the horizon
  bad([](auto& q) { q.sun_direction = Eigen::Vector3f(1, 0, 0); q.ground_normal = Eigen::Vector3f(0, 0, 1); });
  bad([](auto& q) { q.ground_normal = Eigen::Vector3f::Constant(INFINITY); });
  bad([](auto& q) { q.sun_sky_ratio = -1; });
  bad([](auto& q) { q.sun_sky_ratio = 1e9f; });
  bad([](auto& q) { q.neighbours = 1; });
  bad([](auto& q) { q.estimation_neighbours = 100000; });
}

}  // namespace fusion_shadow_correction_test
