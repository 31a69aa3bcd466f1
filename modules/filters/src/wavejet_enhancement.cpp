#include <paps/filters/wavejet_enhancement.h>
#include <paps/filters/impl/wavejet_enhancement.hpp>

#include <cmath>

#include <pcl/point_types.h>

#include <paps/core/error.h>

namespace paps {

void WavejetEnhancementParameters::validate() const {
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "0 (automatic) or a finite value > 0");
  requireInRange("target_neighbours", target_neighbours, 3, 100000);
  wavejet.validate();
  if (!std::isfinite(alpha0)) throw InvalidParameter("alpha0", detail::toString(alpha0), "a finite gain");
  if (!std::isfinite(alpha1.real()) || !std::isfinite(alpha1.imag()))
    throw InvalidParameter("alpha1", detail::toString(alpha1), "a finite complex gain");
  requirePositive("max_motion", max_motion);
}

namespace {

constexpr double kTwoPi = 6.283185307179586;

std::vector<WavejetResult> fitAll(const Positions& points, const WavejetEnhancementParameters& params,
                                  WavejetEnhancementReport* report, const ProgressCallback& progress,
                                  const Normals* orientation, std::vector<WavejetCoefficients>* coefficients) {
  params.validate();
  WavejetReport wr;
  auto res = estimateWavejets(points, params.radius, params.wavejet, &wr, coefficients, nullptr, orientation,
                              progress, params.target_neighbours);
  if (report) {
    *report = WavejetEnhancementReport();
    report->radius = wr.radius;
    report->mean_neighbours = wr.mean_neighbours;
    report->unfitted = wr.too_few_neighbours + wr.failed_fits;
    report->non_finite = wr.non_finite;
    report->lowered = wr.lowered;
    report->duplicates = wr.duplicates;
    report->widened = wr.widened;
    report->widened_radius_median = wr.widened_radius_median;
    report->narrowed = wr.narrowed;
    report->narrowed_radius_median = wr.narrowed_radius_median;
    report->wavejet = wr;
  }
  return res;
}

}  // namespace

Positions enhancePositions(const Positions& points, const WavejetEnhancementParameters& params,
                           WavejetEnhancementReport* report, const std::vector<std::uint8_t>& movable,
                           const ProgressCallback& progress, const Normals* orientation, Normals* normals_out) {
  WavejetEnhancementReport local;
  WavejetEnhancementReport& r = report ? *report : local;
  const auto res = fitAll(points, params, &r, progress, orientation, nullptr);
  Positions out = points;
  if (normals_out) normals_out->assign(points.size(), Eigen::Vector3f::Constant(NAN));
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!res[i].valid()) continue;
    if (normals_out) (*normals_out)[i] = res[i].normal;
    if (!movable.empty() && !movable[i]) continue;
    // Equation 2.21 in unit-disk units, scaled back to metres by the point's own R_phi
    // (larger than the search radius where widened). res.offset is in metres.
    const double R = res[i].radius;
    const double limit = params.max_motion * R;
    double d = res[i].offset - kTwoPi * (params.alpha0 - 1.0) * res[i].a0 * R;
    if (std::abs(d) > limit) { d = d > 0 ? limit : -limit; ++r.clamped; }
    out[i] = points[i] + static_cast<float>(d) * res[i].normal;
    ++r.changed;
  }
  return out;
}

Normals enhanceNormals(const Positions& points, const WavejetEnhancementParameters& params,
                       WavejetEnhancementReport* report, const ProgressCallback& progress,
                       const Normals* orientation) {
  WavejetEnhancementReport local;
  WavejetEnhancementReport& r = report ? *report : local;
  // Without gain the output is the corrected normal itself: no frames to keep (they cost
  // about 170 bytes a point).
  const bool gain = params.alpha1 != std::complex<float>(1.f, 0.f);
  std::vector<WavejetCoefficients> coef;
  const auto res = fitAll(points, params, &r, progress, orientation, gain ? &coef : nullptr);
  Normals out(points.size(), Eigen::Vector3f::Constant(NAN));
  const std::complex<double> alpha(params.alpha1);
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!res[i].valid()) continue;
    if (!gain) {
      out[i] = res[i].normal;
      ++r.changed;
      continue;
    }
    // Equation 2.22, then Corollary 1: phi'_11 defines the false tangent plane
    // z = 2 Re(phi'_11 (x + i y)) over the tangent frame.
    const std::complex<double> phi11 = -M_PI * (alpha - 1.0) * std::complex<double>(res[i].a1);
    const double gx = 2 * phi11.real(), gy = -2 * phi11.imag();
    const LocalFrame& f = coef[i].frame;
    out[i] = (f.n.cast<double>() - gx * f.t1.cast<double>() - gy * f.t2.cast<double>()).normalized().cast<float>();
    ++r.changed;
  }
  return out;
}

Normals enhancedSurfaceNormals(const Positions& enhanced, const WavejetEnhancementParameters& params,
                               const Normals& corrected, const ProgressCallback& progress) {
  if (corrected.size() != enhanced.size())
    throw InvalidParameter("corrected normals", detail::toString(corrected.size()), "one per point");
  WavejetEnhancementParameters unchanged = params;
  unchanged.alpha1 = 1.f;  // the corrected normal, no gain
  return enhanceNormals(enhanced, unchanged, nullptr, progress, &corrected);
}

template class WavejetEnhancement<pcl::PointXYZ>;
template class WavejetEnhancement<pcl::PointXYZI>;
template class WavejetEnhancement<pcl::PointNormal>;
template class WavejetEnhancement<pcl::PointXYZRGB>;
template class WavejetEnhancement<pcl::PointXYZRGBA>;  // RGB-D cameras (PCL's OpenNI2 and RealSense grabbers)
template class WavejetEnhancement<pcl::PointXYZRGBNormal>;

}  // namespace paps
