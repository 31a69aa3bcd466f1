#pragma once
// Bilateral filtering of point positions (Fleishman, Drori, Cohen-Or 2003), the baseline the
// manuscript compares with. PCL's pcl::BilateralFilter filters intensity only.
//
// Each point moves along its PCA normal n by sum(w_c w_s h) / sum(w_c w_s) over the neighbours
// q within the radius, h = <n, q - p>, w_c = exp(-|q - p|^2 / 2 sigma_c^2) (closeness),
// w_s = exp(-h^2 / 2 sigma_s^2) (feature preservation).
#include <pcl/filters/filter.h>

#include <paps/core/normal_refresh.h>
#include <paps/core/thread_count.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

struct PointBilateralParameters {
  /// Neighbourhood radius in metres (> 0), or 0: from `target_neighbours`.
  float radius = 0.f;
  int target_neighbours = 30;
  /// Spatial kernel sigma_c as a fraction of the radius (> 0). Fleishman: radius / 2.
  float sigma_c_fraction = 0.5f;
  /// Height kernel sigma_s in metres (> 0), or 0: the standard deviation of the heights
  /// in each neighbourhood (Fleishman's choice).
  float sigma_s = 0.f;
  /// Filter passes (1 to 100).
  int iterations = 1;
  /// A cloud of more finite points than this is filtered in tiles of at most this many points,
  /// one after the other (0: one piece whatever the size). The neighbour lists of a whole
  /// cloud take about 4 bytes a neighbour a point (5M points at 120 neighbours: 5.3 GB in
  /// all). Each tile carries the points within `iterations` radii of its core, which is all
  /// the filter reads, and the radius is chosen once on the whole cloud: the output is the
  /// one-piece output (to rounding).
  std::size_t max_tile_points = 2000000;
  void validate() const;
};

struct PointBilateralReport {
  float radius = 0.f;
  /// Points the last pass moved; points left in place (fewer than 4 neighbours, or only
  /// collinear ones: no normal); NaN/Inf.
  std::size_t moved = 0, isolated = 0, non_finite = 0;
  /// Tiles the cloud was filtered in (1: one piece) and the most points one of them held,
  /// halo included.
  std::size_t tiles = 1, largest_tile = 0;
};

/// Bilateral filter on positions; non-finite points pass through; only `movable` points move.
Positions bilateralFilterPositions(const Positions& points, const PointBilateralParameters& params,
                                   PointBilateralReport* report = nullptr,
                                   const std::vector<std::uint8_t>& movable = {},
                                   const ProgressCallback& progress = {});

/// The pcl::Filter stage: the points in the indices move; for a point type with normals their
/// normals and curvature are estimated again on the output at the filter's radius
/// (NormalRefreshOption; off: the input's are kept).
template <typename PointT>
class PointBilateralFilter : public pcl::Filter<PointT>, public ThreadCountOption, public NormalRefreshOption {
  using Base = pcl::Filter<PointT>;
  using PointCloud = typename Base::PointCloud;

 public:
  using Ptr = pcl::shared_ptr<PointBilateralFilter<PointT>>;
  PointBilateralFilter() { this->filter_name_ = "PointBilateralFilter"; }
  void setParameters(const PointBilateralParameters& p) { p.validate(); params_ = p; }
  const PointBilateralParameters& getParameters() const { return params_; }
  void setRadius(float r) { auto p = params_; p.radius = r; setParameters(p); }
  void setIterations(int n) { auto p = params_; p.iterations = n; setParameters(p); }
  /// Clouds of more finite points are filtered in tiles of at most n points (0: one piece).
  void setMaxTilePoints(std::size_t n) { auto p = params_; p.max_tile_points = n; setParameters(p); }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const PointBilateralReport& getReport() const { return report_; }

  /// As pcl::Filter::filter, but without an input cloud it throws InvalidInput (PCL's only
  /// prints a message and leaves `output` as it was).
  void filter(PointCloud& output) {
    requireInputCloud(this->input_);
    Base::filter(output);
  }

 protected:
  void applyFilter(PointCloud& output) override;

 private:
  PointBilateralParameters params_;
  PointBilateralReport report_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/filters/impl/point_bilateral_filter.hpp>
#endif
