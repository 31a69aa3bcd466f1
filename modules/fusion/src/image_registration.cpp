#include <paps/fusion/image_registration.h>
#include <paps/fusion/impl/image_registration.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <memory>

#include <nlopt.h>
#include <pcl/point_types.h>
#include <opencv2/imgproc.hpp>

namespace paps {

void ImageRegistrationParameters::validate() const {
  coarse_metric.validate();
  fine_metric.validate();
  rendering.validate();
  requireInRange("coarse_levels", coarse_levels, 0, 6);
  requireInRange("coarse_margin", coarse_margin, 0.01, 1.0);
  requireInRange("coarse_max_rotation_deg", coarse_max_rotation_deg, 0.01, 30.0);
  requireInRange("coarse_max_wide_images", coarse_max_wide_images, 1, 20);
  requireInRange("tolerance_pixels", tolerance_pixels, 1e-3, 100.0);
  requireInRange("fine_scale", fine_scale, 0.05, 1.0);
  requireInRange("fine_max_rotation_deg", fine_max_rotation_deg, 0.0, 30.0);
  requireInRange("fine_max_translation", fine_max_translation, 0.0, 100.0);
  requireInRange("max_evaluations", max_evaluations, 10, 100000);
  requireInRange("fine_levels", fine_levels, 1, 4);
  requireInRange("restarts", restarts, 0, 20);
}

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// Minimises f over a box with NLopt's BOBYQA, from x (updated in place). Exceptions thrown by
/// f stop the optimiser and are rethrown here (they must not cross NLopt's C frames).
struct Bobyqa {
  std::function<double(const std::vector<double>&)> f;
  std::exception_ptr error;
  int evaluations = 0;

  static double call(unsigned n, const double* x, double* /*grad*/, void* data) {
    auto* self = static_cast<Bobyqa*>(data);
    try {
      ++self->evaluations;
      return self->f(std::vector<double>(x, x + n));
    } catch (...) {
      self->error = std::current_exception();
      return 1e30;
    }
  }

  double minimise(std::vector<double>& x, const std::vector<double>& bound, double tolerance, int max_evaluations,
                  double initial_step = 0.25) {
    const unsigned n = static_cast<unsigned>(x.size());
    nlopt_opt opt = nlopt_create(NLOPT_LN_BOBYQA, n);
    if (!opt) throw Error("image registration: NLopt could not create a BOBYQA optimiser");
    std::vector<double> lo(n), hi(n), step(n);
    for (unsigned i = 0; i < n; ++i) {
      lo[i] = -bound[i];
      hi[i] = bound[i];
      step[i] = initial_step * bound[i];
    }
    nlopt_set_lower_bounds(opt, lo.data());
    nlopt_set_upper_bounds(opt, hi.data());
    nlopt_set_initial_step(opt, step.data());
    nlopt_set_min_objective(opt, &Bobyqa::call, this);
    nlopt_set_xtol_abs1(opt, tolerance);
    nlopt_set_maxeval(opt, max_evaluations);
    double best = 0;
    // The result code is not an error here: a stop on maxeval still leaves the best point in x.
    nlopt_optimize(opt, x.data(), &best);
    nlopt_destroy(opt);
    if (error) std::rethrow_exception(error);
    return best;
  }
};

/// Photo as grey float at the size of a scaled camera. The size is the camera's, not
/// OpenCV's rounding of size x scale: that rounds halves to even, and a photo whose pyramid
/// level fell on a half pixel (1242 / 4 = 310.5) then differed in size from its rendering.
cv::Mat scaledGrey(const cv::Mat& grey, const CameraIntrinsics& cam) {
  if (grey.cols == cam.width && grey.rows == cam.height) return grey;
  cv::Mat out;
  cv::resize(grey, out, cv::Size(cam.width, cam.height), 0, 0, cv::INTER_AREA);
  return out;
}

struct Registration {
  const Positions& points;
  const std::vector<float>& values;
  const CameraIntrinsics& camera;
  const ImageRegistrationParameters& p;
  cv::Mat grey;  // photo, CV_32F in [0, 1]
  ImageRegistrationReport& report;
  const ProgressCallback& progress;
  int total_budget;

  void checkCancel(float fraction) const {
    if (progress && !progress("image registration", std::min(1.f, fraction))) throw Cancelled();
  }

  SyntheticImage render(const CameraIntrinsics& cam, const CameraPose& pose) {
    ++report.renderings;
    return renderSyntheticImage(points, values, cam, pose, p.rendering);
  }

