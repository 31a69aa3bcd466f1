#pragma once
#include <paps/core/error.h>
#include <paps/core/positions.h>
#include <paps/surface/mls_upsampling.h>

namespace paps {

template <typename PointIn, typename PointOut, MlsSurface S>
void MlsUpsampling<PointIn, PointOut, S>::performProcessing(pcl::PointCloud<PointOut>& output) {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  writePositions(upsampleMls(positionsAt(*this->input_, *this->indices_), S, params_, &report_, progress_), output);
}

}  // namespace paps
