// Tests of paps/core/lasso_dictionary.h: the LASSO codes against closed forms and their
// optimality conditions, dictionary learning that finds planted atoms, determinism and
// named parameter errors.
#include <cmath>

#include <Eigen/Cholesky>
#include <omp.h>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/lasso_dictionary.h>
#include <paps/core/random.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_lasso_dictionary_test {

Eigen::MatrixXf randomMatrix(int rows, int cols, std::uint64_t seed) {
  paps::Random rng(seed);
  Eigen::MatrixXf m(rows, cols);
  for (int c = 0; c < cols; ++c)
    for (int r = 0; r < rows; ++r) m(r, c) = static_cast<float>(rng.gaussian());
  return m;
}

Eigen::MatrixXf unitColumns(Eigen::MatrixXf m) {
  for (int c = 0; c < m.cols(); ++c) m.col(c).normalize();
  return m;
}

TEST(LassoCodes, OrthonormalDictionaryGivesTheSoftThreshold) {
  // With D = I the LASSO separates: a = sign(x) max(|x| - lambda, 0), exactly.
  const Eigen::MatrixXf D = Eigen::MatrixXf::Identity(6, 6);
  Eigen::MatrixXf X(6, 2);
  X << 1.0f, -0.1f, 0.3f, 0.25f, -2.0f, 0.0f, 0.2f, -0.7f, 0.05f, 3.0f, -0.26f, 0.24f;
  const Eigen::MatrixXf A = paps::lassoCodes(D, X, 0.25f);
  for (int c = 0; c < 2; ++c)
    for (int r = 0; r < 6; ++r) {
      const float x = X(r, c);
      const float expected = std::abs(x) > 0.25f ? x - std::copysign(0.25f, x) : 0.f;
      EXPECT_NEAR(A(r, c), expected, 1e-6f) << r << "," << c;
    }
}

TEST(LassoCodes, DebiasedCodesKeepTheSupportWithoutShrinking) {
  // Relaxed LASSO on D = I: the atoms with |x| > lambda, at their full value x.
  const Eigen::MatrixXf D = Eigen::MatrixXf::Identity(4, 4);
  Eigen::MatrixXf X(4, 1);
  X << 1.0f, -0.1f, -2.0f, 0.3f;
  const Eigen::MatrixXf A = paps::lassoCodes(D, X, 0.25f, 100, true);
  EXPECT_NEAR(A(0, 0), 1.0f, 1e-6f);
  EXPECT_EQ(A(1, 0), 0.f);
  EXPECT_NEAR(A(2, 0), -2.0f, 1e-6f);
  EXPECT_NEAR(A(3, 0), 0.3f, 1e-6f);
}

TEST(LassoCodes, DebiasingKeepsTheLassoValuesOnANearlySingularSupport) {
  // Two atoms 1e-7 apart: a least-squares refit would give huge opposite coefficients.
  Eigen::MatrixXf D(3, 2);
  D << 1.f, 1.f, 0.f, 1e-7f, 0.f, 0.f;
  D.col(1).normalize();
  Eigen::MatrixXf X(3, 1);
  X << 2.f, 0.5f, 0.f;
  const Eigen::MatrixXf A = paps::lassoCodes(D, X, 1e-3f, 1000, true);
  EXPECT_TRUE(A.allFinite());
  EXPECT_LT(A.cwiseAbs().maxCoeff(), 10.f) << A.transpose();
}

TEST(LassoCodes, ZeroLambdaIsLeastSquares) {
  const Eigen::MatrixXf D = unitColumns(randomMatrix(20, 5, 1));
  const Eigen::MatrixXf X = randomMatrix(20, 8, 2);
  const Eigen::MatrixXf A = paps::lassoCodes(D, X, 0.f, 2000);
  const Eigen::MatrixXf expected = (D.transpose() * D).ldlt().solve(D.transpose() * X);
  EXPECT_LT((A - expected).cwiseAbs().maxCoeff(), 1e-3f);
}

TEST(LassoCodes, MeetOptimalityConditions) {
  // KKT of min 0.5 |x - D a|^2 + lambda |a|_1: c = D^T (x - D a) equals lambda sign(a_j)
  // where a_j != 0 and is at most lambda in magnitude elsewhere.
  const Eigen::MatrixXf D = unitColumns(randomMatrix(30, 12, 3));
  const Eigen::MatrixXf X = randomMatrix(30, 20, 4);
  const float lambda = 0.8f;
  const Eigen::MatrixXf A = paps::lassoCodes(D, X, lambda, 5000);
  int nonzero = 0, zero = 0;
  for (int c = 0; c < X.cols(); ++c) {
    const Eigen::VectorXf corr = D.transpose() * (X.col(c) - D * A.col(c));
    for (int j = 0; j < D.cols(); ++j) {
      if (A(j, c) != 0) {
        EXPECT_NEAR(corr[j], lambda * (A(j, c) > 0 ? 1 : -1), 1e-3f) << j << "," << c;
        ++nonzero;
      } else {
        EXPECT_LE(std::abs(corr[j]), lambda + 1e-3f) << j << "," << c;
        ++zero;
      }
    }
  }
  EXPECT_GT(nonzero, 0);
  EXPECT_GT(zero, 0) << "lambda this large must zero some coefficients";
}

