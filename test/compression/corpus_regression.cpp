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
