#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>

#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/fusion/organized_cloud_camera.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace fusion_organized_cloud_camera_test {

using paps::CameraIntrinsics;
using paps::CameraPose;

CameraIntrinsics trueCamera() {
  CameraIntrinsics c;
  c.width = 160;
  c.height = 120;
  c.fx = 150.0;
  c.fy = 143.5;  // non-square pixels and an off-centre principal point
  c.cx = 83.25;
  c.cy = 56.5;
  return c;
}

// What an RGB-D camera at `pose` records of the corner of a room (floor z = 0, walls x = 0 and
// y = 4) with a ball in it: point (u, v) at pixel (u, v), the colour a function of the pixel.
// `depth_noise` moves points along their ray, `noise` in any direction (metres, Gaussian).
pcl::PointCloud<pcl::PointXYZRGB> rgbdFrame(const CameraIntrinsics& camera, const CameraPose& pose,
                                            double depth_noise = 0, bool planar = false, double noise = 0) {
  pcl::PointCloud<pcl::PointXYZRGB> cloud(camera.width, camera.height);
  paps::Random random(3);
  const Eigen::Vector3d eye = pose.translation();
  const Eigen::Vector3d ball(2.0, 2.5, 0.6);
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u) {
      const Eigen::Vector3d d = pose.linear() * camera.ray({double(u), double(v)});
      double t = std::numeric_limits<double>::infinity();
      auto plane = [&](const Eigen::Vector3d& n, double offset) {  // n.x = offset
        const double s = n.dot(d);
        if (std::abs(s) < 1e-12) return;
        const double h = (offset - n.dot(eye)) / s;
        if (h > 1e-6 && h < t) t = h;
      };
      plane(Eigen::Vector3d::UnitZ(), 0);
      if (!planar) {
        plane(Eigen::Vector3d::UnitX(), 0);
        plane(Eigen::Vector3d::UnitY(), 4);
        const Eigen::Vector3d oc = eye - ball;  // ray-sphere, radius 0.5
        const double b = oc.dot(d), c = oc.squaredNorm() - 0.25, disc = b * b - c;
        if (disc > 0 && -b - std::sqrt(disc) > 1e-6) t = std::min(t, -b - std::sqrt(disc));
      }
      pcl::PointXYZRGB& p = cloud.at(u, v);
      p.r = std::uint8_t(u);
      p.g = std::uint8_t(v);
      p.b = std::uint8_t((u * 7 + v * 3) % 256);
      if (!std::isfinite(t) || t > 30) {  // sky: no depth, colour kept (as RGB-D clouds do)
        p.x = p.y = p.z = std::numeric_limits<float>::quiet_NaN();
        continue;
      }
      if (depth_noise > 0) t += depth_noise * random.gaussian();
      const Eigen::Vector3d jitter = random.gaussian3();
      p.getVector3fMap() = (eye + t * d + noise * jitter).cast<float>();
    }
  cloud.is_dense = false;
  return cloud;
}

CameraPose framePose() { return paps::lookAt({6.0, -1.5, 1.6}, {1.0, 2.5, 0.4}); }

TEST(OrganizedCloudCamera, RecoversTheCameraThePoseAndThePhotoExactly) {
  const CameraIntrinsics truth = trueCamera();
  const auto cloud = rgbdFrame(truth, framePose());
  const auto r = paps::cameraOfOrganizedCloud(cloud, {});
  EXPECT_NEAR(r.fit.camera.fx, truth.fx, 1e-6 * truth.fx);
  EXPECT_NEAR(r.fit.camera.fy, truth.fy, 1e-6 * truth.fy);
  EXPECT_NEAR(r.fit.camera.cx, truth.cx, 1e-5);
  EXPECT_NEAR(r.fit.camera.cy, truth.cy, 1e-5);
  EXPECT_EQ(r.fit.camera.width, 160);
  EXPECT_EQ(r.fit.camera.height, 120);
  EXPECT_LT((r.fit.pose.translation() - framePose().translation()).norm(), 1e-6);
  EXPECT_LT((r.fit.pose.linear() - framePose().linear()).norm(), 1e-7);
  EXPECT_LT(r.fit.rms_pixels, 1e-5);
  EXPECT_GT(r.fit.points, 1000u);
  // The photo is the grid of colours, NaN points included.
  ASSERT_EQ(r.photo.image.type(), CV_8UC3);
  for (int v : {0, 60, 119})
    for (int u : {0, 80, 159}) {
      const auto& p = cloud.at(u, v);
      EXPECT_EQ(r.photo.image.at<cv::Vec3b>(v, u), cv::Vec3b(p.b, p.g, p.r));
    }
  EXPECT_NO_THROW(r.photo.validate());
}

