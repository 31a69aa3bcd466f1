// Wavejet enhancement (manuscript 2.4.3) on surfaces with known answers.
#include <cmath>

#include <gtest/gtest.h>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/filters/wavejet_enhancement.h>

#include "filter_test_support.h"

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace filters_wavejet_enhancement_test {

using paps::Positions;

// Irregular samples of z = amp sin(2 pi x / w) sin(2 pi y / w) on [-1, 1]^2.
Positions bumps(int count, double amp, std::uint64_t seed, double noise = 0) {
  paps::Random rng(seed);
  Positions p;
  const double k = 2 * M_PI / 0.5;
  for (int i = 0; i < count; ++i) {
    const double x = rng.uniform(-1, 1), y = rng.uniform(-1, 1);
    p.emplace_back(static_cast<float>(x), static_cast<float>(y),
                   static_cast<float>(amp * std::sin(k * x) * std::sin(k * y) + noise * rng.gaussian()));
  }
  return p;
}

double interiorAmplitude(const Positions& p) {
  double s = 0; int n = 0;
  for (const auto& x : p)
    if (std::abs(x.x()) < 0.7 && std::abs(x.y()) < 0.7) { s += x.z() * x.z(); ++n; }
  return std::sqrt(s / n);
}

paps::WavejetEnhancementParameters baseParams() {
  paps::WavejetEnhancementParameters p;
  p.radius = 0.1f;
  p.wavejet.viewpoint = {0, 0, 10};
  return p;
}

TEST(WavejetEnhancement, PositionGainScalesDetail) {
  const Positions p = bumps(6000, 0.02, 1);
  auto params = baseParams();
  const double a = interiorAmplitude(p);
  params.alpha0 = 1;
  const double a1 = interiorAmplitude(paps::enhancePositions(p, params));
  params.alpha0 = 2;
  paps::WavejetEnhancementReport r;
  const double a2 = interiorAmplitude(paps::enhancePositions(p, params, &r));
  params.alpha0 = 0;
  const double a0 = interiorAmplitude(paps::enhancePositions(p, params));
  EXPECT_NEAR(a1, a, 0.01 * a);  // projection on an exact surface barely moves it
  // The detail's amplitude scales with the gain (equation 2.21): measured 2.07x at alpha0 = 2,
  // 0.07x at alpha0 = 0 (the Wavejet's own smooth part is what is left).
  EXPECT_NEAR(a2 / a, 2.0, 0.15);
  EXPECT_LT(a0 / a, 0.15);
  EXPECT_EQ(r.changed, p.size());
  EXPECT_EQ(r.clamped, 0u);
}

// After the position filter a cloud carries the normals of the enhanced surface: the bumps
// amplified by the measured gain g (about 2 at alpha0 = 2) have the analytic normals of
// z = g amp sin sin; the input's corrected normals describe the unamplified bumps.
TEST(WavejetEnhancement, NormalsAfterThePositionFilterAreTheEnhancedSurfaces) {
  const double amp = 0.02, k = 2 * M_PI / 0.5;
  const Positions p = bumps(6000, amp, 1);
  auto params = baseParams();
  paps::Normals corrected;
  const Positions out = paps::enhancePositions(p, params, nullptr, {}, {}, nullptr, &corrected);
  const double g = interiorAmplitude(out) / interiorAmplitude(p);
  const paps::Normals enhanced = paps::enhancedSurfaceNormals(out, params, corrected);
  double err_new = 0, err_old = 0;
  int n = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double x = out[i].x(), y = out[i].y();
    if (std::abs(x) > 0.7 || std::abs(y) > 0.7) continue;
    const Eigen::Vector3d want = Eigen::Vector3d(-g * amp * k * std::cos(k * x) * std::sin(k * y),
                                                 -g * amp * k * std::sin(k * x) * std::cos(k * y), 1.0)
                                     .normalized();
    ASSERT_GT(enhanced[i].z(), 0.f) << i << ": on the side of the corrected normal";
    err_new += std::acos(std::min(1.0, want.dot(enhanced[i].cast<double>()))) * 180 / M_PI;
    err_old += std::acos(std::min(1.0, want.dot(corrected[i].cast<double>()))) * 180 / M_PI;
    ++n;
  }
  std::printf("gain %.3f; mean angle to the enhanced surface's normal: %.3f degrees (input's corrected: %.3f)\n", g,
              err_new / n, err_old / n);
  EXPECT_LT(err_new / n, 1.0);
  EXPECT_GT(err_old / n, 3 * err_new / n);
}

