#pragma once
// Similarity-based non-local denoising of point sets (manuscript 2.2.2).
//
// S = S_smooth + V: the cloud is smoothed by iterated mean-curvature motion, the residual
// V = p - p_S carries noise, detail and sharp features. Every point gets a plane+height
// descriptor in its principal frame (both frame orientations are indexed); V is then
// averaged, in the local frames, over the k most similar descriptors found anywhere on the
// shape, with weights exp(-d^2 / sigma^2).
#include <cstddef>
#include <string>

#include <pcl/filters/filter.h>

#include <paps/core/normal_refresh.h>
#include <paps/core/thread_count.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

/// Parameters of similarity denoising. Zero means "choose from the data".
struct SimilarityDenoisingParameters {
  /// Neighbourhood radius in metres (> 0), or 0: chosen from the data, see `adapt_to_noise`.
  float radius = 0.f;
  /// Neighbour count of a typical (median) point at the automatic radius (3 to 1000). Manuscript: 30.
  int target_neighbours = 30;
  /// With the automatic radius (radius == 0): measure the noise sigma of the input
  /// (paps::estimateNoiseLevel at the radius r0 holding `target_neighbours`) and set the
  /// radius, `own_weight`, `passes` and `guided_passes` from q = sigma / r0 by the rule of
  /// noiseAdaptedParameters (measured, docs/denoising.md "Noise-adaptive defaults"); the
  /// values of those three given here are then not used. Off, or with an explicit radius:
  /// the radius is r0 (or the given one) and every parameter is used as given.
  bool adapt_to_noise = true;
  /// Noise standard deviation of the input (metres, >= 0) for `adapt_to_noise`; 0: estimated.
  float noise_sigma = 0.f;
  /// Descriptor grid is grid_size x grid_size (1 to 16). Manuscript: 3 or 4.
  int grid_size = 4;
  /// Similarity scale in metres (> 0), or 0: sigma^2 is the median over points of the mean
  /// squared descriptor distance to their similar patches, times `sigma_scale`.
  float sigma = 0.f;
  /// Multiplier of the automatic sigma^2 (> 0). Measured default, see docs/denoising.md.
  float sigma_scale = 2.f;
  /// Mean-curvature-motion iterations that separate S_smooth from V (1 to 1000).
  int smoothing_iterations = 10;
  /// Mean-curvature-motion iterations applied to the points the descriptors are built from
  /// (0: the input itself, as in the manuscript). A lightly smoothed guide makes the
  /// similarity robust to heavy noise; the residual that is averaged is always the input's.
  int descriptor_smoothing = 3;
  /// Times the whole filter is applied (1 to 100).
  int passes = 1;
  /// Later passes average the input again, with the previous pass's output as the guide for
  /// frames, descriptors and heights (two-stage, as BM3D does for images), instead of
  /// filtering that output again.
  bool guided_passes = true;
  /// Number of most similar patches averaged, the point's own included (1 to 1000).
  int similar_patches = 32;
  /// Descriptors compared per similarity query at most (0: exact search, slow on noisy
  /// data). Measured default, see docs/denoising.md.
  int search_checks = 48;
  /// How the similar patches are combined.
  ///  - Centre (manuscript 2.2.2): the residual V of each similar point (the patch centre),
  ///    read in its frame, is averaged.
  ///  - Patch: every similar patch brings all its points, read in its frame; the height at the
  ///    point is then a Gaussian-weighted quadratic fit over the union (non-local MLS). The
  ///    average runs over about k x neighbours samples instead of k, so noise drops further at
  ///    the same detail. Measured default, see docs/denoising.md.
  enum class Aggregation { Centre, Patch };
  Aggregation aggregation = Aggregation::Patch;
  /// Patch aggregation: weight of the point's own patch, as a multiple of the summed weights
  /// of its similar patches (1: half the fit comes from the point's own neighbourhood), or 0:
  /// the largest weight of the others, as in non-local means. The own patch is the only one
  /// whose base point is the point's own; more weight trades noise for offset accuracy.
  float own_weight = 0.f;
  /// Index both frame orientations of every patch (manuscript 2.1.2).
  bool both_orientations = true;
  /// Clouds with more finite points than this are denoised in tiles of at most this many
  /// points, one after the other, so the working memory is one tile's (about 1 KB a point)
  /// instead of the whole cloud's (0: never). The noise, radius and passes are chosen once on
  /// the whole cloud; each tile also carries the points within `tile_margin` radii of it, so
  /// its border points have whole neighbourhoods; similar patches are searched within the
  /// tile. In [0, 2^31). Default 2M points: about 2.5 GB at the noise-adapted defaults.
  std::size_t max_tile_points = 2000000;
  /// Width of a tile's halo in radii (>= 1). Measured in docs/denoising.md ("Tiles").
  float tile_margin = 3.f;
  /// Dense scans under heavy noise. The automatic radius holds a neighbour count, so it
  /// shrinks as the scan gets denser while the noise does not. With the automatic radius and
  /// `adapt_to_noise`, when q = noise / base radius exceeds this ratio, the cloud is split into
  /// J interleaved subsets (a point's subset is drawn from a hash of its position), J grown
  /// from ceil(q^2 / ratio^2) until the first subset measures q at most this ratio; each
  /// subset, a sparser sampling of the same surface, is denoised on its own by the whole rule
  /// (its own noise measurement, radius, passes and tiles; its neighbours and similar patches
  /// are its own points). Only clouds of at least 20,000 finite points split, into subsets of
  /// at least 10,000. 0: never. In [0, 1e3]. Measured default (rs1 at 1M / 0.5% and 5M /
  /// 0.25%), docs/denoising.md "Dense scans: interleaved subsets" and "The noise of dense
  /// scans".
  float max_noise_ratio = 1.15f;
  /// Orient normals towards this point when `use_viewpoint`; otherwise by propagation.
  bool use_viewpoint = false;
  Eigen::Vector3f viewpoint = Eigen::Vector3f::Zero();
  /// Throws InvalidParameter naming the first bad value.
  void validate() const;
};

