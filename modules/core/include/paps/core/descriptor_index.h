#pragma once
// Nearest neighbours in descriptor space (R^d, Euclidean), for similarity search between
// patches. Exact kd-tree search: the answer does not depend on threads or on a random seed.
#include <cstddef>
#include <memory>
#include <vector>

namespace paps {

class DescriptorIndex {
 public:
  /// rows x dims row-major values; the array must outlive the index.
  DescriptorIndex(const float* data, std::size_t rows, std::size_t dims);
  ~DescriptorIndex();
  DescriptorIndex(const DescriptorIndex&) = delete;
  DescriptorIndex& operator=(const DescriptorIndex&) = delete;

  /// The k rows nearest to `query` (dims values), sorted by distance; squared distances out.
  /// Thread-safe. Returns the count.
  int nearestK(const float* query, int k, std::vector<int>& indices,
               std::vector<float>& sq_distances) const;
  std::size_t rows() const { return rows_; }
  std::size_t dims() const { return dims_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::size_t rows_, dims_;
};

}  // namespace paps
