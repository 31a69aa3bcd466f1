#include <paps/surface/mls_upsampling.h>
#include <paps/core/spatial_order.h>
#include <paps/surface/impl/mls_upsampling.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include <pcl/point_types.h>

#include <paps/core/cell_grid.h>
#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>
#include <paps/core/tiling.h>

namespace paps {

void MlsUpsamplingParameters::validate() const {
  if (!(radius >= 0) || !std::isfinite(radius))
    throw InvalidParameter("radius", detail::toString(radius), "0 (automatic) or a finite value > 0");
  requireInRange("target_neighbours", target_neighbours, 6, 1000);
  if (max_neighbours != 0) requireInRange("max_neighbours", max_neighbours, 6, 1000000);
  requireInRange("factor", factor, 1.f, 1000.f);
  requireInRange("iterations", iterations, 1, 50);
  requireInRange("inner_iterations", inner_iterations, 1, 50);
  requirePositive("sigma_r", sigma_r);
  requirePositive("sigma_n", sigma_n);
  requireInRange("disc_scale", disc_scale, 0.1f, 15.f);
  if (max_tile_points != 0 && (max_tile_points < 1000 || max_tile_points >= (std::size_t(1) << 31)))
    throw InvalidParameter("max_tile_points", std::to_string(max_tile_points),
                           "0 (one piece) or a count from 1000 to below 2^31");
}

void checkOutputCount(std::size_t output_count, std::size_t input_points) {
  // output_count > 1000 x input_points, written so that it cannot overflow.
  if (output_count / 1000 > input_points || (output_count / 1000 == input_points && output_count % 1000 != 0))
    throw InvalidParameter("output_count", detail::toString(output_count),
                           "at most 1000 x the " + detail::toString(input_points) + " input points (or 0: the factor)");
}

namespace {

// A cell of a hashed grid, and its hash.
struct Cell {
  std::int64_t x, y, z;
  bool operator==(const Cell& o) const { return x == o.x && y == o.y && z == o.z; }
};
struct CellHash {
  std::size_t operator()(const Cell& c) const {
    std::uint64_t h = static_cast<std::uint64_t>(c.x) * 0x9E3779B97F4A7C15ULL;
    h ^= static_cast<std::uint64_t>(c.y) * 0xC2B2AE3D27D4EB4FULL + (h << 6) + (h >> 2);
    h ^= static_cast<std::uint64_t>(c.z) * 0x165667B19E3779F9ULL + (h << 6) + (h >> 2);
    return static_cast<std::size_t>(h ^ (h >> 29));
  }
};

// Dart throwing over seed candidates that were generated on the tangent discs (radius `disc`)
// of input points. Two candidates closer than d come from input points closer than
// reach = d + 2 disc, so the kept seeds are filed by the input point they come from, and a
// candidate is only tested against the seeds of the input points within d + disc of it. Those
// are found through the caller's complete neighbour lists when it has some that reach far
// enough (APSS and RIMLS: the lists at their kernel support), or else through a grid of cells
// of side >= reach / 2 (5^3 cells around the candidate's input point). The grid needs memory
// linear in the input however dense it is; lists of input points within reach, which the
// thinner built for itself before, grew with the square of the local density (2.4 GB on
// bun0). Both give exactly the maximal Poisson-disk subset that plain dart throwing in the
// same visiting order gives (see run()), and the same crowding measure.
class SeedThinner {
 public:
  SeedThinner(const Positions& points, const std::vector<int>& ranked, const Positions& cand,
              const std::vector<int>& cand_rank, int slots, float disc, const NeighbourGraph* graph,
              float graph_radius)
      : points_(points), ranked_(ranked), cand_(cand), cand_rank_(cand_rank), slots_(slots), disc_(disc),
        graph_(graph), graph_radius_(graph ? graph_radius : 0.f) {
    opos_.resize(ranked.size());
    for (std::size_t k = 0; k < ranked.size(); ++k) opos_[k] = points[ranked[k]];
    lo_ = Eigen::Vector3f::Constant(INFINITY);
    for (const Eigen::Vector3f& p : opos_) lo_ = lo_.cwiseMin(p);
    cand_m2_.resize(cand.size());
    cand_p_.resize(cand.size());
    kept_.resize(ranked.size() * static_cast<std::size_t>(slots));
    kept_c_.resize(kept_.size());
    count_.resize(ranked.size());
    act_pos_.resize(ranked.size());
    act_rank_.resize(ranked.size());
  }

  // Candidates come in blocks of space of side `side` (contiguous ranges, block_start), each
  // with the parity of its block coordinates (0 to 7) and its coordinates (block_coord, as
  // computed from `lo` = the smallest coordinates of the input points). Blocks of the same
  // parity are at least one side apart: when the side is at least d + 2 disc they share no
  // conflict and no grid cell, so they are thinned in parallel, the parities one after the
  // other. The result does not depend on the thread count (it is the sequential result in
  // that order).
  void setBlocks(std::vector<std::size_t> block_start, std::vector<std::uint8_t> block_parity,
                 std::vector<std::array<std::int64_t, 3>> block_coord, double side) {
    block_start_ = std::move(block_start);
    block_parity_ = std::move(block_parity);
    block_coord_ = std::move(block_coord);
    side_ = side;
  }

  // Points already kept elsewhere (the seeds of the tiles run before, near this one): no
  // candidate within d of one is kept. Null or empty: none.
  void setKeptBefore(const Positions* before) { before_ = before && !before->empty() ? before : nullptr; }

  // The kept candidates at radius d: all of them, or (pilot) those of the first
  // `blocks_limit` blocks only (0: all). Pilots, and passes without blocks or with blocks too
  // small for d, visit the candidates in index order, sequentially.
  std::vector<int> run(float d, std::size_t blocks_limit = 0) {
    // The radius tried grows by a few percent a pass, rarely by half (pilots).
    if (before_ && d > before_reach_) nearestKeptBefore(2.f * d);
    if (d * kDenseSeeds < disc_) {
      std::vector<int> kept;
      if (runOnSeedGrid(d, block_start_.empty() || !blocks_limit ? cand_.size()
                                                                 : block_start_[std::min(blocks_limit, block_parity_.size())],
                        kept))
        return kept;
    }
    const float reach = d + 2.f * disc_;
    const std::int64_t blocks = static_cast<std::int64_t>(block_parity_.size());
    const std::int64_t nb = blocks_limit ? std::min<std::int64_t>(blocks, blocks_limit) : blocks;
    const bool aligned = !block_start_.empty() && side_ >= kCellMargin * reach;
    const bool parallel = aligned && nb == blocks;
    use_lists_ = graph_ && graph_radius_ >= reach;
    if (use_lists_)
      nearLists(reach);
    else
      buildCells(reach, aligned);
    reach1_sq_ = (d + disc_) * (d + disc_) * 1.0001f;
    const float d2 = d * d;
    std::vector<int> kept;
    const std::size_t end = block_start_.empty() ? cand_.size() : block_start_[nb];
    std::fill(count_.begin(), count_.end(), 0);
    std::fill(act_count_.begin(), act_count_.end(), 0);
    // Pilots (a prefix of the blocks) run sequentially: they are short, and on a loaded
    // machine the eight parity phases would cost more in waiting than they save.
    if (!parallel) {
      for (std::size_t c = 0; c < end; ++c)
        if (tryKeep(c, d2)) kept.push_back(static_cast<int>(c));
      return kept;
    }
    std::vector<std::uint8_t> keep(end, 0);
    for (int parity = 0; parity < 8; ++parity) {
#pragma omp parallel for schedule(dynamic, 2)
      for (std::int64_t b = 0; b < nb; ++b) {
        if (block_parity_[b] != parity) continue;
        for (std::size_t c = block_start_[b]; c < block_start_[b + 1]; ++c) keep[c] = tryKeep(c, d2);
      }
    }
    kept.reserve(end / 2);
    for (std::size_t c = 0; c < end; ++c)
      if (keep[c]) kept.push_back(static_cast<int>(c));
    return kept;
  }

  // For the seeds `kept` (increasing candidate indices) of the last run: the squared distance
  // to the nearest seed kept before it among those it was tested against (infinite when none)
  // and the position of that seed in `kept` (-1 when none). Seeds closer to an earlier one
  // than the others are the crowded ones.
  void crowding(const std::vector<int>& kept, std::vector<float>& m2, std::vector<int>& partner) {
    const std::size_t n = kept.size();
    m2.resize(n);
    partner.resize(n);
    std::vector<int>& pos = cand_p_pos_;
    pos.resize(cand_.size());
    for (std::size_t i = 0; i < n; ++i) pos[kept[i]] = static_cast<int>(i);
    for (std::size_t i = 0; i < n; ++i) {
      m2[i] = cand_m2_[kept[i]];
      partner[i] = cand_p_[kept[i]] >= 0 ? pos[cand_p_[kept[i]]] : -1;
    }
  }

  // The number of blocks whose candidates make up at least `n` candidates.
  std::size_t blocksCovering(std::size_t n) const {
    std::size_t b = 0;
    while (b < block_parity_.size() && block_start_[b + 1] < n) ++b;
    return std::min(b + 1, block_parity_.size());
  }

 private:
  // Below disc / kDenseSeeds the seeds are far denser than the discs: a candidate then meets
  // about (2 disc / d)^2 seeds of the input points around it, all of them when it is kept.
  // Reached only when the output cannot be spread over the discs otherwise: thousands of
  // copies of a few positions (d = 0.004 disc), a 1 cm cluster beside a 1 km plane (0.008),
  // the test of piles of copies (0.024); the tests and benches otherwise stay above 0.14.
  static constexpr float kDenseSeeds = 8.f;

