#pragma once
// Shadow correction of a coloured point cloud (manuscript 4.5.3): given which points are in
// shadow, relight the cloud as if every point were in sunlight, or every point in shadow.
// Lighting model (eq. 4.5 simplified as in 4.5.3), luminance Y linear in the albedo R:
//   shadow point:  Y = R E beta(p),
//   lit point:     Y = R E (SSR cos(alpha) + beta(p)),   cos(alpha) = max(0, <n, sun>),
//   beta(p) = 0.5 * (<n, n_ground> + 1).
// The manuscript prints beta = 0.5 * <n, n_ground> + 1, which is ambiguous (and would make a
// wall receive 1 and the ground 1.5 of the sky); 0.5 * (<n, n_ground> + 1) is the model its
// text describes (the ground receives the whole sky, a wall half) and the synthetic street's.
// The sun-sky ratio is estimated as in the equation before 4.6,
//   SSR = (mean_L(Y) mean_S(beta) - mean_S(Y) mean_L(beta)) / (mean_S(Y) mean_L(cos alpha)),
// (means over lit points L and shadow points S). The manuscript prints mean_L(Y) in the
// denominator; solving mean_L(Y) / mean_S(Y) = (SSR mean_L(cos) + mean_L(beta)) / mean_S(beta),
// which assumes the same mean albedo on both sides, gives mean_S(Y), used here. To make that
// assumption hold the means are taken, by default, over the points near the shadow
// boundary only, where the same surfaces lie on both sides.
// Luminance (eq. 4.6 and its inverse): all in shadow: Y' = Y mean_S(beta) / beta(p) for shadow
// points, Y' = Y mean_S(beta) / (SSR cos(alpha) + beta(p)) for lit ones; all lit: shadow points
// Y' = Y (SSR cos(alpha) + beta(p)) / beta(p), lit points unchanged. The new L* comes from Y'.
// Chrominance (eq. 4.7), in CIE Lab: the corrected points' a and b are scaled by the ratio of
// the mean |a| (|b|) of the target class over the mean of their own class (means of absolute
// values: a mean of signed a near 0 makes the ratio explode).
// Penumbra: the binary labels leave a line of over- or under-corrected points along the
// boundary (Fig. 4.11c); the points whose neighbourhood holds both labels get the per-channel
// median of their neighbours' corrected colours.
// Colours are linear RGB in [0, 1] (colour_space.h).
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <pcl/filters/filter.h>
#include <pcl/point_types.h>

#include <paps/core/positions.h>
#include <paps/core/progress.h>
#include <paps/core/thread_count.h>

