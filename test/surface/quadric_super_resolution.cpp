// QSR: beats plain interpolation on a repeated relief; with no similar patch it is still an
// interpolator; bad input gives clear errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include <omp.h>

#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/surface/mls.h>

#include <paps/core/metrics.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>
#include <paps/core/synthetic.h>
#include <paps/filters/similarity_denoising.h>
#include <paps/surface/mls_upsampling.h>
#include <paps/surface/quadric_super_resolution.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace surface_quadric_super_resolution_test {

using namespace paps;

// Points away from the border of the square (seeds there overshoot the edge of the shape).
Positions interior(const Positions& p) {
  Positions o;
  for (const auto& x : p)
    if (std::abs(x.x()) < 0.45f && std::abs(x.y()) < 0.45f) o.push_back(x);
  return o;
}
struct Case {
  TriangleMesh mesh = synthetic::engravedPlane(1.f, 0.1f, 0.006f, 300);
  Positions sparse = synthetic::sampleMesh(mesh, 12000, 5);
};
double surfaceError(const Positions& out, const TriangleMesh& mesh) {
  return pointToMeshError(interior(out), PointToMeshDistance(mesh)).rmse;
}

TEST(QuadricSuperResolution, BeatsPlainInterpolationOnEngravedPlane) {
  Case c;
  synthetic::addGaussianNoise(c.sparse, 0.0005f, 9);
  const PointToMeshDistance truth(c.mesh);
  QuadricSuperResolutionParameters p;
  p.factor = 4;
  QuadricSuperResolutionReport r;
  const Positions qsr = superResolveQuadric({c.sparse}, p, &r);
  EXPECT_EQ(qsr.size(), 48000u);
  p.similar_patches = 0;  // plain interpolation of each patch's own points
  QuadricSuperResolutionReport r0;
  const Positions plain = superResolveQuadric({c.sparse}, p, &r0);
  const double e_qsr = pointToMeshError(interior(qsr), truth).rmse, e_plain = pointToMeshError(interior(plain), truth).rmse;
  const double e_in = pointToMeshError(c.sparse, truth).rmse;
  std::printf("input %.3e  plain %.3e  qsr %.3e  (R %g, rsim %g, grid %d -> %d, K-1 %.2f)\n", e_in, e_plain,
              e_qsr, r.patch_radius, r.similarity_radius, r.grid_lr, r.grid_sr, r.mean_similar_weight);
  EXPECT_LT(e_qsr, 0.9 * e_plain);
  EXPECT_LT(e_qsr, 0.8 * e_in);
  EXPECT_GT(r.mean_similar_weight, 0.5);
  EXPECT_EQ(r0.without_similar, r0.patches);
}

// Scans are often stored with every point twice (bun0.pcd). A point's copy has the same
// descriptor: taken as its most similar patch it set the automatic similarity radius to
// nothing (bun0: 8e-8 m), so no other patch counted.
TEST(QuadricSuperResolution, DuplicatedScanKeepsItsSimilarityRadius) {
  Case c;
  synthetic::addGaussianNoise(c.sparse, 0.0005f, 9);
  Positions twice = c.sparse;
  twice.insert(twice.end(), c.sparse.begin(), c.sparse.end());
  QuadricSuperResolutionParameters p;
  p.factor = 2;
  QuadricSuperResolutionReport r1, r2;
  superResolveQuadric({c.sparse}, p, &r1);
  p.patch_radius = r1.patch_radius;  // the same patches and grid, each position seen twice
  p.grid_lr = r1.grid_lr;
  superResolveQuadric({twice}, p, &r2);
  std::printf("similarity radius once %g, twice %g; similar weight %.2f, %.2f\n", r1.similarity_radius,
              r2.similarity_radius, r1.mean_similar_weight, r2.mean_similar_weight);
  EXPECT_NEAR(r2.similarity_radius, r1.similarity_radius, 0.3 * r1.similarity_radius);
}

TEST(QuadricSuperResolution, NoSimilarPatchStillInterpolates) {
  Case c;
  const PointToMeshDistance truth(c.mesh);
  QuadricSuperResolutionParameters p;
  p.similarity_radius = 1e-12f;  // nothing is similar
  QuadricSuperResolutionReport r;
  const Positions out = superResolveQuadric({c.sparse}, p, &r);
  EXPECT_EQ(r.without_similar, r.patches);
  EXPECT_EQ(out.size(), 48000u);
  // Noise-free input: the plain interpolation follows the relief (RMS 3 mm; the same points
  // flattened to z = 0 score 2.9e-3): measured 4.5e-4.
  EXPECT_LT(pointToMeshError(interior(out), truth).rmse, 6e-4);
}

// Patches with too few valid bins to be compared (sparse parts and rims of a scan) still seed
// and anchor the output, as their quadric alone. Seeding only from comparable patches left
// such parts bare: on rs1's rims it tripled the error of the worst 1% of the points. Here the
// right half of the square is scanned at a fifth of the density of the left half.
TEST(QuadricSuperResolution, SparsePartsOfTheScanAreCovered) {
  Case c;
  Positions scan;
  Random rng(4);
  for (const auto& x : c.sparse) if (x.x() < 0.f || rng.uniform() < 0.2) scan.push_back(x);
  QuadricSuperResolutionParameters p;
  p.factor = 4;
  QuadricSuperResolutionReport r;
  const Positions out = superResolveQuadric({scan}, p, &r);
  ASSERT_LT(r.patches + 200, scan.size());  // many sparse patches have no descriptor
  // They anchor the output, all but those too isolated for any fit (measured 790 of 802).
  EXPECT_GT(r.quadric_only, 9 * (scan.size() - r.patches) / 10);
  const SpatialIndex index(out);
  // Input spacing on the right half (1,200 points on half a square metre).
  const double s_right = std::sqrt(0.5 / (0.1 * static_cast<double>(c.sparse.size())));
  std::vector<int> idx;
  std::vector<float> d2;
  double worst = 0;
  std::size_t bare = 0, n = 0;
  for (const auto& t : synthetic::sampleMesh(c.mesh, 200000, 11)) {
    if (t.x() < 0.05f || t.x() > 0.45f || std::abs(t.y()) > 0.45f) continue;  // the sparse half, off its borders
    index.nearestK(t, 1, idx, d2);
    const double d = std::sqrt(d2[0]);
    worst = std::max(worst, d);
    bare += d > s_right;
    ++n;
  }
  std::printf("%zu of %zu patches comparable; sparse half: nearest output worst %.2f spacings, %zu of %zu points farther than a spacing\n",
              r.patches, scan.size(), worst / s_right, bare, n);
  // Measured: 1.65 spacings and 0.8% (before: 4.12 and 36%). The input itself has random gaps,
  // and the seed discs follow the mean spacing, not the local one.
  EXPECT_LT(worst, 2.5 * s_right);
  EXPECT_LT(bare, n / 50);
}

TEST(QuadricSuperResolution, MultiScanAndPclStage) {
  Case c;
  auto s0 = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  auto s1 = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  writePositions(c.sparse, *s0);
  writePositions(synthetic::sampleMesh(c.mesh, 12000, 6), *s1);
  QuadricSuperResolution<pcl::PointXYZ> qsr;
  qsr.setInputCloud(s0);
  qsr.addScan(s1);
  qsr.setUpsamplingFactor(2);
  pcl::PointCloud<pcl::PointXYZ> out;
  qsr.process(out);
  EXPECT_EQ(out.size(), 24000u);
  EXPECT_GT(qsr.getReport().patches, 23800u);  // a few border patches lack valid bins
  // The stage gives what the function gives on the same two scans and parameters, bit for
  // bit, with the same report.
  QuadricSuperResolutionParameters p;
  p.factor = 2;
  QuadricSuperResolutionReport r;
  const Positions expected = superResolveQuadric({positionsOf(*s0), positionsOf(*s1)}, p, &r);
  ASSERT_EQ(expected.size(), out.size());
  for (std::size_t i = 0; i < out.size(); ++i) ASSERT_EQ(out[i].getVector3fMap(), expected[i]) << i;
  EXPECT_EQ(qsr.getReport().patches, r.patches);
}

