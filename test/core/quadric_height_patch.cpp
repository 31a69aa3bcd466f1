// Known answers: paraboloid, sphere and saddle curvatures; a plane falls back.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <Eigen/SVD>

#include <paps/core/irls.h>
#include <paps/core/quadric_height_patch.h>
#include <paps/core/random.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_quadric_height_patch_test {

using namespace paps;

// Points of z = f(x, y) on a jittered grid of half-width h around the origin.
template <typename F>
Positions heightField(F f, float h, int n, float noise = 0.f, std::uint64_t seed = 3) {
  Positions p;
  Random rng(seed);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const float x = -h + 2 * h * (i + 0.5f * static_cast<float>(rng.uniform())) / n;
      const float y = -h + 2 * h * (j + 0.5f * static_cast<float>(rng.uniform())) / n;
      p.emplace_back(x, y, f(x, y) + noise * static_cast<float>(rng.gaussian()));
    }
  return p;
}

std::vector<int> all(const Positions& p) {
  std::vector<int> v(p.size());
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = static_cast<int>(i);
  return v;
}

TEST(QuadricFit, ParaboloidCurvatures) {
  // z = (3 x^2 + 1 y^2) / 2: k1 = 3, k2 = 1 at the apex, t1 along x.
  const Positions p = heightField([](float x, float y) { return 0.5f * (3 * x * x + y * y); }, 0.1f, 20);
  const auto nb = all(p);
  const Eigen::Vector3f up = Eigen::Vector3f::UnitZ();
  const QuadricFit f = fitQuadric(p, Eigen::Vector3f::Zero(), nb.data(), static_cast<int>(nb.size()), 0.1f, &up);
  EXPECT_EQ(f.status, QuadricFit::Status::Quadric);
  EXPECT_NEAR(f.k1, 3.f, 0.05f);
  EXPECT_NEAR(f.k2, 1.f, 0.05f);
  EXPECT_NEAR(std::abs(f.frame.t1.x()), 1.f, 1e-3f);
  EXPECT_NEAR(f.frame.n.z(), 1.f, 1e-3f);
  EXPECT_NEAR(f.frame.t1.cross(f.frame.t2).dot(f.frame.n), 1.f, 1e-4f);
}

TEST(QuadricFit, SphereCurvatureIsOneOverRadius) {
  const float r = 2.f;
  // Lower cap of a sphere centred at (0, 0, r): normal up (towards the centre), k = 1 / r.
  const Positions p = heightField([r](float x, float y) { return r - std::sqrt(r * r - x * x - y * y); }, 0.2f, 24);
  const auto nb = all(p);
  const Eigen::Vector3f up = Eigen::Vector3f::UnitZ();
  const QuadricFit f = fitQuadric(p, Eigen::Vector3f(0.01f, -0.02f, 0.f), nb.data(), static_cast<int>(nb.size()), 0.2f, &up);
  EXPECT_EQ(f.status, QuadricFit::Status::Quadric);
  EXPECT_NEAR(f.k1, 0.5f, 0.01f);
  EXPECT_NEAR(f.k2, 0.5f, 0.01f);
}

TEST(QuadricFit, SaddleAndRobustToOutliers) {
  // z = x y: principal curvatures +1 and -1, directions at 45 degrees.
  Positions p = heightField([](float x, float y) { return x * y; }, 0.1f, 20, 0.f);
  for (int k = 0; k < 20; ++k) p[k * 17].z() += 0.05f;  // 5% gross outliers
  const auto nb = all(p);
  const Eigen::Vector3f up = Eigen::Vector3f::UnitZ();
  const QuadricFit f = fitQuadric(p, Eigen::Vector3f::Zero(), nb.data(), static_cast<int>(nb.size()), 0.1f, &up);
  EXPECT_NEAR(f.k1, 1.f, 0.05f);
  EXPECT_NEAR(f.k2, -1.f, 0.05f);
  EXPECT_NEAR(std::abs(f.frame.t1.x()), std::sqrt(0.5f), 0.02f);
}

