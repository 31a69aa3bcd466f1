#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/fusion/synthetic_image.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace fusion_synthetic_image_test {

// A square plate of side 2 m at 5 m in front of the camera, sampled every `step` metres.
paps::Positions plate(float step) {
  paps::Positions p;
  const int n = static_cast<int>(std::lround(2 / step));
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j) p.push_back({-1 + i * step, 5.f, -1 + j * step});
  return p;
}

TEST(SyntheticImage, FillsTheGapsBetweenSamplesWithoutWideningTheSilhouette) {
  const auto camera = paps::CameraIntrinsics::fromFieldOfView(160, 160, 60);  // fx = 138.6
  const auto pose = paps::lookAt({0, 0, 0}, {0, 1, 0});
  const auto points = plate(0.08f);  // 2.2 px apart at 5 m
  const auto image = paps::renderSyntheticImage(points, std::vector<float>(points.size(), 0.7f), camera, pose);
  // The plate covers x, y in cx +- 27.7 px.
  const double half = camera.fx * 1.0 / 5.0;
  int inside = 0, inside_defined = 0, outside_defined = 0;
  for (int y = 0; y < 160; ++y)
    for (int x = 0; x < 160; ++x) {
      const double dx = std::abs(x - camera.cx), dy = std::abs(y - camera.cy);
      const bool defined = image.mask.at<std::uint8_t>(y, x) != 0;
      if (dx < half - 1 && dy < half - 1) {
        ++inside;
        inside_defined += defined;
        if (defined) EXPECT_NEAR(image.intensity.at<float>(y, x), 0.7f, 1e-5f);
      }
      if (dx > half + 1.5 || dy > half + 1.5) outside_defined += defined;
    }
  EXPECT_EQ(inside_defined, inside);
  EXPECT_EQ(outside_defined, 0);
}

TEST(SyntheticImage, TheNearerSurfaceWins) {
  const auto camera = paps::CameraIntrinsics::fromFieldOfView(120, 120, 60);
  const auto pose = paps::lookAt({0, 0, 0}, {0, 1, 0});
  paps::Positions points = plate(0.1f);
  std::vector<float> values(points.size(), 0.2f);
  for (const auto& p : plate(0.04f)) {  // a denser plate behind, at 8 m
    points.push_back({p.x() * 2, 8.f, p.z() * 2});
    values.push_back(0.9f);
  }
  const auto image = paps::renderSyntheticImage(points, values, camera, pose);
  EXPECT_NEAR(image.intensity.at<float>(static_cast<int>(camera.cy), static_cast<int>(camera.cx)), 0.2f, 1e-5f);
  EXPECT_NEAR(image.depth.at<float>(static_cast<int>(camera.cy), static_cast<int>(camera.cx)), 5.f, 0.01f);
  // Beyond the front plate (cx +- 21 px), on the back one (cx +- 26 px).
  EXPECT_NEAR(image.intensity.at<float>(static_cast<int>(camera.cy), static_cast<int>(camera.cx) + 24), 0.9f, 1e-5f);
}

TEST(SyntheticImage, BadInputThrows) {
  const auto camera = paps::CameraIntrinsics::fromFieldOfView(64, 48, 60);
  const auto pose = paps::lookAt({0, 0, 0}, {0, 1, 0});
  const auto points = plate(0.1f);
  EXPECT_THROW(paps::renderSyntheticImage(points, std::vector<float>(3), camera, pose), paps::InvalidInput);
  paps::SyntheticImageParameters p;
  p.fill_radius = -1;
  EXPECT_THROW(paps::renderSyntheticImage(points, std::vector<float>(points.size()), camera, pose, p), paps::InvalidParameter);
  // No point in view: an empty image, not an error.
  const auto away = paps::renderSyntheticImage(points, std::vector<float>(points.size()), camera, paps::lookAt({0, 0, 0}, {0, -1, 0}));
  EXPECT_EQ(cv::countNonZero(away.mask), 0);
}

}  // namespace fusion_synthetic_image_test
