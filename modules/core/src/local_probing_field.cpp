#include <paps/core/local_probing_field.h>

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <paps/core/error.h>
#include <paps/core/lasso_dictionary.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/poisson_disk_sampling.h>
#include <paps/core/random.h>

namespace paps {

// ---------------------------------------------------------------------------------------
// Pattern

ProbingPattern::ProbingPattern(float radius, float step) : radius_(radius), step_(step) {
  requirePositive("radius", radius);
  requirePositive("step", step);
  if (step > radius) throw InvalidParameter("step", detail::toString(step), "at most the pattern radius " + detail::toString(radius));
  const double ratio = radius / step;
  if (ratio > 80) throw InvalidParameter("step", detail::toString(step), "at least radius / 80 (at most about 20,100 pattern nodes)");
  half_ = static_cast<int>(std::floor(ratio));
  const int side = 2 * half_ + 1;
  node_of_cell_.assign(static_cast<std::size_t>(side) * side, -1);
  for (int y = -half_; y <= half_; ++y)
    for (int x = -half_; x <= half_; ++x) {
      const Eigen::Vector2f u(x * step, y * step);
      if (u.norm() > radius * (1 + 1e-6f)) continue;
      node_of_cell_[(y + half_) * side + (x + half_)] = static_cast<int>(nodes_.size());
      nodes_.push_back(u);
    }
}

int ProbingPattern::nearestNode(float x, float y) const {
  const int side = 2 * half_ + 1;
  const float gx = x / step_, gy = y / step_;
  if (!(std::abs(gx) <= half_ + 1.f && std::abs(gy) <= half_ + 1.f)) {
    // Far outside (or NaN): no rounding to int of an unbounded value.
    if (!std::isfinite(gx) || !std::isfinite(gy)) return 0;
  } else {
    const int cx = static_cast<int>(std::lround(gx)), cy = static_cast<int>(std::lround(gy));
    if (std::abs(cx) <= half_ && std::abs(cy) <= half_) {
      const int n = node_of_cell_[(cy + half_) * side + (cx + half_)];
      if (n >= 0) return n;
    }
  }
  // Outside the disk: the nearest node by search (rare: only points beyond the pattern).
  int best = 0;
  float best_d2 = INFINITY;
  for (int i = 0; i < size(); ++i) {
    const float d2 = (nodes_[i] - Eigen::Vector2f(x, y)).squaredNorm();
    if (d2 < best_d2) { best_d2 = d2; best = i; }
  }
  return best;
}

bool ProbingPattern::cellCorners(float x, float y, int nodes[4], float weights[4]) const {
  const int side = 2 * half_ + 1;
  const float gx = x / step_, gy = y / step_;
  const int x0 = static_cast<int>(std::floor(gx)), y0 = static_cast<int>(std::floor(gy));
  if (!(x0 >= -half_ && x0 + 1 <= half_ && y0 >= -half_ && y0 + 1 <= half_)) return false;
  const float fx = gx - x0, fy = gy - y0;
  for (int c = 0; c < 4; ++c) {
    const int cx = x0 + (c & 1), cy = y0 + (c >> 1);
    nodes[c] = node_of_cell_[(cy + half_) * side + (cx + half_)];
    if (nodes[c] < 0) return false;
    weights[c] = ((c & 1) ? fx : 1 - fx) * ((c >> 1) ? fy : 1 - fy);
  }
  return true;
}

// ---------------------------------------------------------------------------------------
// Parameters

void LocalProbingParameters::validate() const {
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "0 (automatic) or a finite value > 0");
  requireInRange("neighbours", neighbours, 8, 2000);
  requireInRange("noise_sigmas", noise_sigmas, 0.f, 100.f);
  requireInRange("nodes_per_point", nodes_per_point, 1.f, 100.f);
  if (!(step >= 0) || !std::isfinite(step))
    throw InvalidParameter("step", detail::toString(step), "0 (automatic) or a finite value > 0");
  requireInRange("target_factor", target_factor, 1.f, 3.f);
  requireInRange("max_target_points", max_target_points, 0, 1000000);
  if (!(seed_spacing >= 0) || !std::isfinite(seed_spacing))
    throw InvalidParameter("seed_spacing", detail::toString(seed_spacing), "0 (from seed_spacing_radii) or a finite value > 0");
  requireInRange("seed_spacing_radii", seed_spacing_radii, 0.f, 2.f);
  requireInRange("atoms", atoms, 1, 1024);
  if (!std::isfinite(lambda)) throw InvalidParameter("lambda", detail::toString(lambda), "a finite value (< 0: automatic)");
  requireInRange("lambda_factor", lambda_factor, 0.f, 100.f);
  requireInRange("rounds", rounds, 0, 100);
  requireInRange("dictionary_iterations", dictionary_iterations, 1, 100);
  requireInRange("alignment_iterations", alignment_iterations, 0, 100);
}

