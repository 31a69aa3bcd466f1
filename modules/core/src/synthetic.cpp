#include <paps/core/synthetic.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <map>

#include <paps/core/error.h>
#include <paps/core/random.h>

namespace paps {
namespace synthetic {

namespace {

constexpr double kPi = 3.14159265358979323846;

/// Appends a grid of nu x nv quads (two triangles each) whose vertex (i, j) is at(i, j).
/// Triangles face along d(at)/di x d(at)/dj. With `wrap_u` the column nu is column 0
/// (closed strips such as a cylinder) and at() is called for i < nu only.
void addGrid(TriangleMesh& mesh, int nu, int nv, bool wrap_u,
             const std::function<Eigen::Vector3f(int, int)>& at) {
  const int base = static_cast<int>(mesh.vertices.size());
  const int cols = wrap_u ? nu : nu + 1;
  for (int j = 0; j <= nv; ++j)
    for (int i = 0; i < cols; ++i) mesh.vertices.push_back(at(i, j));
  auto id = [&](int i, int j) { return base + j * cols + (wrap_u ? i % nu : i); };
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const int v00 = id(i, j), v10 = id(i + 1, j), v11 = id(i + 1, j + 1), v01 = id(i, j + 1);
      mesh.triangles.emplace_back(v00, v10, v11);
      mesh.triangles.emplace_back(v00, v11, v01);
    }
}

/// Merges vertices with bit-identical coordinates, so separately built panels share
/// their edges (a closed mesh then has every edge used by exactly two triangles).
void weldIdentical(TriangleMesh& mesh) {
  std::map<std::array<float, 3>, int> seen;
  std::vector<int> remap(mesh.vertices.size());
  Positions kept;
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const auto& v = mesh.vertices[i];
    const auto it = seen.emplace(std::array<float, 3>{v.x(), v.y(), v.z()},
                                 static_cast<int>(kept.size()));
    if (it.second) kept.push_back(v);
    remap[i] = it.first->second;
  }
  for (auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) t[k] = remap[t[k]];
  mesh.vertices.swap(kept);
}

void requireAtLeast(const char* name, int value, int minimum) {
  if (value < minimum)
    throw InvalidParameter(name, std::to_string(value), "an integer >= " + std::to_string(minimum));
}

}  // namespace

TriangleMesh cube(float size, int subdivisions) {
  requirePositive("size", size);
  requireAtLeast("subdivisions", subdivisions, 1);
  const int n = subdivisions;
  const float h = 0.5f * size;
  // One table of coordinates for every face, so shared edges weld exactly.
  std::vector<float> c(n + 1);
  for (int i = 0; i <= n; ++i) c[i] = -h + size * static_cast<float>(i) / static_cast<float>(n);
  c[0] = -h;
  c[n] = h;

  TriangleMesh mesh;
  for (int axis = 0; axis < 3; ++axis)
    for (int sign : {-1, 1}) {
      // (axis+1, axis+2, axis) is right-handed: for the + face, u x v is the outward normal;
      // the - face swaps u and v.
      const int ua = sign > 0 ? (axis + 1) % 3 : (axis + 2) % 3;
      const int va = sign > 0 ? (axis + 2) % 3 : (axis + 1) % 3;
      addGrid(mesh, n, n, false, [&](int i, int j) {
        Eigen::Vector3f p;
        p[axis] = sign * h;
        p[ua] = c[i];
        p[va] = c[j];
        return p;
      });
    }
  weldIdentical(mesh);
  return mesh;
}

TriangleMesh tetrahedron(float size) {
  requirePositive("size", size);
  // Alternate corners of a cube of side size / sqrt(2) have edges of length `size`.
  const float h = size / (2.f * std::sqrt(2.f));
  TriangleMesh mesh;
  mesh.vertices = {{h, h, h}, {h, -h, -h}, {-h, h, -h}, {-h, -h, h}};
  for (const Eigen::Vector3i& f : {Eigen::Vector3i(0, 1, 2), Eigen::Vector3i(0, 3, 1), Eigen::Vector3i(0, 2, 3),
                                   Eigen::Vector3i(1, 3, 2)})
    mesh.triangles.push_back(f);  // each counter-clockwise seen from outside
  return mesh;
}

