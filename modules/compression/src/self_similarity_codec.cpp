#include <paps/compression/self_similarity_codec.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <numeric>
#include <utility>

#include <Eigen/Eigenvalues>

#include <paps/compression/seed_coder.h>
#include <array>

#include "point_grid.h"
#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/plane_height_patch.h>
#include <paps/core/poisson_disk_sampling.h>
#include <paps/core/random.h>
#include <paps/core/sparse_coding.h>
#include <paps/core/spatial_order.h>

namespace paps::compression {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr std::uint32_t kTagParm = sectionTag("PARM");
constexpr std::uint32_t kTagSeed = sectionTag("SEED");
constexpr std::uint32_t kTagFram = sectionTag("FRAM");
constexpr std::uint32_t kTagDict = sectionTag("DICT");
constexpr std::uint32_t kTagPtch = sectionTag("PTCH");
constexpr int kPredictionNeighbours = 10;
constexpr float kValidSpacings = 1.5f;  // a pattern sample has data within this many spacings
// Seeds within 2.05 R of a seed, at most. Seeds of a surface at least 0.25 R apart (the
// smallest seed_spacing) number about 270 there; a stream with more is crafted, and would make
// the decoder's work grow with the square of its seed count, so it is rejected (and the encoder
// refuses inputs, such as dense volumes, that would produce one).
constexpr int kMaxSeedNeighbours = 512;
[[noreturn]] void tooManySeedNeighbours() {
  throw CorruptStream("a seed has more than " + std::to_string(kMaxSeedNeighbours) +
                      " other seeds within 2 R (a volume of seeds, not a surface)");
}

// ---------------------------------------------------------------------------------------
// What encoder and decoder share: the header, frame prediction, angle dequantization and the
// radial pattern layout.

struct Header {
  std::uint32_t version = kFormatVersion;  // container's; not written in this section
  std::uint32_t points = 0;
  int bins = 16, atoms = 24, sparsity = 4, seed_bits = 16, coefficient_bits = 8, angle_bits = 8;
  int dictionary_bits = 8;  // format 2 writes it; format 1 always used 8
  float radius = 0, spacing = 0, lo[3] = {0, 0, 0}, seed_step = 0, coefficient_step = 0;
  std::uint32_t seeds = 0;

  int rings() const { return bins / 2; }
  int sectors() const { return 2 * bins; }
  int samples() const { return 1 + rings() * sectors(); }
  int valueSymbols() const { return (1 << coefficient_bits) - 2; }
  int angleLevels() const { return 1 << angle_bits; }
  int dictionaryLevels() const { return (1 << (dictionary_bits - 1)) - 1; }  // atoms in [-L, L] x scale / L

  std::vector<std::uint8_t> write() const {
    ByteWriter w;
    w.u32(points);
    w.u8(std::uint8_t(bins));
    w.u16(std::uint16_t(atoms));
    w.u8(std::uint8_t(sparsity));
    w.u8(std::uint8_t(seed_bits));
    w.u8(std::uint8_t(coefficient_bits));
    w.u8(std::uint8_t(angle_bits));
    if (version >= 2) w.u8(std::uint8_t(dictionary_bits));
    w.f32(radius);
    w.f32(spacing);
    for (float v : lo) w.f32(v);
    w.f32(seed_step);
    w.f32(coefficient_step);
    w.u32(seeds);
    return w.bytes;
  }
  static Header read(const std::vector<std::uint8_t>& b, std::uint32_t version, const DecodeOptions& o) {
    ByteReader r(b.data(), b.size(), "parameter section");
    Header h;
    h.version = version;
    auto range = [](const char* name, int v, int lo, int hi) {
      if (v < lo || v > hi)
        throw CorruptStream("parameter '" + std::string(name) + "' = " + std::to_string(v) + " is out of [" +
                            std::to_string(lo) + ", " + std::to_string(hi) + "]");
    };
    h.points = r.u32();
    h.bins = r.u8();
    range("bins", h.bins, 4, 32);
    if (h.bins % 2) throw CorruptStream("parameter 'bins' is odd");
    h.atoms = r.u16();
    range("atoms", h.atoms, 1, 256);
    h.sparsity = r.u8();
    range("sparsity", h.sparsity, 1, h.atoms);
    h.seed_bits = r.u8();
    range("seed_bits", h.seed_bits, 4, 21);
    h.coefficient_bits = r.u8();
    range("coefficient_bits", h.coefficient_bits, 2, 12);
    h.angle_bits = r.u8();
    range("angle_bits", h.angle_bits, 3, 12);
    if (version >= 2) {
      h.dictionary_bits = r.u8();
      range("dictionary_bits", h.dictionary_bits, 3, 8);
    }
    h.radius = r.f32In("radius", 1e-30f, 1e30f);
    h.spacing = r.f32In("spacing", 1e-30f, 1e30f);
    if (!(h.radius / h.spacing <= 64.f && h.radius / h.spacing >= 0.25f))
      throw CorruptStream("radius / spacing ratio is out of [0.25, 64]");
    for (float& v : h.lo) v = r.f32In("origin", -1e30f, 1e30f);
    h.seed_step = r.f32In("seed_step", 1e-30f, 1e30f);
    h.coefficient_step = r.f32In("coefficient_step", 1e-30f, 1e30f);
    h.seeds = r.u32();
    if (h.seeds < 1 || h.seeds > o.max_seeds)
      throw CorruptStream("seed count " + std::to_string(h.seeds) + " is out of [1, " + std::to_string(o.max_seeds) + "]");
    if (r.left() != 0) throw CorruptStream("parameter section has trailing bytes");
    const double ratio = double(h.radius) / h.spacing;
    const double expected = double(h.seeds) * 4.0 * ratio * ratio;
    if (expected > double(o.max_points))
      throw CorruptStream("the stream would decode to up to " + std::to_string(std::size_t(expected)) +
                          " points, more than the limit " + std::to_string(o.max_points));
    return h;
  }
};

LocalFrame defaultFrame() { return LocalFrame{}; }

// Frames predicted from the decoded seeds alone: PCA normals over the nearest seeds,
// oriented by propagation, principal directions from the seed normals. Deterministic.
LocalFrames predictFrames(const Positions& seeds) {
  LocalFrames frames(seeds.size(), defaultFrame());
  if (seeds.size() < 3) return frames;
  SpatialIndex index(seeds);
  const int k = std::min<int>(kPredictionNeighbours, int(seeds.size()));
  const NeighbourGraph graph = NeighbourGraph::byCount(seeds, index, k);
  Normals normals = estimateNormals(seeds, graph);
  orientNormalsByPropagation(seeds, normals, graph);
  LocalFrames f = estimatePrincipalFrames(normals, graph);
  for (std::size_t i = 0; i < seeds.size(); ++i)
    if (i < f.size() && f[i].valid() && isFinite(f[i].t1) && isFinite(f[i].t2)) frames[i] = f[i];
  return frames;
}

float dequantizeAngle(int q, int levels) { return float(q) * kPi / float(levels - 1) - 0.5f * kPi; }
int quantizeAngle(float a, int levels) {
  const int q = int(std::lround((a + 0.5f * kPi) / kPi * float(levels - 1)));
  return std::clamp(q, 0, levels - 1);
}

// Frame = predicted frame tilted by (alpha, beta) then turned by gamma about the new normal.
LocalFrame correctedFrame(const LocalFrame& pred, int qa, int qb, int qg, int levels) {
  const float a = dequantizeAngle(qa, levels), b = dequantizeAngle(qb, levels), g = dequantizeAngle(qg, levels);
  const Eigen::Vector3f l(std::sin(a) * std::cos(b), std::sin(b), std::cos(a) * std::cos(b));
  LocalFrame f;
  f.n = pred.toWorld(l).normalized();
  Eigen::Vector3f t1 = pred.t1 - pred.t1.dot(f.n) * f.n;
  if (t1.squaredNorm() < 1e-12f) t1 = pred.t2 - pred.t2.dot(f.n) * f.n;
  t1.normalize();
  const Eigen::Vector3f t2 = f.n.cross(t1);
  f.t1 = (std::cos(g) * t1 + std::sin(g) * t2).normalized();
  f.t2 = f.n.cross(f.t1);
  return f;
}

// Height of a decoded patch at (u, v) in units of R, interpolated on the radial pattern over
// the valid samples. Returns false where the patch has no data.
struct RadialLayout {
  int rings, sectors;
  float dr;
  float step;  // heights are held as 16-bit integers of R / 8192 (range +-4 R): half the memory of floats
  explicit RadialLayout(const Header& h)
      : rings(h.rings()), sectors(h.sectors()), dr(1.f / (h.rings() + 0.5f)), step(h.radius / 8192.f) {}
  std::int16_t quantize(float y) const {
    // Clamped as a float first: y / step may overflow to infinity on a corrupt stream.
    return std::int16_t(std::lround(std::clamp(y / step, -32767.f, 32767.f)));
  }
  bool height(const std::int16_t* y, const std::uint8_t* valid, float u, float v, float& out) const {
    const float rho = std::sqrt(u * u + v * v);
    const float t = rho / dr;
    if (t > rings + 0.5f) return false;
    float phi = std::atan2(v, u);
    if (phi < 0) phi += 2 * kPi;
    int r0 = int(t);
    float f = t - r0;
    if (r0 >= rings) { r0 = rings; f = 0; }
    float wsum = 0, hsum = 0;
    auto ring = [&](int r, float w) {
      if (w <= 0) return;
      if (r == 0) {
        if (valid[0]) { wsum += w; hsum += w * float(y[0]); }
        return;
      }
      float sigma = phi * sectors / (2 * kPi) - 0.5f * (r % 2);
      float fl = std::floor(sigma);
      const float g = sigma - fl;
      int s0 = int(fl) % sectors;
      if (s0 < 0) s0 += sectors;
      const int s1 = (s0 + 1) % sectors;
      const int base = 1 + (r - 1) * sectors;
      if (valid[base + s0]) { wsum += w * (1 - g); hsum += w * (1 - g) * float(y[base + s0]); }
      if (valid[base + s1]) { wsum += w * g; hsum += w * g * float(y[base + s1]); }
    };
    ring(r0, 1 - f);
    if (r0 < rings) ring(r0 + 1, f);
    if (wsum < 0.5f) return false;
    out = hsum / wsum * step;
    return true;
  }
};

// Format 2 masks. Overlapping patches see the same data, so a patch codes its validity mask
// only where it owns the surface: where the sample's tangent-plane position is nearer to its
// seed than to any other seed (the nearest seed's patch always covers it, since that seed is
// within R). Elsewhere the sample copies the owner's nearest owned sample. Encoder and decoder
// compute this from the decoded seeds and frames alone. On the LMS400 scan at 1600 points a
// patch 86% of the samples are still owned (its seeds are sparse next to its many borders):
// sharing alone cut the masks by 11%, with the contexts below by 16%.
class SharedMasks {
 public:
  SharedMasks(const Header& h, const Positions& seeds, const LocalFrames& frames, const SpatialIndex& seed_index)
      : seeds_(seeds), frames_(frames), index_(seed_index), pattern_(SamplingPattern::radial(h.rings(), h.sectors())),
        R_(h.radius), k_(h.samples()), rings_(h.rings()), sectors_(h.sectors()), dr_(1.f / (h.rings() + 0.5f)),
        words_((std::size_t(h.samples()) + 63) / 64), owned_(words_ * seeds.size(), 0) {
    const long n = long(seeds.size());
    bool too_many = false;
#pragma omp parallel
    {
      std::vector<int> nb;
      std::vector<float> d2;
#pragma omp for schedule(dynamic, 64) reduction(|| : too_many)
      for (long i = 0; i < n; ++i) {
        if (!neighbours(std::size_t(i), nb, d2)) { too_many = true; continue; }
        std::uint64_t* w = owned_.data() + std::size_t(i) * words_;
        for (int s = 0; s < k_; ++s)
          if (owner(std::size_t(i), s, nb) == int(i)) w[s / 64] |= std::uint64_t(1) << (s % 64);
      }
    }
    crowded_ = too_many;
  }
  // True when some seed has more than kMaxSeedNeighbours seeds within 2.05 R (every seed was
  // checked, so later searches stay within the bound). The caller says what that means.
  bool crowded() const { return crowded_; }
  // For patch i: src[s] = -1 where sample s is coded, else the flat index j * k + s' of the
  // owned sample it copies. Thread-safe.
  void sources(std::size_t i, std::vector<long>& src, std::vector<int>& nb, std::vector<float>& d2) const {
    neighbours(i, nb, d2);
    src.assign(std::size_t(k_), -1);
    for (int s = 0; s < k_; ++s) {
      const int j = owner(i, s, nb);
      if (j == int(i)) continue;
      const Eigen::Vector3f l = frames_[j].toLocal(samplePosition(i, s) - seeds_[j]) / R_;
      const int sj = nearestOwned(std::size_t(j), l.x(), l.y());
      if (sj >= 0) src[s] = long(j) * k_ + sj;
    }
  }

