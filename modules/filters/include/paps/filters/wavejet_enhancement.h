#pragma once
// Wavejet detail enhancement (manuscript 2.4.3).
//
// Position filter (equation 2.21): each point moves along its corrected normal by
//   d = phi_{0,0} - 2 pi (alpha_0 - 1) a_0(s),   s = R_phi,
// in unit-disk units (R_phi = 1), then scaled by R_phi to metres. alpha_0 = 1 projects the
// point on its Wavejet surface; alpha_0 > 1 enhances details, 0 < alpha_0 < 1 smooths them,
// alpha_0 < 0 gives anti-details. |d| is clamped at `max_motion` x R_phi (manuscript: 1/2),
// where the neighbourhood is not a height field; clamped points are counted.
//
// Normal filter (equation 2.22): positions stay, the tangent-plane coefficient phi_{1,1} is
// set to phi'_{1,1} = -pi (alpha_1 - 1) a_1(s) and the false normal is the normal of the
// plane it defines (Corollary 1). alpha_1 is complex (alpha_{-1} = conj(alpha_1)):
// alpha_1 = 2 sharpens the shading, 0 flattens it, imaginary values skew the normals
// (Fig. 2.29). Here theta turns from t1 to t2 and phi_{k,n} multiplies e^{+i n theta}.
//
// a_0 and a_1 are taken in the corrected tangent plane and without phi_{0,0} (volume
// between the surface and its tangent plane, eq. 2.19).
#include <complex>
#include <cstdint>
#include <vector>

#include <pcl/filters/filter.h>

#include <paps/core/thread_count.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>
#include <paps/features/wavejet.h>

namespace paps {

/// WavejetParameters with the order policy fixed (the manuscript's fixed order).
inline WavejetParameters fixedOrderWavejet() {
  WavejetParameters w;
  w.order_policy = WavejetParameters::OrderPolicy::fixed;
  return w;
}

/// Parameters of Wavejet enhancement. Zero radius means "choose from the data".
struct WavejetEnhancementParameters {
  /// R_phi = s in metres (> 0), or 0: the radius holding `target_neighbours` on average
  /// over the distinct positions, widened per point where the ball holds too few for the
  /// order (WavejetParameters::widening; the motion is then scaled by that point's R_phi).
  float radius = 0.f;
  /// Mean neighbour count that sets the radius (3 to 100000). Default 50.
  int target_neighbours = 50;
  /// The Wavejet fit (order, beta, IRLS, plane correction, viewpoint for orientation).
  /// The order policy defaults to fixed here, not automatic as for curvatures: the filters
  /// scale the coefficients of the orders above 1, which the order selection drops under
  /// noise (a normal gain then changes nothing: measured in the PCL filter test); set
  /// automatic to have the noise decide.
  WavejetParameters wavejet = fixedOrderWavejet();
  /// Position gain alpha_0 (finite). 1: projection on the Wavejet surface.
  float alpha0 = 2.f;
  /// Normal gain alpha_1 (finite, complex). 1: the corrected normal unchanged.
  std::complex<float> alpha1{2.f, 0.f};
  /// Motion clamp as a fraction of R_phi (> 0). Manuscript: 0.5.
  float max_motion = 0.5f;
  void validate() const;
};

/// What a run chose and met.
struct WavejetEnhancementReport {
  float radius = 0.f;            ///< R_phi used (metres)
  double mean_neighbours = 0;    ///< mean neighbour count at that radius
  std::size_t changed = 0;       ///< points moved (positions) or re-oriented (normals)
  std::size_t clamped = 0;       ///< motions clamped at max_motion x R_phi
  std::size_t unfitted = 0;      ///< too few neighbours: left unchanged (normal NaN)
  std::size_t non_finite = 0;    ///< NaN/Inf points passed through
  std::size_t lowered = 0;       ///< fitted with a lowered order
  std::size_t duplicates = 0;    ///< points at the exact position of an earlier one (fitted once)
  std::size_t widened = 0;       ///< fitted with R_phi widened (too few points in the ball)
  float widened_radius_median = 0.f;  ///< median R_phi of those (metres)
  std::size_t narrowed = 0;      ///< fitted with R_phi narrowed (more than the cap in the ball)
  float narrowed_radius_median = 0.f; ///< median R_phi of those (metres)
  /// The whole report of the Wavejet fits, with the order policy chosen (noise measured,
  /// order selection, beta, neighbour count).
  WavejetReport wavejet;
};

/// Position filter (2.21) of `points`; only points with movable[i] (all when empty) move.
/// `normals_out`, when given, receives the corrected normals (NaN where unfitted).
/// Orientation: `orientation` hints when given, else the viewpoint of params.wavejet.
Positions enhancePositions(const Positions& points, const WavejetEnhancementParameters& params,
                           WavejetEnhancementReport* report = nullptr,
                           const std::vector<std::uint8_t>& movable = {},
                           const ProgressCallback& progress = {}, const Normals* orientation = nullptr,
                           Normals* normals_out = nullptr);

/// Normal filter (2.22): the false normals (NaN where unfitted).
Normals enhanceNormals(const Positions& points, const WavejetEnhancementParameters& params,
                       WavejetEnhancementReport* report = nullptr, const ProgressCallback& progress = {},
                       const Normals* orientation = nullptr);

/// The normals of the enhanced surface: the corrected Wavejet normals of `enhanced` (the
/// position filter's output), fitted with the same parameters, on the side of `corrected` (the
/// input's corrected normals, enhancePositions' normals_out). NaN where unfitted. What a cloud
/// with normals should carry after the position filter: the input's corrected normals
/// describe the surface before the enhancement.
Normals enhancedSurfaceNormals(const Positions& enhanced, const WavejetEnhancementParameters& params,
                               const Normals& corrected, const ProgressCallback& progress = {});

/// The pcl::Filter stage. Mode positions: x y z of the points in the indices move (equation
/// 2.21), and for point types with normals these are set to the normals of the enhanced
/// surface (enhancedSurfaceNormals). Mode
/// normals: x y z stay and the normals of the indexed points become the false normals of
/// 2.22 (the point type must have normals). Input normals, when present and finite, orient
/// the output; otherwise the viewpoint does.
template <typename PointT>
class WavejetEnhancement : public pcl::Filter<PointT>, public ThreadCountOption {
  using Base = pcl::Filter<PointT>;
  using PointCloud = typename Base::PointCloud;

