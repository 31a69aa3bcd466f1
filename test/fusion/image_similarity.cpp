#include <gtest/gtest.h>

#include <cmath>

#include <opencv2/imgproc.hpp>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/fusion/image_similarity.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace fusion_image_similarity_test {

// A textured test image: rectangles of several grey levels on a gradient.
cv::Mat pattern(int w = 160, int h = 120) {
  cv::Mat m(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) m.at<float>(y, x) = 0.2f + 0.3f * x / w;
  cv::rectangle(m, cv::Rect(20, 15, 30, 40), cv::Scalar(0.9), cv::FILLED);
  cv::rectangle(m, cv::Rect(70, 60, 50, 25), cv::Scalar(0.05), cv::FILLED);
  cv::rectangle(m, cv::Rect(110, 10, 20, 30), cv::Scalar(0.6), cv::FILLED);
  cv::circle(m, cv::Point(45, 90), 15, cv::Scalar(0.75), cv::FILLED);
  return m;
}

cv::Mat shifted(const cv::Mat& m, int dx) {
  cv::Mat out;
  const cv::Mat t = (cv::Mat_<double>(2, 3) << 1, 0, dx, 0, 1, 0);
  cv::warpAffine(m, out, t, m.size(), cv::INTER_NEAREST, cv::BORDER_REPLICATE);
  return out;
}

TEST(ImageSimilarity, NmiIsTwoForIdenticalOrInvertedImagesAndNearOneForIndependentOnes) {
  const cv::Mat a = pattern();
  EXPECT_NEAR(paps::normalizedMutualInformation(a, cv::Mat(), a, cv::Mat()), 2.0, 1e-9);
  const cv::Mat inverted = 1.0 - a;  // another modality, same information
  // Bins fall on slightly different levels once inverted: close to 2, not exactly.
  EXPECT_GT(paps::normalizedMutualInformation(a, cv::Mat(), inverted, cv::Mat()), 1.9);
  cv::Mat noise(a.size(), CV_32F);
  paps::Random rng(3);
  for (int y = 0; y < noise.rows; ++y)
    for (int x = 0; x < noise.cols; ++x) noise.at<float>(y, x) = static_cast<float>(rng.uniform());
  EXPECT_LT(paps::normalizedMutualInformation(a, cv::Mat(), noise, cv::Mat()), 1.1);
}

TEST(ImageSimilarity, NmiOnlyCountsPixelsDefinedInBothMasks) {
  const cv::Mat a = pattern();
  cv::Mat b = a.clone(), mask(a.size(), CV_8U, cv::Scalar(255));
  cv::rectangle(b, cv::Rect(0, 0, 80, 120), cv::Scalar(0.5), cv::FILLED);  // garbage where undefined
  cv::rectangle(mask, cv::Rect(0, 0, 80, 120), cv::Scalar(0), cv::FILLED);
  EXPECT_NEAR(paps::normalizedMutualInformation(a, cv::Mat(), b, mask), 2.0, 1e-9);
  EXPECT_LT(paps::normalizedMutualInformation(a, cv::Mat(), b, cv::Mat()), 1.9);
}

TEST(ImageSimilarity, DhogIsZeroForIdenticalImagesContrastInvariantAndGrowsWithShift) {
  const cv::Mat a = pattern();
  const auto ha = paps::computeHogField(a, cv::Mat());
  EXPECT_NEAR(paps::distanceBetweenHogFields(ha, ha), 0.0, 1e-12);
  // Normalised histograms: halving the contrast moves DHOG less than a 3-pixel shift does
  // (not zero: the normalisation floor keeps faint gradients faint).
  const cv::Mat contrast = 0.5 * a + 0.3;
  const double d_contrast = paps::distanceBetweenHogFields(ha, paps::computeHogField(contrast, cv::Mat()));
  double previous = 0;
  std::vector<double> d;
  for (int dx : {1, 3, 6}) {
    d.push_back(paps::distanceBetweenHogFields(ha, paps::computeHogField(shifted(a, dx), cv::Mat())));
    EXPECT_GT(d.back(), previous) << dx;
    previous = d.back();
  }
  EXPECT_LT(d_contrast, d[1]);
}