namespace paps {

enum class RelightTarget {
  AllLit,     ///< every point as if in sunlight
  AllShadow,  ///< every point as if in shadow, under the mean shadow sky factor
};

struct ShadowCorrectionParameters {
  RelightTarget target = RelightTarget::AllLit;
  /// Direction towards the sun (world frame, any length > 0). Required: there is no default
  /// (it comes from GPS time and position, manuscript [RA04]).
  Eigen::Vector3f sun_direction = Eigen::Vector3f::Constant(NAN);
  /// Ground normal n_ground (any length > 0), default +z.
  Eigen::Vector3f ground_normal = Eigen::Vector3f::UnitZ();
  /// Sun-sky ratio: 0 (default) estimates it (equation before 4.6); > 0 uses the value, up to 1000.
  float sun_sky_ratio = 0;
  /// How an unknown sun-sky ratio is estimated:
  /// - true (default): from local pairs across the boundary: every shadow point of the
  ///   estimation band and each lit one among its estimation_neighbours nearest, of the same
  ///   orientation (normals within 25 degrees, cos(alpha) > 0.1), neither of them on the
  ///   boundary line itself (blended colours), give SSR = (Y_lit / Y_shadow * beta_shadow - beta_lit) / cos(alpha_lit); the median
  ///   over the pairs. Not in the manuscript: the class means below assume the same mean albedo
  ///   on both sides, which a street breaks (on the synthetic street's photo-coloured cloud the means
  ///   gave 1.2 to 1.3 for a true 2.0, the local pairs 1.92);
  /// - false: the equation before 4.6 on the means over the estimation band.
  bool local_pair_ratio = true;
  /// Nearest neighbours (self excluded) that decide the boundary points (both labels among
  /// them) for the penumbra filter, and the filter's window, 2 to 128.
  int neighbours = 12;
  /// Means of the SSR and chrominance estimates over the points whose this many nearest
  /// neighbours hold both labels (the boundary band, same surfaces on both sides), 2 to 1024;
  /// 0 takes every point. Falls back to every point when the band has fewer than 20 points
  /// of either class.
  int estimation_neighbours = 64;
  /// Median filter on the boundary points (penumbra), default on.
  bool median_filter = true;
  void validate() const;
};

struct ShadowCorrectionReport {
  std::size_t lit = 0, shadow = 0;      ///< labelled points (finite)
  std::size_t non_finite = 0;           ///< skipped: non-finite position, normal or colour
  std::size_t estimation_points = 0;    ///< points of the means below
  std::size_t filtered = 0;             ///< boundary points given their neighbours' median
  std::size_t local_pairs = 0;          ///< pairs of the local SSR estimate (0: class means used)
  float sun_sky_ratio = 0;              ///< estimated or given
  float mean_beta_shadow = 0, mean_beta_lit = 0, mean_cos_lit = 0;
  float mean_luminance_shadow = 0, mean_luminance_lit = 0;  ///< linear Y
  float a_ratio = 1, b_ratio = 1;       ///< chrominance factors applied to the corrected class
};

/// Relights `colours` (linear RGB, one per point) given `in_shadow` (1 shadow, 0 lit, one per
/// point) and unit `normals`. Non-finite points keep their colour. Throws InvalidParameter for
/// a size mismatch or bad parameters, InvalidInput for an empty cloud, no finite point, no lit
/// or no shadow point when the sun-sky ratio is to be estimated, no shadow point for AllShadow.
/// Deterministic.
std::vector<Eigen::Vector3f> correctShadows(const Positions& points, const Normals& normals,
                                            const std::vector<Eigen::Vector3f>& colours,
                                            const std::vector<std::uint8_t>& in_shadow,
                                            const ShadowCorrectionParameters& params,
                                            ShadowCorrectionReport* report = nullptr,
                                            const ProgressCallback& progress = {});

/// The pcl::Filter stage: setInputCloud (rgb + normals), setShadowLabels, setParameters (with
/// the sun direction), filter(output): the input with corrected rgb.
template <typename PointT>
class ShadowCorrection : public pcl::Filter<PointT>, public ThreadCountOption {
  using Base = pcl::Filter<PointT>;
  using PointCloud = typename Base::PointCloud;

 public:
  using Ptr = pcl::shared_ptr<ShadowCorrection<PointT>>;
  ShadowCorrection() { this->filter_name_ = "ShadowCorrection"; }
  void setParameters(const ShadowCorrectionParameters& p) { p.validate(); params_ = p; }
  const ShadowCorrectionParameters& getParameters() const { return params_; }
  /// One label per point of the input cloud (1 shadow), e.g. ShadowDetectionResult::in_shadow.
  void setShadowLabels(std::vector<std::uint8_t> labels) { labels_ = std::move(labels); }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const ShadowCorrectionReport& getReport() const { return report_; }
  /// As pcl::Filter::filter; throws InvalidInput without an input cloud or labels.
  void filter(PointCloud& output);

 protected:
  void applyFilter(PointCloud& output) override;

 private:
  ShadowCorrectionParameters params_;
  std::vector<std::uint8_t> labels_;
  ShadowCorrectionReport report_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/fusion/impl/shadow_correction.hpp>
#endif
