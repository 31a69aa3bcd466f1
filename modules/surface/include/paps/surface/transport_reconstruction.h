#pragma once
// Surface reconstruction and simplification by optimal transport (manuscript 5.2): a 3D
// Delaunay triangulation of a random subset of the points, reduced to the facets that receive
// mass, then decimated by half-edge collapses, each chosen as the one that raises the
// transport cost the least, with vertex relocation after each collapse and a final filter on
// facet density. The output is a simplicial complex (possibly non-manifold) with sharp
// creases and boundaries kept, robust to noise and outliers. Costly: meant for point sets of
// thousands to tens of thousands of points reduced to tens to hundreds of vertices; larger
// inputs are merged into at most max_points (20,000) cells first, or 10 a vertex if more. By
// default the decimation starts from CGAL's advancing-front surface over the subset
// (InitialComplex::AdvancingFront, a near-manifold output); InitialComplex::Delaunay is the
// manuscript's start, whose output stacks layers of facets over the surface.
#include <cstddef>
#include <cstdint>
#include <vector>

#include <pcl/PolygonMesh.h>
#include <pcl/point_types.h>
#include <pcl/surface/reconstruction.h>

#include <paps/core/neighbourhood.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>
#include <paps/core/thread_count.h>
#include <paps/core/triangle_mesh.h>
#include <paps/surface/transport_plan.h>

