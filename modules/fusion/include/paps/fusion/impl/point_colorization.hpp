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
  // Points outside the indices take no part: NaN positions keep their colour.
  const Positions points = positionsWithin(input, *this->indices_);
  const std::vector<Eigen::Vector3f> colours = colour::coloursOf(input);
  const std::vector<Eigen::Vector3f> out = colorizePoints(points, colours, photos_, params_, &report_, progress_);
  // The points outside the indices entered as NaN: they are not the input's non-finite points.
  report_.non_finite -= pointsOutside(*this->indices_, input.size());
  PointCloud result = input;
  colour::setColours(out, result);
  output = std::move(result);
}

}  // namespace paps
