#include <paps/fusion/synthetic_street.h>

#include <algorithm>
#include <cmath>

#include <paps/core/error.h>
#include <paps/core/random.h>

namespace paps {
namespace synthetic {
namespace {

enum MaterialId { kAsphalt, kMarking, kPavement, kBrick, kStone, kRender, kPaint, kGlass, kPost, kCarRed,
                  kCarBlue, kCarSilver, kVan, kMaterialCount };

constexpr double kSensorY = -1.5, kSensorZ = 2.5, kCameraZ = 2.6;
constexpr double kGroundHalfWidth = 20.0;

double positiveFmod(double a, double m) {
  const double r = std::fmod(a, m);
  return r < 0 ? r + m : r;
}

// Windows: shop fronts on the ground floor, a window every 2.5 m on the floors above; `s`
// metres along the facade, `z` the height.
bool isWindow(double s, double z) {
  return z < 3 ? (z > 0.5 && z < 2.5 && positiveFmod(s, 5.0) > 0.8 && positiveFmod(s, 5.0) < 4.2)
               : (positiveFmod(z, 3.0) > 1.0 && positiveFmod(z, 3.0) < 2.4 && positiveFmod(s, 2.5) > 0.65 &&
                  positiveFmod(s, 2.5) < 1.85);
}

}  // namespace

double StreetScene::alongFacade(const Box& b, const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
  return std::abs(n.y()) > 0.5 ? p.x() - b.lo.x() : p.y() - b.lo.y();
}

StreetScene::StreetScene(const StreetOptions& options) : options_(options) {
  requireInRange("street length", options.length, 10.0, 1000.0);
  requireInRange("scan_step", options.scan_step, 0.01, 5.0);
  requireInRange("scan_angle_step_deg", options.scan_angle_step_deg, 0.05, 10.0);
  requireInRange("range_noise", options.range_noise, 0.0, 1.0);
  requireInRange("reflectance_noise", options.reflectance_noise, 0.0, 0.5);
  requireInRange("sun_sky_ratio", options.sun_sky_ratio, 0.0, 100.0);
  if (!(options.sun.norm() > 1e-9) || !options.sun.allFinite() || !(options.sun.z() > 0))
    throw InvalidParameter("sun", "a direction below the horizon", "a finite direction with z > 0");
  sun_ = options.sun.normalized();

  materials_.resize(kMaterialCount);
  materials_[kAsphalt] = {{0.22f, 0.22f, 0.23f}, 0.18f};
  materials_[kMarking] = {{0.85f, 0.85f, 0.80f}, 0.75f};
  materials_[kPavement] = {{0.55f, 0.53f, 0.50f}, 0.42f};
  materials_[kBrick] = {{0.58f, 0.27f, 0.19f}, 0.35f};
  materials_[kStone] = {{0.75f, 0.68f, 0.52f}, 0.55f};
  materials_[kRender] = {{0.62f, 0.62f, 0.64f}, 0.50f};
  materials_[kPaint] = {{0.80f, 0.70f, 0.30f}, 0.45f};
  materials_[kGlass] = {{0.12f, 0.14f, 0.18f}, 0.08f};
  materials_[kPost] = {{0.15f, 0.25f, 0.18f}, 0.30f};
  materials_[kCarRed] = {{0.60f, 0.10f, 0.10f}, 0.50f};
  materials_[kCarBlue] = {{0.15f, 0.20f, 0.55f}, 0.50f};
  materials_[kCarSilver] = {{0.70f, 0.70f, 0.72f}, 0.60f};
  materials_[kVan] = {{0.90f, 0.90f, 0.88f}, 0.70f};

  Random rng(options.seed);
  const double half = 0.5 * options.length;
  // Buildings on both sides: widths 6 to 12 m, a narrow alley now and then, setbacks of up to
  // a metre, heights 8 to 20 m.
  for (int side : {1, -1}) {
    double x = -half - 2;
    while (x < half + 2) {
      const double width = rng.uniform(6, 12), front = rng.uniform(6.5, 7.5), height = rng.uniform(8, 20);
      const int material = kBrick + static_cast<int>(rng.below(4));
      Box b;
      b.lo = {x, side > 0 ? front : -front - 8, 0};
      b.hi = {x + width, side > 0 ? front + 8 : -front, height};
      b.material = material;
      b.facade = true;
      const int first = static_cast<int>(boxes_.size());
      boxes_.push_back(b);
      // Street-facing details: a cornice under every floor line, a sill under every window.
      const double face = side > 0 ? b.lo.y() : b.hi.y(), out = side > 0 ? -0.15 : 0.15;
      const double ylo = std::min(face, face + out), yhi = std::max(face, face + out);
      const int detail = material == kBrick ? kStone : material;
      for (int floor = 1; 3.0 * floor < height - 0.5; ++floor) {
        boxes_.push_back({{x, ylo, 3.0 * floor - 0.2}, {x + width, yhi, 3.0 * floor}, detail, false});
        if (3.0 * floor + 2.4 > height) continue;
        for (int k = 0; 2.5 * k + 1.95 < width; ++k)
          boxes_.push_back({{x + 2.5 * k + 0.55, ylo, 3.0 * floor + 0.9}, {x + 2.5 * k + 1.95, yhi, 3.0 * floor + 1.0},
                            detail, false});
      }
      addGroup(first);
      const bool gap = rng.uniform() < 0.3;
      x += width + (gap ? rng.uniform(1.0, 2.5) : 0.0);
    }
  }
  // Lamp posts every 12 m on both pavements, each with an arm over the road.
  for (double x = -half + 6; x < half; x += 12)
    for (int side : {1, -1}) {
      const double y = side * 5.6;
      const int first = static_cast<int>(boxes_.size());
      boxes_.push_back({{x - 0.1, y - 0.1, 0}, {x + 0.1, y + 0.1, 5.5}, kPost, false});
      boxes_.push_back({{x - 0.06, std::min(y, y - side * 1.6), 5.3}, {x + 0.06, std::max(y, y - side * 1.6), 5.45}, kPost, false});
      addGroup(first);
    }
  // Parked cars along both kerbs.
  for (int side : {1, -1})
    for (double x = -half + 2 + rng.uniform(0, 3); x < half - 5; x += rng.uniform(8, 14)) {
      const double y0 = side > 0 ? 3.0 : -4.8;
      const int material = kCarRed + static_cast<int>(rng.below(3));
      boxes_.push_back({{x, y0, 0.25}, {x + 4.2, y0 + 1.8, 1.5}, material, false});
      addGroup(static_cast<int>(boxes_.size()) - 1);
    }
}

void StreetScene::addGroup(int first) {
  Group g{boxes_[first], first, static_cast<int>(boxes_.size()) - first};
  for (int i = first; i < first + g.count; ++i) {
    g.bounds.lo = g.bounds.lo.cwiseMin(boxes_[i].lo);
    g.bounds.hi = g.bounds.hi.cwiseMax(boxes_[i].hi);
  }
  groups_.push_back(g);
}

bool StreetScene::hitBox(const Box& b, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double max_t,
                         double& t, Eigen::Vector3d& n) const {
  double t0 = 1e-6, t1 = max_t;
  int axis = -1;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-15) {
      if (o[k] < b.lo[k] || o[k] > b.hi[k]) return false;
      continue;
    }
    double a = (b.lo[k] - o[k]) / d[k], c = (b.hi[k] - o[k]) / d[k];
    if (a > c) std::swap(a, c);
    if (a > t0) { t0 = a; axis = k; }
    t1 = std::min(t1, c);
    if (t0 > t1) return false;
  }
  if (axis < 0) return false;  // the origin is inside the box
  t = t0;
  n = Eigen::Vector3d::Zero();
  n[axis] = d[axis] > 0 ? -1 : 1;
  return true;
}

