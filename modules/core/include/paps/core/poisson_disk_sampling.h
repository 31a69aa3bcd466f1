#pragma once
// Poisson-disk subsets of a point set by dart throwing (manuscript 2.2.3, seed selection):
// points are visited in a seeded random order and kept when no kept point lies closer
// than the radius. The result is a maximal set: no two kept points are closer than the
// radius, and every input point lies within the radius of a kept one.
#include <cstdint>
#include <vector>

#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

/// Indices (increasing) of a maximal Poisson-disk subset of the finite points at `radius`
/// (metres, > 0). Deterministic for a given `seed`. Non-finite points are never chosen.
/// Throws InvalidParameter for a radius that is not positive or so small against the extent
/// of the points that the hash grid would overflow (more than 2^60 cells).
std::vector<int> poissonDiskSubset(const Positions& points, float radius, std::uint64_t seed = 1,
                                   const ProgressCallback& progress = {});

/// Same, visiting the points in the order given by `priority` (lower first) instead of a
/// random order; ties broken by index. Lets a caller prefer some points (e.g. the
/// best-supported ones when thinning a decoded cloud). An empty `priority` visits the points
/// in index order, which is also much faster on large clouds (memory locality).
std::vector<int> poissonDiskSubsetOrdered(const Positions& points, float radius,
                                          const std::vector<float>& priority);

}  // namespace paps
