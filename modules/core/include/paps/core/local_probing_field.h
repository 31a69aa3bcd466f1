#pragma once
// Local Probing Fields (manuscript chapter 3): a planar pattern of points placed near the
// shape; a probing operator sends each pattern point to a point of the shape; the field is
// the set of displacements (eq. 3.1). The fields of the whole shape are analysed jointly
// (eq. 3.2): a dictionary over which they decompose sparsely, and the pose of every pattern
// that best fits that decomposition, alternated with probing again. No height-field
// assumption: curves, borders and surfaces are probed alike.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include <paps/core/neighbourhood.h>
#include <paps/core/progress.h>

namespace paps {

/// The sampling pattern: the nodes of a square grid of step `step` inside the disk of
/// `radius`, in the pattern plane (manuscript 3.2.6: M ~ pi (r / tau_s)^2 nodes).
class ProbingPattern {
 public:
  /// Throws InvalidParameter unless 0 < step <= radius <= 80 step (about 20,100 nodes at most).
  ProbingPattern(float radius, float step);
  float radius() const { return radius_; }
  float step() const { return step_; }
  int size() const { return static_cast<int>(nodes_.size()); }
  const Eigen::Vector2f& node(int i) const { return nodes_[i]; }
  /// The node nearest to (x, y) of the pattern plane (node 0 for NaN).
  int nearestNode(float x, float y) const;
  /// The four nodes of the grid cell holding (x, y) and their bilinear weights (summing to
  /// 1); false when a corner lies outside the disk.
  bool cellCorners(float x, float y, int nodes[4], float weights[4]) const;

