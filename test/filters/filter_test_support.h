#pragma once
// Helpers shared by the tests of point-moving filters.
#include <cstdint>
#include <cstring>
#include <string>

#include <gtest/gtest.h>
#include <pcl/point_cloud.h>

#include <paps/core/error.h>
#include <paps/core/positions.h>

namespace paps::test {

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

}  // namespace paps::test
