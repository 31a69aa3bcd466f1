#pragma once
// Resampling with Local Probing Fields (manuscript 3.3.1, eqs. 3.7 and 3.8): after the joint
// analysis, every field proposes its pattern as the dictionary reconstructs it,
// p_i = s + R (u_i + (D a)_i); overlapping fields propose nearly the same points, and a
// consensus keeps one point per neighbourhood of radius tau_p, the mean of the proposals
// that conflict there. With a pattern step finer than the input spacing the output is denser
// than the input: upsampling, on wires (along them) as on surfaces.
#include <cstddef>

#include <pcl/point_types.h>
#include <pcl/surface/processing.h>

#include <paps/core/local_probing_field.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>
#include <paps/core/thread_count.h>

namespace paps {

struct LpfResamplingParameters {
  /// The fields. Their radius (0: automatic, from `neighbours`), neighbours, atoms, lambda,
  /// rounds ... as for denoising; one field per half radius (each point lies in about 5
  /// target areas). `step` 0 means the 1:1 step r sqrt(pi / neighbours) over sqrt(factor)
  /// (nodes_per_point and noise_sigmas are set by the resampler: factor and 0).
  LocalProbingParameters probing = [] {
    LocalProbingParameters p;
    p.seed_spacing_radii = 0.5f;
    return p;
  }();
  /// Output density over input density on surfaces (1 to 100): the pattern step is the input
  /// spacing / sqrt(factor), the spacing read from the radius and the neighbour count,
  /// r sqrt(pi / neighbours) (with an explicit radius, give `neighbours` as the points in that
  /// ball, or an explicit step). Along a wire the density grows by sqrt(factor).
  float factor = 4.f;
  /// Consensus radius tau_p in metres (> 0), or 0: 0.7 x the pattern step (kept points are
  /// at least tau_p apart; at 1 x the step the output had half the density asked for).
  float tau_p = 0.f;
  /// Noisy clouds are denoised first by paps::LpfDenoising (ours, not in the manuscript; its
  /// neighbours, seed and tiles follow these parameters). One analysis keeps about half the
  /// noise in its proposals, and where the noise is thicker than the consensus radius tau_p
  /// the consensus keeps them in layers: rs1 sampled with 1M points at 0.05% noise, x2 gave
  /// 2.4x the points at 0.106 RMS to the mesh; denoised first, 1.9x at 0.06 (docs/lpf.md).
  /// Auto: when the noise sigma measured at the pattern radius (estimateNoiseLevel) is at
  /// least `denoise_ratio` x tau_p.
  using Denoise = DenoiseFirst;
  Denoise denoise_input = Denoise::Auto;
  /// The Auto threshold: noise sigma / tau_p, in [0.01, 100].
  float denoise_ratio = 0.5f;
  /// Passes of that first denoising (LpfDenoisingParameters::iterations), 1 to 50, or 0:
  /// twice the noise ratio, 1 to 5. Every pass also erodes relief finer than the pattern:
  /// on the rs1 mesh at 0.01% noise the output came 0.032 from the mesh undenoised, 0.042
  /// after one pass, 0.056 after five, while the plate and wires at 0.5% wanted all five.
  int denoise_passes = 0;
  /// A cloud of more finite points is resampled in tiles of at most this many, one after the
  /// other (the working memory of a tile: about 1.5 KB a point of it at factor 4). The
  /// pattern radius is chosen on the whole cloud; each tile analyses its own fields (its own
  /// dictionary) and keeps the proposals nearest its core; the consensus runs on across the
  /// tiles, so no two output points are closer than tau_p at the seams either. 0: one piece
  /// whatever the size; else 1000 to 2^31 - 1.
  std::size_t max_tile_points = 2000000;
  /// The halo of a tile, in pattern radii (2.5 to 10): the fields that propose in its core
  /// read their target areas (1.1 radii around their seeds) whole.
  float tile_margin = 3.f;
  void validate() const;
};

struct LpfResamplingReport {
  float radius = 0.f, step = 0.f;
  int pattern_nodes = 0;
  std::size_t fields = 0, proposals = 0, output = 0;
  std::size_t tiles = 1;         ///< tiles the cloud was resampled in (1: one piece)
  std::size_t largest_tile = 0;  ///< most points a tile held, halo included (one piece: all)
  /// Noise sigma measured for the Auto decision and the automatic passes (0: not measured,
  /// or no surface to fit), its ratio to tau_p, and whether the cloud was denoised first.
  float noise_sigma = 0.f, noise_ratio = 0.f;
  bool denoised = false;
  int denoise_passes = 0;  ///< passes of the first denoising (0: not denoised)
};

/// Resamples `points` (NaN entries ignored). Deterministic; the output does not depend on
/// the thread count. Throws InvalidInput for fewer than 3 finite points, or points no field
/// can hold enough of to propose any, InvalidParameter for bad parameters.
Positions lpfResample(const Positions& points, const LpfResamplingParameters& params,
                      LpfResamplingReport* report = nullptr, const ProgressCallback& progress = {});

/// The pcl::CloudSurfaceProcessing stage: positions out (LPF gives no normal on a wire).
/// Indices are honoured (only those points are used).
template <typename PointIn, typename PointOut = pcl::PointXYZ>
class LpfResampling : public pcl::CloudSurfaceProcessing<PointIn, PointOut>, public ThreadCountOption {
 public:
  void setParameters(const LpfResamplingParameters& p) { p.validate(); params_ = p; }
  const LpfResamplingParameters& getParameters() const { return params_; }
  void setUpsamplingFactor(float f) { auto p = params_; p.factor = f; setParameters(p); }
  void setRadius(float r) { auto p = params_; p.probing.radius = r; setParameters(p); }
  /// Tiles of at most n points for larger clouds (0: one piece); see max_tile_points.
  void setMaxTilePoints(std::size_t n) { auto p = params_; p.max_tile_points = n; setParameters(p); }
  /// Denoise the cloud first: Auto (from the noise), On, Off; see denoise_input.
  void setDenoiseInput(LpfResamplingParameters::Denoise d) { auto p = params_; p.denoise_input = d; setParameters(p); }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const LpfResamplingReport& getReport() const { return report_; }
  /// As pcl::CloudSurfaceProcessing::process, but without an input cloud it throws InvalidInput.
  void process(pcl::PointCloud<PointOut>& output) override {
    requireInputCloud(this->input_);
    pcl::CloudSurfaceProcessing<PointIn, PointOut>::process(output);
  }

 protected:
  void performProcessing(pcl::PointCloud<PointOut>& output) override;

 private:
  LpfResamplingParameters params_;
  LpfResamplingReport report_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/surface/impl/lpf_resampling.hpp>
#endif
