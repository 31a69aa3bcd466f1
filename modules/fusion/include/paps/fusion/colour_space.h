#pragma once
// Colour conversions shared by colorization and the shadow stages (manuscript 4.5). Colours are
// linear RGB in [0, 1]: the 8-bit values of the photos and of the points are read as linear
// (no sRGB gamma), which is what the outdoor lighting model of eq. 4.5 multiplies. CIE Lab is
// computed from them with the D65 white, L in [0, 100], a and b about [-128, 127].
#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Core>
#include <pcl/point_cloud.h>
#include <vector>

namespace paps {
namespace colour {

/// 8-bit channel -> [0, 1].
inline float fromByte(std::uint8_t v) { return v * (1.f / 255.f); }
/// [0, 1] -> 8-bit channel (rounded, clamped; NaN -> 0).
inline std::uint8_t toByte(float v) {
  if (!(v > 0)) return 0;
  if (v >= 1) return 255;
  return static_cast<std::uint8_t>(std::lround(v * 255.f));
}

/// Relative luminance Y of a linear RGB colour (Rec. 709 / sRGB primaries), in [0, 1].
inline float luminance(const Eigen::Vector3f& rgb) {
  return 0.2126729f * rgb.x() + 0.7151522f * rgb.y() + 0.0721750f * rgb.z();
}

namespace detail {
inline float labF(float t) {
  constexpr float d = 6.f / 29.f;
  return t > d * d * d ? std::cbrt(t) : t / (3 * d * d) + 4.f / 29.f;
}
inline float labFInverse(float f) {
  constexpr float d = 6.f / 29.f;
  return f > d ? f * f * f : 3 * d * d * (f - 4.f / 29.f);
}
constexpr float kWhiteX = 0.950456f, kWhiteZ = 1.088754f;
}  // namespace detail

/// CIE L* of a relative luminance Y (white = 1): 0 to 100.
inline float lightnessOfLuminance(float y) { return 116.f * detail::labF(std::max(0.f, y)) - 16.f; }
/// Relative luminance of a CIE L*.
inline float luminanceOfLightness(float l) { return detail::labFInverse((l + 16.f) / 116.f); }

/// Linear RGB -> CIE Lab (L, a, b), D65.
inline Eigen::Vector3f rgbToLab(const Eigen::Vector3f& rgb) {
  const float x = 0.4124564f * rgb.x() + 0.3575761f * rgb.y() + 0.1804375f * rgb.z();
  const float y = luminance(rgb);
  const float z = 0.0193339f * rgb.x() + 0.1191920f * rgb.y() + 0.9503041f * rgb.z();
  const float fx = detail::labF(std::max(0.f, x) / detail::kWhiteX);
  const float fy = detail::labF(std::max(0.f, y));
  const float fz = detail::labF(std::max(0.f, z) / detail::kWhiteZ);
  return {116.f * fy - 16.f, 500.f * (fx - fy), 200.f * (fy - fz)};
}

/// CIE Lab -> linear RGB (not clamped: a Lab colour may lie outside the RGB gamut).
inline Eigen::Vector3f labToRgb(const Eigen::Vector3f& lab) {
  const float fy = (lab.x() + 16.f) / 116.f;
  const float fx = fy + lab.y() / 500.f;
  const float fz = fy - lab.z() / 200.f;
  const float x = detail::kWhiteX * detail::labFInverse(fx);
  const float y = detail::labFInverse(fy);
  const float z = detail::kWhiteZ * detail::labFInverse(fz);
  return {3.2404542f * x - 1.5371385f * y - 0.4985314f * z, -0.9692660f * x + 1.8760108f * y + 0.0415560f * z,
          0.0556434f * x - 0.2040259f * y + 1.0572252f * z};
}

/// The rgb of every point as linear RGB in [0, 1] (PointT with r, g, b).
template <typename PointT>
std::vector<Eigen::Vector3f> coloursOf(const pcl::PointCloud<PointT>& cloud) {
  std::vector<Eigen::Vector3f> c;
  c.reserve(cloud.size());
  for (const auto& p : cloud) c.emplace_back(fromByte(p.r), fromByte(p.g), fromByte(p.b));
  return c;
}

/// Writes one linear RGB colour per point into r, g, b (rounded, clamped to 8 bits).
template <typename PointT>
void setColours(const std::vector<Eigen::Vector3f>& colours, pcl::PointCloud<PointT>& cloud) {
  for (std::size_t i = 0; i < cloud.size() && i < colours.size(); ++i) {
    cloud[i].r = toByte(colours[i].x());
    cloud[i].g = toByte(colours[i].y());
    cloud[i].b = toByte(colours[i].z());
  }
}

}  // namespace colour
}  // namespace paps