// ---------------------------------------------------------------------------------------
// Probing operator (manuscript 3.1.2): each node goes to the target point whose projection
// on the pattern plane is nearest to it ("as orthogonal as possible").

namespace {

struct ProbeScratch {
  std::vector<Eigen::Vector3f> local;  // finite target points in the field's frame
  std::vector<int> index;              // their indices in the cloud
  std::vector<int> cell_start, cell_points, cell_of, fill;
};

// Probes one field: writes 3 M displacements (in the frame) and the probed point indices.
// Returns false when the target area holds no finite point.
bool probeField(const Positions& points, const int* tb, const int* te, const ProbingPose& pose,
                const ProbingPattern& pattern, float* v, int* probed, ProbeScratch& s) {
  const int m = pattern.size();
  s.local.clear();
  s.index.clear();
  const Eigen::Matrix3f to_local = pose.frame.transpose();
  for (const int* t = tb; t != te; ++t)
    if (isFinite(points[*t])) {
      s.local.push_back(to_local * (points[*t] - pose.seed));
      s.index.push_back(*t);
    }
  const int count = static_cast<int>(s.local.size());
  if (count == 0) {
    std::fill(v, v + 3 * m, 0.f);
    std::fill(probed, probed + m, -1);
    return false;
  }
  // Bucket grid of the projections, cells of one step centred on the nodes, over the
  // pattern's square plus one cell; points outside are clamped in (projection on a box never
  // lengthens a distance to a node inside it, so the ring bound below stays a lower bound).
  const float step = pattern.step();
  const int half = static_cast<int>(std::ceil(pattern.radius() / step)) + 1;
  const int side = 2 * half + 1;
  const float origin = -(half + 0.5f) * step;
  auto cellCoord = [&](float x) {
    const int c = static_cast<int>(std::floor((x - origin) / step));
    return std::clamp(c, 0, side - 1);
  };
  s.cell_start.assign(static_cast<std::size_t>(side) * side + 1, 0);
  s.cell_of.resize(count);
  for (int p = 0; p < count; ++p) {
    const int c = cellCoord(s.local[p].y()) * side + cellCoord(s.local[p].x());
    s.cell_of[p] = c;
    ++s.cell_start[c + 1];
  }
  for (int c = 0; c < side * side; ++c) s.cell_start[c + 1] += s.cell_start[c];
  s.cell_points.resize(count);
  s.fill.assign(s.cell_start.begin(), s.cell_start.end() - 1);
  for (int p = 0; p < count; ++p) s.cell_points[s.fill[s.cell_of[p]]++] = p;  // increasing p in each cell

  for (int i = 0; i < m; ++i) {
    const Eigen::Vector2f& u = pattern.node(i);
    const int cx = cellCoord(u.x()), cy = cellCoord(u.y());
    int best = -1;
    float best_d2 = INFINITY;
    for (int ring = 0; ring < side; ++ring) {
      for (int y = cy - ring; y <= cy + ring; ++y) {
        if (y < 0 || y >= side) continue;
        const bool edge_row = (y == cy - ring || y == cy + ring);
        for (int x = cx - ring; x <= cx + ring; x += edge_row ? 1 : 2 * std::max(ring, 1)) {
          if (x < 0 || x >= side) continue;
          const int c = y * side + x;
          for (int k = s.cell_start[c]; k < s.cell_start[c + 1]; ++k) {
            const int p = s.cell_points[k];
            const float dx = s.local[p].x() - u.x(), dy = s.local[p].y() - u.y();
            const float d2 = dx * dx + dy * dy;
            if (d2 < best_d2 || (d2 == best_d2 && p < best)) { best_d2 = d2; best = p; }
          }
          if (ring == 0) break;
        }
      }
      // The node is at its cell's centre: every point not yet seen is at least
      // (ring + 1/2) steps away.
      const float bound = (ring + 0.5f) * step;
      if (best >= 0 && best_d2 <= bound * bound) break;
    }
    const Eigen::Vector3f& q = s.local[best];
    v[3 * i] = q.x() - u.x();
    v[3 * i + 1] = q.y() - u.y();
    v[3 * i + 2] = q.z();
    probed[i] = s.index[best];
  }
  return true;
}

// Frame of the target area by PCA: t1 along the largest spread, n along the smallest;
// `dimension` gets the dimensionality of Demantke et al. (2011): with s_k the square roots of
// the eigenvalues (s1 >= s2 >= s3), the largest of linearity (s1 - s2) / s1, planarity
// (s2 - s3) / s1 and scattering s3 / s1 gives 1, 2 or 3. Unlike a ratio of two
// eigenvalues it does not depend on the noise: a noisy wire spreads equally in both
// directions across it.
Eigen::Matrix3f pcaFrame(const Positions& points, const int* tb, const int* te, std::uint8_t* dimension) {
  *dimension = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  int n = 0;
  for (const int* t = tb; t != te; ++t)
    if (isFinite(points[*t])) { mean += points[*t].cast<double>(); ++n; }
  if (n < 3) return Eigen::Matrix3f::Identity();
  mean /= n;
  const bool measurable = n >= 6;  // fewer points cannot tell a wire from a surface
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const int* t = tb; t != te; ++t)
    if (isFinite(points[*t])) {
      const Eigen::Vector3d d = points[*t].cast<double>() - mean;
      cov += d * d.transpose();
    }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  const double s1 = std::sqrt(std::max(0.0, es.eigenvalues()[2])), s2 = std::sqrt(std::max(0.0, es.eigenvalues()[1])),
               s3 = std::sqrt(std::max(0.0, es.eigenvalues()[0]));
  if (s1 > 0 && measurable) {
    const double linear = s1 - s2, planar = s2 - s3, scattered = s3;
    *dimension = linear >= planar && linear >= scattered ? 1 : (planar >= scattered ? 2 : 3);
  }
  Eigen::Matrix3f f;
  const Eigen::Vector3f t1 = es.eigenvectors().col(2).cast<float>().normalized();
  const Eigen::Vector3f nrm = es.eigenvectors().col(0).cast<float>().normalized();
  f.col(0) = t1;
  f.col(1) = nrm.cross(t1).normalized();
  f.col(2) = nrm;
  return f;
}

