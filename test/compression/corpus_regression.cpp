// Replays every file of the fuzzing corpus (test/compression/corpus/) through the decoder,
// each with its own expected outcome: the complete seed streams (format 1 and the `v2-*`
// format-2 files) decode to finite points, as many as when they were pinned; the truncated
// stream throws CorruptStream. A new file in the corpus must be given its expectation here.
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <string>

#include <gtest/gtest.h>

#include <paps/compression/bitstream.h>
#include <paps/compression/self_similarity_codec.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace compression_corpus_regression_test {

std::vector<std::uint8_t> corpusFile(const std::string& name) {
  std::ifstream f(std::string(PAPS_COMPRESSION_CORPUS_DIR) + "/" + name, std::ios::binary);
  EXPECT_TRUE(f.good()) << name;
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

paps::compression::DecodeOptions corpusOptions() {
  paps::compression::DecodeOptions o;
  o.max_points = 2000000;
  o.max_seeds = 50000;
  return o;
}

// Complete streams and the number of points each decodes to with the default decoder
// (consolidation and regularisation on), measured when pinned. The decoder is
// deterministic: a change here is a change of the decoded output.
const std::map<std::string, std::size_t> kCompleteStreams = {
    {"engraved-compact.paps", 2101},    {"engraved-fine.paps", 2286},    {"sphere-balanced.paps", 1345},
    {"v2-engraved-compact.paps", 2248}, {"v2-engraved-fine.paps", 1543}, {"v2-sphere-balanced.paps", 1355},
};
const std::set<std::string> kTruncatedStreams = {"engraved-compact-truncated.paps"};

TEST(CompressionCorpus, EveryFileHasAnExpectation) {
  const std::filesystem::path dir = PAPS_COMPRESSION_CORPUS_DIR;
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  std::size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    const std::string name = e.path().filename().string();
    ++files;
    EXPECT_TRUE(kCompleteStreams.count(name) + kTruncatedStreams.count(name) == 1)
        << name << ": a corpus file with no expectation in corpus_regression.cpp";
  }
  EXPECT_EQ(files, kCompleteStreams.size() + kTruncatedStreams.size());
}

TEST(CompressionCorpus, CompleteStreamsDecodeToTheirPinnedCount) {
  for (const auto& [name, count] : kCompleteStreams) {
    const auto b = corpusFile(name);
    ASSERT_GT(b.size(), 12u) << name;
    EXPECT_EQ(b[8], name.rfind("v2-", 0) == 0 ? 2 : 1) << name << ": format version byte";
    paps::compression::DecodeReport r;
    const auto p = paps::compression::decompressPositions(b.data(), b.size(), corpusOptions(), &r);
    EXPECT_EQ(p.size(), count) << name;
    EXPECT_EQ(r.points, p.size()) << name;
    for (const auto& x : p) ASSERT_TRUE(paps::isFinite(x)) << name;
  }
}

TEST(CompressionCorpus, TruncatedStreamThrowsCorruptStream) {
  for (const auto& name : kTruncatedStreams) {
    const auto b = corpusFile(name);
    ASSERT_FALSE(b.empty()) << name;
    EXPECT_THROW(paps::compression::decompressPositions(b.data(), b.size(), corpusOptions()),
                 paps::compression::CorruptStream)
        << name;
  }
}

// The format-2 sphere decodes onto the unit sphere, like the format-1 one below.
TEST(CompressionCorpus, FormatTwoStreamDecodesOntoItsSphere) {
  const auto b = corpusFile("v2-sphere-balanced.paps");
  ASSERT_GT(b.size(), 12u);
  EXPECT_EQ(b[8], 2) << "the file is meant to be a format-2 stream";
  const auto p = paps::compression::decompressPositions(b.data(), b.size());
  EXPECT_EQ(p.size(), kCompleteStreams.at("v2-sphere-balanced.paps"));
  for (const auto& x : p) {
    ASSERT_GT(x.norm(), 0.95f);
    ASSERT_LT(x.norm(), 1.05f);
  }
}

// Format 1 (masks coded in full, 8-bit atoms as plain deltas) is still read: the corpus's
// unit sphere, written by the format-1 encoder, decodes onto the sphere.
TEST(CompressionCorpus, FormatOneStreamStillDecodesOntoItsSphere) {
  const auto b = corpusFile("sphere-balanced.paps");
  ASSERT_GT(b.size(), 12u);
  EXPECT_EQ(b[8], 1) << "the file is meant to be a format-1 stream";
  const auto p = paps::compression::decompressPositions(b.data(), b.size());
  EXPECT_EQ(p.size(), kCompleteStreams.at("sphere-balanced.paps"));  // from 1,500 input points
  for (const auto& x : p) {
    ASSERT_GT(x.norm(), 0.95f);
    ASSERT_LT(x.norm(), 1.05f);
  }
}

}  // namespace compression_corpus_regression_test