  // Dart throwing on a grid of the kept seeds (cells of side d, a candidate tested against
  // the 27 cells around it), sequentially in index order: the same kept seeds as the lists or
  // the cells of input points, each test costing the seeds within 2 d instead of 2 disc. The
  // crowding measure is over those seeds only (nearest earlier seed within the 27 cells).
  // Returns false (nothing done) when the extent holds more than 2^40 cells along an axis.
  bool runOnSeedGrid(float d, std::size_t end, std::vector<int>& kept) {
    Eigen::Vector3f hi = Eigen::Vector3f::Constant(-INFINITY);
    for (const Eigen::Vector3f& p : opos_) hi = hi.cwiseMax(p);
    const Eigen::Vector3d origin = (lo_.cast<double>().array() - 2.0 * disc_).matrix();
    const double inv = 1.0 / d;
    if (!(((hi.cast<double>() - origin).array() + 2.0 * disc_).maxCoeff() * inv < std::ldexp(1.0, 40))) return false;
    auto cellOf = [&](const Eigen::Vector3f& p, int a) {
      return static_cast<std::int64_t>(std::floor((static_cast<double>(p[a]) - origin[a]) * inv));
    };
    std::unordered_map<Cell, int, CellHash> head;  // cell -> last seed filed in it
    std::vector<int> next, seed_c;                // per seed: previous seed of its cell, candidate
    const float d2 = d * d;
    std::fill(count_.begin(), count_.end(), 0);  // keep() files the seeds per input point
    kept.clear();
    for (std::size_t c = 0; c < end; ++c) {
      if (blockedBefore(c, d2)) continue;
      const Eigen::Vector3f& p = cand_[c];
      const std::int64_t cx = cellOf(p, 0), cy = cellOf(p, 1), cz = cellOf(p, 2);
      float best = INFINITY;
      int best_c = -1;
      bool free = true;
      for (std::int64_t z = cz - 1; z <= cz + 1 && free; ++z)
        for (std::int64_t y = cy - 1; y <= cy + 1 && free; ++y)
          for (std::int64_t x = cx - 1; x <= cx + 1 && free; ++x) {
            const auto it = head.find(Cell{x, y, z});
            if (it == head.end()) continue;
            for (int t = it->second; t >= 0; t = next[t]) {
              const float e2 = (cand_[seed_c[t]] - p).squaredNorm();
              if (e2 < d2) { free = false; break; }
              if (e2 < best || (e2 == best && seed_c[t] < best_c)) { best = e2; best_c = seed_c[t]; }
            }
          }
      if (!free) continue;
      const auto it = head.try_emplace(Cell{cx, cy, cz}, -1).first;
      next.push_back(it->second);
      it->second = static_cast<int>(seed_c.size());
      seed_c.push_back(static_cast<int>(c));
      keep(c, cand_rank_[c], best, best_c);
      kept.push_back(static_cast<int>(c));
    }
    return true;
  }

  // Cells of side >= 1.01 reach / kSpan (a little more than needed, so that rounding never
  // hides a neighbour), kSpan cells searched on each side. On rs1 (114K -> 457K, APSS's disc)
  // a candidate then looks at 7 cells and 2 input points with seeds on average.
  static constexpr float kCellMargin = 1.01f;
  static constexpr int kSpan = 2;

  // "Tested against" = the seeds of the input points within d + disc of the candidate (the
  // only ones that can conflict with it): the crowding measure does not depend on the cells.
  bool tryKeep(std::size_t c, float d2) {
    if (blockedBefore(c, d2)) return false;
    const Eigen::Vector3f& p = cand_[c];
    const int k = cand_rank_[c];
    float best = INFINITY;
    int best_c = -1;
    // Tests the seeds of input point r (rank) when it lies within d + disc of p.
    auto test = [&](const Eigen::Vector3f& pos, int r) {
      if ((pos - p).squaredNorm() >= reach1_sq_) return true;
      const std::size_t first = static_cast<std::size_t>(r) * slots_;
      const Eigen::Vector3f* q = kept_.data() + first;
      for (int t = 0; t < count_[r]; ++t) {
        const float e2 = (q[t] - p).squaredNorm();
        if (e2 < d2) return false;
        if (e2 < best) {
          best = e2;
          best_c = kept_c_[first + t];
        }
      }
      return true;
    };
    if (use_lists_) {
      for (std::int64_t m = near_off_[k]; m < near_end_[k]; ++m) {
        const int r = near_[m];
        if (count_[r] != 0 && !test(opos_[r], r)) return false;
      }
      keep(c, k, best, best_c);
      return true;
    }
    const int cell = cell_of_[k];
    for (std::int64_t m = nb_off_[cell]; m < nb_off_[cell + 1]; ++m) {
      const int nc = nb_[m];
      // The input points of that cell with kept seeds.
      for (std::size_t a = act_off_[nc], a_end = a + act_count_[nc]; a < a_end; ++a)
        if (!test(act_pos_[a], act_rank_[a])) return false;
    }
    if (count_[k] == 0) {
      const int cell = cell_of_[k];
      const std::size_t a = act_off_[cell] + act_count_[cell]++;
      act_pos_[a] = opos_[k];
      act_rank_[a] = k;
    }
    keep(c, k, best, best_c);
    return true;
  }

  bool blockedBefore(std::size_t c, float d2) const { return before_ && before_d2_[c] < d2; }

  // before_d2_: per candidate, the squared distance to the nearest point kept before, where
  // it is within `reach` (infinite elsewhere). Those points lie along a seam: a grid of cells
  // of reach + disc holds them; an input point whose cell is not next to one of theirs has no
  // candidate within reach of them (its candidates lie within the disc of it), and the
  // candidates of the others look at the 27 cells around them.
  void nearestKeptBefore(float reach) {
    const Positions& before = *before_;
    before_reach_ = reach;
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY);
    for (const Eigen::Vector3f& p : before) lo = lo.cwiseMin(p.cast<double>());
    const double inv = 1.0 / (static_cast<double>(reach) + disc_);
    auto cellOf = [&](const Eigen::Vector3f& p) {
      const Eigen::Vector3d g = ((p.cast<double>() - lo) * inv).array().floor();
      return Cell{static_cast<std::int64_t>(g.x()), static_cast<std::int64_t>(g.y()), static_cast<std::int64_t>(g.z())};
    };
    std::unordered_map<Cell, std::vector<int>, CellHash> cells;
    for (std::size_t k = 0; k < before.size(); ++k) cells[cellOf(before[k])].push_back(static_cast<int>(k));
    std::unordered_map<Cell, std::uint8_t, CellHash> near;  // cells within one of a kept point's
    for (const auto& [cell, ids] : cells)
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) near[Cell{cell.x + dx, cell.y + dy, cell.z + dz}] = 1;
    const std::int64_t np = static_cast<std::int64_t>(opos_.size());
    std::vector<std::uint8_t> point_near(opos_.size(), 0);
#pragma omp parallel for schedule(static, 4096)
    for (std::int64_t k = 0; k < np; ++k) point_near[k] = near.find(cellOf(opos_[k])) != near.end();
    before_d2_.assign(cand_.size(), INFINITY);
    const std::int64_t n = static_cast<std::int64_t>(cand_.size());
#pragma omp parallel for schedule(static, 4096)
    for (std::int64_t c = 0; c < n; ++c) {
      if (!point_near[cand_rank_[c]]) continue;
      const Eigen::Vector3f& p = cand_[c];
      const Cell at = cellOf(p);
      float best = INFINITY;
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const auto it = cells.find(Cell{at.x + dx, at.y + dy, at.z + dz});
            if (it == cells.end()) continue;
            for (const int k : it->second) best = std::min(best, (before[k] - p).squaredNorm());
          }
      before_d2_[c] = best;
    }
  }

  void keep(std::size_t c, int k, float best, int best_c) {
    const std::size_t slot = static_cast<std::size_t>(k) * slots_ + count_[k]++;
    kept_[slot] = cand_[c];
    kept_c_[slot] = static_cast<int>(c);
    cand_m2_[c] = best;
    cand_p_[c] = best_c;
  }

  // near_ lists, per ranked input point, the ranks of the ranked points within 1.15 reach
  // (itself first, then as in the caller's lists: by distance). Lists made for a larger reach
  // serve as they are, so they are only rebuilt when the reach grows past theirs.
  void nearLists(float reach) {
    if (near_reach_ >= reach) return;
    if (rank_of_.empty()) {
      rank_of_.assign(points_.size(), -1);
      for (std::size_t k = 0; k < ranked_.size(); ++k) rank_of_[ranked_[k]] = static_cast<int>(k);
    }
    reach = std::min(1.15f * reach, graph_radius_);
    near_reach_ = reach;
    const float reach2 = reach * reach;
    const std::int64_t n = static_cast<std::int64_t>(ranked_.size());
    // One pass: each list gets the room of its graph list (an upper bound) and notes its end.
    near_off_.assign(n + 1, 0);
    near_end_.resize(n);
    for (std::int64_t k = 0; k < n; ++k) near_off_[k + 1] = near_off_[k] + graph_->count(ranked_[k]) + 1;
    near_.resize(static_cast<std::size_t>(near_off_[n]));
#pragma omp parallel for schedule(dynamic, 512)
    for (std::int64_t k = 0; k < n; ++k) {
      const int i = ranked_[k];
      std::int64_t pos = near_off_[k];
      near_[pos++] = static_cast<int>(k);
      for (const int* j = graph_->begin(i); j != graph_->end(i); ++j) {
        const int r = rank_of_[*j];
        if (r >= 0 && *j != i && (points_[*j] - points_[i]).squaredNorm() <= reach2) near_[pos++] = r;
      }
      near_end_[k] = pos;
    }
  }

  // Files every input point in a cell. For parallel runs the cells subdivide the blocks in
  // m >= kSpan per side (each cell inside one block, so a thread only writes cells of its own
  // block and reads cells of its own and of adjacent blocks, which have another parity).
  // Cells made for a larger reach serve as they are, unless much larger. Sequential runs use
  // the block-aligned cells too when the blocks are large enough, so that the pilot passes
  // and the full passes share them.
  void buildCells(float reach, bool aligned) {
    const double need = kCellMargin * static_cast<double>(reach) / kSpan;
    std::int64_t m = 1;
    double s = need;
    if (aligned) {
      m = std::max<std::int64_t>(kSpan, static_cast<std::int64_t>(std::floor(side_ / need)));
      s = side_ / static_cast<double>(m);
    }
    if (!cell_of_.empty() && aligned == cells_aligned_ && cell_side_ >= need && cell_side_ <= 1.5 * need) return;
    cells_aligned_ = aligned;
    cell_side_ = s;
    const std::size_t n = opos_.size();
    // Cell coordinates (+ kSpan, so that no neighbour is negative), packed 42 bits each in
    // (z, y, x) order: the cell order is the key order.
    using Key = unsigned __int128;
    constexpr int kBits = 42;
    const Key mask = (Key(1) << kBits) - 1;
    auto pack = [](std::int64_t x, std::int64_t y, std::int64_t z) {
      return (Key(static_cast<std::uint64_t>(z)) << (2 * kBits)) | (Key(static_cast<std::uint64_t>(y)) << kBits) |
             Key(static_cast<std::uint64_t>(x));
    };
    std::vector<std::pair<Key, int>> order(n);
    auto fill = [&](std::size_t k, const std::array<std::int64_t, 3>* block) {
      std::int64_t c[3];
      for (int a = 0; a < 3; ++a) {
        const double x = static_cast<double>(opos_[k][a]) - lo_[a];
        if (block) {
          const double local = std::floor((x - static_cast<double>((*block)[a]) * side_) / s);
          c[a] = (*block)[a] * m + std::clamp<std::int64_t>(static_cast<std::int64_t>(local), 0, m - 1);
        } else {
          c[a] = static_cast<std::int64_t>(std::min(std::floor(x / s), 1e12));
        }
      }
      order[k] = {pack(c[0] + kSpan, c[1] + kSpan, c[2] + kSpan), static_cast<int>(k)};
    };
    if (aligned) {
      for (std::size_t b = 0; b + 1 < block_start_.size(); ++b)
        for (std::size_t k = block_start_[b] / slots_; k < block_start_[b + 1] / slots_; ++k) fill(k, &block_coord_[b]);
    } else {
      for (std::size_t k = 0; k < n; ++k) fill(k, nullptr);
    }
    std::sort(order.begin(), order.end());
    std::vector<Key> cells;
    cell_of_.assign(n, -1);
    act_off_.clear();
    for (std::size_t i = 0; i < n; ++i) {
      if (i == 0 || order[i].first != cells.back()) {
        cells.push_back(order[i].first);
        act_off_.push_back(i);
      }
      cell_of_[order[i].second] = static_cast<int>(cells.size() - 1);
    }
    act_off_.push_back(n);
    act_count_.assign(cells.size(), 0);
    cell_lo_.assign(cells.size(), Eigen::Vector3f::Constant(INFINITY));
    cell_hi_.assign(cells.size(), Eigen::Vector3f::Constant(-INFINITY));
    for (std::size_t k = 0; k < n; ++k) {
      cell_lo_[cell_of_[k]] = cell_lo_[cell_of_[k]].cwiseMin(opos_[k]);
      cell_hi_[cell_of_[k]] = cell_hi_[cell_of_[k]].cwiseMax(opos_[k]);
    }
    // The occupied cells among the 5^3 around each cell. For each (dz, dy) the cells sought
    // form one run along x whose start only moves forward as the cells are visited in order:
    // one sweep per (dz, dy), no search. Cells whose points are all at least the largest reach
    // these cells serve away from the points of cell c hold no input point within d + disc of
    // a candidate of c (which lies within disc of its input point): left out. Nearest cells
    // first (own cell first): a conflicting seed, when there is one, is usually found after a
    // cell or two.
    const float serve = static_cast<float>(cell_side_ * kSpan / kCellMargin) * 1.0001f;
    const float serve2 = serve * serve;
    constexpr int kRows = (2 * kSpan + 1) * (2 * kSpan + 1);
    std::array<std::size_t, kRows> at{};
    std::array<std::pair<int, int>, kRows * (2 * kSpan + 1)> found;  // (squared offset, cell)
    nb_off_.assign(cells.size() + 1, 0);
    nb_.clear();
    for (std::size_t c = 0; c < cells.size(); ++c) {
      int row = 0, nfound = 0;
      const std::int64_t cx = static_cast<std::int64_t>(cells[c] & mask);
      const std::int64_t cy = static_cast<std::int64_t>((cells[c] >> kBits) & mask);
      const std::int64_t cz = static_cast<std::int64_t>(cells[c] >> (2 * kBits));
      for (int dz = -kSpan; dz <= kSpan; ++dz)
        for (int dy = -kSpan; dy <= kSpan; ++dy, ++row) {
          const Key from = pack(cx - kSpan, cy + dy, cz + dz);
          std::size_t& p = at[row];
          while (p < cells.size() && cells[p] < from) ++p;
          for (std::size_t q = p; q < cells.size() && (cells[q] >> kBits) == (from >> kBits); ++q) {
            const std::int64_t qx = static_cast<std::int64_t>(cells[q] & mask);
            if (qx > cx + kSpan) break;
            const Eigen::Vector3f gap = (cell_lo_[q] - cell_hi_[c]).cwiseMax(cell_lo_[c] - cell_hi_[q]).cwiseMax(0.f);
            if (gap.squaredNorm() < serve2)
              found[nfound++] = {dz * dz + dy * dy + static_cast<int>((qx - cx) * (qx - cx)), static_cast<int>(q)};
          }
        }
      std::sort(found.begin(), found.begin() + nfound);
      for (int i = 0; i < nfound; ++i) nb_.push_back(found[i].second);
      nb_off_[c + 1] = static_cast<std::int64_t>(nb_.size());
    }
  }

  const Positions& points_;
  const std::vector<int>& ranked_;
  const Positions& cand_;
  const std::vector<int>& cand_rank_;
  const int slots_;
  const float disc_;
  Positions opos_;  // the ranked input points
  // The caller's lists and those derived from them (near_: ranks within near_reach_).
  const NeighbourGraph* graph_;
  float graph_radius_;
  bool use_lists_ = false;
  std::vector<int> rank_of_, near_;
  std::vector<std::int64_t> near_off_, near_end_;
  float near_reach_ = 0.f;
  Eigen::Vector3f lo_;
  // The grid: cell of each ranked point, the occupied cells near each cell (nearest first),
  // and per cell its input points that have kept seeds so far (room for all of them).
  std::vector<int> cell_of_, nb_;
  std::vector<std::int64_t> nb_off_;
  std::vector<std::size_t> act_off_;  // per cell: room for its input points with kept seeds,
  std::vector<int> act_count_;        // how many have some so far,
  Positions act_pos_;                 // and those points (position, rank)
  std::vector<int> act_rank_;
  Positions cell_lo_, cell_hi_;  // bounding box of the input points of each cell
  Positions kept_;            // per ranked input point, room for its kept seeds
  std::vector<int> kept_c_;   // (slots each): the seed and its candidate index,
  std::vector<int> count_;    // and how many it has
  bool cells_aligned_ = false;
  double cell_side_ = 0;
  std::vector<float> cand_m2_;  // per kept candidate of the last run: squared distance to the
  std::vector<int> cand_p_;     // nearest earlier seed tested, and that seed (-1: none)
  std::vector<int> cand_p_pos_;
  std::vector<std::size_t> block_start_;
  std::vector<std::uint8_t> block_parity_;
  std::vector<std::array<std::int64_t, 3>> block_coord_;
  double side_ = 0;
  float reach1_sq_ = 0.f;
  const Positions* before_ = nullptr;  // kept before (setKeptBefore)
  std::vector<float> before_d2_;       // per candidate: squared distance to the nearest of them,
  float before_reach_ = 0.f;           // known within this reach
};

}  // namespace