// A coloured output type gets the colour of the input point each new point was made from, as
// PCL's MLS copies the missing fields (it was left at 0: r = g = b = 0 on all 6,400 points).
// Two halves of a wavy sheet in two colours; the points away from the seam keep their side's.
// Run for the coloured pairs the library compiles (no template bodies included here: a pair
// left out of the list fails to link): RGB, RGBA (alpha kept) and RGB with normals (the
// normal of the fitted surface, near +-z on this sheet).
template <typename PointT>
void expectColouredOutputsKeepTheSourcePointsColour() {
  auto cloud = pcl::make_shared<pcl::PointCloud<PointT>>();
  paps::Random rng(5);
  for (int i = 0; i < 3000; ++i) {
    PointT q;
    q.x = static_cast<float>(rng.uniform() - 0.5);
    q.y = static_cast<float>(rng.uniform() - 0.5);
    q.z = 0.02f * std::sin(6.f * q.x);
    q.r = q.x < 0 ? 200 : 50;
    q.g = 7;
    q.b = q.x < 0 ? 0 : 99;
    q.a = q.x < 0 ? 255 : 128;
    cloud->push_back(q);
  }
  auto check = [&](const pcl::PointCloud<PointT>& out, const char* what) {
    ASSERT_GT(out.size(), cloud->size()) << what;
    std::size_t away = 0, right = 0, upright = 0;
    for (const auto& q : out) {
      EXPECT_EQ(q.g, 7) << what;
      if constexpr (paps::detail::HasNormal<PointT>::value) upright += std::abs(q.normal_z) > 0.9f;
      if (std::abs(q.x) < 0.05f) continue;
      ++away;
      right += q.x < 0 ? (q.r == 200 && q.b == 0 && q.a == 255) : (q.r == 50 && q.b == 99 && q.a == 128);
    }
    EXPECT_GT(away, out.size() / 2) << what;
    EXPECT_EQ(right, away) << what;
    if constexpr (paps::detail::HasNormal<PointT>::value) EXPECT_EQ(upright, out.size()) << what;
  };
  auto upsample = [&](auto&& stage, const char* what) {
    stage.setInputCloud(cloud);
    stage.setUpsamplingFactor(2);
    pcl::PointCloud<PointT> out;
    stage.process(out);
    check(out, what);
  };
  upsample(QuadricSuperResolution<PointT, PointT>(), "qsr");
  upsample(APSSUpsampling<PointT, PointT>(), "apss");
  upsample(RIMLSUpsampling<PointT, PointT>(), "rimls");
}

TEST(QuadricSuperResolution, ColouredOutputsKeepTheSourcePointsColour) {
  expectColouredOutputsKeepTheSourcePointsColour<pcl::PointXYZRGB>();
  expectColouredOutputsKeepTheSourcePointsColour<pcl::PointXYZRGBA>();
  expectColouredOutputsKeepTheSourcePointsColour<pcl::PointXYZRGBNormal>();
}

TEST(QuadricSuperResolution, BadInput) {
  {
    // process() before setInputCloud: PCL's base reads the missing cloud; ours says so.
    QuadricSuperResolution<pcl::PointXYZ, pcl::PointXYZ> qsr;
    pcl::PointCloud<pcl::PointXYZ> out;
    EXPECT_THROW(qsr.process(out), InvalidInput);
  }
  EXPECT_THROW(superResolveQuadric({}, {}), InvalidInput);
  EXPECT_THROW(superResolveQuadric({Positions{}}, {}), InvalidInput);
  EXPECT_THROW(superResolveQuadric({Positions(100, Eigen::Vector3f::Constant(NAN))}, {}), InvalidInput);
  {
    auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>(20, 1);
    QuadricSuperResolution<pcl::PointXYZ, pcl::PointXYZ> qsr;
    qsr.setInputCloud(cloud);
    qsr.setIndices(pcl::IndicesPtr(new pcl::Indices{0, 19, 20}));
    pcl::PointCloud<pcl::PointXYZ> out;
    try {
      qsr.process(out);
      ADD_FAILURE() << "an index past the cloud was accepted";
    } catch (const InvalidParameter& e) {
      EXPECT_EQ(e.parameter(), "indices");
    }
  }
  QuadricSuperResolutionParameters p;
  p.factor = -3;
  EXPECT_THROW(superResolveQuadric({Positions(100, Eigen::Vector3f::Zero())}, p), InvalidParameter);
  p = {};
  p.patch_radius = -1;
  EXPECT_THROW(p.validate(), InvalidParameter);
  p = {};
  p.similarity_radius = INFINITY;
  EXPECT_THROW(p.validate(), InvalidParameter);
  // Only collinear points: no surface anywhere, a clear error (a plane through a line has no
  // orientation; the run used to write a ribbon of arbitrary orientation).
  Positions line;
  for (int i = 0; i < 200; ++i) line.emplace_back(0.01f * i, 0.f, 0.f);
  QuadricSuperResolutionParameters q;
  q.patch_radius = 0.05f;
  q.widen_sparse_fits = false;
  try {
    superResolveQuadric({line}, q);
    ADD_FAILURE() << "points on a line were super-resolved";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("lines"), std::string::npos) << e.what();
  }
  q.widen_sparse_fits = true;  // widening finds no surface either
  EXPECT_THROW(superResolveQuadric({line}, q), InvalidInput);
  // A wire beside a surface: its fits are ill-posed and counted, and the run answers.
  Positions wired = line;
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j) wired.emplace_back(0.01f * i, 0.5f + 0.01f * j, 0.f);
  QuadricSuperResolutionReport r;
  q.widen_sparse_fits = false;
  q.factor = 2;
  const Positions out = superResolveQuadric({wired}, q, &r);
  std::printf("wire beside a plane: %zu output, %zu flat, %zu ill-posed, %zu patches\n", out.size(), r.flat_fits,
              r.ill_posed_fits, r.patches);
  EXPECT_EQ(out.size(), 2 * wired.size());
  EXPECT_EQ(r.ill_posed_fits, line.size());
  EXPECT_EQ(r.flat_fits, 1600u);
  EXPECT_EQ(r.plane_fallbacks, wired.size());
}

// Flat parts are told apart from ill-posed fits: a plane gives flat fits only, a sphere none.
TEST(QuadricSuperResolution, CountsFlatAndIllPosedFitsApart) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  Positions plane, sphere;
  for (int i = 0; i < 3000; ++i) {  // drawn last to first (paps/core/random.h)
    const float y = u(rng);
    plane.emplace_back(u(rng), y, 0.f);
  }
  for (int i = 0; i < 3000; ++i) {
    const float z = u(rng), y = u(rng);
    sphere.push_back(Eigen::Vector3f(u(rng), y, z).normalized());
  }
  QuadricSuperResolutionParameters p;
  p.patch_radius = 0.3f;  // about 70 neighbours: every fit is well posed
  QuadricSuperResolutionReport rp, rs;
  superResolveQuadric({plane}, p, &rp);
  superResolveQuadric({sphere}, p, &rs);
  EXPECT_EQ(rp.flat_fits, plane.size());
  EXPECT_EQ(rp.ill_posed_fits, 0u);
  EXPECT_EQ(rs.flat_fits, 0u);
  EXPECT_EQ(rs.ill_posed_fits, 0u);
  EXPECT_EQ(rs.plane_fallbacks, 0u);
  EXPECT_EQ(rs.thin_balls, 0u);  // a closed, evenly sampled surface: no ball is thin
  EXPECT_EQ(rs.widened_fits, 0u);
  std::printf("plane: %zu thin balls, %zu widened\n", rp.thin_balls, rp.widened_fits);
}

