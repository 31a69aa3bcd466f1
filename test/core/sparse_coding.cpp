// Tests of paps/core/sparse_coding.h on signals with known sparse structure.
#include <cmath>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/core/sparse_coding.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_sparse_coding_test {

Eigen::MatrixXf randomDictionary(int k, int d, std::uint64_t seed) {
  paps::Random rng(seed);
  Eigen::MatrixXf D(k, d);
  for (int j = 0; j < d; ++j) {
    for (int r = 0; r < k; ++r) D(r, j) = static_cast<float>(rng.gaussian());
    D.col(j).normalize();
  }
  return D;
}

// Signals that are exact T-sparse combinations of D's atoms.
Eigen::MatrixXf sparseSignals(const Eigen::MatrixXf& D, int n, int t, std::uint64_t seed) {
  paps::Random rng(seed);
  Eigen::MatrixXf Y = Eigen::MatrixXf::Zero(D.rows(), n);
  for (int i = 0; i < n; ++i)
    for (int a = 0; a < t; ++a) {
      const double sign = rng.uniform() < 0.5 ? -1 : 1;
      const double v = sign * rng.uniform(0.5, 2.0);
      Y.col(i) += D.col(static_cast<int>(rng.below(D.cols()))) * static_cast<float>(v);
    }
  return Y;
}

TEST(OrthogonalMatchingPursuit, RecoversAnExactSparseCombination) {
  const Eigen::MatrixXf D = randomDictionary(64, 32, 1);
  Eigen::VectorXf y = 1.5f * D.col(3) - 0.7f * D.col(17) + 0.3f * D.col(30);
  const auto codes = paps::orthogonalMatchingPursuit(D, y, 3);
  ASSERT_EQ(codes.size(), 1u);
  ASSERT_EQ(codes[0].size(), 3u);
  EXPECT_LT((paps::reconstructSignal(D, codes[0]) - y).norm(), 1e-4f);
  std::vector<int> atoms = codes[0].atoms;
  std::sort(atoms.begin(), atoms.end());
  EXPECT_EQ(atoms, (std::vector<int>{3, 17, 30}));
}

TEST(OrthogonalMatchingPursuit, RespectsSparsityAndTolerance) {
  const Eigen::MatrixXf D = randomDictionary(32, 48, 2);
  const Eigen::MatrixXf Y = sparseSignals(D, 50, 6, 3);
  // Each signal mixes up to 6 atoms and the default tolerance 0 never stops early: every
  // code takes exactly T0 = 2 atoms, and leaves a residual smaller than the signal.
  const auto codes = paps::orthogonalMatchingPursuit(D, Y, 2);
  ASSERT_EQ(codes.size(), 50u);
  for (std::size_t i = 0; i < codes.size(); ++i) {
    EXPECT_EQ(codes[i].size(), 2u) << i;
    const Eigen::VectorXf y = Y.col(static_cast<Eigen::Index>(i));
    EXPECT_LT((paps::reconstructSignal(D, codes[i]) - y).norm(), y.norm()) << i;
  }
  // Zero signal: empty code.
  const auto z = paps::orthogonalMatchingPursuit(D, Eigen::MatrixXf::Zero(32, 1), 4);
  EXPECT_EQ(z[0].size(), 0u);
  // A huge tolerance stops at once.
  for (const auto& c : paps::orthogonalMatchingPursuit(D, Y, 4, 1e9f)) EXPECT_EQ(c.size(), 0u);
  EXPECT_THROW(paps::orthogonalMatchingPursuit(D, Y, 0), paps::InvalidParameter);
  EXPECT_THROW(paps::orthogonalMatchingPursuit(D, Eigen::MatrixXf::Zero(5, 2), 1), paps::InvalidParameter);
}

TEST(KSvd, LearnsADictionaryThatRepresentsSparseSignals) {
  const Eigen::MatrixXf Dtrue = randomDictionary(20, 12, 4);
  const Eigen::MatrixXf Y = sparseSignals(Dtrue, 3000, 2, 5);
  paps::KSvdParameters p;
  p.atoms = 12;
  p.sparsity = 2;
  p.iterations = 60;
  const auto r = paps::learnDictionaryKSvd(Y, p);
  ASSERT_EQ(r.dictionary.cols(), 12);
  for (int j = 0; j < 12; ++j) EXPECT_NEAR(r.dictionary.col(j).norm(), 1.f, 1e-4f);
  // The error decreases and ends far below the signal scale (~1.5 per sample / sqrt(20)).
  ASSERT_GE(r.rmse.size(), 2u);
  EXPECT_LT(r.rmse.back(), 0.5 * r.rmse.front());
  EXPECT_LT(r.rmse.back(), 0.12);  // a missed atom or two (K-SVD local minimum) allowed
  // Most true atoms are recovered (|cos| > 0.99 with a learned one).
  int found = 0;
  for (int j = 0; j < 12; ++j) {
    const float best = (r.dictionary.transpose() * Dtrue.col(j)).cwiseAbs().maxCoeff();
    found += best > 0.99f;
  }
  EXPECT_GE(found, 10) << "rmse " << r.rmse.back();
}

TEST(KSvd, RejectsAbsurdParameters) {
  const Eigen::MatrixXf Y = Eigen::MatrixXf::Ones(4, 3);
  paps::KSvdParameters p;
  p.atoms = 0;
  EXPECT_THROW(paps::learnDictionaryKSvd(Y, p), paps::InvalidParameter);
  p.atoms = 4;
  p.sparsity = 5;
  EXPECT_THROW(paps::learnDictionaryKSvd(Y, p), paps::InvalidParameter);
  p.sparsity = 1;
  EXPECT_THROW(paps::learnDictionaryKSvd(Eigen::MatrixXf(4, 0), p), paps::InvalidInput);
  Eigen::MatrixXf bad = Y;
  bad(0, 0) = NAN;
  EXPECT_THROW(paps::learnDictionaryKSvd(bad, p), paps::InvalidInput);
  // Fewer distinct signals than atoms: padded, still unit norm.
  const auto r = paps::learnDictionaryKSvd(Y, p);
  for (int j = 0; j < 4; ++j) EXPECT_NEAR(r.dictionary.col(j).norm(), 1.f, 1e-4f);
  EXPECT_LT(r.rmse.back(), 1e-4);
}

}  // namespace core_sparse_coding_test