namespace detail {
std::vector<int> thinSeedCandidates(const Positions& points, const Positions& cand, const std::vector<int>& cand_point,
                                    int slots, float disc, float d, const NeighbourGraph* graph, float graph_radius,
                                    std::vector<float>* m2) {
  std::vector<int> ranked(points.size());
  for (std::size_t i = 0; i < ranked.size(); ++i) ranked[i] = static_cast<int>(i);
  SeedThinner thinner(points, ranked, cand, cand_point, slots, disc, graph, graph_radius);
  std::vector<int> kept = thinner.run(d);
  if (m2) {
    std::vector<int> partner;
    thinner.crowding(kept, *m2, partner);
  }
  return kept;
}
}  // namespace detail

Positions upsamplingSeeds(const Positions& points, const Normals& normals, std::size_t count,
                          float disc_radius, std::uint64_t seed, std::vector<int>* origin) {
  return upsamplingSeeds(points, normals, count, disc_radius, seed, origin, nullptr, 0.f);
}

Positions upsamplingSeeds(const Positions& points, const Normals& normals, std::size_t count,
                          float disc_radius, std::uint64_t seed, std::vector<int>* origin,
                          const NeighbourGraph* graph, float graph_radius, const std::vector<float>* disc_scale,
                          const Positions* kept_before) {
  requirePositive("disc_radius", disc_radius);
  checkOutputCount(count, points.size());
  if (normals.size() != points.size())
    throw InvalidParameter("normals", std::to_string(normals.size()) + " normals",
                           std::to_string(points.size()) + ", one per point");
  if (disc_scale && (disc_scale->size() != points.size() ||
                     std::any_of(disc_scale->begin(), disc_scale->end(), [](float f) { return !(f > 0.f && f <= 1.f); })))
    throw InvalidParameter("disc_scale", std::to_string(disc_scale->size()) + " values",
                           std::to_string(points.size()) + " values in (0, 1], one per point");
  if (graph && graph->size() != points.size())
    throw InvalidParameter("graph", std::to_string(graph->size()) + " lists",
                           std::to_string(points.size()) + ", one per point");
  std::vector<int> usable_pts;
  usable_pts.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i)
    if (isFinite(points[i]) && isFinite(normals[i])) usable_pts.push_back(static_cast<int>(i));
  const std::size_t usable = usable_pts.size();
  if (usable == 0) throw InvalidInput("no finite point with a normal to upsample from");
  if (count == 0) return {};
  // Over-generate (about twice the count), then thin with a Poisson-disk radius found by a few
  // passes.
  const int per_point = static_cast<int>(std::ceil(2.0 * count / usable)) + 1;
  // First estimate of the radius: the area of the discs (with overlaps) over the density of a
  // dart-throwing set of about half the candidates (the constant 2.9 was measured on the bench
  // shapes; the pilot passes below correct it).
  const double area = static_cast<double>(usable) * 3.14159265 * disc_radius * disc_radius * 0.6;
  double d = std::sqrt(area / (2.9 * count));
  // Dart throwing visits the candidates in index order. Input points are grouped in blocks of
  // space visited one after the other, and the candidates of a block are shuffled among
  // themselves: as random locally as a global shuffle, with memory traffic that stays local.
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY);
  for (const int i : usable_pts) lo = lo.cwiseMin(points[i]);
  const double block = std::max(8.0 * d, 4.0 * disc_radius);
  std::vector<std::pair<std::uint64_t, int>> keyed(usable);
  for (std::size_t k = 0; k < usable; ++k) {
    const Eigen::Vector3f& p = points[usable_pts[k]];
    std::uint64_t key = 0;
    for (int a = 0; a < 3; ++a) {
      const auto c = static_cast<std::uint64_t>(std::min(2097151.0, std::floor((double(p[a]) - lo[a]) / block)));
      key = (key << 21) | c;
    }
    keyed[k] = {key, usable_pts[k]};
  }
  std::sort(keyed.begin(), keyed.end());
  std::vector<int> ranked(usable);
  for (std::size_t k = 0; k < usable; ++k) ranked[k] = keyed[k].second;
  // Blocks: runs of input points with the same block key. Candidates k * per_point ..
  // (k + 1) * per_point - 1 come from the k-th ranked point, so a block's candidates are a
  // contiguous range known in advance; each block draws them (and shuffles them) with its own
  // random stream, in parallel: the result does not depend on the thread count.
  std::vector<std::size_t> block_first;  // first rank of each block
  std::vector<std::uint8_t> block_parity;
  std::vector<std::array<std::int64_t, 3>> block_coord;
  for (std::size_t k = 0; k < usable; ++k)
    if (k == 0 || keyed[k].first != keyed[k - 1].first) {
      const std::uint64_t key = keyed[k].first;
      block_first.push_back(k);
      block_coord.push_back({static_cast<std::int64_t>(key >> 42), static_cast<std::int64_t>((key >> 21) & 2097151),
                             static_cast<std::int64_t>(key & 2097151)});
      block_parity.push_back(static_cast<std::uint8_t>(((key >> 42) & 1) | (((key >> 21) & 1) << 1) | ((key & 1) << 2)));
    }
  block_first.push_back(usable);
  const std::int64_t nblocks = static_cast<std::int64_t>(block_parity.size());
  const std::size_t ncand = usable * static_cast<std::size_t>(per_point);
  Positions cand(ncand);
  std::vector<int> cand_rank(ncand);