 private:
  float radius_, step_;
  int half_;                        // grid cells from the centre to the border
  std::vector<Eigen::Vector2f> nodes_;
  std::vector<int> node_of_cell_;   // (2 half + 1)^2 cells, -1 outside the disk
};

/// One field's pose: pattern centre and frame (columns t1, t2, n); pattern node i sits at
/// seed + frame * (u_i, 0).
struct ProbingPose {
  Eigen::Vector3f seed = Eigen::Vector3f::Zero();
  Eigen::Matrix3f frame = Eigen::Matrix3f::Identity();
};

struct LocalProbingParameters {
  /// Pattern radius r in metres (> 0), or 0: the radius whose ball holds `neighbours` points
  /// around a typical point. The scale at which similarities are sought (manuscript 3.2.6).
  float radius = 0.f;
  /// Points in the ball of an automatic radius, in [8, 2000].
  int neighbours = 100;
  /// An automatic radius is at least this many times the measured noise sigma
  /// (estimateNoiseLevel), in [0, 100]; 0: no noise rule. On dense, noisy clouds the
  /// `neighbours` ball is narrower than the noise is thick: 1M points of the plate and wires
  /// at 0.15% noise had r = 2.9 sigma and an error of 6.8e-4 in 73 s; at 6 sigma, 2.9e-4 in
  /// 24 s (docs/lpf.md).
  float noise_sigmas = 6.f;
  /// Pattern step tau_s in metres, or 0: `nodes_per_point` nodes for every point of a
  /// `neighbours` ball, r sqrt(pi / (neighbours x nodes_per_point)).
  float step = 0.f;
  /// Pattern nodes per input point of an automatic step, in [1, 100]: 1 is the 1:1 sampling
  /// of denoising; resampling asks for its density factor.
  float nodes_per_point = 1.f;
  /// The target area of a field: the points within target_factor x r of its first seed,
  /// fixed for the whole analysis (manuscript 3.2.1: 1.1). In [1, 3].
  float target_factor = 1.1f;
  /// At most this many points in a target area, or 0: 4 x `neighbours`. A denser area
  /// (next to a scanner, copies of points) keeps an even subset of its points (every k-th
  /// in spatial order); without the cap the cost grows with the density (bun0.pcd: 3 min 50 s
  /// for 112,586 points, against 8.5 s for 50,000 even ones).
  int max_target_points = 0;
  /// Spacing of the fields' seeds in metres (Poisson disk), or 0: `seed_spacing_radii` x r,
  /// or, when that is 0 too, one field per point (the manuscript's denoising setting).
  float seed_spacing = 0.f;
  /// Seed spacing in pattern radii when `seed_spacing` is 0, in [0, 2] (0: one field per
  /// point). The stages set their own defaults (denoising 1/3, resampling 1/2).
  float seed_spacing_radii = 0.f;
  /// d, the dictionary's atoms, in [1, 1024].
  int atoms = 16;
  /// L1 weight of the sparse codes in metres (>= 0), or < 0: automatic,
  /// lambda_factor x the step tau_s (the probing accuracy).
  float lambda = -1.f;
  float lambda_factor = 0.5f;
  /// Codes for reconstruction (poses, denoising) debiased (lassoCodes' `debias`): the L1
  /// penalty picks the atoms, least squares sets them, so consolidation does not also
  /// flatten every field by lambda. Measured (docs/lpf.md): better near creases (fandisk
  /// 1.88e-3 -> 1.57e-3 at 0.3% noise), worse on the plate and wires (1.32e-3 -> 1.43e-3);
  /// off by default, as in the manuscript.
  bool debias = false;
  /// Free curvature (ours, not in the manuscript): each field's curvature, the quadratic
  /// part of the least-squares quadric z(x, y) through its nodes' heights (less its own
  /// affine fit), is kept out of the L1 penalty as far as it stands out of the fit's residual
  /// (scaled by max(0, 1 - 11.34 / W), W its chi-square statistic); the dictionary codes the
  /// rest. With the whole field penalised, every consolidation flattens every field a little
  /// towards its pattern plane, and on a curved surface repeated denoising passes become a
  /// shrinking flow. Measured (docs/lpf.md, 5 passes): a sphere of radius 11 r at 0.15%
  /// noise shrinks by 0.24 sigma, 0.11 sigma with it; on curved shapes it is better (rs1
  /// mesh 0.707 -> 0.654 at 0.15% noise, cylinder 0.490 -> 0.442), on flat ones worse (the
  /// plate 0.145 -> 0.186, cube 0.530 -> 0.559): after a pass what is left of the noise is
  /// smooth and keeps its bumps as curvature. Off by default.
  bool free_curvature = false;
  /// Rounds of the joint analysis (dictionary, pose, probe again), in [0, 100].
  int rounds = 4;
  /// Dictionary updates per round (warm-started), in [1, 100].
  int dictionary_iterations = 2;
  /// Iterations of the initial pattern-to-shape alignment (the ICP variant of 3.1.2), in [0, 100].
  int alignment_iterations = 3;
  /// Initial frames: false, the PCA frame of the target area (t1 along the largest spread);
  /// true, a random frame (the manuscript's setting), drawn from `seed`.
  bool random_orientation = false;
  std::uint64_t seed = 1;
  void validate() const;
};

/// The joint analysis of the fields of one point set (manuscript 3.2): poses, probed fields,
/// dictionary and codes. Built once on a cloud; `probe` reads the (moved) points again.
class LocalProbingAnalysis {
 public:
  /// Places the fields (seeds, target areas, initial frames) and probes them, then aligns
  /// each pattern on its target area. Non-finite points are never probed.
  /// Throws InvalidInput when fewer than 3 points are finite, InvalidParameter for bad
  /// parameters (also a radius wider than the cloud, or fields that would need more than
  /// 8 GB: 16 bytes a node a field).
  /// `check_extent` false: a radius wider than the points is accepted (a stage run on a tile,
  /// whose radius was checked on the whole cloud).
  LocalProbingAnalysis(const Positions& points, const LocalProbingParameters& parameters,
                       const ProgressCallback& progress = {}, bool check_extent = true);
  /// The pattern radius the analysis of `points` uses: `parameters.radius`, or the automatic
  /// one (the ball of `neighbours` points, widened to noise_sigmas x the measured noise);
  /// `noise_sigma` gets the noise measured (0: none). `index` must be built on `points`.
  /// Throws InvalidInput when the points are all at one position.
  static float chooseRadius(const Positions& points, const SpatialIndex& index, const LocalProbingParameters& parameters,
                            float* noise_sigma);
  ~LocalProbingAnalysis();

  /// Runs `rounds` rounds of eq. 3.2 on the current points: dictionary and codes, pose
  /// optimisation against D a (eqs. 3.4 to 3.6), probing again. `points` must be the cloud
  /// the analysis was built on, possibly moved (same size, same order; InvalidParameter for
  /// another size).
  void analyse(const Positions& points, int rounds, const ProgressCallback& progress = {});
  /// Probes every field again at its current pose (eq. 3.1). `points`: the cloud the
  /// analysis was built on, possibly moved (InvalidParameter for another size).
  void probe(const Positions& points);

