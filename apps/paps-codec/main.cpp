// `paps-codec`: the compress and decompress commands of `paps` in a binary that links only
// what the codec needs (no PCL I/O, hence no VTK): 7 MB of shared libraries mapped at start
// instead of 61 MB, which matters for the codec's memory budget (3x the input cloud).
// It reads binary PCD files with float x y z; other inputs go through `paps compress`.
#include <cstring>

#include "../paps/cli_common.h"
#include "../paps/commands.h"

int main(int argc, char** argv) {
  const char* usage =
      "usage: paps-codec compress IN.pcd OUT.paps [options]   (binary PCD, float x y z)\n"
      "       paps-codec decompress IN.paps OUT.{pcd,ply} [options]\n"
      "The options are those of 'paps compress' and 'paps decompress' (--help on each);\n"
      "--threads N bounds the threads, as in paps.\n";
  return paps::cli::runCommandLine(argc, argv, "paps-codec", usage, [](int argc, char** argv) {
    if (!std::strcmp(argv[1], "compress")) return paps::cli::runCompress(argc, argv);
    if (!std::strcmp(argv[1], "decompress")) return paps::cli::runDecompress(argc, argv);
    return paps::cli::kUnknownCommand;
  });
}
