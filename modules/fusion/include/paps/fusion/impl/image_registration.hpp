#pragma once
#include <paps/core/error.h>
#include <paps/fusion/image_registration.h>

namespace paps {

template <typename PointT>
CameraPose ImageToCloudRegistration<PointT>::align() {
  if (!input_) throw InvalidInput("image registration: no input cloud");
  if (!values_.empty() && values_.size() != input_->size())
    throw InvalidInput("image registration: " + std::to_string(values_.size()) + " point values for " +
                       std::to_string(input_->size()) + " points");
  const std::vector<float> values = values_.empty() ? shadingValues(*input_) : values_;
  report_ = {};
  const ScopedThreadCount threads(this->threads_);
  return registerImageToPoints(positionsOf(*input_), values, photo_, camera_, initial_pose_, parameters_, &report_,
                               progress_);
}

}  // namespace paps
