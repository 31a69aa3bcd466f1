// paps bench lpf: Local Probing Fields denoising against the height-field denoisers (ours by
// similarity, PCL MLS, the point bilateral filter) on the same noisy inputs, in one run: the
// manuscript's mixed surface-and-curves shape (Fig. 3.15, Table 3.1), scored separately on
// the surface and on the curves, and a block with sharp creases (Fig. 3.13). Each method
// runs in its own process (time, peak memory); the peers at their default and at the best
// of a small sweep of radius and passes.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include <paps/core/error.h>
#include <paps/core/metrics.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/synthetic.h>

#ifdef PAPS_HAVE_SURFACE
#include <paps/surface/lpf_resampling.h>
#endif

#include "bench_worker.h"
#include "cli_common.h"
#include "commands.h"
#include "render.h"

namespace paps::cli {

namespace {

const char* kUsage =
    "usage: paps bench lpf [options]\n"
    "  --out DIR        where the table (CSV) goes (default bench_out)\n"
    "  --points N       points of each test shape (default 50000)\n"
    "  --noise LIST     noise sigmas per axis as fractions of the bounding-box diagonal\n"
    "                   (default 0.0015,0.003,0.005)\n"
    "  --shapes LIST    plate-wires (a plate under a net of wires and a circle), fandisk\n"
    "                   (curved faces and creases), cube (flat faces, sharp edges and\n"
    "                   corners), tetrahedron (70.5-degree edges, acute corners), cylinder\n"
    "                   (a curved side meeting flat caps at circular edges), rs1 (points\n"
    "                   sampled on opencv-doc's range-scan mesh rs1_normals.ply: real\n"
    "                   geometry) (default plate-wires,fandisk)\n"
    "  --samples DIR    sample data for rs1 (default $PAPS_SAMPLES or ~/.cache/paps/samples)\n"
    "  --quick          one noise level, no sweeps (a smoke run)\n"
    "  --resample       instead: LPF resampling x4 against QSR, APSS, RIMLS and PCL MLS\n"
    "                   upsampling at the same output count, on the plate and wires\n"
    "                   (accuracy: outputs to the true shape; coverage: a dense sample of the\n"
    "                   true shape to the nearest output); lpf (the default: denoised first\n"
    "                   when the noise is at least 0.5 x the consensus radius), lpf-raw\n"
    "                   (never) and lpf-denoised (always) side by side\n"
    "  --denoise-passes N  with --resample: passes of LPF's first denoising (default 0: from\n"
    "                   the noise)\n";

struct Method {
  std::string name, setting;
  std::map<std::string, double> params;
  bool compared = true;  // false: printed, but not LPF's row nor a peer in the ratios
};

std::vector<Method> methods(float r, bool quick) {
  std::vector<Method> m;
  m.push_back({"lpf", "default", {}});
  // The manuscript's schedule: every point moves in every pass (no crease is held).
  if (!quick) m.push_back({"lpf", "every pass (bend 0)", {{"bend", 0}}, false});
  // The option for curved surfaces: each field's curvature kept out of the L1 penalty.
  if (!quick) m.push_back({"lpf", "free curvature", {{"free-curvature", 1}}, false});
  if (!quick) m.push_back({"lpf", "1 pass", {{"passes", 1}}, false});
  if (!quick) m.push_back({"lpf", "2 passes", {{"passes", 2}}, false});
  m.push_back({"ours", "similarity, default", {}});
  for (double f : quick ? std::vector<double>{1} : std::vector<double>{1, 2, 3})
    m.push_back({"mls", "radius x" + fmt("%g", f), {{"radius", r * f}, {"order", 2}, {"threads", 2}}});
  for (double f : quick ? std::vector<double>{1} : std::vector<double>{1, 2})
    for (double it : quick ? std::vector<double>{1} : std::vector<double>{1, 3})
      m.push_back({"bilateral", "radius x" + fmt("%g", f) + " passes " + fmt("%g", it), {{"radius", r * f}, {"iterations", it}}});
  return m;
}

}  // namespace

#ifdef PAPS_HAVE_SURFACE
namespace {
int runBenchLpfResample(const Arguments& a) {
  const std::string out_dir = a.text("out", "bench_out");
  const std::size_t n_points = a.count("points", 20000);
  const double passes = a.integer("denoise-passes", LpfResamplingParameters().denoise_passes);
  std::vector<double> noises;
  for (const std::string& s : splitList(a.text("noise", "0.0005,0.002"))) noises.push_back(std::atof(s.c_str()));
  std::filesystem::create_directories(out_dir);
  const auto clean = synthetic::plateAndWires(n_points, 3);
  const auto dense = synthetic::plateAndWires(8 * n_points, 9);
  const double diagonal = boundingBoxDiagonal(clean.points);
  std::printf("bench lpf --resample: plate and wires, %zu input points, x4; errors in thousandths of the diagonal;\n"
              "accuracy = RMS distance of the outputs to the true shape (plate: outputs below z = 0.15);\n"
              "coverage = RMS distance from %zu points on the true shape to the nearest output\n",
              n_points, dense.points.size());
  std::printf("%-6s %-14s %8s %8s %8s %9s %9s %9s %9s %9s\n", "noise", "method", "points", "time(s)", "peak MB",
              "acc.all", "acc.plate", "acc.wires", "cov.plate", "cov.wires");
  for (double noise : noises) {
    Positions in = clean.points;
    synthetic::addGaussianNoise(in, static_cast<float>(noise), 5);
    const SpatialIndex index(in);
    const float r = radiusForNeighbourCount(in, index, 30);
    writeRaw(out_dir + "/sr_in0.bin", in);
    std::size_t count = 0;
    double best_other = INFINITY, lpf_acc = 0;
    auto row = [&](const std::string& name, const Positions& out, double seconds, double mb) {
      double s[2] = {0, 0}, c[2] = {0, 0};
      std::size_t ns[2] = {0, 0}, nc[2] = {0, 0};
      for (const auto& p : out) {
        const double d = isFinite(p) ? synthetic::distanceToPlateAndWires(p) : 1e3 * diagonal;
        const int w = isFinite(p) && p.z() >= 0.15f;
        s[w] += d * d;
        ++ns[w];
      }
      if (!out.empty()) {
        const SpatialIndex oi(out);
        std::vector<int> k;
        std::vector<float> d2;
        for (std::size_t i = 0; i < dense.points.size(); ++i) {
          oi.nearestK(dense.points[i], 1, k, d2);
          c[dense.on_curve[i]] += d2.empty() ? diagonal * diagonal : d2[0];
          ++nc[dense.on_curve[i]];
        }
      }
      auto f = [&](double v, std::size_t n) { return n ? std::sqrt(v / n) / diagonal * 1e3 : NAN; };
      const double all = f(s[0] + s[1], ns[0] + ns[1]);
      std::printf("%-6s %-14s %8zu %8.2f %8.0f %9.3f %9.3f %9.3f %9.3f %9.3f\n", fmt("%.2f%%", noise * 100).c_str(),
                  name.c_str(), out.size(), seconds, mb, all, f(s[0], ns[0]), f(s[1], ns[1]), f(c[0], nc[0]), f(c[1], nc[1]));
      return all;
    };
    row("input", in, 0, 0);
    for (const std::string m : {"lpf", "lpf-raw", "lpf-denoised", "qsr", "apss", "rimls", "pcl-mls-plane"}) {
      const WorkerResult w = spawnWorker({"bench-worker-sr", m, out_dir, "1"},
                                         {{"count", static_cast<double>(count)}, {"factor", 4}, {"radius", 2 * r},
                                          {"passes", passes}},
                                         out_dir + "/sr_out.bin", out_dir + "/sr_log.txt");
      if (!w.ok) {
        std::printf("%-6s %-14s failed: %s\n", fmt("%.2f%%", noise * 100).c_str(), m.c_str(), w.message.c_str());
        if (m == "lpf") break;
        continue;
      }
      if (m == "lpf") count = w.output.size();  // the others make as many points
      const double acc = row(m == "pcl-mls-plane" ? "pcl-mls (2x r)" : m, w.output, w.seconds, w.peak_mb);
      if (m == "lpf") {
        lpf_acc = acc;
        if (!w.chosen.empty()) std::printf("%-6s %-14s (chosen: %s)\n", "", "", w.chosen.c_str());
      } else if (m.rfind("lpf-", 0) != 0) {
        best_other = std::min(best_other, acc);
      }
    }
    if (lpf_acc > 0 && std::isfinite(best_other))
      std::printf("  -> LPF accuracy / best other = %.3f\n", lpf_acc / best_other);
  }
  for (const char* scratch : {"sr_in0.bin", "sr_out.bin", "sr_log.txt"}) std::remove((out_dir + "/" + scratch).c_str());
  return 0;
}
}  // namespace
#endif

int runBenchLpf(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 3, {"quick", "help", "resample"});
  if (a.has("help")) { std::fputs(kUsage, stdout); return 0; }
  a.allowOnly({"out", "points", "noise", "shapes", "quick", "resample", "samples", "denoise-passes"});
  if (a.has("resample")) {
#ifdef PAPS_HAVE_SURFACE
    std::setvbuf(stdout, nullptr, _IOLBF, 0);
    return runBenchLpfResample(a);
#else
    throw InvalidParameter("resample", "given", "a build with the surface module");
#endif
  }
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  const std::string out_dir = a.text("out", "bench_out");
  const bool quick = a.has("quick");
  const std::size_t n_points = a.count("points", quick ? 20000 : 50000);
  std::vector<double> noises;
  for (const std::string& s : splitList(a.text("noise", quick ? "0.003" : "0.0015,0.003,0.005"))) {
    const double v = std::atof(s.c_str());
    if (!(v > 0 && v < 0.1)) throw InvalidParameter("noise", s, "fractions of the diagonal in (0, 0.1)");
    noises.push_back(v);
  }
  std::filesystem::create_directories(out_dir);
  std::ofstream csv(out_dir + "/lpf.csv");
  csv << "shape,noise,method,setting,ok,seconds,peak_mb,rmse_surface,rmse_curves,rmse_all\n";
  std::printf("bench lpf: %zu points per shape; noise sigma per axis as a fraction of the bounding-box diagonal;\n"
              "RMSE = distance to the true shape (surface / curves / all points), in units of the diagonal x 1e-3\n",
              n_points);
  for (const std::string& shape : splitList(a.text("shapes", "plate-wires,fandisk"))) {
    Positions clean;
    std::vector<std::uint8_t> on_curve;
    std::unique_ptr<PointToMeshDistance> mesh_distance;
    if (shape == "plate-wires") {
      auto s = synthetic::plateAndWires(n_points, 3);
      clean = std::move(s.points);
      on_curve = std::move(s.on_curve);
    } else if (shape == "fandisk" || shape == "cube" || shape == "tetrahedron" || shape == "cylinder" ||
               shape == "rs1") {
      // rs1: real geometry (opencv-doc's range-scan mesh, scripts/fetch_samples.sh), sampled
      // as the synthetic meshes are; the truth is the mesh, scan noise and all.
      const std::string rs1 = a.text("samples", samplesDir()) + "/rs1_normals.ply";
      if (shape == "rs1" && !std::filesystem::exists(rs1))
        throw InvalidInput(rs1 + " is missing: run scripts/fetch_samples.sh or give --samples DIR");
      const TriangleMesh mesh = shape == "cube"          ? synthetic::cube(0.5f, 16)
                                : shape == "tetrahedron" ? synthetic::tetrahedron(0.8f)
                                : shape == "cylinder"    ? synthetic::cappedCylinder(0.3f, 0.6f, 256)
                                : shape == "rs1"         ? loadTriangleMesh(rs1)
                                                         : synthetic::fandiskBlock(128);
      clean = synthetic::sampleMesh(mesh, n_points, 7);
      on_curve.assign(clean.size(), 0);
      mesh_distance = std::make_unique<PointToMeshDistance>(mesh);
    } else {
      throw InvalidParameter("shapes", shape, "plate-wires, fandisk, cube, tetrahedron, cylinder or rs1");
    }
    const double diagonal = boundingBoxDiagonal(clean);
    const bool has_curves = std::count(on_curve.begin(), on_curve.end(), 1) > 0;
    auto score = [&](const Positions& p, double out[3]) {
      std::vector<double> d = mesh_distance ? mesh_distance->distances(p) : std::vector<double>(p.size());
      if (!mesh_distance)
        for (std::size_t i = 0; i < p.size(); ++i) d[i] = synthetic::distanceToPlateAndWires(p[i]);
      double s[2] = {0, 0};
      std::size_t c[2] = {0, 0};
      for (std::size_t i = 0; i < p.size(); ++i) {
        const double v = std::isfinite(d[i]) ? d[i] : 1e3 * diagonal;  // a lost point counts, hugely
        // Surface or curves by where the output point is (the plate is at z = 0, the wires at
        // 0.3 and above), not by its index: PCL's MLS with two threads does not keep the
        // input order (its rows changed from run to run when split by index).
        const int k = has_curves ? (isFinite(p[i]) && p[i].z() >= 0.15f) : 0;
        s[k] += v * v;
        ++c[k];
      }
      out[0] = c[0] ? std::sqrt(s[0] / c[0]) / diagonal * 1e3 : NAN;
      out[1] = c[1] ? std::sqrt(s[1] / c[1]) / diagonal * 1e3 : NAN;
      out[2] = std::sqrt((s[0] + s[1]) / (c[0] + c[1])) / diagonal * 1e3;
    };
    std::printf("\n%-12s %-6s %-10s %-24s %8s %8s %9s %9s %9s\n", "shape", "noise", "method", "setting", "time(s)",
                "peak MB", "surface", "curves", "all");
    for (double noise : noises) {
      Positions noisy = clean;
      synthetic::addGaussianNoise(noisy, static_cast<float>(noise), 11);
      const SpatialIndex index(noisy);
      const float r = radiusForNeighbourCount(noisy, index, 30);
      const std::string noise_s = fmt("%.2f%%", noise * 100);
      double e[3];
      score(noisy, e);
      std::printf("%-12s %-6s %-10s %-24s %8s %8s %9.3f %9.3f %9.3f\n", shape.c_str(), noise_s.c_str(), "input", "noisy",
                  "-", "-", e[0], e[1], e[2]);
      std::map<std::string, std::array<double, 3>> best;  // per method: the best "all" row
      std::map<std::string, double> seconds;
      std::map<std::string, Positions> best_output;
      for (const Method& m : methods(r, quick)) {
        const WorkerResult w = runWorker(out_dir, m.name, noisy, m.params);
        if (!w.ok) {
          std::printf("%-12s %-6s %-10s %-24s failed: %s\n", shape.c_str(), noise_s.c_str(), m.name.c_str(),
                      m.setting.c_str(), w.message.c_str());
          continue;
        }
        score(w.output, e);
        std::printf("%-12s %-6s %-10s %-24s %8.2f %8.0f %9.3f %9.3f %9.3f\n", shape.c_str(), noise_s.c_str(),
                    m.name.c_str(), m.setting.c_str(), w.seconds, w.peak_mb, e[0], e[1], e[2]);
        if (m.name == "lpf" && m.setting == "default" && !w.chosen.empty())
          std::printf("%-12s %-6s %-10s (chosen: %s)\n", "", "", "", w.chosen.c_str());
        csv << shape << "," << noise << "," << m.name << ",\"" << m.setting << "\",1," << w.seconds << "," << w.peak_mb
            << "," << e[0] << "," << e[1] << "," << e[2] << "\n";
        if (!m.compared) continue;
        auto it = best.find(m.name);
        if (it == best.end() || e[2] < it->second[2]) {
          best[m.name] = {e[0], e[1], e[2]};
          seconds[m.name] = w.seconds;
          if (has_curves && noise == noises.front()) best_output[m.name] = w.output;
        }
      }
      if (!best.count("lpf")) continue;
      const auto& lpf = best["lpf"];
      std::string peer_name;
      for (const auto& [name, v] : best)
        if (name != "lpf" && (peer_name.empty() || v[2] < best[peer_name][2])) peer_name = name;
      if (peer_name.empty()) continue;
      const auto& peer = best[peer_name];
      std::printf("  -> LPF / best other (%s, best setting): all %.3f", peer_name.c_str(), lpf[2] / peer[2]);
      if (has_curves) {
        double best_curves = INFINITY;
        for (const auto& [name, v] : best)
          if (name != "lpf") best_curves = std::min(best_curves, v[1]);
        std::printf(", surface %.3f, curves %.3f (against the best other on curves)", lpf[0] / peer[0], lpf[1] / best_curves);
      }
      std::printf("; time LPF / that method %.1f\n", seconds["lpf"] / seconds[peer_name]);
      if (has_curves && noise == noises.front()) {
        // The wire x = -0.6, z = 0.3 seen end-on (along y, all of it but its ends and the
        // crossings): its
        // points' spread across it, 5 cm square; coloured by the distance to the true wire
        // (red: 3 sigma).
        View view;
        view.axes << 1, 0, 0, 0, 0, 1, 0, 1, 0;
        view.lo = Eigen::Vector2f(-0.625f, 0.275f);
        view.hi = Eigen::Vector2f(-0.575f, 0.325f);
        auto slab = [](const Positions& pts) {
          Positions out;
          for (const auto& q : pts)
            if (isFinite(q) && std::abs(q.y()) < 0.95f && std::abs(std::abs(q.y()) - 0.2f) > 0.03f &&
                std::abs(std::abs(q.y()) - 0.6f) > 0.03f)
              out.push_back(q);  // the crossing wires (y = +-0.2, +-0.6) left out: they would hide the dot
          return out;
        };
        const double vmax = 3 * noise * diagonal;
        auto draw = [&](const Positions& pts, const std::string& name) {
          const Positions cut = slab(pts);
          std::vector<double> d(cut.size());
          for (std::size_t i = 0; i < cut.size(); ++i) d[i] = synthetic::distanceToPlateAndWires(cut[i]);
          renderValues(cut, d, vmax, view, 400, out_dir + "/lpf_wire_" + name + ".png");
        };
        draw(noisy, "input");
        draw(best_output["lpf"], "lpf");
        draw(best_output[peer_name], "best_other_" + peer_name);
        std::printf("  wrote %s/lpf_wire_{input,lpf,best_other_%s}.png (the wire x = -0.6 seen end-on)\n", out_dir.c_str(),
                    peer_name.c_str());
      }
    }
  }
  for (const char* scratch : {"worker_in.bin", "worker_out.bin", "worker_log.txt"})
    std::remove((out_dir + "/" + scratch).c_str());
  std::printf("\nwrote %s/lpf.csv\n", out_dir.c_str());
  return 0;
}

}  // namespace paps::cli