TEST(LassoDictionary, FindsPlantedAtoms) {
  // 2,000 signals, each one or two of 8 planted unit atoms in R^30 with coefficients of
  // magnitude 1 to 3, plus noise of 0.01: each planted atom is learned (|cos| > 0.95).
  const int k = 30, d = 8;
  const Eigen::MatrixXf planted = unitColumns(randomMatrix(k, d, 5));
  paps::Random rng(6);
  Eigen::MatrixXf X(k, 2000);
  for (int c = 0; c < X.cols(); ++c) {
    X.col(c).setZero();
    const int used = 1 + static_cast<int>(rng.below(2));
    for (int u = 0; u < used; ++u) {
      const double magnitude = rng.uniform(1, 3);
      const float a = static_cast<float>(magnitude * (rng.below(2) ? 1 : -1));
      X.col(c) += a * planted.col(static_cast<int>(rng.below(d)));
    }
    for (int r = 0; r < k; ++r) X(r, c) += 0.01f * static_cast<float>(rng.gaussian());
  }
  paps::LassoDictionaryParameters p;
  p.atoms = d;
  p.lambda = 0.1f;
  p.iterations = 100;
  p.update_sweeps = 3;
  const paps::LassoDictionaryResult r = paps::learnDictionaryLasso(X, p);
  ASSERT_EQ(r.dictionary.rows(), k);
  ASSERT_EQ(r.dictionary.cols(), d);
  for (int j = 0; j < d; ++j) {
    const float best = (r.dictionary.transpose() * planted.col(j)).cwiseAbs().maxCoeff();
    EXPECT_GT(best, 0.95f) << "planted atom " << j;
  }
  for (int j = 0; j < d; ++j) EXPECT_LE(r.dictionary.col(j).norm(), 1.f + 1e-5f);
  ASSERT_EQ(r.objective.size(), static_cast<std::size_t>(p.iterations + 1));
  EXPECT_LT(r.objective.back(), 0.5 * r.objective.front());
}

TEST(LassoDictionary, SameWithOneOrTwoThreads) {
  const Eigen::MatrixXf X = randomMatrix(40, 3000, 7);
  paps::LassoDictionaryParameters p;
  p.atoms = 12;
  p.lambda = 0.5f;
  p.iterations = 4;
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const paps::LassoDictionaryResult a = paps::learnDictionaryLasso(X, p);
  omp_set_num_threads(2);
  const paps::LassoDictionaryResult b = paps::learnDictionaryLasso(X, p);
  omp_set_num_threads(saved);
  EXPECT_TRUE(a.dictionary == b.dictionary);
  EXPECT_TRUE(a.codes == b.codes);
}

TEST(LassoDictionary, BadParametersAndInputAreNamed) {
  const Eigen::MatrixXf X = randomMatrix(5, 10, 8);
  EXPECT_THROW(paps::lassoCodes(Eigen::MatrixXf::Identity(5, 5), X, -1.f), paps::InvalidParameter);
  EXPECT_THROW(paps::lassoCodes(Eigen::MatrixXf::Identity(4, 4), X, 0.1f), paps::InvalidParameter);
  paps::LassoDictionaryParameters p;
  p.atoms = 0;
  EXPECT_THROW(paps::learnDictionaryLasso(X, p), paps::InvalidParameter);
  p.atoms = 3;
  Eigen::MatrixXf bad = X;
  bad(2, 3) = std::nanf("");
  EXPECT_THROW(paps::learnDictionaryLasso(bad, p), paps::InvalidInput);
  EXPECT_THROW(paps::learnDictionaryLasso(Eigen::MatrixXf(5, 0), p), paps::InvalidInput);
  // More atoms than distinct signals: padded with random unit atoms, still a valid result.
  p.atoms = 20;
  const auto r = paps::learnDictionaryLasso(X, p);
  EXPECT_TRUE(r.dictionary.allFinite());
  EXPECT_TRUE(r.codes.allFinite());
}

}  // namespace core_lasso_dictionary_test
