#pragma once
// Small shared pieces of the `paps` command line: argument parsing and a progress bar.
#include <cstddef>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <pcl/PCLPointCloud2.h>

#include <paps/core/error.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps::cli {

/// Positional arguments and --name value options. Flags without a value map to "1".
struct Arguments {
  std::vector<std::string> positional;
  std::map<std::string, std::string> options;
  std::string missing_value;  ///< an option given last without its value (reported by allowOnly)

  static Arguments parse(int argc, char** argv, int first, const std::vector<std::string>& flags);
  bool has(const std::string& name) const { return options.count(name) > 0; }
  /// Value of --name as a number; throws paps::InvalidParameter when it is not one.
  double number(const std::string& name, double fallback) const;
  /// Value of --name as a single-precision number (what the library parameters hold); throws
  /// paps::InvalidParameter when it is not a number, or is one that a float would turn into
  /// infinity (1e300) or silently into 0 (1e-300).
  float real(const std::string& name, float fallback) const;
  /// Value of --name as a whole number in the range of int (counts, orders, bits); throws
  /// paps::InvalidParameter naming the option otherwise ("1e12" is not silently wrapped).
  int integer(const std::string& name, int fallback) const;
  /// Value of --name as a point count in [0, 2^40]; throws paps::InvalidParameter otherwise.
  std::size_t count(const std::string& name, std::size_t fallback) const;
  std::string text(const std::string& name, const std::string& fallback) const;
  /// Throws paps::InvalidParameter for an option not in `known`, then for an option whose
  /// value is missing.
  void allowOnly(const std::vector<std::string>& known) const;
  /// Throws paps::InvalidParameter when the output (the last positional argument) is one of
  /// the inputs (the others): inputs are never overwritten, not even on request.
  void requireOutputApart() const;
  /// requireOutputApart, then the output file checked before any work (a long run must not
  /// end on a path it cannot write): an existing folder that takes new files, and a name
  /// ending in `extension` (".pcd or .ply" for clouds: checkCloudOutputPath).
  void requireCloudOutput() const;
  void requireFileOutput(const std::string& extension) const;
};

/// The extension of `path` in lower case, with its dot (".ply"; "" when it has none).
std::string lowerExtension(const std::string& path);

/// checkOutputPath, then a name ending in `extension` (lower case, with its dot): throws
/// InvalidParameter("OUT") otherwise.
void checkFileOutput(const std::string& path, const std::string& extension);

/// Runs `validate` (which sets or checks a library parameter struct) and re-throws an
/// InvalidParameter under the name of the command-line option it came from: the library
/// names its fields (target_neighbours), the user typed the option (--neighbours).
template <typename F>
void validateAsOptions(const std::map<std::string, std::string>& option_of, F&& validate) {
  try {
    validate();
  } catch (const InvalidParameter& e) {
    const auto it = option_of.find(e.parameter());
    throw InvalidParameter(it == option_of.end() ? e.parameter() : it->second, e.value(), e.expected());
  }
}

/// Throws InvalidParameter for an option given on the line that is not in `applies` (the
/// options of the variant chosen, e.g. --atoms under --method similarity), naming `variant`.
void requireOptionsOf(const Arguments& a, const std::vector<std::string>& applies, const std::string& variant);

/// "a,b,,c" -> {"a", "b", "c"}.
std::vector<std::string> splitList(const std::string& s);

/// Option `name` as "X,Y,Z" (a direction: finite, not all zero); `fallback` when absent.
/// Throws InvalidParameter naming the option otherwise.
Eigen::Vector3f parseDirection(const Arguments& a, const char* name, const Eigen::Vector3f& fallback);

/// One number through a printf format ("%.2f%%"), for table cells and labels.
std::string fmt(const char* format, double value);

/// Where scripts/fetch_samples.sh caches the sample scans: $PAPS_SAMPLES, else
/// ~/.cache/paps/samples.
std::string samplesDir();

/// A progress bar on stderr when it is a terminal and not `quiet`; with `timings`, one line
/// per finished stage with its wall time instead.
ProgressCallback progressBar(bool quiet, bool timings = false);

/// Prints "read PATH: N points (M finite)"; throws InvalidInput when no point is finite; and
/// prints, on stderr, a warning when the coordinates are
/// so large that float steps there reach a tenth of the points' typical spacing (UTM-like
/// coordinates without an offset: the file itself has lost the detail).
void printRead(const std::string& path, const Positions& points);

/// `--threads N` anywhere on the line bounds every command (and the bench workers it starts,
/// through OMP_NUM_THREADS); it is taken out of argv before the command parses its options.
/// Throws InvalidParameter on a count outside [1, 4096].
void takeThreadsOption(int& argc, char** argv);

/// What the commands of a binary (paps, paps-fusion, paps-codec) share around them: the
/// interrupt cleanup, --threads, the usage on no command or --help, and one clear error line
/// ("<program>: error: ...") for any exception. `dispatch` runs the command argv[1] names and
/// returns its exit status, or kUnknownCommand.
constexpr int kUnknownCommand = -1;
int runCommandLine(int argc, char** argv, const char* program, const char* usage,
                   const std::function<int(int, char**)>& dispatch);

/// Whether the cloud has a field of that name.
bool hasField(const pcl::PCLPointCloud2& c, const char* name);
/// From the header alone: whether the .pcd or .ply at `path` has normal fields (PCL reads a
/// PLY's nx ny nz as normal_x ...). True when the header cannot be read, so that the reader
/// reports what is wrong with the file.
bool fileMayHaveNormals(const std::string& path);

/// Writes one normal per point into float32 normal_x/y/z, appending the three fields when the
/// cloud has none, with PCL's `curvature` field after them when `curvature` (one per point) is
/// given (only for a cloud without normal fields). Throws InvalidInput when its normal fields
/// are not float32.
void setNormals(pcl::PCLPointCloud2& cloud, const Normals& n, const std::vector<float>* curvature = nullptr);

/// Writes one value per point into the cloud's float32 `curvature` field, where `write(i)`
/// holds (all when not given); nothing when the cloud has no such field.
void setCurvatureField(pcl::PCLPointCloud2& cloud, const std::vector<float>& values,
                       const std::function<bool(std::size_t)>& write = {});

/// The float32 normal_x/y/z of every point (whatever their values: PCL writes 0 0 0 where no
/// normal was computed). False, and `out` untouched, when the cloud has no such fields.
bool blobNormals(const pcl::PCLPointCloud2& cloud, Normals& out);

/// After a point-moving filter wrote `moved` into `cloud`: when the cloud has float32 normal
/// fields and `keep` is false, their normals (and a float32 `curvature` field, when present)
/// are estimated again at `radius` (paps::refreshNormals, oriented as the input's normals, else
/// towards `origin` when it is known, else by propagation), and a line says so; with `keep`
/// a line says the input's were kept. Nothing for a cloud without normals.
void refreshBlobNormals(pcl::PCLPointCloud2& cloud, const Positions& moved, float radius,
                        const Eigen::Vector3f& origin, bool keep);

}  // namespace paps::cli
