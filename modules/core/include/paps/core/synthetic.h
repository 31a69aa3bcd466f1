#pragma once
// Synthetic shapes with ground truth: triangle meshes with sharp features or repeated detail,
// seeded uniform sampling of meshes, Gaussian noise and outliers.
#include <cstdint>

#include <paps/core/triangle_mesh.h>

namespace paps {
namespace synthetic {

/// Axis-aligned cube of side `size` centred at the origin, each face split into
/// `subdivisions`^2 quads (two triangles each).
TriangleMesh cube(float size = 1.f, int subdivisions = 8);

/// Regular tetrahedron of edge `size` centred at the origin: four flat faces meeting at
/// 70.5-degree dihedral angles, sharper creases than the cube's 90.
TriangleMesh tetrahedron(float size = 1.f);

/// Closed cylinder (axis z, centred at the origin) of `radius` and `height`: a curved side
/// meeting two flat caps at 90-degree circular creases; the circle is a polygon of
/// `segments` sides (the side is one band of quads, the caps fans).
TriangleMesh cappedCylinder(float radius = 0.3f, float height = 0.6f, int segments = 256);

/// Fandisk-like block: a box whose top is a cylindrical bulge meeting a slanted chamfer,
/// giving convex and concave creases and a smooth-to-sharp transition. Size about 1.
TriangleMesh fandiskBlock(int resolution = 64);

/// Height field z = amplitude * sin(2 pi x / wavelength) * sin(2 pi y / wavelength) over a
/// square of side `size` (repeated engraved detail, Fig. 2.18), `resolution` quads a side.
TriangleMesh engravedPlane(float size = 1.f, float wavelength = 0.1f, float amplitude = 0.01f,
                           int resolution = 400);

/// Cylinder (open, axis z) of `radius` and `height` whose radius is displaced by
/// amplitude * sin(2 pi s / wavelength) * sin(2 pi z / wavelength), s = arc length.
TriangleMesh engravedCylinder(float radius = 0.3f, float height = 1.f, float wavelength = 0.1f,
                              float amplitude = 0.01f, int resolution = 400);

/// A LiDAR pass over a wavy ground z = 0.15 sin(1.3 x) cos(0.9 y) (metres): a sensor at
/// (0, 0, sensor_height), one scan line per degree of elevation from elevation_min to
/// elevation_max (degrees, negative: down), a return every azimuth_step degrees over
/// [-azimuth_half, azimuth_half), Gaussian range noise (metres), every return stored `copies`
/// times (as in PCL's bun0 sample). With the defaults the returns are 2 to 7 cm apart along
/// a line and the lines 9 cm to 0.9 m apart: far sparser across than along.
struct ScanLinePass {
  float sensor_height = 1.8f;
  int elevation_min = -40, elevation_max = -12;
  float azimuth_step = 0.5f, azimuth_half = 45.f;
  float range_noise = 0.005f;
  int copies = 2;
};
/// Height of the wavy ground at (x, y), and the signed distance of p to it (first order:
/// height difference over the gradient's norm; exact to about 1e-5 m within 2 cm).
float wavyGroundHeight(float x, float y);
float distanceToWavyGround(const Eigen::Vector3f& p);
/// RMS of distanceToWavyGround over the finite points (NaN when there are none).
double rmsDistanceToWavyGround(const Positions& points);
/// The returns of the pass, line by line.
Positions scanLinePass(const ScanLinePass& pass, std::uint64_t seed);
/// The wavy ground inside the scanned sector (azimuth within the pass's, horizontal range
/// between its nearest and farthest line on flat ground, shrunk by `margin` metres), as a
/// polar grid of cells about `cell` metres: ground truth for sampling dense reference points.
TriangleMesh wavyGroundSector(const ScanLinePass& pass, float margin = 0.2f, float cell = 0.02f);

/// A surface under a net of curves, the mixed shape of manuscript Fig. 3.15: the plate
/// [-1, 1]^2 at z = 0; eight straight wires at z = 0.3 (x = -0.6, -0.2, 0.2, 0.6 for y in
/// [-1, 1], and the same along x), which cross; a circle of radius 0.5 at z = 0.6 around the
/// z axis. `count` points in all, uniform on the plate and along the curves, the curves
/// twice as densely (spacing h / 2 along them where the plate's is h).
struct SurfaceAndCurves {
  Positions points;
  std::vector<std::uint8_t> on_curve;  ///< 1 for the points of the wires and the circle
};
SurfaceAndCurves plateAndWires(std::size_t count, std::uint64_t seed);
/// Exact distance from p to that shape.
double distanceToPlateAndWires(const Eigen::Vector3f& p);

/// Samples a mesh uniformly by area with a fixed seed. Returns positions; the true unit
/// normals (of the triangle each sample lies on) when `normals` is given.
Positions sampleMesh(const TriangleMesh& mesh, std::size_t count, std::uint64_t seed,
                     Normals* normals = nullptr);

/// Adds isotropic Gaussian noise of standard deviation `sigma_fraction` x the bounding-box
/// diagonal of the points. NaN points stay NaN.
void addGaussianNoise(Positions& points, float sigma_fraction, std::uint64_t seed);

/// Replaces a `fraction` of the points (chosen by seed) by points uniform in the bounding box
/// enlarged by 10%. Returns their indices.
std::vector<int> addOutliers(Positions& points, float fraction, std::uint64_t seed);

}  // namespace synthetic
}  // namespace paps
