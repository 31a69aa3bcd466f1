#pragma once
#include <paps/core/error.h>
#include <paps/filters/similarity_denoising.h>

namespace paps {

template <typename PointT> void SimilarityDenoising<PointT>::setRadius(float r) {
  auto p = params_; p.radius = r; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setTargetNeighbours(int n) {
  auto p = params_; p.target_neighbours = n; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setGridSize(int n) {
  auto p = params_; p.grid_size = n; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setSigma(float s) {
  auto p = params_; p.sigma = s; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setSmoothingIterations(int n) {
  auto p = params_; p.smoothing_iterations = n; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setSimilarPatches(int k) {
  auto p = params_; p.similar_patches = k; setParameters(p);
}

template <typename PointT>
void SimilarityDenoising<PointT>::applyFilter(PointCloud& output) {
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  applyPositionFilter(*this->input_, *this->indices_, output,
                      [&](const Positions& in, const std::vector<std::uint8_t>& movable) {
                        return denoiseBySimilarity(in, params_, &report_, movable, progress_);
                      });
}

}  // namespace paps
