#pragma once
// A calibrated camera: pinhole intrinsics with Brown-Conrady distortion (manuscript 4.2) and a
// rigid pose. Conventions are OpenCV's: camera x right, y down, z forward; pixel (0, 0) is the
// centre of the top-left pixel. A pose is camera-to-world (the camera sits at translation()).
#include <vector>

#include <Eigen/Geometry>

namespace paps {

/// Intrinsic parameters of a camera, in pixels; distortion coefficients as OpenCV orders them
/// (k1, k2, p1, p2, k3), radial k on the normalised radius, tangential p.
struct CameraIntrinsics {
  int width = 0, height = 0;       ///< image size, pixels (>= 8 each)
  double fx = 0, fy = 0;           ///< focal lengths, pixels (> 0)
  double cx = 0, cy = 0;           ///< principal point, pixels
  double k1 = 0, k2 = 0, k3 = 0;   ///< radial distortion
  double p1 = 0, p2 = 0;           ///< tangential distortion

  /// Square pixels, principal point at the centre, no distortion; `horizontal_fov_deg` in (1, 170).
  static CameraIntrinsics fromFieldOfView(int width, int height, double horizontal_fov_deg);
  /// Throws InvalidParameter for a size below 8, a focal length <= 0 or non-finite values.
  void validate() const;
  /// The same camera for an image `factor` times the size (pyramids; factor in [1e-3, 8]): the
  /// size rounded to whole pixels (at least 8), the focal lengths and principal point scaled
  /// by the rounded size's ratio on each axis, so it fits the image resized to exactly
  /// width x height (cv::resize with that size).
  CameraIntrinsics scaled(double factor) const;
  /// The same lens with the image widened by `margin` pixels on every side (wide-angle image of
  /// the coarse registration, 4.4.1): the principal point moves, the focal lengths stay.
  CameraIntrinsics widened(int margin) const;

  /// Distorted pixel of a point in camera coordinates; false when z <= 1e-9 (behind the
  /// camera), more than 80 degrees off the axis, or where the distortion polynomial has folded
  /// back (its radius no longer grows: such points would land inside the image by mistake).
  bool project(const Eigen::Vector3d& point_in_camera, Eigen::Vector2d& pixel) const;
  /// Unit direction, in camera coordinates, of the ray through a (distorted) pixel.
  Eigen::Vector3d ray(const Eigen::Vector2d& pixel) const;
  /// True when the pixel lies in the image (rounded to the nearest pixel centre).
  bool inside(const Eigen::Vector2d& pixel) const {
    return pixel.x() > -0.5 && pixel.y() > -0.5 && pixel.x() < width - 0.5 && pixel.y() < height - 0.5;
  }
};

/// Camera-to-world rigid transform.
using CameraPose = Eigen::Isometry3d;

/// Pose of a camera at `eye` looking at `target`, with `up` (world) pointing up in the image.
CameraPose lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                  const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

/// A small pose change in the camera's own frame: yaw (about camera y), pitch (about camera
/// x), roll (about camera z), radians; then a translation (metres, camera frame).
struct PoseDelta {
  double yaw = 0, pitch = 0, roll = 0;
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
};
/// pose * delta: the camera turned and moved by `delta` in its own frame.
CameraPose applyPoseDelta(const CameraPose& pose, const PoseDelta& delta);

/// Registration error in pixels: the mean image distance between the projections of `points`
/// (world) through `truth` and through `estimate`, over the points that project inside the
/// image under `truth`. NaN when none does. The measure of manuscript Table 4.1.
double meanReprojectionError(const CameraIntrinsics& camera, const CameraPose& truth,
                             const CameraPose& estimate, const std::vector<Eigen::Vector3d>& points);

}  // namespace paps
