#include <paps/surface/transport_plan.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <numeric>
#include <string_view>
#include <unordered_map>

#include <CGAL/box_intersection_d.h>
#include <ClpSimplex.hpp>
#include <pcl/point_types.h>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>

namespace paps {

void TransportParameters::validate() const {
  if (!(bins_per_area > 0) || !std::isfinite(bins_per_area) || bins_per_area > 1e6)
    throw InvalidParameter("bins_per_area", detail::toString(bins_per_area), "in (0, 1e6]");
  requireInRange("max_bins_per_facet", max_bins_per_facet, 1, 256);
  if (!(tolerance >= 0) || !(tolerance < 1))
    throw InvalidParameter("tolerance", detail::toString(tolerance), "in [0, 1)");
  requireInRange("max_sweeps", max_sweeps, 0, 1000);
  requireInRange("bins_per_point", bins_per_point, 0, 100000);
}

namespace {

FacetBins lloydBins(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, int count) {
  FacetBins out;
  if (count <= 1) {
    out.barycentric.emplace_back(1.0 / 3, 1.0 / 3, 1.0 / 3);
    out.capacity.push_back(1.0);
    return out;
  }
  // Centres of the n^2 congruent sub-triangles of a regular subdivision: equal-area samples.
  const int n = std::max(8, static_cast<int>(std::ceil(std::sqrt(24.0 * count))));
  std::vector<Eigen::Vector3d> w;
  w.reserve(static_cast<std::size_t>(n) * n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; i + j < n; ++j) {
      w.emplace_back((i + 1.0 / 3) / n, (j + 1.0 / 3) / n, 0);  // upward triangle
      if (i + j + 1 < n) w.emplace_back((i + 2.0 / 3) / n, (j + 2.0 / 3) / n, 0);  // downward
    }
  for (auto& x : w) x[2] = 1 - x[0] - x[1];
  std::vector<Eigen::Vector3d> pos(w.size());
  for (std::size_t k = 0; k < w.size(); ++k) pos[k] = w[k][0] * a + w[k][1] * b + w[k][2] * c;
  // Start from equal-count cells (recursive bisection along the longest extent), then Lloyd:
  // seeds by farthest points put cells in the corners that Lloyd then left small.
  std::vector<int> owner(w.size(), 0);
  {
    std::vector<int> all(w.size());
    std::iota(all.begin(), all.end(), 0);
    int next_cell = 0;
    std::function<void(std::vector<int>, int)> split = [&](std::vector<int> ids, int k) {
      if (k == 1) {
        for (int i : ids) owner[i] = next_cell;
        ++next_cell;
        return;
      }
      Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
      for (int i : ids) { lo = lo.cwiseMin(pos[i]); hi = hi.cwiseMax(pos[i]); }
      int axis;
      (hi - lo).maxCoeff(&axis);
      std::stable_sort(ids.begin(), ids.end(), [&](int x, int y) { return pos[x][axis] < pos[y][axis]; });
      const int k1 = k / 2;
      const std::size_t n1 = (ids.size() * k1 + k / 2) / k;
      split(std::vector<int>(ids.begin(), ids.begin() + n1), k1);
      split(std::vector<int>(ids.begin() + n1, ids.end()), k - k1);
    };
    split(all, count);
  }
  std::vector<Eigen::Vector3d> centre_w(count, Eigen::Vector3d::Zero()), centre_p(count);
  std::vector<int> size(count, 0);
  for (std::size_t k = 0; k < w.size(); ++k) { centre_w[owner[k]] += w[k]; ++size[owner[k]]; }
  for (int s = 0; s < count; ++s) {
    centre_w[s] /= std::max(1, size[s]);
    centre_p[s] = centre_w[s][0] * a + centre_w[s][1] * b + centre_w[s][2] * c;
  }
  // Lloyd (the bisection start is already close). Hamerly's bounds skip the samples whose
  // nearest centre cannot have changed: `upper` bounds the distance to the owner, `lower` the
  // distance to every other centre; both follow the centres' moves. A sample is searched
  // (by brute force, lowest index on ties) only when the bounds cross, with a margin against
  // round-off, so the cells are those of plain Lloyd, at a fraction of the cost.
  std::vector<double> upper(w.size(), INFINITY), lower(w.size(), 0.0);
  std::vector<double> moved(count, 0.0);
  for (int it = 0; it < 30; ++it) {
    bool changed = false;
    double max_move = 0;
    for (int s = 0; s < count; ++s) max_move = std::max(max_move, moved[s]);
    for (std::size_t k = 0; k < w.size(); ++k) {
      upper[k] += moved[owner[k]];
      lower[k] -= max_move;
      if (upper[k] < lower[k] * (1 - 1e-9)) continue;
      int o = 0;
      double bd = (pos[k] - centre_p[0]).squaredNorm(), second = INFINITY;
      for (int s = 1; s < count; ++s) {
        const double dd = (pos[k] - centre_p[s]).squaredNorm();
        if (dd < bd) { second = bd; bd = dd; o = s; }
        else if (dd < second) second = dd;
      }
      upper[k] = std::sqrt(bd);
      lower[k] = std::sqrt(second);
      changed |= owner[k] != o;
      owner[k] = o;
    }
    if (!changed) break;
    std::vector<Eigen::Vector3d> sw(count, Eigen::Vector3d::Zero());
    std::fill(size.begin(), size.end(), 0);
    for (std::size_t k = 0; k < w.size(); ++k) { sw[owner[k]] += w[k]; ++size[owner[k]]; }
    for (int s = 0; s < count; ++s) {
      moved[s] = 0;
      if (size[s] > 0) {
        centre_w[s] = sw[s] / size[s];
        const Eigen::Vector3d p = centre_w[s][0] * a + centre_w[s][1] * b + centre_w[s][2] * c;
        moved[s] = (p - centre_p[s]).norm();
        centre_p[s] = p;
      }
    }
  }
  for (int s = 0; s < count; ++s)
    if (size[s] > 0) {
      out.barycentric.push_back(centre_w[s]);
      out.capacity.push_back(static_cast<double>(size[s]) / static_cast<double>(w.size()));
    }
  return out;
}

// A triangle's corners (bit for bit) and bin count: the key of a memoised tessellation.
struct BinsKey {
  std::array<std::uint64_t, 9> bits;
  int count;
  bool operator==(const BinsKey& o) const { return count == o.count && bits == o.bits; }
};
struct BinsKeyHash {
  std::size_t operator()(const BinsKey& k) const {
    const std::string_view corners(reinterpret_cast<const char*>(k.bits.data()), sizeof(k.bits));
    return std::hash<std::string_view>{}(corners) ^ static_cast<std::size_t>(k.count);
  }
};

}  // namespace

FacetBins centroidalBins(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                         int count) {
  if (count <= 1) return lloydBins(a, b, c, count);
  // Memoised per thread: the decimation prepares the same new facets again and again (a
  // candidate collapse drawn at several steps, two collapses making one triangle), and the
  // Lloyd iterations were 12% of a reconstruction. The result is a function of the corners and
  // the count only, so a hit returns exactly what a new tessellation would; a full memo is
  // simply emptied.
  constexpr std::size_t kMemoSize = 8192;
  thread_local std::unordered_map<BinsKey, FacetBins, BinsKeyHash> memo;
  BinsKey key;
  key.count = count;
  for (int k = 0; k < 3; ++k) {
    std::memcpy(&key.bits[k], &a[k], sizeof(double));
    std::memcpy(&key.bits[3 + k], &b[k], sizeof(double));
    std::memcpy(&key.bits[6 + k], &c[k], sizeof(double));
  }
  if (const auto hit = memo.find(key); hit != memo.end()) return hit->second;
  FacetBins out = lloydBins(a, b, c, count);
  if (memo.size() >= kMemoSize) memo.clear();
  memo.emplace(key, out);
  return out;
}

namespace {

// The bins of a local problem: (target, bin) pairs; facet bins get a row each (after the
// points' rows), vertex bins none.
struct LocalBin {
  int target, bin, row;
  Eigen::Vector3d at;
};

std::vector<LocalBin> localBins(const std::vector<TransportTarget>& targets, int first_row, int& rows) {
  std::vector<LocalBin> bins;
  rows = first_row;
  for (int t = 0; t < static_cast<int>(targets.size()); ++t)
    for (int b = 0; b < targets[t].binCount(); ++b)
      bins.push_back({t, b, targets[t].isFacet() ? rows++ : -1, targets[t].bin(b)});
  return bins;
}

// Each point's candidate bins (squared distance, bin), in bin order: all, or its nearest
// `bins_per_point` plus its nearest vertex bin (vertex bins take any mass, so the problem
// stays feasible). One scratch list for all points: a list per point cost more in
// allocations than the selection itself.
std::vector<std::vector<std::pair<double, int>>> candidateBins(const std::vector<Eigen::Vector3d>& points,
                                                               const std::vector<LocalBin>& bins, int bins_per_point) {
  const int np = static_cast<int>(points.size()), nb = static_cast<int>(bins.size());
  std::vector<std::vector<std::pair<double, int>>> cand(np);
  std::vector<std::pair<double, int>> all;
  all.reserve(nb);
  for (int i = 0; i < np; ++i) {
    all.clear();
    for (int k = 0; k < nb; ++k) all.emplace_back((points[i] - bins[k].at).squaredNorm(), k);
    auto& c = cand[i];
    if (bins_per_point > 0 && bins_per_point < nb) {
      std::pair<double, int> vertex{INFINITY, -1};
      for (const auto& x : all)
        if (bins[x.second].row < 0 && x < vertex) vertex = x;
      std::nth_element(all.begin(), all.begin() + (bins_per_point - 1), all.end());
      c.assign(all.begin(), all.begin() + bins_per_point);
      if (vertex.second >= 0 && std::find(c.begin(), c.end(), vertex) == c.end())
        *std::max_element(c.begin(), c.end()) = vertex;  // in place of the farthest kept
      std::sort(c.begin(), c.end(), [](const auto& x, const auto& y) { return x.second < y.second; });
    } else {
      c = all;
    }
  }
  return cand;
}

}  // namespace

LocalTransport solveLocalTransport(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& mass,
                                   const std::vector<TransportTarget>& targets, int bins_per_point) {
  LocalTransport out;
  const int np = static_cast<int>(points.size());
  out.entries.resize(np);
  if (np == 0) { out.solved = true; return out; }
  if (targets.empty()) return out;
  int rows = 0;
  const std::vector<LocalBin> bins = localBins(targets, np, rows);
  const int nb = static_cast<int>(bins.size());
  const auto cand = candidateBins(points, bins, bins_per_point);
  double dmax = 0;
  for (const auto& c : cand)
    for (const auto& x : c) dmax = std::max(dmax, x.first);
  // Scaling: costs to [0, 1], masses to sum 1 (Clp's tolerances are absolute).
  double total = 0;
  for (double m : mass) total += m;
  const double cscale = dmax > 0 ? 1 / dmax : 1;
  // Columns: m_ik for every point and candidate bin, then l_t for every facet target.
  std::vector<int> first(np + 1, 0);
  for (int i = 0; i < np; ++i) first[i + 1] = first[i] + static_cast<int>(cand[i].size());
  const int nm = first[np];
  int facet_targets = 0;
  std::vector<int> l_col(targets.size(), -1);
  for (std::size_t t = 0; t < targets.size(); ++t)
    if (targets[t].isFacet()) l_col[t] = nm + facet_targets++;
  const int ncols = nm + facet_targets;
  std::vector<CoinBigIndex> start;
  std::vector<int> index;
  std::vector<double> value, obj(ncols, 0.0), collb(ncols, 0.0), colub(ncols, COIN_DBL_MAX);
  start.reserve(ncols + 1);
  index.reserve(static_cast<std::size_t>(nm) * 2 + nb);
  value.reserve(index.capacity());
  for (int i = 0; i < np; ++i)
    for (std::size_t c = 0; c < cand[i].size(); ++c) {
      const int k = cand[i][c].second;
      start.push_back(static_cast<CoinBigIndex>(index.size()));
      index.push_back(i);
      value.push_back(1.0);
      if (bins[k].row >= 0) { index.push_back(bins[k].row); value.push_back(1.0); }
      obj[first[i] + c] = cand[i][c].first * cscale;
    }
  for (std::size_t t = 0; t < targets.size(); ++t) {
    if (l_col[t] < 0) continue;
    start.push_back(static_cast<CoinBigIndex>(index.size()));
    for (int k = 0; k < nb; ++k)
      if (bins[k].target == static_cast<int>(t)) {
        index.push_back(bins[k].row);
        value.push_back(-targets[t].bins->capacity[bins[k].bin]);
      }
  }
  start.push_back(static_cast<CoinBigIndex>(index.size()));
  std::vector<double> rowlb(rows, 0.0), rowub(rows, 0.0);
  for (int i = 0; i < np; ++i) rowlb[i] = rowub[i] = mass[i] / total;
  // One model per thread, reloaded for every problem: building a ClpSimplex (its message
  // tables) cost as much as solving these small programs.
  static thread_local ClpSimplex model;
  model.setLogLevel(0);
  model.loadProblem(ncols, rows, start.data(), index.data(), value.data(), collb.data(), colub.data(), obj.data(),
                    rowlb.data(), rowub.data());
  model.scaling(0);  // the problem is scaled above
  // No random perturbation: the same problem gives the same plan, whatever was solved before
  // in the process (two reconstructions in one process differed without this).
  model.setPerturbation(50);
  model.setRandomSeed(1234567);
  model.allSlackBasis(true);
  // Crash basis: every point row made feasible by its cheapest column. The duals y_i = that
  // cost, 0 on the facet bins, price every column at >= 0, so the basis is dual feasible and
  // the dual simplex only has to fix the facet bins' rows (not one pivot per point first):
  // 2.5x-8x fewer iterations, 1.09x-1.41x less time on the same programs (docs/transport.md).
  for (int i = 0; i < np; ++i) {
    int best = first[i];
    for (int c = first[i] + 1; c < first[i + 1]; ++c)
      if (obj[c] < obj[best]) best = c;
    model.setColumnStatus(best, ClpSimplex::basic);
    model.setRowStatus(i, ClpSimplex::atLowerBound);
  }
  model.dual();
  if (!model.isProvenOptimal()) {
    model.primal();
    if (!model.isProvenOptimal()) return out;
  }
  const double* x = model.primalColumnSolution();
  out.cost = 0;
  for (int i = 0; i < np; ++i) {
    // Round-off: drop crumbs, renormalise so every point sends exactly its mass.
    double sum = 0;
    for (int c = first[i]; c < first[i + 1]; ++c)
      if (x[c] > 1e-12) sum += x[c];
    if (!(sum > 0)) return LocalTransport{false, 0, std::vector<std::vector<TransportEntry>>(np)};
    for (int c = first[i]; c < first[i + 1]; ++c) {
      if (x[c] <= 1e-12) continue;
      const auto& [d2, k] = cand[i][c - first[i]];
      const double m = x[c] / sum * mass[i];
      out.entries[i].push_back({bins[k].target, bins[k].bin, m});
      out.cost += m * d2;
    }
  }
  out.solved = true;
  return out;
}

double nearestBinCost(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& mass,
                      const std::vector<TransportTarget>& targets) {
  std::vector<Eigen::Vector3d> bins;
  for (const auto& t : targets)
    for (int b = 0; b < t.binCount(); ++b) bins.push_back(t.bin(b));
  double cost = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    double d2 = INFINITY;
    for (const auto& b : bins) d2 = std::min(d2, (points[i] - b).squaredNorm());
    cost += mass[i] * d2;
  }
  return cost;
}

