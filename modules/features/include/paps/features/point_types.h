#pragma once
// Point types of paps::features, registered with PCL so clouds of them can be saved,
// loaded, copied field by field (pcl::copyPointCloud) and used by pcl::Feature.
#include <cstdint>

#include <pcl/point_types.h>
#include <pcl/register_point_struct.h>

namespace paps {

/// Per-point scalar outputs of WavejetEstimation. Curvatures in 1/metres (Gaussian in
/// 1/metres^2), signed with respect to the normal (positive where the surface bends towards
/// it), k1 >= k2. All NaN (order -1) where the point could not be fitted.
struct EIGEN_ALIGN16 PointWavejet {
  PCL_ADD_NORMAL4D;             ///< corrected unit normal (normal_x, normal_y, normal_z)
  float k1;                     ///< maximal principal curvature (1/m)
  float k2;                     ///< minimal principal curvature (1/m)
  float mean_curvature;         ///< (k1 + k2) / 2 (1/m)
  float gaussian_curvature;     ///< k1 k2 (1/m^2)
  float principal_x;            ///< unit principal direction of k1
  float principal_y;
  float principal_z;
  float offset;                 ///< phi_{0,0}: signed distance to the Wavejet surface (m)
  float a0;                     ///< integral invariant a_0(R_phi), unit-disk units
  float a1_real;                ///< integral invariant a_1(R_phi), unit-disk units
  float a1_imag;
  std::int32_t order;           ///< Wavejet order used at the point (-1: not fitted)
  PCL_MAKE_ALIGNED_OPERATOR_NEW
};

}  // namespace paps

POINT_CLOUD_REGISTER_POINT_STRUCT(paps::PointWavejet,
    (float, normal_x, normal_x)(float, normal_y, normal_y)(float, normal_z, normal_z)
    (float, k1, k1)(float, k2, k2)(float, mean_curvature, mean_curvature)
    (float, gaussian_curvature, gaussian_curvature)
    (float, principal_x, principal_x)(float, principal_y, principal_y)(float, principal_z, principal_z)
    (float, offset, offset)(float, a0, a0)(float, a1_real, a1_real)(float, a1_imag, a1_imag)
    (std::int32_t, order, order))
