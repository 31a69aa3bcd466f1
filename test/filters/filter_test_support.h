#pragma once
// Helpers shared by the tests of point-moving filters.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <omp.h>
#include <pcl/point_types.h>

#include <gtest/gtest.h>
#include <pcl/point_cloud.h>

#include <paps/core/error.h>
#include <paps/core/positions.h>
#include <paps/core/random.h>
#include <paps/core/synthetic.h>

namespace paps::test {

/// A seeded random permutation of 0..n-1: the input order of a shuffled copy.
inline std::vector<int> shuffledOrder(std::size_t n, std::uint64_t seed) {
  std::vector<int> perm(n);
  for (std::size_t i = 0; i < n; ++i) perm[i] = static_cast<int>(i);
  paps::Random rng(seed);
  for (std::size_t i = n; i > 1; --i) std::swap(perm[i - 1], perm[rng.below(i)]);
  return perm;
}

/// A NaN with a payload, so that "passed through untouched" is checked bit for bit.
inline float payloadNaN() {
  const std::uint32_t bits = 0x7fc0beefu;
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}
inline std::uint32_t bitsOf(float f) {
  std::uint32_t b;
  std::memcpy(&b, &f, sizeof b);
  return b;
}
inline bool sameBits(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return bitsOf(a.x()) == bitsOf(b.x()) && bitsOf(a.y()) == bitsOf(b.y()) && bitsOf(a.z()) == bitsOf(b.z());
}

template <typename PointT>
typename pcl::PointCloud<PointT>::Ptr toCloud(const Positions& p) {
  auto c = pcl::make_shared<pcl::PointCloud<PointT>>();
  writePositions(p, *c);
  return c;
}

/// Runs a pcl::Filter stage on a cloud and returns the output.
template <typename Filter, typename CloudPtr>
auto runFilter(Filter& f, const CloudPtr& in) {
  typename CloudPtr::element_type out;
  f.setInputCloud(in);
  f.filter(out);
  return out;
}

/// `fn` must throw paps::InvalidParameter naming `name`.
template <typename Fn>
void expectInvalidParameter(Fn fn, const std::string& name) {
  try {
    fn();
    ADD_FAILURE() << "bad " << name << " accepted";
  } catch (const InvalidParameter& e) {
    EXPECT_EQ(e.parameter(), name) << e.what();
    EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
  }
}

/// Test shapes with a known answer shared by the filters' tests.
/// `count` points uniform on the unit sphere, with Gaussian noise of `noise` x the
/// bounding-box diagonal (2 sqrt 3).
inline Positions noisySphere(std::size_t count, float noise, std::uint64_t seed) {
  Random rng(seed);
  Positions p;
  for (std::size_t i = 0; i < count; ++i) {
    Eigen::Vector3f d = rng.gaussian3().cast<float>();
    p.push_back(d.normalized());
  }
  synthetic::addGaussianNoise(p, noise, seed + 1);
  return p;
}

/// RMS of | |p| - 1 | over the finite points: the exact distance to the unit sphere.
inline double sphereRmse(const Positions& p) {
  double s = 0;
  std::size_t n = 0;
  for (const auto& x : p)
    if (isFinite(x)) {
      s += std::pow(x.cast<double>().norm() - 1.0, 2);
      ++n;
    }
  return std::sqrt(s / n);
}

// The bad-input contract every point-moving filter keeps (foundation issue), shared by the
// tests of each filter.

/// An empty cloud and an all-NaN cloud are InvalidInput.
template <template <typename> class Filter, typename PointT>
void expectEmptyAndAllNaNAreInvalidInput(Filter<PointT>& f) {
  pcl::PointCloud<PointT> out;
  // No input cloud at all (f is new): an error, where pcl::Filter only prints a message.
  EXPECT_THROW(f.filter(out), InvalidInput);
  f.setInputCloud(pcl::make_shared<pcl::PointCloud<PointT>>());
  EXPECT_THROW(f.filter(out), InvalidInput);
  f.setInputCloud(toCloud<PointT>(Positions(10, Eigen::Vector3f::Constant(payloadNaN()))));
  EXPECT_THROW(f.filter(out), InvalidInput);
}

/// A single point passes through bit for bit (counted as isolated), and so does one finite
/// point among NaNs, with is_dense honest in both cases.
template <template <typename> class Filter, typename PointT>
void expectSinglePointUnchanged(Filter<PointT>& f) {
  const Positions one = {{0.3f, -0.2f, 1.5f}};
  const auto out = runFilter(f, toCloud<PointT>(one));
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(sameBits(out[0].getVector3fMap(), one[0]));
  EXPECT_TRUE(out.is_dense);
  EXPECT_EQ(f.getReport().isolated, 1u);
  const Positions mixed = {{payloadNaN(), 0, 0}, {1, 2, 3}, {0, payloadNaN(), 0}};
  const auto out2 = runFilter(f, toCloud<PointT>(mixed));
  for (std::size_t i = 0; i < 3; ++i) EXPECT_TRUE(sameBits(out2[i].getVector3fMap(), mixed[i]));
  EXPECT_FALSE(out2.is_dense);
}

/// `filter(points)` on clouds of 2 to 60 points (fewer than any neighbour count asked for)
/// gives finite points that stay near their input: the points lie on z = 0 with noise of
/// sigma 0.01, and a point moved along a near-vertical normal towards its neighbours' heights
/// moves by at most their spread, about 5 sigma at 60 points. Measured: at most 0.027 (the
/// similarity denoiser and the bilateral filter, 60 points), so 0.05; a fit that went wrong on
/// a tiny neighbourhood (a tilted normal, a huge radius) moves points a good part of the square.
template <typename FilterFn>
void expectTinyCloudsGiveFiniteOutput(FilterFn filter) {
  Random rng(77);
  for (int n : {2, 3, 4, 5, 8, 20, 60}) {
    Positions p;
    for (int i = 0; i < n; ++i) {
      const double z = 0.01 * rng.gaussian(), y = rng.uniform();
      p.emplace_back(rng.uniform(), y, z);
    }
    const Positions out = filter(p);
    ASSERT_EQ(out.size(), p.size());
    for (int i = 0; i < n; ++i) {
      EXPECT_TRUE(isFinite(out[i])) << n << " points, point " << i;
      EXPECT_LT((out[i] - p[i]).norm(), 0.05f) << n << " points, point " << i;
    }
  }
}

/// Points whose output differs (in any bit) between a run on one thread and one on two.
/// `filter()` runs the filter on a fixed input.
template <typename FilterFn>
std::size_t pointsDifferingBetweenOneAndTwoThreads(FilterFn filter) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const Positions a = filter();
  omp_set_num_threads(2);
  const Positions b = filter();
  omp_set_num_threads(saved);
  if (a.size() != b.size()) return std::max(a.size(), b.size());
  std::size_t differ = 0;
  for (std::size_t i = 0; i < a.size(); ++i) differ += !sameBits(a[i], b[i]);
  return differ;
}