TEST(WavejetEnhancement, ProjectionRemovesNoise) {
  paps::Random rng(5);
  Positions p, truth;
  while (p.size() < 5000) {
    Eigen::Vector3d v = rng.gaussian3();
    v.normalize();
    truth.push_back(v.cast<float>());
    p.push_back((v * (1 + 0.005 * rng.gaussian())).cast<float>());
  }
  auto params = baseParams();
  params.radius = 0.25f;
  params.alpha0 = 1;
  params.wavejet.order = 2;
  const Positions q = paps::enhancePositions(p, params);
  double before = 0, after = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    before += std::pow(p[i].norm() - 1, 2);
    after += std::pow(q[i].norm() - 1, 2);
  }
  EXPECT_LT(after, 0.25 * before);
}

TEST(WavejetEnhancement, ProjectionOnVaryingDensityWithDuplicates) {
  // A unit sphere sampled 60x denser in a cap than elsewhere, noise 0.3%, every point twice:
  // with the automatic radius the sparse part is widened (each point's own R_phi scales its
  // motion) and projected too; copies move alike; no point is left unfitted.
  paps::Random rng(9);
  Positions p;
  while (p.size() < 7500) {
    Eigen::Vector3d v = rng.gaussian3();
    v.normalize();
    if (p.size() >= 1500 && v.z() < std::cos(0.2)) continue;
    p.push_back((v * (1 + 0.003 * rng.gaussian())).cast<float>());
  }
  const std::size_t base = p.size();
  for (std::size_t i = 0; i < base; ++i) p.push_back(p[i]);
  paps::WavejetEnhancementParameters params;
  params.alpha0 = 1;
  params.wavejet.order = 2;
  paps::WavejetEnhancementReport r;
  const Positions q = paps::enhancePositions(p, params, &r);
  ASSERT_EQ(q.size(), p.size());
  EXPECT_EQ(r.unfitted, 0u);
  EXPECT_EQ(r.duplicates, base);
  EXPECT_GT(r.widened, 2000u);
  double before = 0, after = 0;
  for (std::size_t i = 0; i < base; ++i) {
    ASSERT_EQ(q[i + base], q[i]);
    if (p[i].z() / p[i].norm() > std::cos(0.25)) continue;  // the sparse part only
    before += std::pow(p[i].norm() - 1, 2);
    after += std::pow(q[i].norm() - 1, 2);
  }
  EXPECT_LT(after, 0.25 * before);
}

TEST(WavejetEnhancement, MotionClampedAtHalfRadius) {
  const Positions p = bumps(3000, 0.05, 2);
  auto params = baseParams();
  params.alpha0 = 1e4f;
  paps::WavejetEnhancementReport r;
  const Positions q = paps::enhancePositions(p, params, &r);
  EXPECT_GT(r.clamped, p.size() / 2);
  for (std::size_t i = 0; i < p.size(); ++i) EXPECT_LE((q[i] - p[i]).norm(), 0.5f * 0.1f * 1.0001f);
}

TEST(WavejetEnhancement, NormalGain) {
  const Positions p = bumps(6000, 0.02, 3);
  auto params = baseParams();
  const double k = 2 * M_PI / 0.5;
  auto meanAngle = [&](std::complex<float> alpha) {
    params.alpha1 = alpha;
    const paps::Normals n = paps::enhanceNormals(p, params);
    double s = 0; int c = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
      if (std::abs(p[i].x()) > 0.7 || std::abs(p[i].y()) > 0.7) continue;
      const double x = p[i].x(), y = p[i].y();
      const Eigen::Vector3d t(-0.02 * k * std::cos(k * x) * std::sin(k * y), -0.02 * k * std::sin(k * x) * std::cos(k * y), 1);
      s += std::acos(std::min(1.0, n[i].cast<double>().dot(t.normalized()))) * 180 / M_PI;
      ++c;
    }
    return s / c;
  };
  const double e1 = meanAngle({1, 0}), e2 = meanAngle({2, 0}), e3 = meanAngle({3, 0}), ei = meanAngle({1, 1});
  EXPECT_LT(e1, 0.3);  // alpha_1 = 1: the true normals (order-4 fit of a sinusoid)
  EXPECT_GT(e2, 1.0);
  EXPECT_GT(e3, 1.8 * e2);  // deviation linear in alpha_1 - 1
  EXPECT_NEAR(ei, e2, 0.2 * e2);  // |alpha_1 - 1| = 1 too, rotated (skewed) deviation
}

