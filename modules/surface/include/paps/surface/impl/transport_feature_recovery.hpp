#pragma once
#include <paps/core/error.h>
#include <paps/surface/transport_feature_recovery.h>

namespace paps {

template <typename PointT>
void TransportFeatureRecovery<PointT>::process(pcl::PolygonMesh& output) {
  if (!input_mesh_) throw InvalidInput("TransportFeatureRecovery: no input mesh (setInputMesh)");
  if (!cloud_) throw InvalidInput("TransportFeatureRecovery: no input cloud (setInputCloud)");
  pcl::MeshProcessing::process(output);
}

template <typename PointT>
void TransportFeatureRecovery<PointT>::performProcessing(pcl::PolygonMesh& output) {
  const ScopedThreadCount threads(this->threads_);
  const pcl::PCLHeader header = output.header;  // the input mesh's (pcl::MeshProcessing::process)
  output = toPolygonMesh(
      transportRecoverFeatures(toTriangleMesh(*input_mesh_), positionsOf(*cloud_), params_, &report_, progress_));
  output.header = header;
  output.cloud.header = input_mesh_->cloud.header;
}

}  // namespace paps