double dualLowerBound(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& mass,
                      const std::vector<TransportTarget>& targets, int bins_per_point, double goal, int iterations) {
  const int np = static_cast<int>(points.size());
  if (np == 0 || targets.empty()) return 0;
  int rows = 0;
  const std::vector<LocalBin> bins = localBins(targets, 0, rows);
  const auto cand = candidateBins(points, bins, bins_per_point);
  // Weak duality: for prices y on the facet bins (0 on vertex bins) with sum_b c_b y_b <= 0 on
  // every facet, F(y) = sum_i m_i min over i's candidates k of (d_ik + y_k) is at most the
  // program's cost. y = 0 is nearestBinCost over the candidates. Projected subgradient ascent
  // (the subgradient is each bin's load; the projection keeps sum_b c_b y_b = 0 per facet),
  // with Polyak's step towards `goal`; the best F met is returned, so any step is safe.
  std::vector<double> y(bins.size(), 0.0), load(bins.size());
  std::vector<int> first_bin(targets.size() + 1, 0);
  for (std::size_t k = 0; k < bins.size(); ++k) first_bin[bins[k].target + 1] = static_cast<int>(k) + 1;
  for (std::size_t t = 0; t < targets.size(); ++t) first_bin[t + 1] = std::max(first_bin[t + 1], first_bin[t]);
  // Each facet's sum_b c_b^2, for the projections onto sum_b c_b y_b = 0.
  std::vector<double> cc(targets.size(), 0.0);
  for (std::size_t t = 0; t < targets.size(); ++t)
    if (targets[t].isFacet())
      for (int k = first_bin[t]; k < first_bin[t + 1]; ++k) {
        const double c = targets[t].bins->capacity[bins[k].bin];
        cc[t] += c * c;
      }
  // Prices beyond the largest candidate distance change no point's choice for the better; a
  // longer step only makes the rounding of sum_b c_b y_b matter, so steps are capped there.
  double dmax = 0;
  for (const auto& c : cand)
    for (const auto& x : c) dmax = std::max(dmax, x.first);
  double best = -INFINITY, lambda = 1;
  int stalled = 0;
  for (int it = 0; it <= iterations; ++it) {
    double f = 0;
    std::fill(load.begin(), load.end(), 0.0);
    for (int i = 0; i < np; ++i) {
      double low = INFINITY;
      int arg = -1;
      for (const auto& [d2, k] : cand[i])
        if (d2 + y[k] < low) { low = d2 + y[k]; arg = k; }
      if (arg < 0) return best;  // not finite (cannot happen with the caps below)
      f += mass[i] * low;
      load[arg] += mass[i];
    }
    if (f > best) {
      best = f;
      stalled = 0;
    } else if (++stalled == 3) {  // the steps overshoot: shorter ones
      lambda *= 0.5;
      stalled = 0;
    }
    if (best >= goal || it == iterations) break;
    // The ascent direction: the loads, minus their c-weighted share on each facet.
    double norm2 = 0;
    for (std::size_t t = 0; t < targets.size(); ++t) {
      if (!targets[t].isFacet()) {
        for (int k = first_bin[t]; k < first_bin[t + 1]; ++k) load[k] = 0;
        continue;
      }
      const auto& cap = targets[t].bins->capacity;
      double cg = 0;
      for (int k = first_bin[t]; k < first_bin[t + 1]; ++k) cg += cap[bins[k].bin] * load[k];
      for (int k = first_bin[t]; k < first_bin[t + 1]; ++k) {
        load[k] -= cap[bins[k].bin] * cg / cc[t];
        norm2 += load[k] * load[k];
      }
    }
    if (!(norm2 > 0)) break;  // the loads already follow the capacities: F is at its maximum
    double step = lambda * (goal - f) / norm2, move = 0;
    for (double g : load) move = std::max(move, std::abs(g));
    if (!std::isfinite(step) || step * move > dmax) step = dmax / move;
    for (std::size_t k = 0; k < bins.size(); ++k) y[k] += step * load[k];
    // Back onto each facet's plane sum_b c_b y_b = 0 (against the rounding of the steps), then
    // a rounding's worth below it: the prices must keep sum_b c_b y_b <= 0 to bound the program.
    for (std::size_t t = 0; t < targets.size(); ++t) {
      if (!targets[t].isFacet()) continue;
      const auto& cap = targets[t].bins->capacity;
      double cy = 0, ymax = 0;
      for (int k = first_bin[t]; k < first_bin[t + 1]; ++k) {
        cy += cap[bins[k].bin] * y[k];
        ymax = std::max(ymax, std::abs(y[k]));
      }
      const double shift = cy / cc[t];
      for (int k = first_bin[t]; k < first_bin[t + 1]; ++k) y[k] -= cap[bins[k].bin] * shift + 1e-12 * ymax;
    }
  }
  return best;
}