TriangleMesh cappedCylinder(float radius, float height, int segments) {
  requirePositive("radius", radius);
  requirePositive("height", height);
  requireAtLeast("segments", segments, 3);
  auto rim = [&](int i, float z) {
    const double theta = 2 * kPi * (i % segments) / segments;
    return Eigen::Vector3f(static_cast<float>(radius * std::cos(theta)), static_cast<float>(radius * std::sin(theta)), z);
  };
  const float top = 0.5f * height, bottom = -0.5f * height;
  TriangleMesh mesh;
  // u = angle, v = z: d/dtheta x d/dz points away from the axis.
  addGrid(mesh, segments, 1, true, [&](int i, int j) { return rim(i, j ? top : bottom); });
  for (const float z : {bottom, top}) {
    const int centre = static_cast<int>(mesh.vertices.size());
    mesh.vertices.emplace_back(0.f, 0.f, z);
    for (int i = 0; i < segments; ++i) {
      const int a = static_cast<int>(mesh.vertices.size());
      mesh.vertices.push_back(rim(i, z));
      mesh.vertices.push_back(rim(i + 1, z));
      // The top cap turns counter-clockwise seen from +z, the bottom one from -z.
      if (z > 0) mesh.triangles.emplace_back(centre, a, a + 1);
      else mesh.triangles.emplace_back(centre, a + 1, a);
    }
  }
  weldIdentical(mesh);  // the caps' rims onto the side's
  return mesh;
}

// Geometry of the fandisk-like block (a closed extrusion along y, y in [-0.5, 0.5]):
// the cross-section at y is { -0.5 <= x <= 0.5, 0 <= z <= top(x, y) } with
//   top = 0.4                                   on x in [-0.5, -0.2]  (flat shelf)
//   top = 0.2 + sqrt(0.08 - x^2)                on x in [-0.2,  0.2]  (cylindrical bulge,
//                                                  radius sqrt(0.08), axis (0, y, 0.2))
//   top = 0.4 + s(y) (x - 0.2), s = -1 + 0.5 t  on x in [ 0.2,  0.5]  (slanted chamfer,
//                                                  t = y + 0.5 in [0, 1])
// Creases: convex at every box edge and where the chamfer meets the right wall; concave
// (45 degrees) where the shelf meets the bulge. The bulge leaves x = 0.2 with slope -1, so
// the bulge/chamfer edge is smooth at y = -0.5 and a concave crease of atan(1) - atan(0.5)
// = 18.4 degrees at y = 0.5: the smooth-to-sharp transition. The ends y = +-0.5 are
// planar caps. Volume = 0.12 + (0.16 + 0.04 (pi/2 - 1)) + 0.08625 = 0.389082 (the mesh
// inscribes the bulge, so it is slightly smaller).
TriangleMesh fandiskBlock(int resolution) {
  requireAtLeast("resolution", resolution, 4);
  const int n_shelf = std::max(1, static_cast<int>(std::lround(0.3 * resolution)));
  const int n_bulge = std::max(2, static_cast<int>(std::lround(0.4 * resolution)));
  const int n_chamfer = std::max(1, static_cast<int>(std::lround(0.3 * resolution)));
  const int ny = resolution;

  // Columns: x and the two pieces of the top that depend on it (z = z0 + slope_factor * s).
  struct Column {
    float x;
    float z0;
    float chamfer_run;  // x - 0.2 on the chamfer, 0 elsewhere
  };
  std::vector<Column> cols;
  for (int k = 0; k < n_shelf; ++k) cols.push_back({-0.5f + 0.3f * k / n_shelf, 0.4f, 0.f});
  const double radius = std::sqrt(0.08);
  for (int k = 0; k < n_bulge; ++k) {
    const double theta = 0.75 * kPi - 0.5 * kPi * k / n_bulge;
    cols.push_back({static_cast<float>(radius * std::cos(theta)),
                    static_cast<float>(0.2 + radius * std::sin(theta)), 0.f});
  }
  cols[n_shelf] = {-0.2f, 0.4f, 0.f};  // exact crease position, no cos() rounding
  for (int k = 0; k <= n_chamfer; ++k) {
    const float x = 0.2f + 0.3f * k / n_chamfer;
    cols.push_back({k == n_chamfer ? 0.5f : x, 0.4f, x - 0.2f});
  }
  const int m = static_cast<int>(cols.size());  // columns per row

  // Per row: m bottom vertices then m top vertices.
  TriangleMesh mesh;
  for (int j = 0; j <= ny; ++j) {
    const float t = static_cast<float>(j) / ny;
    const float y = j == ny ? 0.5f : -0.5f + t;
    const float slope = -1.f + 0.5f * t;
    for (const Column& c : cols) mesh.vertices.emplace_back(c.x, y, 0.f);
    for (const Column& c : cols) mesh.vertices.emplace_back(c.x, y, c.z0 + slope * c.chamfer_run);
  }
  auto bottom = [&](int j, int i) { return 2 * m * j + i; };
  auto top = [&](int j, int i) { return 2 * m * j + m + i; };

  // The closed loop of the cross-section: bottom left to right, up the right wall, top
  // right to left, down the left wall.
  std::vector<std::function<int(int)>> loop;
  for (int i = 0; i < m; ++i) loop.push_back([=](int j) { return bottom(j, i); });
  for (int i = m - 1; i >= 0; --i) loop.push_back([=](int j) { return top(j, i); });
  const int loop_size = static_cast<int>(loop.size());
  for (int j = 0; j < ny; ++j)
    for (int k = 0; k < loop_size; ++k) {
      const int p0 = loop[k](j), p1 = loop[k](j + 1);
      const int q0 = loop[(k + 1) % loop_size](j), q1 = loop[(k + 1) % loop_size](j + 1);
      // Loop direction x row direction (+y) points outwards for this loop orientation.
      mesh.triangles.emplace_back(p0, p1, q1);
      mesh.triangles.emplace_back(p0, q1, q0);
    }
  // End caps: the section is vertically convex, so vertical trapezoids tile it.
  for (int i = 0; i + 1 < m; ++i) {
    mesh.triangles.emplace_back(bottom(0, i), bottom(0, i + 1), top(0, i + 1));
    mesh.triangles.emplace_back(bottom(0, i), top(0, i + 1), top(0, i));
    mesh.triangles.emplace_back(bottom(ny, i), top(ny, i + 1), bottom(ny, i + 1));
    mesh.triangles.emplace_back(bottom(ny, i), top(ny, i), top(ny, i + 1));
  }
  return mesh;
}

