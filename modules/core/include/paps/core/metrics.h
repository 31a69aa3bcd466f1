#pragma once
// Error metrics that tell good from bad: distance to a ground-truth surface, distances
// between clouds (D1), and normal angle errors.
#include <memory>
#include <vector>

#include <paps/core/triangle_mesh.h>

namespace paps {

/// Summary of a set of non-negative errors.
struct ErrorStats {
  double rmse = 0, mean = 0, p95 = 0, max = 0;
  std::size_t count = 0;  // number of finite values summarised
};
/// RMSE, mean, 95th percentile and max of the finite values (NaNs are skipped).
ErrorStats summarize(std::vector<double> values);

/// Exact unsigned distance from points to a triangle mesh, through a bounding volume
/// hierarchy built once. Queries are thread-safe.
class PointToMeshDistance {
 public:
  explicit PointToMeshDistance(const TriangleMesh& mesh);
  ~PointToMeshDistance();
  /// Distance (metres) from p to the closest point of the mesh; closest point and
  /// triangle index are returned when asked.
  double distance(const Eigen::Vector3f& p, Eigen::Vector3f* closest = nullptr,
                  int* triangle = nullptr) const;
  /// Distances of all points (NaN for non-finite points), computed in parallel.
  std::vector<double> distances(const Positions& points) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Statistics of the distances from the (finite) points to the mesh.
ErrorStats pointToMeshError(const Positions& points, const PointToMeshDistance& mesh);

/// Symmetric nearest-neighbour RMSE (D1 point-to-point): the larger of the two one-sided RMSEs.
double symmetricNearestNeighbourRmse(const Positions& a, const Positions& b);
/// D1 PSNR in dB: 10 log10(peak^2 / mse_sym), peak defaults to the bounding-box diagonal of b.
double d1Psnr(const Positions& test, const Positions& reference, double peak = 0);

/// Angle in degrees between corresponding normals, orientation-blind when `unoriented`.
std::vector<double> normalAngleErrors(const Normals& estimated, const Normals& truth,
                                      bool unoriented = true);

}  // namespace paps
