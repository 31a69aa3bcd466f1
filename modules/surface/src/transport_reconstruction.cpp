#include <paps/surface/transport_reconstruction.h>
#include <paps/surface/impl/transport_reconstruction.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <set>
#include <tuple>

#include <Eigen/Eigenvalues>

#include <CGAL/Advancing_front_surface_reconstruction.h>
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <paps/core/error.h>
#include <paps/core/key_sort.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/spatial_order.h>
#include <paps/core/random.h>

namespace paps {

void TransportReconstructionParameters::validate() const {
  if (!(initial_fraction > 0) || !(initial_fraction <= 1))
    throw InvalidParameter("initial_fraction", detail::toString(initial_fraction), "in (0, 1]");
  requireInRange("target_vertices", target_vertices, 3, 100000000);
  requireInRange("candidates", candidates, 0, 100000);
  requireInRange("relocation_iterations", relocation_iterations, 0, 100);
  requireInRange("final_relocation_sweeps", final_relocation_sweeps, 0, 100);
  if (!(density_threshold >= 0) || !(density_threshold < 1))
    throw InvalidParameter("density_threshold", detail::toString(density_threshold), "in [0, 1)");
  if (!(deletion_threshold >= 0) || !std::isfinite(deletion_threshold) || deletion_threshold > 1e6)
    throw InvalidParameter("deletion_threshold", detail::toString(deletion_threshold), "in [0, 1e6]");
  if (!(stacked_threshold >= 0) || !std::isfinite(stacked_threshold) || stacked_threshold > 1e6)
    throw InvalidParameter("stacked_threshold", detail::toString(stacked_threshold), "in [0, 1e6]");
  if (!(stacked_reach > 0) || !std::isfinite(stacked_reach) || stacked_reach > 1000)
    throw InvalidParameter("stacked_reach", detail::toString(stacked_reach), "in (0, 1000]");
  if (!(dangling_support >= 0) || !(dangling_support <= 1000))
    throw InvalidParameter("dangling_support", detail::toString(dangling_support), "in [0, 1000]");
  requireInRange("outlier_neighbours", outlier_neighbours, 0, 1000);
  requireInRange("max_points", max_points, 0, 1000000000);
  requireInRange("merge_points_per_vertex", merge_points_per_vertex, 0, 1000);
  if (!(merge_crease_angle >= 0) || !(merge_crease_angle <= 90))
    throw InvalidParameter("merge_crease_angle", detail::toString(merge_crease_angle), "in [0, 90]");
  transport.validate();
}

std::size_t TransportReconstructionParameters::mergeTarget() const {
  if (max_points <= 0) return 0;
  return std::max(static_cast<std::size_t>(max_points),
                  static_cast<std::size_t>(std::max(merge_points_per_vertex, 0)) *
                      static_cast<std::size_t>(std::max(target_vertices, 0)));
}

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_3<int, Kernel>;
using Tds = CGAL::Triangulation_data_structure_3<Vb>;
using Delaunay = CGAL::Delaunay_triangulation_3<Kernel, Tds>;

using Triple = std::array<int, 3>;
Triple sorted(Triple t) {
  std::sort(t.begin(), t.end());
  return t;
}

// CGAL's advancing front keeps its border edges in a set ordered by (priority, address of
// the edge's record): equal priorities are taken in heap-address order, which depends on
// what the process allocated and freed before (with 2 threads, the fandisk test's two calls
// in one process gave different surfaces in 4 runs of 8). Here its default priority (the
// radius of the smallest empty sphere through the facet) is scaled by 1 + h 2^-44, h from
// the facet's three point indices, so that no two facets tie (after it, 8 runs of 8 gave
// one surface). The same facet seen from two border edges can still tie.
struct TieBrokenPriority {
  template <typename AdvancingFront, typename CellHandle>
  double operator()(const AdvancingFront& front, CellHandle& c, const int& index) const {
    const double radius = front.smallest_radius_delaunay_sphere(c, index);
    if (!std::isfinite(radius) || !(radius > 0)) return radius;
    std::array<std::size_t, 3> ids;
    for (int k = 1; k <= 3; ++k) {
      const auto v = c->vertex((index + k) & 3);
      if (front.triangulation_3().is_infinite(v)) return radius;
      ids[k - 1] = v->info();
    }
    std::sort(ids.begin(), ids.end());
    std::uint64_t h = 0x9e3779b97f4a7c15ull;
    for (std::size_t id : ids) h = (h ^ id) * 0xff51afd7ed558ccdull;
    h ^= h >> 33;
    return radius * (1 + std::ldexp(static_cast<double>(h >> 52), -44));  // below 2^-32
  }
};

// Facets the density filter dropped come back where their emptiness is no evidence of a gap
// and they close a hole. Candidates: alive facets with area that were dropped; those sharing
// an edge no kept facet uses form a group. A group comes back when fewer than 3 points were to
// be expected on it in all (the mean facet density times its area: an area that small is empty
// by chance 5% of the time or more) and, with it, each of its edges has exactly two facets (it
// fills a hole of the kept mesh exactly: no border, no edge of three). With many vertices for
// the points (rs1 merged into 20,000 points to 10,000 vertices), the points near a corner go
// to the vertex and many small facets get none: the filter alone left the mesh in shreds.
// Deterministic (groups by facet order). Returns how many facets came back.
int restoreEnclosedFacets(const TransportPlan& plan, double mean_density, std::vector<char>& kept) {
  constexpr double kExpectedPoints = 3;
  if (!(mean_density > 0)) return 0;
  const auto edge = [&](int f, int e) {
    const int a = plan.facet(f)[e], b = plan.facet(f)[(e + 1) % 3];
    return std::make_pair(std::min(a, b), std::max(a, b));
  };
  std::map<std::pair<int, int>, int> kept_uses;
  std::map<std::pair<int, int>, std::vector<int>> candidate_uses;
  std::vector<int> candidates;
  for (int f = 0; f < plan.facetCount(); ++f) {
    if (!plan.facetAlive(f)) continue;
    if (kept[f]) {
      for (int e = 0; e < 3; ++e) ++kept_uses[edge(f, e)];
    } else if (plan.facetArea(f) > 0) {
      candidates.push_back(f);
      for (int e = 0; e < 3; ++e) candidate_uses[edge(f, e)].push_back(f);
    }
  }
  // Groups: union-find over the candidates, joined across edges without a kept facet.
  std::map<int, int> parent;
  for (int f : candidates) parent[f] = f;
  const auto root = [&](int f) {
    while (parent[f] != f) f = parent[f] = parent[parent[f]];
    return f;
  };
  for (const auto& [e, fs] : candidate_uses)
    if (kept_uses.count(e) == 0)
      for (std::size_t k = 1; k < fs.size(); ++k) parent[root(fs[k])] = root(fs[0]);
  std::map<int, std::vector<int>> groups;  // by root, members in facet order
  for (int f : candidates) groups[root(f)].push_back(f);
  int restored = 0;
  for (const auto& [r, members] : groups) {
    double expected = 0;
    for (int f : members) expected += mean_density * plan.facetArea(f);
    if (!(expected < kExpectedPoints)) continue;
    std::map<std::pair<int, int>, int> uses;
    for (int f : members)
      for (int e = 0; e < 3; ++e) ++uses[edge(f, e)];
    bool fills = true;
    for (const auto& [e, n] : uses) {
      const auto it = kept_uses.find(e);
      fills = fills && n + (it == kept_uses.end() ? 0 : it->second) == 2;
    }
    if (!fills) continue;
    for (int f : members) kept[f] = 1;
    restored += static_cast<int>(members.size());
  }
  return restored;
}

// The decimated complex: the transport plan (vertices, facets, plan) plus the edges, which a
// simplicial complex keeps even where no facet remains (a vertex on a bare edge can still be
// collapsed).
class Decimation {
 public:
  explicit Decimation(TransportPlan& plan)
      : plan_(plan), neighbours_(plan.vertexCount()), degree_tree_(plan.vertexCount() + 1, 0) {
    for (int f = 0; f < plan.facetCount(); ++f)
      if (plan.facetAlive(f)) {
        const auto& t = plan.facet(f);
        for (int e = 0; e < 3; ++e) link(t[e], t[(e + 1) % 3]);
      }
  }
  void link(int a, int b) {
    if (a == b) return;
    if (neighbours_[a].insert(b).second) addDegree(a, 1);
    if (neighbours_[b].insert(a).second) addDegree(b, 1);
  }
  const std::set<int>& neighbours(int v) const { return neighbours_[v]; }

