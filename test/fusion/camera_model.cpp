#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/fusion/camera_model.h>
#include <paps/fusion/point_visibility.h>
#include <paps/fusion/synthetic_street.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace fusion_camera_model_test {

paps::CameraIntrinsics distortedCamera() {
  paps::CameraIntrinsics c = paps::CameraIntrinsics::fromFieldOfView(320, 240, 70);
  c.k1 = -0.12;
  c.k2 = 0.03;
  c.p1 = 0.001;
  c.p2 = -0.0015;
  return c;
}

TEST(CameraModel, RayAndProjectAreInverse) {
  const auto c = distortedCamera();
  for (double u : {0.0, 40.5, 160.0, 319.0})
    for (double v : {0.0, 77.0, 239.0}) {
      Eigen::Vector2d back;
      ASSERT_TRUE(c.project(3.7 * c.ray({u, v}), back));
      EXPECT_NEAR(back.x(), u, 1e-6);
      EXPECT_NEAR(back.y(), v, 1e-6);
    }
}

TEST(CameraModel, PointsBeyondTheDistortionFoldDoNotProject) {
  // k1 = -0.08 alone: the radius r (1 + k1 r^2) peaks at r^2 = 1 / 0.24 (64 degrees off axis),
  // then shrinks back into the image. Those points must not project.
  auto c = paps::CameraIntrinsics::fromFieldOfView(320, 240, 80);
  c.k1 = -0.08;
  Eigen::Vector2d px;
  EXPECT_TRUE(c.project({1.5, 0, 1}, px));   // r^2 = 2.25 < 4.17
  EXPECT_FALSE(c.project({2.5, 0, 1}, px));  // r^2 = 6.25: folded
  EXPECT_FALSE(c.project({10, 0, 1}, px));   // 84 degrees off axis
}

TEST(CameraModel, LookAtPutsTheTargetAtThePrincipalPointAndUpIsUp) {
  const auto c = paps::CameraIntrinsics::fromFieldOfView(100, 80, 60);
  const auto pose = paps::lookAt({1, 2, 3}, {5, 2, 3});
  Eigen::Vector2d px, above;
  ASSERT_TRUE(c.project(pose.inverse() * Eigen::Vector3d(5, 2, 3), px));
  EXPECT_NEAR(px.x(), c.cx, 1e-9);
  EXPECT_NEAR(px.y(), c.cy, 1e-9);
  ASSERT_TRUE(c.project(pose.inverse() * Eigen::Vector3d(5, 2, 4), above));
  EXPECT_LT(above.y(), px.y());  // higher in the world, higher in the image (smaller row)
}

TEST(CameraModel, ScaledAndWidenedKeepTheRays) {
  const auto c = distortedCamera();
  const Eigen::Vector3d p(0.3, -0.2, 2.0);
  Eigen::Vector2d a, b, w;
  ASSERT_TRUE(c.project(p, a));
  ASSERT_TRUE(c.scaled(0.5).project(p, b));
  EXPECT_NEAR(b.x() + 0.5, (a.x() + 0.5) * 0.5, 1e-9);
  EXPECT_NEAR(b.y() + 0.5, (a.y() + 0.5) * 0.5, 1e-9);
  ASSERT_TRUE(c.widened(30).project(p, w));
  EXPECT_NEAR(w.x(), a.x() + 30, 1e-9);
}

// A size that falls between pixels is rounded, and the lens follows the rounded size, so the
// camera fits the image resized to exactly that size: 322 x 242 at 1/4 is 81 x 61 (80.5 and
// 60.5 rounded up), each axis scaled by its own ratio.
TEST(CameraModel, ScaledToWholePixelsFollowsTheRoundedSize) {
  auto c = paps::CameraIntrinsics::fromFieldOfView(322, 242, 80);
  c.k1 = -0.08;
  const auto q = c.scaled(0.25);
  EXPECT_EQ(q.width, 81);
  EXPECT_EQ(q.height, 61);
  const Eigen::Vector3d p(0.3, -0.2, 2.0);
  Eigen::Vector2d a, b;
  ASSERT_TRUE(c.project(p, a));
  ASSERT_TRUE(q.project(p, b));
  EXPECT_NEAR(b.x() + 0.5, (a.x() + 0.5) * 81.0 / 322.0, 1e-9);
  EXPECT_NEAR(b.y() + 0.5, (a.y() + 0.5) * 61.0 / 242.0, 1e-9);
  // The image's corners stay the image's corners.
  EXPECT_NEAR((q.cx + 0.5) / q.width, (c.cx + 0.5) / c.width, 1e-12);
}

TEST(CameraModel, ReprojectionErrorOfAKnownShift) {
  const auto c = paps::CameraIntrinsics::fromFieldOfView(200, 200, 90);  // fx = 100
  const auto truth = paps::lookAt({0, 0, 0}, {0, 10, 0});
  std::vector<Eigen::Vector3d> points;
  for (int i = -3; i <= 3; ++i) points.push_back({i * 0.5, 10, i * 0.3});
  paps::PoseDelta d;
  d.yaw = std::atan(0.05);  // the centre moves by fx * tan = 5 pixels
  const double e = paps::meanReprojectionError(c, truth, paps::applyPoseDelta(truth, d), points);
  EXPECT_NEAR(e, 5.0, 0.3);
  EXPECT_DOUBLE_EQ(paps::meanReprojectionError(c, truth, truth, points), 0.0);
}

