// paps bench superres: the protocol of Table 2.2 on our data. A dense cloud is subsampled to
// 10%, Gaussian noise is added, each method restores the dense count, and the error is the
// RMSE from the dense points to their nearest output points (beside it, the RMS distance from
// the output points to the true surface, which the protocol's error does not see: at heavy
// noise an output that keeps its noise covers the dense points as well as one that removes
// it). Each method runs in a child process (its own peak memory; a crash cannot take the bench down).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/surface/mls.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/metrics.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>
#include <paps/core/synthetic.h>
#include <paps/filters/similarity_denoising.h>
#include <paps/surface/lpf_resampling.h>
#include <paps/surface/mls_upsampling.h>
#include <paps/surface/quadric_super_resolution.h>

#include "bench_worker.h"
#include "cli_common.h"
#include "commands.h"
#include "render.h"

namespace paps::cli {

namespace {

const char* kUsage =
    "usage: paps bench superres [options]\n"
    "  --out DIR        table (CSV), renders (PNG) and scratch files (default bench_out)\n"
    "  --samples DIR    sample data (default $PAPS_SAMPLES or ~/.cache/paps/samples)\n"
    "  --points N       dense points per shape (default 700000; the input is 10% of it)\n"
    "  --speed N        input points of the speed test, super-resolved x4 (default 100000, 0: skip)\n"
    "  --speed-repeat N rounds of the speed test (default 1); the methods alternate within a round,\n"
    "                   and the summary gives each method's min and median wall time, the\n"
    "                   median of its ratio to pcl-mls-plane in the same round, and CPU times\n"
    "  --speed-only     skip the error table (only the speed test)\n"
    "  --quick          100000 dense points, speed test on 30000 (a smoke run)\n"
    "  --normals        instead of the tables below: the output normals of qsr, apss, rimls and\n"
    "                   pcl-mls-plane (setComputeNormals; those of them in --methods) against the true\n"
    "                   surface's, per shape and noise (writes superres_normals.csv)\n"
    "  --shapes LIST    comma-separated subset of engraved-plane,rs1,scan-lines (default all three;\n"
    "                   scan-lines: a simulated LiDAR pass over a wavy ground, every return stored\n"
    "                   twice, 5 mm range noise, upsampled x4; errors to the analytic ground)\n"
    "  --noises LIST    comma-separated noise fractions of the diagonal (default 0.0001,0.001,0.005)\n"
    "  --methods LIST   comma-separated subset of the methods (default all): qsr, qsr-narrow, qsr-even,\n"
    "                   qsr-adapt, qsr-4scans, apss,\n"
    "                   apss-refit, apss-wide, rimls, rimls-refit, rimls-wide, pcl-mls-plane,\n"
    "                   pcl-mls-random, pcl-mls-voxel, simden+mls, seeds-only (also filters the speed\n"
    "                   test) (-refit: fit at every seed; -wide: seed discs as wide as QSR's;\n"
    "                   qsr-narrow: QSR with --seed-disc 0.6 (seeds near the returns);\n"
    "                   qsr-even: QSR with --thin-disc 1 (the same disc for thin balls);\n"
    "                   qsr-adapt: QSR on the raw scan with the opt-in noise-adaptive kernel; qsr-raw: QSR without\n"
    "                   denoising the input first; seeds-only: a control,\n"
    "                   the seeds on the noisy input's tangent discs, projected on no surface;\n"
    "                   qsr-tiles, apss-tiles, rimls-tiles, only when listed: the method with the\n"
    "                   input cut into 4 tiles)\n";

// Child process: runs `method` on the scans in files sr_in0.bin, sr_in1.bin ... of `dir`.
using SrResult = WorkerResult;

SrResult runChild(const std::string& dir, const std::string& method, const std::vector<Positions>& scans,
                  const std::map<std::string, double>& params) {
  for (std::size_t i = 0; i < scans.size(); ++i) writeRaw(dir + "/sr_in" + std::to_string(i) + ".bin", scans[i]);
  return spawnWorker({"bench-worker-sr", method, dir, std::to_string(scans.size())}, params,
                     dir + "/sr_out.bin", dir + "/sr_log.txt");
}

// PCL's MovingLeastSquares upsampling (order 2, 2 threads) to `target` points; with `normals`,
// setComputeNormals and the normals of the kept points.
template <typename PointOut>
Positions pclMlsUpsampleAs(const Positions& input, const std::string& mode, double radius, std::size_t target,
                           Normals* normals) {
  using Mls = pcl::MovingLeastSquares<pcl::PointXYZ, PointOut>;
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  writePositions(finiteInput(input).points, *cloud);  // PCL's MLS aborts on NaN points
  Mls mls;
  mls.setInputCloud(cloud);
  mls.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  mls.setPolynomialOrder(2);
  mls.setSearchRadius(radius);
  mls.setComputeNormals(normals != nullptr);
  mls.setNumberOfThreads(2);
  const double factor = static_cast<double>(target) / std::max<std::size_t>(1, countFinite(input));
  const SpatialIndex index(input);
  const float r30 = static_cast<float>(radius);
  // Mean spacing s0 from the mean neighbour count at the radius.
  std::vector<int> idx;
  std::vector<float> d2;
  double mean = 0;
  int samples = 0;
  for (std::size_t i = 0; i < input.size(); i += std::max<std::size_t>(1, input.size() / 500)) {
    mean += index.radiusSearch(input[i], r30, idx, d2);
    ++samples;
  }
  mean /= std::max(1, samples);
  const double s0 = radius * std::sqrt(M_PI / std::max(1.0, mean));
  if (mode == "plane") {
    mls.setUpsamplingMethod(Mls::SAMPLE_LOCAL_PLANE);
    // Grid of step t on a disc of radius 0.6 s0 around each input point: 5 points at x4, 9 at
    // x10, but at x2 (t = 0.71 s0) only the centre, i.e. no upsampling; there the disc reaches
    // the first ring (5 points, then the seeded subset below keeps the count).
    const double step = s0 / std::sqrt(factor);
    mls.setUpsamplingRadius(std::max(0.5 * s0 * 1.2, factor > 1 ? 1.001 * step : 0.0));
    mls.setUpsamplingStepSize(step);
  } else if (mode == "random") {
    mls.setUpsamplingMethod(Mls::RANDOM_UNIFORM_DENSITY);
    mls.setPointDensity(static_cast<int>(std::lround(factor * mean)));
  } else {
    mls.setUpsamplingMethod(Mls::VOXEL_GRID_DILATION);
    mls.setDilationVoxelSize(static_cast<float>(s0 / std::sqrt(factor)));
    mls.setDilationIterations(1);
  }
  pcl::PointCloud<PointOut> result;
  mls.process(result);
  Positions out;
  if (normals) normals->clear();
  for (const auto& p : result) {
    if (!isFinite(p.getVector3fMap())) continue;
    out.push_back(p.getVector3fMap());
    if constexpr (detail::HasNormal<PointOut>::value) if (normals) normals->push_back(p.getNormalVector3fMap());
  }
  if (out.size() > target) {  // the same count as the others: a seeded random subset
    Random rng(3);
    for (std::size_t i = out.size(); i > 1; --i) {
      const std::size_t j = rng.below(i);
      std::swap(out[i - 1], out[j]);
      if (normals) std::swap((*normals)[i - 1], (*normals)[j]);
    }
    out.resize(target);
    if (normals) normals->resize(target);
  }
  return out;
}

Positions pclMlsUpsample(const Positions& input, const std::string& mode, double radius, std::size_t target,
                         Normals* normals = nullptr) {
  return normals ? pclMlsUpsampleAs<pcl::PointNormal>(input, mode, radius, target, normals)
                 : pclMlsUpsampleAs<pcl::PointXYZ>(input, mode, radius, target, nullptr);
}

// Scan s of a bench row: 10% of the dense points (s = 0) or of another dense sampling of the
// mesh (the other scans of qsr-4scans), with Gaussian noise of `noise` x the diagonal.
Positions benchScan(const TriangleMesh& mesh, const Positions& dense, int s, double noise) {
  Positions sub;
  Random rng(100 + s);
  const Positions& src = s == 0 ? dense : synthetic::sampleMesh(mesh, dense.size(), 50 + s);
  for (const auto& p : src) if (rng.uniform() < 0.1) sub.push_back(p);
  synthetic::addGaussianNoise(sub, static_cast<float>(noise), 11 + s);
  return sub;
}

// RMSE from the dense points to their nearest output point.
double nearestRmse(const Positions& dense, const Positions& output) {
  if (output.empty()) return NAN;
  const SpatialIndex index(output);
  double s = 0;
  std::size_t n = 0;
#pragma omp parallel reduction(+ : s, n)
  {
    std::vector<int> idx;
    std::vector<float> d2;
#pragma omp for schedule(static)
    for (std::int64_t i = 0; i < static_cast<std::int64_t>(dense.size()); ++i)
      if (index.nearestK(dense[i], 1, idx, d2) == 1) { s += d2[0]; ++n; }
  }
  return n ? std::sqrt(s / n) : NAN;
}

// The "cpu" line a worker left in its log (process CPU seconds of the call), NAN if none.
double childCpuSeconds(const std::string& log_path) {
  std::ifstream f(log_path);
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("cpu ", 0) == 0) return std::atof(line.c_str() + 4);
  return NAN;
}

std::string loadAverage() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

std::string fmtE(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3e", v);
  return b;
}

// Scan-line LiDAR (synthetic::scanLinePass: lines 9 cm to 0.9 m apart, returns 2 to 7 cm apart
// along them, each stored twice, 5 mm range noise) upsampled x4 by every method. The truth is
// the analytic ground: "to surface" is the RMS distance of the outputs to it, "RMSE" the
// protocol's (dense points of the scanned sector to their nearest output).
void runScanLines(const std::string& out_dir, const std::vector<std::string>& methods, std::size_t n_dense,
                  std::ofstream& csv) {
  const synthetic::ScanLinePass pass;
  const Positions scan = synthetic::scanLinePass(pass, 5);
  const Positions dense = synthetic::sampleMesh(synthetic::wavyGroundSector(pass), n_dense, 7);
  const SpatialIndex index(scan);
  const float r = radiusForNeighbourCount(scan, index, 30, NeighbourCountStatistic::Median);
  const std::size_t target = 4 * scan.size();
  const double e_in = nearestRmse(dense, scan), g_in = synthetic::rmsDistanceToWavyGround(scan);
  std::printf("\nscan-lines: %zu returns (each stored twice) upsampled x4; RMSE over %zu dense points of the sector,\n"
              "to surface = RMS distance to the analytic ground (metres)\n",
              scan.size(), dense.size());
  std::printf("%-15s %-6s %-15s %9zu %9s %9s %11.3e %11.3e\n", "scan-lines", "5mm", "input", scan.size(), "-", "-", e_in,
              g_in);
  csv << "scan-lines," << dense.size() << "," << scan.size() << ",0.005,input,1,0,0," << scan.size() << "," << e_in << ","
      << g_in << "\n";
  std::map<std::string, double> peer;
  double g_qsr = NAN, g_narrow = NAN;
  for (const auto& m : methods) {
    if (m == "qsr-4scans") continue;
    const SrResult w = runChild(out_dir, m, {scan}, {{"count", static_cast<double>(target)}, {"radius", r}});
    if (!w.ok) {
      std::printf("%-15s %-6s %-15s failed: %s\n", "scan-lines", "5mm", m.c_str(), w.message.c_str());
      csv << "scan-lines," << dense.size() << "," << scan.size() << ",0.005," << m << ",0,,,,,\n";
      continue;
    }
    const double e = nearestRmse(dense, w.output), g = synthetic::rmsDistanceToWavyGround(w.output);
    std::printf("%-15s %-6s %-15s %9zu %9.2f %9.0f %11.3e %11.3e\n", "scan-lines", "5mm", m.c_str(), w.output.size(),
                w.seconds, w.peak_mb, e, g);
    std::fflush(stdout);
    csv << "scan-lines," << dense.size() << "," << scan.size() << ",0.005," << m << ",1," << w.seconds << ","
        << w.peak_mb << "," << w.output.size() << "," << e << "," << g << "\n";
    if (m == "qsr") g_qsr = g;
    if (m == "qsr-narrow") g_narrow = g;
    if (m.rfind("apss", 0) == 0 || m.rfind("rimls", 0) == 0 || m.rfind("pcl-mls-", 0) == 0) peer[m] = g;
  }
  double best = INFINITY;
  std::string best_name;
  for (const auto& [k, v] : peer) if (v < best) { best = v; best_name = k; }
  if (peer.empty()) {
    std::printf("  -> no ratio: no peer in --methods\n");
    return;
  }
  std::printf("  -> to the ground, QSR / best of APSS, RIMLS, PCL MLS (%s) = %.3f; qsr-narrow / best = %.3f; "
              "input / best = %.3f\n",
              best_name.c_str(), g_qsr / best, g_narrow / best, g_in / best);
}

// The normals each method gives its output points (QSR: the SR surface's; APSS, RIMLS: their
// fit's gradient; PCL MLS SAMPLE_LOCAL_PLANE with setComputeNormals: its local polynomial's),
// against the mesh's vertex normals interpolated at the closest point of the mesh. In process (the
// workers carry positions only), same inputs and output count as the error table.
void runNormals(const std::string& name, const TriangleMesh& mesh, const std::vector<double>& noises,
                const std::vector<std::string>& methods, std::size_t n_dense, std::ofstream& csv) {
  const Positions dense = synthetic::sampleMesh(mesh, n_dense, 7);
  const PointToMeshDistance truth(mesh);
  // Vertex normals: the area-weighted mean of the normals of the triangles around each vertex
  // (a scanned mesh's own triangles are noisy: rs1's differ from them by 9 degrees RMS).
  Normals vn(mesh.vertices.size(), Eigen::Vector3f::Zero());
  for (const auto& tri : mesh.triangles) {
    const Eigen::Vector3f n = (mesh.vertices[tri[1]] - mesh.vertices[tri[0]]).cross(mesh.vertices[tri[2]] - mesh.vertices[tri[0]]);
    for (int k = 0; k < 3; ++k) vn[tri[k]] += n;
  }
  for (auto& n : vn) n = n.norm() > 0 ? Eigen::Vector3f(n.normalized()) : n;
  for (double noise : noises) {
    const Positions scan = benchScan(mesh, dense, 0, noise);
    const SpatialIndex index(scan);
    const float r = radiusForNeighbourCount(scan, index, 30, NeighbourCountStatistic::Median);
    char noise_s[16];
    std::snprintf(noise_s, sizeof noise_s, "%.2f%%", noise * 100);
    for (const std::string m : {"qsr", "apss", "rimls", "pcl-mls-plane"}) {
      if (std::find(methods.begin(), methods.end(), m) == methods.end()) continue;
      Normals normals;
      Positions out;
      const auto t0 = std::chrono::steady_clock::now();
      try {
        if (m == "qsr") {
          QuadricSuperResolutionParameters q;
          q.output_count = n_dense;
          out = superResolveQuadric({scan}, q, nullptr, {}, &normals);
        } else if (m == "pcl-mls-plane") {
          out = pclMlsUpsample(scan, "plane", r, n_dense, &normals);
        } else {
          MlsUpsamplingParameters q;
          q.output_count = n_dense;
          out = upsampleMls(scan, m == "apss" ? MlsSurface::Apss : MlsSurface::Rimls, q, nullptr, {}, &normals);
        }
      } catch (const std::exception& e) {
        std::printf("%-15s %-6s %-15s failed: %s\n", name.c_str(), noise_s, m.c_str(), e.what());
        continue;
      }
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      Normals want(out.size(), Eigen::Vector3f::Constant(NAN));
      Normals got(out.size(), Eigen::Vector3f::Constant(NAN));
#pragma omp parallel for schedule(static)
      for (std::int64_t i = 0; i < static_cast<std::int64_t>(out.size()); ++i) {
        int t = -1;
        Eigen::Vector3f c;
        truth.distance(out[i], &c, &t);
        if (t < 0 || !isFinite(normals[i])) continue;
        // The vertex normals interpolated at the closest point (barycentric), as a shaded mesh.
        const auto& tri = mesh.triangles[t];
        const Eigen::Vector3f a = mesh.vertices[tri[0]], e1 = mesh.vertices[tri[1]] - a, e2 = mesh.vertices[tri[2]] - a;
        const Eigen::Vector3f n = e1.cross(e2);
        const float area2 = n.squaredNorm();
        if (!(area2 > 0)) continue;
        const float w1 = (c - a).cross(e2).dot(n) / area2, w2 = e1.cross(c - a).dot(n) / area2;
        const Eigen::Vector3f v = (1 - w1 - w2) * vn[tri[0]] + w1 * vn[tri[1]] + w2 * vn[tri[2]];
        want[i] = v.norm() > 0 ? Eigen::Vector3f(v.normalized()) : Eigen::Vector3f(n.normalized());
        got[i] = normals[i];
      }
      // Orientation: the share of normals on the side of the truth's, up to one global sign
      // (a method that orients by propagation may pick either side for the whole cloud).
      std::size_t agree = 0, counted = 0;
      for (std::size_t i = 0; i < out.size(); ++i)
        if (isFinite(got[i]) && isFinite(want[i])) { ++counted; agree += got[i].dot(want[i]) > 0; }
      const double oriented = counted ? std::max(agree, counted - agree) / double(counted) : NAN;
      const ErrorStats a = summarize(normalAngleErrors(got, want, true));
      const std::size_t missing = out.size() - counted;
      std::printf("%-15s %-6s %-15s %9zu %9.2f %11.3f %11.3f %11.4f %9zu\n", name.c_str(), noise_s, m.c_str(),
                  out.size(), seconds, a.rmse, a.p95, oriented, missing);
      std::fflush(stdout);
      csv << name << "," << noise << "," << m << "," << out.size() << "," << seconds << "," << a.rmse << "," << a.p95
          << "," << oriented << "," << missing << "\n";
    }
  }
}

}  // namespace

