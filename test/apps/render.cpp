// The mesh pictures of the bench (apps/paps/render.cpp): coverage, depth order, edges, views.
#include "render.h"

#include <gtest/gtest.h>

#include <paps/core/error.h>

namespace paps::cli {
namespace {

bool isWhite(const unsigned char* p) { return p[0] == 255 && p[1] == 255 && p[2] == 255; }

double drawnShare(const Image& image, int x0, int x1) {
  std::size_t drawn = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = x0; x < x1; ++x) drawn += !isWhite(image.at(x, y));
  return static_cast<double>(drawn) / (static_cast<double>(x1 - x0) * image.height);
}

// A grid of n x n squares (2 n^2 facets) over [0, 1]^2 at height z.
TriangleMesh grid(int n, float z = 0.f) {
  TriangleMesh m;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.vertices.emplace_back(float(i) / n, float(j) / n, z);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      m.triangles.emplace_back(a, b, d);
      m.triangles.emplace_back(a, d, c);
    }
  return m;
}

const View kTop = View::looking(grid(1).vertices, Eigen::Vector3f::UnitZ(), Eigen::Vector3f::UnitY());

TEST(MeshPicture, ASquareFillsTheViewInsideTheMargin) {
  const Image image = drawMeshPanels({grid(1)}, kTop, 200);
  ASSERT_EQ(image.width, 200);
  ASSERT_EQ(image.height, 200);
  // The square spans the panel but for a 2% margin on each side: 0.96^2 of the pixels.
  EXPECT_NEAR(drawnShare(image, 0, 200), 0.96 * 0.96, 0.02);
  EXPECT_TRUE(isWhite(image.at(1, 1)));
  EXPECT_FALSE(isWhite(image.at(100, 100)));
}

TEST(MeshPicture, OneTriangleCoversHalfTheSquare) {
  TriangleMesh half = grid(1);
  half.triangles.resize(1);  // (0,0) (1,0) (1,1): below the diagonal, the right half on screen
  const Image image = drawMeshPanels({half}, kTop, 200);
  EXPECT_NEAR(drawnShare(image, 0, 200), 0.5 * 0.96 * 0.96, 0.02);
  EXPECT_FALSE(isWhite(image.at(180, 150)));  // x near 1, y near 0 (the bottom of the picture)
  EXPECT_TRUE(isWhite(image.at(20, 50)));     // x near 0, y near 1
}

TEST(MeshPicture, TheNearerFacetShowsWhateverTheOrder) {
  // A flat square, and above it a smaller square tilted by 60 degrees: shaded differently.
  TriangleMesh scene = grid(1);
  TriangleMesh tilted = grid(1, 0.f);
  for (auto& v : tilted.vertices) v = Eigen::Vector3f(0.25f + 0.5f * v.x(), 0.25f + 0.5f * v.y(), 1.f + 0.8f * v.y());
  scene.append(tilted);
  TriangleMesh reversed = scene;
  std::reverse(reversed.triangles.begin(), reversed.triangles.end());
  const Image a = drawMeshPanels({scene}, kTop, 200), b = drawMeshPanels({reversed}, kTop, 200);
  EXPECT_EQ(a.rgb, b.rgb);
  const unsigned char* flat = a.at(15, 15);
  const unsigned char* near = a.at(100, 60);  // off both diagonals
  EXPECT_FALSE(isWhite(flat));
  EXPECT_NE(int(flat[0]), int(near[0]));  // the tilted square hides the flat one there
  // Without the tilted square the centre has the flat shade.
  EXPECT_EQ(int(drawMeshPanels({grid(1)}, kTop, 200).at(100, 60)[0]), int(flat[0]));
}

TEST(MeshPicture, EdgesShowOnLargeFacetsOnly) {
  auto darkPixels = [](const Image& image) {
    std::size_t n = 0;
    for (int y = 0; y < image.height; ++y)
      for (int x = 0; x < image.width; ++x) n += image.at(x, y)[2] > image.at(x, y)[0] + 40;  // edge blue
    return n;
  };
  // 2 facets: the diagonal and the border are drawn, about 5 lines of 190 pixels.
  const std::size_t coarse = darkPixels(drawMeshPanels({grid(1)}, kTop, 200));
  EXPECT_GT(coarse, 400u);
  EXPECT_LT(coarse, 2000u);
  // 20,000 facets of under 2 pixels each: no edges, the surface stays grey.
  EXPECT_EQ(darkPixels(drawMeshPanels({grid(100)}, kTop, 200)), 0u);
}

TEST(MeshPicture, PanelsSideBySideAndAnEmptyMeshLeavesItsPanelWhite) {
  const Image image = drawMeshPanels({grid(1), TriangleMesh(), grid(1)}, kTop, 120);
  ASSERT_EQ(image.width, 360);
  EXPECT_GT(drawnShare(image, 0, 120), 0.85);
  EXPECT_EQ(drawnShare(image, 120, 240), 0.0);
  EXPECT_GT(drawnShare(image, 240, 360), 0.85);
  // A facet with an index out of range is skipped, not read.
  TriangleMesh bad = grid(1);
  bad.triangles.emplace_back(0, 1, 99);
  EXPECT_EQ(drawMeshPanels({bad}, kTop, 120).rgb, drawMeshPanels({grid(1)}, kTop, 120).rgb);
}

TEST(MeshPicture, ViewsFromADirection) {
  // Up parallel to the view, or nothing to fit, is an error; from +x with z up a wall x = 0 fills the panel.
  EXPECT_THROW(View::looking(grid(1).vertices, Eigen::Vector3f::UnitZ(), Eigen::Vector3f::UnitZ()), InvalidParameter);
  EXPECT_THROW(View::looking({}, Eigen::Vector3f::UnitZ(), Eigen::Vector3f::UnitY()), InvalidInput);
  TriangleMesh wall = grid(1);
  for (auto& v : wall.vertices) v = Eigen::Vector3f(0.f, v.x(), v.y());
  const View side = View::looking(wall.vertices, Eigen::Vector3f::UnitX(), Eigen::Vector3f::UnitZ());
  // Screen x is y (up z cross view x), screen y is z: the wall fills the panel.
  EXPECT_NEAR(side.axes.row(0).dot(Eigen::Vector3f::UnitY()), 1.f, 1e-6f);
  EXPECT_NEAR(side.axes.row(1).dot(Eigen::Vector3f::UnitZ()), 1.f, 1e-6f);
  EXPECT_NEAR(drawnShare(drawMeshPanels({wall}, side, 100), 0, 100), 0.96 * 0.96, 0.03);
  // A strip 100 times longer than wide: a picture 2 rows high, still drawn.
  TriangleMesh strip = grid(1);
  for (auto& v : strip.vertices) v.y() *= 0.01f;
  const Image thin = drawMeshPanels({strip}, View::looking(strip.vertices, Eigen::Vector3f::UnitZ(), Eigen::Vector3f::UnitY()), 200);
  ASSERT_EQ(thin.height, 2);
  EXPECT_GT(drawnShare(thin, 0, 200), 0.9);
}

}  // namespace
}  // namespace paps::cli