namespace paps {

/// Where the decimation starts from (both on the same random subset of the points).
enum class InitialComplex {
  /// Every facet of the subset's 3D Delaunay triangulation (the manuscript's 5.2.1); the
  /// transport keeps those that receive mass. On a surface sample the slivers' overlapping
  /// facets get mass too, and the output keeps layers of them (non-manifold edges).
  Delaunay,
  /// The facets of CGAL's advancing-front surface reconstruction of the subset (Cohen-Steiner
  /// and Da, a subset of the same Delaunay facets chosen to form a surface), all kept through
  /// the relaxation (the Delaunay start keeps only those with mass): a near-manifold start
  /// and output, in less time (not in the manuscript; docs/transport.md).
  AdvancingFront,
};

/// Points a vertex below which many small facets get no point and the mesh has holes: the
/// merge keeps at least this many by default (merge_points_per_vertex), and `paps reconstruct`
/// warns below it.
constexpr int kPointsPerVertex = 10;

struct TransportReconstructionParameters {
  /// Share of the points in the initial Delaunay triangulation, in (0, 1]; at least 4 points.
  /// Points are counted by distinct position: copies of a point (overlapping scans) are one
  /// point of their summed mass, which the transport treats exactly as the copies.
  /// The manuscript's 10% left holes and chamfered corners on a 1,500-point cube: 20% (with
  /// 10 final sweeps) brought the mesh's RMS error from 9.3 to 5.4 thousandths of the
  /// diagonal in the same time (more, cheaper collapses).
  float initial_fraction = 0.2f;
  /// Decimation stops at this many vertices (>= 3).
  int target_vertices = 50;
  /// Multiple choice: half-edge collapses simulated per step, drawn at random (the
  /// manuscript's 40); 0 simulates every half-edge (exhaustive, slow). 120 lowered the mesh
  /// error on every clean and noisy shape of `paps bench transport` (cube 2.38 against 2.78,
  /// fandisk block 4.39 against 4.58 thousandths of the diagonal, means of 3 seeds) in 2.2x-2.6x
  /// the time, but with 10% outliers two seeds of three kept a facet hanging into the
  /// cube instead of one: not the default.
  int candidates = 40;
  /// Keep the simulations whose stencil no step has changed, for later draws of the same
  /// half-edge. Exact (the same mesh either way); off only to measure what it saves.
  bool reuse_simulations = true;
  /// Simulate the drawn collapses in order of a lower bound of their cost change (every
  /// point to its nearest bin after the collapse), and stop where the bound exceeds the best
  /// change found: the rest cannot be chosen. Exact (the same mesh either way); off only to
  /// measure what it saves (rs1, 3,000 points to 100 vertices: 1,735 programs instead of 17,004).
  bool bound_simulations = true;
  /// With bound_simulations: past each step's first batch, a drawn collapse's program is
  /// solved only if a dual bound of its cost (prices on the facets' bins, so the uniform
  /// measure counts; dualLowerBound) can still beat the best change found. Exact (the same
  /// mesh either way); off only to measure what it saves (the 3,000-point cube to 30
  /// vertices: 2,886 programs instead of 9,233, 28.0 s instead of 45.4 s on 2 threads).
  bool dual_bound = true;
  /// Relocation rounds after each collapse (move halfway to the optimum, update the plan).
  int relocation_iterations = 2;
  /// Final relocation sweeps over all vertices (cheap next to the decimation).
  int final_relocation_sweeps = 10;
  /// Facets whose mass density (mass / area) is below this fraction of the mean density are
  /// dropped at the end (5.2.5), in [0, 1).
  float density_threshold = 0.1f;
  /// Facet deletion after the decimation (not in the manuscript, which names the lack of it
  /// as a weakness): a facet goes when sending its mass to the simplices around it raises the
  /// transport cost by at most this many times its mass times the median facet's mean squared
  /// transport distance. A facet doubling another goes, and so does one whose mass lies about
  /// as close to the simplices around it (on a cube with 10% outliers, a facet hanging from an
  /// outlier vertex into the cube); a facet of the surface does not (its mass would travel
  /// far). 0 disables; in [0, 1e6].
  float deletion_threshold = 0.2f;
  /// Stacked-facet deletion (not in the manuscript; TransportPlan::deleteStackedFacets), after
  /// the facet deletion: a facet covered along its normal, within `stacked_reach` x the
  /// median facet's RMS transport distance, by near-parallel facets is a layer over the
  /// surface or a fold; it goes when sending its mass to the facets around and under it
  /// raises the cost by at most this many times its mass times the median facet's mean
  /// squared transport distance. In `paps bench transport` (means of 3 seeds) it brought the
  /// Delaunay start's area over the true mesh's from 1.21-1.98 to 0.97-1.01 (edges of three
  /// facets 19-69 -> 2-12) and moved the default's distances by at most 0.8%; 16 deleted the
  /// same facets as 4 on noisy planes (docs/transport.md, session 65). 0 disables; in [0, 1e6].
  float stacked_threshold = 4.0f;
  /// Reach of the stacked-facet test, in RMS transport distances of the median facet; in
  /// (0, 1000].
  float stacked_reach = 3.0f;
  /// Dangling facets (not in the manuscript), for points with outliers: after the density
  /// filter, a facet with a corner that no other kept facet uses goes when fewer than 2 input
  /// points lie within `dangling_support` x the mean point spacing (distance to the nearest
  /// other point) of that corner, until none is left. With 10% outliers a vertex among them
  /// can hold up a facet whose density passes the filter (0.53-0.54 of the mean, against
  /// 0.52-0.55 for the cube's own lowest); its free corner has 1 point near it. 2 brought the
  /// bench's cube with outliers from 1.11x to 0.86x the decimated Poisson's mesh RMS, but on
  /// the real scan rs1 it dropped 2 facets of one seed that covered the scene (coverage RMS
  /// 1.06x -> 1.11x the decimated Poisson's): off by default. 0 disables; in [0, 1000].
  float dangling_support = 0.0f;
  /// Outlier weights (not in the manuscript), for points with outliers: with k > 0 each
  /// point's mass is scaled by outlierWeights(points, k), so that points far from the others
  /// (stray returns inside or around the object) pull the facets little. With 10% outliers
  /// in a cube, base facets joined vertices of different faces across the inside, fed by the
  /// outliers there (1 seed in 10 at 9.2 thousandths of the diagonal, 134 at worst); with
  /// k = 8 the worst of those 10 seeds is 4.4 and the mean 3.64 instead of 4.43, though 6
  /// seeds are somewhat worse (docs/transport.md). Off by default: on a scan whose density
  /// varies, sparse parts weigh less too. 0 disables (unit masses); in [0, 1000].
  int outlier_neighbours = 0;
  /// Large inputs: with more distinct points than this, the points are first merged by a
  /// voxel grid (the finest whose occupied cells are at most this many) into one point a cell
  /// at its centroid, with the cell's summed mass (mergeIntoCells). The transport of a merged
  /// point is the transport of its cell's points sharing one plan, so a plan's cost on the
  /// merged points plus the cells' spread is the cost of a valid plan on the input: the
  /// reported costs stay upper bounds of the input's transport cost. The programs shrink with
  /// the points (the late ones hold thousands of points each); a cell is a few point spacings
  /// wide, well below the facets of tens to hundreds of vertices. 0: never merge.
  /// 20,000: rs1 sampled with 50,000 points to 100 vertices, seeds 1-3 (`paps bench
  /// transport --only-scan --scan-points 50000`): 34 s instead of 127 s on 2 threads, mesh
  /// RMS 0.99x and coverage RMS 0.91x the unmerged run's; 112,586 points (bun0.pcd) to 50
  /// vertices took 48 s instead of not finishing in 28 minutes. On par with a plain sample of
  /// the same size (docs/transport.md), without the user subsampling. On a sharp cube (30,000
  /// points into 3,000) cells across the edges merged inside the cube until they were split
  /// at creases (merge_crease_angle): coverage RMS 0.68x; still about 1.5x the facets of a
  /// plain 3,000-point sample. Inputs up to 20,000 points are not touched.
  int max_points = 20000;
  /// The merge keeps at least this many points a vertex: with max_points > 0, the cells are
  /// at most max(max_points, merge_points_per_vertex x target_vertices) (mergeTarget). Below
  /// about 10 points a vertex many small facets get no point and are dropped: rs1 to 10,000
  /// vertices merged into 20,000 points kept 8,986 border edges, from all its 114,373 points
  /// 1,547 (docs/transport.md). 0: max_points alone; in [0, 1000].
  int merge_points_per_vertex = kPointsPerVertex;
  /// Merging keeps creases: a cell whose points' normals (PCA of their kMergeNormalNeighbours
  /// nearest distinct points) fall in two clusters more than this many degrees apart is split
  /// into its sides, each merged at its own centroid, which lies on its face (mergeIntoCells).
  /// 0: cells are never split; in [0, 90].
  double merge_crease_angle = 30;
  /// The initial complex (InitialComplex). The advancing front by default since session 64:
  /// the Delaunay start's meshes (the manuscript's) covered 1.2x-2.0x the true surface's area
  /// in `paps bench transport` (means of seeds 1-3: clean cube 1.21, 0.5% noise 1.98, 10%
  /// outliers 1.51, fandisk block 1.60, rs1 1.54; 19-69 edges of three facets or more), layers
  /// stacked within the noise that the distances barely see; the advancing front's 0.98-1.03
  /// (0.3-2 such edges), in 0.3x-0.8x the time. Its meshes are closer to the cube and the
  /// fandisk block, but its coverage is worse with noise (1.19x), outliers (1.35x) and on rs1
  /// (1.20x) (docs/transport.md).
  InitialComplex initial_complex = InitialComplex::AdvancingFront;
  /// Points that fill a volume (volumeVariation of the transported points above
  /// kVolumeVariation) are refused: the method transports points onto a surface, and on a
  /// volume its local programs grow with the facets filling it. 2,000 points uniform in a
  /// cube took 73 s and 5,000 took 258 s to 50 vertices, against 5 s for 3,000 points of a
  /// scan; 200,000 (merged into 20,000) did not end in 400 s. True: run anyway.
  bool allow_volume = false;
  std::uint64_t seed = 1;
  /// Quadrature: 4x the manuscript's bins per area (800) and up to 64 bins a facet. With the
  /// manuscript's 200 and 16, a 3,000-point cube at 30 vertices kept chamfers and overlapping
  /// facets (mesh RMS 5.8-7.4 thousandths of the diagonal over seeds 1-3); with 800 and 64,
  /// 2.3-3.6 in 1.8x the time: coarse bins add a tangential cost that hides the geometry from
  /// the collapse choice. Finer still (1,600 or 2,000) gained little for 1.3-2x the time.
  /// bins_per_point stays 16: 8 gave the same meshes on average over seeds 1-3 of the
  /// 3,000-point cube and fandisk block (mesh RMS 2.67 against 2.78, 4.67 against 4.58
  /// thousandths of the diagonal) in about 0.75x the time, but on 600 points of the cube
  /// (more bins than points) its error was 1.2x-2x over four seeds.
  TransportParameters transport = quadrature();
  void validate() const;
  /// The merge's cell count: 0 (never merge) when max_points is 0, else the larger of
  /// max_points and merge_points_per_vertex x target_vertices.
  std::size_t mergeTarget() const;