int runSuperresWorker(int argc, char** argv) {
  if (argc < 5) return 2;
  const std::string method = argv[2], dir = argv[3];
  const int n_scans = std::atoi(argv[4]);
  const WorkerParameters params(argc, argv, 5);
  auto get = [&](const char* k, double d) { return params.get(k, d); };
  std::ofstream lf(dir + "/sr_log.txt");
  try {
    std::vector<Positions> scans;
    for (int i = 0; i < n_scans; ++i) scans.push_back(readRaw(dir + "/sr_in" + std::to_string(i) + ".bin"));
    const std::size_t target = static_cast<std::size_t>(get("count", 0));
    const auto t0 = std::chrono::steady_clock::now();
    timespec c0{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
    Positions out;
    if (method == "qsr" || method == "qsr-adapt" || method == "qsr-raw" || method == "qsr-narrow" || method == "qsr-even" ||
        method == "qsr-tiles") {
      QuadricSuperResolutionParameters q;
      q.output_count = target;
      // qsr-tiles: the input in 4 tiles (QSR's tiles for large scans, measured at bench size).
      if (method == "qsr-tiles") q.max_tile_points = std::max<std::size_t>(1000, (countFinite(scans[0]) + 3) / 4);
      if (method == "qsr-narrow") q.seed_disc = 0.6f;
      if (method == "qsr-even") q.thin_disc = 1.f;  // before session 12: one disc everywhere
      q.adapt_to_noise = method == "qsr-adapt";
      // qsr-adapt: the adaptive kernel acts on raw scans only (a denoised scan gets the quiet one).
      if (method == "qsr-raw" || method == "qsr-adapt") q.denoise_input = QuadricSuperResolutionParameters::Denoise::Off;
      QuadricSuperResolutionReport r;
      out = superResolveQuadric(scans, q, &r);
      lf << "info R " << r.patch_radius << " rsim " << r.similarity_radius << " grid " << r.grid_lr << "->"
         << r.grid_sr << " K-1 " << r.mean_similar_weight << " flat " << r.flat_fits << " ill-posed " << r.ill_posed_fits << " widened " << r.widened_fits << " thin " << r.thin_balls << " noise "
         << r.noise_sigma << " kernel " << r.kernel_scale << " denoised " << r.denoised << " tiles " << r.tiles << "\n";
    } else if (method == "apss" || method == "rimls" || method == "apss-refit" || method == "rimls-refit" ||
               method == "apss-wide" || method == "rimls-wide" || method == "apss-tiles" || method == "rimls-tiles") {
      MlsUpsamplingParameters q;
      q.output_count = target;
      // -tiles: the input in 4 tiles (the tiles of large scans, measured at bench size).
      if (method.find("-tiles") != std::string::npos)
        q.max_tile_points = std::max<std::size_t>(1000, (countFinite(scans[0]) + 3) / 4);
      q.fit_per_input_point = method.find("-refit") == std::string::npos;
      // -wide: seeds spread over discs as wide as QSR's (1.2 mean spacings).
      if (method.find("-wide") != std::string::npos) q.disc_scale = 1.7724539f;
      out = upsampleMls(scans[0], method.rfind("apss", 0) == 0 ? MlsSurface::Apss : MlsSurface::Rimls, q);
    } else if (method == "lpf" || method == "lpf-raw" || method == "lpf-denoised") {
      // lpf: the default (denoised first when the noise is thicker than the consensus
      // radius); lpf-raw never, lpf-denoised always.
      LpfResamplingParameters q;
      q.factor = static_cast<float>(get("factor", q.factor));
      if (method == "lpf-raw") q.denoise_input = LpfResamplingParameters::Denoise::Off;
      if (method == "lpf-denoised") q.denoise_input = LpfResamplingParameters::Denoise::On;
      q.denoise_passes = static_cast<int>(get("passes", q.denoise_passes));
      q.denoise_ratio = static_cast<float>(get("denoise-ratio", q.denoise_ratio));
      LpfResamplingReport r;
      out = lpfResample(scans[0], q, &r);
      if (method == "lpf") {
        char b[160];
        std::snprintf(b, sizeof b, "noise %.3g = %.2f tau_p, %s", r.noise_sigma, r.noise_ratio,
                      r.denoised ? ("denoised first, " + std::to_string(r.denoise_passes) + (r.denoise_passes == 1 ? " pass" : " passes")).c_str()
                                 : "not denoised");
        lf << "chosen " << b << "\n";
      }
    } else if (method == "seeds-only") {
      // Control, not a method: the Poisson-disk seeds over the noisy input's tangent discs
      // (QSR's disc radius, 1.2 mean spacings), projected on no surface at all. Where this
      // row scores as well as the methods, the protocol's error does not see the denoising.
      const RadiusNeighbourhood nh = buildRadiusNeighbourhood(scans[0], 0.f, 36, 4 * 36);
      const Normals normals = estimateNormals(scans[0], nh.graph);
      const float s0 = nh.radius * std::sqrt(3.14159265f / static_cast<float>(std::max(1.0, nh.graph.meanCount())));
      out = upsamplingSeeds(scans[0], normals, target, 1.2f * s0, 1);
    } else if (method.rfind("pcl-mls-", 0) == 0) {
      out = pclMlsUpsample(scans[0], method.substr(8), get("radius", 0), target);
    } else if (method == "simden+mls") {
      SimilarityDenoisingParameters q;
      q.radius = static_cast<float>(get("radius", 0));
      const Positions den = denoiseBySimilarity(scans[0], q);
      out = pclMlsUpsample(den, "plane", get("radius", 0), target);
    } else {
      throw InvalidParameter("method", method, "qsr[-adapt|-raw|-narrow|-even|-tiles], apss[-refit|-wide|-tiles], rimls[-refit|-wide|-tiles], pcl-mls-{plane,random,voxel}, simden+mls");
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    timespec c1{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
    writeRaw(dir + "/sr_out.bin", out);
    lf << "cpu " << (c1.tv_sec - c0.tv_sec) + 1e-9 * (c1.tv_nsec - c0.tv_nsec) << "\n";
    lf << "seconds " << s << "\n";
    return 0;
  } catch (const std::exception& e) {
    lf << "error " << e.what() << "\n";
    return 1;
  }
}

int runBenchSuperres(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 3, {"quick", "help", "speed-only", "normals"});
  if (a.has("help")) { std::fputs(kUsage, stdout); return 0; }
  a.allowOnly({"out", "samples", "points", "speed", "speed-repeat", "speed-only", "quick", "shapes", "noises", "methods",
               "normals"});
  const bool speed_only = a.has("speed-only");
  const int speed_repeat = a.integer("speed-repeat", 1);
  if (speed_repeat < 1 || speed_repeat > 100)
    throw InvalidParameter("speed-repeat", std::to_string(speed_repeat), "1 to 100");
  const bool quick = a.has("quick");
  const std::string out_dir = a.text("out", "bench_out");
  const std::string rs1 = a.text("samples", samplesDir()) + "/rs1_normals.ply";
  const std::size_t n_dense = a.count("points", quick ? 100000 : 700000);
  const std::size_t n_speed = a.count("speed", quick ? 30000 : 100000);
  if (n_dense < 1000) throw InvalidParameter("points", std::to_string(n_dense), "at least 1000");
  std::filesystem::create_directories(out_dir);
  const std::vector<std::string> all_methods = {"qsr",           "qsr-narrow",     "qsr-even",       "qsr-adapt",      "qsr-4scans",     "apss",           "apss-refit",
                                                "apss-wide",     "rimls",          "rimls-refit",    "rimls-wide",
                                                "pcl-mls-plane", "pcl-mls-random", "pcl-mls-voxel",  "simden+mls",
                                                "qsr-raw", "seeds-only", "qsr-tiles", "apss-tiles", "rimls-tiles"};
  // The tiled runs only when asked: they measure the tiles, not a method of the table.
  const std::vector<std::string> methods = a.has("methods") ? splitList(a.text("methods", ""))
                                                            : std::vector<std::string>(all_methods.begin(), all_methods.end() - 3);
  for (const auto& m : methods)
    if (std::find(all_methods.begin(), all_methods.end(), m) == all_methods.end())
      throw InvalidParameter("methods", m, "a comma-separated subset of qsr, qsr-narrow, qsr-even, qsr-adapt, qsr-4scans, apss, apss-refit, apss-wide, "
                                           "rimls, rimls-refit, rimls-wide, pcl-mls-plane, pcl-mls-random, "
                                           "pcl-mls-voxel, simden+mls, qsr-raw, seeds-only, qsr-tiles, apss-tiles, rimls-tiles");
  const std::vector<std::string> shapes = splitList(a.text("shapes", "engraved-plane,rs1,scan-lines"));
  for (const auto& sh : shapes)
    if (sh != "engraved-plane" && sh != "rs1" && sh != "scan-lines")
      throw InvalidParameter("shapes", sh, "a comma-separated subset of engraved-plane, rs1, scan-lines");
  auto wanted = [&](const std::string& sh) { return std::find(shapes.begin(), shapes.end(), sh) != shapes.end(); };
  std::vector<double> noises;
  for (const auto& t : splitList(a.text("noises", "0.0001,0.001,0.005"))) {
    char* end = nullptr;
    const double v = std::strtod(t.c_str(), &end);
    if (end == t.c_str() || *end || !(v >= 0 && v < 0.5)) throw InvalidParameter("noises", t, "fractions in [0, 0.5)");
    noises.push_back(v);
  }
  if (noises.empty()) throw InvalidParameter("noises", a.text("noises", ""), "at least one noise fraction");

  struct Dataset { std::string name; TriangleMesh mesh; bool multi; };
  std::vector<Dataset> datasets;
  // Repeated relief: 2 mm bumps of wavelength 4 cm on a 1 m square (about 10 input points per
  // wavelength at 70K input points).
  if (wanted("engraved-plane"))
    datasets.push_back({"engraved-plane", synthetic::engravedPlane(1.f, 0.04f, 0.002f, 800), true});
  if (!wanted("rs1")) {
  } else if (std::filesystem::exists(rs1)) datasets.push_back({"rs1", loadTriangleMesh(rs1), false});
  else std::fprintf(stderr, "warning: %s missing (scripts/fetch_samples.sh): rs1 rows skipped\n", rs1.c_str());

  if (a.has("normals")) {
    std::ofstream ncsv(out_dir + "/superres_normals.csv");
    ncsv << "dataset,noise,method,output,seconds,angle_rmse_deg,angle_p95_deg,oriented,without_normal\n";
    std::printf("bench superres --normals: dense %zu points per shape, input 10%%, output normals against the mesh's\n"
                "vertex normals at the closest point (degrees, orientation-blind); oriented = share on one side of\n"
                "the truth's\n",
                n_dense);
    std::printf("%-15s %-6s %-15s %9s %9s %11s %11s %11s %9s\n", "dataset", "noise", "method", "output", "time(s)",
                "angle RMS", "angle p95", "oriented", "no normal");
    for (const auto& ds : datasets) runNormals(ds.name, ds.mesh, noises, methods, n_dense, ncsv);
    std::printf("wrote %s/superres_normals.csv\n", out_dir.c_str());
    return 0;
  }
  // apss and rimls fit once per input point (their default); the -refit rows refit at every
  // output point.
  std::ofstream csv(out_dir + "/superres.csv");
  csv << "dataset,dense,input,noise,method,ok,seconds,peak_mb,output,rmse,to_surface_rmse\n";
  std::printf("bench superres: dense %zu points per shape, input 10%%, noise sigma as a fraction of the diagonal\n", n_dense);
  std::printf("%-15s %-6s %-15s %9s %9s %9s %11s %11s\n", "dataset", "noise", "method", "output", "time(s)", "peak MB",
              "RMSE", "to surface");
  for (const auto& ds : datasets) {
    if (speed_only) break;
    const Positions dense = synthetic::sampleMesh(ds.mesh, n_dense, 7);
    const PointToMeshDistance truth(ds.mesh);
    const float diag = boundingBoxDiagonal(dense);
    for (double noise : noises) {
      std::vector<Positions> scans;
      for (int s = 0; s < (ds.multi ? 4 : 1); ++s) scans.push_back(benchScan(ds.mesh, dense, s, noise));
      const SpatialIndex index(scans[0]);
      const float r = radiusForNeighbourCount(scans[0], index, 30, NeighbourCountStatistic::Median);
      const double e_in = nearestRmse(dense, scans[0]);
      const double s_in = pointToMeshError(scans[0], truth).rmse;
      char noise_s[16];
      std::snprintf(noise_s, sizeof noise_s, "%.2f%%", noise * 100);
      std::printf("%-15s %-6s %-15s %9zu %9s %9s %11.3e %11.3e\n", ds.name.c_str(), noise_s, "input (10%)",
                  scans[0].size(), "-", "-", e_in, s_in);
      csv << ds.name << "," << n_dense << "," << scans[0].size() << "," << noise << ",input,1,0,0," << scans[0].size()
          << "," << e_in << "," << s_in << "\n";
      std::map<std::string, double> best_peer;
      std::map<std::string, Positions> outputs;
      double e_qsr = NAN, e_adapt = NAN, e_seeds = NAN;
      for (const auto& m : methods) {
        if (m == "qsr-4scans" && !ds.multi) continue;
        std::vector<Positions> in = m == "qsr-4scans" ? scans : std::vector<Positions>{scans[0]};
        const SrResult w = runChild(out_dir, m == "qsr-4scans" ? "qsr" : m, in, {{"count", static_cast<double>(n_dense)}, {"radius", r}});
        if (!w.ok) {
          std::printf("%-15s %-6s %-15s failed: %s\n", ds.name.c_str(), noise_s, m.c_str(), w.message.c_str());
          csv << ds.name << "," << n_dense << "," << scans[0].size() << "," << noise << "," << m << ",0,,,,,\n";
          continue;
        }
        const double e = nearestRmse(dense, w.output);
        const double e_surf = pointToMeshError(w.output, truth).rmse;
        std::printf("%-15s %-6s %-15s %9zu %9.2f %9.0f %11.3e %11.3e\n", ds.name.c_str(), noise_s, m.c_str(),
                    w.output.size(), w.seconds, w.peak_mb, e, e_surf);
        std::fflush(stdout);
        csv << ds.name << "," << n_dense << "," << scans[0].size() << "," << noise << "," << m << ",1," << w.seconds
            << "," << w.peak_mb << "," << w.output.size() << "," << e << "," << e_surf << "\n";
        if (m == "qsr") e_qsr = e;
        if (m == "qsr-adapt") e_adapt = e;
        if (m == "seeds-only") e_seeds = e;
        if (m.rfind("apss", 0) == 0 || m.rfind("rimls", 0) == 0 || m.rfind("pcl-mls-", 0) == 0) best_peer[m] = e;
        if (noise == 0.0001 && m.find("-refit") == std::string::npos && m.find("-wide") == std::string::npos)
          outputs[m] = w.output;
      }
      double best = INFINITY;
      std::string best_name;
      for (const auto& [k, v] : best_peer) if (v < best) { best = v; best_name = k; }
      if (best_peer.empty() || !(e_qsr > 0))
        std::printf("  -> no ratio: QSR and a peer were not both in --methods\n");
      else
        std::printf("  -> QSR / best of APSS, RIMLS, PCL MLS (%s) = %.3f\n", best_name.c_str(), e_qsr / best);
      if (!std::isnan(e_adapt)) std::printf("  -> QSR-adapt (noise-adaptive kernel) / best = %.3f\n", e_adapt / best);
      if (!std::isnan(e_seeds))
        std::printf("  -> seeds-only (control: no surface, no denoising) / best = %.3f\n", e_seeds / best);
      if (noise == 0.0001 && n_dense >= 50000) {  // render.cpp needs enough points per view
        // Close-ups: a square of 6% of the extent around the centre of the dense cloud.
        Eigen::Vector3f c = Eigen::Vector3f::Zero();
        for (const auto& p : dense) c += p;
        c /= static_cast<float>(dense.size());
        const Eigen::Vector3f mid = dense[std::min_element(dense.begin(), dense.end(), [&](const auto& x, const auto& y) {
                                              return (x - c).squaredNorm() < (y - c).squaredNorm(); }) - dense.begin()];
        const float half = 0.04f * diag;
        auto crop = [&](const Positions& pts) {
          Positions o;
          for (const auto& p : pts) if (((p - mid).cwiseAbs().array() < half).all()) o.push_back(p);
          return o;
        };
        const Positions dc = crop(dense);
        const View view = View::fit(dc, 0.f);
        // render.cpp does not clip points left of or above the view: keep those inside it.
        auto inView = [&](const Positions& pts) {
          Positions o;
          for (const auto& p : crop(pts)) {
            const Eigen::Vector3f sp = view.axes * p;
            if (sp.x() >= view.lo.x() && sp.x() <= view.hi.x() && sp.y() >= view.lo.y() && sp.y() <= view.hi.y())
              o.push_back(p);
          }
          return o;
        };
        const std::string base = out_dir + "/superres_" + ds.name;
        renderShaded(dc, view, 500, base + "_dense.png");
        renderShaded(inView(scans[0]), view, 500, base + "_input.png");
        for (const auto& [name, pts] : outputs) {
          std::string file = name;
          std::replace(file.begin(), file.end(), '+', '_');
          renderShaded(inView(pts), view, 500, base + "_" + file + ".png");
        }
      }
    }
  }
  if (wanted("scan-lines") && !speed_only) runScanLines(out_dir, methods, std::min<std::size_t>(n_dense, 200000), csv);
  const Dataset* rs1_set = nullptr;
  for (const auto& ds : datasets) if (ds.name == "rs1") rs1_set = &ds;
  if (n_speed > 0 && rs1_set) {
    std::printf("\nspeed: %zu input points of rs1 (0.01%% noise) super-resolved x4, same count for all\n", n_speed);
    Positions in = synthetic::sampleMesh(rs1_set->mesh, n_speed, 21);
    synthetic::addGaussianNoise(in, 0.0001f, 22);
    const SpatialIndex index(in);
    const float r = radiusForNeighbourCount(in, index, 30, NeighbourCountStatistic::Median);
    std::printf("(PCL MLS search radius %.6g: a typical point holds 30 neighbours; %d round(s), load average %s)\n", r,
                speed_repeat, loadAverage().c_str());
    struct Times { std::vector<double> wall, cpu, ratio; };
    std::map<std::string, Times> times;
    std::vector<std::string> order;
    for (int round = 0; round < speed_repeat; ++round) {
      std::map<std::string, double> wall_of;
      for (const std::string m : {"qsr", "qsr-adapt", "apss", "apss-refit", "apss-wide", "rimls", "rimls-refit", "rimls-wide",
                                  "pcl-mls-plane", "pcl-mls-random", "pcl-mls-voxel"}) {
        if (std::find(methods.begin(), methods.end(), m) == methods.end()) continue;
        if (round == 0) order.push_back(m);
        const SrResult w = runChild(out_dir, m, {in}, {{"count", 4.0 * n_speed}, {"radius", r}});
        if (!w.ok) { std::printf("%-15s failed: %s\n", m.c_str(), w.message.c_str()); continue; }
        const double cpu = childCpuSeconds(out_dir + "/sr_log.txt");
        std::printf("%-15s %9zu points in %7.2f s (cpu %6.2f s), peak %5.0f MB\n", m.c_str(), w.output.size(),
                    w.seconds, cpu, w.peak_mb);
        std::fflush(stdout);
        csv << "speed-rs1," << n_speed * 4 << "," << n_speed << ",0.0001," << m << ",1," << w.seconds << ","
            << w.peak_mb << "," << w.output.size() << ",,\n";
        times[m].wall.push_back(w.seconds);
        times[m].cpu.push_back(cpu);
        wall_of[m] = w.seconds;
      }
      if (wall_of.count("pcl-mls-plane"))
        for (const auto& [m, t] : wall_of) times[m].ratio.push_back(t / wall_of["pcl-mls-plane"]);
      if (speed_repeat > 1) std::printf("  (end of round %d, load average %s)\n", round + 1, loadAverage().c_str());
    }
    if (speed_repeat > 1) {
      auto median = [](std::vector<double> v) {
        if (v.empty()) return double(NAN);
        std::sort(v.begin(), v.end());
        return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
      };
      std::printf("%-15s %9s %9s %9s %9s %16s\n", "speed summary", "min(s)", "median(s)", "min cpu", "med cpu",
                  "median / pcl-plane");
      for (const auto& m : order) {
        const Times& t = times[m];
        if (t.wall.empty()) continue;
        std::printf("%-15s %9.2f %9.2f %9.2f %9.2f %16.3f\n", m.c_str(), *std::min_element(t.wall.begin(), t.wall.end()),
                    median(t.wall), *std::min_element(t.cpu.begin(), t.cpu.end()), median(t.cpu), median(t.ratio));
      }
    }
  }
  std::printf("wrote %s/superres.csv and PNG close-ups\n", out_dir.c_str());
  return 0;
}

}  // namespace paps::cli
