#pragma once
// Neighbourhoods on pcl::search: a spatial index over positions, fixed neighbour lists
// (radius or k nearest) stored once in compressed rows, and a radius chosen from a target
// neighbour count so that users need not know the scale of their data.
#include <cstdint>
#include <memory>
#include <vector>

#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

/// Largest coordinate magnitude the neighbourhood code takes (metres or any unit): far beyond
/// any scan, far enough below float's 3.4e38 that extents and squared distances stay finite
/// in the kd-tree.
constexpr float kMaxCoordinate = 1e30f;

namespace detail {
[[noreturn]] void throwCoordinateOutOfRange(float magnitude, const char* who);
}

/// Throws InvalidInput (prefixed by `who` when given) when the finite point `p` has a
/// coordinate beyond kMaxCoordinate. The one check behind SpatialIndex and KdTreeSearch.
inline void requireCoordinatesInRange(const Eigen::Vector3f& p, const char* who = nullptr) {
  if (isFinite(p) && p.cwiseAbs().maxCoeff() > kMaxCoordinate) detail::throwCoordinateOutOfRange(p.cwiseAbs().maxCoeff(), who);
}

/// Kd-tree over the finite points of a Positions array. Queries are const and thread-safe;
/// returned indices refer to the original array, sorted by increasing distance.
/// Throws InvalidInput when a coordinate's magnitude exceeds kMaxCoordinate: the tree's float
/// arithmetic overflows there and FLANN aborts the process (seen on a PLY whose records were
/// misaligned, i.e. random floats).
class SpatialIndex {
 public:
  explicit SpatialIndex(const Positions& points);
  ~SpatialIndex();
  SpatialIndex(const SpatialIndex&) = delete;
  SpatialIndex& operator=(const SpatialIndex&) = delete;

  /// Points within `radius` (metres) of q, at most `max_count` (0: all). Returns the count.
  int radiusSearch(const Eigen::Vector3f& q, float radius, std::vector<int>& indices,
                   std::vector<float>& sq_distances, int max_count = 0) const;
  /// The same with the squared radius given: points at a squared distance below
  /// `sq_radius`, as FLANN counts it (pcl::KdTreeFLANN passes float(radius * radius) in
  /// double, which can differ from the float radius squared in float).
  int radiusSearchSquared(const Eigen::Vector3f& q, float sq_radius, std::vector<int>& indices,
                          std::vector<float>& sq_distances, int max_count = 0) const;
  /// The k points nearest to q. Returns the count (fewer when the index holds fewer).
  int nearestK(const Eigen::Vector3f& q, int k, std::vector<int>& indices,
               std::vector<float>& sq_distances) const;
  /// Number of indexed (finite) points.
  std::size_t size() const { return finite_.size(); }

 private:
  std::vector<int> finite_;  // index in the tree -> index in the original array
  struct Tree;
  std::unique_ptr<Tree> tree_;
};

/// Fixed neighbour lists of every point, self included (first, at distance 0).
/// Non-finite points have empty lists.
class NeighbourGraph {
 public:
  /// All finite points within `radius` (metres), at most `max_count` per point (0: all).
  static NeighbourGraph byRadius(const Positions& points, const SpatialIndex& index, float radius,
                                 int max_count = 0, const ProgressCallback& progress = {});
  /// The k nearest finite points (self included).
  static NeighbourGraph byCount(const Positions& points, const SpatialIndex& index, int k,
                                const ProgressCallback& progress = {});

  /// Lists given as compressed rows: list i is indices[offsets[i] .. offsets[i + 1]). offsets
  /// starts at 0, never decreases and ends at indices.size() (else InvalidParameter); the
  /// caller keeps the conventions above (self first, indices in range).
  static NeighbourGraph fromRows(std::vector<std::int64_t> offsets, std::vector<int> indices);

  std::size_t size() const { return offsets_.empty() ? 0 : offsets_.size() - 1; }
  /// Number of neighbours of point i (self included).
  int count(std::size_t i) const { return offsets_[i + 1] - offsets_[i]; }
  const int* begin(std::size_t i) const { return indices_.data() + offsets_[i]; }
  const int* end(std::size_t i) const { return indices_.data() + offsets_[i + 1]; }
  /// The same lists keeping only the neighbours j of i for which keep(i, j) holds; each
  /// point stays first in its own list.
  template <typename Keep>
  NeighbourGraph filtered(Keep keep) const {
    // Counted first, then filled: reserving the full size kept the whole graph's memory
    // for half of it (the denoiser's half graphs).
    NeighbourGraph g;
    g.offsets_.assign(offsets_.size(), 0);
    auto kept = [&](std::size_t i, int j) { return j == static_cast<int>(i) || keep(static_cast<int>(i), j); };
    for (std::size_t i = 0; i < size(); ++i) {
      std::int64_t c = 0;
      for (const int* j = begin(i); j != end(i); ++j) c += kept(i, *j);
      g.offsets_[i + 1] = g.offsets_[i] + c;
    }
    g.indices_.reserve(static_cast<std::size_t>(g.offsets_.back()));
    for (std::size_t i = 0; i < size(); ++i)
      for (const int* j = begin(i); j != end(i); ++j)
        if (kept(i, *j)) g.indices_.push_back(*j);
    return g;
  }
  /// Mean neighbour count over points that have any.
  double meanCount() const;

