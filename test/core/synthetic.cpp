// Tests of paps/core/synthetic.h: shapes with known areas and volumes, seeded sampling,
// noise and outliers.
#include <cmath>
#include <map>
#include <set>
#include <vector>
#include <utility>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/synthetic.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_synthetic_test {

using paps::Positions;
using paps::TriangleMesh;
namespace syn = paps::synthetic;

constexpr double kPi = 3.14159265358979323846;

/// Signed volume by the divergence theorem: positive for a closed, outward-facing mesh.
double signedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& t : m.triangles)
    v += m.vertices[t[0]].cast<double>().dot(
        m.vertices[t[1]].cast<double>().cross(m.vertices[t[2]].cast<double>()));
  return v / 6;
}

/// Number of directed edges without their opposite twin, or used more than once. Zero for a
/// closed, consistently oriented manifold mesh.
int unmatchedEdges(const TriangleMesh& m) {
  std::map<std::pair<int, int>, int> directed;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  int bad = 0;
  for (const auto& [edge, n] : directed) {
    const auto twin = directed.find({edge.second, edge.first});
    if (n != 1 || twin == directed.end() || twin->second != 1) ++bad;
  }
  return bad;
}

double variance(const std::vector<double>& v) {
  double mean = 0, m2 = 0;
  for (double x : v) mean += x;
  mean /= v.size();
  for (double x : v) m2 += (x - mean) * (x - mean);
  return m2 / (v.size() - 1);
}

// ------------------------------------------------------------------------------ shapes

TEST(Cube, AreaVolumeAndClosedness) {
  for (int n : {1, 3, 8}) {
    const float s = 2.f;
    const TriangleMesh m = syn::cube(s, n);
    EXPECT_EQ(m.triangles.size(), static_cast<std::size_t>(12 * n * n));
    EXPECT_EQ(m.vertices.size(), static_cast<std::size_t>(6 * n * n + 2));  // welded
    EXPECT_NEAR(m.area(), 6 * s * s, 1e-4);
    EXPECT_NEAR(signedVolume(m), s * s * s, 1e-4);  // > 0: faces point outwards
    EXPECT_EQ(unmatchedEdges(m), 0);
    EXPECT_NEAR(m.boundingBoxDiagonal(), s * std::sqrt(3.f), 1e-5);
  }
  EXPECT_THROW(syn::cube(-1.f), paps::InvalidParameter);
  EXPECT_THROW(syn::cube(1.f, 0), paps::InvalidParameter);
}

TEST(Tetrahedron, AreaVolumeAndClosedness) {
  const float a = 0.8f;
  const TriangleMesh m = syn::tetrahedron(a);
  EXPECT_EQ(m.triangles.size(), 4u);
  EXPECT_NEAR(m.area(), std::sqrt(3.0) * a * a, 1e-5);
  EXPECT_NEAR(signedVolume(m), a * a * a / (6 * std::sqrt(2.0)), 1e-6);  // > 0: outwards
  EXPECT_EQ(unmatchedEdges(m), 0);
  for (const auto& v : m.vertices) EXPECT_NEAR(v.norm(), a * std::sqrt(6.0) / 4, 1e-6);  // circumradius
  EXPECT_THROW(syn::tetrahedron(0.f), paps::InvalidParameter);
}

TEST(CappedCylinder, AreaVolumeAndClosedness) {
  for (int n : {3, 7, 256}) {
    const float r = 0.3f, h = 0.6f;
    const TriangleMesh m = syn::cappedCylinder(r, h, n);
    // The polygon of n sides: side n chords x h, caps 2 x n triangles of r^2 sin(2 pi / n) / 2.
    const double cap = 0.5 * n * r * r * std::sin(2 * kPi / n);
    EXPECT_NEAR(m.area(), n * 2 * r * std::sin(kPi / n) * h + 2 * cap, 1e-5);
    EXPECT_NEAR(signedVolume(m), cap * h, 1e-6);
    EXPECT_EQ(unmatchedEdges(m), 0);  // the caps' rims welded onto the side's
    EXPECT_EQ(m.vertices.size(), static_cast<std::size_t>(2 * n + 2));
  }
  EXPECT_THROW(syn::cappedCylinder(0.3f, 0.6f, 2), paps::InvalidParameter);
  EXPECT_THROW(syn::cappedCylinder(-0.3f), paps::InvalidParameter);
}

