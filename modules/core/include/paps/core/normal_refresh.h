#pragma once
// Normals of a filtered cloud. A filter that moves points (denoising, bilateral, LPF) changes
// the surface the points describe; the normals a PointNormal cloud carried describe the old
// one (noise included). PCL's MovingLeastSquares recomputes them (setComputeNormals); our
// point-moving filters do too, by default, for every point type with normal_x/y/z.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include <paps/core/positions.h>
#include <paps/core/view_point_option.h>

namespace paps {

/// Normals of moved points, and what the refresh met.
struct NormalRefresh {
  Normals normals;                ///< one per point: the new normal where moved, else the previous
  std::vector<float> variation;   ///< surface variation (PCL's `curvature`) where refreshed, else NaN
  std::size_t refreshed = 0;      ///< moved points that got a new normal
  /// Moved finite points with no new estimate (fewer than 3 neighbours, or only collinear or
  /// coincident ones) that kept their usable previous normal (and curvature).
  std::size_t kept_previous = 0;
  std::size_t without_normal = 0; ///< the same without a usable previous normal: NaN, as PCL's
};

/// At most this many nearest neighbours within the radius enter a refreshed normal: enough for
/// a PCA normal, and the denoiser's noise-grown radius (up to ~190 neighbours) would otherwise
/// make the graph of a 1M-point cloud weigh 0.8 GB.
constexpr int kRefreshNormalNeighbours = 64;

/// Normals of `points` (a filter's output) for the points with moved[i] set (all when empty):
/// PCA over the finite points within `radius` (at most kRefreshNormalNeighbours nearest),
/// each turned to the side of the sum of the previous normals in that ball that are usable
/// (finite, length over 0.5: PCL's default-constructed 0 0 0 is not), otherwise, where the
/// ball holds none, towards `viewpoint` when given, otherwise by propagation over the
/// neighbour graph (orientNormalsByPropagation). A moved point with no new estimate keeps its previous normal when that is usable, else gets
/// NaN. Radius 0 means no neighbourhood (no new estimate anywhere). The result does not depend
/// on the order of the points nor on the thread count. Throws InvalidParameter for a negative
/// or non-finite radius, or sizes that differ from `points`.
NormalRefresh refreshNormals(const Positions& points, float radius, const Normals& previous,
                             const std::vector<std::uint8_t>& moved,
                             const std::optional<Eigen::Vector3f>& viewpoint = std::nullopt);

/// Turns each of `normals` (one per point of `points`) to the side of the usable normals
/// `hint_normals` (finite, length over 0.5; one per point of `hint_points`) of its 16 nearest
/// hint points, summed: how new points (an upsampler's) take the side of the input's normals.
/// A normal with no usable hint among them is left as it is. Returns how many were turned.
/// Throws InvalidParameter when the sizes differ.
std::size_t orientNormalsByNearbyHints(const Positions& points, Normals& normals, const Positions& hint_points,
                                       const Normals& hint_normals);

/// Whether any of `normals` is usable as an orientation (finite, length over 0.5).
bool anyUsableNormal(const Normals& normals);

/// The output normals of an upsampler (QSR, APSS, RIMLS), in this order: towards the explicit
/// viewpoint when one is set; else, for an input type with normals that holds usable ones, to
/// their side nearby (orientNormalsByNearbyHints); else towards the input's sensor origin when
/// it has one; else as the stage propagated them.
template <typename PointIn>
void orientUpsampledNormals(const ViewPointOption& option, const pcl::PointCloud<PointIn>& input,
                            const pcl::Indices& indices, const Positions& out, Normals& normals) {
  if (option.hasViewPoint()) {
    orientNormalsTowards(out, normals, option.getViewPoint());
    return;
  }
  if constexpr (detail::HasNormal<PointIn>::value) {
    Positions at;
    Normals given;
    for (const auto i : indices) {
      at.push_back(input[static_cast<std::size_t>(i)].getVector3fMap());
      given.push_back(input[static_cast<std::size_t>(i)].getNormalVector3fMap());
    }
    if (anyUsableNormal(given)) {
      orientNormalsByNearbyHints(out, normals, at, given);
      return;
    }
  }
  if (const auto o = knownSensorOrigin(input.sensor_origin_.template head<3>())) orientNormalsTowards(out, normals, *o);
}

/// The setRefreshNormals() of a point-moving PAPS filter (on by default). Point types
/// without normals are not affected.
class NormalRefreshOption {
 public:
  /// true (default): the normals (and PCL's `curvature`, the surface variation) of the moved
  /// points are estimated again on the output; false: they keep the input's values.
  void setRefreshNormals(bool on) { refresh_normals_ = on; }
  bool getRefreshNormals() const { return refresh_normals_; }
  /// Of the last run: moved points that got a new normal, and moved finite points that got
  /// NaN (no new estimate and no input normal, as pcl::NormalEstimation).
  std::size_t getRefreshedNormals() const { return refreshed_normals_; }
  /// Moved points with no new estimate that kept their input normal (NormalRefresh::kept_previous).
  std::size_t getKeptNormals() const { return kept_normals_; }
  std::size_t getPointsWithoutNormal() const { return points_without_normal_; }