#pragma omp parallel for schedule(dynamic, 4)
  for (std::int64_t b = 0; b < nblocks; ++b) {
    Random brng(seed * 0x9E3779B97F4A7C15ULL + static_cast<std::uint64_t>(b) * 0xD1B54A32D192ED03ULL + 1);
    const std::size_t c0 = block_first[b] * per_point, c1 = block_first[b + 1] * per_point;
    for (std::size_t k = block_first[b]; k < block_first[b + 1]; ++k) {
      const int i = ranked[k];
      const Eigen::Vector3f& n = normals[i];
      const Eigen::Vector3f a = std::abs(n.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY();
      const Eigen::Vector3f t1 = (a - a.dot(n) * n).normalized(), t2 = n.cross(t1);
      for (int j = 0; j < per_point; ++j) {
        float u, v;  // uniform in the unit disc, by rejection from the square
        do {
          const std::uint64_t bits = brng.next();
          u = static_cast<float>(bits >> 40) * (2.f / 16777216.f) - 1.f;
          v = static_cast<float>((bits >> 16) & 0xFFFFFFu) * (2.f / 16777216.f) - 1.f;
        } while (u * u + v * v > 1.f);
        const std::size_t c = k * per_point + j;
        cand[c] = points[i] + (disc_scale ? (*disc_scale)[i] * disc_radius : disc_radius) * (u * t1 + v * t2);
        cand_rank[c] = static_cast<int>(k);
      }
    }
    for (std::size_t m = c1; m > c0 + 1; --m) {  // shuffle the block
      const std::size_t j = c0 + brng.below(m - c0);
      std::swap(cand[m - 1], cand[j]);
      std::swap(cand_rank[m - 1], cand_rank[j]);
    }
  }
  std::vector<std::size_t> block_start(nblocks + 1);
  for (std::int64_t b = 0; b <= nblocks; ++b) block_start[b] = block_first[b] * per_point;
  Random rng(seed);
  if (cand.size() <= count) {
    if (origin) {
      origin->resize(cand.size());
      for (std::size_t c = 0; c < cand.size(); ++c) (*origin)[c] = ranked[cand_rank[c]];
    }
    return cand;
  }
  // Keep the largest radius tried that gives at least `count` points, stopping at one that
  // gives at most 7% more. The passes aim at 3.5% more: the pilots below overestimate the
  // count by 1-2.3% (their part of the surface is not typical: on the bench shapes a twelfth
  // of the candidates keeps 0.436 to 0.459 of them depending on where it is taken), and a
  // second full pass costs more than dropping a few percent of crowded seeds. The count falls with d about as a power law whose exponent (-2 for
  // a sparse set, less as the set nears the candidates' own spacing) is measured from the last
  // two passes.
  // No radius below d_floor is tried: where the candidates are fewer distinct positions than
  // the count (float coordinates too large for the spacing: a 1 m plane at (5e5, 5e6) has float
  // steps of 0.5 m there), no radius gives enough, and the search went down to 1e-29 m through
  // passes that cost the square of the candidates (60 s on 200K points). Below it the first
  // `count` candidates are taken, as when no radius gives enough.
  float largest = 0.f;
  for (const int i : usable_pts) largest = std::max(largest, points[i].cwiseAbs().maxCoeff());
  const double d_floor = std::max(1e-4 * disc_radius, 2.0 * (std::nextafter(largest, INFINITY) - largest));
  SeedThinner thinner(points, ranked, cand, cand_rank, per_point, disc_radius, graph, graph_radius);
  thinner.setBlocks(block_start, std::move(block_parity), std::move(block_coord), block);
  thinner.setKeptBefore(kept_before);
  std::vector<int> best, best_partner;
  std::vector<float> best_m2;
  double lo_fail = 0, hi_ok = 0;  // smallest radius giving too few, largest giving enough
  double prev_d = 0, prev_n = 0;
  const double want = 1.035 * count;
  // Two pilot passes on the first candidates (a compact part of the surface, thinned exactly
  // as the full pass would) set the radius and the exponent, so that the full pass is usually
  // right the first time.
  const std::size_t pilot_blocks = thinner.blocksCovering(std::max<std::size_t>(cand.size() / 12, 30000));
  const std::size_t pilot = block_start[pilot_blocks];
  double slope_hint = -1.5;
  if (pilot < cand.size() / 2) {
    const double scale = static_cast<double>(cand.size()) / pilot;
    double& slope = slope_hint;
    for (int it = 0; it < 2 && d >= d_floor; ++it) {
      const double found = scale * static_cast<double>(thinner.run(static_cast<float>(d), pilot_blocks).size());
      if (!(found > 0)) break;
      if (prev_d > 0 && std::abs(std::log(d / prev_d)) > 1e-6 && prev_n > 0)
        slope = std::clamp(std::log(found / prev_n) / std::log(d / prev_d), -4.0, -0.3);
      prev_d = d;
      prev_n = found;
      d *= std::pow(want / found, 1.0 / slope);
    }
    prev_d = prev_n = 0;
  }
  for (int it = 0; it < 12 && d >= d_floor; ++it) {
    std::vector<int> s = thinner.run(static_cast<float>(d));
    const double found = static_cast<double>(s.size());
    if (s.size() >= count) {
      hi_ok = std::max(hi_ok, d);
      const bool close = found < 1.07 * count;
      best = std::move(s);
      thinner.crowding(best, best_m2, best_partner);
      if (close) break;
    } else {
      lo_fail = lo_fail > 0 ? std::min(lo_fail, d) : d;
    }
    double slope = slope_hint;
    if (prev_d > 0 && std::abs(std::log(d / prev_d)) > 1e-6 && prev_n > 0 && found > 0)
      slope = std::clamp(std::log(found / prev_n) / std::log(d / prev_d), -4.0, -0.3);
    prev_d = d;
    prev_n = found;
    double next = d * std::pow(want / std::max(found, 1.0), 1.0 / slope);
    // Stay strictly inside the bracket when there is one.
    if (lo_fail > 0 && hi_ok > 0 && !(next > hi_ok && next < lo_fail)) next = 0.5 * (hi_ok + lo_fail);
    d = next;
  }
  if (best.empty()) {  // never enough: take the first `count` candidates
    best.resize(cand.size());
    for (std::size_t i = 0; i < best.size(); ++i) best[i] = static_cast<int>(i);
  }
  // Drop the surplus (a few percent; the kept ones stay in increasing order): the seeds
  // closest to an earlier seed first, skipping a seed whose nearest earlier seed is already
  // dropped (no hole where a close pair was). Against a random drop of the same surplus: bench
  // plane 0.01%, RIMLS 8.513e-4 vs 8.561e-4 (2.4% dropped), RIMLS-wide 6.365e-4 vs 6.392e-4.
  std::vector<std::uint8_t> drop(best.size(), 0);
  if (best_m2.size() == best.size()) {
    // The most crowded seeds first (closest to an earlier seed), but not both of a pair.
    std::vector<int> order(best.size());
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
    const std::size_t surplus = best.size() - count;
    auto closer = [&](int a, int b) { return best_m2[a] < best_m2[b] || (best_m2[a] == best_m2[b] && a < b); };
    const std::size_t span = std::min(order.size(), 3 * surplus + 1);
    std::nth_element(order.begin(), order.begin() + (span - 1), order.end(), closer);
    std::sort(order.begin(), order.begin() + span, closer);
    std::size_t dropped = 0;
    for (std::size_t i = 0; i < span && dropped < surplus; ++i) {
      const int k = order[i];
      if (best_partner[k] >= 0 && drop[best_partner[k]]) continue;
      drop[k] = 1;
      ++dropped;
    }
    for (std::size_t i = 0; i < span && dropped < surplus; ++i)
      if (!drop[order[i]]) { drop[order[i]] = 1; ++dropped; }
    for (std::size_t k = 0; dropped < surplus; ++k)
      if (!drop[k]) { drop[k] = 1; ++dropped; }
  } else {
    for (std::size_t dropped = 0; dropped + count < best.size();) {
      const std::size_t k = rng.below(best.size());
      if (!drop[k]) { drop[k] = 1; ++dropped; }
    }
  }
  Positions out(count);
  if (origin) origin->resize(count);
  std::vector<std::size_t> at(best.size());
  for (std::size_t k = 0, m = 0; k < best.size(); ++k) { at[k] = m; m += !drop[k]; }
#pragma omp parallel for schedule(static)
  for (std::int64_t k = 0; k < static_cast<std::int64_t>(best.size()); ++k) {
    if (drop[k]) continue;
    out[at[k]] = cand[best[k]];
    if (origin) (*origin)[at[k]] = ranked[cand_rank[best[k]]];
  }
  return out;
}

namespace {

// The lists restricted to `radius`.
NeighbourGraph restrictedGraph(const Positions& pts, const NeighbourGraph& graph, float radius) {
  const float r2 = radius * radius;
  std::vector<std::int64_t> off(graph.size() + 1, 0);
  std::size_t total = 0;
  for (std::size_t i = 0; i < graph.size(); ++i) total += graph.count(i);
  std::vector<int> idx;
  idx.reserve(total);
  for (std::size_t i = 0; i < graph.size(); ++i) {
    for (const int* j = graph.begin(i); j != graph.end(i); ++j)
      if ((pts[*j] - pts[i]).squaredNorm() <= r2) idx.push_back(*j);
    off[i + 1] = static_cast<std::int64_t>(idx.size());
  }
  return NeighbourGraph::fromRows(std::move(off), std::move(idx));
}

// e^-x for x >= 0 (relative error below 1e-5, 0 beyond e^-80): a polynomial and an exponent,
// so that the loops of the RIMLS weights vectorise.
inline float expNeg(float x) {
  x = x < 80.f ? x : 80.f;
  const float y = -x * 1.44269504089f;
  const int i = static_cast<int>(y);  // toward zero: y - i in (-1, 0]
  const float z = (y - static_cast<float>(i)) * 0.69314718056f;
  const float p = 1.f + z * (1.f + z * (0.5f + z * (1.f / 6 + z * (1.f / 24 + z * (1.f / 120 + z * (1.f / 720))))));
  const std::int32_t bits = (i + 127) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof scale);
  return p * scale;
}