  // The half-edges (u, v), both directions of every edge, in (u, v) order: their count and
  // the k-th of them, without listing them (a list every step cost O(vertices) a step). A
  // Fenwick tree over the vertices' degrees finds u; v is the remaining rank among u's
  // neighbours.
  std::int64_t halfEdgeCount() const { return prefixDegree(static_cast<int>(neighbours_.size())); }
  std::pair<int, int> halfEdge(std::int64_t k) const {
    int u = 0;  // the largest u with prefixDegree(u) <= k
    int bit = 1;
    while (bit * 2 <= static_cast<int>(neighbours_.size())) bit *= 2;
    for (; bit > 0; bit /= 2)
      if (u + bit <= static_cast<int>(neighbours_.size()) && degree_tree_[u + bit] <= k) {
        u += bit;
        k -= degree_tree_[u];
      }
    return {u, *std::next(neighbours_[u].begin(), static_cast<std::ptrdiff_t>(k))};
  }

  // The collapse of u onto v: the stencil before, the simplices after, and the new facets'
  // corner triples (created only when the collapse is applied).
  struct Collapse {
    int u = -1, v = -1;
    TransportPlan::Stencil before;
    std::vector<int> vertices_after;       // ids
    std::vector<int> kept_facets;          // ids of facets of v that stay
    std::vector<Triple> new_facets;        // u's facets moved onto v
    std::vector<FacetBins> new_bins;
    LocalTransport solution;
    double lower_bound = -INFINITY;  // of delta
    double delta = INFINITY;         // INFINITY: not simulated (or the program failed)
    bool turns_facet = false;        // refused: a facet of u would turn over (refuse_flips)
  };

  // The collapse's stencil, simplices after and new facets' bins, and a lower bound of its
  // cost change (nearestBinCost after, minus the cost before); no program solved yet.
  Collapse prepare(int u, int v) const {
    Collapse c;
    c.u = u;
    c.v = v;
    // A collapse that turns a facet of u over folds the sheet back over itself; the transport
    // cost barely sees it when the facet carries little mass.
    if (plan_.parameters().refuse_flips && plan_.turnsAFacet(u, plan_.vertex(v), v)) {
      c.turns_facet = true;
      c.lower_bound = INFINITY;
      return c;
    }
    std::vector<int> fs = plan_.facetsOf(u), vs{u, v};
    fs.insert(fs.end(), plan_.facetsOf(v).begin(), plan_.facetsOf(v).end());
    for (int f : fs) vs.insert(vs.end(), plan_.facet(f).begin(), plan_.facet(f).end());
    c.before = plan_.gather(vs, fs);
    for (int x : c.before.vertices)
      if (x != u) c.vertices_after.push_back(x);
    std::set<Triple> seen;
    for (int f : c.before.facets) {
      const auto& t = plan_.facet(f);
      if (std::find(t.begin(), t.end(), u) == t.end()) {
        c.kept_facets.push_back(f);
        seen.insert(sorted(t));
      }
    }
    for (int f : c.before.facets) {
      Triple t = plan_.facet(f);
      if (std::find(t.begin(), t.end(), u) == t.end()) continue;
      if (std::find(t.begin(), t.end(), v) != t.end()) continue;  // degenerates
      for (int& x : t)
        if (x == u) x = v;
      if (!seen.insert(sorted(t)).second) continue;  // merges with an existing facet
      c.new_facets.push_back(t);
    }
    c.new_bins.reserve(c.new_facets.size());
    for (const auto& t : c.new_facets) {
      const Eigen::Vector3d &a = plan_.vertex(t[0]), &b = plan_.vertex(t[1]), &d = plan_.vertex(t[2]);
      c.new_bins.push_back(centroidalBins(a, b, d, plan_.binCountFor(triangleArea(a, b, d))));
    }
    c.lower_bound = nearestBinCost(plan_.positionsOf(c.before), c.before.mass, targetsAfter(c)) - c.before.cost;
    return c;
  }

  // A lower bound of the prepared collapse's cost after it (the program's dual), which stops
  // once it reaches `goal`.
  double dualBound(const Collapse& c, double goal) const {
    return dualLowerBound(plan_.positionsOf(c.before), c.before.mass, targetsAfter(c), plan_.parameters().bins_per_point, goal);
  }

  // Solves the prepared collapse's program: its cost change.
  void simulate(Collapse& c) const {
    c.solution = solveLocalTransport(plan_.positionsOf(c.before), c.before.mass, targetsAfter(c), plan_.parameters().bins_per_point);
    if (c.solution.solved) c.delta = c.solution.cost - c.before.cost;
  }

  // The targets after the collapse: vertices, kept facets, new facets (pointing into c).
  std::vector<TransportTarget> targetsAfter(const Collapse& c) const {
    std::vector<TransportTarget> targets;
    for (int x : c.vertices_after) targets.push_back({{plan_.vertex(x), plan_.vertex(x), plan_.vertex(x)}, nullptr});
    for (int f : c.kept_facets) {
      const auto& t = plan_.facet(f);
      targets.push_back({{plan_.vertex(t[0]), plan_.vertex(t[1]), plan_.vertex(t[2])}, &plan_.bins(f)});
    }
    for (std::size_t k = 0; k < c.new_facets.size(); ++k) {
      const auto& t = c.new_facets[k];
      targets.push_back({{plan_.vertex(t[0]), plan_.vertex(t[1]), plan_.vertex(t[2])}, &c.new_bins[k]});
    }
    return targets;
  }

