// paps bench compress: our codec at several rates against Draco (-point_cloud) and PCL's
// octree coder, on the same inputs in one run; rate-distortion tables, CSV and PNG plots.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <sstream>

#include <pcl/compression/octree_pointcloud_compression.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/io/png_io.h>
#include <pcl/point_types.h>

#include <paps/compression/rate_distortion.h>
#include <paps/compression/self_similarity_codec.h>
#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/metrics.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/synthetic.h>
#include <paps/core/triangle_mesh.h>

#include "cli_common.h"
#include "commands.h"
#include "render.h"

namespace paps::cli {
namespace {

const char* kBenchCompressUsage =
    "usage: paps bench compress [options]\n"
    "  --mesh PATH        true surface to sample (default $PAPS_SAMPLES/rs1_normals.ply)\n"
    "  --scan PATH        real scan (default $PAPS_SAMPLES/table_scene_lms400.pcd; 'none' to skip)\n"
    "  --points N         points sampled from the mesh (default 1000000)\n"
    "  --noise F          scanner-like Gaussian noise, sigma = F x the sampling spacing (default 0.3)\n"
    "  --out DIR          CSV and PNG plots (default bench_compress)\n"
    "  --draco-bits LIST  Draco position quantization bits (default 8,9,10,11,12,14,16)\n"
    "  --ours LIST        our rates: patch points per patch, each optionally xS for a seed spacing of\n"
    "                     S x R and/or bN for N_bins N, e.g. 256x1b12\n"
    "                     (default 40b10,48,64,100,160,256,400,700,1000,1300,1600,2400,100b12,160b12,256b12)\n"
    "  --seed-spacing S   seed spacing of the rates without xS, as a fraction of R (default 1.25)\n"
    "  --save-inputs DIR  write the inputs (DIR/rs1-clean.pcd, ...) as binary PCD and stop; for timing\n"
    "                     and measuring the memory of 'paps compress' on the same clouds\n";

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct Result {
  std::string codec, setting;
  std::size_t bytes = 0, out_points = 0;
  double bpp = 0, enc_s = 0, dec_s = 0;
  compression::CloudErrors e;
  double to_surface = NAN, from_surface = NAN;  // RMSE, metres
};

struct Dataset {
  std::string name;
  Positions points;
  const TriangleMesh* mesh = nullptr;  // true surface, when known
  Positions surface_samples;           // dense samples of the true surface
  double spacing = 0;
  std::shared_ptr<compression::PreparedReference> reference;  // index and normals, built once
};

std::vector<int> parseList(const std::string& s) {
  std::vector<int> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) v.push_back(std::stoi(item));
  return v;
}

int run(const std::string& cmd) { return std::system((cmd + " > /dev/null 2>&1").c_str()); }

void writePly(const std::string& path, const Positions& p) {
  pcl::PointCloud<pcl::PointXYZ> c;
  writePositions(p, c);
  if (pcl::io::savePLYFileBinary(path, c) != 0) throw IoError("cannot write " + path);
}

double nearestRmse(const Positions& from, const SpatialIndex& to_index, const Positions& to) {
  double s = 0;
  const long n = long(from.size());
#pragma omp parallel
  {
    std::vector<int> nb;
    std::vector<float> d2;
#pragma omp for reduction(+ : s)
    for (long i = 0; i < n; ++i) {
      to_index.nearestK(from[i], 1, nb, d2);
      s += d2[0];
    }
  }
  (void)to;
  return std::sqrt(s / double(std::max<long>(1, n)));
}

void measure(const Dataset& d, const Positions& decoded, Result& r, const PointToMeshDistance* truth) {
  r.out_points = decoded.size();
  r.bpp = r.bytes * 8.0 / double(d.points.size());
  r.e = d.reference->compare(decoded, d.spacing);
  if (truth) {
    r.to_surface = pointToMeshError(decoded, *truth).rmse;
    SpatialIndex di(decoded);
    r.from_surface = nearestRmse(d.surface_samples, di, decoded);
  }
  std::printf("  %-6s %-22s %9zu B %7.3f bpp  D1 %.3e (%.2f dB)  D2 %.3e (%.2f dB)  >spacing %5.2f%%", r.codec.c_str(),
              r.setting.c_str(), r.bytes, r.bpp, r.e.d1_rmse, r.e.d1_psnr, r.e.d2_rmse, r.e.d2_psnr,
              100 * r.e.share_above_tolerance);
  if (truth) std::printf("  surf %.3e / %.3e", r.to_surface, r.from_surface);
  std::printf("  enc %.2fs dec %.2fs  %zu pts\n", r.enc_s, r.dec_s, r.out_points);
  std::fflush(stdout);
}

// A tiny line plot: log2(bpp) on x, a distortion on y; one colour per codec. No text: the
// axes ranges are printed beside the PNG's name.
void plot(const std::vector<Result>& rs, const std::function<double(const Result&)>& y, bool log_y,
          const std::string& png, const std::string& what) {
  const int W = 800, H = 560, M = 50;
  std::vector<std::uint8_t> img(std::size_t(W) * H * 3, 255);
  auto fy = [&](double v) { return log_y ? std::log10(v) : v; };
  double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
  for (const auto& r : rs) {
    const double v = y(r);
    if (!(v > 0) || !std::isfinite(v) || !(r.bpp > 0)) continue;
    x0 = std::min(x0, std::log2(r.bpp)); x1 = std::max(x1, std::log2(r.bpp));
    y0 = std::min(y0, fy(v)); y1 = std::max(y1, fy(v));
  }
  if (!(x1 > x0)) { x0 -= 1; x1 += 1; }
  if (!(y1 > y0)) { y0 -= 1; y1 += 1; }
  auto px = [&](double x) { return M + int((x - x0) / (x1 - x0) * (W - 2 * M)); };
  auto py = [&](double v) { return H - M - int((fy(v) - y0) / (y1 - y0) * (H - 2 * M)); };
  auto dot = [&](int x, int yy, const std::array<std::uint8_t, 3>& c, int rad) {
    for (int dy = -rad; dy <= rad; ++dy)
      for (int dx = -rad; dx <= rad; ++dx) {
        const int X = x + dx, Y = yy + dy;
        if (X >= 0 && X < W && Y >= 0 && Y < H) std::copy(c.begin(), c.end(), img.begin() + (std::size_t(Y) * W + X) * 3);
      }
  };
  auto line = [&](int xa, int ya, int xb, int yb, const std::array<std::uint8_t, 3>& c, int rad) {
    const int n = std::max({std::abs(xb - xa), std::abs(yb - ya), 1});
    for (int t = 0; t <= n; ++t) dot(xa + (xb - xa) * t / n, ya + (yb - ya) * t / n, c, rad);
  };
  const std::array<std::uint8_t, 3> grey{200, 200, 200}, black{0, 0, 0};
  for (int bits = int(std::ceil(x0)); bits <= int(std::floor(x1)); ++bits) line(px(bits), M, px(bits), H - M, grey, 0);
  line(M, H - M, W - M, H - M, black, 0);
  line(M, M, M, H - M, black, 0);
  const std::map<std::string, std::array<std::uint8_t, 3>> colours{
      {"ours", {220, 40, 40}}, {"draco", {40, 80, 220}}, {"pcl", {30, 160, 60}}};
  for (const auto& [codec, c] : colours) {
    std::vector<const Result*> pts;
    for (const auto& r : rs)
      if (r.codec == codec && y(r) > 0 && std::isfinite(y(r))) pts.push_back(&r);
    std::sort(pts.begin(), pts.end(), [](auto a, auto b) { return a->bpp < b->bpp; });
    for (std::size_t i = 0; i < pts.size(); ++i) {
      dot(px(std::log2(pts[i]->bpp)), py(y(*pts[i])), c, 4);
      if (i) line(px(std::log2(pts[i - 1]->bpp)), py(y(*pts[i - 1])), px(std::log2(pts[i]->bpp)), py(y(*pts[i])), c, 1);
    }
  }
  pcl::io::saveRgbPNGFile(png, img.data(), W, H);
  std::printf("  plot %s: x = log2(bits per input point) in [%.2f, %.2f] (grid every bit), y = %s%s in [%.4g, %.4g]; "
              "red ours, blue Draco, green PCL octree\n",
              png.c_str(), x0, x1, log_y ? "log10 " : "", what.c_str(), y0, y1);
}

// bpp a codec needs to reach distortion <= `target`: log-log interpolation between the points
// of its Pareto front sorted by distortion, or the rate of any point at or below the target
// when that is lower; NaN when no point reaches the target.
double bppAt(const std::vector<Result>& rs, const std::string& codec, const std::function<double(const Result&)>& y,
             double target) {
  std::vector<std::pair<double, double>> c;
  for (const auto& r : rs)
    if (r.codec == codec && y(r) > 0 && std::isfinite(y(r))) c.push_back({y(r), r.bpp});
  std::sort(c.begin(), c.end());
  // Pareto front: drop every point that another beats on both rate and error, so that a
  // dominated setting cannot bend the interpolation.
  {
    std::vector<std::pair<double, double>> front;
    for (const auto& p : c)
      if (front.empty() || p.second < front.back().second) front.push_back(p);
    c.swap(front);
  }
  double best = NAN;
  for (std::size_t i = 1; i < c.size(); ++i) {
    const double a = c[i - 1].first, b = c[i].first;
    if (target < a || target > b || !(b > a)) continue;
    const double t = (std::log(target) - std::log(a)) / (std::log(b) - std::log(a));
    const double v = std::exp(std::log(c[i - 1].second) * (1 - t) + std::log(c[i].second) * t);
    best = std::isnan(best) ? v : std::min(best, v);
  }
  // A point of the curve with a lower error at a lower rate also reaches the target: the
  // rate needed for "error <= target" is at most its rate (the curve's lower envelope).
  for (const auto& p : c)
    if (p.first <= target) best = std::isnan(best) ? p.second : std::min(best, p.second);
  return best;
}

void compareAtEqualError(const std::vector<Result>& rs, const std::function<double(const Result&)>& y,
                         double spacing, const std::string& what) {
  std::printf("  at equal %s (bpp; ratio = ours / best peer):\n", what.c_str());
  for (int i = 0; i <= 6; ++i) {
    const double target = spacing * std::pow(10.0, -i / 6.0);
    const double o = bppAt(rs, "ours", y, target), d = bppAt(rs, "draco", y, target), p = bppAt(rs, "pcl", y, target);
    const double peer = std::isnan(d) ? p : (std::isnan(p) ? d : std::min(d, p));
    std::printf("    %s = %.3e (%.2f x spacing): ours %7.3f  draco %7.3f  pcl %7.3f  ratio %s\n", what.c_str(), target,
                target / spacing, o, d, p,
                std::isnan(o) || std::isnan(peer) ? "n/a (outside a curve)" : std::to_string(o / peer).c_str());
  }
}

}  // namespace

