#pragma once
#include <paps/core/error.h>
#include <paps/core/view_point_option.h>
#include <paps/filters/similarity_denoising.h>

namespace paps {

template <typename PointT> void SimilarityDenoising<PointT>::setRadius(float r) {
  auto p = params_; p.radius = r; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setTargetNeighbours(int n) {
  auto p = params_; p.target_neighbours = n; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setAdaptToNoise(bool on) {
  auto p = params_; p.adapt_to_noise = on; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setNoiseSigma(float s) {
  auto p = params_; p.noise_sigma = s; setParameters(p);
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
template <typename PointT> void SimilarityDenoising<PointT>::setMaxTilePoints(std::size_t n) {
  auto p = params_; p.max_tile_points = n; setParameters(p);
}
template <typename PointT> void SimilarityDenoising<PointT>::setMaxNoiseRatio(float q) {
  auto p = params_; p.max_noise_ratio = q; setParameters(p);
}

template <typename PointT>
void SimilarityDenoising<PointT>::applyFilter(PointCloud& output) {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  // A cloud that knows where its sensor was gets its normals oriented towards it (2.1.2);
  // otherwise orientation is propagated over the neighbour graph.
  SimilarityDenoisingParameters params = params_;
  const auto origin = knownSensorOrigin(this->input_->sensor_origin_.template head<3>());
  if (!params.use_viewpoint && origin) {
    params.use_viewpoint = true;
    params.viewpoint = *origin;
  }
  applyPositionFilter(*this->input_, *this->indices_, output,
                      [&](const Positions& in, const std::vector<std::uint8_t>& movable) {
                        return denoiseBySimilarity(in, params, &report_, movable, progress_);
                      });
  refreshOutputNormals(*this->input_, *this->indices_, output, report_.radius);
}

}  // namespace paps
