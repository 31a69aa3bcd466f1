// Helper of the CLI tests: writes a small test cloud, and checks a `paps` output against
// its input (same number of points, same fields in the same order, only x y z moved).
//   paps_test_cloud_tool write OUT.{pcd,ply} COUNT [binary|compressed|ascii|organized|rough|lines|utm]
//   paps_test_cloud_tool check IN.pcd OUT.pcd
//   paps_test_cloud_tool keeps IN.pcd OUT.pcd FIELD... (same width x height, FIELDs present)
//   paps_test_cloud_tool unhex IN.hex OUT (bytes from hexadecimal text, for damaged files)
//   paps_test_cloud_tool permute IN.pcd OUT.pcd (the same points in a seeded shuffled order)
//   paps_test_cloud_tool same-points A.pcd B.pcd (the same points, byte for byte, in any order)
//   paps_test_cloud_tool normals OUT.pcd MAX_DEGREES [up|down] (unit normals in normal_x/y/z,
//     all on one side of the written surface's, that side if given, and within MAX_DEGREES of
//     it at every point)
// Exit 0 when it went well; otherwise one line on stderr and exit 1.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <algorithm>
#include <string>
#include <vector>

#include <pcl/PCLPointCloud2.h>
#include <pcl/common/io.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

namespace {

int fail(const std::string& what) {
  std::fprintf(stderr, "paps_test_cloud_tool: %s\n", what.c_str());
  return 1;
}

// A gently curved, noisy surface with an intensity per point: enough for the denoiser to
// find neighbours and move points.
// The surface `write` samples (heights above it are the noise).
float surface(float x, float y) { return 0.1f * std::sin(3.f * x) * std::cos(2.f * y); }

int write(const std::string& path, int count, const std::string& format) {
  pcl::PointCloud<pcl::PointXYZI> cloud;
  const int side = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(count))));
  unsigned state = 7u;
  // "rough": noise as large as the spacing, where the normals' orientation is ambiguous.
  const float amplitude = format == "rough" || format == "rough-doubled" ? 0.03f : 0.004f;
  auto noise = [&state, amplitude] {
    state = state * 1664525u + 1013904223u;
    return (static_cast<float>(state >> 8) / 16777216.f - 0.5f) * amplitude;
  };
  const bool lines = format == "lines";  // scan lines: 2 mm apart along x, 5 cm apart in y
  const int per_line = lines ? 200 : side;
  for (int k = 0; k < count; ++k) {
    pcl::PointXYZI p;
    p.x = (lines ? 0.002f : 0.02f) * static_cast<float>(k % per_line);
    p.y = (lines ? 0.05f : 0.02f) * static_cast<float>(k / per_line);
    p.z = surface(p.x, p.y) + noise();
    if (format == "lifted") p.z += 1.f;  // 1 m above the origin, the sensor's place
    if (format == "utm") {  // UTM-like coordinates saved as float: steps of 0.03-0.5 m there
      p.x += 500000.f;
      p.y += 5000000.f;
    }
    p.intensity = static_cast<float>(k);
    cloud.push_back(p);
  }
  if (format == "organized") {  // side x (count / side) rows, a tenth of the points NaN
    cloud.width = static_cast<std::uint32_t>(side);
    cloud.height = static_cast<std::uint32_t>(count / side);
    cloud.resize(std::size_t(cloud.width) * cloud.height);
    cloud.width = static_cast<std::uint32_t>(side);
    cloud.height = static_cast<std::uint32_t>(count / side);
    for (std::size_t k = 3; k < cloud.size(); k += 10) cloud[k].x = cloud[k].y = cloud[k].z = NAN;
    cloud.is_dense = false;
  }
  // "doubled", "rough-doubled": every point stored twice (the copies after the originals), as
  // scans written twice or merged are.
  if (format == "doubled" || format == "rough-doubled") {
    const std::size_t n = cloud.size();
    for (std::size_t k = 0; k < n; ++k) cloud.push_back(cloud[k]);
  }
  // "sensor-below": the file says its sensor was 2 m under the surface (PCD VIEWPOINT).
  if (format == "sensor-below") cloud.sensor_origin_ = Eigen::Vector4f(0.3f, 0.3f, -2.f, 0.f);
  // "stale-normals": normal_x/y/z 30 degrees off the surface's, pointing down, and a curvature
  // of 0.5, as an estimate made before the points moved would be.
  if (format == "stale-normals") {
    pcl::PointCloud<pcl::PointXYZINormal> with;
    pcl::copyPointCloud(cloud, with);
    for (auto& q : with) {
      q.normal_x = 0.5f;
      q.normal_y = 0.f;
      q.normal_z = -0.8660254f;
      q.curvature = 0.5f;
    }
    return pcl::io::savePCDFileBinary(path, with) == 0 ? 0 : fail("cannot write " + path);
  }
  const bool ply = path.size() > 4 && path.compare(path.size() - 4, 4, ".ply") == 0;
  const int rc = ply ? (format == "ascii" ? pcl::io::savePLYFileASCII(path, cloud) : pcl::io::savePLYFileBinary(path, cloud))
                 : format == "compressed" ? pcl::io::savePCDFileBinaryCompressed(path, cloud)
                 : format == "ascii"      ? pcl::io::savePCDFileASCII(path, cloud)
                                          : pcl::io::savePCDFileBinary(path, cloud);
  if (rc != 0) return fail("cannot write " + path);
  return 0;
}

