#pragma once
#include <pcl/conversions.h>

#include <paps/core/error.h>
#include <paps/core/positions.h>
#include <paps/surface/transport_reconstruction.h>

namespace paps {

template <typename PointT>
TriangleMesh TransportReconstruction<PointT>::run() {
  const ScopedThreadCount threads(this->threads_);
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  return transportReconstruct(positionsAt(*this->input_, *this->indices_), params_, &report_, progress_);
}

template <typename PointT>
void TransportReconstruction<PointT>::performReconstruction(pcl::PolygonMesh& output) {
  // The headers pcl::SurfaceReconstruction::reconstruct set from the input cloud stay.
  const pcl::PCLHeader header = output.header, cloud_header = output.cloud.header;
  output = toPolygonMesh(run());
  output.header = header;
  output.cloud.header = cloud_header;
}

template <typename PointT>
void TransportReconstruction<PointT>::performReconstruction(pcl::PointCloud<PointT>& points,
                                                            std::vector<pcl::Vertices>& polygons) {
  const TriangleMesh mesh = run();
  points.clear();
  points.resize(mesh.vertices.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) points[i].getVector3fMap() = mesh.vertices[i];
  polygons.resize(mesh.triangles.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
    polygons[f].vertices = {static_cast<pcl::index_t>(mesh.triangles[f][0]),
                            static_cast<pcl::index_t>(mesh.triangles[f][1]),
                            static_cast<pcl::index_t>(mesh.triangles[f][2])};
}

}  // namespace paps
