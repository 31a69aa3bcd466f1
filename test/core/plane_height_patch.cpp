// Tests of paps/core/plane_height_patch.h: sampling patterns, and descriptors of shapes whose
// heights are known (planes: zero; a paraboloid: a (u^2 + v^2) plus the kernel's bias).
#include <cmath>
#include <limits>
#include <numeric>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include <paps/core/error.h>
#include <paps/core/plane_height_patch.h>
#include <paps/core/random.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_plane_height_patch_test {

using paps::LocalFrame;
using paps::PlaneHeightPatch;
using paps::Positions;
using paps::SamplingPattern;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// Frame with normal n and t1 turned by `angle` (radians) from a fixed tangent.
LocalFrame frameWith(const Eigen::Vector3f& normal, float angle) {
  LocalFrame f;
  f.n = normal.normalized();
  const Eigen::Vector3f a = f.n.unitOrthogonal(), b = f.n.cross(a);
  f.t1 = std::cos(angle) * a + std::sin(angle) * b;
  f.t2 = f.n.cross(f.t1);
  return f;
}

/// Regular grid of points origin + x e1 + y e2 + height(x, y) e3 for x, y in [-half, half].
template <typename Height>
Positions surface(float half, float step, const Eigen::Vector3f& origin, const Eigen::Vector3f& e1,
                  const Eigen::Vector3f& e2, const Eigen::Vector3f& e3, Height height) {
  Positions p;
  const int n = static_cast<int>(std::round(2 * half / step));
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const float x = -half + i * step, y = -half + j * step;
      p.push_back(origin + x * e1 + y * e2 + height(x, y) * e3);
    }
  return p;
}

struct Descriptor {
  std::vector<float> heights;
  std::vector<std::uint8_t> valid;
  int n_valid = 0;
};

Descriptor describe(const PlaneHeightPatch& patch, const LocalFrame& frame,
                    const Eigen::Vector3f& origin, const Positions& points) {
  std::vector<int> all(points.size());
  std::iota(all.begin(), all.end(), 0);
  Descriptor d;
  d.heights.assign(patch.size(), kNaN);
  d.valid.assign(patch.size(), 7);
  d.n_valid = patch.describe(frame, origin, points, all.data(), static_cast<int>(all.size()),
                             d.heights.data(), d.valid.data());
  return d;
}

int countValid(const Descriptor& d) {
  int n = 0;
  for (auto v : d.valid) {
    EXPECT_TRUE(v == 0 || v == 1);
    n += v;
  }
  return n;
}

// ------------------------------------------------------------------ sampling patterns

TEST(SamplingPattern, GridSizeSpacingAndExtent) {
  for (int n = 1; n <= 9; ++n) {
    const SamplingPattern p = SamplingPattern::grid(n);
    ASSERT_EQ(p.size(), static_cast<std::size_t>(n * n));
    EXPECT_NEAR(p.spacing, std::sqrt(2.f) / n, 1e-6f);
    std::set<std::pair<float, float>> distinct;
    for (const auto& s : p.samples) {
      EXPECT_LE(s.norm(), 1.f) << "inside the unit disk";
      EXPECT_LT(std::abs(s.x()), std::sqrt(0.5f));  // inside the inscribed square
      EXPECT_LT(std::abs(s.y()), std::sqrt(0.5f));
      distinct.emplace(s.x(), s.y());
      // Symmetric under the half turn (both frame orientations share one pattern).
      bool mirrored = false;
      for (const auto& t : p.samples) mirrored = mirrored || (s + t).norm() < 1e-5f;
      EXPECT_TRUE(mirrored) << "grid " << n << " sample " << s.transpose();
    }
    EXPECT_EQ(distinct.size(), p.size());
  }
  const SamplingPattern one = SamplingPattern::grid(1);
  EXPECT_EQ(one.samples[0], Eigen::Vector2f::Zero());
}