 private:
  // False when the seed has too many neighbours (the list is then cut).
  bool neighbours(std::size_t i, std::vector<int>& nb, std::vector<float>& d2) const {
    const int cnt = index_.radiusSearch(seeds_[i], 2.05f * R_, nb, d2, kMaxSeedNeighbours + 1);
    nb.resize(std::size_t(std::min(cnt, kMaxSeedNeighbours)));
    if (std::find(nb.begin(), nb.end(), int(i)) == nb.end()) nb.push_back(int(i));
    return cnt <= kMaxSeedNeighbours;
  }
  Eigen::Vector3f samplePosition(std::size_t i, int s) const {
    const Eigen::Vector2f& q = pattern_.samples[std::size_t(s)];
    return seeds_[i] + R_ * (q.x() * frames_[i].t1 + q.y() * frames_[i].t2);
  }
  // Nearest seed to the sample's tangent-plane position; ties go to the lower index.
  int owner(std::size_t i, int s, const std::vector<int>& nb) const {
    const Eigen::Vector3f p = samplePosition(i, s);
    int best = int(i);
    float bd = (p - seeds_[i]).squaredNorm();
    for (const int j : nb) {
      const float d = (p - seeds_[std::size_t(j)]).squaredNorm();
      if (d < bd || (d == bd && j < best)) { best = j; bd = d; }
    }
    return best;
  }
  bool owned(std::size_t j, int s) const { return (owned_[j * words_ + std::size_t(s) / 64] >> (s % 64)) & 1u; }
  // The owned sample of patch j nearest to (u, v) (units of R) among the 3 rings and 2 sectors
  // around it, if one lies within one ring spacing; else -1.
  int nearestOwned(std::size_t j, float u, float v) const {
    const float rho = std::sqrt(u * u + v * v);
    float phi = std::atan2(v, u);
    if (phi < 0) phi += 2 * kPi;
    const int rc = int(std::lround(rho / dr_));
    int best = -1;
    float bd = dr_ * dr_ * 1.0001f;
    auto consider = [&](int s) {
      if (!owned(j, s)) return;
      const Eigen::Vector2f& q = pattern_.samples[std::size_t(s)];
      const float d = (q.x() - u) * (q.x() - u) + (q.y() - v) * (q.y() - v);
      if (d < bd || (d == bd && s < best)) { bd = d; best = s; }
    };
    for (int r = std::max(0, rc - 1); r <= std::min(rings_, rc + 1); ++r) {
      if (r == 0) { consider(0); continue; }
      const float sigma = phi * sectors_ / (2 * kPi) - 0.5f * (r % 2);
      int s0 = int(std::floor(sigma)) % sectors_;
      if (s0 < 0) s0 += sectors_;
      const int base = 1 + (r - 1) * sectors_;
      consider(base + s0);
      consider(base + (s0 + 1) % sectors_);
    }
    return best;
  }

