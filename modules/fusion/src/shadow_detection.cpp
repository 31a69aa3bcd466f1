#include <paps/fusion/shadow_detection.h>
#include <paps/fusion/impl/shadow_detection.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <string>

#include <boost/graph/compressed_sparse_row_graph.hpp>
#include <boost/graph/boykov_kolmogorov_max_flow.hpp>
#include <opencv2/imgproc.hpp>

#include <paps/core/error.h>
#include <paps/core/neighbourhood.h>
#include <paps/fusion/colour_space.h>

namespace paps {

void ShadowDetectionParameters::validate() const {
  requireInRange("neighbours", neighbours, 4, 128);
  if (!(max_reflectance_change > 0 && max_reflectance_change <= 1))
    throw InvalidParameter("max_reflectance_change", detail::toString(max_reflectance_change), "a value in (0, 1]");
  if (!(same_reflectance > 0 && same_reflectance <= 1))
    throw InvalidParameter("same_reflectance", detail::toString(same_reflectance), "a value in (0, 1]");
  if (!(min_lightness_change > 0 && min_lightness_change <= 100))
    throw InvalidParameter("min_lightness_change", detail::toString(min_lightness_change), "a value in (0, 100]");
  if (!(max_chromaticity_difference > 0 && max_chromaticity_difference <= 1))
    throw InvalidParameter("max_chromaticity_difference", detail::toString(max_chromaticity_difference),
                           "a value in (0, 1]");
  if (!(max_normal_angle_deg > 0 && max_normal_angle_deg <= 180))
    throw InvalidParameter("max_normal_angle_deg", detail::toString(max_normal_angle_deg), "a value in (0, 180]");
  requireInRange("min_interface_fraction", min_interface_fraction, 0.f, 1.f);
  requireInRange("histogram_neighbours", histogram_neighbours, 8, 1024);
  requireInRange("histogram_bins", histogram_bins, 4, 256);
  requireInRange("min_bimodality", min_bimodality, 0.f, 1.f);
  requireInRange("min_mode_fraction", min_mode_fraction, 0.f, 0.5f);
  requireNonNegative("sigma", sigma, "half of L_L - L_S");
  if (sigma > 1000) throw InvalidParameter("sigma", detail::toString(sigma), "0 (automatic) or a value up to 1000");
  requireInRange("gamma", gamma, 0.f, 100.f);
  requireInRange("min_pairs_per_view", min_pairs_per_view, 1, 1000000);
  requireInRange("min_view_contrast", min_view_contrast, 0.f, 100.f);
  if (!(graph_cut_scale > 0 && graph_cut_scale <= 1))
    throw InvalidParameter("graph_cut_scale", detail::toString(graph_cut_scale), "a value in (0, 1]");
  requireInRange("max_graph_cut_pixels", max_graph_cut_pixels, 64, 100000000);
  visibility.validate();
}

namespace {

float lightnessOf(const Eigen::Vector3f& rgb) { return colour::lightnessOfLuminance(colour::luminance(rgb)); }

// L* of every pixel of a CV_8UC3 BGR image, CV_32F.
cv::Mat lightnessImage(const cv::Mat& bgr8) {
  float table[256];
  for (int v = 0; v < 256; ++v) table[v] = v / 255.f;
  cv::Mat l(bgr8.rows, bgr8.cols, CV_32F);
  for (int r = 0; r < bgr8.rows; ++r)
    for (int c = 0; c < bgr8.cols; ++c) {
      const cv::Vec3b& p = bgr8.at<cv::Vec3b>(r, c);
      l.at<float>(r, c) = lightnessOf(Eigen::Vector3f(table[p[2]], table[p[1]], table[p[0]]));
    }
  return l;
}

float bilinear(const cv::Mat& f, const Eigen::Vector2f& pixel) {
  const float x = std::clamp(pixel.x(), 0.f, float(f.cols - 1)), y = std::clamp(pixel.y(), 0.f, float(f.rows - 1));
  const int x0 = std::min(int(x), f.cols - 1), y0 = std::min(int(y), f.rows - 1);
  const int x1 = std::min(x0 + 1, f.cols - 1), y1 = std::min(y0 + 1, f.rows - 1);
  const float fx = x - x0, fy = y - y0;
  return (1 - fy) * ((1 - fx) * f.at<float>(y0, x0) + fx * f.at<float>(y0, x1)) +
         fy * ((1 - fx) * f.at<float>(y1, x0) + fx * f.at<float>(y1, x1));
}

float median(std::vector<float> v) {
  if (v.empty()) return NAN;
  const std::size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(h), v.end());
  const float upper = v[h];
  if (v.size() % 2) return upper;
  return 0.5f * (upper + *std::max_element(v.begin(), v.begin() + std::ptrdiff_t(h)));
}

// Otsu on a histogram: the bin index t splitting [0, t) / [t, bins), the between-class over
// the total variance, the share of the lower class.
struct OtsuSplit {
  int threshold = 0;
  double separability = 0, lower_share = 0;
};
OtsuSplit otsu(const std::vector<double>& histogram) {
  double total = 0, sum = 0, sum2 = 0;
  for (std::size_t b = 0; b < histogram.size(); ++b) {
    total += histogram[b];
    sum += b * histogram[b];
    sum2 += double(b) * b * histogram[b];
  }
  OtsuSplit best;
  if (!(total > 0)) return best;
  const double mean = sum / total, variance = sum2 / total - mean * mean;
  double w0 = 0, s0 = 0, best_between = -1;
  for (std::size_t t = 1; t < histogram.size(); ++t) {
    w0 += histogram[t - 1];
    s0 += (t - 1) * histogram[t - 1];
    const double w1 = total - w0;
    if (w0 <= 0 || w1 <= 0) continue;
    const double m0 = s0 / w0, m1 = (sum - s0) / w1;
    const double between = w0 * w1 / (total * total) * (m0 - m1) * (m0 - m1);
    if (between > best_between) {
      best_between = between;
      best.threshold = static_cast<int>(t);
      best.lower_share = w0 / total;
    }
  }
  best.separability = variance > 0 ? std::max(0.0, best_between) / variance : 0;
  return best;
}

// 0..5: the dominant axis of a normal and its sign (+x, -x, +y, -y, +z, -z).
int orientationClass(const Eigen::Vector3f& n) {
  int axis = 0;
  n.cwiseAbs().maxCoeff(&axis);
  return 2 * axis + (n[axis] < 0);
}

// The reflectance (channel 0) and orientation class (channel 1, -1: none) of the points a photo
// sees, splatted onto its pixels (mean reflectance, class of the last point in index order),
// then spread 3 times into empty pixels from their 8 neighbours: the scan is sparser than the
// image.
cv::Mat reflectanceImage(const ProjectedPoints& projected, const std::vector<float>& reflectance,
                         const Normals& normals, const cv::Size& size) {
  cv::Mat sum(size, CV_32F, cv::Scalar(0)), count(size, CV_32F, cv::Scalar(0));
  cv::Mat cls(size, CV_32F, cv::Scalar(-1));
  for (std::size_t i = 0; i < projected.visible.size(); ++i) {
    if (!projected.visible[i]) continue;
    const int c = std::clamp(int(std::lround(projected.pixel[i].x())), 0, size.width - 1);
    const int r = std::clamp(int(std::lround(projected.pixel[i].y())), 0, size.height - 1);
    sum.at<float>(r, c) += reflectance[i];
    count.at<float>(r, c) += 1;
    cls.at<float>(r, c) = float(orientationClass(normals[i]));
  }
  cv::Mat out(size, CV_32FC2, cv::Scalar(0, -1));
  for (int r = 0; r < size.height; ++r)
    for (int c = 0; c < size.width; ++c)
      if (count.at<float>(r, c) > 0) out.at<cv::Vec2f>(r, c) = {sum.at<float>(r, c) / count.at<float>(r, c), cls.at<float>(r, c)};
  for (int pass = 0; pass < 3; ++pass) {
    cv::Mat next = out.clone();
    for (int r = 0; r < size.height; ++r)
      for (int c = 0; c < size.width; ++c) {
        if (out.at<cv::Vec2f>(r, c)[1] >= 0) continue;
        float s = 0, k = 0, o = -1;
        for (int dr = -1; dr <= 1; ++dr)
          for (int dc = -1; dc <= 1; ++dc) {
            const int rr = r + dr, cc = c + dc;
            if (rr < 0 || cc < 0 || rr >= size.height || cc >= size.width) continue;
            const cv::Vec2f q = out.at<cv::Vec2f>(rr, cc);
            if (q[1] < 0) continue;
            s += q[0];
            k += 1;
            if (o < 0) o = q[1];
          }
        if (k > 0) next.at<cv::Vec2f>(r, c) = {s / k, o};
      }
    out = next;
  }
  return out;
}

}  // namespace

