#include <paps/fusion/organized_cloud_camera.h>

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <pcl/point_types.h>

#include <paps/core/error.h>

namespace paps {

namespace {

// RQ decomposition M = U Q, U upper triangular with a positive diagonal, Q a rotation
// (det +1; requires det M > 0). From the QR decomposition of the row-reversed transpose.
void rqDecomposition(const Eigen::Matrix3d& m, Eigen::Matrix3d& upper, Eigen::Matrix3d& rotation) {
  Eigen::Matrix3d flip = Eigen::Matrix3d::Zero();
  flip(0, 2) = flip(1, 1) = flip(2, 0) = 1;
  Eigen::HouseholderQR<Eigen::Matrix3d> qr((flip * m).transpose());
  const Eigen::Matrix3d q0 = qr.householderQ();
  const Eigen::Matrix3d r0 = qr.matrixQR().triangularView<Eigen::Upper>();
  upper = flip * r0.transpose() * flip;
  rotation = flip * q0.transpose();
  for (int k = 0; k < 3; ++k)  // signs: positive focal lengths
    if (upper(k, k) < 0) {
      upper.col(k) *= -1;
      rotation.row(k) *= -1;
    }
}

}  // namespace

PinholeFit fitPinholeCamera(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector2d>& pixels,
                            int width, int height) {
  if (points.size() != pixels.size())
    throw InvalidInput("pinhole fit: " + std::to_string(points.size()) + " points but " +
                       std::to_string(pixels.size()) + " pixels");
  const std::size_t n = points.size();
  if (n < 12) throw InvalidInput("pinhole fit: " + std::to_string(n) + " point/pixel pairs, at least 12 are needed");
  for (std::size_t i = 0; i < n; ++i)
    if (!points[i].allFinite() || !pixels[i].allFinite())
      throw InvalidInput("pinhole fit: pair " + std::to_string(i) + " is not finite");

  // Hartley normalisation: centroids at 0, mean distances sqrt(3) and sqrt(2).
  Eigen::Vector3d mean_point = Eigen::Vector3d::Zero();
  Eigen::Vector2d mean_pixel = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    mean_point += points[i];
    mean_pixel += pixels[i];
  }
  mean_point /= double(n);
  mean_pixel /= double(n);
  double spread_point = 0, spread_pixel = 0;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    spread_point += (points[i] - mean_point).norm();
    spread_pixel += (pixels[i] - mean_pixel).norm();
    covariance += (points[i] - mean_point) * (points[i] - mean_point).transpose();
  }
  if (spread_point <= 0 || spread_pixel <= 0) throw InvalidInput("pinhole fit: all points or all pixels coincide");
  // A plane (or a line) of points leaves the projection matrix undetermined.
  const Eigen::Vector3d extent = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance).eigenvalues();
  if (!(extent[0] > 1e-8 * extent[2]))
    throw InvalidInput("pinhole fit: the points lie on a plane or a line (thickness " +
                       std::to_string(std::sqrt(std::max(0.0, extent[0] / extent[2]))) +
                       " of their extent); a camera cannot be recovered from a planar scene");
  const double scale_point = std::sqrt(3.0) * double(n) / spread_point;
  const double scale_pixel = std::sqrt(2.0) * double(n) / spread_pixel;

  // Each pair gives two rows of A p = 0 (p the 12 entries of P, row-major); accumulate A^T A.
  Eigen::Matrix<double, 12, 12> normal = Eigen::Matrix<double, 12, 12>::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    Eigen::Vector4d x;
    x << (points[i] - mean_point) * scale_point, 1;
    const Eigen::Vector2d u = (pixels[i] - mean_pixel) * scale_pixel;
    Eigen::Matrix<double, 12, 1> a = Eigen::Matrix<double, 12, 1>::Zero(), b = a;
    a.segment<4>(0) = x;
    a.segment<4>(8) = -u.x() * x;
    b.segment<4>(4) = x;
    b.segment<4>(8) = -u.y() * x;
    normal.selfadjointView<Eigen::Lower>().rankUpdate(a);
    normal.selfadjointView<Eigen::Lower>().rankUpdate(b);
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 12, 12>> solver(normal.selfadjointView<Eigen::Lower>());
  const Eigen::Matrix<double, 12, 1> p = solver.eigenvectors().col(0);
  Eigen::Matrix<double, 3, 4> pn;
  pn << p.segment<4>(0).transpose(), p.segment<4>(4).transpose(), p.segment<4>(8).transpose();
  Eigen::Matrix3d to_pixel;
  to_pixel << 1 / scale_pixel, 0, mean_pixel.x(), 0, 1 / scale_pixel, mean_pixel.y(), 0, 0, 1;
  Eigen::Matrix4d from_point = Eigen::Matrix4d::Identity();
  from_point.topLeftCorner<3, 3>() *= scale_point;
  from_point.topRightCorner<3, 1>() = -scale_point * mean_point;
  Eigen::Matrix<double, 3, 4> projection = to_pixel * pn * from_point;
  const double det = projection.leftCols<3>().determinant();
  if (!std::isfinite(det) || std::abs(det) < 1e-300) throw InvalidInput("pinhole fit: the projection is degenerate");
  if (det < 0) projection = -projection;

  Eigen::Matrix3d k, r;
  rqDecomposition(projection.leftCols<3>(), k, r);
  const double s = k(2, 2);
  const Eigen::Vector3d t = k.inverse() * projection.col(3);  // world-to-camera translation
  k /= s;

  PinholeFit fit;
  fit.camera.width = width;
  fit.camera.height = height;
  fit.camera.fx = k(0, 0);
  fit.camera.fy = k(1, 1);
  fit.camera.cx = k(0, 2);
  fit.camera.cy = k(1, 2);  // the skew k(0, 1) is dropped: the residual below shows its cost
  try {
    fit.camera.validate();
  } catch (const InvalidParameter& e) {  // a degenerate fit is the data's fault, not a parameter's
    throw InvalidInput(std::string("pinhole fit: the fitted camera is not valid (") + e.what() + ")");
  }
  fit.pose.setIdentity();
  fit.pose.linear() = r.transpose();
  fit.pose.translation() = -r.transpose() * t;

  const CameraPose world_to_camera = fit.pose.inverse();
  double squares = 0;
  std::size_t in_front = 0;
  for (std::size_t i = 0; i < n; ++i) {
    Eigen::Vector2d pixel;
    if (!fit.camera.project(world_to_camera * points[i], pixel)) continue;
    const double d = (pixel - pixels[i]).norm();
    squares += d * d;
    fit.max_pixels = std::max(fit.max_pixels, d);
    ++in_front;
  }
  if (in_front < n - n / 100)
    throw InvalidInput("pinhole fit: " + std::to_string(n - in_front) + " of " + std::to_string(n) +
                       " points do not project in front of the fitted camera");
  fit.points = in_front;
  fit.rms_pixels = std::sqrt(squares / double(in_front));
  return fit;
}