TEST(CameraModel, BadParametersThrow) {
  EXPECT_THROW(paps::CameraIntrinsics::fromFieldOfView(320, 240, 0), paps::InvalidParameter);
  EXPECT_THROW(paps::CameraIntrinsics::fromFieldOfView(4, 240, 60), paps::InvalidParameter);
  auto c = distortedCamera();
  c.k1 = NAN;
  EXPECT_THROW(c.validate(), paps::InvalidParameter);
  EXPECT_THROW(paps::lookAt({0, 0, 0}, {0, 0, 5}), paps::InvalidParameter);
}

TEST(PointVisibility, ASparseFrontPlaneHidesTheBackPlane) {
  // A front plane sampled every 0.1 m at 5 m and a dense back plane at 10 m: through the gaps
  // of the front, the back is hidden wherever the front covers it.
  paps::Positions points;
  for (int i = -10; i <= 10; ++i)
    for (int j = -10; j <= 10; ++j) points.push_back({i * 0.1f, 5.f, j * 0.1f});
  const std::size_t front = points.size();
  for (int i = -60; i <= 60; ++i)
    for (int j = -60; j <= 60; ++j) points.push_back({i * 0.05f, 10.f, j * 0.05f});
  const auto c = paps::CameraIntrinsics::fromFieldOfView(160, 160, 60);
  const auto pose = paps::lookAt({0, 0, 0}, {0, 1, 0});
  const auto proj = paps::projectVisiblePoints(points, c, pose);
  std::size_t front_visible = 0, back_behind = 0, back_behind_visible = 0, back_outside_visible = 0, back_outside = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (i < front) { front_visible += proj.visible[i]; continue; }
    if (!std::isfinite(proj.depth[i])) continue;
    const bool behind_front = std::abs(points[i].x()) < 0.45 * 2 && std::abs(points[i].z()) < 0.45 * 2;
    const bool well_outside = std::abs(points[i].x()) > 1.2 * 2 || std::abs(points[i].z()) > 1.2 * 2;
    if (behind_front) { ++back_behind; back_behind_visible += proj.visible[i]; }
    if (well_outside) { ++back_outside; back_outside_visible += proj.visible[i]; }
  }
  EXPECT_EQ(front_visible, front);
  ASSERT_GT(back_behind, 500u);
  EXPECT_EQ(back_behind_visible, 0u);
  EXPECT_EQ(back_outside_visible, back_outside);
}

TEST(SyntheticStreet, ScanAndPhotoAgreeOnShadowsAndGeometry) {
  paps::synthetic::StreetOptions o;
  o.length = 20;
  o.scan_step = 0.3;
  o.scan_angle_step_deg = 1.0;
  paps::synthetic::StreetScene scene(o);
  const auto scan = scene.scan();
  ASSERT_GT(scan.cloud.size(), 5000u);
  ASSERT_EQ(scan.reflectance.size(), scan.cloud.size());
  std::size_t shadow = 0;
  for (auto s : scan.in_shadow) shadow += s;
  EXPECT_GT(shadow, scan.cloud.size() / 10);  // the sun leaves both lit and shadowed parts
  EXPECT_LT(shadow, scan.cloud.size() * 9 / 10);
  const auto c = paps::CameraIntrinsics::fromFieldOfView(160, 120, 70);
  const auto pose = scene.cameraPoses(1, 0, 0, 1)[0];
  const auto photo = scene.photo(c, pose);
  // Points visible in the photo lie at the photo's depth, and share its shadow label.
  const auto proj = paps::projectVisiblePoints(paps::positionsOf(scan.cloud), c, pose);
  std::size_t checked = 0, agree = 0;
  for (std::size_t i = 0; i < scan.cloud.size(); ++i) {
    if (!proj.visible[i]) continue;
    const int u = static_cast<int>(std::lround(proj.pixel[i].x())), v = static_cast<int>(std::lround(proj.pixel[i].y()));
    const Eigen::Vector3d ray = pose.linear() * c.ray({double(u), double(v)});
    const double along = (scan.cloud[i].getVector3fMap().cast<double>() - pose.translation()).norm();
    if (std::abs(along - photo.depth.at<float>(v, u)) > 0.1 * along) continue;  // pixel-centre offset on an edge
    (void)ray;
    ++checked;
    agree += (photo.shadow.at<std::uint8_t>(v, u) != 0) == (scan.in_shadow[i] != 0);
  }
  ASSERT_GT(checked, 1000u);
  EXPECT_GT(double(agree) / checked, 0.95);  // the rest: shadow edges under cornices, a pixel wide
}

}  // namespace fusion_camera_model_test
