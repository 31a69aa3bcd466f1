// paps bench curvature: Wavejets against pcl::NormalEstimation + PrincipalCurvaturesEstimation
// and CGAL::Monge_via_jet_fitting, same neighbourhoods, on analytic surfaces with known
// curvature and on a real scan mesh; plus the tilted-plane correction curve, the speed run and
// renders of an enhanced scan. One run, one table.
#include <algorithm>
#include <array>
#include <cstdlib>
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <omp.h>
#include <Eigen/Eigenvalues>

#include <pcl/features/normal_3d.h>
#include <pcl/features/normal_3d_omp.h>
#include <pcl/features/principal_curvatures.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#ifdef PAPS_HAVE_CGAL
#include <CGAL/Monge_via_jet_fitting.h>
#include <CGAL/Simple_cartesian.h>
#endif

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/random.h>
#include <paps/core/spatial_order.h>
#include <paps/core/triangle_mesh.h>
#include <paps/features/wavejet.h>
#include <paps/features/wavejet_estimation.h>
#include <paps/filters/wavejet_enhancement.h>

#include "bench_worker.h"
#include "cli_common.h"
#include "render.h"
#include "commands.h"

namespace paps::cli {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }
constexpr double kPi = 3.14159265358979323846;

// Per-point estimate: unit normal and signed principal curvatures k1 >= k2 (w.r.t. the normal).
struct Estimate {
  Eigen::Vector3f n = Eigen::Vector3f::Constant(NAN);
  float k1 = NAN, k2 = NAN;
};
struct Truth {
  Eigen::Vector3f n;
  float k1, k2;
};

// A height field z = f(x, y) with its derivatives up to order 2.
struct Surface {
  std::string name;
  std::function<double(double, double)> f;
  std::function<void(double, double, double d[5])> deriv;  // fx fy fxx fxy fyy
};

Truth truthOf(const Surface& s, double x, double y) {
  double d[5];
  s.deriv(x, y, d);
  const double fx = d[0], fy = d[1];
  const double e = 1 + fx * fx, f = fx * fy, g = 1 + fy * fy, w = std::sqrt(1 + fx * fx + fy * fy);
  const double L = d[2] / w, M = d[3] / w, N = d[4] / w, det = e * g - f * f;
  const double K = (L * N - M * M) / det, H = (e * N - 2 * f * M + g * L) / (2 * det);
  const double disc = std::sqrt(std::max(0.0, H * H - K));
  return {Eigen::Vector3d(-fx, -fy, 1).normalized().cast<float>(), float(H + disc), float(H - disc)};
}

std::vector<Surface> analyticSurfaces() {
  std::vector<Surface> s;
  const double rs = 1.6, rc = 1.2;
  s.push_back({"sphere r=1.6", [=](double x, double y) { return std::sqrt(rs * rs - x * x - y * y); },
               [=](double x, double y, double d[5]) {
                 const double q = rs * rs - x * x - y * y, r = std::sqrt(q), r3 = q * r;
                 d[0] = -x / r; d[1] = -y / r;
                 d[2] = -(rs * rs - y * y) / r3; d[3] = -x * y / r3; d[4] = -(rs * rs - x * x) / r3;
               }});
  s.push_back({"cylinder r=1.2", [=](double x, double) { return std::sqrt(rc * rc - x * x); },
               [=](double x, double, double d[5]) {
                 const double q = rc * rc - x * x, r = std::sqrt(q);
                 d[0] = -x / r; d[1] = 0; d[2] = -rc * rc / (q * r); d[3] = 0; d[4] = 0;
               }});
  s.push_back({"paraboloid", [](double x, double y) { return 0.5 * x * x + 0.25 * y * y; },
               [](double x, double y, double d[5]) { d[0] = x; d[1] = 0.5 * y; d[2] = 1; d[3] = 0; d[4] = 0.5; }});
  s.push_back({"saddle", [](double x, double y) { return 0.4 * x * x - 0.3 * y * y; },
               [](double x, double y, double d[5]) { d[0] = 0.8 * x; d[1] = -0.6 * y; d[2] = 0.8; d[3] = 0; d[4] = -0.6; }});
  s.push_back({"monkey saddle", [](double x, double y) { return 0.3 * (x * x * x - 3 * x * y * y); },
               [](double x, double y, double d[5]) {
                 d[0] = 0.3 * (3 * x * x - 3 * y * y); d[1] = -1.8 * x * y;
                 d[2] = 1.8 * x; d[3] = -1.8 * y; d[4] = -1.8 * x;
               }});
  s.push_back({"x^4+y^4", [](double x, double y) { return 0.5 * (x * x * x * x + y * y * y * y); },
               [](double x, double y, double d[5]) {
                 d[0] = 2 * x * x * x; d[1] = 2 * y * y * y; d[2] = 6 * x * x; d[3] = 0; d[4] = 6 * y * y;
               }});
  return s;
}

// Irregular sampling of [-1, 1]^2: density grows threefold from x = -1 to x = 1.
void sampleSurface(const Surface& s, std::size_t count, std::uint64_t seed, Positions& p, std::vector<Truth>& t) {
  Random rng(seed);
  p.clear(); t.clear();
  while (p.size() < count) {
    const double x = rng.uniform(-1, 1), y = rng.uniform(-1, 1);
    if (rng.uniform() > 0.3 + 0.7 * (x + 1) / 2) continue;
    p.emplace_back(float(x), float(y), float(s.f(x, y)));
    t.push_back(truthOf(s, x, y));
  }
}

struct Errors {
  double normal_deg = NAN;   // mean normal angle error (degrees)
  double curv_rel = NAN;     // RMSE of (k1, k2) / RMS of the true (k1, k2)
  std::size_t missing = 0;   // evaluated points without an estimate
};

Errors score(const std::vector<Estimate>& est, const std::vector<Truth>& truth, const std::vector<int>& eval,
             bool unsigned_magnitudes) {
  double ang = 0, se = 0, st = 0;
  std::size_t n = 0, miss = 0;
  for (const int i : eval) {
    const Estimate& e = est[i];
    if (!std::isfinite(e.k1) || !isFinite(e.n)) { ++miss; continue; }
    const Truth& t = truth[i];
    ang += std::acos(std::min(1.0, double(std::abs(e.n.normalized().dot(t.n))))) * 180 / kPi;
    double a1 = t.k1, a2 = t.k2;
    if (unsigned_magnitudes) { a1 = std::max(std::abs(t.k1), std::abs(t.k2)); a2 = std::min(std::abs(t.k1), std::abs(t.k2)); }
    se += (e.k1 - a1) * (e.k1 - a1) + (e.k2 - a2) * (e.k2 - a2);
    st += a1 * a1 + a2 * a2;
    ++n;
  }
  Errors r;
  r.missing = miss;
  if (n) { r.normal_deg = ang / n; r.curv_rel = std::sqrt(se / std::max(st, 1e-30)); }
  return r;
}

// Orients every estimate like the reference normal (curvatures change sign with it).
void orientLike(std::vector<Estimate>& est, const std::vector<Eigen::Vector3f>& ref) {
  for (std::size_t i = 0; i < est.size(); ++i)
    if (isFinite(est[i].n) && est[i].n.dot(ref[i]) < 0) {
      est[i].n = -est[i].n;
      const float k1 = est[i].k1;
      est[i].k1 = -est[i].k2;
      est[i].k2 = -k1;
    }
}

// The bench's radius: R_phi holding `neighbours` points ON AVERAGE (self included), the
// protocol the figures of docs/wavejets.md were measured with (on this bench's evenly spread
// irregular samples the median count, core's default, gives a 3% smaller radius).
float benchRadius(const Positions& points, const SpatialIndex& index, int neighbours) {
  return radiusForNeighbourCount(points, index, neighbours, NeighbourCountStatistic::Mean);
}

// ---- the three methods, same radius ----

// select_order: the noise setting of docs/wavejets.md, BIC order selection with beta = 3.
// initial: first parameterization normals (the bound column: order 2 in the true tangent
// plane, no refit).
std::vector<Estimate> runWavejets(const Positions& p, float radius, int order, const Normals& hints, double& secs,
                                  WavejetReport* report = nullptr, bool select_order = false,
                                  const Normals* initial = nullptr) {
  WavejetParameters params;
  params.order = order;
  params.select_order = select_order;
  params.order_policy = select_order ? WavejetParameters::OrderPolicy::select : WavejetParameters::OrderPolicy::fixed;
  if (select_order) params.beta = 3.f;
  if (initial) params.max_refits = 0;
  const auto t0 = Clock::now();
  const auto res = estimateWavejets(p, radius, params, report, nullptr, initial, &hints);
  secs = since(t0);
  std::vector<Estimate> out(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) out[i] = {res[i].normal, res[i].k1, res[i].k2};
  return out;
}

// What `paps curvature` does by default: automatic radius for `neighbours` (widened and
// narrowed per point), order policy automatic (noise-aware), order K.
std::vector<Estimate> runDefault(const Positions& p, int order, int neighbours, const Normals& hints, double& secs,
                                 WavejetReport* report) {
  WavejetParameters params;
  params.order = order;
  const auto t0 = Clock::now();
  const auto res = estimateWavejets(p, 0.f, params, report, nullptr, nullptr, &hints, {}, neighbours);
  secs = since(t0);
  std::vector<Estimate> out(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) out[i] = {res[i].normal, res[i].k1, res[i].k2};
  return out;
}