 private:
  std::vector<std::int64_t> offsets_;
  std::vector<int> indices_;
  friend class NeighbourGraphBuilder;
};

/// Which count radiusForNeighbourCount aims at.
enum class NeighbourCountStatistic {
  /// A typical point (the median) holds the count: the default. A mean count is made by the
  /// densest spots of a real scan (next to the sensor, overlapping passes, duplicated points)
  /// and shrinks the radius for the rest: table_scene_lms400 at a mean of 30 had a median of
  /// 13 and 6.5% of its points under 6 neighbours, bun0.pcd 81%.
  Median,
  /// The mean count (the manuscript's wording), for protocols on evenly sampled surfaces
  /// that were set up that way; on such data it is within a few percent of the median.
  Mean,
};

/// A deterministic sample of at most `samples` finite points spread over the array (every
/// (finite count / samples)-th finite point, in array order): indices into `points`.
std::vector<int> spreadSample(const Positions& points, std::size_t samples);

/// Mean neighbour count (self included) at `radius` over spreadSample(points, samples), at
/// most `max_count` counted per ball (0: all); `index` built on `points`. For a stage run in
/// tiles that sizes something by the whole cloud's count, as one piece does by its lists'.
/// 0 when no point is finite.
double sampledMeanNeighbourCount(const Positions& points, const SpatialIndex& index, float radius, int max_count,
                                 std::size_t samples = 2000);

/// Mean distance (metres) from each finite point to its nearest other point (0 for an exact
/// duplicate), `index` built on `points`. Throws InvalidInput when there are fewer than 2
/// finite points.
double meanNearestNeighbourDistance(const Positions& points, const SpatialIndex& index);

/// Radius (metres) at which a ball holds `target_count` points (self included), measured on
/// a deterministic sample of at most `samples` points: Median, the median of their distances
/// to the target_count-th nearest point; Mean, from there the surface law count ~ r^2 until
/// the mean count is within 3%. Throws InvalidInput when there are fewer than 2 finite points.
float radiusForNeighbourCount(const Positions& points, const SpatialIndex& index, int target_count,
                              NeighbourCountStatistic statistic = NeighbourCountStatistic::Median,
                              int samples = 2000);

/// Exact duplicates: for every point, the index of the first point (in array order) at
/// exactly the same position (itself when it is the first); -1 for non-finite points.
/// Positions compare by value (0.0f equals -0.0f). Scans merged from several passes, or
/// written twice, carry such copies; a local fit should count each position once.
/// `duplicates`, when given, receives the number of finite points that are not the first
/// at their position.
std::vector<int> exactDuplicateRepresentatives(const Positions& points, std::size_t* duplicates = nullptr);

/// The distinct positions of `points` (the representatives of exactDuplicateRepresentatives,
/// `first`, in array order). `slot`, when given, receives for every point the index of its
/// position among them (-1 for non-finite points).
Positions distinctPositions(const Positions& points, const std::vector<int>& first, std::vector<int>* slot = nullptr);

}  // namespace paps

namespace paps {

/// A spatial index, the radius in use and the neighbour lists at that radius: what every
/// local stage builds first.
struct RadiusNeighbourhood {
  std::unique_ptr<SpatialIndex> index;
  float radius = 0.f;
  NeighbourGraph graph;
};

/// Builds a RadiusNeighbourhood. radius > 0 is used as given; radius == 0 picks the radius
/// holding `target_neighbours` around a typical point (radiusForNeighbourCount). At most
/// `max_count` neighbours per point (0: all).
/// Throws InvalidInput when fewer than 2 points are finite.
/// `index`, when given, must have been built on `points`; it is used instead of a new one.
/// A radius wider than the points' extent throws InvalidParameter (requireRadiusWithinExtent)
/// unless `check_extent` is false: a stage run on a piece of a cloud (a tile) has checked the
/// user's radius on the whole cloud, and a dense tile may be narrower than the radius.
RadiusNeighbourhood buildRadiusNeighbourhood(const Positions& points, float radius,
                                             int target_neighbours, int max_count = 0,
                                             const ProgressCallback& progress = {},
                                             std::unique_ptr<SpatialIndex> index = nullptr,
                                             bool check_extent = true);

}  // namespace paps
