// `paps-codec`: the compress and decompress commands of `paps` in a binary that links only
// what the codec needs (no PCL I/O, hence no VTK): 7 MB of shared libraries mapped at start
// instead of 61 MB, which matters for the codec's memory budget (3x the input cloud).
// It reads binary PCD files with float x y z; other inputs go through `paps compress`.
#include <cstdio>
#include <cstring>
#include <exception>

#include <paps/core/error.h>
#include <paps/core/interrupt_cleanup.h>

#include "../paps/cli_common.h"
#include "../paps/commands.h"

int main(int argc, char** argv) {
  paps::installInterruptCleanup();  // an interrupted write leaves no temporary file
  try {
    paps::cli::takeThreadsOption(argc, argv);  // as in paps: --threads N anywhere on the line
  } catch (const paps::Error& e) {
    std::fprintf(stderr, "paps-codec: error: %s\n", e.what());
    return 1;
  }
  const char* usage =
      "usage: paps-codec compress IN.pcd OUT.paps [options]   (binary PCD, float x y z)\n"
      "       paps-codec decompress IN.paps OUT.{pcd,ply} [options]\n"
      "The options are those of 'paps compress' and 'paps decompress' (--help on each);\n"
      "--threads N bounds the threads, as in paps.\n";
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    std::fputs(usage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  try {
    if (!std::strcmp(argv[1], "compress")) return paps::cli::runCompress(argc, argv);
    if (!std::strcmp(argv[1], "decompress")) return paps::cli::runDecompress(argc, argv);
    std::fprintf(stderr, "paps-codec: unknown command '%s'\n%s", argv[1], usage);
    return 2;
  } catch (const paps::Error& e) {
    std::fprintf(stderr, "paps-codec: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "paps-codec: unexpected error: %s\n", e.what());
    return 1;
  }
}