// "fixed, R x1" or "sel., R x2" for a default run.
std::string defaultChoice(const WavejetReport& r) {
  char b[96];
  std::snprintf(b, sizeof b, "%s, R x%g", r.select_order ? "sel." : "fixed", r.support_scale);
  return b;
}

// PCL: normals by NormalEstimation, curvatures by PrincipalCurvaturesEstimation (unsigned,
// variance of the projected normals: pc1 >= pc2). `calibrated` then holds
// s sqrt(pc) with the least-squares best s against the true magnitudes (an oracle favour).
// k > 0: both stages search the k nearest instead (radius unused).
std::vector<Estimate> runPcl(const Positions& p, float radius, double& secs, bool threads, float curv_radius = 0,
                             int k = 0) {
  if (curv_radius <= 0) curv_radius = radius;
  auto setSearch = [&](auto& stage, float r) {
    if (k > 0)
      stage.setKSearch(k);
    else
      stage.setRadiusSearch(r);
  };
  // The finite points, as a PCL user gives them (PCL's estimators abort on NaN points).
  const FiniteInput finite = finiteInput(p);
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  writePositions(finite.points, *cloud);
  pcl::PointCloud<pcl::Normal>::Ptr normals(new pcl::PointCloud<pcl::Normal>);
  pcl::PointCloud<pcl::PrincipalCurvatures> pcs;
  const auto t0 = Clock::now();
  if (threads) {
    pcl::NormalEstimationOMP<pcl::PointXYZ, pcl::Normal> ne(omp_get_max_threads());
    ne.setInputCloud(cloud);
    setSearch(ne, radius);
    ne.compute(*normals);
  } else {
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    ne.setInputCloud(cloud);
    setSearch(ne, radius);
    ne.compute(*normals);
  }
  pcl::PrincipalCurvaturesEstimation<pcl::PointXYZ, pcl::Normal, pcl::PrincipalCurvatures> pc;
  pc.setInputCloud(cloud);
  pc.setInputNormals(normals);
  setSearch(pc, curv_radius);
  pc.compute(pcs);
  secs = since(t0);
  std::vector<Estimate> out(finite.points.size());
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = {(*normals)[i].getNormalVector3fMap(), pcs[i].pc1, pcs[i].pc2};
  return atInputIndices(out, finite, Estimate());
}

std::vector<Estimate> calibratePcl(std::vector<Estimate> est, const std::vector<Truth>& truth, const std::vector<int>& eval) {
  double num = 0, den = 0;
  for (const int i : eval) {
    if (!std::isfinite(est[i].k1)) continue;
    const double a1 = std::max(std::abs(truth[i].k1), std::abs(truth[i].k2));
    const double a2 = std::min(std::abs(truth[i].k1), std::abs(truth[i].k2));
    const double s1 = std::sqrt(std::max(0.f, est[i].k1)), s2 = std::sqrt(std::max(0.f, est[i].k2));
    num += s1 * a1 + s2 * a2;
    den += s1 * s1 + s2 * s2;
  }
  const double s = den > 0 ? num / den : 0;
  for (auto& e : est) { e.k1 = float(s * std::sqrt(std::max(0.f, e.k1))); e.k2 = float(s * std::sqrt(std::max(0.f, e.k2))); }
  return est;
}

// Oracle-free reading of PCL's output: the projected neighbour normals vary like S d (S the
// shape operator, d the tangential offset), and over a uniformly sampled disk of radius rho
// the offsets have variance rho^2 / 4 along any direction, so pc = k^2 rho^2 / 4 and
// |k| = 2 sqrt(pc) / rho, rho the curvature search radius.
std::vector<Estimate> geometricPcl(std::vector<Estimate> est, float curv_radius) {
  for (auto& e : est) {
    e.k1 = float(2 * std::sqrt(std::max(0.f, e.k1)) / curv_radius);
    e.k2 = float(2 * std::sqrt(std::max(0.f, e.k2)) / curv_radius);
  }
  return est;
}

#ifdef PAPS_HAVE_CGAL
// Whether CGAL's jet fitting of degree `order` is posed on these neighbours: as many distinct
// positions as the jet has coefficients, spread over a plane (its PCA frame). CGAL does not
// check (its preconditions are off in a release build): on a pile of copies of two positions
// it crashed the bench's worker (`paps bench files` on such a cloud: "worker died (status 11)").
bool cgalJetIsPosed(const Positions& p, const std::vector<int>& idx, int count, int need) {
  std::vector<std::array<float, 3>> distinct;
  distinct.reserve(static_cast<std::size_t>(count));
  for (int j = 0; j < count; ++j) distinct.push_back({p[idx[j]].x(), p[idx[j]].y(), p[idx[j]].z()});
  std::sort(distinct.begin(), distinct.end());
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  if (static_cast<int>(distinct.size()) < need) return false;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& q : distinct) mean += Eigen::Vector3d(q[0], q[1], q[2]);
  mean /= static_cast<double>(distinct.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& q : distinct) {
    const Eigen::Vector3d d = Eigen::Vector3d(q[0], q[1], q[2]) - mean;
    cov += d * d.transpose();
  }
  const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov, Eigen::EigenvaluesOnly).eigenvalues();
  return ev(1) > 1e-10 * ev(2);  // not on a line
}

std::vector<Estimate> runCgal(const Positions& p, float radius, int order, double& secs) {
  using K = CGAL::Simple_cartesian<double>;
  using Fitting = CGAL::Monge_via_jet_fitting<K>;
  std::vector<Estimate> out(p.size());
  const auto t0 = Clock::now();
  SpatialIndex index(p);
  const int need = (order + 1) * (order + 2) / 2;
  const std::int64_t n = static_cast<std::int64_t>(p.size());
#pragma omp parallel
  {
    std::vector<int> idx;
    std::vector<float> d2;
    std::vector<K::Point_3> pts;
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t i = 0; i < n; ++i) {
      const int c = index.radiusSearch(p[i], radius, idx, d2);  // self first
      if (c < need || !cgalJetIsPosed(p, idx, c, need)) continue;
      pts.clear();
      for (int j = 0; j < c; ++j) pts.emplace_back(p[idx[j]].x(), p[idx[j]].y(), p[idx[j]].z());
      Fitting fit;
      const Fitting::Monge_form m = fit(pts.begin(), pts.end(), order, 2);
      const K::Vector_3 nn = m.normal_direction();
      out[i].n = Eigen::Vector3f(float(nn.x()), float(nn.y()), float(nn.z()));
      const double k1 = m.principal_curvatures(0), k2 = m.principal_curvatures(1);
      out[i].k1 = float(std::max(k1, k2));
      out[i].k2 = float(std::min(k1, k2));
    }
  }
  secs = since(t0);
  return out;
}
#endif

// Every method of the table on one input: ours (order K), ours with order selection at R and
// at 2R, the bound (order 2 in the true tangent plane: the least-squares fit of the exact
// local model, i.e. the best linear unbiased estimate on the ball of R_phi), PCL at R and at
// R/2, and CGAL jet fitting of degree K (when built with CGAL).
struct MethodEstimates {
  std::vector<Estimate> ours, sel, sel2, bound, pcl, pcl_half, cgal, def, cgal2;
  double t_ours = 0, t_sel = 0, t_sel2 = 0, t_bound = 0, t_pcl = 0, t_half = 0, t_cgal = NAN, t_def = 0, t_cgal2 = NAN;
  WavejetReport def_report;
};
MethodEstimates runMethods(const Positions& p, float radius, int order, const Normals& tn, bool with_bound,
                           int neighbours, bool cgal_2r = false) {
  MethodEstimates m;
  m.def = runDefault(p, order, neighbours, tn, m.t_def, &m.def_report);
  m.ours = runWavejets(p, radius, order, tn, m.t_ours);
  m.sel = runWavejets(p, radius, order, tn, m.t_sel, nullptr, true);
  m.sel2 = runWavejets(p, 2 * radius, order, tn, m.t_sel2, nullptr, true);
  if (with_bound) m.bound = runWavejets(p, radius, 2, tn, m.t_bound, nullptr, false, &tn);
  m.pcl = runPcl(p, radius, m.t_pcl, true);
  m.pcl_half = runPcl(p, radius / 2, m.t_half, true);
#ifdef PAPS_HAVE_CGAL
  m.cgal = runCgal(p, radius, order, m.t_cgal);
  // CGAL at 2 R_phi: the support the default uses under noise (--cgal-2r; slow).
  if (cgal_2r) m.cgal2 = runCgal(p, 2 * radius, order, m.t_cgal2);
#else
  (void)cgal_2r;
#endif
  return m;
}

