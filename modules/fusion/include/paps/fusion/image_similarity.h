#pragma once
// Comparing a real photo with a synthetic image of a cloud (manuscript 4.3): the images have
// different modalities (colour vs shading or laser reflectance) and the synthetic one has holes.
//  - NMI, eq. 4.2: (H(A) + H(B)) / H(A, B) over the pixels defined in both, in [1, 2];
//  - DHOG: a localised distance between Histograms of Oriented Gradients computed on sliding
//    windows, weighted towards the image centre (less distorted), 4.3.2;
//  - MIDHOG, eq. 4.3: (2 - NMI) + alpha * DHOG; 0 for identical images.
// All three are costs here (lower is better): NMI enters as 2 - NMI.
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace paps {

struct HogParameters {
  int bins = 9;                ///< unsigned orientation bins over [0, 180) degrees
  int window = 12;             ///< side of the sliding window, pixels (>= 3)
  int stride = 4;              ///< pixels between window centres
  double centre_sigma = 0.6;   ///< centre weight exp(-r^2 / (2 s^2)), s = centre_sigma * half diagonal
  double min_coverage = 0.6;   ///< a window is `valid` when this fraction of its pixels is defined
  void validate() const;
};

/// HOG of every window of an image, L2-normalised (so contrast and modality scale drop out).
/// Every window gets its histogram (zero where nothing is defined); `valid` marks those whose
/// defined pixels reach `min_coverage`.
struct HogField {
  int rows = 0, cols = 0, bins = 0;
  std::vector<float> histograms;       ///< rows * cols * bins
  std::vector<std::uint8_t> valid;     ///< rows * cols
  std::vector<float> weight;           ///< rows * cols, centre weights
};

/// `image`: CV_8U (grey or BGR, converted to grey) or CV_32F grey; `mask` CV_8U (non-zero:
/// defined), or empty for all defined. Gradients are taken only between defined pixels, so
/// the holes of a synthetic image add no edges.
HogField computeHogField(const cv::Mat& image, const cv::Mat& mask, const HogParameters& parameters = {});

/// Which windows DHOG averages over.
enum class HogWindows {
  ValidInBoth,   ///< the windows both images cover
  ValidInFirst,  ///< every window the first (the photo) covers; the second's histogram as it is,
                 ///< zero or partial where its image has holes
};

/// DHOG: centre-weighted mean squared distance between the histograms of the windows chosen by
/// `windows` (same geometry required), in [0, 2]; NaN when there is none.
double distanceBetweenHogFields(const HogField& a, const HogField& b, HogWindows windows = HogWindows::ValidInBoth);

/// NMI of two images over the pixels defined in both masks (each image binned over its own
/// range into `bins` levels); NaN when fewer than 16 pixels are shared or an image is flat.
double normalizedMutualInformation(const cv::Mat& a, const cv::Mat& a_mask, const cv::Mat& b,
                                   const cv::Mat& b_mask, int bins = 32);

enum class ImageMetric { NMI, DHOG, MIDHOG };
const char* imageMetricName(ImageMetric metric);

struct ImageMetricParameters {
  ImageMetric metric = ImageMetric::MIDHOG;
  double alpha = 10;         ///< weight of DHOG in MIDHOG (manuscript: 5 to 20 equally good, 10)
  int nmi_bins = 32;         ///< histogram levels of NMI
  HogParameters hog;
  /// DHOG over every window of the photo (ValidInFirst, default), not only the windows the
  /// synthetic image covers: averaged over the covered windows alone, a pose could lower its
  /// cost by covering less of the photo (leaving out the windows that match worst), and did:
  /// on a real Kinect frame every DHOG and MIDHOG run ended at a pose cheaper than the truth.
  HogWindows dhog_windows = HogWindows::ValidInFirst;
  void validate() const;
};

/// Compares synthetic images with one fixed real image (its grey levels and HOG computed once).
class ImageComparator {
 public:
  ImageComparator(const cv::Mat& real, const ImageMetricParameters& parameters = {});
  /// The cost of a synthetic image (same size as the real one): 2 - NMI, DHOG or MIDHOG.
  /// Images sharing less than a tenth of the real image's windows/pixels cost 4 (worst).
  double cost(const cv::Mat& synthetic, const cv::Mat& mask) const;
  const cv::Mat& realGrey() const { return grey_; }
  const ImageMetricParameters& parameters() const { return parameters_; }

 private:
  ImageMetricParameters parameters_;
  cv::Mat grey_;
  HogField hog_;
};

}  // namespace paps
