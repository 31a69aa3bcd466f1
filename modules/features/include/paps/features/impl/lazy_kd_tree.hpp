#pragma once
// A pcl::search::KdTree that builds its FLANN index at the first query instead of at
// setInputCloud. pcl::Feature::initCompute hands the search its surface before every
// compute(); WavejetEstimation answers radius balls from its own grid and then never queries
// the tree, whose build was 5-9% of the run (rs1 1M by radius, 2 threads).
#include <atomic>
#include <mutex>

#include <pcl/search/kdtree.h>

namespace paps {
namespace detail {

template <typename PointT>
class LazyKdTree : public pcl::search::KdTree<PointT> {
  using Base = pcl::search::KdTree<PointT>;

 public:
  using Base::nearestKSearch;
  using Base::radiusSearch;

  LazyKdTree() : Base(false) {}

  void setInputCloud(const typename Base::PointCloudConstPtr& cloud,
                     const pcl::IndicesConstPtr& indices = pcl::IndicesConstPtr()) override {
    std::lock_guard<std::mutex> lock(mutex_);
    this->input_ = cloud;
    this->indices_ = indices;
    built_.store(false, std::memory_order_release);
  }
  int nearestKSearch(const PointT& point, int k, pcl::Indices& indices, std::vector<float>& sq_distances) const override {
    build();
    return Base::nearestKSearch(point, k, indices, sq_distances);
  }
  int radiusSearch(const PointT& point, double radius, pcl::Indices& indices, std::vector<float>& sq_distances,
                   unsigned int max_nn = 0) const override {
    build();
    return Base::radiusSearch(point, radius, indices, sq_distances, max_nn);
  }
  /// Whether the index has been built (a query came since the last setInputCloud).
  bool built() const { return built_.load(std::memory_order_acquire); }

 private:
  void build() const {
    if (built_.load(std::memory_order_acquire)) return;
    std::lock_guard<std::mutex> lock(mutex_);
    if (built_.load(std::memory_order_relaxed)) return;
    // Queries are const in PCL's interface; the index is the one thing they may fill in.
    auto* self = const_cast<LazyKdTree*>(this);
    self->Base::setInputCloud(this->input_, this->indices_);
    built_.store(true, std::memory_order_release);
  }
  mutable std::mutex mutex_;
  mutable std::atomic<bool> built_{false};
};

}  // namespace detail
}  // namespace paps
