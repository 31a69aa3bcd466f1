#include <paps/fusion/point_visibility.h>

#include <cmath>
#include <limits>

#include <paps/core/error.h>

namespace paps {

void VisibilityParameters::validate() const {
  requireInRange("visibility window_radius", window_radius, 0, 64);
  requireInRange("visibility depth_tolerance", depth_tolerance, 0.0, 0.99);
  requireInRange("visibility min_sectors", min_sectors, 1, 8);
}

std::size_t ProjectedPoints::visibleCount() const {
  std::size_t n = 0;
  for (auto v : visible) n += v;
  return n;
}

ProjectedPoints projectVisiblePoints(const Positions& points, const CameraIntrinsics& camera, const CameraPose& pose,
                                     const VisibilityParameters& parameters) {
  camera.validate();
  parameters.validate();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const long n = static_cast<long>(points.size());
  ProjectedPoints out;
  out.pixel.assign(points.size(), Eigen::Vector2f(nan, nan));
  out.depth.assign(points.size(), nan);
  out.visible.assign(points.size(), 0);
  const Eigen::Isometry3d world_to_camera = pose.inverse();
  std::vector<int> cell(points.size(), -1);
#pragma omp parallel for schedule(static)
  for (long i = 0; i < n; ++i) {
    if (!isFinite(points[i])) continue;
    const Eigen::Vector3d c = world_to_camera * points[i].cast<double>();
    Eigen::Vector2d px;
    if (!camera.project(c, px) || !camera.inside(px)) continue;
    out.pixel[i] = px.cast<float>();
    out.depth[i] = static_cast<float>(c.z());
    cell[i] = static_cast<int>(std::lround(px.y())) * camera.width + static_cast<int>(std::lround(px.x()));
  }
  // Nearest depth per pixel (the minimum is order independent, so this is deterministic).
  std::vector<float> nearest(static_cast<std::size_t>(camera.width) * camera.height, INFINITY);
  for (long i = 0; i < n; ++i)
    if (cell[i] >= 0) nearest[cell[i]] = std::min(nearest[cell[i]], out.depth[i]);

  const int r = parameters.window_radius;
  const float keep = static_cast<float>(1 - parameters.depth_tolerance);
#pragma omp parallel for schedule(static)
  for (long i = 0; i < n; ++i) {
    if (cell[i] < 0) continue;
    const float front = out.depth[i] * keep;
    if (nearest[cell[i]] < front) continue;  // a nearer point in its own pixel
    const int x = cell[i] % camera.width, y = cell[i] / camera.width;
    unsigned sectors = 0;
    for (int dy = -r; dy <= r; ++dy) {
      const int yy = y + dy;
      if (yy < 0 || yy >= camera.height) continue;
      for (int dx = -r; dx <= r; ++dx) {
        const int xx = x + dx;
        if ((dx == 0 && dy == 0) || xx < 0 || xx >= camera.width || dx * dx + dy * dy > r * r) continue;
        if (!(nearest[static_cast<std::size_t>(yy) * camera.width + xx] < front)) continue;
        const double angle = std::atan2(static_cast<double>(dy), static_cast<double>(dx)) + M_PI;  // [0, 2 pi]
        sectors |= 1u << (static_cast<int>(angle / (M_PI / 4)) & 7);
      }
    }
    int count = 0;
    for (int s = 0; s < 8; ++s) count += (sectors >> s) & 1u;
    out.visible[i] = count >= parameters.min_sectors ? 0 : 1;
  }
  return out;
}

}  // namespace paps
