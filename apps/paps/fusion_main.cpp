// `paps-fusion`: the commands of `paps` that read or write images (make-street, register,
// rgbd-photo, colorize, shadows, bench fusion). `paps` hands these commands to it (exec, same
// arguments), so that `paps` itself does not link OpenCV's image codecs: they pull in GDAL
// and about 140 shared libraries, which took about half of every `paps` start-up (0.40 s).
#include <cstring>

#include "cli_common.h"
#include "commands.h"

int main(int argc, char** argv) {
  const char* usage =
      "usage: paps-fusion COMMAND ... (normally run as 'paps COMMAND ...')\n"
      "  make-street, register, rgbd-photo, colorize, shadows, bench fusion: see 'paps --help'\n";
  // Messages say "paps": users type `paps register ...`.
  return paps::cli::runCommandLine(argc, argv, "paps", usage, [](int argc, char** argv) {
    if (!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "fusion")) return paps::cli::runBenchFusion(argc, argv);
    if (!std::strcmp(argv[1], "register")) return paps::cli::runRegister(argc, argv);
    if (!std::strcmp(argv[1], "rgbd-photo")) return paps::cli::runRgbdPhoto(argc, argv);
    if (!std::strcmp(argv[1], "make-street")) return paps::cli::runMakeStreet(argc, argv);
    if (!std::strcmp(argv[1], "colorize")) return paps::cli::runColorize(argc, argv);
    if (!std::strcmp(argv[1], "shadows")) return paps::cli::runShadows(argc, argv);
    return paps::cli::kUnknownCommand;
  });
}