// The errors of every method against one truth (normals of the truth orient the estimates).
struct Comparison {
  Errors ours, sel, sel2, bound, pcl_raw, pcl_cal, pcl_geom, pcl_half, cgal, def, cgal2;
};
// Scored on the points where every method has an estimate (a method that leaves the hardest
// points out, e.g. by a larger beta, must not look better for it); `scored` gets their count.
Comparison scoreMethods(const MethodEstimates& m, float radius, const std::vector<Truth>& truth,
                        const std::vector<int>& all_eval, std::size_t* scored = nullptr) {
  std::vector<int> eval;
  for (const int i : all_eval) {
    bool ok = true;
    for (const auto* e : {&m.ours, &m.sel, &m.sel2, &m.bound, &m.pcl, &m.pcl_half, &m.cgal, &m.def, &m.cgal2})
      if (!e->empty()) ok = ok && std::isfinite((*e)[i].k1) && std::isfinite((*e)[i].k2) && isFinite((*e)[i].n);
    if (ok) eval.push_back(i);
  }
  if (scored) *scored = eval.size();
  std::vector<Eigen::Vector3f> tn(truth.size());
  for (std::size_t i = 0; i < truth.size(); ++i) tn[i] = truth[i].n;
  auto oriented = [&](std::vector<Estimate> e) { orientLike(e, tn); return e; };
  Comparison c;
  c.ours = score(oriented(m.ours), truth, eval, false);
  c.sel = score(oriented(m.sel), truth, eval, false);
  c.sel2 = score(oriented(m.sel2), truth, eval, false);
  if (!m.def.empty()) c.def = score(oriented(m.def), truth, eval, false);
  if (!m.bound.empty()) c.bound = score(oriented(m.bound), truth, eval, false);
  c.pcl_raw = score(m.pcl, truth, eval, true);
  c.pcl_cal = score(calibratePcl(m.pcl, truth, eval), truth, eval, true);
  c.pcl_geom = score(geometricPcl(m.pcl, radius), truth, eval, true);
  c.pcl_half = score(calibratePcl(m.pcl_half, truth, eval), truth, eval, true);
  if (!m.cgal.empty()) c.cgal = score(oriented(m.cgal), truth, eval, false);
  if (!m.cgal2.empty()) c.cgal2 = score(oriented(m.cgal2), truth, eval, false);
  return c;
}

// ---- reference curvature of a scan mesh (per-face second fundamental form from the vertex
// normals, after Rusinkiewicz 2004, accumulated on vertices, then averaged over a ball) ----

std::vector<Eigen::Matrix3d> vertexShapeTensors(const TriangleMesh& mesh, const Normals& vn) {
  std::vector<Eigen::Matrix3d> t(mesh.vertices.size(), Eigen::Matrix3d::Zero());
  std::vector<double> w(mesh.vertices.size(), 0.0);
  for (const auto& tri : mesh.triangles) {
    const Eigen::Vector3d v[3] = {mesh.vertices[tri[0]].cast<double>(), mesh.vertices[tri[1]].cast<double>(),
                                  mesh.vertices[tri[2]].cast<double>()};
    const Eigen::Vector3d n[3] = {vn[tri[0]].cast<double>(), vn[tri[1]].cast<double>(), vn[tri[2]].cast<double>()};
    Eigen::Vector3d nf = (v[1] - v[0]).cross(v[2] - v[0]);
    const double area = 0.5 * nf.norm();
    if (!(area > 0)) continue;
    nf.normalize();
    const Eigen::Vector3d u = (v[1] - v[0]).normalized(), vv = nf.cross(u);
    Eigen::Matrix<double, 6, 3> A;
    Eigen::Matrix<double, 6, 1> b;
    for (int k = 0; k < 3; ++k) {
      const int a = (k + 1) % 3, c = (k + 2) % 3;
      const Eigen::Vector3d e = v[c] - v[a], dn = n[c] - n[a];
      const double eu = e.dot(u), ev = e.dot(vv);
      A.row(2 * k) << eu, ev, 0;
      b[2 * k] = dn.dot(u);
      A.row(2 * k + 1) << 0, eu, ev;
      b[2 * k + 1] = dn.dot(vv);
    }
    const Eigen::Vector3d s = A.colPivHouseholderQr().solve(b);  // dn = S e, S = [[s0 s1][s1 s2]]
    const Eigen::Matrix3d T = s[0] * u * u.transpose() + s[1] * (u * vv.transpose() + vv * u.transpose()) +
                              s[2] * vv * vv.transpose();
    for (int k = 0; k < 3; ++k) { t[tri[k]] += area * T; w[tri[k]] += area; }
  }
  for (std::size_t i = 0; i < t.size(); ++i)
    if (w[i] > 0) t[i] /= w[i];
  return t;
}

// ---- reference curvature from positions only: the normal cycle curvature measure of the
// dense mesh over a ball (Cohen-Steiner and Morvan 2003) ----
// Over a region B, T(B) = sum over the edges e in B of beta(e) |e| e e^T / area(B), beta the
// signed dihedral angle of e, |e| its length, e its direction. Its eigenvalues in the tangent
// plane are the mean principal curvatures over B (the eigenvectors are swapped: the
// direction of k1 carries k2, which does not matter here). It uses only the vertex positions
// and the triangles: no normals (PCL's input) and no fit (ours and CGAL's), so it favours
// neither family. Edges count when their midpoint is in B, faces when their centroid is.
// Signs: positive where the surface bends towards the face normals (a sphere with outward
// normals: -1/r), as the estimates.
struct NormalCycle {
  Positions edge_mid, face_mid;
  std::vector<Eigen::Matrix3d> edge_t;   // beta |e| e e^T
  std::vector<Eigen::Vector3d> face_n;   // area-weighted normal (norm = area)
};
NormalCycle normalCycle(const TriangleMesh& mesh) {
  NormalCycle nc;
  const std::size_t nf = mesh.triangles.size();
  std::vector<Eigen::Vector3d> fn(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    const auto& t = mesh.triangles[f];
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                          c = mesh.vertices[t[2]].cast<double>();
    fn[f] = 0.5 * (b - a).cross(c - a);
    nc.face_mid.push_back(((a + b + c) / 3).cast<float>());
    nc.face_n.push_back(fn[f]);
  }
  struct HalfEdge { std::uint64_t key; int face, from, opposite; };
  std::vector<HalfEdge> he;
  he.reserve(3 * nf);
  for (std::size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.triangles[f][k], b = mesh.triangles[f][(k + 1) % 3], o = mesh.triangles[f][(k + 2) % 3];
      const std::uint64_t key = (std::uint64_t(std::min(a, b)) << 32) | std::uint32_t(std::max(a, b));
      he.push_back({key, int(f), a, o});
    }
  std::sort(he.begin(), he.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.key != y.key ? x.key < y.key : x.face < y.face;
  });
  for (std::size_t i = 0; i < he.size();) {
    std::size_t j = i;
    while (j < he.size() && he[j].key == he[i].key) ++j;
    if (j - i == 2) {  // manifold interior edge (borders and non-manifold edges left out)
      const HalfEdge &h1 = he[i], &h2 = he[i + 1];
      const int a = int(h1.key >> 32), b = int(h1.key & 0xffffffffu);
      Eigen::Vector3d n1 = fn[h1.face], n2 = fn[h2.face];
      if (h1.from == h2.from) n2 = -n2;  // inconsistent orientation of the two faces
      if (n1.norm() > 0 && n2.norm() > 0) {
        n1.normalize();
        n2.normalize();
        const Eigen::Vector3d va = mesh.vertices[a].cast<double>(), vb = mesh.vertices[b].cast<double>();
        const Eigen::Vector3d e = vb - va;
        const double len = e.norm();
        double beta = std::atan2(n1.cross(n2).norm(), n1.dot(n2));
        // Concave (bending towards the normal): the far vertex of face 2 is above face 1.
        if ((mesh.vertices[h2.opposite].cast<double>() - va).dot(n1) < 0) beta = -beta;
        if (len > 0) {
          const Eigen::Vector3d u = e / len;
          nc.edge_mid.push_back(((va + vb) / 2).cast<float>());
          nc.edge_t.push_back(beta * len * u * u.transpose());
        }
      }
    }
    i = j;
  }
  return nc;
}
// The reference at each query point over the ball of radius rho (NaN when the ball holds no
// face).
std::vector<Truth> normalCycleReference(const NormalCycle& nc, const Positions& q, float rho) {
  SpatialIndex ei(nc.edge_mid), fi(nc.face_mid);
  std::vector<Truth> out(q.size(), Truth{Eigen::Vector3f::Constant(NAN), NAN, NAN});
  const std::int64_t n = static_cast<std::int64_t>(q.size());
#pragma omp parallel
  {
    std::vector<int> id;
    std::vector<float> d2;
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t i = 0; i < n; ++i) {
      Eigen::Vector3d nn = Eigen::Vector3d::Zero();
      double area = 0;
      const int cf = fi.radiusSearch(q[i], rho, id, d2);
      for (int j = 0; j < cf; ++j) { nn += nc.face_n[id[j]]; area += nc.face_n[id[j]].norm(); }
      if (!(area > 0) || !(nn.norm() > 0)) continue;
      nn.normalize();
      Eigen::Matrix3d T = Eigen::Matrix3d::Zero();
      const int ce = ei.radiusSearch(q[i], rho, id, d2);
      for (int j = 0; j < ce; ++j) T += nc.edge_t[id[j]];
      T /= area;
      const Eigen::Vector3d u = nn.unitOrthogonal(), v = nn.cross(u);
      Eigen::Matrix2d S;
      S << u.dot(T * u), u.dot(T * v), v.dot(T * u), v.dot(T * v);
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> e2(S);
      out[i] = {nn.cast<float>(), float(e2.eigenvalues()[1]), float(e2.eigenvalues()[0])};
    }
  }
  return out;
}

// ---- small renderer: orthographic splats, z-buffer, Lambert shading by the given normals ----

