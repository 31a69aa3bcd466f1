#pragma once
namespace paps::cli {
extern const char* kDenoiseUsage;
int runDenoise(int argc, char** argv);
int runBench(int argc, char** argv);
}  // namespace paps::cli
