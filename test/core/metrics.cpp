// Tests of paps/core/metrics.h and paps/core/triangle_mesh.h on shapes with known answers.
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>

#include <unistd.h>

#include <gtest/gtest.h>
#include <pcl/PolygonMesh.h>
#include <pcl/conversions.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/metrics.h>
#include <paps/core/random.h>
#include <paps/core/synthetic.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_metrics_test {

using paps::Positions;
using paps::TriangleMesh;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// The square [-1, 1]^2 at z = 0 as two triangles.
TriangleMesh unitSquare() {
  TriangleMesh m;
  m.vertices = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

/// Reference distance from p to triangle (a, b, c), computed differently from the library:
/// inside the prism over the triangle it is the plane distance, otherwise the nearest edge.
double referenceDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                         const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  auto segment = [&](const Eigen::Vector3d& s, const Eigen::Vector3d& e) {
    const double t = std::clamp((p - s).dot(e - s) / (e - s).squaredNorm(), 0.0, 1.0);
    return (p - (s + t * (e - s))).norm();
  };
  const Eigen::Vector3d n = (b - a).cross(c - a);
  const Eigen::Vector3d q = p - n * (p - a).dot(n) / n.squaredNorm();  // projection
  const bool inside = (b - a).cross(q - a).dot(n) >= 0 && (c - b).cross(q - b).dot(n) >= 0 &&
                      (a - c).cross(q - c).dot(n) >= 0;
  if (inside) return (p - q).norm();
  return std::min({segment(a, b), segment(b, c), segment(c, a)});
}

double referenceMeshDistance(const TriangleMesh& m, const Eigen::Vector3f& p, int* best_tri) {
  double best = INFINITY;
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    const auto& f = m.triangles[t];
    const double d = referenceDistance(p.cast<double>(), m.vertices[f[0]].cast<double>(),
                                       m.vertices[f[1]].cast<double>(),
                                       m.vertices[f[2]].cast<double>());
    if (d < best) {
      best = d;
      *best_tri = static_cast<int>(t);
    }
  }
  return best;
}

/// A soup of random small triangles in the unit cube.
TriangleMesh randomSoup(int count, std::uint64_t seed) {
  paps::Random rng(seed);
  TriangleMesh m;
  for (int t = 0; t < count; ++t) {
    const Eigen::Vector3f centre = rng.uniform3(0, 1).cast<float>();
    for (int k = 0; k < 3; ++k)
      m.vertices.push_back(centre + 0.1f * rng.uniform3(-1, 1).cast<float>());
    m.triangles.emplace_back(3 * t, 3 * t + 1, 3 * t + 2);
  }
  return m;
}

/// A regular grid of n^3 points with the given spacing.
Positions grid(int n, float spacing) {
  Positions p;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) p.emplace_back(spacing * i, spacing * j, spacing * k);
  return p;
}

// ------------------------------------------------------------------------------ summarize

TEST(Summarize, KnownValues) {
  const paps::ErrorStats s = paps::summarize({3, 4});
  EXPECT_EQ(s.count, 2u);
  EXPECT_DOUBLE_EQ(s.rmse, std::sqrt(12.5));
  EXPECT_DOUBLE_EQ(s.mean, 3.5);
  EXPECT_DOUBLE_EQ(s.max, 4);
  EXPECT_DOUBLE_EQ(s.p95, 3.95);  // linear interpolation between the order statistics
}

TEST(Summarize, PercentileOfARange) {
  std::vector<double> v;
  for (int i = 100; i >= 0; --i) v.push_back(i);  // order must not matter
  const paps::ErrorStats s = paps::summarize(v);
  EXPECT_EQ(s.count, 101u);
  EXPECT_DOUBLE_EQ(s.p95, 95);
  EXPECT_DOUBLE_EQ(s.mean, 50);
  EXPECT_DOUBLE_EQ(s.max, 100);
}

TEST(Summarize, SkipsNonFiniteAndHandlesEmpty) {
  const paps::ErrorStats s = paps::summarize({kNaN, 2, INFINITY, 2});
  EXPECT_EQ(s.count, 2u);
  EXPECT_DOUBLE_EQ(s.rmse, 2);
  const paps::ErrorStats e = paps::summarize({kNaN});
  EXPECT_EQ(e.count, 0u);
  EXPECT_EQ(e.rmse, 0);
}

// --------------------------------------------------------------------- point to mesh