// ---------------------------------------------------------------- TransportPlan

TransportPlan::TransportPlan(std::vector<Eigen::Vector3d> points, std::vector<double> masses,
                             const TransportParameters& params)
    : params_(params), points_(std::move(points)), masses_(std::move(masses)) {
  params_.validate();
  if (points_.empty()) throw InvalidInput("optimal transport: the point set is empty");
  if (masses_.empty()) masses_.assign(points_.size(), 1.0);
  if (masses_.size() != points_.size())
    throw InvalidInput("optimal transport: " + std::to_string(masses_.size()) + " masses for " +
                       std::to_string(points_.size()) + " points");
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  for (std::size_t i = 0; i < points_.size(); ++i) {
    if (!points_[i].allFinite()) throw InvalidInput("optimal transport: point " + std::to_string(i) + " is not finite");
    if (!(masses_[i] > 0) || !std::isfinite(masses_[i]))
      throw InvalidInput("optimal transport: mass of point " + std::to_string(i) + " is not > 0");
    lo = lo.cwiseMin(points_[i]);
    hi = hi.cwiseMax(points_[i]);
    total_mass_ += masses_[i];
  }
  const double side = (hi - lo).maxCoeff();
  if (!(side > 0)) throw InvalidInput("optimal transport: all points coincide");
  bin_scale2_ = (0.5 / side) * (0.5 / side);
}

