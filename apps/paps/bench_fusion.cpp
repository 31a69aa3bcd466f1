// paps bench fusion [--quick] (manuscript chapter 4): image to cloud registration with the
// protocol of Table 4.1 (error in pixels, its spread, success ratio, the error left on the
// successes, time), then colorization and shadows (bench_fusion_colour.cpp).
// Input: the synthetic street of paps/fusion/synthetic_street.h (real street scans with
// registered photos are not packaged): photos at known poses, a GPS-like error drawn per photo,
// every third photo with a van the scan does not contain, exposures from 0.6 to 0.9.
// Methods on the same photos and start poses: our coarse-to-fine pipeline with MIDHOG, the same
// pipeline with NMI alone (the metric of Taylor and Nieto's registration [TN13]) and with DHOG
// alone, and OpenCV's ECC (findTransformECC, Euclidean image warp, the usual 2D alignment),
// each on shading (normals) and on laser reflectance.
// Then the same methods on real data: an organized RGB-D frame (PCL's Kinect tutorial frame by
// default, fetched by scripts/fetch_samples.sh), whose photo's true pose the grid gives.
#include <algorithm>
#include <filesystem>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <sys/resource.h>

#include <opencv2/imgcodecs.hpp>

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/fusion/image_registration.h>
#include <paps/fusion/organized_cloud_camera.h>
#include <paps/fusion/synthetic_street.h>

#include "cli_common.h"
#include "commands.h"
#include "rgbd_points.h"

namespace paps::cli {

int benchColourAndShadows(bool quick);

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double peakMegabytes() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

// OpenCV ECC peer: the photo's frame inside the synthetic image rendered at the start pose as a
// Euclidean warp (maximum correlation), turned into yaw, pitch and roll as the coarse step
// does; two rounds, re-rendering in between. A failure to converge keeps the pose.
CameraPose eccRegistration(const Positions& points, const std::vector<float>& values, const cv::Mat& photo,
                           const CameraIntrinsics& camera, CameraPose pose) {
  cv::Mat grey;
  cv::cvtColor(photo, grey, cv::COLOR_BGR2GRAY);
  grey.convertTo(grey, CV_32F, 1.0 / 255);
  for (int round = 0; round < 2; ++round) {
    const SyntheticImage s = renderSyntheticImage(points, values, camera, pose);
    cv::Mat warp = cv::Mat::eye(2, 3, CV_32F);
    try {
      cv::findTransformECC(grey, s.intensity, warp, cv::MOTION_EUCLIDEAN,
                           cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-5), s.mask, 5);
    } catch (const cv::Exception&) {
      return pose;
    }
    // photo pixel p -> synthetic pixel R p + t' = R (p - c) + c + t, t = t' + R c - c.
    const double theta = std::atan2(warp.at<float>(1, 0), warp.at<float>(0, 0));
    const double tx = warp.at<float>(0, 2) + warp.at<float>(0, 0) * camera.cx + warp.at<float>(0, 1) * camera.cy - camera.cx;
    const double ty = warp.at<float>(1, 2) + warp.at<float>(1, 0) * camera.cx + warp.at<float>(1, 1) * camera.cy - camera.cy;
    PoseDelta d;
    d.yaw = std::atan(tx / camera.fx);
    d.pitch = -std::atan(ty / camera.fy);
    d.roll = theta;
    pose = applyPoseDelta(pose, d);
  }
  return pose;
}

std::string pipelineName(ImageMetric metric) {
  return std::string("coarse+fine ") + imageMetricName(metric) + (metric == ImageMetric::MIDHOG ? " (ours)" : "");
}

struct Row {
  std::string method, modality;
  std::vector<double> errors;
  double seconds = 0;
  std::vector<double> colour_rms;  // optional: colour error of the points at the found pose
};

