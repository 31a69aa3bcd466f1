#pragma once
// The camera of an organized RGB-D cloud (Kinect, RealSense, rectified stereo): an organized
// cloud stores point (u, v) at pixel (u, v) of the camera that measured it, so that camera can
// be recovered exactly. A 3 x 4 projection matrix is fitted to the finite points and their
// pixels (direct linear transform on normalised coordinates), then split into a pinhole camera
// and a pose by an RQ decomposition. The point colours laid out on the grid give the photo, so
// a single organized cloud becomes a registered photo of itself: real data with a known pose for
// the registration (manuscript 4.4) and the colour stages (4.5), and a way into them for
// RGB-D users. Any frame convention works (PCL's OpenNI grabber writes some clouds with z
// pointing away from the scene): the pose absorbs it.
#include <cstddef>
#include <vector>

#include <Eigen/Core>
#include <pcl/point_cloud.h>

#include <paps/fusion/camera_model.h>
#include <paps/fusion/registered_photo.h>

namespace paps {

/// A pinhole camera fitted to 3D points and the pixels they were seen at.
struct PinholeFit {
  CameraIntrinsics camera;   ///< no distortion, no skew
  CameraPose pose;           ///< camera-to-world
  double rms_pixels = 0;     ///< reprojection error of the fitted points
  double max_pixels = 0;
  std::size_t points = 0;    ///< points fitted
};

/// Fits a pinhole camera of image size `width` x `height` to `points` seen at `pixels` (one
/// each). Throws InvalidInput for fewer than 12 pairs, sizes that differ, non-finite values,
/// points on a line or a plane (a plane does not fix the camera), or a fit where the points do
/// not project in front of the camera.
PinholeFit fitPinholeCamera(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector2d>& pixels,
                            int width, int height);

struct OrganizedCameraOptions {
  int sample_step = 3;          ///< fit on every sample_step-th row and column (1 to 64)
  double max_rms_pixels = 0.5;  ///< refuse a worse fit: the grid is not a pinhole camera's
  void validate() const;
};

/// The photo of an organized cloud: its colours on the grid (all pixels, also those whose point
/// is NaN: RGB-D clouds keep the colour there) and the fitted camera and pose.
struct OrganizedCloudCamera {
  RegisteredPhoto photo;
  PinholeFit fit;
};

/// PointT needs x, y, z and r, g, b (PointXYZRGB, PointXYZRGBA, PointXYZRGBNormal are built).
/// Throws InvalidInput for a cloud that is not organized (height 1), has fewer than 12 finite
/// points, cannot be fitted, or whose fit exceeds `max_rms_pixels` (for instance a spinning
/// LiDAR's scan stored as rings x azimuths).
template <typename PointT>
OrganizedCloudCamera cameraOfOrganizedCloud(const pcl::PointCloud<PointT>& cloud, const OrganizedCameraOptions& options = {});

}  // namespace paps