 protected:
  /// Runs refreshCloudNormals with this option's setting and keeps its counts.
  template <typename PointT>
  void refreshOutputNormals(const pcl::PointCloud<PointT>& input, const pcl::Indices& indices,
                            pcl::PointCloud<PointT>& output, float radius);

  bool refresh_normals_ = true;
  std::size_t refreshed_normals_ = 0, kept_normals_ = 0, points_without_normal_ = 0;
};

/// For a point type with normals, when `on`: refreshNormals on `output` (the filtered copy of
/// `input`) for the points at `indices`, the previous normals read from `input`, and the new
/// ones written with their curvature; is_dense turns false when a moved point gets a NaN
/// normal. Returns the refresh's report (empty for other point types or when off).
template <typename PointT>
NormalRefresh refreshCloudNormals(const pcl::PointCloud<PointT>& input, const pcl::Indices& indices,
                                  pcl::PointCloud<PointT>& output, float radius, bool on) {
  NormalRefresh r;
  if constexpr (detail::HasNormal<PointT>::value) {
    if (!on || output.size() != input.size()) return r;
    std::vector<std::uint8_t> moved(input.size(), 0);
    for (const auto i : indices) moved[static_cast<std::size_t>(i)] = 1;
    Normals previous(input.size());
    for (std::size_t i = 0; i < input.size(); ++i) previous[i] = input[i].getNormalVector3fMap();
    r = refreshNormals(positionsOf(output), radius, previous, moved,
                       knownSensorOrigin(input.sensor_origin_.template head<3>()));
    for (std::size_t i = 0; i < output.size(); ++i) {
      // Refreshed (a finite variation comes with each new normal) or NaN; else kept as it was.
      const bool refreshed = std::isfinite(r.variation[i]), none = !isFinite(r.normals[i]);
      if (!moved[i] || !(refreshed || none)) continue;
      output[i].getNormalVector3fMap() = r.normals[i];
      if constexpr (detail::HasCurvature<PointT>::value) output[i].curvature = r.variation[i];
      if (none) output.is_dense = false;
    }
  }
  return r;
}

template <typename PointT>
void NormalRefreshOption::refreshOutputNormals(const pcl::PointCloud<PointT>& input, const pcl::Indices& indices,
                                               pcl::PointCloud<PointT>& output, float radius) {
  const NormalRefresh r = refreshCloudNormals(input, indices, output, radius, refresh_normals_);
  refreshed_normals_ = r.refreshed;
  kept_normals_ = r.kept_previous;
  points_without_normal_ = r.without_normal;
}

}  // namespace paps
