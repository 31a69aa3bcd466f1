#pragma once
// Point-set denoising with Local Probing Fields (manuscript 3.3.2, eqs. 3.9 to 3.12). The
// fields of the shape are analysed jointly (paps/core/local_probing_field.h); every point
// then moves towards the consensus of what the consolidated fields say it should be: every
// field whose target area holds the point projects it on its pattern plane and proposes
// the consolidated pattern there (the bilinear blend of s + R (u_i + (D a)_i) over the four
// nodes around the projection), weighted by
// exp(-|candidate - point|^2 / 2 tau_p^2) (eq. 3.11), and the point goes `rate` of the way
// to their weighted mean (eq. 3.12). Alternated with the
// analysis for `iterations` passes. Unlike the height-field denoisers (ours, MLS, the
// bilateral filter) it needs no normal, so curves and wires are denoised as well as
// surfaces (manuscript Fig. 3.15, Table 3.1).
#include <pcl/filters/filter.h>

#include <paps/core/local_probing_field.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>
#include <paps/core/normal_refresh.h>
#include <paps/core/thread_count.h>

namespace paps {

struct LpfDenoisingParameters {
  /// The fields: radius, step, atoms, lambda, rounds of the first analysis, ... One field per
  /// third of a radius (about 11 fields cover a point): the manuscript puts one on every
  /// point; measured on the plate and wires (50,000 points), a third of a radius gave 6 times
  /// fewer fields, 1.4 s instead of 8.1 s, for an error 1.6% higher at 0.15% noise
  /// (6.25e-4 against 6.15e-4) and within 1% at 0.5% (docs/lpf.md).
  LocalProbingParameters probing = [] {
    LocalProbingParameters p;
    p.seed_spacing_radii = 1.f / 3.f;
    return p;
  }();
  /// Denoising passes (analysis then consensus), in [1, 50], or 0: from the relief. Measured
  /// (docs/lpf.md): on the plate and wires 3 -> 5 passes took the error from 1.10e-3 to
  /// 6.3e-4; on the rs1 mesh, whose relief is finer than the pattern, the passes past the
  /// second erode it (50,000 points at 0.15% noise: 0.583 / 0.603 / 0.707 after 1 / 2 / 5).
  /// 0 runs 5 passes where the surface is smooth at the pattern scale (noiseGrowth at the
  /// pattern radius below `relief_growth`: plate and wires 1.01-1.03, fandisk 1.05-1.06) and
  /// 2 where it has relief (rs1 1.23-1.32).
  int iterations = 0;
  /// The noise growth from which the automatic passes take the surface for relief, in
  /// [1, 10].
  float relief_growth = 1.15f;
  /// Rounds of the analysis before each pass after the first (warm-started), in [0, 100].
  int rounds_per_pass = 1;
  /// Fraction of the way to the consensus position a point moves per pass, in (0, 1].
  /// The manuscript's eq. 3.12 with gamma moves gamma / (1 + gamma) of the way (its text
  /// says "gamma = 0.5, halfway"). 1 (all the way) measured better at equal passes on every
  /// noise level of the bench (docs/lpf.md).
  float rate = 1.f;
  /// Where a field's target area is a surface (LocalProbingAnalysis::targetDimension 2)
  /// the points it moves go along the pattern's normal only; on wires, in every direction
  /// across them. false: every field moves points in every direction (the manuscript's
  /// rule), which draws the borders of surfaces in by about half a spacing.
  bool normal_motion_on_surfaces = true;
  /// Width of the consensus weight in metres (> 0), or 0: the pattern step (the probing
  /// accuracy tau_p of 3.3.1).
  float tau_p = 0.f;
  /// Creases stop moving (ours, not in the manuscript). Every pass rounds a crease a little
  /// more (16 atoms draw a V poorly), so the rounding grows like a flow: on the fandisk block
  /// the points near creases ended worse than the input after 5 passes. After each analysis
  /// a surface field is *bent* when its consolidated pattern (u + D a) lies farther than
  /// `bend_threshold` x the pattern radius (RMS) from its least-squares plane; a field whose
  /// target area is scattered (dimension 3: an edge or corner too sharp for a height field,
  /// such as a tetrahedron's) counts as bent. A point is held after the pass whose analysis
  /// first finds at least `bent_share` of its covering fields (of known dimension) bent and
  /// fewer than `bent_share` of them wire fields (wires need their passes). The test is
  /// repeated after every analysis because the first pass lowers the noise that hides mild
  /// creases at high noise. The noise rule for the radius (r >= 6 sigma) keeps the noise's
  /// own bend of a flat field below about 0.08 r (99th percentile on the bench's plate at
  /// 0.3% and 0.5%).
  /// Measured (docs/lpf.md; RMSE in thousandths of the diagonal at 0.15%, 0.3% and 0.5%
  /// noise, every pass -> this rule): fandisk block 1.15 -> 0.55, 1.26 -> 0.75, 1.45 -> 1.20;
  /// cube 1.25 -> 0.53, 1.38 -> 0.73, 1.58 -> 1.14; tetrahedron 1.37 -> 0.53, 1.52 -> 0.85,
  /// 1.81 -> 1.46; plate and wires within 1%.
  /// 0 disables; bend_threshold in [0, 10], bent_share in (0, 1].
  float bend_threshold = 0.08f;
  float bent_share = 0.25f;
  /// A cloud of more finite points than this is denoised in tiles of at most this many points,
  /// one after the other (0: one piece whatever the size); the analysis takes about 0.75 KB a
  /// point (5M points: 3.7 GB in one piece). The radius (and with it the step and lambda) is
  /// chosen once on the whole cloud; each tile then places its own fields and learns its own
  /// dictionary, so the output is not the one-piece output bit for bit (docs/lpf.md).
  std::size_t max_tile_points = 2000000;
  /// Halo of a tile in pattern radii, >= 1: the points a core point's covering fields
  /// (centred within 1.1 r of it) probe lie within 2.2 r.
  float tile_margin = 3.f;
  void validate() const;
};

struct LpfDenoisingReport {
  float radius = 0.f, step = 0.f, lambda = 0.f;
  /// Noise sigma measured for the automatic radius (0: not measured).
  float noise_sigma = 0.f;
  /// Passes run, and the noise growth the automatic count read (0: not measured).
  int passes = 0;
  float noise_growth = 0.f;
  int pattern_nodes = 0;
  std::size_t fields = 0;
  /// Representation error sum_j |V_j - D a_j|^2 / N after each round, all passes.
  std::vector<double> round_errors;
  /// Points the last pass moved; points left in place because no candidate weighed
  /// anything (or fewer than 3 finite points in all); NaN/Inf.
  std::size_t moved = 0, isolated = 0, non_finite = 0;
  /// Fields found bent (scattered ones included) by any analysis, and the points held
  /// (bend_threshold): in all, and after each pass but the last (entry k: points whose last
  /// move was pass k + 1).
  std::size_t bent_fields = 0, held_points = 0;
  std::vector<std::size_t> held_after_pass;
  /// Tiles the cloud was denoised in (1: one piece) and the most points one held, halo
  /// included. In tiles, `fields` and `bent_fields` add up every tile's (halos included) and
  /// `round_errors` are their mean over all fields.
  std::size_t tiles = 1, largest_tile = 0;
};

/// LPF denoising of positions; non-finite points pass through; only `movable` points move.
/// Deterministic, and the output does not depend on the input order or the thread count.
Positions lpfDenoisePositions(const Positions& points, const LpfDenoisingParameters& params,
                              LpfDenoisingReport* report = nullptr, const std::vector<std::uint8_t>& movable = {},
                              const ProgressCallback& progress = {});

/// The pcl::Filter stage: the points in the indices move; for a point type with normals their
/// normals and curvature are estimated again on the output at the filter's radius
/// (NormalRefreshOption; off: the input's are kept), on a wire any direction across it.
template <typename PointT>
class LpfDenoising : public pcl::Filter<PointT>, public ThreadCountOption, public NormalRefreshOption {
  using Base = pcl::Filter<PointT>;
  using PointCloud = typename Base::PointCloud;