int check(const std::string& in_path, const std::string& out_path) {
  pcl::PCLPointCloud2 in, out;
  if (pcl::io::loadPCDFile(in_path, in) != 0) return fail("cannot read " + in_path);
  if (pcl::io::loadPCDFile(out_path, out) != 0) return fail("cannot read " + out_path);
  const std::size_t n_in = static_cast<std::size_t>(in.width) * in.height;
  const std::size_t n_out = static_cast<std::size_t>(out.width) * out.height;
  if (n_in != n_out) return fail("point count " + std::to_string(n_out) + " != " + std::to_string(n_in));
  if (in.fields.size() != out.fields.size())
    return fail("field count " + std::to_string(out.fields.size()) + " != " + std::to_string(in.fields.size()));
  for (std::size_t f = 0; f < in.fields.size(); ++f)
    if (in.fields[f].name != out.fields[f].name || in.fields[f].datatype != out.fields[f].datatype ||
        in.fields[f].count != out.fields[f].count)
      return fail("field " + std::to_string(f) + " is '" + out.fields[f].name + "', expected '" +
                  in.fields[f].name + "'");
  pcl::PointCloud<pcl::PointXYZI> a, b;
  pcl::fromPCLPointCloud2(in, a);
  pcl::fromPCLPointCloud2(out, b);
  std::size_t moved = 0;
  double before = 0, after = 0;  // squared heights over the written surface
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a[i].intensity != b[i].intensity) return fail("intensity of point " + std::to_string(i) + " changed");
    if (!std::isfinite(b[i].x) || !std::isfinite(b[i].y) || !std::isfinite(b[i].z))
      return fail("point " + std::to_string(i) + " is not finite");
    if ((a[i].getVector3fMap() - b[i].getVector3fMap()).norm() > 0.05f)
      return fail("point " + std::to_string(i) + " moved too far");
    moved += a[i].getVector3fMap() != b[i].getVector3fMap();
    before += std::pow(a[i].z - surface(a[i].x, a[i].y), 2);
    after += std::pow(b[i].z - surface(b[i].x, b[i].y), 2);
  }
  if (moved < a.size() / 2) return fail("only " + std::to_string(moved) + " points moved");
  // A denoiser brings the points closer to the surface `write` drew them around (measured on
  // 900 points: RMS 1.17e-3 before, 3.5e-4 similarity, 5.7e-4 bilateral).
  const double rms_before = std::sqrt(before / a.size()), rms_after = std::sqrt(after / a.size());
  if (!(rms_after < 0.6 * rms_before))
    return fail("not denoised: RMS height over the surface " + std::to_string(rms_after) + ", input " +
                std::to_string(rms_before));
  std::printf("%zu points, %zu fields, %zu moved, RMS to the surface %.3g -> %.3g\n", n_out, out.fields.size(), moved,
              rms_before, rms_after);
  return 0;
}

