// paps make-street DIR: the synthetic street (cloud, photos, true and GPS-like poses) as files.
// paps register CLOUD LIST OUT_LIST: image to cloud registration of every photo of a list.
// paps rgbd-photo FRAME DIR: the photo, camera and pose of an organized RGB-D cloud as files.
#include <chrono>
#include <cstdio>
#include <filesystem>

#include <unistd.h>

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include <paps/core/cloud_file_layout.h>
#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/fusion/image_registration.h>
#include <paps/fusion/organized_cloud_camera.h>
#include <paps/fusion/photo_list.h>
#include <paps/fusion/synthetic_street.h>

#include "cli_common.h"
#include "commands.h"
#include "rgbd_points.h"

namespace paps::cli {

namespace {

const char* kMakeStreetUsage =
    "usage: paps make-street DIR [options]\n"
    "  Writes the synthetic street of the chapter 4 benches into DIR (created if missing):\n"
    "  street.pcd            the mobile LiDAR pass: x y z, normal_x/y/z (true), intensity (laser\n"
    "                        reflectance in [0, 1])\n"
    "  photo_NN.png          photos from a camera on the vehicle (320x240, k1 -0.08), some with\n"
    "                        a van the scan does not contain\n"
    "  photos_true.txt       their true poses (photo list, see docs/registration.md)\n"
    "  photos_gps.txt        the same with a GPS-like error (yaw, pitch +-5 deg, roll +-2 deg,\n"
    "                        translation +-0.5 m), the input of paps register\n"
    "  --photos N            number of photos, 1 to 200 (default 6)\n"
    "  --seed S              seed of the scene and the errors (default 1)\n";

const char* kRegisterUsage =
    "usage: paps register CLOUD LIST OUT_LIST [options]\n"
    "  Refines the pose of every photo of LIST against CLOUD (manuscript 4.4): a coarse search of\n"
    "  the 3 rotations in a wide synthetic image, multiscale, then the 6 degrees of freedom.\n"
    "  CLOUD                 .pcd or .ply with an 'intensity' field (laser reflectance) and/or\n"
    "                        normals (shading)\n"
    "  LIST, OUT_LIST        photo lists (image width height fx fy cx cy k1 k2 p1 p2 k3 and a 3x4\n"
    "                        camera-to-world pose per line; docs/registration.md); OUT_LIST gets the\n"
    "                        refined poses, written atomically\n"
    "  --values V            intensity (default when the cloud has it) or shading (|<n, light>|)\n"
    "  --metric M            midhog (default), nmi or dhog, both steps\n"
    "  --alpha A             weight of DHOG in MIDHOG (default 10)\n"
    "  --light X,Y,Z         light direction of the shading, cloud frame (default 0.5,-0.3,0.8)\n"
    "  --band M              translation searched by the fine step, metres per axis (default 0.5,\n"
    "                        for a street; about 0.1 for a room)\n"
    "  --coarse-only         skip the 6-DoF fine step\n"
    "  --truth LIST          true poses: print the reprojection error before and after\n"
    "  --quiet               no progress bar\n";

const char* kRgbdPhotoUsage =
    "usage: paps rgbd-photo FRAME DIR [options]\n"
    "  Recovers the pinhole camera and the pose of an organized RGB-D cloud (Kinect, RealSense,\n"
    "  rectified stereo: point (u, v) of the grid was seen at pixel (u, v)) and writes into DIR\n"
    "  (created if missing), atomically:\n"
    "  photo.png             the colours of the grid (NaN points keep theirs)\n"
    "  photo.txt             its photo list: the fitted camera and the true pose\n"
    "  cloud.pcd             the finite points: x y z, normals (oriented towards the camera), rgb\n"
    "  photo_start.txt       with --perturb: the same photo from a seeded wrong pose, to try\n"
    "                        paps register ... --truth DIR/photo.txt on real data\n"
    "  --perturb DEG,M       yaw and pitch in +-DEG, roll in +-DEG/2, translation in +-M metres\n"
    "  --seed S              seed of the perturbation (default 1)\n"
    "  --neighbours K        nearest points per normal, 3 to 1000 (default 30: RGB-D depth is\n"
    "                        quantised)\n"
    "  --sample-step N       fit on every N-th row and column (default 3)\n"
    "  --max-rms PX          refuse a fit worse than this (default 0.5)\n";

// Writes an image atomically: a temporary file with the same extension, then a rename.
void writeImageAtomic(const std::string& path, const cv::Mat& image) {
  const std::filesystem::path p(path);
  const std::string tmp = (p.parent_path() / (".tmp" + std::to_string(::getpid()) + "_" + p.filename().string())).string();
  bool ok = false;
  try {
    ok = cv::imwrite(tmp, image);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw IoError("cannot write image '" + path + "'");
  }
  commitTemporaryFile(tmp, path, "image ");
}

}  // namespace

int runMakeStreet(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"help"});
  if (a.has("help")) { std::fputs(kMakeStreetUsage, stdout); return 0; }
  a.allowOnly({"photos", "seed"});
  if (a.positional.size() != 1) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "DIR");
  const int photos = a.integer("photos", 6);
  requireInRange("photos", photos, 1, 200);
  synthetic::StreetOptions o;
  o.seed = a.count("seed", 1);
  const std::string dir = a.positional[0];
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (!std::filesystem::is_directory(dir))
    throw IoError("cannot create folder '" + dir + "'" + (ec ? ": " + ec.message() : std::string()));
  checkOutputPath((std::filesystem::path(dir) / "photo.txt").string());  // a folder that takes files
  const synthetic::StreetScene scene(o);
  const synthetic::StreetScan scan = scene.scan();
  pcl::PointCloud<pcl::PointXYZ> xyz;
  pcl::PointCloud<pcl::Intensity> intensity;
  Normals normals;
  for (std::size_t i = 0; i < scan.cloud.size(); ++i) {
    xyz.push_back(pcl::PointXYZ(scan.cloud[i].x, scan.cloud[i].y, scan.cloud[i].z));
    pcl::Intensity v;
    v.intensity = scan.reflectance[i];
    intensity.push_back(v);
    normals.push_back(scan.cloud[i].getNormalVector3fMap());
  }
  pcl::PCLPointCloud2 blob, extra;
  pcl::toPCLPointCloud2(xyz, blob);
  setNormals(blob, normals);
  pcl::toPCLPointCloud2(intensity, extra);
  blob = appendFields(blob, extra);
  saveCloudAtomic(dir + "/street.pcd", blob);
  std::printf("wrote %s/street.pcd: %zu points (normals, intensity = reflectance)\n", dir.c_str(), xyz.size());
  CameraIntrinsics camera = CameraIntrinsics::fromFieldOfView(320, 240, 80);
  camera.k1 = -0.08;
  camera.k2 = 0.01;
  Random rng(o.seed * 7 + 3);
  std::vector<PhotoListEntry> truth, gps;
  for (int i = 0; i < photos; ++i) {
    const double x = photos == 1 ? 0 : -20 + 40.0 * i / (photos - 1);
    const int side = i % 2 ? -1 : 1;
    PhotoListEntry e;
    e.camera = camera;
    e.pose = scene.cameraPoses(1, x, x, side, rng.uniform(10, 20), 10)[0];
    char name[32];
    std::snprintf(name, sizeof name, "photo_%02d.png", i);
    e.image = name;
    synthetic::PhotoOptions po;
    po.exposure = rng.uniform(0.6, 0.9);
    po.passing_van = i % 3 == 2;
    po.van_x = x + 2;
    po.seed = 100 + i;
    writeImageAtomic(dir + "/" + name, scene.photo(camera, e.pose, po).image);
    truth.push_back(e);
    PoseDelta d;
    d.yaw = rng.uniform(-5, 5) * M_PI / 180;
    d.pitch = rng.uniform(-5, 5) * M_PI / 180;
    d.roll = rng.uniform(-2, 2) * M_PI / 180;
    d.translation = rng.uniform3(-0.5, 0.5);
    e.pose = applyPoseDelta(e.pose, d);
    gps.push_back(e);
  }
  savePhotoListAtomic(dir + "/photos_true.txt", truth);
  savePhotoListAtomic(dir + "/photos_gps.txt", gps);
  std::printf("wrote %d photos (%dx%d), %s/photos_true.txt and %s/photos_gps.txt\n", photos, camera.width,
              camera.height, dir.c_str(), dir.c_str());
  return 0;
}

