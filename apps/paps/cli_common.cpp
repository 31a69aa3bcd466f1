#include "cli_common.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <limits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <chrono>
#include <memory>
#include <mutex>
#include <utility>

#include <unistd.h>

#include <omp.h>

#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include <paps/core/cloud_file_layout.h>
#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/interrupt_cleanup.h>
#include <paps/core/normal_refresh.h>
#include <paps/core/view_point_option.h>

namespace paps::cli {

Arguments Arguments::parse(int argc, char** argv, int first, const std::vector<std::string>& flags) {
  Arguments a;
  for (int i = first; i < argc; ++i) {
    std::string s = argv[i];
    if (s.rfind("--", 0) == 0 && s.size() > 2) {
      const std::string name = s.substr(2);
      const bool is_flag = std::find(flags.begin(), flags.end(), name) != flags.end();
      if (is_flag) { a.options[name] = "1"; continue; }
      // A value missing at the end of the line is reported by allowOnly, after an unknown
      // name (a misspelt flag is more likely than a forgotten value).
      if (i + 1 >= argc) { a.options[name] = ""; a.missing_value = name; continue; }
      a.options[name] = argv[++i];
    } else {
      a.positional.push_back(s);
    }
  }
  return a;
}

double Arguments::number(const std::string& name, double fallback) const {
  const auto it = options.find(name);
  if (it == options.end()) return fallback;
  char* end = nullptr;
  const double v = std::strtod(it->second.c_str(), &end);
  if (end == it->second.c_str() || *end != '\0') throw InvalidParameter(name, it->second, "a number");
  return v;
}

float Arguments::real(const std::string& name, float fallback) const {
  if (!has(name)) return fallback;
  const double v = number(name, fallback);
  if (std::isfinite(v) && std::abs(v) > double(std::numeric_limits<float>::max()))
    throw InvalidParameter(name, options.at(name), "a number of magnitude at most 3.4e38 (single precision)");
  if (v != 0 && std::abs(v) < double(std::numeric_limits<float>::min()))
    throw InvalidParameter(name, options.at(name), "0 or a number of magnitude at least 1.2e-38 (single precision)");
  return static_cast<float>(v);
}

int Arguments::integer(const std::string& name, int fallback) const {
  if (!has(name)) return fallback;
  const double v = number(name, fallback);
  if (!(v == std::floor(v)) || v < double(std::numeric_limits<int>::min()) || v > double(std::numeric_limits<int>::max()))
    throw InvalidParameter(name, options.at(name), "a whole number");
  return int(v);
}

std::size_t Arguments::count(const std::string& name, std::size_t fallback) const {
  if (!has(name)) return fallback;
  const double v = number(name, double(fallback));
  if (!(v == std::floor(v)) || v < 0 || v > 1099511627776.0)
    throw InvalidParameter(name, options.at(name), "a whole number in [0, 2^40]");
  return std::size_t(v);
}

std::string Arguments::text(const std::string& name, const std::string& fallback) const {
  const auto it = options.find(name);
  return it == options.end() ? fallback : it->second;
}

void Arguments::allowOnly(const std::vector<std::string>& known) const {
  for (const auto& [name, value] : options)
    if (std::find(known.begin(), known.end(), name) == known.end())
      throw InvalidParameter(name, value.empty() ? "(no value)" : value, "a known option (see paps --help)");
  if (!missing_value.empty()) throw InvalidParameter(missing_value, "(missing)", "a value after --" + missing_value);
}

void Arguments::requireOutputApart() const {
  if (positional.size() < 2) return;
  // An output that does not exist yet cannot be an (existing) input.
  std::error_code ec;
  for (std::size_t i = 0; i + 1 < positional.size(); ++i)
    if (std::filesystem::equivalent(positional[i], positional.back(), ec))
      throw InvalidParameter("OUT", positional.back(), "a file other than the input (inputs are never overwritten)");
}

void Arguments::requireCloudOutput() const {
  requireOutputApart();
  if (!positional.empty()) checkCloudOutputPath(positional.back());
}

void Arguments::requireFileOutput(const std::string& extension) const {
  requireOutputApart();
  if (!positional.empty()) checkFileOutput(positional.back(), extension);
}

std::string lowerExtension(const std::string& path) {
  std::string e = std::filesystem::path(path).extension().string();
  for (auto& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

void checkFileOutput(const std::string& path, const std::string& extension) {
  checkOutputPath(path);
  if (lowerExtension(path) != extension) throw InvalidParameter("OUT", path, "a " + extension + " file");
}

void requireOptionsOf(const Arguments& a, const std::vector<std::string>& applies, const std::string& variant) {
  for (const auto& [name, value] : a.options)
    if (std::find(applies.begin(), applies.end(), name) == applies.end())
      throw InvalidParameter(name, value.empty() ? "(flag)" : value, "an option that " + variant + " uses (see --help)");
}

std::vector<std::string> splitList(const std::string& s) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (start <= s.size()) {
    const std::size_t end = std::min(s.find(',', start), s.size());
    if (end > start) out.push_back(s.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

Eigen::Vector3f parseDirection(const Arguments& a, const char* name, const Eigen::Vector3f& fallback) {
  if (!a.has(name)) return fallback;
  const std::string text = a.text(name, "");
  const std::vector<std::string> parts = splitList(text);
  Eigen::Vector3f v = Eigen::Vector3f::Zero();
  bool ok = parts.size() == 3;
  for (int k = 0; ok && k < 3; ++k) {
    try {
      std::size_t used = 0;
      v[k] = std::stof(parts[k], &used);
      ok = used == parts[k].size() && std::isfinite(v[k]);
    } catch (const std::exception&) {
      ok = false;
    }
  }
  if (!ok || v.norm() == 0 || !std::isfinite(v.norm()))
    throw InvalidParameter(name, text.empty() ? "''" : text, "three numbers X,Y,Z, not all zero");
  return v;
}

std::string samplesDir() {
  if (const char* e = std::getenv("PAPS_SAMPLES")) return e;
  const char* home = std::getenv("HOME");
  return std::string(home ? home : ".") + "/.cache/paps/samples";
}

ProgressCallback progressBar(bool quiet, bool timings) {
  if (timings) {
    // One line per finished stage with its wall time, for profiling runs and logs.
    auto start = std::make_shared<std::chrono::steady_clock::time_point>(std::chrono::steady_clock::now());
    auto printed = std::make_shared<bool>(false);
    return [start, printed](const std::string& stage, float f) {
      const auto now = std::chrono::steady_clock::now();
      if (f <= 0.f) { *start = now; *printed = false; }
      if (f >= 1.f && !*printed && (*printed = true))
        std::fprintf(stderr, "  %-18s %8.2f s\n", stage.c_str(),
                     std::chrono::duration<double>(now - *start).count());
      return true;
    };
  }
  if (quiet || !isatty(fileno(stderr))) return {};
  // The bar never steps back: two parts of a stage that report under one name (passes of
  // a filter, the two frame orientations) each count from 0; the later one only shows once
  // it passes the earlier, unless the earlier finished (its line is closed).
  auto shown = std::make_shared<std::pair<std::string, float>>("", 1.f);
  return [shown](const std::string& stage, float f) {
    if (stage == shown->first && shown->second < 1.f && f < shown->second) return true;
    *shown = {stage, f};
    const int width = 30, filled = static_cast<int>(f * width + 0.5f);
    std::fprintf(stderr, "\r%-18s [%.*s%*s] %3d%%", stage.c_str(), filled,
                 "##############################", width - filled, "", static_cast<int>(f * 100 + 0.5f));
    if (f >= 1.f) std::fprintf(stderr, "\n");
    std::fflush(stderr);
    return true;
  };
}

void takeThreadsOption(int& argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--threads") != 0) continue;
    if (i + 1 >= argc) throw InvalidParameter("threads", "(missing)", "a thread count in [1, 4096]");
    char* end = nullptr;
    const long n = std::strtol(argv[i + 1], &end, 10);
    if (end == argv[i + 1] || *end != '\0' || n < 1 || n > 4096)
      throw InvalidParameter("threads", argv[i + 1], "a thread count in [1, 4096]");
    ::setenv("OMP_NUM_THREADS", argv[i + 1], 1);
    omp_set_num_threads(static_cast<int>(n));
    for (int j = i; j + 2 <= argc; ++j) argv[j] = argv[j + 2];
    argc -= 2;
    --i;
  }
}

int runCommandLine(int argc, char** argv, const char* program, const char* usage,
                   const std::function<int(int, char**)>& dispatch) {
  installInterruptCleanup();  // an interrupted write leaves no temporary file
  try {
    takeThreadsOption(argc, argv);
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", program, e.what());
    return 1;
  }
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    std::fputs(usage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  try {
    const int status = dispatch(argc, argv);
    if (status != kUnknownCommand) return status;
    std::fprintf(stderr, "%s: unknown command '%s'\n%s", program, argv[1], usage);
    return 2;
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", program, e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: unexpected error: %s\n", program, e.what());
    return 1;
  }
}

void printRead(const std::string& path, const Positions& points) {
  const std::size_t finite = countFinite(points);
  std::printf("read %s: %zu points (%zu finite)\n", path.c_str(), points.size(), finite);
  // Said here, in the file's words: deeper down an all-NaN cloud reads as an empty one.
  if (finite == 0)
    throw InvalidInput("'" + path + "' has no finite point (" + (points.empty() ? std::string("it holds no point")
                       : "all " + std::to_string(points.size()) + " are NaN or Inf") + ")");
  float largest = 0.f;
  for (const auto& p : points)
    if (isFinite(p)) largest = std::max(largest, p.cwiseAbs().maxCoeff());
  const float extent = boundingBoxDiagonal(points);
  if (finite < 2 || !(extent > 0)) return;
  // A surface's typical spacing, roughly; float's step at the largest coordinate.
  const double spacing = extent / std::sqrt(double(finite));
  const double step = double(largest) * std::numeric_limits<float>::epsilon();
  if (step > 0.1 * spacing)
    std::fprintf(stderr, "warning: coordinates reach %g, where float steps are %g, a tenth or more of the points' "
                 "typical spacing (about %g): the positions are quantized; save the cloud with an offset\n",
                 double(largest), step, spacing);
}

bool hasField(const pcl::PCLPointCloud2& c, const char* name) {
  for (const auto& f : c.fields)
    if (f.name == name) return true;
  return false;
}

bool fileMayHaveNormals(const std::string& path) {
  try {
    const std::string ext = lowerExtension(path);  // as the reader takes it: scan.PCD is a .pcd
    if (ext == ".pcd") return readPcdLayout(path).field("normal_x") >= 0;
    if (ext == ".ply") {
      const PlyLayout layout = readPlyLayout(path);
      const int v = layout.element("vertex");
      if (v < 0) return true;  // the reader will say what is wrong
      for (const auto& prop : layout.elements[static_cast<std::size_t>(v)].properties)
        if (prop.name == "nx" || prop.name == "normal_x") return true;
      return false;
    }
  } catch (const Error&) {
  }
  return true;  // unreadable here: the reader's own error comes later
}

void setNormals(pcl::PCLPointCloud2& cloud, const Normals& n, const std::vector<float>* curvature) {
  pcl::PointCloud<pcl::Normal> nc;
  nc.resize(n.size());
  for (std::size_t i = 0; i < n.size(); ++i) {
    nc[i].getNormalVector3fMap() = n[i];
    nc[i].curvature = curvature ? (*curvature)[i] : 0.f;
  }
  if (!hasField(cloud, "normal_x")) {
    pcl::PCLPointCloud2 nb;
    pcl::toPCLPointCloud2(nc, nb);
    if (!curvature)
      nb.fields.erase(std::remove_if(nb.fields.begin(), nb.fields.end(),
                                     [](const pcl::PCLPointField& f) { return f.name == "curvature"; }),
                      nb.fields.end());
    cloud = appendFields(cloud, nb);  // in the input's width x height
    return;
  }
  if (curvature) throw InvalidParameter("curvature", "given", "a cloud without normal fields (a new cloud)");
  std::size_t off[3] = {0, 0, 0};
  for (const auto& f : cloud.fields) {
    if (f.datatype != pcl::PCLPointField::FLOAT32 &&
        (f.name == "normal_x" || f.name == "normal_y" || f.name == "normal_z"))
      throw InvalidInput("normal fields of the input are not float32");
    if (f.name == "normal_x") off[0] = f.offset;
    if (f.name == "normal_y") off[1] = f.offset;
    if (f.name == "normal_z") off[2] = f.offset;
  }
  for (std::size_t i = 0; i < n.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const float v = n[i][k];
      std::memcpy(&cloud.data[i * cloud.point_step + off[k]], &v, sizeof(float));
    }
}

void setCurvatureField(pcl::PCLPointCloud2& cloud, const std::vector<float>& values,
                       const std::function<bool(std::size_t)>& write) {
  for (const auto& f : cloud.fields) {
    if (f.name != "curvature" || f.datatype != pcl::PCLPointField::FLOAT32) continue;
    if (values.size() != std::size_t(cloud.width) * cloud.height)
      throw InvalidParameter("curvature", std::to_string(values.size()), "one value per point");
    for (std::size_t i = 0; i < values.size(); ++i)
      if (!write || write(i)) std::memcpy(&cloud.data[i * cloud.point_step + f.offset], &values[i], sizeof(float));
  }
}

bool blobNormals(const pcl::PCLPointCloud2& c, Normals& out) {
  int off[3] = {-1, -1, -1};
  const char* names[3] = {"normal_x", "normal_y", "normal_z"};
  for (const auto& f : c.fields)
    for (int k = 0; k < 3; ++k)
      if (f.name == names[k] && f.datatype == pcl::PCLPointField::FLOAT32) off[k] = static_cast<int>(f.offset);
  if (off[0] < 0 || off[1] < 0 || off[2] < 0) return false;
  const std::size_t n = std::size_t(c.width) * c.height;
  out.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) std::memcpy(&out[i][k], &c.data[i * c.point_step + off[k]], sizeof(float));
  return true;
}

void refreshBlobNormals(pcl::PCLPointCloud2& cloud, const Positions& moved, float radius,
                        const Eigen::Vector3f& origin, bool keep) {
  Normals previous;
  if (!blobNormals(cloud, previous)) return;
  if (keep) {
    std::printf("normals: the input's kept (--keep-normals)\n");
    return;
  }
  const NormalRefresh r = refreshNormals(moved, radius, previous, {}, knownSensorOrigin(origin));
  setNormals(cloud, r.normals);
  // Curvature where refreshed, or NaN with the normal; kept where the normal was kept.
  setCurvatureField(cloud, r.variation,
                    [&](std::size_t i) { return std::isfinite(r.variation[i]) || !isFinite(r.normals[i]); });
  cloud.is_dense = cloud.is_dense && r.without_normal == 0;
  std::printf("normals%s estimated again on the output (radius %g m, at most %d neighbours): %zu\n",
              hasField(cloud, "curvature") ? " and curvature" : "", double(radius), kRefreshNormalNeighbours,
              r.refreshed);
  if (r.kept_previous)
    std::printf("normals: %zu points with too few neighbours for a new one kept the input's\n", r.kept_previous);
  if (r.without_normal)
    std::fprintf(stderr, "warning: %zu points have too few neighbours (or only collinear ones): normal NaN\n",
                 r.without_normal);
}

std::string fmt(const char* format, double value) {
  char b[64];
  std::snprintf(b, sizeof b, format, value);
  return b;
}

}  // namespace paps::cli
