#include <paps/core/metrics.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <utility>

#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/spatial_order.h>

namespace paps {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace

ErrorStats summarize(std::vector<double> values) {
  values.erase(std::remove_if(values.begin(), values.end(),
                              [](double v) { return !std::isfinite(v); }),
               values.end());
  ErrorStats s;
  s.count = values.size();
  if (values.empty()) return s;
  std::sort(values.begin(), values.end());
  // Sum the sorted values: smallest first keeps the rounding error low and the result
  // independent of the input order.
  double sum = 0, sum2 = 0;
  for (double v : values) {
    sum += v;
    sum2 += v * v;
  }
  const double n = static_cast<double>(values.size());
  s.mean = sum / n;
  s.rmse = std::sqrt(sum2 / n);
  s.max = values.back();
  // 95th percentile by linear interpolation between order statistics (numpy's default).
  const double pos = 0.95 * (n - 1);
  const std::size_t lo = static_cast<std::size_t>(std::floor(pos));
  const std::size_t hi = std::min(lo + 1, values.size() - 1);
  s.p95 = values[lo] + (pos - static_cast<double>(lo)) * (values[hi] - values[lo]);
  return s;
}

// ---------------------------------------------------------------------------------------
// Point to mesh distance: a bounding volume hierarchy over the triangles.

namespace {

/// Closest point of segment [a, b] to p.
Eigen::Vector3d closestOnSegment(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                 const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double len2 = ab.squaredNorm();
  if (len2 <= 0) return a;
  const double t = std::clamp((p - a).dot(ab) / len2, 0.0, 1.0);
  return a + t * ab;
}

/// Exact closest point of triangle (a, b, c) to p. The plane of the triangle is split into
/// the Voronoi regions of its vertices, edges and face; the tests below find the region
/// holding p from dot products only, so no projection is computed that is not used.
Eigen::Vector3d closestOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                  const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a;
  if (ab.cross(ac).squaredNorm() == 0) {
    // Degenerate (segment or point): the region tests would divide by zero.
    const Eigen::Vector3d q1 = closestOnSegment(p, a, b), q2 = closestOnSegment(p, b, c),
                          q3 = closestOnSegment(p, c, a);
    const double d1 = (p - q1).squaredNorm(), d2 = (p - q2).squaredNorm(),
                 d3 = (p - q3).squaredNorm();
    if (d1 <= d2 && d1 <= d3) return q1;
    return d2 <= d3 ? q2 : q3;
  }
  const Eigen::Vector3d ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;  // vertex a

  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;  // vertex b

  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;  // edge ab

  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;  // vertex c

  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;  // edge ac

  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0)  // edge bc
    return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);

  // Inside the face: barycentric coordinates from the signed sub-areas.
  const double inv = 1.0 / (va + vb + vc);
  return a + (vb * inv) * ab + (vc * inv) * ac;
}

/// Squared distance from p to an axis-aligned box (0 inside).
inline float boxDistance2(const Eigen::Vector3f& p, const Eigen::Vector3f& lo,
                          const Eigen::Vector3f& hi) {
  const Eigen::Vector3f d = (lo - p).cwiseMax(p - hi).cwiseMax(0.f);
  return d.squaredNorm();
}

// The float box distance may overestimate the exact one by a few ulps; shrinking it by
// this factor keeps pruning conservative, so the result is exactly the brute-force one.
constexpr float kBoxShrink = 1.f - 1e-5f;

}  // namespace

struct PointToMeshDistance::Impl {
  struct Node {
    Eigen::Vector3f lo, hi;
    // Leaf: triangles [first, first + count). Inner node (count == 0): left child is the
    // next node, right child is `first`.
    int first = 0;
    int count = 0;
  };
  struct Triangle {
    Eigen::Vector3f a, b, c;
    int index;  // index in the input mesh
  };
  static constexpr int kLeafSize = 4;

  std::vector<Node> nodes;
  std::vector<Triangle> tris;  // in leaf order, so a leaf reads contiguous memory

  void build(const TriangleMesh& mesh) {
    const int nv = static_cast<int>(mesh.vertices.size());
    tris.reserve(mesh.triangles.size());
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      const Eigen::Vector3i& f = mesh.triangles[t];
      for (int k = 0; k < 3; ++k)
        if (f[k] < 0 || f[k] >= nv)
          throw InvalidInput("triangle " + std::to_string(t) + " refers to vertex " +
                             std::to_string(f[k]) + " but the mesh has " + std::to_string(nv) +
                             " vertices");
      const Triangle tri{mesh.vertices[f[0]], mesh.vertices[f[1]], mesh.vertices[f[2]],
                         static_cast<int>(t)};
      // A triangle with a NaN corner has no closest point; leave it out.
      if (isFinite(tri.a) && isFinite(tri.b) && isFinite(tri.c)) tris.push_back(tri);
    }
    if (tris.empty()) throw InvalidInput("the mesh has no triangle with finite vertices");

