// paps bench files: ours and the peers on the user's own clouds, in one run. There is no ground
// truth here, so the table gives what can be measured on any input: wall time of the
// algorithm alone, peak memory of its process, output count and whether it finished. Each run
// is a child process with a time and an address-space limit, so that a peer that does not end
// on a hard input (millions of neighbours per ball) is reported instead of stalling the bench.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <paps/core/cloud_io.h>
#include <paps/core/cloud_file_layout.h>
#include <paps/core/error.h>
#include <paps/core/interrupt_cleanup.h>
#include <paps/core/neighbourhood.h>

#include "bench_worker.h"
#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

namespace {

const char* kFilesUsage =
    "usage: paps bench files IN [IN ...] [options]\n"
    "  Ours and the peers on your own clouds (PCD or PLY), each run in its own process: time of\n"
    "  the algorithm alone, peak memory, output points. No ground truth, so no error column\n"
    "  (the other benches measure errors on data with a known surface).\n"
    "    denoise:   ours (default) | PCL MLS (order 2, 2 threads) and the point bilateral\n"
    "               filter at the radius ours chose\n"
    "    superres:  QSR | APSS, RIMLS, PCL MLS SAMPLE_LOCAL_PLANE at the radius holding 30\n"
    "               neighbours, all to the same output count\n"
    "    curvature: Wavejets (default, automatic R_phi) | PCL normals + principal curvatures\n"
    "               and CGAL jet fitting (order 4) on the balls of ours' R_phi\n"
    "  --stages LIST      comma list of denoise, superres, curvature (default: all)\n"
    "  --factor F         super-resolution factor (default 2)\n"
    "  --timeout S        seconds before a run is stopped and reported (default 300, 0: none)\n"
    "  --memory-limit GB  address space of a run (default 8, 0: none); past it a run fails\n"
    "  --out DIR          scratch files and files.csv (default bench_out)\n";

struct Run {
  std::string input, stage, method, setting;
  std::size_t input_points = 0, output_points = 0;
  WorkerResult w;
};

std::string status(const WorkerResult& w) {
  if (w.ok) return "ok";
  return w.timed_out ? "timeout" : "error";
}

void printRun(const Run& r) {
  const std::string note = r.w.ok ? r.setting + (r.w.chosen.empty() ? "" : " (" + r.w.chosen + ")") : r.w.message;
  if (r.w.ok)
    std::printf("%-14s %-9s %-13s %-7s %9.2f %8.0f %10zu  %s\n", r.input.c_str(), r.stage.c_str(), r.method.c_str(),
                "ok", r.w.seconds, r.w.peak_mb, r.output_points, note.c_str());
  else
    std::printf("%-14s %-9s %-13s %-7s %9s %8.0f %10s  %s\n", r.input.c_str(), r.stage.c_str(), r.method.c_str(),
                status(r.w).c_str(), "-", r.w.peak_mb, "-", note.c_str());
}

// "ours / peer" time ratios of one stage, where both finished; "peer did not finish" otherwise.
void printRatios(const std::vector<Run>& runs, std::size_t first) {
  const Run& ours = runs[first];
  std::string line = "  -> " + ours.stage + ", ours / peer time:";
  for (std::size_t k = first + 1; k < runs.size(); ++k) {
    const Run& peer = runs[k];
    line += " " + peer.method + " ";
    if (ours.w.ok && peer.w.ok && peer.w.seconds > 0) line += fmt("%.3g", ours.w.seconds / peer.w.seconds);
    else if (ours.w.ok) line += "(peer " + status(peer.w) + ")";
    else line += "(ours " + status(ours.w) + ")";
  }
  std::printf("%s\n", line.c_str());
}

}  // namespace