void printRow(const Row& r, double success_px) {
  std::vector<double> e = r.errors;
  const double n = static_cast<double>(e.size());
  double mean = 0, var = 0, ok = 0, remaining = 0;
  for (double v : e) mean += v / n;
  for (double v : e) var += (v - mean) * (v - mean) / n;
  for (double v : e)
    if (v < success_px) { ++ok; remaining += v; }
  std::nth_element(e.begin(), e.begin() + e.size() / 2, e.end());
  std::printf("%-24s %-12s %8.2f %8.2f %8.2f %7.0f%% %10s %8.2f", r.method.c_str(), r.modality.c_str(), mean,
              std::sqrt(var), e[e.size() / 2], 100 * ok / n,
              ok ? std::to_string(remaining / ok).substr(0, 5).c_str() : "-", r.seconds / n);
  if (!r.colour_rms.empty()) {
    double c = 0;
    for (double v : r.colour_rms) c += v / double(r.colour_rms.size());
    std::printf(" %10.4f", c);
  }
  std::printf("\n");
}

// Fig. 4.3-like picture: the photo in grey, the edges of the synthetic image of the cloud
// drawn from the start pose (magenta) and from the registered pose (green).
void writeOverlay(const std::string& path, const cv::Mat& photo, const SyntheticImage& start, const SyntheticImage& final_image) {
  cv::Mat grey, out;
  cv::cvtColor(photo, grey, cv::COLOR_BGR2GRAY);
  cv::cvtColor(grey, out, cv::COLOR_GRAY2BGR);
  auto edges = [](const SyntheticImage& s) {
    cv::Mat v, e, inside;
    s.intensity.convertTo(v, CV_8U, 255);
    cv::Canny(v, e, 40, 100);
    cv::erode(s.mask, inside, cv::Mat());  // not the borders of the holes
    e.setTo(0, inside == 0);
    return e;
  };
  out.setTo(cv::Scalar(255, 0, 255), edges(start));
  out.setTo(cv::Scalar(0, 255, 0), edges(final_image));
  cv::resize(out, out, cv::Size(), 2, 2, cv::INTER_NEAREST);
  if (!cv::imwrite(path, out)) std::fprintf(stderr, "could not write %s\n", path.c_str());
  else std::printf("wrote %s (photo; cloud edges from the start pose in magenta, after registration in green)\n", path.c_str());
}