TriangleMesh engravedPlane(float size, float wavelength, float amplitude, int resolution) {
  requirePositive("size", size);
  requirePositive("wavelength", wavelength);
  if (!std::isfinite(amplitude))
    throw InvalidParameter("amplitude", detail::toString(amplitude), "a finite value");
  requireAtLeast("resolution", resolution, 1);
  const double k = 2 * kPi / wavelength;
  TriangleMesh mesh;
  addGrid(mesh, resolution, resolution, false, [&](int i, int j) {
    const double x = size * (static_cast<double>(i) / resolution - 0.5);
    const double y = size * (static_cast<double>(j) / resolution - 0.5);
    return Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y),
                           static_cast<float>(amplitude * std::sin(k * x) * std::sin(k * y)));
  });
  return mesh;
}

float wavyGroundHeight(float x, float y) { return 0.15f * std::sin(1.3f * x) * std::cos(0.9f * y); }

float distanceToWavyGround(const Eigen::Vector3f& p) {
  const float gx = 0.15f * 1.3f * std::cos(1.3f * p.x()) * std::cos(0.9f * p.y());
  const float gy = -0.15f * 0.9f * std::sin(1.3f * p.x()) * std::sin(0.9f * p.y());
  return (p.z() - wavyGroundHeight(p.x(), p.y())) / std::sqrt(1 + gx * gx + gy * gy);
}

double rmsDistanceToWavyGround(const Positions& points) {
  double s = 0;
  std::size_t n = 0;
  for (const auto& p : points)
    if (isFinite(p)) {
      const double d = distanceToWavyGround(p);
      s += d * d;
      ++n;
    }
  return n ? std::sqrt(s / n) : NAN;
}

