#include <paps/features/wavejet.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/QR>

#include <paps/core/cell_grid.h>
#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/spatial_order.h>
#include <paps/core/tiling.h>
#include <paps/features/wavejet_noise.h>

namespace paps {

void WavejetParameters::validate() const {
  requireInRange("order", order, 1, 20);
  if (!std::isfinite(beta)) throw InvalidParameter("beta", detail::toString(beta), "a value in [1, 100]");
  requireInRange("beta", beta, 1.f, 100.f);
  requireInRange("irls_iterations", irls_iterations, 0, 100);
  requireInRange("max_refits", max_refits, 0, 50);
  if (!std::isfinite(refit_angle)) throw InvalidParameter("refit_angle", detail::toString(refit_angle), "a value in [0, 90]");
  requireInRange("refit_angle", refit_angle, 0.f, 90.f);
  requireInRange("widened_neighbours", widened_neighbours, 0, 100000);
  requireInRange("narrowed_neighbours", narrowed_neighbours, 0, 1000000);
  if (!isFinite(viewpoint)) throw InvalidParameter("viewpoint", "non-finite", "finite coordinates");
  if (max_tile_points > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw InvalidParameter("max_tile_points", std::to_string(max_tile_points), "0 (one piece) or a count below 2^31");
}

std::complex<float> WavejetCoefficients::at(int k, int n) const {
  if (k < 0 || k > order || std::abs(n) > k || ((k - n) & 1)) return {0.f, 0.f};
  const std::complex<float> c = phi[wavejetIndex(k, std::abs(n))];
  return n >= 0 ? c : std::conj(c);
}

std::complex<float> WavejetCoefficients::integralInvariant(int n, float s) const {
  std::complex<double> a(0, 0);
  const int first = std::max(std::abs(n), 1);
  double sk = double(s) * s;  // s^(k+2)
  for (int k = 0; k < first; ++k) sk *= s;
  for (int k = first; k <= order; ++k, sk *= s) a += std::complex<double>(at(k, n)) * sk / double(k + 2);
  return std::complex<float>(a);
}

namespace {
// Orders up to this use the normal equations (Cholesky of the Gram matrix, accumulated
// row by row): the same nested least-squares solutions as the Householder QR below (the
// Cholesky factor of A^T A is the R of A = QR up to signs), at a fraction of the cost and
// without per-point allocations. Above it, or when the Gram matrix is ill-conditioned
// (squared condition number), the QR path is used.
constexpr int kGramMaxOrder = 6;

// The Gram matrix A^T A and A^T b of the basis of buildRows() from moments: every product
// of two basis functions r^k e^{i n theta} is r2^j z^n or r2^j zbar^n for some j, n, so the
// sums over the neighbours of r2^j z^n (2j + n <= 2K) and of z r2^j z^n give every entry:
// about (K+1)^2 complex sums per neighbour instead of the m (m + 1) / 2 products of the
// design matrix (m = (K+1)(K+2)/2).
struct GramFromMoments {
  static constexpr int kJ = kGramMaxOrder + 1, kN = 2 * kGramMaxOrder + 1;
  double mr[kJ][kN], mi[kJ][kN];  // sum r2^j z^n (real, imaginary)
  double qr[kJ][kN], qi[kJ][kN];  // sum h r2^j z^n, 2j + n <= K (h: height)
  double hh;                      // sum h^2

  void accumulate(const std::vector<Eigen::Vector3d>& local, int order) {
    const int k2 = 2 * order;
    for (int j = 0; j <= order; ++j)
      for (int n = 0; n + 2 * j <= k2; ++n) mr[j][n] = mi[j][n] = qr[j][n] = qi[j][n] = 0.0;
    hh = 0;
    double zr[kN], zi[kN], r2p[kJ];
    for (const Eigen::Vector3d& q : local) {
      zr[0] = 1; zi[0] = 0;
      for (int n = 1; n <= k2; ++n) {
        zr[n] = zr[n - 1] * q.x() - zi[n - 1] * q.y();
        zi[n] = zr[n - 1] * q.y() + zi[n - 1] * q.x();
      }
      const double r2 = q.x() * q.x() + q.y() * q.y(), h = q.z();
      r2p[0] = 1;
      for (int j = 1; j <= order; ++j) r2p[j] = r2p[j - 1] * r2;
      hh += h * h;
      for (int j = 0; j <= order; ++j) {
        const double w = r2p[j], wh = w * h;
        const int nmax = k2 - 2 * j;
        for (int n = 0; n <= nmax; ++n) { mr[j][n] += w * zr[n]; mi[j][n] += w * zi[n]; }
        for (int n = 0; n + 2 * j <= order; ++n) { qr[j][n] += wh * zr[n]; qi[j][n] += wh * zi[n]; }
      }
    }
  }
  // sum A B and sum A conj(B) for A = r2^a z^na, B = r2^b z^nb.
  void products(int a, int na, int b, int nb, double& ab_r, double& ab_i, double& acb_r, double& acb_i) const {
    ab_r = mr[a + b][na + nb];
    ab_i = mi[a + b][na + nb];
    if (na >= nb) { acb_r = mr[a + b + nb][na - nb]; acb_i = mi[a + b + nb][na - nb]; }
    else { acb_r = mr[a + b + na][nb - na]; acb_i = -mi[a + b + na][nb - na]; }
  }
};

}  // namespace

struct WavejetWorkspace {
  std::vector<int> finite;
  Eigen::MatrixXd a, aw;
  Eigen::VectorXd b, bw, w, x, residual, c;
  std::vector<double> abs_residual;
  Eigen::HouseholderQR<Eigen::MatrixXd> qr;
  std::vector<Eigen::Vector3d> local;
  std::vector<std::complex<double>> zpow;
  std::vector<double> r2pow;
  // Normal-equations path (fixed orders up to kGramMaxOrder, no IRLS): row-major design
  // rows, Gram matrix and its Cholesky factor, right-hand side. Reused across points.
  std::vector<double> rows;
  std::vector<double> gram, rhs, cvec;
  GramFromMoments moments;
  // Covariance of the fitted (Re phi_11, Im phi_11) under the fit's own residual variance
  // (valid when the fit has residual degrees of freedom): xx, xy, yy.
  double tilt_cov[3] = {0, 0, 0};
  bool tilt_cov_valid = false;
  int tilt_dof = 0;  // residual degrees of freedom of that fit
  double residual_variance = -1;  // rss / (rows - m) of that fit, unit-disk units (-1: none)
  std::vector<double> cov_u;
  // Per-point scratch of fitWavejet and the Corollary 2 product.
  std::vector<std::complex<double>> phi, mono_f, mono_d, mono_prod;
  WavejetCoefficients coefficients;
};
void WavejetWorkspaceDeleter::operator()(WavejetWorkspace* w) const { delete w; }
WavejetWorkspacePtr makeWavejetWorkspace() { return WavejetWorkspacePtr(new WavejetWorkspace); }

namespace {

const float kNaN = std::numeric_limits<float>::quiet_NaN();

// Full complex coefficient table c[p][q] of the monomials z^p zbar^q (p + q <= K), where
// c[p][q] = phi_{p+q, p-q}. Used for the products of Corollary 2.
struct MonomialTable {
  int order;
  std::vector<std::complex<double>>& c;  // storage reused from the workspace
  MonomialTable(int k, std::vector<std::complex<double>>& storage) : order(k), c(storage) {
    c.assign(std::size_t(k + 1) * (k + 1), 0.0);
  }
  std::complex<double>& at(int p, int q) { return c[std::size_t(p) * (order + 1) + q]; }
};

// Builds the design matrix rows (unknowns ordered by k, then n >= 0; n > 0 takes two real
// unknowns: Re and Im of phi_{k,n}).
void buildRows(WavejetWorkspace& ws, int order) {
  const int rows = static_cast<int>(ws.local.size());
  const int m = wavejetUnknowns(order);
  ws.a.resize(rows, m);
  ws.b.resize(rows);
  ws.zpow.resize(order + 1);
  ws.r2pow.resize(order / 2 + 1);
  for (int l = 0; l < rows; ++l) {
    const Eigen::Vector3d& q = ws.local[l];
    const std::complex<double> z(q.x(), q.y());
    const double r2 = q.x() * q.x() + q.y() * q.y();
    ws.zpow[0] = 1.0;
    for (int n = 1; n <= order; ++n) ws.zpow[n] = ws.zpow[n - 1] * z;
    ws.r2pow[0] = 1.0;
    for (int j = 1; j <= order / 2; ++j) ws.r2pow[j] = ws.r2pow[j - 1] * r2;
    int col = 0;
    for (int k = 0; k <= order; ++k)
      for (int n = k & 1; n <= k; n += 2) {
        const std::complex<double> c = ws.r2pow[(k - n) / 2] * ws.zpow[n];
        if (n == 0) {
          ws.a(l, col++) = c.real();
        } else {
          // phi r^k e^{in theta} + conj = 2 Re(phi c) = 2 (Re phi Re c - Im phi Im c)
          ws.a(l, col++) = 2.0 * c.real();
          ws.a(l, col++) = -2.0 * c.imag();
        }
      }
    ws.b[l] = q.z();
  }
}


// Fills ws.gram (m x m), ws.rhs (m) and returns |b|^2, for the columns of buildRows():
// n = 0: Re e; n > 0: 2 Re e and -2 Im e, e = r2^((k-n)/2) z^n.
double buildGram(WavejetWorkspace& ws, int order) {
  GramFromMoments& g = ws.moments;
  g.accumulate(ws.local, order);
  const int m = wavejetUnknowns(order);
  // Columns: (j, n, part, factor), part 0 = real, 1 = imaginary.
  int cj[64], cn[64], cp[64];
  double cf[64];
  int c = 0;
  for (int k = 0; k <= order; ++k)
    for (int n = k & 1; n <= k; n += 2) {
      const int j = (k - n) / 2;
      if (n == 0) { cj[c] = j; cn[c] = 0; cp[c] = 0; cf[c] = 1; ++c; }
      else {
        cj[c] = j; cn[c] = n; cp[c] = 0; cf[c] = 2; ++c;
        cj[c] = j; cn[c] = n; cp[c] = 1; cf[c] = -2; ++c;
      }
    }
  ws.gram.resize(std::size_t(m) * m);
  ws.rhs.resize(m);
  for (int u = 0; u < m; ++u) {
    for (int v = u; v < m; ++v) {
      double abr, abi, acbr, acbi;
      g.products(cj[u], cn[u], cj[v], cn[v], abr, abi, acbr, acbi);
      double t;
      if (cp[u] == 0 && cp[v] == 0) t = 0.5 * (abr + acbr);
      else if (cp[u] == 1 && cp[v] == 1) t = 0.5 * (acbr - abr);
      else if (cp[u] == 0) t = 0.5 * (abi - acbi);  // Re A Im B
      else t = 0.5 * (abi + acbi);                  // Im A Re B
      const double e = cf[u] * cf[v] * t;
      ws.gram[std::size_t(u) * m + v] = e;
      ws.gram[std::size_t(v) * m + u] = e;
    }
    const double qv = cp[u] == 0 ? g.qr[cj[u]][cn[u]] : g.qi[cj[u]][cn[u]];
    ws.rhs[u] = cf[u] * qv;
  }
  return g.hh;
}

// Order selection criterion of the nested fits (Bayesian information criterion):
// L ln(RSS_m / L) + m ln L, m unknowns, L neighbours. RSS is floored at 1e-24 |b|^2 so that
// exact fits tie (and the lowest exact order wins) instead of comparing rounding errors.
// Measured against GCV (L RSS / (L - m)^2) on the bench surfaces: GCV lets about 15% of the
// points take order 3 or 4 under noise, whose curvatures are then much worse (the r^2 and
// r^4 columns are strongly correlated on the disk); BIC's ln L penalty keeps order 2 there.
double selectionCriterion(double rss, double btb, int rows, int unknowns) {
  const double floor = 1e-24 * std::max(btb, 1e-300);
  return rows * std::log(std::max(rss, floor) / rows) + unknowns * std::log(double(rows));
}

// Covariance of the two real unknowns of phi_11 (columns 1 and 2) for a least-squares fit
// with upper-triangular factor r(i, j) (m x m, R^T R = A^T A) and residual sum of squares
// rss over `rows` equations: s^2 [(R^T R)^-1]_{1..2}, s^2 = rss / (rows - m), with
// (R^T R)^-1 = R^-1 R^-T, so the entries are dot products of u_a = R^-T e_a. Not valid
// (no residual degree of freedom) when rows <= m.
template <class Factor>
void tiltCovariance(WavejetWorkspace& ws, const Factor& r, int m, double rss, int rows) {
  ws.tilt_cov_valid = false;
  ws.residual_variance = rows > m ? std::max(rss, 0.0) / (rows - m) : -1;
  if (rows <= m || m < 3) return;
  ws.cov_u.assign(std::size_t(2) * m, 0.0);
  for (int a = 0; a < 2; ++a) {
    double* u = ws.cov_u.data() + std::size_t(a) * m;
    for (int i = 1 + a; i < m; ++i) {  // forward substitution, R^T lower triangular
      double v = i == 1 + a ? 1.0 : 0.0;
      for (int k = 1 + a; k < i; ++k) v -= r(k, i) * u[k];
      u[i] = v / r(i, i);
    }
  }
  const double s2 = std::max(rss, 0.0) / (rows - m);
  ws.tilt_dof = rows - m;
  const double* u1 = ws.cov_u.data();
  const double* u2 = u1 + m;
  double xx = 0, xy = 0, yy = 0;
  for (int i = 0; i < m; ++i) { xx += u1[i] * u1[i]; xy += u1[i] * u2[i]; yy += u2[i] * u2[i]; }
  ws.tilt_cov[0] = s2 * xx;
  ws.tilt_cov[1] = s2 * xy;
  ws.tilt_cov[2] = s2 * yy;
  ws.tilt_cov_valid = true;
}

// Normal-equations solve with the same order selection as solve(). Returns 1 on success,
// -1 when the Gram matrix is too ill-conditioned to decide (the caller then uses the QR
// path, which also judges rank deficiency).
int solveGram(WavejetWorkspace& ws, int& order, bool select_order) {
  const int rows = static_cast<int>(ws.local.size());
  const int m = wavejetUnknowns(order);
  const double btb = buildGram(ws, order);
  double* g = ws.gram.data();
  // Cholesky G = R^T R, R upper triangular, stored in the upper triangle of g.
  double rmax = 0, rmin = INFINITY;
  for (int i = 0; i < m; ++i) {
    double* gi = g + std::size_t(i) * m;
    for (int k = 0; k < i; ++k) gi[i] -= g[std::size_t(k) * m + i] * g[std::size_t(k) * m + i];
    if (!(gi[i] > 0)) return -1;  // let the QR path judge the rank
    const double rii = std::sqrt(gi[i]);
    gi[i] = rii;
    rmax = std::max(rmax, rii);
    rmin = std::min(rmin, rii);
    const double inv = 1.0 / rii;
    for (int j = i + 1; j < m; ++j) {
      double v = gi[j];
      for (int k = 0; k < i; ++k) v -= g[std::size_t(k) * m + i] * g[std::size_t(k) * m + j];
      gi[j] = v * inv;
    }
  }
  // The Gram matrix squares the condition number: below 1e-6 the pivots are not trusted.
  if (!(rmin > 1e-6 * rmax)) return -1;
  // c = R^{-T} A^T b: the coordinates of b on the orthonormalised columns (Q^T b).
  ws.cvec.resize(m);
  for (int i = 0; i < m; ++i) {
    double v = ws.rhs[i];
    for (int k = 0; k < i; ++k) v -= g[std::size_t(k) * m + i] * ws.cvec[k];
    ws.cvec[i] = v / g[std::size_t(i) * m + i];
  }
  int mk = m;
  if (select_order && order > 2) {
    // RSS_m = |b|^2 - |c_0..m|^2 for the nested orders 2..K.
    double head = 0;
    for (int i = 0; i < m; ++i) head += ws.cvec[i] * ws.cvec[i];
    double best = INFINITY;
    int best_order = order;
    for (int k = order; k >= 2; --k) {
      const int mkk = wavejetUnknowns(k);
      if (k < order)
        for (int i = mkk; i < wavejetUnknowns(k + 1); ++i) head -= ws.cvec[i] * ws.cvec[i];
      const double rss = std::max(0.0, btb - head);
      const double score = selectionCriterion(rss, btb, rows, mkk);
      if (score < best - 1e-9) { best = score; best_order = k; }
    }
    order = best_order;
    mk = wavejetUnknowns(order);
  }
  {
    double head_mk = 0;
    for (int i = 0; i < mk; ++i) head_mk += ws.cvec[i] * ws.cvec[i];
    tiltCovariance(ws, [g, m](int i, int j) { return g[std::size_t(i) * m + j]; }, mk,
                   std::max(0.0, btb - head_mk), rows);
  }
  // x = R_mk^{-1} c_mk (the leading block of R is the factor of the leading block of G).
  ws.x.resize(mk);
  for (int i = mk - 1; i >= 0; --i) {
    double v = ws.cvec[i];
    for (int j = i + 1; j < mk; ++j) v -= g[std::size_t(i) * m + j] * ws.x[j];
    ws.x[i] = v / g[std::size_t(i) * m + i];
  }
  return 1;
}

// Least squares by Householder QR (columns ordered by increasing order, so the residual of
// every lower order comes from the same factorisation), optional order selection by
// the information criterion below, optional IRLS. Returns false when the system is rank
// deficient; `order` may be lowered by the selection.
bool solve(WavejetWorkspace& ws, int& order, int irls_iterations, bool select_order) {
  if (irls_iterations <= 0 && order <= kGramMaxOrder) {
    const int r = solveGram(ws, order, select_order);
    if (r >= 0) return r == 1;
  }
  buildRows(ws, order);
  const int rows = static_cast<int>(ws.a.rows());
  int m = static_cast<int>(ws.a.cols());
  ws.qr.compute(ws.a);
  const auto& qr = ws.qr.matrixQR();
  double rmax = 0, rmin = INFINITY;
  for (int i = 0; i < m; ++i) { rmax = std::max(rmax, std::abs(qr(i, i))); rmin = std::min(rmin, std::abs(qr(i, i))); }
  if (!(rmin > 1e-10 * rmax)) return false;
  ws.c = ws.b;
  ws.c.applyOnTheLeft(ws.qr.householderQ().adjoint());
  if (select_order && order > 2) {
    // Residual of each nested order 2..K from the same factorisation.
    double tail = ws.c.tail(rows - m).squaredNorm();
    const double btb = ws.b.squaredNorm();
    double best = INFINITY;
    int best_order = order;
    for (int k = order; k >= 2; --k) {
      const int mk = wavejetUnknowns(k);
      if (k < order) tail += ws.c.segment(mk, wavejetUnknowns(k + 1) - mk).squaredNorm();
      const double score = selectionCriterion(tail, btb, rows, mk);
      if (score < best - 1e-9) { best = score; best_order = k; }
    }
    order = best_order;
    m = wavejetUnknowns(order);
  }
  ws.x = qr.topLeftCorner(m, m).triangularView<Eigen::Upper>().solve(ws.c.head(m));
  tiltCovariance(ws, [&qr](int i, int j) { return qr(i, j); }, m, ws.c.tail(rows - m).squaredNorm(), rows);
  if (irls_iterations <= 0) return true;
  ws.a.conservativeResize(rows, m);
  ws.w.resize(rows);
  for (int it = 0; it < irls_iterations; ++it) {
    ws.residual = ws.b - ws.a * ws.x;
    ws.abs_residual.resize(rows);
    for (int l = 0; l < rows; ++l) ws.abs_residual[l] = std::abs(ws.residual[l]);
    auto mid = ws.abs_residual.begin() + rows / 2;
    std::nth_element(ws.abs_residual.begin(), mid, ws.abs_residual.end());
    const double sigma = 1.4826 * *mid;
    if (!(sigma > 1e-9)) break;  // (nearly) exact fit: nothing to reweight
    const double c = 4.685 * sigma;
    int used = 0;
    for (int l = 0; l < rows; ++l) {
      const double u = ws.residual[l] / c;
      ws.w[l] = std::abs(u) < 1 ? (1 - u * u) : 0.0;  // sqrt of the Tukey weight
      used += ws.w[l] > 0;
    }
    if (used < m) break;
    ws.aw = ws.w.asDiagonal() * ws.a;
    ws.bw = ws.w.cwiseProduct(ws.b);
    ws.qr.compute(ws.aw);
    const auto& r = ws.qr.matrixQR();
    double lo = INFINITY, hi = 0;
    for (int i = 0; i < m; ++i) { hi = std::max(hi, std::abs(r(i, i))); lo = std::min(lo, std::abs(r(i, i))); }
    if (!(lo > 1e-10 * hi)) break;
    ws.c = ws.bw;
    ws.c.applyOnTheLeft(ws.qr.householderQ().adjoint());
    ws.x = r.topLeftCorner(m, m).triangularView<Eigen::Upper>().solve(ws.c.head(m));
    tiltCovariance(ws, [&r](int i, int j) { return r(i, j); }, m, ws.c.tail(rows - m).squaredNorm(), rows);
  }
  return true;
}

// Complex coefficients phi_{k,n}, n >= 0, from the real solution vector.
void unpack(const Eigen::VectorXd& x, int order, std::vector<std::complex<double>>& phi) {
  phi.assign(wavejetStoredCoefficients(order), 0.0);
  int col = 0;
  for (int k = 0; k <= order; ++k)
    for (int n = k & 1; n <= k; n += 2) {
      if (n == 0) phi[wavejetIndex(k, n)] = {x[col++], 0.0};
      else { phi[wavejetIndex(k, n)] = {x[col], x[col + 1]}; col += 2; }
    }
}

std::complex<double> coef(const std::vector<std::complex<double>>& phi, int k, int n) {
  const std::complex<double> c = phi[wavejetIndex(k, std::abs(n))];
  return n >= 0 ? c : std::conj(c);
}

// Corollary 2: with the plane tilted so that the linear part of the fitted height has
// gradient g, the tangent-plane coefficients are, to first order in the tilt,
// phi = Phi - [f (g . grad f)], f the fitted height without its orders 0 and 1 and [.] the
// coefficients of the product. (Rotating the frame by the small angle gamma maps
// (x, y, h) to (x, y + gamma h, h - gamma y); solving H(X, Y) to first order gives
// H = f - gamma f f_y - gamma Y, i.e. g = (0, -gamma); this is eq. 2.15-2.16 written
// convention-free in the monomials z^p zbar^q.) Orders k >= 3 only change.
void correctCoefficients(std::vector<std::complex<double>>& phi, int order, double gx, double gy,
                         WavejetWorkspace& ws) {
  if (order < 3) return;
  MonomialTable f(order, ws.mono_f), d(order, ws.mono_d), prod(order, ws.mono_prod);
  for (int p = 0; p <= order; ++p)
    for (int q = 0; p + q <= order; ++q)
      if (p + q >= 2) f.at(p, q) = coef(phi, p + q, p - q);
  const std::complex<double> gz(gx, gy), gzb(gx, -gy);
  for (int p = 0; p <= order; ++p)
    for (int q = 0; p + q <= order; ++q) {
      const std::complex<double> c = f.at(p, q);
      if (c == 0.0) continue;
      if (p > 0) d.at(p - 1, q) += gz * double(p) * c;
      if (q > 0) d.at(p, q - 1) += gzb * double(q) * c;
    }
  for (int p1 = 0; p1 <= order; ++p1)
    for (int q1 = 0; p1 + q1 <= order; ++q1) {
      const std::complex<double> c = f.at(p1, q1);
      if (c == 0.0) continue;
      for (int p2 = 0; p1 + p2 <= order; ++p2)
        for (int q2 = 0; p1 + p2 + q1 + q2 <= order; ++q2) prod.at(p1 + p2, q1 + q2) += c * d.at(p2, q2);
    }
  for (int k = 3; k <= order; ++k)
    for (int n = k & 1; n <= k; n += 2) phi[wavejetIndex(k, n)] -= prod.at((k + n) / 2, (k - n) / 2);
}

// Is the fitted gradient (gx, gy) = (2 Re phi_11, -2 Im phi_11) distinguishable from zero?
// d2 = g^T Cov^-1 g with Cov from the residual variance s^2 of the fit: d2 / 2 follows
// Fisher's F(2, nu), nu the residual degrees of freedom, whose tail is exactly
// (1 + 2 f / nu)^(-nu / 2). The threshold is the level exp(-8) (about 3e-4), i.e. 4
// standard errors (d2 > 16) when nu is large, and more with few residual degrees of freedom
// (3 * (e^(16/3) - 1) = 617 at nu = 3), where s^2 itself is unreliable. Measured on the
// bench surfaces at 1% noise, fixed order 4 (docs/wavejets.md): at the level exp(-4.5)
// (3 standard errors) one point per surface still refitted on a noise-made tilt; at exp(-8)
// none did, while every clean tilted-plane case still refits (s^2 ~ 0 there). Without
// residual degrees of freedom the noise cannot be told from the tilt: significant (refit).
constexpr double kRefitLevelLog = -8;
bool tiltSignificant(const WavejetWorkspace& ws, double gx, double gy) {
  if (!ws.tilt_cov_valid) return true;
  // Cov(gx, gy) = J Cov(x1, x2) J^T, J = diag(2, -2).
  const double cxx = 4 * ws.tilt_cov[0], cxy = -4 * ws.tilt_cov[1], cyy = 4 * ws.tilt_cov[2];
  const double det = cxx * cyy - cxy * cxy;
  if (!(det > 0)) return true;  // exact fit (clean data) or degenerate: refit
  const double d2 = (cyy * gx * gx - 2 * cxy * gx * gy + cxx * gy * gy) / det;
  const double nu = ws.tilt_dof;
  const double limit = nu * std::expm1(-2.0 * kRefitLevelLog / nu);
  return d2 > limit;
}

Eigen::Vector3d anyTangent(const Eigen::Vector3d& n) {
  const Eigen::Vector3d a = std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return (a - n * n.dot(a)).normalized();
}

}  // namespace

WavejetResult fitWavejet(const Positions& points, const int* neighbours, int count,
                         const Eigen::Vector3f& pf, float radius, const WavejetParameters& params,
                         WavejetWorkspace& ws, const Eigen::Vector3f& initial_normal,
                         const Eigen::Vector3f& orientation, WavejetCoefficients* coefficients) {
  WavejetResult res;
  if (coefficients) { coefficients->order = -1; coefficients->radius = radius; coefficients->phi.clear(); }
  if (!isFinite(pf) || !(radius > 0) || !std::isfinite(radius)) return res;
  ws.finite.clear();
  for (int j = 0; j < count; ++j)
    if (isFinite(points[neighbours[j]])) ws.finite.push_back(neighbours[j]);
  // In index order: the fit must not depend on the order a search returned the ball in
  // (pcl::search::KdTree sorted or not; on a scan's border fits, where the least squares are
  // ill-conditioned, the summation order moved mean curvatures from 0.105 to 0.65).
  std::sort(ws.finite.begin(), ws.finite.end());
  const int l = static_cast<int>(ws.finite.size());
  int order = params.order;
  while (order >= 0 && l < params.beta * wavejetUnknowns(order)) --order;
  if (order < 2) return res;

  const Eigen::Vector3d p = pf.cast<double>();
  Eigen::Vector3d n;
  if (isFinite(initial_normal) && initial_normal.norm() > 0) {
    n = initial_normal.cast<double>().normalized();
  } else {
    // One pass, relative to p: sums of the offsets and of their products.
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Matrix3d prod = Eigen::Matrix3d::Zero();
    for (const int j : ws.finite) {
      const Eigen::Vector3d d = (points[j] - pf).cast<double>();
      sum += d;
      prod.noalias() += d * d.transpose();
    }
    const Eigen::Vector3d mean = sum / l;
    const Eigen::Matrix3d cov = prod - double(l) * mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
    eig.computeDirect(cov);
    n = eig.eigenvectors().col(0).normalized();
  }
  const Eigen::Vector3d toward = isFinite(orientation) ? Eigen::Vector3d(orientation.cast<double>())
                                                       : Eigen::Vector3d(params.viewpoint.cast<double>() - p);
  if (n.dot(toward) < 0) n = -n;
  Eigen::Vector3d t1 = anyTangent(n), t2 = n.cross(t1);

  const double inv_r = 1.0 / radius;
  const double refit_tan = std::tan(params.refit_angle * M_PI / 180.0);
  std::vector<std::complex<double>>& phi = ws.phi;
  double gx = 0, gy = 0;
  for (int refits = 0;; ++refits) {
    ws.local.resize(l);
    for (int j = 0; j < l; ++j) {
      const Eigen::Vector3d d = (points[ws.finite[j]].cast<double>() - p) * inv_r;
      ws.local[j] = {d.dot(t1), d.dot(t2), d.dot(n)};
    }
    ++res.fits;
    while (!solve(ws, order, params.irls_iterations,
                  params.select_order || params.order_policy == WavejetParameters::OrderPolicy::select)) {
      if (--order < 2) { res = WavejetResult(); return res; }
    }
    unpack(ws.x, order, phi);
    // Linear part 2 Re(phi_11 (x + i y)): gradient (2 Re phi_11, -2 Im phi_11).
    gx = 2 * phi[wavejetIndex(1, 1)].real();
    gy = -2 * phi[wavejetIndex(1, 1)].imag();
    const double tilt_tan = std::hypot(gx, gy);
    res.converged = tilt_tan <= refit_tan;
    if (res.converged || refits >= params.max_refits) break;
    // The refit is for a plane that is really off, not for a tilt the noise made: when the
    // fitted gradient is not distinguishable from zero given the fit's own residuals
    // (tiltSignificant), the plane is kept, as jet fitting keeps its PCA plane. Measured: on
    // noisy data with few neighbours per unknown (17 to 25 for 15 unknowns), refitting in
    // the plane of a noise-made tilt made already noise-bound curvatures worse (this was
    // the whole difference with CGAL's jet fitting at the same order, docs/wavejets.md).
    if (!tiltSignificant(ws, gx, gy)) { res.tilt_within_noise = true; break; }
    // Corollary 1, then refit: rotate the plane about u (orthogonal to the gradient) into
    // the tangent plane of the fitted height field.
    const Eigen::Vector3d n_new = (n - gx * t1 - gy * t2).normalized();
    const Eigen::Quaterniond rot = Eigen::Quaterniond::FromTwoVectors(n, n_new);
    n = n_new;
    t1 = (rot * t1).normalized();
    t1 = (t1 - n * n.dot(t1)).normalized();
    t2 = n.cross(t1);
  }

  // Differential quantities of the fitted height field at the origin (equations 2.9-2.11,
  // written through the fundamental forms so a residual tilt is accounted for exactly).
  const std::complex<double> p20 = phi[wavejetIndex(2, 0)], p22 = phi[wavejetIndex(2, 2)];
  const double fxx = 2 * (p20.real() + 2 * p22.real()) * inv_r;
  const double fyy = 2 * (p20.real() - 2 * p22.real()) * inv_r;
  const double fxy = -4 * p22.imag() * inv_r;
  const double e = 1 + gx * gx, f = gx * gy, g = 1 + gy * gy, w = std::sqrt(1 + gx * gx + gy * gy);
  const double L = fxx / w, M = fxy / w, N = fyy / w;
  const double det1 = e * g - f * f;
  const double gauss = (L * N - M * M) / det1;
  const double mean = (e * N - 2 * f * M + g * L) / (2 * det1);
  const double disc = std::sqrt(std::max(0.0, mean * mean - gauss));
  const double k1 = mean + disc, k2 = mean - disc;
  // Eigenvector of (II - k1 I): two candidate rows, take the better conditioned.
  Eigen::Vector2d v1(M - k1 * f, -(L - k1 * e)), v2(N - k1 * g, -(M - k1 * f));
  Eigen::Vector2d v = v1.squaredNorm() >= v2.squaredNorm() ? v1 : v2;
  if (v.squaredNorm() < 1e-24) v = Eigen::Vector2d(1, 0);  // umbilic: any direction
  Eigen::Vector3d dir = v.x() * (t1 + gx * n) + v.y() * (t2 + gy * n);

  // Corollary 1 (final, small residual tilt): the tangent frame. Corollary 2: coefficients.
  const Eigen::Vector3d n_t = (n - gx * t1 - gy * t2).normalized();
  const Eigen::Quaterniond rot = Eigen::Quaterniond::FromTwoVectors(n, n_t);
  Eigen::Vector3d t1_t = rot * t1;
  t1_t = (t1_t - n_t * n_t.dot(t1_t)).normalized();
  dir = (dir - n_t * n_t.dot(dir)).normalized();
  const double cos_tilt = 1.0 / w;
  correctCoefficients(phi, order, gx, gy, ws);
  phi[wavejetIndex(1, 1)] = 0.0;

  res.order = order;
  res.radius = radius;
  res.normal = n_t.cast<float>();
  res.direction1 = dir.cast<float>();
  res.k1 = static_cast<float>(k1);
  res.k2 = static_cast<float>(k2);
  res.mean_curvature = static_cast<float>(mean);
  res.gaussian_curvature = static_cast<float>(gauss);
  res.offset = static_cast<float>(phi[0].real() * cos_tilt * radius);
  res.residual = ws.residual_variance >= 0 ? static_cast<float>(std::sqrt(ws.residual_variance) * radius) : kNaN;
  WavejetCoefficients& c = coefficients ? *coefficients : ws.coefficients;
  c.order = order;
  c.radius = radius;
  c.frame.n = res.normal;
  c.frame.t1 = t1_t.cast<float>();
  c.frame.t2 = n_t.cross(t1_t).cast<float>();
  c.phi.resize(phi.size());
  for (std::size_t i = 0; i < phi.size(); ++i) c.phi[i] = std::complex<float>(phi[i]);
  res.a0 = c.integralInvariant(0).real();
  res.a1 = c.integralInvariant(1);
  return res;
}

int wavejetNeededNeighbours(const WavejetParameters& params) {
  // The same comparison as the order lowering of fitWavejet (int against float).
  const int m = wavejetUnknowns(params.order);
  int need = m;
  while (need < params.beta * m) ++need;
  return need;
}

int wavejetWidenedNeighbours(const WavejetParameters& params, int default_neighbours) {
  return std::max(wavejetNeededNeighbours(params),
                  params.widened_neighbours > 0 ? params.widened_neighbours : default_neighbours);
}

int wavejetNarrowedNeighbours(const WavejetParameters& params, int default_neighbours) {
  const int n = wavejetWidenedNeighbours(params, default_neighbours);
  return std::max(n, params.narrowed_neighbours > 0 ? params.narrowed_neighbours : 4 * n);
}

namespace {

// Which neighbours a point was fitted on.
enum Support : std::uint8_t { kBall = 0, kWidened = 1, kNarrowed = 2 };

// Wavejets of distinct positions (no exact duplicates). `neighbour_count` gets the count
// used per point, `support` its Support, `reach` (when given) the radius around the point
// within which every position of the whole cloud must lie in `points` for its output to be
// the whole cloud's (its ball, or the ball of its widened neighbours; infinite where the
// points held fewer than the widening asks): a tile checks its halo with it. `fit_only`,
// when given, flags the points to fit (the others get no output).
//
// fitWavejet sums a neighbourhood in the order of its indices: into the grid's copy, whose
// cells lie on a lattice anchored at 0 (ordered z, y, x, then by index), or into `points` for
// widened balls; narrowing and widening break ties by index. A tile whose points keep the
// cloud's relative order therefore fits each of its points on the same neighbours in the same
// order as the whole cloud: the same floats, whatever the tile's extent or the kd-tree's order.
std::vector<WavejetResult> estimateDistinct(const Positions& points, float& radius, const WavejetParameters& params,
                                            std::vector<WavejetCoefficients>* coefficients,
                                            const Normals* initial_normals, const Normals* orientation,
                                            const ProgressCallback& progress, int target_neighbours,
                                            std::vector<int>& neighbour_count, std::vector<std::uint8_t>& support,
                                            std::unique_ptr<SpatialIndex> index, float radius_scale,
                                            std::vector<float>* reach = nullptr,
                                            const std::vector<std::uint8_t>* fit_only = nullptr) {
  const bool automatic = radius == 0;
  const bool widen = params.widening == WavejetParameters::Widening::always ||
                     (params.widening == WavejetParameters::Widening::automatic && automatic);
  if (!index && (automatic || widen)) index = std::make_unique<SpatialIndex>(points);
  if (automatic) radius = radius_scale * radiusForNeighbourCount(points, *index, target_neighbours);
  const int need = wavejetNeededNeighbours(params);
  const int widen_to = wavejetWidenedNeighbours(params, target_neighbours);
  const int narrow_to = wavejetNarrowedNeighbours(params, target_neighbours);
  const std::int64_t count = static_cast<std::int64_t>(points.size());
  std::vector<WavejetResult> out(points.size());
  neighbour_count.assign(points.size(), 0);
  support.assign(points.size(), kBall);
  if (reach) reach->assign(points.size(), radius);
  if (coefficients) coefficients->assign(points.size(), WavejetCoefficients());
  ProgressReporter reporter(progress, "wavejets", points.size());
  const Eigen::Vector3f nan3 = Eigen::Vector3f::Constant(kNaN);
  // The grid (below) keys its cells on the lattice of multiples of the radius, so a tile
  // orders its points as the whole cloud does: the fits see their balls in the same order.
  CellGrid grid;
  const bool gridded = grid.build(points, radius, true);
  // Slot in the grid's copy of each point (for the kd-tree's answers in the grid's order).
  std::vector<int> slot_of;
  if (gridded && widen) {
    slot_of.assign(points.size(), -1);
    for (std::size_t s = 0; s < grid.original().size(); ++s) slot_of[grid.original()[s]] = static_cast<int>(s);
  }
  // The `n` nearest of q among the kd-tree's answer for `asked` (>= n) points, nearest first
  // with ties by index (by slot when `slots`: indices into the grid's copy), into idx; false
  // when the answer cannot be shown to hold every point tied with the n-th (the last point it
  // returned is within rounding of the n-th).
  auto nearestOfTree = [&](const Eigen::Vector3f& q, int n, int asked, bool slots, std::vector<int>& idx,
                           std::vector<int>& knn, std::vector<float>& kd2,
                           std::vector<std::pair<float, int>>& order) -> bool {
    const int got = index->nearestK(q, asked, knn, kd2);
    if (got < asked) return false;
    order.resize(got);
    for (int j = 0; j < got; ++j) order[j] = {(points[knn[j]] - q).squaredNorm(), slots ? slot_of[knn[j]] : knn[j]};
    std::sort(order.begin(), order.end());
    if (!(order[n - 1].first < (1.f - 1e-5f) * order[got - 1].first)) return false;
    idx.resize(n);
    for (int j = 0; j < n; ++j) idx[j] = order[j].second;
    return true;
  };
  // A ball with fewer than `widen_to` positions: the `widen_to` nearest instead (indices into
  // `points`, ties by index), at their radius (R_phi at the point = max(R_phi, distance of its
  // widen_to-th nearest)). Returns the radius to use, or 0 when not widened (the points hold
  // fewer than `need` finite positions: NaN outputs as before, or the ball is full after all).
  auto widenAt = [&](int i, std::vector<int>& idx, std::vector<int>& knn, std::vector<float>& kd2,
                     std::vector<std::pair<float, int>>& order) -> float {
    const Eigen::Vector3f& q = points[i];
    // One more than needed shows whether the cut falls between two distances.
    if (!nearestOfTree(q, widen_to, widen_to + 1, false, idx, knn, kd2, order)) {
      // Ties at the cut, or fewer points than asked: every point out to the farthest the
      // tree gave, then the same order and cut.
      const int got = index->nearestK(q, widen_to, knn, kd2);
      if (got < widen_to) {
        if (reach) (*reach)[i] = INFINITY;  // the whole cloud may hold more than these
        if (got < need) return 0.f;
      }
      float far2 = 0.f;
      for (int j = 0; j < got; ++j) far2 = std::max(far2, (points[knn[j]] - q).squaredNorm());
      index->radiusSearch(q, std::sqrt(far2) * (1.f + 1e-5f), knn, kd2);
      order.resize(knn.size());
      for (std::size_t j = 0; j < knn.size(); ++j) order[j] = {(points[knn[j]] - q).squaredNorm(), knn[j]};
      std::sort(order.begin(), order.end());
      const int n = std::min<int>(widen_to, static_cast<int>(order.size()));
      idx.resize(n);
      for (int j = 0; j < n; ++j) idx[j] = order[j].second;
    }
    const float r = std::sqrt((points[idx.back()] - q).squaredNorm());
    if (reach && std::isfinite((*reach)[i])) (*reach)[i] = std::max(radius, r);
    // A ball one short by the grid's float test but full by the kd-tree's (its last point on
    // the sphere): the ball itself, as it would be without widening.
    return r > radius ? r : 0.f;
  };
  // A ball with more than `narrow_to` positions (indices into pts in idx): keeps its
  // `narrow_to` nearest, ties broken by index, moved to the front of idx in that order, and
  // returns their radius (the distance of the farthest).
  auto narrowAt = [&](const Positions& pts, const Eigen::Vector3f& q, std::vector<int>& idx,
                      std::vector<std::pair<float, int>>& order) {
    const int found = static_cast<int>(idx.size());
    order.resize(found);
    for (int j = 0; j < found; ++j) order[j] = {(pts[idx[j]] - q).squaredNorm(), idx[j]};
    std::nth_element(order.begin(), order.begin() + (narrow_to - 1), order.end());
    std::sort(order.begin(), order.begin() + narrow_to);
    for (int j = 0; j < narrow_to; ++j) idx[j] = order[j].second;
    idx.resize(narrow_to);
    return std::sqrt(order[narrow_to - 1].first);
  };
  // Point i fitted on the neighbours nb (indices into pts: the points or the grid's copy).
  auto fitPoint = [&](int i, const Positions& pts, const int* nb, int found, float r, WavejetWorkspace& ws) {
    neighbour_count[i] = found;
    out[i] = fitWavejet(pts, nb, found, points[i], r, params, ws, initial_normals ? (*initial_normals)[i] : nan3,
                        orientation ? (*orientation)[i] : nan3, coefficients ? &(*coefficients)[i] : nullptr);
  };
  // Point i and its ball (indices into pts, any order) in idx: widened, narrowed or as it is.
  auto fitBall = [&](int i, const Positions& pts, std::vector<int>& idx, std::vector<int>& wide,
                     std::vector<int>& knn, std::vector<float>& kd2, std::vector<std::pair<float, int>>& order,
                     WavejetWorkspace& ws) {
    const int found = static_cast<int>(idx.size());
    const float r = widen && found < widen_to ? widenAt(i, wide, knn, kd2, order) : 0.f;
    if (r > 0) {
      support[i] = kWidened;
      fitPoint(i, points, wide.data(), static_cast<int>(wide.size()), r, ws);
    } else if (widen && found > narrow_to) {
      const float rn = narrowAt(pts, points[i], idx, order);
      support[i] = kNarrowed;
      fitPoint(i, pts, idx.data(), narrow_to, rn, ws);
    } else {
      fitPoint(i, pts, idx.data(), found, radius, ws);
    }
  };
  // Uniform grid of cells of side R_phi (the shared core one); falls back to the kd-tree when
  // the extent is too large for it.
  constexpr int kTreeExtra = 16;  // the kd-tree's extra answers for a crowded ball (below)
  if (gridded) {
    // Points visited in cell order and fitted on the grid's copy in that order (memory
    // locality; fitting on `points` cost 10-15%).
    const Positions& sorted = grid.sorted();
    const std::vector<int>& original = grid.original();
    const std::int64_t finite = static_cast<std::int64_t>(sorted.size());
#pragma omp parallel
    {
      WavejetWorkspacePtr ws = makeWavejetWorkspace();
      std::vector<int> idx, wide, knn;
      std::vector<float> kd2;
      std::vector<std::pair<float, int>> order;
      idx.reserve(256);
      CellGrid::Cursor cursor;
      bool dense = false;  // the last ball of this thread was far over narrow_to
#pragma omp for schedule(dynamic, 256)
      for (std::int64_t s = 0; s < finite; ++s) {
        if (reporter.cancelled()) continue;
        const int i = original[s];
        if (fit_only && !(*fit_only)[i]) {
          reporter.advance();
          continue;
        }
        // A ball far larger than `narrow_to` (a cluster much denser than the rest of the
        // cloud): its `narrow_to` nearest from the kd-tree, the same points in the same order
        // as narrowing the whole ball, whose gathering costs the ball's size (200K points,
        // half of them in a 1 cm cluster: 46 s, most of it there). Where the tree's answer
        // cannot be shown to be the same (ties, or the ball holds fewer), the ball is gathered.
        if (dense && nearestOfTree(points[i], narrow_to, narrow_to + kTreeExtra, true, idx, knn, kd2, order) &&
            order[narrow_to].first <= radius * radius) {
          support[i] = kNarrowed;
          fitPoint(i, sorted, idx.data(), narrow_to, std::sqrt(order[narrow_to - 1].first), *ws);
          reporter.advance();
          continue;
        }
        const int found = grid.query(sorted[s], radius, idx, cursor);
        // Points come in cell order: a ball four times over the cap is followed by others.
        dense = widen && found > 4 * narrow_to;
        fitBall(i, sorted, idx, wide, knn, kd2, order, *ws);
        reporter.advance();
      }
    }
    reporter.advance(static_cast<std::size_t>(count - finite));
  } else {
    if (!index) index = std::make_unique<SpatialIndex>(points);
#pragma omp parallel
    {
      WavejetWorkspacePtr ws = makeWavejetWorkspace();
      std::vector<int> idx, wide, knn;
      std::vector<float> d2, kd2;
      std::vector<std::pair<float, int>> order;
#pragma omp for schedule(dynamic, 256)
      for (std::int64_t i = 0; i < count; ++i) {
        if (reporter.cancelled()) continue;
        if (isFinite(points[i]) && (!fit_only || (*fit_only)[i])) {
          index->radiusSearch(points[i], radius, idx, d2);
          fitBall(static_cast<int>(i), points, idx, wide, knn, kd2, order, *ws);
        }
        reporter.advance();
      }
    }
  }
  reporter.throwIfCancelled();
  reporter.finish();
  return out;
}

// Where estimateDistinctInTiles writes: at the input index first[d] of distinct position d.
struct TiledOutputs {
  const std::vector<int>& first;
  std::vector<WavejetResult>& out;
  std::vector<int>& neighbour_count;
  std::vector<std::uint8_t>& support;
  std::vector<WavejetCoefficients>* coefficients;
};

struct TileCount {
  std::size_t tiles = 1, largest = 0, grown_halos = 0;
};

// estimateDistinct tile by tile (WavejetParameters::max_tile_points) on distinct positions
// in spatial order, with the radius and the widening resolved here on the whole cloud, so
// that each tile fits its core points as the whole cloud would. A tile holds its points in
// the cloud's relative order (estimateDistinct's canonical neighbour order), and its halo is
// grown and the tile run again where a fit reached past it (a widened ball in a sparse spot).
// `radius` is already chosen; `automatic` says whether it was chosen (not given), which
// decides the widening as in estimateDistinct.
TileCount estimateDistinctInTiles(const Positions& points, float radius, bool automatic, WavejetParameters run,
                                  const Normals* initial_normals, const Normals* orientation,
                                  const ProgressCallback& progress, int target_neighbours, TiledOutputs& to) {
  const bool widen = run.widening == WavejetParameters::Widening::always ||
                     (run.widening == WavejetParameters::Widening::automatic && automatic);
  run.widening = widen ? WavejetParameters::Widening::always : WavejetParameters::Widening::never;
  // Three radii: every ball, and most widened ones (rs1 sampled with 5M points at 0.25%
  // noise: 2% of the points reached past 2 radii, 0.2% past 3), without growing the halo.
  std::vector<Tile> tiles = splitIntoTiles(points, run.max_tile_points, 3 * radius);
  TileCount count;
  count.tiles = tiles.size();
  for (std::size_t t = 0; t < tiles.size(); ++t) {
    // First the whole tile; then, while some core points reached past the halo (a widened
    // ball in a sparse spot), those points alone, on a halo grown to what they reached.
    Tile part = std::move(tiles[t]);
    const ProgressCallback sub = tileProgress(progress, t, tiles.size());
    // A pass on a grown halo is its own stage (not the tile's bar starting again).
    const ProgressCallback grown =
        sub ? ProgressCallback([sub](const std::string& stage, float f) { return sub(stage + " (grown halo)", f); })
            : ProgressCallback();
    float margin = 3 * radius;
    for (bool first = true; !part.core.empty(); first = false) {
      std::vector<int> ids(part.core.size() + part.halo.size());
      std::merge(part.core.begin(), part.core.end(), part.halo.begin(), part.halo.end(), ids.begin());
      count.largest = std::max(count.largest, ids.size());
      std::vector<int> core_at;  // positions of the core points in ids
      core_at.reserve(part.core.size());
      for (std::size_t j = 0, c = 0; j < ids.size() && c < part.core.size(); ++j)
        if (ids[j] == part.core[c]) { core_at.push_back(static_cast<int>(j)); ++c; }
      std::vector<std::uint8_t> only(ids.size(), 0);  // the halo is only read
      for (const int j : core_at) only[j] = 1;
      Normals t_initial, t_orientation;
      if (initial_normals) t_initial = gathered(*initial_normals, ids);
      if (orientation) t_orientation = gathered(*orientation, ids);
      float r = radius;
      std::vector<int> t_count;
      std::vector<std::uint8_t> t_support;
      std::vector<float> reach;
      std::vector<WavejetCoefficients> t_coefficients;
      std::vector<WavejetResult> res =
          estimateDistinct(gathered(points, ids), r, run, to.coefficients ? &t_coefficients : nullptr,
                           initial_normals ? &t_initial : nullptr, orientation ? &t_orientation : nullptr,
                           first ? sub : grown,
                           target_neighbours, t_count, t_support, nullptr, 1.f, &reach, &only);
      // The halo box holds every point within `margin` of a core point (float rounding aside).
      std::vector<int> again;
      float needed = 0.f;
      for (std::size_t c = 0; c < core_at.size(); ++c) {
        const int j = core_at[c];
        if (!(reach[j] * (1.f + 1e-5f) <= margin)) {
          again.push_back(part.core[c]);
          needed = std::max(needed, reach[j]);
          continue;
        }
        const int i = to.first[part.core[c]];
        to.out[i] = res[j];
        to.neighbour_count[i] = t_count[j];
        to.support[i] = t_support[j];
        if (to.coefficients) (*to.coefficients)[i] = std::move(t_coefficients[j]);
      }
      if (!again.empty()) {
        // Doubled at most: the few points that reach farthest (a stray return) go on alone
        // with a wider halo, the many just past it stop at a narrow one.
        margin = std::min(2 * margin, std::isfinite(needed) ? needed * 1.001f : INFINITY);
        part.halo = tileHalo(points, again, margin);
        ++count.grown_halos;
      }
      part.core = std::move(again);
    }
  }
  return count;
}

}  // namespace

std::vector<WavejetResult> estimateWavejets(const Positions& points, float radius,
                                            const WavejetParameters& params, WavejetReport* report,
                                            std::vector<WavejetCoefficients>* coefficients,
                                            const Normals* initial_normals, const Normals* orientation,
                                            const ProgressCallback& progress, int target_neighbours) {
  params.validate();
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "0 (automatic) or a finite value > 0");
  requireInRange("target_neighbours", target_neighbours, 3, 100000);
  requireRadiusWithinExtent("radius", radius, points);
  if (initial_normals && initial_normals->size() != points.size())
    throw InvalidParameter("initial_normals", detail::toString(initial_normals->size()), "one per point");
  if (orientation && orientation->size() != points.size())
    throw InvalidParameter("orientation", detail::toString(orientation->size()), "one per point");
  if (countFinite(points) == 0) throw InvalidInput("no finite point");
  const bool target_was_automatic = radius == 0;
  // Exact duplicates: each position is fitted once and counted once as a neighbour (a copy
  // adds no geometry, only weight, and would fake the neighbour count that sets the order);
  // every copy then gets its position's output. The distinct positions are fitted in spatial
  // order: on a shuffled cloud the loops waited on memory, and the output no longer depends
  // on the order of the input.
  std::size_t duplicates = 0;
  const std::vector<int> rep = exactDuplicateRepresentatives(points, &duplicates);
  std::vector<int> slot(points.size(), -1);  // input index -> index among the distinct positions
  Positions distinct;
  Normals d_initial, d_orientation;
  distinct.reserve(points.size() - duplicates);
  for (const int i : spatialOrder(points))
    if (rep[i] == i) {
      slot[i] = static_cast<int>(distinct.size());
      distinct.push_back(points[i]);
      if (initial_normals) d_initial.push_back((*initial_normals)[i]);
      if (orientation) d_orientation.push_back((*orientation)[i]);
    }
  for (std::size_t i = 0; i < points.size(); ++i)
    if (rep[i] >= 0) slot[i] = slot[rep[i]];
  if (distinct.size() < 2) {
    const std::size_t finite = countFinite(points);
    throw InvalidInput(finite == 1 ? std::string("only one finite point: no surface to fit")
                                   : "all " + detail::toString(finite) + " finite points are at one position: no surface to fit");
  }
  const Positions& fitted = distinct;
  // Order policy (WavejetParameters::order_policy): automatic measures the noise with a
  // pilot of fixed-order fits and chooses (wavejet_noise.h); the index is shared with the run.
  const bool widens = params.widening == WavejetParameters::Widening::always ||
                      (params.widening == WavejetParameters::Widening::automatic && radius == 0);
  WavejetParameters run = params;
  float radius_scale = 1.f;
  std::unique_ptr<SpatialIndex> index;
  bool measured = false;
  WavejetNoise noise;
  float scale_ratio = NAN;
  if (params.order_policy == WavejetParameters::OrderPolicy::select) run.select_order = true;
  if (params.order_policy == WavejetParameters::OrderPolicy::automatic && !params.select_order) {
    index = std::make_unique<SpatialIndex>(fitted);
    try {
      const float r0 = radius > 0 ? radius : radiusForNeighbourCount(fitted, *index, target_neighbours);
      const int widen_to = wavejetWidenedNeighbours(params, target_neighbours);
      noise = wavejetResidualNoise(fitted, *index, r0, params, widen_to);
      measured = true;
      const bool may_grow = radius == 0 && params.adapt_support && wavejetSupportGrowth(noise.relative) > 1.f;
      if (may_grow) {
        // Noise or relief? The same pilot at twice the radius (four times the count).
        const WavejetNoise wide = wavejetResidualNoise(fitted, *index, 2 * r0, params, 4 * widen_to);
        scale_ratio = noise.sigma > 0 ? wide.sigma / noise.sigma : NAN;
      }
      const WavejetNoisePolicy policy = wavejetNoisePolicy(params, noise.relative, target_neighbours, may_grow,
                                                           std::isnan(scale_ratio) ? 1.f : scale_ratio);
      run = policy.params;
      // Beta 3 only where every ball is widened to the count it needs; with a fixed ball
      // it would turn the sparse points (7 to 17 neighbours) into NaN outputs.
      if (!widens) run.beta = params.beta;
      if (policy.neighbours > target_neighbours) {
        // The grown support: the radius of `target_neighbours` scaled by the square root of
        // the growth (x2), sparse balls still widened to the same count (growing that count
        // too would fit a sparse region on a patch 2x wider than its own spacing needs: the
        // enhancement test of a sphere with a dense cap lost its projection that way), the
        // cap of narrowing raised with the count.
        radius_scale = std::sqrt(float(policy.neighbours) / float(target_neighbours));
        if (params.narrowed_neighbours == 0)
          run.narrowed_neighbours = policy.neighbours / target_neighbours * wavejetNarrowedNeighbours(params, target_neighbours);
      }
    } catch (const InvalidInput&) {
      // Too few points for any fit: nothing to measure, the outputs are NaN either way.
      run.order_policy = WavejetParameters::OrderPolicy::fixed;
    }
  }
  const bool tiled = params.max_tile_points != 0 && fitted.size() > params.max_tile_points;
  const bool radius_chosen = radius == 0;
  if (tiled) {
    // The radius now, and the index of the whole cloud (the pilot's) released before the
    // outputs are allocated: the tiles search their own. Both were held at once at the
    // peak (`paps curvature` on rs1 sampled with 20M points: 4,639 -> 4,042 MB).
    if (radius_chosen) {
      if (!index) index = std::make_unique<SpatialIndex>(fitted);
      radius = radius_scale * radiusForNeighbourCount(fitted, *index, target_neighbours);
    }
    index.reset();
  }
  std::vector<WavejetResult> out(points.size());
  std::vector<int> neighbour_count(points.size(), 0);
  std::vector<std::uint8_t> support(points.size(), kBall);
  if (coefficients) coefficients->assign(points.size(), WavejetCoefficients());
  TileCount tiles;
  if (!tiled) {
    std::vector<int> d_count;
    std::vector<std::uint8_t> d_support;
    std::vector<WavejetCoefficients> d_coefficients;
    std::vector<WavejetResult> d_out =
        estimateDistinct(fitted, radius, run, coefficients ? &d_coefficients : nullptr,
                         initial_normals ? &d_initial : nullptr, orientation ? &d_orientation : nullptr, progress,
                         target_neighbours, d_count, d_support, std::move(index), radius_scale);
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (slot[i] < 0) continue;
      out[i] = d_out[slot[i]];
      neighbour_count[i] = d_count[slot[i]];
      support[i] = d_support[slot[i]];
      if (coefficients) (*coefficients)[i] = d_coefficients[slot[i]];
    }
  } else {
    // Outputs written at the input index of each position's first copy, then copied.
    std::vector<int> first(fitted.size());
    for (std::size_t i = 0; i < points.size(); ++i)
      if (rep[i] == static_cast<int>(i)) first[slot[i]] = static_cast<int>(i);
    std::vector<int>().swap(slot);
    TiledOutputs to{first, out, neighbour_count, support, coefficients};
    tiles = estimateDistinctInTiles(fitted, radius, radius_chosen, run, initial_normals ? &d_initial : nullptr,
                                    orientation ? &d_orientation : nullptr, progress, target_neighbours, to);
    for (std::size_t i = 0; i < points.size(); ++i) {
      const int r = rep[i];
      if (r < 0 || r == static_cast<int>(i)) continue;
      out[i] = out[r];
      neighbour_count[i] = neighbour_count[r];
      support[i] = support[r];
      if (coefficients) (*coefficients)[i] = (*coefficients)[r];
    }
  }
  if (report) {
    *report = WavejetReport();
    report->radius = radius;
    report->noise_measured = measured;
    report->noise_sigma = measured ? noise.sigma : NAN;
    report->noise_relative = measured ? noise.relative : NAN;
    report->noise_scale_ratio = scale_ratio;
    report->select_order = run.select_order;
    report->beta = run.beta;
    report->support_scale = target_was_automatic ? radius_scale : 1.f;
    report->duplicates = duplicates;
    report->tiles = tiles.tiles;
    report->largest_tile = tiles.largest;
    report->grown_halos = tiles.grown_halos;
    double sum = 0;
    std::vector<float> widened_radii, narrowed_radii;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (!isFinite(points[i])) { ++report->non_finite; continue; }
      if (!out[i].valid()) {
        ++(neighbour_count[i] >= run.beta * wavejetUnknowns(2) ? report->failed_fits : report->too_few_neighbours);
        continue;
      }
      ++report->fitted;
      sum += neighbour_count[i];
      report->lowered += out[i].order < params.order;
      report->not_converged += !out[i].converged && !out[i].tilt_within_noise;
      report->tilt_within_noise += out[i].tilt_within_noise;
      report->max_radius = std::max(report->max_radius, out[i].radius);
      if (support[i] == kWidened) { ++report->widened; widened_radii.push_back(out[i].radius); }
      if (support[i] == kNarrowed) { ++report->narrowed; narrowed_radii.push_back(out[i].radius); }
    }
    auto median = [](std::vector<float>& v) {
      if (v.empty()) return 0.f;
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      return v[v.size() / 2];
    };
    report->widened_radius_median = median(widened_radii);
    report->narrowed_radius_median = median(narrowed_radii);
    report->mean_neighbours = report->fitted ? sum / report->fitted : 0.0;
  }
  return out;
}

}  // namespace paps