int runBenchFiles(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 3, {"help"});
  if (a.has("help") || a.positional.empty()) {
    std::fputs(kFilesUsage, a.has("help") ? stdout : stderr);
    return a.has("help") ? 0 : 2;
  }
  a.allowOnly({"stages", "factor", "timeout", "memory-limit", "out", "help"});
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // rows appear as they are measured
  const std::string out_dir = a.text("out", "bench_out");
  const double factor = a.number("factor", 2);
  if (!(factor >= 1 && factor <= 100)) throw InvalidParameter("factor", a.text("factor", ""), "1 to 100");
  const int timeout = a.integer("timeout", 300);
  if (timeout < 0 || timeout > 864000) throw InvalidParameter("timeout", std::to_string(timeout), "0 to 864000 seconds");
  const double memory_gb = a.number("memory-limit", 8);
  if (!(memory_gb == 0 || (memory_gb >= 0.25 && memory_gb <= 65536)))
    throw InvalidParameter("memory-limit", a.text("memory-limit", ""), "0 (none) or 0.25 to 65536 GB");
  std::vector<std::string> stages;
  for (const std::string& s : splitList(a.text("stages", "denoise,superres,curvature"))) {
    if (s != "denoise" && s != "superres" && s != "curvature")
      throw InvalidParameter("stages", s, "a comma list of denoise, superres, curvature");
#ifndef PAPS_HAVE_SURFACE
    if (s == "superres") throw InvalidParameter("stages", s, "a stage of a module this build has (no surface module)");
#endif
#ifndef PAPS_HAVE_FEATURES
    if (s == "curvature") throw InvalidParameter("stages", s, "a stage of a module this build has (no features module)");
#endif
    stages.push_back(s);
  }
  if (stages.empty()) throw InvalidParameter("stages", "", "a comma list of denoise, superres, curvature");
  for (const auto& path : a.positional) checkInputPath(path);
  std::filesystem::create_directories(out_dir);
  // The workers' scratch files: removed at the end, when a run throws, and on Ctrl-C.
  std::vector<std::string> scratch;
  for (const char* f : {"worker_out.bin", "worker_log.txt", "sr_in0.bin", "sr_out.bin", "sr_log.txt"})
    scratch.push_back(out_dir + "/" + f);
  std::vector<std::unique_ptr<TemporaryFileGuard>> scratch_guards;
  for (const auto& f : scratch) scratch_guards.push_back(std::make_unique<TemporaryFileGuard>(f));
  struct RemoveOnExit {
    const std::vector<std::string>& files;
    ~RemoveOnExit() {
      for (const auto& f : files) std::remove(f.c_str());
    }
  } remove_scratch{scratch};
  setWorkerLimits({timeout, memory_gb});

  std::printf("bench files: %zu input(s); each run limited to %s and %s of address space\n", a.positional.size(),
              timeout > 0 ? (std::to_string(timeout) + " s").c_str() : "no time",
              memory_gb > 0 ? (fmt("%g", memory_gb) + " GB").c_str() : "no limit");
  std::printf("%-14s %-9s %-13s %-7s %9s %8s %10s  %s\n", "input", "stage", "method", "status", "time(s)", "peak MB",
              "points", "setting / error");
  std::vector<Run> runs;
  for (const auto& path : a.positional) {
    const std::string name = std::filesystem::path(path).stem().string();
    // One input that cannot be benched (unreadable, no radius to choose...) is reported and
    // skipped: the others' rows and the CSV are still written.
    try {
      const Positions pts = loadPositions(path);
      const std::size_t finite = countFinite(pts);
      std::printf("%s: %zu points (%zu finite)\n", path.c_str(), pts.size(), finite);
      if (finite < 2) {
        std::printf("%-14s skipped: fewer than 2 finite points\n", name.c_str());
        continue;
      }
      // The fallback radius of the peers when ours gives none (it refused the input), and the
      // superres kernel: a typical point holds 30 neighbours.
      const SpatialIndex index(pts);
      const float r30 = radiusForNeighbourCount(pts, index, 30, NeighbourCountStatistic::Median);
      auto add = [&](const std::string& stage, const std::string& method, const std::string& setting, WorkerResult w) {
        runs.push_back({name, stage, method, setting, pts.size(), w.output.size(), std::move(w)});
        printRun(runs.back());
        runs.back().w.output.clear();
        runs.back().w.output.shrink_to_fit();
        return runs.back().w;
      };
      // One raw copy of the input for every worker: the superres worker reads it by its name
      // (sr_in0.bin of the scratch directory), the others take it as IN.
      const std::string in = out_dir + "/sr_in0.bin", out = out_dir + "/worker_out.bin", log = out_dir + "/worker_log.txt";
      writeRaw(in, pts);
      auto run = [&](const char* command, const std::string& method, const std::map<std::string, double>& p) {
        if (std::string(command) == "bench-worker-sr")
          return spawnWorker({command, method, out_dir, "1"}, p, out_dir + "/sr_out.bin", out_dir + "/sr_log.txt");
        return spawnWorker({command, method, in, out, log}, p, out, log);
      };
      for (const auto& stage : stages) {
        const std::size_t first = runs.size();
        if (stage == "denoise") {
          const WorkerResult ours = add(stage, "ours", "default", run("bench-worker", "ours", {}));
          const double r = ours.ok && ours.radius > 0 ? ours.radius : r30;
          const std::string at = (ours.ok ? "radius of ours " : "30-neighbour radius ") + fmt("%.4g", r);
          add(stage, "pcl-mls", at, run("bench-worker", "mls", {{"radius", r}, {"order", 2}, {"threads", 2}}));
          add(stage, "bilateral", at, run("bench-worker", "bilateral", {{"radius", r}}));
        } else if (stage == "superres") {
          const std::map<std::string, double> p{{"count", factor * static_cast<double>(finite)}, {"radius", r30}};
          for (const std::string m : {"qsr", "apss", "rimls", "pcl-mls-plane"})
            add(stage, m, m == "pcl-mls-plane" ? "radius " + fmt("%.4g", r30) : "default", run("bench-worker-sr", m, p));
        } else {
          const WorkerResult ours = add(stage, "wavejets", "default", run("bench-worker-curv", "wavejets", {}));
          const double r = ours.ok && ours.radius > 0 ? ours.radius : r30;
          const std::string at = (ours.ok ? "R_phi of ours " : "30-neighbour radius ") + fmt("%.4g", r);
          add(stage, "pcl", at, run("bench-worker-curv", "pcl", {{"radius", r}}));
#ifdef PAPS_HAVE_CGAL
          add(stage, "cgal", at + ", order 4", run("bench-worker-curv", "cgal", {{"radius", r}}));
#endif
        }
        printRatios(runs, first);
      }
    } catch (const Error& e) {
      std::printf("%-14s skipped: %s\n", name.c_str(), e.what());
    }
  }
  const std::string csv_path = out_dir + "/files.csv";
  {
    std::ofstream csv(csv_path + ".tmp");
    csv << "input,input_points,stage,method,setting,status,seconds,peak_mb,output_points,message\n";
    for (const auto& r : runs)
      csv << r.input << "," << r.input_points << "," << r.stage << "," << r.method << ",\"" << r.setting << "\","
          << status(r.w) << "," << (r.w.ok ? r.w.seconds : -1) << "," << r.w.peak_mb << "," << r.output_points
          << ",\"" << r.w.message << "\"\n";
    if (!csv) throw IoError("cannot write '" + csv_path + ".tmp'");
  }
  commitTemporaryFile(csv_path + ".tmp", csv_path);
  std::printf("wrote %s\n", csv_path.c_str());
  return 0;
}

}  // namespace paps::cli
