#include <paps/core/plane_height_patch.h>

#include <cmath>

#include <paps/core/error.h>

namespace paps {

SamplingPattern SamplingPattern::grid(int n) {
  requireInRange("grid_size", n, 1, 64);
  SamplingPattern p;
  const float half = 1.f / std::sqrt(2.f);  // square inscribed in the unit disk
  p.spacing = 2.f * half / n;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      p.samples.emplace_back(-half + (i + 0.5f) * p.spacing, -half + (j + 0.5f) * p.spacing);
  return p;
}

SamplingPattern SamplingPattern::radial(int rings, int sectors) {
  requireInRange("rings", rings, 1, 64);
  requireInRange("sectors", sectors, 3, 256);
  SamplingPattern p;
  p.samples.emplace_back(0.f, 0.f);
  const float dr = 1.f / (rings + 0.5f);
  for (int r = 1; r <= rings; ++r)
    for (int s = 0; s < sectors; ++s) {
      const float a = 6.2831853f * (s + 0.5f * (r % 2)) / sectors;
      p.samples.emplace_back(r * dr * std::cos(a), r * dr * std::sin(a));
    }
  p.spacing = dr;
  return p;
}

PlaneHeightPatch::PlaneHeightPatch(SamplingPattern pattern, float radius, float kernel_width)
    : pattern_(std::move(pattern)), radius_(radius) {
  requirePositive("radius", radius);
  requirePositive("kernel_width", kernel_width);
  if (pattern_.samples.empty()) throw InvalidParameter("pattern", "empty", "at least one sample");
  const float sigma = kernel_width * pattern_.spacing * radius;
  inv_two_sigma2_ = 1.f / (2.f * sigma * sigma);
  // Valid when a neighbour lies within about 1.5 kernel widths of the sample.
  min_weight_ = std::exp(-1.5f * 1.5f / 2.f);
}

int PlaneHeightPatch::describe(const LocalFrame& frame, const Eigen::Vector3f& origin,
                               const Positions& points, const int* neighbours, int count,
                               float* heights, std::uint8_t* valid) const {
  const std::size_t m = pattern_.size();
  // Local coordinates of the neighbours once, then one weighted pass per sample.
  thread_local std::vector<Eigen::Vector3f> local;
  local.resize(count);
  for (int k = 0; k < count; ++k) local[k] = frame.toLocal(points[neighbours[k]] - origin);
  int n_valid = 0;
  for (std::size_t s = 0; s < m; ++s) {
    const Eigen::Vector2f c = pattern_.samples[s] * radius_;
    float w_sum = 0, h_sum = 0;
    for (int k = 0; k < count; ++k) {
      const float du = local[k].x() - c.x(), dv = local[k].y() - c.y();
      const float w = std::exp(-(du * du + dv * dv) * inv_two_sigma2_);
      w_sum += w;
      h_sum += w * local[k].z();
    }
    const bool ok = w_sum >= min_weight_;
    valid[s] = ok;
    heights[s] = ok ? h_sum / w_sum : 0.f;
    n_valid += ok;
  }
  return n_valid;
}

}  // namespace paps