    std::vector<Eigen::Vector3f> centroids(tris.size());
    for (std::size_t i = 0; i < tris.size(); ++i)
      centroids[i] = (tris[i].a + tris[i].b + tris[i].c) / 3.f;
    std::vector<int> order(tris.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
    nodes.reserve(2 * tris.size() / kLeafSize + 2);
    buildNode(order, centroids, 0, static_cast<int>(order.size()));

    std::vector<Triangle> sorted(tris.size());
    for (std::size_t i = 0; i < order.size(); ++i) sorted[i] = tris[order[i]];
    tris.swap(sorted);
  }

  int buildNode(std::vector<int>& order, const std::vector<Eigen::Vector3f>& centroids,
                int begin, int end) {
    const int id = static_cast<int>(nodes.size());
    nodes.emplace_back();
    Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
    Eigen::Vector3f clo = lo, chi = hi;
    for (int i = begin; i < end; ++i) {
      const Triangle& t = tris[order[i]];
      lo = lo.cwiseMin(t.a).cwiseMin(t.b).cwiseMin(t.c);
      hi = hi.cwiseMax(t.a).cwiseMax(t.b).cwiseMax(t.c);
      clo = clo.cwiseMin(centroids[order[i]]);
      chi = chi.cwiseMax(centroids[order[i]]);
    }
    nodes[id].lo = lo;
    nodes[id].hi = hi;
    if (end - begin <= kLeafSize) {
      nodes[id].first = begin;
      nodes[id].count = end - begin;
      return id;
    }
    // Median split of the centroids along their widest axis: balanced depth, and cheap.
    int axis = 0;
    (chi - clo).maxCoeff(&axis);
    const int mid = begin + (end - begin) / 2;
    std::nth_element(order.begin() + begin, order.begin() + mid, order.begin() + end,
                     [&](int x, int y) { return centroids[x][axis] < centroids[y][axis]; });
    buildNode(order, centroids, begin, mid);  // left child is id + 1
    const int right = buildNode(order, centroids, mid, end);
    nodes[id].first = right;
    nodes[id].count = 0;
    return id;
  }

  double query(const Eigen::Vector3f& pf, Eigen::Vector3f* closest, int* triangle) const {
    const Eigen::Vector3d p = pf.cast<double>();
    double best2 = INFINITY;
    Eigen::Vector3d best_point = Eigen::Vector3d::Zero();
    int best_tri = -1;

    // Depth-first, nearer child first, subtrees pruned by their box distance. The stack
    // keeps the box distance so a subtree is re-checked against the best found meanwhile.
    struct Entry {
      int node;
      float d2;
    };
    Entry stack[96];  // depth is about log2(n / kLeafSize), far below this
    int top = 0;
    stack[top++] = {0, boxDistance2(pf, nodes[0].lo, nodes[0].hi) * kBoxShrink};
    while (top > 0) {
      const Entry e = stack[--top];
      if (e.d2 > best2) continue;
      int n = e.node;
      while (true) {
        const Node& node = nodes[n];
        if (node.count > 0) {
          for (int i = node.first; i < node.first + node.count; ++i) {
            const Triangle& t = tris[i];
            const Eigen::Vector3d q =
                closestOnTriangle(p, t.a.cast<double>(), t.b.cast<double>(), t.c.cast<double>());
            const double d2 = (q - p).squaredNorm();
            // Ties go to the lower input index so the answer does not depend on the tree.
            if (d2 < best2 || (d2 == best2 && t.index < best_tri)) {
              best2 = d2;
              best_point = q;
              best_tri = t.index;
            }
          }
          break;
        }
        const int l = n + 1, r = node.first;
        const float dl = boxDistance2(pf, nodes[l].lo, nodes[l].hi) * kBoxShrink;
        const float dr = boxDistance2(pf, nodes[r].lo, nodes[r].hi) * kBoxShrink;
        const int near = dl <= dr ? l : r, far = dl <= dr ? r : l;
        const float dnear = std::min(dl, dr), dfar = std::max(dl, dr);
        // `<=` keeps subtrees that could hold an equally close triangle (tie rule above).
        if (dfar <= best2) stack[top++] = {far, dfar};
        if (dnear > best2) break;
        n = near;
      }
    }
    if (closest) *closest = best_point.cast<float>();
    if (triangle) *triangle = best_tri;
    return std::sqrt(best2);
  }
};

PointToMeshDistance::PointToMeshDistance(const TriangleMesh& mesh) : impl_(new Impl) {
  impl_->build(mesh);
}

PointToMeshDistance::~PointToMeshDistance() = default;

