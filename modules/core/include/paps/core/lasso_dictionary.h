#pragma once
// L1-sparse coding (the LASSO) and dictionary learning over it, as the Local Probing Fields of
// manuscript 3.2.3 (eq. 3.3) use them: min sum_j 0.5 |x_j - D a_j|^2 + lambda |a_j|_1 with
// atoms in the unit ball. The manuscript solves the coding with LARS and updates the
// dictionary as Mairal et al. (2010) do; here the same LASSO problem is solved by cyclic
// coordinate descent on the Gram matrix (exact on convergence, deterministic, no active-set
// bookkeeping), and the dictionary by Mairal's block coordinate descent on the sufficient
// statistics A = sum a a^T, B = sum x a^T, warm-started from the previous dictionary.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include <paps/core/progress.h>

namespace paps {

/// Codes of the columns of `signals` (k x n) over `dictionary` (k x d): the d x n matrix of
/// coefficients minimising 0.5 |x - D a|^2 + lambda |a|_1 for each column. `lambda` is in
/// the units of the signals (>= 0; 0 gives least squares where D^T D is invertible).
/// Coordinate descent stops when no coefficient moves by more than 1e-5 of the largest or
/// after `max_sweeps`. Parallel over the columns, same result for any thread count.
/// With `debias`, the coefficients of each code's support are then refitted by least
/// squares (the "relaxed" LASSO): the L1 penalty picks the atoms but no longer shrinks them,
/// so a signal the support spans is reproduced without the bias of lambda.
/// Throws InvalidParameter for a negative lambda, max_sweeps < 1 or mismatched sizes.
Eigen::MatrixXf lassoCodes(const Eigen::MatrixXf& dictionary, const Eigen::MatrixXf& signals, float lambda,
                           int max_sweeps = 100, bool debias = false);

struct LassoDictionaryParameters {
  int atoms = 16;          ///< d, in [1, 4096]
  float lambda = 0.f;      ///< L1 weight in signal units (>= 0)
  int iterations = 10;     ///< coding / dictionary-update rounds, in [0, 1000]
  int update_sweeps = 1;   ///< block-coordinate sweeps over the atoms per round, in [1, 100]
  std::uint64_t seed = 1;  ///< picks the initial atoms among the signals
  void validate() const;
};

struct LassoDictionaryResult {
  Eigen::MatrixXf dictionary;  ///< k x d, columns of norm <= 1
  Eigen::MatrixXf codes;       ///< d x n, the codes of the last round (over the final dictionary)
  /// The objective sum_j 0.5 |x_j - D a_j|^2 + lambda |a_j|_1, divided by n, at the start of
  /// each round and at the end (iterations + 1 values).
  std::vector<double> objective;
};

/// Learns a dictionary for the columns of `signals` (k x n, n >= 1). Starts from `initial`
/// when it is k x atoms, otherwise from distinct non-zero signals picked at random and scaled
/// to unit norm (random unit vectors when there are too few). An atom no code uses is
/// replaced by the worst-represented signal. Deterministic for a seed.
LassoDictionaryResult learnDictionaryLasso(const Eigen::MatrixXf& signals, const LassoDictionaryParameters& parameters,
                                           const Eigen::MatrixXf& initial = Eigen::MatrixXf(),
                                           const ProgressCallback& progress = {});

}  // namespace paps
