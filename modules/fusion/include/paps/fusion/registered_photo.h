#pragma once
// A photo registered to a point cloud (manuscript 4.5): the image and the calibrated camera
// that took it. Colorization and shadow detection take a list of them.
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <paps/fusion/camera_model.h>

namespace paps {

struct RegisteredPhoto {
  cv::Mat image;              ///< CV_8UC3, BGR, camera.width x camera.height; 8-bit values read as linear
  CameraIntrinsics camera;    ///< intrinsics (OpenCV conventions)
  CameraPose pose;            ///< camera-to-world
  /// Throws InvalidInput for an empty image or one that is not CV_8UC3, InvalidParameter for a
  /// bad camera or an image whose size is not the camera's. `what` names the photo in the message.
  void validate(const char* what = "photo") const;
};

/// Bilinear sample of a CV_8UC3 BGR image at a (sub)pixel position (pixel (0, 0) is the centre
/// of the top-left pixel; positions outside are clamped to the border): linear RGB in [0, 1].
Eigen::Vector3f sampleBilinear(const cv::Mat& bgr8, const Eigen::Vector2f& pixel);

}  // namespace paps
