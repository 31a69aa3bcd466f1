#pragma once
#include <paps/core/error.h>
#include <paps/core/positions.h>
#include <paps/surface/mls_upsampling.h>

namespace paps {

template <typename PointIn, typename PointOut, MlsSurface S>
void MlsUpsampling<PointIn, PointOut, S>::performProcessing(pcl::PointCloud<PointOut>& output) {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  Normals normals;  // the fitted surface's, when the output type has them
  constexpr bool with_normals = detail::HasNormal<PointOut>::value;
  const Positions out = upsampleMls(positionsAt(*this->input_, *this->indices_), S, params_, &report_, progress_,
                                    with_normals ? &normals : nullptr);
  if (with_normals) this->orientTowardsViewPoint(out, normals, this->input_->sensor_origin_);
  writePositionsAndNormals(out, normals, output);
}

}  // namespace paps