// The rule (measured, docs/superresolution.md "Noise-adaptive kernel"): 0.7 up to
// q = sigma / R = 0.05, linear to 1.4 at q = 0.25, then 1.4.
TEST(QuadricSuperResolution, NoiseAdaptedKernelFollowsTheMeasuredRule) {
  QuadricSuperResolutionParameters automatic;
  EXPECT_EQ(automatic.kernel_scale, 0.f);
  EXPECT_FALSE(automatic.adapt_to_noise);  // opt-in
  automatic.adapt_to_noise = true;
  const float R = 0.02f;
  for (float q : {0.f, 0.03f, 0.05f}) EXPECT_FLOAT_EQ(noiseAdaptedParameters(automatic, R, q * R).kernel_scale, 0.7f);
  EXPECT_NEAR(noiseAdaptedParameters(automatic, R, 0.15f * R).kernel_scale, 1.05f, 1e-5f);
  for (float q : {0.25f, 0.5f, 3.f}) EXPECT_NEAR(noiseAdaptedParameters(automatic, R, q * R).kernel_scale, 1.4f, 1e-5f);
  // Without adaptation the automatic kernel is the fixed one; an explicit kernel is kept.
  QuadricSuperResolutionParameters fixed;
  fixed.adapt_to_noise = false;
  EXPECT_FLOAT_EQ(noiseAdaptedParameters(fixed, R, 0.5f * R).kernel_scale, 0.7f);
  QuadricSuperResolutionParameters given;
  given.kernel_scale = 0.5f;
  given.similarity_scale = 3.f;
  given.irls_iterations = 5;
  const QuadricSuperResolutionParameters kept = noiseAdaptedParameters(given, R, 0.5f * R);
  EXPECT_EQ(kept.kernel_scale, 0.5f);
  EXPECT_EQ(kept.similarity_scale, 3.f);
  EXPECT_EQ(kept.irls_iterations, 5);
  EXPECT_THROW(noiseAdaptedParameters(automatic, 0.f, 0.001f), InvalidParameter);
  EXPECT_THROW(noiseAdaptedParameters(automatic, R, -1.f), InvalidParameter);
  EXPECT_THROW(noiseAdaptedParameters(automatic, R, NAN), InvalidParameter);
}

TEST(QuadricSuperResolution, GivenNoiseIsUsedAndExplicitKernelKept) {
  const TriangleMesh mesh = synthetic::engravedPlane(0.5f, 0.1f, 0.006f, 150);
  const Positions in = synthetic::sampleMesh(mesh, 3000, 5);  // noise-free: measured q is small
  QuadricSuperResolutionParameters p;
  p.adapt_to_noise = true;
  p.denoise_input = QuadricSuperResolutionParameters::Denoise::Off;  // the kernel rule alone
  p.factor = 1;
  p.noise_sigma = 0.02f;  // given: q = 0.02 / R > 0.25 whatever R here (about 0.03 m)
  QuadricSuperResolutionReport r;
  superResolveQuadric({in}, p, &r);
  EXPECT_FALSE(r.noise_estimated);
  EXPECT_EQ(r.noise_sigma, 0.02f);
  EXPECT_LT(r.patch_radius, 0.08f);
  EXPECT_NEAR(r.kernel_scale, 1.4f, 1e-5f);
  p.noise_sigma = 0;  // measured: the relief left over by the quadrics, q well under 0.05
  superResolveQuadric({in}, p, &r);
  EXPECT_TRUE(r.noise_estimated);
  EXPECT_GT(r.noise_sigma, 0.f);
  EXPECT_LT(r.noise_sigma, 0.05f * r.patch_radius);
  EXPECT_FLOAT_EQ(r.kernel_scale, 0.7f);
  p.noise_sigma = 0.02f;
  p.kernel_scale = 0.5f;  // explicit: kept, and no noise is needed
  superResolveQuadric({in}, p, &r);
  EXPECT_EQ(r.kernel_scale, 0.5f);
  EXPECT_EQ(r.noise_sigma, 0.f);
  p.kernel_scale = 0;
  p.adapt_to_noise = false;
  superResolveQuadric({in}, p, &r);
  EXPECT_FLOAT_EQ(r.kernel_scale, 0.7f);
  EXPECT_EQ(r.noise_sigma, 0.f);
}

// The noise-adaptive kernel (opt-in) against the fixed default kernel (0.7) on the 12K engraved plane, error to
// the true surface (interior). Measured: at 0.5% noise (measured q = 0.223, kernel 1.30)
// 2.957e-3 against 3.242e-3 (0.91); at 0.05% (q = 0.036, kernel 0.7: the same run) 4.391e-4
// for both. Margins: 0.95 and 1.01.
TEST(QuadricSuperResolution, NoiseAdaptiveKernelBeatsFixedKernelAtHighNoise) {
  for (float noise : {0.0005f, 0.005f}) {
    Case c;
    synthetic::addGaussianNoise(c.sparse, noise, 9);
    QuadricSuperResolutionParameters p;
    p.adapt_to_noise = true;
    p.denoise_input = QuadricSuperResolutionParameters::Denoise::Off;  // the kernel rule alone
    QuadricSuperResolutionReport ra, rf;
    const double adaptive = surfaceError(superResolveQuadric({c.sparse}, p, &ra), c.mesh);
    p.adapt_to_noise = false;
    const double fixed = surfaceError(superResolveQuadric({c.sparse}, p, &rf), c.mesh);
    std::printf("noise %.2f%%: measured %.3g m (q %.3f), kernel %.3g: %.4e; fixed kernel %.3g: %.4e\n", noise * 100,
                ra.noise_sigma, ra.noise_sigma / ra.patch_radius, ra.kernel_scale, adaptive, rf.kernel_scale, fixed);
    EXPECT_TRUE(ra.noise_estimated);
    EXPECT_FLOAT_EQ(rf.kernel_scale, 0.7f);
    if (noise > 0.001f) {
      EXPECT_GT(ra.kernel_scale, 1.1f);
      EXPECT_LT(adaptive, 0.95 * fixed);
    } else {
      EXPECT_LT(adaptive, 1.01 * fixed);
    }
  }
}

TEST(QuadricSuperResolution, NoiseAdaptiveRunIsThreadCountIndependent) {
  const TriangleMesh mesh = synthetic::engravedPlane(0.5f, 0.1f, 0.006f, 150);
  Positions in = synthetic::sampleMesh(mesh, 3000, 5);
  synthetic::addGaussianNoise(in, 0.01f, 3);  // loud: the kernel is adapted, or the scan denoised
  for (const auto denoise : {QuadricSuperResolutionParameters::Denoise::Off, QuadricSuperResolutionParameters::Denoise::Auto}) {
    QuadricSuperResolutionParameters p;
    p.adapt_to_noise = true;
    p.denoise_input = denoise;
    p.factor = 2;
    const int threads = omp_get_max_threads();
    QuadricSuperResolutionReport r1, r2;
    omp_set_num_threads(1);
    const Positions a = superResolveQuadric({in}, p, &r1);
    omp_set_num_threads(2);
    const Positions b = superResolveQuadric({in}, p, &r2);
    omp_set_num_threads(threads);
    EXPECT_EQ(r1.denoised, denoise == QuadricSuperResolutionParameters::Denoise::Auto);
    // Denoised first, the kernel is the quiet one.
    if (r1.denoised) EXPECT_FLOAT_EQ(r1.kernel_scale, 0.7f); else EXPECT_GT(r1.kernel_scale, 0.7f);
    EXPECT_EQ(r1.noise_sigma, r2.noise_sigma);
    EXPECT_EQ(r1.kernel_scale, r2.kernel_scale);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])));
  }
}

// The scans run in spatial order: the output is the same set of points, in the same order,
// whatever the order of the input points (raw and denoised-first runs, two scans, a NaN).
TEST(QuadricSuperResolution, OutputDoesNotDependOnTheInputOrder) {
  const TriangleMesh mesh = synthetic::engravedPlane(0.5f, 0.1f, 0.006f, 150);
  Positions in = synthetic::sampleMesh(mesh, 3000, 5);
  synthetic::addGaussianNoise(in, 0.01f, 3);
  in[7] = Eigen::Vector3f::Constant(NAN);
  const Positions second = synthetic::sampleMesh(mesh, 1500, 6);
  paps::Random rng(9);
  auto shuffled = [&](Positions p) {
    for (std::size_t i = p.size() - 1; i > 0; --i) std::swap(p[i], p[rng.below(i + 1)]);
    return p;
  };
  for (const auto denoise : {QuadricSuperResolutionParameters::Denoise::Off, QuadricSuperResolutionParameters::Denoise::Auto}) {
    QuadricSuperResolutionParameters p;
    p.denoise_input = denoise;
    p.factor = 2;
    QuadricSuperResolutionReport r1, r2;
    const Positions a = superResolveQuadric({in, second}, p, &r1);
    const Positions b = superResolveQuadric({shuffled(in), shuffled(second)}, p, &r2);
    EXPECT_EQ(r1.denoised, denoise == QuadricSuperResolutionParameters::Denoise::Auto);
    EXPECT_EQ(r1.patch_radius, r2.patch_radius);
    EXPECT_EQ(r1.similarity_radius, r2.similarity_radius);
    ASSERT_EQ(a.size(), 5998u);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])));
  }
}

