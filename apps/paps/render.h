#pragma once
// Point renders for the bench and demo pictures: orthographic splats with a z-buffer,
// Lambert-shaded by PCA normals (noise shows as speckle) or coloured by a per-point value.
#include <string>
#include <utility>
#include <vector>

#include <paps/core/positions.h>

namespace paps::cli {

/// An orthographic view: screen x, screen y and depth axes (rows), fitted to a cloud.
struct View {
  Eigen::Matrix3f axes = Eigen::Matrix3f::Identity();
  Eigen::Vector2f lo{0, 0}, hi{1, 1};
  /// Looks along the direction of least extent of the points (e.g. down on a terrain),
  /// tilted by `tilt_degrees` about the screen x axis so that relief shows.
  static View fit(const Positions& points, float tilt_degrees = 0.f);
};

/// Shaded render (grey, light from the viewer's upper left). Writes a PNG; throws IoError.
void renderShaded(const Positions& points, const View& view, int width, const std::string& png);

/// Side-by-side panels in one view, each shaded by its own normals (e.g. normals a filter
/// changed). Writes a PNG; throws IoError.
void renderShadedPanels(const std::vector<std::pair<Positions, Normals>>& panels, const View& view, int width,
                        const std::string& png);

/// Render coloured by `values` mapped on a blue-to-red scale over [0, vmax] (NaN: grey).
void renderValues(const Positions& points, const std::vector<double>& values, double vmax,
                  const View& view, int width, const std::string& png);

}  // namespace paps::cli
