#pragma once
#include <paps/core/error.h>
#include <paps/surface/mls_upsampling.h>

namespace paps {

template <typename PointIn, typename PointOut, MlsSurface S>
void MlsUpsampling<PointIn, PointOut, S>::performProcessing(pcl::PointCloud<PointOut>& output) {
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  Positions in;
  in.reserve(this->indices_->size());
  for (const auto i : *this->indices_) in.push_back((*this->input_)[i].getVector3fMap());
  writePositions(upsampleMls(in, S, params_, &report_, progress_), output);
}

}  // namespace paps