/// 200 copies of one point: with a given radius every point is every other's neighbour and no
/// normal exists, so all stay put (isolated); with the automatic radius there is no scale to
/// choose, and a clear InvalidInput is the contract. `filter(points, params, report)`.
template <typename Params, typename Report, typename FilterFn>
void expectAllIdenticalPointsDoNotCrash(FilterFn filter) {
  const Positions same(200, Eigen::Vector3f(1.f, 2.f, 3.f));
  Params params;
  params.radius = 0.1f;
  Report report;
  const Positions out = filter(same, params, &report);
  for (std::size_t i = 0; i < out.size(); ++i) EXPECT_TRUE(sameBits(out[i], same[i])) << i;
  EXPECT_EQ(report.isolated, same.size());
  // No radius can be chosen, and none is needed: left as they are, as one point alone is.
  params.radius = 0.f;
  Report automatic;
  const Positions out2 = filter(same, params, &automatic);
  for (std::size_t i = 0; i < out2.size(); ++i) EXPECT_TRUE(sameBits(out2[i], same[i])) << i;
  EXPECT_EQ(automatic.isolated, same.size());
  EXPECT_EQ(automatic.moved, 0u);
}

/// NaN and infinite points pass through bit for bit and are counted, the other fields
/// (intensity) and the cloud's shape are kept, and the finite points move. `p`: a noisy
/// surface of at least 3,000 points.
template <template <typename> class Filter>
void expectNaNPassThroughAndOtherFieldsKept(Positions p) {
  const float nan = payloadNaN();
  const std::vector<std::size_t> holes = {0, 7, 500, 1234, 2999};
  for (std::size_t i : holes) p[i] = Eigen::Vector3f(nan, i == 7 ? 0.5f : nan, nan);
  p[42].x() = std::numeric_limits<float>::infinity();
  auto in = toCloud<pcl::PointXYZI>(p);
  for (std::size_t i = 0; i < in->size(); ++i) (*in)[i].intensity = 0.25f * static_cast<float>(i);
  ASSERT_FALSE(in->is_dense);
  Filter<pcl::PointXYZI> f;
  const auto out = runFilter(f, in);
  ASSERT_EQ(out.size(), in->size());
  EXPECT_EQ(out.width, in->width);
  EXPECT_EQ(out.height, in->height);
  EXPECT_FALSE(out.is_dense);
  std::size_t moved = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(bitsOf(out[i].intensity), bitsOf((*in)[i].intensity)) << i;
    if (!isFinite(p[i])) {
      EXPECT_TRUE(sameBits(out[i].getVector3fMap(), p[i])) << "non-finite point " << i << " changed";
    } else {
      EXPECT_TRUE(isFinite(out[i].getVector3fMap())) << i;
      moved += out[i].getVector3fMap() != p[i];
    }
  }
  EXPECT_GT(moved, 0.9 * (p.size() - holes.size() - 1));
  EXPECT_EQ(f.getReport().non_finite, holes.size() + 1);
}