// Units: the same cloud in metres and in units 2^27 times larger (about nanometres) or
// 2^13 times smaller gives the same output, scaled, bit for bit (power-of-two scales are exact
// in float). The arc-length inversion of the bins once stopped at an absolute step of 1e-9,
// i.e. after one step on a nanometre patch (0.03 spacings RMS off on rs1).
TEST(QuadricSuperResolution, OutputScalesWithTheUnits) {
  const TriangleMesh mesh = synthetic::engravedPlane(0.5f, 0.1f, 0.006f, 150);
  Positions in = synthetic::sampleMesh(mesh, 3000, 5);
  synthetic::addGaussianNoise(in, 0.001f, 3);
  QuadricSuperResolutionParameters p;
  p.factor = 2;
  const Positions ref = superResolveQuadric({in}, p);
  ASSERT_EQ(ref.size(), 6000u);
  for (const int e : {-27, 13}) {
    const float scale = std::ldexp(1.f, e);
    Positions scaled = in;
    for (auto& q : scaled) q *= scale;
    Positions out = superResolveQuadric({scaled}, p);
    ASSERT_EQ(out.size(), ref.size()) << e;
    for (auto& q : out) q /= scale;
    EXPECT_EQ(0, std::memcmp(out.data(), ref.data(), ref.size() * sizeof(ref[0]))) << "2^" << e;
  }
}

// Denoising first (the default under heavy noise) against QSR on the raw scan, error of the
// output to the true surface (interior) on the 12K engraved plane. At 0.05% noise (q under
// 0.05) the default does not denoise and gives the raw run's output bit for bit.
TEST(QuadricSuperResolution, NoisyScansAreDenoisedFirst) {
  for (float noise : {0.0005f, 0.005f}) {
    Case c;
    synthetic::addGaussianNoise(c.sparse, noise, 9);
    QuadricSuperResolutionParameters p;
    QuadricSuperResolutionReport ra, ro;
    const Positions a = superResolveQuadric({c.sparse}, p, &ra);
    p.denoise_input = QuadricSuperResolutionParameters::Denoise::Off;
    const Positions o = superResolveQuadric({c.sparse}, p, &ro);
    const double auto_err = surfaceError(a, c.mesh), raw_err = surfaceError(o, c.mesh);
    std::printf("noise %.2f%%: q %.3f, noise growth 2R / R %.2f, denoised %d: %.4e; raw %.4e\n", noise * 100,
                ra.noise_sigma / ra.patch_radius, ra.noise_growth, int(ra.denoised), auto_err, raw_err);
    EXPECT_TRUE(ra.noise_estimated);
    EXPECT_FALSE(ro.denoised);
    ASSERT_EQ(a.size(), o.size());
    if (noise > 0.001f) {
      EXPECT_TRUE(ra.denoised);
      EXPECT_LT(auto_err, 0.8 * raw_err);  // measured 0.70 (2.301e-3 against 3.284e-3)
    } else {
      // q 0.036: quiet, and the relief shows at the patch scale (the noise measured over balls
      // of 2R grows), so the scan is kept as it is.
      EXPECT_GE(ra.noise_growth, 1.3f);
      EXPECT_FALSE(ra.denoised);
      EXPECT_EQ(0, std::memcmp(a.data(), o.data(), a.size() * sizeof(a[0])));
    }
  }
  // On: denoised whatever the noise.
  Case c;
  QuadricSuperResolutionParameters p;
  p.denoise_input = QuadricSuperResolutionParameters::Denoise::On;
  p.factor = 1;
  QuadricSuperResolutionReport r;
  superResolveQuadric({c.sparse}, p, &r);
  EXPECT_TRUE(r.denoised);
}

// A quiet scan of a surface smooth at the patch scale (the scan-line ground: noise about 1% of
// R, the same over balls of 2R) is denoised first too: nothing there for the denoiser to
// flatten. Measured on the bench's scan-line shape: 1.279e-3 m to the ground against 1.534e-3
// kept as it is (docs/superresolution.md, "Scan-line sampling").
TEST(QuadricSuperResolution, QuietSmoothScansAreDenoisedFirst) {
  const Positions scan = synthetic::scanLinePass({}, 5);
  QuadricSuperResolutionParameters p;
  p.factor = 2;
  QuadricSuperResolutionReport ra, ro;
  const Positions a = superResolveQuadric({scan}, p, &ra);
  p.denoise_input = QuadricSuperResolutionParameters::Denoise::Off;
  const Positions o = superResolveQuadric({scan}, p, &ro);
  const double ea = synthetic::rmsDistanceToWavyGround(a), eo = synthetic::rmsDistanceToWavyGround(o);
  std::printf("scan lines x2: q %.4f, noise growth 2R / R %.3f, denoised %d: %.4e; kept as it is %.4e\n",
              ra.noise_sigma / ra.patch_radius, ra.noise_growth, int(ra.denoised), ea, eo);
  EXPECT_GT(ra.noise_sigma, 0.005f * ra.patch_radius);
  EXPECT_LT(ra.noise_sigma, 0.05f * ra.patch_radius);
  EXPECT_GT(ra.noise_growth, 0.8f);
  EXPECT_LT(ra.noise_growth, 1.3f);
  EXPECT_TRUE(ra.denoised);
  EXPECT_FALSE(ro.denoised);
  EXPECT_EQ(ro.noise_growth, 0.f);  // not measured when the input is kept whatever
  EXPECT_LT(ea, 0.9 * eo);
}

// Under heavy noise (q >= 0.6) the denoiser's own default runs two passes or more; before QSR
// it runs one up to q = 0.75 (the aggregation is the second filter; measured on rs1 at 0.5%,
// docs/superresolution.md), and its own count from there (dense scans under heavy noise).
// The denoised-first run equals, bit for bit, QSR on the raw scan hand-denoised that way.
TEST(QuadricSuperResolution, DenoisingFirstIsTheNoiseResolvedDenoiserWithOnePassUpToQ075) {
  const TriangleMesh mesh = synthetic::engravedPlane(1.f, 0.1f, 0.006f, 300);
  Positions raw = synthetic::sampleMesh(mesh, 4000, 5);
  synthetic::addGaussianNoise(raw, 0.03f, 9);
  // The denoiser's base radius (its target count): the given noise sets q.
  const float r0 = radiusForNeighbourCount(raw, SpatialIndex(raw), SimilarityDenoisingParameters{}.target_neighbours);
  for (const float q : {0.7f, 1.0f}) {
    QuadricSuperResolutionParameters p;
    p.factor = 2;
    p.noise_sigma = q * r0;
    p.denoise_input = QuadricSuperResolutionParameters::Denoise::On;
    // Both runs at the patch radius QSR would choose on the raw scan.
    p.patch_radius = buildRadiusNeighbourhood(raw, 0.f, p.target_neighbours, 4 * p.target_neighbours).radius;
    QuadricSuperResolutionReport r;
    const Positions first = superResolveQuadric({raw}, p, &r);
    ASSERT_TRUE(r.denoised);

    SimilarityDenoisingParameters dp;
    dp.noise_sigma = p.noise_sigma;
    SimilarityDenoisingParameters dr = noiseResolvedParameters(raw, dp);
    if (q < 0.75f) {
      ASSERT_EQ(dr.passes, 2) << "the case must be in the denoiser's two-pass regime";
      dr.passes = 1;
    } else {
      ASSERT_EQ(dr.passes, 3) << "q = 1: the denoiser's three passes";
    }
    EXPECT_EQ(r.denoise_passes, dr.passes) << "q = " << q;
    const Positions hand = denoiseBySimilarity(raw, dr);
    p.denoise_input = QuadricSuperResolutionParameters::Denoise::Off;
    const Positions second = superResolveQuadric({hand}, p);
    ASSERT_EQ(first.size(), second.size());
    EXPECT_EQ(0, std::memcmp(first.data(), second.data(), first.size() * sizeof(first[0]))) << "q = " << q;
  }
  // And the raw scan is left as it was.
  Positions again = synthetic::sampleMesh(mesh, 4000, 5);
  synthetic::addGaussianNoise(again, 0.03f, 9);
  EXPECT_EQ(0, std::memcmp(raw.data(), again.data(), raw.size() * sizeof(raw[0])));
}

