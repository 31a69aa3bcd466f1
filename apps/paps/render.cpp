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

namespace {
// The view along `axes`, its screen bounds those of the finite points.
View framed(const Eigen::Matrix3f& axes, const Positions& points) {
  View v;
  v.axes = axes;
  v.lo = Eigen::Vector2f::Constant(std::numeric_limits<float>::max());
  v.hi = -v.lo;
  for (const auto& p : points)
    if (isFinite(p)) {
      const Eigen::Vector3f s = v.axes * p;
      v.lo = v.lo.cwiseMin(s.head<2>());
      v.hi = v.hi.cwiseMax(s.head<2>());
    }
  if (!(v.lo.x() <= v.hi.x())) throw InvalidInput("nothing to render");
  return v;
}
}  // namespace

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
  return framed(tilt * a, points);
}

View View::looking(const Positions& points, const Eigen::Vector3f& towards_viewer, const Eigen::Vector3f& up) {
  const Eigen::Vector3f d = towards_viewer.normalized();
  const Eigen::Vector3f x = up.cross(d);
  if (!(x.norm() > 1e-6f) || !isFinite(d)) throw InvalidParameter("view", "up parallel to the view", "two directions apart");
  Eigen::Matrix3f axes;
  axes.row(0) = x.normalized().transpose();
  axes.row(2) = d.transpose();
  axes.row(1) = d.cross(x.normalized()).transpose();
  return framed(axes, points);
}

namespace {

int heightFor(const View& view, int width) {
  const Eigen::Vector2f ext = (view.hi - view.lo).cwiseMax(1e-12f);
  return std::max(1, static_cast<int>(width * ext.y() / ext.x()));
}

// Splats every point as a square block with a z-buffer into the panel of `panel_width`
// columns starting at column `offset`; colour from `colour(i)`.
template <typename ColourFn>
void splat(const Positions& points, const View& view, int panel_width, int offset, Image& image, ColourFn colour) {
  const Eigen::Vector2f ext = (view.hi - view.lo).cwiseMax(1e-12f);
  const int width = panel_width, height = image.height;
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
        const std::size_t o = (static_cast<std::size_t>(y + dy) * image.width + offset + x + dx) * 3;
        for (int ch = 0; ch < 3; ++ch)
          image.rgb[o + ch] = static_cast<unsigned char>(std::clamp(c[ch], 0.f, 1.f) * 255.f);
      }
  }
}

// PCL's PNG writer reports nothing when it fails (e.g. a missing folder): check the file.
void save(const Image& image, const std::string& png) {
  std::remove(png.c_str());
  pcl::io::saveRgbPNGFile(png, image.rgb.data(), image.width, image.height);
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
  Image image(width * static_cast<int>(panels.size()), heightFor(view, width));
  for (std::size_t k = 0; k < panels.size(); ++k) {
    const Normals& normals = panels[k].second;
    splat(panels[k].first, view, width, static_cast<int>(k) * width, image,
          [&](std::size_t i) { return shade(normals[i], light); });
  }
  save(image, png);
}

void renderMeshPanels(const std::vector<TriangleMesh>& meshes, const View& view, int width, const std::string& png) {
  save(drawMeshPanels(meshes, view, width), png);
}

