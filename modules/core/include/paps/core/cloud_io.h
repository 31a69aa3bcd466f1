#pragma once
// Reading and writing clouds with every field kept: a stage reads x, y, z out of the blob,
// and writes the moved positions back into it, so intensity, colour, normals... survive.
// Writes are atomic: a temporary file beside the target, then a rename.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <pcl/PCLPointCloud2.h>

#include <paps/core/positions.h>

namespace paps {

/// Loads a .pcd or .ply file. Throws IoError naming the path when it is missing, unreadable,
/// of another format, or has no x/y/z fields.
/// `origin`, when given, receives the sensor origin stored in a .pcd (VIEWPOINT; zero
/// otherwise, and when it is not finite).
pcl::PCLPointCloud2 loadCloud(const std::string& path, Eigen::Vector3f* origin = nullptr);

/// Writes a .pcd (binary) or .ply (binary) file atomically. Throws IoError on failure; the
/// target is then untouched and no temporary file is left. A .pcd's VIEWPOINT gets
/// `sensor_origin` (a stage that keeps the input's frame passes the input's on).
void saveCloudAtomic(const std::string& path, const pcl::PCLPointCloud2& cloud,
                     const Eigen::Vector3f& sensor_origin = Eigen::Vector3f::Zero());

/// A cloud handed to the writer a block of points at a time, so that a large output is never
/// held whole beside what it is made from. `layout` has the fields, point_step, width,
/// height and is_dense of the cloud, and no data; `fill(first, count, rows)` writes the
/// points first .. first + count - 1, point_step bytes each, into `rows`.
struct CloudRows {
  pcl::PCLPointCloud2 layout;
  std::function<void(std::size_t first, std::size_t count, std::uint8_t* rows)> fill;
};

/// saveCloudAtomic for a cloud given by blocks of rows. A .pcd without padding fields is
/// written a block at a time (the bytes PCL's binary writer gives for the whole blob); a .ply,
/// or a layout with padding, is gathered whole first (PCL's writers need the blob).
void saveCloudAtomic(const std::string& path, const CloudRows& rows,
                     const Eigen::Vector3f& sensor_origin = Eigen::Vector3f::Zero());

/// The whole blob of `rows` (fill called once for all points).
pcl::PCLPointCloud2 gatherRows(const CloudRows& rows);

/// What saveCloudAtomic checks of `path` before writing: checkOutputPath, and a .pcd or .ply
/// name. Throws IoError naming the problem; for a command to call before any work.
void checkCloudOutputPath(const std::string& path);

/// x, y, z of every point of a blob (float32 or float64 fields).
Positions positionsOf(const pcl::PCLPointCloud2& cloud);
/// Writes positions back into the x, y, z fields of a blob of the same size; is_dense follows.
void writePositions(const Positions& p, pcl::PCLPointCloud2& cloud);

/// `cloud` with the fields of `extra` (a blob of the same number of points) added, in its
/// width x height: a field of `cloud` that `extra` also has is replaced, padding fields are
/// dropped. How a stage that computes new per-point values (normals, curvatures) keeps the
/// input's own fields (intensity, colour...) and organisation.
pcl::PCLPointCloud2 appendFields(const pcl::PCLPointCloud2& cloud, const pcl::PCLPointCloud2& extra);

/// appendFields without the extra blob and without the result: the rows of `cloud` (held by
/// reference; it must outlive the result) with the fields `extra_fields` added in the same
/// layout, the values of point i written by `fill_extra(i, row)` into a row of `extra_step`
/// bytes laid out as `extra_fields` say (a PCL point struct copied in whole, say). With
/// saveCloudAtomic, a stage adds its per-point outputs to a large scan holding neither the
/// outputs as a blob nor the combined cloud.
CloudRows appendedRows(const pcl::PCLPointCloud2& cloud, const std::vector<pcl::PCLPointField>& extra_fields,
                       std::uint32_t extra_step, std::function<void(std::size_t, std::uint8_t*)> fill_extra);

/// The points `rows` of a blob (indices into its width x height points, any order, repeats
/// allowed), every field as it is, as one row of rows.size() points: how a stage that makes
/// new points from input points carries their other fields (colour, intensity) along.
/// Throws InvalidParameter for an index outside the blob.
pcl::PCLPointCloud2 gatherPoints(const pcl::PCLPointCloud2& cloud, const std::vector<int>& rows);

/// Loads a cloud straight into positions (any file loadCloud accepts).
Positions loadPositions(const std::string& path);

}  // namespace paps
