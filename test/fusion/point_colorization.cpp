// PointColorization (manuscript 4.5.1): consensus colours from several registered photos.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include <pcl/common/io.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/fusion/colour_space.h>
#include <paps/fusion/point_colorization.h>
#include <paps/fusion/synthetic_street.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace fusion_point_colorization_test {

using paps::CameraIntrinsics;
using paps::CameraPose;
using Cloud = pcl::PointCloud<pcl::PointXYZRGB>;

// A plane z = 0 of 21 x 21 points (10 cm apart) seen from 5 m above by a camera looking down.
struct PlaneScene {
  Cloud::Ptr cloud{new Cloud};
  CameraIntrinsics camera = CameraIntrinsics::fromFieldOfView(64, 48, 60);
  CameraPose pose = paps::lookAt({0, 0, 5}, {0, 0, 0}, {0, 1, 0});
  PlaneScene() {
    for (int i = -10; i <= 10; ++i)
      for (int j = -10; j <= 10; ++j) {
        pcl::PointXYZRGB p;
        p.x = 0.1f * i;
        p.y = 0.1f * j;
        p.z = 0;
        p.r = 1;
        p.g = 2;
        p.b = 3;
        cloud->push_back(p);
      }
  }
};

TEST(PointColorization, UniformPhotoGivesItsColourAndUnseenPointsKeepTheirs) {
  PlaneScene s;
  pcl::PointXYZRGB far;
  far.x = 100;
  far.y = 0;
  far.z = 0;  // outside every photo
  far.r = 9;
  far.g = 8;
  far.b = 7;
  s.cloud->push_back(far);
  const cv::Mat image(s.camera.height, s.camera.width, CV_8UC3, cv::Scalar(30, 120, 200));  // BGR
  paps::PointColorization<pcl::PointXYZRGB> colorize;
  colorize.setInputCloud(s.cloud);
  colorize.addView(image, s.camera, s.pose);
  colorize.addView(image, s.camera, s.pose);
  Cloud out;
  colorize.filter(out);
  ASSERT_EQ(out.size(), s.cloud->size());
  for (std::size_t i = 0; i + 1 < out.size(); ++i) {
    EXPECT_EQ(out[i].r, 200);
    EXPECT_EQ(out[i].g, 120);
    EXPECT_EQ(out[i].b, 30);
  }
  EXPECT_EQ(out.back().r, 9);
  EXPECT_EQ(out.back().b, 7);
  EXPECT_EQ(colorize.getReport().unseen, 1u);
  EXPECT_EQ(colorize.getReport().coloured, s.cloud->size() - 1);
  EXPECT_EQ(colorize.getReport().non_finite, 0u);

  // Half the points indexed: the others keep their colour and are not counted as non-finite
  // (they enter as NaN); no index at all is said so, not "no finite point".
  pcl::IndicesPtr half(new pcl::Indices);
  for (std::size_t i = 0; i + 1 < s.cloud->size(); i += 2) half->push_back(static_cast<int>(i));
  colorize.setIndices(half);
  Cloud out2;
  colorize.filter(out2);
  EXPECT_EQ(colorize.getReport().non_finite, 0u);
  EXPECT_EQ(colorize.getReport().coloured, half->size());
  EXPECT_EQ(out2[0].r, 200);
  EXPECT_EQ(out2[1].r, (*s.cloud)[1].r);
  colorize.setIndices(pcl::IndicesPtr(new pcl::Indices));
  try {
    colorize.filter(out2);
    ADD_FAILURE() << "empty indices accepted";
  } catch (const paps::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("the indices are empty"), std::string::npos) << e.what();
  }
}

// The type of PCL's RGB-D grabbers: the photo's colour goes to r, g, b; alpha is kept.
TEST(PointColorization, RgbaCloudsKeepTheirAlpha) {
  PlaneScene s;
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZRGBA>>();
  pcl::copyPointCloud(*s.cloud, *cloud);
  for (std::size_t i = 0; i < cloud->size(); ++i) (*cloud)[i].a = static_cast<std::uint8_t>(i % 200);
  const cv::Mat image(s.camera.height, s.camera.width, CV_8UC3, cv::Scalar(30, 120, 200));  // BGR
  paps::PointColorization<pcl::PointXYZRGBA> colorize;
  colorize.setInputCloud(cloud);
  colorize.addView(image, s.camera, s.pose);
  pcl::PointCloud<pcl::PointXYZRGBA> out;
  colorize.filter(out);
  ASSERT_EQ(out.size(), cloud->size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(out[i].r, 200) << i;
    EXPECT_EQ(out[i].g, 120) << i;
    EXPECT_EQ(out[i].b, 30) << i;
    EXPECT_EQ(out[i].a, (*cloud)[i].a) << i;
  }
  EXPECT_EQ(colorize.getReport().coloured, cloud->size());
}