int runBenchCompress(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 3, {"help"});
  if (a.has("help")) { std::fputs(kBenchCompressUsage, stdout); return 0; }
  a.allowOnly({"mesh", "scan", "points", "noise", "out", "draco-bits", "ours", "seed-spacing", "save-inputs"});
  // Same sample cache as the other benches (scripts/fetch_samples.sh).
  const std::string data = samplesDir();
  const std::string mesh_path = a.text("mesh", data + "/rs1_normals.ply");
  const std::string scan_path = a.text("scan", data + "/table_scene_lms400.pcd");
  const long n = long(a.count("points", 1000000));
  requireInRange("points", n, 1000L, 100000000L);
  const double noise = a.number("noise", 0.3);
  const std::string out = a.text("out", "bench_compress");
  const std::vector<int> draco_bits = parseList(a.text("draco-bits", "8,9,10,11,12,14,16"));
  // Our rates: "PP", "PPxS" (seed spacing S x R) and/or "PPbN" (N_bins N), e.g. 256x1b12.
  struct OurRate {
    int patch_points;
    float seed_spacing;
    int bins;  // 0: the preset's
  };
  std::vector<OurRate> ours;
  {
    const float default_spacing = a.real("seed-spacing", 1.25);
    requireInRange("seed-spacing", default_spacing, 0.25f, 2.f);
    std::stringstream ss(a.text("ours", "40b10,48,64,100,160,256,400,700,1000,1300,1600,2400,100b12,160b12,256b12"));
    std::string item;
    while (std::getline(ss, item, ','))
      if (!item.empty()) {
        OurRate r{0, default_spacing, 0};
        std::size_t used = 0;
        try {
          r.patch_points = std::stoi(item, &used);
          while (used < item.size()) {
            const char tag = item[used];
            std::size_t more = 0;
            if (tag == 'x') r.seed_spacing = std::stof(item.substr(used + 1), &more);
            else if (tag == 'b') r.bins = std::stoi(item.substr(used + 1), &more);
            else throw std::invalid_argument(item);
            used += 1 + more;
          }
        } catch (const std::logic_error&) {
          throw InvalidParameter("ours", item, "PP, PPxS or PPbN (patch points, seed spacing, N_bins)");
        }
        ours.push_back(r);
      }
  }
  std::filesystem::create_directories(out);
  const std::string tmp = out + "/tmp";
  std::filesystem::create_directories(tmp);
  const bool have_draco = run("draco_encoder -h") != 127 && run("which draco_encoder") == 0;

  const TriangleMesh mesh = loadTriangleMesh(mesh_path);
  const PointToMeshDistance truth(mesh);
  std::vector<Dataset> sets;
  {
    Dataset clean;
    clean.name = "rs1-clean";
    clean.points = synthetic::sampleMesh(mesh, std::size_t(n), 1);
    clean.mesh = &mesh;
    clean.spacing = std::sqrt(mesh.area() / double(n));
    clean.surface_samples = synthetic::sampleMesh(mesh, std::size_t(std::min<long>(n, 300000)), 2);
    Dataset noisy = clean;
    noisy.name = "rs1-noisy";
    const float frac = float(noise * clean.spacing / boundingBoxDiagonal(clean.points));
    synthetic::addGaussianNoise(noisy.points, frac, 3);
    sets.push_back(std::move(clean));
    sets.push_back(std::move(noisy));
  }
  if (scan_path != "none") {
    Dataset scan;
    scan.name = "table-scan";
    for (const auto& p : loadPositions(scan_path))
      if (isFinite(p)) scan.points.push_back(p);
    // Spacing: the RMS nearest-neighbour distance.
    SpatialIndex si(scan.points);
    std::vector<int> nb;
    std::vector<float> d2;
    double s = 0;
    for (std::size_t i = 0; i < scan.points.size(); i += 97) { si.nearestK(scan.points[i], 2, nb, d2); s += d2[1]; }
    scan.spacing = std::sqrt(s / double((scan.points.size() + 96) / 97));
    sets.push_back(std::move(scan));
  }

  if (a.has("save-inputs")) {
    const std::string dir = a.text("save-inputs", ".");
    std::filesystem::create_directories(dir);
    for (const Dataset& d : sets) {
      pcl::PointCloud<pcl::PointXYZ> c;
      writePositions(d.points, c);
      const std::string path = dir + "/" + d.name + ".pcd";
      if (pcl::io::savePCDFileBinary(path, c) != 0) throw IoError("cannot write " + path);
      std::printf("wrote %s: %zu points, spacing %.4g\n", path.c_str(), d.points.size(), d.spacing);
    }
    std::filesystem::remove_all(tmp);
    return 0;
  }
  std::ofstream csv(out + "/rate_distortion.csv");
  csv << "dataset,codec,setting,input_points,bytes,bpp,d1_rmse,d1_psnr,d2_rmse,d2_psnr,share_above_spacing,"
         "to_surface_rmse,from_surface_rmse,encode_s,decode_s,output_points\n";
  for (Dataset& d : sets) {
    d.reference = std::make_shared<compression::PreparedReference>(d.points);
    const bool clean = d.name == "rs1-clean";
    const PointToMeshDistance* t = d.mesh ? &truth : nullptr;
    std::printf("%s: %zu points, spacing %.4g, bounding-box diagonal %.4g%s\n", d.name.c_str(), d.points.size(),
                d.spacing, boundingBoxDiagonal(d.points), d.mesh ? ", true surface known" : "");
    if (t) std::printf("  input to true surface RMSE %.3e\n", pointToMeshError(d.points, truth).rmse);
    std::vector<Result> rs;
    Positions ours_mid;
    for (const auto& [pp, seed_spacing, bins] : ours) {
      Result r;
      r.codec = "ours";
      compression::CompressionParameters p = pp >= 400 ? compression::compressionPreset("compact")
                                            : pp <= 160 ? compression::compressionPreset("fine")
                                                        : compression::compressionPreset("balanced");
      p.patch_points = pp;
      // Seeds 1.25 R apart by default (not R, the manuscript's choice): the patches overlap
      // less, for the same seed count the pattern is finer; on both inputs 30% fewer bytes for
      // 3-7% more D2 (table scan at 256: 69.4 KB, D2 1.114e-3 m against 99.7 KB, 1.075e-3 m).
      p.seed_spacing = seed_spacing;
      if (pp < 100) p.bins = 12;  // a pattern finer than the points only costs mask bits
      if (bins > 0) p.bins = bins;
      // 12-bit seeds (the presets compact and fine use them; balanced keeps the manuscript's
      // 16): 10% fewer bytes at patch_points=256 for 1% more D2 error. From 400 points per
      // patch (R >= 11 spacings), 10-bit seeds and 6-bit frame angles: both sides use the
      // quantized seeds, so a coarser grid only moves the patch origins (table scan at 700:
      // 13% fewer bytes, 1.5% more D2).
      p.seed_bits = pp >= 400 ? 10 : 12;
      if (pp >= 400) p.angle_bits = 6;
      // From 1200 points per patch, 8 atoms: the dictionary is a fixed cost (16 atoms: 3.4 KB,
      // a third of the stream at 2400 on the scan) and these rows have 1-2 non-zeros a patch.
      if (pp >= 1200) p.atoms = 8;
      r.setting = "patch_points=" + std::to_string(pp);
      if (seed_spacing != 1.25f) {
        char buf[32];
        std::snprintf(buf, sizeof buf, " seeds %.3gR", seed_spacing);
        r.setting += buf;
      }
      if (bins > 0) r.setting += " N_bins " + std::to_string(bins);
      auto t0 = Clock::now();
      const auto bytes = compression::compressPositions(d.points, p);
      r.enc_s = since(t0);
      t0 = Clock::now();
      const Positions dec = compression::decompressPositions(bytes.data(), bytes.size());
      r.dec_s = since(t0);
      r.bytes = bytes.size();
      measure(d, dec, r, t);
      if (pp == 256) ours_mid = dec;
      rs.push_back(r);
    }
    if (have_draco) {
      const std::string in_ply = tmp + "/in.ply";
      writePly(in_ply, d.points);
      for (const int q : draco_bits) {
        Result r;
        r.codec = "draco";
        r.setting = "qp=" + std::to_string(q) + " cl=10";
        const std::string drc = tmp + "/out.drc", dec_ply = tmp + "/dec.ply";
        auto t0 = Clock::now();
        if (run("draco_encoder -point_cloud -i " + in_ply + " -o " + drc + " -qp " + std::to_string(q) + " -cl 10") != 0)
          throw IoError("draco_encoder failed");
        r.enc_s = since(t0);
        t0 = Clock::now();
        if (run("draco_decoder -i " + drc + " -o " + dec_ply) != 0) throw IoError("draco_decoder failed");
        r.dec_s = since(t0);
        r.bytes = std::filesystem::file_size(drc);
        measure(d, loadPositions(dec_ply), r, t);
        rs.push_back(r);
      }
    } else {
      std::printf("  draco_encoder not found: Draco skipped\n");
    }
    {
      pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
      writePositions(d.points, *cloud);
      struct Config { std::string name; pcl::io::compression_Profiles_e profile; double point_res, octree_res; };
      std::vector<Config> configs{{"LOW_RES_OFFLINE", pcl::io::LOW_RES_OFFLINE_COMPRESSION_WITHOUT_COLOR, 0, 0},
                                  {"MED_RES_OFFLINE", pcl::io::MED_RES_OFFLINE_COMPRESSION_WITHOUT_COLOR, 0, 0},
                                  {"HIGH_RES_OFFLINE", pcl::io::HIGH_RES_OFFLINE_COMPRESSION_WITHOUT_COLOR, 0, 0}};
      for (const double f : {8.0, 4.0, 2.0, 1.0, 0.5, 0.25}) {
        char name[64];
        std::snprintf(name, sizeof name, "manual res=%.2gxspacing", f);
        configs.push_back({name, pcl::io::MANUAL_CONFIGURATION, f * d.spacing, f * d.spacing});
      }
      for (const auto& c : configs) {
        Result r;
        r.codec = "pcl";
        r.setting = c.name;
        pcl::io::OctreePointCloudCompression<pcl::PointXYZ> enc(c.profile, false, c.point_res > 0 ? c.point_res : 0.001,
                                                               c.octree_res > 0 ? c.octree_res : 0.01, false, 0, false);
        std::stringstream ss;
        auto t0 = Clock::now();
        enc.encodePointCloud(cloud, ss);
        r.enc_s = since(t0);
        r.bytes = ss.str().size();
        pcl::io::OctreePointCloudCompression<pcl::PointXYZ> dec;
        pcl::PointCloud<pcl::PointXYZ>::Ptr decoded(new pcl::PointCloud<pcl::PointXYZ>);
        t0 = Clock::now();
        dec.decodePointCloud(ss, decoded);
        r.dec_s = since(t0);
        if (decoded->size() < 3) { std::printf("  pcl %s: decoded %zu points, skipped\n", c.name.c_str(), decoded->size()); continue; }
        measure(d, positionsOf(*decoded), r, t);
        rs.push_back(r);
      }
    }
    for (const auto& r : rs)
      csv << d.name << ',' << r.codec << ",\"" << r.setting << "\"," << d.points.size() << ',' << r.bytes << ',' << r.bpp
          << ',' << r.e.d1_rmse << ',' << r.e.d1_psnr << ',' << r.e.d2_rmse << ',' << r.e.d2_psnr << ','
          << r.e.share_above_tolerance << ',' << r.to_surface << ',' << r.from_surface << ',' << r.enc_s << ','
          << r.dec_s << ',' << r.out_points << '\n';
    const std::string base = out + "/" + d.name;
    auto d1 = [](const Result& r) { return r.e.d1_rmse; };
    auto d2 = [](const Result& r) { return r.e.d2_rmse; };
    auto d1p = [](const Result& r) { return r.e.d1_psnr; };
    auto d2p = [](const Result& r) { return r.e.d2_psnr; };
    plot(rs, d1p, false, base + "_d1_psnr.png", "D1 PSNR (dB)");
    plot(rs, d2p, false, base + "_d2_psnr.png", "D2 PSNR (dB)");
    compareAtEqualError(rs, d2, d.spacing, "D2 RMSE");
    compareAtEqualError(rs, d1, d.spacing, "D1 RMSE");
    if (clean) {
      // Decoded -> true surface. (True surface -> decoded is printed per row: it has a floor of
      // about half the spacing for every codec, sampling alone, so it cannot rank them.)
      auto surf = [](const Result& r) { return r.to_surface; };
      plot(rs, surf, true, base + "_surface.png", "decoded->true surface RMSE");
      compareAtEqualError(rs, surf, d.spacing, "distance to the true surface");
    }
    if (!ours_mid.empty()) {
      const View view = View::fit(d.points, 20.f);
      renderShaded(d.points, view, 800, base + "_before.png");
      renderShaded(ours_mid, view, 800, base + "_after_ours256.png");
    }
    d.reference.reset();
  }
  std::filesystem::remove_all(tmp);
  std::printf("wrote %s/rate_distortion.csv and the PNGs\n", out.c_str());
  return 0;
}

}  // namespace paps::cli
