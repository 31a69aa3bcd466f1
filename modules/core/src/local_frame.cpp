#include <paps/core/local_frame.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <limits>
#include <queue>
#include <tuple>

#include <Eigen/Eigenvalues>

namespace paps {

namespace {
const Eigen::Vector3f kNaN3 = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());

// A tangent direction chosen only from n, so that flat regions get a reproducible frame.
Eigen::Vector3f anyTangent(const Eigen::Vector3f& n) {
  const Eigen::Vector3f a = std::abs(n.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY();
  return (a - a.dot(n) * n).normalized();
}
}  // namespace

Eigen::Vector3f pcaNormal(const Positions& points, const int* idx, int count, Eigen::Vector3f* centroid) {
  if (centroid) *centroid = kNaN3;
  if (count < 1) return kNaN3;
  // Double precision and centring keep PCA accurate for scans far from the origin.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int j = 0; j < count; ++j) mean += points[idx[j]].cast<double>();
  mean /= count;
  if (centroid) *centroid = mean.cast<float>();
  if (count < 3) return kNaN3;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (int j = 0; j < count; ++j) {
    const Eigen::Vector3d d = points[idx[j]].cast<double>() - mean;
    cov.noalias() += d * d.transpose();
  }
  // Closed-form 3x3 solver: several times faster than the iterative one, and exact enough
  // in double precision on centred data.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  eig.computeDirect(cov);
  const Eigen::Vector3d ev = eig.eigenvalues();
  if (!(ev(1) > 1e-12 * std::max(1.0, ev(2)))) return kNaN3;  // collinear or coincident
  return eig.eigenvectors().col(0).cast<float>().normalized();
}

Normals estimateNormals(const Positions& points, const NeighbourGraph& graph) {
  Normals normals(points.size(), kNaN3);
  const std::int64_t n = static_cast<std::int64_t>(points.size());
#pragma omp parallel for schedule(dynamic, 512)
  for (std::int64_t i = 0; i < n; ++i) normals[i] = pcaNormal(points, graph.begin(i), graph.count(i));
  return normals;
}

std::size_t orientNormalsTowards(const Positions& points, Normals& normals,
                                 const Eigen::Vector3f& viewpoint) {
  std::size_t flips = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!isFinite(normals[i]) || !isFinite(points[i])) continue;
    if (normals[i].dot(viewpoint - points[i]) < 0) { normals[i] = -normals[i]; ++flips; }
  }
  return flips;
}

std::size_t orientNormalsByPropagation(const Positions& points, Normals& normals,
                                       const NeighbourGraph& graph) {
  const std::size_t n = points.size();
  std::vector<int> order;
  order.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    if (isFinite(normals[i])) order.push_back(static_cast<int>(i));
  // Highest point first; ties broken by index for determinism.
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return points[a].z() != points[b].z() ? points[a].z() > points[b].z() : a < b;
  });
  std::vector<std::uint8_t> done(n, 0);
  // Priority: least parallel last. (cost, target, source), cost = 1 - |ni.nj|.
  using Item = std::tuple<float, int, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> heap;
  std::size_t flips = 0;
  // The nearest few neighbours suffice to connect the graph and cost far less heap traffic
  // than all of them.
  constexpr int kPropagationNeighbours = 10;
  auto pushNeighbours = [&](int i) {
    const int* last = graph.begin(i) + std::min(graph.count(i), kPropagationNeighbours);
    for (const int* j = graph.begin(i); j != last; ++j)
      if (!done[*j] && isFinite(normals[*j]))
        heap.emplace(1.f - std::abs(normals[i].dot(normals[*j])), *j, i);
  };
  for (int seed : order) {
    if (done[seed]) continue;
    if (normals[seed].z() < 0) { normals[seed] = -normals[seed]; ++flips; }
    done[seed] = 1;
    pushNeighbours(seed);
    while (!heap.empty()) {
      const auto [cost, j, from] = heap.top();
      heap.pop();
      if (done[j]) continue;
      done[j] = 1;
      if (normals[j].dot(normals[from]) < 0) { normals[j] = -normals[j]; ++flips; }
      pushNeighbours(j);
    }
  }
  return flips;
}

LocalFrames estimatePrincipalFrames(const Normals& normals, const NeighbourGraph& graph) {
  LocalFrames frames(normals.size());
  const std::int64_t n = static_cast<std::int64_t>(normals.size());
#pragma omp parallel for schedule(dynamic, 512)
  for (std::int64_t i = 0; i < n; ++i) {
    LocalFrame& f = frames[i];
    const Eigen::Vector3f ni = normals[i];
    if (!isFinite(ni)) { f.t1 = f.t2 = f.n = kNaN3; continue; }
    // Covariance of the neighbours' normals (sign-aligned with ni), restricted to the
    // tangent plane: its main axis is the direction in which the normal turns fastest.
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    int m = 0;
    for (const int* j = graph.begin(i); j != graph.end(i); ++j) {
      if (!isFinite(normals[*j])) continue;
      Eigen::Vector3d nj = normals[*j].cast<double>();
      if (nj.dot(ni.cast<double>()) < 0) nj = -nj;
      mean += nj;
      ++m;
    }
    Eigen::Vector3f t1 = anyTangent(ni);
    if (m >= 3) {
      mean /= m;
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (const int* j = graph.begin(i); j != graph.end(i); ++j) {
        if (!isFinite(normals[*j])) continue;
        Eigen::Vector3d nj = normals[*j].cast<double>();
        if (nj.dot(ni.cast<double>()) < 0) nj = -nj;
        const Eigen::Vector3d d = nj - mean;
        cov.noalias() += d * d.transpose();
      }
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - ni.cast<double>() * ni.cast<double>().transpose();
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
      eig.computeDirect(P * cov * P);
      if (eig.eigenvalues()(2) > 1e-14 * m) {
        Eigen::Vector3f d = eig.eigenvectors().col(2).cast<float>();
        d -= d.dot(ni) * ni;
        if (d.norm() > 1e-6f) {
          t1 = d.normalized();
          // Eigenvectors have no sign: pick the one closest to the deterministic tangent.
          if (t1.dot(anyTangent(ni)) < 0) t1 = -t1;
        }
      }
    }
    f.n = ni;
    f.t1 = t1;
    f.t2 = ni.cross(t1);
  }
  return frames;
}

}  // namespace paps
