#pragma once
namespace paps::cli {
extern const char* kDenoiseUsage;
int runDenoise(int argc, char** argv);
int runSampleMesh(int argc, char** argv);
int runMeshDistance(int argc, char** argv);
int runBench(int argc, char** argv);
int runBenchFiles(int argc, char** argv);
int runBenchNeighbours(int argc, char** argv);
int runBenchLpf(int argc, char** argv);
int runCurvatureWorker(int argc, char** argv);
int runCurvature(int argc, char** argv);
int runEnhance(int argc, char** argv);
int runBenchCurvature(int argc, char** argv);
int runCompress(int argc, char** argv);
int runDecompress(int argc, char** argv);
int runBenchCompress(int argc, char** argv);
int runSuperres(int argc, char** argv);
int runBenchSuperres(int argc, char** argv);
int runSuperresWorker(int argc, char** argv);
int runReconstruct(int argc, char** argv);
int runRecoverFeatures(int argc, char** argv);
int runBenchTransport(int argc, char** argv);
int runTransportWorker(int argc, char** argv);
int runBenchFusion(int argc, char** argv);
int runRegister(int argc, char** argv);
int runRgbdPhoto(int argc, char** argv);
int runMakeStreet(int argc, char** argv);
int runColorize(int argc, char** argv);
int runShadows(int argc, char** argv);
}  // namespace paps::cli
