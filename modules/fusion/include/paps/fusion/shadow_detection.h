#pragma once
// Shadow detection on a coloured point cloud with laser reflectance and registered photos
// (manuscript 4.5.2, Fig. 4.10). Two nearby points lie on either side of a shadow boundary
// when their laser reflectances agree (the laser does not see the sun) while their colours'
// lightness differs a lot. Three steps:
//  (a) interface points: on each point's k nearest neighbours, least-squares gradients (in
//      the tangent plane) of the CIE L* lightness and of the reflectance, multiplied by the
//      neighbourhood radius (the change across the neighbourhood, so the thresholds do not
//      depend on the sampling density). Candidates: reflectance change below
//      max_reflectance_change, lightness change above min_lightness_change. Each candidate is
//      paired with its neighbour of most different lightness among those of the same
//      reflectance and surface orientation. Density filter: a candidate whose neighbourhood
//      holds few other candidates is an isolated false detection (a shadow interface is a
//      curve, not a point) and is dropped;
//  (b) a pair is kept when the L* histogram of the same-material, same-orientation points
//      around it has two clearly dominant modes (Otsu's between-class variance over the total
//      variance above min_bimodality, each mode holding at least min_mode_fraction of the
//      points) with the pair's dark end in the dark mode and its bright end in the bright one;
//  (c) in every photo, the kept pairs that it sees give the shadow lightness L_S (median of
//      the dark ends' pixels) and the lit lightness L_L (bright ends); the pixels are labelled
//      by minimising eq. 4.4 with a graph cut (Boost.Graph boykov_kolmogorov_max_flow, 4-
//      connected pixels), and the labels are voted back onto the points each photo sees.
// The cut's energy (eq. 4.4), L in L* units [0, 100], delta = 1 for shadow:
//   E_data(p) = exp(-(L(p) - L_S)^2 / 2 sigma^2) if delta(p) = 0 (lit),
//               exp(-(L(p) - L_L)^2 / 2 sigma^2) if delta(p) = 1 (shadow);
//   E_smooth(p, q) = exp(-(L(p) - L(q))^2 / 2 sigma^2) [delta(p) != delta(q)], weighted by gamma.
// The manuscript prints the smoothness exponent without the square; the square is used here
// (the exponent must not change sign with the order of p and q).
// The photos' lightness is computed from the 8-bit values read as linear RGB (colour_space.h).
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <pcl/pcl_base.h>
#include <pcl/point_types.h>

#include <paps/core/positions.h>
#include <paps/core/progress.h>
#include <paps/core/thread_count.h>
#include <paps/fusion/point_visibility.h>
#include <paps/fusion/registered_photo.h>