Image drawMeshPanels(const std::vector<TriangleMesh>& meshes, const View& view, int width) {
  const Eigen::Vector3f light = view.axes.transpose() * Eigen::Vector3f(-0.4f, 0.5f, 0.77f).normalized();
  const int height = heightFor(view, width);
  const Eigen::Vector2f ext = (view.hi - view.lo).cwiseMax(1e-12f);
  // A 2% margin, so that edges on the border of the view show (of the shorter side: a view
  // of a flat mesh may be one row high).
  const float margin = 0.02f * static_cast<float>(std::min(width, height));
  const float scale = std::min((width - 2 * margin) / ext.x(), (height - 2 * margin) / ext.y());
  Image image(width * static_cast<int>(meshes.size()), height);
  for (std::size_t k = 0; k < meshes.size(); ++k) {
    const TriangleMesh& mesh = meshes[k];
    std::vector<float> depth(static_cast<std::size_t>(width) * height, -std::numeric_limits<float>::max());
    std::vector<Eigen::Vector3f> screen(mesh.vertices.size());
    for (std::size_t i = 0; i < screen.size(); ++i) {
      const Eigen::Vector3f s = view.axes * mesh.vertices[i];
      screen[i] = {margin + (s.x() - view.lo.x()) * scale, margin + (view.hi.y() - s.y()) * scale, s.z()};
    }
    // Edges only where facets are large on screen (a dense mesh would turn dark).
    double covered = 0;
    for (const Eigen::Vector3i& t : mesh.triangles)
      if (t.minCoeff() >= 0 && t.maxCoeff() < static_cast<int>(screen.size())) {
        const Eigen::Vector3f u = screen[t[1]] - screen[t[0]], v = screen[t[2]] - screen[t[0]];
        covered += 0.5 * std::abs(static_cast<double>(u.x() * v.y() - u.y() * v.x()));
      }
    const bool edges = !mesh.triangles.empty() && covered / static_cast<double>(mesh.triangles.size()) >= 40.0;
    for (const Eigen::Vector3i& t : mesh.triangles) {
      if (t.minCoeff() < 0 || t.maxCoeff() >= static_cast<int>(screen.size())) continue;
      const Eigen::Vector3f a = screen[static_cast<std::size_t>(t[0])], b = screen[static_cast<std::size_t>(t[1])],
                            c = screen[static_cast<std::size_t>(t[2])];
      if (!isFinite(a) || !isFinite(b) || !isFinite(c)) continue;
      // Twice the signed area on screen; a facet seen edge-on covers no pixel centre.
      const float area2 = (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
      if (std::abs(area2) < 1e-9f) continue;
      const Eigen::Vector3f& pa = mesh.vertices[static_cast<std::size_t>(t[0])];
      const Eigen::Vector3f n = (mesh.vertices[static_cast<std::size_t>(t[1])] - pa)
                                    .cross(mesh.vertices[static_cast<std::size_t>(t[2])] - pa)
                                    .normalized();
      const Eigen::Vector3f fill = shade(n, light);
      // Pixel distance to each edge = barycentric weight x twice the area / the edge's length.
      const float len[3] = {(c - b).head<2>().norm(), (a - c).head<2>().norm(), (b - a).head<2>().norm()};
      const int x0 = std::max(0, static_cast<int>(std::floor(std::min({a.x(), b.x(), c.x()}))));
      const int x1 = std::min(width - 1, static_cast<int>(std::ceil(std::max({a.x(), b.x(), c.x()}))));
      const int y0 = std::max(0, static_cast<int>(std::floor(std::min({a.y(), b.y(), c.y()}))));
      const int y1 = std::min(height - 1, static_cast<int>(std::ceil(std::max({a.y(), b.y(), c.y()}))));
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const float px = x + 0.5f, py = y + 0.5f;
          const float w[3] = {((b.x() - px) * (c.y() - py) - (b.y() - py) * (c.x() - px)) / area2,
                              ((c.x() - px) * (a.y() - py) - (c.y() - py) * (a.x() - px)) / area2,
                              ((a.x() - px) * (b.y() - py) - (a.y() - py) * (b.x() - px)) / area2};
          if (w[0] < 0 || w[1] < 0 || w[2] < 0) continue;
          const float z = w[0] * a.z() + w[1] * b.z() + w[2] * c.z();
          const std::size_t d = static_cast<std::size_t>(y) * width + x;
          if (z <= depth[d]) continue;
          depth[d] = z;
          float edge = INFINITY;
          for (int e = 0; e < 3; ++e)
            if (len[e] > 0) edge = std::min(edge, w[e] * std::abs(area2) / len[e]);
          const Eigen::Vector3f colour = edges && edge < 0.8f ? Eigen::Vector3f(0.1f, 0.1f, 0.35f) : fill;
          const std::size_t o = (static_cast<std::size_t>(y) * image.width + static_cast<std::size_t>(k) * width + x) * 3;
          for (int ch = 0; ch < 3; ++ch)
            image.rgb[o + ch] = static_cast<unsigned char>(std::clamp(colour[ch], 0.f, 1.f) * 255.f);
        }
    }
  }
  return image;
}

void renderValues(const Positions& points, const std::vector<double>& values, double vmax,
                  const View& view, int width, const std::string& png) {
  Image image(width, heightFor(view, width));
  splat(points, view, width, 0, image, [&](std::size_t i) {
    if (!std::isfinite(values[i])) return Eigen::Vector3f(0.6f, 0.6f, 0.6f);
    const float t = static_cast<float>(std::clamp(values[i] / vmax, 0.0, 1.0));
    // Blue -> cyan -> green -> yellow -> red (no grey in between).
    auto ramp = [](float x) { return std::clamp(1.5f - std::abs(x), 0.f, 1.f); };
    return Eigen::Vector3f(ramp(4.f * t - 3.f), ramp(4.f * t - 2.f), ramp(4.f * t - 1.f));
  });
  save(image, png);
}

}  // namespace paps::cli