  void apply(const Collapse& c) {
    touch(c.before.vertices, c.before.facets);
    plan_.release(c.before);
    plan_.removeVertex(c.u);  // and its facets
    std::vector<int> facets = c.kept_facets;
    for (std::size_t k = 0; k < c.new_facets.size(); ++k) {
      const auto& t = c.new_facets[k];
      facets.push_back(plan_.addFacet(t[0], t[1], t[2], c.new_bins[k]));
    }
    plan_.assign(c.before, c.vertices_after, facets, c.solution);
    for (int w : neighbours_[c.u]) {
      if (neighbours_[w].erase(c.u) > 0) addDegree(w, -1);
      link(c.v, w);
    }
    addDegree(c.u, -static_cast<int>(neighbours_[c.u].size()));
    neighbours_[c.u].clear();
  }

  // A simulation stays exact while no simplex of its stencil changed (position, facets, plan):
  // it depends on nothing else. The decimation marks what each step changes, and keeps the
  // simulations of unchanged stencils for the next steps' draws (same result, fewer programs).
  void touch(const std::vector<int>& vertices, const std::vector<int>& facets) {
    ++step_;
    if (vertex_step_.size() < static_cast<std::size_t>(plan_.vertexCount())) vertex_step_.resize(plan_.vertexCount(), 0);
    if (facet_step_.size() < static_cast<std::size_t>(plan_.facetCount())) facet_step_.resize(plan_.facetCount(), 0);
    for (int v : vertices) vertex_step_[v] = step_;
    for (int f : facets) facet_step_[f] = step_;
  }
  /// Marks what relocating v changes: its stencil (v, its facets and their corners).
  void touchAround(int v) {
    std::vector<int> vs, fs;
    plan_.vertexStencilSimplices(v, vs, fs);
    touch(vs, fs);
  }
  std::uint64_t step() const { return step_; }
  bool unchangedSince(const TransportPlan::Stencil& s, std::uint64_t since) const {
    for (int v : s.vertices)
      if (static_cast<std::size_t>(v) < vertex_step_.size() && vertex_step_[v] > since) return false;
    for (int f : s.facets)
      if (static_cast<std::size_t>(f) < facet_step_.size() && facet_step_[f] > since) return false;
    return true;
  }

 private:
  std::uint64_t step_ = 0;
  std::vector<std::uint64_t> vertex_step_, facet_step_;
  TransportPlan& plan_;
  std::vector<std::set<int>> neighbours_;
  std::vector<std::int64_t> degree_tree_;  // Fenwick tree (1-based) of the neighbour counts

  void addDegree(int v, int d) {
    for (int i = v + 1; i < static_cast<int>(degree_tree_.size()); i += i & -i) degree_tree_[i] += d;
  }
  std::int64_t prefixDegree(int n) const {  // sum of the degrees of vertices [0, n)
    std::int64_t sum = 0;
    for (int i = n; i > 0; i -= i & -i) sum += degree_tree_[i];
    return sum;
  }
};

}  // namespace

int dropDanglingFacets(TriangleMesh& mesh, const SpatialIndex& points, float radius) {
  if (!(radius > 0) || !std::isfinite(radius)) throw InvalidParameter("radius", detail::toString(radius), "> 0");
  for (const auto& t : mesh.triangles)
    if (t.minCoeff() < 0 || t.maxCoeff() >= static_cast<int>(mesh.vertices.size()))
      throw InvalidInput("dangling facets: a facet refers to a vertex that does not exist");
  std::vector<int> support(mesh.vertices.size(), -1), k;  // -1: not searched yet
  std::vector<float> d2;
  auto supported = [&](int v) {
    if (support[v] < 0) support[v] = points.radiusSearch(mesh.vertices[v], radius, k, d2, 2);
    return support[v] >= 2;
  };
  int dropped = 0;
  for (bool again = true; again;) {
    again = false;
    std::vector<int> degree(mesh.vertices.size(), 0);
    for (const auto& t : mesh.triangles)
      for (int c = 0; c < 3; ++c) ++degree[t[c]];
    std::vector<Eigen::Vector3i> kept;
    kept.reserve(mesh.triangles.size());
    for (const auto& t : mesh.triangles) {
      bool hangs = false;
      for (int c = 0; c < 3 && !hangs; ++c) hangs = degree[t[c]] == 1 && !supported(t[c]);
      if (hangs) { ++dropped; again = true; } else kept.push_back(t);
    }
    mesh.triangles = std::move(kept);
  }
  if (dropped > 0) {  // keep only the vertices the facets use, in their order
    std::vector<int> id(mesh.vertices.size(), -1);
    Positions used;
    for (auto& t : mesh.triangles)
      for (int c = 0; c < 3; ++c) {
        int& n = id[t[c]];
        if (n < 0) { n = static_cast<int>(used.size()); used.push_back(mesh.vertices[t[c]]); }
        t[c] = n;
      }
    mesh.vertices = std::move(used);
  }
  return dropped;
}

std::vector<double> outlierWeights(const Positions& points, int neighbours) {
  requireInRange("neighbours", neighbours, 1, 1000);
  const SpatialIndex index(points);  // finite points only
  if (index.size() < 2) throw InvalidInput("outlier weights need at least 2 finite points");
  const int want = std::min<int>(neighbours + 1, static_cast<int>(index.size()));  // self included
  std::vector<double> reach(points.size(), NAN);
#pragma omp parallel
  {
    std::vector<int> idx;
    std::vector<float> d2;
#pragma omp for schedule(static)
    for (std::int64_t i = 0; i < static_cast<std::int64_t>(points.size()); ++i)
      if (isFinite(points[i]) && index.nearestK(points[i], want, idx, d2) > 0)
        reach[i] = std::sqrt(static_cast<double>(d2.back()));
  }
  // The median over the points not at the position of K others (piles of copies would
  // make it 0 and weigh everything else 0).
  std::vector<double> positive;
  for (const double r : reach)
    if (r > 0) positive.push_back(r);
  std::vector<double> w(points.size(), 0.0);
  for (std::size_t i = 0; i < points.size(); ++i)
    if (std::isfinite(reach[i])) w[i] = 1.0;
  if (positive.empty()) return w;
  std::nth_element(positive.begin(), positive.begin() + positive.size() / 2, positive.end());
  const double limit = kOutlierReach * positive[positive.size() / 2];
  for (std::size_t i = 0; i < points.size(); ++i)
    if (reach[i] > limit) w[i] = std::max(kMinOutlierWeight, std::pow(limit / reach[i], 4));
  return w;
}

