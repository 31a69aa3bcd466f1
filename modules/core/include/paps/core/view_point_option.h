#pragma once
// The viewpoint of an output's normals, for a PAPS stage that writes normals (the upsamplers):
// the setViewPoint() of pcl::NormalEstimation. By default the normals are oriented by
// propagation over the scan, which can cross a fold between two scan pieces with the wrong
// sign; a range scan in its sensor's frame is better served by its sensor's position.
#include <Eigen/Core>

#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/positions.h>

namespace paps {

class ViewPointOption {
 public:
  /// Every output normal is flipped to face (vx, vy, vz) (metres, the cloud's frame).
  void setViewPoint(float vx, float vy, float vz) {
    const Eigen::Vector3f v(vx, vy, vz);
    if (!isFinite(v))
      throw InvalidParameter("viewpoint", detail::toString(vx) + " " + detail::toString(vy) + " " + detail::toString(vz),
                             "finite coordinates");
    view_point_ = v;
    use_view_point_ = true;
  }
  /// Back to the default: normals oriented by propagation over the scan.
  void useNoViewPoint() { use_view_point_ = false; }
  bool hasViewPoint() const { return use_view_point_; }
  const Eigen::Vector3f& getViewPoint() const { return view_point_; }

 protected:
  /// Orients `normals` (one per point of `points`) towards the viewpoint, when one is set.
  void orientTowardsViewPoint(const Positions& points, Normals& normals) const {
    if (use_view_point_) orientNormalsTowards(points, normals, view_point_);
  }

 private:
  Eigen::Vector3f view_point_ = Eigen::Vector3f::Zero();
  bool use_view_point_ = false;
};

}  // namespace paps
