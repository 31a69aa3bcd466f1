#pragma once
// Plane+height patch descriptor (manuscript 2.2.1): the heights of the neighbours over the
// tangent plane of a local frame, interpolated at the samples of a fixed sampling pattern.
#include <cstdint>
#include <vector>

#include <paps/core/local_frame.h>

namespace paps {

/// Sample positions in the tangent plane, in units of the patch radius (inside the unit disk).
struct SamplingPattern {
  std::vector<Eigen::Vector2f> samples;
  /// Spacing between neighbouring samples, in units of the patch radius; sets the
  /// interpolation kernel width.
  float spacing = 1.f;

  /// n x n grid aligned with (t1, t2), covering the square inscribed in the unit disk.
  static SamplingPattern grid(int n);
  /// Radial pattern (Fig. 2.4): the centre plus `rings` rings of `sectors` samples.
  static SamplingPattern radial(int rings, int sectors);
  std::size_t size() const { return samples.size(); }
};

/// Computes HP(p) for a frame placed at an origin. Heights are interpolated from the
/// irregular neighbours by a normalised Gaussian radial basis (Nadaraya-Watson) of width
/// `kernel_width` x spacing; a sample is valid when enough weight reaches it, and an invalid
/// sample has height 0.
class PlaneHeightPatch {
 public:
  /// radius: patch radius in metres (> 0). kernel_width: in units of the pattern spacing.
  PlaneHeightPatch(SamplingPattern pattern, float radius, float kernel_width = 0.6f);

  std::size_t size() const { return pattern_.size(); }
  const SamplingPattern& pattern() const { return pattern_; }
  float radius() const { return radius_; }

  /// Fills heights[size()] (metres) and valid[size()] from the points `neighbours[0..count)`
  /// of `points`, seen in `frame` placed at `origin`. Returns the number of valid samples.
  int describe(const LocalFrame& frame, const Eigen::Vector3f& origin, const Positions& points,
               const int* neighbours, int count, float* heights, std::uint8_t* valid) const;

 private:
  SamplingPattern pattern_;
  float radius_;
  float inv_two_sigma2_;  // Gaussian kernel, in metres^-2
  float min_weight_;      // below this summed weight a sample is invalid
};

}  // namespace paps
