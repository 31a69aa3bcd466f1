#pragma once
// Lossless coding of quantized 3-D positions by recursive halving of a kd-tree cell, in the
// spirit of Devillers and Gandoin (2000): the number of points in the first half of each
// non-empty cell is range-coded given the number in the cell, until cells are single voxels.
#include <array>
#include <cstdint>
#include <vector>

namespace paps::compression {

using VoxelCoordinate = std::array<std::uint32_t, 3>;

/// Codes distinct voxels of a 2^bits grid (bits in [1, 21]); `voxels` is reordered into the
/// order the decoder returns them in. Duplicates must have been removed.
std::vector<std::uint8_t> encodeVoxels(std::vector<VoxelCoordinate>& voxels, int bits);

/// Decodes `count` voxels; throws CorruptStream when the data are inconsistent.
std::vector<VoxelCoordinate> decodeVoxels(const std::vector<std::uint8_t>& payload, std::size_t count, int bits);

}  // namespace paps::compression