double PointToMeshDistance::distance(const Eigen::Vector3f& p, Eigen::Vector3f* closest,
                                     int* triangle) const {
  if (!isFinite(p)) {
    if (closest) closest->setConstant(NAN);
    if (triangle) *triangle = -1;
    return kNaN;
  }
  return impl_->query(p, closest, triangle);
}


std::vector<double> PointToMeshDistance::distances(const Positions& points) const {
  std::vector<double> out(points.size(), kNaN);
  // Neighbouring queries walk the same nodes and triangles: visiting them in Z order keeps
  // those in cache and is about twice as fast as the input order of a shuffled cloud. Each
  // query writes only its own slot, so the result does not depend on order or threads.
  const std::vector<int> order = spatialOrder(points);
  const long n = static_cast<long>(order.size());
#pragma omp parallel for schedule(dynamic, 1024)
  for (long k = 0; k < n; ++k) out[order[k]] = impl_->query(points[order[k]], nullptr, nullptr);
  return out;
}

ErrorStats pointToMeshError(const Positions& points, const PointToMeshDistance& mesh) {
  return summarize(mesh.distances(points));
}

// ---------------------------------------------------------------------------------------
// Cloud to cloud (D1).

namespace {

/// Squared distance from every finite point of `query` to its nearest neighbour in `tree`.
std::vector<double> nearestSquaredDistances(const Positions& query, const SpatialIndex& tree) {
  std::vector<double> d2(query.size(), kNaN);
  const long n = static_cast<long>(query.size());
#pragma omp parallel
  {
    std::vector<int> index;
    std::vector<float> dist;
#pragma omp for schedule(dynamic, 1024)
    for (long i = 0; i < n; ++i)
      if (isFinite(query[i]) && tree.nearestK(query[i], 1, index, dist) == 1) d2[i] = dist[0];
  }
  return d2;
}

/// The index of the finite points of `p`; InvalidInput naming the cloud when there are none.
std::unique_ptr<SpatialIndex> finiteIndex(const Positions& p, const char* name) {
  auto index = std::make_unique<SpatialIndex>(p);
  if (index->size() == 0)
    throw InvalidInput(std::string("cloud '") + name + "' has no finite point (" +
                       std::to_string(p.size()) + " points)");
  return index;
}

/// Mean squared nearest-neighbour distance from the finite points of `from` to `to`.
double oneSidedMse(const Positions& from, const SpatialIndex& to) {
  const std::vector<double> d2 = nearestSquaredDistances(from, to);
  double sum = 0;
  std::size_t n = 0;
  for (double v : d2)  // serial sum: same result for any thread count
    if (std::isfinite(v)) {
      sum += v;
      ++n;
    }
  return n ? sum / static_cast<double>(n) : 0.0;
}

double symmetricMse(const Positions& a, const Positions& b) {
  const auto tree_a = finiteIndex(a, "a");
  const auto tree_b = finiteIndex(b, "b");
  return std::max(oneSidedMse(a, *tree_b), oneSidedMse(b, *tree_a));
}

}  // namespace

double symmetricNearestNeighbourRmse(const Positions& a, const Positions& b) {
  return std::sqrt(symmetricMse(a, b));
}

double d1Psnr(const Positions& test, const Positions& reference, double peak) {
  if (peak < 0 || !std::isfinite(peak))
    throw InvalidParameter("peak", detail::toString(peak), "0 (automatic) or a finite value > 0");
  if (peak == 0) peak = boundingBoxDiagonal(reference);
  if (!(peak > 0))
    throw InvalidInput("the reference cloud has a zero bounding box, so the PSNR peak is 0");
  const double mse = symmetricMse(test, reference);
  if (mse == 0) return INFINITY;
  return 10.0 * std::log10(peak * peak / mse);
}

std::vector<double> normalAngleErrors(const Normals& estimated, const Normals& truth,
                                      bool unoriented) {
  if (estimated.size() != truth.size())
    throw InvalidInput("normal counts differ: " + std::to_string(estimated.size()) +
                       " estimated vs " + std::to_string(truth.size()) + " true");
  std::vector<double> out(estimated.size(), kNaN);
  constexpr double kDegrees = 180.0 / 3.14159265358979323846;
  for (std::size_t i = 0; i < estimated.size(); ++i) {
    if (!isFinite(estimated[i]) || !isFinite(truth[i])) continue;
    const Eigen::Vector3d a = estimated[i].cast<double>(), b = truth[i].cast<double>();
    if (a.squaredNorm() == 0 || b.squaredNorm() == 0) continue;  // no direction, no angle
    // atan2 of |cross| and dot is accurate at small angles, where acos is not, and needs
    // no normalisation.
    double dot = a.dot(b);
    if (unoriented) dot = std::abs(dot);
    out[i] = std::atan2(a.cross(b).norm(), dot) * kDegrees;
  }
  return out;
}

}  // namespace paps