// PCL's OpenNI grabber wrote some clouds in a frame whose z points away from the scene (the
// tutorial's milk_cartoon_all_small_clorox.pcd has z < 0): the pose absorbs the convention.
TEST(OrganizedCloudCamera, AnyWorldFrameIsAbsorbedByThePose) {
  const CameraIntrinsics truth = trueCamera();
  auto cloud = rgbdFrame(truth, framePose());
  Eigen::Isometry3d gl = Eigen::Isometry3d::Identity();
  gl.linear() = Eigen::Vector3d(1, -1, -1).asDiagonal();
  gl.translation() = Eigen::Vector3d(-3, 10, 0.5);
  for (auto& p : cloud)
    if (std::isfinite(p.x)) p.getVector3fMap() = (gl * p.getVector3fMap().cast<double>()).cast<float>();
  const auto r = paps::cameraOfOrganizedCloud(cloud);
  EXPECT_NEAR(r.fit.camera.fx, truth.fx, 1e-4);
  EXPECT_NEAR(r.fit.camera.cy, truth.cy, 1e-4);
  const CameraPose expected = gl * framePose();
  EXPECT_LT((r.fit.pose.translation() - expected.translation()).norm(), 1e-4);
  EXPECT_LT((r.fit.pose.linear() - expected.linear()).norm(), 1e-5);
  EXPECT_NEAR(r.fit.pose.linear().determinant(), 1.0, 1e-9);
}

// The depth noise of an RGB-D sensor moves points along their rays: the pixels stay exact, and
// so does the camera (1 cm at 3 to 8 m here).
TEST(OrganizedCloudCamera, DepthNoiseAlongTheRaysKeepsTheCameraExact) {
  const CameraIntrinsics truth = trueCamera();
  const auto r = paps::cameraOfOrganizedCloud(rgbdFrame(truth, framePose(), 0.01));
  EXPECT_NEAR(r.fit.camera.fx, truth.fx, 1e-4 * truth.fx);
  EXPECT_NEAR(r.fit.camera.cy, truth.cy, 1e-3);
  EXPECT_LT(r.fit.rms_pixels, 1e-3);
}

// Noise across the rays (5 mm at 3 to 8 m, about 0.15 px) shows in the residual; the camera
// stays within 1%.
TEST(OrganizedCloudCamera, NoiseAcrossTheRaysShowsInTheResidual) {
  const CameraIntrinsics truth = trueCamera();
  const auto r = paps::cameraOfOrganizedCloud(rgbdFrame(truth, framePose(), 0, false, 0.005));
  EXPECT_NEAR(r.fit.camera.fx, truth.fx, 0.01 * truth.fx);
  EXPECT_NEAR(r.fit.camera.fy, truth.fy, 0.01 * truth.fy);
  EXPECT_NEAR(r.fit.camera.cx, truth.cx, 1.0);
  EXPECT_NEAR(r.fit.camera.cy, truth.cy, 1.0);
  EXPECT_LT(r.fit.rms_pixels, 0.3);
  EXPECT_GT(r.fit.rms_pixels, 0.03);  // the noise does show
}

TEST(OrganizedCloudCamera, APlanarSceneIsRefusedWithAReason) {
  const auto cloud = rgbdFrame(trueCamera(), framePose(), 0, true);
  try {
    paps::cameraOfOrganizedCloud(cloud);
    FAIL() << "a planar scene cannot fix the camera";
  } catch (const paps::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("plane"), std::string::npos) << e.what();
  }
}

// A spinning LiDAR's scan stored as rings x azimuths is organized, but not by one pinhole.
TEST(OrganizedCloudCamera, AGridThatIsNotAPinholeImageIsRefused) {
  pcl::PointCloud<pcl::PointXYZRGB> cloud(360, 16);
  paps::Random random(9);
  for (int ring = 0; ring < 16; ++ring)
    for (int a = 0; a < 360; ++a) {
      const double az = a * M_PI / 180, el = (-15 + 2.0 * ring) * M_PI / 180, range = random.uniform(3, 20);
      cloud.at(a, ring).getVector3fMap() =
          Eigen::Vector3f(range * std::cos(el) * std::cos(az), range * std::cos(el) * std::sin(az), range * std::sin(el));
    }
  EXPECT_THROW(paps::cameraOfOrganizedCloud(cloud), paps::InvalidInput);
}