/// A dense cloud stays dense, colours (and alpha) and the header are kept.
template <template <typename> class Filter, typename PointT>
void expectDenseStaysDenseAndColoursKeptFor(const Positions& p) {
  auto in = toCloud<PointT>(p);
  for (std::size_t i = 0; i < in->size(); ++i) {
    (*in)[i].r = static_cast<std::uint8_t>(i);
    (*in)[i].g = static_cast<std::uint8_t>(i / 7);
    (*in)[i].b = static_cast<std::uint8_t>(255 - i % 256);
    (*in)[i].a = static_cast<std::uint8_t>(i % 251);
  }
  in->header.frame_id = "scanner";
  Filter<PointT> f;
  const auto out = runFilter(f, in);
  ASSERT_EQ(out.size(), in->size());
  EXPECT_TRUE(out.is_dense);
  EXPECT_EQ(out.header.frame_id, "scanner");
  for (std::size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(out[i].rgba, (*in)[i].rgba) << i;
    EXPECT_TRUE(isFinite(out[i].getVector3fMap()));
  }
}

/// The same for the coloured types the filters are compiled for: PointXYZRGB and
/// PointXYZRGBA (RGB-D cameras); a type left out of the library's list fails to link.
template <template <typename> class Filter>
void expectDenseStaysDenseAndColoursKept(const Positions& p) {
  expectDenseStaysDenseAndColoursKeptFor<Filter, pcl::PointXYZRGB>(p);
  expectDenseStaysDenseAndColoursKeptFor<Filter, pcl::PointXYZRGBA>(p);
}

/// With setIndices, the output keeps every point; only the listed ones move.
template <template <typename> class Filter>
void expectOnlyIndexedPointsMove(const Positions& p) {
  auto indices = pcl::make_shared<pcl::Indices>();
  std::vector<bool> listed(p.size(), false);
  for (std::size_t i = 1; i < p.size() * 2 / 3; i += 3) {
    indices->push_back(static_cast<int>(i));
    listed[i] = true;
  }
  Filter<pcl::PointXYZ> f;
  f.setIndices(indices);
  const auto out = runFilter(f, toCloud<pcl::PointXYZ>(p));
  ASSERT_EQ(out.size(), p.size()) << "the output keeps every point, indexed or not";
  std::size_t moved_listed = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (listed[i]) moved_listed += out[i].getVector3fMap() != p[i];
    else EXPECT_TRUE(sameBits(out[i].getVector3fMap(), p[i])) << "unlisted point " << i << " moved";
  }
  EXPECT_GT(moved_listed, 0.9 * indices->size());
  EXPECT_EQ(f.getReport().moved, indices->size());
}