  const LocalProbingParameters& parameters() const { return params_; }
  const ProbingPattern& pattern() const { return *pattern_; }
  std::size_t fieldCount() const { return poses_.size(); }
  const ProbingPose& pose(std::size_t j) const { return poses_[j]; }
  /// Probed displacements of field j in its frame: column j, 3 M values (x, y, z per node).
  const Eigen::MatrixXf& fields() const { return fields_; }
  /// Index of the point node i of field j probed (-1 when its target area is empty).
  int probedPoint(std::size_t j, int i) const { return probed_[j * pattern_->size() + i]; }
  /// Centre of field j's target area (its first seed; the area is the ball of
  /// target_factor x radius() around it).
  const Eigen::Vector3f& targetCentre(std::size_t j) const { return centres_[j]; }
  /// Target area of field j: point indices.
  const int* targetBegin(std::size_t j) const { return target_idx_.data() + target_off_[j]; }
  const int* targetEnd(std::size_t j) const { return target_idx_.data() + target_off_[j + 1]; }
  /// Dimension of field j's target area by the dimensionality features of its covariance
  /// (Demantke et al. 2011): 1 on a wire, 2 on a surface (also at its border), 3 for a
  /// scattered blob; 0 when it holds fewer than 6 points (too few to tell).
  int targetDimension(std::size_t j) const { return dimension_[j]; }
  const Eigen::MatrixXf& dictionary() const { return dictionary_; }
  /// Codes of the current fields over the dictionary (d x N), as of the last analyse() or
  /// recode().
  const Eigen::MatrixXf& codes() const { return codes_; }
  /// Codes the current fields again over the dictionary (after probe()).
  void recode();
  /// Field j as the analysis represents it (3 M values, in its frame): D a_j, plus its
  /// curvature with `free_curvature`.
  Eigen::VectorXf reconstructed(std::size_t j) const;
  /// The same restricted to node i (x, y, z in field j's frame).
  Eigen::Vector3f reconstructedNode(std::size_t j, int i) const;
  /// Representation error sum_j |V_j - reconstructed(j)|^2 / N after each round of analyse().
  const std::vector<double>& roundErrors() const { return round_errors_; }
  float radius() const { return pattern_->radius(); }
  /// The noise sigma measured for the automatic radius (0: not measured).
  float noiseSigma() const { return noise_sigma_; }
  float lambda() const { return lambda_; }

 private:
  void align(std::size_t j, const Eigen::VectorXf& goal);
  /// With free_curvature: fits every field's curvature (curvature_) and subtracts it from
  /// the heights (sign +1), or adds it back (sign -1).
  void splitCurvature(int sign);
  float curvatureHeight(std::size_t j, int i) const;

  LocalProbingParameters params_;
  std::unique_ptr<ProbingPattern> pattern_;
  std::vector<ProbingPose> poses_;
  std::vector<std::uint8_t> dimension_;
  std::vector<Eigen::Vector3f> centres_;
  std::vector<std::int64_t> target_off_;
  std::vector<int> target_idx_;
  Eigen::MatrixXf fields_;
  std::vector<int> probed_;
  Eigen::MatrixXf dictionary_, codes_;
  Eigen::Matrix3Xf curvature_;      // per field: the x^2, xy, y^2 coefficients (free_curvature)
  Eigen::Matrix<float, 6, Eigen::Dynamic> quadric_fit_;  // the quadric's coefficients from the M heights
  Eigen::Matrix<float, Eigen::Dynamic, 6> quadric_basis_;  // 1, x, y, x^2, xy, y^2 at the nodes
  Eigen::Matrix3f curvature_information_;  // inverse of the x^2, xy, y^2 block of (A^T A)^-1
  Eigen::Matrix<float, Eigen::Dynamic, 3> curvature_basis_;  // x^2, xy, y^2 at the nodes, less their affine fit
  std::vector<double> round_errors_;
  std::size_t points_ = 0;  // size of the cloud the analysis was built on
  float noise_sigma_ = 0.f;
  float lambda_ = 0.f;
};

}  // namespace paps
