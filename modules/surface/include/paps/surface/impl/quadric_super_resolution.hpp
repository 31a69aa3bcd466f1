#pragma once
#include <type_traits>

#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/normal_refresh.h>
#include <paps/core/local_frame.h>
#include <paps/core/positions.h>
#include <paps/core/source_fields.h>
#include <paps/surface/quadric_super_resolution.h>

namespace paps {

template <typename PointIn, typename PointOut>
void QuadricSuperResolution<PointIn, PointOut>::performProcessing(pcl::PointCloud<PointOut>& output) {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  std::vector<Positions> scans(1, positionsAt(*this->input_, *this->indices_));
  for (const auto& s : extra_) {
    if (!s) throw InvalidInput("a null scan was added");
    scans.push_back(positionsOf(*s));
  }
  // Output normals (the SR surface's) when the output type has them, as PCL's MLS with
  // setComputeNormals.
  Normals normals;
  constexpr bool with_normals = detail::HasNormal<PointOut>::value;
  // PCL's MLS also fills the curvature field (the surface variation of the input ball).
  std::vector<float> curvature;
  constexpr bool with_curvature = detail::HasCurvature<PointOut>::value;
  // The other fields (colour, intensity) of the input point each new point was made from, as
  // PCL's MLS copies them; none to copy into a PointXYZ.
  std::vector<int> source;
  constexpr bool with_fields = !std::is_same_v<PointOut, pcl::PointXYZ>;
  const Positions out = superResolveQuadric(scans, params_, &report_, progress_, with_normals ? &normals : nullptr,
                                            with_curvature ? &curvature : nullptr, with_fields ? &source : nullptr);
  if (with_normals) orientUpsampledNormals(*this, *this->input_, *this->indices_, out, normals);
  if (with_fields && source.size() == out.size()) copySourceFields(*this->input_, *this->indices_, source, output);
  writePositionsAndNormals(out, normals, output);
  writeCurvatures(curvature, output);
}

}  // namespace paps