// Eight lanes of floats (GCC / Clang vector extensions: two SSE registers, or one AVX
// register in the AVX2 clone of the functions marked PAPS_AVX2_CLONE). The loops over a
// block's neighbours use them explicitly: the compiler's own vectoriser leaves these short
// loops with many sums scalar (its cost model), and explicit lanes fix the order of the
// additions, so the result is the same whatever instructions run them (no FMA: each lane
// does the same float operations in either clone).
// (-Wpsabi: the 32-byte vectors never cross a call boundary: the helpers are always inlined.)
#pragma GCC diagnostic ignored "-Wpsabi"
constexpr int kLanes = 8;
typedef float FV __attribute__((vector_size(32)));
typedef std::int32_t IV __attribute__((vector_size(32)));
#define PAPS_LANES_INLINE inline __attribute__((always_inline))
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define PAPS_AVX2_CLONE __attribute__((target_clones("avx2", "default")))
#else
#define PAPS_AVX2_CLONE
#endif
PAPS_LANES_INLINE FV splat(float v) { return FV{v, v, v, v, v, v, v, v}; }
PAPS_LANES_INLINE FV loadv(const float* p) { FV v; std::memcpy(&v, p, sizeof v); return v; }
PAPS_LANES_INLINE void storev(float* p, FV v) { std::memcpy(p, &v, sizeof v); }
PAPS_LANES_INLINE float hsum(FV v) { return ((v[0] + v[1]) + (v[2] + v[3])) + ((v[4] + v[5]) + (v[6] + v[7])); }
// expNeg on each lane (the same operations lane by lane).
PAPS_LANES_INLINE FV expNegV(FV x) {
  x = x < splat(80.f) ? x : splat(80.f);
  const FV y = -x * 1.44269504089f;
  const IV i = __builtin_convertvector(y, IV);  // toward zero
  const FV z = (y - __builtin_convertvector(i, FV)) * 0.69314718056f;
  const FV p = 1.f + z * (1.f + z * (0.5f + z * (1.f / 6 + z * (1.f / 24 + z * (1.f / 120 + z * (1.f / 720))))));
  const IV bits = (i + 127) << 23;
  return p * (FV)bits;
}

// The neighbours (with a finite normal) of one input point in arrays, positions relative to
// that point and in units of the kernel support h: what the projections of all the seeds
// generated from it read. The arrays are padded to a multiple of kLanes with points far beyond
// h (weight 0 seen from any seed) and zero normals.
struct Block {
  std::vector<float> x, y, z, nx, ny, nz, alpha;
  // At the origin (the block's input point), per neighbour: t = 1 - |d|^2 (0 beyond h; the
  // Wendland weight is t^4) and fx = d.n, with d = -(x, y, z).
  std::vector<float> t, fx;
  int n = 0;       // neighbours
  int padded = 0;  // n rounded up to a multiple of kLanes
  // Neighbours within `within` h of o only.
  void gather(const Positions& p, const Normals& nrm, const int* nb, int count, const Eigen::Vector3f& o, float inv_h,
              float within) {
    const float w2 = within * within;
    const std::size_t cap = static_cast<std::size_t>(count) + kLanes;
    if (x.size() < cap) {
      for (auto* v : {&x, &y, &z, &nx, &ny, &nz, &alpha, &t, &fx}) v->resize(cap);
    }
    n = 0;
    for (int k = 0; k < count; ++k) {
      const int j = nb[k];
      if (!isFinite(nrm[j])) continue;
      const Eigen::Vector3f d = (p[j] - o) * inv_h;
      if (d.squaredNorm() > w2) continue;
      x[n] = d.x(); y[n] = d.y(); z[n] = d.z();
      nx[n] = nrm[j].x(); ny[n] = nrm[j].y(); nz[n] = nrm[j].z();
      ++n;
    }
    padded = (n + kLanes - 1) / kLanes * kLanes;
    for (int k = n; k < padded; ++k) {
      x[k] = 1e4f; y[k] = z[k] = 0.f;
      nx[k] = ny[k] = nz[k] = 0.f;
      alpha[k] = 0.f;
    }
  }
};

// APSS: the algebraic sphere u0 + u.x + u4 |x|^2 fitted with normal constraints around q
// (closed form of Guennebaud and Gross 2007, beta = 1), in the block's units, relative to q.
struct Sphere {
  Eigen::Vector3f centre = Eigen::Vector3f::Zero();  // the point the fit is relative to (block units)
  double u0 = 0, u4 = 0;
  Eigen::Vector3d u = Eigen::Vector3d::Zero();
  bool ok = false;
  // Projection of x (block units, near centre) on the sphere.
  bool project(const Eigen::Vector3f& xq, Eigen::Vector3f& out) const {
    const Eigen::Vector3d x0 = (xq - centre).cast<double>();
    Eigen::Vector3d x;
    if (std::abs(u4) < 1e-6) {
      const double un2 = u.squaredNorm();
      if (!(un2 > 0)) return false;
      x = x0 - (u0 + u.dot(x0) + u4 * x0.squaredNorm()) / un2 * u;
    } else {
      const Eigen::Vector3d c = -u / (2 * u4);
      const double r2 = c.squaredNorm() - u0 / u4;
      const Eigen::Vector3d d = x0 - c;
      if (!(r2 > 0) || !(d.norm() > 0)) return false;
      x = c + std::sqrt(r2) * d / d.norm();
    }
    out = centre + x.cast<float>();
    return out.allFinite();
  }
  // Gradient of u0 + u.x + u4 |x|^2 at p (block units): the normal there, oriented as the
  // input normals the fit was constrained by.
  Eigen::Vector3f gradient(const Eigen::Vector3f& p) const {
    return (u + 2 * u4 * (p - centre).cast<double>()).cast<float>();
  }
};

PAPS_AVX2_CLONE __attribute__((noinline)) Sphere fitSphere(const Block& b, const Eigen::Vector3f& q) {
  Sphere s;
  s.centre = q;
  const FV zero = splat(0.f);
  FV vw = zero, vpx = zero, vpy = zero, vpz = zero, vnx = zero, vny = zero, vnz = zero, vpn = zero, vpp = zero,
     vused = zero;
  const float *X = b.x.data(), *Y = b.y.data(), *Z = b.z.data(), *NX = b.nx.data(), *NY = b.ny.data(), *NZ = b.nz.data();
  for (int k = 0; k < b.padded; k += kLanes) {  // the padding is far away: weight 0
    const FV dx = loadv(X + k) - q.x(), dy = loadv(Y + k) - q.y(), dz = loadv(Z + k) - q.z();
    const FV nx = loadv(NX + k), ny = loadv(NY + k), nz = loadv(NZ + k);
    const FV d2 = dx * dx + dy * dy + dz * dz;
    const IV inside = d2 < splat(1.f);
    const FV t = inside ? 1.f - d2 : zero;
    const FV t2 = t * t, w = t2 * t2;
    vw += w;
    vpx += w * dx; vpy += w * dy; vpz += w * dz;
    vnx += w * nx; vny += w * ny; vnz += w * nz;
    vpn += w * (dx * nx + dy * ny + dz * nz);
    vpp += w * d2;
    vused += inside ? splat(1.f) : zero;
  }
  const float sw = hsum(vw), spx = hsum(vpx), spy = hsum(vpy), spz = hsum(vpz), snx = hsum(vnx), sny = hsum(vny),
              snz = hsum(vnz), spn = hsum(vpn), spp = hsum(vpp);
  const int used = static_cast<int>(hsum(vused));
  if (used < 4 || !(sw > 0)) return s;
  const Eigen::Vector3d mp = Eigen::Vector3d(spx, spy, spz) / sw, mn = Eigen::Vector3d(snx, sny, snz) / sw;
  const double den = double(spp) / sw - mp.squaredNorm();
  s.u4 = den > 1e-9 ? 0.5 * (double(spn) / sw - mp.dot(mn)) / den : 0.0;
  s.u = mn - 2 * s.u4 * mp;
  s.u0 = -s.u.dot(mp) - s.u4 * double(spp) / sw;
  s.ok = std::isfinite(s.u0) && std::isfinite(s.u4) && s.u.allFinite();
  return s;
}

// RIMLS (Oztireli et al. 2009): robust implicit MLS with residual and normal reweighting
// (sigma_r in units of h); one step f / |grad f|^2 along grad f from q (block units).
enum class Alpha { One, Robust, Frozen };

template <Alpha A>
__attribute__((noinline)) void rimlsSums(const Block& b, const Eigen::Vector3f& q, float f, const Eigen::Vector3f& g, float inv_sr2,
                      float inv_sn2, float* S) {
  const float* AL = b.alpha.data();
  float sw = 0, sf = 0, gwx = 0, gwy = 0, gwz = 0, gfx = 0, gfy = 0, gfz = 0, snx = 0, sny = 0, snz = 0;
  const float qx = q.x(), qy = q.y(), qz = q.z(), gx = g.x(), gy = g.y(), gz = g.z();
  const float *X = b.x.data(), *Y = b.y.data(), *Z = b.z.data(), *NX = b.nx.data(), *NY = b.ny.data(), *NZ = b.nz.data();
#pragma omp simd reduction(+ : sw, sf, gwx, gwy, gwz, gfx, gfy, gfz, snx, sny, snz)
  for (int k = 0; k < b.n; ++k) {
    const float dx = qx - X[k], dy = qy - Y[k], dz = qz - Z[k];
    const float d2 = dx * dx + dy * dy + dz * dz;
    const float t = d2 < 1.f ? 1.f - d2 : 0.f;
    const float fx = dx * NX[k] + dy * NY[k] + dz * NZ[k];
    float alpha = 1.f;
    if (A == Alpha::Robust) {
      const float rr = fx - f, ex = NX[k] - gx, ey = NY[k] - gy, ez = NZ[k] - gz;
      alpha = expNeg(rr * rr * inv_sr2 + (ex * ex + ey * ey + ez * ez) * inv_sn2);
    } else if (A == Alpha::Frozen) {
      alpha = AL[k];
    }
    const float t3 = t * t * t;
    const float w = alpha * t3 * t, gw = -8.f * alpha * t3;
    sw += w; sf += w * fx;
    gwx += gw * dx; gwy += gw * dy; gwz += gw * dz;
    gfx += gw * dx * fx; gfy += gw * dy * fx; gfz += gw * dz * fx;
    snx += w * NX[k]; sny += w * NY[k]; snz += w * NZ[k];
  }
  S[0] = sw; S[1] = sf; S[2] = gwx; S[3] = gwy; S[4] = gwz; S[5] = gfx; S[6] = gfy; S[7] = gfz; S[8] = snx; S[9] = sny; S[10] = snz;
}