Eigen::Matrix3f randomFrame(std::uint64_t seed, std::size_t j) {
  Random rng(seed * 0x9e3779b97f4a7c15ULL + j + 1);
  // Drawn last to first, as GCC evaluated the four arguments this replaces (random.h).
  const float z = static_cast<float>(rng.gaussian()), y = static_cast<float>(rng.gaussian());
  const float x = static_cast<float>(rng.gaussian()), w = static_cast<float>(rng.gaussian());
  Eigen::Quaternionf q(w, x, y, z);
  if (q.norm() < 1e-6f) q = Eigen::Quaternionf::Identity();
  return q.normalized().toRotationMatrix();
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Analysis

LocalProbingAnalysis::~LocalProbingAnalysis() = default;

float LocalProbingAnalysis::chooseRadius(const Positions& points, const SpatialIndex& index,
                                         const LocalProbingParameters& parameters, float* noise_sigma) {
  if (noise_sigma) *noise_sigma = 0.f;
  float r = parameters.radius;
  if (r > 0) return r;
  r = radiusForNeighbourCount(points, index, parameters.neighbours);
  if (!(r > 0)) throw InvalidInput("the points are all at one position: no pattern radius fits them");
  if (parameters.noise_sigmas > 0) {
    float sigma = 0.f;
    try {
      sigma = estimateNoiseLevel(points, index, r).sigma;
    } catch (const InvalidInput&) {
      sigma = 0.f;  // no ball to fit a surface in (a few points, or wires only)
    }
    if (noise_sigma) *noise_sigma = sigma;
    // Wider for the noise, but never beyond half the cloud.
    r = std::max(r, std::min(parameters.noise_sigmas * sigma, 0.5f * boundingBoxDiagonal(points)));
  }
  return r;
}

LocalProbingAnalysis::LocalProbingAnalysis(const Positions& points, const LocalProbingParameters& parameters,
                                           const ProgressCallback& progress, bool check_extent)
    : params_(parameters) {
  params_.validate();
  const std::size_t finite = countFinite(points);
  if (finite < 3) throw InvalidInput("Local Probing Fields need at least 3 finite points, got " + std::to_string(finite));
  if (check_extent) requireRadiusWithinExtent("radius", params_.radius, points);
  SpatialIndex index(points);
  const float r = chooseRadius(points, index, params_, &noise_sigma_);
  float step = params_.step;
  if (!(step > 0)) step = r * std::sqrt(3.14159265f / (params_.neighbours * params_.nodes_per_point));
  if (step > r) throw InvalidParameter("step", detail::toString(step), "at most the pattern radius " + detail::toString(r));
  pattern_ = std::make_unique<ProbingPattern>(r, step);
  lambda_ = params_.lambda >= 0 ? params_.lambda : params_.lambda_factor * step;
  {
    // Least squares z = c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2 over the nodes (in
    // units of r): its pseudo-inverse, and the (A^T A)^-1 block of c3..c5, whose inverse
    // weighs the curvature against the fit's residual (splitCurvature).
    const int m = pattern_->size();
    Eigen::MatrixXd A(m, 6);
    for (int i = 0; i < m; ++i) {
      const double x = pattern_->node(i).x() / r, y = pattern_->node(i).y() / r;
      A.row(i) << 1, x, y, x * x, x * y, y * y;
    }
    const Eigen::Matrix<double, 6, 6> AtA = A.transpose() * A;
    quadric_fit_ = AtA.ldlt().solve(A.transpose()).cast<float>();
    quadric_basis_ = A.cast<float>();
    const Eigen::Matrix<double, 6, 6> inv = AtA.inverse();
    curvature_information_ = inv.bottomRightCorner<3, 3>().inverse().cast<float>();
    // The free part is the quadratic terms less their own affine fit: zero mean and no tilt
    // over the pattern, so the penalised rest keeps the field's offset and tilt (which the
    // pose follows) and is not handed a constant to shrink.
    const Eigen::MatrixXd affine = A.leftCols(3), quadratic = A.rightCols(3);
    curvature_basis_ = (quadratic - affine * (affine.transpose() * affine).ldlt().solve(affine.transpose() * quadratic)).cast<float>();
  }

  // Seeds and target areas.
  std::vector<int> seeds;
  const float seed_spacing = params_.seed_spacing > 0 ? params_.seed_spacing : params_.seed_spacing_radii * r;
  if (seed_spacing > 0) {
    seeds = poissonDiskSubset(points, seed_spacing, params_.seed, progress);
  } else {
    for (std::size_t i = 0; i < points.size(); ++i)
      if (isFinite(points[i])) seeds.push_back(static_cast<int>(i));
  }
  const std::size_t n = seeds.size();
  const float target_r = params_.target_factor * r;
  const std::size_t cap = static_cast<std::size_t>(params_.max_target_points > 0 ? params_.max_target_points
                                                                                  : 4 * params_.neighbours);
  std::vector<std::vector<int>> lists(n);
  ProgressReporter rep(progress, "probing fields", n);
#pragma omp parallel
  {
    std::vector<float> d2;
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t j = 0; j < static_cast<std::int64_t>(n); ++j) {
      index.radiusSearch(points[seeds[j]], target_r, lists[j], d2);
      std::sort(lists[j].begin(), lists[j].end());
      const std::size_t count = lists[j].size();
      if (count > cap) {
        // An even subset: the k-th of every `count / cap` (the points are in spatial order
        // when they come from the stages, so this spreads over the ball).
        std::vector<int> kept(cap);
        for (std::size_t k = 0; k < cap; ++k) kept[k] = lists[j][k * count / cap];
        lists[j].swap(kept);
      }
      rep.advance();
    }
  }
  rep.throwIfCancelled();
  target_off_.assign(n + 1, 0);
  for (std::size_t j = 0; j < n; ++j) target_off_[j + 1] = target_off_[j] + static_cast<std::int64_t>(lists[j].size());
  target_idx_.resize(static_cast<std::size_t>(target_off_[n]));
  for (std::size_t j = 0; j < n; ++j) {
    std::copy(lists[j].begin(), lists[j].end(), target_idx_.begin() + target_off_[j]);
    std::vector<int>().swap(lists[j]);
  }

  poses_.resize(n);
  dimension_.resize(n);
  centres_.resize(n);
#pragma omp parallel for schedule(dynamic, 1024)
  for (std::int64_t j = 0; j < static_cast<std::int64_t>(n); ++j) {
    poses_[j].seed = centres_[j] = points[seeds[j]];
    poses_[j].frame = pcaFrame(points, targetBegin(j), targetEnd(j), &dimension_[j]);
    if (params_.random_orientation) poses_[j].frame = randomFrame(params_.seed, j);
  }
  const int m = pattern_->size();
  // The fields hold 3 floats and an index per node: refuse what cannot fit rather than
  // failing half-way through an allocation.
  const double bytes = 16.0 * m * static_cast<double>(n);
  if (bytes > 8e9)
    throw InvalidParameter("seed_spacing", detail::toString(params_.seed_spacing),
                           "fewer fields or a coarser step: " + std::to_string(n) + " fields of " + std::to_string(m) +
                               " nodes need " + detail::toString(bytes / 1e9) + " GB (at most 8)");
  points_ = points.size();
  fields_.resize(3 * m, static_cast<Eigen::Index>(n));
  probed_.assign(static_cast<std::size_t>(m) * n, -1);
  probe(points);
  // Initial alignment: the ICP variant of 3.1.2 (minimise sum |v_i|^2).
  const Eigen::VectorXf zero = Eigen::VectorXf::Zero(3 * m);
  for (int it = 0; it < params_.alignment_iterations; ++it) {
#pragma omp parallel for schedule(dynamic, 256)
    for (std::int64_t j = 0; j < static_cast<std::int64_t>(n); ++j) align(j, zero);
    probe(points);
  }
}