TEST(QuadricFit, PlaneFallsBack) {
  const Positions p = heightField([](float, float) { return 0.f; }, 0.1f, 10);
  const auto nb = all(p);
  const QuadricFit f = fitQuadric(p, Eigen::Vector3f::Zero(), nb.data(), static_cast<int>(nb.size()), 0.1f);
  EXPECT_EQ(f.status, QuadricFit::Status::FlatPlane);
  EXPECT_TRUE(f.isPlaneFallback());
  EXPECT_EQ(f.k1, 0.f);
  EXPECT_NEAR(std::abs(f.frame.n.z()), 1.f, 1e-4f);
}

TEST(QuadricFit, IllPosedCases) {
  Positions line;
  for (int i = 0; i < 10; ++i) line.emplace_back(0.01f * i, 0.f, 0.f);
  const auto nb = all(line);
  EXPECT_EQ(fitQuadric(line, line[0], nb.data(), 10, 0.1f).status, QuadricFit::Status::Degenerate);
  Positions few = {{0, 0, 0}, {0.01f, 0, 0}, {0, 0.01f, 0}, {0.01f, 0.01f, 0.001f}};
  const auto nb2 = all(few);
  EXPECT_EQ(fitQuadric(few, few[0], nb2.data(), 4, 0.1f).status, QuadricFit::Status::TooFewPoints);
  EXPECT_THROW(fitQuadric(few, few[0], nb2.data(), 4, -1.f), InvalidParameter);
}

TEST(QuadricHeightPatch, GeodesicBinsAndHeights) {
  EXPECT_NEAR(parabolaAbscissaForArcLength(0.f, 0.3f), 0.3f, 1e-6f);
  // Arc length of y = x^2 from 0 to 1 is 1.4789.
  EXPECT_NEAR(parabolaAbscissaForArcLength(1.f, 1.47894286f), 1.f, 1e-4f);
  EXPECT_NEAR(parabolaAbscissaForArcLength(1.f, -1.47894286f), -1.f, 1e-4f);
  // A cylinder-like quadric with a small bump: heights are the bump, not the curvature.
  auto surf = [](float x, float y) { return 0.5f * 4.f * x * x + 0.002f * std::cos(60.f * y); };
  const Positions p = heightField(surf, 0.12f, 40);
  const auto nb = all(p);
  const Eigen::Vector3f up = Eigen::Vector3f::UnitZ();
  const QuadricFit f = fitQuadric(p, Eigen::Vector3f::Zero(), nb.data(), static_cast<int>(nb.size()), 0.1f, &up);
  const QuadricHeightPatch patch(5, 0.1f, 0.6f, 1);
  std::vector<float> h(patch.size());
  std::vector<std::uint8_t> v(patch.size());
  EXPECT_EQ(patch.describe(f, p, nb.data(), static_cast<int>(nb.size()), h.data(), v.data()), 25);
  // Rows run along t2 (y), the bump's direction. The large-scale curvature (up to 0.01 m) is
  // gone: a row is flat along x (its ends equal), and the rows follow the bump, whose
  // 0.002 cos(60 y) differs by 3.9 mm between the centre row (y = 0) and the first (y = -2
  // bins = -5.7 cm), less the kernel's smoothing (measured 3.0 mm).
  EXPECT_NEAR(h[10], h[14], 2e-4f);
  EXPECT_NEAR(h[12] - h[2], 0.0030f, 5e-4f);
  EXPECT_NEAR(h[12] - h[22], 0.0030f, 5e-4f);
  // Bins along t1 are geodesically equidistant on the curve z = k1 x^2 / 2: the arc length
  // between neighbours (closed form) is the bin spacing. Bins evenly spaced in x instead would
  // be 1.3% off.
  std::vector<Eigen::Vector3f> c(patch.size());
  patch.binCentres(f, c.data());
  const double a = 0.5 * f.k1;
  ASSERT_GT(a, 1.5);
  auto arc = [a](double x) { return 0.5 * x * std::sqrt(1 + 4 * a * a * x * x) + std::asinh(2 * a * x) / (4 * a); };
  for (int k = 0; k + 1 < 5; ++k)
    EXPECT_NEAR(arc(c[k + 1].x()) - arc(c[k].x()), patch.binSpacing(), 1e-3 * patch.binSpacing()) << k;
}

