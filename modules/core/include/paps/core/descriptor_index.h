#pragma once
// Nearest neighbours in descriptor space (R^d, Euclidean), for similarity search between
// patches. A kd-tree with best-bin-first search: exact when max_checks is 0, otherwise
// approximate, visiting at most max_checks descriptors per query (noise-like descriptors
// defeat exact kd-tree search in 16 dimensions). Built and searched without any random
// choice, so answers do not depend on threads or seeds.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace paps {

class DescriptorIndex {
 public:
  /// rows x dims row-major values, copied into tree order. max_checks: descriptors compared
  /// per query at most (0: exact search).
  DescriptorIndex(const float* data, std::size_t rows, std::size_t dims, int max_checks = 0);

  /// The k rows nearest to `query` (dims values), sorted by distance then row; squared
  /// distances out. Thread-safe. Returns the count.
  int nearestK(const float* query, int k, std::vector<int>& indices,
               std::vector<float>& sq_distances) const;
  std::size_t rows() const { return rows_; }
  /// The rows in the order the tree stores them: similar rows are close in this order, so
  /// querying the rows themselves in it keeps the tree and the data in cache.
  const std::vector<int>& storageOrder() const { return order_; }
  /// The values of row storageOrder()[t] (dims of them), as given: the index keeps a copy, so
  /// a caller that queries the rows themselves need not keep its own.
  const float* storedRow(std::size_t t) const { return &data_[t * dims_]; }
  std::size_t dims() const { return dims_; }

 private:
  struct Node {
    int split_dim;    // -1 for a leaf
    float split_val;  // left: value <= split_val
    int left, right;  // child nodes, or [begin, end) of the leaf in order_
  };
  // Splits rows order_[begin, end) of `values` (the caller's rows, row-major) into `nodes`.
  int build(const float* values, int begin, int end, std::vector<Node>& nodes, int depth);

  std::size_t rows_, dims_;
  int max_checks_;
  std::vector<float> data_;  // rows in tree order
  std::vector<int> order_;   // tree order -> original row
  std::vector<Node> nodes_;
};

}  // namespace paps
