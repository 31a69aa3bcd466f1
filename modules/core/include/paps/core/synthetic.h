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
