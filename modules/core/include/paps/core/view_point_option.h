#pragma once
// The viewpoint of an output's normals, for a PAPS stage that writes normals (the upsamplers):
// the setViewPoint() of pcl::NormalEstimation. Without it the normals take the side of the
// input's own normals when it has some, else face the input's sensor origin when it has one,
// else keep the orientation propagated over the scan (orientUpsampledNormals), which can
// cross a fold between two scan pieces with the wrong sign.
#include <optional>

#include <Eigen/Core>

#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/positions.h>

namespace paps {

/// The sensor origin a cloud carries (pcl::PointCloud::sensor_origin_, a PCD's VIEWPOINT),
/// when it says something: finite and not PCL's default 0 0 0, which a cloud gets whether or
/// not anyone knows where its sensor was.
inline std::optional<Eigen::Vector3f> knownSensorOrigin(const Eigen::Vector3f& sensor_origin) {
  if (!isFinite(sensor_origin) || sensor_origin.squaredNorm() == 0) return std::nullopt;
  return sensor_origin;
}

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
  /// Back to the default: the input normals' side, else the sensor origin, else propagation.
  void useNoViewPoint() { use_view_point_ = false; }
  bool hasViewPoint() const { return use_view_point_; }
  const Eigen::Vector3f& getViewPoint() const { return view_point_; }

 private:
  Eigen::Vector3f view_point_ = Eigen::Vector3f::Zero();
  bool use_view_point_ = false;
};

}  // namespace paps
