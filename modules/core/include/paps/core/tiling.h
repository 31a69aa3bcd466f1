#pragma once
// Tiles: a cloud too large for a stage's working memory, processed a piece at a time. Each
// tile answers for its core points and also carries the points within a margin of them (its
// halo), so that the neighbourhoods of the core points near its border are whole.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

/// A piece of a cloud: the points it answers for and the extra points its core's
/// neighbourhoods reach, as indices into the cloud, each list in increasing order.
struct Tile {
  std::vector<int> core;
  std::vector<int> halo;
};

/// Splits the finite points into tiles of at most `max_core` core points (>= 1): the point set
/// is halved at its median along the longest side of its bounding box, recursively. Points at
/// exactly the same position always land in the same tile, and the split depends on the
/// positions only (not on their order nor on the thread count), so a tile can hold more than
/// `max_core` points when copies of one position outnumber it. The halo of a tile is every
/// other finite point inside the bounding box of its core grown by `margin` (>= 0, metres) on
/// each side. Non-finite points are in no tile. Throws InvalidParameter for max_core == 0 or
/// a negative or non-finite margin.
std::vector<Tile> splitIntoTiles(const Positions& points, std::size_t max_core, float margin);

/// The halo of a tile of `points` whose core is `core` (increasing indices) for another
/// margin than splitIntoTiles was given: every other finite point inside the bounding box of
/// the core grown by `margin` (>= 0, metres; infinite: every other finite point), in
/// increasing order. For a stage that finds after a run that its fits reached farther.
std::vector<int> tileHalo(const Positions& points, const std::vector<int>& core, float margin);

/// The finite points of `other` (another scan of the same object, registered) inside the
/// bounding box of `tile`'s core (points of `cloud`) grown by `margin` on each side, as indices
/// into `other` in increasing order: what a stage that reads several scans sees beside a tile.
std::vector<int> pointsAroundTile(const Positions& cloud, const Tile& tile, const Positions& other, float margin);

/// `progress` with its stage names prefixed "tile t/n: " (t from 1), as runSortedInTiles
/// reports; empty when `progress` is.
ProgressCallback tileProgress(const ProgressCallback& progress, std::size_t tile, std::size_t tiles);

/// A point-moving stage run tile by tile (one after the other: the working memory is one
/// tile's): `stage(points, movable, tile_number)` gets a tile's core then halo positions and
/// their movable flags, and returns one position per point; the outputs of the core points
/// are kept, non-finite points pass through. `movable` empty means all.
using TileStage = std::function<Positions(const Positions&, const std::vector<std::uint8_t>&, std::size_t)>;
Positions runInTiles(const Positions& points, const std::vector<std::uint8_t>& movable,
                     const std::vector<Tile>& tiles, const TileStage& stage);

/// A stage of runSortedInTiles: a tile's points in spatial order (spatialOrderAll, as
/// runInSpatialOrder gives them) and their movable flags (empty: all), the tile's number and
/// progress;
/// returns one position per point and may set `status` to one byte per point (the stage's
/// own codes: moved, isolated, ...) or leave it empty.
using SortedTileStage = std::function<Positions(const Positions& sorted, const std::vector<std::uint8_t>& movable,
                                                std::vector<std::uint8_t>& status, std::size_t tile,
                                                const ProgressCallback& progress)>;

/// runInTiles for the stages that run in spatial order (every point-moving stage of PAPS):
/// each tile is put in spatial order, its stage names are prefixed "tile t/n: " in the
/// progress, and two kinds of tile are left as they are, their stage not run: one none of
/// whose core points may move, and one whose finite points all stand at one position (a pile
/// of copies larger than a tile, which cannot be cut; the stages leave such a cloud as it is
/// too). `status`, when given, gets one byte per point of the cloud: the stage's status of
/// each core point, `pile_status` for the core of a pile, 0 for a tile none of whose points may
/// move, for non-finite points and where the stage set none. `largest_tile`, when given, gets
/// the most points a tile held, halo included.
Positions runSortedInTiles(const Positions& points, const std::vector<std::uint8_t>& movable,
                           const std::vector<Tile>& tiles, const SortedTileStage& stage,
                           const ProgressCallback& progress = {}, std::vector<std::uint8_t>* status = nullptr,
                           std::uint8_t pile_status = 0, std::size_t* largest_tile = nullptr);

/// An axis-aligned box (empty: lo above hi).
struct BoundingBox {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = Eigen::Vector3f::Constant(-INFINITY);
  void add(const Eigen::Vector3f& p) { lo = lo.cwiseMin(p); hi = hi.cwiseMax(p); }
  /// Distance from p to the box (0 inside).
  float distance(const Eigen::Vector3f& p) const { return (lo - p).cwiseMax(p - hi).cwiseMax(0.f).norm(); }
};
/// The box of points[ids] (of a tile's core, say).
BoundingBox boundingBox(const Positions& points, const std::vector<int>& ids);

/// The points within `margin` of `box`, in order: for a stage run tile by tile that keeps its
/// output spaced across the seams, what the tiles before made near this one.
Positions pointsNearBox(const Positions& points, const BoundingBox& box, float margin);

/// `total` split over parts in proportion to `weights` (largest remainders, ties to the first
/// part); all zero when the weights sum to 0.
std::vector<std::size_t> splitInProportion(std::size_t total, const std::vector<std::size_t>& weights);

/// Cells of a grid of side `cell` (metres, lattice of its multiples) holding a point of `ids`:
/// the surface those points cover, up to a factor of its orientation. An upsampling stage
/// gives each tile its share of the output by it: one piece spreads the output evenly over the
/// surface, and a share per input point would crowd the densely sampled tiles (a scan's near
/// field, a wire).
std::size_t occupiedCells(const Positions& points, const std::vector<int>& ids, float cell);

/// An upsampling stage run tile by tile, each with its share of the output (`shares`, one per
/// tile): `run(t, count)` appends `count` points made from tile t and returns true, or appends
/// nothing and returns false when the tile holds no surface (lines, piles of copies); its
/// share then goes to the next tile. When the last tiles hold none, `undo(t)` drops what the
/// last tile t that made any appended, and that tile runs again with their shares too, so the
/// total is always sum(shares). Returns the tiles that made output, in order (empty: none did).
std::vector<std::size_t> runTileShares(const std::vector<std::size_t>& shares,
                                       const std::function<bool(std::size_t, std::size_t)>& run,
                                       const std::function<void(std::size_t)>& undo);

}  // namespace paps
