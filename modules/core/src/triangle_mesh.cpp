#include <paps/core/triangle_mesh.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <pcl/PolygonMesh.h>
#include <pcl/conversions.h>
#include <pcl/point_types.h>
#include <pcl/io/ply_io.h>

#include <paps/core/cloud_file_layout.h>
#include <paps/core/cloud_io.h>
#include <paps/core/error.h>

#include "quiet_pcl_io.h"

namespace paps {

double TriangleMesh::area() const {
  // Accumulate in double: large meshes have many small triangles.
  double sum = 0;
  for (const auto& t : triangles) {
    const Eigen::Vector3d a = vertices[t[0]].cast<double>();
    const Eigen::Vector3d b = vertices[t[1]].cast<double>();
    const Eigen::Vector3d c = vertices[t[2]].cast<double>();
    sum += 0.5 * (b - a).cross(c - a).norm();
  }
  return sum;
}

int TriangleMesh::nonManifoldEdgeCount() const {
  std::vector<std::pair<int, int>> edges;
  edges.reserve(3 * triangles.size());
  for (const auto& t : triangles)
    for (int k = 0; k < 3; ++k) edges.push_back(std::minmax(t[k], t[(k + 1) % 3]));
  std::sort(edges.begin(), edges.end());
  int count = 0;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    count += j - i > 2;
    i = j;
  }
  return count;
}

void TriangleMesh::append(const TriangleMesh& other) {
  const int offset = static_cast<int>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  triangles.reserve(triangles.size() + other.triangles.size());
  for (const auto& t : other.triangles) triangles.push_back(t + Eigen::Vector3i::Constant(offset));
}

TriangleMesh toTriangleMesh(const pcl::PolygonMesh& mesh) {
  // Read through the checked converter: PCL's fromPCLPointCloud2 indexed an empty cloud when
  // the vertices had no x, y, z (a crash found by fuzzing the PLY mesh reader).
  TriangleMesh out;
  out.vertices = positionsOf(mesh.cloud);
  const std::size_t n = out.vertices.size();
  out.triangles.reserve(mesh.polygons.size());
  for (std::size_t f = 0; f < mesh.polygons.size(); ++f) {
    const auto& v = mesh.polygons[f].vertices;
    for (const auto index : v)
      if (static_cast<std::size_t>(index) >= n)
        throw InvalidInput("polygon " + std::to_string(f) + " refers to vertex " +
                           std::to_string(index) + " but the mesh has " + std::to_string(n) +
                           " vertices");
    // Polygons with fewer than 3 vertices carry no area; larger ones are fanned from the first.
    for (std::size_t k = 1; k + 1 < v.size(); ++k)
      out.triangles.emplace_back(static_cast<int>(v[0]), static_cast<int>(v[k]),
                                 static_cast<int>(v[k + 1]));
  }
  return out;
}

pcl::PolygonMesh toPolygonMesh(const TriangleMesh& mesh) {
  pcl::PointCloud<pcl::PointXYZ> cloud;
  cloud.resize(mesh.vertices.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) cloud[i].getVector3fMap() = mesh.vertices[i];
  pcl::PolygonMesh out;
  pcl::toPCLPointCloud2(cloud, out.cloud);
  out.polygons.resize(mesh.triangles.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
    out.polygons[f].vertices = {static_cast<pcl::index_t>(mesh.triangles[f][0]),
                                static_cast<pcl::index_t>(mesh.triangles[f][1]),
                                static_cast<pcl::index_t>(mesh.triangles[f][2])};
  return out;
}

namespace {

// OBJ, read here rather than by PCL's reader, which crashes on a face index past the vertices
// (found by the API audit). Only "v" and "f" lines matter; faces of more than three vertices
// are fanned like the PLY ones; "f 1/2/3" keeps the vertex index; negative indices count back
// from the last vertex read, as the format says.
TriangleMesh readObj(const std::string& path) {
  std::ifstream in(path);
  TriangleMesh out;
  std::vector<int> face;
  std::string line;
  std::size_t number = 0;
  auto bad = [&](const std::string& what) {
    return IoError("cannot read mesh '" + path + "': line " + std::to_string(number) + ": " + what);
  };
  while (std::getline(in, line)) {
    ++number;
    std::istringstream words(line);
    std::string key;
    if (!(words >> key)) continue;
    if (key == "v") {
      Eigen::Vector3f v;
      if (!(words >> v.x() >> v.y() >> v.z()) || !isFinite(v)) throw bad("a vertex needs three finite coordinates");
      out.vertices.push_back(v);
    } else if (key == "f") {
      face.clear();
      for (std::string token; words >> token;) {
        std::size_t used = 0;
        long index = 0;
        try {
          index = std::stol(token, &used);
        } catch (const std::exception&) {
          throw bad("face vertex '" + token + "' is not an index");
        }
        if (used < token.size() && token[used] != '/') throw bad("face vertex '" + token + "' is not an index");
        const long count = static_cast<long>(out.vertices.size());
        const long zero_based = index > 0 ? index - 1 : count + index;
        if (index == 0 || zero_based < 0 || zero_based >= count)
          throw bad("face vertex " + token + " refers to no vertex (" + std::to_string(count) + " read so far)");
        face.push_back(static_cast<int>(zero_based));
      }
      for (std::size_t k = 1; k + 1 < face.size(); ++k) out.triangles.emplace_back(face[0], face[k], face[k + 1]);
    }
  }
  if (in.bad()) throw IoError("cannot read mesh '" + path + "': read error");
  return out;
}

}  // namespace

TriangleMesh loadTriangleMesh(const std::string& path) {
  checkInputPath(path, "mesh ");

  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });

  // PLY through PCL's own reader (not the VTK one: fewer dependencies, faces kept as written),
  // its header checked first; OBJ through readObj above.
  TriangleMesh out;
  if (ext == ".ply") {
    readPlyLayoutForPcl(path);  // a header PCL would crash on or trust into a huge allocation
    pcl::PolygonMesh mesh;
    std::string thrown;
    if (detail::quietPclIo([&] { return pcl::io::loadPLYFile(path, mesh); }, thrown) < 0)
      throw IoError("cannot read mesh '" + path + "': the file could not be parsed" +
                    (thrown.empty() ? "" : " (" + thrown + ")"));
    try {
      out = toTriangleMesh(mesh);
    } catch (const InvalidInput& e) {
      throw IoError("cannot read mesh '" + path + "': " + e.what());
    }
  } else if (ext == ".obj") {
    out = readObj(path);
  } else {
    throw IoError("cannot read mesh '" + path + "': unsupported extension '" + ext + "' (expected .ply or .obj)");
  }
  if (out.triangles.empty()) throw IoError("cannot read mesh '" + path + "': it has no faces");
  return out;
}

}  // namespace paps