TEST(SamplingPattern, GridOrderIsRowMajorAlongT1ThenT2) {
  const SamplingPattern p = SamplingPattern::grid(2);
  const float a = 0.5f / std::sqrt(2.f);
  ASSERT_EQ(p.size(), 4u);
  EXPECT_TRUE(p.samples[0].isApprox(Eigen::Vector2f(-a, -a), 1e-6f));
  EXPECT_TRUE(p.samples[1].isApprox(Eigen::Vector2f(a, -a), 1e-6f));
  EXPECT_TRUE(p.samples[2].isApprox(Eigen::Vector2f(-a, a), 1e-6f));
  EXPECT_TRUE(p.samples[3].isApprox(Eigen::Vector2f(a, a), 1e-6f));
}

TEST(SamplingPattern, RadialSizeRingsAndExtent) {
  for (int rings : {1, 2, 5}) {
    for (int sectors : {3, 6, 8, 13}) {
      const SamplingPattern p = SamplingPattern::radial(rings, sectors);
      ASSERT_EQ(p.size(), static_cast<std::size_t>(1 + rings * sectors));
      EXPECT_EQ(p.samples[0], Eigen::Vector2f::Zero());
      const float dr = 1.f / (rings + 0.5f);
      EXPECT_NEAR(p.spacing, dr, 1e-6f);
      for (int r = 1; r <= rings; ++r) {
        for (int s = 0; s < sectors; ++s) {
          const Eigen::Vector2f x = p.samples[1 + (r - 1) * sectors + s];
          EXPECT_NEAR(x.norm(), r * dr, 1e-5f) << "ring " << r;
          EXPECT_LT(x.norm(), 1.f);
        }
      }
    }
  }
}

TEST(SamplingPattern, InvalidSizes) {
  auto expectParameter = [](auto make, const char* name) {
    try {
      make();
      ADD_FAILURE() << name << " accepted";
    } catch (const paps::InvalidParameter& e) {
      EXPECT_EQ(e.parameter(), name);
    }
  };
  expectParameter([] { SamplingPattern::grid(0); }, "grid_size");
  expectParameter([] { SamplingPattern::grid(-2); }, "grid_size");
  expectParameter([] { SamplingPattern::grid(65); }, "grid_size");
  expectParameter([] { SamplingPattern::radial(0, 8); }, "rings");
  expectParameter([] { SamplingPattern::radial(65, 8); }, "rings");
  expectParameter([] { SamplingPattern::radial(2, 2); }, "sectors");
  expectParameter([] { SamplingPattern::radial(2, 257); }, "sectors");
  expectParameter([] { PlaneHeightPatch(SamplingPattern::grid(4), 0.f); }, "radius");
  expectParameter([] { PlaneHeightPatch(SamplingPattern::grid(4), -1.f); }, "radius");
  expectParameter([] { PlaneHeightPatch(SamplingPattern::grid(4), kNaN); }, "radius");
  expectParameter([] { PlaneHeightPatch(SamplingPattern::grid(4), 1.f, 0.f); }, "kernel_width");
  expectParameter([] { PlaneHeightPatch(SamplingPattern::grid(4), 1.f, -0.5f); }, "kernel_width");
  expectParameter([] { PlaneHeightPatch(SamplingPattern{}, 1.f); }, "pattern");
}

TEST(PlaneHeightPatch, Accessors) {
  const PlaneHeightPatch patch(SamplingPattern::radial(3, 8), 0.25f);
  EXPECT_EQ(patch.size(), 25u);
  EXPECT_EQ(patch.pattern().size(), 25u);
  EXPECT_EQ(patch.radius(), 0.25f);
}

// ------------------------------------------------------------------------ planes