/// For a point type with normals (PointNormal): the moved points' normals are estimated again
/// on the output. Input normals tilted 10 degrees off the unit sphere's (a stale estimate)
/// come out radial within `mean_degrees` on average, on the input's side, with a small finite
/// curvature; points outside the indices keep normal and curvature bit for bit; with
/// setRefreshNormals(false) every point keeps them. `configure(filter)` sets the filter up.
template <template <typename> class Filter, typename Configure>
void expectNormalsRefreshed(const Positions& p, double mean_degrees, Configure configure) {
  auto in = toCloud<pcl::PointNormal>(p);
  Random rng(3);
  const float tilt = static_cast<float>(10.0 * M_PI / 180.0);
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Eigen::Vector3f radial = p[i].normalized();
    const Eigen::Vector3f any = rng.gaussian3().cast<float>();
    const Eigen::Vector3f across = (any - any.dot(radial) * radial).normalized();
    (*in)[i].getNormalVector3fMap() = std::cos(tilt) * radial + std::sin(tilt) * across;
    (*in)[i].curvature = 0.5f;
  }
  auto indices = pcl::make_shared<pcl::Indices>();
  std::vector<bool> listed(p.size(), false);
  for (std::size_t i = 0; i < p.size(); ++i)
    if (i % 4 != 0) {
      indices->push_back(static_cast<int>(i));
      listed[i] = true;
    }
  Filter<pcl::PointNormal> f;
  configure(f);
  f.setIndices(indices);
  const auto out = runFilter(f, in);
  ASSERT_EQ(out.size(), p.size());
  double sum = 0, sum_before = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Eigen::Vector3f n = out[i].getNormalVector3fMap(), before = (*in)[i].getNormalVector3fMap();
    if (!listed[i]) {
      ASSERT_TRUE(sameBits(n, before)) << "unlisted point " << i;
      ASSERT_EQ(out[i].curvature, 0.5f);
      continue;
    }
    ASSERT_NEAR(n.norm(), 1.f, 1e-4f) << "point " << i;
    const double c = std::min(1.0, static_cast<double>(n.dot(out[i].getVector3fMap().normalized())));
    ASSERT_GT(c, 0.0) << "point " << i << ": turned inward, unlike its input normal";
    sum += std::acos(c) * 180.0 / M_PI;
    sum_before += std::acos(std::min(1.0, static_cast<double>(before.dot(p[i].normalized())))) * 180.0 / M_PI;
    ASSERT_TRUE(std::isfinite(out[i].curvature));
    ASSERT_LT(out[i].curvature, 0.05f);  // a sphere's cap: nearly flat
  }
  EXPECT_NEAR(sum_before / indices->size(), 10.0, 0.01);
  EXPECT_LT(sum / indices->size(), mean_degrees);
  EXPECT_TRUE(out.is_dense);
  EXPECT_EQ(f.getRefreshedNormals(), indices->size());
  EXPECT_EQ(f.getPointsWithoutNormal(), 0u);

  Filter<pcl::PointNormal> keep;
  configure(keep);
  keep.setRefreshNormals(false);
  EXPECT_FALSE(keep.getRefreshNormals());
  const auto kept = runFilter(keep, in);
  for (std::size_t i = 0; i < p.size(); ++i) {
    ASSERT_TRUE(sameBits(kept[i].getNormalVector3fMap(), (*in)[i].getNormalVector3fMap())) << "point " << i;
    ASSERT_EQ(kept[i].curvature, 0.5f);
  }
  EXPECT_EQ(keep.getRefreshedNormals(), 0u);
}

/// An index outside the cloud is a paps::Error (it once wrote outside a vector).
template <template <typename> class Filter>
void expectIndexOutOfRangeIsRejected(const Positions& p) {
  const int n = static_cast<int>(p.size());
  for (int bad : {-1, n, 100000}) {
    Filter<pcl::PointXYZ> f;
    f.setIndices(pcl::make_shared<pcl::Indices>(pcl::Indices{0, 1, bad}));
    f.setInputCloud(toCloud<pcl::PointXYZ>(p));
    pcl::PointCloud<pcl::PointXYZ> out;
    EXPECT_THROW(f.filter(out), Error) << "index " << bad;
  }
}

/// The pcl::Filter class gives what its function gives, also in place (input = output).
template <template <typename> class Filter, typename Params, typename FilterFn>
void expectClassMatchesFunctionAndInPlace(const Positions& p, const Params& params, FilterFn filter) {
  const Positions expected = filter(p, params);
  Filter<pcl::PointXYZ> f;
  f.setParameters(params);
  auto cloud = toCloud<pcl::PointXYZ>(p);
  const auto out = runFilter(f, cloud);
  f.filter(*cloud);
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_TRUE(sameBits(out[i].getVector3fMap(), expected[i])) << i;
    EXPECT_TRUE(sameBits((*cloud)[i].getVector3fMap(), expected[i])) << i;
  }
}

}  // namespace paps::test