// OUT has IN's width x height, and each named field with IN's values where IN has it (the
// fields a stage adds are only required to be there).
int keeps(const std::string& in_path, const std::string& out_path, const std::vector<std::string>& names) {
  pcl::PCLPointCloud2 in, out;
  if (pcl::io::loadPCDFile(in_path, in) != 0) return fail("cannot read " + in_path);
  if (pcl::io::loadPCDFile(out_path, out) != 0) return fail("cannot read " + out_path);
  if (in.width != out.width || in.height != out.height)
    return fail("organisation " + std::to_string(out.width) + " x " + std::to_string(out.height) + " != " +
                std::to_string(in.width) + " x " + std::to_string(in.height));
  for (const std::string& name : names) {
    const pcl::PCLPointField *a = nullptr, *b = nullptr;
    for (const auto& f : in.fields) if (f.name == name) a = &f;
    for (const auto& f : out.fields) if (f.name == name) b = &f;
    if (!b) return fail("output has no field '" + name + "'");
    if (!a) continue;
    if (a->datatype != b->datatype || a->count != b->count) return fail("field '" + name + "' changed type");
    const std::size_t bytes = pcl::getFieldSize(a->datatype) * std::max<std::uint32_t>(a->count, 1);
    for (std::size_t i = 0; i < std::size_t(in.width) * in.height; ++i)
      if (std::memcmp(&in.data[i * in.point_step + a->offset], &out.data[i * out.point_step + b->offset], bytes))
        return fail("field '" + name + "' of point " + std::to_string(i) + " changed");
  }
  std::printf("%u x %u, %zu fields checked\n", out.width, out.height, names.size());
  return 0;
}

int unhex(const std::string& in_path, const std::string& out_path) {
  std::FILE* in = std::fopen(in_path.c_str(), "rb");
  if (!in) return fail("cannot read " + in_path);
  std::string text;
  for (int c; (c = std::fgetc(in)) != EOF;) text.push_back(static_cast<char>(c));
  std::fclose(in);
  std::FILE* out = std::fopen(out_path.c_str(), "wb");
  if (!out) return fail("cannot write " + out_path);
  for (std::size_t i = 0; i + 1 < text.size(); i += 2) {
    const int byte = std::stoi(text.substr(i, 2), nullptr, 16);
    std::fputc(byte, out);
  }
  std::fclose(out);
  return 0;
}

// The points of IN in a shuffled order (Fisher-Yates on a fixed LCG), every field kept.
int permute(const std::string& in_path, const std::string& out_path) {
  pcl::PCLPointCloud2 in;
  if (pcl::io::loadPCDFile(in_path, in) != 0) return fail("cannot read " + in_path);
  const std::size_t n = static_cast<std::size_t>(in.width) * in.height;
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = i;
  std::uint64_t state = 12345u;
  for (std::size_t i = n; i > 1; --i) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    std::swap(order[i - 1], order[(state >> 33) % i]);
  }
  pcl::PCLPointCloud2 out = in;
  out.width = static_cast<std::uint32_t>(n);
  out.height = 1;
  out.row_step = out.width * out.point_step;
  for (std::size_t k = 0; k < n; ++k)
    std::memcpy(&out.data[k * out.point_step], &in.data[order[k] * in.point_step], in.point_step);
  if (pcl::io::savePCDFile(out_path, out, Eigen::Vector4f::Zero(), Eigen::Quaternionf::Identity(), true) != 0)
    return fail("cannot write " + out_path);
  return 0;
}

