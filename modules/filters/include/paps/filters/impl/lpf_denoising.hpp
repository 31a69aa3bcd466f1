#pragma once
#include <paps/core/error.h>
#include <paps/filters/lpf_denoising.h>

namespace paps {

template <typename PointT>
void LpfDenoising<PointT>::applyFilter(PointCloud& output) {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  applyPositionFilter(*this->input_, *this->indices_, output,
                      [&](const Positions& in, const std::vector<std::uint8_t>& movable) {
                        return lpfDenoisePositions(in, params_, &report_, movable, progress_);
                      });
  refreshOutputNormals(*this->input_, *this->indices_, output, report_.radius);
}

}  // namespace paps
