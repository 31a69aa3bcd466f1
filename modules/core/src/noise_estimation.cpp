#include <paps/core/noise_estimation.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>

#include <Eigen/Cholesky>

#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/spatial_order.h>

namespace paps {

namespace {

constexpr int kMinFitPoints = 10;     // 6 unknowns and a few degrees of freedom to spare
constexpr int kMaxBallPoints = 1500;  // a fit needs no more; bounds the cost of a huge ball
constexpr int kThinnedBallPoints = 800;  // what a thinned cloud's ball should hold (below the cap)

struct BallFit {
  double variance = -1;  // unbiased residual variance, < 0 when no fit
  int dof = 0;
};

// Least-squares height quadric over one ball in its PCA frame.
BallFit fitBall(const Positions& points, const std::vector<int>& idx, int count) {
  BallFit out;
  if (count < kMinFitPoints) return out;
  Eigen::Vector3f centroid;
  const Eigen::Vector3f n = pcaNormal(points, idx.data(), count, &centroid);
  if (!isFinite(n)) return out;
  const Eigen::Vector3f t1 = n.unitOrthogonal(), t2 = n.cross(t1);
  Eigen::Matrix<double, 6, 6> ata = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> atb = Eigen::Matrix<double, 6, 1>::Zero();
  double btb = 0;
  for (int j = 0; j < count; ++j) {
    const Eigen::Vector3f d = points[idx[j]] - centroid;
    const double u = t1.dot(d), v = t2.dot(d), h = n.dot(d);
    Eigen::Matrix<double, 6, 1> a;
    a << 1, u, v, u * u, u * v, v * v;
    ata.selfadjointView<Eigen::Lower>().rankUpdate(a);
    atb += h * a;
    btb += h * h;
  }
  ata.triangularView<Eigen::StrictlyUpper>() = ata.transpose();
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(ata);
  if (ldlt.info() != Eigen::Success) return out;
  const Eigen::Matrix<double, 6, 1> c = ldlt.solve(atb);
  // RSS = b'b - c'A'b for the least-squares solution.
  const double rss = std::max(0.0, btb - c.dot(atb));
  out.dof = count - 6;
  out.variance = rss / out.dof;
  return out;
}

}  // namespace

NoiseEstimate estimateNoiseLevel(const Positions& points, const SpatialIndex& index, float radius, int samples) {
  if (!(radius > 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "a finite value > 0");
  requirePositive("samples", samples);
  if (countFinite(points) < static_cast<std::size_t>(kMinFitPoints))
    throw InvalidInput("fewer than 10 finite points: cannot estimate the noise");
  const std::vector<int> sample = spreadSample(points, static_cast<std::size_t>(samples));
  const std::size_t m = sample.size();

  NoiseEstimate est;
  est.radius = radius;
  // Where the balls hold more than kMaxBallPoints, the search keeps the nearest ones: a smaller
  // ball, which cuts a noise slab as thick as it is wide and reads the noise low (a plane at
  // sigma 0.006, ball 0.0375, 1M points: 0.0054). There the fits run on an even thinning of
  // the cloud instead (one point in `keep_one_in`, by position hash, so the thinning depends
  // on neither the order nor the threads), whose balls keep the whole radius.
  std::size_t keep_one_in = 1;
  std::unique_ptr<SpatialIndex> thin_index;
  Positions thin;
  const auto thinnedTo = [&](std::size_t one_in) {
    keep_one_in = one_in;
    thin.clear();
    for (const Eigen::Vector3f& p : points)
      if (isFinite(p) && (positionHash(p) >> 8) % one_in == 0) thin.push_back(p);
    thin_index = thin.size() >= static_cast<std::size_t>(kMinFitPoints) ? std::make_unique<SpatialIndex>(thin) : nullptr;
  };
  for (int round = 0, thinnings = 0; round < 5; ++round) {
    const Positions& cloud = thin_index ? thin : points;
    const SpatialIndex& tree = thin_index ? *thin_index : index;
    std::vector<BallFit> fits(m);
    std::vector<float> reach(m, 0.f);  // squared distance of the farthest point fitted, for a full ball
    const std::int64_t mm = static_cast<std::int64_t>(m);
#pragma omp parallel
    {
      std::vector<int> idx;
      std::vector<float> d2;
#pragma omp for schedule(dynamic, 16)
      for (std::int64_t s = 0; s < mm; ++s) {
        const int count = tree.radiusSearch(points[sample[s]], est.radius, idx, d2, kMaxBallPoints);
        if (count == kMaxBallPoints) reach[s] = *std::max_element(d2.begin(), d2.begin() + count);
        fits[s] = fitBall(cloud, idx, count);
      }
    }
    // Most balls full: thin (further) so that they hold about kThinnedBallPoints, from the
    // width the full ones reached (a surface: the count grows as the radius squared).
    std::vector<float> full;
    for (const float r2 : reach)
      if (r2 > 0) full.push_back(r2);
    if (2 * full.size() > m && thinnings < 4) {
      const std::size_t mid = full.size() / 2;
      std::nth_element(full.begin(), full.begin() + mid, full.end());
      const double held = kMaxBallPoints * static_cast<double>(est.radius) * est.radius / full[mid];
      // Capped: near-copies (a reach of almost nothing) must not overflow the count.
      const double factor = std::min(std::ceil(held / kThinnedBallPoints), static_cast<double>(points.size()));
      const std::size_t one_in = std::min(keep_one_in * static_cast<std::size_t>(factor), points.size());
      if (one_in > keep_one_in) {
        thinnedTo(one_in);
        ++thinnings;
        --round;  // the same radius again, on the thinned cloud
        continue;
      }
    }
    std::vector<double> var;
    std::vector<int> dof;
    for (const BallFit& f : fits)
      if (f.variance >= 0) { var.push_back(f.variance); dof.push_back(f.dof); }
    if (var.empty()) {
      if (round == 0)
        throw InvalidInput("no ball of radius " + detail::toString(radius) + " holds the 10 points a noise fit needs");
      break;  // keep the last estimate
    }
    const std::size_t mid = var.size() / 2;
    std::nth_element(var.begin(), var.begin() + mid, var.end());
    std::nth_element(dof.begin(), dof.begin() + mid, dof.end());
    // The median of chi2_k / k is about (1 - 2 / (9k))^3 (Wilson-Hilferty).
    const double k = std::max(1, dof[mid]);
    const double median_factor = std::pow(1.0 - 2.0 / (9.0 * k), 3.0);
    est.sigma = static_cast<float>(std::sqrt(var[mid] / median_factor));
    est.fits = var.size();
    // A noise slab as thick as the ball is wide has no reliable PCA plane: grow the ball.
    if (est.sigma <= est.radius / 5 || round == 4) break;
    est.radius = 1.25f * 5.f * est.sigma;
  }
  return est;
}

float noiseGrowth(const Positions& points, const SpatialIndex& index, float radius, float at_radius) {
  const float at_r = at_radius > 0 ? at_radius : estimateNoiseLevel(points, index, radius).sigma;
  if (!(at_r > 0)) return 0.f;
  return estimateNoiseLevel(points, index, 2 * radius).sigma / at_r;
}

}  // namespace paps