// The conditioning of the regression tells a ball that covers the disc from one whose points lie
// along lines (scan lines), whatever their count, and does not depend on the scale.
TEST(QuadricFit, ConditioningSeparatesDiscsFromLines) {
  auto fit = [](const Positions& p, float radius) {
    const auto nb = all(p);
    return fitQuadric(p, Eigen::Vector3f::Zero(), nb.data(), static_cast<int>(p.size()), radius);
  };
  // A saddle sampled over the whole ball of radius 0.1.
  Positions disc;
  for (const auto& p : heightField([](float x, float y) { return 0.2f * (x * x - y * y); }, 0.1f, 14))
    if (p.head<2>().norm() <= 0.1f) disc.push_back(p);
  const float c_disc = fit(disc, 0.1f).conditioning;
  EXPECT_GT(c_disc, 3e-3f);
  Positions half;
  for (const auto& p : disc) if (p.x() >= 0) half.push_back(p);
  const float c_half = fit(half, 0.1f).conditioning;
  EXPECT_LT(c_half, c_disc);
  EXPECT_GT(c_half, 1e-3f);  // a rim is not thin
  // Two parallel lines 0.05 apart, 40 points each, 0.1 mm of noise: thin.
  Random rng(7);
  Positions lines;
  for (int l = 0; l < 2; ++l)
    for (int i = 0; i < 40; ++i)
      lines.emplace_back(-0.08f + 0.004f * i, -0.025f + 0.05f * l, 1e-4f * static_cast<float>(rng.gaussian()));
  EXPECT_LT(fit(lines, 0.1f).conditioning, 1e-4f);
  // Scaled by 10 (points and radius): the same conditioning.
  Positions big = disc;
  for (auto& p : big) p *= 10.f;
  EXPECT_NEAR(fit(big, 1.f).conditioning, c_disc, 1e-3f * c_disc);
  // Stopped before the regression: 0.
  Positions few = {{0, 0, 0}, {0.01f, 0, 0}, {0, 0.01f, 0}};
  EXPECT_EQ(fit(few, 0.1f).conditioning, 0.f);
}

// solveIrlsL1: a full-rank system is solved exactly, and the l1 passes shrug off a gross
// outlier that plain least squares follows; a rank-deficient one reports false and gives the
// minimum-norm least-squares solution (the pseudo-inverse's, computed here by SVD).
TEST(IrlsL1, ExactRobustAndMinimumNormWhenSingular) {
  Random rng(11);
  const int n = 40;
  Eigen::Matrix<double, Eigen::Dynamic, 3> A(n, 3);
  for (int i = 0; i < n; ++i) {
    A(i, 0) = rng.uniform(-1, 1);
    A(i, 1) = rng.uniform(-1, 1);
    A(i, 2) = 1;
  }
  const Eigen::Vector3d truth(0.5, -2.0, 0.25);
  Eigen::VectorXd b = A * truth;
  const Eigen::VectorXd w = Eigen::VectorXd::Ones(n);
  Eigen::Matrix<double, 3, 1> x;
  ASSERT_TRUE(solveIrlsL1<3>(A, b, w, 0, 1e-4, x));
  EXPECT_LT((x - truth).norm(), 1e-10);
  b[7] += 50;  // one gross outlier
  Eigen::Matrix<double, 3, 1> plain, robust;
  ASSERT_TRUE(solveIrlsL1<3>(A, b, w, 0, 1e-4, plain));
  ASSERT_TRUE(solveIrlsL1<3>(A, b, w, 20, 1e-6, robust));
  EXPECT_GT((plain - truth).norm(), 0.5);
  EXPECT_LT((robust - truth).norm(), 1e-3);
  // Third column = first + second: rank 2.
  Eigen::Matrix<double, Eigen::Dynamic, 3> S = A;
  S.col(2) = A.col(0) + A.col(1);
  const Eigen::VectorXd c = S * truth;
  Eigen::Matrix<double, 3, 1> xs;
  EXPECT_FALSE(solveIrlsL1<3>(S, c, w, 3, 1e-4, xs));
  const Eigen::MatrixXd Sd = S;
  const Eigen::Vector3d min_norm = Sd.jacobiSvd(Eigen::ComputeThinU | Eigen::ComputeThinV).solve(c);
  EXPECT_LT((xs - min_norm).norm(), 1e-8 * min_norm.norm());
  EXPECT_LT((S * xs - c).norm(), 1e-8 * c.norm());
  EXPECT_GT((xs - truth).norm(), 0.1);  // the data cannot tell truth from the minimum-norm answer
}

}  // namespace core_quadric_height_patch_test
