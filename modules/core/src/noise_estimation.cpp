#include <paps/core/noise_estimation.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Cholesky>

#include <paps/core/error.h>
#include <paps/core/local_frame.h>

namespace paps {

namespace {

constexpr int kMinFitPoints = 10;     // 6 unknowns and a few degrees of freedom to spare
constexpr int kMaxBallPoints = 1500;  // the nearest ones suffice; bounds the cost of a huge ball

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
  for (int round = 0; round < 5; ++round) {
    std::vector<BallFit> fits(m);
    const std::int64_t mm = static_cast<std::int64_t>(m);
#pragma omp parallel
    {
      std::vector<int> idx;
      std::vector<float> d2;
#pragma omp for schedule(dynamic, 16)
      for (std::int64_t s = 0; s < mm; ++s) {
        const int count = index.radiusSearch(points[sample[s]], est.radius, idx, d2, kMaxBallPoints);
        fits[s] = fitBall(points, idx, count);
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

}  // namespace paps