// A dense scan under heavy noise (q 1.37 for the denoiser, above its subset ratio 1.15): QSR's
// output is about as close to the surface as the denoiser's own output (the first denoising
// runs the denoiser's passes and subsets; with one pass it was 1.5x farther on rs1 at 2M).
TEST(QuadricSuperResolution, DenseScansUnderHeavyNoiseEndNearTheDenoisersOutput) {
  const TriangleMesh mesh = synthetic::engravedPlane(1.f, 0.1f, 0.01f, 200);
  Positions raw = synthetic::sampleMesh(mesh, 40000, 17);
  synthetic::addGaussianNoise(raw, 0.03f, 18);
  const PointToMeshDistance truth(mesh);
  SimilarityDenoisingReport dr;
  const double denoiser = pointToMeshError(denoiseBySimilarity(raw, {}, &dr), truth).rmse;
  QuadricSuperResolutionParameters p;
  p.factor = 2;
  QuadricSuperResolutionReport r;
  const double qsr = pointToMeshError(superResolveQuadric({raw}, p, &r), truth).rmse;
  QuadricSuperResolutionParameters one = p;
  one.noise_sigma = r.noise_sigma;
  std::printf("engraved plane 40K, noise 3%%: denoiser (%zu subsets, %d passes) %.4g, QSR x2 (first denoising "
              "%zu subsets, %d passes) %.4g\n", dr.subsets, dr.passes, denoiser, r.denoise_subsets, r.denoise_passes, qsr);
  ASSERT_TRUE(r.denoised);
  EXPECT_EQ(r.denoise_passes, dr.passes);
  // The denoiser's own choice, interleaved subsets included.
  EXPECT_EQ(r.denoise_subsets, dr.subsets);
  EXPECT_GE(r.denoise_subsets, 2u);
  EXPECT_LT(qsr, 1.1 * denoiser);  // 7.683e-3 against 8.595e-3 (2 subsets, 3 passes)
}

TEST(QuadricSuperResolution, NoiseParametersBadValuesAndTinyClouds) {
  QuadricSuperResolutionParameters p;
  p.noise_sigma = -1e-3f;
  EXPECT_THROW(p.validate(), InvalidParameter);
  p.noise_sigma = NAN;
  EXPECT_THROW(superResolveQuadric({Positions(100, Eigen::Vector3f::Zero())}, p), InvalidParameter);
  p = {};
  p.kernel_scale = -0.7f;
  EXPECT_THROW(p.validate(), InvalidParameter);
  p.kernel_scale = INFINITY;
  EXPECT_THROW(p.validate(), InvalidParameter);
  // A few points: too few for a noise fit; the run still answers with the fixed kernel.
  Positions few;
  for (int i = 0; i < 12; ++i) few.emplace_back(0.01f * (i % 4), 0.01f * (i / 4), 0.f);
  few.emplace_back(NAN, 0.f, 0.f);
  QuadricSuperResolutionReport r;
  const Positions out = superResolveQuadric({few}, {}, &r);
  EXPECT_EQ(out.size(), 48u);
  EXPECT_FLOAT_EQ(r.kernel_scale, 0.7f);
  // NaN points are skipped, and fewer than 10 finite points is a clear error.
  Positions nine(few.begin(), few.begin() + 9);
  nine.emplace_back(NAN, NAN, NAN);
  EXPECT_THROW(superResolveQuadric({nine}, {}), InvalidInput);
  // Extreme kernels: the SR bins' windows of x columns are capped (a kernel of 1e-6 asked for
  // millions of columns per patch: 100K points ran for minutes). The output stays on the plane.
  Positions grid;
  for (int i = 0; i < 400; ++i) grid.emplace_back(0.01f * (i % 20), 0.01f * (i / 20), 0.f);
  for (float kernel : {1e-6f, 1e3f}) {
    p = {};
    p.kernel_scale = kernel;
    p.factor = 2;
    const Positions up = superResolveQuadric({grid}, p);
    ASSERT_EQ(up.size(), 800u) << kernel;
    for (const auto& q : up) {
      ASSERT_TRUE(q.allFinite()) << kernel;
      EXPECT_NEAR(q.z(), 0.f, 1e-5f) << kernel;
    }
  }
  // An output count past 1000x the scan is named before any work, not an allocation failure.
  p = {};
  p.output_count = SIZE_MAX;
  try {
    superResolveQuadric({few}, p);
    ADD_FAILURE() << "accepted";
  } catch (const InvalidParameter& e) {
    EXPECT_EQ(e.parameter(), "output_count");
  }
}

// The default pass of paps::synthetic (2 to 7 cm along a line, 9 cm to 0.9 m across, every
// return stored twice, 5 mm range noise).
Positions scanLineGround() { return synthetic::scanLinePass({}, 5); }

// On scan lines the balls along one or two lines are too thin for a quadric: their fits are
// remade on a support reaching the next lines, and their seeds stay nearer the returns (half
// the disc). QSR then lands closer to the ground than APSS and PCL's MLS, and closer than the
// returns themselves, with the default disc as with the narrow one (0.6 spacings, APSS's is
// 0.68). Measured: docs/superresolution.md, "Scan-line sampling" and "Narrower seed discs on
// thin balls" (this test prints the figures).
TEST(QuadricSuperResolution, ScanLinesAreFittedAcrossTheLines) {
  const Positions scan = scanLineGround();
  QuadricSuperResolutionParameters wide, wide_even, narrow, narrow_even, unwidened;
  wide.factor = wide_even.factor = narrow.factor = narrow_even.factor = unwidened.factor = 4;
  narrow.seed_disc = narrow_even.seed_disc = unwidened.seed_disc = 0.6f;
  wide_even.thin_disc = narrow_even.thin_disc = unwidened.thin_disc = 1.f;  // one disc everywhere
  unwidened.widen_sparse_fits = false;
  QuadricSuperResolutionReport rw, rw1, rn, rn1, ru;
  const Positions ow = superResolveQuadric({scan}, wide, &rw);
  const Positions ow1 = superResolveQuadric({scan}, wide_even, &rw1);
  const Positions on = superResolveQuadric({scan}, narrow, &rn);
  const Positions on1 = superResolveQuadric({scan}, narrow_even, &rn1);
  const Positions ou = superResolveQuadric({scan}, unwidened, &ru);
  MlsUpsamplingParameters mp;
  mp.factor = 4;
  MlsUpsamplingReport ra;
  const Positions oa = upsampleMls(scan, MlsSurface::Apss, mp, &ra);
  // PCL's MLS upsampling as the bench runs it (order 2, voxel-grid dilation at the output
  // spacing, the search radius of QSR's patches).
  pcl::MovingLeastSquares<pcl::PointXYZ, pcl::PointXYZ> mls;
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  writePositions(scan, *cloud);
  mls.setInputCloud(cloud);
  mls.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  mls.setPolynomialOrder(2);
  mls.setSearchRadius(rn.patch_radius);
  mls.setUpsamplingMethod(pcl::MovingLeastSquares<pcl::PointXYZ, pcl::PointXYZ>::VOXEL_GRID_DILATION);
  mls.setDilationVoxelSize(rn.spacing / 2);
  mls.setDilationIterations(1);
  pcl::PointCloud<pcl::PointXYZ> pcl_out;
  mls.process(pcl_out);
  Positions op = positionsOf(pcl_out);
  op.erase(std::remove_if(op.begin(), op.end(), [](const Eigen::Vector3f& p) { return !isFinite(p); }), op.end());
  using synthetic::rmsDistanceToWavyGround;
  const double ew = rmsDistanceToWavyGround(ow), ew1 = rmsDistanceToWavyGround(ow1);
  const double en = rmsDistanceToWavyGround(on), en1 = rmsDistanceToWavyGround(on1), eu = rmsDistanceToWavyGround(ou);
  const double ea = rmsDistanceToWavyGround(oa), ep = rmsDistanceToWavyGround(op), ei = rmsDistanceToWavyGround(scan);
  std::printf("scan lines: %zu returns -> %zu; to the ground: input %.3e, QSR disc 1.2 %.3e (%.3g m; one disc "
              "everywhere %.3e), QSR disc 0.6 %.3e (%.3g m; one disc everywhere %.3e, and unwidened %.3e), APSS %.3e "
              "(%.3g m), PCL MLS voxel %.3e (%zu points); thin balls %zu, widened %zu, narrowed discs %zu\n",
              scan.size(), ow.size(), ei, ew, rw.disc_radius, ew1, en, rn.disc_radius, en1, eu, ea, ra.disc_radius,
              ep, op.size(), rn.thin_balls, rn.widened_fits, rw.narrowed_discs);
  ASSERT_EQ(on.size(), 4 * scan.size());
  EXPECT_NEAR(rn.disc_radius, 0.5f * rw.disc_radius, 1e-6f * rw.disc_radius);
  EXPECT_EQ(rn.spacing, rw.spacing);
  EXPECT_GT(rn.thin_balls, scan.size() / 10);
  EXPECT_EQ(ru.thin_balls, 0u);
  EXPECT_GT(rw.narrowed_discs, scan.size() / 10);
  EXPECT_EQ(rw1.narrowed_discs, 0u);
  // One disc everywhere (as before session 12), narrow: the widened fits.
  EXPECT_LT(en1, ei);        // closer to the ground than the returns
  EXPECT_LT(en1, 0.6 * ea);  // measured 0.37
  EXPECT_LT(en1, 0.6 * eu);  // what the widening brings (measured 0.39)
  // Seeds between the lines read SR bins whose points lie along a line: with the ridge on the
  // bins' slopes the default disc lands within 1.2x the returns' distance (measured 1.176; a
  // plain first-order fit 1.326, session 11's pivot switch 1.277).
  EXPECT_LT(ew1, 1.2 * ei);
  EXPECT_GT(ew1, 1.2 * en1);  // the trade-off the disc parameter is for
  // The default: thin balls seed over half discs. The default disc then lands closer than the
  // returns (measured 0.71 of their distance) and 0.60 of one disc everywhere.
  EXPECT_LT(ew, ei);
  EXPECT_LT(ew, 0.7 * ew1);
  EXPECT_LT(ew, ea);
  EXPECT_LT(ew, ep);
  EXPECT_LT(en, en1);  // measured 1.261e-3 against 1.533e-3
  // A seed stays within its disc of the return it was spread from (then moves along the normal
  // by the projection, a few mm here).
  const SpatialIndex index(scan);
  std::vector<int> idx;
  std::vector<float> d2;
  float farthest = 0;
  for (const auto& p : on) {
    index.nearestK(p, 1, idx, d2);
    farthest = std::max(farthest, std::sqrt(d2[0]));
  }
  EXPECT_LT(farthest, rn.disc_radius + 0.02f);
  QuadricSuperResolutionParameters bad;
  bad.seed_disc = 0.f;
  EXPECT_THROW(bad.validate(), InvalidParameter);
  bad.seed_disc = NAN;
  EXPECT_THROW(bad.validate(), InvalidParameter);
  bad = QuadricSuperResolutionParameters();
  for (const float t : {0.f, -0.5f, 1.01f, NAN}) {
    bad.thin_disc = t;
    EXPECT_THROW(bad.validate(), InvalidParameter) << t;
  }
  bad.thin_disc = 1.f;
  EXPECT_NO_THROW(bad.validate());
}

