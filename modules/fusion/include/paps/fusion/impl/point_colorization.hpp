#pragma once
#include <paps/core/error.h>
#include <paps/fusion/colour_space.h>
#include <paps/fusion/point_colorization.h>

namespace paps {

template <typename PointT>
void PointColorization<PointT>::addView(const cv::Mat& bgr8, const CameraIntrinsics& camera, const CameraPose& pose) {
  RegisteredPhoto photo{bgr8, camera, pose};
  photo.validate(("view " + std::to_string(photos_.size())).c_str());
  photos_.push_back(std::move(photo));
}

template <typename PointT>
void PointColorization<PointT>::filter(PointCloud& output) {
  requireInputCloud(this->input_);
  if (photos_.empty()) throw InvalidInput("PointColorization: no view (call addView)");
  Base::filter(output);
}

template <typename PointT>
void PointColorization<PointT>::applyFilter(PointCloud& output) {
  const ScopedThreadCount threads(this->threads_);
  const PointCloud& input = *this->input_;
  checkIndices(*this->indices_, input.size());
  // Points outside the indices take no part: NaN positions keep their colour.
  Positions points(input.size(), Eigen::Vector3f::Constant(NAN));
  for (const auto i : *this->indices_) points[i] = input[i].getVector3fMap();
  std::vector<Eigen::Vector3f> colours(input.size());
  for (std::size_t i = 0; i < input.size(); ++i)
    colours[i] = Eigen::Vector3f(colour::fromByte(input[i].r), colour::fromByte(input[i].g), colour::fromByte(input[i].b));
  const std::vector<Eigen::Vector3f> out = colorizePoints(points, colours, photos_, params_, &report_, progress_);
  PointCloud result = input;
  for (std::size_t i = 0; i < input.size(); ++i) {
    result[i].r = colour::toByte(out[i].x());
    result[i].g = colour::toByte(out[i].y());
    result[i].b = colour::toByte(out[i].z());
  }
  output = std::move(result);
}

}  // namespace paps