TEST(WavejetEnhancement, PclFilterPositionsAndNormals) {
  const Positions p = bumps(3000, 0.02, 4);
  pcl::PointCloud<pcl::PointNormal>::Ptr cloud(new pcl::PointCloud<pcl::PointNormal>);
  for (const auto& x : p) {
    pcl::PointNormal q;
    q.getVector3fMap() = x;
    q.getNormalVector3fMap() = Eigen::Vector3f::UnitZ();  // orientation hint
    cloud->push_back(q);
  }
  pcl::PointNormal nan_point;
  nan_point.x = nan_point.y = nan_point.z = NAN;
  cloud->push_back(nan_point);
  cloud->is_dense = false;
  // The functions on the same positions, parameters and orientation hints (the input
  // normals) give the filter's answer bit for bit.
  const Positions in = paps::positionsOf(*cloud);
  paps::Normals hints(cloud->size());
  for (std::size_t i = 0; i < cloud->size(); ++i) hints[i] = (*cloud)[i].getNormalVector3fMap();
  paps::WavejetEnhancementParameters params;
  params.radius = 0.1f;
  params.alpha0 = 1.5f;  // not the default 2: the setter must reach the run
  paps::Normals corrected;
  const Positions moved = paps::enhancePositions(in, params, nullptr, {}, {}, &hints, &corrected);
  const paps::Normals enhanced = paps::enhancedSurfaceNormals(moved, params, corrected);

  paps::WavejetEnhancement<pcl::PointNormal> f;
  f.setInputCloud(cloud);
  f.setRadius(0.1f);
  f.setPositionGain(1.5f);
  EXPECT_EQ(f.getMode(), paps::WavejetEnhancement<pcl::PointNormal>::Mode::positions);
  pcl::PointCloud<pcl::PointNormal> out;
  f.filter(out);
  ASSERT_EQ(out.size(), cloud->size());
  EXPECT_FALSE(out.is_dense);
  EXPECT_EQ(f.getReport().non_finite, 1u);
  std::size_t moved_count = 0, unfitted = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_TRUE(paps::test::sameBits(out[i].getVector3fMap(), moved[i])) << i;
    EXPECT_TRUE(paps::test::sameBits(out[i].getNormalVector3fMap(), enhanced[i])) << i;
    moved_count += out[i].getVector3fMap() != p[i];
    // A few sparse balls (fixed radius: no widening) hold too few points for the order:
    // left in place with a NaN normal; the others are oriented by the hints.
    if (std::isnan(out[i].normal_z)) ++unfitted;
    else EXPECT_GT(out[i].normal_z, 0.5f) << i;
  }
  EXPECT_GE(unfitted, 1u);
  EXPECT_LT(unfitted, p.size() / 100);
  EXPECT_GT(moved_count, p.size() * 9 / 10);
  EXPECT_TRUE(paps::test::sameBits(out[p.size()].getVector3fMap(), in[p.size()]));  // NaN passed through

  // Normal mode: positions stay, the normals are enhanceNormals' false normals.
  params.alpha1 = {0.f, 3.f};
  const paps::Normals false_normals = paps::enhanceNormals(in, params, nullptr, {}, &hints);
  f.setNormalGain({0.f, 3.f});
  pcl::PointCloud<pcl::PointNormal> out2;
  f.filter(out2);
  ASSERT_EQ(out2.size(), cloud->size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_TRUE(paps::test::sameBits(out2[i].getVector3fMap(), p[i])) << i;
    EXPECT_TRUE(paps::test::sameBits(out2[i].getNormalVector3fMap(), false_normals[i])) << i;
    if (!std::isnan(out[i].normal_z)) EXPECT_GT(out2[i].normal_z, 0.f) << i;
  }
  EXPECT_NE(out2[10].normal_x, out[10].normal_x);

  pcl::PointCloud<pcl::PointXYZ>::Ptr xyz(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& x : p) xyz->push_back(pcl::PointXYZ(x.x(), x.y(), x.z()));
  paps::WavejetEnhancement<pcl::PointXYZ> g;
  g.setInputCloud(xyz);
  g.setNormalGain({2.f, 0.f});
  pcl::PointCloud<pcl::PointXYZ> o;
  EXPECT_THROW(g.filter(o), paps::InvalidParameter);  // no normals to write

  // The normal filter checks its indices too (it wrote through an index past the cloud).
  for (const int bad_index : {-1, static_cast<int>(cloud->size()), 100000}) {
    paps::WavejetEnhancement<pcl::PointNormal> h;
    h.setInputCloud(cloud);
    h.setNormalGain({2.f, 0.f});
    h.setIndices(pcl::IndicesPtr(new pcl::Indices{0, 5, bad_index}));
    pcl::PointCloud<pcl::PointNormal> o2;
    try {
      h.filter(o2);
      ADD_FAILURE() << "index " << bad_index << " accepted";
    } catch (const paps::InvalidParameter& e) {
      EXPECT_EQ(e.parameter(), "indices");
    }
  }
}

