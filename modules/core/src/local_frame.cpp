#include <paps/core/local_frame.h>
#include <paps/core/spatial_order.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <limits>
#include <queue>
#include <utility>
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

Eigen::Vector3f pcaNormal(const Positions& points, const int* idx, int count, Eigen::Vector3f* centroid,
                          float* variation) {
  if (centroid) *centroid = kNaN3;
  if (variation) *variation = NAN;
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
  // Collinear or coincident: the middle eigenvalue negligible against the largest. Relative,
  // so that the test does not depend on the units (an absolute 1e-12 m^2 once made every
  // ball of a micrometre-sized object "collinear"), and well above the closed-form solver's
  // error on a repeated zero eigenvalue (about 1e-8 of the largest: an exact line gave
  // +-1e-11 against 2.5e-3, and an arbitrary normal).
  if (!(ev(1) > 1e-6 * ev(2))) return kNaN3;
  if (variation) *variation = static_cast<float>(std::max(0.0, ev(0)) / ev.sum());
  return eig.eigenvectors().col(0).cast<float>().normalized();
}

double volumeVariation(const Positions& points, const SpatialIndex& index, std::size_t samples) {
  const std::size_t finite = index.size();
  if (finite < 256) return 0;
  const std::vector<int> sample = spreadSample(points, samples);
  double least = INFINITY;
  int previous = 0;
  for (int k : {32, 128, 512}) {
    k = std::min<int>(k, static_cast<int>(finite / 8));
    if (k == previous) break;  // capped: the larger scales are this one again
    previous = k;
    std::vector<float> variation(sample.size(), std::numeric_limits<float>::quiet_NaN());
#pragma omp parallel
    {
      std::vector<int> idx;
      std::vector<float> sq;
#pragma omp for schedule(static)
      for (std::int64_t s = 0; s < static_cast<std::int64_t>(sample.size()); ++s) {
        const int n = index.nearestK(points[sample[s]], k, idx, sq);
        pcaNormal(points, idx.data(), n, nullptr, &variation[s]);
      }
    }
    // Collinear or coincident balls (NaN) count as flat: no volume there.
    for (float& v : variation)
      if (!std::isfinite(v)) v = 0;
    std::nth_element(variation.begin(), variation.begin() + variation.size() / 2, variation.end());
    least = std::min(least, static_cast<double>(variation[variation.size() / 2]));
  }
  return least;
}

