#include "bench_worker.h"

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <pcl/point_types.h>
#include <pcl/surface/mls.h>
#include <pcl/search/kdtree.h>

#include <paps/core/error.h>
#include <paps/filters/lpf_denoising.h>
#include <paps/filters/point_bilateral_filter.h>
#include <paps/filters/similarity_denoising.h>

namespace paps::cli {

void writeRaw(const std::string& path, const Positions& p) {
  std::ofstream f(path, std::ios::binary);
  const std::uint64_t n = p.size();
  f.write(reinterpret_cast<const char*>(&n), sizeof n);
  f.write(reinterpret_cast<const char*>(p.data()), static_cast<std::streamsize>(n * sizeof(Eigen::Vector3f)));
  if (!f) throw IoError("cannot write scratch file '" + path + "'");
}

Positions readRaw(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::uint64_t n = 0;
  f.read(reinterpret_cast<char*>(&n), sizeof n);
  if (!f || n > (1ull << 32)) throw IoError("cannot read scratch file '" + path + "'");
  Positions p(n);
  f.read(reinterpret_cast<char*>(p.data()), static_cast<std::streamsize>(n * sizeof(Eigen::Vector3f)));
  if (!f) throw IoError("truncated scratch file '" + path + "'");
  return p;
}

namespace {
WorkerLimits g_limits;
}

void setWorkerLimits(const WorkerLimits& limits) { g_limits = limits; }

FiniteInput finiteInput(const Positions& p) {
  FiniteInput f;
  f.input_size = p.size();
  for (std::size_t i = 0; i < p.size(); ++i)
    if (isFinite(p[i])) {
      f.points.push_back(p[i]);
      f.at.push_back(i);
    }
  return f;
}

WorkerResult spawnWorker(std::vector<std::string> args, const std::map<std::string, double>& params,
                         const std::string& out_path, const std::string& log_path) {
  std::remove(out_path.c_str());
  std::remove(log_path.c_str());
  args.insert(args.begin(), "/proc/self/exe");
  for (const auto& [k, v] : params) {
    std::ostringstream s;
    s.precision(9);
    s << k << "=" << v;
    args.push_back(s.str());
  }
  WorkerResult r;
  const pid_t pid = fork();
  if (pid == 0) {
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    if (g_limits.memory_gb > 0) {
      const rlim_t bytes = static_cast<rlim_t>(g_limits.memory_gb * 1073741824.0);
      const rlimit lim{bytes, bytes};
      setrlimit(RLIMIT_AS, &lim);
    }
    if (g_limits.seconds > 0) alarm(static_cast<unsigned>(g_limits.seconds));  // kept across execv
    execv("/proc/self/exe", argv.data());
    _exit(127);
  }
  int status = 0;
  rusage usage{};
  wait4(pid, &status, 0, &usage);
  r.peak_mb = usage.ru_maxrss / 1024.0;
  std::ifstream lf(log_path);
  std::string line;
  while (std::getline(lf, line)) {
    if (line.rfind("seconds ", 0) == 0) r.seconds = std::atof(line.c_str() + 8);
    else if (line.rfind("error ", 0) == 0) r.message = line.substr(6);
    else if (line.rfind("radius ", 0) == 0) r.radius = std::atof(line.c_str() + 7);
    else if (line.rfind("chosen ", 0) == 0) r.chosen = line.substr(7);
  }
  r.ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  r.timed_out = !r.ok && WIFSIGNALED(status) && WTERMSIG(status) == SIGALRM;
  if (r.timed_out) r.message = "timed out after " + std::to_string(g_limits.seconds) + " s";
  if (!r.ok && r.message.empty()) r.message = "worker died (status " + std::to_string(status) + ")";
  if (r.ok) r.output = readRaw(out_path);
  return r;
}

WorkerResult runWorker(const std::string& scratch_dir, const std::string& method,
                       const Positions& input, const std::map<std::string, double>& params) {
  const std::string in = scratch_dir + "/worker_in.bin", out = scratch_dir + "/worker_out.bin",
                    log = scratch_dir + "/worker_log.txt";
  writeRaw(in, input);
  return spawnWorker({"bench-worker", method, in, out, log}, params, out, log);
}

WorkerParameters::WorkerParameters(int argc, char** argv, int first) {
  for (int i = first; i < argc; ++i) {
    const std::string a = argv[i];
    const auto eq = a.find('=');
    values[a.substr(0, eq)] = std::atof(a.c_str() + eq + 1);
  }
}

int runWorkerFrame(int argc, char** argv, const WorkerBody& body) {
  if (argc < 6) return 2;
  const std::string method = argv[2], in = argv[3], out = argv[4], log = argv[5];
  const WorkerParameters params(argc, argv, 6);
  std::ofstream lf(log);
  try {
    const Positions input = readRaw(in);
    double seconds = -1;
    const auto t0 = std::chrono::steady_clock::now();
    const Positions output = body(method, input, params, lf, seconds);
    if (seconds < 0) seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    writeRaw(out, output);
    lf << "seconds " << seconds << "\n";
    return 0;
  } catch (const std::exception& e) {
    lf << "error " << e.what() << "\n";
    return 1;
  }
}

int runBenchWorker(int argc, char** argv) {
  return runWorkerFrame(argc, argv, [](const std::string& method, const Positions& input, const WorkerParameters& params,
                                       std::ostream& lf, double&) {
    auto get = [&](const char* k, double d) { return params.get(k, d); };
    Positions output;
    if (method == "ours") {
      SimilarityDenoisingParameters q;
      q.radius = static_cast<float>(get("radius", 0));
      q.sigma_scale = static_cast<float>(get("sigma_scale", q.sigma_scale));
      q.similar_patches = static_cast<int>(get("patches", q.similar_patches));
      q.smoothing_iterations = static_cast<int>(get("smoothing", q.smoothing_iterations));
      q.grid_size = static_cast<int>(get("grid", q.grid_size));
      q.search_checks = static_cast<int>(get("checks", q.search_checks));
      q.passes = static_cast<int>(get("passes", q.passes));
      q.descriptor_smoothing = static_cast<int>(get("guide", q.descriptor_smoothing));
      q.guided_passes = get("guided", 1) != 0;
      q.own_weight = static_cast<float>(get("own", q.own_weight));
      q.adapt_to_noise = get("adapt", 1) != 0;
      q.max_tile_points = static_cast<std::size_t>(get("tile", static_cast<double>(q.max_tile_points)));
      q.max_noise_ratio = static_cast<float>(get("split", q.max_noise_ratio));
      if (get("centre", 0) != 0) q.aggregation = SimilarityDenoisingParameters::Aggregation::Centre;
      SimilarityDenoisingReport report;
      output = denoiseBySimilarity(input, q, &report);
      lf << "radius " << report.radius << "\n";
      if (report.noise_sigma > 0) {
        char b[160];
        std::snprintf(b, sizeof b, "noise %.3g, radius x%.2f, own %g, %d pass%s", report.noise_sigma,
                      report.radius_scale, report.own_weight, report.passes,
                      report.passes > 1 ? (report.guided_passes ? "es guided" : "es refiltered") : "");
        lf << "chosen " << b
           << (report.subsets > 1 ? ", " + std::to_string(report.subsets) + " interleaved subsets" : std::string())
           << (report.tiles > report.subsets ? ", " + std::to_string(report.tiles) + " tiles" : std::string()) << "\n";
      }
    } else if (method == "lpf") {
      LpfDenoisingParameters q;
      q.probing.radius = static_cast<float>(get("radius", 0));
      q.probing.neighbours = static_cast<int>(get("neighbours", q.probing.neighbours));
      q.probing.atoms = static_cast<int>(get("atoms", q.probing.atoms));
      q.iterations = static_cast<int>(get("passes", q.iterations));
      q.bend_threshold = static_cast<float>(get("bend", q.bend_threshold));
      q.probing.free_curvature = get("free-curvature", 0) != 0;
      q.max_tile_points = static_cast<std::size_t>(get("tile", static_cast<double>(q.max_tile_points)));
      LpfDenoisingReport report;
      output = lpfDenoisePositions(input, q, &report);
      lf << "radius " << report.radius << "\n";
      {
        char b[160];
        std::snprintf(b, sizeof b, "noise %.3g = %.2f step, growth %.3f, %d pass%s", report.noise_sigma,
                      report.step > 0 ? report.noise_sigma / report.step : 0.f, report.noise_growth, report.passes,
                      report.passes == 1 ? "" : "es");
        lf << "chosen " << b << (report.tiles > 1 ? ", " + std::to_string(report.tiles) + " tiles" : std::string())
           << "\n";
      }
    } else if (method == "bilateral") {
      PointBilateralParameters q;
      q.radius = static_cast<float>(get("radius", 0));
      q.iterations = static_cast<int>(get("iterations", 1));
      q.max_tile_points = static_cast<std::size_t>(get("tile", static_cast<double>(q.max_tile_points)));
      PointBilateralReport report;
      output = bilateralFilterPositions(input, q, &report);
      lf << "radius " << report.radius << "\n";
      if (report.tiles > 1) lf << "chosen " << report.tiles << " tiles\n";
    } else if (method == "mls") {
      auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
      const FiniteInput finite = finiteInput(input);
      writePositions(finite.points, *cloud);
      pcl::MovingLeastSquares<pcl::PointXYZ, pcl::PointXYZ> mls;
      mls.setInputCloud(cloud);
      mls.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
      mls.setPolynomialOrder(static_cast<int>(get("order", 2)));
      mls.setSearchRadius(get("radius", 0));
      mls.setComputeNormals(false);
      mls.setNumberOfThreads(static_cast<unsigned>(get("threads", 2)));
      pcl::PointCloud<pcl::PointXYZ> result;
      mls.process(result);
      // One projection per point (no upsampling): back at the input's indices.
      output = result.size() == finite.points.size()
                   ? atInputIndices(positionsOf(result), finite, Eigen::Vector3f::Constant(NAN).eval())
                   : positionsOf(result);
      lf << "radius " << get("radius", 0) << "\n";
    } else {
      throw InvalidParameter("method", method, "ours, lpf, bilateral or mls");
    }
    return output;
  });
}

}  // namespace paps::cli