int TransportPlan::addVertex(const Eigen::Vector3d& p) {
  vertices_.push_back(p);
  vertex_alive_.push_back(1);
  vertex_facets_.emplace_back();
  vertex_shares_.emplace_back();
  return static_cast<int>(vertices_.size()) - 1;
}

int TransportPlan::binCountFor(double area) const {
  const double n = std::round(params_.bins_per_area * area * bin_scale2_);
  return static_cast<int>(std::clamp(n, 1.0, static_cast<double>(params_.max_bins_per_facet)));
}

int TransportPlan::addFacet(int a, int b, int c) {
  return addFacet(a, b, c, centroidalBins(vertices_[a], vertices_[b], vertices_[c], binCountFor(triangleArea(vertices_[a], vertices_[b], vertices_[c]))));
}

int TransportPlan::addFacet(int a, int b, int c, FacetBins bins) {
  const int f = static_cast<int>(facets_.size());
  facets_.push_back({a, b, c});
  facet_alive_.push_back(1);
  bins_.push_back(std::move(bins));
  facet_shares_.emplace_back();
  for (int v : {a, b, c}) vertex_facets_[v].push_back(f);
  return f;
}

void TransportPlan::removeFacet(int f) {
  if (!facet_alive_[f]) return;
  facet_alive_[f] = 0;
  for (int v : facets_[f]) {
    auto& l = vertex_facets_[v];
    l.erase(std::remove(l.begin(), l.end(), f), l.end());
  }
  std::vector<Share>().swap(facet_shares_[f]);
}

void TransportPlan::removeVertex(int v) {
  if (!vertex_alive_[v]) return;
  for (int f : std::vector<int>(vertex_facets_[v])) removeFacet(f);
  vertex_alive_[v] = 0;
  std::vector<Share>().swap(vertex_shares_[v]);
}

int TransportPlan::aliveVertexCount() const {
  return static_cast<int>(std::count(vertex_alive_.begin(), vertex_alive_.end(), 1));
}
int TransportPlan::aliveFacetCount() const {
  return static_cast<int>(std::count(facet_alive_.begin(), facet_alive_.end(), 1));
}

double TransportPlan::facetArea(int f) const {
  const auto& t = facets_[f];
  return triangleArea(vertices_[t[0]], vertices_[t[1]], vertices_[t[2]]);
}

