#pragma once
// Optimal transport from a weighted point set to a simplicial complex (manuscript 5.1):
// every vertex is one bin, every facet is tiled with bins by a centroidal Voronoi
// tessellation, each bin has a capacity (its share of the facet's area), and a transport plan
// sends the points' mass to the bins so that every facet receives a uniform measure
// (eqs. 5.1 to 5.3). The cost sum m_ij |p_i - b_j|^2 is minimised by local linear programs
// (Clp) over small stencils, starting from "every point to its nearest vertex" (5.1.5), so
// the cost found is an upper bound of the global optimum that only ever decreases.
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include <paps/core/progress.h>

namespace paps {

/// Bins of one facet: barycentric coordinates of the CVT cell centroids (they move with the
/// facet's vertices) and capacities (cell area / facet area, summing to 1).
struct FacetBins {
  std::vector<Eigen::Vector3d> barycentric;
  std::vector<double> capacity;
};

inline double triangleArea(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return 0.5 * (b - a).cross(c - a).norm();
}

/// CVT of a triangle into `count` cells (Lloyd iterations on a fine barycentric lattice),
/// deterministic. count >= 1.
FacetBins centroidalBins(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                         int count);

/// One target of a local transport problem: a vertex (one bin of unconstrained capacity) or a
/// facet with its bins (uniform measure).
struct TransportTarget {
  std::array<Eigen::Vector3d, 3> corners;  // a vertex uses corners[0]
  const FacetBins* bins = nullptr;         // null: a vertex
  bool isFacet() const { return bins != nullptr; }
  int binCount() const { return bins ? static_cast<int>(bins->capacity.size()) : 1; }
  Eigen::Vector3d bin(int b) const {
    if (!bins) return corners[0];
    const Eigen::Vector3d& w = bins->barycentric[b];
    return w[0] * corners[0] + w[1] * corners[1] + w[2] * corners[2];
  }
};

/// Mass sent by one point to one bin of one target.
struct TransportEntry {
  int target;  // index into the target list of the problem
  int bin;
  double mass;
};

/// Solution of a local problem: cost, and for every point its entries (target = index in the
/// target list).
struct LocalTransport {
  bool solved = false;  // false: the LP failed (the caller keeps its old plan)
  double cost = 0;
  std::vector<std::vector<TransportEntry>> entries;
};

/// Optimal transport of `points` (masses `mass`, all > 0) to `targets` with the uniformity
/// constraint on every facet target: one linear program solved by Clp. With bins_per_point
/// > 0 a point may only send mass to its nearest bins (and its nearest vertex bin): a smaller
/// program, exact unless the optimum sends mass farther.
LocalTransport solveLocalTransport(const std::vector<Eigen::Vector3d>& points,
                                   const std::vector<double>& mass,
                                   const std::vector<TransportTarget>& targets, int bins_per_point = 0);

/// The cost of sending every point's mass to its nearest bin of `targets`, the facets'
/// uniform measure ignored: no plan of the local problem costs less (solveLocalTransport's
/// cost is at least this). Cheap next to the program (one pass over points x bins); it lets
/// a caller skip programs that cannot beat one it already has.
double nearestBinCost(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& mass,
                      const std::vector<TransportTarget>& targets);

/// A lower bound of solveLocalTransport's cost with the same arguments, the facets' uniform
/// measure taken into account through prices on their bins (weak duality, projected
/// subgradient ascent): at least the nearest-bin cost over the points' candidate bins, and
/// usually closer to the program's cost. It stops as soon as it reaches `goal` (a caller that
/// only needs to know whether the cost exceeds a value passes that value) or after
/// `iterations` steps. Cheap next to the program: a pass over each point's candidates a step.
double dualLowerBound(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& mass,
                      const std::vector<TransportTarget>& targets, int bins_per_point, double goal,
                      int iterations = 30);

struct TransportParameters {
  /// Facet bins per unit area once the points are scaled into a box of side 0.5 (the
  /// manuscript's 200); a facet has at least one bin and at most max_bins_per_facet.
  double bins_per_area = 200;
  int max_bins_per_facet = 16;
  /// Relaxation sweeps stop when a sweep lowers the cost by less than this fraction (1e-5 in
  /// the manuscript), or after max_sweeps.
  double tolerance = 1e-5;
  int max_sweeps = 10;
  /// Bins a point may send mass to in a local problem (its nearest, plus its nearest vertex);
  /// 0: every bin of the stencil (the manuscript's program; on a 1,500-point cube 16 gave the
  /// same mesh 3.3x faster).
  int bins_per_point = 16;
  /// Refuse moves that turn a facet over (its normal by more than 90 degrees): they fold the
  /// sheet back over itself, and the transport cost barely sees it when the facet carries
  /// little mass (not in the manuscript; a classic check of mesh decimation). A relocation is
  /// shortened until no facet of the vertex turns; the reconstruction's decimation refuses
  /// such a collapse. In `paps bench transport` (session 66, means of 3 seeds) the default's
  /// mesh RMS became 0.80x-0.93x what it was on the cube and the fandisk block, in 0.73x-0.81x
  /// the time, and 1.06x on rs1 (within its seeds' spread).
  bool refuse_flips = true;
  void validate() const;
};

/// A simplicial complex (vertices, facets; edges are implied by the facets or given apart) and
/// a transport plan from a point set onto it, kept consistent under local edits. Simplices are
/// never renumbered: removed ones are marked dead.
class TransportPlan {
 public:
  /// Points (finite), masses (> 0, or empty for 1 each). Throws InvalidInput on bad input.
  TransportPlan(std::vector<Eigen::Vector3d> points, std::vector<double> masses,
                const TransportParameters& params);

