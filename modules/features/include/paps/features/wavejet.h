#pragma once
// Wavejets (manuscript 2.4, Bearzi, Digne, Chaine 2018): the local height field of a surface
// over a parameterization plane, decomposed on the basis r^k e^{i n theta} (equation 2.8),
// fitted by least squares (2.23), with the plane corrected into the tangent plane
// (Corollary 1) and the coefficients corrected accordingly (Corollary 2).
//
// This header is the non-template engine. The pcl::Feature stage is WavejetEstimation
// (wavejet_estimation.h); both share fitWavejet().
//
// Conventions.
//  * Local frame (t1, t2, n) at the point p; a neighbour q has unit-disk coordinates
//    (x, y, z) = ((q - p).t1, (q - p).t2, (q - p).n) / R_phi, x + i y = r e^{i theta}.
//  * z = sum_{k=0..K} sum_{n=-k..k, n = k mod 2} phi_{k,n} r^k e^{i n theta}, with
//    phi_{k,-n} = conj(phi_{k,n}) (a real surface), so only n >= 0 is stored.
//  * Coefficients are stored in unit-disk units (R_phi = 1, dimensionless, as the manuscript
//    does "for numerical reasons"); phi_{k,n} in metres^(1-k) is phi * R_phi^(1-k).
//  * Curvatures are signed with respect to the output normal: positive where the surface
//    bends towards the normal (a sphere with outward normals has k1 = k2 = -1/r). k1 >= k2.
#include <complex>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include <paps/core/local_frame.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

