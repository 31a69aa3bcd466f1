#include <paps/compression/seed_coder.h>

#include <algorithm>
#include <memory>

#include <paps/compression/bitstream.h>
#include <paps/compression/range_coder.h>

namespace paps::compression {
namespace {

constexpr std::size_t kModelled = 32;  // counts up to this use adaptive models

struct CountModels {
  std::vector<std::unique_ptr<AdaptiveModel>> by_n;
  CountModels() {
    by_n.resize(kModelled + 1);
    for (std::size_t n = 1; n <= kModelled; ++n) by_n[n] = std::make_unique<AdaptiveModel>(int(n) + 1, 24);
  }
};

struct Cell {
  std::uint32_t lo[3];
  int lev[3];
  int splitAxis() const {
    int a = 0;
    for (int k = 1; k < 3; ++k)
      if (lev[k] > lev[a]) a = k;
    return a;
  }
  bool leaf() const { return lev[0] == 0 && lev[1] == 0 && lev[2] == 0; }
};

void putCount(RangeEncoder& enc, CountModels& m, std::size_t c, std::size_t n) {
  if (n <= kModelled) { enc.encode(*m.by_n[n], int(c)); return; }
  if (n + 1 <= 65536) { enc.encode(std::uint32_t(c), 1, std::uint32_t(n + 1)); return; }
  enc.encode(std::uint32_t(c >> 16), 1, std::uint32_t((n >> 16) + 1));
  enc.encodeBits(std::uint32_t(c & 0xFFFF), 16);
}

std::size_t getCount(RangeDecoder& dec, CountModels& m, std::size_t n) {
  std::size_t c;
  if (n <= kModelled) {
    c = std::size_t(dec.decode(*m.by_n[n]));
  } else if (n + 1 <= 65536) {
    c = dec.decodeTarget(std::uint32_t(n + 1));
    dec.consume(std::uint32_t(c), 1);
  } else {
    const std::uint32_t hi = dec.decodeTarget(std::uint32_t((n >> 16) + 1));
    dec.consume(hi, 1);
    c = (std::size_t(hi) << 16) | dec.decodeBits(16);
  }
  if (c > n) throw CorruptStream("seed positions: a cell count exceeds its parent's");
  if (dec.overrun()) throw CorruptStream("seed positions stream ends too early");
  return c;
}

void encodeCell(RangeEncoder& enc, CountModels& m, VoxelCoordinate* begin, VoxelCoordinate* end, Cell cell) {
  const std::size_t n = std::size_t(end - begin);
  if (n == 0 || cell.leaf()) return;
  const int a = cell.splitAxis();
  const std::uint32_t mid = cell.lo[a] + (1u << (cell.lev[a] - 1));
  VoxelCoordinate* split = std::partition(begin, end, [&](const VoxelCoordinate& v) { return v[a] < mid; });
  putCount(enc, m, std::size_t(split - begin), n);
  Cell left = cell, right = cell;
  left.lev[a] = right.lev[a] = cell.lev[a] - 1;
  right.lo[a] = mid;
  encodeCell(enc, m, begin, split, left);
  encodeCell(enc, m, split, end, right);
}

void decodeCell(RangeDecoder& dec, CountModels& m, std::size_t n, Cell cell, std::vector<VoxelCoordinate>& out) {
  if (n == 0) return;
  if (cell.leaf()) {
    if (n != 1) throw CorruptStream("seed positions: two seeds in one voxel");
    out.push_back({cell.lo[0], cell.lo[1], cell.lo[2]});
    return;
  }
  const int a = cell.splitAxis();
  const std::size_t c = getCount(dec, m, n);
  Cell left = cell, right = cell;
  left.lev[a] = right.lev[a] = cell.lev[a] - 1;
  right.lo[a] = cell.lo[a] + (1u << (cell.lev[a] - 1));
  decodeCell(dec, m, c, left, out);
  decodeCell(dec, m, n - c, right, out);
}

}  // namespace

std::vector<std::uint8_t> encodeVoxels(std::vector<VoxelCoordinate>& voxels, int bits) {
  requireInRange("seed_bits", bits, 1, 21);
  RangeEncoder enc;
  CountModels m;
  Cell root{{0, 0, 0}, {bits, bits, bits}};
  encodeCell(enc, m, voxels.data(), voxels.data() + voxels.size(), root);
  return enc.finish();
}

std::vector<VoxelCoordinate> decodeVoxels(const std::vector<std::uint8_t>& payload, std::size_t count, int bits) {
  if (bits < 1 || bits > 21) throw CorruptStream("seed bits out of range");
  if (count > (std::size_t(1) << std::min(3 * bits, 40))) throw CorruptStream("more seeds than voxels");
  RangeDecoder dec(payload.data(), payload.size());
  CountModels m;
  std::vector<VoxelCoordinate> out;
  out.reserve(count);
  decodeCell(dec, m, count, Cell{{0, 0, 0}, {bits, bits, bits}}, out);
  if (dec.overrun()) throw CorruptStream("seed positions stream ends too early");
  return out;
}

}  // namespace paps::compression
