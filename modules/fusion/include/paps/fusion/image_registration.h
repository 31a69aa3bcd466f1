#pragma once
// Image to point-cloud registration, coarse then fine (manuscript 4.4). Given a photo, its
// camera intrinsics and an approximate pose (GPS), find the pose at which a synthetic image of
// the cloud (synthetic_image.h) best matches the photo under NMI, DHOG or MIDHOG.
//  - Coarse (4.4.1): one wide-angle synthetic image is rendered; small yaw and pitch act as
//    translations of the photo's frame inside it and roll as a rotation about its centre, so
//    the 3 rotations are searched without re-rendering. Multiscale (coarsest first); a new wide
//    image is rendered when the rotation found is large. Optimiser: BOBYQA (NLopt), stopped
//    when the pose moves less than `tolerance_pixels`.
//  - Fine (4.4.2): the 6 degrees of freedom, with a synthetic image rendered at every step,
//    in a narrow band around the coarse pose; at half then full scale, and BOBYQA restarted
//    from its best point while the cost drops (rendering makes the cost slightly noisy, and a
//    trust region then shrinks early; measured: mean error 2.3 -> 2.1 px on reflectance).
#include <vector>

#include <opencv2/core.hpp>
#include <pcl/pcl_base.h>
#include <pcl/point_types.h>

#include <paps/core/positions.h>
#include <paps/core/progress.h>
#include <paps/core/thread_count.h>
#include <paps/fusion/camera_model.h>
#include <paps/fusion/image_similarity.h>
#include <paps/fusion/synthetic_image.h>

namespace paps {

struct ImageRegistrationParameters {
  ImageMetricParameters coarse_metric;  ///< default MIDHOG, alpha 10
  ImageMetricParameters fine_metric;    ///< default MIDHOG (DHOG is faster, 4.4.2)
  SyntheticImageParameters rendering;
  int coarse_levels = 3;                ///< pyramid levels of the coarse step (1/4, 1/2, 1); 0: no coarse step
  double coarse_margin = 0.2;           ///< wide image margin on each side, fraction of the width
  double coarse_max_rotation_deg = 8;   ///< yaw/pitch/roll searched around each wide image
  int coarse_max_wide_images = 3;       ///< wide images rendered per level at most
  double tolerance_pixels = 0.5;        ///< BOBYQA stops when the pose moves less (at each level's scale)
  bool fine = true;                     ///< run the fine 6-DoF step
  double fine_scale = 1.0;              ///< image scale of the fine step's last level, (0, 1]
  int fine_levels = 2;                  ///< fine step at scales fine_scale / 2^k, coarsest first (1 to 4)
  int restarts = 3;                     ///< BOBYQA restarts from its best point while the cost drops
  double fine_max_rotation_deg = 1.5;   ///< band searched by the fine step, each angle
  double fine_max_translation = 0.5;    ///< band searched by the fine step, metres each axis
  int max_evaluations = 300;            ///< per BOBYQA run
  void validate() const;
};

struct ImageRegistrationReport {
  CameraPose initial_pose, coarse_pose, final_pose;
  double initial_cost = 0, coarse_cost = 0, final_cost = 0;  ///< fine metric at full scale
  int evaluations = 0;                  ///< synthetic-image comparisons, both steps
  int renderings = 0;                   ///< synthetic images rendered, both steps
  double coarse_seconds = 0, fine_seconds = 0;
};

/// The compiled core: registers `photo` (8-bit BGR or grey) to `points` whose grey values are
/// `values` (shading or reflectance, one per point). Returns the refined camera-to-world pose.
/// Throws InvalidInput for an empty photo, a photo not of the camera's size, too few points
/// in view, or values not one per point; Cancelled when `progress` says so.
CameraPose registerImageToPoints(const Positions& points, const std::vector<float>& values, const cv::Mat& photo,
                                 const CameraIntrinsics& camera, const CameraPose& initial_pose,
                                 const ImageRegistrationParameters& parameters = {},
                                 ImageRegistrationReport* report = nullptr, const ProgressCallback& progress = {});

/// PCL-style front end: the cloud is the input; grey values come from setPointValues() (for
/// instance the laser reflectance) or, by default, from the normals (shading).
template <typename PointT>
class ImageToCloudRegistration : public pcl::PCLBase<PointT>, public ThreadCountOption {
 public:
  using pcl::PCLBase<PointT>::input_;

  void setPhoto(const cv::Mat& photo, const CameraIntrinsics& camera) {
    photo_ = photo;
    camera_ = camera;
  }
  void setInitialPose(const CameraPose& pose) { initial_pose_ = pose; }
  /// One grey value per input point (e.g. reflectance in [0, 1]); empty: shading from normals.
  void setPointValues(const std::vector<float>& values) { values_ = values; }
  void setParameters(const ImageRegistrationParameters& p) { parameters_ = p; }
  const ImageRegistrationParameters& getParameters() const { return parameters_; }
  void setProgressCallback(const ProgressCallback& cb) { progress_ = cb; }
  /// Runs coarse then fine; returns the pose (also in getReport()).
  CameraPose align();
  const ImageRegistrationReport& getReport() const { return report_; }

 private:
  cv::Mat photo_;
  CameraIntrinsics camera_;
  CameraPose initial_pose_ = CameraPose::Identity();
  std::vector<float> values_;
  ImageRegistrationParameters parameters_;
  ProgressCallback progress_;
  ImageRegistrationReport report_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/fusion/impl/image_registration.hpp>
#endif