// A uniform point of the unit sphere's upper (z > 0) or lower half.
Eigen::Vector3f onUnitHemisphere(Random& rng, bool upper) {
  for (;;) {
    Eigen::Vector3f v = rng.gaussian3().cast<float>();
    v.normalize();
    if ((v.z() > 0) == upper) return v;
  }
}

// A sphere whose lower half is sampled 10x more sparsely than its upper half, every point stored
// twice: at the radius chosen on the dense half, the sparse half's balls hold too few distinct
// positions for a quadric. Widened fits (the default) put its output on the sphere; without
// them those points keep the plane through their few neighbours.
TEST(QuadricSuperResolution, SparsePartsAreFittedOnAWiderSupport) {
  Random rng(11);
  Positions pts;
  auto onSphere = [&](bool upper) { return onUnitHemisphere(rng, upper); };
  for (int i = 0; i < 3000; ++i) { const Eigen::Vector3f v = onSphere(true); pts.push_back(v); pts.push_back(v); }
  for (int i = 0; i < 300; ++i) { const Eigen::Vector3f v = onSphere(false); pts.push_back(v); pts.push_back(v); }
  auto lowerRms = [](const Positions& out) {
    double s = 0;
    std::size_t n = 0;
    for (const auto& p : out)
      if (p.z() < -0.5f) { s += (p.norm() - 1.0) * (p.norm() - 1.0); ++n; }
    return std::sqrt(s / std::max<std::size_t>(1, n));
  };
  QuadricSuperResolutionParameters on, off;
  off.widen_sparse_fits = false;
  QuadricSuperResolutionReport r_on, r_off;
  const Positions o_on = superResolveQuadric({pts}, on, &r_on);
  const Positions o_off = superResolveQuadric({pts}, off, &r_off);
  const double e_on = lowerRms(o_on), e_off = lowerRms(o_off);
  std::printf("sparse half: widened %zu, ill-posed %zu (without widening %zu), thin %zu; radial RMS below z = -0.5: "
              "%.3e vs %.3e\n",
              r_on.widened_fits, r_on.ill_posed_fits, r_off.ill_posed_fits, r_on.thin_balls, e_on, e_off);
  EXPECT_EQ(r_off.widened_fits, 0u);
  EXPECT_GT(r_off.ill_posed_fits, 300u);
  // Near the equator the nearest positions lie on the dense side (one-sided): those keep the
  // plane, the rest of the sparse half is widened.
  EXPECT_GT(r_on.widened_fits, r_off.ill_posed_fits / 2);
  // Every ill-posed fit that went is a widened one; the other widened fits are thin balls (the
  // sparse half's balls near the equator, along its rim).
  EXPECT_LE(r_on.ill_posed_fits, r_off.ill_posed_fits);
  EXPECT_GE(r_on.widened_fits, r_off.ill_posed_fits - r_on.ill_posed_fits);
  EXPECT_LE(r_on.widened_fits, r_off.ill_posed_fits - r_on.ill_posed_fits + r_on.thin_balls);
  EXPECT_LT(e_on, 0.5 * e_off);
  // The widened fits do not depend on the thread count either.
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  QuadricSuperResolutionReport r_one;
  const Positions o_one = superResolveQuadric({pts}, on, &r_one);
  omp_set_num_threads(threads);
  EXPECT_EQ(r_one.widened_fits, r_on.widened_fits);
  ASSERT_EQ(o_one.size(), o_on.size());
  EXPECT_EQ(std::memcmp(o_one.data(), o_on.data(), o_on.size() * sizeof(o_on[0])), 0);
}

// A sparse part whose every position is stored many times (merged scans, float-rounded
// coordinates) is widened like one stored once: the wider support counts distinct positions,
// and reaching 30 of them no longer means walking through every copy (before, a search
// through 64 x 30 points gave up on 200 copies each and kept the ill-posed plane: 3,096
// widened fits instead of 17,496).
TEST(QuadricSuperResolution, PilesOfCopiesAreWidenedToo) {
  Random rng(11);
  Positions pts;
  auto onSphere = [&](bool upper) { return onUnitHemisphere(rng, upper); };
  for (int i = 0; i < 3000; ++i) pts.push_back(onSphere(true));
  for (int i = 0; i < 150; ++i) {
    const Eigen::Vector3f v = onSphere(false);
    for (int c = 0; c < 200; ++c) pts.push_back(v);
  }
  QuadricSuperResolutionParameters on, off;
  off.widen_sparse_fits = false;
  on.factor = off.factor = 1.5f;
  QuadricSuperResolutionReport r_on, r_off;
  superResolveQuadric({pts}, on, &r_on);
  superResolveQuadric({pts}, off, &r_off);
  std::printf("piles of 200 copies: widened %zu, ill-posed %zu (without widening %zu)\n", r_on.widened_fits,
              r_on.ill_posed_fits, r_off.ill_posed_fits);
  // Every copy of a lower position has a ball of fewer than 6 distinct positions.
  EXPECT_GE(r_off.ill_posed_fits, 150u * 200u);
  // Most of them are refitted on 30 distinct positions (those near the equator are one-sided
  // and keep their plane).
  EXPECT_GT(r_on.widened_fits, r_off.ill_posed_fits / 2);
}

