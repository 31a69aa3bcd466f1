#pragma once
// Deterministic random numbers. std::*_distribution differ between standard
// libraries, so seeded data would differ between platforms; these do not.
//
// Draw once per statement, or with the helpers below: C++ leaves the order in which the
// arguments of one call are evaluated unspecified, so `Vector3d(gaussian(), gaussian(),
// gaussian())` or `emplace_back(uniform(), uniform(), 0)` gives other data with another
// compiler (GCC evaluates them last to first, Clang first to last).
// test/core/random.cpp checks the tree for such calls.
#include <cmath>
#include <cstdint>

#include <Eigen/Core>

namespace paps {

/// SplitMix64 generator with uniform and Gaussian draws that are the same on every platform.
class Random {
 public:
  explicit Random(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  /// Uniform in [0, 1).
  double uniform() { return (next() >> 11) * (1.0 / 9007199254740992.0); }
  /// Uniform in [lo, hi).
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  /// Uniform integer in [0, n).
  std::uint64_t below(std::uint64_t n) { return n ? next() % n : 0; }
  /// Standard normal (Box-Muller; the second value is discarded for simplicity of state).
  double gaussian() {
    double u1 = uniform();
    if (u1 < 1e-300) u1 = 1e-300;
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }
  /// Three standard normals (x, y, z), drawn z first, then y, then x: the order GCC gave the
  /// unsequenced `Vector3d(gaussian(), gaussian(), gaussian())` this replaces, so seeded data
  /// keep their values.
  Eigen::Vector3d gaussian3() {
    const double z = gaussian(), y = gaussian(), x = gaussian();
    return Eigen::Vector3d(x, y, z);
  }
  /// Three uniforms in [lo, hi), drawn z first, then y, then x (as gaussian3).
  Eigen::Vector3d uniform3(double lo, double hi) {
    const double z = uniform(lo, hi), y = uniform(lo, hi), x = uniform(lo, hi);
    return Eigen::Vector3d(x, y, z);
  }

 private:
  std::uint64_t state_;
};

}  // namespace paps