  // --- the complex
  int addVertex(const Eigen::Vector3d& p);
  /// Adds a facet with its bins (CVT sized by its area); returns its id.
  int addFacet(int a, int b, int c);
  /// Adds a facet with bins already computed for these corners.
  int addFacet(int a, int b, int c, FacetBins bins);
  void removeFacet(int f);   // the plan must not use it any more
  void removeVertex(int v);  // idem
  bool vertexAlive(int v) const { return vertex_alive_[v]; }
  bool facetAlive(int f) const { return facet_alive_[f]; }
  int vertexCount() const { return static_cast<int>(vertices_.size()); }
  int facetCount() const { return static_cast<int>(facets_.size()); }
  int aliveVertexCount() const;
  int aliveFacetCount() const;
  const Eigen::Vector3d& vertex(int v) const { return vertices_[v]; }
  const std::array<int, 3>& facet(int f) const { return facets_[f]; }
  const FacetBins& bins(int f) const { return bins_[f]; }
  double facetArea(int f) const;
  /// Alive facets incident to v.
  const std::vector<int>& facetsOf(int v) const { return vertex_facets_[v]; }
  /// The number of bins a facet of this area gets.
  int binCountFor(double area) const;
  const TransportParameters& parameters() const { return params_; }

  // --- the plan
  /// Every point to its nearest alive vertex (the valid, crude start of 5.1.5).
  void assignToNearestVertices();
  std::size_t pointCount() const { return points_.size(); }
  const Eigen::Vector3d& point(std::size_t i) const { return points_[i]; }
  double totalMass() const { return total_mass_; }
  /// Mass received by a simplex, point by point (bin -1 on a vertex). The plan is stored per
  /// simplex, so that stencils without a common simplex can be solved at the same time.
  struct Share {
    int point;
    int bin;
    double mass;
  };
  const std::vector<Share>& sharesOfVertex(int v) const { return vertex_shares_[v]; }
  const std::vector<Share>& sharesOfFacet(int f) const { return facet_shares_[f]; }
  /// Mass each point sends (its mass, when the plan is complete).
  std::vector<double> massSent() const;
  double massOnFacet(int f) const;
  /// Mass on the alive facets over their area (0 without area): the reference of the
  /// density filters (5.2.5).
  double meanFacetDensity() const;
  /// Total cost sum m_ij |p_i - b_j|^2 (recomputed).
  double cost() const;

