#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <type_traits>

#include <paps/core/cell_grid.h>
#include <paps/core/error.h>
#include <paps/core/positions.h>
#include <paps/core/spatial_order.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/kd_tree_search.h>
#include <paps/features/wavejet_estimation.h>
#include <paps/features/wavejet_noise.h>

namespace paps {

namespace detail {
// Output types written by toPoint; the others (pcl::Normal, pcl::PointNormal, ...) get the
// normal and PCL's surface variation.
template <typename PointOutT>
constexpr bool kWavejetToPoint =
    std::is_same_v<PointOutT, PointWavejet> || std::is_same_v<PointOutT, pcl::PrincipalCurvatures>;
}  // namespace detail

template <typename PointInT, typename PointOutT>
bool WavejetEstimation<PointInT, PointOutT>::initCompute() {
  params_.validate();
  if (!this->input_) throw InvalidInput("no input cloud set");
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  if (this->search_radius_ != 0.0 && this->k_ != 0)
    throw InvalidParameter("search", "radius and k", "either setRadiusSearch(R_phi) or setKSearch(k), not both");
  if (this->search_radius_ == 0.0 && this->k_ == 0)
    throw InvalidParameter("search", "none", "setRadiusSearch(R_phi > 0) or setKSearch(k > 0)");
  if (this->k_ == 0) requirePositive("radius (R_phi)", this->search_radius_);
  if (this->k_ < 0 || this->k_ > 100000) throw InvalidParameter("k", detail::toString(this->k_), "0 < k <= 100000");
  {
    const Positions surface = positionsOf(this->surface_ ? *this->surface_ : *this->input_);
    // PCL's kd-tree would be built on nothing and then queried (a crash, not an error).
    if (this->surface_ && this->surface_ != this->input_ && countFinite(surface) == 0)
      throw InvalidInput(this->surface_->empty() ? "the search surface is empty"
                                                 : "no finite point in the search surface (all NaN or Inf)");
    if (this->k_ == 0) requireRadiusWithinExtent("radius (R_phi)", static_cast<float>(this->search_radius_), surface);
  }
  if (initial_normals_ && initial_normals_->size() != this->input_->size())
    throw InvalidParameter("initial_normals", detail::toString(initial_normals_->size()), "one per input point");
  if (orientation_ && orientation_->size() != this->input_->size())
    throw InvalidParameter("orientation_hints", detail::toString(orientation_->size()), "one per input point");
  const bool default_search = !this->tree_ || this->tree_ == default_tree_;
  // Where PCL would make a pcl::search::KdTree, a paps::KdTreeSearch: the same lists, about
  // 3x faster a query, built at its first query (the grid answers radius balls without it).
  // Organized clouds keep PCL's OrganizedNeighbor.
  if (!this->tree_) {
    const auto& surface = this->surface_ ? this->surface_ : this->input_;
    if (!(surface->isOrganized() && this->input_->isOrganized()))
      this->tree_ = pcl::make_shared<KdTreeSearch<PointInT>>();
  }
  if (!Base::initCompute()) throw InvalidInput("pcl::Feature::initCompute failed (see PCL's message)");
  default_tree_ = default_search ? this->tree_ : nullptr;
  grid_search_ = default_search && this->k_ == 0;
  checkIndices(*this->indices_, this->input_->size());
  return true;
}

template <typename PointInT, typename PointOutT>
void WavejetEstimation<PointInT, PointOutT>::computeFeature(PointCloudOut& output) {
  static_assert(detail::kWavejetToPoint<PointOutT> || detail::HasNormal<PointOutT>::value,
                "WavejetEstimation writes paps::PointWavejet, pcl::PrincipalCurvatures, or a type with normals");
  constexpr bool variation_out = !detail::kWavejetToPoint<PointOutT> && detail::HasCurvature<PointOutT>::value;
  const ScopedThreadCount threads(this->threads_);
  const Positions surface = positionsOf(*this->surface_);
  const pcl::Indices& indices = *this->indices_;
  const std::int64_t count = static_cast<std::int64_t>(indices.size());
  coefficients_.clear();
  if (keep_coefficients_) coefficients_.resize(indices.size());
  const bool by_radius = this->k_ == 0;
  // The order policy: automatic runs the pilot over the search surface at the search radius
  // (for a k search, the radius holding k on average), no support growth.
  WavejetParameters run = params_;
  bool measured = false;
  WavejetNoise noise;
  if (run.order_policy == WavejetParameters::OrderPolicy::select) run.select_order = true;
  if (run.order_policy == WavejetParameters::OrderPolicy::automatic && !run.select_order) {
    SpatialIndex index(surface);
    try {
      const int k = by_radius ? 50 : this->k_;
      const float r0 = by_radius ? static_cast<float>(this->search_radius_) : radiusForNeighbourCount(surface, index, k);
      noise = wavejetResidualNoise(surface, index, r0, params_, wavejetWidenedNeighbours(params_, k));
      measured = true;
      run = wavejetNoisePolicy(params_, noise.relative, k, false).params;
      // Beta 3 only where every ball is widened to the count it needs (as estimateWavejets).
      if (!(by_radius && run.widening == WavejetParameters::Widening::always)) run.beta = params_.beta;
    } catch (const InvalidInput&) {
      run.order_policy = WavejetParameters::OrderPolicy::fixed;
    }
  }
  if (!view_point_set_)
    if (const auto origin = knownSensorOrigin(this->input_->sensor_origin_.template head<3>())) run.viewpoint = *origin;
  // Widening (WavejetParameters::widening): the radius here is always explicit, so only
  // Widening::always widens, to the `widen_to` nearest points of the search surface (exact
  // duplicates are not merged here: they count as neighbours).
  const bool widen = by_radius && run.widening == WavejetParameters::Widening::always;
  const int need = wavejetNeededNeighbours(run);
  const int widen_to = wavejetWidenedNeighbours(run, 50);
  // Narrowing under the same rule: a ball with more than `narrow_to` points keeps its
  // `narrow_to` nearest (ties by index), at their radius.
  const int narrow_to = wavejetNarrowedNeighbours(run, 50);
  const Eigen::Vector3f nan3 = Eigen::Vector3f::Constant(NAN);
  // Radius balls from a grid where the search is PCL's default: its kd-tree descent took
  // 46% of the time (perf, 1M points, one thread). The ball is FLANN's: open, with the float
  // squared radius pcl::KdTreeFLANN passes, and distances summed in FLANN's order
  // ((dx^2 + dy^2) + dz^2; Eigen's squaredNorm adds dx^2 + (dy^2 + dz^2), which put a point
  // at exactly R^2 in one ball of 28,572 on rs1). The fit sorts its list, so the outputs
  // are the same bits.
  // Only for many queries: for a few indices into a large surface (keypoints) the grid's
  // build and its copy of the surface would cost more than the kd-tree's descents save.
  CellGrid grid;
  const bool use_grid = grid_search_ && indices.size() * 8 >= surface.size() &&
                        grid.build(surface, static_cast<float>(this->search_radius_));
  const float grid_r2 = static_cast<float>(this->search_radius_ * this->search_radius_);
  // Cells a little past R: a point FLANN keeps may lie a rounding beyond it.
  const float grid_reach = static_cast<float>(this->search_radius_) * (1 + 1e-5f);
  // The points are visited in space order (Z-order of their positions), each output still
  // written at its own index: on a shuffled cloud the searches and fits stay in cache
  // (FLANN's k searches 1.7x faster on rs1 1M in that order, one thread).
  std::vector<int> visit;
  if (count >= 4096) {
    Positions queries(indices.size());
    for (std::size_t i = 0; i < indices.size(); ++i) queries[i] = (*this->input_)[indices[i]].getVector3fMap();
    visit = spatialOrderAll(queries);
  }
  ProgressReporter reporter(progress_, "wavejets", indices.size());
  // Each fit goes straight into the output and the report's counts: no per-point copy of the
  // results (76 bytes a point, a third of the peak at 5M points). The counts are integer
  // sums and a maximum, so the report does not depend on how the threads split the points.
  report_ = WavejetReport();
  std::uint64_t neighbour_sum = 0;
  bool dense = true;
#pragma omp parallel
  {
    WavejetReport counts;
    std::uint64_t neighbours_here = 0;
    bool dense_here = true;
    WavejetWorkspacePtr ws = makeWavejetWorkspace();
    pcl::Indices nn;
    std::vector<float> d2;
    std::vector<int> nn_int;
    std::vector<std::pair<float, int>> order;
    CellGrid::Cursor cursor;
    const auto ball = [&](pcl::index_t idx, const Eigen::Vector3f& q) -> int {
      if (!use_grid) return this->searchForNeighbors(idx, this->search_parameter_, nn, d2);
      nn.clear();
      d2.clear();
      grid.forEachInReach(q, grid_reach, cursor, [&](int slot) {
        const Eigen::Vector3f d = q - grid.sorted()[static_cast<std::size_t>(slot)];
        float dd = d.x() * d.x();
        dd += d.y() * d.y();
        dd += d.z() * d.z();
        if (dd < grid_r2) {
          nn.push_back(grid.original()[static_cast<std::size_t>(slot)]);
          d2.push_back(dd);
        }
      });
      return static_cast<int>(nn.size());
    };
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t k = 0; k < count; ++k) {
      if (reporter.cancelled()) continue;
      const std::int64_t i = visit.empty() ? k : visit[static_cast<std::size_t>(k)];
      const auto idx = indices[i];
      const Eigen::Vector3f p = (*this->input_)[idx].getVector3fMap();
      WavejetResult result;
      float variation = NAN;  // as pcl::NormalEstimation's curvature
      int neighbour_count = 0;
      bool widened = false, narrowed = false;
      if (isFinite(p) && ball(idx, p) > 0) {
        float radius = static_cast<float>(this->search_radius_);
        if (widen && static_cast<int>(nn.size()) < widen_to &&
            this->tree_->nearestKSearch((*this->input_)[idx], widen_to, nn, d2) >= need) {
          widened = true;
          float m = 0.f;
          for (const float d : d2) m = std::max(m, d);
          radius = std::max(radius, std::sqrt(m));
        } else if (widen && static_cast<int>(nn.size()) < widen_to) {
          ball(idx, p);  // restore the ball
        } else if (widen && static_cast<int>(nn.size()) > narrow_to) {
          order.resize(nn.size());
          for (std::size_t j = 0; j < nn.size(); ++j) order[j] = {d2[j], static_cast<int>(nn[j])};
          std::nth_element(order.begin(), order.begin() + (narrow_to - 1), order.end());
          std::sort(order.begin(), order.begin() + narrow_to);
          nn.resize(narrow_to);
          for (int j = 0; j < narrow_to; ++j) nn[j] = order[j].second;
          narrowed = true;
          radius = std::sqrt(order[narrow_to - 1].first);
        }
        if (!by_radius) {
          float m = 0.f;
          for (const float d : d2) m = std::max(m, d);
          radius = std::sqrt(m);
        }
        nn_int.assign(nn.begin(), nn.end());
        neighbour_count = static_cast<int>(nn_int.size());
        result = fitWavejet(surface, nn_int.data(), neighbour_count, p, radius, run, *ws,
                            initial_normals_ ? (*initial_normals_)[idx] : nan3,
                            orientation_ ? (*orientation_)[idx] : nan3,
                            keep_coefficients_ ? &coefficients_[i] : nullptr);
        if constexpr (variation_out)
          if (result.valid()) pcaNormal(surface, nn_int.data(), neighbour_count, nullptr, &variation);
      }
      if constexpr (detail::kWavejetToPoint<PointOutT>) {
        toPoint(result, output[i]);
      } else {
        output[i].getNormalVector3fMap() = result.normal;
        if constexpr (variation_out) output[i].curvature = variation;
      }
      if (!isFinite(p)) {
        ++counts.non_finite;
        dense_here = false;
      } else if (!result.valid()) {
        ++(neighbour_count >= run.beta * wavejetUnknowns(2) ? counts.failed_fits : counts.too_few_neighbours);
        dense_here = false;
      } else {
        ++counts.fitted;
        neighbours_here += static_cast<std::uint64_t>(neighbour_count);
        counts.lowered += result.order < run.order;
        counts.not_converged += !result.converged && !result.tilt_within_noise;
        counts.tilt_within_noise += result.tilt_within_noise;
        counts.max_radius = std::max(counts.max_radius, result.radius);
        counts.widened += widened;
        counts.narrowed += narrowed;
      }
      reporter.advance();
    }
#pragma omp critical(paps_wavejet_report)
    {
      report_.non_finite += counts.non_finite;
      report_.failed_fits += counts.failed_fits;
      report_.too_few_neighbours += counts.too_few_neighbours;
      report_.fitted += counts.fitted;
      report_.lowered += counts.lowered;
      report_.not_converged += counts.not_converged;
      report_.tilt_within_noise += counts.tilt_within_noise;
      report_.max_radius = std::max(report_.max_radius, counts.max_radius);
      report_.widened += counts.widened;
      report_.narrowed += counts.narrowed;
      neighbour_sum += neighbours_here;
      dense = dense && dense_here;
    }
  }
  reporter.throwIfCancelled();
  reporter.finish();
  report_.radius = static_cast<float>(this->search_radius_);
  report_.noise_measured = measured;
  report_.noise_sigma = measured ? noise.sigma : NAN;
  report_.noise_relative = measured ? noise.relative : NAN;
  report_.select_order = run.select_order;
  report_.beta = run.beta;
  report_.mean_neighbours = report_.fitted ? static_cast<double>(neighbour_sum) / report_.fitted : 0.0;
  output.is_dense = dense;
}

}  // namespace paps
