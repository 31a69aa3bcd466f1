#include <paps/fusion/shadow_correction.h>
#include <paps/fusion/impl/shadow_correction.hpp>

#include <algorithm>
#include <array>
#include <string>
#include <tuple>
#include <utility>
#include <cmath>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/fusion/colour_space.h>

namespace paps {

void ShadowCorrectionParameters::validate() const {
  if (!sun_direction.allFinite() || !(sun_direction.norm() > 1e-6f))
    throw InvalidParameter("sun_direction", "(" + detail::toString(sun_direction.transpose()) + ")",
                           "a finite non-zero direction towards the sun");
  if (!ground_normal.allFinite() || !(ground_normal.norm() > 1e-6f))
    throw InvalidParameter("ground_normal", "(" + detail::toString(ground_normal.transpose()) + ")",
                           "a finite non-zero direction");
  // A sun at or below the horizon lights no ground: the sun-sky model of the correction
  // (the lit ground's irradiance grows with the sun's elevation) has nothing to relight.
  if (!(sun_direction.dot(ground_normal) > 0))
    throw InvalidParameter("sun_direction", "(" + detail::toString(sun_direction.transpose()) + ")",
                           "a direction above the ground plane (positive along ground_normal)");
  requireNonNegative("sun_sky_ratio", sun_sky_ratio, "estimated");
  if (sun_sky_ratio > 1000) throw InvalidParameter("sun_sky_ratio", detail::toString(sun_sky_ratio), "0 (estimated) to 1000");
  requireInRange("neighbours", neighbours, 2, 128);
  if (estimation_neighbours != 0) requireInRange("estimation_neighbours", estimation_neighbours, 2, 1024);
}

std::vector<Eigen::Vector3f> correctShadows(const Positions& points, const Normals& normals,
                                            const std::vector<Eigen::Vector3f>& colours,
                                            const std::vector<std::uint8_t>& in_shadow,
                                            const ShadowCorrectionParameters& params,
                                            ShadowCorrectionReport* report_out, const ProgressCallback& progress) {
  params.validate();
  const std::size_t n = points.size();
  if (n == 0) throw InvalidInput("shadow correction: the input cloud is empty");
  auto requireSize = [&](const char* name, std::size_t size) {
    if (size != n) throw InvalidParameter(name, detail::toString(size), "one per point (" + detail::toString(n) + ")");
  };
  requireSize("normals", normals.size());
  requireSize("colours", colours.size());
  requireSize("shadow labels", in_shadow.size());
  ShadowCorrectionReport report;
  const Eigen::Vector3f sun = params.sun_direction.normalized(), up = params.ground_normal.normalized();

  Positions usable(n, Eigen::Vector3f::Constant(NAN));
  std::vector<float> beta(n, 0), cosine(n, 0);
  std::vector<Eigen::Vector3f> lab(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (!isFinite(points[i]) || !isFinite(normals[i]) || !(normals[i].norm() > 0.5f) || !colours[i].allFinite()) {
      ++report.non_finite;
      continue;
    }
    usable[i] = points[i];
    const Eigen::Vector3f nrm = normals[i].normalized();
    beta[i] = 0.5f * (nrm.dot(up) + 1);
    cosine[i] = std::max(0.f, nrm.dot(sun));
    lab[i] = colour::rgbToLab(colours[i].cwiseMax(0.f));
    (in_shadow[i] ? report.shadow : report.lit) += 1;
  }
  if (report.non_finite == n) throw InvalidInput("shadow correction: no finite point in the cloud (all NaN or Inf)");
  const bool estimate = params.sun_sky_ratio == 0;
  if (estimate && (report.lit == 0 || report.shadow == 0))
    throw InvalidInput(std::string("shadow correction: no ") + (report.lit == 0 ? "lit" : "shadow") +
                       " point: nothing to estimate the sun-sky ratio from (give sun_sky_ratio)");
  if (params.target == RelightTarget::AllShadow && report.shadow == 0)
    throw InvalidInput("shadow correction: no shadow point: no mean shadow sky factor to relight to");
  ProgressReporter rep(progress, "shadow correction", 3 * n);

  const SpatialIndex index(usable);
  // Boundary points: both labels among the neighbours (the estimation band uses more of them).
  auto mixed = [&](std::size_t i, int k, std::vector<int>& nn, std::vector<float>& d2) {
    index.nearestK(usable[i], k + 1, nn, d2);
    bool shadow = false, lit = false;
    for (const int j : nn) (in_shadow[j] ? shadow : lit) = true;
    return shadow && lit;
  };
  std::vector<std::uint8_t> band(n, 0), boundary(n, 0);
#pragma omp parallel
  {
    std::vector<int> nn;
    std::vector<float> d2;
#pragma omp for schedule(static)
    for (std::int64_t ii = 0; ii < std::int64_t(n); ++ii) {
      const std::size_t i = std::size_t(ii);
      if (!isFinite(usable[i])) continue;
      band[i] = params.estimation_neighbours == 0 || mixed(i, params.estimation_neighbours, nn, d2);
      boundary[i] = mixed(i, params.neighbours, nn, d2);
    }
  }
  rep.advance(n);
  rep.throwIfCancelled();

  // Means over the band (or every point), in index order (the same whatever the threads).
  // lit: count, Y, beta, cos, |a|, |b|; shadow: count, Y, beta, |a|, |b|.
  using LitMeans = std::array<double, 6>;
  using ShadowMeans = std::array<double, 5>;
  auto means = [&](bool use_band) {
    LitMeans sl{};
    ShadowMeans ss{};
    for (std::size_t i = 0; i < n; ++i) {
      if (!isFinite(usable[i]) || (use_band && !band[i])) continue;
      const double y = colour::luminanceOfLightness(lab[i].x());
      if (in_shadow[i]) {
        const double v[5] = {1, y, beta[i], std::abs(lab[i].y()), std::abs(lab[i].z())};
        for (int k = 0; k < 5; ++k) ss[k] += v[k];
      } else {
        const double v[6] = {1, y, beta[i], cosine[i], std::abs(lab[i].y()), std::abs(lab[i].z())};
        for (int k = 0; k < 6; ++k) sl[k] += v[k];
      }
    }
    for (int k = 1; k < 6; ++k) sl[k] /= std::max(sl[0], 1.0);
    for (int k = 1; k < 5; ++k) ss[k] /= std::max(ss[0], 1.0);
    return std::make_pair(sl, ss);
  };
  auto [lit_means, shadow_means] = means(params.estimation_neighbours != 0);
  if (lit_means[0] < 20 || shadow_means[0] < 20) std::tie(lit_means, shadow_means) = means(false);
  report.estimation_points = std::size_t(lit_means[0] + shadow_means[0]);
  report.mean_luminance_lit = float(lit_means[1]);
  report.mean_beta_lit = float(lit_means[2]);
  report.mean_cos_lit = float(lit_means[3]);
  report.mean_luminance_shadow = float(shadow_means[1]);
  report.mean_beta_shadow = float(shadow_means[2]);
  float ssr = estimate ? NAN : params.sun_sky_ratio;
  if (estimate && params.local_pair_ratio) {
    // Median over local pairs (shadow boundary point, lit neighbour of the same orientation).
    std::vector<std::vector<float>> per_point(n);
    const float cos_same = std::cos(25.f * float(M_PI) / 180.f);
    // Pairs across the band, both ends off the boundary line itself, whose colours the photos'
    // pixels and the colorization blend across the edge.
    const int pair_neighbours = params.estimation_neighbours > 0 ? params.estimation_neighbours : 64;
#pragma omp parallel
    {
      std::vector<int> nn;
      std::vector<float> d2;
#pragma omp for schedule(static)
      for (std::int64_t ii = 0; ii < std::int64_t(n); ++ii) {
        const std::size_t i = std::size_t(ii);
        if (!band[i] || boundary[i] || !in_shadow[i]) continue;
        const double yi = colour::luminanceOfLightness(lab[i].x());
        if (!(yi > 1e-3)) continue;
        index.nearestK(usable[i], pair_neighbours + 1, nn, d2);
        for (const int j : nn) {
          if (in_shadow[j] || boundary[j] || cosine[j] < 0.1f || normals[i].normalized().dot(normals[j].normalized()) < cos_same) continue;
          const double yj = colour::luminanceOfLightness(lab[j].x());
          per_point[i].push_back(float((yj / yi * beta[i] - beta[j]) / cosine[j]));
        }
      }
    }
    std::vector<float> all;
    for (const auto& v : per_point) all.insert(all.end(), v.begin(), v.end());
    if (all.size() >= 20) {
      std::nth_element(all.begin(), all.begin() + std::ptrdiff_t(all.size() / 2), all.end());
      ssr = all[all.size() / 2];
    } else {
      ssr = NAN;  // too few local pairs: the class means below
    }
    report.local_pairs = all.size();
  }
  if (estimate && !(ssr >= 0)) {
    const double denominator = shadow_means[1] * lit_means[3];
    ssr = denominator > 0 ? float((lit_means[1] * shadow_means[2] - shadow_means[1] * lit_means[2]) / denominator) : 0.f;
  }
  if (!std::isfinite(ssr) || ssr < 0) ssr = 0;  // lit no brighter than shadow: no sun to remove or add
  report.sun_sky_ratio = ssr;
  const double a_lit = lit_means[4], b_lit = lit_means[5], a_shadow = shadow_means[3], b_shadow = shadow_means[4];
  auto ratio = [](double num, double den) { return den > 1e-3 && num > 1e-3 ? float(std::clamp(num / den, 0.2, 5.0)) : 1.f; };
  const bool to_lit = params.target == RelightTarget::AllLit;
  report.a_ratio = to_lit ? ratio(a_lit, a_shadow) : ratio(a_shadow, a_lit);
  report.b_ratio = to_lit ? ratio(b_lit, b_shadow) : ratio(b_shadow, b_lit);
  const float beta_bar_shadow = std::max(1e-3f, report.mean_beta_shadow);

  // Luminance (eq. 4.6 or its inverse) and chrominance (eq. 4.7).
  std::vector<Eigen::Vector3f> corrected = colours;
#pragma omp parallel for schedule(static)
  for (std::int64_t ii = 0; ii < std::int64_t(n); ++ii) {
    const std::size_t i = std::size_t(ii);
    if (!isFinite(usable[i])) continue;
    const float b = std::max(1e-3f, beta[i]);
    const float lit_factor = ssr * cosine[i] + b;
    float factor = 1;
    bool chroma = false;
    if (to_lit) {
      if (in_shadow[i]) {
        factor = lit_factor / b;
        chroma = true;
      }
    } else if (in_shadow[i]) {
      factor = beta_bar_shadow / b;
    } else {
      factor = beta_bar_shadow / lit_factor;
      chroma = true;
    }
    Eigen::Vector3f l = lab[i];
    l.x() = colour::lightnessOfLuminance(factor * colour::luminanceOfLightness(l.x()));
    if (chroma) {
      l.y() *= report.a_ratio;
      l.z() *= report.b_ratio;
    }
    corrected[i] = colour::labToRgb(l).cwiseMax(0.f).cwiseMin(1.f);
  }
  rep.advance(n);
  rep.throwIfCancelled();

  // Penumbra: boundary points take the median of their neighbours' corrected colours.
  std::vector<Eigen::Vector3f> out = corrected;
  if (params.median_filter) {
#pragma omp parallel
    {
      std::vector<int> nn;
      std::vector<float> d2, values;
#pragma omp for schedule(static)
      for (std::int64_t ii = 0; ii < std::int64_t(n); ++ii) {
        const std::size_t i = std::size_t(ii);
        if (!boundary[i]) continue;
        index.nearestK(usable[i], params.neighbours + 1, nn, d2);
        for (int ch = 0; ch < 3; ++ch) {
          values.clear();
          for (const int j : nn) values.push_back(corrected[j][ch]);
          std::sort(values.begin(), values.end());
          const std::size_t h = values.size() / 2;
          out[i][ch] = values.size() % 2 ? values[h] : 0.5f * (values[h - 1] + values[h]);
        }
      }
    }
    for (std::size_t i = 0; i < n; ++i) report.filtered += boundary[i];
  }
  rep.advance(n);
  rep.finish();
  if (report_out) *report_out = report;
  return out;
}

template class ShadowCorrection<pcl::PointXYZRGBNormal>;

}  // namespace paps
