// Optimal transport on a scan of a box: PCL's Poisson reconstruction rounds the box's edges
// and corners off; paps::TransportFeatureRecovery (a pcl::MeshProcessing) pulls the mesh's
// vertices back onto the creases the points describe. paps::TransportReconstruction (a
// pcl::SurfaceReconstruction) instead builds a mesh of a few dozen vertices straight from the
// points, keeping the creases.
//
//   example_optimal_transport [scan.pcd]   (writes poisson.ply, recovered.ply, simplified.ply)
//
// Without a file it samples a 0.5 m cube (20,000 points) and exits 1 unless the recovery
// halves the mean distance from the cube's corners to the nearest vertex (Poisson rounds
// them off) and the 20 vertices of the reconstruction lie within 1 cm (RMS) of the cube. (At
// 1,000 points the reconstruction does not find the corners: docs/transport.md.)
#include <cmath>
#include <iostream>
#include <random>

#include <pcl/common/centroid.h>
#include <pcl/common/io.h>
#include <pcl/features/normal_3d.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/surface/poisson.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/surface/transport_feature_recovery.h>
#include <paps/surface/transport_reconstruction.h>

// Mean distance from the cube's 8 corners to the nearest vertex of a mesh: a rounded corner
// has no vertex near it.
double cornerGap(const pcl::PolygonMesh& mesh) {
  pcl::PointCloud<pcl::PointXYZ> v;
  pcl::fromPCLPointCloud2(mesh.cloud, v);
  double sum = 0;
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3f corner(k & 1 ? 0.25f : -0.25f, k & 2 ? 0.25f : -0.25f, k & 4 ? 0.25f : -0.25f);
    float best = INFINITY;
    for (const auto& p : v) best = std::min(best, (p.getVector3fMap() - corner).norm());
    sum += best / 8;
  }
  return sum;
}

// RMS distance of a mesh's vertices to the surface of that cube.
double surfaceRms(const pcl::PolygonMesh& mesh) {
  pcl::PointCloud<pcl::PointXYZ> v;
  pcl::fromPCLPointCloud2(mesh.cloud, v);
  double sum = 0;
  for (const auto& p : v) {
    const Eigen::Vector3f a = p.getVector3fMap().cwiseAbs() - Eigen::Vector3f::Constant(0.25f);
    const double d = a.maxCoeff() > 0 ? a.cwiseMax(0.f).norm() : -a.maxCoeff();
    sum += d * d;
  }
  return std::sqrt(sum / v.size());
}

int main(int argc, char** argv) try {
  pcl::PointCloud<pcl::PointXYZ>::Ptr scan(new pcl::PointCloud<pcl::PointXYZ>);
  if (argc > 1) {
    pcl::fromPCLPointCloud2(paps::loadCloud(argv[1]), *scan);  // PCD or PLY; paps::IoError if unreadable
  } else {
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-0.25f, 0.25f);
    for (int i = 0; i < 20000; ++i) {  // uniform on the six faces
      Eigen::Vector3f p(u(rng), u(rng), u(rng));
      p[i % 3] = (i / 3) % 2 ? 0.25f : -0.25f;
      scan->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    }
  }
  // The smooth reconstruction: normals facing away from the centroid, Poisson depth 6.
  pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
  ne.setInputCloud(scan);
  ne.setKSearch(20);
  pcl::PointCloud<pcl::Normal> normals;
  ne.compute(normals);
  Eigen::Vector4f c;
  pcl::compute3DCentroid(*scan, c);
  pcl::PointCloud<pcl::PointNormal>::Ptr oriented(new pcl::PointCloud<pcl::PointNormal>);
  pcl::concatenateFields(*scan, normals, *oriented);
  for (auto& p : *oriented)
    if ((p.getVector3fMap() - c.head<3>()).dot(p.getNormalVector3fMap()) < 0) p.getNormalVector3fMap() *= -1.f;
  pcl::Poisson<pcl::PointNormal> poisson;
  poisson.setDepth(5);  // about 4 points a vertex: the recovery needs several
  poisson.setInputCloud(oriented);
  pcl::PolygonMesh::Ptr smooth(new pcl::PolygonMesh);
  poisson.reconstruct(*smooth);

  // Feature recovery: the mesh and the points it came from.
  paps::TransportFeatureRecovery<pcl::PointXYZ> recovery;
  recovery.setInputMesh(smooth);
  recovery.setInputCloud(scan);
  paps::TransportFeatureRecoveryParameters rp;
  rp.sweeps = 3;  // clean points: more than the default single sweep pays
  recovery.setParameters(rp);
  pcl::PolygonMesh recovered;
  recovery.process(recovered);

  // Reconstruction and simplification down to 20 vertices, the scan first merged into at most
  // 1,000 voxel cells (centroids carrying their points' mass): the linear programs shrink with
  // the points, and 20 vertices need no finer measure. (The default merges above 20,000.)
  paps::TransportReconstruction<pcl::PointXYZ> reconstruction;
  reconstruction.setInputCloud(scan);
  reconstruction.setMaxPoints(1000);
  reconstruction.setTargetVertices(20);
  pcl::PolygonMesh simplified;
  reconstruction.reconstruct(simplified);

  std::cout << scan->size() << " points: Poisson " << smooth->polygons.size() << " triangles, recovered in "
            << recovery.getReport().final_cost << " transport cost; reconstruction "
            << simplified.polygons.size() << " triangles on " << reconstruction.getReport().output_vertices
            << " vertices\n";
  if (argc > 1)
    return pcl::io::savePLYFileBinary("poisson.ply", *smooth) < 0 || pcl::io::savePLYFileBinary("recovered.ply", recovered) < 0 ||
           pcl::io::savePLYFileBinary("simplified.ply", simplified) < 0;
  const double before = cornerGap(*smooth), after = cornerGap(recovered), simple = surfaceRms(simplified);
  std::cout << "mean distance from a corner of the cube to the nearest vertex: Poisson " << before
            << " m, recovered " << after << " m; RMS distance of the 20 vertices to the cube " << simple << " m\n";
  return after < 0.5 * before && simple < 0.01 ? 0 : 1;
} catch (const paps::Error& e) {
  std::cerr << "example_optimal_transport: " << e.what() << "\n";
  return 1;
}