bool StreetScene::castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_distance,
                          double& distance, Eigen::Vector3d& normal, int& box, bool with_van, double van_x) const {
  const Eigen::Vector3d d = direction.normalized();
  double best = max_distance;
  bool hit = false;
  const double half = 0.5 * options_.length + 4;
  if (d.z() < -1e-12) {
    const double t = -origin.z() / d.z();
    const Eigen::Vector3d p = origin + t * d;
    if (t > 1e-6 && t < best && std::abs(p.x()) <= half && std::abs(p.y()) <= kGroundHalfWidth) {
      best = t;
      normal = Eigen::Vector3d::UnitZ();
      box = -1;
      hit = true;
    }
  }
  double t;
  Eigen::Vector3d n;
  for (const Group& g : groups_) {
    // Enter the group when its bounds are hit nearer than the best, or contain the origin.
    const bool inside = (origin.array() >= g.bounds.lo.array()).all() && (origin.array() <= g.bounds.hi.array()).all();
    if (!inside && !(hitBox(g.bounds, origin, d, best, t, n) && t < best)) continue;
    for (int i = g.first; i < g.first + g.count; ++i)
      if (hitBox(boxes_[i], origin, d, best, t, n) && t < best) {
        best = t;
        normal = n;
        box = i;
        hit = true;
      }
  }
  if (with_van) {
    const Box van{{van_x - 3, 1.0, 0.3}, {van_x + 3, 3.0, 2.9}, kVan, false};
    if (hitBox(van, origin, d, best, t, n) && t < best) {
      best = t;
      normal = n;
      box = static_cast<int>(boxes_.size());  // one past the boxes: the van
      hit = true;
    }
  }
  if (hit) distance = best;
  return hit;
}

