#include <paps/fusion/camera_model.h>

#include <cmath>
#include <limits>

#include <paps/core/error.h>

namespace paps {

CameraIntrinsics CameraIntrinsics::fromFieldOfView(int width, int height, double horizontal_fov_deg) {
  requireInRange("horizontal_fov_deg", horizontal_fov_deg, 1.0, 170.0);
  CameraIntrinsics c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = 0.5 * width / std::tan(0.5 * horizontal_fov_deg * M_PI / 180.0);
  c.cx = 0.5 * (width - 1);
  c.cy = 0.5 * (height - 1);
  c.validate();
  return c;
}

void CameraIntrinsics::validate() const {
  requireInRange("camera width", width, 8, 1 << 15);
  requireInRange("camera height", height, 8, 1 << 15);
  requirePositive("camera fx", fx);
  requirePositive("camera fy", fy);
  for (double v : {cx, cy, k1, k2, k3, p1, p2})
    if (!std::isfinite(v)) throw InvalidParameter("camera principal point or distortion", detail::toString(v), "finite values");
}

CameraIntrinsics CameraIntrinsics::scaled(double factor) const {
  requireInRange("scale factor", factor, 1e-3, 8.0);
  CameraIntrinsics c = *this;
  c.width = std::max(8, static_cast<int>(std::lround(width * factor)));
  c.height = std::max(8, static_cast<int>(std::lround(height * factor)));
  // The ratio of the whole-pixel sizes on each axis (the factor itself unless the size was
  // rounded), as an image resized to exactly width x height is sampled.
  const double sx = static_cast<double>(c.width) / width, sy = static_cast<double>(c.height) / height;
  c.fx = fx * sx;
  c.fy = fy * sy;
  // Pixel centres: x' + 0.5 = (x + 0.5) * sx.
  c.cx = (cx + 0.5) * sx - 0.5;
  c.cy = (cy + 0.5) * sy - 0.5;
  return c;
}

CameraIntrinsics CameraIntrinsics::widened(int margin) const {
  requireInRange("margin", margin, 0, 1 << 14);
  CameraIntrinsics c = *this;
  c.width += 2 * margin;
  c.height += 2 * margin;
  c.cx += margin;
  c.cy += margin;
  return c;
}

bool CameraIntrinsics::project(const Eigen::Vector3d& p, Eigen::Vector2d& pixel) const {
  if (!(p.z() > 1e-9)) return false;
  const double x = p.x() / p.z(), y = p.y() / p.z();
  const double r2 = x * x + y * y;
  // The polynomial folds back beyond some radius (k1 < 0 alone: at r^2 = 1 / (3 |k1|)): points
  // far off the axis would land inside the image. Keep the increasing branch, within 80 deg.
  if (r2 > 32.0 || !(1 + r2 * (3 * k1 + r2 * (5 * k2 + r2 * 7 * k3)) > 0)) return false;
  const double radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const double xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
  const double yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
  pixel = {fx * xd + cx, fy * yd + cy};
  return std::isfinite(pixel.x()) && std::isfinite(pixel.y());
}

Eigen::Vector3d CameraIntrinsics::ray(const Eigen::Vector2d& pixel) const {
  const double xd = (pixel.x() - cx) / fx, yd = (pixel.y() - cy) / fy;
  // Undistort by fixed-point iteration (converges for the mild distortion of real lenses).
  double x = xd, y = yd;
  for (int it = 0; it < 20; ++it) {
    const double r2 = x * x + y * y;
    const double radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
    const double dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
    x = (xd - dx) / radial;
    y = (yd - dy) / radial;
  }
  return Eigen::Vector3d(x, y, 1).normalized();
}

CameraPose lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = z.cross(up);
  if (!(x.norm() > 1e-9)) throw InvalidParameter("lookAt up", "parallel to the view direction", "a direction not along target - eye");
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);  // down in the image when up is up
  CameraPose pose = CameraPose::Identity();
  pose.linear().col(0) = x;
  pose.linear().col(1) = y;
  pose.linear().col(2) = z;
  pose.translation() = eye;
  return pose;
}

CameraPose applyPoseDelta(const CameraPose& pose, const PoseDelta& d) {
  CameraPose delta = CameraPose::Identity();
  delta.linear() = (Eigen::AngleAxisd(d.yaw, Eigen::Vector3d::UnitY()) *
                    Eigen::AngleAxisd(d.pitch, Eigen::Vector3d::UnitX()) *
                    Eigen::AngleAxisd(d.roll, Eigen::Vector3d::UnitZ())).toRotationMatrix();
  delta.translation() = d.translation;
  return pose * delta;
}

double meanReprojectionError(const CameraIntrinsics& camera, const CameraPose& truth,
                             const CameraPose& estimate, const std::vector<Eigen::Vector3d>& points) {
  const CameraPose to_truth = truth.inverse(), to_estimate = estimate.inverse();
  double sum = 0;
  std::size_t n = 0;
  for (const auto& p : points) {
    Eigen::Vector2d a, b;
    if (!camera.project(to_truth * p, a) || !camera.inside(a)) continue;
    if (!camera.project(to_estimate * p, b)) b = a + Eigen::Vector2d(camera.width + camera.height, 0);  // behind: far off
    sum += (a - b).norm();
    ++n;
  }
  return n ? sum / n : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace paps
