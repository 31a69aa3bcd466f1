#include <paps/surface/mls_upsampling.h>
#include <paps/surface/impl/mls_upsampling.hpp>

#include <algorithm>
#include <cmath>

#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/poisson_disk_sampling.h>
#include <paps/core/random.h>

namespace paps {

void MlsUpsamplingParameters::validate() const {
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "0 (automatic) or a finite value > 0");
  requireInRange("target_neighbours", target_neighbours, 6, 1000);
  requireInRange("factor", factor, 1.f, 1000.f);
  requireInRange("iterations", iterations, 1, 50);
  requirePositive("sigma_r", sigma_r);
  requirePositive("sigma_n", sigma_n);
}

Positions upsamplingSeeds(const Positions& points, const Normals& normals, std::size_t count,
                          float disc_radius, std::uint64_t seed, std::vector<int>* origin) {
  requirePositive("disc_radius", disc_radius);
  std::size_t usable = 0;
  for (std::size_t i = 0; i < points.size(); ++i) usable += isFinite(points[i]) && isFinite(normals[i]);
  if (usable == 0) throw InvalidInput("no finite point with a normal to upsample from");
  if (count == 0) return {};
  // Over-generate, then thin with a Poisson-disk radius found by bisection.
  const int per_point = static_cast<int>(std::ceil(2.0 * count / usable)) + 1;
  Positions cand;
  std::vector<int> from;
  cand.reserve(usable * per_point);
  from.reserve(usable * per_point);
  Random rng(seed);
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!isFinite(points[i]) || !isFinite(normals[i])) continue;
    const Eigen::Vector3f& n = normals[i];
    const Eigen::Vector3f a = std::abs(n.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY();
    const Eigen::Vector3f t1 = (a - a.dot(n) * n).normalized(), t2 = n.cross(t1);
    for (int k = 0; k < per_point; ++k) {
      const float r = disc_radius * std::sqrt(static_cast<float>(rng.uniform()));
      const float phi = static_cast<float>(6.283185307179586 * rng.uniform());
      cand.push_back(points[i] + r * std::cos(phi) * t1 + r * std::sin(phi) * t2);
      from.push_back(static_cast<int>(i));
    }
  }
  // Shuffle (deterministically) so index order does not favour the first input points.
  for (std::size_t i = cand.size(); i > 1; --i) {
    const std::size_t j = rng.below(i);
    std::swap(cand[i - 1], cand[j]);
    std::swap(from[i - 1], from[j]);
  }
  if (cand.size() <= count) {
    if (origin) *origin = std::move(from);
    return cand;
  }
  // A maximal Poisson-disk set at radius d holds about A / (c d^2) points: start from the
  // estimate of the disc area, then correct d by sqrt(found / wanted); a few passes suffice.
  // Keep the largest radius that gives at least `count` points.
  const double area = static_cast<double>(usable) * 3.14159265 * disc_radius * disc_radius * 0.6;
  double d = std::sqrt(area / (0.75 * count));
  std::vector<int> best;
  double lo_fail = 0;  // smallest radius seen giving too few points (0: none yet)
  for (int it = 0; it < 10; ++it) {
    std::vector<int> s = poissonDiskSubsetOrdered(cand, static_cast<float>(d), {});
    const double ratio = static_cast<double>(s.size()) / count;
    if (s.size() >= count) {
      const bool close = ratio < 1.03;
      best = std::move(s);
      if (close) break;
      d *= std::min(std::sqrt(ratio) * 0.995, lo_fail > 0 ? 0.5 * (1 + lo_fail / d) : 1e9);
    } else {
      lo_fail = d;
      d *= std::sqrt(ratio) * 0.985;
    }
  }
  if (best.empty()) {  // lo stayed 0: take the first `count` candidates
    best.resize(cand.size());
    for (std::size_t i = 0; i < best.size(); ++i) best[i] = static_cast<int>(i);
  }
  // Drop the surplus at random.
  for (std::size_t i = best.size(); i > 1; --i) std::swap(best[i - 1], best[rng.below(i)]);
  best.resize(count);
  std::sort(best.begin(), best.end());
  Positions out;
  out.reserve(count);
  if (origin) origin->clear();
  for (int i : best) {
    out.push_back(cand[i]);
    if (origin) origin->push_back(from[i]);
  }
  return out;
}