Eigen::Vector3f StreetScene::albedo(const Eigen::Vector3d& p, const Eigen::Vector3d& n, int box) const {
  if (box < 0) {
    const double ay = std::abs(p.y());
    if (ay < 0.08 && positiveFmod(p.x(), 6.0) < 3.0) return materials_[kMarking].albedo;
    if (ay >= 5.0) return materials_[kPavement].albedo;
    // Asphalt with faint patches (colour texture the reflectance does not have).
    const float patch = 1.f + 0.08f * static_cast<float>(std::sin(0.9 * p.x()) * std::cos(1.3 * p.y()));
    return materials_[kAsphalt].albedo * patch;
  }
  if (box >= static_cast<int>(boxes_.size())) return materials_[kVan].albedo;
  const Box& b = boxes_[box];
  Eigen::Vector3f a = materials_[b.material].albedo;
  if (!b.facade || std::abs(n.z()) > 0.5) return a;
  const double s = alongFacade(b, p, n), z = p.z();
  if (isWindow(s, z)) return materials_[kGlass].albedo;
  if (b.material == kBrick) {
    const int course = static_cast<int>(std::floor(z / 0.075));
    if (positiveFmod(z, 0.075) < 0.012 || positiveFmod(s + (course % 2) * 0.11, 0.22) < 0.012)
      return {0.70f, 0.68f, 0.62f};  // mortar
  }
  // Weathering stains: low-frequency colour variation with the same reflectance.
  return a * (1.f + 0.07f * static_cast<float>(std::sin(0.7 * s + box) * std::sin(0.5 * z)));
}

float StreetScene::reflectance(const Eigen::Vector3d& p, const Eigen::Vector3d& n, int box) const {
  if (box < 0) {
    const double ay = std::abs(p.y());
    if (ay < 0.08 && positiveFmod(p.x(), 6.0) < 3.0) return materials_[kMarking].reflectance;
    return ay >= 5.0 ? materials_[kPavement].reflectance : materials_[kAsphalt].reflectance;
  }
  if (box >= static_cast<int>(boxes_.size())) return materials_[kVan].reflectance;
  const Box& b = boxes_[box];
  if (b.facade && std::abs(n.z()) <= 0.5 && isWindow(alongFacade(b, p, n), p.z())) return materials_[kGlass].reflectance;
  return materials_[b.material].reflectance;
}

bool StreetScene::sunlit(const Eigen::Vector3d& p, const Eigen::Vector3d& n) const {
  if (n.dot(sun_) <= 0) return false;
  double t;
  Eigen::Vector3d m;
  int box;
  return !castRay(p + 1e-4 * n, sun_, 500, t, m, box);
}

double StreetScene::irradiance(const Eigen::Vector3d& p, const Eigen::Vector3d& n) const {
  const double sun = sunlit(p, n) ? options_.sun_sky_ratio * n.dot(sun_) : 0.0;
  return sun + 0.5 * (n.z() + 1);
}

StreetScan StreetScene::scan() const {
  const double half = 0.5 * options_.length;
  const int lines = static_cast<int>(std::floor((options_.length - 2) / options_.scan_step)) + 1;
  const int rays = static_cast<int>(std::lround(360.0 / options_.scan_angle_step_deg));
  const double tilt = std::tan(15.0 * M_PI / 180);  // the scan plane leans forward: side walls are seen
  std::vector<StreetScan> per_line(lines);
#pragma omp parallel for schedule(dynamic, 8)
  for (int l = 0; l < lines; ++l) {
    Random rng(options_.seed * 1000003ULL + static_cast<std::uint64_t>(l));
    const Eigen::Vector3d o(-half + 1 + l * options_.scan_step, kSensorY, kSensorZ);
    StreetScan& out = per_line[l];
    for (int r = 0; r < rays; ++r) {
      const double a = r * 2 * M_PI / rays;
      const Eigen::Vector3d d = Eigen::Vector3d(tilt, std::cos(a), std::sin(a)).normalized();
      double t;
      Eigen::Vector3d n;
      int box;
      if (!castRay(o, d, 60, t, n, box)) continue;
      const Eigen::Vector3d exact = o + t * d;
      const Eigen::Vector3d p = o + (t + options_.range_noise * rng.gaussian()) * d;
      pcl::PointXYZRGBNormal q;
      q.getVector3fMap() = p.cast<float>();
      q.getNormalVector3fMap() = n.cast<float>();
      q.r = q.g = q.b = 0;
      q.curvature = 0;
      out.cloud.push_back(q);
      out.reflectance.push_back(std::clamp(
          reflectance(exact, n, box) + static_cast<float>(options_.reflectance_noise * rng.gaussian()), 0.f, 1.f));
      out.albedo.push_back(albedo(exact, n, box));
      out.in_shadow.push_back(sunlit(exact, n) ? 0 : 1);
    }
  }
  StreetScan scan;
  for (auto& s : per_line) {
    scan.cloud.insert(scan.cloud.end(), s.cloud.begin(), s.cloud.end());
    scan.reflectance.insert(scan.reflectance.end(), s.reflectance.begin(), s.reflectance.end());
    scan.albedo.insert(scan.albedo.end(), s.albedo.begin(), s.albedo.end());
    scan.in_shadow.insert(scan.in_shadow.end(), s.in_shadow.begin(), s.in_shadow.end());
  }
  scan.cloud.width = static_cast<std::uint32_t>(scan.cloud.size());
  scan.cloud.height = 1;
  scan.cloud.is_dense = true;
  return scan;
}