const char* kBenchCurvatureUsage =
    "usage: paps bench curvature [options]\n"
    "  --points N         samples per analytic surface (default 20000)\n"
    "  --neighbours N     mean neighbour count that sets the radius (default 50)\n"
    "  --order K          Wavejet order = CGAL jet fitting degree (default 4)\n"
    "  --scan PATH        scan mesh (.ply with faces and normals; default rs1_normals.ply of the\n"
    "                     samples, skipped when missing)\n"
    "  --scan-step N      evaluate on every N-th scan vertex (default 4)\n"
    "  --speed-points N   size of the speed run (default 1000000, 0: skip)\n"
    "  --out DIR          where the PNG renders go (default .)\n"
    "  --skip LIST        parts left out, a comma list of analytic, tilt, scan, density, render, speed\n"
    "  --noise LIST       noise levels of the analytic part, fractions of R_phi (default 0,0.0025,0.005,0.01)\n"
    "  --cgal-2r          also CGAL jet fitting at 2 R_phi in the table of ours default (slow)\n";

}  // namespace

int runBenchCurvature(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 3, {"help", "cgal-2r"});
  if (a.has("help")) { std::fputs(kBenchCurvatureUsage, stdout); return 0; }
  a.allowOnly({"points", "neighbours", "order", "scan", "scan-step", "speed-points", "out", "skip", "help", "noise", "cgal-2r"});
  const std::string skip = "," + a.text("skip", "") + ",";
  for (std::size_t b = 1; b < skip.size();) {
    const std::size_t e = skip.find(',', b);
    const std::string item = skip.substr(b, e - b);
    if (!item.empty() && item != "analytic" && item != "tilt" && item != "scan" && item != "render" && item != "speed" &&
        item != "density")
      throw InvalidParameter("skip", item, "a comma list of analytic, tilt, scan, density, render, speed");
    b = e + 1;
  }
  auto skipped = [&](const char* part) { return skip.find("," + std::string(part) + ",") != std::string::npos; };
  const std::size_t npts = a.count("points", 20000);
  const int neighbours = a.integer("neighbours", 50);
  const int order = a.integer("order", 4);
  const std::size_t speed_points = a.count("speed-points", 1000000);
  const std::string out_dir = a.text("out", ".");
  std::filesystem::create_directories(out_dir);
  const std::string scan = a.text("scan", samplesDir() + "/rs1_normals.ply");
  const int scan_step = a.integer("scan-step", 4);
  requireInRange("points", static_cast<double>(npts), 1000.0, 1e7);
  requireInRange("order", order, 2, 10);
  requireInRange("scan-step", scan_step, 1, 1000);
#ifndef PAPS_HAVE_CGAL
  std::printf("note: built without CGAL, the jet-fitting column is empty\n");