namespace {

inline float wendland(float d2, float inv_h2) {
  const float t = 1.f - d2 * inv_h2;
  return t > 0 ? t * t * t * t : 0.f;
}

// APSS: algebraic sphere u0 + u.x + u4 |x|^2 fitted to points and normals (closed form of
// Guennebaud and Gross 2007, beta = 1), then q is projected on it. Coordinates relative to q.
struct Sphere {
  Eigen::Vector3f centre_point;  // the point the fit is relative to
  double u0 = 0, u4 = 0;
  Eigen::Vector3d u = Eigen::Vector3d::Zero();
  float h = 1;
  bool ok = false;
  // Projection of q (near centre_point) on the algebraic sphere.
  bool project(const Eigen::Vector3f& q, Eigen::Vector3f& out) const {
    const Eigen::Vector3d x0 = ((q - centre_point) / h).cast<double>();
    Eigen::Vector3d x;
    if (std::abs(u4) < 1e-6) {
      const double un2 = u.squaredNorm();
      if (!(un2 > 0)) return false;
      x = x0 - (u0 + u.dot(x0)) / un2 * u;
    } else {
      const Eigen::Vector3d c = -u / (2 * u4);
      const double r2 = c.squaredNorm() - u0 / u4;
      const Eigen::Vector3d d = x0 - c;
      if (!(r2 > 0) || !(d.norm() > 0)) return false;
      x = c + std::sqrt(r2) * d / d.norm();
    }
    out = centre_point + (x * h).cast<float>();
    return out.allFinite();
  }
};

Sphere fitApss(const Eigen::Vector3f& q0, const Positions& p, const Normals& n, const int* nb, int count, float h) {
  Sphere s;
  s.centre_point = q0;
  s.h = h;
  const float inv_h2 = 1.f / (h * h);
  double sw = 0, spn = 0, spp = 0;
  Eigen::Vector3d sp = Eigen::Vector3d::Zero(), sn = Eigen::Vector3d::Zero();
  int used = 0;
  for (int k = 0; k < count; ++k) {
    const int j = nb[k];
    if (!isFinite(n[j])) continue;
    const Eigen::Vector3d d = ((p[j] - q0) / h).cast<double>();
    const double w = wendland((p[j] - q0).squaredNorm(), inv_h2);
    if (w <= 0) continue;
    const Eigen::Vector3d nj = n[j].cast<double>();
    sw += w; sp += w * d; sn += w * nj; spn += w * d.dot(nj); spp += w * d.squaredNorm();
    ++used;
  }
  if (used < 3 || !(sw > 0)) return s;
  const Eigen::Vector3d mp = sp / sw, mn = sn / sw;
  const double den = spp / sw - mp.squaredNorm();
  s.u4 = den > 1e-12 ? 0.5 * (spn / sw - mp.dot(mn)) / den : 0.0;
  s.u = mn - 2 * s.u4 * mp;
  s.u0 = -s.u.dot(mp) - s.u4 * spp / sw;
  s.ok = std::isfinite(s.u0) && std::isfinite(s.u4) && s.u.allFinite();
  return s;
}

// One APSS projection step: the sphere fitted around q0, and q0 projected on it.
bool projectApss(const Eigen::Vector3f& q0, const Positions& p, const Normals& n, const int* nb, int count,
                 float h, Eigen::Vector3f& out) {
  const Sphere s = fitApss(q0, p, n, nb, count, h);
  return s.ok && s.project(q0, out);
}

// RIMLS (Oztireli et al. 2009): robust implicit MLS with residual and normal reweighting;
// one step f / |grad f|^2 along grad f.
bool projectRimls(const Eigen::Vector3f& q, const Positions& p, const Normals& n, const int* nb, int count,
                  float h, float sigma_r, float sigma_n, Eigen::Vector3f& out) {
  const float inv_h2 = 1.f / (h * h);
  float f = 0;
  Eigen::Vector3f grad = Eigen::Vector3f::Zero();
  const float inv_sr2 = 1.f / (sigma_r * sigma_r * h * h), inv_sn2 = 1.f / (sigma_n * sigma_n);
  for (int it = 0; it < 6; ++it) {
    float sw = 0, sf = 0;
    Eigen::Vector3f sgw = Eigen::Vector3f::Zero(), sgf = Eigen::Vector3f::Zero(), sn = Eigen::Vector3f::Zero();
    for (int k = 0; k < count; ++k) {
      const int j = nb[k];
      if (!isFinite(n[j])) continue;
      const Eigen::Vector3f d = q - p[j];
      const float d2 = d.squaredNorm();
      const float t = 1.f - d2 * inv_h2;
      if (t <= 0) continue;
      const float fx = d.dot(n[j]);
      float alpha = 1.f;
      if (it > 0) {
        const float rr = fx - f;
        alpha = std::exp(-rr * rr * inv_sr2) * std::exp(-(n[j] - grad).squaredNorm() * inv_sn2);
      }
      const float w = alpha * t * t * t * t;
      const Eigen::Vector3f gw = alpha * (-8.f * inv_h2 * t * t * t) * d;
      sw += w; sf += w * fx; sgw += gw; sgf += gw * fx; sn += w * n[j];
    }
    if (!(sw > 1e-12f)) return false;
    const float f_new = sf / sw;
    grad = (sgf - f_new * sgw + sn) / sw;
    const bool done = it > 0 && std::abs(f_new - f) < 1e-4f * h;
    f = f_new;
    if (done) break;
  }
  const float g2 = grad.squaredNorm();
  if (!(g2 > 1e-12f)) return false;
  out = q - f * grad / g2;
  return out.allFinite();
}

}  // namespace

