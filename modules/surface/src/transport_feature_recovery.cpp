#include <paps/surface/transport_feature_recovery.h>
#include <paps/surface/impl/transport_feature_recovery.hpp>

#include <algorithm>
#include <cmath>

#include <paps/core/error.h>
#include <paps/core/spatial_order.h>

namespace paps {

void TransportFeatureRecoveryParameters::validate() const {
  requireInRange("sweeps", sweeps, 1, 1000);
  if (!(density_threshold >= 0) || !(density_threshold < 1))
    throw InvalidParameter("density_threshold", detail::toString(density_threshold), "in [0, 1)");
  transport.validate();
}

TriangleMesh transportRecoverFeatures(const TriangleMesh& mesh, const Positions& input,
                                      const TransportFeatureRecoveryParameters& params,
                                      TransportFeatureRecoveryReport* report_out, const ProgressCallback& progress) {
  params.validate();
  TransportFeatureRecoveryReport report;
  if (mesh.vertices.empty() || mesh.triangles.empty()) throw InvalidInput("feature recovery: the mesh is empty");
  // In spatial order (finite points only): the output does not depend on the input order.
  std::vector<Eigen::Vector3d> points;
  points.reserve(input.size());
  for (int k : spatialOrderAll(input))
    if (isFinite(input[k])) points.push_back(input[k].cast<double>());
  if (points.empty()) throw InvalidInput("feature recovery: the point set has no finite point");
  report.points = points.size();
  for (const auto& v : mesh.vertices)
    if (!isFinite(v)) throw InvalidInput("feature recovery: the mesh has a non-finite vertex");

  TransportPlan plan(std::move(points), {}, params.transport);
  for (const auto& v : mesh.vertices) plan.addVertex(v.cast<double>());
  const int nv = static_cast<int>(mesh.vertices.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    if ((t.array() < 0).any() || (t.array() >= nv).any())
      throw InvalidInput("feature recovery: triangle " + std::to_string(f) + " refers to a missing vertex");
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;  // degenerate: no area, no bin
    plan.addFacet(t[0], t[1], t[2]);
  }
  report.vertices = nv;
  report.facets = plan.facetCount();
  plan.assignToNearestVertices();
  report.initial_cost = plan.cost();
  report.relaxation_sweeps = plan.relax(progress);
  report.relaxed_cost = plan.cost();

  const std::vector<Eigen::Vector3d> start = [&] {
    std::vector<Eigen::Vector3d> s(nv);
    for (int v = 0; v < nv; ++v) s[v] = plan.vertex(v);
    return s;
  }();
  ProgressReporter rep(progress, "transport feature recovery", static_cast<std::size_t>(params.sweeps) * nv);
  for (int sweep = 0; sweep < params.sweeps && !rep.cancelled(); ++sweep) {
    report.sweep_moves.push_back(plan.relocateAll());
    rep.advance(nv);
  }
  rep.throwIfCancelled();
  rep.finish();
  report.final_cost = plan.cost();
  for (int v = 0; v < nv; ++v) {
    const double d = (plan.vertex(v) - start[v]).norm();
    report.mean_move += d / nv;
    report.max_move = std::max(report.max_move, d);
  }

  const double mean_density = plan.meanFacetDensity();
  TriangleMesh out;
  out.vertices.resize(nv);
  for (int v = 0; v < nv; ++v) out.vertices[v] = plan.vertex(v).cast<float>();
  for (int f = 0; f < plan.facetCount(); ++f) {
    if (params.density_threshold > 0) {
      const double a = plan.facetArea(f);
      if (!(a > 0) || plan.massOnFacet(f) / a < params.density_threshold * mean_density) continue;
    }
    const auto& t = plan.facet(f);
    out.triangles.emplace_back(t[0], t[1], t[2]);
  }
  report.output_facets = static_cast<int>(out.triangles.size());
  if (report_out) *report_out = report;
  return out;
}

template class TransportFeatureRecovery<pcl::PointXYZ>;
template class TransportFeatureRecovery<pcl::PointNormal>;
template class TransportFeatureRecovery<pcl::PointXYZRGBNormal>;

}  // namespace paps
