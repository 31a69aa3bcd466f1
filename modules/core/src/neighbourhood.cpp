#include <paps/core/neighbourhood.h>
#include <paps/core/spatial_order.h>

#include <algorithm>
#include <cstring>
#include <cmath>
#include <tuple>

#include <flann/flann.hpp>
#include <pcl/point_types.h>

#include <paps/core/cell_grid.h>
#include <paps/core/error.h>

namespace paps {

// FLANN's single k-d tree (leaf size 15, exact, sorted results), as pcl::KdTreeFLANN builds
// it, holding only FLANN's own reordered copy of the finite points: PCL's class also held a
// PointXYZ cloud and a float array of it (about 0.5 GB more at 20M points), and allocated
// vectors at every radius query. The tree and the searches are the same, so are the results.
struct SpatialIndex::Tree {
  std::vector<float> xyz;  // finite points, 3 floats each, until FLANN has its copy
  std::unique_ptr<flann::KDTreeSingleIndex<flann::L2_Simple<float>>> index;
  flann::SearchParams params{-1, 0.f, true};
};

namespace {

// FLANN's result sets, kept per thread between queries with the same bounds (a radius set
// keeps the room of its largest answer). FLANN's own knnSearch and radiusSearch make new
// ones at every query (a 16 KB reserve for a radius search) inside an OpenMP region of their
// own: 12-nearest queries on 2M points, one thread, took 3.95 us each that way and 1.23 us
// this way. The tree, the result sets and their copies are FLANN's: the same lists.
template <typename Set, typename... Bounds>
Set& resultSetFor(std::unique_ptr<Set>& kept, std::tuple<Bounds...>& kept_bounds, Bounds... bounds) {
  if (!kept || kept_bounds != std::tuple<Bounds...>(bounds...)) {
    kept = std::make_unique<Set>(bounds...);
    kept_bounds = std::tuple<Bounds...>(bounds...);
  }
  kept->clear();
  return *kept;
}

}  // namespace

namespace detail {
void throwCoordinateOutOfRange(float magnitude, const char* who) {
  throw InvalidInput(std::string(who ? std::string(who) + ": " : "") + "a point has a coordinate of magnitude " +
                     toString(magnitude) + ", beyond " + toString(kMaxCoordinate) + " (a corrupt file?)");
}
}  // namespace detail

SpatialIndex::SpatialIndex(const Positions& points) {
  tree_ = std::make_unique<Tree>();
  std::size_t count = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!isFinite(points[i])) continue;
    requireCoordinatesInRange(points[i]);
    ++count;
  }
  finite_.reserve(count);
  tree_->xyz.reserve(3 * count);
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!isFinite(points[i])) continue;
    finite_.push_back(static_cast<int>(i));
    tree_->xyz.insert(tree_->xyz.end(), {points[i].x(), points[i].y(), points[i].z()});
  }
  if (count == 0) return;
  // The index flann::Index makes for these parameters, held directly: its searches are called
  // without the per-query wrapper (resultSetFor).
  tree_->index = std::make_unique<flann::KDTreeSingleIndex<flann::L2_Simple<float>>>(
      flann::Matrix<float>(tree_->xyz.data(), count, 3), flann::KDTreeSingleIndexParams(15, /*reorder=*/true));
  tree_->index->buildIndex();
  // Reordered, the tree searches its own copy (leaf by leaf in memory): ours is not read again.
  std::vector<float>().swap(tree_->xyz);
}

SpatialIndex::~SpatialIndex() = default;

namespace {

// Runs one FLANN search into result set `s` and copies its first `cap` results, nearest
// first (ties by tree index, FLANN's order).
template <typename Set>
std::size_t searchInto(const flann::KDTreeSingleIndex<flann::L2_Simple<float>>& tree, const flann::SearchParams& params,
                       const float* query, Set& s, std::size_t cap, std::vector<std::size_t>& idx,
                       std::vector<float>& sq_distances) {
  tree.findNeighbors(s, query, params);
  const std::size_t n = std::min(s.size(), cap);
  idx.resize(n);
  sq_distances.resize(n);
  if (n > 0) s.copy(idx.data(), sq_distances.data(), n, true);
  return n;
}

}  // namespace

int SpatialIndex::radiusSearch(const Eigen::Vector3f& q, float radius, std::vector<int>& indices,
                               std::vector<float>& sq_distances, int max_count) const {
  return radiusSearchSquared(q, radius * radius, indices, sq_distances, max_count);
}