void TransportPlan::assignToNearestVertices() {
  std::vector<int> alive;
  Positions alive_positions;
  for (int v = 0; v < vertexCount(); ++v)
    if (vertex_alive_[v]) {
      alive.push_back(v);
      alive_positions.push_back(vertices_[v].cast<float>());
    }
  if (alive.empty()) throw InvalidInput("optimal transport: the complex has no vertex");
  for (auto& l : vertex_shares_) l.clear();
  for (auto& l : facet_shares_) l.clear();
  const SpatialIndex tree(alive_positions);
  if (tree.size() == 0) throw InvalidInput("optimal transport: the complex has no finite vertex");
  std::vector<int> k;
  std::vector<float> d;
  for (std::size_t i = 0; i < points_.size(); ++i) {
    tree.nearestK(points_[i].cast<float>(), 1, k, d);
    vertex_shares_[alive[k[0]]].push_back({static_cast<int>(i), -1, masses_[i]});
  }
}

std::vector<double> TransportPlan::massSent() const {
  std::vector<double> m(points_.size(), 0.0);
  for (const auto& l : vertex_shares_)
    for (const auto& x : l) m[x.point] += x.mass;
  for (const auto& l : facet_shares_)
    for (const auto& x : l) m[x.point] += x.mass;
  return m;
}

double TransportPlan::massOnFacet(int f) const {
  double m = 0;
  for (const auto& x : facet_shares_[f]) m += x.mass;
  return m;
}

double TransportPlan::meanFacetDensity() const {
  double mass = 0, area = 0;
  for (int f = 0; f < facetCount(); ++f)
    if (facet_alive_[f]) { mass += massOnFacet(f); area += facetArea(f); }
  return area > 0 ? mass / area : 0;
}

namespace {
Eigen::Vector3d binPosition(const std::vector<Eigen::Vector3d>& vertices, const std::array<int, 3>& f,
                            const FacetBins& bins, int b) {
  const Eigen::Vector3d& w = bins.barycentric[b];
  return w[0] * vertices[f[0]] + w[1] * vertices[f[1]] + w[2] * vertices[f[2]];
}
}  // namespace

double TransportPlan::cost() const {
  double c = 0;
  for (int v = 0; v < vertexCount(); ++v)
    for (const auto& x : vertex_shares_[v]) c += x.mass * (points_[x.point] - vertices_[v]).squaredNorm();
  for (int f = 0; f < facetCount(); ++f)
    for (const auto& x : facet_shares_[f])
      c += x.mass * (points_[x.point] - binPosition(vertices_, facets_[f], bins_[f], x.bin)).squaredNorm();
  return c;
}

TransportPlan::Stencil TransportPlan::gather(std::vector<int> vertices, std::vector<int> facets) const {
  Stencil s;
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  std::sort(facets.begin(), facets.end());
  facets.erase(std::unique(facets.begin(), facets.end()), facets.end());
  s.vertices = std::move(vertices);
  s.facets = std::move(facets);
  // The distinct points in index order, and each one's slot, through per-thread arrays over
  // the points stamped by call (a point sends mass to several bins: sorting and searching
  // every share was 7% of a reconstruction).
  thread_local std::vector<std::uint32_t> stamp;
  thread_local std::vector<int> slot_of;
  thread_local std::uint32_t call = 0;
  if (stamp.size() < points_.size()) {
    stamp.resize(points_.size(), 0);
    slot_of.resize(points_.size());
  }
  if (++call == 0) {  // wrapped: no stale stamp may equal the new one
    std::fill(stamp.begin(), stamp.end(), 0);
    call = 1;
  }
  const auto note = [&](int i) {
    if (stamp[i] != call) {
      stamp[i] = call;
      s.points.push_back(i);
    }
  };
  for (int v : s.vertices)
    for (const auto& x : vertex_shares_[v]) note(x.point);
  for (int f : s.facets)
    for (const auto& x : facet_shares_[f]) note(x.point);
  std::sort(s.points.begin(), s.points.end());
  for (std::size_t k = 0; k < s.points.size(); ++k) slot_of[s.points[k]] = static_cast<int>(k);
  s.mass.assign(s.points.size(), 0.0);
  const auto slot = [&](int i) { return slot_of[i]; };
  for (int v : s.vertices)
    for (const auto& x : vertex_shares_[v]) {
      s.mass[slot(x.point)] += x.mass;
      s.cost += x.mass * (points_[x.point] - vertices_[v]).squaredNorm();
    }
  for (int f : s.facets)
    for (const auto& x : facet_shares_[f]) {
      s.mass[slot(x.point)] += x.mass;
      s.cost += x.mass * (points_[x.point] - binPosition(vertices_, facets_[f], bins_[f], x.bin)).squaredNorm();
    }
  return s;
}

std::vector<TransportTarget> TransportPlan::targetsOf(const Stencil& s) const {
  std::vector<TransportTarget> t;
  t.reserve(s.vertices.size() + s.facets.size());
  for (int v : s.vertices) t.push_back({{vertices_[v], vertices_[v], vertices_[v]}, nullptr});
  for (int f : s.facets) {
    const auto& x = facets_[f];
    t.push_back({{vertices_[x[0]], vertices_[x[1]], vertices_[x[2]]}, &bins_[f]});
  }
  return t;
}

void TransportPlan::release(const Stencil& s) {
  for (int v : s.vertices) vertex_shares_[v].clear();
  for (int f : s.facets) facet_shares_[f].clear();
}

void TransportPlan::assign(const Stencil& s, const std::vector<int>& vertices, const std::vector<int>& facets,
                          const LocalTransport& solution) {
  const int nv = static_cast<int>(vertices.size());
  for (std::size_t k = 0; k < s.points.size(); ++k)
    for (const auto& e : solution.entries[k]) {
      if (e.target < nv) vertex_shares_[vertices[e.target]].push_back({s.points[k], -1, e.mass});
      else facet_shares_[facets[e.target - nv]].push_back({s.points[k], e.bin, e.mass});
    }
}

void TransportPlan::apply(const Stencil& s, const LocalTransport& solution) {
  release(s);
  assign(s, s.vertices, s.facets, solution);
}