int runRegister(int argc, char** argv) {
  // OpenCV's own warnings (a damaged image...) would add lines to our one-line errors.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  const Arguments a = Arguments::parse(argc, argv, 2, {"help", "quiet", "coarse-only"});
  if (a.has("help")) { std::fputs(kRegisterUsage, stdout); return 0; }
  a.allowOnly({"values", "metric", "alpha", "light", "band", "coarse-only", "truth", "quiet"});
  if (a.positional.size() != 3) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "CLOUD LIST OUT_LIST");
  a.requireOutputApart();
  checkOutputPath(a.positional[2]);
  std::error_code same_ec;
  if (a.has("truth") && std::filesystem::equivalent(a.text("truth", ""), a.positional[2], same_ec))
    throw InvalidParameter("truth", a.text("truth", ""), "a file other than OUT_LIST");
  ImageRegistrationParameters p;
  const std::string metric = a.text("metric", "midhog");
  if (metric == "midhog") p.coarse_metric.metric = ImageMetric::MIDHOG;
  else if (metric == "nmi") p.coarse_metric.metric = ImageMetric::NMI;
  else if (metric == "dhog") p.coarse_metric.metric = ImageMetric::DHOG;
  else throw InvalidParameter("metric", metric, "midhog, nmi or dhog");
  p.coarse_metric.alpha = a.number("alpha", p.coarse_metric.alpha);
  p.fine_metric = p.coarse_metric;
  p.fine = !a.has("coarse-only");
  p.fine_max_translation = a.number("band", p.fine_max_translation);
  const Eigen::Vector3f light = parseDirection(a, "light", Eigen::Vector3f(0.5f, -0.3f, 0.8f)).normalized();
  if (a.has("band")) requireInRange("band", p.fine_max_translation, 1e-6, 1e6);
  try {
    p.validate();
  } catch (const InvalidParameter& e) {
    throw InvalidParameter("alpha", e.value(), e.expected());
  }
  // Inputs read and checked before any work.
  const auto entries = loadPhotoList(a.positional[1]);
  if (entries.empty()) throw InvalidInput("photo list '" + a.positional[1] + "' holds no photo");
  // The photos are inputs too: OUT_LIST must not be written over one of them.
  for (const auto& e : entries)
    if (std::filesystem::equivalent(std::filesystem::absolute(a.positional[1]).parent_path() / e.image, a.positional[2],
                                    same_ec))
      throw InvalidParameter("OUT_LIST", a.positional[2], "a file other than the inputs (it is the photo '" + e.image +
                                                              "' of the list; inputs are never overwritten)");
  std::vector<PhotoListEntry> truth;
  if (a.has("truth")) {
    truth = loadPhotoList(a.text("truth", ""));
    if (truth.size() != entries.size())
      throw InvalidInput("--truth lists " + std::to_string(truth.size()) + " photos, LIST " + std::to_string(entries.size()));
  }
  const auto photos = loadPhotos(a.positional[1], entries);
  const pcl::PCLPointCloud2 blob = loadCloud(a.positional[0]);
  const Positions points = positionsOf(blob);
  printRead(a.positional[0], points);
  std::string values_kind = a.text("values", hasField(blob, "intensity") ? "intensity" : "shading");
  std::vector<float> values(points.size(), 0.f);
  if (values_kind == "intensity") {
    if (!hasField(blob, "intensity")) throw InvalidInput("--values intensity: the cloud has no 'intensity' field");
    pcl::PointCloud<pcl::PointXYZI> c;
    pcl::fromPCLPointCloud2(blob, c);
    float hi = 0;
    for (const auto& q : c) if (std::isfinite(q.intensity)) hi = std::max(hi, q.intensity);
    for (std::size_t i = 0; i < c.size(); ++i) values[i] = std::isfinite(c[i].intensity) ? c[i].intensity : 0.f;
    std::printf("register: grey values from the intensity field (max %g)\n", hi);
  } else if (values_kind == "shading") {
    if (!hasField(blob, "normal_x")) throw InvalidInput("--values shading: the cloud has no normals (normal_x/y/z)");
    pcl::PointCloud<pcl::PointNormal> c;
    pcl::fromPCLPointCloud2(blob, c);
    values = shadingValues(c, light);
    std::printf("register: grey values from the normals (shading, light %.3g,%.3g,%.3g)\n", light.x(), light.y(), light.z());
  } else {
    throw InvalidParameter("values", values_kind, "intensity or shading");
  }
  std::vector<Eigen::Vector3d> probe;
  for (std::size_t i = 0; i < points.size(); i += std::max<std::size_t>(1, points.size() / 20000))
    if (isFinite(points[i])) probe.push_back(points[i].cast<double>());
  std::vector<PhotoListEntry> out = entries;
  double sum_before = 0, sum_after = 0;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    ImageRegistrationReport r;
    const auto t0 = std::chrono::steady_clock::now();
    out[i].pose = registerImageToPoints(points, values, photos[i].image, entries[i].camera, entries[i].pose, p, &r,
                                        progressBar(a.has("quiet")));
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("photo %zu (%s): %s %.4f -> %.4f (coarse) -> %.4f, %d renderings, %.1f s", i, entries[i].image.c_str(),
                imageMetricName(p.fine_metric.metric), r.initial_cost, r.coarse_cost, r.final_cost, r.renderings, s);
    if (!truth.empty()) {
      const double before = meanReprojectionError(entries[i].camera, truth[i].pose, entries[i].pose, probe);
      const double after = meanReprojectionError(entries[i].camera, truth[i].pose, out[i].pose, probe);
      sum_before += before;
      sum_after += after;
      std::printf("; error %.2f -> %.2f px", before, after);
    }
    std::printf("\n");
  }
  if (!truth.empty())
    std::printf("register: mean error %.2f -> %.2f px over %zu photos\n", sum_before / entries.size(),
                sum_after / entries.size(), entries.size());
  // Image paths are relative to their list's folder: re-express them for OUT_LIST's.
  const std::filesystem::path in_folder = std::filesystem::absolute(a.positional[1]).parent_path();
  const std::filesystem::path out_folder = std::filesystem::absolute(a.positional[2]).parent_path();
  for (auto& e : out) e.image = std::filesystem::relative(in_folder / e.image, out_folder).lexically_normal().string();
  savePhotoListAtomic(a.positional[2], out);
  std::printf("wrote %s\n", a.positional[2].c_str());
  return 0;
}

