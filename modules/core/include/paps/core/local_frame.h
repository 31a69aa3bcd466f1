#pragma once
// Local frames (manuscript 2.1.2): normal by PCA, principal directions from the local normal
// covariance matrix, consistent normal orientation, and the two frame orientations.
#include <cstddef>
#include <vector>

#include <paps/core/neighbourhood.h>

namespace paps {

/// An orthonormal right-handed frame (t1, t2, n). t1 is the direction of largest normal
/// variation (maximal principal direction), n the unit normal.
struct LocalFrame {
  Eigen::Vector3f t1{Eigen::Vector3f::UnitX()}, t2{Eigen::Vector3f::UnitY()}, n{Eigen::Vector3f::UnitZ()};

  /// World offset -> (u, v, h) coordinates in the frame.
  Eigen::Vector3f toLocal(const Eigen::Vector3f& d) const { return {t1.dot(d), t2.dot(d), n.dot(d)}; }
  /// (u, v, h) -> world offset.
  Eigen::Vector3f toWorld(const Eigen::Vector3f& l) const { return l.x() * t1 + l.y() * t2 + l.z() * n; }
  /// The other admissible frame: the same normal, principal directions turned by 180 degrees.
  LocalFrame rotatedHalfTurn() const { return {-t1, -t2, n}; }
  bool valid() const { return isFinite(n); }
};
using LocalFrames = std::vector<LocalFrame>;

/// Unit normal by PCA of points[idx[0]] .. points[idx[count - 1]] (centred, in double); NaN
/// when count < 3 or the points are collinear or coincident (the middle eigenvalue of their
/// covariance at most 1e-6 of the largest: a test that does not depend on the units). Sign
/// arbitrary. `centroid`, when given, receives their mean; `variation` the surface variation
/// lambda0 / (lambda0 + lambda1 + lambda2) of their covariance (NaN with the normal).
Eigen::Vector3f pcaNormal(const Positions& points, const int* idx, int count, Eigen::Vector3f* centroid = nullptr,
                          float* variation = nullptr);

/// Unit normals by PCA of each neighbour list (pcaNormal); NaN where a point has fewer than 3
/// neighbours or they are collinear. Orientation is arbitrary until one of the orient* calls.
/// `variation`, when given, receives each list's surface variation (pcaNormal; NaN with the
/// normal): what PCL writes in the `curvature` field of its normals (pcl::NormalEstimation,
/// and pcl::MovingLeastSquares for the points it makes from a ball).
Normals estimateNormals(const Positions& points, const NeighbourGraph& graph, std::vector<float>* variation = nullptr);

/// How much the points fill a volume rather than lie on a surface: over
/// spreadSample(points, samples), the median surface variation (pcaNormal) of each sampled
/// point's k nearest, for k = 32, 128 and 512 (each at most an eighth of the finite points,
/// so that a ball stays a patch of a closed surface), and the least of those medians. A
/// surface is flat at some scale: noise is at most a few spacings thick, curvature shows only
/// at large scales. Measured (docs/transport.md): scans and synthetic surfaces 0 to 0.044 (a
/// plane with noise of twice its point spacing), points uniform in a cube 0.205 to 0.25 (1/3
/// is isotropic). 0 with fewer than 256 finite points (too few for the smallest scale);
/// `index` built on `points`. Deterministic.
double volumeVariation(const Positions& points, const SpatialIndex& index, std::size_t samples = 1000);

/// Flips each normal to face `viewpoint` (e.g. the cloud's sensor origin). Returns flips.
std::size_t orientNormalsTowards(const Positions& points, Normals& normals,
                                 const Eigen::Vector3f& viewpoint);

/// orientNormalsByPropagation reads the first this many entries of each neighbour list (the
/// nearest): they suffice to connect the graph and cost far less heap traffic than all.
constexpr int kPropagationNeighbours = 10;

/// Consistent orientation without a viewpoint: propagation over the neighbour graph along
/// the most parallel normals first (Hoppe et al. 1992), one component at a time, each seeded
/// at its highest point; each connected component is then turned up (+z): a component whose
/// normals point one way on the whole (a scan seen from one side: |sum of z| >= 0.2 sum of
/// |z|) by their summed z, otherwise (a closed surface) by the normal of its highest point
/// within 60 degrees of vertical, otherwise by its seed's. Returns flips.
/// Parallel (OpenMP) and deterministic whatever the thread count: the points are cut into
/// fixed blocks of space (runs of 4096 points in Morton order); the propagation runs inside
/// each block on its own, then the pieces are oriented relative to each other by the summed
/// agreement (ni.nj) over the edges that cross them, strongest first, over the small graph of
/// pieces. Up to 4096 points it is the plain sequential propagation.
std::size_t orientNormalsByPropagation(const Positions& points, Normals& normals,
                                       const NeighbourGraph& graph);

/// For a stage run in tiles: turns each connected component of `graph` (as
/// orientNormalsByPropagation reads it: the first kPropagationNeighbours entries of each list)
/// whose normals disagree with `hints` (the sum of n.h over its points with a finite, unit
/// hint is negative), so that the tile goes on from the normals of the tiles before it where
/// they meet. Components without a hint stay as they are.
void turnComponentsToHints(Normals& normals, const NeighbourGraph& graph, const Normals& hints);

/// +1 or -1: the sign that turns a group of consistently oriented normals up, by
/// orientNormalsByPropagation's rule for a connected component: their summed z when they
/// point one way on the whole, else the normal of the highest point within 60 degrees of
/// vertical, else +1. Non-finite points and normals are skipped. For a stage that oriented a
/// component piece by piece (tiles) and turns the whole at the end as one piece would.
int upwardSign(const Positions& points, const Normals& normals);

/// Principal frames: for each point, t1 is the eigenvector of largest eigenvalue of the
/// covariance of the neighbours' normals, projected on the tangent plane. Where the normals
/// do not vary (a plane), t1 is any tangent direction chosen deterministically.
LocalFrames estimatePrincipalFrames(const Normals& normals, const NeighbourGraph& graph);

}  // namespace paps