namespace {
void checkPass(const ScanLinePass& pass) {
  requirePositive("sensor_height", pass.sensor_height);
  if (!(pass.elevation_min <= pass.elevation_max && pass.elevation_max < 0 && pass.elevation_min > -90))
    throw InvalidParameter("elevation", std::to_string(pass.elevation_min) + ".." + std::to_string(pass.elevation_max),
                           "-90 < elevation_min <= elevation_max < 0 (degrees, looking down)");
  requireInRange("azimuth_step", pass.azimuth_step, 0.01f, 90.f);
  requireInRange("azimuth_half", pass.azimuth_half, 0.01f, 80.f);
  if (!(pass.range_noise >= 0) || !std::isfinite(pass.range_noise))
    throw InvalidParameter("range_noise", detail::toString(pass.range_noise), "a finite value >= 0 (metres)");
  requireInRange("copies", pass.copies, 1, 100);
}
}  // namespace

Positions scanLinePass(const ScanLinePass& pass, std::uint64_t seed) {
  checkPass(pass);
  Random rng(seed);
  Positions scan;
  const Eigen::Vector3f sensor(0, 0, pass.sensor_height);
  for (int el = pass.elevation_min; el <= pass.elevation_max; ++el)
    for (float az = -pass.azimuth_half; az < pass.azimuth_half; az += pass.azimuth_step) {
      const float e = static_cast<float>(el) * 3.14159265f / 180, a = az * 3.14159265f / 180;
      const Eigen::Vector3f d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
      float t = -sensor.z() / d.z();
      for (int it = 0; it < 30; ++it) {  // march along the ray onto the ground
        const Eigen::Vector3f p = sensor + t * d;
        t += 0.8f * (p.z() - wavyGroundHeight(p.x(), p.y())) / -d.z();
      }
      const Eigen::Vector3f p = sensor + (t + pass.range_noise * static_cast<float>(rng.gaussian())) * d;
      for (int c = 0; c < pass.copies; ++c) scan.push_back(p);
    }
  return scan;
}

TriangleMesh wavyGroundSector(const ScanLinePass& pass, float margin, float cell) {
  checkPass(pass);
  requirePositive("cell", cell);
  if (!(margin >= 0) || !std::isfinite(margin))
    throw InvalidParameter("margin", detail::toString(margin), "a finite value >= 0 (metres)");
  const double deg = kPi / 180;
  const double r0 = pass.sensor_height / std::tan(-pass.elevation_min * deg) + margin;
  const double r1 = pass.sensor_height / std::tan(-pass.elevation_max * deg) - margin;
  if (!(r1 > r0)) throw InvalidParameter("margin", detail::toString(margin), "less than half the scanned depth");
  const double a0 = -pass.azimuth_half * deg, a1 = pass.azimuth_half * deg;
  const int nr = std::max(1, static_cast<int>(std::ceil((r1 - r0) / cell)));
  const int na = std::max(1, static_cast<int>(std::ceil((a1 - a0) * r1 / cell)));
  TriangleMesh mesh;
  addGrid(mesh, na, nr, false, [&](int i, int j) {
    const double a = a0 + (a1 - a0) * i / na, r = r0 + (r1 - r0) * j / nr;
    const float x = static_cast<float>(r * std::cos(a)), y = static_cast<float>(r * std::sin(a));
    return Eigen::Vector3f(x, y, wavyGroundHeight(x, y));
  });
  return mesh;
}