int SpatialIndex::radiusSearchSquared(const Eigen::Vector3f& q, float r2, std::vector<int>& indices,
                                      std::vector<float>& sq_distances, int max_count) const {
  indices.clear();
  sq_distances.clear();
  if (finite_.empty() || !isFinite(q)) return 0;
  thread_local std::unique_ptr<flann::RadiusResultSet<float>> all;
  thread_local std::tuple<float> all_bounds;
  thread_local std::unique_ptr<flann::KNNRadiusResultSet<float>> capped;
  thread_local std::tuple<float, std::size_t> capped_bounds;
  thread_local std::vector<std::size_t> idx;
  const float query[3] = {q.x(), q.y(), q.z()};
  const std::size_t cap = max_count > 0 ? static_cast<std::size_t>(max_count) : finite_.size();
  // As FLANN's radiusSearch: a capped result set only when the cap can bind.
  const std::size_t n =
      cap < finite_.size()
          ? searchInto(*tree_->index, tree_->params, query, resultSetFor(capped, capped_bounds, r2, cap), cap, idx, sq_distances)
          : searchInto(*tree_->index, tree_->params, query, resultSetFor(all, all_bounds, r2), cap, idx, sq_distances);
  indices.resize(n);
  for (std::size_t i = 0; i < n; ++i) indices[i] = finite_[idx[i]];
  return static_cast<int>(n);
}

int SpatialIndex::nearestK(const Eigen::Vector3f& q, int k, std::vector<int>& indices,
                           std::vector<float>& sq_distances) const {
  indices.clear();
  sq_distances.clear();
  if (finite_.empty() || !isFinite(q) || k <= 0) return 0;
  thread_local std::unique_ptr<flann::KNNSimpleResultSet<float>> simple;
  thread_local std::tuple<std::size_t> simple_bounds;
  thread_local std::unique_ptr<flann::KNNResultSet2<float>> heap;
  thread_local std::tuple<std::size_t> heap_bounds;
  thread_local std::vector<std::size_t> idx;
  const float query[3] = {q.x(), q.y(), q.z()};
  const std::size_t kk = std::min<std::size_t>(static_cast<std::size_t>(k), finite_.size());
  // FLANN's choice of result set by k, as its knnSearch makes it.
  const std::size_t n =
      kk > KNN_HEAP_THRESHOLD
          ? searchInto(*tree_->index, tree_->params, query, resultSetFor(heap, heap_bounds, kk), kk, idx, sq_distances)
          : searchInto(*tree_->index, tree_->params, query, resultSetFor(simple, simple_bounds, kk), kk, idx, sq_distances);
  indices.resize(n);
  for (std::size_t i = 0; i < n; ++i) indices[i] = finite_[idx[i]];
  return static_cast<int>(n);
}

namespace {

// Self first, even among exact duplicates or when a capped search left it out.
void putSelfFirst(std::vector<int>& idx, int self_index) {
  auto self = std::find(idx.begin(), idx.end(), self_index);
  if (self != idx.end()) {
    std::rotate(idx.begin(), self, self + 1);
  } else {
    if (!idx.empty()) idx.pop_back();
    idx.insert(idx.begin(), self_index);
  }
}

}  // namespace

// Builds the compressed rows in parallel, so that the result does not depend on the thread
// count. Queries run in spatial order: consecutive queries walk the same tree nodes and
// points, which a shuffled cloud otherwise fetches from memory each time (each row is the
// same).
class NeighbourGraphBuilder {
 public:
  // Rows of any length: each thread fills per-point lists, then one pass concatenates them in
  // point order.
  template <typename Query>
  static NeighbourGraph build(const Positions& points, const ProgressCallback& progress,
                              const char* stage, Query query) {
    std::vector<std::vector<int>> lists(points.size());
    queryAll(points, progress, stage, query, [&](int i, const std::vector<int>& idx) { lists[i] = idx; });
    NeighbourGraph g;
    g.offsets_.resize(points.size() + 1, 0);
    for (std::size_t i = 0; i < points.size(); ++i) g.offsets_[i + 1] = g.offsets_[i] + lists[i].size();
    g.indices_.resize(g.offsets_.back());
    for (std::size_t i = 0; i < points.size(); ++i) {
      std::copy(lists[i].begin(), lists[i].end(), g.indices_.begin() + g.offsets_[i]);
      std::vector<int>().swap(lists[i]);
    }
    return g;
  }