// One RIMLS step from q. With `frozen`, the robust weights are the block's `alpha` (those
// converged at the block's input point) and there is a single pass.
bool rimlsStep(const Block& b, const Eigen::Vector3f& q, float sigma_r, float sigma_n, int inner, bool frozen,
               Eigen::Vector3f& out, float* f_out = nullptr, Eigen::Vector3f* grad_out = nullptr) {
  const float inv_sr2 = 1.f / (sigma_r * sigma_r), inv_sn2 = 1.f / (sigma_n * sigma_n);
  float f = 0;
  Eigen::Vector3f grad = Eigen::Vector3f::Zero();
  float S[11];
  for (int it = 0; it < (frozen ? 1 : inner); ++it) {
    if (frozen) rimlsSums<Alpha::Frozen>(b, q, f, grad, inv_sr2, inv_sn2, S);
    else if (it == 0) rimlsSums<Alpha::One>(b, q, f, grad, inv_sr2, inv_sn2, S);
    else rimlsSums<Alpha::Robust>(b, q, f, grad, inv_sr2, inv_sn2, S);
    if (!(S[0] > 1e-12f)) return false;
    const float f_new = S[1] / S[0];
    grad = (Eigen::Vector3f(S[5], S[6], S[7]) - f_new * Eigen::Vector3f(S[2], S[3], S[4]) + Eigen::Vector3f(S[8], S[9], S[10])) / S[0];
    const bool done = it > 0 && std::abs(f_new - f) < 1e-4f;
    f = f_new;
    if (done) break;
  }
  if (f_out) *f_out = f;
  if (grad_out) *grad_out = grad;
  const float g2 = grad.squaredNorm();
  if (!(g2 > 1e-12f)) return false;
  out = q - f * grad / g2;
  return out.allFinite();
}

// The RIMLS function with the block's frozen weights, to second order about the origin (the
// block's input point): f(q) ~ f0 + g.q + q'Hq / 2. One pass over the neighbours per input
// point instead of one per seed, used for the seeds within kTaylorReach h of the origin, where
// the expansion differs from the function by third-order terms (on the bench's plane, 70K ->
// 700K at 0.01% noise: error 8.518e-4 instead of 8.511e-4); seeds farther out (wide discs)
// take the exact step.
constexpr float kTaylorReach = 0.25f;
struct RimlsQuadratic {
  float f0 = 0;
  Eigen::Vector3f g = Eigen::Vector3f::Zero();
  Eigen::Matrix3f H = Eigen::Matrix3f::Zero();
  // One step f / |grad f|^2 along grad f from q, as rimlsStep does on the function itself.
  bool project(const Eigen::Vector3f& q, Eigen::Vector3f& out) const {
    const Eigen::Vector3f Hq = H * q;
    const Eigen::Vector3f gq = g + Hq;
    const float fq = f0 + g.dot(q) + 0.5f * q.dot(Hq);
    const float g2 = gq.squaredNorm();
    if (!(g2 > 1e-12f)) return false;
    out = q - fq * gq / g2;
    return out.allFinite();
  }
  Eigen::Vector3f gradient(const Eigen::Vector3f& q) const { return g + H * q; }
};

// RIMLS at the block's own input point (the origin), where the Wendland factors and the
// residuals fx do not change from one reweighting to the next (computed first): the
// reweighting iterations (the first with alpha = 1, as rimlsStep), then, in one more pass, the
// robust weights alpha converged there (kept in b.alpha for the exact steps of far seeds) and
// the value, gradient and Hessian at the origin of f = sum(w fx) / sum(w) with those frozen
// weights: w = alpha t^4 with t = 1 - |d|^2 (d = x - p_k), fx = d.n_k; grad w = -8 alpha t^3 d,
// hess w = alpha (48 t^2 d d' - 8 t^3 I); grad f = (grad Sf - f grad Sw) / Sw; hess f = (hess Sf -
// f hess Sw - grad Sw grad f' - grad f grad Sw') / Sw. Returns false (origin unusable) when
// the weights vanish or the gradient does; quad_ok tells whether the expansion is finite.
PAPS_AVX2_CLONE __attribute__((noinline)) bool fitRimlsAtOrigin(Block& b, float sigma_r, float sigma_n, int inner,
                                                RimlsQuadratic& quad, bool& quad_ok) {
  quad_ok = false;
  // t and fx at the origin (the padding gets t = 0).
  for (int k = 0; k < b.padded; k += kLanes) {
    const FV X = loadv(&b.x[k]), Y = loadv(&b.y[k]), Z = loadv(&b.z[k]);
    const FV d2 = X * X + Y * Y + Z * Z;
    storev(&b.t[k], d2 < splat(1.f) ? 1.f - d2 : splat(0.f));
    storev(&b.fx[k], -(X * loadv(&b.nx[k]) + Y * loadv(&b.ny[k]) + Z * loadv(&b.nz[k])));
  }
  const float inv_sr2 = 1.f / (sigma_r * sigma_r), inv_sn2 = 1.f / (sigma_n * sigma_n);
  const int np = b.padded;
  const float *X = b.x.data(), *Y = b.y.data(), *Z = b.z.data(), *NX = b.nx.data(), *NY = b.ny.data(),
              *NZ = b.nz.data(), *T = b.t.data(), *FX = b.fx.data();
  float f = 0, gx = 0, gy = 0, gz = 0;
  for (int it = 0; it < inner; ++it) {
    const FV zero = splat(0.f);
    FV sw = zero, sf = zero, gwx = zero, gwy = zero, gwz = zero, gfx = zero, gfy = zero, gfz = zero, snx = zero,
       sny = zero, snz = zero;
    const bool robust = it > 0;
    for (int k = 0; k < np; k += kLanes) {
      const FV nx = loadv(NX + k), ny = loadv(NY + k), nz = loadv(NZ + k), fk = loadv(FX + k), tk = loadv(T + k);
      FV t3 = tk * tk * tk;
      if (robust) {
        const FV rr = fk - f, ex = nx - gx, ey = ny - gy, ez = nz - gz;
        t3 *= expNegV(rr * rr * inv_sr2 + (ex * ex + ey * ey + ez * ez) * inv_sn2);  // alpha t^3
      }
      const FV w = t3 * tk, gw = 8.f * t3;  // grad w = -8 alpha t^3 d, d = -(x, y, z)
      const FV gwX = gw * loadv(X + k), gwY = gw * loadv(Y + k), gwZ = gw * loadv(Z + k);
      sw += w; sf += w * fk;
      gwx += gwX; gwy += gwY; gwz += gwZ;
      gfx += gwX * fk; gfy += gwY * fk; gfz += gwZ * fk;
      snx += w * nx; sny += w * ny; snz += w * nz;
    }
    const float Sw = hsum(sw);
    if (!(Sw > 1e-12f)) return false;
    const float f_new = hsum(sf) / Sw;
    gx = (hsum(gfx) - f_new * hsum(gwx) + hsum(snx)) / Sw;
    gy = (hsum(gfy) - f_new * hsum(gwy) + hsum(sny)) / Sw;
    gz = (hsum(gfz) - f_new * hsum(gwz) + hsum(snz)) / Sw;
    const bool done = it > 0 && std::abs(f_new - f) < 1e-4f;
    f = f_new;
    if (done) break;
  }
  const float g2 = gx * gx + gy * gy + gz * gz;
  if (!(g2 > 1e-12f) || !std::isfinite(f / g2)) return false;
  // Frozen weights and the expansion, in one pass. hess Sw = 48 A2 - 8 A3 I, hess Sf = 48 B2 -
  // 8 B3 I + C with A2 = sum(alpha t^2 d d'), A3 = sum(alpha t^3), B2, B3 the same times fx,
  // C = sum(gw n' + n gw') (symmetric matrices as xx, yy, zz, xy, xz, yz).
  float* AL = b.alpha.data();
  const FV zero = splat(0.f);
  FV sw = zero, sf = zero, gsx = zero, gsy = zero, gsz = zero, gfx = zero, gfy = zero, gfz = zero, a3 = zero,
     b3 = zero;
  FV axx = zero, ayy = zero, azz = zero, axy = zero, axz = zero, ayz = zero;
  FV bxx = zero, byy = zero, bzz = zero, bxy = zero, bxz = zero, byz = zero;
  FV cxx = zero, cyy = zero, czz = zero, cxy = zero, cxz = zero, cyz = zero;
  for (int k = 0; k < np; k += kLanes) {
    const FV nx = loadv(NX + k), ny = loadv(NY + k), nz = loadv(NZ + k), fk = loadv(FX + k), tk = loadv(T + k);
    const FV rr = fk - f, ex = nx - gx, ey = ny - gy, ez = nz - gz;
    const FV a = expNegV(rr * rr * inv_sr2 + (ex * ex + ey * ey + ez * ez) * inv_sn2);
    storev(AL + k, a);
    const FV dx = -loadv(X + k), dy = -loadv(Y + k), dz = -loadv(Z + k);
    const FV at2 = a * tk * tk, at3 = at2 * tk, w = at3 * tk;
    const FV gwx = -8.f * at3 * dx, gwy = -8.f * at3 * dy, gwz = -8.f * at3 * dz;
    sw += w; sf += w * fk;
    gsx += gwx; gsy += gwy; gsz += gwz;
    gfx += gwx * fk + w * nx; gfy += gwy * fk + w * ny; gfz += gwz * fk + w * nz;
    a3 += at3; b3 += at3 * fk;
    const FV pxx = at2 * dx * dx, pyy = at2 * dy * dy, pzz = at2 * dz * dz, pxy = at2 * dx * dy, pxz = at2 * dx * dz,
             pyz = at2 * dy * dz;
    axx += pxx; ayy += pyy; azz += pzz; axy += pxy; axz += pxz; ayz += pyz;
    bxx += pxx * fk; byy += pyy * fk; bzz += pzz * fk; bxy += pxy * fk; bxz += pxz * fk; byz += pyz * fk;
    cxx += 2.f * gwx * nx; cyy += 2.f * gwy * ny; czz += 2.f * gwz * nz;
    cxy += gwx * ny + nx * gwy; cxz += gwx * nz + nx * gwz; cyz += gwy * nz + ny * gwz;
  }
  const double Sw = hsum(sw);
  if (!(Sw > 1e-12)) return false;
  const double f0 = hsum(sf) / Sw, A3 = hsum(a3), B3 = hsum(b3);
  const Eigen::Vector3d gsw(hsum(gsx), hsum(gsy), hsum(gsz));
  const Eigen::Vector3d gf = (Eigen::Vector3d(hsum(gfx), hsum(gfy), hsum(gfz)) - f0 * gsw) / Sw;
  const double Axx = hsum(axx), Ayy = hsum(ayy), Azz = hsum(azz), Axy = hsum(axy), Axz = hsum(axz), Ayz = hsum(ayz);
  const double Bxx = hsum(bxx), Byy = hsum(byy), Bzz = hsum(bzz), Bxy = hsum(bxy), Bxz = hsum(bxz), Byz = hsum(byz);
  const double Cxx = hsum(cxx), Cyy = hsum(cyy), Czz = hsum(czz), Cxy = hsum(cxy), Cxz = hsum(cxz), Cyz = hsum(cyz);
  Eigen::Matrix3d hsw, hsf;
  hsw << 48 * Axx - 8 * A3, 48 * Axy, 48 * Axz, 48 * Axy, 48 * Ayy - 8 * A3, 48 * Ayz, 48 * Axz, 48 * Ayz,
      48 * Azz - 8 * A3;
  hsf << 48 * Bxx - 8 * B3 + Cxx, 48 * Bxy + Cxy, 48 * Bxz + Cxz, 48 * Bxy + Cxy, 48 * Byy - 8 * B3 + Cyy,
      48 * Byz + Cyz, 48 * Bxz + Cxz, 48 * Byz + Cyz, 48 * Bzz - 8 * B3 + Czz;
  const Eigen::Matrix3d hf = (hsf - f0 * hsw - gsw * gf.transpose() - gf * gsw.transpose()) / Sw;
  quad.f0 = static_cast<float>(f0);
  quad.g = gf.cast<float>();
  quad.H = hf.cast<float>();
  quad_ok = std::isfinite(quad.f0) && quad.g.allFinite() && quad.H.allFinite();
  return true;
}

}  // namespace

