#pragma once
// Noise-aware order policy of the Wavejets (WavejetParameters::OrderPolicy::automatic): a
// pilot of order-K fits on a sample of the points measures how far the points scatter about
// the fitted surfaces, and the policy keeps the manuscript's fixed order on clean data and
// selects the order per point (BIC, beta 3), on a support grown with the noise, otherwise.
//
// Why the order-K residual and not the quadric residual of core estimateNoiseLevel: on a
// clean surface with cubic or quartic terms the quadric leaves a residual of the order of
// the noise that matters here (monkey saddle at R_phi: docs/wavejets.md, "Noise-aware
// defaults"), while the order-K fit is exact there; the decision is between order K and
// lower orders, so the residual of order K is the statistic that says whether K fits noise.
#include <cstddef>

#include <paps/core/neighbourhood.h>
#include <paps/features/wavejet.h>

namespace paps {

/// What the pilot measured.
struct WavejetNoise {
  /// Median over the sampled points of the unbiased residual standard deviation of their
  /// order-K fit (metres), corrected for the median of a chi-square.
  float sigma = 0.f;
  /// The same median of residual / R_phi at each point (dimensionless): the noise in units
  /// of the support, what the decision uses.
  float relative = 0.f;
  std::size_t fits = 0;  ///< sampled points with a fit that had residual degrees of freedom
};

/// Order-`params.order` fits (fixed order, no selection) at a deterministic sample of at
/// most `samples` finite points of `points`, each on its ball of `radius` (metres) or, where
/// the ball holds fewer than `neighbours`, on its `neighbours` nearest (as the widening of
/// estimateWavejets). Deterministic for any thread count. Throws InvalidParameter for a bad
/// radius, neighbour or sample count; InvalidInput when no sampled point could be fitted.
WavejetNoise wavejetResidualNoise(const Positions& points, const SpatialIndex& index, float radius,
                                  const WavejetParameters& params, int neighbours, int samples = 1000);

/// Relative residual (residual / R_phi) under which data count as clean: the fixed order is
/// kept. Measured (bench, docs/wavejets.md): clean surfaces read at most 5.3e-7 (float
/// rounding), 0.01% noise reads 1.0e-4, and there the order selection at 2 R_phi is already
/// 10x more accurate than the fixed order; 2e-5 sits between, 38x above the clean reading.
constexpr float kWavejetCleanResidual = 2e-5f;

/// Largest ratio sigma(2 R_phi) / sigma(R_phi) of the pilot's residuals (metres) for which
/// the residual counts as noise, which a larger support averages out, rather than relief
/// finer than the ball, which a larger support would blur: noise is the same at both
/// scales, relief leaves a larger residual at 2 R_phi.
constexpr float kWavejetNoiseScaleRatio = 1.15f;

/// The parameters the automatic policy runs with, from the pilot's relative residual:
/// clean (below kWavejetCleanResidual): `params` unchanged, policy fixed; noisy:
/// select_order, beta at least 3, and `neighbours` (the count of the automatic radius)
/// multiplied by wavejetSupportGrowth(relative) when `grow_support` and `scale_ratio`
/// (sigma at 2 R_phi / sigma at R_phi) is at most kWavejetNoiseScaleRatio. `params` with a
/// policy other than automatic is returned as given.
struct WavejetNoisePolicy {
  WavejetParameters params;
  int neighbours = 0;
  bool noisy = false;
};
WavejetNoisePolicy wavejetNoisePolicy(const WavejetParameters& params, float relative, int neighbours,
                                      bool grow_support, float scale_ratio = 1.f);

/// Factor on the neighbour count of the automatic radius for a relative noise: 1 on clean
/// data, 4 (radius x2, the support PCL's curvature estimator sees) under noise;
/// estimateWavejets applies it as a radius x sqrt(factor).
float wavejetSupportGrowth(float relative);

}  // namespace paps
