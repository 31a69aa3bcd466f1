#pragma once
// Iteratively reweighted least squares for l1 regression (Beaton-Tukey style reweighting,
// [BBS94] in the manuscript): minimise sum_i w_i |a_i . x - b_i| by repeated weighted least
// squares with weights w_i / max(|r_i|, delta). Header-only: used on small dense systems
// (quadric regression, 6 unknowns) inside hot loops.
#include <algorithm>
#include <cmath>
#include <Eigen/Dense>
#include <Eigen/Eigenvalues>

namespace paps {

/// Robust (l1) weight of a residual: 1 / max(|r|, delta). delta > 0 (metres) keeps the
/// weight bounded when a residual vanishes.
inline float l1Weight(float residual, float delta) { return 1.f / std::max(std::abs(residual), delta); }

/// Solves min_x sum_i w_i |A_i x - b_i| by IRLS.
/// [in] A (n x m), b (n), prior weights w (n, >= 0), `iterations` reweighting passes after the
/// least-squares start (0: plain weighted least squares), `delta` the l1 smoothing (> 0).
/// [out] the solution x (m); returns false when the normal equations are singular (rank < m),
/// in which case x holds the least-squares solution of the pseudo-inverse.
template <int M>
bool solveIrlsL1(const Eigen::Matrix<double, Eigen::Dynamic, M>& A, const Eigen::VectorXd& b,
                 const Eigen::VectorXd& w, int iterations, double delta,
                 Eigen::Matrix<double, M, 1>& x) {
  Eigen::VectorXd cw = w;
  bool ok = true;
  for (int it = 0; it <= iterations; ++it) {
    Eigen::Matrix<double, M, M> N = A.transpose() * cw.asDiagonal() * A;
    Eigen::Matrix<double, M, 1> r = A.transpose() * cw.asDiagonal() * b;
    Eigen::LDLT<Eigen::Matrix<double, M, M>> ldlt(N);
    const double scale = N.diagonal().cwiseAbs().maxCoeff();
    if (ldlt.info() != Eigen::Success || !(scale > 0) ||
        ldlt.vectorD().cwiseAbs().minCoeff() < 1e-12 * scale) {
      // Minimum-norm least squares through the eigen decomposition of the symmetric N:
      // the complete orthogonal decomposition gives the same x, and its fixed-size
      // instantiation doubled the compile time of the file that includes this header.
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, M, M>> es(N);
      const auto& lambda = es.eigenvalues();
      const double cut = 1e-12 * lambda.cwiseAbs().maxCoeff();
      Eigen::Matrix<double, M, 1> y = es.eigenvectors().transpose() * r;
      for (int k = 0; k < M; ++k) y[k] = std::abs(lambda[k]) > cut ? y[k] / lambda[k] : 0.0;
      x = es.eigenvectors() * y;
      ok = false;
      break;
    }
    x = ldlt.solve(r);
    if (it == iterations) break;
    const Eigen::VectorXd res = A * x - b;
    for (Eigen::Index i = 0; i < res.size(); ++i) cw[i] = w[i] / std::max(std::abs(res[i]), delta);
  }
  return ok;
}

}  // namespace paps