  /// A local problem: the points with mass on any simplex of the stencil, their mass there
  /// and its current cost.
  struct Stencil {
    std::vector<int> vertices, facets;  // simplex ids
    std::vector<int> points;
    std::vector<double> mass;           // per point: its mass on the stencil
    double cost = 0;                    // current cost of that mass
  };
  Stencil gather(std::vector<int> vertices, std::vector<int> facets) const;
  /// Targets of the stencil's simplices, in order (vertices, then facets).
  std::vector<TransportTarget> targetsOf(const Stencil& s) const;
  /// Positions of the stencil's points, in the order of s.points (a local program's points).
  std::vector<Eigen::Vector3d> positionsOf(const Stencil& s) const;
  /// Replaces the plan of the stencil's mass with `solution` (targets as from targetsOf).
  void apply(const Stencil& s, const LocalTransport& solution);
  /// For edits of the complex: release() takes the stencil's mass off the plan (the points
  /// then send less than their mass), the caller edits the complex, and assign() sends that
  /// mass by `solution`, whose targets are `vertices` then `facets` (simplex ids).
  void release(const Stencil& s);
  void assign(const Stencil& s, const std::vector<int>& vertices, const std::vector<int>& facets,
              const LocalTransport& solution);
  /// Re-solves the stencil; applies and returns the decrease when the cost goes down.
  double improve(const Stencil& s);
  /// Stencil of facet f: the facets sharing an edge with it, and all their vertices.
  Stencil facetStencil(int f) const;
  /// Stencil of vertex v: its facets and all their vertices (and v).
  Stencil vertexStencil(int v) const;
  /// The simplex ids of vertexStencil(v), without gathering its plan (vertices may repeat).
  void vertexStencilSimplices(int v, std::vector<int>& vertices, std::vector<int>& facets) const;
  /// Sweeps over the facet stencils until the cost stalls (5.1.5). Returns the sweeps done.
  /// A progress callback hears of each sweep (of at most max_sweeps) and may cancel.
  int relax(const ProgressCallback& progress = {});

  /// Whether moving v to `to` turns one of its facets over (the facet's normal by more than
  /// 90 degrees); facets that also hold vertex `except` are not checked (a collapse of v onto
  /// `except` removes them). The test of refuse_flips, for relocations and collapses alike.
  bool turnsAFacet(int v, const Eigen::Vector3d& to, int except = -1) const;

  /// Vertex relocation (5.2.4): moves v halfway to the optimal position for the current plan,
  /// then re-solves its stencil. Returns the distance moved.
  double relocate(int v);
  /// relocate() on every alive vertex; returns the RMS move.
  double relocateAll();
  /// Facet deletion (not in the manuscript): visiting the facets with mass by increasing mass
  /// density, deletes a facet when re-solving its stencil without it raises the cost by at
  /// most threshold x its mass x the median facet's mean squared transport distance (its mass
  /// then goes to the simplices around it). A facet doubling another passes its mass on
  /// cheaply; a facet of the surface does not. Passes repeat until one deletes nothing (at
  /// most 10). Returns the number deleted.
  int deleteRedundantFacets(double threshold);
  /// Stacked-facet deletion (not in the manuscript): a facet whose bins are covered (at least
  /// `min_coverage` of its area), along its normal within `reach` x the median facet's RMS
  /// transport distance, by other facets with mass at most 37 degrees from parallel lies in a
  /// layer over the surface (or in a fold). Visiting those by increasing mass density, one
  /// goes when re-solving its stencil plus the facets covering it, without it, raises the
  /// cost by at most threshold x its mass x the median facet's mean squared transport
  /// distance. Coverage is checked again on each visit, so of two layers covering each other
  /// one stays: no hole opens. Passes repeat until one deletes nothing (at most 10). Returns
  /// the number deleted.
  int deleteStackedFacets(double threshold, double reach, double min_coverage = 0.9);

  /// Runs `work(item)` for every item in rounds: a round takes, in item order, the items whose
  /// stencil (the simplex ids `simplices(item)` fills, vertices then facets) shares no simplex
  /// with an item taken before in that round, and runs them in parallel. Rounds follow each
  /// other until every item ran: the result does not depend on the thread count.
  void forEachIndependent(const std::vector<int>& items,
                          const std::function<void(int, std::vector<int>&, std::vector<int>&)>& simplices,
                          const std::function<void(int)>& work);

 private:
  void facetStencilSimplices(int f, std::vector<int>& vertices, std::vector<int>& facets) const;
  /// Deletes facet f (one of s's facets) when re-solving stencil s without it raises the cost
  /// by at most `allowed`; returns whether it did (the facets of s then hold f's mass).
  bool deleteFacetIfCheap(int f, const Stencil& s, double allowed);
  /// Mean squared transport distance of the median facet with mass (0 without any): the
  /// unit of the deletion thresholds.
  double medianFacetMeanSquaredDistance() const;

  TransportParameters params_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<double> masses_;
  double total_mass_ = 0;
  double bin_scale2_ = 1;  // (0.5 / longest box side)^2: areas in the manuscript's units
  std::vector<Eigen::Vector3d> vertices_;
  std::vector<char> vertex_alive_;
  std::vector<std::array<int, 3>> facets_;
  std::vector<char> facet_alive_;
  std::vector<FacetBins> bins_;
  std::vector<std::vector<int>> vertex_facets_;
  std::vector<std::vector<Share>> vertex_shares_, facet_shares_;
};

}  // namespace paps