void OrganizedCameraOptions::validate() const {
  requireInRange("sample_step", sample_step, 1, 64);
  requireInRange("max_rms_pixels", max_rms_pixels, 1e-9, 1e6);
}

template <typename PointT>
OrganizedCloudCamera cameraOfOrganizedCloud(const pcl::PointCloud<PointT>& cloud, const OrganizedCameraOptions& options) {
  options.validate();
  if (cloud.height <= 1 || cloud.width < 8 || cloud.height < 8 || cloud.size() != std::size_t(cloud.width) * cloud.height)
    throw InvalidInput("organized cloud camera: the cloud is not organized (width " + std::to_string(cloud.width) +
                       ", height " + std::to_string(cloud.height) + ", " + std::to_string(cloud.size()) +
                       " points); an image grid of at least 8 x 8 is needed");
  const int w = int(cloud.width), h = int(cloud.height);
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> pixels;
  for (int v = 0; v < h; v += options.sample_step)
    for (int u = 0; u < w; u += options.sample_step) {
      const PointT& q = cloud.at(u, v);
      if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z)) continue;
      points.emplace_back(q.x, q.y, q.z);
      pixels.emplace_back(u, v);
    }
  if (points.size() < 12)
    throw InvalidInput("organized cloud camera: " + std::to_string(points.size()) +
                       " finite points on the sampled grid, at least 12 are needed");
  OrganizedCloudCamera out;
  out.fit = fitPinholeCamera(points, pixels, w, h);
  if (out.fit.rms_pixels > options.max_rms_pixels)
    throw InvalidInput("organized cloud camera: the best pinhole camera misses the grid by " +
                       std::to_string(out.fit.rms_pixels) + " px RMS (limit " + std::to_string(options.max_rms_pixels) +
                       "): the cloud is organized, but not as the image of one pinhole camera");
  out.photo.camera = out.fit.camera;
  out.photo.pose = out.fit.pose;
  out.photo.image.create(h, w, CV_8UC3);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const PointT& q = cloud.at(u, v);
      out.photo.image.template at<cv::Vec3b>(v, u) = cv::Vec3b(q.b, q.g, q.r);
    }
  return out;
}

template OrganizedCloudCamera cameraOfOrganizedCloud(const pcl::PointCloud<pcl::PointXYZRGB>&, const OrganizedCameraOptions&);
template OrganizedCloudCamera cameraOfOrganizedCloud(const pcl::PointCloud<pcl::PointXYZRGBA>&, const OrganizedCameraOptions&);
template OrganizedCloudCamera cameraOfOrganizedCloud(const pcl::PointCloud<pcl::PointXYZRGBNormal>&, const OrganizedCameraOptions&);

}  // namespace paps
