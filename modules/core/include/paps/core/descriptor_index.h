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
  /// The axes the tree splits along. Given: the descriptors' own. Principal: their principal
  /// axes (PCA of the rows, largest variance first), for approximate search only. A rotation
  /// keeps every distance, but puts the variance in the first axes, where the tree splits
  /// first: on QSR's descriptors (36 and 49 dimensions) a search of 128 checks then finds
  /// about twice as many of the exact 24 nearest (docs/superresolution.md, session 23).
  enum class Axes { Given, Principal };

  /// rows x dims row-major values, copied into tree order. max_checks: descriptors compared
  /// per query at most (0: exact search, always on the given axes).
  DescriptorIndex(const float* data, std::size_t rows, std::size_t dims, int max_checks = 0,
                  Axes axes = Axes::Given);

  /// The k rows nearest to `query` (dims values, on the given axes), sorted by distance then
  /// row; squared distances out. Thread-safe. Returns the count.
  int nearestK(const float* query, int k, std::vector<int>& indices,
               std::vector<float>& sq_distances) const;
  /// As nearestK with the query storedRow(t): the stored rows themselves, without turning them.
  int nearestKOfStored(std::size_t t, int k, std::vector<int>& indices, std::vector<float>& sq_distances) const;
  std::size_t rows() const { return rows_; }
  /// The rows in the order the tree stores them: similar rows are close in this order, so
  /// querying the rows themselves in it keeps the tree and the data in cache.
  const std::vector<int>& storageOrder() const { return order_; }
  /// The values of row storageOrder()[t] (dims of them) on the index's axes: as given, or
  /// turned to the principal axes (Axes::Principal, approximate search). The index keeps a
  /// copy, so a caller that queries the rows themselves (nearestKOfStored) need not keep its own.
  const float* storedRow(std::size_t t) const { return &data_[t * dims_]; }
  std::size_t dims() const { return dims_; }
  /// Whether the rows were turned to their principal axes.
  bool principalAxes() const { return !basis_.empty(); }

 private:
  struct Node {
    int split_dim;    // -1 for a leaf
    float split_val;  // left: value <= split_val
    int left, right;  // child nodes, or [begin, end) of the leaf in order_
  };
  // Splits rows order_[begin, end) of `values` (the caller's rows, row-major) into `nodes`.
  int build(const float* values, int begin, int end, std::vector<Node>& nodes, int depth);
  // Sets mean_ and basis_ from `data` and writes the turned rows, in the given order, to data_.
  void turnToPrincipalAxes(const float* data);
  int search(const float* query, int k, std::vector<int>& indices, std::vector<float>& sq_distances) const;

  std::size_t rows_, dims_;
  int max_checks_;
  std::vector<float> data_;  // rows in tree order
  std::vector<int> order_;   // tree order -> original row
  std::vector<Node> nodes_;
  // Principal axes: row values are (x - mean_) * basis_ (dims x dims, column-major, one axis
  // per column, largest variance first). Empty: the given axes.
  std::vector<float> mean_, basis_;
};

}  // namespace paps
