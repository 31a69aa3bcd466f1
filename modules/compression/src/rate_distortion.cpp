#include <paps/compression/rate_distortion.h>

#include <algorithm>
#include <cmath>


#include <paps/core/error.h>
#include <paps/core/local_frame.h>
#include <paps/core/neighbourhood.h>

namespace paps::compression {
namespace {
Positions finiteOnly(const Positions& p) {
  Positions out;
  out.reserve(p.size());
  for (const auto& x : p)
    if (isFinite(x)) out.push_back(x);
  return out;
}
double psnr(double peak, double mse) { return mse > 0 ? 10.0 * std::log10(peak * peak / mse) : 999.0; }
}  // namespace

struct PreparedReference::Data {
  Positions ref;
  std::unique_ptr<SpatialIndex> index;
  Normals normals;
};

PreparedReference::PreparedReference(const Positions& reference_in, int normal_neighbours) : d_(new Data) {
  d_->ref = finiteOnly(reference_in);
  const Positions& ref = d_->ref;
  if (ref.size() < 3) throw InvalidInput("comparing clouds needs 3 finite points in each");
  d_->index = std::make_unique<SpatialIndex>(ref);
  const long nr = long(ref.size());
  d_->normals.resize(ref.size());
#pragma omp parallel
  {
    std::vector<int> nb;
    std::vector<float> d2;
#pragma omp for schedule(static)
    for (long i = 0; i < nr; ++i) {
      const int c = d_->index->nearestK(ref[i], int(std::min<long>(normal_neighbours, nr)), nb, d2);
      d_->normals[i] = pcaNormal(ref, nb.data(), c);
    }
  }
}

PreparedReference::~PreparedReference() = default;

CloudErrors PreparedReference::compare(const Positions& decoded_in, double tolerance) const {
  const Positions& ref = d_->ref;
  const Positions dec = finiteOnly(decoded_in);
  if (dec.size() < 3) throw InvalidInput("comparing clouds needs 3 finite points in each");
  const SpatialIndex& ri = *d_->index;
  const Normals& rn = d_->normals;
  SpatialIndex di(dec);
  const long nr = long(ref.size()), nd = long(dec.size());
  double a1 = 0, a2 = 0, b1 = 0, b2 = 0;
  std::size_t above = 0;
#pragma omp parallel
  {
    std::vector<int> nb;
    std::vector<float> d2;
#pragma omp for schedule(static) reduction(+ : a1, a2, above)
    for (long i = 0; i < nr; ++i) {  // reference -> decoded
      const int c = di.nearestK(ref[i], int(std::min<long>(8, nd)), nb, d2);
      const Eigen::Vector3f e = ref[i] - dec[nb[0]];
      a1 += e.squaredNorm();
      const double p = isFinite(rn[i]) ? e.dot(rn[i]) : e.norm();  // degenerate patch: point-to-point
      a2 += p * p;
      Eigen::Vector3f centroid;
      const Eigen::Vector3f n = pcaNormal(dec, nb.data(), c, &centroid);
      const double dist = isFinite(n) ? std::abs((ref[i] - centroid).dot(n)) : std::sqrt(d2[0]);
      above += dist > tolerance;
    }
#pragma omp for schedule(static) reduction(+ : b1, b2)
    for (long i = 0; i < nd; ++i) {  // decoded -> reference
      ri.nearestK(dec[i], 1, nb, d2);
      const Eigen::Vector3f e = dec[i] - ref[nb[0]];
      b1 += e.squaredNorm();
      const double p = isFinite(rn[nb[0]]) ? e.dot(rn[nb[0]]) : e.norm();
      b2 += p * p;
    }
  }
  CloudErrors r;
  r.peak = boundingBoxDiagonal(ref);
  const double mse1 = std::max(a1 / nr, b1 / nd), mse2 = std::max(a2 / nr, b2 / nd);
  r.d1_rmse = std::sqrt(mse1);
  r.d2_rmse = std::sqrt(mse2);
  r.d1_psnr = psnr(r.peak, mse1);
  r.d2_psnr = psnr(r.peak, mse2);
  r.share_above_tolerance = double(above) / double(nr);
  return r;
}

CloudErrors compareClouds(const Positions& reference, const Positions& decoded, double tolerance,
                          int normal_neighbours) {
  if (finiteOnly(decoded).size() < 3) throw InvalidInput("comparing clouds needs 3 finite points in each");
  return PreparedReference(reference, normal_neighbours).compare(decoded, tolerance);
}

}  // namespace paps::compression
