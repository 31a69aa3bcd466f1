// paps sample-mesh / paps mesh-distance: clouds with a known surface, and how far a cloud lies
// from it. They make the large-input figures of the docs reproducible without scratch programs.
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include <pcl/PCLPointCloud2.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/metrics.h>
#include <paps/core/synthetic.h>
#include <paps/core/triangle_mesh.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

namespace {
const char* kSampleMeshUsage =
    "usage: paps sample-mesh MESH N OUT [options]\n"
    "  N points sampled uniformly by area on MESH (.ply or .obj), written to OUT (.pcd or .ply)\n"
    "  as x y z: a cloud whose true surface is known (paps mesh-distance measures against it).\n"
    "  --noise F     Gaussian noise of standard deviation F x the bounding-box diagonal of the\n"
    "                samples, on each axis (default 0; the benches' 0.25% is 0.0025)\n"
    "  --seed S      seed of the sampling; the noise uses S + 1 (default 5)\n";

const char* kMeshDistanceUsage =
    "usage: paps mesh-distance MESH CLOUD\n"
    "  Distance of CLOUD's finite points to the triangle mesh MESH (exact, point to triangle):\n"
    "  RMS, mean, 95th percentile and maximum, in the cloud's units.\n";
}  // namespace

int runSampleMesh(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"help"});
  if (a.has("help")) { std::fputs(kSampleMeshUsage, stdout); return 0; }
  a.allowOnly({"noise", "seed"});
  if (a.positional.size() != 3) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "MESH N OUT");
  const std::size_t count = [&] {
    char* end = nullptr;
    const std::string& s = a.positional[1];
    const unsigned long long v = std::strtoull(s.c_str(), &end, 10);
    if (s.empty() || *end != '\0' || s[0] == '-' || v == 0 || v > 2000000000ULL)
      throw InvalidParameter("N", s, "a point count from 1 to 2000000000");
    return static_cast<std::size_t>(v);
  }();
  const float noise = a.real("noise", 0.f);
  if (!(noise >= 0.f && noise <= 1.f)) throw InvalidParameter("noise", detail::toString(noise), "0 to 1 (of the diagonal)");
  const std::size_t seed = a.count("seed", 5);
  checkCloudOutputPath(a.positional[2]);
  const TriangleMesh mesh = loadTriangleMesh(a.positional[0]);
  if (!(mesh.area() > 0)) throw InvalidInput("the mesh '" + a.positional[0] + "' has no area to sample");
  Positions p = synthetic::sampleMesh(mesh, count, seed);
  if (noise > 0) synthetic::addGaussianNoise(p, noise, seed + 1);
  // x y z only, 12 bytes a point (a PointXYZ blob carries 4 bytes of padding a point).
  pcl::PCLPointCloud2 blob;
  for (const char* name : {"x", "y", "z"}) {
    pcl::PCLPointField f;
    f.name = name;
    f.offset = static_cast<std::uint32_t>(4 * blob.fields.size());
    f.datatype = pcl::PCLPointField::FLOAT32;
    f.count = 1;
    blob.fields.push_back(f);
  }
  blob.height = 1;
  blob.width = static_cast<std::uint32_t>(p.size());
  blob.point_step = 12;
  blob.row_step = blob.point_step * blob.width;
  blob.is_dense = true;
  blob.data.resize(p.size() * 12);
  for (std::size_t i = 0; i < p.size(); ++i) std::memcpy(&blob.data[12 * i], p[i].data(), 12);
  saveCloudAtomic(a.positional[2], blob);
  std::printf("wrote %s: %zu points on %s (%zu triangles), noise %g x the diagonal, seed %zu\n", a.positional[2].c_str(),
              p.size(), a.positional[0].c_str(), mesh.triangles.size(), noise, seed);
  return 0;
}

int runMeshDistance(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"help"});
  if (a.has("help")) { std::fputs(kMeshDistanceUsage, stdout); return 0; }
  a.allowOnly({});
  if (a.positional.size() != 2) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "MESH CLOUD");
  const TriangleMesh mesh = loadTriangleMesh(a.positional[0]);
  const Positions p = loadPositions(a.positional[1]);
  const PointToMeshDistance truth(mesh);
  const ErrorStats e = pointToMeshError(p, truth);
  if (e.count == 0) throw InvalidInput("the cloud '" + a.positional[1] + "' has no finite point");
  std::printf("%s: %zu finite points of %zu, distance to %s: RMS %.4e mean %.4e p95 %.4e max %.4e\n",
              a.positional[1].c_str(), e.count, p.size(), a.positional[0].c_str(), e.rmse, e.mean, e.p95, e.max);
  return 0;
}

}  // namespace paps::cli