TEST(PointColorization, WeightedMedianOfCandidates) {
  paps::ColourCandidates c;
  c.offsets = {0, 2, 5};
  c.colour = {Eigen::Vector3f::Constant(0.1f), Eigen::Vector3f::Constant(0.5f), Eigen::Vector3f(0.2f, 0.9f, 0.4f),
              Eigen::Vector3f(0.3f, 0.1f, 0.5f), Eigen::Vector3f(0.9f, 0.2f, 0.6f)};
  c.photo = {0, 1, 0, 1, 2};
  EXPECT_TRUE(paps::medianCandidate(c, 0).isApprox(Eigen::Vector3f::Constant(0.3f)));  // two equal weights: the mean
  EXPECT_TRUE(paps::medianCandidate(c, 1).isApprox(Eigen::Vector3f(0.3f, 0.2f, 0.5f)));  // per channel
  const std::vector<float> w = {1, 0.1f, 0.1f, 0.1f, 1};
  EXPECT_TRUE(paps::medianCandidate(c, 0, &w).isApprox(Eigen::Vector3f::Constant(0.1f)));
  EXPECT_TRUE(paps::medianCandidate(c, 1, &w).isApprox(Eigen::Vector3f(0.9f, 0.2f, 0.6f)));
}

TEST(PointColorization, ProgressCallbackCancels) {
  PlaneScene s;
  const cv::Mat image(s.camera.height, s.camera.width, CV_8UC3, cv::Scalar(30, 120, 200));
  cv::Mat noisy = image.clone();
  cv::randu(noisy, cv::Scalar::all(0), cv::Scalar::all(255));
  paps::PointColorization<pcl::PointXYZRGB> c;
  c.setInputCloud(s.cloud);
  c.addView(image, s.camera, s.pose);
  c.addView(noisy, s.camera, s.pose);
  int calls = 0;
  c.setProgressCallback([&](const std::string&, float) { return ++calls < 2; });
  Cloud out;
  EXPECT_THROW(c.filter(out), paps::Cancelled);
}

TEST(PointColorization, BadInputThrows) {
  PlaneScene s;
  const cv::Mat image(s.camera.height, s.camera.width, CV_8UC3, cv::Scalar(1, 2, 3));
  paps::PointColorization<pcl::PointXYZRGB> c;
  Cloud out;
  EXPECT_THROW(c.filter(out), paps::InvalidInput);  // no cloud
  c.setInputCloud(s.cloud);
  EXPECT_THROW(c.filter(out), paps::InvalidInput);  // no view
  EXPECT_THROW(c.addView(cv::Mat(), s.camera, s.pose), paps::InvalidInput);
  EXPECT_THROW(c.addView(cv::Mat(s.camera.height, s.camera.width, CV_8UC1), s.camera, s.pose), paps::InvalidInput);
  EXPECT_THROW(c.addView(cv::Mat(10, 10, CV_8UC3), s.camera, s.pose), paps::InvalidParameter);
  c.addView(image, s.camera, s.pose);
  Cloud::Ptr empty(new Cloud);
  c.setInputCloud(empty);
  EXPECT_THROW(c.filter(out), paps::InvalidInput);
  Cloud::Ptr nans(new Cloud);
  pcl::PointXYZRGB p;
  p.x = p.y = p.z = NAN;
  nans->push_back(p);
  nans->push_back(p);
  c.setInputCloud(nans);
  EXPECT_THROW(c.filter(out), paps::InvalidInput);
  paps::PointColorizationParameters bad;
  bad.neighbours = 0;
  EXPECT_THROW(c.setParameters(bad), paps::InvalidParameter);
  bad = {};
  bad.smoothness = -1;
  EXPECT_THROW(c.setParameters(bad), paps::InvalidParameter);
  bad = {};
  bad.huber_threshold = 0;
  EXPECT_THROW(c.setParameters(bad), paps::InvalidParameter);
  bad = {};
  bad.iterations = 1000000;
  EXPECT_THROW(c.setParameters(bad), paps::InvalidParameter);
  bad = {};
  bad.occlusion_map_scale = 2;
  EXPECT_THROW(c.setParameters(bad), paps::InvalidParameter);
  bad = {};
  bad.tolerance = NAN;
  EXPECT_THROW(c.setParameters(bad), paps::InvalidParameter);
}