/// Parameters of the Wavejet fit. The radius R_phi is not here: it is the search radius.
struct WavejetParameters {
  /// Wavejet order K (1 to 20). (K+1)(K+2)/2 real unknowns. Default 4 (curvatures and
  /// corrections); the manuscript uses 6 to 9 for detail enhancement.
  int order = 4;
  /// beta >= 1: the order is lowered locally until the neighbour count L (self included)
  /// is at least beta (K+1)(K+2)/2 (manuscript: 1.1; larger under noise). Range [1, 100].
  float beta = 1.1f;
  /// Iteratively reweighted least squares passes against noise and outliers (Tukey
  /// biweight on the residuals, scale from their median absolute deviation). 0: plain
  /// least squares (0 to 100).
  int irls_iterations = 0;
  /// Lower the order further, per point, where the higher orders only fit noise: the order
  /// in [2, K] minimising the Bayesian information criterion L ln(RSS / L) + M ln L of the
  /// nested fits (one factorisation gives them all). Off by default (the manuscript's fixed
  /// order); on, it trades a little bias on clean data for much lower variance under noise.
  /// Under noise, pair it with beta = 3 (no order 4 below 45 neighbours) and a radius
  /// holding about 200 neighbours: measured in docs/wavejets.md.
  bool select_order = false;
  /// Who decides between the fixed order and the order selection:
  ///  * automatic (default): the data. A pilot of order-`order` fits on a sample measures
  ///    the residual noise (wavejet_noise.h); on clean data the fixed order is kept (the
  ///    manuscript's method, ~1e-4 curvature error on the bench surfaces), under noise the
  ///    order is selected (select_order; beta raised to at least 3 where the balls are
  ///    widened, see `widening`) and, with the automatic radius and `adapt_support`, the
  ///    automatic radius doubles (about 4x the neighbours) where the residual is noise rather
  ///    than relief. Measured in docs/wavejets.md ("Noise-aware
  ///    defaults"). fitWavejet alone runs no pilot: automatic is fixed there.
  ///  * fixed: the order as given (select_order decides, false: the manuscript's).
  ///  * select: order selection as given (the same as select_order = true).
  /// select_order = true always means selection. WavejetEstimation::setOrder, setBeta and
  /// setSelectOrder make the policy explicit (fixed or select).
  enum class OrderPolicy { automatic, fixed, select };
  OrderPolicy order_policy = OrderPolicy::automatic;
  /// With order_policy automatic and the automatic radius (estimateWavejets radius 0): let
  /// the neighbour count of the radius grow with the measured noise (false: the count as
  /// given, e.g. an explicit `--neighbours`).
  bool adapt_support = true;
  /// While the fitted tangent is tilted by more than `refit_angle` degrees from the
  /// parameterization plane, the plane is rotated into it (Corollary 1) and the fit redone,
  /// at most `max_refits` times (0 to 50). Below it, the first-order corrections of
  /// Corollaries 1 and 2 are applied without refitting. Range of refit_angle: [0, 90].
  /// Measured default 45 degrees (was 10): without refit, the corrected normal stays within
  /// 0.03 degrees of the truth up to 20 degrees of tilt on the bench surfaces, because the
  /// tangent is taken exactly from the fitted height field, and on the rs1 scan every refit
  /// angle below 45 degrees made the curvatures worse (docs/wavejets.md). No refit either
  /// when the tilt is not distinguishable from zero given the fit's residuals (a tilt made
  /// by the noise; WavejetResult::tilt_within_noise).
  int max_refits = 4;
  float refit_angle = 45.f;
  /// Normals are oriented towards `viewpoint` (metres; PCL's convention, default the
  /// origin), unless an orientation hint is given for the point.
  Eigen::Vector3f viewpoint = Eigen::Vector3f::Zero();
  /// Per-point widening of R_phi where the ball holds too few points: at a point whose
  /// ball of R_phi holds fewer than N = `widened_neighbours` distinct positions (self
  /// included), the fit uses its N nearest distinct positions, rescaled to the unit disk of
  /// radius the distance of the farthest; i.e. R_phi at the point = max(R_phi, distance of
  /// its N-th nearest). The manuscript rescales every neighbourhood to the unit disk, so a
  /// per-point R_phi is the same method at that point's sampling scale. Points whose ball
  /// holds N or more keep R_phi exactly. Without it, a scan whose density varies a lot gets
  /// NaN wherever it is sparser than the radius assumes (docs/wavejets.md: 83% of bun0.pcd).
  ///  * automatic (default): only when the radius is chosen from the data (radius 0 in
  ///    estimateWavejets, WavejetEnhancement); an explicit radius is kept as given
  ///    (PCL's semantics: NaN outputs where too few neighbours).
  ///  * always: also with an explicit radius (estimateWavejets, WavejetEstimation with
  ///    setRadiusSearch). `paps curvature` / `paps enhance` use automatic (`--fixed-radius`:
  ///    never).
  ///  * never: fixed radius everywhere (the curvature bench compares methods on the same
  ///    balls).
  enum class Widening { automatic, always, never };
  Widening widening = Widening::automatic;
  /// N above (0 to 100000, at least the count the order needs, beta (K+1)(K+2)/2): 0 = the
  /// target neighbour count of estimateWavejets (50 by default), 50 in WavejetEstimation.
  /// Measured (docs/wavejets.md, bench part "density"): widening only below the order's
  /// need (17 for K = 4) and to that count is ill-conditioned (order 4 on 17 points: sphere
  /// curvature error 0.31 without noise, 0.0036 on 50); "at least N" beats both that and
  /// plain N-nearest neighbourhoods on every surface of the bench.
  int widened_neighbours = 0;
  /// Per-point narrowing, the converse of widening, under the same rule (`widening`: by
  /// default only with the automatic radius): at a point whose ball of R_phi holds more than
  /// `narrowed_neighbours` distinct positions (self included), the fit uses its
  /// `narrowed_neighbours` nearest distinct positions (ties broken by index), rescaled to the
  /// unit disk of radius the distance of the farthest; i.e. R_phi at the point = distance of
  /// its cap-th nearest. Bounds the cost per point where the density is far above the
  /// median (docs/wavejets.md: bun0.pcd, ~2,000 per ball in its dense parts, 6-9 s -> see the
  /// table). 0 = 4 N (N the widening count above, 200 by default); any value is raised to at
  /// least N. Never binds on evenly sampled surfaces (bench part "analytic": 0 narrowed).
  int narrowed_neighbours = 0;
  /// estimateWavejets fits a cloud of more distinct positions than this in tiles of at most
  /// this many (0: one piece whatever the size). The noise, the radius and the order policy
  /// are resolved once on the whole cloud, and each tile carries the points its fits reach,
  /// so the outputs are the one-piece outputs, bit for bit; the working memory is a tile's.
  std::size_t max_tile_points = 2000000;
  /// Throws InvalidParameter naming the first bad value.
  void validate() const;
};

/// Number of real unknowns of an order-K Wavejet: (K+1)(K+2)/2.
inline int wavejetUnknowns(int order) { return (order + 1) * (order + 2) / 2; }
/// Number of stored complex coefficients phi_{k,n}, 0 <= n <= k, n = k mod 2.
inline int wavejetStoredCoefficients(int order) {
  int c = 0;
  for (int k = 0; k <= order; ++k) c += k / 2 + 1;
  return c;
}
/// Storage index of phi_{k,n} (n >= 0, same parity as k).
inline int wavejetIndex(int k, int n) {
  int base = 0;
  for (int j = 0; j < k; ++j) base += j / 2 + 1;
  return base + (n - (k & 1)) / 2;
}