int benchRegistration(bool quick, const std::string& out_dir) {
  synthetic::StreetScene scene;
  const synthetic::StreetScan scan = scene.scan();
  const Positions points = positionsOf(scan.cloud);
  const std::vector<float> shading = shadingValues(scan.cloud);
  std::vector<Eigen::Vector3d> probe;
  for (std::size_t i = 0; i < points.size(); i += 13) probe.push_back(points[i].cast<double>());
  CameraIntrinsics camera = CameraIntrinsics::fromFieldOfView(320, 240, 80);
  camera.k1 = -0.08;
  camera.k2 = 0.01;
  const int photos = quick ? 4 : 20;
  const double success_px = 4.0;
  std::printf("== Image to cloud registration (manuscript 4.4, Table 4.1 protocol)\n");
  std::printf("input: synthetic street, %zu LiDAR points; %d photos of %dx%d (fx %.0f px, k1 %.2f), %d with a van the scan lacks\n",
              points.size(), photos, camera.width, camera.height, camera.fx, camera.k1, photos / 3);
  std::printf("(ratios between rows are what the table shows; the machine is shared, times are noisy)\n");
  std::printf("start poses: true pose + yaw, pitch in +-5 deg, roll in +-2 deg, translation in +-0.5 m per axis (seeded)\n");
  std::printf("error: mean reprojection distance of the scan's points, pixels; success: error < %.0f px (%.2f%% of the width)\n\n",
              success_px, 100 * success_px / camera.width);
  // Photos: both sides of the street, turned 10 to 20 degrees along it.
  Random rng(2024);
  std::vector<CameraPose> truth, start;
  std::vector<cv::Mat> images;
  for (int i = 0; i < photos; ++i) {
    const int side = i % 2 ? -1 : 1;
    const double x = -20 + 40.0 * i / std::max(1, photos - 1);
    truth.push_back(scene.cameraPoses(1, x, x, side, rng.uniform(10, 20), 10)[0]);
    synthetic::PhotoOptions po;
    po.exposure = rng.uniform(0.6, 0.9);
    po.passing_van = i % 3 == 2;
    po.van_x = x + 2;
    po.seed = 100 + i;
    images.push_back(scene.photo(camera, truth.back(), po).image);
    PoseDelta d;
    d.yaw = rng.uniform(-5, 5) * M_PI / 180;
    d.pitch = rng.uniform(-5, 5) * M_PI / 180;
    d.roll = rng.uniform(-2, 2) * M_PI / 180;
    d.translation = rng.uniform3(-0.5, 0.5);
    start.push_back(applyPoseDelta(truth.back(), d));
  }
  std::printf("%-24s %-12s %8s %8s %8s %8s %10s %8s\n", "method", "modality", "mean px", "std px", "median", "success",
              "remaining", "time s");
  Row initial{"start pose (GPS)", "-", {}, 0};
  for (int i = 0; i < photos; ++i) initial.errors.push_back(meanReprojectionError(camera, truth[i], start[i], probe));
  printRow(initial, success_px);
  for (int modality = 0; modality < 2; ++modality) {
    const std::vector<float>& values = modality ? scan.reflectance : shading;
    const char* name = modality ? "reflectance" : "shading";
    Row ecc{"OpenCV ECC (2D warp)", name, {}, 0};
    for (int i = 0; i < photos; ++i) {
      const auto t0 = Clock::now();
      const CameraPose pose = eccRegistration(points, values, images[i], camera, start[i]);
      ecc.seconds += secondsSince(t0);
      ecc.errors.push_back(meanReprojectionError(camera, truth[i], pose, probe));
    }
    printRow(ecc, success_px);
    for (ImageMetric metric : {ImageMetric::NMI, ImageMetric::DHOG, ImageMetric::MIDHOG}) {
      Row row{pipelineName(metric), name, {}, 0};
      ImageRegistrationParameters p;
      p.coarse_metric.metric = p.fine_metric.metric = metric;
      for (int i = 0; i < photos; ++i) {
        const auto t0 = Clock::now();
        const CameraPose pose = registerImageToPoints(points, values, images[i], camera, start[i], p);
        row.seconds += secondsSince(t0);
        row.errors.push_back(meanReprojectionError(camera, truth[i], pose, probe));
        if (i == 0 && modality == 1 && metric == ImageMetric::MIDHOG && !out_dir.empty())
          writeOverlay(out_dir + "/registration_overlay.png", images[i], renderSyntheticImage(points, values, camera, start[i]),
                       renderSyntheticImage(points, values, camera, pose));
      }
      printRow(row, success_px);
    }
  }
  std::printf("\npeak memory of the process: %.0f MB (every method works on the same cloud and photos)\n", peakMegabytes());
  std::printf("manuscript Table 4.1 (45 real photos of 2046x2046, start error 123.6 px): success NMI 31%% (normals) / 91%% "
              "(reflectance), DHOG 89%% / 98%%, MIDHOG 93%% / 98%%\n\n");
  return 0;
}

// RMS difference (linear RGB in [0, 1]) between the cloud's own colours and the colours the
// photo gives its visible points when placed at `pose`: what a colorization from this pose
// would get wrong. Over the points visible from the true pose.
double colourError(const Positions& points, const std::vector<Eigen::Vector3f>& colours, const RegisteredPhoto& photo,
                   const CameraPose& pose, const std::vector<std::uint8_t>& scored) {
  const ProjectedPoints seen = projectVisiblePoints(points, photo.camera, pose);
  double squares = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!scored[i]) continue;
    // A point the photo no longer sees from `pose` would keep no colour: it counts as black.
    const Eigen::Vector3f c = seen.visible[i] && photo.camera.inside(seen.pixel[i].cast<double>())
                                  ? sampleBilinear(photo.image, seen.pixel[i])
                                  : Eigen::Vector3f::Zero();
    squares += (c - colours[i]).squaredNorm() / 3;
    ++n;
  }
  return n ? std::sqrt(squares / double(n)) : NAN;
}