// The street, three photos of the same facades; a van the scan does not contain stands in
// front of the middle camera. The true colour of a point is what a photo without the van and
// without noise records: exposure * albedo * irradiance. Texture finer than a pixel (about 4 cm
// on the facades: brick courses and 1.2 cm mortar joints) is aliased in every photo, so no
// method can recover it: the error is measured on the points whose 8 nearest neighbours have
// the same true colour (within 0.03), i.e. away from texture, window and shadow edges.
struct StreetColours {
  paps::synthetic::StreetScene scene;
  paps::synthetic::StreetScan scan;
  std::vector<paps::RegisteredPhoto> photos;
  std::vector<Eigen::Vector3f> truth;
  std::vector<std::uint8_t> measurable;  // not mortar
  static paps::synthetic::StreetOptions options() {
    paps::synthetic::StreetOptions o;
    o.length = 16;
    o.scan_step = 0.1;
    o.scan_angle_step_deg = 0.5;
    o.range_noise = 0;
    return o;
  }
  std::vector<paps::RegisteredPhoto> clean_photos;  // without the van and without noise
  StreetColours() : scene(options()), scan(scene.scan()) {
    const auto camera = CameraIntrinsics::fromFieldOfView(320, 240, 75);
    const auto poses = scene.cameraPoses(3, -2.5, 2.5, 1, 0, 8);
    for (int v = 0; v < 3; ++v) {
      paps::synthetic::PhotoOptions po;
      po.seed = 11 + v;
      po.passing_van = v == 1;
      po.van_x = poses[v].translation().x();
      photos.push_back({scene.photo(camera, poses[v], po).image, camera, poses[v]});
      paps::synthetic::PhotoOptions clean;
      clean.noise_sigma = 0;
      clean_photos.push_back({scene.photo(camera, poses[v], clean).image, camera, poses[v]});
    }
    const double exposure = paps::synthetic::PhotoOptions{}.exposure;
    for (std::size_t i = 0; i < scan.cloud.size(); ++i) {
      const Eigen::Vector3d p = scan.cloud[i].getVector3fMap().cast<double>();
      const Eigen::Vector3d n = scan.cloud[i].getNormalVector3fMap().cast<double>();
      truth.push_back((scan.albedo[i] * float(exposure * scene.irradiance(p, n))).cwiseMin(1.f));
    }
    const paps::Positions points = paps::positionsOf(scan.cloud);
    const paps::SpatialIndex index(points);
    std::vector<int> nn;
    std::vector<float> d2;
    for (std::size_t i = 0; i < points.size(); ++i) {
      index.nearestK(points[i], 9, nn, d2);
      bool uniform = true;
      for (const int j : nn) uniform = uniform && (truth[j] - truth[i]).norm() < 0.03f;
      measurable.push_back(uniform);
    }
  }
};

double rms(const std::vector<Eigen::Vector3f>& c, const std::vector<Eigen::Vector3f>& truth,
           const std::vector<std::uint8_t>& mask) {
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < c.size(); ++i)
    if (mask[i]) {
      sum += (c[i] - truth[i]).squaredNorm() / 3;
      ++n;
    }
  return std::sqrt(sum / std::max<std::size_t>(n, 1));
}

TEST(PointColorization, VanInOneOfThreeViewsIsOutvotedAndBeatsTheMean) {
  const StreetColours s;
  const paps::Positions points = paps::positionsOf(s.scan.cloud);
  const auto candidates = paps::collectColourCandidates(points, s.photos);
  // Points seen by all three photos, of which the middle one shows the van instead.
  std::vector<std::uint8_t> all3(points.size(), 0);
  std::vector<Eigen::Vector3f> mean(points.size(), Eigen::Vector3f::Zero()), median(points.size());
  std::size_t count = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::size_t c = candidates.count(i);
    for (std::size_t k = 0; k < c; ++k) mean[i] += candidates.colour[candidates.offsets[i] + k] / float(c);
    median[i] = paps::medianCandidate(candidates, i);
    // occluded by the van in the middle photo: its candidate is far from the truth
    if (c == 3 && s.measurable[i] && (candidates.colour[candidates.offsets[i] + 1] - s.truth[i]).norm() > 0.15) {
      all3[i] = 1;
      ++count;
    }
  }
  ASSERT_GT(count, 500u) << "the van should hide a good part of the middle photo";
  const std::vector<Eigen::Vector3f> input(points.size(), Eigen::Vector3f::Zero());
  paps::PointColorizationReport report;
  const auto ours = paps::colorizeFromCandidates(points, input, candidates, {}, &report);
  const double e_mean = rms(mean, s.truth, all3), e_median = rms(median, s.truth, all3), e_ours = rms(ours, s.truth, all3);
  std::printf("occluded points %zu: RMS mean %.4f median %.4f ours %.4f (%d iterations)\n", count, e_mean, e_median,
              e_ours, report.iterations);
  EXPECT_LT(e_ours, 0.5 * e_mean);
  EXPECT_LT(e_ours, 0.08);
  EXPECT_LT(e_ours, e_median);
  // Over every point seen at least once, ours is no worse than the median.
  std::vector<std::uint8_t> seen(points.size(), 0);
  for (std::size_t i = 0; i < points.size(); ++i) seen[i] = candidates.count(i) > 0 && s.measurable[i];
  const double all_median = rms(median, s.truth, seen), all_ours = rms(ours, s.truth, seen), all_mean = rms(mean, s.truth, seen);
  std::printf("all seen points: RMS mean %.4f median %.4f ours %.4f\n", all_mean, all_median, all_ours);
  EXPECT_LT(all_ours, 0.6 * all_median);
  EXPECT_LT(all_ours, all_mean);
}

