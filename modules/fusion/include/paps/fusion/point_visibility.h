#pragma once
// Which points of a cloud a camera sees (manuscript 4.2, Fig. 4.1b). A LiDAR cloud is not a
// surface: where the foreground is sparse, background points project between its samples.
// Following the idea of Pintus et al. 2011 (a cone of visibility per pixel), a point is hidden
// when nearer points surround it on the image: in at least `min_sectors` of 8 angular sectors around its
// pixel, within `window_radius` pixels, some point is nearer than depth * (1 - depth_tolerance).
// A point with a nearer one in its own pixel is hidden too.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include <paps/core/positions.h>
#include <paps/fusion/camera_model.h>

namespace paps {

struct VisibilityParameters {
  int window_radius = 6;          ///< pixels; twice the largest gap between foreground samples
  double depth_tolerance = 0.05;  ///< relative depth difference that counts as "in front"
  int min_sectors = 7;            ///< sectors (of 8) that must hold a nearer point to hide one
  void validate() const;
};

/// Every point's projection into one camera.
struct ProjectedPoints {
  std::vector<Eigen::Vector2f> pixel;   ///< distorted pixel (x, y); NaN when not projected
  std::vector<float> depth;             ///< z in the camera frame, metres; NaN when not projected
  std::vector<std::uint8_t> visible;    ///< 1: inside the image, in front of the camera, not hidden
  std::size_t visibleCount() const;
};

/// Projects `points` (world, non-finite skipped) through `camera` at `pose` and decides their
/// visibility. Deterministic; parallel over pixels.
ProjectedPoints projectVisiblePoints(const Positions& points, const CameraIntrinsics& camera,
                                     const CameraPose& pose, const VisibilityParameters& parameters = {});

}  // namespace paps