  // The same rows when none is longer than `max_count`: each written at its point's slot of
  // one flat buffer, then packed in place. No list per point (vector, heap block and its
  // header: about 88 bytes a point at 12 neighbours, beside the graph's 56): the peak heap
  // went from 2.37x to 1.11x the graph's bytes (test), `paps curvature` at 20M points from
  // 5.79 to 4.66 GB.
  template <typename Query>
  static NeighbourGraph buildBounded(const Positions& points, std::size_t max_count, const ProgressCallback& progress,
                                     const char* stage, Query query) {
    NeighbourGraph g;
    g.offsets_.assign(points.size() + 1, 0);  // row lengths at i + 1 first, then their sums
    g.indices_.resize(points.size() * max_count);
    queryAll(points, progress, stage, query, [&](int i, const std::vector<int>& idx) {
      const std::size_t c = std::min(idx.size(), max_count);  // the query's own bound
      std::copy(idx.begin(), idx.begin() + static_cast<std::ptrdiff_t>(c),
                g.indices_.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(i) * max_count));
      g.offsets_[static_cast<std::size_t>(i) + 1] = static_cast<std::int64_t>(c);
    });
    for (std::size_t i = 0; i < points.size(); ++i) {
      const std::int64_t c = g.offsets_[i + 1];
      g.offsets_[i + 1] = g.offsets_[i] + c;
      // Row i moves down to its packed place (never past its own slot): memmove for overlaps.
      if (c > 0 && static_cast<std::size_t>(g.offsets_[i]) != i * max_count)
        std::memmove(g.indices_.data() + g.offsets_[i], g.indices_.data() + i * max_count,
                     static_cast<std::size_t>(c) * sizeof(int));
    }
    g.indices_.resize(static_cast<std::size_t>(g.offsets_.back()));
    return g;
  }

 private:
  // Runs `query` for every finite point in spatial order, in parallel, and hands each point's
  // row (self first) to `store(i, row)`; rows of distinct points may be stored concurrently.
  template <typename Query, typename Store>
  static void queryAll(const Positions& points, const ProgressCallback& progress, const char* stage, Query& query,
                       Store store) {
    const std::vector<int> order = spatialOrder(points);
    const std::int64_t n = static_cast<std::int64_t>(order.size());
    ProgressReporter report(progress, stage, points.size());
#pragma omp parallel
    {
      std::vector<int> idx;
      std::vector<float> d2;
#pragma omp for schedule(dynamic, 256)
      for (std::int64_t k = 0; k < n; ++k) {
        if (report.cancelled()) continue;
        const int i = order[k];
        query(points[i], idx, d2);
        putSelfFirst(idx, i);
        store(i, idx);
        report.advance();
      }
    }
    report.advance(points.size() - order.size());
    report.throwIfCancelled();
    report.finish();
  }
};

NeighbourGraph NeighbourGraph::byRadius(const Positions& points, const SpatialIndex& index,
                                        float radius, int max_count, const ProgressCallback& progress) {
  requirePositive("radius", radius);
  // The core cell grid gives the same lists faster (queries in cell order): open ball and
  // (distance, index) order like the kd-tree. A ball over the cap keeps its max_count nearest,
  // ties by index (the kd-tree keeps the nearest too, but its choice among exact ties at the
  // cap differs). Sending those balls to the kd-tree instead cost 12 s of 15 on 200K points
  // at 120 of ~190 neighbours (the denoiser under heavy noise).
  CellGrid grid;
  if (index.size() > 0 && grid.build(points, radius))
    return grid.radiusGraph(points.size(), radius, /*open_ball=*/true, progress, max_count);
  return NeighbourGraphBuilder::build(points, progress, "neighbours",
      [&](const Eigen::Vector3f& q, std::vector<int>& idx, std::vector<float>& d2) {
        index.radiusSearch(q, radius, idx, d2, max_count);
      });
}

NeighbourGraph NeighbourGraph::byCount(const Positions& points, const SpatialIndex& index, int k,
                                       const ProgressCallback& progress) {
  requirePositive("k", k);
  // A row holds at most k of the indexed points, or the point itself alone.
  const std::size_t bound = std::max<std::size_t>(1, std::min<std::size_t>(static_cast<std::size_t>(k), index.size()));
  return NeighbourGraphBuilder::buildBounded(points, bound, progress, "neighbours",
      [&](const Eigen::Vector3f& q, std::vector<int>& idx, std::vector<float>& d2) {
        index.nearestK(q, k, idx, d2);
      });
}