  static TransportParameters quadrature() {
    TransportParameters t;
    t.bins_per_area = 800;
    t.max_bins_per_facet = 64;
    return t;
  }
};

struct TransportReconstructionReport {
  std::size_t points = 0;
  /// Points the transport ran on: the distinct positions, or the cells they were merged
  /// into (max_points), with the cells' side (0: not merged) and spread (their points' summed
  /// m |p - centroid|^2, included in the costs below).
  std::size_t transported_points = 0;
  /// The merge's cell count (TransportReconstructionParameters::mergeTarget; 0: never merge).
  std::size_t merge_target = 0;
  double merge_cell = 0, merge_spread = 0;
  /// Of transported_points, those added by splitting cells at creases (merge_crease_angle).
  std::size_t crease_points = 0;
  int initial_vertices = 0, initial_facets = 0;  // the initial complex (InitialComplex)
  /// With InitialComplex::AdvancingFront: its surface had no facet, so the Delaunay facets
  /// were used. (Points on one plane always start from their flat Delaunay triangulation,
  /// a surface already; not counted here.)
  bool advancing_front_fallback = false;
  /// volumeVariation of the transported points (0: fewer than 256): about 0.2 to 1/3 where
  /// they fill a volume, below 0.05 on the scans and noisy surfaces measured.
  double volume_variation = 0;
  /// Facets after the relaxation: those with mass (the Delaunay start), all (the advancing front).
  int complex_facets = 0;
  int collapses = 0;
  /// Collapse simulations run (local programs solved), and those reused from an earlier step
  /// because nothing in their stencil had changed since.
  int simulations = 0, reused_simulations = 0;
  /// Drawn collapses not simulated because their lower bound could not beat the best change.
  int bounded_simulations = 0;
  /// Drawn collapses refused because they would turn a facet over (refuse_flips).
  int refused_collapses = 0;
  int deleted_facets = 0;  // by the facet deletion
  int stacked_facets = 0;  // by the stacked-facet deletion
  int dangling_facets = 0;  // dropped at the end for want of points near a free corner
  /// Facets the density filter dropped that came back: groups of them on which fewer than 3
  /// points were to be expected in all, each filling a hole of the kept mesh exactly.
  int restored_facets = 0;
  /// With outlier weights: distinct points weighing less than 1, and less than 0.1.
  std::size_t light_points = 0, outlier_points = 0;
  int output_vertices = 0, output_facets = 0;
  /// Transport cost, sum m |p - b|^2, m = the copies of a position (times its outlier weight).
  double initial_cost = 0, final_cost = 0;
  /// sqrt(cost / total mass): root mean square transport distance, metres.
  double rms_transport = 0;
};

/// Above this volumeVariation the points fill a volume (allow_volume). Measured
/// (docs/transport.md): surfaces 0 to 0.044 (a plane with noise twice its point spacing),
/// points uniform in a cube 0.205 to 0.25.
constexpr double kVolumeVariation = 0.15;

/// Neighbours (self included) of the PCA normals that find the creases when merging.
constexpr int kMergeNormalNeighbours = 10;

/// Reach beyond which a point counts as an outlier: this many times the median reach.
constexpr double kOutlierReach = 1.5;
/// The least outlier weight (masses stay > 0, as the transport needs).
constexpr double kMinOutlierWeight = 1e-12;

/// Weight of each point against outliers: with r its distance to its `neighbours`-th nearest
/// finite point (1 to 1000) and m the median of the r > 0, 1 where r <= 1.5 m (kOutlierReach;
/// a surface sampled at random rarely reaches it) and (1.5 m / r)^4 beyond (1/16 at twice
/// that reach; at least kMinOutlierWeight); all 1 when every r is 0 (copies of a few
/// positions). 0 for non-finite points. Throws InvalidInput with fewer than 2 finite points,
/// InvalidParameter for `neighbours` outside [1, 1000].
std::vector<double> outlierWeights(const Positions& points, int neighbours);

/// Weighted points merged by a voxel grid: one point a cell at the mass-weighted centroid of
/// its points, with their summed mass, in the cells' (x, y, z) order.
struct MergedPoints {
  std::vector<Eigen::Vector3d> points;
  std::vector<double> masses;
  double cell = 0;    // side of the cells (metres); 0: nothing merged (the input as given)
  /// sum m |p - c|^2 over the input, c its cell's centroid: for any plan on the merged points
  /// the same plan split in proportion on each cell's points costs this much more (exactly).
  double spread = 0;
  /// Points added by splitting cells at creases (one more for each split).
  std::size_t crease_points = 0;
};

/// Merges `points` (finite; masses > 0, one each) with the finest grid, cell sides tried by
/// bisection, whose groups are at most `max_points`; the grid starts at the points' lowest
/// corner. A group is a cell's points, or with `normals` (one a point, unit or NaN, sign
/// free) and `crease_degrees` > 0, part of them: a cell whose points' normals fall in two
/// clusters more than `crease_degrees` apart, and 2.5x further apart than their spread
/// around their axes (2-means on unoriented normals; each side 3 points or more, so noise
/// rarely splits), is split in two, and each side once more (at most 4 groups: a cube's
/// corner has 3 faces). The centroid of a cell across a crease lies off the surface, inside
/// a convex edge; the centroid of each side lies on its own face. With at most `max_points`
/// points, or max_points = 0, returns them as given. Deterministic: the result does not
/// depend on the input's order beyond float rounding of the sums. Throws InvalidInput when
/// the sizes differ or a point is not finite, InvalidParameter for crease_degrees outside
/// [0, 90].
MergedPoints mergeIntoCells(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& masses,
                            std::size_t max_points, const Normals* normals = nullptr, double crease_degrees = 0);

/// Reconstructs a mesh from `points` (NaN entries ignored). Deterministic for a seed, whatever
/// the thread count. Points on one plane give a mesh in that plane. Throws InvalidInput for
/// fewer than 4 distinct finite points, collinear points, or a run that keeps no facet (the
/// report is filled first), InvalidParameter for bad parameters.
TriangleMesh transportReconstruct(const Positions& points, const TransportReconstructionParameters& params,
                                  TransportReconstructionReport* report = nullptr,
                                  const ProgressCallback& progress = {});

/// Drops, until none is left, every facet with a corner that no other facet uses and that
/// has fewer than 2 of the indexed points within `radius` (metres, > 0); then the vertices no
/// facet uses. Returns the number of facets dropped. The last step of transportReconstruct.
int dropDanglingFacets(TriangleMesh& mesh, const SpatialIndex& points, float radius);

/// The pcl::SurfaceReconstruction stage (indices honoured). The output mesh's cloud holds
/// x, y, z of the kept vertices.
template <typename PointT>
class TransportReconstruction : public pcl::SurfaceReconstruction<PointT>, public ThreadCountOption {
 public:
  TransportReconstruction() { this->check_tree_ = false; }
  void setParameters(const TransportReconstructionParameters& p) { p.validate(); params_ = p; }
  const TransportReconstructionParameters& getParameters() const { return params_; }
  void setTargetVertices(int n) { auto p = params_; p.target_vertices = n; setParameters(p); }
  /// Outlier weights with K neighbours (TransportReconstructionParameters::outlier_neighbours).
  void setOutlierNeighbours(int k) { auto p = params_; p.outlier_neighbours = k; setParameters(p); }
  /// Merge large inputs into at most N points first (TransportReconstructionParameters::max_points).
  void setMaxPoints(int n) { auto p = params_; p.max_points = n; setParameters(p); }
  /// The merge keeps at least this many points a vertex (merge_points_per_vertex; 0: max_points alone).
  void setMergePointsPerVertex(int n) { auto p = params_; p.merge_points_per_vertex = n; setParameters(p); }
  /// Split merged cells at creases sharper than this many degrees (merge_crease_angle; 0: never).
  void setMergeCreaseAngle(double degrees) { auto p = params_; p.merge_crease_angle = degrees; setParameters(p); }
  /// Start from the subset's Delaunay facets (the manuscript) or its advancing-front surface.
  void setInitialComplex(InitialComplex c) { auto p = params_; p.initial_complex = c; setParameters(p); }
  /// Run on points that fill a volume too (allow_volume; slow).
  void setAllowVolume(bool allow) { auto p = params_; p.allow_volume = allow; setParameters(p); }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const TransportReconstructionReport& getReport() const { return report_; }
  /// As pcl::SurfaceReconstruction::reconstruct, but without an input cloud it throws
  /// InvalidInput (PCL's prints an error and returns an empty mesh).
  void reconstruct(pcl::PolygonMesh& output) override {
    requireInputCloud(this->input_);
    pcl::SurfaceReconstruction<PointT>::reconstruct(output);
  }
  void reconstruct(pcl::PointCloud<PointT>& points, std::vector<pcl::Vertices>& polygons) override {
    requireInputCloud(this->input_);
    pcl::SurfaceReconstruction<PointT>::reconstruct(points, polygons);
  }

 protected:
  std::string getClassName() const override { return "TransportReconstruction"; }
  void performReconstruction(pcl::PolygonMesh& output) override;
  void performReconstruction(pcl::PointCloud<PointT>& points, std::vector<pcl::Vertices>& polygons) override;

 private:
  TriangleMesh run();
  TransportReconstructionParameters params_;
  TransportReconstructionReport report_;
  ProgressCallback progress_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/surface/impl/transport_reconstruction.hpp>
#endif
