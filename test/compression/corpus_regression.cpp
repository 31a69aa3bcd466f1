// Replays every file of the fuzzing corpus (seed streams and any crash the fuzzer found,
// test/compression/corpus/) through the decoder: each must decode or throw paps::Error.
#include <filesystem>
#include <fstream>
#include <iterator>

#include <gtest/gtest.h>

#include <paps/compression/self_similarity_codec.h>

TEST(CompressionCorpus, EveryFileDecodesOrFailsCleanly) {
  const std::filesystem::path dir = PAPS_COMPRESSION_CORPUS_DIR;
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  int files = 0, decoded = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    std::ifstream f(e.path(), std::ios::binary);
    const std::vector<std::uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    paps::compression::DecodeOptions o;
    o.max_points = 2000000;
    o.max_seeds = 50000;
    try {
      const auto p = paps::compression::decompressPositions(b.data(), b.size(), o);
      ++decoded;
      for (const auto& x : p) ASSERT_TRUE(paps::isFinite(x)) << e.path();
    } catch (const paps::Error&) {
    }
    ++files;
  }
  std::printf("%d corpus files, %d decode\n", files, decoded);
  EXPECT_GT(files, 0);
  EXPECT_GT(decoded, 0);  // the seed streams are valid
}

// Format 1 (masks coded in full, 8-bit atoms as plain deltas) is still read: the corpus's
// unit sphere, written by the format-1 encoder, decodes onto the sphere.
TEST(CompressionCorpus, FormatOneStreamStillDecodesOntoItsSphere) {
  std::ifstream f(std::string(PAPS_COMPRESSION_CORPUS_DIR) + "/sphere-balanced.paps", std::ios::binary);
  const std::vector<std::uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  ASSERT_GT(b.size(), 12u);
  EXPECT_EQ(b[8], 1) << "the file is meant to be a format-1 stream";
  const auto p = paps::compression::decompressPositions(b.data(), b.size());
  EXPECT_GT(p.size(), 1000u);  // 1,345 at the time of writing, from 1,500 input points
  for (const auto& x : p) {
    ASSERT_GT(x.norm(), 0.95f);
    ASSERT_LT(x.norm(), 1.05f);
  }
}
