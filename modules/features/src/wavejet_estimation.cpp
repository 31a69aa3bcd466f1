#include <paps/features/wavejet_estimation.h>
#include <paps/features/impl/wavejet_estimation.hpp>

#include <pcl/point_types.h>

namespace paps {

void toPoint(const WavejetResult& r, PointWavejet& out) {
  out.normal_x = r.normal.x(); out.normal_y = r.normal.y(); out.normal_z = r.normal.z();
  out.data_n[3] = 0.f;
  out.k1 = r.k1; out.k2 = r.k2;
  out.mean_curvature = r.mean_curvature;
  out.gaussian_curvature = r.gaussian_curvature;
  out.principal_x = r.direction1.x(); out.principal_y = r.direction1.y(); out.principal_z = r.direction1.z();
  out.offset = r.offset;
  out.a0 = r.a0;
  out.a1_real = r.a1.real();
  out.a1_imag = r.a1.imag();
  out.order = r.order;
}

void toPoint(const WavejetResult& r, pcl::PrincipalCurvatures& out) {
  const bool first = !(std::abs(r.k2) > std::abs(r.k1));  // NaN: the first, all NaN anyway
  const Eigen::Vector3f d = first ? r.direction1 : Eigen::Vector3f(r.normal.cross(r.direction1));
  out.principal_curvature_x = d.x();
  out.principal_curvature_y = d.y();
  out.principal_curvature_z = d.z();
  out.pc1 = std::max(std::abs(r.k1), std::abs(r.k2));
  out.pc2 = std::min(std::abs(r.k1), std::abs(r.k2));
  if (!r.valid()) out.pc1 = out.pc2 = NAN;
}

template class WavejetEstimation<pcl::PointXYZ>;
template class WavejetEstimation<pcl::PointXYZI>;
template class WavejetEstimation<pcl::PointNormal>;
template class WavejetEstimation<pcl::PointXYZRGB>;
template class WavejetEstimation<pcl::PointXYZRGBA>;  // RGB-D cameras
template class WavejetEstimation<pcl::PointXYZRGBNormal>;
// PCL's output types, for the input types most pipelines hold (others: PAPS_NO_PRECOMPILE).
template class WavejetEstimation<pcl::PointXYZ, pcl::PrincipalCurvatures>;
template class WavejetEstimation<pcl::PointXYZ, pcl::Normal>;
template class WavejetEstimation<pcl::PointXYZ, pcl::PointNormal>;
template class WavejetEstimation<pcl::PointNormal, pcl::PrincipalCurvatures>;

}  // namespace paps