 public:
  using Ptr = pcl::shared_ptr<LpfDenoising<PointT>>;
  LpfDenoising() { this->filter_name_ = "LpfDenoising"; }
  void setParameters(const LpfDenoisingParameters& p) { p.validate(); params_ = p; }
  const LpfDenoisingParameters& getParameters() const { return params_; }
  /// Pattern radius r in metres (0: automatic).
  void setRadius(float r) { auto p = params_; p.probing.radius = r; setParameters(p); }
  /// Dictionary atoms d.
  void setAtoms(int d) { auto p = params_; p.probing.atoms = d; setParameters(p); }
  void setIterations(int n) { auto p = params_; p.iterations = n; setParameters(p); }
  /// Fields' curvature out of the L1 penalty (LocalProbingParameters::free_curvature).
  void setFreeCurvature(bool on) { auto p = params_; p.probing.free_curvature = on; setParameters(p); }
  /// Clouds of more finite points are denoised in tiles of at most n points (0: one piece).
  void setMaxTilePoints(std::size_t n) { auto p = params_; p.max_tile_points = n; setParameters(p); }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const LpfDenoisingReport& getReport() const { return report_; }

  /// As pcl::Filter::filter, but without an input cloud it throws InvalidInput.
  void filter(PointCloud& output) {
    requireInputCloud(this->input_);
    Base::filter(output);
  }

 protected:
  void applyFilter(PointCloud& output) override;

 private:
  LpfDenoisingParameters params_;
  LpfDenoisingReport report_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/filters/impl/lpf_denoising.hpp>
#endif