  const Positions& seeds_;
  const LocalFrames& frames_;
  const SpatialIndex& index_;
  SamplingPattern pattern_;
  float R_;
  int k_, rings_, sectors_;
  float dr_;
  std::size_t words_;
  std::vector<std::uint64_t> owned_;
  bool crowded_ = false;
};

// Flat indices of the two samples of ring r - 1 (r >= 2) on either side of the angle of sample
// k of ring r: odd rings sit half a sector ahead of even ones.
std::pair<int, int> innerNeighbours(int r, int k, int sectors) {
  const int base = 1 + (r - 2) * sectors;
  const int behind = r % 2 ? k : (k + sectors - 1) % sectors;
  return {base + behind, base + (behind + 1) % sectors};
}

// Context of a format-2 mask bit: the previous sample on the ring and the two samples of the
// ring inside it on either side of its angle (rings alternate a half-sector offset), each
// 0, 1 or 2 (not known yet: copied from a patch that comes later).
constexpr int kSharedMaskContexts = 28;
int sharedMaskContext(const std::uint8_t* known, int s, int sectors) {
  if (s == 0) return 27;
  const int r = (s - 1) / sectors + 1, k = (s - 1) % sectors;
  const int prev = k > 0 ? known[s - 1] : known[0];
  int a = known[0], b = known[0];
  if (r > 1) {
    const auto [behind, ahead] = innerNeighbours(r, k, sectors);
    a = known[behind];
    b = known[ahead];
  }
  return prev * 9 + a * 3 + b;
}

// Format 2 atoms: each quantized atom value is predicted from the samples already coded
// around it (see atomPrediction), and the residual goes as an adaptive magnitude class plus
// adaptive mantissa bits. Format 1 coded plain deltas on a 509-symbol alphabet, which a few
// thousand values cannot teach an adaptive model (7 bits a value on the LMS400 scan).
struct AtomResidualCoder {
  static constexpr int kClasses = 10;  // zigzagged residuals up to 2 x 254 < 2^9
  AdaptiveModel cls{kClasses};
  std::vector<AdaptiveModel> mantissa;
  AtomResidualCoder() : mantissa(kClasses * kClasses, AdaptiveModel(2)) {}
  void put(SymbolWriter& w, int v) {
    const unsigned z = v >= 0 ? 2u * unsigned(v) : 2u * unsigned(-v) - 1u;
    int c = 0;
    while ((z >> c) != 0) ++c;
    w.put(cls, c);
    for (int b = c - 2; b >= 0; --b) w.put(mantissa[std::size_t(c * kClasses + b)], int((z >> b) & 1u));
  }
  int get(SymbolReader& r) {
    const int c = r.get(cls);
    if (c == 0) return 0;
    unsigned z = 1;
    for (int b = c - 2; b >= 0; --b) z = (z << 1) | unsigned(r.get(mantissa[std::size_t(c * kClasses + b)]));
    return z % 2 == 0 ? int(z / 2) : -int((z + 1) / 2);
  }
};

// Prediction of sample s of an atom from the samples before it on the radial pattern: the
// previous sample on the ring plus the change of the ring inside between the two angles.
int atomPrediction(const int* q, int s, int sectors, int levels) {
  if (s == 0) return 0;
  const int r = (s - 1) / sectors + 1, k = (s - 1) % sectors;
  auto inner = [&](int kk) {
    if (r == 1) return q[0];
    const auto [behind, ahead] = innerNeighbours(r, kk, sectors);
    return (q[behind] + q[ahead]) / 2;
  };
  // Planar prediction; measured on the LMS400 scan, it beats the previous sample alone and the
  // mean of the previous and inner samples by 6% and 4% of the dictionary bytes.
  const int p = k == 0 ? inner(0) : q[s - 1] + inner(k) - inner(k - 1);
  return std::clamp(p, -levels, levels);
}

// Symbol models of the patch stream.
struct PatchModels {
  AdaptiveModel all_valid{2};
  std::vector<AdaptiveModel> mask;  // 4 contexts (format 1), kSharedMaskContexts (format 2)
  AdaptiveModel count;
  AdaptiveModel gap;
  std::vector<AdaptiveModel> value;  // one per atom
  explicit PatchModels(const Header& h)
      : mask(h.version >= 2 ? kSharedMaskContexts : 4, AdaptiveModel(2)), count(h.sparsity + 1), gap(std::max(h.atoms, 2)),
        value(h.atoms, AdaptiveModel(h.valueSymbols(), 16)) {}
};

int maskContext(const std::uint8_t* valid, int s, int sectors) {
  if (s == 0) return 3;
  const int r = (s - 1) / sectors + 1, k = (s - 1) % sectors;
  const int prev = k > 0 ? valid[s - 1] : valid[0];
  const int inner = r > 1 ? valid[s - sectors] : valid[0];
  return prev * 2 + inner;
}

int zigzag(int q) { return q > 0 ? 2 * q - 2 : -2 * q - 1; }
int unzigzag(int z) { return (z % 2 == 0) ? z / 2 + 1 : -(z + 1) / 2; }

// The plane+height estimator of PlaneHeightPatch::describe (normalised Gaussian of width
// 0.6 x the ring spacing), but each
// sample only visits the neighbours in the 3 x 3 nearby cells of a grid over the tangent plane
// (cut-off at 3 sigma, where the weight is 1%): about 8x faster on 256-point patches, which
// makes the descriptors affordable at a million points.
class FastRadialDescriber {
 public:
  FastRadialDescriber(SamplingPattern pattern, float R, float spacing, float kernel_width = 0.6f) : pattern_(std::move(pattern)), R_(R) {
    const float sigma = kernel_width * pattern_.spacing * R;
    inv2s2_ = 1.f / (2.f * sigma * sigma);
    cell_ = 3.f * sigma;
    cut2_ = cell_ * cell_;
    dim_ = std::max(1, int(std::ceil(2.f * R / cell_)));
    // Valid when the kernel weights reach the weight of one point at 1.5 x the point spacing,
    // that distance kept in [1, 2.5] sigma: low enough that scans sparser than the pattern do
    // not riddle the masks with holes, high enough that large patches reach less far past
    // the data (always 2.5 sigma before: at patch_points 2400 on the LMS400 scan, D2 2.6e-3 m
    // against 2.2e-3 m with this rule, for the same bytes).
    const float vd = std::clamp(kValidSpacings * spacing, sigma, 2.5f * sigma) / sigma;
    min_weight_ = std::exp(-vd * vd / 2.f);
  }
  int size() const { return int(pattern_.size()); }
  void describe(const LocalFrame& f, const Eigen::Vector3f& o, const Positions& pts, const int* nb, int cnt,
                float* heights, std::uint8_t* valid) const {
    thread_local std::vector<Eigen::Vector3f> local, sorted;
    thread_local std::vector<int> start, cellOf;
    local.resize(cnt);
    cellOf.resize(cnt);
    start.assign(std::size_t(dim_) * dim_ + 1, 0);
    for (int j = 0; j < cnt; ++j) {
      local[j] = f.toLocal(pts[nb[j]] - o);
      const int cx = std::clamp(int((local[j].x() + R_) / cell_), 0, dim_ - 1);
      const int cy = std::clamp(int((local[j].y() + R_) / cell_), 0, dim_ - 1);
      cellOf[j] = cy * dim_ + cx;
      ++start[cellOf[j] + 1];
    }
    for (int c = 0; c < dim_ * dim_; ++c) start[c + 1] += start[c];
    sorted.resize(cnt);
    {
      thread_local std::vector<int> fill;
      fill.assign(start.begin(), start.end() - 1);
      for (int j = 0; j < cnt; ++j) sorted[fill[cellOf[j]]++] = local[j];
    }
    for (std::size_t s = 0; s < pattern_.size(); ++s) {
      const float cu = pattern_.samples[s].x() * R_, cv = pattern_.samples[s].y() * R_;
      const int cx = std::clamp(int((cu + R_) / cell_), 0, dim_ - 1), cy = std::clamp(int((cv + R_) / cell_), 0, dim_ - 1);
      float ws = 0, hs = 0;
      for (int y = std::max(0, cy - 1); y <= std::min(dim_ - 1, cy + 1); ++y)
        for (int x = std::max(0, cx - 1); x <= std::min(dim_ - 1, cx + 1); ++x) {
          const int c = y * dim_ + x;
          for (int j = start[c]; j < start[c + 1]; ++j) {
            const float du = sorted[j].x() - cu, dv = sorted[j].y() - cv;
            const float d2 = du * du + dv * dv;
            if (d2 > cut2_) continue;
            const float w = std::exp(-d2 * inv2s2_);
            ws += w;
            hs += w * sorted[j].z();
          }
        }
      const bool ok = ws >= min_weight_;
      valid[s] = ok;
      heights[s] = ok ? hs / ws : 0.f;
    }
  }

 private:
  SamplingPattern pattern_;
  float R_, inv2s2_, cell_, cut2_, min_weight_;
  int dim_;
};

}  // namespace