// The output normals are the SR surface's: on the engraved plane they follow the relief (the
// quadrics' slopes plus those of the SR heights), not just the base plane; one orientation;
// the positions are those of a run without normals; the PCL stage writes them into
// PointNormal outputs.
TEST(QuadricSuperResolution, NormalsFollowTheRelief) {
  Case c;
  synthetic::addGaussianNoise(c.sparse, 0.0001f, 9);
  QuadricSuperResolutionParameters p;
  p.factor = 3;
  Normals normals;
  const Positions out = superResolveQuadric({c.sparse}, p, nullptr, {}, &normals);
  ASSERT_EQ(normals.size(), out.size());
  EXPECT_EQ(out, superResolveQuadric({c.sparse}, p));
  // The relief's normal where each output point lands (nearest triangle of the fine mesh).
  const PointToMeshDistance truth(c.mesh);
  Normals got, want;
  std::size_t up = 0, flat_closer = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (std::abs(out[i].x()) > 0.45f || std::abs(out[i].y()) > 0.45f) continue;
    ASSERT_TRUE(isFinite(normals[i])) << i;
    int t = -1;
    truth.distance(out[i], nullptr, &t);
    ASSERT_GE(t, 0);
    const auto& tri = c.mesh.triangles[t];
    want.push_back((c.mesh.vertices[tri[1]] - c.mesh.vertices[tri[0]])
                       .cross(c.mesh.vertices[tri[2]] - c.mesh.vertices[tri[0]])
                       .normalized());
    got.push_back(normals[i]);
    up += normals[i].z() > 0;
    // Closer to the base plane's normal than to the relief's: the relief not followed.
    flat_closer += std::abs(normals[i].z()) > std::abs(normals[i].dot(want.back()));
  }
  EXPECT_TRUE(up == 0 || up == got.size()) << up << " of " << got.size() << " point up";
  const ErrorStats e = summarize(normalAngleErrors(got, want));
  // The relief tilts the true normals by up to 20 degrees. Measured: 2.84 degrees RMS, 4.90 at
  // the 95th percentile, 338 of 28,897 normals closer to the plane's normal than to the relief's.
  std::printf("normal angle RMS %.2f, p95 %.2f degrees; %zu of %zu closer to the plane's normal\n", e.rmse, e.p95,
              flat_closer, got.size());
  EXPECT_LT(e.rmse, 3.5);
  EXPECT_LT(e.p95, 6.5);
  EXPECT_LT(flat_closer, got.size() / 20);
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  writePositions(c.sparse, *cloud);
  QuadricSuperResolution<pcl::PointXYZ, pcl::PointNormal> qsr;
  qsr.setInputCloud(cloud);
  qsr.setParameters(p);
  pcl::PointCloud<pcl::PointNormal> cloud_out;
  qsr.process(cloud_out);
  ASSERT_EQ(cloud_out.size(), out.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_EQ(Eigen::Vector3f(cloud_out[i].getVector3fMap()), out[i]) << i;
    ASSERT_EQ(Eigen::Vector3f(cloud_out[i].getNormalVector3fMap()), normals[i]) << i;
  }
  // PCL's curvature field, as its MLS fills it: the surface variation of the input ball each
  // point was made from. The relief bends the balls a little; positions do not change.
  std::vector<float> variation;
  const Positions again = superResolveQuadric({c.sparse}, p, nullptr, {}, nullptr, &variation);
  ASSERT_EQ(again, out);
  float most = 0.f;
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_EQ(cloud_out[i].curvature, variation[i]) << i;
    ASSERT_TRUE(std::isfinite(variation[i])) << i;
    most = std::max(most, variation[i]);
  }
  EXPECT_GT(most, 1e-4f);
  EXPECT_LT(most, 0.1f);
  // A viewpoint below the plane turns every normal down, whatever the propagation chose.
  qsr.setViewPoint(0.f, 0.f, -1.f);
  qsr.process(cloud_out);
  ASSERT_EQ(cloud_out.size(), out.size());
  for (std::size_t i = 0; i < out.size(); ++i) ASSERT_LT(cloud_out[i].normal_z, 0.f) << i;
  // Without one, a cloud that knows its sensor's position (sensor_origin_) is seen from there,
  // as pcl::NormalEstimation does: below, then above the plane; positions unchanged.
  for (const float z : {-1.f, 1.f}) {
    cloud->sensor_origin_ = Eigen::Vector4f(0.f, 0.f, z, 0.f);
    QuadricSuperResolution<pcl::PointXYZ, pcl::PointNormal> seen;
    seen.setInputCloud(cloud);
    seen.setParameters(p);
    seen.process(cloud_out);
    ASSERT_EQ(cloud_out.size(), out.size());
    for (std::size_t i = 0; i < out.size(); ++i) {
      ASSERT_EQ(Eigen::Vector3f(cloud_out[i].getVector3fMap()), out[i]) << i;
      ASSERT_GT(cloud_out[i].normal_z * z, 0.f) << i << " seen from z = " << z;
    }
  }
  // An input with normals of its own: the output takes their side (here down, although the
  // sensor origin is above), a given viewpoint still wins; positions unchanged.
  auto with_normals = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  writePositions(c.sparse, *with_normals);
  for (auto& q : *with_normals) q.getNormalVector3fMap() = Eigen::Vector3f(0.3f, 0.f, -0.95f).normalized();
  with_normals->sensor_origin_ = Eigen::Vector4f(0.f, 0.f, 1.f, 0.f);
  QuadricSuperResolution<pcl::PointNormal, pcl::PointNormal> hinted;
  hinted.setInputCloud(with_normals);
  hinted.setParameters(p);
  hinted.process(cloud_out);
  ASSERT_EQ(cloud_out.size(), out.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_EQ(Eigen::Vector3f(cloud_out[i].getVector3fMap()), out[i]) << i;
    ASSERT_LT(cloud_out[i].normal_z, 0.f) << i << ": not on the input normals' side";
  }
  hinted.setViewPoint(0.f, 0.f, 1.f);
  hinted.process(cloud_out);
  for (std::size_t i = 0; i < out.size(); ++i) ASSERT_GT(cloud_out[i].normal_z, 0.f) << i;
}

// Nearest-neighbour distance of every point to the others, sorted.
std::vector<float> spacingsOf(const Positions& p) {
  const SpatialIndex index(p);
  std::vector<int> idx;
  std::vector<float> d2;
  std::vector<float> s;
  for (const auto& x : p) {
    index.nearestK(x, 2, idx, d2);
    s.push_back(std::sqrt(d2.back()));
  }
  std::sort(s.begin(), s.end());
  return s;
}