TEST(PointToMeshDistance, OffsetsAboveAPlane) {
  const paps::PointToMeshDistance d(unitSquare());
  for (float h : {0.f, 0.01f, -0.25f, 3.f}) {
    const Eigen::Vector3f p(0.3f, -0.7f, h);
    Eigen::Vector3f q;
    int tri = -2;
    EXPECT_NEAR(d.distance(p, &q, &tri), std::abs(h), 1e-7) << "h = " << h;
    EXPECT_TRUE(q.isApprox(Eigen::Vector3f(0.3f, -0.7f, 0.f), 1e-6f));
    EXPECT_EQ(tri, 0);  // (0.3, -0.7) is in triangle 0 (below the diagonal y = x)
  }
  // Beside the square the closest point is on its border.
  EXPECT_NEAR(d.distance(Eigen::Vector3f(3, 0, 0)), 2.0, 1e-7);
  EXPECT_NEAR(d.distance(Eigen::Vector3f(2, 2, 1)), std::sqrt(3.0), 1e-6);
}

TEST(PointToMeshDistance, ErrorOfAnOffsetCloud) {
  const paps::PointToMeshDistance d(unitSquare());
  Positions p;
  paps::Random rng(3);
  for (int i = 0; i < 1000; ++i) {
    const double y = rng.uniform(-1, 1);
    p.emplace_back(rng.uniform(-1, 1), y, i % 2 ? 0.05f : -0.05f);
  }
  p.emplace_back(NAN, 0.f, 0.f);
  const paps::ErrorStats s = paps::pointToMeshError(p, d);
  EXPECT_EQ(s.count, 1000u);
  EXPECT_NEAR(s.rmse, 0.05, 1e-7);
  EXPECT_NEAR(s.mean, 0.05, 1e-7);
  EXPECT_NEAR(s.max, 0.05, 1e-7);
}

TEST(PointToMeshDistance, BvhEqualsBruteForce) {
  const TriangleMesh m = randomSoup(1500, 11);
  const paps::PointToMeshDistance d(m);
  paps::Random rng(12);
  for (int i = 0; i < 400; ++i) {
    // Queries inside, near and well outside the soup.
    const float spread = i < 300 ? 1.2f : 4.f;
    const Eigen::Vector3f p = rng.uniform3(-spread, spread).cast<float>();
    Eigen::Vector3f q;
    int tri = -1;
    const double got = d.distance(p, &q, &tri);
    int ref_tri = -1;
    const double want = referenceMeshDistance(m, p, &ref_tri);
    ASSERT_NEAR(got, want, 1e-6 * (1 + want)) << "query " << i;
    ASSERT_GE(tri, 0);
    // The reported triangle and closest point are consistent with the distance.
    const auto& f = m.triangles[tri];
    EXPECT_NEAR(referenceDistance(p.cast<double>(), m.vertices[f[0]].cast<double>(),
                                  m.vertices[f[1]].cast<double>(), m.vertices[f[2]].cast<double>()),
                got, 1e-6 * (1 + want));
    EXPECT_NEAR((p - q).norm(), got, 1e-5 * (1 + want));
  }
}

TEST(PointToMeshDistance, DegenerateTriangles) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {5, 5, 5}};
  m.triangles = {{0, 1, 2}, {3, 3, 3}};  // a segment and a point
  const paps::PointToMeshDistance d(m);
  EXPECT_NEAR(d.distance(Eigen::Vector3f(1.5f, 2.f, 0.f)), 2.0, 1e-7);
  EXPECT_NEAR(d.distance(Eigen::Vector3f(3.f, 0.f, 0.f)), 1.0, 1e-7);
  EXPECT_NEAR(d.distance(Eigen::Vector3f(5.f, 5.f, 6.f)), 1.0, 1e-7);
}

TEST(PointToMeshDistance, SampledPointsLieOnTheMesh) {
  const TriangleMesh m = paps::synthetic::fandiskBlock(40);
  const paps::PointToMeshDistance d(m);
  Positions p = paps::synthetic::sampleMesh(m, 20000, 5);
  p[17] = Eigen::Vector3f(NAN, NAN, NAN);
  const std::vector<double> dist = d.distances(p);
  ASSERT_EQ(dist.size(), p.size());
  EXPECT_TRUE(std::isnan(dist[17]));
  const double diag = m.boundingBoxDiagonal();
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (i == 17) continue;
    ASSERT_LT(dist[i], 1e-5 * diag) << "sample " << i;
    ASSERT_EQ(dist[i], d.distance(p[i]));  // the parallel path gives the serial answer
  }
}

