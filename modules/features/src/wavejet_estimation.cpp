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

template class WavejetEstimation<pcl::PointXYZ>;
template class WavejetEstimation<pcl::PointXYZI>;
template class WavejetEstimation<pcl::PointNormal>;
template class WavejetEstimation<pcl::PointXYZRGB>;
template class WavejetEstimation<pcl::PointXYZRGBNormal>;

}  // namespace paps
