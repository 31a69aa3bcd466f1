// libFuzzer target: the decoder must reject any input with paps::Error, never crash, hang or
// allocate without bound. Built by scripts/fuzz_compression.sh (clang, -fsanitize=fuzzer,address).
//
// Every section is CRC-checked, so random mutations would almost never get past the
// container. When the input's section lengths are consistent, the target therefore also
// decodes a copy whose checksums are recomputed, so that the mutations reach the parameter
// checks, the kd-tree seed decoder, the symbol streams and the point generation.
#include <cstddef>
#include <cstdint>
#include <vector>

#include <paps/compression/bitstream.h>
#include <paps/compression/self_similarity_codec.h>

namespace {
void decode(const std::uint8_t* data, std::size_t size) {
  paps::compression::DecodeOptions o;
  o.max_points = 2000000;  // keep each run short and small
  o.max_seeds = 50000;
  try {
    paps::compression::decompressPositions(data, size, o);
  } catch (const paps::Error&) {
  }
}

std::uint64_t le(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
void put32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = std::uint8_t(v >> (8 * i));
}

// Recomputes section and file CRCs in place; false when the layout is inconsistent.
bool fixChecksums(std::vector<std::uint8_t>& b) {
  if (b.size() < 16) return false;
  const std::uint64_t count = le(b.data() + 12, 4);
  if (count < 1 || count > 16) return false;
  std::size_t pos = 16;
  for (std::uint64_t s = 0; s < count; ++s) {
    if (b.size() - pos < 16) return false;
    const std::uint64_t len = le(b.data() + pos + 4, 8);
    if (len > b.size() - pos - 16) return false;
    put32(b.data() + pos + 12, paps::compression::crc32(b.data() + pos + 16, std::size_t(len)));
    pos += 16 + std::size_t(len);
  }
  if (b.size() - pos != 4) return false;
  put32(b.data() + pos, paps::compression::crc32(b.data(), pos));
  return true;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  decode(data, size);
  std::vector<std::uint8_t> fixed(data, data + size);
  if (fixChecksums(fixed)) decode(fixed.data(), fixed.size());
  return 0;
}
