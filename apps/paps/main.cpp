// The `paps` command line: one subcommand per algorithm, one clear error line on failure.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <cerrno>
#include <string>

#include <unistd.h>

#include "bench_worker.h"
#include "cli_common.h"
#include "commands.h"

namespace {
const char* kUsage =
    "PAPS: patch-aware processing of surfaces\n"
    "usage: paps COMMAND ...\n"
    "  denoise IN OUT [options]      similarity-based denoising (or --method bilateral|lpf)\n"
    "  bench denoise [options]       ours vs PCL MLS and the bilateral filter, in one run\n"
    "  bench lpf [options]           Local Probing Fields denoising vs the others, surfaces and wires\n"
    "  compress IN OUT.paps [opts]   self-similarity compression (sparse patches over a dictionary)\n"
    "  decompress IN.paps OUT        decode a .paps file to .pcd or .ply\n"
    "  bench compress [options]      ours vs Draco and the PCL octree coder: rate-distortion curves\n"
    "  curvature IN OUT [options]    Wavejet normals and curvatures; enhance IN OUT: details\n"
    "  bench curvature [options]     Wavejets vs PCL and CGAL jets on analytic surfaces and a scan\n"
    "  superres IN [IN2..] OUT --factor F   QSR super-resolution (or --method apss|rimls)\n"
    "  bench superres [options]      QSR vs APSS, RIMLS and PCL MLS upsampling (Table 2.2 protocol)\n"
    "  reconstruct IN OUT.ply [opts] surface reconstruction by optimal transport (a mesh of few vertices)\n"
    "  recover-features MESH IN OUT.ply   sharpen a smooth mesh's creases by optimal transport to IN\n"
    "  bench transport [options]     OT feature recovery and reconstruction vs PCL Poisson and GP3\n"
    "  make-street DIR               write the synthetic street: cloud, photos, true and GPS poses\n"
    "  register CLOUD LIST OUT_LIST  refine photo poses against a cloud (NMI/DHOG/MIDHOG, BOBYQA)\n"
    "  rgbd-photo FRAME DIR          photo, camera and pose of an organized RGB-D cloud (Kinect, stereo)\n"
    "  colorize CLOUD LIST OUT       colour a cloud from registered photos (consensus, occlusion maps)\n"
    "  shadows CLOUD LIST OUT --sun X,Y,Z   detect and relight the shadows of a coloured cloud\n"
    "  bench fusion [options]        image-cloud registration (Table 4.1; street and a real Kinect frame), colorization, shadows\n"
    "  bench files IN [IN..]         ours vs the peers on your own clouds: time, memory, output\n"
    "  bench neighbours [options]    our k-d tree queries vs pcl::KdTreeFLANN: time a query, same lists\n"
    "  sample-mesh MESH N OUT        N points on a mesh, with --noise: a cloud of known surface\n"
    "  mesh-distance MESH CLOUD      distance of a cloud to a mesh (RMS, mean, p95, max)\n"
    "Run 'paps COMMAND --help' for the options of a command.\n"
    "--threads N (any command): at most N threads (default: OMP_NUM_THREADS, else every core).\n";

#ifdef PAPS_HAVE_FUSION
// The image commands live in paps-fusion, beside this binary (fusion_main.cpp says why): run
// it in this process's place with the same arguments (--threads was turned into
// OMP_NUM_THREADS, which it inherits). Returns only when it cannot be run.
int runFusionBinary(char** argv) {
  std::string self(4096, '\0');
  const ssize_t n = ::readlink("/proc/self/exe", self.data(), self.size());
  if (n <= 0 || static_cast<std::size_t>(n) >= self.size()) {
    // Without our own path, "paps-fusion" would be looked up in the working folder.
    std::fprintf(stderr, "paps: error: cannot find this binary's folder (/proc/self/exe: %s), where paps-fusion "
                 "holds the '%s' command\n", std::strerror(errno), argv[1]);
    return 1;
  }
  self.resize(static_cast<std::size_t>(n));
  const std::string fusion = self.substr(0, self.rfind('/') + 1) + "paps-fusion";
  argv[0] = const_cast<char*>("paps");
  std::fflush(stdout);
  ::execv(fusion.c_str(), argv);
  std::fprintf(stderr, "paps: error: cannot run %s, which holds the '%s' command (%s): install it beside paps\n",
               fusion.c_str(), argv[1], std::strerror(errno));
  return 1;
}
#endif

}  // namespace

int main(int argc, char** argv) {
  return paps::cli::runCommandLine(argc, argv, "paps", kUsage, [](int argc, char** argv) {
    if (!std::strcmp(argv[1], "denoise")) return paps::cli::runDenoise(argc, argv);
#ifdef PAPS_HAVE_FEATURES
    if (!std::strcmp(argv[1], "curvature")) return paps::cli::runCurvature(argc, argv);
    if (!std::strcmp(argv[1], "enhance")) return paps::cli::runEnhance(argc, argv);
    if (!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "curvature")) return paps::cli::runBenchCurvature(argc, argv);
    if (!std::strcmp(argv[1], "bench-worker-curv")) return paps::cli::runCurvatureWorker(argc, argv);
#endif
#ifdef PAPS_HAVE_COMPRESSION
    if (!std::strcmp(argv[1], "compress")) return paps::cli::runCompress(argc, argv);
    if (!std::strcmp(argv[1], "decompress")) return paps::cli::runDecompress(argc, argv);
    if (!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "compress")) return paps::cli::runBenchCompress(argc, argv);
#endif
#ifdef PAPS_HAVE_SURFACE
    if (!std::strcmp(argv[1], "superres")) return paps::cli::runSuperres(argc, argv);
    if (!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "superres")) return paps::cli::runBenchSuperres(argc, argv);
    if (!std::strcmp(argv[1], "bench-worker-sr")) return paps::cli::runSuperresWorker(argc, argv);
    if (!std::strcmp(argv[1], "reconstruct")) return paps::cli::runReconstruct(argc, argv);
    if (!std::strcmp(argv[1], "recover-features")) return paps::cli::runRecoverFeatures(argc, argv);
    if (!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "transport")) return paps::cli::runBenchTransport(argc, argv);
    if (!std::strcmp(argv[1], "bench-worker-ot")) return paps::cli::runTransportWorker(argc, argv);
#endif
#ifdef PAPS_HAVE_FUSION
    if ((!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "fusion")) ||
        !std::strcmp(argv[1], "register") || !std::strcmp(argv[1], "rgbd-photo") ||
        !std::strcmp(argv[1], "make-street") || !std::strcmp(argv[1], "colorize") || !std::strcmp(argv[1], "shadows"))
      return runFusionBinary(argv);
#endif
    if (!std::strcmp(argv[1], "sample-mesh")) return paps::cli::runSampleMesh(argc, argv);
    if (!std::strcmp(argv[1], "mesh-distance")) return paps::cli::runMeshDistance(argc, argv);
    if (!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "files")) return paps::cli::runBenchFiles(argc, argv);
    if (!std::strcmp(argv[1], "bench") && argc > 2 && !std::strcmp(argv[2], "neighbours")) return paps::cli::runBenchNeighbours(argc, argv);
    if (!std::strcmp(argv[1], "bench")) return paps::cli::runBench(argc, argv);
    if (!std::strcmp(argv[1], "bench-worker")) return paps::cli::runBenchWorker(argc, argv);
    return paps::cli::kUnknownCommand;
  });
}