// ---------------------------------------------------------------------------------------

void CompressionParameters::validate() const {
  if (!(patch_radius == 0.f || (patch_radius > 0.f && patch_radius < 1e30f)))
    throw InvalidParameter("patch_radius", paps::detail::toString(patch_radius), "0 (automatic) or a finite value > 0");
  requireInRange("patch_points", patch_points, 8, 100000);
  requireInRange("bins", bins, 4, 32);
  if (bins % 2) throw InvalidParameter("bins", std::to_string(bins), "an even value in [4, 32]");
  requireInRange("atoms", atoms, 1, 256);
  requireInRange("sparsity", sparsity, 1, atoms);
  requireInRange("seed_bits", seed_bits, 4, 21);
  requireInRange("coefficient_bits", coefficient_bits, 2, 12);
  requireInRange("angle_bits", angle_bits, 3, 12);
  requireInRange("dictionary_bits", dictionary_bits, 3, 8);
  requireInRange("seed_spacing", seed_spacing, 0.25f, 2.f);
  requireInRange("ksvd_iterations", ksvd_iterations, 0, 200);
  requireInRange("max_training_patches", max_training_patches, 16, 10000000);
  if (!(output_spacing == 0.f || (output_spacing > 0.f && output_spacing < 1e30f)))
    throw InvalidParameter("output_spacing", paps::detail::toString(output_spacing), "0 (automatic) or a finite value > 0");
}

std::vector<std::string> compressionPresetNames() { return {"compact", "balanced", "fine"}; }

CompressionParameters compressionPreset(const std::string& name) {
  CompressionParameters p;
  if (name == "compact") {
    // N_bins 12: at 400 points a patch the LMS400 scan and rs1 (1M points) reach a given D2
    // with 14% and 7% fewer bytes than with 16; 5-bit atoms cost no measurable D2 there.
    p.patch_points = 400; p.atoms = 16; p.sparsity = 3; p.coefficient_bits = 7; p.seed_bits = 12;
    p.bins = 12; p.dictionary_bits = 5;
  } else if (name == "balanced") {
    // defaults
  } else if (name == "fine") {
    // 12-bit seeds and 8-bit coefficients: on rs1 (1M points, patch_points 100) 12% fewer
    // bytes than 16/9 bits for 1.5% more D2 error.
    p.patch_points = 160; p.atoms = 32; p.sparsity = 6; p.coefficient_bits = 8; p.seed_bits = 12;
  } else {
    throw InvalidParameter("preset", name, "one of compact, balanced, fine");
  }
  return p;
}

namespace {

// Radius whose ball around a typical point holds `target` finite points (the median count
// over a deterministic sample of at most 2000 points), and a grid of about that cell size.
// The first guess comes from the area the points cover (occupied cells of a fine grid); then
// the surface law count ~ r^2 corrects it until within 3%. The median, as in core's
// radiusForNeighbourCount: a mean count is made by the densest spots of a real scan and
// shrank R until most points had only their duplicate (bun0.pcd decoded to 873 points).
float chooseRadius(const Positions& pts, std::size_t finite, float diag, int target, const std::vector<int>& sample,
                   std::unique_ptr<detail::PointGrid>& grid) {
  // About one point in `stride`, chosen by position (positionHash, whatever the input
  // order), cells holding about 4 of them.
  const std::size_t stride = std::max<std::size_t>(1, finite / 65536);
  const float c0 = std::max(diag * std::sqrt(4.f * float(stride) / float(finite)), diag * 1e-6f);
  detail::CellHash occupied;
  occupied.reset(std::min<std::size_t>(finite / stride, 1u << 16));
  {
    const float inv = 1.f / c0;
    const std::uint64_t below = ~std::uint64_t(0) / stride;
    for (std::size_t i = 0; i < pts.size(); ++i)
      if (isFinite(pts[i]) && positionHash(pts[i]) <= below)
        occupied.insert(detail::packCell(std::int64_t(std::floor(pts[i].x() * inv)),
                                         std::int64_t(std::floor(pts[i].y() * inv)),
                                         std::int64_t(std::floor(pts[i].z() * inv))));
  }
  const double area = double(occupied.size()) * c0 * c0 / 1.5;
  float r = float(std::sqrt(double(target) * area / (kPi * double(finite))));
  if (!(r > 0) || !std::isfinite(r)) r = diag * 1e-2f;
  grid = std::make_unique<detail::PointGrid>(pts, r);
  for (int iter = 0; iter < 12; ++iter) {
    // A quarter of the sample steers the radius (as before); the caller measures on all.
    std::vector<int> counts;
    for (std::size_t s = 0; s < sample.size(); s += 4) counts.push_back(grid->countWithin(pts[sample[s]], r));
    std::nth_element(counts.begin(), counts.begin() + counts.size() / 2, counts.end());
    const double typical = counts[counts.size() / 2];
    if (typical <= 0) break;
    if (std::abs(typical - target) < 0.03 * target) break;
    r *= float(std::clamp(std::sqrt(target / typical), 0.5, 2.0));
    if (r > 1.6f * grid->cell() || r < 0.6f * grid->cell()) grid = std::make_unique<detail::PointGrid>(pts, r);
  }
  return r;
}

// Dart throwing (a maximal Poisson-disk subset at radius rho): the grid's cells are visited
// by blocks of 8 x 8 x 8 cells, and the points of a block in a seeded random order, so the
// darts are as random locally and the memory traffic stays local. Returns increasing indices.
std::vector<int> throwSeeds(const Positions& pts, const detail::PointGrid& grid, float rho, std::uint64_t seed) {
  const std::size_t cells = grid.cellCount();
  std::vector<std::pair<std::uint64_t, int>> order(cells);
  for (std::size_t c = 0; c < cells; ++c) {
    const Eigen::Vector3f& p = pts[*grid.cellBegin(c)];
    const std::int64_t x = grid.coord(p, 0), y = grid.coord(p, 1), z = grid.coord(p, 2);
    const std::uint64_t block = detail::packCell(x >> 3, y >> 3, z >> 3);
    const std::uint64_t inner = std::uint64_t(((z & 7) << 6) | ((y & 7) << 3) | (x & 7));
    order[c] = {(block << 9) | inner, int(c)};
  }
  std::sort(order.begin(), order.end());
  Random rng(seed);
  detail::ThinningGrid kept(rho, 1024);
  Positions kept_pts;
  std::vector<int> chosen, candidates;
  for (std::size_t a = 0; a < cells;) {
    std::size_t b = a;
    candidates.clear();
    while (b < cells && (order[b].first >> 9) == (order[a].first >> 9)) {
      const int c = order[b].second;
      candidates.insert(candidates.end(), grid.cellBegin(c), grid.cellEnd(c));
      ++b;
    }
    for (std::size_t i = candidates.size(); i > 1; --i) std::swap(candidates[i - 1], candidates[rng.below(i)]);
    for (const int i : candidates)
      if (kept.offer(pts[i], kept_pts)) chosen.push_back(i);
    a = b;
  }
  std::sort(chosen.begin(), chosen.end());
  return chosen;
}

}  // namespace