#endif
  const int threads = omp_get_max_threads();
  std::printf("paps bench curvature: order %d, ~%d neighbours, %zu irregular samples per surface, %d threads\n",
              order, neighbours, npts, threads);

  // ---- 1. analytic surfaces x noise ----
  if (!skipped("analytic")) {
  std::printf("\n## Analytic surfaces (noise sigma in %% of R_phi; evaluated on points farther than 0.8 from the border)\n");
  std::printf("curvature error = RMSE(k1, k2) / RMS(true k1, k2); normal error = mean angle (deg)\n");
  std::printf("PCL raw = pc1, pc2 of PrincipalCurvaturesEstimation against |k|; PCL cal. = s*sqrt(pc) with the oracle best s\n\n");
  std::printf("ours = fixed order K; ours sel. = order chosen in [2, K] per point by BIC (--select-order), beta 3\n");
  std::printf("ours sel. 2R = the same at radius 2 R_phi: the support PCL's estimator sees (its curvature at p\n"
              "averages normals of neighbours within R_phi, each fitted over R_phi)\n");
  std::printf("PCL geom. = 2 sqrt(pc) / R_phi, the oracle-free reading of pc (uniform disk: pc = k^2 R^2 / 4)\n");
  std::printf("PCL(R/2) cal. = PCL with R_phi / 2 for normals and curvatures (effective support R_phi, as ours\n"
              "and ours sel.), oracle-calibrated\n\n");
  std::printf("bound = order 2 fitted in the true tangent plane over R_phi (the exact local model, no refit): the\n"
              "best linear unbiased estimate on the ball of R_phi, what no local fit on that support beats on average\n\n");
  std::printf("| surface | noise | R_phi | ours curv | ours sel. curv | ours sel. 2R curv | bound curv | CGAL curv | PCL cal. curv | PCL geom. curv | PCL raw curv | PCL(R/2) cal. curv | ours normal | ours sel. normal | ours sel. 2R normal | CGAL normal | PCL normal | ours s | ours sel. 2R s | CGAL s | PCL s |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::vector<double> noise_levels;
  {
    std::string list = a.text("noise", "0,0.0025,0.005,0.01") + ",";
    for (std::size_t b = 0, e; (e = list.find(',', b)) != std::string::npos; b = e + 1)
      if (e > b) noise_levels.push_back(std::stod(list.substr(b, e - b)));
  }
  double worst_def_pcl = 0, worst_def_geom = 0, worst_def_half = 0, worst_def_cgal = 0, worst_def_clean = 0,
         worst_def_cgal2 = 0;
  const bool cgal_2r = a.has("cgal-2r");
  std::string default_rows;
  double worst_ratio_pcl = 0, worst_ratio_cgal = 0, worst_sel_pcl = 0, worst_raw_pcl = 0;
  double worst_bound_half = 0, min_scored = 1;
  double worst_sel2_pcl = 0, worst_sel2_geom = 0, worst_sel2_raw = 0, worst_sel_half = 0, worst_sel_cgal = 0,
         worst_sel2_cgal = 0;
  std::uint64_t seed = 1;
  std::size_t analytic_narrowed = 0, analytic_checked = 0;
  for (const Surface& s : analyticSurfaces()) {
    Positions clean;
    std::vector<Truth> truth;
    sampleSurface(s, npts, seed++, clean, truth);
    std::vector<int> eval;
    for (std::size_t i = 0; i < clean.size(); ++i)
      if (std::abs(clean[i].x()) < 0.8 && std::abs(clean[i].y()) < 0.8) eval.push_back(int(i));
    SpatialIndex idx0(clean);
    const float radius = benchRadius(clean, idx0, neighbours);
    Normals tn(clean.size());
    for (std::size_t i = 0; i < clean.size(); ++i) tn[i] = truth[i].n;
    for (const double noise : noise_levels) {
      Positions p = clean;
      Random rng(seed * 7919 + std::uint64_t(noise * 1e6));
      for (auto& x : p)
        x += rng.gaussian3().cast<float>() * float(noise * radius);
      const MethodEstimates m = runMethods(p, radius, order, tn, true, neighbours, cgal_2r);
      // The cap of narrowing at the automatic radius (paps curvature's defaults) on an evenly
      // sampled surface: counted, expected 0.
      analytic_narrowed += m.def_report.narrowed;
      analytic_checked += p.size();
      // The core's quadric noise estimate on the same points, next to the pilot's order-K
      // residual (docs/wavejets.md, "Noise-aware defaults": why the pilot uses the latter).
      float quadric_sigma = NAN;
      try {
        SpatialIndex pidx(p);
        quadric_sigma = estimateNoiseLevel(p, pidx, radius).sigma;
      } catch (const Error&) {}
      std::size_t scored = 0;
      const Comparison c = scoreMethods(m, radius, truth, eval, &scored);
      min_scored = std::min(min_scored, double(scored) / double(eval.size()));
      const Errors &eo = c.ours, &es = c.sel, &es2 = c.sel2, &ep = c.pcl_raw, &epc = c.pcl_cal, &epg = c.pcl_geom,
                   &eph = c.pcl_half, &ec = c.cgal, &eb = c.bound;
      const double t_ours = m.t_ours, t_sel2 = m.t_sel2, t_cgal = m.t_cgal, t_pcl = m.t_pcl;
      worst_bound_half = std::max(worst_bound_half, eb.curv_rel / eph.curv_rel);
      worst_ratio_pcl = std::max(worst_ratio_pcl, eo.curv_rel / epc.curv_rel);
      worst_sel_pcl = std::max(worst_sel_pcl, es.curv_rel / epc.curv_rel);
      worst_raw_pcl = std::max(worst_raw_pcl, eo.curv_rel / ep.curv_rel);
      // Ratios to CGAL only where CGAL's error is measurable (> 1e-3).
      if (ec.curv_rel > 1e-3) {
        worst_ratio_cgal = std::max(worst_ratio_cgal, eo.curv_rel / ec.curv_rel);
        worst_sel_cgal = std::max(worst_sel_cgal, es.curv_rel / ec.curv_rel);
        worst_sel2_cgal = std::max(worst_sel2_cgal, es2.curv_rel / ec.curv_rel);
      }
      worst_sel2_pcl = std::max(worst_sel2_pcl, es2.curv_rel / epc.curv_rel);
      worst_sel2_geom = std::max(worst_sel2_geom, es2.curv_rel / epg.curv_rel);
      worst_sel2_raw = std::max(worst_sel2_raw, es2.curv_rel / ep.curv_rel);
      worst_sel_half = std::max(worst_sel_half, es.curv_rel / eph.curv_rel);
      {
        const Errors& ed = c.def;
        const WavejetReport& dr = m.def_report;
        worst_def_pcl = std::max(worst_def_pcl, ed.curv_rel / epc.curv_rel);
        worst_def_geom = std::max(worst_def_geom, ed.curv_rel / epg.curv_rel);
        worst_def_half = std::max(worst_def_half, ed.curv_rel / eph.curv_rel);
        if (ec.curv_rel > 1e-3) worst_def_cgal = std::max(worst_def_cgal, ed.curv_rel / ec.curv_rel);
        if (noise == 0) worst_def_clean = std::max(worst_def_clean, ed.curv_rel);
        char line[512], cgal2_cells[64] = "";
        if (cgal_2r)
          std::snprintf(cgal2_cells, sizeof cgal2_cells, " %.4f | %.3f |", c.cgal2.curv_rel, ed.curv_rel / c.cgal2.curv_rel);
        std::snprintf(line, sizeof line,
                      "| %s | %.2f%% | %.2e | %.2e | %s | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.3f | %.3f | %.3f | %.3f | %.2f |%s\n",
                      s.name.c_str(), noise * 100, dr.noise_sigma / radius, quadric_sigma / radius,
                      defaultChoice(dr).c_str(), ed.curv_rel, eo.curv_rel, es.curv_rel, es2.curv_rel, ec.curv_rel,
                      epc.curv_rel, epg.curv_rel, eph.curv_rel, ed.curv_rel / epc.curv_rel,
                      ec.curv_rel > 1e-3 ? ed.curv_rel / ec.curv_rel : NAN, ed.normal_deg, ec.normal_deg, m.t_def,
                      cgal2_cells);
        if (cgal_2r && c.cgal2.curv_rel > 1e-3) worst_def_cgal2 = std::max(worst_def_cgal2, ed.curv_rel / c.cgal2.curv_rel);
        default_rows += line;
      }
      std::printf("| %s | %.2f%% | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.3g | %.4f | %.3f | %.3f | %.3f | %.3f | %.3f | %.2f | %.2f | %.2f | %.2f |\n",
                  s.name.c_str(), noise * 100, radius, eo.curv_rel, es.curv_rel, es2.curv_rel, eb.curv_rel, ec.curv_rel,
                  epc.curv_rel, epg.curv_rel, ep.curv_rel, eph.curv_rel, eo.normal_deg, es.normal_deg, es2.normal_deg, ec.normal_deg,
                  ep.normal_deg, t_ours, t_sel2, t_cgal, t_pcl);
      std::fflush(stdout);
    }
  }
  std::printf("\nworst ratios over the table: ours / PCL raw %.3f; ours / PCL calibrated %.3f; ours sel. / PCL calibrated "
              "%.3f; ours / CGAL %.3f (where CGAL > 1e-3)\n", worst_raw_pcl, worst_ratio_pcl, worst_sel_pcl, worst_ratio_cgal);
  std::printf("same support 2 R_phi: ours sel. 2R / PCL calibrated %.3f, / PCL geom. %.3f, / PCL raw %.3f\n", worst_sel2_pcl,
              worst_sel2_geom, worst_sel2_raw);
  std::printf("scored on the points where every method has an estimate: at least %.1f%% of the evaluated points\n",
              100 * min_scored);
  std::printf("same support R_phi: ours sel. / PCL(R/2) calibrated %.3f; bound / PCL(R/2) calibrated %.3f\n",
              worst_sel_half, worst_bound_half);
  std::printf("fixed order %d / CGAL degree %d at the same radius (where CGAL > 1e-3): %.4f\n", order, order,
              worst_ratio_cgal);
  std::printf("against CGAL (degree %d, where CGAL > 1e-3): ours sel. %.3f, ours sel. 2R %.3f\n", order, worst_sel_cgal,
              worst_sel2_cgal);
  std::printf("narrowing at the automatic radius (defaults of paps curvature, cap 4 x %d): %zu of %zu points "
              "narrowed over the table's surfaces and noise levels\n", neighbours, analytic_narrowed, analytic_checked);
  std::printf("\n## Ours default (what paps curvature does without options: automatic radius for %d neighbours,\n"
              "## widened/narrowed per point, noise-aware order policy), same points, same run, scored on the same points\n",
              neighbours);
  std::printf("pilot = sigma of the default's order-%d residuals / the bench's R_phi; quadric = core\n"
              "estimateNoiseLevel sigma / R_phi at the bench's R_phi; choice = fixed order or selection, neighbour count\n\n", order);
  std::printf("| surface | noise | pilot | quadric | choice | ours default curv | ours curv | ours sel. curv | ours sel. 2R curv | CGAL curv | PCL cal. curv | PCL geom. curv | PCL(R/2) cal. curv | default / PCL cal. | default / CGAL | ours default normal | CGAL normal | ours default s |%s\n",
              cgal_2r ? " CGAL 2R curv | default / CGAL 2R |" : "");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|%s\n%s", cgal_2r ? "---|---|" : "",
              default_rows.c_str());
  if (cgal_2r) std::printf("\nworst ratio of ours default / CGAL degree %d at 2 R_phi (where CGAL > 1e-3): %.3f\n", order, worst_def_cgal2);
  std::printf("\nworst ratios of ours default: / PCL cal. %.3f, / PCL geom. %.3f, / PCL(R/2) cal. %.3f, / CGAL %.3f (where "
              "CGAL > 1e-3); largest error without noise %.4f\n", worst_def_pcl, worst_def_geom, worst_def_half,
              worst_def_cgal, worst_def_clean);

  }

  // ---- 2. tilted parameterization plane ----
  if (!skipped("tilt")) {
  std::printf("\n## Tilted parameterization plane (no noise): normal error (deg) after correction, max over evaluated points\n");
  std::printf("| surface | tilt | Cor. 1 once (no refit, as the default below 45 degrees): mean / max | refit above 10 degrees: mean / max |\n|---|---|---|---|\n");
  std::uint64_t seed = 1;
  for (const Surface& s : analyticSurfaces()) {
    Positions p;
    std::vector<Truth> truth;
    sampleSurface(s, npts / 4, seed++, p, truth);
    SpatialIndex index(p);
    const float radius = benchRadius(p, index, neighbours);
    Normals tn(p.size());
    for (std::size_t i = 0; i < p.size(); ++i) tn[i] = truth[i].n;
    for (const double tilt : {0.0, 5.0, 10.0, 15.0, 20.0}) {
      Normals init(p.size());
      Random rng(99);
      for (std::size_t i = 0; i < p.size(); ++i) {
        const Eigen::Vector3f axis = tn[i].unitOrthogonal();
        const float az = float(rng.uniform(0, 2 * kPi));
        const Eigen::Vector3f ax2 = Eigen::AngleAxisf(az, tn[i]) * axis;
        init[i] = Eigen::AngleAxisf(float(tilt * kPi / 180), ax2) * tn[i];
      }
      double mean[2] = {0, 0}, mx[2] = {0, 0};
      std::size_t cnt = 0;
      for (int mode = 0; mode < 2; ++mode) {
        WavejetParameters params;
        params.order = order;
        if (mode == 0) { params.max_refits = 0; params.refit_angle = 90; }
        else params.refit_angle = 10;  // the refit at work (the default, 45, does not refit below 20)
        const auto res = estimateWavejets(p, radius, params, nullptr, nullptr, &init, &tn);
        cnt = 0;
        for (std::size_t i = 0; i < p.size(); ++i) {
          if (!(std::abs(p[i].x()) < 0.8 && std::abs(p[i].y()) < 0.8) || !res[i].valid()) continue;
          const double e = std::acos(std::min(1.0, double(res[i].normal.dot(tn[i])))) * 180 / kPi;
          mean[mode] += e; mx[mode] = std::max(mx[mode], e); ++cnt;
        }
        mean[mode] /= double(cnt);
      }
      std::printf("| %s | %.0f | %.4f / %.4f | %.4f / %.4f |\n", s.name.c_str(), tilt, mean[0], mx[0], mean[1], mx[1]);
    }
  }

  }

  // ---- 3. real scan ----
  bool have_scan = false;
  if (!skipped("scan")) try {
    const TriangleMesh mesh = loadTriangleMesh(scan);
    have_scan = !mesh.triangles.empty();
    if (have_scan) {
      // Reference: the dense mesh. Vertex normals from the file would be unit after
      // normalisation; we recompute area-weighted ones from the faces for consistency.
      Normals vn(mesh.vertices.size(), Eigen::Vector3f::Zero());
      for (const auto& t : mesh.triangles) {
        const Eigen::Vector3f fn = (mesh.vertices[t[1]] - mesh.vertices[t[0]]).cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
        for (int k = 0; k < 3; ++k) vn[t[k]] += fn;
      }
      for (auto& n : vn) n.normalize();
      const auto tensors = vertexShapeTensors(mesh, vn);
      Positions p;
      std::vector<int> dense_of;
      for (std::size_t i = 0; i < mesh.vertices.size(); i += scan_step) { p.push_back(mesh.vertices[i]); dense_of.push_back(int(i)); }
      SpatialIndex sidx(p);
      const float radius = benchRadius(p, sidx, neighbours);
      // Reference at scale: average the dense tensors and normals over the ball of R_phi / 2.
      SpatialIndex didx(mesh.vertices);
      std::vector<Truth> truth(p.size());
      Normals tn(p.size());
      std::vector<int> eval;
      {
        std::vector<int> id; std::vector<float> d2;
        for (std::size_t i = 0; i < p.size(); ++i) {
          const int c = didx.radiusSearch(p[i], 0.5f * radius, id, d2);
          Eigen::Matrix3d T = Eigen::Matrix3d::Zero();
          Eigen::Vector3d n = Eigen::Vector3d::Zero();
          for (int j = 0; j < c; ++j) { T += tensors[id[j]]; n += vn[id[j]].cast<double>(); }
          n.normalize();
          const Eigen::Vector3d u = n.unitOrthogonal(), v = n.cross(u);
          Eigen::Matrix2d S;
          S << u.dot(T * u), u.dot(T * v), v.dot(T * u), v.dot(T * v);
          S /= std::max(c, 1);
          Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> e2(0.5 * (S + S.transpose()));
          // dn = S de: a sphere with outward normals has S = +1/r; our sign is the opposite.
          truth[i] = {n.cast<float>(), float(-e2.eigenvalues()[0]), float(-e2.eigenvalues()[1])};
          tn[i] = truth[i].n;
          if (c >= 8) eval.push_back(int(i));
        }
      }
      // Leave out the border of the scan: points whose neighbourhood is lopsided.
      {
        std::vector<int> keep; std::vector<int> id; std::vector<float> d2;
        for (const int i : eval) {
          const int c = sidx.radiusSearch(p[i], radius, id, d2);
          Eigen::Vector3f m = Eigen::Vector3f::Zero();
          for (int j = 0; j < c; ++j) m += p[id[j]];
          m /= float(c);
          if ((m - p[i]).norm() < 0.25f * radius) keep.push_back(i);
        }
        eval.swap(keep);
      }
      // The references, each at the query points of the sparse cloud (see the docs for the
      // choice): the normal cycle of the dense mesh over balls of R/4, R/2 (the main one) and
      // R; the earlier normal-based one (favours PCL: built from averaged vertex normals);
      // an order-2 Wavejet fit on the dense mesh over R/2 (favours fits: ours and CGAL).
      struct Reference { std::string name; std::vector<Truth> truth; };
      std::vector<Reference> refs;
      const NormalCycle nc = normalCycle(mesh);
      refs.push_back({"normal cycle, ball R/2 (main)", normalCycleReference(nc, p, 0.5f * radius)});
      refs.push_back({"normal cycle, ball R/4", normalCycleReference(nc, p, 0.25f * radius)});
      refs.push_back({"normal cycle, ball R", normalCycleReference(nc, p, radius)});
      refs.push_back({"vertex-normal tensors, ball R/2 (earlier)", truth});
      {
        WavejetParameters dp;
        dp.order = 2;
        dp.order_policy = WavejetParameters::OrderPolicy::fixed;
        const auto dense_fit = estimateWavejets(mesh.vertices, 0.5f * radius, dp, nullptr, nullptr, nullptr, &vn);
        std::vector<Truth> t(p.size());
        for (std::size_t i = 0; i < p.size(); ++i) {
          const WavejetResult& r = dense_fit[dense_of[i]];
          t[i] = {r.normal, r.k1, r.k2};
        }
        refs.push_back({"order-2 fit of the dense mesh, ball R/2", t});
      }
      {  // evaluate where every reference is defined
        std::vector<int> keep;
        for (const int i : eval) {
          bool ok = true;
          for (const Reference& r : refs) ok = ok && std::isfinite(r.truth[i].k1) && isFinite(r.truth[i].n);
          if (ok) keep.push_back(i);
        }
        eval.swap(keep);
      }
      const MethodEstimates me = runMethods(p, radius, order, tn, false, neighbours);
      std::printf("\n## Scan %s: %zu of %zu vertices (every %d-th), %zu evaluated (border left out), R_phi %.3f;\n"
                  "## one row per reference (all from the dense mesh)\n",
                  scan.c_str(), p.size(), mesh.vertices.size(), scan_step, eval.size(), radius);
      std::printf("ours default: %s, R_phi %.3f (automatic), pilot residual %.3g%% of it\n", defaultChoice(me.def_report).c_str(),
                  me.def_report.radius, 100 * me.def_report.noise_relative);
      std::printf("| reference | ours default curv | ours curv | ours sel. curv | ours sel. 2R curv | CGAL curv | PCL cal. curv | PCL geom. curv | PCL raw curv | PCL(R/2) cal. curv | ours default normal | ours normal | ours sel. normal | ours sel. 2R normal | CGAL normal | PCL normal |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
      std::size_t scored = 0;
      for (const Reference& r : refs) {
        const Comparison c = scoreMethods(me, radius, r.truth, eval, &scored);
        std::printf("| %s | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.3g | %.4f | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f |\n",
                    r.name.c_str(), c.def.curv_rel, c.ours.curv_rel, c.sel.curv_rel, c.sel2.curv_rel, c.cgal.curv_rel, c.pcl_cal.curv_rel,
                    c.pcl_geom.curv_rel, c.pcl_raw.curv_rel, c.pcl_half.curv_rel, c.def.normal_deg, c.ours.normal_deg, c.sel.normal_deg,
                    c.sel2.normal_deg, c.cgal.normal_deg, c.pcl_raw.normal_deg);
      }
      std::printf("scored on the %zu points where every method has an estimate\n", scored);
      {
        // Where the error of the main reference sits: share of the squared error held by the
        // worst 1% of the points, median absolute error, and the least-squares best scale of
        // each estimate against the reference (an oracle; < 1: estimates too large).
        const std::vector<Truth>& tr = refs.front().truth;
        std::vector<int> common;
        for (const int i : eval) {
          bool ok = true;
          for (const auto* e : {&me.ours, &me.sel, &me.sel2, &me.pcl, &me.pcl_half, &me.cgal, &me.def})
            if (!e->empty()) ok = ok && std::isfinite((*e)[i].k1) && std::isfinite((*e)[i].k2) && isFinite((*e)[i].n);
          if (ok) common.push_back(i);
        }
        std::vector<Eigen::Vector3f> rn(tr.size());
        for (std::size_t i = 0; i < tr.size(); ++i) rn[i] = tr[i].n;
        auto profile = [&](const char* name, std::vector<Estimate> e, bool magnitudes) {
          if (!magnitudes) orientLike(e, rn);
          std::vector<double> se;
          double total = 0, num = 0, den = 0;
          for (const int i : common) {
            double a1 = tr[i].k1, a2 = tr[i].k2;
            if (magnitudes) {
              a1 = std::max(std::abs(tr[i].k1), std::abs(tr[i].k2));
              a2 = std::min(std::abs(tr[i].k1), std::abs(tr[i].k2));
            }
            se.push_back((e[i].k1 - a1) * (e[i].k1 - a1) + (e[i].k2 - a2) * (e[i].k2 - a2));
            total += se.back();
            num += e[i].k1 * a1 + e[i].k2 * a2;
            den += double(e[i].k1) * e[i].k1 + double(e[i].k2) * e[i].k2;
          }
          if (se.empty()) return;
          std::sort(se.begin(), se.end());
          double top = 0;
          for (std::size_t k = se.size() - se.size() / 100; k < se.size(); ++k) top += se[k];
          std::printf("  %s: worst 1%% hold %.0f%% of the squared error, median |error| %.4f, best scale %.2f\n", name,
                      100 * top / std::max(total, 1e-300), std::sqrt(se[se.size() / 2] / 2), den > 0 ? num / den : NAN);
        };
        std::printf("error profile against the main reference (RMS of its curvatures %.4f):\n", [&] {
          double st = 0;
          for (const int i : common) st += tr[i].k1 * tr[i].k1 + tr[i].k2 * tr[i].k2;
          return std::sqrt(st / std::max<std::size_t>(1, 2 * common.size()));
        }());
        profile("ours sel.", me.sel, false);
        profile("CGAL", me.cgal, false);
        profile("PCL geom.", geometricPcl(me.pcl, radius), true);
        profile("PCL(R/2) geom.", geometricPcl(me.pcl_half, radius / 2), true);
      }
      std::printf("times (s, %zu points): ours default %.2f, ours %.2f, ours sel. %.2f, ours sel. 2R %.2f, CGAL %.2f, PCL %.2f, PCL(R/2) %.2f\n",
                  p.size(), me.t_def, me.t_ours, me.t_sel, me.t_sel2, me.t_cgal, me.t_pcl, me.t_half);

      // Renders of the enhanced scan (full resolution): original, positions alpha0 = 2,
      // normals alpha1 = 3 and alpha1 = 3i (skewed).
      if (!skipped("render")) {
      const Positions& dense = mesh.vertices;
      Normals hints = vn;
      WavejetEnhancementParameters ep2;
      ep2.wavejet.order = 6;
      ep2.wavejet.order_policy = WavejetParameters::OrderPolicy::fixed;  // as `paps enhance --order 6`
      ep2.target_neighbours = 60;
      Normals corrected;
      WavejetEnhancementReport r1, r2;
      ep2.alpha0 = 1;
      const Positions proj = enhancePositions(dense, ep2, &r1, {}, {}, &hints, &corrected);
      ep2.alpha0 = 2.5f;
      Normals nn2;
      const Positions enh = enhancePositions(dense, ep2, &r2, {}, {}, &hints, &nn2);
      // Shade the moved points with normals refitted on the moved cloud.
      WavejetParameters wp;
      wp.order = 4;
      wp.order_policy = WavejetParameters::OrderPolicy::fixed;
      const auto refit = estimateWavejets(enh, r2.radius, wp, nullptr, nullptr, nullptr, &hints);
      Normals enh_normals(enh.size());
      for (std::size_t i = 0; i < enh.size(); ++i) enh_normals[i] = refit[i].normal;
      ep2.alpha1 = {3.f, 0.f};
      const Normals n3 = enhanceNormals(dense, ep2, nullptr, {}, &hints);
      ep2.alpha1 = {1.f, 3.f};
      const Normals n3i = enhanceNormals(dense, ep2, nullptr, {}, &hints);
      const std::string png = out_dir + "/wavejets_enhanced_scan.png";
      renderShadedPanels({{dense, corrected}, {enh, enh_normals}, {dense, n3}, {dense, n3i}}, View::fit(dense), 480,
                         png);
      std::printf("\nrender: %s (original with Wavejet normals | positions alpha0 = 2.5 | normals alpha1 = 3 | "
                  "normals alpha1 = 1+3i), order 6, R_phi %.3f, clamped %zu of %zu\n",
                  png.c_str(), r2.radius, r2.clamped, dense.size());
      }
    }
  } catch (const Error& e) {
    std::printf("\nscan skipped: %s\n", e.what());
  }
  (void)have_scan;

  // ---- 3b. varying density and duplicates: the defaults a scan user gets ----
  if (!skipped("density")) {
    std::printf("\n## Varying density and exact duplicates (the automatic radius, as paps curvature chooses it)\n");
    std::printf("%zu samples per surface: a share (uniform share) uniform over [-1, 1]^2, the rest in the disk of\n"
                "radius 0.15 around (0.3, 0.2) (share 0.3: about 130x denser; 0.9: 6x), every sample written twice (exact duplicates, as in bun0.pcd);\n"
                "scored on the first copies with |x|, |y| < 0.8. R_phi = the automatic radius of paps curvature\n"
                "(core radiusForNeighbourCount(%d), median) over the distinct positions. fixed R = --fixed-radius (no\n"
                "widening, NaN where too few); default = a point\n"
                "whose ball holds fewer than %d distinct positions is fitted on its %d nearest (R_phi there =\n"
                "distance of the farthest); widen below need = the same only where the ball holds fewer than the\n"
                "order needs (an alternative, not used); kNN = every point on its %d nearest distinct positions.\n"
                "default curv widened / narrowed / in ball: the default on its widened points / on its points\n"
                "whose ball held more than the cap (4 x %d distinct positions: fitted on that many nearest) / on the\n"
                "others. no cap = the default without the cap (full crowded balls, the default before narrowing).\n"
                "Curvature error as above (RMSE / RMS); fixed R is scored on its own fitted points only.\n\n",
                npts, neighbours, neighbours, neighbours, neighbours, neighbours);
    std::printf("| surface | uniform share | noise (abs.) | R_phi | NaN fixed R | NaN default | widened | narrowed | default curv | default curv widened "
                "| default curv narrowed | no cap curv | no cap curv narrowed pts | default curv in ball | widen below need curv | kNN curv | fixed R curv (its fitted points) | default s | no cap s | kNN s |\n"
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    std::uint64_t seed = 101;
    // Sparse share 0.3: the dense disk sets the radius (sparse balls widened); 0.9: the
    // sparse part sets it and the disk (6x denser) holds more than the cap (narrowed).
    for (const double sparse_share : {0.3, 0.9})
    for (const Surface& s : analyticSurfaces()) {
      for (const double noise : {0.0, 2e-5}) {
        Random rng(seed++);
        Positions p;
        std::vector<Truth> truth;
        while (p.size() < npts) {
          double x, y;
          if (rng.uniform() < sparse_share) { x = rng.uniform(-1, 1); y = rng.uniform(-1, 1); }
          else {
            do { x = rng.uniform(-0.15, 0.15); y = rng.uniform(-0.15, 0.15); } while (x * x + y * y > 0.15 * 0.15);
            x += 0.3; y += 0.2;
          }
          Eigen::Vector3f q(float(x), float(y), float(s.f(x, y)));
          q += rng.gaussian3().cast<float>() * float(noise);
          p.push_back(q);
          truth.push_back(truthOf(s, x, y));
        }
        const std::size_t base = p.size();
        for (std::size_t i = 0; i < base; ++i) { p.push_back(p[i]); truth.push_back(truth[i]); }
        Normals tn(p.size());
        for (std::size_t i = 0; i < p.size(); ++i) tn[i] = truth[i].n;
        std::vector<int> eval, eval_wide, eval_narrow, eval_ball;
        WavejetParameters params;
        params.order = order;
        params.order_policy = WavejetParameters::OrderPolicy::fixed;  // this part is about the supports, at the fixed order
        params.widening = WavejetParameters::Widening::never;
        WavejetReport r_fixed, r_def;
        const auto fixed = estimateWavejets(p, 0.f, params, &r_fixed, nullptr, nullptr, &tn, {}, neighbours);
        params.widening = WavejetParameters::Widening::automatic;
        auto t0 = Clock::now();
        const auto def = estimateWavejets(p, 0.f, params, &r_def, nullptr, nullptr, &tn, {}, neighbours);
        const double t_def = since(t0);
        // The same without the cap of narrowing (full balls where crowded: the default before it).
        params.narrowed_neighbours = 1000000;
        WavejetReport r_nocap;
        t0 = Clock::now();
        const auto nocap = estimateWavejets(p, 0.f, params, &r_nocap, nullptr, nullptr, &tn, {}, neighbours);
        const double t_nocap = since(t0);
        params.narrowed_neighbours = 0;
        // Alternatives fitted here from explicit lists on the distinct positions: kNN (every
        // point on its `neighbours` nearest) and "need" (the `neighbours` nearest only where the
        // ball of R_phi holds fewer than the order needs, 17 for K = 4; else the ball).
        const std::vector<int> rep = exactDuplicateRepresentatives(p);
        Positions u;
        std::vector<int> slot(p.size(), -1);
        for (std::size_t i = 0; i < p.size(); ++i)
          if (rep[i] == int(i)) { slot[i] = int(u.size()); u.push_back(p[i]); }
        const SpatialIndex uindex(u);
        const int need = wavejetNeededNeighbours(params);
        auto custom = [&](bool knn_everywhere) {
          std::vector<WavejetResult> ku(u.size()), res(p.size());
#pragma omp parallel
          {
            WavejetWorkspacePtr ws = makeWavejetWorkspace();
            std::vector<int> idx;
            std::vector<float> d2;
#pragma omp for schedule(dynamic, 256)
            for (std::int64_t j = 0; j < std::int64_t(p.size()); ++j) {
              if (slot[j] < 0) continue;
              float rj = r_def.radius;
              int n = knn_everywhere ? 0 : uindex.radiusSearch(p[j], rj, idx, d2);
              if (knn_everywhere || n < need) {
                n = uindex.nearestK(p[j], neighbours, idx, d2);
                rj = std::max(knn_everywhere ? 0.f : rj, std::sqrt(d2[n - 1]));
              }
              ku[slot[j]] = fitWavejet(u, idx.data(), n, p[j], rj, params, *ws, Eigen::Vector3f::Constant(NAN), tn[j]);
            }
          }
          for (std::size_t i = 0; i < p.size(); ++i) res[i] = ku[slot[rep[i]]];
          return res;
        };
        t0 = Clock::now();
        const std::vector<WavejetResult> knn = custom(true);
        const double t_knn = since(t0);
        const std::vector<WavejetResult> below_need = custom(false);
        std::size_t nan_fixed = 0, nan_def = 0;
        for (std::size_t i = 0; i < base; ++i) {
          nan_fixed += !fixed[i].valid();
          nan_def += !def[i].valid();
          if (!(std::abs(p[i].x()) < 0.8f && std::abs(p[i].y()) < 0.8f)) continue;
          eval.push_back(int(i));
          (def[i].radius > r_def.radius ? eval_wide : def[i].radius < r_def.radius ? eval_narrow : eval_ball)
              .push_back(int(i));
        }
        auto toEst = [&](const std::vector<WavejetResult>& res) {
          std::vector<Estimate> e(res.size());
          for (std::size_t i = 0; i < res.size(); ++i) e[i] = {res[i].normal, res[i].k1, res[i].k2};
          orientLike(e, tn);
          return e;
        };
        const auto e_nocap = toEst(nocap);
        const auto e_def = toEst(def), e_knn = toEst(knn), e_fixed = toEst(fixed), e_need = toEst(below_need);
        std::printf("| %s | %.1f | %.1e | %.4f | %.1f%% | %.1f%% | %.1f%% | %.1f%% | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f | %.2f | %.2f | %.2f |\n",
                    s.name.c_str(), sparse_share, noise, r_def.radius, 100.0 * nan_fixed / base, 100.0 * nan_def / base,
                    100.0 * r_def.widened / p.size(), 100.0 * r_def.narrowed / p.size(),
                    score(e_def, truth, eval, false).curv_rel, score(e_def, truth, eval_wide, false).curv_rel,
                    eval_narrow.empty() ? 0.0 : score(e_def, truth, eval_narrow, false).curv_rel,
                    score(e_nocap, truth, eval, false).curv_rel,
                    eval_narrow.empty() ? 0.0 : score(e_nocap, truth, eval_narrow, false).curv_rel,
                    score(e_def, truth, eval_ball, false).curv_rel,
                    score(e_need, truth, eval, false).curv_rel, score(e_knn, truth, eval, false).curv_rel,
                    score(e_fixed, truth, eval, false).curv_rel, t_def, t_nocap, t_knn);
        std::fflush(stdout);
      }
    }
  }

  // ---- 4. speed ----
  if (speed_points > 0 && !skipped("speed")) {
    const Surface s = analyticSurfaces()[4];
    Positions p;
    std::vector<Truth> truth;
    sampleSurface(s, speed_points, 12345, p, truth);
    SpatialIndex index(p);
    const float radius = benchRadius(p, index, neighbours);
    WavejetParameters params;
    params.order = order;
    params.order_policy = WavejetParameters::OrderPolicy::fixed;
    WavejetReport rep;
    auto t0 = Clock::now();
    std::clock_t c0 = std::clock();
    estimateWavejets(p, radius, params, &rep);
    const double t_all = since(t0);
    const double cpu_all = double(std::clock() - c0) / CLOCKS_PER_SEC;
    std::printf("\n## Speed: %zu points (monkey saddle), order %d, mean %.1f neighbours, R_phi %.4f\n", p.size(), order,
                rep.mean_neighbours, radius);
    std::printf("ours fixed order, %d threads: %.2f s wall, %.2f s CPU over all threads (neighbour search and grid build "
                "included)\n", threads, t_all, cpu_all);
    // The default (automatic radius, widening, noise-aware policy with its pilot), clean and
    // at 1%% noise (the largest support growth).
    const double noises[] = {0.0, 0.0, 0.01};
    for (int k = 0; k < 3; ++k) {
      // The first run: the default without its pilot (order policy fixed), what the pilot costs.
      const double noise = noises[k];
      const bool pilot = k > 0;
      Positions q = p;
      Random rng(777);
      for (auto& x : q)
        x += rng.gaussian3().cast<float>() * float(noise * radius);
      WavejetParameters dp;
      dp.order = order;
      if (!pilot) dp.order_policy = WavejetParameters::OrderPolicy::fixed;
      WavejetReport dr;
      t0 = Clock::now();
      c0 = std::clock();
      estimateWavejets(q, 0.f, dp, &dr, nullptr, nullptr, nullptr, {}, neighbours);
      const double tw = since(t0), tc = double(std::clock() - c0) / CLOCKS_PER_SEC;
      std::printf("ours default%s, noise %.2f%%, %d threads: %.2f s wall, %.2f s CPU (%s, pilot residual %.3g%%, mean %.1f "
                  "neighbours, R_phi %.4f, %zu NaN)\n", pilot ? "" : " without pilot (--order-policy fixed)", noise * 100,
                  threads, tw, tc, defaultChoice(dr).c_str(),
                  100 * dr.noise_relative, dr.mean_neighbours, dr.radius, dr.too_few_neighbours);
    }
    // The pcl::Feature class on the same points and R_phi, fixed order, as a PCL pipeline
    // runs it: with PCL's default search (answered by our grid) and with a
    // pcl::search::KdTree set (PCL's balls); beside PCL's own normal and curvature estimators
    // on the same balls, all with the same threads.
    {
      pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
      cloud->resize(p.size());
      for (std::size_t i = 0; i < p.size(); ++i) (*cloud)[i].getVector3fMap() = p[i];
      pcl::PointCloud<PointWavejet> out[2];
      double secs[2];
      for (int tree = 0; tree < 2; ++tree) {
        WavejetEstimation<pcl::PointXYZ> wj;
        wj.setInputCloud(cloud);
        wj.setRadiusSearch(radius);
        wj.setOrder(order);
        if (tree) wj.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>(false));
        const auto tw = Clock::now();
        wj.compute(out[tree]);
        secs[tree] = since(tw);
      }
      std::size_t same = 0;
      for (std::size_t i = 0; i < p.size(); ++i)
        same += std::memcmp(&out[0][i], &out[1][i], sizeof(PointWavejet)) == 0;
      double t_pcl = 0;
      runPcl(p, radius, t_pcl, true);
      std::printf("pcl::Feature WavejetEstimation (fixed order, R_phi), %d threads: %.2f s with PCL's default search "
                  "(our grid), %.2f s with a pcl::search::KdTree set (%.2fx); %zu of %zu outputs identical; PCL "
                  "NormalEstimationOMP + PrincipalCurvaturesEstimation on the same balls %.2f s\n",
                  threads, secs[0], secs[1], secs[1] / secs[0], same, p.size(), t_pcl);
    }
    // The same with setKSearch, as most PCL pipelines call their estimators, on the points
    // as sampled (random order) and gathered in space order: ours visits them in space order
    // whatever their order (its own and FLANN's memory accesses stay in cache).
    {
      double ours_k[2], pcl_k[2], kd_k = 0;
      std::size_t same_k = 0;
      const std::vector<int> by_space = spatialOrder(p);
      for (int ordered = 0; ordered < 2; ++ordered) {
        const Positions q = ordered ? gathered(p, by_space) : p;
        pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
        cloud->resize(q.size());
        for (std::size_t i = 0; i < q.size(); ++i) (*cloud)[i].getVector3fMap() = q[i];
        WavejetEstimation<pcl::PointXYZ> wj;
        wj.setInputCloud(cloud);
        wj.setKSearch(neighbours);
        wj.setOrder(order);
        pcl::PointCloud<PointWavejet> out;
        auto tw = Clock::now();
        wj.compute(out);
        ours_k[ordered] = since(tw);
        if (!ordered) {
          // PCL's own kd-tree set instead of the default (paps::KdTreeSearch): the same lists.
          WavejetEstimation<pcl::PointXYZ> kd;
          kd.setInputCloud(cloud);
          kd.setKSearch(neighbours);
          kd.setOrder(order);
          kd.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
          pcl::PointCloud<PointWavejet> out_kd;
          tw = Clock::now();
          kd.compute(out_kd);
          kd_k = since(tw);
          for (std::size_t i = 0; i < out.size() && out.size() == out_kd.size(); ++i)
            same_k += std::memcmp(&out[i], &out_kd[i], sizeof(PointWavejet)) == 0;
        }
        runPcl(q, 0.f, pcl_k[ordered], true, 0.f, neighbours);
      }
      std::printf("pcl::Feature WavejetEstimation with setKSearch(%d), %d threads: %.2f s on the points as sampled "
                  "(random order), %.2f s in space order; PCL NormalEstimationOMP + PrincipalCurvaturesEstimation with "
                  "setKSearch(%d): %.2f s / %.2f s\n",
                  neighbours, threads, ours_k[0], ours_k[1], neighbours, pcl_k[0], pcl_k[1]);
      std::printf("pcl::Feature WavejetEstimation with setKSearch(%d), points as sampled: %.2f s with PCL's default "
                  "search (paps::KdTreeSearch), %.2f s with a pcl::search::KdTree set (%.2fx); %zu of %zu outputs "
                  "identical\n", neighbours, ours_k[0], kd_k, kd_k / ours_k[0], same_k, p.size());
    }
    const std::size_t sub = std::min<std::size_t>(p.size(), 100000);
    Positions ps(p.begin(), p.begin() + sub);
    SpatialIndex is(ps);
    const float rs = benchRadius(ps, is, neighbours);
    omp_set_num_threads(1);
    double t1 = 0, tc = NAN, tp = 0;
    Normals none(ps.size(), Eigen::Vector3f::Constant(NAN));
    runWavejets(ps, rs, order, none, t1);  // fixed order
#ifdef PAPS_HAVE_CGAL
    runCgal(ps, rs, order, tc);
#endif
    runPcl(ps, rs, tp, false);
    omp_set_num_threads(threads);
    std::printf("1 thread, %zu points at ~%d neighbours: ours %.2f s, CGAL jet fitting (degree %d) %.2f s, PCL normals + "
                "principal curvatures %.2f s\n", ps.size(), neighbours, t1, order, tc, tp);
  }
  return 0;
}