 public:
  using Ptr = pcl::shared_ptr<WavejetEnhancement<PointT>>;
  using ConstPtr = pcl::shared_ptr<const WavejetEnhancement<PointT>>;
  enum class Mode { positions, normals };

  WavejetEnhancement() { this->filter_name_ = "WavejetEnhancement"; }

  void setParameters(const WavejetEnhancementParameters& p) { p.validate(); params_ = p; }
  const WavejetEnhancementParameters& getParameters() const { return params_; }
  /// R_phi in metres; 0 chooses it from the target neighbour count.
  void setRadius(float r) { auto p = params_; p.radius = r; setParameters(p); }
  void setOrder(int k) { auto p = params_; p.wavejet.order = k; setParameters(p); }
  /// Position filter with gain alpha_0.
  void setPositionGain(float alpha0) { auto p = params_; p.alpha0 = alpha0; setParameters(p); mode_ = Mode::positions; }
  /// Normal filter with complex gain alpha_1.
  void setNormalGain(std::complex<float> alpha1) { auto p = params_; p.alpha1 = alpha1; setParameters(p); mode_ = Mode::normals; }
  Mode getMode() const { return mode_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const WavejetEnhancementReport& getReport() const { return report_; }

  /// As pcl::Filter::filter, but without an input cloud it throws InvalidInput (PCL's only
  /// prints a message and leaves `output` as it was).
  void filter(PointCloud& output) {
    requireInputCloud(this->input_);
    Base::filter(output);
  }

 protected:
  void applyFilter(PointCloud& output) override;

 private:
  WavejetEnhancementParameters params_;
  Mode mode_ = Mode::positions;
  WavejetEnhancementReport report_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/filters/impl/wavejet_enhancement.hpp>
#endif
