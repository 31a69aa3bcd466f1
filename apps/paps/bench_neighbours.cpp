// paps bench neighbours: the library's k-d tree (paps::SpatialIndex) against pcl::KdTreeFLANN,
// the tree it replaced, on the same points and queries in one run: time a query, build time,
// and whether every list is the same (ids, order and distances).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <cstring>

#include <omp.h>
#include <pcl/features/normal_3d_omp.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <paps/core/error.h>
#include <paps/core/kd_tree_search.h>
#include <paps/core/neighbourhood.h>
#include <paps/core/random.h>
#include <paps/core/spatial_order.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

namespace {

const char* kUsage =
    "usage: paps bench neighbours [--points N] [--k K]\n"
    "  N points of a noisy wavy sheet on a unit square, in spatial order (default 2000000);\n"
    "  every point queried once, on one thread, by paps::SpatialIndex and by pcl::KdTreeFLANN:\n"
    "  its K nearest (default 12), then a small and a large radius ball (mean counts printed).\n"
    "  Then a PCL stage, pcl::NormalEstimationOMP on every thread (30 nearest, then the small\n"
    "  radius), with pcl::search::KdTree and with paps::KdTreeSearch: time and normals that differ.\n";

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

int runBenchNeighbours(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 3, {"help"});
  if (a.has("help")) { std::fputs(kUsage, stdout); return 0; }
  a.allowOnly({"points", "k", "help"});
  const int n = a.integer("points", 2000000);
  const int k = a.integer("k", 12);
  requireInRange("points", n, 1000, 100000000);
  requireInRange("k", k, 1, 1000);
  Random rng(3);
  Positions p;
  p.reserve(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const double x = rng.uniform();
    const double y = rng.uniform();
    const double z = 0.05 * std::sin(10 * x) + 0.002 * rng.gaussian();
    p.emplace_back(x, y, z);
  }
  p = gathered(p, spatialOrder(p));
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const auto& q : p) cloud->push_back(pcl::PointXYZ(q.x(), q.y(), q.z()));
  // Queries on one thread: the per-query cost, not the scaling.
  const int saved_threads = omp_get_max_threads();
  omp_set_num_threads(1);
  auto t0 = Clock::now();
  const SpatialIndex ours(p);
  const double build_ours = since(t0);
  t0 = Clock::now();
  pcl::KdTreeFLANN<pcl::PointXYZ> theirs(/*sorted=*/true);
  theirs.setInputCloud(cloud);
  const double build_theirs = since(t0);
  std::printf("%d points of a noisy wavy sheet in spatial order; one thread; build: paps::SpatialIndex %.3f s, "
              "pcl::KdTreeFLANN %.3f s\n", n, build_ours, build_theirs);
  std::printf("%-28s %-22s %12s %12s %10s %14s\n", "query", "method", "us/query", "mean count", "ratio", "lists differ");
  // Radii of discs of about 30 and 550 points on the sheet (area about 1); the noise spreads
  // the points off it, so the balls hold fewer (their mean count is printed).
  const float r_small = static_cast<float>(std::sqrt(30.0 / (M_PI * n)));
  const float r_large = static_cast<float>(std::sqrt(550.0 / (M_PI * n)));
  const int stride_radius = std::max(1, n / 500000);  // the large balls on a sample of the points
  struct Query { std::string name; float radius; int stride; };
  const std::vector<Query> queries = {{std::to_string(k) + "-nearest", 0.f, 1},
                                      {"radius, small", r_small, 1},
                                      {"radius, large", r_large, stride_radius}};
  for (const Query& q : queries) {
    std::vector<int> io, it_int;
    pcl::Indices it;
    std::vector<float> dout, dthe;
    std::size_t differ = 0, total = 0, asked = 0;
    double t_ours = 0, t_theirs = 0;
    // Alternated in chunks of the points, so that a change of machine load hits both alike.
    const int chunk = 20000;
    for (int start = 0; start < n; start += chunk) {
      const int end = std::min(n, start + chunk);
      auto c0 = Clock::now();
      std::vector<std::vector<int>> got;
      std::vector<std::vector<float>> got_d;
      for (int i = start; i < end; i += q.stride) {
        if (q.radius > 0) ours.radiusSearch(p[i], q.radius, io, dout);
        else ours.nearestK(p[i], k, io, dout);
        got.push_back(io);
        got_d.push_back(dout);
      }
      t_ours += since(c0);
      c0 = Clock::now();
      std::vector<pcl::Indices> want;
      std::vector<std::vector<float>> want_d;
      for (int i = start; i < end; i += q.stride) {
        if (q.radius > 0) theirs.radiusSearch((*cloud)[i], q.radius, it, dthe);
        else theirs.nearestKSearch((*cloud)[i], k, it, dthe);
        want.push_back(it);
        want_d.push_back(dthe);
      }
      t_theirs += since(c0);
      for (std::size_t j = 0; j < got.size(); ++j) {
        it_int.assign(want[j].begin(), want[j].end());
        differ += got[j] != it_int || got_d[j] != want_d[j];
        total += got[j].size();
        ++asked;
      }
    }
    const double us_ours = 1e6 * t_ours / asked, us_theirs = 1e6 * t_theirs / asked;
    std::printf("%-28s %-22s %12.3f %12.1f %10s %14zu\n", q.name.c_str(), "paps::SpatialIndex", us_ours,
                double(total) / asked, "", differ);
    std::printf("%-28s %-22s %12.3f %12.1f %10.2f %14s\n", "", "pcl::KdTreeFLANN", us_theirs, double(total) / asked,
                us_theirs / us_ours, "");
  }
  omp_set_num_threads(saved_threads);
  std::printf("ratio: pcl::KdTreeFLANN's time a query over ours (the copies of the results are timed with each)\n");

  // A PCL stage given either search (setSearchMethod), twice each, alternated; the tree's
  // build is timed with the stage (the stage hands the search its cloud).
  std::printf("\n%-34s %-24s %10s %10s %16s\n", "pcl::NormalEstimationOMP (threads)", "search", "s (best)", "ratio",
              "normals differ");
  for (const bool by_radius : {false, true}) {
    double best[2] = {1e300, 1e300};
    pcl::PointCloud<pcl::Normal> out[2];
    for (int round = 0; round < 2; ++round)
      for (int m = 0; m < 2; ++m) {
        pcl::NormalEstimationOMP<pcl::PointXYZ, pcl::Normal> ne(static_cast<unsigned>(saved_threads));
        ne.setInputCloud(cloud);
        if (by_radius) ne.setRadiusSearch(r_small);
        else ne.setKSearch(30);
        if (m == 0) ne.setSearchMethod(pcl::make_shared<KdTreeSearch<pcl::PointXYZ>>());
        else ne.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
        const auto c0 = Clock::now();
        ne.compute(out[m]);
        best[m] = std::min(best[m], since(c0));
      }
    // Bits of the normal and the curvature (NaN where a ball is too small compares equal).
    std::size_t differ = std::max(out[0].size(), out[1].size());
    if (out[0].size() == out[1].size()) {
      differ = 0;
      for (std::size_t i = 0; i < out[0].size(); ++i)
        differ += std::memcmp(out[0][i].normal, out[1][i].normal, 3 * sizeof(float)) != 0 ||
                  std::memcmp(&out[0][i].curvature, &out[1][i].curvature, sizeof(float)) != 0;
    }
    const std::string stage = std::string(by_radius ? "small radius" : "30 nearest") + " (" + std::to_string(saved_threads) + ")";
    std::printf("%-34s %-24s %10.3f %10s %16zu\n", stage.c_str(), "paps::KdTreeSearch", best[0], "", differ);
    std::printf("%-34s %-24s %10.3f %10.2f %16s\n", "", "pcl::search::KdTree", best[1], best[1] / best[0], "");
  }
  std::printf("ratio: pcl::search::KdTree's time over paps::KdTreeSearch's, the same stage and points\n");
  return 0;
}

}  // namespace paps::cli