// Hidden `paps bench-worker-curv METHOD IN OUT LOG key=value...`, the child of `paps bench
// files`: ours at the defaults of `paps curvature` (automatic R_phi), PCL normals + principal
// curvatures and CGAL jet fitting on the balls of the radius given (ours' R_phi). Writes the
// points that got finite curvatures (their positions) and the time of the estimate alone.
int runCurvatureWorker(int argc, char** argv) {
  return runWorkerFrame(argc, argv, [](const std::string& method, const Positions& input, const WorkerParameters& params,
                                       std::ostream& lf, double& secs) {
    auto get = [&](const char* k, double d) { return params.get(k, d); };
    const int order = static_cast<int>(get("order", 4));
    const float radius = static_cast<float>(get("radius", 0));
    std::vector<Estimate> est;
    if (method == "wavejets") {
      WavejetParameters wp;
      wp.order = order;
      WavejetReport rep;
      const auto t0 = Clock::now();
      const auto res = estimateWavejets(input, 0.f, wp, &rep, nullptr, nullptr, nullptr, {},
                                        static_cast<int>(get("neighbours", 50)));
      secs = since(t0);
      est.resize(res.size());
      for (std::size_t i = 0; i < res.size(); ++i) est[i] = {res[i].normal, res[i].k1, res[i].k2};
      lf << "radius " << rep.radius << "\n";
      lf << "chosen " << defaultChoice(rep) << ", mean " << rep.mean_neighbours << " neighbours, " << rep.narrowed
         << " narrowed, " << rep.widened << " widened\n";
    } else if (method == "pcl") {
      if (!(radius > 0)) throw InvalidParameter("radius", std::to_string(radius), "> 0");
      est = runPcl(input, radius, secs, true);
#ifdef PAPS_HAVE_CGAL
    } else if (method == "cgal") {
      if (!(radius > 0)) throw InvalidParameter("radius", std::to_string(radius), "> 0");
      est = runCgal(input, radius, order, secs);
#endif
    } else {
      throw InvalidParameter("method", method, "wavejets, pcl or cgal");
    }
    Positions fitted;
    for (std::size_t i = 0; i < est.size(); ++i)
      if (std::isfinite(est[i].k1) && std::isfinite(est[i].k2)) fitted.push_back(input[i]);
    return fitted;
  });
}

}  // namespace paps::cli
