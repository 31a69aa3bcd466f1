#include <paps/fusion/registered_photo.h>

#include <algorithm>
#include <cmath>
#include <string>

#include <paps/core/error.h>

namespace paps {

void RegisteredPhoto::validate(const char* what) const {
  if (image.empty()) throw InvalidInput(std::string(what) + ": the image is empty");
  if (image.type() != CV_8UC3)
    throw InvalidInput(std::string(what) + ": the image must be CV_8UC3 (8-bit BGR), got type " +
                       std::to_string(image.type()));
  camera.validate();
  if (image.cols != camera.width || image.rows != camera.height)
    throw InvalidParameter(std::string(what) + ".camera",
                           std::to_string(camera.width) + "x" + std::to_string(camera.height),
                           "the image size " + std::to_string(image.cols) + "x" + std::to_string(image.rows));
  if (!pose.matrix().allFinite()) throw InvalidParameter(std::string(what) + ".pose", "non-finite", "a finite pose");
}

Eigen::Vector3f sampleBilinear(const cv::Mat& bgr8, const Eigen::Vector2f& pixel) {
  const float x = std::clamp(pixel.x(), 0.f, float(bgr8.cols - 1));
  const float y = std::clamp(pixel.y(), 0.f, float(bgr8.rows - 1));
  const int x0 = std::min(int(x), bgr8.cols - 1), y0 = std::min(int(y), bgr8.rows - 1);
  const int x1 = std::min(x0 + 1, bgr8.cols - 1), y1 = std::min(y0 + 1, bgr8.rows - 1);
  const float fx = x - x0, fy = y - y0;
  auto at = [&](int r, int c) {
    const cv::Vec3b& v = bgr8.at<cv::Vec3b>(r, c);
    return Eigen::Vector3f(v[2], v[1], v[0]);
  };
  const Eigen::Vector3f top = (1 - fx) * at(y0, x0) + fx * at(y0, x1);
  const Eigen::Vector3f bottom = (1 - fx) * at(y1, x0) + fx * at(y1, x1);
  return ((1 - fy) * top + fy * bottom) * (1.f / 255.f);
}

}  // namespace paps
