#pragma once
#include <type_traits>

#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/normal_refresh.h>
#include <paps/core/local_frame.h>
#include <paps/core/positions.h>
#include <paps/core/source_fields.h>
#include <paps/surface/mls_upsampling.h>

namespace paps {

template <typename PointIn, typename PointOut, MlsSurface S>
void MlsUpsampling<PointIn, PointOut, S>::performProcessing(pcl::PointCloud<PointOut>& output) {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  Normals normals;  // the fitted surface's, when the output type has them
  constexpr bool with_normals = detail::HasNormal<PointOut>::value;
  // PCL's MLS also fills the curvature field (the surface variation of the input ball).
  std::vector<float> curvature;
  constexpr bool with_curvature = detail::HasCurvature<PointOut>::value;
  // The other fields (colour, intensity) of the input point each new point was made from, as
  // PCL's MLS copies them; none to copy into a PointXYZ.
  std::vector<int> source;
  constexpr bool with_fields = !std::is_same_v<PointOut, pcl::PointXYZ>;
  const Positions out = upsampleMls(positionsAt(*this->input_, *this->indices_), S, params_, &report_, progress_,
                                    with_normals ? &normals : nullptr, with_curvature ? &curvature : nullptr,
                                    with_fields ? &source : nullptr);
  if (with_normals) orientUpsampledNormals(*this, *this->input_, *this->indices_, out, normals);
  if (with_fields && source.size() == out.size()) copySourceFields(*this->input_, *this->indices_, source, output);
  writePositionsAndNormals(out, normals, output);
  writeCurvatures(curvature, output);
}

}  // namespace paps
