#pragma once
// Spatial order: points that are close in space made close in memory.
#include <cstdint>
#include <vector>

#include <paps/core/positions.h>

namespace paps {

/// Indices of the finite points sorted along a Z-order (Morton) curve over their bounding
/// cube, cut in 2^bits_per_axis - 1 steps per axis (bits 1 to 21), ties by coordinates
/// (x, y, z), then, for copies of one position, by index. Loops over
/// neighbourhoods of a shuffled cloud are memory-bound; in this order they stay in cache.
/// The order depends on the points only, never on the thread count.
std::vector<int> spatialOrder(const Positions& points, int bits_per_axis = 21);

/// Lexicographic order of positions (x, then y, then z): the tie-break of the orders and
/// samples here, which must not depend on the input order.
inline bool coordinatesBefore(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  for (int k = 0; k < 3; ++k)
    if (a[k] != b[k]) return a[k] < b[k];
  return false;
}

/// A hash of a position's coordinate bits: copies of a point share it, whatever their index.
std::uint64_t positionHash(const Eigen::Vector3f& p);

/// At most `samples` finite points chosen by their positions alone (the smallest
/// positionHash, ties by coordinates): the same positions whatever the order of the input,
/// spread at random over the cloud. Indices into `points`, in hash order.
std::vector<int> positionSample(const Positions& points, std::size_t samples);

/// Every index of `points`: the finite ones in spatialOrder, then the non-finite ones in
/// input order. A stage run on gathered(points, order) sees every point.
std::vector<int> spatialOrderAll(const Positions& points);

/// `values` rearranged as `order` says: out[k] = values[order[k]].
template <typename T>
std::vector<T> gathered(const std::vector<T>& values, const std::vector<int>& order) {
  std::vector<T> out;
  out.reserve(order.size());
  for (const int i : order) out.push_back(values[i]);
  return out;
}

/// Runs a point-moving stage on the points in spatialOrderAll order and returns its output in
/// input order. `stage(points, movable)` gets both rearranged (movable may be empty) and
/// returns one position per point. The input is checked first (checkMovableInput: an empty
/// or all-NaN cloud, or a movable list of the wrong size, throws before anything is moved).
template <typename Stage>
Positions runInSpatialOrder(const Positions& points, const std::vector<std::uint8_t>& movable, Stage&& stage) {
  checkMovableInput(points, movable);
  const std::vector<int> order = spatialOrderAll(points);
  const Positions sorted_out = stage(gathered(points, order), movable.empty() ? movable : gathered(movable, order));
  Positions out(points.size());
  for (std::size_t k = 0; k < order.size(); ++k) out[order[k]] = sorted_out[k];
  return out;
}

}  // namespace paps