// Centred on the origin, z in [-height/2, height/2]. `resolution` quads along z and about as
// many per unit length around, so quads are roughly square. Around the axis the wavelength
// is rounded to fit a whole number of periods in the circumference: otherwise the pattern
// would jump at the seam theta = 0.
TriangleMesh engravedCylinder(float radius, float height, float wavelength, float amplitude,
                              int resolution) {
  requirePositive("radius", radius);
  requirePositive("height", height);
  requirePositive("wavelength", wavelength);
  if (!(std::abs(amplitude) < radius))
    throw InvalidParameter("amplitude", detail::toString(amplitude),
                           "a value with |amplitude| < radius");
  requireAtLeast("resolution", resolution, 1);
  const double circumference = 2 * kPi * radius;
  const int n_around =
      std::max(3, static_cast<int>(std::lround(resolution * circumference / height)));
  const double periods = std::max(1.0, std::round(circumference / wavelength));
  const double kz = 2 * kPi / wavelength;
  TriangleMesh mesh;
  // u = angle, v = z: d/dtheta x d/dz points away from the axis.
  addGrid(mesh, n_around, resolution, true, [&](int i, int j) {
    const double theta = 2 * kPi * i / n_around;
    const double z = height * (static_cast<double>(j) / resolution - 0.5);
    const double r = radius + amplitude * std::sin(periods * theta) * std::sin(kz * z);
    return Eigen::Vector3f(static_cast<float>(r * std::cos(theta)),
                           static_cast<float>(r * std::sin(theta)), static_cast<float>(z));
  });
  return mesh;
}

Positions sampleMesh(const TriangleMesh& mesh, std::size_t count, std::uint64_t seed,
                     Normals* normals) {
  const int nv = static_cast<int>(mesh.vertices.size());
  // Cumulative areas: a uniform draw in [0, total) then picks a triangle with probability
  // proportional to its area by binary search.
  std::vector<double> cumulative(mesh.triangles.size());
  double total = 0;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Eigen::Vector3i& f = mesh.triangles[t];
    if (f.minCoeff() < 0 || f.maxCoeff() >= nv)
      throw InvalidInput("triangle " + std::to_string(t) + " refers to a vertex outside [0, " +
                         std::to_string(nv) + ")");
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>();
    const double area =
        0.5 * (mesh.vertices[f[1]].cast<double>() - a)
                  .cross(mesh.vertices[f[2]].cast<double>() - a)
                  .norm();
    if (std::isfinite(area)) total += area;  // NaN corners: never sampled
    cumulative[t] = total;
  }
  if (count > 0 && !(total > 0))
    throw InvalidInput("cannot sample a mesh of zero area (" +
                       std::to_string(mesh.triangles.size()) + " triangles)");

  Random rng(seed);
  Positions points(count);
  if (normals) normals->resize(count);
  for (std::size_t s = 0; s < count; ++s) {
    const double u = rng.uniform() * total;
    // First triangle whose cumulative area exceeds u: zero-area triangles are never chosen.
    std::size_t t = std::upper_bound(cumulative.begin(), cumulative.end(), u) - cumulative.begin();
    t = std::min(t, cumulative.size() - 1);
    const Eigen::Vector3i& f = mesh.triangles[t];
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[f[1]].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[f[2]].cast<double>();
    // sqrt(r1) makes the barycentric coordinates uniform over the triangle's area.
    const double r1 = std::sqrt(rng.uniform()), r2 = rng.uniform();
    points[s] = ((1 - r1) * a + r1 * (1 - r2) * b + r1 * r2 * c).cast<float>();
    if (normals) (*normals)[s] = (b - a).cross(c - a).normalized().cast<float>();
  }
  return points;
}

void addGaussianNoise(Positions& points, float sigma_fraction, std::uint64_t seed) {
  if (!(sigma_fraction >= 0) || !std::isfinite(sigma_fraction))
    throw InvalidParameter("sigma_fraction", detail::toString(sigma_fraction),
                           "a finite value >= 0");
  const double sigma = sigma_fraction * static_cast<double>(boundingBoxDiagonal(points));
  Random rng(seed);
  for (auto& p : points) {
    if (!isFinite(p)) continue;
    const double dx = rng.gaussian(), dy = rng.gaussian(), dz = rng.gaussian();
    p += (sigma * Eigen::Vector3d(dx, dy, dz)).cast<float>();
  }
}