std::vector<std::uint8_t> compressPositions(const Positions& input, const CompressionParameters& prm,
                                            EncodeReport* report, const ProgressCallback& progress) {
  prm.validate();
  EncodeReport rep;
  auto clock = std::chrono::steady_clock::now();
  auto lap = [&clock]() {
    const auto now = std::chrono::steady_clock::now();
    const double t = std::chrono::duration<double>(now - clock).count();
    clock = now;
    return t;
  };
  rep.input_points = input.size();
  // The input is used in place: the non-finite points are skipped by every stage (the grid
  // indexes the finite ones only), so no copy of the cloud is made.
  const Positions& pts = input;
  std::size_t finite = 0;
  for (const auto& p : pts) finite += isFinite(p);
  rep.dropped_non_finite = input.size() - finite;
  constexpr std::size_t kMinPoints = 16;
  if (finite == 0) throw InvalidInput("the cloud has no finite points");
  if (finite < kMinPoints)
    throw InvalidInput(std::to_string(finite) + " finite points, fewer than one patch needs (" +
                       std::to_string(kMinPoints) + ")");
  if (finite > 0xFFFFFFF0u) throw InvalidInput("more than 2^32 points");
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pts)
    if (isFinite(p)) { lo = lo.cwiseMin(p); hi = hi.cwiseMax(p); mean += p.cast<double>(); }
  mean /= double(finite);
  const float extent = (hi - lo).maxCoeff();
  if (!(extent > 0)) throw InvalidInput("all points are identical");
  {
    // Spread of the points around `centre`: false when they lie on a line.
    auto spansAPlane = [&pts](const Eigen::Vector3d& centre, double reach2) {
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (const auto& p : pts)
        if (isFinite(p)) {
          const Eigen::Vector3d d = p.cast<double>() - centre;
          if (d.squaredNorm() <= reach2) cov += d * d.transpose();
        }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
      return es.eigenvalues()[1] > 1e-10 * es.eigenvalues()[2];
    };
    if (!spansAPlane(mean, INFINITY)) {
      // A few points far from the rest (a stray return, a second scan far away) also make
      // the whole cloud look like a line: say so when the nearest quarter of the points
      // around the median point, and four times their reach, do span a surface.
      const Eigen::Vector3d median = medianPoint(pts);
      std::vector<double> v;
      for (const auto& p : pts)
        if (isFinite(p)) v.push_back((p.cast<double>() - median).squaredNorm());
      std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 4), v.end());
      const double reach2 = 16 * v[v.size() / 4];
      std::size_t far = 0;
      for (const double d2 : v) far += d2 > reach2;
      if (reach2 > 0 && spansAPlane(median, reach2))
        throw InvalidInput(std::to_string(far) + " of the " + std::to_string(finite) + " points lie more than " +
                           paps::detail::toString(std::sqrt(reach2)) +
                           " m from the median point and make the cloud span " + paps::detail::toString(extent) +
                           " m along one line; the codec quantizes over the whole extent: remove the far points "
                           "first (e.g. pcl::StatisticalOutlierRemoval or pcl::CropBox)");
      throw InvalidInput("the points lie on a line; a surface codec needs a surface");
    }
  }

  // Radius and spacing, on a deterministic sample of the finite points.
  // Chosen by position, not by index, so that the same points in another order give the
  // same stream.
  const std::vector<int> sample = positionSample(pts, 2000);
  std::unique_ptr<detail::PointGrid> grid;
  float R = prm.patch_radius;
  requireRadiusWithinExtent("patch_radius", R, pts);
  if (R == 0.f) {
    try {
      R = chooseRadius(pts, finite, (hi - lo).norm(), prm.patch_points, sample, grid);
    } catch (const InvalidParameter&) {  // the grid of a candidate radius: not the caller's parameter
      throw InvalidInput("no automatic patch radius fits: " + std::to_string(prm.patch_points) +
                         " points a patch need a radius below extent / 2^20 of the points (piles of copies, or a few "
                         "dense spots in a wide extent); remove the copies or the far points first, or give a radius");
    }
  }
  const std::uint32_t qmax = (1u << prm.seed_bits) - 1u;
  const float seed_step = extent / float(qmax);
  // Seeds are the patch centres: quantized farther than a quarter of the patch radius they
  // leave their points (1% of a 1 m plane's points moved 1 km away: step 0.45 R, 35% fewer
  // points decoded than without them; 10 km: 3.5 R, 65 of 6,600; 20 positions stored 1,000
  // times each, whose radius is chosen on copies: 10 R, 0 points decoded). Refused.
  if (seed_step > 0.25f * R)
    throw InvalidInput("the cloud spans " + paps::detail::toString(extent) + " m: seeds quantized on " +
                       std::to_string(prm.seed_bits) + " bits are " + paps::detail::toString(seed_step) +
                       " m apart, more than a quarter of the patch radius " + paps::detail::toString(R) +
                       " m, and the patches would miss their points (the extent is too large for the radius: far points, "
                       "or a radius made tiny by piles of copies); remove far points first (e.g. "
                       "pcl::StatisticalOutlierRemoval or pcl::CropBox) or raise seed_bits (at most 21)");
  if (!grid || R > 1.25f * grid->cell() || R < 0.8f * grid->cell()) {
    grid.reset();
    grid = std::make_unique<detail::PointGrid>(pts, R);
  }
  // Each point owns pi R^2 / (points in its R-ball) of surface; the mean of that area gives
  // the output spacing (a harmonic mean of the counts, right on unevenly sampled scans).
  double mean_count = 0, mean_inverse = 0;
  for (const int i : sample) {
    const int c = grid->countWithin(pts[i], R);
    mean_count += c;
    mean_inverse += 1.0 / std::max(c, 1);
  }
  mean_count /= double(sample.size());
  mean_inverse /= double(sample.size());
  if (mean_count < 8)
    throw InvalidInput("patch radius " + paps::detail::toString(R) + " m holds only " +
                       paps::detail::toString(mean_count) + " points on average (fewer points than one patch needs, at least 8)");
  float spacing = prm.output_spacing > 0 ? prm.output_spacing : R * std::sqrt(kPi * float(mean_inverse));
  if (R / spacing > 64.f) throw InvalidParameter("output_spacing", paps::detail::toString(spacing), "at least patch radius / 64");
  if (R / spacing < 0.25f) throw InvalidParameter("output_spacing", paps::detail::toString(spacing), "at most 4 x patch radius");
  rep.patch_radius = R;
  rep.output_spacing = spacing;
  rep.seconds_setup = lap();

  // Seeds: dart throwing, quantization, kd-tree coding.
  const std::vector<int> seed_idx = throwSeeds(pts, *grid, prm.seed_spacing * R, prm.random_seed);
  Header h;
  h.points = std::uint32_t(finite);
  h.bins = prm.bins; h.atoms = prm.atoms; h.sparsity = prm.sparsity; h.seed_bits = prm.seed_bits;
  h.coefficient_bits = prm.coefficient_bits; h.angle_bits = prm.angle_bits;
  h.dictionary_bits = prm.dictionary_bits;
  h.radius = R; h.spacing = spacing;
  for (int a = 0; a < 3; ++a) h.lo[a] = lo[a];
  h.seed_step = seed_step;
  std::vector<VoxelCoordinate> vox;
  vox.reserve(seed_idx.size());
  for (const int i : seed_idx) {
    VoxelCoordinate v;
    for (int a = 0; a < 3; ++a) {
      const double q = std::round((double(pts[i][a]) - h.lo[a]) / h.seed_step);
      v[a] = std::uint32_t(std::clamp(q, 0.0, double(qmax)));
    }
    vox.push_back(v);
  }
  std::sort(vox.begin(), vox.end());
  vox.erase(std::unique(vox.begin(), vox.end()), vox.end());
  if (vox.size() > (std::size_t(1) << 22))
    throw InvalidParameter("patch_radius", paps::detail::toString(R), "a radius giving at most 2^22 seeds");
  const std::vector<std::uint8_t> seed_bytes = encodeVoxels(vox, prm.seed_bits);
  h.seeds = std::uint32_t(vox.size());
  const std::size_t n = vox.size();
  Positions seeds(n);
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) seeds[i][a] = h.lo[a] + float(vox[i][a]) * h.seed_step;
  rep.seeds = n;
  rep.seconds_seeds = lap();

  // Frames: predicted on the seeds, corrected towards the full cloud; descriptors.
  const LocalFrames pred = predictFrames(seeds);
  const int L = h.angleLevels(), k = h.samples();
  std::vector<std::array<int, 3>> qangles(n);
  // Validity masks, bit-packed, one run of whole words per seed (no word is shared by two
  // seeds, so the threads never write the same word).
  const std::size_t mask_words = (std::size_t(k) + 63) / 64;
  std::vector<std::uint64_t> mask_bits(mask_words * n, 0);
  auto isValid = [&](std::size_t i, int s) { return (mask_bits[i * mask_words + s / 64] >> (s % 64)) & 1u; };
  const FastRadialDescriber patch(SamplingPattern::radial(h.rings(), h.sectors()), R, spacing);
  const int max_nb = std::max(64, prm.patch_points * 4);
  // Frame correction and descriptor of seed i (deterministic, thread-safe).
  auto describeSeed = [&](std::size_t i, std::vector<int>& nb, std::vector<float>& d2, float* col,
                          std::vector<std::uint8_t>& vi) {
    const int cnt = grid->radiusSearch(seeds[i], R, nb, d2, max_nb);
    LocalFrame f0 = pred[i];
    int qa = quantizeAngle(0, L), qb = qa, qg = qa;
    if (cnt >= 3) {
      Eigen::Vector3f nt = pcaNormal(pts, nb.data(), cnt);
      if (isFinite(nt)) {
        if (nt.dot(f0.n) < 0) nt = -nt;
        const Eigen::Vector3f l = f0.toLocal(nt);
        qa = quantizeAngle(std::atan2(l.x(), l.z()), L);
        qb = quantizeAngle(std::asin(std::clamp(l.y(), -1.f, 1.f)), L);
      }
      // Principal direction of the heights (quadric fit) sets the turn about the normal.
      const LocalFrame f1 = correctedFrame(f0, qa, qb, qg, L);
      Eigen::Matrix<float, 6, 6> A = Eigen::Matrix<float, 6, 6>::Zero();
      Eigen::Matrix<float, 6, 1> bvec = Eigen::Matrix<float, 6, 1>::Zero();
      for (int j = 0; j < cnt; ++j) {
        const Eigen::Vector3f l = f1.toLocal(pts[nb[j]] - seeds[i]);
        const float u = l.x() / R, v = l.y() / R;
        Eigen::Matrix<float, 6, 1> row;
        row << u * u, u * v, v * v, u, v, 1.f;
        A.selfadjointView<Eigen::Lower>().rankUpdate(row);
        bvec += row * l.z();
      }
      A.triangularView<Eigen::StrictlyUpper>() = A.transpose();
      if (cnt >= 8) {
        const Eigen::Matrix<float, 6, 1> x = A.ldlt().solve(bvec);
        if (x.allFinite()) {
          Eigen::Matrix2f H;
          H << 2 * x[0], x[1], x[1], 2 * x[2];
          Eigen::SelfAdjointEigenSolver<Eigen::Matrix2f> e2(H);
          const Eigen::Vector2f lam = e2.eigenvalues();
          if (std::abs(lam[1] - lam[0]) * 0.5f > 0.5f * spacing) {
            const int m = std::abs(lam[1]) >= std::abs(lam[0]) ? 1 : 0;
            const Eigen::Vector2f dir = e2.eigenvectors().col(m);
            float th = std::atan2(dir.y(), dir.x());
            if (th >= 0.5f * kPi) th -= kPi;
            if (th < -0.5f * kPi) th += kPi;
            qg = quantizeAngle(th, L);
          }
        }
      }
    }
    qangles[i] = {qa, qb, qg};
    const LocalFrame f = correctedFrame(f0, qa, qb, qg, L);
    vi.resize(k);
    patch.describe(f, seeds[i], pts, nb.data(), cnt, col, vi.data());
    // Close one-sample holes along the rings: they cost mask bits and are not real holes.
    const int S = h.sectors();
    for (int r = 1; r <= h.rings(); ++r) {
      const int base = 1 + (r - 1) * S;
      for (int q = 0; q < S; ++q) {
        const int a = base + (q + S - 1) % S, b = base + q, c = base + (q + 1) % S;
        if (!vi[b] && vi[a] == 1 && vi[c] == 1) { col[b] = 0.5f * (col[a] + col[c]); vi[b] = 2; }
      }
      for (int q = 0; q < S; ++q)
        if (vi[base + q] == 2) vi[base + q] = 1;
    }
    std::uint64_t* w = mask_bits.data() + i * mask_words;
    for (int s = 0; s < k; ++s)
      if (vi[s]) w[s / 64] |= std::uint64_t(1) << (s % 64);
  };

  // Pass 1: descriptors of the training subset (all seeds when there are few), K-SVD.
  std::vector<long> train_of(n, -1);
  std::vector<long> train_seeds;
  if (long(n) > prm.max_training_patches) {
    std::vector<long> order(n);
    std::iota(order.begin(), order.end(), 0L);
    Random rng(prm.random_seed + 7);
    for (std::size_t i = n - 1; i > 0; --i) std::swap(order[i], order[rng.below(i + 1)]);
    train_seeds.assign(order.begin(), order.begin() + prm.max_training_patches);
    std::sort(train_seeds.begin(), train_seeds.end());
  } else {
    train_seeds.resize(n);
    std::iota(train_seeds.begin(), train_seeds.end(), 0L);
  }
  for (std::size_t t = 0; t < train_seeds.size(); ++t) train_of[train_seeds[t]] = long(t);
  ProgressReporter prog(progress, "patch descriptors", n);
  Eigen::MatrixXf train(k, long(train_seeds.size()));