std::vector<Eigen::Vector3d> TransportPlan::positionsOf(const Stencil& s) const {
  std::vector<Eigen::Vector3d> pts(s.points.size());
  for (std::size_t k = 0; k < pts.size(); ++k) pts[k] = points_[s.points[k]];
  return pts;
}

double TransportPlan::improve(const Stencil& s) {
  if (s.points.empty()) return 0;
  // Most stencils already send every point to its nearest bin: no program can lower that
  // (nearestBinCost), so none is solved. The margin leaves out gains of round-off size only.
  const std::vector<Eigen::Vector3d> pts = positionsOf(s);
  const std::vector<TransportTarget> targets = targetsOf(s);
  if (nearestBinCost(pts, s.mass, targets) >= s.cost * (1 - 1e-12)) return 0;
  const LocalTransport sol = solveLocalTransport(pts, s.mass, targets, params_.bins_per_point);
  if (!sol.solved || !(sol.cost < s.cost)) return 0;
  apply(s, sol);
  return s.cost - sol.cost;
}

void TransportPlan::facetStencilSimplices(int f, std::vector<int>& vs, std::vector<int>& fs) const {
  fs.assign(1, f);
  vs.clear();
  const auto& t = facets_[f];
  for (int e = 0; e < 3; ++e) {
    const int a = t[e], b = t[(e + 1) % 3];
    for (int g : vertex_facets_[a]) {
      const auto& u = facets_[g];
      if (g != f && std::find(u.begin(), u.end(), b) != u.end()) fs.push_back(g);
    }
  }
  for (int g : fs) vs.insert(vs.end(), facets_[g].begin(), facets_[g].end());
}

void TransportPlan::vertexStencilSimplices(int v, std::vector<int>& vs, std::vector<int>& fs) const {
  fs = vertex_facets_[v];
  vs.assign(1, v);
  for (int g : fs) vs.insert(vs.end(), facets_[g].begin(), facets_[g].end());
}

TransportPlan::Stencil TransportPlan::facetStencil(int f) const {
  std::vector<int> vs, fs;
  facetStencilSimplices(f, vs, fs);
  return gather(std::move(vs), std::move(fs));
}

TransportPlan::Stencil TransportPlan::vertexStencil(int v) const {
  std::vector<int> vs, fs;
  vertexStencilSimplices(v, vs, fs);
  return gather(std::move(vs), std::move(fs));
}

void TransportPlan::forEachIndependent(const std::vector<int>& items,
                                       const std::function<void(int, std::vector<int>&, std::vector<int>&)>& simplices,
                                       const std::function<void(int)>& work) {
  // Each item's stencil, listed once (the rounds below read it again and again: the stencils
  // of a Delaunay complex overlap, so a sweep takes many rounds). Facets are stored as
  // -1 - f after the vertices.
  std::vector<std::size_t> first(items.size() + 1, 0);
  std::vector<int> ids, vs, fs;
  for (std::size_t k = 0; k < items.size(); ++k) {
    simplices(items[k], vs, fs);
    ids.insert(ids.end(), vs.begin(), vs.end());
    for (int f : fs) ids.push_back(-1 - f);
    first[k + 1] = ids.size();
  }
  // Greedy rounds: an item joins the round unless one of its simplices is already taken in it.
  std::vector<int> vertex_round(vertices_.size(), -1), facet_round(facets_.size(), -1);
  std::vector<int> remaining(items.size()), next, round;
  std::iota(remaining.begin(), remaining.end(), 0);
  for (int r = 0; !remaining.empty(); ++r) {
    next.clear();
    round.clear();
    for (int k : remaining) {
      bool free = true;
      for (std::size_t i = first[k]; free && i < first[k + 1]; ++i)
        free = ids[i] >= 0 ? vertex_round[ids[i]] != r : facet_round[-1 - ids[i]] != r;
      if (!free) { next.push_back(k); continue; }
      for (std::size_t i = first[k]; i < first[k + 1]; ++i)
        (ids[i] >= 0 ? vertex_round[ids[i]] : facet_round[-1 - ids[i]]) = r;
      round.push_back(items[k]);
    }
    // One item at a time: a round holds tens of items, each a linear program.
    const std::int64_t n = static_cast<std::int64_t>(round.size());
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t k = 0; k < n; ++k) work(round[k]);
    std::swap(remaining, next);
  }
}

int TransportPlan::relax(const ProgressCallback& progress) {
  std::vector<int> alive;
  for (int f = 0; f < facetCount(); ++f)
    if (facet_alive_[f]) alive.push_back(f);
  std::vector<double> gain(facets_.size(), 0.0);
  ProgressReporter rep(progress, "transport relaxation", static_cast<std::size_t>(std::max(1, params_.max_sweeps)));
  int sweeps = 0;
  double c = cost();
  for (; sweeps < params_.max_sweeps; ++sweeps) {
    forEachIndependent(
        alive, [&](int f, std::vector<int>& vs, std::vector<int>& fs) { facetStencilSimplices(f, vs, fs); },
        [&](int f) { gain[f] = improve(facetStencil(f)); });
    rep.advance();
    rep.throwIfCancelled();
    double total = 0;
    for (int f : alive) total += gain[f];  // in facet order: the same sum whatever the threads
    if (!(total > params_.tolerance * c)) { ++sweeps; break; }
    c -= total;
  }
  rep.finish();
  return sweeps;
}

bool TransportPlan::turnsAFacet(int v, const Eigen::Vector3d& to, int except) const {
  for (int f : vertex_facets_[v]) {
    const auto& t = facets_[f];
    if (std::find(t.begin(), t.end(), except) != t.end()) continue;
    const int slot = t[0] == v ? 0 : t[1] == v ? 1 : 2;
    const Eigen::Vector3d &a = vertices_[t[(slot + 1) % 3]], &b = vertices_[t[(slot + 2) % 3]];
    if ((a - vertices_[v]).cross(b - vertices_[v]).dot((a - to).cross(b - to)) < 0) return true;
  }
  return false;
}

