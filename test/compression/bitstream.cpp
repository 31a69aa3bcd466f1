// Tests of the range coder, the container and the seed coder: exact round trips, and every
// truncation or bit flip rejected with CorruptStream.
#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include <paps/compression/bitstream.h>
#include <paps/compression/range_coder.h>
#include <paps/compression/seed_coder.h>
#include <paps/core/random.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace compression_bitstream_test {

using namespace paps::compression;

TEST(RangeCoder, RoundTripsSkewedAndFlatSymbols) {
  paps::Random rng(3);
  std::vector<int> a, b;
  std::vector<std::uint32_t> bits;
  for (int i = 0; i < 50000; ++i) {
    const bool zero = rng.uniform() < 0.9;
    a.push_back(zero ? 0 : int(rng.below(256)));
    b.push_back(int(rng.below(3)));
    bits.push_back(std::uint32_t(rng.next()));
  }
  RangeEncoder enc;
  AdaptiveModel ma(256), mb(3);
  for (int i = 0; i < 50000; ++i) { enc.encode(ma, a[i]); enc.encode(mb, b[i]); enc.encodeBits(bits[i] & 0x7FFFF, 19); }
  const auto bytes = enc.finish();
  // Adaptive models learn the skew: measured 136,885 bytes. The symbols' own entropy (0.9 x
  // 0 plus 0.1 x 256 values: 1.27 bits, log2(3), 19 raw bits) is about 136,600 bytes; flat models
  // (8 + log2 3 + 19 bits) would need 178,662.
  EXPECT_LT(bytes.size(), 140000u);
  RangeDecoder dec(bytes.data(), bytes.size());
  AdaptiveModel da(256), db(3);
  for (int i = 0; i < 50000; ++i) {
    ASSERT_EQ(dec.decode(da), a[i]);
    ASSERT_EQ(dec.decode(db), b[i]);
    ASSERT_EQ(dec.decodeBits(19), bits[i] & 0x7FFFF);
  }
  EXPECT_FALSE(dec.overrun());
}

TEST(RangeCoder, GarbageNeverCrashes) {
  paps::Random rng(4);
  std::vector<std::uint8_t> junk(64);
  for (auto& c : junk) c = std::uint8_t(rng.below(256));
  RangeDecoder dec(junk.data(), junk.size());
  AdaptiveModel m(100);
  for (int i = 0; i < 10000; ++i) {
    const int s = dec.decode(m);
    ASSERT_GE(s, 0);
    ASSERT_LT(s, 100);
  }
  EXPECT_TRUE(dec.overrun());
}

TEST(SymbolStreams, AllBackEndsRoundTrip) {
  paps::Random rng(5);
  std::vector<int> s(20000);
  for (auto& v : s) {
    const bool seven = rng.uniform() < 0.5;
    v = seven ? 7 : int(rng.below(40));
  }
  SymbolWriter w;
  AdaptiveModel m(40);
  for (int v : s) w.put(m, v);
  EntropyMethod chosen;
  std::size_t sizes[3];
  const auto bytes = w.finish(&chosen, sizes);
  EXPECT_EQ(bytes.size() - 1, std::min({sizes[0], sizes[1], sizes[2]}));
  // The best back end is within 2% of the symbols' empirical (order-0) entropy: measured
  // 9,030 bytes against 8,980.
  std::vector<int> count(40, 0);
  for (int v : s) ++count[v];
  double entropy_bits = 0;
  for (int c : count)
    if (c > 0) entropy_bits -= c * std::log2(double(c) / s.size());
  EXPECT_LT(double(bytes.size() - 1), 1.02 * entropy_bits / 8);
  SymbolReader r(bytes, s.size(), "test");
  AdaptiveModel rm(40);
  for (int v : s) ASSERT_EQ(r.get(rm), v);
  r.checkEnd();
}

TEST(Container, RoundTripAndRejectsEveryTruncationAndFlip) {
  std::vector<Section> sections{{sectionTag("PARM"), {1, 2, 3, 4}}, {sectionTag("DATA"), std::vector<std::uint8_t>(300, 9)}};
  const auto bytes = writeContainer(sections);
  const auto back = readContainer(bytes.data(), bytes.size());
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[1].payload, sections[1].payload);
  EXPECT_EQ(tagName(back[0].tag), "PARM");
  for (std::size_t len = 0; len < bytes.size(); ++len)
    EXPECT_THROW(readContainer(bytes.data(), len), CorruptStream) << "length " << len;
  for (std::size_t i = 0; i < bytes.size(); ++i)
    for (int bit = 0; bit < 8; bit += 3) {
      auto bad = bytes;
      bad[i] ^= std::uint8_t(1 << bit);
      EXPECT_THROW(readContainer(bad.data(), bad.size()), CorruptStream) << "byte " << i;
    }
  auto longer = bytes;
  longer.push_back(0);
  EXPECT_THROW(readContainer(longer.data(), longer.size()), CorruptStream);
  const std::string foreign = "ply\nformat ascii 1.0\n";
  try {
    readContainer(reinterpret_cast<const std::uint8_t*>(foreign.data()), foreign.size());
    FAIL();
  } catch (const CorruptStream& e) {
    EXPECT_NE(std::string(e.what()).find("magic"), std::string::npos);
  }
}

TEST(SeedCoder, RoundTripsDistinctVoxels) {
  paps::Random rng(6);
  std::vector<VoxelCoordinate> v;
  for (int i = 0; i < 5000; ++i)
    v.push_back({std::uint32_t(rng.below(65536)), std::uint32_t(rng.below(65536)), std::uint32_t(rng.below(512))});
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
  auto order = v;
  const auto bytes = encodeVoxels(order, 16);
  const auto back = decodeVoxels(bytes, v.size(), 16);
  EXPECT_EQ(back, order);
  auto sorted = back;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(sorted, v);
  // Close to the entropy of the set: choosing n voxels among 2^41 costs about
  // 41 - log2(n) + log2(e) bits a voxel (30.2 here); measured 32.8.
  const double set_bits = 41 - std::log2(double(v.size())) + std::log2(std::exp(1.0));
  EXPECT_LT(bytes.size() * 8.0 / v.size(), set_bits + 3.0);
  // Truncated: an error, not a crash.
  std::vector<std::uint8_t> cut(bytes.begin(), bytes.begin() + bytes.size() / 2);
  EXPECT_THROW(decodeVoxels(cut, v.size(), 16), CorruptStream);
}

}  // namespace compression_bitstream_test