/// The coefficients of one point, in the corrected (tangent) frame, unit-disk units.
struct WavejetCoefficients {
  int order = -1;                 ///< order used at this point (-1: none)
  float radius = 0.f;             ///< R_phi (metres)
  LocalFrame frame;               ///< tangent frame: theta is measured from t1 towards t2
  std::vector<std::complex<float>> phi;  ///< phi_{k,n}, n >= 0, at wavejetIndex(k, n)

  /// phi_{k,n} for any -k <= n <= k (0 when the parities differ or k > order).
  std::complex<float> at(int k, int n) const;
  /// Integral invariant a_n(s) of equation 2.18 in unit-disk units (s in (0, 1]):
  /// sum_{k >= |n|} phi_{k,n} s^{k+2} / (k+2). The offset phi_{0,0} is left out so a_0 is
  /// the volume / 2 pi between the surface and its tangent plane (equation 2.19).
  std::complex<float> integralInvariant(int n, float s = 1.f) const;
};

/// The scalar outputs of one point. Every field is NaN (order -1) when the point could not
/// be fitted.
struct WavejetResult {
  Eigen::Vector3f normal = Eigen::Vector3f::Constant(NAN);     ///< corrected unit normal
  Eigen::Vector3f direction1 = Eigen::Vector3f::Constant(NAN); ///< principal direction of k1
  float k1 = NAN, k2 = NAN;               ///< principal curvatures (1/metres), k1 >= k2
  float mean_curvature = NAN;             ///< (k1 + k2) / 2 (1/metres), equation 2.11
  float gaussian_curvature = NAN;         ///< k1 k2 (1/metres^2), equation 2.10
  float offset = NAN;                     ///< phi_{0,0}: signed distance from p to the
                                          ///< Wavejet surface along the normal (metres)
  float a0 = NAN;                         ///< a_0(R_phi), unit-disk units (equation 2.18)
  std::complex<float> a1{NAN, NAN};       ///< a_1(R_phi), unit-disk units
  int order = -1;                         ///< order used (lowered when few neighbours)
  float radius = NAN;                     ///< R_phi used at this point (metres): the
                                          ///< search radius, or larger where widened
  int fits = 0;                           ///< least-squares fits done (1 + refits)
  /// Root of the unbiased residual variance RSS / (L - M) of the last fit along its plane
  /// normal (metres; NaN without residual degree of freedom): the noise plus what the order
  /// used cannot follow.
  float residual = NAN;
  bool converged = false;                 ///< the tilt fell below refit_angle
  /// The tilt stayed above refit_angle but is not distinguishable from zero given the fit's
  /// own residuals (F test at level 3e-4, 4 standard errors with many neighbours): a tilt
  /// the noise made, so the plane was kept instead of refitting.
  bool tilt_within_noise = false;
  bool valid() const { return order >= 0; }
};

/// Scratch memory reused between points by one thread.
struct WavejetWorkspace;
struct WavejetWorkspaceDeleter { void operator()(WavejetWorkspace*) const; };
using WavejetWorkspacePtr = std::unique_ptr<WavejetWorkspace, WavejetWorkspaceDeleter>;
WavejetWorkspacePtr makeWavejetWorkspace();

/// Fits the Wavejet of point `p` from the neighbours `neighbours[0..count)` (indices into
/// `points`; non-finite ones are skipped; p itself may be among them). `radius` is R_phi in
/// metres. `initial_normal`, when finite, replaces the PCA plane as the first
/// parameterization plane. `orientation`, when finite, orients the normal (else the
/// viewpoint). Needs at least 2 as order after lowering (curvatures); otherwise the result
/// is invalid (NaN). `coefficients` is filled when given.
WavejetResult fitWavejet(const Positions& points, const int* neighbours, int count,
                         const Eigen::Vector3f& p, float radius, const WavejetParameters& params,
                         WavejetWorkspace& workspace,
                         const Eigen::Vector3f& initial_normal = Eigen::Vector3f::Constant(NAN),
                         const Eigen::Vector3f& orientation = Eigen::Vector3f::Constant(NAN),
                         WavejetCoefficients* coefficients = nullptr);