TEST(PlaneHeightPatch, PlaneIsZeroForAnyFrameOrientation) {
  const Positions plane = surface(1.6f, 0.04f, Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(),
                                  Eigen::Vector3f::UnitY(), Eigen::Vector3f::UnitZ(),
                                  [](float, float) { return 0.f; });
  for (const SamplingPattern& pattern : {SamplingPattern::grid(4), SamplingPattern::radial(3, 8)}) {
    const PlaneHeightPatch patch(pattern, 1.f);
    for (float angle : {0.f, 0.3f, 0.785f, 1.7f, 3.14159f, 4.5f}) {
      for (const Eigen::Vector3f n : {Eigen::Vector3f(0, 0, 1), Eigen::Vector3f(0, 0, -1)}) {
        for (const Eigen::Vector3f& origin : {Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(0.2f, -0.3f, 0)}) {
          const Descriptor d = describe(patch, frameWith(n, angle), origin, plane);
          EXPECT_EQ(d.n_valid, static_cast<int>(patch.size()));
          EXPECT_EQ(countValid(d), d.n_valid);
          for (float h : d.heights) EXPECT_NEAR(h, 0.f, 1e-6f) << "angle " << angle;
        }
      }
    }
  }
}

TEST(PlaneHeightPatch, HeightsAreMeasuredFromTheOrigin) {
  // The same plane seen from an origin 0.1 below it: every height is +0.1 (or -0.1 when
  // the normal points down).
  const Positions plane = surface(1.6f, 0.04f, Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(),
                                  Eigen::Vector3f::UnitY(), Eigen::Vector3f::UnitZ(),
                                  [](float, float) { return 0.f; });
  const PlaneHeightPatch patch(SamplingPattern::grid(3), 1.f);
  const Descriptor up = describe(patch, frameWith(Eigen::Vector3f::UnitZ(), 0.4f),
                                 Eigen::Vector3f(0, 0, -0.1f), plane);
  const Descriptor down = describe(patch, frameWith(-Eigen::Vector3f::UnitZ(), 0.4f),
                                   Eigen::Vector3f(0, 0, -0.1f), plane);
  for (std::size_t s = 0; s < patch.size(); ++s) {
    EXPECT_NEAR(up.heights[s], 0.1f, 1e-6f);
    EXPECT_NEAR(down.heights[s], -0.1f, 1e-6f);
  }
}

TEST(PlaneHeightPatch, TiltedPlaneInItsOwnFrameIsZero) {
  const Eigen::Vector3f n = Eigen::Vector3f(1, 2, 3).normalized();
  const Eigen::Vector3f e1 = Eigen::Vector3f(3, 0, -1).normalized();  // in the plane
  const Eigen::Vector3f e2 = n.cross(e1);
  const Eigen::Vector3f origin(10.f, -4.f, 2.5f);
  const Positions plane = surface(0.8f, 0.02f, origin, e1, e2, n, [](float, float) { return 0.f; });
  const PlaneHeightPatch patch(SamplingPattern::grid(4), 0.5f);
  for (float angle : {0.f, 1.f, 2.5f}) {
    const Descriptor d = describe(patch, frameWith(n, angle), origin + 0.1f * e1, plane);
    EXPECT_EQ(d.n_valid, 16);
    for (float h : d.heights) EXPECT_NEAR(h, 0.f, 1e-5f);
  }
  // Seen in a frame tilted by 10 degrees about e1, the heights are -tan(10 deg) * v:
  // not zero, so the test above can fail.
  LocalFrame tilted;
  tilted.t1 = e1;
  tilted.n = Eigen::AngleAxisf(0.17453f, e1) * n;
  tilted.t2 = tilted.n.cross(tilted.t1);
  const Descriptor d = describe(patch, tilted, origin, plane);
  for (std::size_t s = 0; s < patch.size(); ++s) {
    const float v = patch.pattern().samples[s].y() * patch.radius();
    EXPECT_NEAR(d.heights[s], -std::tan(0.17453f) * v, 2e-3f) << "sample " << s;
  }
}

// -------------------------------------------------------------------- paraboloid