TEST(PointToMeshDistance, RejectsBadMeshes) {
  EXPECT_THROW(paps::PointToMeshDistance(TriangleMesh{}), paps::InvalidInput);
  TriangleMesh m = unitSquare();
  m.triangles.emplace_back(0, 1, 7);
  EXPECT_THROW(paps::PointToMeshDistance{m}, paps::InvalidInput);
}

// ---------------------------------------------------------------------------------- D1

TEST(D1, CloudToItselfIsZero) {
  const Positions a = grid(6, 0.1f);
  EXPECT_EQ(paps::symmetricNearestNeighbourRmse(a, a), 0);
  EXPECT_TRUE(std::isinf(paps::d1Psnr(a, a)));
}

TEST(D1, TranslatedCopyErrorIsTheTranslation) {
  // Every lattice vector v != 0 has |v - t| >= h - |t| > |t| when |t| < h / 2, so every
  // point's nearest neighbour in the other cloud is its own translated copy.
  const float h = 0.1f;
  const Positions a = grid(8, h);
  const Eigen::Vector3f t = 0.3f * h * Eigen::Vector3f(1, 2, -2).normalized();
  Positions b = a;
  for (auto& p : b) p += t;
  EXPECT_NEAR(paps::symmetricNearestNeighbourRmse(a, b), t.norm(), 1e-6);
  EXPECT_NEAR(paps::symmetricNearestNeighbourRmse(b, a), t.norm(), 1e-6);
  const double peak = 2.0;
  EXPECT_NEAR(paps::d1Psnr(b, a, peak), 10 * std::log10(peak * peak / t.squaredNorm()), 1e-3);
  // Default peak: the reference's bounding-box diagonal, 7 h sqrt(3).
  const double diag = 7 * h * std::sqrt(3.0);
  EXPECT_NEAR(paps::d1Psnr(b, a), 10 * std::log10(diag * diag / t.squaredNorm()), 1e-3);
}

TEST(D1, SymmetricTakesTheWorseSideAndSkipsNaN) {
  // b = a plus one far point: a -> b is 0, b -> a is D^2 / (n + 1) in the mean.
  const Positions a = grid(5, 0.1f);
  Positions b = a;
  const float far = 3.f;
  b.emplace_back(0.4f + far, 0.4f, 0.4f);  // nearest in a: the corner (0.4, 0.4, 0.4)
  b.emplace_back(NAN, 0.f, 0.f);
  const double want = far / std::sqrt(static_cast<double>(a.size() + 1));
  EXPECT_NEAR(paps::symmetricNearestNeighbourRmse(a, b), want, 1e-6);
  EXPECT_NEAR(paps::symmetricNearestNeighbourRmse(b, a), want, 1e-6);
}

TEST(D1, AllNaNCloudThrows) {
  const Positions a = grid(3, 1.f);
  const Positions nan(4, Eigen::Vector3f::Constant(NAN));
  EXPECT_THROW(paps::symmetricNearestNeighbourRmse(a, nan), paps::InvalidInput);
  EXPECT_THROW(paps::d1Psnr(a, a, -1.0), paps::InvalidParameter);
}

// ------------------------------------------------------------------------- normals

TEST(NormalAngleErrors, KnownAngles) {
  const paps::Normals est = {{1, 0, 0}, {-1, 0, 0}, {1, 1, 0}, {0, 0, 0}, {0, 0, 2}};
  const paps::Normals truth = {{0, 1, 0}, {1, 0, 0}, {1, 0, 0}, {1, 0, 0}, {0, 0, 1}};
  const auto un = paps::normalAngleErrors(est, truth);
  EXPECT_NEAR(un[0], 90, 1e-9);
  EXPECT_NEAR(un[1], 0, 1e-9);
  EXPECT_NEAR(un[2], 45, 1e-9);
  EXPECT_TRUE(std::isnan(un[3]));  // no direction, no angle
  EXPECT_NEAR(un[4], 0, 1e-9);     // lengths do not matter
  const auto oriented = paps::normalAngleErrors(est, truth, false);
  EXPECT_NEAR(oriented[1], 180, 1e-9);
  EXPECT_THROW(paps::normalAngleErrors(est, paps::Normals(2)), paps::InvalidInput);
}

// ---------------------------------------------------------------------- triangle mesh

