// An organized RGB-D frame (Kinect, RealSense, rectified stereo) is a photo with a known
// camera: paps::cameraOfOrganizedCloud recovers it from the grid. Processing the cloud
// (pcl::VoxelGrid here; denoising or upsampling alike) moves points off the grid and loses
// their colours; paps::PointColorization gives them back from the frame's own photo, with
// visibility.
//
//   example_rgbd_frame [FRAME.pcd [OUT.pcd]]   (e.g. PCL's milk_cartoon_all_small_clorox.pcd)
//
// Without arguments it runs on a synthetic frame (the corner of a room with a ball, coloured
// by a known function of position) and exits 1 unless the camera comes back exactly and the
// voxel centroids the photo sees (99% of them: a centroid can fall inside the ball, behind its
// surface) get their colour to within 0.02 RMS.
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include <pcl/filters/voxel_grid.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/fusion/organized_cloud_camera.h>
#include <paps/fusion/point_colorization.h>
#include <paps/fusion/point_visibility.h>

namespace {

// The true colour of a point of the synthetic room (linear RGB in [0, 1]).
Eigen::Vector3f roomColour(const Eigen::Vector3f& p) {
  return {0.5f + 0.4f * std::sin(2.0f * p.x()), 0.5f + 0.4f * std::cos(1.5f * p.y()), 0.2f + 0.25f * p.z()};
}

// What an RGB-D camera at `pose` records of a room corner (floor z = 0, walls x = 0, y = 4)
// with a ball: 160 x 120 pixels, point (u, v) at pixel (u, v).
pcl::PointCloud<pcl::PointXYZRGBA> syntheticFrame(const paps::CameraIntrinsics& camera, const paps::CameraPose& pose) {
  pcl::PointCloud<pcl::PointXYZRGBA> frame(camera.width, camera.height);
  const Eigen::Vector3d eye = pose.translation(), ball(2.0, 2.5, 0.6);
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u) {
      const Eigen::Vector3d d = pose.linear() * camera.ray({double(u), double(v)});
      double t = std::numeric_limits<double>::infinity();
      for (const auto& [n, offset] : {std::pair{Eigen::Vector3d::UnitZ(), 0.0}, std::pair{Eigen::Vector3d::UnitX(), 0.0},
                                      std::pair{Eigen::Vector3d::UnitY(), 4.0}}) {
        const double s = n.dot(d), h = std::abs(s) > 1e-12 ? (offset - n.dot(eye)) / s : -1;
        if (h > 1e-6 && h < t) t = h;
      }
      const Eigen::Vector3d oc = eye - ball;
      const double b = oc.dot(d), disc = b * b - oc.squaredNorm() + 0.25;
      if (disc > 0 && -b - std::sqrt(disc) > 1e-6) t = std::min(t, -b - std::sqrt(disc));
      pcl::PointXYZRGBA& p = frame.at(u, v);
      if (!std::isfinite(t)) {
        p.x = p.y = p.z = std::numeric_limits<float>::quiet_NaN();
        continue;
      }
      p.getVector3fMap() = (eye + t * d).cast<float>();
      const Eigen::Vector3f c = roomColour(p.getVector3fMap()) * 255.f + Eigen::Vector3f::Constant(0.5f);
      p.r = std::uint8_t(c.x()), p.g = std::uint8_t(c.y()), p.b = std::uint8_t(c.z()), p.a = 255;
    }
  return frame;
}

}  // namespace

int main(int argc, char** argv) try {
  const bool synthetic = argc < 2;
  paps::CameraIntrinsics truth;
  truth.width = 160, truth.height = 120, truth.fx = truth.fy = 150, truth.cx = 79.5, truth.cy = 59.5;
  const paps::CameraPose truth_pose = paps::lookAt({6.0, -1.5, 1.6}, {1.0, 2.5, 0.4});
  pcl::PointCloud<pcl::PointXYZRGBA> frame;
  if (synthetic) frame = syntheticFrame(truth, truth_pose);
  else pcl::fromPCLPointCloud2(paps::loadCloud(argv[1]), frame);  // paps::IoError if unreadable

  // 1. The frame's camera, pose and photo.
  const paps::OrganizedCloudCamera view = paps::cameraOfOrganizedCloud(frame);
  std::printf("camera: fx %.3f fy %.3f cx %.3f cy %.3f, grid fitted to %.4f px RMS\n", view.fit.camera.fx,
              view.fit.camera.fy, view.fit.camera.cx, view.fit.camera.cy, view.fit.rms_pixels);

  // 2. Any PCL processing that moves points off the grid: a voxel grid (its averaged colours
  //    kept aside as the reference, then dropped).
  pcl::PointCloud<pcl::PointXYZRGBA>::Ptr finite(new pcl::PointCloud<pcl::PointXYZRGBA>);
  for (const auto& p : frame)
    if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) finite->push_back(p);
  pcl::VoxelGrid<pcl::PointXYZRGBA> grid;
  grid.setInputCloud(finite);
  grid.setLeafSize(synthetic ? 0.05f : 0.01f, synthetic ? 0.05f : 0.01f, synthetic ? 0.05f : 0.01f);
  pcl::PointCloud<pcl::PointXYZRGBA> centroids;
  grid.filter(centroids);
  pcl::PointCloud<pcl::PointXYZRGBA>::Ptr processed(new pcl::PointCloud<pcl::PointXYZRGBA>(centroids));
  for (auto& p : *processed) p.r = p.g = p.b = 0;

  // 3. Colours back from the photo, in the grabber's own point type.
  paps::PointColorization<pcl::PointXYZRGBA> colorize;
  colorize.setInputCloud(processed);
  colorize.addView(view.photo.image, view.photo.camera, view.photo.pose);
  pcl::PointCloud<pcl::PointXYZRGBA> coloured;
  colorize.filter(coloured);

  // Unseen points keep their input colour (black here): scored are the points the photo sees.
  const paps::ProjectedPoints seen = paps::projectVisiblePoints(paps::positionsOf(*processed), view.photo.camera,
                                                                view.photo.pose);
  double squares = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < coloured.size(); ++i) {
    if (!seen.visible[i]) continue;
    const Eigen::Vector3f got(coloured[i].r / 255.f, coloured[i].g / 255.f, coloured[i].b / 255.f);
    const Eigen::Vector3f want = synthetic ? roomColour(coloured[i].getVector3fMap())
                                           : Eigen::Vector3f(centroids[i].r, centroids[i].g, centroids[i].b) / 255.f;
    squares += (got - want).squaredNorm() / 3;
    ++n;
  }
  const double rms = std::sqrt(squares / double(std::max<std::size_t>(n, 1)));
  std::printf("%zu voxel centroids, %zu coloured from the photo, %zu unseen; colour RMS %.4f (seen points) against %s\n",
              coloured.size(), colorize.getReport().coloured, colorize.getReport().unseen, rms,
              synthetic ? "the true colours" : "the voxel grid's averaged colours");
  if (argc > 2) pcl::io::savePCDFileBinary(argv[2], coloured);
  if (!synthetic) return 0;
  const bool camera_ok = std::abs(view.fit.camera.fx - truth.fx) < 1e-3 && std::abs(view.fit.camera.cy - truth.cy) < 1e-3 &&
                         (view.fit.pose.translation() - truth_pose.translation()).norm() < 1e-4;
  return camera_ok && rms < 0.02 && colorize.getReport().unseen < coloured.size() / 100 ? 0 : 1;
} catch (const paps::Error& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