/// What a run chose and met.
struct SimilarityDenoisingReport {
  float radius = 0.f;              ///< radius used (metres)
  float noise_sigma = 0.f;         ///< noise the radius was adapted to (metres; 0: no adaptation)
  bool noise_estimated = false;    ///< noise_sigma was measured (not given)
  float radius_scale = 1.f;        ///< radius / the target-count radius (1 without adaptation)
  int passes = 1;                  ///< passes run
  bool guided_passes = true;       ///< later passes were guided (else refiltered)
  float own_weight = 0.f;          ///< own patch weight used
  float sigma = 0.f;               ///< similarity scale used (metres)
  double mean_neighbours = 0.0;    ///< mean neighbour count at that radius
  std::size_t moved = 0;           ///< points denoised
  std::size_t isolated = 0;        ///< finite points left in place: fewer than 4 neighbours, or collinear ones (no normal)
  std::size_t non_finite = 0;      ///< NaN/Inf points passed through
  /// Tiles the cloud was denoised in (1: one piece), and their largest point count, halo
  /// included. With tiles, sigma and mean_neighbours are means over the tiles weighted by
  /// their core points; moved and isolated count each core point as one piece would.
  std::size_t tiles = 1, largest_tile = 0;
  /// Interleaved subsets the cloud was denoised in (1: none; see max_noise_ratio), and the q
  /// measured on the whole cloud to decide (0 when not measured). With subsets,
  /// radius, noise_sigma, radius_scale, sigma and mean_neighbours are means over the subsets
  /// weighted by their point counts, passes the most any subset ran, tiles their sum.
  std::size_t subsets = 1;
  float split_noise_ratio = 0.f;
};

/// The noise-adaptive rule (measured on the engraved plane and the rs1 scan at 0.05% to 0.5%
/// noise, docs/denoising.md): `params` with radius = base_radius x s(q), q = noise_sigma /
/// base_radius, s growing linearly from 1 at q <= 0.2 to 2.5 at q >= 0.65; own_weight 1; one
/// pass below q = 0.6, from there refiltering passes (noiseAdaptedPasses). Every other field
/// is kept. base_radius > 0 and noise_sigma >= 0, else InvalidParameter.
SimilarityDenoisingParameters noiseAdaptedParameters(const SimilarityDenoisingParameters& params,
                                                     float base_radius, float noise_sigma);