TEST(PlaneHeightPatch, ParaboloidHeights) {
  // z = a (x^2 + y^2) sampled densely; the normalised Gaussian kernel of width sigma
  // averages a (u^2 + v^2) into a (u^2 + v^2) + 2 a sigma^2 (exact for a quadratic on a
  // dense, regular sampling that extends past the kernel's reach).
  const float a = 0.5f, radius = 1.f;
  const Positions para = surface(1.8f, 0.02f, Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(),
                                 Eigen::Vector3f::UnitY(), Eigen::Vector3f::UnitZ(),
                                 [a](float x, float y) { return a * (x * x + y * y); });
  for (const SamplingPattern& pattern : {SamplingPattern::grid(4), SamplingPattern::radial(2, 6)}) {
    const float kernel_width = 0.6f;
    const PlaneHeightPatch patch(pattern, radius, kernel_width);
    const float sigma = kernel_width * pattern.spacing * radius;
    const float bias = 2 * a * sigma * sigma;
    for (float angle : {0.f, 0.9f, 2.f}) {  // the paraboloid is symmetric about z
      const Descriptor d = describe(patch, frameWith(Eigen::Vector3f::UnitZ(), angle),
                                    Eigen::Vector3f::Zero(), para);
      ASSERT_EQ(d.n_valid, static_cast<int>(patch.size()));
      for (std::size_t s = 0; s < patch.size(); ++s) {
        const Eigen::Vector2f uv = pattern.samples[s] * radius;
        const float expected = a * uv.squaredNorm();
        EXPECT_NEAR(d.heights[s], expected, bias + 1e-3f) << "sample " << s;
        EXPECT_NEAR(d.heights[s], expected + bias, 0.02f * bias + 1e-4f) << "sample " << s;
      }
    }
  }
}

TEST(PlaneHeightPatch, HeightsScaleWithTheShape) {
  const float a = 0.8f;
  auto make = [a](float scale) {
    return surface(1.6f * scale, 0.04f * scale, Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(),
                   Eigen::Vector3f::UnitY(), Eigen::Vector3f::UnitZ(),
                   [a, scale](float x, float y) { return a * (x * x - 0.5f * y * y) / scale; });
  };
  const Positions small = make(1.f), big = make(10.f);
  const Descriptor ds = describe(PlaneHeightPatch(SamplingPattern::grid(4), 1.f),
                                 frameWith(Eigen::Vector3f::UnitZ(), 0.2f), Eigen::Vector3f::Zero(), small);
  const Descriptor db = describe(PlaneHeightPatch(SamplingPattern::grid(4), 10.f),
                                 frameWith(Eigen::Vector3f::UnitZ(), 0.2f), Eigen::Vector3f::Zero(), big);
  float largest = 0;
  for (std::size_t s = 0; s < ds.heights.size(); ++s) {
    EXPECT_NEAR(db.heights[s], 10.f * ds.heights[s], 1e-3f) << s;
    largest = std::max(largest, std::abs(ds.heights[s]));
  }
  EXPECT_GT(largest, 0.05f);
}

TEST(PlaneHeightPatch, HalfTurnPermutesTheGrid) {
  // A shape without symmetry: the turned frame sees the sample s where the frame saw -s.
  const Positions p = surface(1.6f, 0.03f, Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(),
                              Eigen::Vector3f::UnitY(), Eigen::Vector3f::UnitZ(),
                              [](float x, float y) { return 0.3f * x + 0.1f * x * y + 0.2f * y * y * y; });
  const PlaneHeightPatch patch(SamplingPattern::grid(4), 1.f);
  const LocalFrame f = frameWith(Eigen::Vector3f::UnitZ(), 0.3f);
  const Descriptor d0 = describe(patch, f, Eigen::Vector3f::Zero(), p);
  const Descriptor d1 = describe(patch, f.rotatedHalfTurn(), Eigen::Vector3f::Zero(), p);
  for (std::size_t s = 0; s < 16; ++s) {
    EXPECT_NEAR(d1.heights[s], d0.heights[15 - s], 1e-5f) << s;
    EXPECT_GT(std::abs(d0.heights[s] - d0.heights[15 - s]), 1e-3f) << "the shape is not symmetric";
  }
}

// ------------------------------------------------------------------ invalid samples