// Tiles (max_tile_points): the radius, the noise and the denoising decision are the whole
// scan's, the output count is the one-piece count, and the output is as close to the surface,
// with no more close pairs than one piece where the tiles meet.
TEST(QuadricSuperResolution, TilesKeepTheAccuracyAndTheChoicesOfTheWholeScan) {
  for (float noise : {0.0005f, 0.005f}) {
    Case c;
    synthetic::addGaussianNoise(c.sparse, noise, 9);
    QuadricSuperResolutionParameters p;
    QuadricSuperResolutionReport one, tiled;
    const Positions a = superResolveQuadric({c.sparse}, p, &one);
    p.max_tile_points = 3000;
    std::vector<int> source;
    const Positions b = superResolveQuadric({c.sparse}, p, &tiled, {}, nullptr, nullptr, &source);
    const double ea = surfaceError(a, c.mesh), eb = surfaceError(b, c.mesh);
    const std::vector<float> sa = spacingsOf(a), sb = spacingsOf(b);
    const float median = sa[sa.size() / 2];
    auto closePairs = [&](const std::vector<float>& s) {
      return std::lower_bound(s.begin(), s.end(), 0.25f * median) - s.begin();
    };
    std::printf("noise %.2f%%: one piece %.4e, %zu tiles (largest %zu) %.4e; denoised %d/%d; points closer than "
                "1/4 of the median spacing: %td / %td; rsim %.4g / %.4g, grids %d->%d / %d->%d\n",
                noise * 100, ea, tiled.tiles, tiled.largest_tile, eb, int(one.denoised), int(tiled.denoised),
                closePairs(sa), closePairs(sb), one.similarity_radius, tiled.similarity_radius, one.grid_lr,
                one.grid_sr, tiled.grid_lr, tiled.grid_sr);
    EXPECT_EQ(one.tiles, 1u);
    EXPECT_EQ(tiled.tiles, 4u);
    EXPECT_GT(tiled.largest_tile, 3000u);
    EXPECT_LT(tiled.largest_tile, 4500u);
    EXPECT_EQ(b.size(), a.size());
    EXPECT_EQ(tiled.output, b.size());
    EXPECT_EQ(tiled.patch_radius, one.patch_radius);
    EXPECT_EQ(tiled.noise_sigma, one.noise_sigma);
    EXPECT_EQ(tiled.denoised, one.denoised);
    EXPECT_EQ(tiled.grid_lr, one.grid_lr);
    EXPECT_LT(eb, 1.1 * ea);
    // Each tile's seeds keep their distance from the tiles before (measured: 316 and 76 in
    // tiles against 372 and 118 in one piece; 410 and 174 when each tile was thinned alone).
    EXPECT_LE(closePairs(sb), closePairs(sa) + static_cast<std::ptrdiff_t>(b.size() / 1000));
    ASSERT_EQ(source.size(), b.size());
    for (std::size_t i = 0; i < b.size(); ++i) {
      ASSERT_GE(source[i], 0);
      ASSERT_LT(source[i], static_cast<int>(c.sparse.size()));
      ASSERT_LT((b[i] - c.sparse[source[i]]).norm(), 1.5f * one.patch_radius) << i;  // noise, denoised
    }
  }
}

// Each tile orients its normals by propagation over its own points; where it meets the tiles
// before it, it takes their side, and the whole is turned at the end as one piece turns it.
// On a closed sphere cut into 8 tiles every output normal points out, as in one piece (each
// piece on its own turns its normals up: measured, 16,114 of 32,000 out without the hints).
// The same through the PCL stage.
TEST(QuadricSuperResolution, TiledNormalsRunOnAcrossTiles) {
  Positions sphere;
  Random rng(4);
  while (sphere.size() < 16000) {
    const Eigen::Vector3f v = rng.gaussian3().cast<float>();
    if (v.norm() > 1e-3f) sphere.push_back(v.normalized());
  }
  QuadricSuperResolutionParameters p;
  p.factor = 2;
  p.max_tile_points = 2000;
  QuadricSuperResolutionReport r;
  Normals normals;
  const Positions out = superResolveQuadric({sphere}, p, &r, {}, &normals);
  ASSERT_EQ(normals.size(), out.size());
  EXPECT_EQ(r.tiles, 8u);
  std::size_t outward = 0, finite = 0;
  double radial = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    radial = std::max(radial, static_cast<double>(std::abs(out[i].norm() - 1.f)));
    if (!isFinite(normals[i])) continue;
    ++finite;
    outward += normals[i].dot(out[i]) > 0;
  }
  std::printf("%zu tiles: %zu of %zu normals point out, farthest off the sphere %.3e\n", r.tiles, outward, finite, radial);
  EXPECT_EQ(finite, out.size());
  EXPECT_EQ(outward, finite);
  EXPECT_LT(radial, 0.01);
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  writePositions(sphere, *cloud);
  QuadricSuperResolution<pcl::PointXYZ, pcl::PointNormal> qsr;
  qsr.setInputCloud(cloud);
  qsr.setParameters(p);
  pcl::PointCloud<pcl::PointNormal> cloud_out;
  qsr.process(cloud_out);
  ASSERT_EQ(cloud_out.size(), out.size());
  EXPECT_EQ(qsr.getReport().tiles, 8u);
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_EQ(Eigen::Vector3f(cloud_out[i].getVector3fMap()), out[i]) << i;
    ASSERT_EQ(Eigen::Vector3f(cloud_out[i].getNormalVector3fMap()), normals[i]) << i;
  }
}

// Tiles give the same output whatever the thread count and the order of the points, and read
// the other scans' points around each tile.
TEST(QuadricSuperResolution, TiledOutputIsDeterministicAndUsesTheOtherScans) {
  Case c;
  synthetic::addGaussianNoise(c.sparse, 0.0005f, 9);
  const Positions other = synthetic::sampleMesh(c.mesh, 12000, 6);
  QuadricSuperResolutionParameters p;
  p.factor = 2;
  p.max_tile_points = 3000;
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  QuadricSuperResolutionReport r1;
  const Positions one_thread = superResolveQuadric({c.sparse, other}, p, &r1);
  omp_set_num_threads(std::max(2, threads));
  QuadricSuperResolutionReport r2, alone;
  const Positions two_threads = superResolveQuadric({c.sparse, other}, p, &r2);
  omp_set_num_threads(threads);
  EXPECT_EQ(one_thread, two_threads);
  EXPECT_EQ(r1.tiles, 4u);
  // The tiles and each tile's run depend on the positions only, not on their order.
  Positions reversed(c.sparse.rbegin(), c.sparse.rend());
  EXPECT_EQ(superResolveQuadric({reversed, other}, p), one_thread);
  const Positions single = superResolveQuadric({c.sparse}, p, &alone);
  // The second scan's patches are read around each tile: about twice the patches, and more
  // similar weight per patch.
  std::printf("patches %zu with the second scan, %zu alone; K - 1 %.2f / %.2f; to the surface %.4e / %.4e\n",
              r1.patches, alone.patches, r1.mean_similar_weight, alone.mean_similar_weight,
              surfaceError(one_thread, c.mesh), surfaceError(single, c.mesh));
  EXPECT_GT(r1.patches, alone.patches * 19 / 10);
  EXPECT_GT(r1.mean_similar_weight, alone.mean_similar_weight);
  EXPECT_EQ(one_thread.size(), 24000u);
}

// A tile with no surface (here the far end of a wire, 6,000 points in a line, beside a plate)
// makes no point, as one piece would not refuse the cloud; its share goes to a tile that has
// one, and the output count is kept. The shares follow the surface a tile covers, not its
// point count: the densely sampled wire is not crowded.
TEST(QuadricSuperResolution, TilesWithoutSurfaceGiveTheirShareAway) {
  Case c;
  Positions cloud = c.sparse;
  for (int i = 0; i < 6000; ++i) cloud.push_back(Eigen::Vector3f(5.f + 3.f * i / 6000.f, 0.f, 0.f));
  QuadricSuperResolutionParameters p;
  p.factor = 2;
  auto onWire = [](const Positions& out) {
    return std::count_if(out.begin(), out.end(), [](const Eigen::Vector3f& x) { return x.x() > 1.f; });
  };
  const Positions one = superResolveQuadric({cloud}, p);
  p.max_tile_points = 4000;
  QuadricSuperResolutionReport r;
  const Positions out = superResolveQuadric({cloud}, p, &r);
  std::printf("%zu tiles; on the wire: %td in one piece, %td in tiles\n", r.tiles, onWire(one), onWire(out));
  EXPECT_GE(r.tiles, 5u);
  EXPECT_EQ(out.size(), 2 * cloud.size());
  EXPECT_EQ(one.size(), 2 * cloud.size());
  // Measured: 2,098 in one piece, 889 in tiles; 4,747 with shares by point count.
  EXPECT_LT(onWire(out), 3 * onWire(one) / 2);
  // Only wires: refused, as in one piece.
  Positions wire(cloud.begin() + 12000, cloud.end());
  p.max_tile_points = 2000;
  EXPECT_THROW(superResolveQuadric({wire}, p), InvalidInput);
  p.max_tile_points = 0;
  EXPECT_THROW(superResolveQuadric({wire}, p), InvalidInput);
}

TEST(QuadricSuperResolution, TileParametersAreChecked) {
  QuadricSuperResolutionParameters p;
  p.max_tile_points = 999;
  EXPECT_THROW(p.validate(), InvalidParameter);
  p.max_tile_points = 0;
  p.validate();
  p.tile_margin = 0.5f;
  EXPECT_THROW(p.validate(), InvalidParameter);
  p.tile_margin = 11.f;
  EXPECT_THROW(p.validate(), InvalidParameter);
}

}  // namespace surface_quadric_super_resolution_test
