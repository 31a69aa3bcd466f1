#pragma once
// Distortion measures of a decoded cloud against its reference, in the MPEG PCC style:
// D1 (point-to-point) and D2 (point-to-plane, normals estimated on the reference), each
// symmetric (the worse of the two directions), as RMSE and PSNR with the bounding-box
// diagonal of the reference as the peak; and the share of reference points farther than a
// tolerance from the decoded surface (Table 2.1, last column).
#include <memory>

#include <paps/core/positions.h>

namespace paps::compression {

struct CloudErrors {
  double d1_rmse = 0, d1_psnr = 0;  ///< metres, dB
  double d2_rmse = 0, d2_psnr = 0;  ///< metres, dB
  /// Share of reference points whose distance to the decoded surface (the plane fitted to
  /// their 8 nearest decoded points) exceeds `tolerance`.
  double share_above_tolerance = 0;
  double peak = 0;  ///< metres
};

/// Both clouds must have finite points (non-finite ones are skipped). `normal_neighbours`
/// reference points estimate each reference normal (PCA). Throws InvalidInput when either
/// cloud has fewer than 3 finite points.
CloudErrors compareClouds(const Positions& reference, const Positions& decoded, double tolerance,
                          int normal_neighbours = 12);

/// A reference cloud prepared once (finite points, spatial index, PCA normals), for comparing
/// many decoded clouds against it: same results as compareClouds, without redoing that work.
class PreparedReference {
 public:
  explicit PreparedReference(const Positions& reference, int normal_neighbours = 12);
  ~PreparedReference();
  PreparedReference(const PreparedReference&) = delete;
  PreparedReference& operator=(const PreparedReference&) = delete;
  CloudErrors compare(const Positions& decoded, double tolerance) const;

 private:
  struct Data;
  std::unique_ptr<Data> d_;
};

}  // namespace paps::compression