NeighbourGraph NeighbourGraph::fromRows(std::vector<std::int64_t> offsets, std::vector<int> indices) {
  bool ok = !offsets.empty() && offsets.front() == 0 &&
            offsets.back() == static_cast<std::int64_t>(indices.size());
  for (std::size_t i = 1; ok && i < offsets.size(); ++i) ok = offsets[i] >= offsets[i - 1];
  if (!ok) throw InvalidParameter("offsets", std::to_string(offsets.size()) + " row offsets",
                                  "0 first, non-decreasing, the index count last");
  NeighbourGraph g;
  g.offsets_ = std::move(offsets);
  g.indices_ = std::move(indices);
  return g;
}

double NeighbourGraph::meanCount() const {
  std::size_t pts = 0, total = 0;
  for (std::size_t i = 0; i < size(); ++i)
    if (count(i) > 0) { ++pts; total += count(i); }
  return pts ? static_cast<double>(total) / pts : 0.0;
}

std::vector<int> spreadSample(const Positions& points, std::size_t samples) {
  std::vector<int> finite;
  for (std::size_t i = 0; i < points.size(); ++i)
    if (isFinite(points[i])) finite.push_back(static_cast<int>(i));
  const std::size_t m = std::min(samples, finite.size());
  if (m == finite.size()) return finite;
  const double stride = static_cast<double>(finite.size()) / m;
  std::vector<int> out(m);
  for (std::size_t s = 0; s < m; ++s) out[s] = finite[static_cast<std::size_t>(s * stride)];
  return out;
}

double meanNearestNeighbourDistance(const Positions& points, const SpatialIndex& index) {
  if (index.size() < 2)
    throw InvalidInput("mean spacing: needs at least 2 finite points, got " + std::to_string(index.size()));
  std::vector<int> k;
  std::vector<float> d2;
  double sum = 0;
  std::size_t n = 0;
  for (const auto& p : points) {
    if (!isFinite(p)) continue;
    index.nearestK(p, 2, k, d2);
    sum += std::sqrt(d2[1]);  // a float root: the spacing the bench and the filter had before
    ++n;
  }
  return sum / static_cast<double>(n);
}

double sampledMeanNeighbourCount(const Positions& points, const SpatialIndex& index, float radius, int max_count,
                                 std::size_t samples) {
  std::vector<int> idx;
  std::vector<float> d2;
  double sum = 0;
  const std::vector<int> sample = spreadSample(points, samples);
  for (const int i : sample) sum += index.radiusSearch(points[i], radius, idx, d2, max_count);
  return sample.empty() ? 0.0 : sum / static_cast<double>(sample.size());
}

float radiusForNeighbourCount(const Positions& points, const SpatialIndex& index, int target_count,
                              NeighbourCountStatistic statistic, int samples) {
  requireInRange("target_count", target_count, 2, 100000);
  requirePositive("samples", samples);
  if (index.size() < 2) throw InvalidInput("fewer than 2 finite points: cannot choose a radius");
  const std::vector<int> sample = spreadSample(points, static_cast<std::size_t>(samples));
  const std::size_t m = sample.size();
  std::vector<int> idx;
  std::vector<float> d2;
  std::vector<float> kth;
  kth.reserve(m);
  for (const int i : sample) {
    const int n = index.nearestK(points[i], target_count, idx, d2);
    if (n > 1) kth.push_back(std::sqrt(d2[n - 1]));
  }
  // The median of the k-th neighbour distances: half of the points have at least
  // target_count points within it.
  std::nth_element(kth.begin(), kth.begin() + kth.size() / 2, kth.end());
  float r = kth.empty() ? 0.f : kth[kth.size() / 2];
  // Squared distances are floats: spacings beyond about 1e19 m overflow them and spacings
  // below about 1e-19 m underflow them. Said in those words rather than as a bad radius.
  auto extent = [&points] {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
    for (const auto& p : points)
      if (isFinite(p)) { lo = lo.cwiseMin(p.cast<double>()); hi = hi.cwiseMax(p.cast<double>()); }
    return (hi - lo).maxCoeff();
  };
  auto overflow = [&] {
    return InvalidInput("the points span " + detail::toString(extent()) +
                        " m: their squared distances overflow float arithmetic; scale the cloud down");
  };
  if (!std::isfinite(r)) throw overflow();
  if (!(r > 0)) {
    // Duplicates dominate: fall back to a fraction of the extent.
    r = boundingBoxDiagonal(points) * 1e-3f;
    if (!(r > 0)) {
      const double e = extent();
      if (e > 0)
        throw InvalidInput("the points span only " + detail::toString(e) +
                           " m: their squared distances underflow float arithmetic; scale the cloud up");
      throw InvalidInput("all points are identical: cannot choose a radius");
    }
    if (!std::isfinite(r)) throw overflow();
  }
  if (statistic == NeighbourCountStatistic::Mean) {
    // The k-th neighbour distance overshoots the mean count near borders and undershoots in
    // dense spots; correct by the surface law count ~ r^2 until within 3% (scan lines make
    // the law inexact, hence a few rounds).
    for (int iter = 0; iter < 6; ++iter) {
      double total = 0;
      std::size_t used = 0;
      for (std::size_t s = 0; s < m; s += std::max<std::size_t>(1, m / 500)) {
        total += index.radiusSearch(points[sample[s]], r, idx, d2);
        ++used;
      }
      const double mean = total / used;
      if (mean <= 0 || std::abs(mean - target_count) < 0.03 * target_count) break;
      r *= static_cast<float>(std::clamp(std::sqrt(target_count / mean), 0.5, 2.0));
    }
  }
  return r;
}