cv::Mat segmentShadowsGraphCut(const cv::Mat& bgr8, float shadow_lightness, float lit_lightness, float sigma,
                               float gamma, double* energy) {
  if (bgr8.empty()) throw InvalidInput("shadow graph cut: the image is empty");
  if (bgr8.type() != CV_8UC3) throw InvalidInput("shadow graph cut: the image must be CV_8UC3");
  requirePositive("sigma", sigma);
  const cv::Mat l = lightnessImage(bgr8);
  return segmentShadowsGraphCut(l, cv::Mat(l.size(), CV_32F, cv::Scalar(shadow_lightness)),
                                cv::Mat(l.size(), CV_32F, cv::Scalar(lit_lightness)),
                                cv::Mat(l.size(), CV_32F, cv::Scalar(sigma)), sigma, gamma, energy);
}

cv::Mat segmentShadowsGraphCut(const cv::Mat& l, const cv::Mat& shadow_lightness, const cv::Mat& lit_lightness,
                               const cv::Mat& data_sigma, float sigma, float gamma, double* energy) {
  if (l.empty() || l.type() != CV_32F) throw InvalidInput("shadow graph cut: the lightness image must be CV_32F, not empty");
  for (const cv::Mat* m : {&shadow_lightness, &lit_lightness, &data_sigma})
    if (m->size() != l.size() || m->type() != CV_32F)
      throw InvalidInput("shadow graph cut: L_S, L_L and sigma images must be CV_32F of the lightness image's size");
  requirePositive("sigma", sigma);
  requireInRange("gamma", gamma, 0.f, 100.f);
  // A compressed sparse row graph with 32-bit vertex and edge indices and the flow's maps in
  // plain arrays: about 300 bytes per pixel at the peak (an adjacency_list took 650).
  using Graph = boost::compressed_sparse_row_graph<boost::directedS, boost::no_property, boost::no_property,
                                                   boost::no_property, std::uint32_t, std::uint32_t>;
  using Edge = boost::graph_traits<Graph>::edge_descriptor;
  const int rows = l.rows, cols = l.cols;
  const std::size_t pixels = std::size_t(rows) * std::size_t(cols);
  if (pixels + 2 > std::size_t(std::numeric_limits<std::uint32_t>::max() / 8))
    throw InvalidInput("shadow graph cut: the image is too large (use graph_cut_scale)");
  const std::uint32_t source = std::uint32_t(pixels), sink = std::uint32_t(pixels + 1);
  // Integer capacities (energies times 1e4): the max flow is exact and the same everywhere.
  constexpr double kScale = 1e4;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> ends;
  std::vector<std::int64_t> given;  // capacity of each edge of `ends`, in the same order
  ends.reserve(pixels * 6);
  given.reserve(pixels * 6);
  auto addPair = [&](std::uint32_t a, std::uint32_t b, double ab, double ba) {
    ends.emplace_back(a, b);
    given.push_back(std::llround(ab * kScale));
    ends.emplace_back(b, a);
    given.push_back(std::llround(ba * kScale));
  };
  const double k = 1.0 / (2.0 * double(sigma) * sigma);
  double constant = 0;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const std::uint32_t p = std::uint32_t(std::size_t(r) * cols + c);
      const double lp = l.at<float>(r, c);
      // Source side = lit (delta 0): cutting p -> sink pays E_data(lit); source -> p pays E_data(shadow).
      const double ls = shadow_lightness.at<float>(r, c), ll = lit_lightness.at<float>(r, c);
      const double sd = std::max(1e-3f, data_sigma.at<float>(r, c)), kd = 1.0 / (2 * sd * sd);
      const double lit_cost = std::exp(-kd * (lp - ls) * (lp - ls));
      const double shadow_cost = std::exp(-kd * (lp - ll) * (lp - ll));
      // Only the difference of the two data costs needs an edge; the common part is a
      // constant of the energy.
      constant += std::min(lit_cost, shadow_cost);
      if (shadow_cost > lit_cost) addPair(source, p, shadow_cost - lit_cost, 0);
      else if (lit_cost > shadow_cost) addPair(p, sink, lit_cost - shadow_cost, 0);
      if (gamma > 0) {
        if (c + 1 < cols) {
          const double d = lp - l.at<float>(r, c + 1), w = gamma * std::exp(-k * d * d);
          addPair(p, p + 1, w, w);
        }
        if (r + 1 < rows) {
          const double d = lp - l.at<float>(r + 1, c), w = gamma * std::exp(-k * d * d);
          addPair(p, p + std::uint32_t(cols), w, w);
        }
      }
    }
  // Edges sorted by source, stably (each vertex's out-edges keep their order of creation).
  std::vector<std::uint32_t> order(ends.size());
  for (std::uint32_t e = 0; e < order.size(); ++e) order[e] = e;
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return ends[a].first < ends[b].first; });
  std::vector<std::pair<std::uint32_t, std::uint32_t>> sorted(ends.size());
  std::vector<std::int64_t> capacity(ends.size()), residual(ends.size(), 0);
  std::vector<std::uint32_t> source_of_sorted(ends.size());
  for (std::size_t e = 0; e < order.size(); ++e) {
    sorted[e] = ends[order[e]];
    capacity[e] = given[order[e]];
    source_of_sorted[e] = sorted[e].first;
  }
  std::vector<std::pair<std::uint32_t, std::uint32_t>>().swap(ends);
  std::vector<std::int64_t>().swap(given);
  const std::vector<std::uint32_t> order_of_sorted = std::move(order);
  const Graph g(boost::edges_are_sorted, sorted.begin(), sorted.end(), pixels + 2);
  std::vector<std::pair<std::uint32_t, std::uint32_t>>().swap(sorted);
  const auto edge_index = boost::get(boost::edge_index, g);
  // Edges were created in pairs (2k, 2k + 1), each the other's reverse; `slot` says where each
  // landed in the sorted order.
  std::vector<Edge> reverse(boost::num_edges(g));
  {
    std::vector<std::uint32_t> slot(order_of_sorted.size());
    for (std::uint32_t e = 0; e < order_of_sorted.size(); ++e) slot[order_of_sorted[e]] = e;
    for (std::uint32_t k = 0; k + 1 < slot.size(); k += 2) {
      const std::uint32_t a = slot[k], b = slot[k + 1];
      reverse[a] = Edge(source_of_sorted[b], b);
      reverse[b] = Edge(source_of_sorted[a], a);
    }
  }
  std::vector<boost::default_color_type> colour(pixels + 2);
  std::vector<std::int64_t> distance(pixels + 2, 0);
  std::vector<Edge> predecessor(pixels + 2);
  const auto vertex_index = boost::get(boost::vertex_index, g);
  const std::int64_t flow = boost::boykov_kolmogorov_max_flow(
      g, boost::make_iterator_property_map(capacity.begin(), edge_index),
      boost::make_iterator_property_map(residual.begin(), edge_index),
      boost::make_iterator_property_map(reverse.begin(), edge_index),
      boost::make_iterator_property_map(predecessor.begin(), vertex_index),
      boost::make_iterator_property_map(colour.begin(), vertex_index),
      boost::make_iterator_property_map(distance.begin(), vertex_index), vertex_index, source, sink);
  if (energy) *energy = constant + double(flow) / kScale;
  const auto source_colour = colour[source];
  cv::Mat mask(rows, cols, CV_8U);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c)
      mask.at<std::uint8_t>(r, c) = colour[std::size_t(r) * cols + c] == source_colour ? 0 : 255;
  return mask;
}