TEST(OrganizedCloudCamera, BadInputGetsClearErrors) {
  pcl::PointCloud<pcl::PointXYZRGB> unorganized = rgbdFrame(trueCamera(), framePose());
  unorganized.width = unorganized.size();
  unorganized.height = 1;
  EXPECT_THROW(paps::cameraOfOrganizedCloud(unorganized), paps::InvalidInput);
  EXPECT_THROW(paps::cameraOfOrganizedCloud(pcl::PointCloud<pcl::PointXYZRGB>()), paps::InvalidInput);
  pcl::PointCloud<pcl::PointXYZRGB> nan(32, 24);
  for (auto& p : nan) p.x = p.y = p.z = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(paps::cameraOfOrganizedCloud(nan), paps::InvalidInput);
  const auto cloud = rgbdFrame(trueCamera(), framePose());
  paps::OrganizedCameraOptions o;
  o.sample_step = 0;
  EXPECT_THROW(paps::cameraOfOrganizedCloud(cloud, o), paps::InvalidParameter);
  o.sample_step = 3;
  o.max_rms_pixels = -1;
  EXPECT_THROW(paps::cameraOfOrganizedCloud(cloud, o), paps::InvalidParameter);
  // The core fit checks its pairs.
  EXPECT_THROW(paps::fitPinholeCamera({Eigen::Vector3d::Zero()}, {}, 160, 120), paps::InvalidInput);
  std::vector<Eigen::Vector3d> points(20, Eigen::Vector3d(1, 2, 3));
  std::vector<Eigen::Vector2d> pixels(20, Eigen::Vector2d(5, 5));
  EXPECT_THROW(paps::fitPinholeCamera(points, pixels, 160, 120), paps::InvalidInput);
  points[3].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(paps::fitPinholeCamera(points, pixels, 160, 120), paps::InvalidInput);
}

// Random garbage on a grid (huge and tiny coordinates, repeated points, NaN and Inf, lines,
// random pixels): every call either returns a finite camera that passed its own checks or
// throws paps::InvalidInput; nothing crashes or returns NaN.
TEST(OrganizedCloudCamera, GarbageGivesACameraOrAClearError) {
  paps::Random random(11);
  int refused = 0, fitted = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int rows = 8 + int(random.below(24)), cols = 8 + int(random.below(24));
    pcl::PointCloud<pcl::PointXYZRGB> cloud(cols, rows);
    const int kind = int(random.below(6));
    const double scale = std::pow(10.0, random.uniform(-30, 30));
    for (auto& p : cloud) {
      const float z = float(random.uniform(0.1, 1) * scale), y = float(random.uniform(-1, 1) * scale);
      Eigen::Vector3f v(float(random.uniform(-1, 1) * scale), y, z);
      if (kind == 1) v = Eigen::Vector3f(1, 2, 3);                              // one point repeated
      if (kind == 2) v = Eigen::Vector3f(1, 1, 1) * float(random.uniform(0, 5));  // a line
      if (kind == 3 && random.below(3) == 0) v.x() = std::numeric_limits<float>::infinity();
      if (kind == 4 && random.below(2) == 0) v.y() = std::numeric_limits<float>::quiet_NaN();
      if (kind == 5) v *= 3.0e38f / float(std::max(scale, 1.0));                  // near FLT_MAX
      p.getVector3fMap() = v;
    }
    try {
      const auto r = paps::cameraOfOrganizedCloud(cloud);
      ++fitted;
      EXPECT_TRUE(std::isfinite(r.fit.camera.fx) && r.fit.camera.fx > 0) << trial;
      EXPECT_TRUE(std::isfinite(r.fit.camera.fy) && r.fit.camera.fy > 0) << trial;
      EXPECT_TRUE(r.fit.pose.matrix().allFinite()) << trial;
      EXPECT_LE(r.fit.rms_pixels, 0.5) << trial;
    } catch (const paps::InvalidInput&) {  // the data's fault, said as such
      ++refused;
    }
  }
  EXPECT_EQ(refused + fitted, 300);
  EXPECT_GT(refused, 250);  // random points on a grid are not a pinhole image
}

// PCL's tutorial Kinect frame (python3-pcl, fetched by scripts/fetch_samples.sh); skipped if
// absent. Its grid is the image of a 525 px pinhole at the centre of a 640 x 480 image.
TEST(OrganizedCloudCamera, RealKinectFrame) {
  const char* samples = std::getenv("PAPS_SAMPLES");
  const char* home = std::getenv("HOME");
  const std::string path = (samples ? std::string(samples) : std::string(home ? home : ".") + "/.cache/paps/samples") +
                           "/milk_cartoon_all_small_clorox.pcd";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no sample at " << path;
  pcl::PointCloud<pcl::PointXYZRGBA> cloud;
  ASSERT_EQ(pcl::io::loadPCDFile(path, cloud), 0);
  const auto r = paps::cameraOfOrganizedCloud(cloud);
  EXPECT_NEAR(r.fit.camera.fx, 525.0, 0.01);
  EXPECT_NEAR(r.fit.camera.fy, 525.0, 0.01);
  EXPECT_NEAR(r.fit.camera.cx, 319.5, 0.01);
  EXPECT_NEAR(r.fit.camera.cy, 239.5, 0.01);
  EXPECT_LT(r.fit.rms_pixels, 0.01);
  EXPECT_LT(r.fit.pose.translation().norm(), 1e-4);
  EXPECT_GT(r.fit.pose.linear()(0, 0), 0.9999);   // x kept,
  EXPECT_LT(r.fit.pose.linear()(1, 1), -0.9999);  // y and z flipped: the grabber's frame
}

}  // namespace fusion_organized_cloud_camera_test