TEST(TriangleMesh, AreaAndAppend) {
  TriangleMesh m = unitSquare();
  EXPECT_DOUBLE_EQ(m.area(), 4);
  TriangleMesh other = unitSquare();
  for (auto& v : other.vertices) v.z() = 1;
  m.append(other);
  EXPECT_EQ(m.vertices.size(), 8u);
  ASSERT_EQ(m.triangles.size(), 4u);
  EXPECT_EQ(m.triangles[3], Eigen::Vector3i(4, 6, 7));
  EXPECT_DOUBLE_EQ(m.area(), 8);
}

TEST(TriangleMesh, NonManifoldEdgesAreThoseOfThreeTrianglesOrMore) {
  TriangleMesh m = unitSquare();  // two triangles sharing the diagonal
  EXPECT_EQ(m.nonManifoldEdgeCount(), 0);
  // A third triangle on the diagonal (whatever its orientation): one edge of three.
  const int d0 = m.triangles[0][0], d2 = m.triangles[0][2];
  m.vertices.emplace_back(0, 0, 1);
  const int top = static_cast<int>(m.vertices.size()) - 1;
  m.triangles.emplace_back(d2, d0, top);
  EXPECT_EQ(m.nonManifoldEdgeCount(), 1);
  // The same two triangles stacked again over the same vertices: each of the 4 sides is in 2
  // triangles (a copy and its original), the diagonal in 4.
  TriangleMesh stacked = unitSquare();
  stacked.triangles.push_back(stacked.triangles[0]);
  stacked.triangles.push_back(stacked.triangles[1]);
  EXPECT_EQ(stacked.nonManifoldEdgeCount(), 1);
  // A tetrahedron: closed and manifold.
  TriangleMesh tet;
  tet.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tet.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  EXPECT_EQ(tet.nonManifoldEdgeCount(), 0);
}

TEST(TriangleMesh, PolygonMeshIsFanned) {
  pcl::PointCloud<pcl::PointXYZ> cloud;
  for (const auto& v : unitSquare().vertices) cloud.push_back(pcl::PointXYZ(v.x(), v.y(), v.z()));
  pcl::PolygonMesh pm;
  pcl::toPCLPointCloud2(cloud, pm.cloud);
  pcl::Vertices quad;
  quad.vertices = {0, 1, 2, 3};
  pm.polygons.push_back(quad);
  const TriangleMesh m = paps::toTriangleMesh(pm);
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.triangles[1], Eigen::Vector3i(0, 2, 3));
  EXPECT_DOUBLE_EQ(m.area(), 4);
}