#pragma omp parallel
  {
    std::vector<int> nb;
    std::vector<float> d2;
    std::vector<std::uint8_t> vi;
#pragma omp for schedule(dynamic, 16)
    for (long t = 0; t < long(train_seeds.size()); ++t) {
      if (prog.cancelled()) continue;
      describeSeed(std::size_t(train_seeds[t]), nb, d2, train.col(t).data(), vi);
      prog.advance();
    }
  }
  prog.throwIfCancelled();
  rep.seconds_descriptors = lap();
  KSvdParameters kp;
  kp.atoms = prm.atoms;
  kp.sparsity = prm.sparsity;
  kp.iterations = prm.ksvd_iterations;
  kp.seed = prm.random_seed;
  ByteWriter dict;
  Eigen::MatrixXf D(k, prm.atoms);
  {
    const KSvdResult ks = learnDictionaryKSvd(train, kp, progress);
    SymbolWriter dw;
    AtomResidualCoder coder;
    const int L_dict = h.dictionaryLevels();
    std::vector<int> q(k);
    for (int j = 0; j < prm.atoms; ++j) {
      float scale = ks.dictionary.col(j).cwiseAbs().maxCoeff();
      if (!(scale > 0 && std::isfinite(scale))) scale = 1.f;
      dict.f32(scale);
      for (int s = 0; s < k; ++s) {
        q[s] = std::clamp(int(std::lround(ks.dictionary(s, j) / scale * L_dict)), -L_dict,
                          L_dict);
        coder.put(dw, q[s] - atomPrediction(q.data(), s, h.sectors(), L_dict));
        D(s, j) = float(q[s]) * scale / L_dict;
      }
    }
    dict.raw(dw.finish());
  }
  rep.seconds_dictionary = lap();

  // Pass 2: by blocks of seeds, the descriptors not computed yet and the sparse codes on the
  // quantized dictionary; only one block of descriptors is held at a time.
  std::vector<SparseCode> codes(n);
  double err2 = 0, nvalid = 0;
  {
    constexpr long kBlock = 2048;
    Eigen::MatrixXf Yb;
    for (long b0 = 0; b0 < long(n); b0 += kBlock) {
      const long bn = std::min<long>(kBlock, long(n) - b0);
      Yb.resize(k, bn);
#pragma omp parallel
      {
        std::vector<int> nb;
        std::vector<float> d2;
        std::vector<std::uint8_t> vi;
#pragma omp for schedule(dynamic, 16)
        for (long j = 0; j < bn; ++j) {
          if (prog.cancelled()) continue;
          const long i = b0 + j;
          if (train_of[i] >= 0) {
            Yb.col(j) = train.col(train_of[i]);
          } else {
            describeSeed(std::size_t(i), nb, d2, Yb.col(j).data(), vi);
            prog.advance();
          }
        }
      }
      prog.throwIfCancelled();
      std::vector<SparseCode> bc = orthogonalMatchingPursuit(D, Yb, prm.sparsity);
      for (long j = 0; j < bn; ++j) {
        const std::size_t i = std::size_t(b0 + j);
        Eigen::VectorXf yr = Eigen::VectorXf::Zero(k);
        for (std::size_t a = 0; a < bc[j].size(); ++a) yr += D.col(bc[j].atoms[a]) * bc[j].values[a];
        for (int s = 0; s < k; ++s)
          if (isValid(i, s)) { err2 += double(yr[s] - Yb(s, j)) * (yr[s] - Yb(s, j)); nvalid += 1; }
        codes[i] = std::move(bc[j]);
      }
    }
  }
  train.resize(0, 0);
  grid.reset();  // the cloud's index is not needed to code the symbols
  prog.finish();
  rep.seconds_dictionary += lap();

  // Frame stream.
  SymbolWriter fw;
  {
    AdaptiveModel ma(L), mb(L), mg(L);
    for (std::size_t i = 0; i < n; ++i) { fw.put(ma, qangles[i][0]); fw.put(mb, qangles[i][1]); fw.put(mg, qangles[i][2]); }
  }
  const std::vector<std::uint8_t> frame_bytes = fw.finish(&rep.frames_method, rep.frames_sizes);

  // Coefficients: scalar quantization, then the patch symbol stream.
  float cmax = 0;
  for (const auto& c : codes)
    for (float v : c.values) cmax = std::max(cmax, std::abs(v));
  const int qlim = (1 << (prm.coefficient_bits - 1)) - 1;
  h.coefficient_step = cmax > 0 && std::isfinite(cmax) ? cmax / float(qlim) : 1.f;
  PatchModels pm(h);
  SymbolWriter pw;
  double nnz = 0;
  auto cost = [](const AdaptiveModel& m, int sym) { return -std::log2(double(m.frequency(sym)) / m.total()); };
  std::vector<std::uint8_t> vi(k);
  std::vector<std::pair<int, int>> q;
  // The decoder's frames, for the mask sharing of format 2.
  LocalFrames frames(n);
  for (std::size_t i = 0; i < n; ++i) frames[i] = correctedFrame(pred[i], qangles[i][0], qangles[i][1], qangles[i][2], L);
  const SpatialIndex seed_index(seeds);
  const SharedMasks shared(h, seeds, frames, seed_index);
  if (shared.crowded())
    throw InvalidInput("more than " + std::to_string(kMaxSeedNeighbours) +
                       " seeds lie within 2 R of one seed: the points fill a volume, not a surface "
                       "(a larger seed_spacing or patch radius may help)");
  std::vector<long> src;
  std::vector<int> snb;
  std::vector<float> sd2;
  for (std::size_t i = 0; i < n; ++i) {
    shared.sources(i, src, snb, sd2);
    bool all = true;
    for (int s = 0; s < k; ++s)
      if (src[s] < 0) all = all && isValid(i, s);
    rep.bits_masks += cost(pm.all_valid, all ? 1 : 0);
    pw.put(pm.all_valid, all ? 1 : 0);
    if (!all)
      for (int s = 0; s < k; ++s) {
        if (src[s] >= 0) {
          // Copied: known to the decoder only when the owner came earlier.
          const std::size_t j = std::size_t(src[s] / k);
          vi[s] = j < i ? std::uint8_t(isValid(j, int(src[s] % k))) : 2;
          continue;
        }
        vi[s] = std::uint8_t(isValid(i, s));
        AdaptiveModel& mm = pm.mask[sharedMaskContext(vi.data(), s, h.sectors())];
        rep.bits_masks += cost(mm, vi[s]);
        pw.put(mm, vi[s]);
      }
    q.clear();
    for (std::size_t a = 0; a < codes[i].size(); ++a) {
      const int v = std::clamp(int(std::lround(codes[i].values[a] / h.coefficient_step)), -qlim, qlim);
      if (v != 0) q.push_back({codes[i].atoms[a], v});
    }
    std::sort(q.begin(), q.end());
    pw.put(pm.count, int(q.size()));
    int prev = -1;
    for (const auto& [atom, v] : q) {
      rep.bits_atoms += cost(pm.gap, atom - prev - 1);
      pw.put(pm.gap, atom - prev - 1);
      prev = atom;
      rep.bits_values += cost(pm.value[atom], zigzag(v));
      pw.put(pm.value[atom], zigzag(v));
    }
    nnz += double(q.size());
  }
  const std::vector<std::uint8_t> patch_bytes = pw.finish(&rep.patches_method, rep.patches_sizes);
  rep.mean_nonzeros = nnz / double(n);
  rep.ksvd_rmse = nvalid > 0 ? std::sqrt(err2 / nvalid) : 0;
  rep.valid_fraction = nvalid / (double(n) * k);

  std::vector<Section> sections(5);
  sections[0] = {kTagParm, h.write()};
  sections[1] = {kTagSeed, seed_bytes};
  sections[2] = {kTagFram, frame_bytes};
  sections[3] = {kTagDict, dict.bytes};
  sections[4] = {kTagPtch, patch_bytes};
  std::vector<std::uint8_t> out = writeContainer(sections);
  rep.seconds_coding = lap();
  rep.bytes_total = out.size();
  rep.bytes_seeds = seed_bytes.size();
  rep.bytes_frames = frame_bytes.size();
  rep.bytes_dictionary = dict.bytes.size();
  rep.bytes_patches = patch_bytes.size();
  rep.bytes_header = out.size() - rep.bytes_seeds - rep.bytes_frames - rep.bytes_dictionary - rep.bytes_patches;
  if (report) *report = rep;
  return out;
}