void LocalProbingAnalysis::probe(const Positions& points) {
  if (points.size() != points_)
    throw InvalidParameter("points", std::to_string(points.size()) + " points",
                           std::to_string(points_) + " (the cloud the analysis was built on)");
  const int m = pattern_->size();
  const std::int64_t n = static_cast<std::int64_t>(poses_.size());
#pragma omp parallel
  {
    ProbeScratch scratch;
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t j = 0; j < n; ++j)
      probeField(points, targetBegin(j), targetEnd(j), poses_[j], *pattern_, fields_.col(j).data(),
                 probed_.data() + j * m, scratch);
  }
}

// Rigid motion (R_d, t_d) of the frame taking the pattern shape u + goal onto the probed
// u + v (eq. 3.5, least squares, Kabsch/Umeyama), then the pose update of eq. 3.6: the
// pattern's nodes plus `goal` now sit where the probed points are.
void LocalProbingAnalysis::align(std::size_t j, const Eigen::VectorXf& goal) {
  const int m = pattern_->size();
  const int* probed = probed_.data() + j * m;
  int valid = 0;
  for (int i = 0; i < m; ++i) valid += probed[i] >= 0;
  if (valid < 3) return;
  Eigen::Matrix3Xf src(3, valid), dst(3, valid);
  int c = 0;
  for (int i = 0; i < m; ++i) {
    if (probed[i] < 0) continue;
    const Eigen::Vector3f u(pattern_->node(i).x(), pattern_->node(i).y(), 0.f);
    src.col(c) = u + goal.segment<3>(3 * i);
    dst.col(c) = u + fields_.col(j).segment<3>(3 * i);
    ++c;
  }
  const Eigen::Matrix4f T = Eigen::umeyama(src, dst, false);
  const Eigen::Matrix3f Rd = T.topLeftCorner<3, 3>();
  const Eigen::Vector3f td = T.topRightCorner<3, 1>();
  if (!Rd.allFinite() || !td.allFinite()) return;
  ProbingPose& pose = poses_[j];
  pose.seed += pose.frame * td;
  pose.frame = pose.frame * Rd;
  // Keep the frame orthonormal against float drift over many rounds.
  Eigen::Quaternionf q(pose.frame);
  pose.frame = q.normalized().toRotationMatrix();
}