namespace {

// The points in float, as the spatial index and the normals take them.
Positions asPositions(const std::vector<Eigen::Vector3d>& points) {
  Positions out(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) out[i] = points[i].cast<float>();
  return out;
}

// Crease splits: a cell's points in at most 2^kCreaseDepth groups (a cube's corner has 3 faces).
constexpr int kCreaseDepth = 2;

// Largest-eigenvalue axis of sum m n n^T over the points of [first, last) with a normal.
Eigen::Vector3d normalAxis(const int* first, const int* last, const Normals& normals, const std::vector<double>& masses) {
  Eigen::Matrix3d t = Eigen::Matrix3d::Zero();
  for (const int* i = first; i != last; ++i)
    if (isFinite(normals[*i])) {
      const Eigen::Vector3d n = normals[*i].cast<double>();
      t += masses[*i] * n * n.transpose();
    }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  eig.computeDirect(t);
  return eig.eigenvectors().col(2);
}

// Whether the sides [first, mid) and [mid, last) of a cell, with normal axes a and b, are a
// crease rather than noise: each side holds kMinCreaseSide normals or more, and the axes lie
// further apart than kCreaseContrast x the RMS angle (sines) of the tighter side's normals to
// its axis. Splitting the normals of a flat cell that only noise tilts gives axes about 1.4x
// that RMS apart (half-means of a 2-D Gaussian); a crease gives tight clusters. The tighter
// side, not both: at a cube's corner the first split leaves two faces on one side.
constexpr int kMinCreaseSide = 3;
constexpr double kCreaseContrast = 2.5;
bool separatedBeyondNoise(const int* first, const int* mid, const int* last, const Eigen::Vector3d& a,
                          const Eigen::Vector3d& b, const Normals& normals, const std::vector<double>& masses) {
  const auto spreadOf = [&](const int* from, const int* to, const Eigen::Vector3d& axis) {
    double m = 0, spread = 0;
    int count = 0;
    for (const int* i = from; i != to; ++i)
      if (isFinite(normals[*i])) {
        ++count;
        m += masses[*i];
        spread += masses[*i] * (1 - std::pow(axis.dot(normals[*i].cast<double>()), 2));
      }
    return count < kMinCreaseSide ? -1.0 : spread / m;
  };
  const double sa = spreadOf(first, mid, a), sb = spreadOf(mid, last, b);
  if (sa < 0 || sb < 0) return false;
  return 1 - std::pow(a.dot(b), 2) > kCreaseContrast * kCreaseContrast * std::min(sa, sb);
}

// Splits the points of [first, last) (a cell, reordered in place) into groups whose normals
// lie within `cos_crease` of one axis: 2-means on unoriented normals, started from the
// normal tensor's main axis and the normal furthest from it (chosen by value, so the
// points' order does not matter), a split kept when the two axes end further apart than the
// crease angle and beyond the noise of the normals (separatedBeyondNoise), then each side
// again. Appends the end of each group to `ends` (room for 2^kCreaseDepth), counting them in
// `count`. Points without a normal stay with the first side.
void splitAtCreases(int* first, int* last, const Normals& normals, const std::vector<double>& masses,
                    double cos_crease, int depth, std::vector<char>& side, int** ends, int& count) {
  if (depth < kCreaseDepth && last - first >= 2 * kMinCreaseSide) {
    Eigen::Vector3d a = normalAxis(first, last, normals, masses), b;
    double furthest = 2;
    Eigen::Vector3f far_normal = Eigen::Vector3f::Zero();
    const auto lexicographic = [](const Eigen::Vector3f& u, const Eigen::Vector3f& v) {
      return std::tie(u.x(), u.y(), u.z()) < std::tie(v.x(), v.y(), v.z());
    };
    for (const int* i = first; i != last; ++i) {
      const Eigen::Vector3f& n = normals[*i];
      if (!isFinite(n)) continue;
      const double c = std::abs(n.cast<double>().dot(a));
      if (c < furthest || (c == furthest && lexicographic(n, far_normal))) {
        furthest = c;
        far_normal = n;
      }
    }
    b = far_normal.cast<double>();
    for (int round = 0; round < 4 && furthest < cos_crease; ++round) {
      bool moved = round == 0;  // `side` holds another cell's flags before the first round
      for (int* i = first; i != last; ++i) {
        const Eigen::Vector3d n = normals[*i].cast<double>();
        const char s = isFinite(normals[*i]) && std::abs(n.dot(b)) > std::abs(n.dot(a));
        moved |= s != side[*i];
        side[*i] = s;
      }
      const auto firstSide = [&](int i) { return side[i] == 0; };
      int* mid;
      if (moved) {
        mid = std::stable_partition(first, last, firstSide);
        if (mid == first || mid == last) break;
        a = normalAxis(first, mid, normals, masses);
        b = normalAxis(mid, last, normals, masses);
      } else {
        // A fixed point: the later rounds would repeat this one (same sides, same axes).
        mid = std::partition_point(first, last, firstSide);
        round = 3;
      }
      if (round == 3 && std::abs(a.dot(b)) < cos_crease && separatedBeyondNoise(first, mid, last, a, b, normals, masses)) {
        splitAtCreases(first, mid, normals, masses, cos_crease, depth + 1, side, ends, count);
        splitAtCreases(mid, last, normals, masses, cos_crease, depth + 1, side, ends, count);
        return;
      }
    }
  }
  ends[count++] = last;
}

}  // namespace

