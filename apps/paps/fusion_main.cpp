// `paps-fusion`: the commands of `paps` that read or write images (make-street, register,
// rgbd-photo, colorize, shadows, bench fusion). `paps` hands these commands to it (exec, same
// arguments), so that `paps` itself does not link OpenCV's image codecs: they pull in GDAL
// and about 140 shared libraries, which took about half of every `paps` start-up (0.40 s).
#include <cstdio>
#include <cstring>
#include <exception>

#include <paps/core/error.h>
#include <paps/core/interrupt_cleanup.h>

#include "cli_common.h"
#include "commands.h"

int main(int argc, char** argv) {
  paps::installInterruptCleanup();  // an interrupted write leaves no temporary file
  try {
    paps::cli::takeThreadsOption(argc, argv);
  } catch (const paps::Error& e) {
    std::fprintf(stderr, "paps: error: %s\n", e.what());
    return 1;
  }
  const char* usage =
      "usage: paps-fusion COMMAND ... (normally run as 'paps COMMAND ...')\n"
      "  make-street, register, rgbd-photo, colorize, shadows, bench fusion: see 'paps --help'\n";
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    std::fputs(usage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  // Messages say "paps": users type `paps register ...`.
  try {
    if (!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "fusion")) return paps::cli::runBenchFusion(argc, argv);
    if (!std::strcmp(argv[1], "register")) return paps::cli::runRegister(argc, argv);
    if (!std::strcmp(argv[1], "rgbd-photo")) return paps::cli::runRgbdPhoto(argc, argv);
    if (!std::strcmp(argv[1], "make-street")) return paps::cli::runMakeStreet(argc, argv);
    if (!std::strcmp(argv[1], "colorize")) return paps::cli::runColorize(argc, argv);
    if (!std::strcmp(argv[1], "shadows")) return paps::cli::runShadows(argc, argv);
    std::fprintf(stderr, "paps-fusion: unknown command '%s'\n%s", argv[1], usage);
    return 2;
  } catch (const paps::Error& e) {
    std::fprintf(stderr, "paps: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "paps: unexpected error: %s\n", e.what());
    return 1;
  }
}
