#include "render.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <Eigen/Eigenvalues>
#include <pcl/io/png_io.h>

#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>

namespace paps::cli {

View View::fit(const Positions& points, float tilt_degrees) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  std::size_t n = 0;
  for (const auto& p : points)
    if (isFinite(p)) { mean += p.cast<double>(); ++n; }
  if (n == 0) throw InvalidInput("nothing to render");
  mean /= n;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : points)
    if (isFinite(p)) { const Eigen::Vector3d d = p.cast<double>() - mean; cov += d * d.transpose(); }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  Eigen::Matrix3f a;
  a.row(0) = eig.eigenvectors().col(2).cast<float>().transpose();
  a.row(2) = eig.eigenvectors().col(0).cast<float>().transpose();
  if (a(2, 2) < 0) a.row(2) = -a.row(2);  // look from +z when it is ambiguous
  a.row(1) = a.row(2).cross(a.row(0));
  const float t = tilt_degrees * 3.14159265f / 180.f;
  const Eigen::Matrix3f tilt = Eigen::AngleAxisf(t, Eigen::Vector3f::UnitX()).toRotationMatrix();
  View v;
  v.axes = tilt * a;
  v.lo = Eigen::Vector2f::Constant(std::numeric_limits<float>::max());
  v.hi = -v.lo;
  for (const auto& p : points)
    if (isFinite(p)) {
      const Eigen::Vector3f s = v.axes * p;
      v.lo = v.lo.cwiseMin(s.head<2>());
      v.hi = v.hi.cwiseMax(s.head<2>());
    }
  return v;
}

namespace {

struct Canvas {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;
  Canvas(int w, int h) : width(w), height(h), rgb(static_cast<std::size_t>(w) * h * 3, 255) {}
};

int heightFor(const View& view, int width) {
  const Eigen::Vector2f ext = (view.hi - view.lo).cwiseMax(1e-12f);
  return std::max(1, static_cast<int>(width * ext.y() / ext.x()));
}

// Splats every point as a square block with a z-buffer into the panel of `panel_width`
// columns starting at column `offset`; colour from `colour(i)`.
template <typename ColourFn>
void splat(const Positions& points, const View& view, int panel_width, int offset, Canvas& canvas, ColourFn colour) {
  const Eigen::Vector2f ext = (view.hi - view.lo).cwiseMax(1e-12f);
  const int width = panel_width, height = canvas.height;
  std::vector<float> depth(static_cast<std::size_t>(width) * height, -std::numeric_limits<float>::max());
  // Splats as wide as the mean spacing on screen, so that the surface shows without holes.
  const std::size_t shown = std::max<std::size_t>(1, countFinite(points));
  const int size = std::clamp(static_cast<int>(std::ceil(1.3 * std::sqrt(double(width) * height / shown))), 2,
                              std::max(2, std::min(width, height) / 8));
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!isFinite(points[i])) continue;
    const Eigen::Vector3f s = view.axes * points[i];
    const int x = static_cast<int>((s.x() - view.lo.x()) / ext.x() * (width - size));
    const int y = static_cast<int>((view.hi.y() - s.y()) / ext.y() * (height - size));
    if (x < 0 || y < 0 || x >= width || y >= height) continue;  // outside the view
    const Eigen::Vector3f c = colour(i);
    for (int dy = 0; dy < size; ++dy)
      for (int dx = 0; dx < size; ++dx) {
        const std::size_t k = static_cast<std::size_t>(y + dy) * width + (x + dx);
        if (x + dx >= width || y + dy >= height || s.z() <= depth[k]) continue;
        depth[k] = s.z();
        const std::size_t o = (static_cast<std::size_t>(y + dy) * canvas.width + offset + x + dx) * 3;
        for (int ch = 0; ch < 3; ++ch)
          canvas.rgb[o + ch] = static_cast<unsigned char>(std::clamp(c[ch], 0.f, 1.f) * 255.f);
      }
  }
}

// PCL's PNG writer reports nothing when it fails (e.g. a missing folder): check the file.
void save(const Canvas& canvas, const std::string& png) {
  std::remove(png.c_str());
  pcl::io::saveRgbPNGFile(png, canvas.rgb.data(), canvas.width, canvas.height);
  std::FILE* f = std::fopen(png.c_str(), "rb");
  if (!f) throw IoError("cannot write " + png);
  std::fclose(f);
}

// Two-sided Lambert shade of a unit normal (NaN: mid grey).
Eigen::Vector3f shade(const Eigen::Vector3f& n, const Eigen::Vector3f& light) {
  const float l = isFinite(n) ? std::abs(n.dot(light)) : 0.5f;
  return Eigen::Vector3f::Constant(0.15f + 0.85f * l);
}

}  // namespace

void renderShaded(const Positions& points, const View& view, int width, const std::string& png) {
  SpatialIndex index(points);
  const NeighbourGraph g = NeighbourGraph::byCount(points, index, 12);
  renderShadedPanels({{points, estimateNormals(points, g)}}, view, width, png);
}

void renderShadedPanels(const std::vector<std::pair<Positions, Normals>>& panels, const View& view, int width,
                        const std::string& png) {
  const Eigen::Vector3f light = view.axes.transpose() * Eigen::Vector3f(-0.4f, 0.5f, 0.77f).normalized();
  Canvas canvas(width * static_cast<int>(panels.size()), heightFor(view, width));
  for (std::size_t k = 0; k < panels.size(); ++k) {
    const Normals& normals = panels[k].second;
    splat(panels[k].first, view, width, static_cast<int>(k) * width, canvas,
          [&](std::size_t i) { return shade(normals[i], light); });
  }
  save(canvas, png);
}

void renderValues(const Positions& points, const std::vector<double>& values, double vmax,
                  const View& view, int width, const std::string& png) {
  Canvas canvas(width, heightFor(view, width));
  splat(points, view, width, 0, canvas, [&](std::size_t i) {
    if (!std::isfinite(values[i])) return Eigen::Vector3f(0.6f, 0.6f, 0.6f);
    const float t = static_cast<float>(std::clamp(values[i] / vmax, 0.0, 1.0));
    // Blue -> cyan -> green -> yellow -> red (no grey in between).
    auto ramp = [](float x) { return std::clamp(1.5f - std::abs(x), 0.f, 1.f); };
    return Eigen::Vector3f(ramp(4.f * t - 3.f), ramp(4.f * t - 2.f), ramp(4.f * t - 1.f));
  });
  save(canvas, png);
}

}  // namespace paps::cli