Positions upsampleMls(const Positions& points, MlsSurface surface, const MlsUpsamplingParameters& params,
                      MlsUpsamplingReport* report, const ProgressCallback& progress) {
  params.validate();
  const std::size_t finite = countFinite(points);
  if (finite < 3) throw InvalidInput("APSS/RIMLS need at least 3 finite points (got " + detail::toString(finite) + ")");
  RadiusNeighbourhood nh = buildRadiusNeighbourhood(points, params.radius, params.target_neighbours, 0, progress);
  Normals normals = estimateNormals(points, nh.graph);
  orientNormalsByPropagation(points, normals, nh.graph);
  const std::size_t count = params.output_count ? params.output_count
                                                : static_cast<std::size_t>(std::llround(params.factor * finite));
  const float h = nh.radius;
  const float disc = h / std::sqrt(static_cast<float>(std::max(1.0, nh.graph.meanCount()))) * 1.2f;
  std::vector<int> origin;
  Positions out = upsamplingSeeds(points, normals, count, disc, params.seed, &origin);
  std::size_t unprojected = 0;
  if (surface == MlsSurface::Apss && params.fit_per_input_point) {
    std::vector<Sphere> spheres(points.size());
    const std::int64_t np = static_cast<std::int64_t>(points.size());
#pragma omp parallel for schedule(dynamic, 512)
    for (std::int64_t i = 0; i < np; ++i)
      if (isFinite(points[i]) && nh.graph.count(i) >= 4)
        spheres[i] = fitApss(points[i], points, normals, nh.graph.begin(i), nh.graph.count(i), h);
    const std::int64_t m = static_cast<std::int64_t>(out.size());
#pragma omp parallel for schedule(static) reduction(+ : unprojected)
    for (std::int64_t i = 0; i < m; ++i) {
      Eigen::Vector3f x;
      const Sphere& s = spheres[origin[i]];
      if (s.ok && s.project(out[i], x)) out[i] = x;
      else ++unprojected;
    }
    if (report) { report->radius = h; report->output = out.size(); report->unprojected = unprojected; }
    return out;
  }
  ProgressReporter rep(progress, surface == MlsSurface::Apss ? "APSS projection" : "RIMLS projection", out.size());
  const std::int64_t m = static_cast<std::int64_t>(out.size());
#pragma omp parallel reduction(+ : unprojected)
  {
    std::vector<int> idx;
    std::vector<float> d2;
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t i = 0; i < m; ++i) {
      if (rep.cancelled()) continue;
      Eigen::Vector3f q = out[i];
      bool ok = true;
      for (int it = 0; it < params.iterations && ok; ++it) {
        const int c = nh.index->radiusSearch(q, h, idx, d2, 64);
        if (c < 4) { ok = false; break; }
        Eigen::Vector3f next;
        ok = surface == MlsSurface::Apss ? projectApss(q, points, normals, idx.data(), c, h, next)
                                         : projectRimls(q, points, normals, idx.data(), c, h, params.sigma_r, params.sigma_n, next);
        if (ok) {
          const float step = (next - q).norm();
          q = next;
          if (step < 1e-4f * h) break;
        }
      }
      if (ok) out[i] = q;
      else ++unprojected;
      rep.advance();
    }
  }
  rep.throwIfCancelled();
  rep.finish();
  if (report) { report->radius = h; report->output = out.size(); report->unprojected = unprojected; }
  return out;
}

template class MlsUpsampling<pcl::PointXYZ, pcl::PointXYZ, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZ, pcl::PointXYZ, MlsSurface::Rimls>;
template class MlsUpsampling<pcl::PointNormal, pcl::PointNormal, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointNormal, pcl::PointNormal, MlsSurface::Rimls>;
template class MlsUpsampling<pcl::PointXYZRGB, pcl::PointXYZ, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZRGB, pcl::PointXYZ, MlsSurface::Rimls>;

}  // namespace paps
