#pragma once
#include <paps/core/error.h>
#include <paps/fusion/colour_space.h>
#include <paps/fusion/shadow_correction.h>

namespace paps {

template <typename PointT>
void ShadowCorrection<PointT>::filter(PointCloud& output) {
  requireInputCloud(this->input_);
  if (labels_.empty()) throw InvalidInput("ShadowCorrection: no shadow labels (call setShadowLabels)");
  Base::filter(output);
}

template <typename PointT>
void ShadowCorrection<PointT>::applyFilter(PointCloud& output) {
  const ScopedThreadCount threads(this->threads_);
  const PointCloud& input = *this->input_;
  checkIndices(*this->indices_, input.size());
  Positions points(input.size(), Eigen::Vector3f::Constant(NAN));
  for (const auto i : *this->indices_) points[i] = input[i].getVector3fMap();
  Normals normals(input.size());
  std::vector<Eigen::Vector3f> colours(input.size());
  for (std::size_t i = 0; i < input.size(); ++i) {
    normals[i] = input[i].getNormalVector3fMap();
    colours[i] = Eigen::Vector3f(colour::fromByte(input[i].r), colour::fromByte(input[i].g), colour::fromByte(input[i].b));
  }
  const auto out = correctShadows(points, normals, colours, labels_, params_, &report_, progress_);
  PointCloud result = input;
  for (std::size_t i = 0; i < input.size(); ++i) {
    result[i].r = colour::toByte(out[i].x());
    result[i].g = colour::toByte(out[i].y());
    result[i].b = colour::toByte(out[i].z());
  }
  output = std::move(result);
}

}  // namespace paps
