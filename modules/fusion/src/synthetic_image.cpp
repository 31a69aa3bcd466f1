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
  // Front-most depth of each pixel (the points rounded to their pixel).
  cv::Mat front_depth(h, w, CV_32F, cv::Scalar(INFINITY));
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!proj.visible[i] || !std::isfinite(values[i])) continue;
    const int x = static_cast<int>(std::lround(proj.pixel[i].x())), y = static_cast<int>(std::lround(proj.pixel[i].y()));
    front_depth.at<float>(y, x) = std::min(front_depth.at<float>(y, x), proj.depth[i]);
  }
  // Drawn pixels: every point splats bilinearly onto its four pixels, where it is in the front
  // layer, so the image (and the costs of the registration) change continuously with the pose.
  const float layer = static_cast<float>(1 + parameters.fill_depth_tolerance);
  cv::Mat weight(h, w, CV_32F, cv::Scalar(0)), value_sum(h, w, CV_32F, cv::Scalar(0)), depth_sum(h, w, CV_32F, cv::Scalar(0));
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!proj.visible[i] || !std::isfinite(values[i])) continue;
    const float fx = proj.pixel[i].x(), fy = proj.pixel[i].y();
    const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
    for (int dy = 0; dy <= 1; ++dy)
      for (int dx = 0; dx <= 1; ++dx) {
        const int x = x0 + dx, y = y0 + dy;
        if (x < 0 || y < 0 || x >= w || y >= h) continue;
        const float f = front_depth.at<float>(y, x);
        if (std::isfinite(f) && proj.depth[i] > f * layer) continue;
        const float wgt = (dx ? fx - x0 : 1 - (fx - x0)) * (dy ? fy - y0 : 1 - (fy - y0));
        weight.at<float>(y, x) += wgt;
        value_sum.at<float>(y, x) += wgt * values[i];
        depth_sum.at<float>(y, x) += wgt * proj.depth[i];
      }
  }
  cv::Mat drawn_depth(h, w, CV_32F, cv::Scalar(INFINITY));
  cv::Mat drawn_value(h, w, CV_32F, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float wgt = weight.at<float>(y, x);
      if (wgt < 0.25f) continue;
      drawn_depth.at<float>(y, x) = depth_sum.at<float>(y, x) / wgt;
      drawn_value.at<float>(y, x) = value_sum.at<float>(y, x) / wgt;
    }
  out.intensity = drawn_value.clone();
  out.depth = cv::Mat(h, w, CV_32F, cv::Scalar(0));
  out.mask = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  const int r = parameters.fill_radius;
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
          if (!(d <= front * layer)) continue;
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
