#pragma once
// WavejetEstimation: a pcl::Feature computing, for each input point, the Wavejet of its
// neighbourhood (manuscript 2.4) and from it the corrected normal, principal curvatures and
// direction, mean and Gaussian curvature (equations 2.9 to 2.13) and the integral
// invariants a_0, a_1 (2.18).
//
//   paps::WavejetEstimation<pcl::PointXYZ> wj;
//   wj.setInputCloud(cloud);
//   wj.setRadiusSearch(0.01);      // R_phi in metres (or setKSearch(k): R_phi per point =
//                                  // distance of the k-th neighbour)
//   wj.setOrder(4);
//   pcl::PointCloud<paps::PointWavejet> out;
//   wj.compute(out);               // NaN outputs (is_dense false) where too few neighbours
//
// Without setSearchMethod, radius balls come from a grid of cells of side R_phi instead of
// PCL's default kd-tree (when the indices cover at least an eighth of the search surface):
// the same balls as FLANN's (squared float distances < R_phi^2, as pcl::KdTreeFLANN asks),
// so the same outputs, 1.24-1.33x faster. A search method the caller sets is used as given;
// the kd-tree PCL would make is one that builds its index at its first query (k searches,
// widening, or getSearchMethod()'s user), so radius runs never build it. Index sets of 4,096
// or more are visited in space order (outputs at their own index): a shuffled cloud stays
// in cache (rs1 1M shuffled by k: 1.43x faster, the same outputs).
//
// PCL's own output types work too, as drop-ins for PCL's estimators in a pipeline:
//  - pcl::PrincipalCurvatures (as pcl::PrincipalCurvaturesEstimation): principal_curvature =
//    the unit direction of the curvature of largest magnitude, pc1 >= pc2 >= 0 the magnitudes
//    |k| of the two principal curvatures in 1/metres (PCL's are eigenvalues of the projected
//    normals' covariance, without units; the signs are in PointWavejet's k1, k2);
//  - pcl::Normal, pcl::PointNormal (as pcl::NormalEstimation): the corrected normal, and in
//    `curvature` PCL's surface variation lambda0 / (lambda0 + lambda1 + lambda2) of the same
//    ball (the other fields of the output, x y z for PointNormal, are left as they are).
//
// Bad parameters throw paps::InvalidParameter (naming the parameter and the value), an empty
// input paps::InvalidInput: no silent empty output.
#include <memory>
#include <vector>

#include <pcl/features/feature.h>

#include <paps/core/thread_count.h>
#include <paps/core/view_point_option.h>
#include <paps/features/point_types.h>
#include <paps/features/wavejet.h>

namespace paps {

template <typename PointInT, typename PointOutT = PointWavejet>
class WavejetEstimation : public pcl::Feature<PointInT, PointOutT>, public ThreadCountOption {
  using Base = pcl::Feature<PointInT, PointOutT>;

 public:
  using PointCloudOut = typename Base::PointCloudOut;
  using Ptr = pcl::shared_ptr<WavejetEstimation<PointInT, PointOutT>>;
  using ConstPtr = pcl::shared_ptr<const WavejetEstimation<PointInT, PointOutT>>;

  WavejetEstimation() { this->feature_name_ = "WavejetEstimation"; }

  void setParameters(const WavejetParameters& p) { p.validate(); params_ = p; }
  const WavejetParameters& getParameters() const { return params_; }
  /// Wavejet order K (1 to 20, default 4). Makes the order policy explicit: the order is
  /// kept fixed (unless setSelectOrder(true)), whatever the noise.
  void setOrder(int k) { auto p = params_; p.order = k; explicitPolicy(p); setParameters(p); }
  /// Order lowering rate beta in [1, 100] (default 1.1). Makes the order policy explicit.
  void setBeta(float b) { auto p = params_; p.beta = b; explicitPolicy(p); setParameters(p); }
  /// Per-point order selection by BIC (WavejetParameters::select_order), explicitly on or off.
  void setSelectOrder(bool on) {
    auto p = params_;
    p.select_order = on;
    p.order_policy = on ? WavejetParameters::OrderPolicy::select : WavejetParameters::OrderPolicy::fixed;
    setParameters(p);
  }
  /// Default automatic: a pilot at the search radius measures the noise and keeps the fixed
  /// order on clean data, selects the order (beta >= 3) under noise (wavejet_noise.h). The
  /// radius is the search radius either way (no support growth here).
  void setOrderPolicy(WavejetParameters::OrderPolicy policy) { auto p = params_; p.order_policy = policy; setParameters(p); }
  /// IRLS passes against noise and outliers (0 to 100, default 0).
  void setIrlsIterations(int n) { auto p = params_; p.irls_iterations = n; setParameters(p); }
  /// Plane correction: refit while the tilt exceeds `angle_degrees`, at most `max_refits`.
  void setPlaneCorrection(int max_refits, float angle_degrees) {
    auto p = params_; p.max_refits = max_refits; p.refit_angle = angle_degrees; setParameters(p);
  }
  /// Normals face this point (metres). Without it, as pcl::NormalEstimation, they face the
  /// input's sensor_origin_ when it is set (not 0 0 0), else the parameters' viewpoint
  /// (default the origin).
  void setViewPoint(float x, float y, float z) {
    auto p = params_; p.viewpoint = {x, y, z}; setParameters(p);
    view_point_set_ = true;
  }
  /// Optional first parameterization normals, one per input point (NaN entries: PCA).
  void setInitialNormals(std::shared_ptr<const Normals> n) { initial_normals_ = std::move(n); }
  /// Optional orientation hints, one per input point: the output normal takes their side.
  void setOrientationHints(std::shared_ptr<const Normals> n) { orientation_ = std::move(n); }
  /// Keep the complex coefficients of every point (off by default: memory).
  void setKeepCoefficients(bool keep) { keep_coefficients_ = keep; }
  /// Coefficients of the last compute(), one per index, when setKeepCoefficients(true).
  const std::vector<WavejetCoefficients>& getCoefficients() const { return coefficients_; }
  /// Counts of the last compute() (fitted, order lowered, too few neighbours, ...).
  const WavejetReport& getReport() const { return report_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }

 protected:
  bool initCompute() override;
  void computeFeature(PointCloudOut& output) override;

 private:
  static void explicitPolicy(WavejetParameters& p) {
    if (p.order_policy == WavejetParameters::OrderPolicy::automatic)
      p.order_policy = p.select_order ? WavejetParameters::OrderPolicy::select : WavejetParameters::OrderPolicy::fixed;
  }
  WavejetParameters params_;
  // The search PCL made when none was given (null: none made yet). While it is the one in
  // use, radius balls come from our own grid: the same balls, found faster.
  typename Base::KdTreePtr default_tree_;
  bool grid_search_ = false;
  std::shared_ptr<const Normals> initial_normals_, orientation_;
  bool keep_coefficients_ = false;
  bool view_point_set_ = false;
  std::vector<WavejetCoefficients> coefficients_;
  WavejetReport report_;
  ProgressCallback progress_;
};

/// Writes one result into a PointWavejet (all NaN, order -1, when invalid).
void toPoint(const WavejetResult& r, PointWavejet& out);
/// Into a pcl::PrincipalCurvatures: the direction of the curvature of largest magnitude,
/// pc1 >= pc2 >= 0 the magnitudes (1/m); all NaN when invalid.
void toPoint(const WavejetResult& r, pcl::PrincipalCurvatures& out);

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/features/impl/wavejet_estimation.hpp>
#endif