double TransportPlan::relocate(int v) {
  // The position that minimises the cost of the current plan (5.2.4): the cost is quadratic in
  // v, sum m_ij |p_i - a_j v - (rest of b_j)|^2 over the bins of v and of its facets (a_j = 1
  // on v's own bin), so v* = sum m a (p - rest) / sum m a^2. (The manuscript averages one
  // optimum per simplex, weighted by mass; a facet whose mass sits near its other corners
  // then extrapolates v far off, a_j being small, and pushed vertices past the cube's faces.)
  Eigen::Vector3d num = Eigen::Vector3d::Zero(), vnum = Eigen::Vector3d::Zero();
  double weight = 0, vweight = 0;
  for (const auto& x : vertex_shares_[v]) { vnum += x.mass * points_[x.point]; vweight += x.mass; }
  for (int f : vertex_facets_[v]) {
    const auto& t = facets_[f];
    const int slot = t[0] == v ? 0 : t[1] == v ? 1 : 2;
    for (const auto& x : facet_shares_[f]) {
      const Eigen::Vector3d& w = bins_[f].barycentric[x.bin];
      Eigen::Vector3d rest = points_[x.point];
      for (int c = 0; c < 3; ++c)
        if (c != slot) rest -= w[c] * vertices_[t[c]];
      num += x.mass * w[slot] * rest;
      weight += x.mass * w[slot] * w[slot];
    }
  }
  num += vnum;
  weight += vweight;
  if (!(weight > 0)) return 0;
  const Eigen::Vector3d target = num / weight;
  Eigen::Vector3d moved = 0.5 * (vertices_[v] + target);
  if (params_.refuse_flips) {
    // A move that turns a facet of v over folds the sheet: the step is halved until none
    // turns (at most 4 times), else v stays.
    for (int halvings = 0; halvings < 4 && turnsAFacet(v, moved); ++halvings) moved = 0.5 * (vertices_[v] + moved);
    if (turnsAFacet(v, moved)) moved = vertices_[v];
  }
  const double dist = (moved - vertices_[v]).norm();
  vertices_[v] = moved;
  improve(vertexStencil(v));
  return dist;
}

double TransportPlan::relocateAll() {
  std::vector<int> alive;
  for (int v = 0; v < vertexCount(); ++v)
    if (vertex_alive_[v]) alive.push_back(v);
  if (alive.empty()) return 0;
  // A relocation reads v's ring and re-solves v's stencil: rounds of vertices whose stencils
  // share no simplex run in parallel.
  std::vector<double> moved(vertices_.size(), 0.0);
  forEachIndependent(
      alive, [&](int v, std::vector<int>& vs, std::vector<int>& fs) { vertexStencilSimplices(v, vs, fs); },
      [&](int v) { moved[v] = relocate(v); });
  double sum2 = 0;
  for (int v : alive) sum2 += moved[v] * moved[v];
  return std::sqrt(sum2 / alive.size());
}

bool TransportPlan::deleteFacetIfCheap(int f, const Stencil& s, double allowed) {
  Stencil without = s;  // the same simplices but f
  without.facets.erase(std::find(without.facets.begin(), without.facets.end(), f));
  const std::vector<Eigen::Vector3d> pts = positionsOf(s);
  const std::vector<TransportTarget> targets = targetsOf(without);
  // Every plan without f costs at least each point's nearest remaining bin: when that
  // already exceeds the allowance (with a round-off margin), f stays without a program.
  if (nearestBinCost(pts, s.mass, targets) - s.cost > allowed + 1e-6 * (std::abs(s.cost) + allowed)) return false;
  const LocalTransport sol = solveLocalTransport(pts, s.mass, targets, params_.bins_per_point);
  if (!sol.solved || sol.cost - s.cost > allowed) return false;
  release(s);
  removeFacet(f);
  assign(s, without.vertices, without.facets, sol);
  return true;
}

double TransportPlan::medianFacetMeanSquaredDistance() const {
  std::vector<double> mean_d2;
  for (int f = 0; f < facetCount(); ++f) {
    const double m = facetAlive(f) ? massOnFacet(f) : 0.0;
    if (m > 0) mean_d2.push_back(gather({}, {f}).cost / m);
  }
  if (mean_d2.empty()) return 0;
  std::nth_element(mean_d2.begin(), mean_d2.begin() + mean_d2.size() / 2, mean_d2.end());
  return mean_d2[mean_d2.size() / 2];
}

// Facet deletion: in order of increasing mass density, a facet goes when re-solving its
// stencil without it raises the cost by at most threshold x its mass x the median facet's mean
// squared transport distance. A deletion hands mass to the neighbours (a facet fed by outliers
// may pass it to another such facet), so passes repeat, in the new density order, until one
// deletes nothing (at most 10). Sequential, in a fixed order: deterministic.
int TransportPlan::deleteRedundantFacets(double threshold) {
  const double unit = medianFacetMeanSquaredDistance();
  if (!(unit > 0)) return 0;
  int deleted = 0;
  for (int pass = 0; pass < 10; ++pass) {
    std::vector<std::pair<double, int>> order;
    for (int f = 0; f < facetCount(); ++f) {
      const double m = facetAlive(f) ? massOnFacet(f) : 0.0, a = facetArea(f);
      if (m > 0) order.emplace_back(a > 0 ? m / a : INFINITY, f);  // without mass: the density filter's
    }
    std::sort(order.begin(), order.end());
    int deleted_now = 0;
    for (const auto& [density, f] : order) {
      if (deleteFacetIfCheap(f, facetStencil(f), threshold * massOnFacet(f) * unit)) ++deleted_now;
    }
    deleted += deleted_now;
    if (deleted_now == 0) break;
  }
  return deleted;
}