void LocalProbingAnalysis::recode() {
  splitCurvature(+1);
  codes_ = lassoCodes(dictionary_, fields_, lambda_, 100, params_.debias);
  splitCurvature(-1);
}

float LocalProbingAnalysis::curvatureHeight(std::size_t j, int i) const {
  return curvature_basis_.row(i).dot(curvature_.col(static_cast<Eigen::Index>(j)));
}

void LocalProbingAnalysis::splitCurvature(int sign) {
  if (!params_.free_curvature) return;
  const int m = pattern_->size();
  const std::int64_t n = static_cast<std::int64_t>(poses_.size());
  if (sign < 0) {
#pragma omp parallel for schedule(static)
    for (std::int64_t j = 0; j < n; ++j)
      for (int i = 0; i < m; ++i) fields_(3 * i + 2, j) += curvatureHeight(j, i);
    return;
  }
  curvature_.resize(3, n);
#pragma omp parallel for schedule(static)
  for (std::int64_t j = 0; j < n; ++j) {
    // The curvature goes free in proportion to its significance: W = c^T Sigma^-1 c, with
    // Sigma the covariance of c3..c5 given the residual of the field's own quadric fit, is
    // chi-square with 3 degrees of freedom on a plane under white noise; c is scaled by
    // max(0, 1 - q / W), q its 99th percentile (11.34).
    const Eigen::Map<const Eigen::VectorXf, 0, Eigen::InnerStride<3>> z(fields_.col(j).data() + 2, m);
    const Eigen::Matrix<float, 6, 1> c6 = quadric_fit_ * z;
    const double residual = (z - quadric_basis_ * c6).squaredNorm() / std::max(1, m - 6);
    const Eigen::Vector3f c = c6.tail<3>();
    const double w = residual > 0 ? c.dot(curvature_information_ * c) / residual : INFINITY;
    const double keep = w > 0 ? std::max(0.0, 1.0 - 11.34 / w) : 0.0;
    curvature_.col(j) = c * static_cast<float>(keep);
    for (int i = 0; i < m; ++i) fields_(3 * i + 2, j) -= curvatureHeight(j, i);
  }
}

