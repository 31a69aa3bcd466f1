#pragma once
// Colorization of a point cloud from registered photos (manuscript 4.5.1, after Cho et al.
// 2014). Every photo proposes a colour for each point it sees (projectVisiblePoints, bilinear
// sample); occluders that the scan does not contain (a passing van, Fig. 4.7) and lighting
// changes make these candidates disagree. The consensus colour C minimises, over the points
// seen by at least one photo,
//
//   E(C) = sum_i w_i |C_i - m_i|^2 + smoothness * sum_{(i,j) in G} huber_delta(|C_i - C_j|)
//
// m_i: the per-channel median of the candidates of point i (the data term), weighted by the
//      occlusion maps (below; all weights 1 gives the plain median of the manuscript);
// w_i: its confidence, the (weighted) fraction of the candidates within `agreement_distance`
//      of m_i (at least 0.1): photos that disagree leave the point to its neighbours;
// G:   the symmetrised k-nearest-neighbour graph of the seen points;
// huber_delta(d) = d^2 / 2 below delta, delta (d - delta / 2) beyond: neighbours of different
//      colours (a material edge) pull with a force that stops growing, so edges stay sharp.
// It is minimised by IRLS: edge weights min(1, delta / |C_i - C_j|) from the current colours,
// then one Jacobi step C_i <- (w_i m_i + s sum_j a_ij C_j) / (w_i + s sum_j a_ij), repeated.
// Jacobi steps read only the previous iterate, so the result does not depend on the thread
// count. Points no photo sees keep their input colour.
// Occlusion maps (an addition): with three photos and a van in front of one, the median
// outvotes the van; with two, it averages the van in. But the van covers a region of its
// photo, and where that region overlaps points seen by three photos its candidates are
// outliers: the residuals to the median, spread over the image, say which part of which photo
// to distrust (occlusion_map_scale). On the synthetic street (24 m, 320 x 240 photos) the RMS
// error to what the photos record without the van went, on the points the van hides in one
// photo, from 0.135 (median) to 0.033.
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <pcl/filters/filter.h>

#include <paps/core/positions.h>
#include <paps/core/progress.h>
#include <paps/core/thread_count.h>
#include <paps/fusion/point_visibility.h>
#include <paps/fusion/registered_photo.h>

