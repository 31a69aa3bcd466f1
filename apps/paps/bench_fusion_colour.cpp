// paps bench colour (manuscript 4.5): colorization, shadow detection and shadow correction
// on the synthetic street, against the simple alternatives, with the true colours and shadow
// labels the synthetic scene provides.
//  - colorization: RMS error (linear RGB in [0, 1]) to the true colour (exposure * albedo *
//    irradiance, no noise) and to what the photos record without the van and without noise,
//    for ours (occlusion-weighted median + Huber kNN regularisation), the nearest photo alone,
//    the per-point mean and median of the candidates; three photos, a van (not in the scan)
//    in front of the middle one;
//  - shadow detection: accuracy, IoU and balanced accuracy on the points the photos see for
//    ours (reflectance-guided), eq. 4.4 as printed, and one Otsu threshold on L*;
//  - shadow correction (all lit): mean shadow over mean lit luminance of same-albedo points
//    (Y / Y(albedo)), ground and facades, before and after, with the detected and the true labels.
// Texture finer than a pixel (brick courses, mortar) is aliased in every photo: colour errors
// are measured on the points whose 8 nearest neighbours have the same true colour.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

#include <paps/core/neighbourhood.h>
#include <paps/fusion/colour_space.h>
#include <paps/fusion/point_colorization.h>
#include <paps/fusion/shadow_correction.h>
#include <paps/fusion/shadow_detection.h>
#include <paps/fusion/synthetic_street.h>

namespace paps::cli {

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double rmsError(const std::vector<Eigen::Vector3f>& c, const std::vector<Eigen::Vector3f>& truth,
                const std::vector<std::uint8_t>& mask) {
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < c.size(); ++i)
    if (mask[i] && c[i].allFinite()) {
      sum += (c[i] - truth[i]).squaredNorm() / 3;
      ++n;
    }
  return n ? std::sqrt(sum / n) : NAN;
}

struct LabelScore {
  double accuracy = 0, iou = 0, balanced = 0;
};
LabelScore scoreLabels(const std::vector<std::uint8_t>& labels, const std::vector<std::uint8_t>& truth,
                       const std::vector<std::uint8_t>& mask) {
  double tp = 0, tn = 0, fp = 0, fn = 0;
  for (std::size_t i = 0; i < labels.size(); ++i) {
    if (!mask[i]) continue;
    if (truth[i]) (labels[i] ? tp : fn) += 1;
    else (labels[i] ? fp : tn) += 1;
  }
  LabelScore s;
  const double n = tp + tn + fp + fn;
  s.accuracy = n > 0 ? (tp + tn) / n : NAN;
  s.iou = tp + fp + fn > 0 ? tp / (tp + fp + fn) : NAN;
  s.balanced = 0.5 * (tp / std::max(tp + fn, 1.0) + tn / std::max(tn + fp, 1.0));
  return s;
}

// Mean over shadow points of Y / Y(albedo) over the same for lit points, among the points
// whose normal is within 25 degrees of `axis` and that `mask` selects.
double shadowOverLit(const std::vector<Eigen::Vector3f>& colours, const synthetic::StreetScan& scan,
                     const std::vector<std::uint8_t>& mask, const Eigen::Vector3f& axis) {
  double sum[2] = {0, 0}, count[2] = {0, 0};
  for (std::size_t i = 0; i < colours.size(); ++i) {
    if (!mask[i] || scan.cloud[i].getNormalVector3fMap().dot(axis) < 0.9f) continue;
    const float albedo = colour::luminance(scan.albedo[i]);
    if (albedo < 0.05f) continue;
    const int k = scan.in_shadow[i] ? 1 : 0;
    sum[k] += colour::luminance(colours[i]) / albedo;
    count[k] += 1;
  }
  return count[0] > 0 && count[1] > 0 ? (sum[1] / count[1]) / (sum[0] / count[0]) : NAN;
}

}  // namespace