TEST(FandiskBlock, ClosedWithTheDocumentedVolume) {
  const TriangleMesh m = syn::fandiskBlock(64);
  EXPECT_EQ(unmatchedEdges(m), 0);
  // Exact volume 0.389082; the mesh inscribes the bulge, so it is a little smaller.
  const double volume = signedVolume(m);
  EXPECT_LT(volume, 0.389082);
  EXPECT_GT(volume, 0.389082 - 1e-3);
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  for (const auto& v : m.vertices) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  EXPECT_TRUE(lo.isApprox(Eigen::Vector3f(-0.5f, -0.5f, 0.f)));
  // Top of the bulge: 0.2 + sqrt(0.08).
  EXPECT_TRUE(hi.isApprox(Eigen::Vector3f(0.5f, 0.5f, 0.2f + std::sqrt(0.08f)), 1e-5f));
}

TEST(FandiskBlock, HasSharpCreasesAndASmoothToSharpTransition) {
  const TriangleMesh m = syn::fandiskBlock(48);
  // Dihedral angle (degrees between the two face normals) of every edge.
  std::map<std::pair<int, int>, std::vector<Eigen::Vector3d>> normals;
  for (const auto& t : m.triangles) {
    const Eigen::Vector3d a = m.vertices[t[0]].cast<double>();
    const Eigen::Vector3d n = (m.vertices[t[1]].cast<double>() - a)
                                  .cross(m.vertices[t[2]].cast<double>() - a)
                                  .normalized();
    for (int k = 0; k < 3; ++k) normals[std::minmax(t[k], t[(k + 1) % 3])].push_back(n);
  }
  double max_angle = 0, near_end_angle = -1, far_end_angle = -1;
  for (const auto& [e, n] : normals) {
    ASSERT_EQ(n.size(), 2u);
    const double angle = std::acos(std::clamp(n[0].dot(n[1]), -1.0, 1.0)) * 180 / kPi;
    max_angle = std::max(max_angle, angle);
    // The bulge/chamfer edge runs along y at x = 0.2, z = 0.4; look at its two end pieces.
    const Eigen::Vector3f p = m.vertices[e.first], q = m.vertices[e.second];
    const bool on_edge = p.x() == 0.2f && q.x() == 0.2f && p.z() == 0.4f && q.z() == 0.4f;
    if (on_edge && std::min(p.y(), q.y()) == -0.5f) near_end_angle = angle;
    if (on_edge && std::max(p.y(), q.y()) == 0.5f) far_end_angle = angle;
  }
  EXPECT_GE(max_angle, 90 - 1e-3);  // the box edges are sharp
  // Smooth (up to the chord of the bulge's last segment) at y = -0.5, an 18.4 degree crease
  // at y = 0.5.
  ASSERT_GE(near_end_angle, 0);
  ASSERT_GE(far_end_angle, 0);
  EXPECT_LT(near_end_angle, 4);
  EXPECT_GT(far_end_angle, 14);
  EXPECT_LT(far_end_angle, 19);
  EXPECT_THROW(syn::fandiskBlock(2), paps::InvalidParameter);
}

TEST(EngravedPlane, AreaAndHeights) {
  const float size = 1.f, amplitude = 0.02f;
  const TriangleMesh flat = syn::engravedPlane(size, 0.1f, 0.f, 50);
  EXPECT_EQ(flat.vertices.size(), 51u * 51u);
  EXPECT_NEAR(flat.area(), size * size, 1e-5);
  const TriangleMesh m = syn::engravedPlane(size, 0.1f, amplitude, 200);
  // True area of z = 0.02 sin(2 pi x / 0.1) sin(2 pi y / 0.1) on the unit square: the
  // integral of sqrt(1 + z_x^2 + z_y^2), 100 whole periods, computed to 1e-12 by the
  // periodic midpoint rule: 1.329309. The mesh interpolates it linearly on 200 quads a side
  // (20 per wavelength) and misses O(h^2) of it: 1.326575 computed for this triangulation
  // (1.318449 at 100 quads, 1.328624 at 400). So the area lies below the truth by less than
  // 0.004, which excludes both a coarser mesh and a wrong amplitude or wavelength.
  const double truth = 1.329309;
  EXPECT_LT(m.area(), truth);
  EXPECT_GT(m.area(), truth - 0.004);
  float zmax = 0;
  for (const auto& v : m.vertices) zmax = std::max(zmax, std::abs(v.z()));
  EXPECT_LE(zmax, amplitude * (1 + 1e-6f));
  EXPECT_GT(zmax, 0.99f * amplitude);  // crests fall on grid nodes for this resolution
}

