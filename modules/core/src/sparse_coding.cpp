#include <paps/core/sparse_coding.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include <Eigen/Cholesky>

#include <paps/core/error.h>
#include <paps/core/random.h>

namespace paps {

std::vector<SparseCode> orthogonalMatchingPursuit(const Eigen::MatrixXf& D, const Eigen::MatrixXf& Y,
                                                  int sparsity, float tolerance) {
  if (sparsity < 1) throw InvalidParameter("sparsity", std::to_string(sparsity), "a value >= 1");
  if (D.rows() != Y.rows())
    throw InvalidParameter("signals", std::to_string(Y.rows()) + " rows",
                           std::to_string(D.rows()) + " rows like the dictionary");
  const int d = static_cast<int>(D.cols());
  const long n = Y.cols();
  std::vector<SparseCode> codes(n);
  if (d == 0 || n == 0) return codes;
  const int t0 = std::min(sparsity, d);
  const Eigen::MatrixXf G = D.transpose() * D;
  // A = D^T Y by blocks, so that huge n does not need a second n x d matrix at once.
  const long block = 4096;
  for (long b0 = 0; b0 < n; b0 += block) {
    const long bn = std::min(block, n - b0);
    const Eigen::MatrixXf A = D.transpose() * Y.middleCols(b0, bn);
#pragma omp parallel for schedule(dynamic, 64)
    for (long c = 0; c < bn; ++c) {
      const long i = b0 + c;
      const Eigen::VectorXf alpha = A.col(c);
      float resid = Y.col(i).squaredNorm();
      Eigen::VectorXf corr = alpha;
      std::vector<int> S;
      std::vector<char> used(d, 0);
      Eigen::VectorXf x;
      for (int t = 0; t < t0; ++t) {
        if (tolerance > 0 && resid <= tolerance) break;
        int best = -1;
        float best_v = 1e-12f;
        for (int j = 0; j < d; ++j)
          if (!used[j] && std::abs(corr[j]) > best_v) { best_v = std::abs(corr[j]); best = j; }
        if (best < 0) break;
        S.push_back(best);
        used[best] = 1;
        const int s = static_cast<int>(S.size());
        Eigen::MatrixXf Gs(s, s);
        Eigen::VectorXf as(s);
        for (int a = 0; a < s; ++a) {
          as[a] = alpha[S[a]];
          for (int b = 0; b < s; ++b) Gs(a, b) = G(S[a], S[b]);
        }
        Eigen::LDLT<Eigen::MatrixXf> ldlt(Gs);
        Eigen::VectorXf xs = ldlt.solve(as);
        if (!xs.allFinite()) { S.pop_back(); break; }
        x = xs;
        corr = alpha;
        for (int a = 0; a < s; ++a) corr -= G.col(S[a]) * x[a];
        resid = Y.col(i).squaredNorm() - x.dot(as);
      }
      codes[i].atoms = S;
      codes[i].values.assign(x.data(), x.data() + x.size());
      codes[i].values.resize(S.size());
    }
  }
  return codes;
}

Eigen::VectorXf reconstructSignal(const Eigen::MatrixXf& D, const SparseCode& code) {
  Eigen::VectorXf y = Eigen::VectorXf::Zero(D.rows());
  for (std::size_t a = 0; a < code.size(); ++a) y += D.col(code.atoms[a]) * code.values[a];
  return y;
}

namespace {
// Residual of signal i, Y_i - D x_i, formed when needed: K-SVD holds no k x n residual matrix
// (4.2 MB of the codec's peak on 1M points). `zeroed` marks signals an unused atom was just
// made of, whose residual counts as 0 until the next round (as the textbook's R does).
void residualOf(const Eigen::MatrixXf& D, const Eigen::MatrixXf& Y, const SparseCode& code, long i,
                Eigen::VectorXf& r) {
  r = Y.col(i);
  for (std::size_t a = 0; a < code.size(); ++a) r -= D.col(code.atoms[a]) * code.values[a];
}
double residualEnergy(const Eigen::MatrixXf& D, const Eigen::MatrixXf& Y, const std::vector<SparseCode>& codes,
                      const std::vector<char>& zeroed) {
  double e = 0;
#pragma omp parallel reduction(+ : e)
  {
    Eigen::VectorXf r;
#pragma omp for schedule(static)
    for (long i = 0; i < Y.cols(); ++i) {
      if (zeroed[std::size_t(i)]) continue;
      residualOf(D, Y, codes[std::size_t(i)], i, r);
      e += double(r.squaredNorm());
    }
  }
  return e;
}
}  // namespace

KSvdResult learnDictionaryKSvd(const Eigen::MatrixXf& Y, const KSvdParameters& p,
                               const ProgressCallback& progress) {
  requireInRange("atoms", p.atoms, 1, 4096);
  requireInRange("sparsity", p.sparsity, 1, p.atoms);
  requireInRange("iterations", p.iterations, 0, 1000);
  if (!(p.tolerance >= 0)) throw InvalidParameter("tolerance", detail::toString(p.tolerance), "a value >= 0");
  const long k = Y.rows(), n = Y.cols();
  if (k < 1 || n < 1) throw InvalidInput("K-SVD needs at least one signal of at least one sample");
  if (!Y.allFinite()) throw InvalidInput("K-SVD signals contain NaN or infinite values");
  const int d = p.atoms;
  Random rng(p.seed);
  KSvdResult out;
  Eigen::MatrixXf& D = out.dictionary;
  D.resize(k, d);
  // Initial atoms: distinct random non-zero signals, then random unit vectors.
  std::vector<long> order(n);
  std::iota(order.begin(), order.end(), 0L);
  for (long i = n - 1; i > 0; --i) std::swap(order[i], order[rng.below(i + 1)]);
  int filled = 0;
  for (long i = 0; i < n && filled < d; ++i) {
    const float nn = Y.col(order[i]).norm();
    if (nn <= 1e-20f) continue;
    const Eigen::VectorXf c = Y.col(order[i]) / nn;
    bool dup = false;
    for (int j = 0; j < filled && !dup; ++j) dup = std::abs(D.col(j).dot(c)) > 0.9999f;
    if (!dup) D.col(filled++) = c;
  }
  for (; filled < d; ++filled) {
    Eigen::VectorXf c(k);
    for (long r = 0; r < k; ++r) c[r] = static_cast<float>(rng.gaussian());
    D.col(filled) = c.normalized();
  }
  ProgressReporter rep(progress, "dictionary learning (K-SVD)", static_cast<std::size_t>(p.iterations) + 1);
  std::vector<char> zeroed(static_cast<std::size_t>(n), 0);
  Eigen::VectorXf r, e;
  for (int it = 0; it < p.iterations; ++it) {
    out.codes = orthogonalMatchingPursuit(D, Y, p.sparsity, p.tolerance);
    std::fill(zeroed.begin(), zeroed.end(), 0);
    std::vector<std::vector<std::pair<long, int>>> users(d);
    for (long i = 0; i < n; ++i)
      for (std::size_t a = 0; a < out.codes[i].size(); ++a) users[out.codes[i].atoms[a]].push_back({i, static_cast<int>(a)});
    for (int j = 0; j < d; ++j) {
      const auto& I = users[j];
      if (I.empty()) {
        // An unused atom becomes the worst-represented signal.
        long worst = -1;
        float worst_v = 1e-20f;
        for (long i = 0; i < n; ++i) {
          if (zeroed[std::size_t(i)]) continue;
          residualOf(D, Y, out.codes[i], i, r);
          const float v = r.squaredNorm();
          if (v > worst_v) { worst_v = v; worst = i; }
        }
        if (worst >= 0) {
          residualOf(D, Y, out.codes[worst], worst, r);
          D.col(j) = r.normalized();
          zeroed[std::size_t(worst)] = 1;  // that signal is now representable
        }
        continue;
      }
      // One power step on E = R_I + d_j g^T (the residual without atom j, restricted to its
      // users): a = E g, then g = E^T a. E's columns are formed one at a time.
      const long m = static_cast<long>(I.size());
      const Eigen::VectorXf dj = D.col(j);
      Eigen::VectorXf a = Eigen::VectorXf::Zero(k);
      for (long c = 0; c < m; ++c) {
        const float gc = out.codes[I[c].first].values[I[c].second];
        if (zeroed[std::size_t(I[c].first)]) {
          e = dj * gc;
        } else {
          residualOf(D, Y, out.codes[I[c].first], I[c].first, e);
          e += dj * gc;
        }
        a += e * gc;
      }
      const float an = a.norm();
      if (!(an > 1e-20f)) continue;
      a /= an;
      D.col(j) = a;
      for (long c = 0; c < m; ++c) {
        float& gc = out.codes[I[c].first].values[I[c].second];
        // E's column with the old atom and coefficient: the residual under the new atom
        // plus the new atom times the old coefficient.
        if (zeroed[std::size_t(I[c].first)]) {
          e = dj * gc;
        } else {
          residualOf(D, Y, out.codes[I[c].first], I[c].first, e);
          e += a * gc;
        }
        gc = e.dot(a);
      }
    }
    out.rmse.push_back(std::sqrt(residualEnergy(D, Y, out.codes, zeroed) / double(k * n)));
    rep.advance();
    rep.throwIfCancelled();
  }
  out.codes = orthogonalMatchingPursuit(D, Y, p.sparsity, p.tolerance);
  std::fill(zeroed.begin(), zeroed.end(), 0);
  out.rmse.push_back(std::sqrt(residualEnergy(D, Y, out.codes, zeroed) / double(k * n)));
  rep.finish();
  return out;
}

}  // namespace paps