namespace paps {

struct PointColorizationParameters {
  /// Nearest neighbours per point in the regularisation graph (self excluded), 1 to 64.
  int neighbours = 8;
  /// Weight of the regularisation against the data term, in [0, 1000]; 0 gives the per-point
  /// median of the candidates. Per edge: with 8 neighbours the neighbours together weigh
  /// about 8 * smoothness against a data weight of at most 1.
  float smoothness = 0.25f;
  /// Huber threshold delta of the regularisation, a distance between linear RGB colours in
  /// [0, 1]^3, in (0, 2]: differences below it are smoothed, beyond it treated as edges.
  float huber_threshold = 0.04f;
  /// Distance (linear RGB) within which a candidate agrees with the median, in (0, 2].
  float agreement_distance = 0.08f;
  /// Occlusion maps (not in the manuscript): a photo that shows an occluder the scan does not
  /// hold (the van) disagrees with the other photos over a whole region of its image. Where a
  /// point has 3 or more candidates, the distance of each candidate to their median is
  /// splatted into its photo and spread by a Gaussian of this standard deviation, as a
  /// fraction of the image width, in [0, 1]; 0 disables. Every candidate is then weighted by
  /// 1 / (1 + (r / agreement_distance)^2), r the map's value at its pixel, and the data term
  /// pulls towards the weighted median: a point seen by two photos, one of them hidden by the
  /// van, takes the other's colour instead of their average.
  float occlusion_map_scale = 0.1f;
  /// Maximum IRLS/Jacobi iterations, 1 to 10000.
  int iterations = 60;
  /// Stop once no colour moved more than this in an iteration (linear RGB), in [0, 1].
  float tolerance = 1e-4f;
  /// Visibility test of each photo.
  VisibilityParameters visibility;
  /// Throws InvalidParameter for a value out of its range.
  void validate() const;
};

struct PointColorizationReport {
  std::size_t points = 0;       ///< input points
  std::size_t non_finite = 0;   ///< NaN/Inf points (kept as they are)
  std::size_t unseen = 0;       ///< finite points no photo sees: input colour kept
  std::size_t coloured = 0;     ///< points given a consensus colour
  std::size_t candidates = 0;   ///< colour candidates over all photos
  std::vector<std::size_t> seen_per_photo;
  int iterations = 0;           ///< Jacobi iterations run
  float last_change = 0;        ///< largest colour move in the last iteration
};

/// The candidate colours of every point: list i is colour[offsets[i] .. offsets[i + 1]),
/// in photo order, `photo` saying which photo proposed each.
struct ColourCandidates {
  std::vector<std::int64_t> offsets;
  std::vector<Eigen::Vector3f> colour;  ///< linear RGB in [0, 1]
  std::vector<int> photo;
  std::vector<Eigen::Vector2f> pixel;   ///< where the candidate was sampled in its photo
  std::vector<cv::Size> photo_size;     ///< image size of every photo
  std::size_t count(std::size_t i) const { return static_cast<std::size_t>(offsets[i + 1] - offsets[i]); }
};

/// Projects the points (non-finite skipped) into every photo and samples the colour of each
/// visible one. Throws as RegisteredPhoto::validate for a bad photo.
ColourCandidates collectColourCandidates(const Positions& points, const std::vector<RegisteredPhoto>& photos,
                                         const VisibilityParameters& visibility = {});

/// Per-channel median of the candidates of point i (NaN when it has none). With `weights` (one
/// per candidate, >= 0, of the same layout as candidates.colour), the weighted median.
Eigen::Vector3f medianCandidate(const ColourCandidates& candidates, std::size_t i,
                                const std::vector<float>* weights = nullptr);

/// The consensus colours (linear RGB in [0, 1]) of `points` given `input` colours (one per
/// point; kept for unseen and non-finite points). Throws InvalidInput for an empty cloud, no
/// finite point, no photo; InvalidParameter for a colour count that is not the point count.
std::vector<Eigen::Vector3f> colorizePoints(const Positions& points, const std::vector<Eigen::Vector3f>& input,
                                            const std::vector<RegisteredPhoto>& photos,
                                            const PointColorizationParameters& params,
                                            PointColorizationReport* report = nullptr,
                                            const ProgressCallback& progress = {});

/// The same, from candidates already collected (benches compare it with the mean and median).
std::vector<Eigen::Vector3f> colorizeFromCandidates(const Positions& points, const std::vector<Eigen::Vector3f>& input,
                                                    const ColourCandidates& candidates,
                                                    const PointColorizationParameters& params,
                                                    PointColorizationReport* report = nullptr,
                                                    const ProgressCallback& progress = {});

/// The pcl::Filter stage: setInputCloud(cloud), addView(...) for each photo, filter(output).
/// The output is the input with the rgb of the points in the indices (all by default) set to
/// their consensus colour; other fields and points unchanged.
template <typename PointT>
class PointColorization : public pcl::Filter<PointT>, public ThreadCountOption {
  using Base = pcl::Filter<PointT>;
  using PointCloud = typename Base::PointCloud;

 public:
  using Ptr = pcl::shared_ptr<PointColorization<PointT>>;
  PointColorization() { this->filter_name_ = "PointColorization"; }
  void setParameters(const PointColorizationParameters& p) { p.validate(); params_ = p; }
  const PointColorizationParameters& getParameters() const { return params_; }
  /// Adds a registered photo (CV_8UC3 BGR, the camera's size). Throws InvalidInput for an empty
  /// or non-8-bit image, InvalidParameter for a bad camera or a size mismatch.
  void addView(const cv::Mat& bgr8, const CameraIntrinsics& camera, const CameraPose& pose);
  void clearViews() { photos_.clear(); }
  const std::vector<RegisteredPhoto>& getViews() const { return photos_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const PointColorizationReport& getReport() const { return report_; }

  /// As pcl::Filter::filter, but without an input cloud or a view it throws InvalidInput.
  void filter(PointCloud& output);

 protected:
  void applyFilter(PointCloud& output) override;

 private:
  PointColorizationParameters params_;
  PointColorizationReport report_;
  std::vector<RegisteredPhoto> photos_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/fusion/impl/point_colorization.hpp>
#endif
