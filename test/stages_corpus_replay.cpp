// Replays test/stages_corpus (the stage fuzz target's seeds and the inputs that once crashed
// it) through the target's entry point in an ordinary build: each must return, not crash.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

TEST(StagesCorpus, EveryInputReturns) {
  namespace fs = std::filesystem;
  const fs::path dir = PAPS_STAGES_CORPUS_DIR;
  ASSERT_TRUE(fs::is_directory(dir)) << dir;
  int seeds = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    SCOPED_TRACE(name);
    ASSERT_TRUE(name.rfind("seed-", 0) == 0 || name.rfind("regression-", 0) == 0);
    std::ifstream f(entry.path(), std::ios::binary);
    const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    EXPECT_EQ(LLVMFuzzerTestOneInput(bytes.data(), bytes.size()), 0);
    seeds += name.rfind("seed-", 0) == 0;
  }
  EXPECT_EQ(seeds, 11);  // one a stage
}
