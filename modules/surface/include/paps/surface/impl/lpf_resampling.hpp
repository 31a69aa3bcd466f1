#pragma once
#include <paps/core/error.h>
#include <paps/core/positions.h>
#include <paps/surface/lpf_resampling.h>

namespace paps {

template <typename PointIn, typename PointOut>
void LpfResampling<PointIn, PointOut>::performProcessing(pcl::PointCloud<PointOut>& output) {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  writePositions(lpfResample(positionsAt(*this->input_, *this->indices_), params_, &report_, progress_), output);
}

}  // namespace paps