  // The photo's frame inside the wide image: real pixel p -> c + margin + R(roll)(p - c) + t.
  static void warpFromWide(const SyntheticImage& wide, const CameraIntrinsics& cam, int margin, double tx, double ty,
                           double roll, cv::Mat& intensity, cv::Mat& mask) {
    const double c = std::cos(roll), s = std::sin(roll);
    cv::Mat m = (cv::Mat_<double>(2, 3) << c, -s, 0, s, c, 0);
    m.at<double>(0, 2) = cam.cx + margin + tx - (c * cam.cx - s * cam.cy);
    m.at<double>(1, 2) = cam.cy + margin + ty - (s * cam.cx + c * cam.cy);
    const cv::Size size(cam.width, cam.height);
    cv::warpAffine(wide.intensity, intensity, m, size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_CONSTANT, 0);
    cv::warpAffine(wide.mask, mask, m, size, cv::INTER_NEAREST | cv::WARP_INVERSE_MAP, cv::BORDER_CONSTANT, 0);
  }

  CameraPose coarse(CameraPose pose) {
    const double max_rotation = p.coarse_max_rotation_deg * M_PI / 180;
    for (int level = 0; level < p.coarse_levels; ++level) {
      const double scale = std::ldexp(1.0, level - (p.coarse_levels - 1));
      const CameraIntrinsics cam = camera.scaled(scale);
      const ImageComparator comparator(scaledGrey(grey, cam), p.coarse_metric);
      const int margin = std::max(2, static_cast<int>(std::lround(p.coarse_margin * cam.width)));
      const CameraIntrinsics wide_camera = cam.widened(margin);
      // Roll enters in pixels at the image's half width, so the trust region is isotropic.
      const double roll_unit = 0.5 * cam.width;
      for (int round = 0; round < p.coarse_max_wide_images; ++round) {
        checkCancel(static_cast<float>(report.evaluations) / total_budget);
        const SyntheticImage wide = render(wide_camera, pose);
        cv::Mat intensity, mask;
        Bobyqa opt;
        opt.f = [&](const std::vector<double>& x) {
          warpFromWide(wide, cam, margin, x[0], x[1], x[2] / roll_unit, intensity, mask);
          return comparator.cost(intensity, mask);
        };
        const double shift = std::min(0.8 * margin, cam.fx * std::tan(max_rotation));
        std::vector<double> x{0, 0, 0};
        opt.minimise(x, {shift, shift, max_rotation * roll_unit}, p.tolerance_pixels, p.max_evaluations);
        report.evaluations += opt.evaluations;
        PoseDelta d;
        d.yaw = std::atan(x[0] / cam.fx);
        d.pitch = -std::atan(x[1] / cam.fy);
        d.roll = x[2] / roll_unit;
        pose = applyPoseDelta(pose, d);
        // Small move: the wide image of this pose would barely differ; next level.
        if (std::hypot(x[0], x[1]) + std::abs(x[2]) < 2.0) break;
      }
    }
    return pose;
  }

  CameraPose fine(const CameraPose& start, double& cost_out, double scale) {
    const CameraIntrinsics cam = camera.scaled(scale);
    const ImageComparator comparator(scaledGrey(grey, cam), p.fine_metric);
    // Pixel units for every degree of freedom: angles by the focal length, translations by
    // the image motion they cause at the median depth of the points in view.
    const SyntheticImage first = render(cam, start);
    std::vector<float> depths;
    for (int y = 0; y < first.depth.rows; ++y)
      for (int x = 0; x < first.depth.cols; ++x)
        if (first.mask.at<std::uint8_t>(y, x)) depths.push_back(first.depth.at<float>(y, x));
    if (depths.empty()) throw InvalidInput("image registration: no point of the cloud in view of the camera");
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    const double depth = std::max(1e-3, static_cast<double>(depths[depths.size() / 2]));
    const double f = cam.fx, half_width = 0.5 * cam.width;
    auto poseOf = [&](const std::vector<double>& x) {
      PoseDelta d;
      d.yaw = std::atan(x[0] / f);
      d.pitch = std::atan(x[1] / f);
      d.roll = x[2] / half_width;
      d.translation = Eigen::Vector3d(x[3] * depth / f, x[4] * depth / f, x[5] * depth / half_width);
      return applyPoseDelta(start, d);
    };
    Bobyqa opt;
    opt.f = [&](const std::vector<double>& x) {
      checkCancel(static_cast<float>(report.evaluations + opt.evaluations) / total_budget);
      const SyntheticImage s = render(cam, poseOf(x));
      return comparator.cost(s.intensity, s.mask);
    };
    const double rot = p.fine_max_rotation_deg * M_PI / 180, tr = p.fine_max_translation;
    std::vector<double> bound{f * std::tan(rot), f * std::tan(rot), rot * half_width,
                              tr * f / depth, tr * f / depth, tr * half_width / depth};
    for (double& b : bound) b = std::max(b, 1e-6);
    std::vector<double> x(6, 0.0);
    // BOBYQA stops when its trust region shrinks below the tolerance; on a cost with
    // rendering noise that can be early, so restart from the best point while it improves.
    std::vector<double> best = x;
    cost_out = INFINITY;
    for (int attempt = 0; attempt <= p.restarts; ++attempt) {
      std::vector<double> y = best;
      const double c = opt.minimise(y, bound, p.tolerance_pixels * scale, p.max_evaluations);
      if (!(c < cost_out - 1e-4)) break;
      cost_out = c;
      best = y;
    }
    x = best;
    report.evaluations += opt.evaluations;
    return poseOf(x);
  }