MergedPoints mergeIntoCells(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& masses,
                            std::size_t max_points, const Normals* normals, double crease_degrees) {
  if (masses.size() != points.size())
    throw InvalidInput("mergeIntoCells: " + std::to_string(points.size()) + " points but " +
                       std::to_string(masses.size()) + " masses");
  for (const auto& p : points)
    if (!p.allFinite()) throw InvalidInput("mergeIntoCells: a point is not finite");
  if (normals && normals->size() != points.size())
    throw InvalidInput("mergeIntoCells: " + std::to_string(points.size()) + " points but " +
                       std::to_string(normals->size()) + " normals");
  if (!(crease_degrees >= 0) || !(crease_degrees <= 90))
    throw InvalidParameter("crease_degrees", detail::toString(crease_degrees), "in [0, 90]");
  MergedPoints out;
  if (max_points == 0 || points.size() <= max_points) {
    out.points = points;
    out.masses = masses;
    return out;
  }
  bool creases = normals != nullptr && crease_degrees > 0;
  const double cos_crease = std::cos(crease_degrees * M_PI / 180);
  Eigen::Vector3d lo = points[0], hi = points[0];
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double side = std::max((hi - lo).maxCoeff(), 1e-300);
  // The points in cell order (then by index: a total order) and where each cell starts.
  std::vector<int> order(points.size());
  std::vector<std::size_t> starts;
  using Key = std::array<std::int64_t, 3>;
  std::vector<std::pair<Key, int>> keyed;
  // With keys packed into one integer (the grid has fewer than 4e18 cells) a radix sort
  // orders them in linear time; the cells come in the same (x, y, z) order as triples.
  std::vector<std::uint64_t> packed, packed_scratch;
  std::vector<std::pair<std::uint64_t, int>> packed_index, packed_index_scratch;
  const auto sortIntoCells = [&](double cell, bool need_order) {
    const Eigen::Array3d dims = ((hi - lo) / cell).array().floor() + 1;
    starts.clear();
    if (dims.prod() < 4e18) {
      const auto ny = static_cast<std::uint64_t>(dims.y()), nz = static_cast<std::uint64_t>(dims.z());
      const auto keyOf = [&](std::size_t i) {
        const Eigen::Array3d q = ((points[i] - lo) / cell).array().floor().min(dims - 1);
        return (static_cast<std::uint64_t>(q.x()) * ny + static_cast<std::uint64_t>(q.y())) * nz +
               static_cast<std::uint64_t>(q.z());
      };
      if (!need_order) {  // a count only
        packed.resize(points.size());
#pragma omp parallel for schedule(static)
        for (std::int64_t i = 0; i < static_cast<std::int64_t>(points.size()); ++i) packed[i] = keyOf(i);
        sortKeys(packed, &packed_scratch);
        for (std::size_t i = 0; i < packed.size(); ++i)
          if (i == 0 || packed[i] != packed[i - 1]) starts.push_back(i);
        return;
      }
      packed_index.resize(points.size());
#pragma omp parallel for schedule(static)
      for (std::int64_t i = 0; i < static_cast<std::int64_t>(points.size()); ++i)
        packed_index[i] = {keyOf(i), static_cast<int>(i)};
      sortByKey(packed_index, &packed_index_scratch);  // indices in order: ties stay by index
      for (std::size_t i = 0; i < packed_index.size(); ++i) {
        order[i] = packed_index[i].second;
        if (i == 0 || packed_index[i].first != packed_index[i - 1].first) starts.push_back(i);
      }
      return;
    }
    keyed.resize(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d q = (points[i] - lo) / cell;
      keyed[i] = {{static_cast<std::int64_t>(std::floor(q.x())), static_cast<std::int64_t>(std::floor(q.y())),
                   static_cast<std::int64_t>(std::floor(q.z()))},
                  static_cast<int>(i)};
    }
    std::sort(keyed.begin(), keyed.end());
    for (std::size_t i = 0; i < keyed.size(); ++i) {
      order[i] = keyed[i].second;
      if (i == 0 || keyed[i].first != keyed[i - 1].first) starts.push_back(i);
    }
  };
  // The groups of each cell (its points, or its crease splits), as ends into `order`.
  std::vector<char> split_side(creases ? points.size() : 0);  // scratch of splitAtCreases
  std::vector<int*> ends, cell_ends;
  std::vector<int> cell_groups;
  const auto groupsOf = [&](double cell, bool need_order) {
    sortIntoCells(cell, creases || need_order);
    ends.clear();
    const auto cells = static_cast<std::int64_t>(starts.size());
    const auto endOf = [&](std::int64_t c) {
      return order.data() + (c + 1 < cells ? starts[c + 1] : order.size());
    };
    if (!creases) {
      for (std::int64_t c = 0; c < cells; ++c) ends.push_back(endOf(c));
      return ends.size();
    }
    // Cells are split independently (each touches its own points' entries of order and
    // split_side), in parallel; their groups are then listed in cell order.
    constexpr int kMaxGroups = 1 << kCreaseDepth;
    cell_ends.resize(kMaxGroups * starts.size());
    cell_groups.assign(starts.size(), 0);
#pragma omp parallel for schedule(dynamic, 256)
    for (std::int64_t c = 0; c < cells; ++c)
      splitAtCreases(order.data() + starts[c], endOf(c), *normals, masses, cos_crease, 0, split_side,
                     cell_ends.data() + kMaxGroups * c, cell_groups[c]);
    for (std::int64_t c = 0; c < cells; ++c)
      ends.insert(ends.end(), cell_ends.begin() + kMaxGroups * c, cell_ends.begin() + kMaxGroups * c + cell_groups[c]);
    return ends.size();
  };
  // The cell side by bisection on its logarithm: `fine` has too many groups, `coarse` few
  // enough (a cell of the box's side holds at most 8 cells' worth: 2 a dimension).
  double fine = side * 1e-7, coarse = side;
  if (groupsOf(fine, false) <= max_points) coarse = fine;  // only copies of a few positions
  while (coarse > fine && coarse / fine > 1 + 1e-3) {
    const double mid = std::sqrt(fine * coarse);
    (groupsOf(mid, false) <= max_points ? coarse : fine) = mid;
  }
  // At the box's side 8 cells may be too many; one cell split at creases may be too (up to
  // 4 groups): then it stays whole, and the doubling ends.
  while (groupsOf(coarse, false) > max_points) {
    if (starts.size() == 1) creases = false;
    else coarse *= 2;
  }
  groupsOf(coarse, true);
  out.cell = coarse;
  out.crease_points = ends.size() - starts.size();
  const int* first = order.data();
  for (const int* last : ends) {
    double m = 0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const int* i = first; i != last; ++i) {
      m += masses[*i];
      sum += masses[*i] * points[*i];
    }
    const Eigen::Vector3d c = sum / m;
    for (const int* i = first; i != last; ++i) out.spread += masses[*i] * (points[*i] - c).squaredNorm();
    out.points.push_back(c);
    out.masses.push_back(m);
    first = last;
  }
  return out;
}