TEST(TriangleMesh, MissingFileThrowsIoError) {
  const std::string path = "/nonexistent/paps/mesh.ply";
  try {
    paps::loadTriangleMesh(path);
    FAIL() << "no exception";
  } catch (const paps::IoError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

TEST(TriangleMesh, PlyRoundTrip) {
  // The process id keeps parallel runs of the test apart.
  const auto dir = std::filesystem::path(::testing::TempDir()) /
                   ("paps_test_mesh_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const TriangleMesh cube = paps::synthetic::cube(2.f, 2);

  pcl::PointCloud<pcl::PointXYZ> cloud;
  for (const auto& v : cube.vertices) cloud.push_back(pcl::PointXYZ(v.x(), v.y(), v.z()));
  pcl::PolygonMesh pm;
  pcl::toPCLPointCloud2(cloud, pm.cloud);
  for (const auto& t : cube.triangles) {
    pcl::Vertices f;
    f.vertices = {static_cast<pcl::index_t>(t[0]), static_cast<pcl::index_t>(t[1]),
                  static_cast<pcl::index_t>(t[2])};
    pm.polygons.push_back(f);
  }
  const std::string ascii = (dir / "cube.ply").string();
  const std::string binary = (dir / "cube_binary.PLY").string();  // extension case is ignored
  ASSERT_EQ(pcl::io::savePLYFile(ascii, pm), 0);
  ASSERT_EQ(pcl::io::savePLYFileBinary(binary, pm), 0);
  for (const std::string& path : {ascii, binary}) {
    const TriangleMesh back = paps::loadTriangleMesh(path);
    ASSERT_EQ(back.vertices.size(), cube.vertices.size()) << path;
    ASSERT_EQ(back.triangles.size(), cube.triangles.size()) << path;
    for (std::size_t i = 0; i < cube.vertices.size(); ++i)
      EXPECT_TRUE(back.vertices[i].isApprox(cube.vertices[i], 1e-5f));
    for (std::size_t i = 0; i < cube.triangles.size(); ++i)
      EXPECT_EQ(back.triangles[i], cube.triangles[i]);
    EXPECT_NEAR(back.area(), 24.0, 1e-4);
  }

  // A cloud without faces is not a mesh, and neither is garbage.
  pm.polygons.clear();
  const std::string points_only = (dir / "points.ply").string();
  ASSERT_EQ(pcl::io::savePLYFile(points_only, pm), 0);
  EXPECT_THROW(paps::loadTriangleMesh(points_only), paps::IoError);
  const std::string garbage = (dir / "garbage.ply").string();
  std::ofstream(garbage) << "this is not a mesh\n";
  EXPECT_THROW(paps::loadTriangleMesh(garbage), paps::IoError);
  // Neither is a file with an unknown extension.
  const std::string other = (dir / "cube.stl").string();
  std::filesystem::copy_file(ascii, other, std::filesystem::copy_options::overwrite_existing);
  EXPECT_THROW(paps::loadTriangleMesh(other), paps::IoError);
  std::filesystem::remove_all(dir);
}

TEST(TriangleMesh, LoadsObjWithQuads) {
  const auto path = std::filesystem::path(::testing::TempDir()) /
                    ("paps_test_quad_" + std::to_string(::getpid()) + ".obj");
  std::ofstream(path) << "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nv 0 0 1\nf 1 2 3 4\nf 1 2 5\n";
  const TriangleMesh m = paps::loadTriangleMesh(path.string());
  std::filesystem::remove(path);
  EXPECT_EQ(m.vertices.size(), 5u);
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_NEAR(m.area(), 4 + std::sqrt(2.0), 1e-6);  // the quad and a triangle of base 2, slant sqrt(2)
}

TEST(TriangleMesh, ObjIndicesAreCheckedAndRelativeOnesFollowTheFormat) {
  const auto path = std::filesystem::path(::testing::TempDir()) /
                    ("paps_test_obj_" + std::to_string(::getpid()) + ".obj");
  auto load = [&](const std::string& text) {
    std::ofstream(path) << text;
    return paps::loadTriangleMesh(path.string());
  };
  // "f v/vt/vn" keeps v; -1 is the last vertex read; comments and other records are skipped.
  const TriangleMesh m = load("# a triangle\nv 0 0 0\nvn 0 0 1\nv 2 0 0\nv 0 2 0\ng part\nf 1/1/1 -2//1 -1\n");
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(m.triangles[0], Eigen::Vector3i(0, 1, 2));
  EXPECT_DOUBLE_EQ(m.area(), 2.0);
  // A face past the vertices crashed PCL's reader; every damaged line is named.
  for (const char* bad : {"v 1 2\nf 1 2 9999999\n", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9999999\n",
                          "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n",
                          "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "v 0 0 nan\n", "v 0 0 0\n"}) {
    try {
      load(bad);
      ADD_FAILURE() << "accepted: " << bad;
    } catch (const paps::IoError& e) {
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove(path);
}

// The OpenCV surface-matching sample fetched by scripts/fetch_samples.sh into $PAPS_SAMPLES
// (PAPS_SAMPLE_MESH overrides the path); skipped if absent.
TEST(TriangleMesh, LoadsRealPlyMesh) {
  const char* env = std::getenv("PAPS_SAMPLE_MESH");
  const char* samples = std::getenv("PAPS_SAMPLES");
  const char* home = std::getenv("HOME");
  const std::string path = env ? std::string(env)
                               : (samples ? std::string(samples)
                                          : std::string(home ? home : ".") + "/.cache/paps/samples") +
                                     "/rs1_normals.ply";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no sample mesh at " << path;
  const TriangleMesh m = paps::loadTriangleMesh(path);
  if (!env) {
    EXPECT_EQ(m.vertices.size(), 114373u);
    EXPECT_EQ(m.triangles.size(), 221803u);
    EXPECT_TRUE(m.vertices[0].isApprox(Eigen::Vector3f(-160.32f, 129.02f, -588.31f)));
  }
  EXPECT_GT(m.area(), 0);
  const paps::PointToMeshDistance d(m);
  const Positions p = paps::synthetic::sampleMesh(m, 2000, 1);
  EXPECT_LT(paps::pointToMeshError(p, d).max, 1e-5 * m.boundingBoxDiagonal());
}

}  // namespace core_metrics_test
