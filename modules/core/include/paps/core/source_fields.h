#pragma once
// Fields an upsampling stage carries from an input point to the new points made from it.
#include <cstddef>
#include <vector>

#include <pcl/common/copy_point.h>
#include <pcl/point_cloud.h>
#include <pcl/types.h>

#include <paps/core/error.h>

namespace paps {

/// Resizes `output` to `source.size()` points, each a copy of the fields it shares with
/// input[indices[source[q]]] (colour, intensity, label...), as PCL's MLS copies them to its
/// new points. The caller writes x, y, z, normals and curvature after. Throws InvalidParameter
/// for a source index outside `indices`.
template <typename PointIn, typename PointOut>
void copySourceFields(const pcl::PointCloud<PointIn>& input, const pcl::Indices& indices,
                      const std::vector<int>& source, pcl::PointCloud<PointOut>& output) {
  output.resize(source.size());
  for (std::size_t q = 0; q < source.size(); ++q) {
    const int s = source[q];
    if (s < 0 || static_cast<std::size_t>(s) >= indices.size())
      throw InvalidParameter("source", detail::toString(s), "an index of the input's indices");
    pcl::copyPoint(input[static_cast<std::size_t>(indices[static_cast<std::size_t>(s)])], output[q]);
  }
}

}  // namespace paps