// How well the frame's colour and depth agree (the true pose is only as good as the sensor's
// depth-to-colour registration): the shift of the photo's edges (Canny) that best matches the
// depth discontinuities between finite neighbours (> 5 cm and > 5%), by mean truncated
// distance. Returns the shift; prints the scores.
Eigen::Vector2i colourDepthShift(const pcl::PointCloud<pcl::PointXYZRGBA>& frame, const cv::Mat& photo) {
  const int w = int(frame.width), h = int(frame.height), reach = 6;
  std::vector<Eigen::Vector2i> depth_edges;
  for (int v = reach; v < h - reach; ++v)
    for (int u = reach; u < w - reach; ++u) {
      const float z = frame.at(u, v).z;
      if (!std::isfinite(z)) continue;
      for (const Eigen::Vector2i& d : {Eigen::Vector2i(1, 0), Eigen::Vector2i(0, 1)}) {
        const float z2 = frame.at(u + d.x(), v + d.y()).z;
        if (std::isfinite(z2) && std::abs(z - z2) > 0.05f && std::abs(z - z2) > 0.05f * std::abs(z)) {
          depth_edges.emplace_back(u, v);
          break;
        }
      }
    }
  cv::Mat grey, edges, distance;
  cv::cvtColor(photo, grey, cv::COLOR_BGR2GRAY);
  cv::Canny(grey, edges, 50, 150);
  cv::distanceTransform(255 - edges, distance, cv::DIST_L2, 3);
  auto score = [&](int dx, int dy) {
    double sum = 0;
    for (const auto& e : depth_edges) sum += std::min(distance.at<float>(e.y() + dy, e.x() + dx), 10.f);
    return sum / double(std::max<std::size_t>(1, depth_edges.size()));
  };
  Eigen::Vector2i best(0, 0);
  double best_score = score(0, 0);
  for (int dy = -reach; dy <= reach; ++dy)
    for (int dx = -reach; dx <= reach; ++dx)
      if (const double s = score(dx, dy); s < best_score) best_score = s, best = Eigen::Vector2i(dx, dy);
  std::printf("colour-depth agreement: %zu depth-edge pixels; mean distance to the photo's edges %.3f px as recorded, "
              "%.3f px at the best shift (%d, %d) px in +-%d\n",
              depth_edges.size(), score(0, 0), best_score, best.x(), best.y(), reach);
  return best;
}