Normals estimateNormals(const Positions& points, const NeighbourGraph& graph, std::vector<float>* variation) {
  Normals normals(points.size(), kNaN3);
  if (variation) variation->assign(points.size(), NAN);
  const std::int64_t n = static_cast<std::int64_t>(points.size());
#pragma omp parallel for schedule(dynamic, 512)
  for (std::int64_t i = 0; i < n; ++i)
    normals[i] = pcaNormal(points, graph.begin(i), graph.count(i), nullptr, variation ? &(*variation)[i] : nullptr);
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

namespace {

// Points per block of the parallel orientation: inputs up to this size are one block, i.e. the
// plain sequential propagation.
constexpr std::size_t kOrientBlock = 4096;
// |n.z| from which a normal's sign says up or down (60 degrees from vertical).
constexpr float kUprightNormal = 0.5f;
// |summed z| / summed |z| from which a group's normals point one way on the whole (a closed
// surface has about 0, a scan seen from above about 1).
constexpr double kOneSided = 0.2;

// +1 or -1: the sign that points a group's normals up, from their summed z, summed |z| and the
// z of the normal of its highest upright point (0: none). A piece seen from one side (a scan)
// has most of its normals on one side of the horizontal: they point up on the whole (summed
// z). A closed surface has as many down as up: the normal of its highest upright point
// points up (outward).
int upwardRule(double z, double a, float top_z) {
  if (std::abs(z) >= kOneSided * a && z != 0) return z > 0 ? 1 : -1;
  if (top_z != 0) return top_z > 0 ? 1 : -1;
  return 1;
}

// Hoppe-style propagation inside one block: the points `members` (sorted highest first, ties
// by index), edges to points of the same block only. Each component inside the block is
// seeded at its highest point with the normal up; comp[i] receives the component's number
// within the block (0, 1, ...). Returns the number of components.
int propagateInBlock(Normals& normals, const NeighbourGraph& graph,
                     const std::vector<int>& members, const std::vector<int>& block_of, int block,
                     std::vector<int>& comp, std::vector<std::uint8_t>& flipped,
                     std::vector<std::pair<float, int>>& offer) {
  using Item = std::tuple<float, int, int>;  // (1 - |ni.nj|, target, source): most parallel first
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> heap;
  // offer[j]: the best (cost, source) pushed for j so far. An offer that would pop after it
  // can never be the one that reaches j, so it is not pushed: the same result as pushing all,
  // with far less heap traffic.
  auto pushNeighbours = [&](int i) {
    const int* last = graph.begin(i) + std::min(graph.count(i), kPropagationNeighbours);
    for (const int* j = graph.begin(i); j != last; ++j)
      if (block_of[*j] == block && comp[*j] < 0) {
        const std::pair<float, int> o(1.f - std::abs(normals[i].dot(normals[*j])), i);
        if (!(o < offer[*j])) continue;
        offer[*j] = o;
        heap.emplace(o.first, *j, i);
      }
  };
  int comps = 0;
  for (const int seed : members) {
    if (comp[seed] >= 0) continue;
    const int c = comps++;
    if (normals[seed].z() < 0) { normals[seed] = -normals[seed]; flipped[seed] ^= 1; }
    comp[seed] = c;
    pushNeighbours(seed);
    while (!heap.empty()) {
      const auto [cost, j, from] = heap.top();
      heap.pop();
      if (comp[j] >= 0) continue;
      comp[j] = c;
      if (normals[j].dot(normals[from]) < 0) { normals[j] = -normals[j]; flipped[j] ^= 1; }
      pushNeighbours(j);
    }
  }
  return comps;
}

// Orders (component a, component b, value) by the pair.
template <typename T>
bool byPair(const std::tuple<int, int, T>& x, const std::tuple<int, int, T>& y) {
  return std::get<0>(x) != std::get<0>(y) ? std::get<0>(x) < std::get<0>(y) : std::get<1>(x) < std::get<1>(y);
}

// Appends to `out` one (a, b, sum of the values) per run of equal pairs in `sorted` (sorted
// by pair), summing in order: a fixed order of additions.
template <typename T>
void sumPerPair(const std::vector<std::tuple<int, int, T>>& sorted, std::vector<std::tuple<int, int, double>>& out) {
  for (std::size_t k = 0; k < sorted.size();) {
    std::size_t e = k;
    double sum = 0;
    for (; e < sorted.size() && !byPair(sorted[k], sorted[e]); ++e) sum += std::get<2>(sorted[e]);
    out.emplace_back(std::get<0>(sorted[k]), std::get<1>(sorted[k]), sum);
    k = e;
  }
}

}  // namespace

std::size_t orientNormalsByPropagation(const Positions& points, Normals& normals,
                                       const NeighbourGraph& graph) {
  const std::size_t n = points.size();
  std::vector<int> order;
  order.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    if (isFinite(normals[i]) && isFinite(points[i])) order.push_back(static_cast<int>(i));
  if (order.empty()) return 0;
  // Fixed blocks of space: the points in Morton order (10 bits per axis over the bounding cube,
  // ties by index), cut into runs of kOrientBlock. They depend on the points only, never on
  // the thread count.
  std::vector<int> sorted;
  sorted.reserve(order.size());
  for (const int k : spatialOrder(gathered(points, order), 10)) sorted.push_back(order[k]);
  const int blocks = static_cast<int>((sorted.size() + kOrientBlock - 1) / kOrientBlock);
  std::vector<int> block_of(n, -1);
  std::vector<std::vector<int>> members(blocks);
  for (std::size_t k = 0; k < sorted.size(); ++k) {
    block_of[sorted[k]] = static_cast<int>(k / kOrientBlock);
    members[k / kOrientBlock].push_back(sorted[k]);
  }
  auto higher = [&](int a, int b) {  // highest first; ties broken by index
    return points[a].z() != points[b].z() ? points[a].z() > points[b].z() : a < b;
  };
  // 1. Propagation inside each block, in parallel. Component numbers are made global after.
  std::vector<int> comp(n, -1), block_comps(blocks, 0);
  std::vector<std::uint8_t> flipped(n, 0);
  std::vector<std::pair<float, int>> offer(n, {INFINITY, -1});
#pragma omp parallel for schedule(dynamic, 1)
  for (int b = 0; b < blocks; ++b) {
    std::sort(members[b].begin(), members[b].end(), higher);
    block_comps[b] = propagateInBlock(normals, graph, members[b], block_of, b, comp, flipped, offer);
  }
  std::vector<int> comp_base(blocks + 1, 0);
  for (int b = 0; b < blocks; ++b) comp_base[b + 1] = comp_base[b] + block_comps[b];
  const int ncomp = comp_base[blocks];
#pragma omp parallel for schedule(static)
  for (int b = 0; b < blocks; ++b)
    for (const int i : members[b]) comp[i] += comp_base[b];
  std::vector<int> comp_seed(ncomp);  // each component's highest point (the first of its block)
  for (int b = 0; b < blocks; ++b)
    for (auto it = members[b].rbegin(); it != members[b].rend(); ++it) comp_seed[comp[*it]] = *it;
  // What sets the sign of a whole connected group (step 3): each piece's summed normal z and
  // summed |z| (signs of step 1; block then member order, a fixed order of additions), and its
  // highest point whose normal is within 60 degrees of vertical (members are sorted highest
  // first).
  std::vector<double> zsum(ncomp, 0.0), zabs(ncomp, 0.0);
  std::vector<int> top(ncomp, -1);
  for (int b = 0; b < blocks; ++b)
    for (const int i : members[b]) {
      const int c = comp[i];
      zsum[c] += normals[i].z();
      zabs[c] += std::abs(normals[i].z());
      if (top[c] < 0 && std::abs(normals[i].z()) >= kUprightNormal) top[c] = i;
    }
  // upwardRule sets the sign of each group. The seed's own sign (step 1: the highest point's
  // normal up) is kept only when neither tells: that point is often on a rim, where the normal
  // is near horizontal and its sign is noise (on rs1 sampled at 70K points it flipped one of
  // the scan's pieces, 13% of the points).
  if (ncomp == 1) {
    const bool down = upwardRule(zsum[0], zabs[0], top[0] >= 0 ? normals[top[0]].z() : 0.f) < 0;
    std::size_t flips = 0;
    for (const int i : order) {
      if (down) { normals[i] = -normals[i]; flipped[i] ^= 1; }
      flips += flipped[i];
    }
    return flips;
  }
  // 2. Agreement between components over the edges that cross them: the sum of ni.nj (with
  // the signs of step 1). Positive: the two components are oriented alike.
  std::vector<std::vector<std::tuple<int, int, float>>> crossing(blocks);
#pragma omp parallel for schedule(dynamic, 1)
  for (int b = 0; b < blocks; ++b) {
    auto& out = crossing[b];
    for (const int i : members[b]) {
      const int* last = graph.begin(i) + std::min(graph.count(i), kPropagationNeighbours);
      for (const int* j = graph.begin(i); j != last; ++j) {
        const int cj = comp[*j];
        if (cj < 0 || cj == comp[i]) continue;
        out.emplace_back(std::min(comp[i], cj), std::max(comp[i], cj), normals[i].dot(normals[*j]));
      }
    }
    std::stable_sort(out.begin(), out.end(), byPair<float>);
  }
  // Sums per pair, in block order then pair order.
  std::vector<std::tuple<int, int, double>> pairs;
  for (int b = 0; b < blocks; ++b) {
    sumPerPair(crossing[b], pairs);
    std::vector<std::tuple<int, int, float>>().swap(crossing[b]);
  }
  std::stable_sort(pairs.begin(), pairs.end(), byPair<double>);
  std::vector<std::int64_t> off(ncomp + 1, 0);
  std::vector<std::pair<int, double>> adj;
  {
    std::vector<std::tuple<int, int, double>> merged;
    sumPerPair(pairs, merged);
    merged.erase(std::remove_if(merged.begin(), merged.end(), [](const auto& t) { return std::get<2>(t) == 0; }),
                 merged.end());
    for (const auto& [a, c, s] : merged) { ++off[a + 1]; ++off[c + 1]; }
    for (int c = 0; c < ncomp; ++c) off[c + 1] += off[c];
    adj.resize(off[ncomp]);
    std::vector<std::int64_t> cur(off.begin(), off.end() - 1);
    for (const auto& [a, c, s] : merged) { adj[cur[a]++] = {c, s}; adj[cur[c]++] = {a, s}; }
  }
  // 3. Components oriented relative to each other by propagation over the component graph,
  // strongest agreement first, from the component of the highest point not yet reached; then
  // the whole group reached from it is turned up (upwardRule, above).
  std::vector<int> comp_order(ncomp);
  std::iota(comp_order.begin(), comp_order.end(), 0);
  std::sort(comp_order.begin(), comp_order.end(), [&](int a, int b) { return higher(comp_seed[a], comp_seed[b]); });
  std::vector<std::int8_t> sign(ncomp, 0);
  // (-|agreement|, target, source, agreement): strongest first; the edge carries its sign.
  using Item = std::tuple<double, int, int, double>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> heap;
  auto push = [&](int c) {
    for (std::int64_t k = off[c]; k < off[c + 1]; ++k)
      if (!sign[adj[k].first]) heap.emplace(-std::abs(adj[k].second), adj[k].first, c, adj[k].second);
  };
  std::vector<int> group;
  for (const int root : comp_order) {
    if (sign[root]) continue;
    sign[root] = 1;
    group.assign(1, root);
    push(root);
    while (!heap.empty()) {
      const auto [cost, c, from, agreement] = heap.top();
      heap.pop();
      if (sign[c]) continue;
      sign[c] = static_cast<std::int8_t>(agreement >= 0 ? sign[from] : -sign[from]);
      group.push_back(c);
      push(c);
    }
    std::sort(group.begin(), group.end());  // a fixed order of additions
    double z = 0, a = 0;
    int best = -1;
    for (const int c : group) {
      z += sign[c] * zsum[c];
      a += zabs[c];
      if (top[c] >= 0 && (best < 0 || higher(top[c], top[best]))) best = c;
    }
    if (upwardRule(z, a, best >= 0 ? sign[best] * normals[top[best]].z() : 0.f) < 0)
      for (const int c : group) sign[c] = static_cast<std::int8_t>(-sign[c]);
  }
  std::size_t flips = 0;
#pragma omp parallel for schedule(static) reduction(+ : flips)
  for (std::int64_t k = 0; k < static_cast<std::int64_t>(order.size()); ++k) {
    const int i = order[k];
    if (sign[comp[i]] < 0) { normals[i] = -normals[i]; flipped[i] ^= 1; }
    flips += flipped[i];
  }
  return flips;
}

void turnComponentsToHints(Normals& normals, const NeighbourGraph& g, const Normals& hints) {
  const std::size_t n = normals.size();
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  for (std::size_t i = 0; i < g.size(); ++i) {
    const int* e = std::min(g.end(i), g.begin(i) + kPropagationNeighbours);
    for (const int* j = g.begin(i); j != e; ++j) {
      const int a = root(static_cast<int>(i)), b = root(*j);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  }
  std::vector<double> agreement(n, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    if (isFinite(normals[i]) && isFinite(hints[i]) && hints[i].norm() > 0.5f)
      agreement[root(static_cast<int>(i))] += normals[i].dot(hints[i]);
  for (std::size_t i = 0; i < n; ++i)
    if (agreement[root(static_cast<int>(i))] < 0) normals[i] = -normals[i];
}

int upwardSign(const Positions& points, const Normals& normals) {
  double z = 0, a = 0;
  int top = -1;
  for (std::size_t i = 0; i < normals.size(); ++i) {
    if (!isFinite(normals[i]) || !isFinite(points[i])) continue;
    z += normals[i].z();
    a += std::abs(normals[i].z());
    if (std::abs(normals[i].z()) >= kUprightNormal && (top < 0 || points[i].z() > points[top].z())) top = static_cast<int>(i);
  }
  return upwardRule(z, a, top >= 0 ? normals[top].z() : 0.f);
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
