#pragma once
// Positions: the one representation of point coordinates inside the non-template core.
// Template stages copy xyz from pcl::PointCloud<PointT> into it, run the compiled core, and
// write positions back, so the heavy code is compiled once, not once per point type.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <pcl/point_cloud.h>
#include <pcl/types.h>

#include <paps/core/error.h>

namespace paps {

using Positions = std::vector<Eigen::Vector3f>;
using Normals = std::vector<Eigen::Vector3f>;

inline bool isFinite(const Eigen::Vector3f& p) {
  return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
}

/// Copies x, y, z of every point (non-finite points keep their NaN/Inf).
template <typename PointT>
Positions positionsOf(const pcl::PointCloud<PointT>& cloud) {
  Positions out(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) out[i] = cloud[i].getVector3fMap();
  return out;
}

/// Number of points with finite coordinates.
inline std::size_t countFinite(const Positions& p) {
  std::size_t n = 0;
  for (const auto& x : p) n += isFinite(x);
  return n;
}

/// Axis-aligned bounding box diagonal of the finite points (0 if none).
inline float boundingBoxDiagonal(const Positions& p) {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  bool any = false;
  for (const auto& x : p)
    if (isFinite(x)) { lo = lo.cwiseMin(x); hi = hi.cwiseMax(x); any = true; }
  return any ? (hi - lo).norm() : 0.f;
}

/// Throws InvalidParameter(`name`) when an explicit radius exceeds the extent of the finite
/// points (their bounding-box diagonal, when not 0): a ball that wide holds the whole cloud,
/// which no local operator wants, and its cost grows with the square of the cloud.
inline void requireRadiusWithinExtent(const std::string& name, float radius, const Positions& p) {
  if (!(radius > 0)) return;  // automatic (0), or refused by the caller's own check
  const float extent = boundingBoxDiagonal(p);
  if (extent > 0 && radius > extent)
    throw InvalidParameter(name, detail::toString(radius),
                           "at most the extent of the cloud (its bounding-box diagonal, " + detail::toString(extent) +
                               "); 0 chooses it from the data");
}

/// Per-axis median of the finite points (0 if none): a centre that a few far points cannot
/// move, unlike the mean or the bounding box.
inline Eigen::Vector3d medianPoint(const Positions& p) {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  std::vector<double> axis;
  axis.reserve(p.size());
  for (int a = 0; a < 3; ++a) {
    axis.clear();
    for (const auto& x : p)
      if (isFinite(x)) axis.push_back(double(x[a]));
    if (axis.empty()) return m;
    std::nth_element(axis.begin(), axis.begin() + std::ptrdiff_t(axis.size() / 2), axis.end());
    m[a] = axis[axis.size() / 2];
  }
  return m;
}

/// Writes positions into the xyz of a cloud, resizing it (other fields of new points are
/// default-constructed). Keeps is_dense honest.
template <typename PointT>
void writePositions(const Positions& p, pcl::PointCloud<PointT>& cloud) {
  cloud.resize(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) cloud[i].getVector3fMap() = p[i];
  cloud.width = static_cast<std::uint32_t>(p.size());
  cloud.height = 1;
  cloud.is_dense = countFinite(p) == p.size();
}

namespace detail {
// Whether PointT has normal_x/y/z (pcl::traits::has_normal_v without including every point type).
template <typename PointT, typename = void>
struct HasNormal : std::false_type {};
template <typename PointT>
struct HasNormal<PointT, std::void_t<decltype(std::declval<PointT&>().getNormalVector3fMap())>> : std::true_type {};
// Whether PointT has PCL's `curvature` field (PointNormal, PointXYZRGBNormal, ...).
template <typename PointT, typename = void>
struct HasCurvature : std::false_type {};
template <typename PointT>
struct HasCurvature<PointT, std::void_t<decltype(std::declval<PointT&>().curvature)>> : std::true_type {};
}  // namespace detail

/// writePositions, and for a point type with normals the normals too (one per position; a
/// NaN normal makes the cloud not dense). The curvature field is left as it is
/// (writeCurvatures fills it).
template <typename PointT>
void writePositionsAndNormals(const Positions& p, const Normals& n, pcl::PointCloud<PointT>& cloud) {
  writePositions(p, cloud);
  if constexpr (detail::HasNormal<PointT>::value) {
    if (n.size() != p.size()) throw InvalidParameter("normals", detail::toString(n.size()), "one per position");
    for (std::size_t i = 0; i < p.size(); ++i) {
      cloud[i].getNormalVector3fMap() = n[i];
      cloud.is_dense = cloud.is_dense && isFinite(n[i]);
    }
  }
}

/// For a point type with PCL's `curvature` field: one value per point (a stage's surface
/// variations, as PCL fills the field).
template <typename PointT>
void writeCurvatures(const std::vector<float>& c, pcl::PointCloud<PointT>& cloud) {
  if constexpr (detail::HasCurvature<PointT>::value) {
    if (c.size() != cloud.size()) throw InvalidParameter("curvatures", detail::toString(c.size()), "one per point");
    for (std::size_t i = 0; i < c.size(); ++i) cloud[i].curvature = c[i];
  }
}

/// The checks every point-moving stage makes on its input: throws InvalidInput when the cloud
/// is empty or has no finite point, InvalidParameter when `movable` (one flag per point, or
/// empty for all) has the wrong size. Returns the number of finite points.
inline std::size_t checkMovableInput(const Positions& points, const std::vector<std::uint8_t>& movable) {
  if (points.empty()) throw InvalidInput("the input cloud is empty");
  if (!movable.empty() && movable.size() != points.size())
    throw InvalidParameter("movable", detail::toString(movable.size()), "one flag per point");
  const std::size_t finite = countFinite(points);
  if (finite == 0) throw InvalidInput("no finite point in the cloud (all NaN or Inf)");
  return finite;
}

/// The number of finite points when they all stand at one position, else 0 (also 0 for none).
inline std::size_t finiteCountAtOnePosition(const Positions& points) {
  const Eigen::Vector3f* first = nullptr;
  std::size_t finite = 0;
  for (const auto& p : points) {
    if (!isFinite(p)) continue;
    if (first && p != *first) return 0;
    if (!first) first = &p;
    ++finite;
  }
  return finite;
}

/// A cloud whose finite points all stand at one position has no scale and no surface: a
/// point-moving filter leaves it as it is, every finite point counted as isolated (as one
/// point alone is), rather than failing on the radius it cannot choose. Returns true in that
/// case, with `report` (moved, isolated, non_finite; may be null) filled. Call after
/// checkMovableInput.
template <typename Report>
bool leaveOnePositionAsItIs(const Positions& points, Report* report) {
  const std::size_t finite = finiteCountAtOnePosition(points);
  if (finite < 2) return false;  // none, one point, or several positions: the stages' own paths
  if (report) {
    *report = Report();
    report->isolated = finite;
    report->non_finite = points.size() - finite;
  }
  return true;
}

/// Throws InvalidInput when a PCL-style stage runs before setInputCloud: pcl::Filter::filter
/// only prints a message then (leaving the output as it was), and
/// pcl::CloudSurfaceProcessing::process reads the missing cloud.
template <typename CloudConstPtr>
void requireInputCloud(const CloudConstPtr& input) {
  if (!input) throw InvalidInput("no input cloud: call setInputCloud first");
}

/// Throws InvalidParameter unless every index is a point of a cloud of `size` points (PCL's
/// own classes read past the cloud on a bad index; ours say which one is wrong).
inline void checkIndices(const pcl::Indices& indices, std::size_t size) {
  for (const auto i : indices)
    if (i < 0 || static_cast<std::size_t>(i) >= size)
      throw InvalidParameter("indices", detail::toString(i), "indices in [0, " + detail::toString(size) + ")");
}

/// Positions of the points of `input` at `indices` (checked).
template <typename PointT>
Positions positionsAt(const pcl::PointCloud<PointT>& input, const pcl::Indices& indices) {
  checkIndices(indices, input.size());
  Positions out;
  out.reserve(indices.size());
  for (const auto i : indices) out.push_back(input[static_cast<std::size_t>(i)].getVector3fMap());
  return out;
}

/// How many of a cloud's `size` points `indices` leaves out (each counted once, repeats in
/// `indices` too): the points positionsWithin turns into NaN, which a stage's count of
/// non-finite inputs must not include.
inline std::size_t pointsOutside(const pcl::Indices& indices, std::size_t size) {
  std::vector<std::uint8_t> in(size, 0);
  for (const auto i : indices) in[static_cast<std::size_t>(i)] = 1;
  return static_cast<std::size_t>(std::count(in.begin(), in.end(), std::uint8_t(0)));
}

/// Positions of every point of `input`, those not at `indices` (checked) set to NaN: a stage
/// that keeps the cloud's size and order and skips the points outside its indices.
template <typename PointT>
Positions positionsWithin(const pcl::PointCloud<PointT>& input, const pcl::Indices& indices) {
  checkIndices(indices, input.size());
  if (indices.empty() && !input.empty()) throw InvalidInput("no point to process: the indices are empty");
  Positions out(input.size(), Eigen::Vector3f::Constant(NAN));
  for (const auto i : indices) out[static_cast<std::size_t>(i)] = input[static_cast<std::size_t>(i)].getVector3fMap();
  return out;
}

/// The shape every point-moving pcl::Filter shares: copy the input (all fields, organisation),
/// let `move(positions, movable)` return new positions for the points in `indices`, write
/// them back and keep is_dense honest. Input empty -> InvalidInput (thrown by the caller's
/// check in move, or here).
template <typename PointT, typename MoveFn>
void applyPositionFilter(const pcl::PointCloud<PointT>& input, const pcl::Indices& indices,
                         pcl::PointCloud<PointT>& output, MoveFn move) {
  checkIndices(indices, input.size());
  std::vector<std::uint8_t> movable(input.size(), 0);
  for (const auto i : indices) movable[static_cast<std::size_t>(i)] = 1;
  const Positions out = move(positionsOf(input), movable);
  output = input;
  bool dense = true;
  for (std::size_t i = 0; i < out.size(); ++i) {
    output[i].getVector3fMap() = out[i];
    dense = dense && isFinite(out[i]);
  }
  output.is_dense = dense;
}

}  // namespace paps