Positions distinctPositions(const Positions& points, const std::vector<int>& first, std::vector<int>* slot) {
  if (first.size() != points.size())
    throw InvalidParameter("first", detail::toString(first.size()), "one representative per point");
  Positions distinct;
  std::vector<int> at(points.size(), -1);
  for (std::size_t i = 0; i < points.size(); ++i)
    if (first[i] == static_cast<int>(i)) {
      at[i] = static_cast<int>(distinct.size());
      distinct.push_back(points[i]);
    }
  if (slot) {
    slot->assign(points.size(), -1);
    for (std::size_t i = 0; i < points.size(); ++i)
      if (first[i] >= 0) (*slot)[i] = at[static_cast<std::size_t>(first[i])];
  }
  return distinct;
}

std::vector<int> exactDuplicateRepresentatives(const Positions& points, std::size_t* duplicates) {
  std::vector<int> rep(points.size(), -1);
  std::vector<int> order;
  order.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i)
    if (isFinite(points[i])) order.push_back(static_cast<int>(i));
  // Lexicographic by value, then by index: each run of equal positions starts at its first.
  auto less = [&](int a, int b) {
    const Eigen::Vector3f& p = points[a];
    const Eigen::Vector3f& q = points[b];
    if (p.x() != q.x()) return p.x() < q.x();
    if (p.y() != q.y()) return p.y() < q.y();
    if (p.z() != q.z()) return p.z() < q.z();
    return a < b;
  };
  std::sort(order.begin(), order.end(), less);
  std::size_t dup = 0;
  for (std::size_t s = 0; s < order.size();) {
    std::size_t e = s + 1;
    while (e < order.size() && points[order[e]] == points[order[s]]) ++e;
    for (std::size_t t = s; t < e; ++t) rep[order[t]] = order[s];
    dup += e - s - 1;
    s = e;
  }
  if (duplicates) *duplicates = dup;
  return rep;
}

}  // namespace paps

namespace paps {

RadiusNeighbourhood buildRadiusNeighbourhood(const Positions& points, float radius,
                                             int target_neighbours, int max_count,
                                             const ProgressCallback& progress,
                                             std::unique_ptr<SpatialIndex> index, bool check_extent) {
  if (radius < 0 || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "0 (automatic) or a finite value > 0");
  if (check_extent) requireRadiusWithinExtent("radius", radius, points);
  RadiusNeighbourhood nb;
  nb.index = index ? std::move(index) : std::make_unique<SpatialIndex>(points);
  if (nb.index->size() == 0) throw InvalidInput("no finite point in the cloud");
  if (nb.index->size() < 2) throw InvalidInput("only one finite point: no neighbourhood exists");
  nb.radius = radius > 0 ? radius : radiusForNeighbourCount(points, *nb.index, target_neighbours);
  nb.graph = NeighbourGraph::byRadius(points, *nb.index, nb.radius, max_count, progress);
  return nb;
}

}  // namespace paps