/// The pass count of the noise-adaptive rule at q = noise sigma / base radius: one pass below
/// q = 0.6, two below 0.95, three below 1.2, four from there (measured, docs/denoising.md
/// "Dense scans under heavy noise": the radius stops growing at x2.5 while q goes on growing
/// with the density, and each further pass widens the support the output is averaged over).
int noiseAdaptedPasses(float q);

/// The parameters denoiseBySimilarity runs `params` with on `points`: with the automatic
/// radius and adapt_to_noise, noiseAdaptedParameters at the given noise_sigma or the noise
/// measured at the target-count radius (paps::estimateNoiseLevel), with that radius filled in
/// and adapt_to_noise off; otherwise `params` unchanged. `report`, when given, receives
/// noise_sigma, noise_estimated and radius_scale. For callers that override part of the
/// choice (e.g. an explicit pass count) before running.
SimilarityDenoisingParameters noiseResolvedParameters(const Positions& points,
                                                      const SimilarityDenoisingParameters& params,
                                                      SimilarityDenoisingReport* report = nullptr);

/// Denoises `points` (non-finite entries pass through). Only points with `movable[i]` set
/// (all when empty) move; all finite points serve as neighbours and similar patches.
/// Deterministic for any thread count. Throws InvalidInput when no point is finite.
Positions denoiseBySimilarity(const Positions& points, const SimilarityDenoisingParameters& params,
                              SimilarityDenoisingReport* report = nullptr,
                              const std::vector<std::uint8_t>& movable = {},
                              const ProgressCallback& progress = {});

/// The pcl::Filter stage. The output has the input's size and fields; only the positions of
/// the points in the indices move, and, for a point type with normals, their normals and
/// curvature are estimated again on the output (NormalRefreshOption; off: the input's are
/// kept). NaN points pass through; is_dense is kept honest. When the cloud's sensor_origin_ is
/// set (non-zero) and no viewpoint was given, normals are oriented towards it.
template <typename PointT>
class SimilarityDenoising : public pcl::Filter<PointT>, public ThreadCountOption, public NormalRefreshOption {
  using Base = pcl::Filter<PointT>;
  using PointCloud = typename Base::PointCloud;

 public:
  using Ptr = pcl::shared_ptr<SimilarityDenoising<PointT>>;
  using ConstPtr = pcl::shared_ptr<const SimilarityDenoising<PointT>>;

  SimilarityDenoising() { this->filter_name_ = "SimilarityDenoising"; }

  void setParameters(const SimilarityDenoisingParameters& p) { p.validate(); params_ = p; }
  const SimilarityDenoisingParameters& getParameters() const { return params_; }
  /// Radius in metres; 0 chooses it from the target neighbour count.
  void setRadius(float r);
  void setTargetNeighbours(int n);
  /// With the automatic radius, scale radius and passes to the measured noise (default on).
  void setAdaptToNoise(bool on);
  /// Noise standard deviation in metres for the adaptation; 0 estimates it.
  void setNoiseSigma(float s);
  void setGridSize(int n);
  /// Similarity scale in metres; 0 chooses it from the descriptor statistics.
  void setSigma(float s);
  void setSmoothingIterations(int n);
  void setSimilarPatches(int k);
  /// Tiles of at most n points for clouds larger than that (0: one piece); see
  /// SimilarityDenoisingParameters::max_tile_points.
  void setMaxTilePoints(std::size_t n);
  /// Interleaved subsets above this noise ratio (0: never); see
  /// SimilarityDenoisingParameters::max_noise_ratio.
  void setMaxNoiseRatio(float q);
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  /// What the last run chose (radius, sigma) and how many points it could not move.
  const SimilarityDenoisingReport& getReport() const { return report_; }

  /// As pcl::Filter::filter, but without an input cloud it throws InvalidInput (PCL's only
  /// prints a message and leaves `output` as it was).
  void filter(PointCloud& output) {
    requireInputCloud(this->input_);
    Base::filter(output);
  }

 protected:
  void applyFilter(PointCloud& output) override;

 private:
  SimilarityDenoisingParameters params_;
  SimilarityDenoisingReport report_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/filters/impl/similarity_denoising.hpp>
#endif
