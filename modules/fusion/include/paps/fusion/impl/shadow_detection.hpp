#pragma once
#include <string>

#include <paps/core/error.h>
#include <paps/fusion/colour_space.h>
#include <paps/fusion/shadow_detection.h>

namespace paps {

template <typename PointT>
void ShadowDetection<PointT>::addView(const cv::Mat& bgr8, const CameraIntrinsics& camera, const CameraPose& pose) {
  RegisteredPhoto photo{bgr8, camera, pose};
  photo.validate(("view " + std::to_string(photos_.size())).c_str());
  photos_.push_back(std::move(photo));
}

template <typename PointT>
void ShadowDetection<PointT>::detect(ShadowDetectionResult& result) {
  requireInputCloud(this->input_);
  if (photos_.empty()) throw InvalidInput("ShadowDetection: no view (call addView)");
  if (reflectance_.empty()) throw InvalidInput("ShadowDetection: no reflectance (call setReflectance)");
  if (reflectance_.size() != this->input_->size())
    throw InvalidParameter("reflectance", detail::toString(reflectance_.size()),
                           "one value per point (" + detail::toString(this->input_->size()) + ")");
  if (!this->initCompute()) throw InvalidInput("ShadowDetection: the input cloud or its indices are not usable");
  const ScopedThreadCount threads(this->threads_);
  const auto& input = *this->input_;
  const Positions points = positionsWithin(input, *this->indices_);
  Normals normals(input.size());
  for (std::size_t i = 0; i < input.size(); ++i) normals[i] = input[i].getNormalVector3fMap();
  const std::vector<Eigen::Vector3f> colours = colour::coloursOf(input);
  result = detectShadows(points, normals, colours, reflectance_, photos_, params_, progress_);
  // The points outside the indices entered as NaN: they are not the input's non-finite points.
  result.non_finite -= pointsOutside(*this->indices_, input.size());
  this->deinitCompute();
}

}  // namespace paps
