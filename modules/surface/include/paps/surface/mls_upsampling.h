#pragma once
// Point set surface upsampling baselines that PCL lacks: APSS (algebraic point set surfaces,
// Guennebaud and Gross 2007: algebraic spheres fitted with normal constraints) and RIMLS
// (robust implicit MLS, Oztireli, Guennebaud and Gross 2009). Both generate a uniform set of
// seed points near the input (the same seeds QSR uses) and project them on their surface,
// so the output count is exactly the one asked for.
#include <cstddef>
#include <cstdint>

#include <pcl/surface/processing.h>

#include <paps/core/thread_count.h>
#include <paps/core/view_point_option.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

enum class MlsSurface { Apss, Rimls };

/// The seed disc of `disc_scale` 1 in mean input spacings: 1.2 h / sqrt(n) over the spacing
/// h sqrt(pi / n) of n neighbours within h, i.e. 1.2 / sqrt(pi). A disc of S spacings is
/// disc_scale = S / kMlsDiscSpacingsAtScaleOne.
constexpr float kMlsDiscSpacingsAtScaleOne = 0.6770275f;

/// Parameters of APSS / RIMLS upsampling. Zero means "choose from the data".
struct MlsUpsamplingParameters {
  /// Kernel support h in metres (> 0), or 0: the radius holding `target_neighbours` points.
  float radius = 0.f;
  /// Neighbour count that sets the radius: a typical (median) point holds it (6 to 1000).
  int target_neighbours = 30;
  /// Most neighbours a kernel holds: where the input is far denser than typical (clusters,
  /// overlapping or duplicated scans), a point keeps its nearest ones within h. Without a cap
  /// memory grows with the square of the local density (PCL's bun0.pcd sample: 15,800
  /// neighbours at the 90th percentile where the median has 30; 2.4 GB). 0: 16 x
  /// target_neighbours; otherwise 6 to 10^6.
  int max_neighbours = 0;
  /// Output count = factor x finite input count when output_count is 0 (1 to 1000).
  float factor = 4.f;
  /// Exact output count (0: from factor).
  std::size_t output_count = 0;
  /// Projection steps per output point when fitting at every output point (1 to 50). One
  /// step is as accurate as four here (the seeds start on tangent discs, close to the surface).
  int iterations = 1;
  /// Fit once per input point and project each seed (generated on the tangent disc of an input
  /// point) with that fit, as PCL MLS does with its polynomial: APSS projects the seed on the
  /// sphere of its input point; RIMLS takes the robust weights converged at its input point and
  /// makes one projection step with them. Otherwise (false) every seed is refitted on its own.
  /// The per-input-point mode costs about one fit per input point instead of one (APSS) or
  /// `inner_iterations` (RIMLS) per output point; on the bench (70K -> 700K) its error is within
  /// about 2% of the other mode (see docs/superresolution.md).
  bool fit_per_input_point = true;
  /// RIMLS: reweighting iterations per projection (1 to 50).
  int inner_iterations = 3;
  /// RIMLS: residual scale in units of the radius, and normal scale (Oztireli et al.: 0.5-1.5).
  float sigma_r = 0.2f, sigma_n = 0.8f;
  /// Radius of the tangent discs the seeds are spread over, as a multiple of 1.2 h / sqrt(mean
  /// neighbour count at h) (0.1 to 15). The default keeps the seeds close to their input
  /// points (cheap thinning, accurate per-point fits). sqrt(pi) = 1.7725 gives QSR's disc (1.2
  /// mean spacings): on the bench the output then covers the surface more evenly, and the
  /// error (dense points to their nearest output point) drops by 17-25% at 0.01% noise, for
  /// up to 1.5x the time (docs/superresolution.md).
  float disc_scale = 1.f;
  /// Seed of the seed points.
  std::uint64_t seed = 1;
  /// A cloud of more finite points is upsampled in tiles of at most this many (a core, plus a
  /// halo of every point its fits read), one after the other: the working memory of a tile.
  /// The kernel support and the seed disc are chosen on the whole cloud; each tile gets a
  /// share of the output by the surface it covers and orients its normals as the tiles before
  /// it where they meet; its seeds keep the Poisson-disk radius from those of the tiles before.
  /// 0: one piece whatever the size; else 1000 to 2^31 - 1.
  std::size_t max_tile_points = 2000000;
  void validate() const;
};

struct MlsUpsamplingReport {
  float radius = 0.f;
  std::size_t output = 0;
  /// Seeds whose fit failed (too few neighbours, a fit that does not reach them), left where
  /// generated: on their input point's tangent disc, with its normal.
  std::size_t unprojected = 0;
  std::size_t capped = 0;       ///< input points whose kernel holds max_neighbours (the cap)
  int max_neighbours = 0;       ///< the cap used
  float disc_radius = 0.f;      ///< radius of the tangent discs the seeds were spread over
  std::size_t tiles = 1;        ///< tiles the cloud was upsampled in (1: one piece)
  std::size_t largest_tile = 0; ///< most points a tile held, halo included (one piece: all)
};