std::vector<int> addOutliers(Positions& points, float fraction, std::uint64_t seed) {
  requireInRange("fraction", fraction, 0.f, 1.f);
  const std::size_t n = points.size();
  const std::size_t count =
      std::min(n, static_cast<std::size_t>(std::llround(static_cast<double>(fraction) * n)));
  if (count == 0) return {};

  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  for (const auto& p : points)
    if (isFinite(p)) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  if (!(lo.array() <= hi.array()).all())
    throw InvalidInput("cannot place outliers: no finite point among " + std::to_string(n));
  // Enlarge the box by 10% (5% each side) so outliers also fall around the shape.
  const Eigen::Vector3f margin = 0.05f * (hi - lo);
  lo -= margin;
  hi += margin;

  // Partial Fisher-Yates shuffle: the first `count` entries are a uniform random subset.
  Random rng(seed);
  std::vector<int> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<int>(i);
  for (std::size_t k = 0; k < count; ++k) std::swap(order[k], order[k + rng.below(n - k)]);
  std::vector<int> chosen(order.begin(), order.begin() + count);
  std::sort(chosen.begin(), chosen.end());
  for (int i : chosen)
    for (int d = 0; d < 3; ++d) points[i][d] = static_cast<float>(rng.uniform(lo[d], hi[d]));
  return chosen;
}

namespace {
const float kWireOffsets[4] = {-0.6f, -0.2f, 0.2f, 0.6f};
constexpr float kWireHeight = 0.3f, kCircleRadius = 0.5f, kCircleHeight = 0.6f;

}  // namespace

SurfaceAndCurves plateAndWires(std::size_t count, std::uint64_t seed) {
  if (count < 100) throw InvalidParameter("count", std::to_string(count), "at least 100");
  // Plate area 4 at spacing h: 4 / h^2 points; curves of length L at h / 2: 2 L / h points.
  const double length = 8 * 2.0 + 2 * kPi * kCircleRadius;
  const double x = (-2 * length + std::sqrt(4 * length * length + 16.0 * count)) / 8.0;  // 1 / h
  const std::size_t n_curve = std::min(count - 1, static_cast<std::size_t>(std::llround(2 * length * x)));
  const std::size_t n_plate = count - n_curve;
  Random rng(seed);
  SurfaceAndCurves out;
  out.points.reserve(count);
  out.on_curve.reserve(count);
  for (std::size_t i = 0; i < n_plate; ++i) {
    const float px = static_cast<float>(rng.uniform(-1, 1)), py = static_cast<float>(rng.uniform(-1, 1));
    out.points.emplace_back(px, py, 0.f);
    out.on_curve.push_back(0);
  }
  for (std::size_t i = 0; i < n_curve; ++i) {
    const double s = rng.uniform(0, length);
    Eigen::Vector3f p;
    if (s < 16) {
      const int w = static_cast<int>(s / 2);
      const float t = static_cast<float>(s - 2 * w) - 1.f;
      p = w < 4 ? Eigen::Vector3f(kWireOffsets[w], t, kWireHeight) : Eigen::Vector3f(t, kWireOffsets[w - 4], kWireHeight);
    } else {
      const double a = (s - 16) / kCircleRadius;
      p = Eigen::Vector3f(static_cast<float>(kCircleRadius * std::cos(a)), static_cast<float>(kCircleRadius * std::sin(a)),
                          kCircleHeight);
    }
    out.points.push_back(p);
    out.on_curve.push_back(1);
  }
  return out;
}

double distanceToPlateAndWires(const Eigen::Vector3f& p) {
  const Eigen::Vector3d q = p.cast<double>();
  auto clamp1 = [](double v) { return std::clamp(v, -1.0, 1.0); };
  double d2 = Eigen::Vector3d(q.x() - clamp1(q.x()), q.y() - clamp1(q.y()), q.z()).squaredNorm();
  for (float c : kWireOffsets) {
    d2 = std::min(d2, Eigen::Vector3d(q.x() - c, q.y() - clamp1(q.y()), q.z() - kWireHeight).squaredNorm());
    d2 = std::min(d2, Eigen::Vector3d(q.x() - clamp1(q.x()), q.y() - c, q.z() - kWireHeight).squaredNorm());
  }
  const double rho = std::hypot(q.x(), q.y());
  d2 = std::min(d2, (rho - kCircleRadius) * (rho - kCircleRadius) + (q.z() - kCircleHeight) * (q.z() - kCircleHeight));
  return std::sqrt(d2);
}

}  // namespace synthetic
}  // namespace paps