TEST(PlaneHeightPatch, HalfDiskLeavesTheOtherHalfInvalid) {
  // About 60 neighbours over the disk (a realistic count), but only where x >= 0.
  const Positions full = surface(1.f, 0.2f, Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(),
                                 Eigen::Vector3f::UnitY(), Eigen::Vector3f::UnitZ(),
                                 [](float x, float y) { return 0.05f * x + 0.02f * y; });
  Positions half;
  for (const auto& x : full)
    if (x.x() >= -1e-6f && x.head<2>().norm() <= 1.f) half.push_back(x);
  const PlaneHeightPatch patch(SamplingPattern::grid(4), 1.f);
  const LocalFrame world;  // t1 = x, t2 = y, n = z
  const Descriptor d = describe(patch, world, Eigen::Vector3f::Zero(), half);
  int valid_right = 0, invalid_left = 0, far_left = 0;
  for (std::size_t s = 0; s < patch.size(); ++s) {
    const Eigen::Vector2f uv = patch.pattern().samples[s];
    if (uv.x() > 0) {
      EXPECT_TRUE(d.valid[s]) << "sample " << s << " over the covered half";
      valid_right += d.valid[s];
      if (d.valid[s]) EXPECT_NEAR(d.heights[s], 0.05f * uv.x() + 0.02f * uv.y(), 0.01f);
    } else if (uv.x() < -0.4f) {
      ++far_left;
      EXPECT_FALSE(d.valid[s]) << "sample " << s << " at u = " << uv.x() << " has no neighbour near";
      invalid_left += !d.valid[s];
    }
    if (!d.valid[s]) EXPECT_EQ(d.heights[s], 0.f) << "an invalid sample has height 0";
  }
  EXPECT_EQ(valid_right, 8);
  EXPECT_EQ(far_left, 4);
  EXPECT_EQ(invalid_left, 4);
  EXPECT_EQ(countValid(d), d.n_valid);
  EXPECT_LT(d.n_valid, 16);
}

TEST(PlaneHeightPatch, NoNeighboursNoValidSample) {
  const PlaneHeightPatch patch(SamplingPattern::radial(2, 6), 1.f);
  std::vector<float> h(patch.size(), 5.f);
  std::vector<std::uint8_t> v(patch.size(), 1);
  const Positions none;
  EXPECT_EQ(patch.describe(LocalFrame(), Eigen::Vector3f::Zero(), none, nullptr, 0, h.data(), v.data()), 0);
  for (std::size_t s = 0; s < patch.size(); ++s) {
    EXPECT_EQ(v[s], 0);
    EXPECT_EQ(h[s], 0.f);
  }
  // Neighbours far outside the patch count for nothing either.
  const Positions far = {{5, 5, 1}, {-5, 6, 2}, {7, -5, 0}};
  const Descriptor d = describe(patch, LocalFrame(), Eigen::Vector3f::Zero(), far);
  EXPECT_EQ(d.n_valid, 0);
}

TEST(PlaneHeightPatch, OnlyTheListedNeighboursCount) {
  // Points listed in `neighbours` are used, others ignored: list only the plane's points
  // of a cloud that also holds a far higher layer.
  Positions p = surface(1.4f, 0.05f, Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(),
                        Eigen::Vector3f::UnitY(), Eigen::Vector3f::UnitZ(), [](float, float) { return 0.f; });
  const int plane_count = static_cast<int>(p.size());
  for (int i = 0; i < plane_count; ++i) p.push_back(p[i] + Eigen::Vector3f(0, 0, 1));
  std::vector<int> first(plane_count);
  std::iota(first.begin(), first.end(), 0);
  const PlaneHeightPatch patch(SamplingPattern::grid(3), 1.f);
  std::vector<float> h(patch.size());
  std::vector<std::uint8_t> v(patch.size());
  EXPECT_EQ(patch.describe(LocalFrame(), Eigen::Vector3f::Zero(), p, first.data(), plane_count, h.data(), v.data()), 9);
  for (float x : h) EXPECT_NEAR(x, 0.f, 1e-6f);
  const Descriptor both = describe(patch, LocalFrame(), Eigen::Vector3f::Zero(), p);
  for (float x : both.heights) EXPECT_NEAR(x, 0.5f, 1e-5f);
}

}  // namespace core_plane_height_patch_test