// Real data: an organized RGB-D frame is a photo whose pose in its own cloud is known exactly
// (cameraOfOrganizedCloud), so registration can be scored on a real photo and a real cloud.
int benchRegistrationRgbd(bool quick, const std::string& path, const std::string& out_dir) {
  pcl::PointCloud<pcl::PointXYZRGBA> frame;
  if (pcl::io::loadPCDFile(path, frame) != 0) {
    std::fprintf(stderr, "bench fusion: cannot read %s (run scripts/fetch_samples.sh, or --rgbd none)\n", path.c_str());
    return 1;
  }
  const OrganizedCloudCamera real = cameraOfOrganizedCloud(frame);
  std::printf("== Image to cloud registration on a real RGB-D frame\n");
  colourDepthShift(frame, real.photo.image);
  // The registration runs at half the native size (as the street's 320 x 240); errors are in
  // native pixels.
  RegisteredPhoto half;
  half.camera = real.photo.camera.scaled(0.5);
  cv::resize(real.photo.image, half.image, cv::Size(half.camera.width, half.camera.height), 0, 0, cv::INTER_AREA);
  // The cloud as `paps rgbd-photo` writes it: the finite points, normals of the 30 nearest.
  const RgbdPoints rgbd = rgbdPoints(frame, 30, real.photo.pose.translation().cast<float>());
  const Positions& points = rgbd.points;
  pcl::PointCloud<pcl::PointNormal> cloud;
  cloud.resize(points.size());
  std::vector<Eigen::Vector3f> colours(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    cloud[i].getVector3fMap() = points[i];
    cloud[i].getNormalVector3fMap() = rgbd.normals[i];
    colours[i] = Eigen::Vector3f((rgbd.rgb[i] >> 16) & 0xff, (rgbd.rgb[i] >> 8) & 0xff, rgbd.rgb[i] & 0xff) / 255.f;
  }
  // Shading needs a light; an indoor frame is lit from above: the camera's up (-y), tilted
  // towards the camera. The fixed default light of shadingValues() is shown beside it.
  const Eigen::Vector3f up_light = (real.photo.pose.linear() * Eigen::Vector3d(0, -1, -0.3)).normalized().cast<float>();
  const std::vector<float> shading_up = shadingValues(cloud, up_light);
  const std::vector<float> shading_default = shadingValues(cloud);
  std::vector<Eigen::Vector3d> probe;
  for (std::size_t i = 0; i < points.size(); i += 13) probe.push_back(points[i].cast<double>());
  const ProjectedPoints truly_seen = projectVisiblePoints(points, real.photo.camera, real.photo.pose);
  const std::vector<std::uint8_t>& scored = truly_seen.visible;

  const CameraIntrinsics& native = real.photo.camera;
  const int starts = quick ? 2 : 10;
  const double success_px = 0.0125 * native.width;  // the street's 4 px of 320
  std::printf("input: %s: %zu finite points of %ux%u; camera recovered from the grid: fx %.2f fy %.2f cx %.2f cy %.2f, "
              "residual %.4f px RMS (the true pose)\n",
              path.c_str(), points.size(), frame.width, frame.height, native.fx, native.fy, native.cx, native.cy,
              real.fit.rms_pixels);
  std::printf("registration on the photo at half size (%dx%d); errors in native pixels (%dx%d); success: error < %.0f px "
              "(1.25%% of the width, as the street's 4 px of 320)\n",
              half.camera.width, half.camera.height, native.width, native.height, success_px);
  std::printf("start poses: true pose + yaw, pitch in +-3 deg, roll in +-1.5 deg, translation in +-3 cm per axis (seeded); "
              "fine band +-10 cm (the street's 0.5 m, scaled to a room)\n");
  std::printf("colour RMS: the cloud's own colours against the photo's at the found pose (linear RGB, %zu points seen "
              "from the true pose; 0 at the true pose up to the visibility test)\n\n", std::size_t(truly_seen.visibleCount()));
  Random rng(77);
  std::vector<CameraPose> start;
  for (int i = 0; i < starts; ++i) {
    PoseDelta d;
    d.yaw = rng.uniform(-3, 3) * M_PI / 180;
    d.pitch = rng.uniform(-3, 3) * M_PI / 180;
    d.roll = rng.uniform(-1.5, 1.5) * M_PI / 180;
    d.translation = rng.uniform3(-0.03, 0.03);
    start.push_back(applyPoseDelta(real.photo.pose, d));
  }
  if (!out_dir.empty()) {  // the photo beside the synthetic image the metrics compare it with
    const SyntheticImage at_truth = renderSyntheticImage(points, shading_up, half.camera, real.photo.pose);
    cv::Mat grey, synthetic, both;
    cv::cvtColor(half.image, grey, cv::COLOR_BGR2GRAY);
    at_truth.intensity.convertTo(synthetic, CV_8U, 255);
    cv::hconcat(grey, synthetic, both);
    const std::string file = out_dir + "/kinect_photo_and_shading.png";
    if (cv::imwrite(file, both)) std::printf("wrote %s (the photo; the cloud's shading, light from above, at the true pose)\n", file.c_str());
    else std::fprintf(stderr, "could not write %s\n", file.c_str());
  }
  std::printf("%-24s %-12s %8s %8s %8s %8s %10s %8s %10s\n", "method", "modality", "mean px", "std px", "median",
              "success", "remaining", "time s", "colour RMS");
  Row truth_row{"true pose", "-", std::vector<double>(starts, 0.0), 0};
  truth_row.colour_rms.push_back(colourError(points, colours, real.photo, real.photo.pose, scored));
  printRow(truth_row, success_px);
  Row initial{"start pose", "-", {}, 0};
  for (int i = 0; i < starts; ++i) {
    initial.errors.push_back(meanReprojectionError(native, real.photo.pose, start[i], probe));
    initial.colour_rms.push_back(colourError(points, colours, real.photo, start[i], scored));
  }
  printRow(initial, success_px);
  for (int modality = 0; modality < 2; ++modality) {
    const std::vector<float>& values = modality ? shading_default : shading_up;
    const char* name = modality ? "shading dflt" : "shading up";
    Row ecc{"OpenCV ECC (2D warp)", name, {}, 0};
    for (int i = 0; i < starts; ++i) {
      const auto t0 = Clock::now();
      const CameraPose pose = eccRegistration(points, values, half.image, half.camera, start[i]);
      ecc.seconds += secondsSince(t0);
      ecc.errors.push_back(meanReprojectionError(native, real.photo.pose, pose, probe));
      ecc.colour_rms.push_back(colourError(points, colours, real.photo, pose, scored));
    }
    printRow(ecc, success_px);
    const SyntheticImage at_truth = renderSyntheticImage(points, values, half.camera, real.photo.pose);
    for (ImageMetric metric : {ImageMetric::NMI, ImageMetric::DHOG, ImageMetric::MIDHOG}) {
      Row row{pipelineName(metric), name, {}, 0};
      ImageRegistrationParameters p;
      p.coarse_metric.metric = p.fine_metric.metric = metric;
      p.fine_max_translation = 0.1;
      int below_truth = 0;
      const double truth_cost = ImageComparator(half.image, p.fine_metric).cost(at_truth.intensity, at_truth.mask);
      for (int i = 0; i < starts; ++i) {
        const auto t0 = Clock::now();
        ImageRegistrationReport report;
        const CameraPose pose = registerImageToPoints(points, values, half.image, half.camera, start[i], p, &report);
        row.seconds += secondsSince(t0);
        row.errors.push_back(meanReprojectionError(native, real.photo.pose, pose, probe));
        row.colour_rms.push_back(colourError(points, colours, real.photo, pose, scored));
        below_truth += report.final_cost < truth_cost;
      }
      printRow(row, success_px);
      if (below_truth)
        std::printf("    %d of %d found poses cost less than the true pose (%s %.4f at the truth): the metric's minimum "
                    "is off the truth on this frame\n", below_truth, starts, imageMetricName(metric), truth_cost);
    }
  }
  std::printf("\npeak memory of the process: %.0f MB\n\n", peakMegabytes());
  return 0;
}

}  // namespace