TriangleMesh transportReconstruct(const Positions& input, const TransportReconstructionParameters& params,
                                  TransportReconstructionReport* report_out, const ProgressCallback& progress) {
  params.validate();
  TransportReconstructionReport report;
  // In spatial order (finite points only): the output does not depend on the input order.
  // Copies of one position (overlapping scans) are one point of their summed mass: the same
  // transport, but the initial subset no longer draws the same position several times
  // (300 points stored 3 times: 4 vertices, or no facet at all, instead of the 10 asked).
  // In spatial order the copies are consecutive.
  std::vector<Eigen::Vector3d> points;
  std::vector<double> masses;
  points.reserve(input.size());
  for (int k : spatialOrderAll(input)) {
    if (!isFinite(input[k])) continue;
    ++report.points;
    const Eigen::Vector3d p = input[k].cast<double>();
    if (!points.empty() && points.back() == p) {
      masses.back() += 1;
      continue;
    }
    points.push_back(p);
    masses.push_back(1);
  }
  if (points.size() < 4)
    throw InvalidInput("transport reconstruction needs at least 4 distinct finite points, got " +
                       std::to_string(points.size()));
  if (params.outlier_neighbours > 0) {
    const std::vector<double> w = outlierWeights(asPositions(points), params.outlier_neighbours);
    for (std::size_t i = 0; i < points.size(); ++i) {
      masses[i] *= w[i];
      report.light_points += w[i] < 1;
      report.outlier_points += w[i] < 0.1;
    }
  }

  // Large inputs are merged into cells: the reconstruction runs on the merged points, the
  // dangling filter below looks at the distinct ones.
  std::vector<Eigen::Vector3d> distinct_points;
  report.transported_points = points.size();
  const std::size_t merge_target = params.mergeTarget();
  report.merge_target = merge_target;
  if (merge_target > 0 && points.size() > merge_target) {
    ProgressReporter merging(progress, "transport merge", 1);  // only when merging: a --timings line
    Normals normals;
    if (params.merge_crease_angle > 0) {
      const Positions distinct = asPositions(points);
      const SpatialIndex index(distinct);
      normals = estimateNormals(distinct, NeighbourGraph::byCount(distinct, index, kMergeNormalNeighbours));
    }
    MergedPoints merged = mergeIntoCells(points, masses, merge_target,
                                         normals.empty() ? nullptr : &normals, params.merge_crease_angle);
    merging.advance();
    merging.throwIfCancelled();
    merging.finish();
    distinct_points = std::move(points);
    points = std::move(merged.points);
    masses = std::move(merged.masses);
    report.transported_points = points.size();
    report.merge_cell = merged.cell;
    report.merge_spread = merged.spread;
    report.crease_points = merged.crease_points;
    if (points.size() < 4)
      throw InvalidInput("transport reconstruction: merging into at most " + std::to_string(merge_target) +
                         " points left " + std::to_string(points.size()) + " (raise max_points)");
  }

  // A volume of points is refused before the costly stages (allow_volume). Measured on the
  // points transported: merged cells average a scan's noise away, not a volume.
  {
    const Positions transported = asPositions(points);
    report.volume_variation = volumeVariation(transported, SpatialIndex(transported));
    if (report.volume_variation > kVolumeVariation && !params.allow_volume)
      throw InvalidInput(
          "transport reconstruction: the points fill a volume, not a surface (median surface variation of "
          "their neighbourhoods " +
          detail::toString(report.volume_variation) + " at the flattest of 32, 128 and 512 neighbours; above " +
          detail::toString(kVolumeVariation) +
          ": surfaces measure below 0.05 at some scale, a uniform volume about 1/3). The method transports "
          "points onto a surface; on a volume it runs far longer (5,000 points in a cube: 258 s, 3,000 of a "
          "scan: 5 s). Set allow_volume (--allow-volume) to run anyway");
  }

  // Initial subset: a seeded shuffle, so the result does not depend on anything else.
  std::vector<int> order(points.size());
  std::iota(order.begin(), order.end(), 0);
  Random rng(params.seed);
  for (std::size_t k = order.size(); k > 1; --k) std::swap(order[k - 1], order[rng.below(k)]);
  const std::size_t subset =
      std::clamp<std::size_t>(static_cast<std::size_t>(std::ceil(params.initial_fraction * points.size())), 4,
                              points.size());
  std::vector<std::pair<Kernel::Point_3, int>> sites;
  for (std::size_t k = 0; k < subset; ++k) {
    const auto& p = points[order[k]];
    sites.emplace_back(Kernel::Point_3(p.x(), p.y(), p.z()), static_cast<int>(k));
  }
  ProgressReporter triangulation(progress, "transport Delaunay", 1);
  Delaunay dt(sites.begin(), sites.end());
  triangulation.advance();
  triangulation.throwIfCancelled();
  triangulation.finish();
  // Points on one plane give a flat triangulation (dimension 2): its triangles are the
  // complex, and everything below holds for them. On a line there is no facet.
  if (dt.dimension() < 2)
    throw InvalidInput("transport reconstruction: the initial points are collinear (dimension " +
                       std::to_string(dt.dimension()) + ")" +
                       (report.merge_cell > 0 ? "; the input was merged into " +
                                                    std::to_string(report.transported_points) + " cells of side " +
                                                    detail::toString(report.merge_cell) +
                                                    ": a larger max_points (--max-points) keeps more of its detail"
                                              : std::string()));

  TransportPlan plan(points, masses, params.transport);
  // Vertex ids by site index and facets in sorted order: CGAL's iteration order depends on
  // its spatial sort, which draws from a process-wide random generator (two runs in one
  // process gave different meshes when ids followed it).
  std::map<int, int> vertex_of_site;
  {
    std::vector<std::pair<int, Eigen::Vector3d>> sorted_sites;
    for (auto v = dt.finite_vertices_begin(); v != dt.finite_vertices_end(); ++v) {
      const auto& p = v->point();
      sorted_sites.emplace_back(v->info(), Eigen::Vector3d(p.x(), p.y(), p.z()));
    }
    std::sort(sorted_sites.begin(), sorted_sites.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [site, p] : sorted_sites) vertex_of_site[site] = plan.addVertex(p);
  }
  std::vector<Triple> dt_facets;
  if (params.initial_complex == InitialComplex::AdvancingFront && dt.dimension() == 3) {
    // CGAL's own Delaunay of the same sites: its facets are a subset of dt's. Indices are
    // the sites' (their order in `sites`), so the result does not depend on CGAL's
    // iteration order.
    std::vector<Kernel::Point_3> site_points;
    for (const auto& site : sites) site_points.push_back(site.first);
    std::vector<std::array<std::size_t, 3>> surface;
    // Its triangulation is built with a spatial sort that draws from CGAL's default random
    // generator (seeded by the clock), and the surface it grows depends on that order: two
    // calls in one process gave different meshes. A fixed seed for the call, then the
    // caller's generator back.
    struct SeededCgal {
      const CGAL::Random callers = CGAL::get_default_random();
      SeededCgal() { CGAL::get_default_random() = CGAL::Random(1); }
      ~SeededCgal() { CGAL::get_default_random() = callers; }
    } seeded;
    CGAL::advancing_front_surface_reconstruction(site_points.begin(), site_points.end(), std::back_inserter(surface),
                                                 TieBrokenPriority());
    report.advancing_front_fallback = surface.empty();
    for (const auto& t : surface)
      dt_facets.push_back(sorted(Triple{vertex_of_site.at(static_cast<int>(t[0])),
                                        vertex_of_site.at(static_cast<int>(t[1])),
                                        vertex_of_site.at(static_cast<int>(t[2]))}));
  }
  if (dt_facets.empty())  // the Delaunay start (or the advancing front's fallback)
    for (auto f = dt.finite_facets_begin(); f != dt.finite_facets_end(); ++f) {
      Triple t;
      int k = 0;
      for (int i = 0; i < 4; ++i)
        if (i != f->second) t[k++] = vertex_of_site.at(f->first->vertex(i)->info());
      dt_facets.push_back(sorted(t));
    }
  std::sort(dt_facets.begin(), dt_facets.end());
  for (const auto& t : dt_facets) plan.addFacet(t[0], t[1], t[2]);
  report.initial_vertices = plan.vertexCount();
  report.initial_facets = plan.facetCount();
  if (report.initial_vertices <= params.target_vertices) {
    // What to change: the fraction, if the points allow it; else the merge or the vertices.
    const std::size_t n = report.transported_points;
    const double fraction = static_cast<double>(params.target_vertices + 1) / static_cast<double>(n);
    std::string how;
    if (fraction <= 1)
      how = "raise initial_fraction (--initial-fraction; now " + detail::toString(params.initial_fraction) + ") to at least " +
            detail::toString(std::ceil(fraction * 1000 - 1e-9) / 1000);
    else if (report.merge_cell > 0)
      how = "the input was merged into " + std::to_string(n) +
            " points: raise max_points (--max-points) or merge_points_per_vertex (--merge-points-per-vertex), or ask "
            "for fewer vertices";
    else
      how = "the input has " + std::to_string(n) + " distinct points: ask for fewer vertices";
    throw InvalidParameter("target_vertices", std::to_string(params.target_vertices),
                           "fewer than the " + std::to_string(report.initial_vertices) +
                               " vertices of the initial triangulation (" + how + ")");
  }

  // Initial plan (5.2.2): nearest vertex, relaxation, then only the facets with mass remain.
  plan.assignToNearestVertices();
  plan.relax(progress);
  // The advancing front's facets are a surface already: all stay (the final density filter
  // still drops those left without mass). Dropping them opened holes: on rs1 (3,000 points,
  // 100 vertices) coverage RMS 7.6 against 5.6 thousandths of the diagonal kept; on a
  // fandisk block 6.2 against 5.2.
  if (params.initial_complex != InitialComplex::AdvancingFront || report.advancing_front_fallback)
    for (int f = 0; f < plan.facetCount(); ++f)
      if (plan.facetAlive(f) && plan.sharesOfFacet(f).empty()) plan.removeFacet(f);
  report.complex_facets = plan.aliveFacetCount();
  report.initial_cost = plan.cost() + report.merge_spread;

  Decimation dec(plan);
  // A vertex left without facets keeps an edge to its nearest Delaunay neighbour if it carries
  // mass (so it can still be collapsed); without mass it goes.
  std::vector<Delaunay::Vertex_handle> by_id(plan.vertexCount());
  for (auto v = dt.finite_vertices_begin(); v != dt.finite_vertices_end(); ++v) by_id[vertex_of_site.at(v->info())] = v;
  for (int id = 0; id < static_cast<int>(by_id.size()); ++id)
    if (plan.facetsOf(id).empty() && plan.sharesOfVertex(id).empty()) plan.removeVertex(id);
  for (int id = 0; id < static_cast<int>(by_id.size()); ++id) {
    if (!plan.vertexAlive(id) || !plan.facetsOf(id).empty()) continue;
    std::vector<Delaunay::Vertex_handle> adj;
    dt.finite_adjacent_vertices(by_id[id], std::back_inserter(adj));
    int best = -1;
    double bd = INFINITY;
    for (auto w : adj) {
      const int wid = vertex_of_site.at(w->info());
      if (!plan.vertexAlive(wid)) continue;  // removed above: no link to it
      const double d = (plan.vertex(wid) - plan.vertex(id)).squaredNorm();
      if (d < bd || (d == bd && wid < best)) { bd = d; best = wid; }
    }
    if (best >= 0) dec.link(id, best);
  }

  // Decimation (5.2.3) with relocation (5.2.4).
  struct Cached {
    Decimation::Collapse collapse;
    std::uint64_t step;  // the decimation's step when simulated
  };
  std::map<std::pair<int, int>, Cached> cache;
  std::size_t swept_size = 0;  // the cache's size after its last sweep
  const int start = plan.aliveVertexCount();
  ProgressReporter rep(progress, "transport decimation", static_cast<std::size_t>(std::max(1, start - params.target_vertices)));
  int fruitless_draws = 0;  // in a row: every drawn collapse refused (or its program failed)
  while (plan.aliveVertexCount() > params.target_vertices) {
    const std::int64_t half_edges = dec.halfEdgeCount();
    if (half_edges == 0) break;
    std::vector<std::pair<int, int>> candidates;
    const bool exhaustive = params.candidates == 0 || params.candidates >= half_edges;
    if (exhaustive) {
      for (int u = 0; u < plan.vertexCount(); ++u)
        for (int v : dec.neighbours(u)) candidates.emplace_back(u, v);
    } else {
      for (int k = 0; k < params.candidates; ++k)
        candidates.push_back(dec.halfEdge(static_cast<std::int64_t>(rng.below(static_cast<std::uint64_t>(half_edges)))));
      std::sort(candidates.begin(), candidates.end());
      candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
    }
    // The simulations are kept: the chosen one is applied as simulated (its plan and bins).
    // Those of unchanged stencils come from the cache; the others are run in parallel.
    std::vector<Decimation::Collapse> simulated(candidates.size());
    std::vector<std::int64_t> missing;
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      const auto hit = cache.find(candidates[k]);
      if (params.reuse_simulations && hit != cache.end() && dec.unchangedSince(hit->second.collapse.before, hit->second.step)) {
        simulated[k] = hit->second.collapse;
        ++report.reused_simulations;
      } else
        missing.push_back(static_cast<std::int64_t>(k));
    }
    // Branch and bound: the others are prepared (with a lower bound of their cost change) in
    // parallel, then simulated in order of that bound, four at a time, until the next bound
    // exceeds the best change found. Those skipped cannot beat it, so the collapse chosen is
    // the one simulating them all would choose (rs1, 3,000 points to 100 vertices: 1,735 of
    // 17,004 programs). The margin (1e-6 of the costs, above the programs' tolerances) leaves
    // near ties, which round-off could misorder, to their programs. Batches of fixed size:
    // the programs run do not depend on the thread count.
    const std::int64_t nm = static_cast<std::int64_t>(missing.size());
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t j = 0; j < nm; ++j)
      simulated[missing[j]] = dec.prepare(candidates[missing[j]].first, candidates[missing[j]].second);
    std::stable_sort(missing.begin(), missing.end(),
                     [&](std::int64_t a, std::int64_t b) { return simulated[a].lower_bound < simulated[b].lower_bound; });
    double best_delta = INFINITY;  // of the reused simulations
    std::vector<char> is_missing(simulated.size(), 0);
    for (std::int64_t k : missing) is_missing[static_cast<std::size_t>(k)] = 1;
    for (std::size_t k = 0; k < simulated.size(); ++k)
      if (!is_missing[k]) best_delta = std::min(best_delta, simulated[k].delta);
    constexpr std::int64_t kBatch = 4;
    std::vector<std::int64_t> run;
    for (std::int64_t first = 0; first < nm; first += kBatch) {
      const auto beaten = [&](const Decimation::Collapse& c) {
        return c.lower_bound - best_delta > 1e-6 * (std::abs(best_delta) + c.before.cost);
      };
      if (params.bound_simulations && std::isfinite(best_delta) && beaten(simulated[missing[first]])) break;
      const std::int64_t last = std::min(nm, first + kBatch);
      std::vector<std::int64_t> batch;
      for (std::int64_t j = first; j < last; ++j)
        if (!params.bound_simulations || !std::isfinite(best_delta) || !beaten(simulated[missing[j]]))
          batch.push_back(missing[j]);
      const std::int64_t nb = static_cast<std::int64_t>(batch.size());
      // Past the first batch, a program is solved only if its dual bound (which sees the
      // facets' uniform measure) does not already show it cannot beat the best change found.
      const bool tighten = params.bound_simulations && params.dual_bound && std::isfinite(best_delta);
      std::vector<char> ran(static_cast<std::size_t>(nb), 1);
#pragma omp parallel for schedule(dynamic, 1)
      for (std::int64_t j = 0; j < nb; ++j) {
        Decimation::Collapse& c = simulated[batch[j]];
        if (c.turns_facet) { ran[j] = 0; continue; }
        if (tighten) {
          const double margin = 1e-6 * (std::abs(best_delta) + c.before.cost);
          c.lower_bound = std::max(c.lower_bound, dec.dualBound(c, c.before.cost + best_delta + 2 * margin) - c.before.cost);
          if (beaten(c)) { ran[j] = 0; continue; }
        }
        dec.simulate(c);
      }
      for (std::int64_t j = 0; j < nb; ++j) {
        if (!ran[j]) continue;
        best_delta = std::min(best_delta, simulated[batch[j]].delta);
        run.push_back(batch[j]);
      }
    }
    int refused = 0;
    for (std::int64_t k : missing) refused += simulated[k].turns_facet ? 1 : 0;
    report.refused_collapses += refused;
    report.simulations += static_cast<int>(run.size());
    report.bounded_simulations += static_cast<int>(nm - static_cast<std::int64_t>(run.size())) - refused;
    if (params.reuse_simulations)
      for (std::int64_t k : run) cache[candidates[k]] = {simulated[k], dec.step()};
    std::size_t best = 0;
    for (std::size_t k = 1; k < simulated.size(); ++k)
      if (simulated[k].delta < simulated[best].delta) best = k;  // ties: the first in (u, v) order
    if (!std::isfinite(simulated[best].delta)) {
      // Every drawn collapse was refused or failed: draw again (the draws are random), up to
      // 100 times in a row; after an exhaustive step no other collapse is left.
      if (exhaustive || ++fruitless_draws > 100) break;
      if (rep.cancelled()) break;
      continue;
    }
    fruitless_draws = 0;
    const Decimation::Collapse collapse = std::move(simulated[best]);
    dec.apply(collapse);
    ++report.collapses;
    for (int it = 0; it < params.relocation_iterations; ++it) plan.relocate(collapse.v);
    if (params.relocation_iterations > 0) dec.touchAround(collapse.v);
    // Drop what has gone stale (a collapsed vertex is in its collapse's stencil, so this also
    // drops its half-edges), once the cache has doubled since the last sweep: a sweep every
    // step cost O(cache) a step, and a stale entry is never used (lookups check).
    if (cache.size() > 2 * swept_size + 64) {
      for (auto it = cache.begin(); it != cache.end();)
        it = dec.unchangedSince(it->second.collapse.before, it->second.step) ? std::next(it) : cache.erase(it);
      swept_size = cache.size();
    }
    rep.advance();
    if (rep.cancelled()) break;
  }
  rep.throwIfCancelled();
  rep.finish();
  // The final stages get their own progress (and --timings lines): with few vertices left, each
  // relocation re-solves a program over hundreds of points.
  {
    ProgressReporter sweeps(progress, "transport relocation",
                            static_cast<std::size_t>(std::max(1, params.final_relocation_sweeps)));
    for (int sweep = 0; sweep < params.final_relocation_sweeps; ++sweep) {
      plan.relocateAll();
      sweeps.advance();
      sweeps.throwIfCancelled();
    }
    sweeps.finish();
    sweeps.throwIfCancelled();
  }
  if (params.deletion_threshold > 0) {
    ProgressReporter deletion(progress, "transport facet deletion", 1);
    report.deleted_facets = plan.deleteRedundantFacets(params.deletion_threshold);
    deletion.advance();
    deletion.finish();
    deletion.throwIfCancelled();
  }
  if (params.stacked_threshold > 0) {
    ProgressReporter deletion(progress, "transport stacked facets", 1);
    report.stacked_facets = plan.deleteStackedFacets(params.stacked_threshold, params.stacked_reach);
    deletion.advance();
    deletion.finish();
    deletion.throwIfCancelled();
  }
  report.final_cost = plan.cost() + report.merge_spread;
  report.rms_transport = std::sqrt(report.final_cost / plan.totalMass());

  // Post-processing (5.2.5): facets of low mass density go.
  const double mean_density = plan.meanFacetDensity();
  std::vector<char> kept(plan.facetCount(), 0);
  for (int f = 0; f < plan.facetCount(); ++f) {
    if (!plan.facetAlive(f)) continue;
    const double a = plan.facetArea(f), m = plan.massOnFacet(f);
    kept[f] = m > 0 && a > 0 && m / a >= params.density_threshold * mean_density;
  }
  report.restored_facets = restoreEnclosedFacets(plan, mean_density, kept);
  TriangleMesh out;
  std::vector<int> index(plan.vertexCount(), -1);
  for (int f = 0; f < plan.facetCount(); ++f) {
    if (!kept[f]) continue;
    Eigen::Vector3i t;
    for (int k = 0; k < 3; ++k) {
      int& id = index[plan.facet(f)[k]];
      if (id < 0) {
        id = static_cast<int>(out.vertices.size());
        out.vertices.push_back(plan.vertex(plan.facet(f)[k]).cast<float>());
      }
      t[k] = id;
    }
    out.triangles.push_back(t);
  }
  if (params.dangling_support > 0 && !out.triangles.empty()) {
    const Positions finite = asPositions(distinct_points.empty() ? points : distinct_points);  // the input's distinct points
    const SpatialIndex index(finite);  // one index for the spacing and the support searches
    const double spacing = meanNearestNeighbourDistance(finite, index);
    if (spacing > 0)
      report.dangling_facets = dropDanglingFacets(out, index, static_cast<float>(params.dangling_support * spacing));
  }
  report.output_vertices = static_cast<int>(out.vertices.size());
  report.output_facets = static_cast<int>(out.triangles.size());
  if (report_out) *report_out = report;
  // An empty mesh is no answer (the PCL stage would hand it on as one).
  if (out.triangles.empty())
    throw InvalidInput("transport reconstruction kept no facet (lower the density threshold or ask for more vertices)");
  return out;
}

template class TransportReconstruction<pcl::PointXYZ>;
template class TransportReconstruction<pcl::PointNormal>;
template class TransportReconstruction<pcl::PointXYZRGBNormal>;

}  // namespace paps
