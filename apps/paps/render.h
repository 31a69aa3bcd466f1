#pragma once
// Point renders for the bench and demo pictures: orthographic splats with a z-buffer,
// Lambert-shaded by PCA normals (noise shows as speckle) or coloured by a per-point value.
#include <string>
#include <utility>
#include <vector>

#include <paps/core/positions.h>
#include <paps/core/triangle_mesh.h>

namespace paps::cli {

/// An orthographic view: screen x, screen y and depth axes (rows), fitted to a cloud.
struct View {
  Eigen::Matrix3f axes = Eigen::Matrix3f::Identity();
  Eigen::Vector2f lo{0, 0}, hi{1, 1};
  /// Looks along the direction of least extent of the points (e.g. down on a terrain),
  /// tilted by `tilt_degrees` about the screen x axis so that relief shows.
  static View fit(const Positions& points, float tilt_degrees = 0.f);
  /// Looks at the points from `towards_viewer` (a direction from the scene to the eye), with
  /// `up` (not parallel to it) pointing up on screen.
  static View looking(const Positions& points, const Eigen::Vector3f& towards_viewer,
                      const Eigen::Vector3f& up = Eigen::Vector3f::UnitZ());
};

/// An RGB picture, 8 bits a channel, rows top to bottom; white where nothing is drawn.
struct Image {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;
  Image(int w, int h) : width(w), height(h), rgb(static_cast<std::size_t>(w) * h * 3, 255) {}
  const unsigned char* at(int x, int y) const { return &rgb[(static_cast<std::size_t>(y) * width + x) * 3]; }
};

/// Shaded render (grey, light from the viewer's upper left). Writes a PNG; throws IoError.
void renderShaded(const Positions& points, const View& view, int width, const std::string& png);

/// Side-by-side panels in one view, each shaded by its own normals (e.g. normals a filter
/// changed). Writes a PNG; throws IoError.
void renderShadedPanels(const std::vector<std::pair<Positions, Normals>>& panels, const View& view, int width,
                        const std::string& png);

/// Side-by-side panels of triangle meshes in one view: facets flat-shaded on both sides
/// (our complexes are not consistently oriented), their edges drawn dark so that the
/// decimation shows. An empty mesh leaves its panel white. Writes a PNG; throws IoError.
void renderMeshPanels(const std::vector<TriangleMesh>& meshes, const View& view, int width, const std::string& png);
/// The same picture in memory (panels `width` pixels wide, a 2% margin around the view).
Image drawMeshPanels(const std::vector<TriangleMesh>& meshes, const View& view, int width);

/// Render coloured by `values` mapped on a blue-to-red scale over [0, vmax] (NaN: grey).
void renderValues(const Positions& points, const std::vector<double>& values, double vmax,
                  const View& view, int width, const std::string& png);

}  // namespace paps::cli
