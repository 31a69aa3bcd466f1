#pragma once
// A synthetic urban street with ground truth for the chapter 4 stages (manuscript 4.0: mobile
// LiDAR with photos at known approximate poses). Real street scans with registered photos are
// not available as Debian packages, so tests and benches build this scene: facades of several
// materials with windows and brick texture, cornices and window sills (geometry a shading
// image shows), pavements, a road with lane markings, parked cars,
// lamp posts, and a sun that casts shadows. It gives
//  - a mobile LiDAR pass (points, true normals, a laser reflectance per material, the true
//    albedo and the true shadow label of every point; rooftops unseen, as on real scans);
//  - photos from any camera: the albedo lit by the paper's outdoor model (eq. 4.5, below),
//    with lens distortion, exposure, sensor noise and, optionally, a passing van that the scan
//    does not contain (the occluder of manuscript Fig. 4.7 and 4.10);
//  - the true shadow mask of each photo.
// Lighting (eq. 4.5 with the simplifications of 4.5.3): colour = exposure * albedo *
// (sun_sky_ratio * max(0, <n, sun>) * lit + beta(n)), beta(n) = 0.5 * (<n, up> + 1).
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <paps/fusion/camera_model.h>

namespace paps {
namespace synthetic {

struct StreetOptions {
  double length = 60;                 ///< street length along x, metres (centred on x = 0)
  double scan_step = 0.12;            ///< LiDAR: metres between scan lines along the street
  double scan_angle_step_deg = 0.5;   ///< LiDAR: degrees between returns along a line
  double range_noise = 0.01;          ///< LiDAR: Gaussian range noise, metres
  double reflectance_noise = 0.02;    ///< LiDAR: Gaussian noise on the reflectance (in [0, 1])
  Eigen::Vector3d sun = Eigen::Vector3d(0.5, -0.35, 0.8);  ///< towards the sun (normalised)
  double sun_sky_ratio = 2.0;         ///< sun light over sky light on a surface facing the sun
  std::uint64_t seed = 1;             ///< building sizes, materials, cars
};

/// One LiDAR return of the pass.
struct StreetScan {
  pcl::PointCloud<pcl::PointXYZRGBNormal> cloud;  ///< true normals; rgb left black (no colour yet)
  std::vector<float> reflectance;                 ///< laser reflectance in [0, 1], per point
  std::vector<Eigen::Vector3f> albedo;            ///< true albedo (r, g, b in [0, 1]), per point
  std::vector<std::uint8_t> in_shadow;            ///< 1 where the sun does not reach (cast or attached)
};

struct PhotoOptions {
  double exposure = 0.75;        ///< global gain of the photo
  double noise_sigma = 2.0;      ///< Gaussian sensor noise, grey levels of 255
  bool passing_van = false;      ///< a van on the road that the scan does not contain
  double van_x = 0;              ///< its position along the street, metres
  std::uint64_t seed = 7;        ///< noise
};

struct StreetPhoto {
  cv::Mat image;   ///< CV_8UC3, BGR
  cv::Mat shadow;  ///< CV_8U: 255 where the surface seen is in shadow, 0 lit or sky
  cv::Mat depth;   ///< CV_32F: distance along the ray, metres; 0 for sky
};

class StreetScene {
 public:
  explicit StreetScene(const StreetOptions& options = {});

  /// The mobile LiDAR pass: a 2D scanner turning in the plane across the street, on a vehicle
  /// driving along y = -1.5 at 2.5 m height.
  StreetScan scan() const;
  /// The photo a camera with these intrinsics (distortion included) takes from `pose`.
  StreetPhoto photo(const CameraIntrinsics& camera, const CameraPose& pose,
                    const PhotoOptions& options = {}) const;
  /// `count` poses of a camera on the vehicle (y = -1.5, z = 2.6), evenly spaced in x over
  /// [x_from, x_to], looking across the street to the facades of y > 0 (`side` = +1) or y < 0
  /// (-1), turned `yaw_deg` towards +x and tilted `pitch_deg` up.
  std::vector<CameraPose> cameraPoses(int count, double x_from, double x_to, int side = 1,
                                      double yaw_deg = 0, double pitch_deg = 8) const;

  /// Nearest surface along a ray (direction need not be unit): distance along the unit
  /// direction, normal and the index of the box hit (-1: ground); false when nothing is hit
  /// within max_distance. The van counts only when `with_van` is set.
  bool castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_distance,
               double& distance, Eigen::Vector3d& normal, int& box, bool with_van = false,
               double van_x = 0) const;
  /// True albedo and laser reflectance of a surface point (box index from castRay).
  Eigen::Vector3f albedo(const Eigen::Vector3d& point, const Eigen::Vector3d& normal, int box) const;
  float reflectance(const Eigen::Vector3d& point, const Eigen::Vector3d& normal, int box) const;
  /// True when the sun reaches the point (not behind the surface, not cast over).
  bool sunlit(const Eigen::Vector3d& point, const Eigen::Vector3d& normal) const;
  /// The lighting factor of a surface point: sun_sky_ratio * max(0, <n, sun>) * lit + beta(n).
  double irradiance(const Eigen::Vector3d& point, const Eigen::Vector3d& normal) const;

  const StreetOptions& options() const { return options_; }
  Eigen::Vector3d sunDirection() const { return sun_; }

 private:
  struct Box {
    Eigen::Vector3d lo, hi;
    int material;  // index into materials_
    bool facade;   // windows and bricks on its vertical faces
  };
  struct Material {
    Eigen::Vector3f albedo;
    float reflectance;
  };
  struct Group {  // a building and its details, or a single box: culled by its bounds first
    Box bounds;
    int first, count;
  };
  void addGroup(int first);
  /// Metres along a facade's vertical face from the box's corner.
  static double alongFacade(const Box& b, const Eigen::Vector3d& p, const Eigen::Vector3d& n);
  bool hitBox(const Box& b, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double max_t,
              double& t, Eigen::Vector3d& n) const;
  StreetOptions options_;
  Eigen::Vector3d sun_;
  std::vector<Box> boxes_;
  std::vector<Group> groups_;
  std::vector<Material> materials_;
};

}  // namespace synthetic
}  // namespace paps
