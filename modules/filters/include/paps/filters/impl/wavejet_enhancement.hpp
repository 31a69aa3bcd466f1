#pragma once
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/filters/wavejet_enhancement.h>

namespace paps {

namespace detail {
template <typename PointT>
bool inputNormals(const pcl::PointCloud<PointT>& cloud, Normals& out) {
  if constexpr (pcl::traits::has_normal_v<PointT>) {
    out.resize(cloud.size());
    bool any = false;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      out[i] = cloud[i].getNormalVector3fMap();
      any = any || (isFinite(out[i]) && out[i].squaredNorm() > 0);
    }
    return any;
  } else {
    (void)cloud; (void)out;
    return false;
  }
}
template <typename PointT>
void writeNormal(PointT& p, const Eigen::Vector3f& n) {
  if constexpr (pcl::traits::has_normal_v<PointT>) p.getNormalVector3fMap() = n;
  else { (void)p; (void)n; }
}
}  // namespace detail

template <typename PointT>
void WavejetEnhancement<PointT>::applyFilter(PointCloud& output) {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  Normals hints;
  const bool have_hints = detail::inputNormals(*this->input_, hints);
  if (mode_ == Mode::normals) {
    if (!pcl::traits::has_normal_v<PointT>)
      throw InvalidParameter("alpha1", "normal filter", "a point type with normal_x, normal_y, normal_z");
    checkIndices(*this->indices_, this->input_->size());
    const Normals n = enhanceNormals(positionsOf(*this->input_), params_, &report_, progress_,
                                     have_hints ? &hints : nullptr);
    output = *this->input_;
    // As pcl::NormalEstimation: a point without an estimate gets a NaN normal, and the cloud
    // is then not dense.
    for (const auto i : *this->indices_) {
      detail::writeNormal(output[i], n[i]);
      if (!isFinite(n[i])) output.is_dense = false;
    }
    return;
  }
  Normals corrected;
  applyPositionFilter(*this->input_, *this->indices_, output,
                      [&](const Positions& in, const std::vector<std::uint8_t>& movable) {
                        return enhancePositions(in, params_, &report_, movable, progress_,
                                                have_hints ? &hints : nullptr, &corrected);
                      });
  // The normals of the enhanced surface, on the side of the corrected ones; NaN where no
  // estimate (too few neighbours to fit).
  if (pcl::traits::has_normal_v<PointT>) {
    const Normals enhanced = enhancedSurfaceNormals(positionsOf(output), params_, corrected, progress_);
    for (const auto i : *this->indices_) {
      detail::writeNormal(output[i], enhanced[i]);
      if (!isFinite(enhanced[i])) output.is_dense = false;
    }
  }
}

}  // namespace paps
