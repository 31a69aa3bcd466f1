#pragma once
// A plain indexed triangle mesh: ground truth for metrics and synthetic shapes.
#include <string>
#include <vector>

#include <paps/core/positions.h>

namespace pcl { struct PolygonMesh; }

namespace paps {

struct TriangleMesh {
  Positions vertices;
  std::vector<Eigen::Vector3i> triangles;

  float boundingBoxDiagonal() const { return paps::boundingBoxDiagonal(vertices); }
  double area() const;
  /// Edges shared by more than two triangles (a manifold has none; layers of facets stacked
  /// over one surface have many).
  int nonManifoldEdgeCount() const;
  /// Appends another mesh (indices shifted).
  void append(const TriangleMesh& other);
};

/// Converts a pcl::PolygonMesh (polygons with more than 3 vertices are fanned).
TriangleMesh toTriangleMesh(const pcl::PolygonMesh& mesh);
/// The mesh as a pcl::PolygonMesh (a PointXYZ cloud and triangles).
pcl::PolygonMesh toPolygonMesh(const TriangleMesh& mesh);
/// Loads a PLY or OBJ mesh. Throws IoError when the file is missing, unreadable or has no faces.
TriangleMesh loadTriangleMesh(const std::string& path);

}  // namespace paps
