#pragma once
// The PAPS error hierarchy. Every failure a caller can act on is an exception
// that says what was wrong and, where there is one, the offending value.
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace paps {

/// Base of every PAPS error.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

/// A parameter is out of its valid range; names the parameter and the value.
class InvalidParameter : public Error {
 public:
  InvalidParameter(const std::string& name, const std::string& value, const std::string& expected)
      : Error("invalid parameter '" + name + "' = " + value + " (expected " + expected + ")"),
        name_(name), value_(value), expected_(expected) {}
  const std::string& parameter() const { return name_; }
  const std::string& value() const { return value_; }
  const std::string& expected() const { return expected_; }

 private:
  std::string name_, value_, expected_;
};

/// The input data cannot be processed (empty, all NaN, degenerate, ...).
class InvalidInput : public Error {
 public:
  explicit InvalidInput(const std::string& what) : Error("invalid input: " + what) {}
};

/// A file could not be read or written.
class IoError : public Error {
 public:
  explicit IoError(const std::string& what) : Error(what) {}
};

/// A progress callback asked to stop.
class Cancelled : public Error {
 public:
  Cancelled() : Error("cancelled by the progress callback") {}
};

namespace detail {
template <typename T>
std::string toString(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
}  // namespace detail

/// Throws InvalidParameter unless 0 < value < 1e30 (beyond, squares overflow a float).
template <typename T>
void requirePositive(const char* name, T value) {
  const double v = static_cast<double>(value);  // no T(1e30) overflow for integer T; NaN fails
  if (!(v > 0) || !(v < 1e30)) throw InvalidParameter(name, detail::toString(value), "a value > 0 and below 1e30");
}

/// Throws InvalidParameter unless value >= 0 and finite; `zero` says what 0 means ("automatic",
/// "estimated", ...), or is empty when 0 is just a value.
inline void requireNonNegative(const char* name, double value, const char* zero = "") {
  if (!(value >= 0) || !std::isfinite(value))
    throw InvalidParameter(name, detail::toString(value),
                           *zero ? std::string("0 (") + zero + ") or a finite value > 0" : "a finite value >= 0");
}

/// Throws InvalidParameter unless lo <= value <= hi.
template <typename T>
void requireInRange(const char* name, T value, T lo, T hi) {
  if (!(value >= lo && value <= hi))
    throw InvalidParameter(name, detail::toString(value),
                           "a value in [" + detail::toString(lo) + ", " + detail::toString(hi) + "]");
}

}  // namespace paps