TEST(EngravedCylinder, AreaRadiusAndBorder) {
  const float r = 0.3f, h = 1.f, a = 0.01f;
  // Without detail the area is that of the inscribed prism, close to 2 pi r h.
  const TriangleMesh plain = syn::engravedCylinder(r, h, 0.1f, 0.f, 200);
  EXPECT_NEAR(plain.area(), 2 * kPi * r * h, 1e-4 * 2 * kPi * r * h);
  const TriangleMesh m = syn::engravedCylinder(r, h, 0.1f, a, 200);
  EXPECT_GT(m.area(), plain.area());
  for (const auto& v : m.vertices) {
    const float radius = std::hypot(v.x(), v.y());
    ASSERT_LE(radius, r + a + 1e-5f);
    ASSERT_GE(radius, r - a - 1e-5f);
    ASSERT_LE(std::abs(v.z()), 0.5f * h + 1e-6f);
  }
  // Open tube: only the two rims are border edges; no seam.
  std::map<std::pair<int, int>, int> edges;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++edges[std::minmax(t[k], t[(k + 1) % 3])];
  int border = 0;
  for (const auto& e : edges) border += e.second == 1;
  const int around = static_cast<int>(std::lround(200 * 2 * kPi * r / h));
  EXPECT_EQ(border, 2 * around);
  EXPECT_GT(signedVolume(m), 0);  // faces point away from the axis (the open rims add 0)
  EXPECT_THROW(syn::engravedCylinder(0.3f, 1.f, 0.1f, 0.5f), paps::InvalidParameter);
}

// ---------------------------------------------------------------------------- sampling

TEST(SampleMesh, CountDeterminismAndNormals) {
  const TriangleMesh m = syn::cube(2.f, 3);
  paps::Normals n;
  const Positions p = syn::sampleMesh(m, 5000, 42, &n);
  ASSERT_EQ(p.size(), 5000u);
  ASSERT_EQ(n.size(), 5000u);
  const Positions same = syn::sampleMesh(m, 5000, 42);
  const Positions other = syn::sampleMesh(m, 5000, 43);
  EXPECT_EQ(p, same);
  EXPECT_NE(p, other);
  for (std::size_t i = 0; i < p.size(); ++i) {
    ASSERT_NEAR(n[i].norm(), 1.f, 1e-6f);
    // On a cube the true normal is the axis along which the point touches the surface.
    int axis = 0;
    p[i].cwiseAbs().maxCoeff(&axis);
    ASSERT_NEAR(p[i].cwiseAbs()[axis], 1.f, 1e-6f);
    ASSERT_NEAR(n[i][axis], p[i][axis] > 0 ? 1.f : -1.f, 1e-6f) << "sample " << i;
  }
  EXPECT_TRUE(syn::sampleMesh(m, 0, 1).empty());
  EXPECT_THROW(syn::sampleMesh(TriangleMesh{}, 10, 1), paps::InvalidInput);
}

TEST(SampleMesh, UniformByArea) {
  // Triangles of areas 1 and 3 (the second is degenerate-free but far away): a quarter of
  // the samples in the first. Within each triangle the mean is the centroid.
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {2, 0, 0}, {0, 1, 0}, {10, 0, 0}, {13, 0, 0}, {10, 2, 0}};
  m.triangles = {{0, 1, 2}, {3, 4, 5}};
  const std::size_t count = 200000;
  const Positions p = syn::sampleMesh(m, count, 7);
  std::size_t first = 0;
  Eigen::Vector3d mean_first = Eigen::Vector3d::Zero(), mean_second = mean_first;
  for (const auto& x : p) {
    if (x.x() < 5) {
      ++first;
      mean_first += x.cast<double>();
    } else {
      mean_second += x.cast<double>();
    }
  }
  const double fraction = static_cast<double>(first) / count;
  EXPECT_NEAR(fraction, 0.25, 0.005);  // ~5 standard errors
  mean_first /= first;
  mean_second /= count - first;
  EXPECT_TRUE(mean_first.isApprox(Eigen::Vector3d(2.0 / 3, 1.0 / 3, 0), 1e-2));
  EXPECT_TRUE(mean_second.isApprox(Eigen::Vector3d(11, 2.0 / 3, 0), 2e-3));
}

// ------------------------------------------------------------------ noise and outliers

TEST(GaussianNoise, StandardDeviationIsTheRequestedFraction) {
  const TriangleMesh m = syn::engravedPlane(1.f, 0.1f, 0.f, 20);
  const Positions clean = syn::sampleMesh(m, 100000, 3);
  Positions noisy = clean;
  noisy[10] = Eigen::Vector3f(NAN, 0, 0);
  Positions reference = clean;
  reference[10] = noisy[10];
  const float fraction = 0.01f;
  const double sigma = fraction * paps::boundingBoxDiagonal(reference);
  syn::addGaussianNoise(noisy, fraction, 9);
  EXPECT_TRUE(std::isnan(noisy[10].x()));
  for (int d = 0; d < 3; ++d) {
    std::vector<double> diff;
    for (std::size_t i = 0; i < clean.size(); ++i)
      if (i != 10) diff.push_back(noisy[i][d] - clean[i][d]);
    EXPECT_NEAR(std::sqrt(variance(diff)), sigma, 0.05 * sigma) << "axis " << d;
  }
  // Same seed, same noise.
  Positions again = clean;
  again[10] = noisy[10];
  syn::addGaussianNoise(again, fraction, 9);
  for (std::size_t i = 0; i < clean.size(); ++i) {
    if (i == 10) continue;
    ASSERT_EQ(again[i], noisy[i]);
  }
  EXPECT_THROW(syn::addGaussianNoise(again, -0.1f, 1), paps::InvalidParameter);
}