/// Upsamples `points` (NaN entries ignored). Throws InvalidInput for fewer than 3 finite points.
/// With `normals`, also the unit normal of the fitted surface at each output point (the
/// gradient of the sphere or of the RIMLS function there), oriented as the input's normals
/// propagated over the cloud. A seed that could not be projected stays on its input point's
/// tangent disc, with that plane's normal. With `curvature`, what PCL's MLS writes in the
/// curvature field: the surface variation of the kernel ball of the input point each output
/// point was made from (NaN where that ball has no normal). With `source`, the index of that
/// input point (the PCL stages copy its other fields, colour or intensity, to the new point,
/// as PCL's MLS does).
Positions upsampleMls(const Positions& points, MlsSurface surface, const MlsUpsamplingParameters& params,
                      MlsUpsamplingReport* report = nullptr, const ProgressCallback& progress = {},
                      Normals* normals = nullptr, std::vector<float>* curvature = nullptr,
                      std::vector<int>* source = nullptr);

/// Throws InvalidParameter("output_count") unless an explicit output count (0: from the
/// factor) is at most 1000 x the input points, the bound of the factor: a larger one is a
/// typo, and would end in an allocation failure rather than a clear error.
void checkOutputCount(std::size_t output_count, std::size_t input_points);

/// Seeds for upsampling: about `count` points spread uniformly over the tangent discs of the
/// input points (discs of radius `disc_radius`), regularised by Poisson-disk thinning to
/// exactly `count` points. `normals` must be unit (NaN normals: the point spawns nothing).
/// `origin` (optional) receives, per seed, the index of the input point it was generated from.
Positions upsamplingSeeds(const Positions& points, const Normals& normals, std::size_t count,
                          float disc_radius, std::uint64_t seed, std::vector<int>* origin = nullptr);
/// Same, given the complete neighbour lists of `points` within `graph_radius` (no truncation),
/// which spare the thinning its own grid. They are used when graph_radius >= d + 2 disc_radius
/// (d the Poisson-disk radius), as is the case for the kernel neighbourhoods of APSS and RIMLS;
/// the seeds are the same with or without them (null graph: the thinner's own grid). With
/// `disc_scale`, point i spreads its seeds over a disc of radius (*disc_scale)[i] x disc_radius
/// (each scale in (0, 1]; null: 1 for every point). `kept_before` (optional): points already
/// in the output nearby (a tile's neighbours' seeds): no seed is kept within the Poisson-disk
/// radius of one, so tiles keep their seeds apart across the seams as one piece does.
Positions upsamplingSeeds(const Positions& points, const Normals& normals, std::size_t count,
                          float disc_radius, std::uint64_t seed, std::vector<int>* origin,
                          const NeighbourGraph* graph, float graph_radius,
                          const std::vector<float>* disc_scale = nullptr, const Positions* kept_before = nullptr);

namespace detail {
/// For tests: one sequential dart-throwing pass of the seed thinner over `cand` in index order
/// at radius d. Candidate c lies within `disc` of points[cand_point[c]], at most `slots`
/// candidates per point. With `graph` (complete lists within graph_radius >= d + 2 disc) the
/// thinner takes them, otherwise its own grid (not aligned to any blocks). Returns the kept
/// candidates; m2 gets, per kept one, the squared distance to the nearest earlier kept one
/// among those from points within d + disc of it (infinite when none).
std::vector<int> thinSeedCandidates(const Positions& points, const Positions& cand, const std::vector<int>& cand_point,
                                    int slots, float disc, float d, const NeighbourGraph* graph, float graph_radius,
                                    std::vector<float>* m2 = nullptr);
}  // namespace detail

/// The pcl::CloudSurfaceProcessing stages. Indices are honoured (only those points are used).
/// An output type with normals gets the fit's gradient, turned towards setViewPoint()'s point,
/// else towards the input's sensor_origin_ when it is set (not 0 0 0), else propagated.
template <typename PointIn, typename PointOut, MlsSurface S>
class MlsUpsampling : public pcl::CloudSurfaceProcessing<PointIn, PointOut>, public ThreadCountOption,
                               public ViewPointOption {
 public:
  void setParameters(const MlsUpsamplingParameters& p) { p.validate(); params_ = p; }
  const MlsUpsamplingParameters& getParameters() const { return params_; }
  void setUpsamplingFactor(float f) { auto p = params_; p.factor = f; setParameters(p); }
  void setRadius(float r) { auto p = params_; p.radius = r; setParameters(p); }
  /// Tiles of at most n points for larger clouds (0: one piece); see max_tile_points.
  void setMaxTilePoints(std::size_t n) { auto p = params_; p.max_tile_points = n; setParameters(p); }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const MlsUpsamplingReport& getReport() const { return report_; }

  /// As pcl::CloudSurfaceProcessing::process, but without an input cloud it throws
  /// InvalidInput (PCL's reads the missing cloud).
  void process(pcl::PointCloud<PointOut>& output) override {
    requireInputCloud(this->input_);
    pcl::CloudSurfaceProcessing<PointIn, PointOut>::process(output);
  }

 protected:
  void performProcessing(pcl::PointCloud<PointOut>& output) override;

 private:
  MlsUpsamplingParameters params_;
  MlsUpsamplingReport report_;
  ProgressCallback progress_;
};

template <typename PointIn, typename PointOut = PointIn>
using APSSUpsampling = MlsUpsampling<PointIn, PointOut, MlsSurface::Apss>;
template <typename PointIn, typename PointOut = PointIn>
using RIMLSUpsampling = MlsUpsampling<PointIn, PointOut, MlsSurface::Rimls>;

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/surface/impl/mls_upsampling.hpp>
#endif
