#pragma once
// Direct readers of the x y z of PCD and PLY files, without PCL: no whole-cloud copies, so a
// reader's peak memory stays near the cloud's own 12 bytes per point (the lean `paps-codec`
// binary and `paps compress` use them). Headers are parsed and checked against the file's
// size by readPcdLayout / readPlyLayout first; every error is an IoError naming the file.
#include <string>

#include <paps/core/positions.h>

namespace paps {

/// Reads the x y z of a binary or binary_compressed PCD file whose x, y and z are 4-byte float
/// fields of count 1 into `out`. Returns false, reading nothing, for another layout (ascii
/// data, other types, another extension): the caller then uses a general reader.
bool readPcdXyz(const std::string& path, Positions& out);

/// Reads the vertex x y z (float or double) of an ascii or binary_little_endian PLY file
/// whose first element is the vertices; other vertex properties are skipped and later
/// elements (faces) are not read. Returns false, reading nothing, for another layout.
bool readPlyXyz(const std::string& path, Positions& out);

}  // namespace paps
