#include <paps/core/descriptor_index.h>

#include <algorithm>

#include <flann/flann.hpp>

#include <paps/core/error.h>

namespace paps {

struct DescriptorIndex::Impl {
  flann::Matrix<float> data;
  std::unique_ptr<flann::Index<flann::L2<float>>> index;
};

DescriptorIndex::DescriptorIndex(const float* data, std::size_t rows, std::size_t dims)
    : impl_(std::make_unique<Impl>()), rows_(rows), dims_(dims) {
  requirePositive("dims", dims);
  if (rows == 0) return;
  impl_->data = flann::Matrix<float>(const_cast<float*>(data), rows, dims);
  // Single exact kd-tree: deterministic, no random trees.
  impl_->index = std::make_unique<flann::Index<flann::L2<float>>>(
      impl_->data, flann::KDTreeSingleIndexParams(15));
  impl_->index->buildIndex();
}

DescriptorIndex::~DescriptorIndex() = default;

int DescriptorIndex::nearestK(const float* query, int k, std::vector<int>& indices,
                              std::vector<float>& sq_distances) const {
  k = std::min<int>(k, static_cast<int>(rows_));
  indices.resize(std::max(k, 0));
  sq_distances.resize(std::max(k, 0));
  if (k <= 0) return 0;
  flann::Matrix<float> q(const_cast<float*>(query), 1, dims_);
  flann::Matrix<int> idx(indices.data(), 1, k);
  flann::Matrix<float> dist(sq_distances.data(), 1, k);
  flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED, 0, true);
  const int found = impl_->index->knnSearch(q, idx, dist, k, params);
  indices.resize(found);
  sq_distances.resize(found);
  return found;
}

}  // namespace paps