int benchColourAndShadows(bool quick) {
  synthetic::StreetOptions options;
  options.length = quick ? 24 : 48;
  options.scan_step = 0.1;
  options.range_noise = 0.005;
  const synthetic::StreetScene scene(options);
  const synthetic::StreetScan scan = scene.scan();
  const Positions points = positionsOf(scan.cloud);
  const auto camera = CameraIntrinsics::fromFieldOfView(quick ? 320 : 640, quick ? 240 : 480, 75);
  const double exposure = synthetic::PhotoOptions{}.exposure;
  std::printf("synthetic street: %.0f m, %zu scan points, photos %dx%d\n\n", options.length, points.size(),
              camera.width, camera.height);

  // Truth and the measurable points (uniform true colour around them).
  std::vector<Eigen::Vector3f> truth(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d n = scan.cloud[i].getNormalVector3fMap().cast<double>();
    truth[i] = (scan.albedo[i] * float(exposure * scene.irradiance(points[i].cast<double>(), n))).cwiseMin(1.f);
  }
  std::vector<std::uint8_t> uniform(points.size(), 0);
  {
    const SpatialIndex index(points);
    std::vector<int> nn;
    std::vector<float> d2;
    for (std::size_t i = 0; i < points.size(); ++i) {
      index.nearestK(points[i], 9, nn, d2);
      bool u = true;
      for (const int j : nn) u = u && (truth[j] - truth[i]).norm() < 0.03f;
      uniform[i] = u;
    }
  }

  // 1. Colorization: three photos, the van in front of the middle one.
  {
    const auto poses = scene.cameraPoses(3, -2.5, 2.5, 1, 0, 8);
    std::vector<RegisteredPhoto> photos;
    for (int v = 0; v < 3; ++v) {
      synthetic::PhotoOptions po;
      po.seed = 11 + v;
      po.passing_van = v == 1;
      po.van_x = poses[v].translation().x();
      photos.push_back({scene.photo(camera, poses[v], po).image, camera, poses[v]});
    }
    // What the same photos record without the van and without noise: the colour a method can
    // at best recover from them (the sub-pixel texture aliased the same way).
    std::vector<RegisteredPhoto> clean_photos;
    for (int v = 0; v < 3; ++v) {
      synthetic::PhotoOptions po;
      po.noise_sigma = 0;
      clean_photos.push_back({scene.photo(camera, poses[v], po).image, camera, poses[v]});
    }
    const ColourCandidates clean = collectColourCandidates(points, clean_photos);
    std::vector<Eigen::Vector3f> recoverable(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) recoverable[i] = medianCandidate(clean, i);
    auto t = Clock::now();
    const ColourCandidates candidates = collectColourCandidates(points, photos);
    const double t_candidates = secondsSince(t);
    std::vector<Eigen::Vector3f> nearest(points.size(), Eigen::Vector3f::Constant(NAN)), mean = nearest, median = nearest;
    t = Clock::now();
    for (std::size_t i = 0; i < points.size(); ++i) {
      const std::size_t c = candidates.count(i);
      if (c == 0) continue;
      double best = INFINITY;
      mean[i].setZero();
      for (std::size_t k = 0; k < c; ++k) {
        const auto slot = candidates.offsets[i] + std::int64_t(k);
        mean[i] += candidates.colour[slot] / float(c);
        const double d = (photos[candidates.photo[slot]].pose.translation().cast<float>() - points[i]).norm();
        if (d < best) {
          best = d;
          nearest[i] = candidates.colour[slot];
        }
      }
    }
    const double t_simple = secondsSince(t);
    t = Clock::now();
    for (std::size_t i = 0; i < points.size(); ++i) median[i] = medianCandidate(candidates, i);
    const double t_median = secondsSince(t);
    t = Clock::now();
    PointColorizationReport report;
    const auto ours = colorizeFromCandidates(points, std::vector<Eigen::Vector3f>(points.size(), Eigen::Vector3f::Zero()),
                                             candidates, {}, &report);
    const double t_ours = secondsSince(t);
    std::vector<std::uint8_t> seen(points.size(), 0), occluded(points.size(), 0);
    std::vector<std::uint8_t> seen_all(points.size(), 0), occluded_all(points.size(), 0);
    std::size_t n_seen = 0, n_occluded = 0, n_seen_all = 0, n_occluded_all = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (candidates.count(i) == 0) continue;
      seen_all[i] = 1;
      ++n_seen_all;
      for (std::size_t k = 0; k < candidates.count(i); ++k) {
        const auto slot = candidates.offsets[i] + std::int64_t(k);
        if (candidates.photo[slot] == 1 && (candidates.colour[slot] - recoverable[i]).norm() > 0.15f) {
          occluded_all[i] = 1;
          ++n_occluded_all;
        }
      }
      if (!uniform[i]) continue;
      seen[i] = 1;
      ++n_seen;
      for (std::size_t k = 0; k < candidates.count(i); ++k) {
        const auto slot = candidates.offsets[i] + std::int64_t(k);
        if (candidates.photo[slot] == 1 && (candidates.colour[slot] - truth[i]).norm() > 0.15f) {
          occluded[i] = 1;
          ++n_occluded;
        }
      }
    }
    std::printf("Colorization (3 photos, van in front of the middle one; candidates %.2f s)\n", t_candidates);
    std::printf("  against the true colour, on points of uniform true colour; against what the photos\n"
                "  record without van and noise (median of those), on every point seen\n");
    std::printf("  %-26s %10s %12s %10s %12s %8s\n", "method", "true: all", "true: van", "photos: all",
                "photos: van", "time s");
    std::printf("  %-26s %10s %12s %10s %12s %8s\n", "", ("(" + std::to_string(n_seen) + ")").c_str(),
                ("(" + std::to_string(n_occluded) + ")").c_str(), ("(" + std::to_string(n_seen_all) + ")").c_str(),
                ("(" + std::to_string(n_occluded_all) + ")").c_str(), "");
    auto row = [&](const char* name, const std::vector<Eigen::Vector3f>& c, double time) {
      std::printf("  %-26s %10.4f %12.4f %10.4f %12.4f %8.3f\n", name, rmsError(c, truth, seen),
                  rmsError(c, truth, occluded), rmsError(c, recoverable, seen_all), rmsError(c, recoverable, occluded_all),
                  time);
    };
    row("nearest photo only", nearest, t_simple);
    row("per-point mean", mean, t_simple);
    row("per-point median", median, t_median);
    row("ours", ours, t_ours);
    std::printf("  ours: %d iterations, %zu points coloured, %zu unseen\n\n", report.iterations, report.coloured,
                report.unseen);
  }

  // 2. Shadow detection on the cloud coloured by ours from photos along the street.
  const int views = quick ? 5 : 9;
  const auto poses = scene.cameraPoses(views, -0.35 * options.length, 0.35 * options.length, 1, 0, -5);
  std::vector<RegisteredPhoto> photos;
  for (int v = 0; v < views; ++v) {
    synthetic::PhotoOptions po;
    po.seed = 20 + v;
    po.exposure = 0.5;  // lit pavement stays below 255 (saturation would cap the lit side)
    photos.push_back({scene.photo(camera, poses[v], po).image, camera, poses[v]});
  }
  auto cloud = scan.cloud.makeShared();
  pcl::PointCloud<pcl::PointXYZRGBNormal>::Ptr coloured(new pcl::PointCloud<pcl::PointXYZRGBNormal>);
  {
    PointColorization<pcl::PointXYZRGBNormal> colorize;
    colorize.setInputCloud(cloud);
    for (const auto& p : photos) colorize.addView(p.image, p.camera, p.pose);
    colorize.filter(*coloured);
  }
  const std::vector<Eigen::Vector3f> colours = colour::coloursOf(*coloured);
  ShadowDetectionResult ours, plain;
  auto detect = [&](bool guided, ShadowDetectionResult& r) {
    ShadowDetection<pcl::PointXYZRGBNormal> d;
    ShadowDetectionParameters p;
    p.reflectance_guided = guided;
    d.setParameters(p);
    d.setInputCloud(coloured);
    d.setReflectance(scan.reflectance);
    for (const auto& ph : photos) d.addView(ph.image, ph.camera, ph.pose);
    const auto t = Clock::now();
    d.detect(r);
    return secondsSince(t);
  };
  const double t_ours = detect(true, ours), t_plain = detect(false, plain);
  auto t = Clock::now();
  const auto otsu = shadowLabelsByOtsu(colours);
  const double t_otsu = secondsSince(t);
  std::vector<std::uint8_t> voted(points.size(), 0);
  std::size_t n_voted = 0, n_shadow = 0;
  for (std::size_t i = 0; i < points.size(); ++i)
    if (ours.decided[i] == 2 && plain.decided[i] == 2) {
      voted[i] = 1;
      ++n_voted;
      n_shadow += scan.in_shadow[i];
    }
  std::printf("Shadow detection (%d photos; %zu points voted on, %.0f%% in shadow)\n", views, n_voted,
              100.0 * n_shadow / std::max<std::size_t>(n_voted, 1));
  std::printf("  %-32s %9s %7s %9s %9s\n", "method", "accuracy", "IoU", "balanced", "time s");
  auto drow = [&](const char* name, const std::vector<std::uint8_t>& labels, double time) {
    const LabelScore s = scoreLabels(labels, scan.in_shadow, voted);
    std::printf("  %-32s %9.3f %7.3f %9.3f %9.3f\n", name, s.accuracy, s.iou, s.balanced, time);
  };
  drow("Otsu threshold on L*", otsu, t_otsu);
  drow("eq. 4.4 as printed", plain.in_shadow, t_plain);
  drow("ours (reflectance-guided)", ours.in_shadow, t_ours);
  std::size_t true_pairs = 0;
  for (const auto& [d, b] : ours.interface_pairs) true_pairs += scan.in_shadow[d] && !scan.in_shadow[b];
  std::printf("  interface candidates %zu, after density filter %zu, pairs %zu, kept (bimodal) %zu, of which %zu "
              "straddle a true shadow edge\n\n",
              ours.candidates.size(), ours.dense_candidates.size(), ours.pairs_before_histogram,
              ours.interface_pairs.size(), true_pairs);

  // 3. Correction to all lit. Measured on the voted points, and on those of them farther than
  // 0.3 m from a true shadow edge (the photos blend colours across the edge).
  std::vector<std::uint8_t> inner = voted;
  {
    const SpatialIndex index(points);
    std::vector<int> nn;
    std::vector<float> d2;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (!inner[i]) continue;
      index.radiusSearch(points[i], 0.3f, nn, d2);
      for (const int j : nn) inner[i] = inner[i] && scan.in_shadow[j] == scan.in_shadow[i];
    }
  }
  std::printf("Shadow correction to all lit: mean shadow / mean lit of Y / Y(albedo), same orientation;\n"
              "  all voted points, and those farther than 0.3 m from a true shadow edge\n");
  std::printf("  %-24s %9s %9s %9s %9s %11s %11s\n", "labels", "SSR", "time s", "ground", "facades", "ground>0.3",
              "facades>0.3");
  const Eigen::Vector3f up = Eigen::Vector3f::UnitZ(), facade = -Eigen::Vector3f::UnitY();
  std::printf("  %-24s %9s %9s %9.3f %9.3f %11.3f %11.3f\n", "before", "", "", shadowOverLit(colours, scan, voted, up),
              shadowOverLit(colours, scan, voted, facade), shadowOverLit(colours, scan, inner, up),
              shadowOverLit(colours, scan, inner, facade));
  // Only the points the photos saw carry photo colours (the others keep black): the
  // correction runs on them alone (its indices).
  pcl::IndicesPtr seen_indices(new pcl::Indices);
  for (std::size_t i = 0; i < points.size(); ++i)
    if (voted[i]) seen_indices->push_back(int(i));
  auto crow = [&](const char* name, const std::vector<std::uint8_t>& labels, float ssr = 0) {
    ShadowCorrection<pcl::PointXYZRGBNormal> c;
    ShadowCorrectionParameters p;
    p.sun_direction = scene.sunDirection().cast<float>();
    p.sun_sky_ratio = ssr;
    c.setParameters(p);
    c.setInputCloud(coloured);
    c.setShadowLabels(labels);
    c.setIndices(seen_indices);
    pcl::PointCloud<pcl::PointXYZRGBNormal> out;
    const auto t0 = Clock::now();
    c.filter(out);
    const double time = secondsSince(t0);
    const auto relit = colour::coloursOf(out);
    std::printf("  %-24s %9.3f %9.3f %9.3f %9.3f %11.3f %11.3f\n", name, c.getReport().sun_sky_ratio, time,
                shadowOverLit(relit, scan, voted, up), shadowOverLit(relit, scan, voted, facade),
                shadowOverLit(relit, scan, inner, up), shadowOverLit(relit, scan, inner, facade));
  };
  std::vector<std::uint8_t> detected = ours.in_shadow, truth_labels(points.size(), 0);
  for (std::size_t i = 0; i < points.size(); ++i) truth_labels[i] = voted[i] && scan.in_shadow[i];
  crow("ours (detected)", detected);
  crow("true labels", truth_labels);
  crow("true labels and SSR", truth_labels, float(options.sun_sky_ratio));
  std::printf("  (true sun-sky ratio %.2f; photos at exposure 0.5: only lane markings saturate)\n",
              options.sun_sky_ratio);
  return 0;
}

}  // namespace paps::cli
