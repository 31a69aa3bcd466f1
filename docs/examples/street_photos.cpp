// Chapter 4 as one PCL pipeline on a mobile-mapping street: photos whose GPS poses are off by
// degrees and decimetres are registered to the LiDAR cloud (paps::ImageToCloudRegistration,
// MIDHOG on the laser reflectance), then colour the cloud (paps::PointColorization), whose
// shadows are found (paps::ShadowDetection) and relit (paps::ShadowCorrection).
//
//   example_street_photos [OUT_DIR]   (writes coloured.pcd and relit.pcd there)
//
// The street is paps' synthetic one (real scans with registered photos are not packaged); it
// exits 1 unless every photo ends within 3 px of its true pose (from 8 px or more) and the
// shadow labels agree with the truth on 85% of the points.
#include <cstdio>
#include <string>

#include <pcl/io/pcd_io.h>

#include <paps/core/error.h>
#include <paps/fusion/image_registration.h>
#include <paps/fusion/point_colorization.h>
#include <paps/fusion/shadow_correction.h>
#include <paps/fusion/shadow_detection.h>
#include <paps/fusion/synthetic_street.h>

int main(int argc, char** argv) try {
  paps::synthetic::StreetOptions options;
  options.length = 40;
  const paps::synthetic::StreetScene street(options);
  const paps::synthetic::StreetScan scan = street.scan();
  auto cloud = scan.cloud.makeShared();  // pcl::PointXYZRGBNormal, no colour yet
  std::vector<Eigen::Vector3d> probe;
  for (std::size_t i = 0; i < cloud->size(); i += 11) probe.push_back((*cloud)[i].getVector3fMap().cast<double>());

  paps::CameraIntrinsics camera = paps::CameraIntrinsics::fromFieldOfView(320, 240, 80);
  camera.k1 = -0.08;
  const auto truth = street.cameraPoses(3, -8, 8, 1, 15, 10);
  bool ok = true;
  paps::PointColorization<pcl::PointXYZRGBNormal> colorize;
  paps::ShadowDetection<pcl::PointXYZRGBNormal> shadows;
  std::vector<cv::Mat> photos;
  std::vector<paps::CameraPose> registered;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    paps::synthetic::PhotoOptions po;
    po.seed = 10 + i;
    photos.push_back(street.photo(camera, truth[i], po).image);
    paps::PoseDelta gps;  // what a GPS/IMU pose is off by
    gps.yaw = (i % 2 ? 3.0 : -3.0) * M_PI / 180;
    gps.pitch = 2.0 * M_PI / 180;
    gps.translation = Eigen::Vector3d(0.3, -0.2, 0.2);
    const paps::CameraPose start = paps::applyPoseDelta(truth[i], gps);

    paps::ImageToCloudRegistration<pcl::PointXYZRGBNormal> reg;
    reg.setInputCloud(cloud);
    reg.setPointValues(scan.reflectance);  // synthetic images of the reflectance (manuscript Table 4.1)
    reg.setPhoto(photos.back(), camera);
    reg.setInitialPose(start);
    registered.push_back(reg.align());
    const double before = paps::meanReprojectionError(camera, truth[i], start, probe);
    const double after = paps::meanReprojectionError(camera, truth[i], registered.back(), probe);
    std::printf("photo %zu: %.1f px -> %.1f px from its true pose (%.1f s)\n", i, before, after,
                reg.getReport().coarse_seconds + reg.getReport().fine_seconds);
    ok = ok && before >= 8 && after < 3;
  }
  for (std::size_t i = 0; i < photos.size(); ++i) colorize.addView(photos[i], camera, registered[i]);
  colorize.setInputCloud(cloud);
  pcl::PointCloud<pcl::PointXYZRGBNormal> coloured;
  colorize.filter(coloured);
  std::printf("colorization: %zu points coloured, %zu unseen\n", colorize.getReport().coloured,
              colorize.getReport().unseen);

  auto coloured_ptr = coloured.makeShared();
  shadows.setInputCloud(coloured_ptr);
  shadows.setReflectance(scan.reflectance);
  for (std::size_t i = 0; i < photos.size(); ++i) shadows.addView(photos[i], camera, registered[i]);
  paps::ShadowDetectionResult labels;
  shadows.detect(labels);
  std::size_t seen = 0, agree = 0;
  for (std::size_t i = 0; i < labels.in_shadow.size(); ++i)
    if (labels.decided[i] == 2) {
      ++seen;
      agree += labels.in_shadow[i] == scan.in_shadow[i];
    }
  const double accuracy = seen ? double(agree) / seen : 0;
  std::printf("shadow detection: %zu interface pairs; labels right on %.1f%% of the %zu points the photos see\n",
              labels.interface_pairs.size(), 100 * accuracy, seen);
  ok = ok && accuracy > 0.85;

  paps::ShadowCorrection<pcl::PointXYZRGBNormal> relight;
  paps::ShadowCorrectionParameters p;
  p.sun_direction = street.sunDirection().cast<float>();  // from GPS time and position in practice
  relight.setParameters(p);
  relight.setInputCloud(coloured_ptr);
  relight.setShadowLabels(labels.in_shadow);
  pcl::PointCloud<pcl::PointXYZRGBNormal> relit;
  relight.filter(relit);
  if (argc > 1) {
    pcl::io::savePCDFileBinary(std::string(argv[1]) + "/coloured.pcd", coloured);
    pcl::io::savePCDFileBinary(std::string(argv[1]) + "/relit.pcd", relit);
  }
  std::printf(ok ? "ok\n" : "FAILED\n");
  return ok ? 0 : 1;
} catch (const paps::Error& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
