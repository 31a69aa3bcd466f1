#pragma once
// Synthetic images of a point cloud (manuscript 4.2, Fig. 4.1): what a camera at a given pose
// would see of the cloud, one grey value per pixel, to be compared with the real photo.
//  1. projection through the calibrated camera (distortion included);
//  2. occlusion: only the points projectVisiblePoints() keeps (the cone-of-visibility test);
//  3. interpolation: an empty pixel takes the inverse-distance mean of the front-most drawn
//     pixels within `fill_radius` only when drawn pixels surround it in all four quadrants, so
//     the gaps between samples close but silhouettes do not widen (unlike splatting).
// Grey values come per point: shading (|<n, light>|, needs normals) or the laser reflectance.
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <pcl/point_cloud.h>

#include <paps/core/positions.h>
#include <paps/fusion/camera_model.h>
#include <paps/fusion/point_visibility.h>

namespace paps {

struct SyntheticImageParameters {
  VisibilityParameters visibility;
  int fill_radius = 5;             ///< pixels searched to fill an empty pixel; 0: no filling
  double fill_depth_tolerance = 0.05;  ///< relative depth beyond the front-most that is not mixed in
  void validate() const;
};

/// A rendered synthetic image.
struct SyntheticImage {
  cv::Mat intensity;  ///< CV_32F, grey value of each pixel (0 where undefined)
  cv::Mat mask;       ///< CV_8U, 255 where the value is defined (a point or the filling)
  cv::Mat depth;      ///< CV_32F, camera z of the pixel's front points, metres (0 where undefined)
  std::size_t visible_points = 0;
};

/// Renders `values` (one per point) of `points` as seen by `camera` at `pose`.
SyntheticImage renderSyntheticImage(const Positions& points, const std::vector<float>& values,
                                    const CameraIntrinsics& camera, const CameraPose& pose,
                                    const SyntheticImageParameters& parameters = {});

/// Grey value per point from its normal: |<n, light>| (normals of scans are rarely oriented).
/// `light` is a world direction; points with a non-finite normal get 0.
template <typename PointT>
std::vector<float> shadingValues(const pcl::PointCloud<PointT>& cloud,
                                 const Eigen::Vector3f& light = Eigen::Vector3f(0.5f, -0.3f, 0.8f).normalized()) {
  std::vector<float> v(cloud.size(), 0.f);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f n = cloud[i].getNormalVector3fMap();
    if (n.allFinite()) v[i] = std::abs(n.dot(light)) / std::max(n.norm(), 1e-12f);
  }
  return v;
}

}  // namespace paps
