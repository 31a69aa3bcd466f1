#pragma once
#include <paps/core/error.h>
#include <paps/surface/quadric_super_resolution.h>

namespace paps {

template <typename PointIn, typename PointOut>
void QuadricSuperResolution<PointIn, PointOut>::performProcessing(pcl::PointCloud<PointOut>& output) {
  if (this->input_->empty()) throw InvalidInput("the input cloud is empty");
  std::vector<Positions> scans(1);
  scans[0].reserve(this->indices_->size());
  for (const auto i : *this->indices_) scans[0].push_back((*this->input_)[i].getVector3fMap());
  for (const auto& s : extra_) {
    if (!s) throw InvalidInput("a null scan was added");
    scans.push_back(positionsOf(*s));
  }
  writePositions(superResolveQuadric(scans, params_, &report_, progress_), output);
}

}  // namespace paps
