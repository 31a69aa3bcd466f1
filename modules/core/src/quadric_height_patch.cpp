#include <paps/core/quadric_height_patch.h>

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>

#include <paps/core/error.h>
#include <paps/core/irls.h>

namespace paps {

namespace {

// A tangent direction of `n` from a hint, or any one chosen deterministically.
Eigen::Vector3f tangentFrom(const Eigen::Vector3f& n, const Eigen::Vector3f* hint) {
  if (hint && isFinite(*hint)) {
    Eigen::Vector3f t = *hint - hint->dot(n) * n;
    if (t.norm() > 1e-4f) return t.normalized();
  }
  Eigen::Vector3f a = std::abs(n.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY();
  return (a - a.dot(n) * n).normalized();
}

QuadricFit planeFit(const Eigen::Vector3f& origin, const Eigen::Vector3f& n,
                    const Eigen::Vector3f* direction_hint, QuadricFit::Status status) {
  QuadricFit f;
  f.origin = origin;
  f.frame.n = n;
  f.frame.t1 = tangentFrom(n, direction_hint);
  f.frame.t2 = n.cross(f.frame.t1);
  f.status = status;
  return f;
}

}  // namespace

QuadricFit fitQuadric(const Positions& points, const Eigen::Vector3f& centre, const int* nb, int count,
                      float radius, const Eigen::Vector3f* normal_hint,
                      const Eigen::Vector3f* direction_hint, const QuadricFitOptions& options) {
  requirePositive("radius", radius);
  const bool hint_ok = normal_hint && isFinite(*normal_hint) && normal_hint->norm() > 0.5f;
  // PCA frame of the neighbours.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  int m = 0;
  for (int k = 0; k < count; ++k)
    if (isFinite(points[nb[k]])) { mean += (points[nb[k]] - centre).cast<double>(); ++m; }
  if (m < 3) {
    const Eigen::Vector3f n = hint_ok ? normal_hint->normalized() : Eigen::Vector3f(Eigen::Vector3f::UnitZ());
    QuadricFit f = planeFit(centre, n, direction_hint, QuadricFit::Status::TooFewPoints);
    if (!hint_ok) f.frame.n = Eigen::Vector3f::Constant(NAN);
    return f;
  }
  mean /= m;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (int k = 0; k < count; ++k)
    if (isFinite(points[nb[k]])) {
      const Eigen::Vector3d d = (points[nb[k]] - centre).cast<double>() - mean;
      cov += d * d.transpose();
    }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  const Eigen::Vector3d ev = es.eigenvalues();
  Eigen::Vector3f n0 = es.eigenvectors().col(0).cast<float>();
  if (hint_ok && n0.dot(*normal_hint) < 0) n0 = -n0;
  const Eigen::Vector3f origin_plane = centre + static_cast<float>(mean.dot(n0.cast<double>())) * n0;
  // Collinear: the middle eigenvalue vanishes against the largest.
  if (!(ev[1] > 1e-6 * ev[2]) || !(ev[2] > 0)) {
    const Eigen::Vector3f n = hint_ok ? normal_hint->normalized() : n0;
    return planeFit(centre, n, direction_hint, QuadricFit::Status::Degenerate);
  }
  if (m < 6) return planeFit(origin_plane, n0, direction_hint, QuadricFit::Status::TooFewPoints);

  const Eigen::Vector3f e1 = es.eigenvectors().col(2).cast<float>();
  const Eigen::Vector3f e2 = n0.cross(e1);
  // z = a x^2 + b xy + c y^2 + d x + e y + f, in units of the radius for conditioning.
  Eigen::Matrix<double, Eigen::Dynamic, 6> A(m, 6);
  Eigen::VectorXd z(m), w = Eigen::VectorXd::Ones(m);
  const double s = 1.0 / radius;
  int r = 0;
  for (int k = 0; k < count; ++k) {
    if (!isFinite(points[nb[k]])) continue;
    const Eigen::Vector3f d = points[nb[k]] - centre;
    const double x = e1.dot(d) * s, y = e2.dot(d) * s;
    A.row(r) << x * x, x * y, y * y, x, y, 1.0;
    z[r] = n0.dot(d) * s;
    ++r;
  }
  const float conditioning = static_cast<float>(
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>>((A.transpose() * A) / m, Eigen::EigenvaluesOnly)
          .eigenvalues()[0]);
  auto fallback = [&](QuadricFit f) {
    f.conditioning = conditioning;
    return f;
  };
  Eigen::Matrix<double, 6, 1> c;
  const bool ok = solveIrlsL1<6>(A, z, w, options.irls_iterations, 1e-4, c);
  if (!ok || !c.allFinite()) return fallback(planeFit(origin_plane, n0, direction_hint, QuadricFit::Status::Degenerate));
  // Back to metres: h(x) = a' x^2 ... with a' = a / R, d' = d, f' = f R.
  const double a = c[0] * s, b = c[1] * s, cc = c[2] * s, dx = c[3], dy = c[4], f0 = c[5] * radius;
  // Fundamental forms at (0, 0).
  const Eigen::Vector3d Xu(1, 0, dx), Xv(0, 1, dy);
  const double W = std::sqrt(1 + dx * dx + dy * dy);
  Eigen::Matrix2d I, II;
  I << Xu.dot(Xu), Xu.dot(Xv), Xu.dot(Xv), Xv.dot(Xv);
  II << 2 * a / W, b / W, b / W, 2 * cc / W;
  const Eigen::Matrix2d R = I.llt().matrixU();
  const Eigen::Matrix2d Ri = R.inverse();
  const Eigen::Matrix2d S = Ri.transpose() * II * Ri;  // symmetric shape operator, orthonormal basis
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> ss(S);
  const double k2 = ss.eigenvalues()[0], k1 = ss.eigenvalues()[1];
  const Eigen::Vector2d dir1 = Ri * ss.eigenvectors().col(1);  // parameter-space direction of k1
  Eigen::Vector3d t1l = dir1[0] * Xu + dir1[1] * Xv;
  const Eigen::Vector3d nl = Eigen::Vector3d(-dx, -dy, 1) / W;
  auto world = [&](const Eigen::Vector3d& l) -> Eigen::Vector3f {
    return static_cast<float>(l[0]) * e1 + static_cast<float>(l[1]) * e2 + static_cast<float>(l[2]) * n0;
  };
  // A quadric bending away by more than the patch within the patch, or whose apex is half a
  // radius off the points, fits noise or a crease: not a local surface model.
  if (std::abs(f0) > 0.5 * radius || std::max(std::abs(k1), std::abs(k2)) * radius > 4.0)
    return fallback(planeFit(origin_plane, n0, direction_hint, QuadricFit::Status::Degenerate));
  QuadricFit fit;
  fit.conditioning = conditioning;
  fit.origin = centre + static_cast<float>(f0) * n0;
  fit.frame.n = world(nl).normalized();
  if (std::max(std::abs(k1), std::abs(k2)) * radius < options.flat_threshold) {
    return fallback(planeFit(fit.origin, fit.frame.n, direction_hint, QuadricFit::Status::FlatPlane));
  }
  fit.status = QuadricFit::Status::Quadric;
  if ((k1 - k2) * radius < options.umbilic_threshold) {
    fit.frame.t1 = tangentFrom(fit.frame.n, direction_hint);
    fit.k1 = fit.k2 = static_cast<float>(0.5 * (k1 + k2));
  } else {
    fit.frame.t1 = tangentFrom(fit.frame.n, nullptr);
    const Eigen::Vector3f t = world(t1l);
    fit.frame.t1 = (t - t.dot(fit.frame.n) * fit.frame.n).normalized();
    fit.k1 = static_cast<float>(k1);
    fit.k2 = static_cast<float>(k2);
  }
  fit.frame.t2 = fit.frame.n.cross(fit.frame.t1);
  return fit;
}

float parabolaAbscissaForArcLength(float a, float s) {
  const double aa = std::abs(static_cast<double>(a)), target = std::abs(static_cast<double>(s));
  if (aa * target < 1e-7) return s;
  // arc(x) = x/2 sqrt(1 + 4 a^2 x^2) + asinh(2 a x) / (4 a); arc'(x) = sqrt(1 + 4 a^2 x^2).
  double x = target;
  for (int it = 0; it < 30; ++it) {
    const double q = std::sqrt(1 + 4 * aa * aa * x * x);
    const double g = 0.5 * x * q + std::asinh(2 * aa * x) / (4 * aa) - target;
    const double step = g / q;
    x -= step;
    if (x < 0) x = 0;
    if (std::abs(step) <= 1e-9 * target) break;  // relative: the same steps in any unit
  }
  return static_cast<float>(s < 0 ? -x : x);
}

QuadricHeightPatch::QuadricHeightPatch(int grid_size, float radius, float kernel_width, int irls_passes)
    : n_(grid_size), radius_(radius), irls_passes_(irls_passes) {
  requireInRange("grid_size", grid_size, 1, 64);
  requirePositive("radius", radius);
  requirePositive("kernel_width", kernel_width);
  requireInRange("irls_passes", irls_passes, 0, 10);
  spacing_ = std::sqrt(2.f) * radius / static_cast<float>(n_);
  const float sigma = kernel_width * spacing_;
  inv_two_sigma2_ = 1.f / (2.f * sigma * sigma);
  min_weight_ = 0.3f;
}

void QuadricHeightPatch::binCentres(const QuadricFit& fit, Eigen::Vector3f* centres) const {
  std::vector<float> xs(n_), ys(n_);
  for (int i = 0; i < n_; ++i) {
    xs[i] = parabolaAbscissaForArcLength(0.5f * fit.k1, binCoordinate(i));
    ys[i] = parabolaAbscissaForArcLength(0.5f * fit.k2, binCoordinate(i));
  }
  for (int j = 0; j < n_; ++j)
    for (int i = 0; i < n_; ++i) centres[j * n_ + i] = {xs[i], ys[j], fit.height(xs[i], ys[j])};
}

int QuadricHeightPatch::describe(const QuadricFit& fit, const Positions& points, const int* nb, int count,
                                 float* heights, std::uint8_t* valid) const {
  const std::size_t nb_bins = size();
  std::vector<Eigen::Vector3f> centres(nb_bins);
  binCentres(fit, centres.data());
  // The neighbours in the intrinsic frame, as structure of arrays: every bin's kernel weights,
  // their exp and the sums then run on SIMD packets (QSR describes every point of the scan;
  // the scalar loop with std::exp was 11% of its time on table_scene). Eigen's sums have a
  // fixed lane order, so the heights do not depend on the run or the thread count.
  thread_local Eigen::ArrayXf lx, ly, lz, h, w, rw;
  if (lx.size() < count)
    for (Eigen::ArrayXf* a : {&lx, &ly, &lz, &h, &w, &rw}) a->resize(count);
  Eigen::Index m = 0;
  for (int k = 0; k < count; ++k) {
    if (!isFinite(points[nb[k]])) continue;
    const Eigen::Vector3f l = fit.frame.toLocal(points[nb[k]] - fit.origin);
    lx[m] = l.x();
    ly[m] = l.y();
    lz[m] = l.z();
    ++m;
  }
  const float delta = 1e-3f * spacing_;
  int n_valid = 0;
  for (std::size_t b = 0; b < nb_bins; ++b) {
    const Eigen::Vector3f& c = centres[b];
    const Eigen::Vector3f nb_ = fit.normalAt(c.x(), c.y());
    auto hb_ = h.head(m), wb = w.head(m);
    {
      const auto dx = lx.head(m) - c.x(), dy = ly.head(m) - c.y(), dz = lz.head(m) - c.z();
      hb_ = dx * nb_.x() + dy * nb_.y() + dz * nb_.z();
      // Distance from the bin's normal line, squared: the kernel of equation 2.2.
      wb = (-inv_two_sigma2_ * (dx.square() + dy.square() + dz.square() - hb_.square()).max(0.f)).exp();
    }
    const float sw = wb.sum();
    if (!(sw >= min_weight_)) { heights[b] = 0.f; valid[b] = 0; continue; }
    float hb = (wb * hb_).sum() / sw;
    for (int pass = 0; pass < irls_passes_; ++pass) {
      // l1Weight (paps/core/irls.h) on packets.
      rw.head(m) = wb / (hb_ - hb).abs().max(delta);
      const float sw2 = rw.head(m).sum();
      if (sw2 > 0) hb = (rw.head(m) * hb_).sum() / sw2;
    }
    heights[b] = hb;
    valid[b] = 1;
    ++n_valid;
  }
  return n_valid;
}

}  // namespace paps