RgbdPoints rgbdPoints(const pcl::PointCloud<pcl::PointXYZRGBA>& frame, int neighbours, const Eigen::Vector3f& eye) {
  RgbdPoints r;
  for (const auto& q : frame)
    if (std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z)) {
      r.points.emplace_back(q.x, q.y, q.z);
      r.rgb.push_back(q.rgba & 0xffffffu);
    }
  r.normals = estimateNormals(r.points, NeighbourGraph::byCount(r.points, SpatialIndex(r.points), neighbours), &r.variation);
  for (std::size_t i = 0; i < r.points.size(); ++i)  // a single view: towards the camera
    if (r.normals[i].allFinite() && r.normals[i].dot(eye - r.points[i]) < 0) r.normals[i] = -r.normals[i];
  return r;
}

int runRgbdPhoto(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"help"});
  if (a.has("help")) { std::fputs(kRgbdPhotoUsage, stdout); return 0; }
  a.allowOnly({"perturb", "seed", "neighbours", "sample-step", "max-rms"});
  if (a.positional.size() != 2) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "FRAME DIR");
  OrganizedCameraOptions o;
  o.sample_step = a.integer("sample-step", o.sample_step);
  o.max_rms_pixels = a.number("max-rms", o.max_rms_pixels);
  requireInRange("sample-step", o.sample_step, 1, 64);  // the options' own names in messages
  requireInRange("max-rms", o.max_rms_pixels, 1e-9, 1e6);
  o.validate();
  double perturb_deg = 0, perturb_m = 0;
  if (a.has("perturb")) {
    const std::vector<std::string> parts = splitList(a.text("perturb", ""));
    bool ok = parts.size() == 2;
    try {
      if (ok) perturb_deg = std::stod(parts[0]), perturb_m = std::stod(parts[1]);
    } catch (const std::exception&) {
      ok = false;
    }
    if (!ok || !(perturb_deg >= 0 && perturb_deg <= 45) || !(perturb_m >= 0 && perturb_m <= 1e3))
      throw InvalidParameter("perturb", a.text("perturb", ""), "DEG,M with DEG in [0, 45] and M in [0, 1000]");
  }
  const std::size_t seed = a.count("seed", 1);
  {  // the frame must not be one of the files written into DIR
    std::error_code ec;
    for (const char* name : {"cloud.pcd", "photo.png", "photo.txt", "photo_start.txt"})
      if (std::filesystem::equivalent(a.positional[0], std::filesystem::path(a.positional[1]) / name, ec))
        throw InvalidParameter("DIR", a.positional[1], std::string("a folder that does not hold the input as ") + name +
                                                           " (inputs are never overwritten)");
  }
  const int neighbours = a.integer("neighbours", 30);
  requireInRange("neighbours", neighbours, 3, 1000);
  // Inputs read and checked before anything is written.
  const pcl::PCLPointCloud2 blob = loadCloud(a.positional[0]);
  if (!hasField(blob, "rgb") && !hasField(blob, "rgba"))
    throw InvalidInput("'" + a.positional[0] + "' has no rgb or rgba field: an RGB-D frame carries the colours of its photo");
  pcl::PointCloud<pcl::PointXYZRGBA> frame;
  pcl::fromPCLPointCloud2(blob, frame);
  const OrganizedCloudCamera real = cameraOfOrganizedCloud(frame, o);
  std::printf("read %s: %ux%u grid; camera fx %.3f fy %.3f cx %.3f cy %.3f, fit %.4f px RMS (max %.4f) on %zu points\n",
              a.positional[0].c_str(), frame.width, frame.height, real.fit.camera.fx, real.fit.camera.fy,
              real.fit.camera.cx, real.fit.camera.cy, real.fit.rms_pixels, real.fit.max_pixels, real.fit.points);
  const RgbdPoints finite = rgbdPoints(frame, neighbours, real.fit.pose.translation().cast<float>());

  const std::string dir = a.positional[1];
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (!std::filesystem::is_directory(dir))
    throw IoError("cannot create folder '" + dir + "'" + (ec ? ": " + ec.message() : std::string()));
  checkOutputPath((std::filesystem::path(dir) / "photo.txt").string());  // a folder that takes files
  pcl::PointCloud<pcl::PointXYZRGB> out;
  out.resize(finite.points.size());
  for (std::size_t i = 0; i < finite.points.size(); ++i) {
    out[i].getVector3fMap() = finite.points[i];
    out[i].rgba = finite.rgb[i] | 0xff000000u;
  }
  pcl::PCLPointCloud2 cloud_blob;
  pcl::toPCLPointCloud2(out, cloud_blob);
  setNormals(cloud_blob, finite.normals, &finite.variation);
  saveCloudAtomic(dir + "/cloud.pcd", cloud_blob);
  writeImageAtomic(dir + "/photo.png", real.photo.image);
  PhotoListEntry e;
  e.image = "photo.png";
  e.camera = real.photo.camera;
  e.pose = real.photo.pose;
  savePhotoListAtomic(dir + "/photo.txt", {e});
  std::printf("wrote %s/cloud.pcd (%zu points, normals, rgb), %s/photo.png, %s/photo.txt\n", dir.c_str(),
              finite.points.size(), dir.c_str(), dir.c_str());
  if (a.has("perturb")) {
    Random rng(seed * 7 + 5);
    PoseDelta d;
    d.yaw = rng.uniform(-perturb_deg, perturb_deg) * M_PI / 180;
    d.pitch = rng.uniform(-perturb_deg, perturb_deg) * M_PI / 180;
    d.roll = rng.uniform(-perturb_deg / 2, perturb_deg / 2) * M_PI / 180;
    d.translation = rng.uniform3(-perturb_m, perturb_m);
    PhotoListEntry wrong = e;
    wrong.pose = applyPoseDelta(e.pose, d);
    savePhotoListAtomic(dir + "/photo_start.txt", {wrong});
    std::vector<Eigen::Vector3d> probe;
    for (std::size_t i = 0; i < finite.points.size(); i += 13) probe.push_back(finite.points[i].cast<double>());
    std::printf("wrote %s/photo_start.txt (%.2f px from the true pose)\n", dir.c_str(),
                meanReprojectionError(e.camera, e.pose, wrong.pose, probe));
  }
  return 0;
}

}  // namespace paps::cli