StreetPhoto StreetScene::photo(const CameraIntrinsics& camera, const CameraPose& pose,
                               const PhotoOptions& options) const {
  camera.validate();
  requireInRange("exposure", options.exposure, 0.0, 100.0);
  requireInRange("noise_sigma", options.noise_sigma, 0.0, 255.0);
  StreetPhoto photo;
  photo.image.create(camera.height, camera.width, CV_8UC3);
  photo.shadow.create(camera.height, camera.width, CV_8U);
  photo.depth.create(camera.height, camera.width, CV_32F);
  const Eigen::Vector3f sky(0.62f, 0.76f, 0.95f);
#pragma omp parallel for schedule(dynamic, 4)
  for (int v = 0; v < camera.height; ++v) {
    Random rng(options.seed * 7919ULL + static_cast<std::uint64_t>(v));
    for (int u = 0; u < camera.width; ++u) {
      const Eigen::Vector3d d = pose.linear() * camera.ray(Eigen::Vector2d(u, v));
      double t;
      Eigen::Vector3d n;
      int box;
      Eigen::Vector3f colour;
      std::uint8_t in_shadow = 0;
      float depth = 0;
      if (castRay(pose.translation(), d, 1000, t, n, box, options.passing_van, options.van_x)) {
        const Eigen::Vector3d p = pose.translation() + t * d.normalized();
        const bool lit = sunlit(p, n);
        const double light = (lit ? options_.sun_sky_ratio * n.dot(sun_) : 0.0) + 0.5 * (n.z() + 1);
        colour = albedo(p, n, box) * static_cast<float>(options.exposure * light);
        in_shadow = lit ? 0 : 255;
        depth = static_cast<float>(t);
      } else {
        colour = sky * static_cast<float>(options.exposure * 1.3);
      }
      cv::Vec3b& px = photo.image.at<cv::Vec3b>(v, u);
      for (int c = 0; c < 3; ++c) {
        const double value = 255.0 * colour[2 - c] + options.noise_sigma * rng.gaussian();  // BGR
        px[c] = static_cast<std::uint8_t>(std::clamp(std::lround(value), 0L, 255L));
      }
      photo.shadow.at<std::uint8_t>(v, u) = in_shadow;
      photo.depth.at<float>(v, u) = depth;
    }
  }
  return photo;
}

std::vector<CameraPose> StreetScene::cameraPoses(int count, double x_from, double x_to, int side, double yaw_deg,
                                                 double pitch_deg) const {
  requireInRange("count", count, 1, 100000);
  if (side != 1 && side != -1) throw InvalidParameter("side", detail::toString(side), "+1 or -1");
  std::vector<CameraPose> poses;
  const double yaw = yaw_deg * M_PI / 180, pitch = pitch_deg * M_PI / 180;
  for (int i = 0; i < count; ++i) {
    const double x = count == 1 ? 0.5 * (x_from + x_to) : x_from + (x_to - x_from) * i / (count - 1);
    const Eigen::Vector3d eye(x, kSensorY, kCameraZ);
    const Eigen::Vector3d flat(std::sin(yaw), side * std::cos(yaw), 0);
    const Eigen::Vector3d forward = std::cos(pitch) * flat + std::sin(pitch) * Eigen::Vector3d::UnitZ();
    poses.push_back(lookAt(eye, eye + forward));
  }
  return poses;
}

}  // namespace synthetic
}  // namespace paps
