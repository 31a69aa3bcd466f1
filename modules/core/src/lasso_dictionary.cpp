#include <paps/core/lasso_dictionary.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include <Eigen/Cholesky>

#include <paps/core/error.h>
#include <paps/core/random.h>

namespace paps {

namespace {

// D^T D in double, column by column: no Eigen GEMM at the top level, whose blocking (and so
// its rounding) depends on the thread count.
Eigen::MatrixXd gramOf(const Eigen::MatrixXf& D) {
  const Eigen::MatrixXd Dd = D.cast<double>();
  const long d = D.cols();
  Eigen::MatrixXd G(d, d);
  for (long a = 0; a < d; ++a)
    for (long b = a; b < d; ++b) G(a, b) = G(b, a) = Dd.col(a).dot(Dd.col(b));
  return G;
}

double softThreshold(double z, double t) { return z > t ? z - t : (z < -t ? z + t : 0.0); }

// One column: cyclic coordinate descent on the correlations r = D^T x - G a.
void codeOne(const Eigen::MatrixXd& G, Eigen::VectorXd r, double lambda, int max_sweeps, bool debias, float* a_out) {
  const long d = G.rows();
  const Eigen::VectorXd c = debias ? r : Eigen::VectorXd();
  Eigen::VectorXd a = Eigen::VectorXd::Zero(d);
  for (int sweep = 0; sweep < max_sweeps; ++sweep) {
    double max_delta = 0, max_a = 0;
    for (long j = 0; j < d; ++j) {
      const double gjj = G(j, j);
      if (!(gjj > 0)) continue;
      const double z = r[j] + gjj * a[j];
      const double next = softThreshold(z, lambda) / gjj;
      const double delta = next - a[j];
      if (delta != 0) {
        r.noalias() -= G.col(j) * delta;
        a[j] = next;
      }
      max_delta = std::max(max_delta, std::abs(delta));
      max_a = std::max(max_a, std::abs(a[j]));
    }
    if (max_delta <= 1e-5 * max_a) break;
  }
  if (debias) {
    std::vector<long> support;
    for (long j = 0; j < d; ++j)
      if (a[j] != 0) support.push_back(j);
    const long s = static_cast<long>(support.size());
    if (s > 0) {
      Eigen::MatrixXd Gs(s, s);
      Eigen::VectorXd cs(s);
      for (long p = 0; p < s; ++p) {
        cs[p] = c[support[p]];
        for (long q = 0; q < s; ++q) Gs(p, q) = G(support[p], support[q]);
      }
      // Only a well-conditioned support is refitted: two nearly equal atoms would get huge
      // opposite coefficients, finite but meaningless once rounded to float.
      const Eigen::LDLT<Eigen::MatrixXd> ldlt(Gs);
      if (ldlt.info() == Eigen::Success && ldlt.rcond() > 1e-8) {
        const Eigen::VectorXd refit = ldlt.solve(cs);
        if (refit.allFinite())
          for (long p = 0; p < s; ++p) a[support[p]] = refit[p];
      }
    }
  }
  for (long j = 0; j < d; ++j) a_out[j] = static_cast<float>(a[j]);
}

}  // namespace

Eigen::MatrixXf lassoCodes(const Eigen::MatrixXf& D, const Eigen::MatrixXf& X, float lambda, int max_sweeps,
                           bool debias) {
  if (!(lambda >= 0) || !std::isfinite(lambda))
    throw InvalidParameter("lambda", detail::toString(lambda), "a finite value >= 0");
  requireInRange("max_sweeps", max_sweeps, 1, 100000);
  if (D.rows() != X.rows())
    throw InvalidParameter("signals", std::to_string(X.rows()) + " rows",
                           std::to_string(D.rows()) + " rows like the dictionary");
  const long d = D.cols(), n = X.cols();
  Eigen::MatrixXf codes = Eigen::MatrixXf::Zero(d, n);
  if (d == 0 || n == 0) return codes;
  const Eigen::MatrixXd G = gramOf(D);
  const Eigen::MatrixXd Dd = D.cast<double>();
#pragma omp parallel for schedule(dynamic, 64)
  for (long i = 0; i < n; ++i) {
    const Eigen::VectorXd c = Dd.transpose() * X.col(i).cast<double>();
    codeOne(G, c, lambda, max_sweeps, debias, codes.col(i).data());
  }
  return codes;
}

void LassoDictionaryParameters::validate() const {
  requireInRange("atoms", atoms, 1, 4096);
  if (!(lambda >= 0) || !std::isfinite(lambda))
    throw InvalidParameter("lambda", detail::toString(lambda), "a finite value >= 0");
  requireInRange("iterations", iterations, 0, 1000);
  requireInRange("update_sweeps", update_sweeps, 1, 100);
}

namespace {

// A = sum a a^T and B = sum x a^T, one atom p per task (row p of A, column p of B), each
// summed over the signals in order: the same bits for any thread count, and no per-thread
// copies of A and B (64 copies of B were 31 GB at the largest allowed sizes).
void sufficientStatistics(const Eigen::MatrixXf& X, const Eigen::MatrixXf& codes, Eigen::MatrixXd& A,
                          Eigen::MatrixXd& B) {
  const long k = X.rows(), d = codes.rows(), n = X.cols();
  A = Eigen::MatrixXd::Zero(d, d);
  B = Eigen::MatrixXd::Zero(k, d);
#pragma omp parallel for schedule(dynamic, 1)
  for (long p = 0; p < d; ++p) {
    Eigen::VectorXd row = Eigen::VectorXd::Zero(d), col = Eigen::VectorXd::Zero(k);
    for (long i = 0; i < n; ++i) {
      const double ap = codes(p, i);
      if (ap == 0) continue;
      row += ap * codes.col(i).cast<double>();
      col += ap * X.col(i).cast<double>();
    }
    A.row(p) = row.transpose();
    B.col(p) = col;
  }
}

double objectiveOf(const Eigen::MatrixXf& D, const Eigen::MatrixXf& X, const Eigen::MatrixXf& codes, float lambda,
                   std::vector<double>* residual = nullptr) {
  const long n = X.cols();
  std::vector<double> per(n);
#pragma omp parallel for schedule(static)
  for (long i = 0; i < n; ++i) {
    const Eigen::VectorXf r = X.col(i) - D * codes.col(i);
    per[i] = 0.5 * r.cast<double>().squaredNorm();
  }
  double sum = 0;
  for (long i = 0; i < n; ++i) sum += per[i] + lambda * codes.col(i).cwiseAbs().cast<double>().sum();
  if (residual) *residual = std::move(per);
  return n ? sum / n : 0.0;
}

}  // namespace

LassoDictionaryResult learnDictionaryLasso(const Eigen::MatrixXf& X, const LassoDictionaryParameters& p,
                                           const Eigen::MatrixXf& initial, const ProgressCallback& progress) {
  p.validate();
  const long k = X.rows(), n = X.cols();
  if (n < 1 || k < 1) throw InvalidInput("dictionary learning needs at least one non-empty signal");
  if (!X.allFinite()) throw InvalidInput("the training signals hold NaN or Inf");
  const long d = p.atoms;
  LassoDictionaryResult out;
  Random rng(p.seed);
  if (initial.rows() == k && initial.cols() == d) {
    out.dictionary = initial;
  } else {
    out.dictionary.resize(k, d);
    std::vector<long> order(n);
    std::iota(order.begin(), order.end(), 0L);
    for (long i = n - 1; i > 0; --i) std::swap(order[i], order[static_cast<long>(rng.below(i + 1))]);
    long filled = 0;
    for (long i = 0; i < n && filled < d; ++i) {
      const Eigen::VectorXf x = X.col(order[i]);
      const float norm = x.norm();
      if (!(norm > 0)) continue;
      bool duplicate = false;
      for (long j = 0; j < filled && !duplicate; ++j) duplicate = (out.dictionary.col(j) - x / norm).norm() < 1e-6f;
      if (!duplicate) out.dictionary.col(filled++) = x / norm;
    }
    for (; filled < d; ++filled) {
      Eigen::VectorXf v(k);
      for (long r = 0; r < k; ++r) v[r] = static_cast<float>(rng.gaussian());
      out.dictionary.col(filled) = v.normalized();
    }
  }
  ProgressReporter rep(progress, "dictionary", static_cast<std::size_t>(p.iterations) + 1);
  Eigen::MatrixXd A, B;
  for (int it = 0; it < p.iterations; ++it) {
    out.codes = lassoCodes(out.dictionary, X, p.lambda);
    std::vector<double> residual;
    out.objective.push_back(objectiveOf(out.dictionary, X, out.codes, p.lambda, &residual));
    sufficientStatistics(X, out.codes, A, B);
    Eigen::MatrixXd D = out.dictionary.cast<double>();
    for (int sweep = 0; sweep < p.update_sweeps; ++sweep) {
      for (long j = 0; j < d; ++j) {
        if (A(j, j) > 1e-12) {
          Eigen::VectorXd u = D.col(j) + (B.col(j) - D * A.col(j)) / A(j, j);
          D.col(j) = u / std::max(1.0, u.norm());
        } else if (sweep == 0) {
          // Unused atom: restart it on the worst-represented signal.
          const long worst = static_cast<long>(std::max_element(residual.begin(), residual.end()) - residual.begin());
          const double norm = X.col(worst).norm();
          if (norm > 0) D.col(j) = X.col(worst).cast<double>() / norm;
          residual[worst] = 0;
        }
      }
    }
    out.dictionary = D.cast<float>();
    rep.advance();
    rep.throwIfCancelled();
  }
  out.codes = lassoCodes(out.dictionary, X, p.lambda);
  out.objective.push_back(objectiveOf(out.dictionary, X, out.codes, p.lambda));
  rep.finish();
  return out;
}

}  // namespace paps