Eigen::VectorXf LocalProbingAnalysis::reconstructed(std::size_t j) const {
  Eigen::VectorXf out = dictionary_ * codes_.col(static_cast<Eigen::Index>(j));
  if (params_.free_curvature)
    for (int i = 0; i < pattern_->size(); ++i) out[3 * i + 2] += curvatureHeight(j, i);
  return out;
}

Eigen::Vector3f LocalProbingAnalysis::reconstructedNode(std::size_t j, int i) const {
  const auto code = codes_.col(static_cast<Eigen::Index>(j));
  Eigen::Vector3f out = Eigen::Vector3f::Zero();
  for (Eigen::Index k = 0; k < code.size(); ++k)
    if (code[k] != 0) out += code[k] * dictionary_.block<3, 1>(3 * i, k);
  if (params_.free_curvature) out.z() += curvatureHeight(j, i);
  return out;
}

void LocalProbingAnalysis::analyse(const Positions& points, int rounds, const ProgressCallback& progress) {
  if (points.size() != points_)
    throw InvalidParameter("points", std::to_string(points.size()) + " points",
                           std::to_string(points_) + " (the cloud the analysis was built on)");
  requireInRange("rounds", rounds, 0, 100);
  const std::int64_t n = static_cast<std::int64_t>(poses_.size());
  ProgressReporter rep(progress, "joint analysis", static_cast<std::size_t>(rounds));
  for (int round = 0; round < rounds; ++round) {
    LassoDictionaryParameters dp;
    dp.atoms = params_.atoms;
    dp.lambda = lambda_;
    dp.iterations = params_.dictionary_iterations;
    dp.seed = params_.seed + static_cast<std::uint64_t>(round);
    splitCurvature(+1);
    LassoDictionaryResult learned = learnDictionaryLasso(fields_, dp, dictionary_);
    dictionary_ = std::move(learned.dictionary);
    if (params_.debias) codes_ = lassoCodes(dictionary_, fields_, lambda_, 100, true);
    else codes_ = std::move(learned.codes);
    splitCurvature(-1);
#pragma omp parallel for schedule(dynamic, 256)
    for (std::int64_t j = 0; j < n; ++j) align(j, reconstructed(j));
    probe(points);
    std::vector<double> err(n);
#pragma omp parallel for schedule(static)
    for (std::int64_t j = 0; j < n; ++j) err[j] = (fields_.col(j) - reconstructed(j)).cast<double>().squaredNorm();
    double sum = 0;
    for (double e : err) sum += e;
    round_errors_.push_back(n ? sum / n : 0.0);
    rep.advance();
    rep.throwIfCancelled();
  }
  if (dictionary_.size() == 0) {
    // No round asked for: a dictionary learned on the fields as they are.
    LassoDictionaryParameters dp;
    dp.atoms = params_.atoms;
    dp.lambda = lambda_;
    dp.iterations = params_.dictionary_iterations;
    dp.seed = params_.seed;
    splitCurvature(+1);
    dictionary_ = learnDictionaryLasso(fields_, dp).dictionary;
    splitCurvature(-1);
  }
  recode();
  rep.finish();
}

}  // namespace paps
