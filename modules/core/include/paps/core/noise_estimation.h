#pragma once
// Noise level of a sampled surface: how far the points scatter about the surface, estimated
// from the residuals of local quadric fits, so that stages can scale themselves to the noise
// of the data (a user rarely knows it).
#include <cstddef>

#include <paps/core/neighbourhood.h>

namespace paps {

/// Whether an upsampler denoises its input first: from the noise it measures (Auto), always
/// (On) or never (Off). QSR and LPF resampling each have their own Auto rule.
enum class DenoiseFirst { Off, Auto, On };

/// What estimateNoiseLevel measured.
struct NoiseEstimate {
  /// Standard deviation of the points' offsets along the surface normal (metres): the noise,
  /// plus whatever relief a quadric over the ball cannot follow (detail finer than the ball).
  float sigma = 0.f;
  /// Ball radius the fits were made at (metres); larger than the requested one when the
  /// noise was too thick for a plane to be found at that radius.
  float radius = 0.f;
  /// Sampled points whose ball held enough points for a fit.
  std::size_t fits = 0;
};

/// Estimates the noise of `points` (finite entries only) at the scale `radius` (metres, > 0):
/// on a deterministic sample of at most `samples` points, a height quadric
/// h = a0 + a1 u + a2 v + a3 u^2 + a4 uv + a5 v^2 is fitted by least squares over each ball in
/// its PCA frame; sigma^2 is the median of the unbiased residual variances RSS / (n - 6),
/// corrected for the median of a chi-square. When sigma comes out above radius / 5 the PCA
/// plane is not trustworthy (the noise slab is as thick as the ball is wide) and the radius
/// grows to 5 sigma x 1.25, at most 4 times. Where most balls hold more than 1,500 points the
/// fits run on an even thinning of the cloud (by position hash) whose balls hold about 800,
/// so that a dense cloud reads the noise a sparse one does (the 1,500 nearest would be a
/// smaller ball, which cuts a thick noise slab). Deterministic. Throws InvalidParameter for a bad
/// radius or sample count, InvalidInput when no ball holds the 10 points a fit needs.
NoiseEstimate estimateNoiseLevel(const Positions& points, const SpatialIndex& index, float radius,
                                 int samples = 2000);

/// How much the residual of the quadric fits grows from balls of `radius` to balls of twice
/// it: sigma(2 radius) / sigma(radius) (estimateNoiseLevel). Near 1 where the surface is smooth
/// at that scale (what the fits leave is noise), above where it has relief finer than the
/// balls (the wider fits leave it too). `at_radius` > 0: sigma(radius), already measured.
/// Returns 0 when sigma(radius) is 0. Throws as estimateNoiseLevel.
float noiseGrowth(const Positions& points, const SpatialIndex& index, float radius, float at_radius = 0.f);

}  // namespace paps