TEST(ImageSimilarity, MidhogIsZeroForIdenticalImagesAndSymmetric) {
  const cv::Mat a = pattern(), b = shifted(pattern(), 2);
  paps::ImageMetricParameters p;
  const paps::ImageComparator ca(a, p), cb(b, p);
  const cv::Mat full(a.size(), CV_8U, cv::Scalar(255));
  EXPECT_NEAR(ca.cost(a, full), 0.0, 1e-9);
  EXPECT_NEAR(ca.cost(b, full), cb.cost(a, full), 1e-9);
  EXPECT_GT(ca.cost(b, full), 0.05);
  // MIDHOG = (2 - NMI) + alpha * DHOG.
  p.metric = paps::ImageMetric::NMI;
  const double nmi_cost = paps::ImageComparator(a, p).cost(b, full);
  p.metric = paps::ImageMetric::DHOG;
  const double dhog = paps::ImageComparator(a, p).cost(b, full);
  EXPECT_NEAR(ca.cost(b, full), nmi_cost + 10 * dhog, 1e-9);
}

// A synthetic image that covers only the part of the photo it matches best must not look
// better than one that covers all of the photo and matches it slightly worse everywhere: with
// DHOG over the windows both cover, it does (the bias seen on a real Kinect frame).
TEST(ImageSimilarity, DhogOverThePhotosWindowsDoesNotRewardCoveringLess) {
  const cv::Mat photo = pattern();
  const cv::Mat full(photo.size(), CV_8U, cv::Scalar(255));
  const cv::Mat near_miss = shifted(photo, 1);        // everywhere, 1 px off
  cv::Mat partial_mask = full.clone();                 // exact, but only over the left third
  cv::rectangle(partial_mask, cv::Rect(55, 0, 105, 120), cv::Scalar(0), cv::FILLED);
  cv::Mat partial = photo.clone();
  partial.setTo(0, partial_mask == 0);
  paps::ImageMetricParameters p;
  p.metric = paps::ImageMetric::DHOG;
  EXPECT_EQ(p.dhog_windows, paps::HogWindows::ValidInFirst);  // the default
  const paps::ImageComparator photo_windows(photo, p);
  EXPECT_NEAR(photo_windows.cost(photo, full), 0.0, 1e-12);
  EXPECT_LT(photo_windows.cost(near_miss, full), photo_windows.cost(partial, partial_mask));
  p.dhog_windows = paps::HogWindows::ValidInBoth;
  const paps::ImageComparator shared_windows(photo, p);
  EXPECT_GT(shared_windows.cost(near_miss, full), shared_windows.cost(partial, partial_mask));
  // Both agree where the synthetic image covers everything.
  EXPECT_NEAR(shared_windows.cost(near_miss, full), photo_windows.cost(near_miss, full), 1e-12);
}

TEST(ImageSimilarity, HolesAddNoEdges) {
  // A flat synthetic image with holes has no gradient: its histograms stay near zero.
  cv::Mat flat(120, 160, CV_32F, cv::Scalar(0.5)), mask(120, 160, CV_8U, cv::Scalar(255));
  for (int y = 0; y < 120; y += 4)
    for (int x = 0; x < 160; x += 5) mask.at<std::uint8_t>(y, x) = 0;
  flat.setTo(0, mask == 0);
  const auto h = paps::computeHogField(flat, mask);
  double total = 0;
  for (float v : h.histograms) total += v;
  EXPECT_NEAR(total, 0.0, 1e-9);
}

TEST(ImageSimilarity, BadInputThrows) {
  EXPECT_THROW(paps::computeHogField(cv::Mat(), cv::Mat()), paps::InvalidInput);
  EXPECT_THROW(paps::computeHogField(cv::Mat(10, 10, CV_64F), cv::Mat()), paps::InvalidInput);
  EXPECT_THROW(paps::computeHogField(pattern(), cv::Mat(5, 5, CV_8U)), paps::InvalidInput);
  paps::HogParameters bad;
  bad.window = 1;
  EXPECT_THROW(paps::computeHogField(pattern(), cv::Mat(), bad), paps::InvalidParameter);
  EXPECT_THROW(paps::normalizedMutualInformation(pattern(), cv::Mat(), pattern(80, 60), cv::Mat()), paps::InvalidInput);
  EXPECT_TRUE(std::isnan(paps::normalizedMutualInformation(cv::Mat(40, 40, CV_32F, cv::Scalar(1)), cv::Mat(),
                                                           pattern(40, 40), cv::Mat())));  // a flat image
  paps::ImageMetricParameters p;
  p.alpha = -1;
  EXPECT_THROW(paps::ImageComparator(pattern(), p), paps::InvalidParameter);
  EXPECT_THROW(paps::ImageComparator(pattern(), {}).cost(pattern(80, 60), cv::Mat(60, 80, CV_8U, cv::Scalar(255))),
               paps::InvalidInput);
}

}  // namespace fusion_image_similarity_test