  // The fine metric at full scale (the photo's HOG computed once, on first use).
  std::unique_ptr<ImageComparator> full_scale;
  double costAt(const CameraPose& pose, int* defined_pixels = nullptr) {
    if (!full_scale) full_scale = std::make_unique<ImageComparator>(grey, p.fine_metric);
    const SyntheticImage s = render(camera, pose);
    if (defined_pixels) *defined_pixels = cv::countNonZero(s.mask);
    return full_scale->cost(s.intensity, s.mask);
  }
};

}  // namespace

CameraPose registerImageToPoints(const Positions& points, const std::vector<float>& values, const cv::Mat& photo,
                                 const CameraIntrinsics& camera, const CameraPose& initial_pose,
                                 const ImageRegistrationParameters& parameters, ImageRegistrationReport* report_out,
                                 const ProgressCallback& progress) {
  parameters.validate();
  camera.validate();
  if (photo.empty()) throw InvalidInput("image registration: empty photo");
  if (photo.cols != camera.width || photo.rows != camera.height)
    throw InvalidInput("image registration: photo of " + std::to_string(photo.cols) + "x" + std::to_string(photo.rows) +
                       " for a camera of " + std::to_string(camera.width) + "x" + std::to_string(camera.height));
  if (values.size() != points.size())
    throw InvalidInput("image registration: " + std::to_string(values.size()) + " values for " +
                       std::to_string(points.size()) + " points");
  if (!initial_pose.matrix().allFinite()) throw InvalidInput("image registration: non-finite initial pose");
  if (countFinite(points) < 16) throw InvalidInput("image registration: fewer than 16 finite points");
  ImageRegistrationReport local;
  ImageRegistrationReport& report = report_out ? *report_out : local;
  report = {};
  report.initial_pose = initial_pose;
  cv::Mat grey;
  if (photo.type() == CV_8UC3) {
    cv::cvtColor(photo, grey, cv::COLOR_BGR2GRAY);
    grey.convertTo(grey, CV_32F, 1.0 / 255);
  } else if (photo.type() == CV_8UC1) {
    photo.convertTo(grey, CV_32F, 1.0 / 255);
  } else {
    throw InvalidInput("image registration: photo type " + std::to_string(photo.type()) + " (expected 8-bit BGR or grey)");
  }
  const int budget = parameters.max_evaluations *
                     (parameters.coarse_levels * parameters.coarse_max_wide_images + parameters.fine_levels * (parameters.restarts + 1));
  Registration r{points, values, camera, parameters, grey, report, progress, budget, nullptr};
  int defined = 0;
  report.initial_cost = r.costAt(initial_pose, &defined);
  // Below a few percent of the image there is nothing to register against (wrong pose or cloud).
  if (defined < static_cast<int>(0.02 * camera.width * camera.height))
    throw InvalidInput("image registration: the cloud covers " + std::to_string(defined) + " of the " +
                       std::to_string(camera.width * camera.height) + " pixels seen from the initial pose (at least 2% needed)");
  auto t0 = Clock::now();
  CameraPose pose = r.coarse(initial_pose);
  report.coarse_seconds = secondsSince(t0);
  report.coarse_pose = pose;
  report.coarse_cost = r.costAt(pose);
  report.final_cost = report.coarse_cost;
  if (parameters.fine) {
    t0 = Clock::now();
    double cost = 0;
    // Coarsest scale first: its cost is smoother, the full scale then settles the last pixel.
    CameraPose refined = pose;
    for (int level = parameters.fine_levels - 1; level >= 0; --level)
      refined = r.fine(refined, cost, std::ldexp(parameters.fine_scale, -level));
    report.fine_seconds = secondsSince(t0);
    // BOBYQA returns its best point; keep the coarse pose if the full-scale cost says otherwise.
    const double full = parameters.fine_scale == 1.0 ? cost : r.costAt(refined);
    if (full <= report.coarse_cost) {
      pose = refined;
      report.final_cost = full;
    }
  }
  report.final_pose = pose;
  if (progress) progress("image registration", 1.f);
  return pose;
}

template class ImageToCloudRegistration<pcl::PointNormal>;
template class ImageToCloudRegistration<pcl::PointXYZINormal>;
template class ImageToCloudRegistration<pcl::PointXYZRGBNormal>;

}  // namespace paps