Positions decompressPositions(const std::uint8_t* data, std::size_t size, const DecodeOptions& o,
                              DecodeReport* report, const ProgressCallback& progress) {
  std::uint32_t version = 0;
  const std::vector<Section> sections = readContainer(data, size, &version);
  auto find = [&](std::uint32_t tag) -> const std::vector<std::uint8_t>& {
    const std::vector<std::uint8_t>* found = nullptr;
    for (const auto& s : sections)
      if (s.tag == tag) {
        if (found) throw CorruptStream("section '" + tagName(tag) + "' appears twice");
        found = &s.payload;
      }
    if (!found) throw CorruptStream("section '" + tagName(tag) + "' is missing");
    return *found;
  };
  const Header h = Header::read(find(kTagParm), version, o);
  const std::size_t n = h.seeds;
  const int k = h.samples(), L = h.angleLevels();

  // Seeds.
  const std::vector<VoxelCoordinate> vox = decodeVoxels(find(kTagSeed), n, h.seed_bits);
  Positions seeds(n);
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) seeds[i][a] = h.lo[a] + float(vox[i][a]) * h.seed_step;
  for (const auto& s : seeds)
    if (!isFinite(s)) throw CorruptStream("a seed position is not finite");

  // Frames.
  LocalFrames frames = predictFrames(seeds);
  {
    SymbolReader fr(find(kTagFram), 3 * n, "frame");
    AdaptiveModel ma(L), mb(L), mg(L);
    for (std::size_t i = 0; i < n; ++i) {
      const int qa = fr.get(ma), qb = fr.get(mb), qg = fr.get(mg);
      frames[i] = correctedFrame(frames[i], qa, qb, qg, L);
    }
    fr.checkEnd();
  }

  // Dictionary.
  Eigen::MatrixXf D(k, h.atoms);
  {
    const auto& b = find(kTagDict);
    ByteReader r(b.data(), b.size(), "dictionary section");
    std::vector<float> scale(h.atoms);
    for (auto& s : scale) s = r.f32In("atom scale", 0.f, 1e30f);
    const std::uint8_t* rest = r.take(r.left());
    const std::vector<std::uint8_t> sym(rest, b.data() + b.size());
    const int L_dict = h.dictionaryLevels();
    SymbolReader dr(sym, std::size_t(k) * h.atoms * (h.version >= 2 ? AtomResidualCoder::kClasses : 1), "dictionary");
    if (h.version >= 2) {
      AtomResidualCoder coder;
      std::vector<int> q(k);
      for (int j = 0; j < h.atoms; ++j)
        for (int s = 0; s < k; ++s) {
          q[s] = atomPrediction(q.data(), s, h.sectors(), L_dict) + coder.get(dr);
          if (q[s] < -L_dict || q[s] > L_dict) throw CorruptStream("dictionary value out of range");
          D(s, j) = float(q[s]) * scale[j] / L_dict;
        }
    } else {
      AdaptiveModel first(2 * L_dict + 1), delta(4 * L_dict + 1);
      for (int j = 0; j < h.atoms; ++j) {
        int prev = 0;
        for (int s = 0; s < k; ++s) {
          const int q = s == 0 ? dr.get(first) - L_dict : prev + dr.get(delta) - 2 * L_dict;
          if (q < -L_dict || q > L_dict) throw CorruptStream("dictionary value out of range");
          prev = q;
          D(s, j) = float(q) * scale[j] / L_dict;
        }
      }
    }
    dr.checkEnd();
  }

  // Patches: heights and masks.
  const SpatialIndex seed_index(seeds);
  const RadialLayout layout(h);
  std::vector<std::int16_t> heights(std::size_t(k) * n);
  std::vector<std::uint8_t> valid(std::size_t(k) * n);
  {
    PatchModels pm(h);
    SymbolReader pr(find(kTagPtch), n * (2 + k + 2 * h.sparsity), "patch");
    const int qlim = (1 << (h.coefficient_bits - 1)) - 1;
    Eigen::VectorXf y(k);
    std::unique_ptr<SharedMasks> shared;
    if (h.version >= 2) {
      shared = std::make_unique<SharedMasks>(h, seeds, frames, seed_index);
      if (shared->crowded()) tooManySeedNeighbours();
    }
    std::vector<long> src;
    std::vector<int> snb;
    std::vector<float> sd2;
    for (std::size_t i = 0; i < n; ++i) {
      std::uint8_t* vi = valid.data() + i * k;
      if (!shared) {
        if (pr.get(pm.all_valid)) std::fill(vi, vi + k, 1);
        else
          for (int s = 0; s < k; ++s) vi[s] = std::uint8_t(pr.get(pm.mask[maskContext(vi, s, h.sectors())]));
      } else {
        // Format 2: coded samples are read; copied ones are taken from an earlier owner now
        // and marked 2 when the owner comes later (resolved below).
        shared->sources(i, src, snb, sd2);
        const bool all = pr.get(pm.all_valid) != 0;
        for (int s = 0; s < k; ++s) {
          if (src[s] >= 0) {
            vi[s] = std::size_t(src[s] / k) < i ? valid[std::size_t(src[s])] : 2;
          } else {
            vi[s] = all ? 1 : std::uint8_t(pr.get(pm.mask[sharedMaskContext(vi, s, h.sectors())]));
          }
        }
      }
      const int m = pr.get(pm.count);
      int prev = -1;
      y.setZero();
      for (int c = 0; c < m; ++c) {
        const int atom = prev + 1 + pr.get(pm.gap);
        if (atom >= h.atoms) throw CorruptStream("patch coefficient names atom " + std::to_string(atom) + " of " + std::to_string(h.atoms));
        prev = atom;
        const int v = unzigzag(pr.get(pm.value[atom]));
        if (v < -qlim || v > qlim) throw CorruptStream("patch coefficient out of range");
        y += D.col(atom) * (float(v) * h.coefficient_step);
      }
      if (!y.allFinite()) throw CorruptStream("decoded heights are not finite");
      for (int s = 0; s < k; ++s) heights[i * k + s] = layout.quantize(y[s]);
    }
    pr.checkEnd();
    if (shared) {
      // Copies from owners that came later. A copy's source is a coded sample, so it is final.
#pragma omp parallel
      {
        std::vector<long> src_t;
        std::vector<int> nb_t;
        std::vector<float> d2_t;
#pragma omp for schedule(dynamic, 64)
        for (long i = 0; i < long(n); ++i) {
          std::uint8_t* vi = valid.data() + std::size_t(i) * k;
          if (std::find(vi, vi + k, std::uint8_t(2)) == vi + k) continue;
          shared->sources(std::size_t(i), src_t, nb_t, d2_t);
          for (int s = 0; s < k; ++s)
            if (vi[s] == 2) vi[s] = valid[std::size_t(src_t[s])];
        }
      }
    }
  }

  // Point generation: a grid at the output spacing in each patch, kept in the seed's
  // Voronoi cell (where a neighbouring patch with data is closer, that patch places it),
  // then consolidated where the nearby patches agree. Seeds are processed by blocks (in
  // parallel inside a block); the points of a block are then regularised in seed order by
  // streaming Poisson-disk thinning at half the spacing, so only one block of unthinned
  // points is ever held.
  const float R = h.radius, s = h.spacing;
  ProgressReporter prog(progress, "decoding patches", n);
  const int G = int(std::ceil(R / s));
  DecodeReport rep;
  Positions out;
  {
    // At most the grid points of every disk; the encoder's count is a good guess of the
    // output size. Both are bounded by max_points (checked with the header).
    const double per_seed_bound = double(kPi) * (R / s + 1.5) * (R / s + 1.5);
    const double bound = std::min(double(n) * per_seed_bound, double(o.max_points));
    out.reserve(std::size_t(std::min(bound, double(h.points) * 1.05 + 1024.0)));
  }
  detail::ThinningGrid thin(0.5f * s, out.capacity());
  if (o.regularise) thin.reserve(out.capacity());
  std::size_t generated = 0;
  constexpr long kBlock = 512;  // 1.2 MB of unthinned points on rs1 1M (1024: 2.5 MB)
  std::vector<Positions> per_seed(std::min<std::size_t>(n, kBlock));
  bool too_many = false;
  for (long b0 = 0; b0 < long(n); b0 += kBlock) {
    const long bn = std::min<long>(kBlock, long(n) - b0);
#pragma omp parallel reduction(|| : too_many)
    {
      std::vector<int> nb, close;
      std::vector<float> d2;
#pragma omp for schedule(dynamic, 16)
      for (long bi = 0; bi < bn; ++bi) {
        const long i = b0 + bi;
        Positions& mine_out = per_seed[bi];
        mine_out.clear();
        if (prog.cancelled()) continue;
        const std::int16_t* yi = heights.data() + std::size_t(i) * k;
        const std::uint8_t* vi = valid.data() + std::size_t(i) * k;
        const LocalFrame& fi = frames[i];
        const int cnt = seed_index.radiusSearch(seeds[i], 2.05f * R, nb, d2, kMaxSeedNeighbours + 1);
        if (cnt > kMaxSeedNeighbours) {
          // Thrown outside the parallel region: flag and stop this thread's work.
          too_many = true;
          continue;
        }
        for (int gy = -G; gy < G; ++gy)
          for (int gx = -G; gx < G; ++gx) {
            const float u = (gx + 0.5f) * s, v = (gy + 0.5f) * s;
            if (u * u + v * v > R * R) continue;
            float hh;
            if (!layout.height(yi, vi, u / R, v / R, hh)) continue;
            Eigen::Vector3f p = seeds[i] + fi.toWorld(Eigen::Vector3f(u, v, hh));
            const float di = (p - seeds[i]).squaredNorm();
            bool mine = true;
            close.clear();
            for (int c = 0; c < cnt && mine; ++c) {
              const int j = nb[c];
              if (j == i) continue;
              const float dj = (p - seeds[j]).squaredNorm();
              if (dj < R * R) close.push_back(j);
              if (dj < di) {
                const Eigen::Vector3f l = frames[j].toLocal(p - seeds[j]);
                float hj;
                if (layout.height(heights.data() + std::size_t(j) * k, valid.data() + std::size_t(j) * k, l.x() / R,
                                  l.y() / R, hj))
                  mine = false;
              }
            }
            if (!mine) continue;
            if (o.consolidate && !close.empty()) {
              const float wi0 = 1.f - di / (R * R);
              float wsum = wi0 * wi0;
              Eigen::Vector3f acc = p * wsum;
              for (const int j : close) {
                const Eigen::Vector3f l = frames[j].toLocal(p - seeds[j]);
                float hj;
                if (!layout.height(heights.data() + std::size_t(j) * k, valid.data() + std::size_t(j) * k, l.x() / R,
                                   l.y() / R, hj))
                  continue;
                const Eigen::Vector3f q = seeds[j] + frames[j].toWorld(Eigen::Vector3f(l.x(), l.y(), hj));
                const float t = 1.f - (p - seeds[j]).squaredNorm() / (R * R);
                const float w = t * t;
                acc += w * q;
                wsum += w;
              }
              if (wsum > 0) p = acc / wsum;
            }
            mine_out.push_back(p);
          }
        prog.advance();
      }
    }
    prog.throwIfCancelled();
    if (too_many) tooManySeedNeighbours();
    for (long bi = 0; bi < bn; ++bi) {
      generated += per_seed[bi].size();
      if (generated > o.max_points) throw CorruptStream("decoded point count exceeds the limit");
      if (o.regularise) {
        for (const auto& p : per_seed[bi]) thin.offer(p, out);
      } else {
        out.insert(out.end(), per_seed[bi].begin(), per_seed[bi].end());
      }
    }
  }
  prog.finish();
  per_seed.clear();
  per_seed.shrink_to_fit();
  rep.seeds = n;
  rep.patch_radius = R;
  rep.output_spacing = s;
  rep.encoded_points = h.points;
  rep.removed_by_regularisation = generated - out.size();
  rep.points = out.size();
  if (report) *report = rep;
  return out;
}

}  // namespace paps::compression
