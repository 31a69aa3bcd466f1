#include <paps/fusion/synthetic_image.h>

#include <cmath>

#include <paps/core/error.h>

namespace paps {

void SyntheticImageParameters::validate() const {
  visibility.validate();
  requireInRange("fill_radius", fill_radius, 0, 32);
  requireInRange("fill_depth_tolerance", fill_depth_tolerance, 0.0, 10.0);
}

SyntheticImage renderSyntheticImage(const Positions& points, const std::vector<float>& values,
                                    const CameraIntrinsics& camera, const CameraPose& pose,
                                    const SyntheticImageParameters& parameters) {
  parameters.validate();
  if (values.size() != points.size())
    throw InvalidInput("synthetic image: " + std::to_string(values.size()) + " values for " +
                       std::to_string(points.size()) + " points");
  const ProjectedPoints proj = projectVisiblePoints(points, camera, pose, parameters.visibility);
  SyntheticImage out;
  out.visible_points = proj.visibleCount();
  const int w = camera.width, h = camera.height;
  // Drawn pixels: the front-most visible point of each pixel (ties: lowest index).
  cv::Mat drawn_depth(h, w, CV_32F, cv::Scalar(INFINITY));
  cv::Mat drawn_value(h, w, CV_32F, cv::Scalar(0));
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!proj.visible[i] || !std::isfinite(values[i])) continue;
    const int x = static_cast<int>(std::lround(proj.pixel[i].x())), y = static_cast<int>(std::lround(proj.pixel[i].y()));
    float& d = drawn_depth.at<float>(y, x);
    if (proj.depth[i] < d) {
      d = proj.depth[i];
      drawn_value.at<float>(y, x) = values[i];
    }
  }
  out.intensity = drawn_value.clone();
  out.depth = cv::Mat(h, w, CV_32F, cv::Scalar(0));
  out.mask = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  const int r = parameters.fill_radius;
  const float tolerance = static_cast<float>(1 + parameters.fill_depth_tolerance);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float d0 = drawn_depth.at<float>(y, x);
      if (std::isfinite(d0)) {
        out.mask.at<std::uint8_t>(y, x) = 255;
        out.depth.at<float>(y, x) = d0;
        continue;
      }
      if (r == 0) continue;
      // Front-most depth around, then the quadrants that hold a front pixel.
      float front = INFINITY;
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx >= 0 && yy >= 0 && xx < w && yy < h && dx * dx + dy * dy <= r * r)
            front = std::min(front, drawn_depth.at<float>(yy, xx));
        }
      if (!std::isfinite(front)) continue;
      unsigned quadrants = 0;
      double sum = 0, weight = 0, depth_sum = 0;
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h || dx * dx + dy * dy > r * r) continue;
          const float d = drawn_depth.at<float>(yy, xx);
          if (!(d <= front * tolerance)) continue;
          quadrants |= 1u << ((dx > 0 || (dx == 0 && dy > 0) ? 1 : 0) + (dy > 0 || (dy == 0 && dx < 0) ? 2 : 0));
          const double wgt = 1.0 / std::sqrt(double(dx * dx + dy * dy));
          sum += wgt * drawn_value.at<float>(yy, xx);
          depth_sum += wgt * d;
          weight += wgt;
        }
      if (quadrants != 15u) continue;
      out.intensity.at<float>(y, x) = static_cast<float>(sum / weight);
      out.depth.at<float>(y, x) = static_cast<float>(depth_sum / weight);
      out.mask.at<std::uint8_t>(y, x) = 255;
    }
  return out;
}

}  // namespace paps