// Against what the photos record without the van and without noise (the best any method can
// get from them, sub-pixel texture aliased alike), on every point seen, split by the number
// of photos: with two, one of them showing the van, the median can only average; the
// occlusion maps tell which photo to trust.
TEST(PointColorization, OcclusionMapsRecoverPointsSeenByTwoPhotos) {
  const StreetColours s;
  const paps::Positions points = paps::positionsOf(s.scan.cloud);
  const auto candidates = paps::collectColourCandidates(points, s.photos);
  const auto clean = paps::collectColourCandidates(points, s.clean_photos);
  const std::vector<Eigen::Vector3f> input(points.size(), Eigen::Vector3f::Zero());
  const auto ours = paps::colorizeFromCandidates(points, input, candidates, {});
  paps::PointColorizationParameters no_maps;
  no_maps.occlusion_map_scale = 0;
  const auto without = paps::colorizeFromCandidates(points, input, candidates, no_maps);
  double e_median[4] = {0, 0, 0, 0}, e_ours[4] = {0, 0, 0, 0}, e_without[4] = {0, 0, 0, 0};
  std::size_t count[4] = {0, 0, 0, 0};
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::size_t c = candidates.count(i);
    if (c < 2 || c > 3) continue;
    const Eigen::Vector3f truth = paps::medianCandidate(clean, i);
    bool van = false;
    for (std::size_t k = 0; k < c; ++k) {
      const auto slot = candidates.offsets[i] + std::int64_t(k);
      van = van || (candidates.photo[slot] == 1 && (candidates.colour[slot] - truth).norm() > 0.15f);
    }
    if (!van) continue;
    ++count[c];
    e_median[c] += (paps::medianCandidate(candidates, i) - truth).squaredNorm() / 3;
    e_ours[c] += (ours[i] - truth).squaredNorm() / 3;
    e_without[c] += (without[i] - truth).squaredNorm() / 3;
  }
  for (std::size_t c : {2, 3}) {
    ASSERT_GT(count[c], 200u);
    for (double* e : {e_median, e_ours, e_without}) e[c] = std::sqrt(e[c] / count[c]);
    std::printf("van-hidden points seen by %zu photos (%zu): RMS median %.4f, without maps %.4f, ours %.4f\n", c,
                count[c], e_median[c], e_without[c], e_ours[c]);
  }
  EXPECT_LT(e_ours[3], e_median[3]);
  EXPECT_LT(e_ours[3], 0.04);
  EXPECT_GT(e_median[2], 0.15);  // the median of two averages the van in
  EXPECT_LT(e_ours[2], 0.3 * e_median[2]);
  EXPECT_LT(e_ours[2], 0.06);
}

TEST(PointColorization, SameOutputWithOneAndTwoThreads) {
  const StreetColours s;
  auto cloud = s.scan.cloud.makeShared();
  Cloud outputs[2];
  for (int t = 0; t < 2; ++t) {
    paps::PointColorization<pcl::PointXYZRGBNormal> c;
    c.setNumberOfThreads(t + 1);
    c.setInputCloud(cloud);
    for (const auto& p : s.photos) c.addView(p.image, p.camera, p.pose);
    pcl::PointCloud<pcl::PointXYZRGBNormal> out;
    c.filter(out);
    pcl::copyPointCloud(out, outputs[t]);
  }
  ASSERT_EQ(outputs[0].size(), outputs[1].size());
  for (std::size_t i = 0; i < outputs[0].size(); ++i)
    ASSERT_EQ(outputs[0][i].rgba, outputs[1][i].rgba) << "point " << i;
}

}  // namespace fusion_point_colorization_test
