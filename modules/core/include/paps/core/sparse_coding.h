#pragma once
// Sparse coding over a learned dictionary (manuscript 2.2.3, eq. 2.1): orthogonal matching
// pursuit (OMP) and the K-SVD dictionary learning of Aharon, Elad and Bruckstein (2006), in the
// fast "approximate K-SVD" form of Rubinstein, Zibulevsky and Elad (2008). Shared by the
// compression codec and the Local Probing Fields work.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include <paps/core/progress.h>

namespace paps {

/// A sparse code of one signal: at most T0 (atom index, coefficient) pairs.
struct SparseCode {
  std::vector<int> atoms;
  std::vector<float> values;
  std::size_t size() const { return atoms.size(); }
};

/// Orthogonal matching pursuit of the columns of `signals` (k x n) over `dictionary`
/// (k x d, columns of unit norm). Each code has at most `sparsity` (T0 >= 1) atoms and stops
/// early when the squared residual norm falls to `tolerance` (squared units of the signal;
/// 0 = never). Uses the Gram matrix (batch OMP), runs in parallel.
/// Throws InvalidParameter when sparsity < 1 or the sizes disagree.
std::vector<SparseCode> orthogonalMatchingPursuit(const Eigen::MatrixXf& dictionary,
                                                  const Eigen::MatrixXf& signals, int sparsity,
                                                  float tolerance = 0.f);

/// y ~= D x for one code.
Eigen::VectorXf reconstructSignal(const Eigen::MatrixXf& dictionary, const SparseCode& code);

/// Parameters of K-SVD.
struct KSvdParameters {
  int atoms = 32;        ///< d, number of atoms, in [1, 4096]
  int sparsity = 4;      ///< T0, non-zero coefficients per signal, in [1, atoms]
  int iterations = 10;   ///< sparse-coding / dictionary-update rounds, in [0, 1000]
  float tolerance = 0;   ///< OMP early stop on the squared residual (0 = none)
  std::uint64_t seed = 1;  ///< picks the initial atoms among the signals
};

struct KSvdResult {
  Eigen::MatrixXf dictionary;            ///< k x d, unit-norm columns
  std::vector<SparseCode> codes;         ///< one per training signal, after the last update
  std::vector<double> rmse;              ///< per-sample RMSE after each iteration
};

/// Learns a dictionary for the columns of `signals` (k x n, n >= 1). The initial atoms are
/// distinct non-zero signals chosen at random (padded with random unit vectors when there
/// are fewer). An atom that no signal uses is replaced by the worst-represented signal.
KSvdResult learnDictionaryKSvd(const Eigen::MatrixXf& signals, const KSvdParameters& parameters,
                               const ProgressCallback& progress = {});

}  // namespace paps
