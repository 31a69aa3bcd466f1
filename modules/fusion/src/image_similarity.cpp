#include <paps/fusion/image_similarity.h>

#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

#include <paps/core/error.h>

namespace paps {
namespace {

cv::Mat toGreyFloat(const cv::Mat& image) {
  if (image.empty()) throw InvalidInput("image comparison: empty image");
  cv::Mat grey;
  if (image.type() == CV_8UC3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
    grey.convertTo(grey, CV_32F, 1.0 / 255);
  } else if (image.type() == CV_8UC1) {
    image.convertTo(grey, CV_32F, 1.0 / 255);
  } else if (image.type() == CV_32FC1) {
    grey = image;
  } else {
    throw InvalidInput("image comparison: type " + std::to_string(image.type()) + " (expected 8-bit grey or BGR, or 32-bit float grey)");
  }
  return grey;
}

cv::Mat definedMask(const cv::Mat& mask, const cv::Size& size) {
  if (mask.empty()) return cv::Mat(size, CV_8U, cv::Scalar(255));
  if (mask.size() != size || mask.type() != CV_8UC1)
    throw InvalidInput("image comparison: mask must be 8-bit, one channel, the image's size");
  return mask;
}

const double kWorstCost = 4.0;

}  // namespace

void HogParameters::validate() const {
  requireInRange("hog bins", bins, 2, 64);
  requireInRange("hog window", window, 3, 256);
  requireInRange("hog stride", stride, 1, 256);
  requireInRange("hog centre_sigma", centre_sigma, 0.01, 100.0);
  requireInRange("hog min_coverage", min_coverage, 0.0, 1.0);
}

void ImageMetricParameters::validate() const {
  requireInRange("alpha", alpha, 0.0, 1000.0);
  requireInRange("nmi_bins", nmi_bins, 2, 256);
  hog.validate();
}

const char* imageMetricName(ImageMetric metric) {
  switch (metric) {
    case ImageMetric::NMI: return "NMI";
    case ImageMetric::DHOG: return "DHOG";
    case ImageMetric::MIDHOG: return "MIDHOG";
  }
  return "?";
}

HogField computeHogField(const cv::Mat& image, const cv::Mat& mask_in, const HogParameters& p) {
  p.validate();
  const cv::Mat grey = toGreyFloat(image);
  const cv::Mat mask = definedMask(mask_in, grey.size());
  const int w = grey.cols, h = grey.rows;
  // Per-bin gradient magnitude images (linear vote between the two nearest bins).
  std::vector<cv::Mat> planes(p.bins);
  for (auto& b : planes) b = cv::Mat(h, w, CV_32F, cv::Scalar(0));
  cv::Mat defined(h, w, CV_32F, cv::Scalar(0));
  const float bin_width = static_cast<float>(M_PI / p.bins);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!mask.at<std::uint8_t>(y, x)) continue;
      defined.at<float>(y, x) = 1;
      if (x == 0 || y == 0 || x == w - 1 || y == h - 1) continue;
      if (!mask.at<std::uint8_t>(y, x - 1) || !mask.at<std::uint8_t>(y, x + 1) || !mask.at<std::uint8_t>(y - 1, x) ||
          !mask.at<std::uint8_t>(y + 1, x))
        continue;
      const float gx = 0.5f * (grey.at<float>(y, x + 1) - grey.at<float>(y, x - 1));
      const float gy = 0.5f * (grey.at<float>(y + 1, x) - grey.at<float>(y - 1, x));
      const float m = std::sqrt(gx * gx + gy * gy);
      if (!(m > 0)) continue;
      float a = std::atan2(gy, gx);
      if (a < 0) a += static_cast<float>(M_PI);
      const float f = a / bin_width - 0.5f;
      int b0 = static_cast<int>(std::floor(f));
      const float t = f - b0;
      const int b1 = (b0 + 1) % p.bins;
      b0 = (b0 + p.bins) % p.bins;
      planes[b0].at<float>(y, x) += (1 - t) * m;
      planes[b1].at<float>(y, x) += t * m;
    }
  for (auto& b : planes) cv::boxFilter(b, b, -1, cv::Size(p.window, p.window), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  cv::boxFilter(defined, defined, -1, cv::Size(p.window, p.window), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);

  HogField f;
  f.bins = p.bins;
  const int half = p.window / 2;
  f.cols = std::max(0, (w - 2 * half - 1) / p.stride + 1);
  f.rows = std::max(0, (h - 2 * half - 1) / p.stride + 1);
  f.histograms.assign(static_cast<std::size_t>(f.rows) * f.cols * p.bins, 0.f);
  f.valid.assign(static_cast<std::size_t>(f.rows) * f.cols, 0);
  f.weight.assign(static_cast<std::size_t>(f.rows) * f.cols, 0.f);
  const double s = p.centre_sigma * 0.5 * std::hypot(w, h);
  const float area = static_cast<float>(p.window * p.window);
  // Normalisation floor: a window with less gradient than a faint edge stays near zero.
  const float floor = 0.02f * p.window;
  for (int r = 0; r < f.rows; ++r)
    for (int c = 0; c < f.cols; ++c) {
      const int x = half + c * p.stride, y = half + r * p.stride;
      const std::size_t k = static_cast<std::size_t>(r) * f.cols + c;
      f.weight[k] = static_cast<float>(std::exp(-(std::pow(x - 0.5 * (w - 1), 2) + std::pow(y - 0.5 * (h - 1), 2)) / (2 * s * s)));
      f.valid[k] = defined.at<float>(y, x) >= p.min_coverage * area;
      float* hist = &f.histograms[k * p.bins];
      double norm2 = 0;
      for (int b = 0; b < p.bins; ++b) {
        hist[b] = planes[b].at<float>(y, x);
        norm2 += double(hist[b]) * hist[b];
      }
      const float scale = static_cast<float>(1.0 / std::sqrt(norm2 + double(floor) * floor));
      for (int b = 0; b < p.bins; ++b) hist[b] *= scale;
    }
  return f;
}