// A and B hold the same points (every field, byte for byte), whatever their order.
int samePoints(const std::string& a_path, const std::string& b_path) {
  pcl::PCLPointCloud2 a, b;
  if (pcl::io::loadPCDFile(a_path, a) != 0) return fail("cannot read " + a_path);
  if (pcl::io::loadPCDFile(b_path, b) != 0) return fail("cannot read " + b_path);
  if (a.point_step != b.point_step || a.data.size() != b.data.size())
    return fail("different layouts or point counts");
  auto rows = [](const pcl::PCLPointCloud2& c) {
    std::vector<std::string> r(c.data.size() / c.point_step);
    for (std::size_t i = 0; i < r.size(); ++i)
      r[i].assign(reinterpret_cast<const char*>(&c.data[i * c.point_step]), c.point_step);
    std::sort(r.begin(), r.end());
    return r;
  };
  const std::vector<std::string> ra = rows(a), rb = rows(b);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < ra.size(); ++i) differ += ra[i] != rb[i];
  if (differ) return fail(std::to_string(differ) + " of " + std::to_string(ra.size()) + " sorted points differ");
  std::printf("%zu points, the same in both\n", ra.size());
  return 0;
}

// OUT (an upsampled `write` surface) has a unit normal per point, within max_degrees of the
// surface's own normal (orientation-blind), and all of them on one side of it.
int normals(const std::string& path, double max_degrees, const std::string& side) {
  pcl::PointCloud<pcl::PointNormal> cloud;
  pcl::PCLPointCloud2 blob;
  if (pcl::io::loadPCDFile(path, blob) != 0) return fail("cannot read " + path);
  for (const char* f : {"normal_x", "normal_y", "normal_z"})
    if (std::none_of(blob.fields.begin(), blob.fields.end(), [f](const pcl::PCLPointField& x) { return x.name == f; }))
      return fail(path + " has no field " + f);
  pcl::fromPCLPointCloud2(blob, cloud);
  if (cloud.empty()) return fail(path + " is empty");
  std::size_t up = 0;
  double worst = 0;
  for (const auto& p : cloud) {
    const Eigen::Vector3f n = p.getNormalVector3fMap();
    if (!std::isfinite(n.norm()) || std::abs(n.norm() - 1.f) > 1e-3f) return fail("a normal is not a unit vector");
    const float h = 1e-3f;  // the surface's normal by central differences
    const Eigen::Vector3f t((surface(p.x + h, p.y) - surface(p.x - h, p.y)) / (2 * h),
                            (surface(p.x, p.y + h) - surface(p.x, p.y - h)) / (2 * h), 1.f);
    const float c = n.dot(Eigen::Vector3f(-t.x(), -t.y(), 1.f).normalized());
    up += c > 0;
    worst = std::max(worst, std::acos(std::min(1.f, std::abs(c))) * 180.0 / M_PI);
  }
  if (up != 0 && up != cloud.size())
    return fail(std::to_string(up) + " of " + std::to_string(cloud.size()) + " normals point up: not one orientation");
  if ((side == "up" && up == 0) || (side == "down" && up != 0)) return fail("the normals do not point " + side);
  if (worst > max_degrees) return fail("a normal is " + std::to_string(worst) + " degrees off the surface's");
  std::printf("%zu unit normals, one orientation, at most %.2f degrees off the surface's\n", cloud.size(), worst);
  return 0;
}

// B holds twice A's points (B's first half, then its second half), each half equal to A byte
// for byte: a stage gave every copy of a point what it gives the point alone.
int halves(const std::string& a_path, const std::string& b_path) {
  pcl::PCLPointCloud2 a, b;
  if (pcl::io::loadPCDFile(a_path, a) != 0) return fail("cannot read " + a_path);
  if (pcl::io::loadPCDFile(b_path, b) != 0) return fail("cannot read " + b_path);
  if (a.point_step != b.point_step || 2 * a.data.size() != b.data.size())
    return fail("different layouts, or not twice the points");
  const std::size_t n = a.data.size() / a.point_step;
  std::size_t differ = 0;
  for (std::size_t h = 0; h < 2; ++h)
    for (std::size_t i = 0; i < n; ++i)
      differ += std::memcmp(&a.data[i * a.point_step], &b.data[(h * n + i) * a.point_step], a.point_step) != 0;
  if (differ) return fail(std::to_string(differ) + " of " + std::to_string(2 * n) + " copies differ from the point alone");
  std::printf("%zu points, each copy as the point alone\n", n);
  return 0;
}

