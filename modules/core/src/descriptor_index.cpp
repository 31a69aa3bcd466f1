#include <paps/core/descriptor_index.h>

#include <algorithm>
#include <limits>
#include <numeric>
#include <queue>

#include <Eigen/Dense>

#include <paps/core/error.h>

namespace paps {

namespace {
constexpr int kLeafSize = 32;  // contiguous scans are cheap; tree steps are cache misses
// Dimensions summed between two checks of a partial distance against the k-th best.
constexpr std::size_t kDistanceBlock = 16;
// The covariance of the principal axes is summed over at most about this many rows (evenly
// spaced): plenty for a d x d matrix, and it bounds the cost on large tables.
constexpr std::size_t kCovarianceRows = 65536;
using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
}  // namespace

DescriptorIndex::DescriptorIndex(const float* data, std::size_t rows, std::size_t dims, int max_checks, Axes axes)
    : rows_(rows), dims_(dims), max_checks_(max_checks) {
  requirePositive("dims", dims);
  if (max_checks < 0) throw InvalidParameter("max_checks", detail::toString(max_checks), "0 (exact) or > 0");
  order_.resize(rows);
  std::iota(order_.begin(), order_.end(), 0);
  if (axes == Axes::Principal && max_checks > 0 && dims > 1 && rows > 2 * dims) {
    // Turned rows in data_ (given order), the tree built on them, then data_ permuted in
    // place into leaf order: the caller's rows and one copy, as below.
    turnToPrincipalAxes(data);
    build(data_.data(), 0, static_cast<int>(rows), nodes_, 0);
    std::vector<std::uint8_t> placed(rows, 0);
    std::vector<float> held(dims);
    for (std::size_t start = 0; start < rows; ++start) {
      if (placed[start]) continue;
      // Slot r takes row order_[r]: follow the cycle through start.
      std::copy_n(data_.begin() + start * dims, dims, held.begin());
      std::size_t r = start;
      while (true) {
        placed[r] = 1;
        const std::size_t from = static_cast<std::size_t>(order_[r]);
        if (from == start) { std::copy_n(held.begin(), dims, data_.begin() + r * dims); break; }
        std::copy_n(data_.begin() + from * dims, dims, data_.begin() + r * dims);
        r = from;
      }
    }
    return;
  }
  // Build on the caller's rows, read through order_, then lay them out in leaf order so that
  // a leaf scan reads contiguous memory: one copy (building on a copy of its own held three
  // at once with the caller's, the denoiser's peak on table_scene).
  if (rows > 0) build(data, 0, static_cast<int>(rows), nodes_, 0);
  data_.resize(rows * dims);
  for (std::size_t r = 0; r < rows; ++r)
    std::copy_n(data + static_cast<std::size_t>(order_[r]) * dims, dims, data_.begin() + r * dims);
}

void DescriptorIndex::turnToPrincipalAxes(const float* data) {
  const Eigen::Index n = static_cast<Eigen::Index>(rows_), d = static_cast<Eigen::Index>(dims_);
  const Eigen::Map<const RowMajor> x(data, n, d);
  // Mean and covariance in double, over evenly spaced rows, in a fixed order.
  const std::size_t stride = std::max<std::size_t>(1, rows_ / kCovarianceRows);
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(d);
  std::size_t used = 0;
  for (std::size_t r = 0; r < rows_; r += stride, ++used) mean += x.row(static_cast<Eigen::Index>(r)).cast<double>().transpose();
  mean /= static_cast<double>(used);
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(d, d);
  Eigen::VectorXd c(d);
  for (std::size_t r = 0; r < rows_; r += stride) {
    c = x.row(static_cast<Eigen::Index>(r)).cast<double>().transpose() - mean;
    cov.selfadjointView<Eigen::Lower>().rankUpdate(c);
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(cov.selfadjointView<Eigen::Lower>());
  // Eigen sorts eigenvalues up: reversed, the largest variance comes first. A non-finite
  // table (it should not happen) keeps the given axes.
  if (eig.info() != Eigen::Success || !eig.eigenvectors().allFinite()) {
    data_.assign(data, data + rows_ * dims_);
    return;
  }
  const Eigen::MatrixXf basis = eig.eigenvectors().rowwise().reverse().cast<float>();
  mean_.resize(dims_);
  basis_.resize(dims_ * dims_);
  Eigen::Map<Eigen::VectorXf>(mean_.data(), d) = mean.cast<float>();
  Eigen::Map<Eigen::MatrixXf>(basis_.data(), d, d) = basis;
  data_.resize(rows_ * dims_);
  const Eigen::RowVectorXf m = mean.cast<float>().transpose();
  constexpr Eigen::Index kBlock = 4096;
#pragma omp parallel for schedule(static)
  for (Eigen::Index b = 0; b < n; b += kBlock) {
    const Eigen::Index len = std::min(kBlock, n - b);
    Eigen::Map<RowMajor> out(data_.data() + static_cast<std::size_t>(b) * dims_, len, d);
    out.noalias() = (x.middleRows(b, len).rowwise() - m) * basis;
  }
}

// Nodes are numbered in depth-first pre-order. The two subtrees of the root are built at the
// same time into their own lists and appended with their ids shifted, which gives the very
// same numbering as a sequential build.
int DescriptorIndex::build(const float* values, int begin, int end, std::vector<Node>& nodes, int depth) {
  const int id = static_cast<int>(nodes.size());
  nodes.push_back({-1, 0.f, begin, end});
  if (end - begin <= kLeafSize) return id;
  // Split the dimension of largest spread at the median (ties by index: deterministic).
  int best = 0;
  float best_spread = -1.f;
  // The spread is measured on at most ~256 evenly spaced rows: enough to pick the axis, and
  // it keeps the build O(n log n) instead of O(n d log n).
  const int stride = std::max(1, (end - begin) / 256);
  for (std::size_t d = 0; d < dims_; ++d) {
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
    for (int i = begin; i < end; i += stride) {
      const float v = values[static_cast<std::size_t>(order_[i]) * dims_ + d];
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
    if (hi - lo > best_spread) { best_spread = hi - lo; best = static_cast<int>(d); }
  }
  // All rows equal (e.g. empty patches): still split, by row, so that leaves stay small and
  // the check budget bounds the search.
  if (!(best_spread > 0)) best = 0;
  const int mid = begin + (end - begin) / 2;
  auto key = [&](int r) { return values[static_cast<std::size_t>(r) * dims_ + best]; };
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](int a, int b) { return key(a) != key(b) ? key(a) < key(b) : a < b; });
  const float split = key(order_[mid]);
  if (depth > 0 || end - begin < 65536) {
    const int left = build(values, begin, mid, nodes, depth + 1);
    const int right = build(values, mid, end, nodes, depth + 1);
    nodes[id] = {best, split, left, right};
    return id;
  }
  std::vector<Node> sub[2];  // the subtrees touch disjoint ranges of order_
#pragma omp parallel for schedule(static, 1) num_threads(2)
  for (int side = 0; side < 2; ++side)
    build(values, side == 0 ? begin : mid, side == 0 ? mid : end, sub[side], depth + 1);
  const int left = static_cast<int>(nodes.size());
  const int right = left + static_cast<int>(sub[0].size());
  for (int side = 0; side < 2; ++side) {
    const int shift = side == 0 ? left : right;
    for (Node nd : sub[side]) {
      if (nd.split_dim >= 0) { nd.left += shift; nd.right += shift; }
      nodes.push_back(nd);
    }
  }
  nodes[id] = {best, split, left, right};
  return id;
}

int DescriptorIndex::nearestK(const float* query, int k, std::vector<int>& indices,
                              std::vector<float>& sq_distances) const {
  if (basis_.empty()) return search(query, k, indices, sq_distances);
  const Eigen::Index d = static_cast<Eigen::Index>(dims_);
  thread_local Eigen::VectorXf turned;
  turned.resize(d);
  turned.noalias() = Eigen::Map<const Eigen::MatrixXf>(basis_.data(), d, d).transpose() *
                     (Eigen::Map<const Eigen::VectorXf>(query, d) - Eigen::Map<const Eigen::VectorXf>(mean_.data(), d));
  return search(turned.data(), k, indices, sq_distances);
}

int DescriptorIndex::nearestKOfStored(std::size_t t, int k, std::vector<int>& indices,
                                      std::vector<float>& sq_distances) const {
  return search(storedRow(t), k, indices, sq_distances);
}

int DescriptorIndex::search(const float* query, int k, std::vector<int>& indices,
                            std::vector<float>& sq_distances) const {
  indices.clear();
  sq_distances.clear();
  k = std::min<int>(k, static_cast<int>(rows_));
  if (k <= 0) return 0;
  // Max-heap of the best k (distance, row).
  // Per-thread scratch: no allocation per query.
  thread_local std::vector<std::pair<float, int>> best;
  best.clear();
  auto worst = [&]() {
    return static_cast<int>(best.size()) < k ? std::numeric_limits<float>::infinity() : best.front().first;
  };
  // Min-heap of branches to revisit, by lower bound on distance (one-axis bound, as in
  // best-bin-first).
  using Branch = std::pair<float, int>;
  thread_local std::vector<Branch> heap;
  heap.clear();
  auto pushBranch = [&](float b, int node) {
    heap.emplace_back(b, node);
    std::push_heap(heap.begin(), heap.end(), std::greater<Branch>());
  };
  pushBranch(0.f, 0);
  int checks = 0;
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), std::greater<Branch>());
    const auto [bound, start] = heap.back();
    heap.pop_back();
    if (bound > worst()) break;
    if (max_checks_ > 0 && checks >= max_checks_ && static_cast<int>(best.size()) >= k) break;
    int node = start;
    float node_bound = bound;
    // Descend to a leaf, queueing the far sides.
    while (nodes_[node].split_dim >= 0) {
      const Node& nd = nodes_[node];
      const float diff = query[nd.split_dim] - nd.split_val;
      const int near = diff <= 0 ? nd.left : nd.right;
      const int far = diff <= 0 ? nd.right : nd.left;
      const float far_bound = std::max(node_bound, diff * diff);
      if (far_bound <= worst()) pushBranch(far_bound, far);
      node = near;
    }
    const Node& leaf = nodes_[node];
    for (int i = leaf.left; i < leaf.right; ++i) {
      const float* row = &data_[static_cast<std::size_t>(i) * dims_];
      // Squared distance on SIMD lanes, a block of dimensions at a time; a row already
      // farther than the k-th best is dropped after the block that shows it (the terms are
      // non-negative, so it could not enter the k best): the answers are those of the full sum.
      const float limit = worst();
      float d2 = 0.f;
      for (std::size_t d0 = 0; d0 < dims_; d0 += kDistanceBlock) {
        const std::size_t d1 = std::min(dims_, d0 + kDistanceBlock);
        float part = 0.f;
#pragma omp simd reduction(+ : part)
        for (std::size_t d = d0; d < d1; ++d) {
          const float t = row[d] - query[d];
          part += t * t;
        }
        d2 += part;
        if (d2 > limit) break;
      }
      ++checks;
      const std::pair<float, int> cand(d2, order_[i]);
      if (static_cast<int>(best.size()) < k) {
        best.push_back(cand);
        std::push_heap(best.begin(), best.end());
      } else if (cand < best.front()) {
        std::pop_heap(best.begin(), best.end());
        best.back() = cand;
        std::push_heap(best.begin(), best.end());
      }
    }
  }
  std::sort_heap(best.begin(), best.end());
  for (const auto& [d2, r] : best) {
    indices.push_back(r);
    sq_distances.push_back(d2);
  }
  return static_cast<int>(indices.size());
}

}  // namespace paps