namespace {
// No kernel anywhere holds 3 distinct points off a line.
[[noreturn]] void throwNoNormalAnywhere(const MlsUpsamplingParameters& params, float h) {
  if (params.radius > 0)
    throw InvalidParameter("radius", detail::toString(h),
                           "a kernel support holding at least 3 points around some point (none does: no normal)");
  // The automatic support holds the target count, so its balls are all copies or lines.
  throw InvalidInput("no ball of the automatic kernel support " + detail::toString(h) +
                     " m holds 3 distinct points off a line (no normal anywhere): the cloud is piles of copies "
                     "or lines; give a radius wide enough to reach other positions");
}

// The radius of the lists of projections refitted at every seed: past h by about the seed
// disc at the target count, then by the disc actually used when it is wider (sparser than the
// target count at a user radius).
float firstListReach(float h, int target_neighbours) {
  return h * (1.1f + 1.5f / std::sqrt(static_cast<float>(target_neighbours)));
}
float kernelListReach(float h, float disc, int target_neighbours) {
  return std::max(firstListReach(h, target_neighbours), 1.05f * h + disc);
}

// What a tile adds to a run (upsampleInTiles): the kernel support and the seed disc, chosen on
// the whole cloud; in the tile's order, which points seed the output (its core) and the
// normals of the tiles before it where it meets them (NaN elsewhere); what those tiles output
// near it (its seeds keep their distance); out, its oriented normals, or that no ball of it
// has a normal (nothing made).
struct MlsTileRun {
  float h = 0.f, disc = 0.f;
  std::vector<std::uint8_t> seedable;
  Normals hints;
  Positions kept_before;
  Normals oriented;
  bool no_normal = false;
};

Positions upsampleInSpatialOrder(const Positions& points, MlsSurface surface, const MlsUpsamplingParameters& params,
                                 MlsUpsamplingReport* report, const ProgressCallback& progress, Normals* normals_out,
                                 std::vector<float>* curvature_out, std::vector<int>* source_out,
                                 MlsTileRun* tile = nullptr) {
  const std::size_t finite = countFinite(points);
  // A tile with nothing to fit hands its share on; the whole cloud was checked.
  auto nothingHere = [&] {
    tile->no_normal = true;
    return Positions();
  };
  if (finite < 3) {
    if (tile) return nothingHere();
    throw InvalidInput("APSS/RIMLS need at least 3 finite points (got " + detail::toString(finite) + ")");
  }
  // A tile's share follows the surface it covers, and its support was checked on the whole.
  if (!tile) {
    checkOutputCount(params.output_count, finite);
    requireRadiusWithinExtent("radius", params.radius, points);
  }
  // Kernel support h, then neighbour lists reaching past h by the seed disc radius, so that
  // the lists of an input point hold every point within h of the seeds generated from it.
  float h = tile ? tile->h : params.radius;
  if (h <= 0) {

    const SpatialIndex index(points);
    h = radiusForNeighbourCount(points, index, params.target_neighbours, NeighbourCountStatistic::Median);
  }
  const bool per_point = params.fit_per_input_point;
  const bool apss = surface == MlsSurface::Apss;
  // Fitted once per input point, APSS and RIMLS read the neighbours within h of that point
  // only (for RIMLS this drops points within h of a seed but farther than h from its input
  // point: their Wendland weight is below 0.03 of the largest, and the bench errors move by
  // less than 0.1%): the lists at h serve for everything. Refitted at every seed, the
  // projections read past h by the seed disc.
  const bool only_h = per_point;
  float reach = tile ? kernelListReach(h, tile->disc, params.target_neighbours) : firstListReach(h, params.target_neighbours);
  // Grid neighbour lists (core CellGrid): on scanned surfaces several times faster than
  // kd-tree radius searches, which dominated the cost of the whole upsampling.
  // Lists capped at the nearest max_neighbours (the same lists as uncapped where no ball holds
  // more).
  const int cap = params.max_neighbours > 0 ? params.max_neighbours : 16 * params.target_neighbours;
  // Mostly copies (3 points in 4 or more): the distinct positions are looked at first. A
  // kernel's capped list holds copies besides its distinct positions, which are among the cap
  // nearest distinct ones: when none of those lists has a normal, no kernel list can, and the
  // cloud is refused before the lists of copies are built (1M points on 20 positions: 6 s and
  // 3.9 GB before the same error).
  std::size_t copies = 0;
  const std::vector<int> first = exactDuplicateRepresentatives(points, &copies);
  if (copies * 4 >= finite * 3) {
    const Positions distinct = distinctPositions(points, first);
    const Normals n = estimateNormals(distinct, gridRadiusGraph(distinct, h, {}, cap));
    if (std::none_of(n.begin(), n.end(), [](const Eigen::Vector3f& v) { return isFinite(v); })) {
      if (tile) return nothingHere();
      throwNoNormalAnywhere(params, h);
    }
  }
  NeighbourGraph graph_ext, graph_h;
  if (only_h) {
    graph_h = gridRadiusGraph(points, h, {}, cap);
  } else {
    graph_ext = gridRadiusGraph(points, reach, {}, cap);
    graph_h = restrictedGraph(points, graph_ext, h);
  }
  const double mean_count = std::max(1.0, graph_h.meanCount());
  const float disc = tile ? tile->disc : h / std::sqrt(static_cast<float>(mean_count)) * 1.2f * params.disc_scale;
  if (!only_h && reach < kernelListReach(h, disc, params.target_neighbours)) {
    reach = kernelListReach(h, disc, params.target_neighbours);
    graph_ext = gridRadiusGraph(points, reach, {}, cap);
  }
  auto seeds = [&](std::size_t i) { return !tile || tile->seedable[i]; };
  std::size_t capped = 0, capped_seeding = 0;
  {
    const NeighbourGraph& g = only_h ? graph_h : graph_ext;
    for (std::size_t i = 0; i < g.size(); ++i)
      if (g.count(i) >= cap) ++capped, capped_seeding += seeds(i);
  }
  const NeighbourGraph& lists = only_h ? graph_h : graph_ext;
  std::vector<float> variation;
  Normals normals = estimateNormals(points, graph_h, curvature_out ? &variation : nullptr);
  const std::size_t np = points.size();
  bool seeding_normal = false;
  for (std::size_t i = 0; i < np && !seeding_normal; ++i) seeding_normal = seeds(i) && isFinite(normals[i]);
  if (!seeding_normal) {
    if (tile) return nothingHere();
    throwNoNormalAnywhere(params, h);
  }
  orientNormalsByPropagation(points, normals, graph_h);
  // Only the core seeds in a tile (NaN normals spawn nothing); the halo is read by the fits.
  Normals core_normals;
  if (tile) {
    turnComponentsToHints(normals, graph_h, tile->hints);
    tile->oriented = normals;
    core_normals = normals;
    for (std::size_t i = 0; i < np; ++i)
      if (!seeds(i)) core_normals[i] = Eigen::Vector3f::Constant(NAN);
  }
  const std::size_t count = params.output_count ? params.output_count
                                                : static_cast<std::size_t>(std::llround(params.factor * finite));
  std::vector<int> origin;
  // The lists are complete (and spare the thinner its grid) unless a ball was over the cap.
  Positions out = upsamplingSeeds(points, tile ? core_normals : normals, count, disc, params.seed, &origin,
                                  capped ? nullptr : &lists, only_h ? h : reach, nullptr,
                                  tile ? &tile->kept_before : nullptr);
  Normals().swap(core_normals);
  // Seeds grouped by the input point they were generated from.
  std::vector<std::int64_t> soff(np + 1, 0);
  for (const int o : origin) ++soff[o + 1];
  for (std::size_t i = 0; i < np; ++i) soff[i + 1] += soff[i];
  std::vector<int> slist(out.size());
  {
    std::vector<std::int64_t> cur(soff.begin(), soff.end() - 1);
    for (std::size_t s = 0; s < origin.size(); ++s) slist[cur[origin[s]]++] = static_cast<int>(s);
  }
  std::size_t unprojected = 0;
  if (normals_out) normals_out->assign(out.size(), Eigen::Vector3f::Constant(NAN));
  if (curvature_out) {  // PCL's MLS: the surface variation of the ball a point was made from
    curvature_out->resize(out.size());
    for (std::size_t s = 0; s < out.size(); ++s) (*curvature_out)[s] = variation[origin[s]];
  }
  if (source_out) *source_out = origin;
  const float inv_h = 1.f / h;
  // What the projections read, in units of h: the sphere at the input point reads its
  // neighbours within h; a projection at a seed (within disc of its input point) those within
  // h of the seed; refitted projections may move a little further.
  const float gather_within = only_h ? 1.f : per_point ? 1.f + disc / h : reach / h;
  ProgressReporter rep(progress, surface == MlsSurface::Apss ? "APSS projection" : "RIMLS projection", out.size());
#pragma omp parallel reduction(+ : unprojected)
  {
    Block b;
#pragma omp for schedule(dynamic, 64)
    for (std::int64_t o = 0; o < static_cast<std::int64_t>(np); ++o) {
      const std::int64_t s0 = soff[o], s1 = soff[o + 1];
      if (s0 == s1 || rep.cancelled()) continue;
      const Eigen::Vector3f& po = points[o];
      b.gather(points, normals, lists.begin(o), lists.count(o), po, inv_h, gather_within);
      Sphere sphere;
      bool origin_ok = true;
      if (per_point && apss) sphere = fitSphere(b, Eigen::Vector3f::Zero()), origin_ok = sphere.ok;
      RimlsQuadratic quad;
      bool quad_ok = false;
      if (per_point && !apss) {
        origin_ok = fitRimlsAtOrigin(b, params.sigma_r, params.sigma_n, params.inner_iterations, quad, quad_ok);
      }
      for (std::int64_t k = s0; k < s1; ++k) {
        const int s = slist[k];
        Eigen::Vector3f q = (out[s] - po) * inv_h, next, grad = Eigen::Vector3f::Constant(NAN);
        bool ok = origin_ok;
        if (per_point && apss) {
          ok = ok && sphere.project(q, next);
          if (ok) q = next, grad = sphere.gradient(q);
        } else if (per_point && quad_ok && q.squaredNorm() <= kTaylorReach * kTaylorReach) {
          ok = quad.project(q, next);
          if (ok) q = next, grad = quad.gradient(q);
        } else {
          for (int it = 0; it < params.iterations && ok; ++it) {
            if (apss) {
              const Sphere sp = fitSphere(b, q);
              ok = sp.ok && sp.project(q, next);
              if (ok) grad = sp.gradient(next);
            } else {
              // The gradient at the step's start: one step from near the surface, so within
              // the step's length of the projected point's.
              ok = rimlsStep(b, q, params.sigma_r, params.sigma_n, params.inner_iterations, per_point, next, nullptr,
                             &grad);
            }
            if (!ok) break;
            const float step = (next - q).norm();
            q = next;
            if (step < 1e-4f) break;
          }
        }
        if (ok) {
          out[s] = po + q * h;
          if (normals_out) (*normals_out)[s] = grad.norm() > 0 ? Eigen::Vector3f(grad.normalized()) : grad;
        } else {  // the seed stays on its input point's tangent disc: that plane's normal
          ++unprojected;
          if (normals_out) (*normals_out)[s] = normals[o];
        }
      }
      rep.advance(static_cast<std::size_t>(s1 - s0));
    }
  }
  rep.throwIfCancelled();
  rep.finish();
  if (report) {
    report->radius = h;
    report->output = out.size();
    report->unprojected = unprojected;
    report->capped = capped_seeding;
    report->tiles = 1;
    report->largest_tile = np;
    report->max_neighbours = cap;
    report->disc_radius = disc;
  }
  return out;
}

// The tiled run (max_tile_points): the kernel support and the seed disc are chosen on the
// whole cloud, as one piece chooses them; each tile then fits its core and halo, seeds from its
// core only, and orients its normals as the tiles before it did where they meet. The halo
// holds every point the core's fits read and the points their normals were estimated from.
Positions upsampleInTiles(const Positions& points, MlsSurface surface, const MlsUpsamplingParameters& params,
                          MlsUpsamplingReport* report, const ProgressCallback& progress, Normals* normals_out,
                          std::vector<float>* curvature_out, std::vector<int>* source_out) {
  const std::size_t finite = countFinite(points);
  checkOutputCount(params.output_count, finite);
  requireRadiusWithinExtent("radius", params.radius, points);
  const int cap = params.max_neighbours > 0 ? params.max_neighbours : 16 * params.target_neighbours;
  float h = params.radius;
  double mean_count = 0;
  {
    // On the cloud in spatial order, as one piece measures it (the radius's samples are drawn
    // along the array): the same h. The disc follows the mean count of a spread sample where
    // one piece takes the mean of its lists.
    const Positions sorted = gathered(points, spatialOrderAll(points));
    const SpatialIndex index(sorted);
    if (h <= 0) h = radiusForNeighbourCount(sorted, index, params.target_neighbours, NeighbourCountStatistic::Median);
    mean_count = std::max(1.0, sampledMeanNeighbourCount(sorted, index, h, cap, 20000));
  }
  MlsTileRun base;
  base.h = h;
  base.disc = h / std::sqrt(static_cast<float>(mean_count)) * 1.2f * params.disc_scale;
  const float lists = params.fit_per_input_point ? h : kernelListReach(h, base.disc, params.target_neighbours);
  const std::vector<Tile> tiles = splitIntoTiles(points, params.max_tile_points, 1.01f * (lists + h));
  const std::size_t total = params.output_count ? params.output_count
                                                : static_cast<std::size_t>(std::llround(params.factor * finite));
  // The oriented normals of the core points of the tiles done so far: the hints of the next.
  Normals oriented(points.size(), Eigen::Vector3f::Constant(NAN));
  Positions out;
  if (normals_out) normals_out->clear();
  if (curvature_out) curvature_out->clear();
  if (source_out) source_out->clear();
  MlsUpsamplingParameters run = params;
  run.max_tile_points = 0;
  std::vector<MlsUpsamplingReport> reports(tiles.size());
  std::vector<std::size_t> starts(tiles.size(), 0);
  std::size_t largest = 0;
  const float spacing = h * std::sqrt(3.14159265f / static_cast<float>(mean_count));  // the mean input spacing
  std::vector<BoundingBox> boxes;
  for (const Tile& t : tiles) boxes.push_back(boundingBox(points, t.core));
  auto runTile = [&](std::size_t t, std::size_t count) {
    const Tile& tile = tiles[t];
    std::vector<int> members(tile.core);
    members.insert(members.end(), tile.halo.begin(), tile.halo.end());
    largest = std::max(largest, members.size());
    // In spatial order, as one piece runs.
    std::vector<int> sorted = spatialOrderAll(gathered(points, members));
    MlsTileRun tr = base;
    tr.seedable.resize(sorted.size());
    for (std::size_t k = 0; k < sorted.size(); ++k) {
      tr.seedable[k] = static_cast<std::size_t>(sorted[k]) < tile.core.size();
      sorted[k] = members[static_cast<std::size_t>(sorted[k])];
    }
    std::vector<int>().swap(members);
    tr.hints = gathered(oriented, sorted);
    // Seeds lie within the disc of a core point, and keep the Poisson-disk radius (about the
    // output spacing, below the input's) from what the tiles before made.
    tr.kept_before = pointsNearBox(out, boxes[t], base.disc + 2.f * spacing);
    run.output_count = count;
    run.seed = params.seed + t;  // each tile draws its own seeds
    Normals n;
    std::vector<float> c;
    std::vector<int> src;
    const Positions o = upsampleInSpatialOrder(gathered(points, sorted), surface, run, &reports[t],
                                               tileProgress(progress, t, tiles.size()), normals_out ? &n : nullptr,
                                               curvature_out ? &c : nullptr, source_out ? &src : nullptr, &tr);
    if (tr.no_normal) return false;
    for (std::size_t k = 0; k < sorted.size(); ++k)
      if (tr.seedable[k]) oriented[static_cast<std::size_t>(sorted[k])] = tr.oriented[k];
    starts[t] = out.size();
    out.insert(out.end(), o.begin(), o.end());
    if (normals_out) normals_out->insert(normals_out->end(), n.begin(), n.end());
    if (curvature_out) curvature_out->insert(curvature_out->end(), c.begin(), c.end());
    if (source_out)
      for (const int k : src) source_out->push_back(sorted[static_cast<std::size_t>(k)]);
    return true;
  };
  // Each tile's share of the output (runTileShares), by the surface its core covers, counted
  // in cells of the mean spacing or the seed disc, the larger.
  const float cell = std::max(base.disc, spacing);
  std::vector<std::size_t> cells;
  for (const Tile& t : tiles) cells.push_back(occupiedCells(points, t.core, cell));
  const std::vector<std::size_t> made = runTileShares(splitInProportion(total, cells), runTile, [&](std::size_t t) {
    out.resize(starts[t]);
    if (normals_out) normals_out->resize(starts[t]);
    if (curvature_out) curvature_out->resize(starts[t]);
    if (source_out) source_out->resize(starts[t]);
  });
  if (made.empty()) throwNoNormalAnywhere(params, h);
  // The tiles' orientation runs on from the first tile, whose pieces were turned up on their
  // own; the whole is turned as one piece turns a connected cloud.
  if (normals_out && upwardSign(points, oriented) < 0)
    for (Eigen::Vector3f& n : *normals_out) n = -n;
  if (report) {
    MlsUpsamplingReport rep;
    rep.radius = h;
    rep.output = out.size();
    rep.max_neighbours = cap;
    rep.disc_radius = base.disc;
    rep.tiles = tiles.size();
    rep.largest_tile = largest;
    for (const std::size_t t : made) {
      rep.unprojected += reports[t].unprojected;
      rep.capped += reports[t].capped;
    }
    *report = rep;
  }
  return out;
}
}  // namespace

