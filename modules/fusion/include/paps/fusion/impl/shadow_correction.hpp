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
  const Positions points = positionsWithin(input, *this->indices_);
  Normals normals(input.size());
  for (std::size_t i = 0; i < input.size(); ++i) normals[i] = input[i].getNormalVector3fMap();
  const std::vector<Eigen::Vector3f> colours = colour::coloursOf(input);
  const auto out = correctShadows(points, normals, colours, labels_, params_, &report_, progress_);
  PointCloud result = input;
  colour::setColours(out, result);
  output = std::move(result);
}

}  // namespace paps
