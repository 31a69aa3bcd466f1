#pragma once
// Quadric+height patch descriptor (manuscript 2.3.1). Around a point, a quadric is regressed
// robustly (l1, by IRLS) in the PCA frame of its neighbours; its first and second
// fundamental forms give the principal curvatures k1 >= k2 and directions, hence the
// intrinsic frame (t1, t2, n) in which the quadric reads Q(x, y) = k1 x^2 / 2 + k2 y^2 / 2.
// A grid of bins is laid on Q with centres at equal geodesic steps along the two principal
// curves, and each bin holds the height of the neighbours over the plane tangent to Q at the
// bin (equation 2.2), with a validity flag.
#include <cstdint>
#include <vector>

#include <paps/core/local_frame.h>

namespace paps {

/// The local quadric of a point, in its intrinsic frame.
struct QuadricFit {
  enum class Status : std::uint8_t {
    Quadric,        ///< well-posed quadric fit
    FlatPlane,      ///< curvature below the resolution of the patch: the plane is used
    TooFewPoints,   ///< fewer than 6 neighbours: plane (if 3 or more), k1 = k2 = 0
    Degenerate,     ///< collinear neighbours or singular system: plane or given frame
  };
  /// t1, t2: principal directions of k1, k2; n: unit normal. origin: the point of the quadric
  /// above the centre (metres).
  LocalFrame frame;
  Eigen::Vector3f origin = Eigen::Vector3f::Zero();
  float k1 = 0.f, k2 = 0.f;  ///< principal curvatures (1/m), k1 >= k2
  Status status = Status::Degenerate;
  /// How well the neighbours determine the regression: the smallest eigenvalue of its normal
  /// matrix A^T A / m, coordinates in units of the radius (a uniform disc about 0.03, a half
  /// disc 2e-3, points along two parallel lines 1e-5, along one line 1e-8, whatever their
  /// count); 0 when the fit stopped before the regression (fewer than 6 points, collinear).
  float conditioning = 0.f;
  bool isPlaneFallback() const { return status != Status::Quadric; }
  /// Q(x, y) in the intrinsic frame (metres).
  float height(float x, float y) const { return 0.5f * (k1 * x * x + k2 * y * y); }
  /// Unit normal of Q at (x, y), in intrinsic coordinates.
  Eigen::Vector3f normalAt(float x, float y) const {
    return Eigen::Vector3f(-k1 * x, -k2 * y, 1.f).normalized();
  }
};

/// Options of the quadric regression.
struct QuadricFitOptions {
  /// IRLS reweighting passes of the l1 regression (0: least squares). Manuscript: l1.
  int irls_iterations = 4;
  /// Below max(|k1|, |k2|) * radius < flat_threshold the fit falls back to the plane.
  float flat_threshold = 1e-3f;
  /// Below |k1 - k2| * radius < umbilic_threshold the principal directions are not
  /// defined by the quadric; t1 then comes from `direction_hint` (if given) and k1 = k2.
  float umbilic_threshold = 0.02f;
};

/// Fits the quadric of the neighbours `nb[0..count)` of `points` around `centre`, within
/// `radius` (metres, > 0). `normal_hint` (unit, or null) orients n; `direction_hint` (or null)
/// gives t1 when the directions are undefined (plane, umbilic). Never throws on bad
/// geometry: the status says which fallback was taken.
QuadricFit fitQuadric(const Positions& points, const Eigen::Vector3f& centre, const int* nb, int count,
                      float radius, const Eigen::Vector3f* normal_hint = nullptr,
                      const Eigen::Vector3f* direction_hint = nullptr,
                      const QuadricFitOptions& options = {});

/// Abscissa x >= 0 (sign of s) at which the arc length of y = a x^2 from 0 equals s.
float parabolaAbscissaForArcLength(float a, float s);

/// The quadric+height descriptor: grid_size^2 bins on Q, geodesically equidistant along the
/// principal curves, covering the square inscribed in the disk of the patch radius.
class QuadricHeightPatch {
 public:
  /// grid_size: bins per side (1 to 64). radius: patch radius (metres, > 0). kernel_width:
  /// the Gaussian width d_lr of equation 2.2 in units of the bin spacing (> 0).
  /// irls_passes: robust reweighting passes of the bin heights (0 to 10).
  QuadricHeightPatch(int grid_size, float radius, float kernel_width = 0.6f, int irls_passes = 0);
  int gridSize() const { return n_; }
  std::size_t size() const { return static_cast<std::size_t>(n_) * n_; }
  float radius() const { return radius_; }
  /// Geodesic distance between adjacent bin centres (metres).
  float binSpacing() const { return spacing_; }
  /// Geodesic coordinate of bin index i (metres, centred on 0).
  float binCoordinate(int i) const { return (i - 0.5f * (n_ - 1)) * spacing_; }
  /// Bin centres in intrinsic coordinates (x, y, Q(x, y)), row-major (row = t2 index).
  void binCentres(const QuadricFit& fit, Eigen::Vector3f* centres) const;
  /// Fills heights[size()] (metres) and valid[size()] from the neighbours nb[0..count) of
  /// `points` (equation 2.2). Invalid bins (too little kernel weight) get height 0.
  /// Returns the number of valid bins.
  int describe(const QuadricFit& fit, const Positions& points, const int* nb, int count,
               float* heights, std::uint8_t* valid) const;
  /// Minimum summed kernel weight of a valid bin.
  float minWeight() const { return min_weight_; }

 private:
  int n_;
  float radius_, spacing_, inv_two_sigma2_, min_weight_;
  int irls_passes_;
};

}  // namespace paps