Positions upsampleMls(const Positions& points, MlsSurface surface, const MlsUpsamplingParameters& params,
                      MlsUpsamplingReport* report, const ProgressCallback& progress, Normals* normals,
                      std::vector<float>* curvature, std::vector<int>* source) {
  params.validate();
  if (params.max_tile_points > 0 && countFinite(points) > params.max_tile_points)
    return upsampleInTiles(points, surface, params, report, progress, normals, curvature, source);
  // In Z order, as QSR: neighbourhood loops stay in cache, the output ignores the input order.
  const std::vector<int> order = spatialOrderAll(points);
  Positions out =
      upsampleInSpatialOrder(gathered(points, order), surface, params, report, progress, normals, curvature, source);
  if (source)
    for (int& s : *source) s = order[static_cast<std::size_t>(s)];  // back to the input's order
  return out;
}

template class MlsUpsampling<pcl::PointXYZ, pcl::PointXYZ, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZ, pcl::PointXYZ, MlsSurface::Rimls>;
template class MlsUpsampling<pcl::PointNormal, pcl::PointNormal, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointNormal, pcl::PointNormal, MlsSurface::Rimls>;
template class MlsUpsampling<pcl::PointXYZRGB, pcl::PointXYZ, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZRGB, pcl::PointXYZ, MlsSurface::Rimls>;
template class MlsUpsampling<pcl::PointXYZI, pcl::PointXYZ, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZI, pcl::PointXYZ, MlsSurface::Rimls>;
template class MlsUpsampling<pcl::PointXYZ, pcl::PointNormal, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZ, pcl::PointNormal, MlsSurface::Rimls>;
// Coloured scans into their own type, as QuadricSuperResolution.
template class MlsUpsampling<pcl::PointXYZRGB, pcl::PointXYZRGB, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZRGB, pcl::PointXYZRGB, MlsSurface::Rimls>;
template class MlsUpsampling<pcl::PointXYZRGBA, pcl::PointXYZRGBA, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZRGBA, pcl::PointXYZRGBA, MlsSurface::Rimls>;
template class MlsUpsampling<pcl::PointXYZRGBNormal, pcl::PointXYZRGBNormal, MlsSurface::Apss>;
template class MlsUpsampling<pcl::PointXYZRGBNormal, pcl::PointXYZRGBNormal, MlsSurface::Rimls>;

}  // namespace paps