double distanceBetweenHogFields(const HogField& a, const HogField& b, HogWindows windows) {
  if (a.rows != b.rows || a.cols != b.cols || a.bins != b.bins)
    throw InvalidInput("DHOG: HOG fields of different geometry");
  double sum = 0, weight = 0;
  for (std::size_t k = 0; k < a.valid.size(); ++k) {
    if (!a.valid[k] || (windows == HogWindows::ValidInBoth && !b.valid[k])) continue;
    double d = 0;
    for (int i = 0; i < a.bins; ++i) {
      const double e = a.histograms[k * a.bins + i] - b.histograms[k * a.bins + i];
      d += e * e;
    }
    sum += a.weight[k] * d;
    weight += a.weight[k];
  }
  return weight > 0 ? sum / weight : std::numeric_limits<double>::quiet_NaN();
}

double normalizedMutualInformation(const cv::Mat& a_in, const cv::Mat& a_mask_in, const cv::Mat& b_in,
                                   const cv::Mat& b_mask_in, int bins) {
  requireInRange("nmi bins", bins, 2, 256);
  const cv::Mat a = toGreyFloat(a_in), b = toGreyFloat(b_in);
  if (a.size() != b.size()) throw InvalidInput("NMI: images of different sizes");
  const cv::Mat am = definedMask(a_mask_in, a.size()), bm = definedMask(b_mask_in, b.size());
  float alo = INFINITY, ahi = -INFINITY, blo = INFINITY, bhi = -INFINITY;
  std::size_t shared = 0;
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!am.at<std::uint8_t>(y, x) || !bm.at<std::uint8_t>(y, x)) continue;
      const float u = a.at<float>(y, x), v = b.at<float>(y, x);
      if (!std::isfinite(u) || !std::isfinite(v)) continue;
      alo = std::min(alo, u); ahi = std::max(ahi, u);
      blo = std::min(blo, v); bhi = std::max(bhi, v);
      ++shared;
    }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (shared < 16 || !(ahi > alo) || !(bhi > blo)) return nan;
  std::vector<double> joint(static_cast<std::size_t>(bins) * bins, 0.0), pa(bins, 0.0), pb(bins, 0.0);
  const float sa = bins / (ahi - alo) * 0.99999f, sb = bins / (bhi - blo) * 0.99999f;
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!am.at<std::uint8_t>(y, x) || !bm.at<std::uint8_t>(y, x)) continue;
      const float u = a.at<float>(y, x), v = b.at<float>(y, x);
      if (!std::isfinite(u) || !std::isfinite(v)) continue;
      const int i = std::min(bins - 1, static_cast<int>((u - alo) * sa));
      const int j = std::min(bins - 1, static_cast<int>((v - blo) * sb));
      joint[static_cast<std::size_t>(i) * bins + j] += 1;
      pa[i] += 1;
      pb[j] += 1;
    }
  auto entropy = [&](const std::vector<double>& p) {
    double e = 0;
    for (double c : p)
      if (c > 0) e -= c / shared * std::log(c / shared);
    return e;
  };
  const double hab = entropy(joint);
  return hab > 0 ? (entropy(pa) + entropy(pb)) / hab : nan;
}

ImageComparator::ImageComparator(const cv::Mat& real, const ImageMetricParameters& parameters)
    : parameters_(parameters) {
  parameters_.validate();
  grey_ = toGreyFloat(real).clone();
  if (parameters_.metric != ImageMetric::NMI) hog_ = computeHogField(grey_, cv::Mat(), parameters_.hog);
}

double ImageComparator::cost(const cv::Mat& synthetic, const cv::Mat& mask) const {
  if (synthetic.size() != grey_.size()) throw InvalidInput("image comparison: synthetic and real images differ in size");
  double nmi_cost = 0, dhog = 0;
  if (parameters_.metric != ImageMetric::DHOG) {
    if (cv::countNonZero(mask) < static_cast<int>(grey_.total() / 10)) return kWorstCost;
    const double nmi = normalizedMutualInformation(grey_, cv::Mat(), synthetic, mask, parameters_.nmi_bins);
    if (!std::isfinite(nmi)) return kWorstCost;
    nmi_cost = 2.0 - nmi;
  }
  if (parameters_.metric != ImageMetric::NMI) {
    const HogField s = computeHogField(synthetic, mask, parameters_.hog);
    std::size_t valid = 0;
    for (auto v : s.valid) valid += v;
    if (valid < s.valid.size() / 10) return kWorstCost;
    dhog = distanceBetweenHogFields(hog_, s, parameters_.dhog_windows);
    if (!std::isfinite(dhog)) return kWorstCost;
  }
  switch (parameters_.metric) {
    case ImageMetric::NMI: return nmi_cost;
    case ImageMetric::DHOG: return dhog;
    case ImageMetric::MIDHOG: return nmi_cost + parameters_.alpha * dhog;
  }
  return kWorstCost;
}

}  // namespace paps
