#pragma once
// Reading and writing clouds with every field kept: a stage reads x, y, z out of the blob,
// and writes the moved positions back into it, so intensity, colour, normals... survive.
// Writes are atomic: a temporary file beside the target, then a rename.
#include <string>

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

/// The points `rows` of a blob (indices into its width x height points, any order, repeats
/// allowed), every field as it is, as one row of rows.size() points: how a stage that makes
/// new points from input points carries their other fields (colour, intensity) along.
/// Throws InvalidParameter for an index outside the blob.
pcl::PCLPointCloud2 gatherPoints(const pcl::PCLPointCloud2& cloud, const std::vector<int>& rows);

/// Loads a cloud straight into positions (any file loadCloud accepts).
Positions loadPositions(const std::string& path);

}  // namespace paps
