#pragma once
// paps::KdTreeSearch: a drop-in pcl::search::Search on x, y, z answered by paps::SpatialIndex.
// The tree is the one pcl::search::KdTree builds (FLANN's single k-d tree, leaf size 15,
// exact) searched with FLANN's own result sets, but without FLANN's per-query wrapper (an
// OpenMP region and new result sets at every call): the same lists in the same order, about
// 3x faster a query for small k and radii (`paps bench neighbours`). Give it to any PCL
// stage: `ne.setSearchMethod(pcl::make_shared<paps::KdTreeSearch<PointT>>())`.
// The tree is built at the first query, not at setInputCloud: pcl::Feature hands its search
// the surface at every compute(), also when the stage then never queries it.
// Differences from pcl::search::KdTree: x, y, z only (no point representation, no epsilon);
// results always sorted; a non-finite query finds nothing (PCL asserts); a coordinate beyond
// paps::kMaxCoordinate throws InvalidInput at setInputCloud (FLANN's tree would abort).
#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <type_traits>
#include <vector>

#include <pcl/point_cloud.h>
#include <pcl/search/search.h>
#include <pcl/type_traits.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/positions.h>

namespace paps {

template <typename PointT>
class KdTreeSearch : public pcl::search::Search<PointT> {
  static_assert(pcl::traits::has_xyz_v<PointT>, "paps::KdTreeSearch searches x, y, z");
  using Base = pcl::search::Search<PointT>;

 public:
  using Ptr = pcl::shared_ptr<KdTreeSearch<PointT>>;
  using ConstPtr = pcl::shared_ptr<const KdTreeSearch<PointT>>;
  using typename Base::PointCloudConstPtr;
  using Base::nearestKSearch;
  using Base::radiusSearch;

  explicit KdTreeSearch(bool sorted = true) : Base("paps::KdTreeSearch", sorted) {}

  /// Throws InvalidInput for a coordinate beyond kMaxCoordinate (a corrupt file): here,
  /// where a stage sets its search, not at the first query, which PCL's OpenMP stages make
  /// inside a parallel region (an exception there would end the process).
  void setInputCloud(const PointCloudConstPtr& cloud, const pcl::IndicesConstPtr& indices = pcl::IndicesConstPtr()) override {
    if (cloud)
      for (const auto& p : *cloud) requireCoordinatesInRange(p.getVector3fMap(), "paps::KdTreeSearch");
    std::lock_guard<std::mutex> lock(mutex_);
    this->input_ = cloud;
    this->indices_ = indices;
    index_.reset();
    built_.store(false, std::memory_order_release);
  }

  int nearestKSearch(const PointT& point, int k, pcl::Indices& k_indices, std::vector<float>& k_sqr_distances) const override {
    const SpatialIndex& index = this->index();
    return mapped(index.nearestK(point.getVector3fMap(), k, listOf(k_indices), k_sqr_distances), k_indices);
  }

  /// As pcl::KdTreeFLANN: the squared radius is the float of radius * radius in double, and
  /// max_nn = 0 (or more than the points) returns the whole ball.
  int radiusSearch(const PointT& point, double radius, pcl::Indices& k_indices, std::vector<float>& k_sqr_distances,
                   unsigned int max_nn = 0) const override {
    const SpatialIndex& index = this->index();
    const int cap = max_nn == 0 || max_nn >= index.size() ? 0 : static_cast<int>(max_nn);
    return mapped(index.radiusSearchSquared(point.getVector3fMap(), static_cast<float>(radius * radius),
                                            listOf(k_indices), k_sqr_distances, cap),
                  k_indices);
  }

  /// Whether the tree has been built (a query came since the last setInputCloud).
  bool built() const noexcept { return built_.load(std::memory_order_acquire); }

 private:
  // pcl::Indices is std::vector<int> unless PCL was built with 64-bit indices.
  static constexpr bool kIntIndices = std::is_same_v<pcl::index_t, int>;
  std::vector<int>& listOf(pcl::Indices& out) const {
    if constexpr (kIntIndices) {
      return out;
    } else {
      thread_local std::vector<int> list;
      return list;
    }
  }
  // Tree positions -> cloud indices (through the indices given to setInputCloud).
  int mapped(int n, pcl::Indices& out) const {
    if constexpr (!kIntIndices) {
      const std::vector<int>& list = listOf(out);
      out.assign(list.begin(), list.end());
    }
    if (!mapping_.empty())
      for (int i = 0; i < n; ++i) out[static_cast<std::size_t>(i)] = mapping_[static_cast<std::size_t>(out[static_cast<std::size_t>(i)])];
    return n;
  }
  const SpatialIndex& index() const {
    if (!built_.load(std::memory_order_acquire)) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!built_.load(std::memory_order_relaxed)) {
        if (!this->input_) throw InvalidInput("paps::KdTreeSearch: a query before setInputCloud");
        Positions points;
        mapping_.clear();
        if (this->indices_) {
          points.reserve(this->indices_->size());
          for (const auto i : *this->indices_) points.push_back((*this->input_)[static_cast<std::size_t>(i)].getVector3fMap());
          mapping_.assign(this->indices_->begin(), this->indices_->end());
        } else {
          points.reserve(this->input_->size());
          for (const auto& p : *this->input_) points.push_back(p.getVector3fMap());
        }
        index_ = std::make_unique<SpatialIndex>(points);
        built_.store(true, std::memory_order_release);
      }
    }
    return *index_;
  }

  mutable std::mutex mutex_;
  mutable std::atomic<bool> built_{false};
  mutable std::unique_ptr<SpatialIndex> index_;
  mutable std::vector<pcl::index_t> mapping_;
};

}  // namespace paps