namespace {

// Facets seen from one facet's bins: each alive facet's corners, unit normal and box grown by
// the reach (shaped: not degenerate); usable while it is alive and has mass.
struct FacetGeometry {
  Eigen::Vector3d a, b, c, normal, lo, hi;
  bool shaped = false, usable = false;
};

// Where the line through p along direction d meets triangle (a, b, c) within |t| <= reach.
bool hitsWithin(const Eigen::Vector3d& p, const Eigen::Vector3d& d, const FacetGeometry& g, double reach) {
  const double dn = g.normal.dot(d);
  if (std::abs(dn) < 1e-12) return false;
  const double t = g.normal.dot(g.a - p) / dn;
  if (std::abs(t) > reach) return false;
  const Eigen::Vector3d q = p + t * d;
  // Inside when q lies on the inner side of the three edges (in g's plane), with a margin of
  // 1e-9 of the edges for round-off on a shared edge.
  const Eigen::Vector3d* v[3] = {&g.a, &g.b, &g.c};
  for (int e = 0; e < 3; ++e) {
    const Eigen::Vector3d& u = *v[e];
    const Eigen::Vector3d& w = *v[(e + 1) % 3];
    if ((w - u).cross(q - u).dot(g.normal) < -1e-9 * (w - u).squaredNorm()) return false;
  }
  return true;
}

}  // namespace

// Sequential, in a fixed order (density, then facet id): deterministic. The vertices do not
// move here, so the pairs of near-parallel facets whose grown boxes meet are listed once, by
// CGAL's box intersection (a visit tested every facet's box before: rs1 to 3,500 vertices
// spent 2.8 s here against 4.1 s of decimation).
int TransportPlan::deleteStackedFacets(double threshold, double reach, double min_coverage) {
  if (!(threshold >= 0) || !std::isfinite(threshold))
    throw InvalidParameter("stacked threshold", detail::toString(threshold), "finite and >= 0");
  if (!(reach > 0) || !std::isfinite(reach)) throw InvalidParameter("stacked reach", detail::toString(reach), "finite and > 0");
  if (!(min_coverage > 0 && min_coverage <= 1))
    throw InvalidParameter("min_coverage", detail::toString(min_coverage), "in (0, 1]");
  const double unit = medianFacetMeanSquaredDistance();
  if (!(unit > 0)) return 0;
  const double reach_abs = reach * std::sqrt(unit);
  constexpr double kMinCos = 0.8;  // about 37 degrees from parallel, either orientation
  int deleted = 0;
  std::vector<FacetGeometry> geometry(facetCount());
  using Box = CGAL::Box_intersection_d::Box_with_info_d<double, 3, int>;
  std::vector<Box> boxes;
  for (int g = 0; g < facetCount(); ++g) {
    if (!facetAlive(g)) continue;
    FacetGeometry& x = geometry[g];
    x.a = vertex(facet(g)[0]);
    x.b = vertex(facet(g)[1]);
    x.c = vertex(facet(g)[2]);
    const Eigen::Vector3d n = (x.b - x.a).cross(x.c - x.a);
    if (!(n.norm() > 0)) continue;
    x.shaped = true;
    x.normal = n.normalized();
    x.lo = x.a.cwiseMin(x.b).cwiseMin(x.c).array() - reach_abs;
    x.hi = x.a.cwiseMax(x.b).cwiseMax(x.c).array() + reach_abs;
    double lo[3] = {x.lo.x(), x.lo.y(), x.lo.z()}, hi[3] = {x.hi.x(), x.hi.y(), x.hi.z()};
    boxes.emplace_back(lo, hi, g);
  }
  const auto refresh = [&](int g) { geometry[g].usable = geometry[g].shaped && facetAlive(g) && massOnFacet(g) > 0; };
  for (int g = 0; g < facetCount(); ++g) refresh(g);
  // Each facet's candidate covers: near-parallel, boxes meeting (closed boxes), by facet id.
  std::vector<std::vector<int>> candidates(facetCount());
  CGAL::box_self_intersection_d(boxes.begin(), boxes.end(), [&](const Box& p, const Box& q) {
    const int f = p.info(), g = q.info();
    if (std::abs(geometry[f].normal.dot(geometry[g].normal)) < kMinCos) return;
    candidates[f].push_back(g);
    candidates[g].push_back(f);
  });
  for (auto& c : candidates) {
    std::sort(c.begin(), c.end());
    c.erase(std::unique(c.begin(), c.end()), c.end());
  }
  // The facets covering f, and whether they cover at least min_coverage of its bins' capacity.
  const auto covering = [&](int f, std::vector<int>& cover) {
    cover.clear();
    const FacetGeometry& x = geometry[f];
    std::vector<int> near;
    for (int g : candidates[f])
      if (geometry[g].usable) near.push_back(g);
    if (near.empty()) return false;
    const FacetBins& bf = bins(f);
    double covered = 0;
    std::vector<char> used(near.size(), 0);
    for (std::size_t k = 0; k < bf.capacity.size(); ++k) {
      const Eigen::Vector3d& w = bf.barycentric[k];
      const Eigen::Vector3d p = w[0] * x.a + w[1] * x.b + w[2] * x.c;
      for (std::size_t j = 0; j < near.size(); ++j)
        if (hitsWithin(p, x.normal, geometry[near[j]], reach_abs)) {
          covered += bf.capacity[k];
          used[j] = 1;
          break;
        }
    }
    for (std::size_t j = 0; j < near.size(); ++j)
      if (used[j]) cover.push_back(near[j]);
    return covered >= min_coverage;
  };
  for (int pass = 0; pass < 10; ++pass) {
    std::vector<std::pair<double, int>> order;
    for (int f = 0; f < facetCount(); ++f) {
      const double m = facetAlive(f) ? massOnFacet(f) : 0.0, a = facetArea(f);
      if (m > 0 && a > 0) order.emplace_back(m / a, f);
    }
    std::sort(order.begin(), order.end());
    int deleted_now = 0;
    std::vector<int> cover, vs, fs;
    for (const auto& [density, f] : order) {
      if (!geometry[f].usable || !covering(f, cover)) continue;
      facetStencilSimplices(f, vs, fs);
      for (int g : cover) {
        fs.push_back(g);
        vs.insert(vs.end(), facet(g).begin(), facet(g).end());
      }
      const Stencil s = gather(vs, fs);
      if (!deleteFacetIfCheap(f, s, threshold * massOnFacet(f) * unit)) continue;
      for (int g : s.facets) refresh(g);  // their mass changed (one may have had none), and f is gone
      ++deleted_now;
    }
    deleted += deleted_now;
    if (deleted_now == 0) break;
  }
  return deleted;
}

}  // namespace paps