// Prints the sensor origin a .pcd stores (VIEWPOINT), "x y z".
int origin(const std::string& path) {
  pcl::PCLPointCloud2 blob;
  Eigen::Vector4f o;
  Eigen::Quaternionf q;
  if (pcl::io::loadPCDFile(path, blob, o, q) != 0) return fail("cannot read " + path);
  std::printf("%g %g %g\n", o.x(), o.y(), o.z());
  return 0;
}

// OUT made of new points from IN's (written by `write`, intensity = index): every new point
// carries the intensity of an input point within `reach` of it, and some input points are
// carried more than once (there are more new points than input points).
int sources(const std::string& in_path, const std::string& out_path, float reach) {
  pcl::PointCloud<pcl::PointXYZI> in, out;
  if (pcl::io::loadPCDFile(in_path, in) != 0 || pcl::io::loadPCDFile(out_path, out) != 0)
    return fail("cannot read " + in_path + " or " + out_path);
  if (out.size() <= in.size()) return fail("no more points out than in");
  for (std::size_t q = 0; q < out.size(); ++q) {
    const float k = out[q].intensity;
    if (!(k >= 0) || k != std::floor(k) || k >= static_cast<float>(in.size()))
      return fail("point " + std::to_string(q) + " carries intensity " + std::to_string(k) + ", no input point's");
    const auto& s = in[static_cast<std::size_t>(k)];
    if ((s.getVector3fMap() - out[q].getVector3fMap()).norm() > reach)
      return fail("point " + std::to_string(q) + " carries the intensity of a point " +
                  std::to_string((s.getVector3fMap() - out[q].getVector3fMap()).norm()) + " away");
  }
  return 0;
}

// Every point of OUT carries the normal and curvature the "stale-normals" input was written
// with (a run told to keep the input's normals).
int stale(const std::string& path) {
  pcl::PointCloud<pcl::PointXYZINormal> cloud;
  if (pcl::io::loadPCDFile(path, cloud) != 0 || cloud.empty()) return fail("cannot read " + path);
  for (std::size_t i = 0; i < cloud.size(); ++i)
    if (cloud[i].normal_x != 0.5f || cloud[i].normal_y != 0.f || cloud[i].normal_z != -0.8660254f ||
        cloud[i].curvature != 0.5f)
      return fail("point " + std::to_string(i) + " does not carry the input's normal and curvature");
  std::printf("%zu points carry the input's normal and curvature\n", cloud.size());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (mode == "write" && (argc == 4 || argc == 5)) return write(argv[2], std::atoi(argv[3]), argc == 5 ? argv[4] : "binary");
  if (mode == "check" && argc == 4) return check(argv[2], argv[3]);
  if (mode == "unhex" && argc == 4) return unhex(argv[2], argv[3]);
  if (mode == "permute" && argc == 4) return permute(argv[2], argv[3]);
  if (mode == "same-points" && argc == 4) return samePoints(argv[2], argv[3]);
  if (mode == "origin" && argc == 3) return origin(argv[2]);
  if (mode == "halves" && argc == 4) return halves(argv[2], argv[3]);
  if (mode == "normals" && (argc == 4 || argc == 5)) return normals(argv[2], std::atof(argv[3]), argc == 5 ? argv[4] : "");
  if (mode == "sources" && argc == 5) return sources(argv[2], argv[3], static_cast<float>(std::atof(argv[4])));
  if (mode == "stale" && argc == 3) return stale(argv[2]);
  if (mode == "keeps" && argc >= 4) return keeps(argv[2], argv[3], std::vector<std::string>(argv + 4, argv + argc));
  return fail("usage: paps_test_cloud_tool write OUT COUNT [binary|compressed|ascii] | check IN OUT");
}