namespace paps {

struct ShadowDetectionParameters {
  /// Nearest neighbours of the gradient estimates and of the density filter (self excluded),
  /// 4 to 128.
  int neighbours = 16;
  /// (a) Largest change of the laser reflectance (units of reflectance, [0, 1]) across a
  /// neighbourhood for a shadow interface candidate, in (0, 1]. Conservative: well below the
  /// difference between materials, a few times the reflectance noise of one point over sqrt(k).
  float max_reflectance_change = 0.05f;
  /// (a) Reflectance difference (same units) within which two points count as the same
  /// material (pair partners, histogram points), in (0, 1]; about 3 times the noise of a point.
  float same_reflectance = 0.08f;
  /// (a) Smallest change of L* (0 to 100) across a neighbourhood for a candidate, in (0, 100].
  float min_lightness_change = 12.f;
  /// (a) Largest difference of rg chromaticity (r / (r + g + b), g / (r + g + b)) between the
  /// two ends of a pair, in (0, 1]; 1 disables the test. Not in the manuscript: a shadow
  /// dims a surface without changing its hue much, while texture of one laser reflectance
  /// (mortar joints against brick, paint) changes the hue: without it such texture edges,
  /// aliased in every photo, outnumber the shadow pairs.
  float max_chromaticity_difference = 0.04f;
  /// (a) Pair partners and histogram points must have normals within this angle (degrees,
  /// (0, 180]) of the candidate's: the same surface (orientation changes lighting too).
  float max_normal_angle_deg = 25.f;
  /// (a) Density filter: a candidate is kept when at least this fraction of its neighbours
  /// are candidates too, in [0, 1]; 0 keeps all.
  float min_interface_fraction = 0.2f;
  /// (b) Points around a pair (nearest to its midpoint) whose L* histogram is analysed, 8 to 1024.
  int histogram_neighbours = 64;
  /// (b) Bins of the L* histogram over [0, 100], 4 to 256.
  int histogram_bins = 50;
  /// (b) Otsu's between-class variance over the total variance of the histogram, in [0, 1].
  float min_bimodality = 0.8f;
  /// (b) Smallest share of the histogram's points in each of the two modes, in [0, 0.5].
  float min_mode_fraction = 0.15f;
  /// (c) sigma of eq. 4.4 in L* units, >= 0; 0 (default): half of L_L - L_S of each photo, so
  /// that a pixel at L_S pays exp(-2) = 0.14 to be shadow and 1 to be lit.
  float sigma = 0.f;
  /// (c) gamma of eq. 4.4, the weight of the smoothness term, in [0, 100]; 1 as the manuscript.
  float gamma = 1.f;
  /// (c) Photos seeing fewer kept pairs than this are not segmented (no L_S / L_L), 1 to 1e6.
  int min_pairs_per_view = 5;
  /// (c) Photos whose L_L - L_S (L* units) is below this are not segmented, in [0, 100].
  float min_view_contrast = 5.f;
  /// (c) Reflectance-guided data term (not in the manuscript; false gives eq. 4.4 as printed).
  /// One L_S and one L_L per photo label every dark material in sunlight (glass, brick) as
  /// shadow. With it, the pixels where scan points project get their own L_L and L_S: under
  /// the Lambertian model the lit luminance of a surface is about kappa * reflectance and its
  /// shadow luminance rho times that, with kappa (lit luminance over laser reflectance) and rho
  /// (shadow over lit luminance) the medians over the photo's interface pairs of the same
  /// orientation class (dominant normal axis; all pairs when a class has fewer than
  /// min_pairs_per_view). The data sigma there is half of that pixel's L_L - L_S (or `sigma`);
  /// pixels without scan points (sky, unscanned) keep the photo's L_S and L_L.
  bool reflectance_guided = true;
  /// (c) Scale of the image the graph cut runs on, in (0, 1]: 0.5 halves each side (four
  /// times fewer nodes); the mask is scaled back to the photo's size. The graph takes about
  /// 300 bytes per pixel of the scaled image at its peak (90 MB for 640 x 480).
  float graph_cut_scale = 1.f;
  /// (c) Largest graph cut image, pixels (64 to 1e8): a larger photo is scaled down further,
  /// keeping its aspect (the default, 2^20, holds 1280 x 800 whole and bounds the graph to
  /// about 300 MB; a 12-megapixel photo is cut at about 0.3 of its size).
  int max_graph_cut_pixels = 1 << 20;
  /// Visibility test of each photo.
  VisibilityParameters visibility;
  /// Throws InvalidParameter for a value out of its range.
  void validate() const;
};

/// The segmentation of one photo.
struct ShadowView {
  bool segmented = false;        ///< false: too few pairs seen or too little contrast
  std::size_t pairs_seen = 0;    ///< kept pairs with both ends visible in the photo
  float shadow_lightness = 0;    ///< L_S, L* units
  float lit_lightness = 0;       ///< L_L, L* units
  float sigma = 0;               ///< sigma used, L* units
  double energy = 0;             ///< minimum of eq. 4.4 (on the scaled image)
  float graph_cut_scale = 1;     ///< scale the cut ran at (graph_cut_scale, max_graph_cut_pixels)
  cv::Mat mask;                  ///< CV_8U, the photo's size: 255 shadow, 0 lit; empty when not segmented
};

struct ShadowDetectionResult {
  /// Per point: 1 in shadow, 0 lit or undecided.
  std::vector<std::uint8_t> in_shadow;
  /// Per point: 2 voted by photos, 1 taken from its voted neighbours (no photo sees it), 0 undecided.
  std::vector<std::uint8_t> decided;
  /// Step (a): interface candidates; after the density filter; (b): the kept pairs
  /// (shadow-side point, lit-side point). Indices into the cloud, increasing.
  std::vector<int> candidates, dense_candidates;
  std::vector<std::pair<int, int>> interface_pairs;
  std::size_t pairs_before_histogram = 0;  ///< pairs of the density-filtered candidates
  std::vector<ShadowView> views;
  std::size_t non_finite = 0;  ///< points skipped: non-finite position, normal, colour or reflectance
  std::size_t unseen = 0;      ///< finite points no photo sees: not used in (a) and (b), labelled from neighbours
};

/// Detects the shadows. `colours`: linear RGB in [0, 1]; `normals`: unit normals; one of each
/// and one reflectance per point (InvalidParameter otherwise). Non-finite points (position or
/// normal) are skipped. Throws InvalidInput for an empty cloud, no finite point, no photo, a
/// bad photo. Deterministic.
ShadowDetectionResult detectShadows(const Positions& points, const Normals& normals,
                                    const std::vector<Eigen::Vector3f>& colours, const std::vector<float>& reflectance,
                                    const std::vector<RegisteredPhoto>& photos, const ShadowDetectionParameters& params,
                                    const ProgressCallback& progress = {});

/// Labels the pixels of one photo by the graph cut of eq. 4.4 given L_S and L_L (L* units) and
/// sigma (> 0): CV_8U, 255 shadow. `energy`, when given, receives the minimum energy.
cv::Mat segmentShadowsGraphCut(const cv::Mat& bgr8, float shadow_lightness, float lit_lightness, float sigma,
                               float gamma = 1.f, double* energy = nullptr);

/// The same with a per-pixel L_S, L_L and data sigma (CV_32F images of the lightness image's
/// size; `lightness` is L* in CV_32F); `sigma` (> 0) is the smoothness term's.
cv::Mat segmentShadowsGraphCut(const cv::Mat& lightness, const cv::Mat& shadow_lightness, const cv::Mat& lit_lightness,
                               const cv::Mat& data_sigma, float sigma, float gamma = 1.f, double* energy = nullptr);

/// Baseline: one global Otsu threshold on the points' L*; 1 for the points below it.
std::vector<std::uint8_t> shadowLabelsByOtsu(const std::vector<Eigen::Vector3f>& colours);

/// The PCL stage: setInputCloud (rgb + normals), setReflectance, addView for each photo,
/// detect(result).
template <typename PointT>
class ShadowDetection : public pcl::PCLBase<PointT>, public ThreadCountOption {
  using Base = pcl::PCLBase<PointT>;

 public:
  using Ptr = pcl::shared_ptr<ShadowDetection<PointT>>;
  void setParameters(const ShadowDetectionParameters& p) { p.validate(); params_ = p; }
  const ShadowDetectionParameters& getParameters() const { return params_; }
  /// Laser reflectance of every point of the input cloud, in [0, 1] (checked at detect()).
  void setReflectance(std::vector<float> reflectance) { reflectance_ = std::move(reflectance); }
  /// Adds a registered photo; throws as RegisteredPhoto::validate.
  void addView(const cv::Mat& bgr8, const CameraIntrinsics& camera, const CameraPose& pose);
  void clearViews() { photos_.clear(); }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  /// Runs the three steps on the points in the indices (all by default; others undecided).
  /// Throws InvalidInput without an input cloud, a view or reflectances; InvalidParameter when
  /// the reflectance count is not the point count.
  void detect(ShadowDetectionResult& result);

 private:
  ShadowDetectionParameters params_;
  std::vector<float> reflectance_;
  std::vector<RegisteredPhoto> photos_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/fusion/impl/shadow_detection.hpp>
#endif
