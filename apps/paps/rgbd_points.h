#pragma once
// The finite points of an organized RGB-D frame with their colours and normals: what
// `paps rgbd-photo` writes and what `paps bench fusion` registers against, made in one place so
// the bench measures the command's cloud.
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <paps/core/positions.h>

namespace paps::cli {

struct RgbdPoints {
  Positions points;                 ///< the frame's finite points, in grid order
  std::vector<std::uint32_t> rgb;   ///< 0xRRGGBB of each
  Normals normals;                  ///< of the `neighbours` nearest, turned towards the camera
  std::vector<float> variation;     ///< surface variation of each fit (PCL's 'curvature')
};

/// `eye`: the camera centre (the fitted pose's translation).
RgbdPoints rgbdPoints(const pcl::PointCloud<pcl::PointXYZRGBA>& frame, int neighbours, const Eigen::Vector3f& eye);

}  // namespace paps::cli