// A dense cloud whose far point has no neighbour within the radius: left in place with a NaN
// normal in both modes, so the output is no longer dense (PCL: no NaN in any field).
TEST(WavejetEnhancement, NaNNormalsMakeTheOutputNotDense) {
  pcl::PointCloud<pcl::PointNormal>::Ptr cloud(new pcl::PointCloud<pcl::PointNormal>);
  for (int i = 0; i < 30; ++i)
    for (int j = 0; j < 30; ++j) {
      pcl::PointNormal q;
      q.getVector3fMap() = Eigen::Vector3f(0.01f * i, 0.01f * j, 0.002f * std::sin(0.7f * i));
      q.getNormalVector3fMap() = Eigen::Vector3f::UnitZ();
      cloud->push_back(q);
    }
  pcl::PointNormal far;
  far.getVector3fMap() = Eigen::Vector3f(5.f, 5.f, 0.f);
  far.getNormalVector3fMap() = Eigen::Vector3f::UnitZ();
  cloud->push_back(far);
  ASSERT_TRUE(cloud->is_dense);
  for (const bool normal_mode : {false, true}) {
    paps::WavejetEnhancement<pcl::PointNormal> f;
    f.setInputCloud(cloud);
    f.setRadius(0.03f);
    if (normal_mode) f.setNormalGain({2.f, 0.f});
    else f.setPositionGain(1.5f);
    pcl::PointCloud<pcl::PointNormal> out;
    f.filter(out);
    ASSERT_EQ(out.size(), cloud->size());
    EXPECT_TRUE(std::isnan(out.back().normal_z)) << normal_mode;
    EXPECT_TRUE(paps::test::sameBits(out.back().getVector3fMap(), far.getVector3fMap())) << normal_mode;
    EXPECT_FALSE(out.is_dense) << normal_mode;
    EXPECT_TRUE(std::isfinite(out[450].normal_z)) << normal_mode;
  }
}

TEST(WavejetEnhancement, BadParameters) {
  paps::WavejetEnhancement<pcl::PointXYZ> f;
  EXPECT_THROW(f.setRadius(-1.f), paps::InvalidParameter);
  EXPECT_THROW(f.setPositionGain(NAN), paps::InvalidParameter);
  EXPECT_THROW(f.setNormalGain({INFINITY, 0.f}), paps::InvalidParameter);
  EXPECT_THROW(f.setOrder(0), paps::InvalidParameter);
  auto params = baseParams();
  params.max_motion = 0;
  EXPECT_THROW(paps::enhancePositions(bumps(100, 0.01, 1), params), paps::InvalidParameter);
}

// The bad-input contract shared with the other position filters (filter_test_support.h), on
// the default stage (projection on the Wavejet surface, automatic radius).
using namespace paps::test;
Positions noisyBumps(int count) { return bumps(count, 0.02, 12, 0.002); }

TEST(WavejetEnhancement, EmptyAndAllNaNAreInvalidInput) {
  paps::WavejetEnhancement<pcl::PointXYZ> f;
  expectEmptyAndAllNaNAreInvalidInput(f);
}

TEST(WavejetEnhancement, NaNPassThroughAndOtherFieldsKept) {
  expectNaNPassThroughAndOtherFieldsKept<paps::WavejetEnhancement>(noisyBumps(4000));
}

TEST(WavejetEnhancement, DenseStaysDenseAndColoursKept) {
  expectDenseStaysDenseAndColoursKept<paps::WavejetEnhancement>(noisyBumps(3000));
}

TEST(WavejetEnhancement, IndexOutOfRangeIsRejected) {
  expectIndexOutOfRangeIsRejected<paps::WavejetEnhancement>(noisyBumps(500));
}

}  // namespace filters_wavejet_enhancement_test