std::vector<std::uint8_t> shadowLabelsByOtsu(const std::vector<Eigen::Vector3f>& colours) {
  std::vector<double> histogram(256, 0);
  std::vector<int> bin(colours.size(), -1);
  for (std::size_t i = 0; i < colours.size(); ++i) {
    const float l = lightnessOf(colours[i]);
    if (!std::isfinite(l)) continue;
    bin[i] = std::clamp(int(l * 2.55f), 0, 255);
    histogram[bin[i]] += 1;
  }
  const OtsuSplit s = otsu(histogram);
  std::vector<std::uint8_t> labels(colours.size(), 0);
  for (std::size_t i = 0; i < colours.size(); ++i) labels[i] = bin[i] >= 0 && bin[i] < s.threshold;
  return labels;
}

ShadowDetectionResult detectShadows(const Positions& points, const Normals& normals,
                                    const std::vector<Eigen::Vector3f>& colours, const std::vector<float>& reflectance,
                                    const std::vector<RegisteredPhoto>& photos, const ShadowDetectionParameters& params,
                                    const ProgressCallback& progress) {
  params.validate();
  const std::size_t n = points.size();
  if (n == 0) throw InvalidInput("shadow detection: the input cloud is empty");
  auto requireSize = [&](const char* name, std::size_t size) {
    if (size != n)
      throw InvalidParameter(name, detail::toString(size), "one per point (" + detail::toString(n) + ")");
  };
  requireSize("normals", normals.size());
  requireSize("colours", colours.size());
  requireSize("reflectance", reflectance.size());
  if (photos.empty()) throw InvalidInput("shadow detection: no photo");
  for (std::size_t v = 0; v < photos.size(); ++v) photos[v].validate(("photo " + std::to_string(v)).c_str());

  ShadowDetectionResult result;
  // Usable points: finite position, normal, colour and reflectance.
  Positions usable(n, Eigen::Vector3f::Constant(NAN));
  std::vector<float> lightness(n, NAN);
  for (std::size_t i = 0; i < n; ++i) {
    if (isFinite(points[i]) && isFinite(normals[i]) && normals[i].norm() > 0.5f && colours[i].allFinite() &&
        std::isfinite(reflectance[i])) {
      usable[i] = points[i];
      lightness[i] = lightnessOf(colours[i]);
    } else {
      ++result.non_finite;
    }
  }
  if (result.non_finite == n) throw InvalidInput("shadow detection: no finite point in the cloud (all NaN or Inf)");
  // Only points some photo sees have a colour from the photos: the others (under cars, behind
  // posts) keep whatever colour they had and would make false interfaces.
  std::vector<ProjectedPoints> projections;
  std::vector<std::uint8_t> seen(n, 0);
  for (const auto& photo : photos) {
    projections.push_back(projectVisiblePoints(usable, photo.camera, photo.pose, params.visibility));
    for (std::size_t i = 0; i < n; ++i) seen[i] |= projections.back().visible[i];
  }
  for (std::size_t i = 0; i < n; ++i)
    if (!seen[i] && isFinite(usable[i])) {
      usable[i] = Eigen::Vector3f::Constant(NAN);
      ++result.unseen;
    }
  std::vector<Eigen::Vector2f> chromaticity(n, Eigen::Vector2f::Constant(1.f / 3));
  for (std::size_t i = 0; i < n; ++i) {
    const float sum = colours[i].sum();
    if (sum > 1e-3f) chromaticity[i] = colours[i].head<2>() / sum;
  }
  ProgressReporter rep(progress, "shadow detection", n * 3 + photos.size() * 100);

  const SpatialIndex index(usable);
  const NeighbourGraph knn = NeighbourGraph::byCount(usable, index, params.neighbours + 1);
  const float cos_max = std::cos(params.max_normal_angle_deg * float(M_PI) / 180.f);
  auto sameSurface = [&](std::size_t i, std::size_t j) {
    return normals[i].dot(normals[j]) >= cos_max * normals[i].norm() * normals[j].norm() &&
           std::abs(reflectance[i] - reflectance[j]) <= params.same_reflectance;
  };

  // (a) Gradients in the tangent plane and the pair partner of every candidate.
  std::vector<int> partner(n, -1);
#pragma omp parallel for schedule(dynamic, 256)
  for (std::int64_t ii = 0; ii < std::int64_t(n); ++ii) {
    const std::size_t i = std::size_t(ii);
    if (!isFinite(usable[i]) || knn.count(i) < 4) continue;
    const Eigen::Vector3f nrm = normals[i].normalized();
    Eigen::Vector3f u = nrm.unitOrthogonal(), w = nrm.cross(u);
    Eigen::Matrix2f a = Eigen::Matrix2f::Zero();
    Eigen::Vector2f bl = Eigen::Vector2f::Zero(), br = Eigen::Vector2f::Zero();
    float radius = 0;
    for (const int* j = knn.begin(i); j != knn.end(i); ++j) {
      if (*j == int(i)) continue;
      const Eigen::Vector3f d = usable[*j] - usable[i];
      const Eigen::Vector2f t(d.dot(u), d.dot(w));
      a += t * t.transpose();
      bl += t * (lightness[*j] - lightness[i]);
      br += t * (reflectance[*j] - reflectance[i]);
      radius = std::max(radius, d.norm());
    }
    if (std::abs(a.determinant()) < 1e-12f * std::pow(a.trace(), 2)) continue;  // collinear
    const Eigen::Matrix2f inv = a.inverse();
    const float lightness_change = (inv * bl).norm() * radius, reflectance_change = (inv * br).norm() * radius;
    if (!(reflectance_change < params.max_reflectance_change) || !(lightness_change > params.min_lightness_change))
      continue;
    int best = -1;
    float best_difference = params.min_lightness_change;
    for (const int* j = knn.begin(i); j != knn.end(i); ++j) {
      if (*j == int(i) || !sameSurface(i, std::size_t(*j)) ||
          (chromaticity[*j] - chromaticity[i]).norm() > params.max_chromaticity_difference)
        continue;
      const float difference = std::abs(lightness[*j] - lightness[i]);
      if (difference > best_difference) {
        best_difference = difference;
        best = *j;
      }
    }
    partner[i] = best;
  }
  for (std::size_t i = 0; i < n; ++i)
    if (partner[i] >= 0) result.candidates.push_back(int(i));
  rep.advance(n);

  // Density filter.
  std::vector<std::uint8_t> dense(n, 0);
#pragma omp parallel for schedule(static)
  for (std::int64_t ii = 0; ii < std::int64_t(n); ++ii) {
    const std::size_t i = std::size_t(ii);
    if (partner[i] < 0) continue;
    int others = 0;
    for (const int* j = knn.begin(i); j != knn.end(i); ++j) others += *j != int(i) && partner[*j] >= 0;
    dense[i] = others >= params.min_interface_fraction * float(knn.count(i) - 1);
  }
  std::vector<std::pair<int, int>> pairs;
  for (std::size_t i = 0; i < n; ++i) {
    if (!dense[i]) continue;
    result.dense_candidates.push_back(int(i));
    const int j = partner[i];
    const std::pair<int, int> p = lightness[i] < lightness[j] ? std::make_pair(int(i), j) : std::make_pair(j, int(i));
    pairs.push_back(p);
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  result.pairs_before_histogram = pairs.size();
  rep.advance(n);
  rep.throwIfCancelled();

  // (b) Bimodal L* histogram around each pair.
  std::vector<std::uint8_t> keep(pairs.size(), 0);
  const int bins = params.histogram_bins;
#pragma omp parallel for schedule(dynamic, 16)
  for (std::int64_t k = 0; k < std::int64_t(pairs.size()); ++k) {
    const auto [dark, bright] = pairs[std::size_t(k)];
    const Eigen::Vector3f mid = 0.5f * (usable[dark] + usable[bright]);
    std::vector<int> around;
    std::vector<float> d2;
    index.nearestK(mid, params.histogram_neighbours, around, d2);
    std::vector<double> histogram(std::size_t(bins), 0);
    auto binOf = [&](float l) { return std::clamp(int(l / 100.f * bins), 0, bins - 1); };
    for (const int j : around)
      if (sameSurface(std::size_t(dark), std::size_t(j))) histogram[binOf(lightness[j])] += 1;
    const OtsuSplit s = otsu(histogram);
    keep[k] = s.separability >= params.min_bimodality && s.lower_share >= params.min_mode_fraction &&
              1 - s.lower_share >= params.min_mode_fraction && binOf(lightness[dark]) < s.threshold &&
              binOf(lightness[bright]) >= s.threshold;
  }
  for (std::size_t k = 0; k < pairs.size(); ++k)
    if (keep[k]) result.interface_pairs.push_back(pairs[k]);
  rep.advance(n);
  rep.throwIfCancelled();

  // (c) Graph cut in every photo, votes back onto the points.
  std::vector<int> shadow_votes(n, 0), lit_votes(n, 0);
  result.views.resize(photos.size());
  for (std::size_t v = 0; v < photos.size(); ++v) {
    const RegisteredPhoto& photo = photos[v];
    ShadowView& view = result.views[v];
    const ProjectedPoints& projected = projections[v];
    const cv::Mat l = lightnessImage(photo.image);
    std::vector<float> dark_l, bright_l;
    std::vector<int> pair_class;
    std::vector<float> pair_kappa, pair_rho;  // lit luminance over reflectance; shadow over lit luminance
    for (const auto& [dark, bright] : result.interface_pairs) {
      if (!projected.visible[dark] || !projected.visible[bright]) continue;
      dark_l.push_back(bilinear(l, projected.pixel[dark]));
      bright_l.push_back(bilinear(l, projected.pixel[bright]));
      const float y_dark = colour::luminanceOfLightness(dark_l.back());
      const float y_bright = colour::luminanceOfLightness(bright_l.back());
      const float refl = 0.5f * (reflectance[dark] + reflectance[bright]);
      pair_class.push_back(orientationClass(normals[dark]));
      pair_kappa.push_back(refl > 0.02f && y_bright > 0 ? y_bright / refl : NAN);
      pair_rho.push_back(y_bright > 0 ? y_dark / y_bright : NAN);
    }
    view.pairs_seen = dark_l.size();
    if (dark_l.size() < std::size_t(params.min_pairs_per_view)) continue;
    view.shadow_lightness = median(dark_l);
    view.lit_lightness = median(bright_l);
    if (!(view.lit_lightness - view.shadow_lightness >= std::max(params.min_view_contrast, 1e-3f))) continue;
    view.sigma = params.sigma > 0 ? params.sigma : 0.5f * (view.lit_lightness - view.shadow_lightness);
    cv::Mat ls(l.size(), CV_32F, cv::Scalar(view.shadow_lightness));
    cv::Mat ll(l.size(), CV_32F, cv::Scalar(view.lit_lightness));
    cv::Mat data_sigma(l.size(), CV_32F, cv::Scalar(view.sigma));
    if (params.reflectance_guided) {
      // Per orientation class (and over all pairs where a class has too few): kappa, rho.
      auto finiteMedian = [](std::vector<float> v) {
        v.erase(std::remove_if(v.begin(), v.end(), [](float x) { return !std::isfinite(x); }), v.end());
        return median(std::move(v));
      };
      const float kappa_all = finiteMedian(pair_kappa), rho_all = finiteMedian(pair_rho);
      float kappa[6], rho[6];
      for (int o = 0; o < 6; ++o) {
        std::vector<float> k, r;
        for (std::size_t q = 0; q < pair_class.size(); ++q)
          if (pair_class[q] == o) {
            k.push_back(pair_kappa[q]);
            r.push_back(pair_rho[q]);
          }
        const bool enough = k.size() >= std::size_t(params.min_pairs_per_view);
        kappa[o] = enough ? finiteMedian(k) : kappa_all;
        rho[o] = enough ? finiteMedian(r) : rho_all;
      }
      const cv::Mat guide = reflectanceImage(projected, reflectance, normals, l.size());
      for (int r = 0; r < l.rows; ++r)
        for (int c = 0; c < l.cols; ++c) {
          const cv::Vec2f g = guide.at<cv::Vec2f>(r, c);
          if (!(g[1] >= 0)) continue;
          const int o = int(g[1]);
          if (!std::isfinite(kappa[o]) || !std::isfinite(rho[o]) || !(rho[o] < 1)) continue;
          const float lit = colour::lightnessOfLuminance(kappa[o] * g[0]);
          const float shadow = colour::lightnessOfLuminance(rho[o] * kappa[o] * g[0]);
          ll.at<float>(r, c) = lit;
          ls.at<float>(r, c) = shadow;
          data_sigma.at<float>(r, c) = params.sigma > 0 ? params.sigma : std::max(1.f, 0.5f * (lit - shadow));
        }
    }
    cv::Mat lc = l;
    const double scale = std::min<double>(params.graph_cut_scale,
                                          std::sqrt(double(params.max_graph_cut_pixels) / double(l.total())));
    view.graph_cut_scale = float(std::min(1.0, scale));
    if (scale < 1) {
      const cv::Size size(std::max(1, int(std::lround(l.cols * scale))), std::max(1, int(std::lround(l.rows * scale))));
      cv::resize(l, lc, size, 0, 0, cv::INTER_AREA);
      cv::resize(ls, ls, size, 0, 0, cv::INTER_AREA);
      cv::resize(ll, ll, size, 0, 0, cv::INTER_AREA);
      cv::resize(data_sigma, data_sigma, size, 0, 0, cv::INTER_AREA);
    }
    cv::Mat mask = segmentShadowsGraphCut(lc, ls, ll, data_sigma, view.sigma, params.gamma, &view.energy);
    if (mask.size() != photo.image.size()) cv::resize(mask, mask, photo.image.size(), 0, 0, cv::INTER_NEAREST);
    view.mask = mask;
    view.segmented = true;
    for (std::size_t i = 0; i < n; ++i) {
      if (!projected.visible[i]) continue;
      const int c = std::clamp(int(std::lround(projected.pixel[i].x())), 0, mask.cols - 1);
      const int r = std::clamp(int(std::lround(projected.pixel[i].y())), 0, mask.rows - 1);
      (mask.at<std::uint8_t>(r, c) ? shadow_votes : lit_votes)[i] += 1;
    }
    rep.advance(100);
    rep.throwIfCancelled();
  }

  result.in_shadow.assign(n, 0);
  result.decided.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i)
    if (shadow_votes[i] + lit_votes[i] > 0) {
      result.decided[i] = 2;
      result.in_shadow[i] = shadow_votes[i] > lit_votes[i];
    }
  // Points no segmented photo sees: the majority of their voted neighbours.
  std::vector<std::uint8_t> from_neighbours(n, 0);
  std::vector<std::uint8_t> finite(n, 0);
  for (std::size_t i = 0; i < n; ++i) finite[i] = isFinite(points[i]) && isFinite(normals[i]);
  std::unique_ptr<SpatialIndex> all_index;
  if (result.unseen > 0) {
    Positions finite_points(n, Eigen::Vector3f::Constant(NAN));
    for (std::size_t i = 0; i < n; ++i)
      if (finite[i]) finite_points[i] = points[i];
    all_index = std::make_unique<SpatialIndex>(finite_points);
  }
#pragma omp parallel for schedule(static)
  for (std::int64_t ii = 0; ii < std::int64_t(n); ++ii) {
    const std::size_t i = std::size_t(ii);
    if (result.decided[i] || !finite[i]) continue;
    int shadow = 0, lit = 0;
    std::vector<int> around;
    std::vector<float> d2;
    if (isFinite(usable[i])) {
      around.assign(knn.begin(i), knn.end(i));
    } else if (all_index) {
      all_index->nearestK(points[i], params.neighbours + 1, around, d2);
    }
    for (const int* j = around.data(); j != around.data() + around.size(); ++j)
      if (result.decided[*j] == 2) (result.in_shadow[*j] ? shadow : lit) += 1;
    from_neighbours[i] = shadow + lit == 0 ? 0 : shadow > lit ? 2 : 1;
  }
  for (std::size_t i = 0; i < n; ++i)
    if (from_neighbours[i]) {
      result.decided[i] = 1;
      result.in_shadow[i] = from_neighbours[i] == 2;
    }
  rep.finish();
  return result;
}

template class ShadowDetection<pcl::PointXYZRGBNormal>;

}  // namespace paps