TEST(Outliers, CountIndicesAndBox) {
  const TriangleMesh m = syn::cube(1.f, 2);
  const Positions clean = syn::sampleMesh(m, 10000, 4);
  Positions p = clean;
  const std::vector<int> idx = syn::addOutliers(p, 0.05f, 8);
  ASSERT_EQ(idx.size(), 500u);
  EXPECT_TRUE(std::is_sorted(idx.begin(), idx.end()));
  EXPECT_EQ(std::set<int>(idx.begin(), idx.end()).size(), idx.size());
  const std::set<int> chosen(idx.begin(), idx.end());
  int off_surface = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!chosen.count(static_cast<int>(i))) {
      ASSERT_EQ(p[i], clean[i]);
      continue;
    }
    // Cube of side 1 enlarged by 10%: |coordinate| <= 0.55.
    ASSERT_LE(p[i].cwiseAbs().maxCoeff(), 0.55f + 1e-6f);
    off_surface += std::abs(p[i].cwiseAbs().maxCoeff() - 0.5f) > 1e-3f;
  }
  EXPECT_GT(off_surface, 450);
  Positions q = clean;
  EXPECT_EQ(syn::addOutliers(q, 0.05f, 8), idx);
  EXPECT_EQ(q, p);
  EXPECT_TRUE(syn::addOutliers(q, 0.f, 8).empty());
  EXPECT_THROW(syn::addOutliers(q, 1.5f, 8), paps::InvalidParameter);
}

// The scan-line pass: one line per degree of elevation, one return per azimuth step, each
// stored `copies` times; returns lie on the ground within the range noise projected on the
// vertical; the sector mesh lies on the ground and has the area of its annular sector.
TEST(ScanLinePass, CountsGeometryAndSectorMesh) {
  syn::ScanLinePass pass;
  const Positions scan = syn::scanLinePass(pass, 5);
  ASSERT_EQ(scan.size(), 29u * 180u * 2u);
  double s = 0;
  float nearest = INFINITY, farthest = 0;
  for (std::size_t i = 0; i < scan.size(); i += 2) {
    EXPECT_EQ(scan[i], scan[i + 1]);
    const double d = syn::distanceToWavyGround(scan[i]);
    s += d * d;
    const float r = std::hypot(scan[i].x(), scan[i].y());
    nearest = std::min(nearest, r);
    farthest = std::max(farthest, r);
  }
  // 5 mm along rays 12 to 40 degrees below the horizon (and tilted ground): 1 to 3 mm vertically.
  const double rms = std::sqrt(s / (scan.size() / 2));
  EXPECT_GT(rms, 1e-3);
  EXPECT_LT(rms, 3.5e-3);
  EXPECT_NEAR(nearest, 1.8 / std::tan(40 * kPi / 180), 0.25);
  EXPECT_NEAR(farthest, 1.8 / std::tan(12 * kPi / 180), 1.0);
  pass.range_noise = 0;
  pass.copies = 1;
  for (const auto& p : syn::scanLinePass(pass, 5)) EXPECT_LT(std::abs(syn::distanceToWavyGround(p)), 1e-4f);
  const TriangleMesh sector = syn::wavyGroundSector(pass, 0.2f, 0.05f);
  const double r0 = 1.8 / std::tan(40 * kPi / 180) + 0.2, r1 = 1.8 / std::tan(12 * kPi / 180) - 0.2;
  const double flat_area = kPi / 4 * (r1 * r1 - r0 * r0);
  EXPECT_GT(sector.area(), flat_area * 0.99);  // the slopes (at most 0.23) add up to 2.6%
  EXPECT_LT(sector.area(), flat_area * 1.03);
  for (const auto& v : sector.vertices) EXPECT_LT(std::abs(syn::distanceToWavyGround(v)), 1e-6f);
  pass.elevation_max = 5;
  EXPECT_THROW(syn::scanLinePass(pass, 5), paps::InvalidParameter);
  pass = {};
  pass.copies = 0;
  EXPECT_THROW(syn::scanLinePass(pass, 5), paps::InvalidParameter);
  pass = {};
  EXPECT_THROW(syn::wavyGroundSector(pass, 5.f), paps::InvalidParameter);
}

}  // namespace core_synthetic_test