/// What a whole-cloud run met.
struct WavejetReport {
  /// The order policy (WavejetParameters::order_policy): what the run used and why.
  bool noise_measured = false;       ///< automatic policy: the pilot ran
  float noise_sigma = NAN;           ///< residual noise of the pilot's fits (metres)
  float noise_relative = NAN;        ///< noise_sigma / the pilot's R_phi
  /// sigma of a second pilot at 2 R_phi over sigma at R_phi (NaN when not run: clean data
  /// or no growth allowed): near 1 for noise, larger for relief the ball does not resolve;
  /// the support grows only for noise (kWavejetNoiseScaleRatio).
  float noise_scale_ratio = NAN;
  bool select_order = false;         ///< the run selected the order per point (BIC)
  float beta = NAN;                  ///< beta used
  /// The automatic radius over the radius of the target count: 1, or 2 where the policy grew
  /// the support (balls of about 4x the count; sparse balls still widened to the count).
  float support_scale = 1.f;
  float radius = 0.f;                ///< R_phi used (metres)
  double mean_neighbours = 0;        ///< mean neighbour count of the fitted points
  std::size_t fitted = 0;            ///< points with valid outputs
  std::size_t lowered = 0;           ///< fitted at an order below the requested one
  std::size_t too_few_neighbours = 0;///< NaN outputs: not enough neighbours for order 2
  /// NaN outputs although the ball held enough neighbours for order 2 (beta x 6): the fit
  /// was degenerate (neighbours along a line, or a radius far beyond the cloud's extent).
  std::size_t failed_fits = 0;
  std::size_t not_converged = 0;     ///< tilt still above refit_angle after max_refits
  std::size_t tilt_within_noise = 0; ///< tilt above refit_angle but within the noise: no refit
  std::size_t non_finite = 0;        ///< NaN/Inf input points (NaN outputs)
  /// Finite points at exactly the position of an earlier point. The fit counts each
  /// position once (estimateWavejets); every copy gets the output of its position.
  std::size_t duplicates = 0;
  std::size_t widened = 0;           ///< fitted with R_phi widened (WavejetParameters::widening)
  float widened_radius_median = 0.f; ///< median R_phi of the widened points (metres)
  std::size_t narrowed = 0;          ///< fitted with R_phi narrowed (WavejetParameters::narrowed_neighbours)
  float narrowed_radius_median = 0.f;///< median R_phi of the narrowed points (metres)
  float max_radius = 0.f;            ///< largest R_phi used at a fitted point (metres)
  /// Tiles the distinct positions were fitted in (1: one piece; max_tile_points), the most
  /// points one held with its halo (0 in one piece), and how many tiles were run again on a
  /// grown halo because a widened ball reached past it.
  std::size_t tiles = 1;
  std::size_t largest_tile = 0;
  std::size_t grown_halos = 0;
};

/// The count of distinct neighbours (self included) that order `params.order` needs before
/// it is lowered: the smallest L with L >= beta (K+1)(K+2)/2.
int wavejetNeededNeighbours(const WavejetParameters& params);

/// The per-point neighbour counts of widening and narrowing: N = max(need,
/// widened_neighbours or `default_neighbours` when 0) and the cap = max(N,
/// narrowed_neighbours or 4 N when 0).
int wavejetWidenedNeighbours(const WavejetParameters& params, int default_neighbours);
int wavejetNarrowedNeighbours(const WavejetParameters& params, int default_neighbours);

/// Wavejets of every point of `points` with neighbourhoods of radius `radius` (metres; 0:
/// the radius holding `target_neighbours` on average over the distinct positions), widened
/// per point where too few (WavejetParameters::widening). Exact duplicate positions are
/// fitted once and counted once as neighbours; every input point gets an output (the one
/// of its position; initial normals and hints of the first copy). `initial_normals` /
/// `orientation` are optional per-point arrays (see fitWavejet). Deterministic for any
/// thread count. Throws InvalidParameter / InvalidInput / Cancelled.
std::vector<WavejetResult> estimateWavejets(const Positions& points, float radius,
                                            const WavejetParameters& params,
                                            WavejetReport* report = nullptr,
                                            std::vector<WavejetCoefficients>* coefficients = nullptr,
                                            const Normals* initial_normals = nullptr,
                                            const Normals* orientation = nullptr,
                                            const ProgressCallback& progress = {},
                                            int target_neighbours = 50);

}  // namespace paps
