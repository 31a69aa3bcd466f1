#pragma once
// Runs one method on one input in a child process, so that each row of a bench table gets
// its own peak memory (wait4's ru_maxrss) and a crash in one method cannot take the bench down.
#include <functional>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include <paps/core/positions.h>

namespace paps::cli {

struct WorkerResult {
  bool ok = false;
  bool timed_out = false;  // stopped by WorkerLimits::seconds
  double seconds = 0;      // algorithm wall time, measured in the child around the call only
  double peak_mb = 0;      // peak resident memory of the child
  std::string message;     // child's error line when !ok
  double radius = 0;       // radius the method used, when it reports one (metres)
  std::string chosen;      // what an automatic setting chose, when it reports it
  Positions output;
};

/// A PCL peer's input as a PCL user gives it (pcl::removeNaNFromPointCloud): the finite points
/// and where each was. PCL's MLS and normal estimators abort on NaN points, even with
/// is_dense false (their kd-tree skips them; their loop over the points still queries them):
/// `paps bench files` on a cloud with NaNs lost the PCL rows ("worker died (status 6)").
struct FiniteInput {
  Positions points;
  std::vector<std::size_t> at;  // index in the original input of points[j]
  std::size_t input_size = 0;
};
FiniteInput finiteInput(const Positions& p);
/// One value per finite point, put back at its point's index; `missing` at the others.
template <typename T>
std::vector<T> atInputIndices(const std::vector<T>& values, const FiniteInput& f, const T& missing) {
  std::vector<T> out(f.input_size, missing);
  for (std::size_t j = 0; j < f.at.size() && j < values.size(); ++j) out[f.at[j]] = values[j];
  return out;
}

/// Bounds on every worker started afterwards (0: none). A worker past `seconds` is killed
/// (SIGALRM) and reported as timed out; `memory_gb` caps its address space (RLIMIT_AS), so a
/// method whose memory grows without bound fails with bad_alloc instead of swapping.
struct WorkerLimits {
  int seconds = 0;
  double memory_gb = 0;
};
void setWorkerLimits(const WorkerLimits& limits);

/// Runs `/proc/self/exe args...` in a child process and collects what it left: the
/// "seconds"/"error" lines of `log_path`, the positions in `out_path` (raw dump), and the
/// child's peak memory. `params` are appended as key=value arguments.
WorkerResult spawnWorker(std::vector<std::string> args, const std::map<std::string, double>& params,
                         const std::string& out_path, const std::string& log_path);

/// Saves `input` to a scratch file and runs `paps bench-worker METHOD ...` on it.
WorkerResult runWorker(const std::string& scratch_dir, const std::string& method,
                       const Positions& input, const std::map<std::string, double>& params);

/// The key=value arguments of a worker command line, argv[first] onwards (spawnWorker's
/// `params`).
struct WorkerParameters {
  std::map<std::string, double> values;
  WorkerParameters(int argc, char** argv, int first);
  double get(const char* key, double fallback) const {
    const auto it = values.find(key);
    return it == values.end() ? fallback : it->second;
  }
};

/// The frame of a worker command `paps CMD METHOD IN OUT LOG key=value...`: reads IN, runs
/// `body`, writes the positions it returns to OUT, and to LOG what `body` wrote there, then
/// "seconds S" (the wall time of `body`, or the time it set in `seconds` when >= 0) or
/// "error MESSAGE". Returns the process exit code.
using WorkerBody = std::function<Positions(const std::string& method, const Positions& input,
                                           const WorkerParameters& params, std::ostream& log, double& seconds)>;
int runWorkerFrame(int argc, char** argv, const WorkerBody& body);

/// Entry of the hidden `paps bench-worker` command.
int runBenchWorker(int argc, char** argv);

/// Raw float dumps, for the scratch files only.
void writeRaw(const std::string& path, const Positions& p);
Positions readRaw(const std::string& path);

}  // namespace paps::cli