constexpr const char* kBenchFusionUsage =
    "usage: paps bench fusion [options]\n"
    "  image-cloud registration on the synthetic street (Table 4.1: NMI, DHOG, MIDHOG, coarse\n"
    "  then fine), colorization and shadows, and registration on a real Kinect frame\n"
    "  --quick               fewer starts and photos (a smoke run)\n"
    "  --out DIR             where the renders (PNG) go\n"
    "  --registration-only, --colour-only, --rgbd-only   one part only\n"
    "  --rgbd PCD|none       the organized RGB-D frame of the real part (default\n"
    "                        milk_cartoon_all_small_clorox.pcd from the samples; none skips it)\n";

int runBenchFusion(int argc, char** argv) {
  bool quick = false, registration = true, colour = true, rgbd = true, rgbd_given = false;
  std::string out_dir, rgbd_path = samplesDir() + "/milk_cartoon_all_small_clorox.pcd";
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // rows appear as they are measured
  for (int i = 3; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--help")) {
      std::fputs(kBenchFusionUsage, stdout);
      return 0;
    }
    if (!std::strcmp(argv[i], "--quick")) quick = true;
    else if (!std::strcmp(argv[i], "--out") && i + 1 < argc) out_dir = argv[++i];
    else if (!std::strcmp(argv[i], "--registration-only")) colour = rgbd = false;
    else if (!std::strcmp(argv[i], "--colour-only")) registration = rgbd = false;
    else if (!std::strcmp(argv[i], "--rgbd-only")) registration = colour = false;
    else if (!std::strcmp(argv[i], "--rgbd") && i + 1 < argc) rgbd_path = argv[++i], rgbd_given = true;
    else {
      std::fprintf(stderr, "paps bench fusion: unknown option '%s' (options: --quick, --out DIR, --registration-only, "
                   "--colour-only, --rgbd-only, --rgbd PCD|none)\n", argv[i]);
      return 2;
    }
  }
  if (rgbd_path == "none") rgbd = false;
  // Made before the parts run (they take minutes): the renders were lost when DIR was new.
  if (!out_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(out_dir, ec);
    if (ec || !std::filesystem::is_directory(out_dir))
      throw IoError("bench fusion: cannot create the output folder " + out_dir + " (" +
                    (ec ? ec.message() : std::string("a file of that name exists")) + ")");
  }
  if (rgbd && !rgbd_given && !std::filesystem::exists(rgbd_path)) {
    std::printf("(real RGB-D part skipped: no %s; scripts/fetch_samples.sh fetches it)\n", rgbd_path.c_str());
    rgbd = false;
  }
  int rc = 0;
  if (registration) rc |= benchRegistration(quick, out_dir);
  if (rgbd) rc |= benchRegistrationRgbd(quick, rgbd_path, out_dir);
  if (colour) rc |= benchColourAndShadows(quick);
  return rc;
}

}  // namespace paps::cli
