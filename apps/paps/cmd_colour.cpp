// paps colorize CLOUD LIST OUT: colours a cloud from registered photos (PointColorization).
// paps shadows CLOUD LIST OUT --sun X,Y,Z: detects (ShadowDetection) and relights
// (ShadowCorrection) the shadows of a coloured cloud with laser reflectance.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core/utils/logger.hpp>
#include <pcl/common/io.h>
#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/fusion/photo_list.h>
#include <paps/fusion/point_colorization.h>
#include <paps/fusion/shadow_correction.h>
#include <paps/fusion/shadow_detection.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

namespace {

const char* kColorizeUsage =
    "usage: paps colorize CLOUD LIST OUT [options]\n"
    "  Colours CLOUD from the registered photos of LIST (manuscript 4.5.1): every photo proposes\n"
    "  a colour for the points it sees (occlusion test), the consensus minimises a median data\n"
    "  term plus a Huber smoothness over the k-nearest-neighbour graph; a photo region that\n"
    "  disagrees with the others (an occluder the scan lacks) is down-weighted.\n"
    "  CLOUD                 .pcd or .ply with x y z (normals optional, other fields kept)\n"
    "  LIST                  photo list with registered poses (paps register's output,\n"
    "                        docs/registration.md)\n"
    "  OUT                   .pcd or .ply: CLOUD with every field kept and 'rgb' set (replaced\n"
    "                        when present, 'rgba' when CLOUD has that); points no photo sees\n"
    "                        keep CLOUD's colour, else black. Written atomically\n"
    "  --neighbours K        neighbours in the smoothness graph, 1 to 64 (default 8)\n"
    "  --smoothness S        weight of the smoothness term, 0 (per-point median) to 1000\n"
    "                        (default 0.25)\n"
    "  --huber D             Huber threshold (linear RGB distance) between smoothing and an edge,\n"
    "                        in (0, 2] (default 0.04)\n"
    "  --agreement D         distance of a candidate that agrees with the median, in (0, 2]\n"
    "                        (default 0.08)\n"
    "  --occlusion-scale F   spread of the occlusion maps, fraction of the image width, in [0, 1];\n"
    "                        0 disables them (default 0.1)\n"
    "  --iterations N        largest number of smoothing iterations, 1 to 10000 (default 60)\n"
    "  --quiet               no progress bar\n";

const char* kShadowsUsage =
    "usage: paps shadows CLOUD LIST OUT --sun X,Y,Z [options]\n"
    "  Detects the cast shadows of a coloured cloud (manuscript 4.5.2: pairs across a shadow\n"
    "  boundary, same laser reflectance but different lightness; a graph cut in every photo\n"
    "  voted back to the points) and relights it (4.5.3, sun-sky ratio estimated).\n"
    "  CLOUD                 .pcd or .ply with x y z, rgb or rgba (e.g. from paps colorize),\n"
    "                        normal_x/y/z and 'intensity' (laser reflectance in [0, 1])\n"
    "  LIST                  photo list with registered poses (docs/registration.md)\n"
    "  OUT                   .pcd or .ply: CLOUD with every field kept, rgb relit (unless\n"
    "                        --relight none) and a uint8 field 'shadow' (1 shadow, 0 lit or\n"
    "                        undecided). Written atomically\n"
    "  --sun X,Y,Z           direction towards the sun in the cloud's frame (any length; from\n"
    "                        GPS time and position). Required\n"
    "  --relight T           lit (default: every point as in sunlight), shadow (every point as in\n"
    "                        shadow) or none (labels only, rgb unchanged)\n"
    "  --ground X,Y,Z        ground normal of the sky-light model (default 0,0,1)\n"
    "  --sun-sky-ratio R     sun over sky light, 0 estimates it (default), up to 1000\n"
    "  --neighbours K        neighbours of the gradients and the density filter, 4 to 128\n"
    "                        (default 16)\n"
    "  --min-lightness-change L  smallest L* change across a neighbourhood for a boundary, in\n"
    "                        (0, 100] (default 12)\n"
    "  --max-reflectance-change R  largest reflectance change across a neighbourhood for a\n"
    "                        boundary, in (0, 1] (default 0.05)\n"
    "  --graph-cut-scale F   image scale of the graph cuts, in (0, 1] (default 1)\n"
    "  --quiet               no progress bar\n";

// The colour field of a blob: 'rgb', else 'rgba' (PCL's .ply reader names it so when the file
// has alpha), else "" (none).
std::string colourField(const pcl::PCLPointCloud2& blob) {
  if (hasField(blob, "rgb")) return "rgb";
  if (hasField(blob, "rgba")) return "rgba";
  return "";
}

// The packed 0xAARRGGBB colours of the 4-byte field `name` of every point.
std::vector<std::uint32_t> packedColours(const pcl::PCLPointCloud2& blob, const std::string& name) {
  const auto f = std::find_if(blob.fields.begin(), blob.fields.end(), [&](const pcl::PCLPointField& x) { return x.name == name; });
  if (f == blob.fields.end() || pcl::getFieldSize(f->datatype) != 4)
    throw InvalidInput("the '" + name + "' field is not a packed 4-byte colour");
  const std::size_t n = std::size_t(blob.width) * blob.height;
  std::vector<std::uint32_t> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t at = (i / blob.width) * blob.row_step + (i % blob.width) * blob.point_step + f->offset;
    if (at + 4 > blob.data.size()) throw InvalidInput("the cloud's data is shorter than its header says");
    std::memcpy(&v[i], &blob.data[at], 4);
  }
  return v;
}

// The values of the numeric field `name` (count 1, any PCL type) of every point, as floats
// (a uint16 intensity or float64 normals are read too, not silently left at zero).
std::vector<float> numericField(const pcl::PCLPointCloud2& blob, const std::string& name) {
  const auto f = std::find_if(blob.fields.begin(), blob.fields.end(), [&](const pcl::PCLPointField& x) { return x.name == name; });
  if (f == blob.fields.end()) throw InvalidInput("the cloud has no '" + name + "' field");
  const std::size_t n = std::size_t(blob.width) * blob.height;
  const std::size_t size = pcl::getFieldSize(f->datatype);
  if (size == 0) throw InvalidInput("the '" + name + "' field has an unknown type");
  std::vector<float> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t at = (i / blob.width) * blob.row_step + (i % blob.width) * blob.point_step + f->offset;
    if (at + size > blob.data.size()) throw InvalidInput("the cloud's data is shorter than its header says");
    const std::uint8_t* d = &blob.data[at];
    switch (f->datatype) {
      case pcl::PCLPointField::INT8: { std::int8_t x; std::memcpy(&x, d, 1); v[i] = x; break; }
      case pcl::PCLPointField::UINT8: { std::uint8_t x; std::memcpy(&x, d, 1); v[i] = x; break; }
      case pcl::PCLPointField::INT16: { std::int16_t x; std::memcpy(&x, d, 2); v[i] = x; break; }
      case pcl::PCLPointField::UINT16: { std::uint16_t x; std::memcpy(&x, d, 2); v[i] = x; break; }
      case pcl::PCLPointField::INT32: { std::int32_t x; std::memcpy(&x, d, 4); v[i] = static_cast<float>(x); break; }
      case pcl::PCLPointField::UINT32: { std::uint32_t x; std::memcpy(&x, d, 4); v[i] = static_cast<float>(x); break; }
      case pcl::PCLPointField::FLOAT32: { float x; std::memcpy(&x, d, 4); v[i] = x; break; }
      case pcl::PCLPointField::FLOAT64: { double x; std::memcpy(&x, d, 8); v[i] = static_cast<float>(x); break; }
      default: throw InvalidInput("the '" + name + "' field has an unsupported type");
    }
  }
  return v;
}

// A blob of one packed colour field `name` ('rgb': float32 as PCL writes it; 'rgba': uint32,
// alpha 255) with the points' colours.
template <typename PointT>
pcl::PCLPointCloud2 colourBlob(const pcl::PointCloud<PointT>& c, const std::string& name) {
  pcl::PCLPointCloud2 b;
  b.height = 1;
  b.width = static_cast<std::uint32_t>(c.size());
  pcl::PCLPointField f;
  f.name = name;
  f.offset = 0;
  f.datatype = name == "rgba" ? pcl::PCLPointField::UINT32 : pcl::PCLPointField::FLOAT32;
  f.count = 1;
  b.fields.push_back(f);
  b.point_step = 4;
  b.row_step = 4 * b.width;
  b.is_dense = false;
  b.data.resize(b.row_step);
  const std::uint32_t alpha = name == "rgba" ? 0xff000000u : 0u;
  for (std::size_t i = 0; i < c.size(); ++i) {
    const std::uint32_t v = alpha | (std::uint32_t(c[i].r) << 16) | (std::uint32_t(c[i].g) << 8) | std::uint32_t(c[i].b);
    std::memcpy(&b.data[4 * i], &v, 4);
  }
  return b;
}

// A blob of one uint8 field.
pcl::PCLPointCloud2 byteBlob(const char* name, const std::vector<std::uint8_t>& v) {
  pcl::PCLPointCloud2 b;
  b.height = 1;
  b.width = static_cast<std::uint32_t>(v.size());
  pcl::PCLPointField f;
  f.name = name;
  f.offset = 0;
  f.datatype = pcl::PCLPointField::UINT8;
  f.count = 1;
  b.fields.push_back(f);
  b.point_step = 1;
  b.row_step = b.width;
  b.is_dense = false;
  b.data = v;
  return b;
}

std::vector<RegisteredPhoto> readPhotos(const std::string& list) {
  const auto entries = loadPhotoList(list);
  if (entries.empty()) throw InvalidInput("photo list '" + list + "' holds no photo");
  return loadPhotos(list, entries);
}

}  // namespace

int runColorize(int argc, char** argv) {
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  const Arguments a = Arguments::parse(argc, argv, 2, {"help", "quiet"});
  if (a.has("help")) { std::fputs(kColorizeUsage, stdout); return 0; }
  a.allowOnly({"neighbours", "smoothness", "huber", "agreement", "occlusion-scale", "iterations", "quiet"});
  if (a.positional.size() != 3) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "CLOUD LIST OUT");
  a.requireCloudOutput();
  PointColorizationParameters p;
  p.neighbours = a.integer("neighbours", p.neighbours);
  p.smoothness = a.real("smoothness", p.smoothness);
  p.huber_threshold = a.real("huber", p.huber_threshold);
  p.agreement_distance = a.real("agreement", p.agreement_distance);
  p.occlusion_map_scale = a.real("occlusion-scale", p.occlusion_map_scale);
  p.iterations = a.integer("iterations", p.iterations);
  PointColorization<pcl::PointXYZRGB> colorize;
  validateAsOptions({{"neighbours", "neighbours"},
              {"smoothness", "smoothness"},
              {"huber_threshold", "huber"},
              {"agreement_distance", "agreement"},
              {"occlusion_map_scale", "occlusion-scale"},
              {"iterations", "iterations"}},
             [&] { colorize.setParameters(p); });
  // Inputs read and checked before any work.
  const auto photos = readPhotos(a.positional[1]);
  const pcl::PCLPointCloud2 blob = loadCloud(a.positional[0]);
  const Positions points = positionsOf(blob);
  printRead(a.positional[0], points);
  const std::string field = colourField(blob);
  const std::vector<std::uint32_t> input =
      field.empty() ? std::vector<std::uint32_t>(points.size(), 0u) : packedColours(blob, field);
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZRGB>>();
  cloud->resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    auto& q = (*cloud)[i];
    q.getVector3fMap() = points[i];
    q.r = static_cast<std::uint8_t>(input[i] >> 16);
    q.g = static_cast<std::uint8_t>(input[i] >> 8);
    q.b = static_cast<std::uint8_t>(input[i]);
  }
  cloud->width = static_cast<std::uint32_t>(cloud->size());
  cloud->height = 1;
  cloud->is_dense = false;
  for (const auto& ph : photos) colorize.addView(ph.image, ph.camera, ph.pose);
  colorize.setInputCloud(cloud);
  colorize.setProgressCallback(progressBar(a.has("quiet")));
  pcl::PointCloud<pcl::PointXYZRGB> out;
  colorize.filter(out);
  const PointColorizationReport& r = colorize.getReport();
  std::printf("colorize: %zu points coloured, %zu unseen (%s), %zu non-finite; %zu candidates from %zu photos, "
              "%d iterations (last change %.2g)\n",
              r.coloured, r.unseen, field.empty() ? "black" : ("input " + field + " kept").c_str(), r.non_finite, r.candidates,
              photos.size(), r.iterations, r.last_change);
  if (r.coloured == 0)
    std::fprintf(stderr, "warning: no photo sees any point (check the poses and the cloud's frame): every point is %s\n",
                 field.empty() ? "black" : "left with its input colour");
  std::printf("colorize: points seen per photo:");
  for (const auto s : r.seen_per_photo) std::printf(" %zu", s);
  std::printf("\n");
  saveCloudAtomic(a.positional[2], appendFields(blob, colourBlob(out, field.empty() ? "rgb" : field)));
  std::printf("wrote %s\n", a.positional[2].c_str());
  return 0;
}

int runShadows(int argc, char** argv) {
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  const Arguments a = Arguments::parse(argc, argv, 2, {"help", "quiet"});
  if (a.has("help")) { std::fputs(kShadowsUsage, stdout); return 0; }
  a.allowOnly({"sun", "relight", "ground", "sun-sky-ratio", "neighbours", "min-lightness-change",
               "max-reflectance-change", "graph-cut-scale", "quiet"});
  if (a.positional.size() != 3) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "CLOUD LIST OUT");
  a.requireCloudOutput();
  if (!a.has("sun")) throw InvalidParameter("sun", "missing", "--sun X,Y,Z, the direction towards the sun");
  ShadowCorrectionParameters cp;
  cp.sun_direction = parseDirection(a, "sun", cp.sun_direction);
  cp.ground_normal = parseDirection(a, "ground", cp.ground_normal);
  cp.sun_sky_ratio = a.real("sun-sky-ratio", cp.sun_sky_ratio);
  const std::string relight = a.text("relight", "lit");
  if (relight == "lit") cp.target = RelightTarget::AllLit;
  else if (relight == "shadow") cp.target = RelightTarget::AllShadow;
  else if (relight != "none") throw InvalidParameter("relight", relight, "lit, shadow or none");
  ShadowDetectionParameters dp;
  dp.neighbours = a.integer("neighbours", dp.neighbours);
  dp.min_lightness_change = a.real("min-lightness-change", dp.min_lightness_change);
  dp.max_reflectance_change = a.real("max-reflectance-change", dp.max_reflectance_change);
  dp.graph_cut_scale = a.real("graph-cut-scale", dp.graph_cut_scale);
  ShadowDetection<pcl::PointXYZRGBNormal> detect;
  ShadowCorrection<pcl::PointXYZRGBNormal> correct;
  validateAsOptions({{"neighbours", "neighbours"},
              {"min_lightness_change", "min-lightness-change"},
              {"max_reflectance_change", "max-reflectance-change"},
              {"graph_cut_scale", "graph-cut-scale"},
              {"sun_sky_ratio", "sun-sky-ratio"},
              {"sun_direction", "sun"},
              {"ground_normal", "ground"}},
             [&] {
               detect.setParameters(dp);
               correct.setParameters(cp);
             });
  // Inputs read and checked before any work.
  const auto photos = readPhotos(a.positional[1]);
  const std::string& in = a.positional[0];
  const pcl::PCLPointCloud2 blob = loadCloud(in);
  const std::string field = colourField(blob);
  if (field.empty()) throw InvalidInput("'" + in + "' has no 'rgb' field (colour it first: paps colorize)");
  if (!hasField(blob, "normal_x") || !hasField(blob, "normal_y") || !hasField(blob, "normal_z"))
    throw InvalidInput("'" + in + "' has no normals (normal_x/y/z; e.g. paps curvature computes them)");
  if (!hasField(blob, "intensity"))
    throw InvalidInput("'" + in + "' has no 'intensity' field (the laser reflectance)");
  const Positions points = positionsOf(blob);
  printRead(in, points);
  const std::vector<std::uint32_t> rgb = packedColours(blob, field);
  const std::vector<float> nx = numericField(blob, "normal_x"), ny = numericField(blob, "normal_y"),
                           nz = numericField(blob, "normal_z");
  const std::vector<float> reflectance = numericField(blob, "intensity");
  std::size_t outside = 0;
  for (const float v : reflectance)
    if (std::isfinite(v) && (v < 0 || v > 1)) ++outside;
  if (outside)
    throw InvalidInput("'" + in + "': " + std::to_string(outside) +
                       " intensity values outside [0, 1] (the laser reflectance is expected, scaled to [0, 1])");
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZRGBNormal>>();
  cloud->resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    auto& q = (*cloud)[i];
    q.getVector3fMap() = points[i];
    q.r = static_cast<std::uint8_t>(rgb[i] >> 16);
    q.g = static_cast<std::uint8_t>(rgb[i] >> 8);
    q.b = static_cast<std::uint8_t>(rgb[i]);
    q.a = 255;
    q.normal_x = nx[i];
    q.normal_y = ny[i];
    q.normal_z = nz[i];
    q.curvature = 0;
  }
  cloud->width = static_cast<std::uint32_t>(cloud->size());
  cloud->height = 1;
  cloud->is_dense = false;

  detect.setInputCloud(cloud);
  detect.setReflectance(reflectance);
  for (const auto& ph : photos) detect.addView(ph.image, ph.camera, ph.pose);
  detect.setProgressCallback(progressBar(a.has("quiet")));
  ShadowDetectionResult labels;
  detect.detect(labels);
  std::size_t in_shadow = 0, lit = 0, undecided = 0, segmented = 0;
  for (std::size_t i = 0; i < labels.in_shadow.size(); ++i) {
    if (!labels.decided[i]) ++undecided;
    else if (labels.in_shadow[i]) ++in_shadow;
    else ++lit;
  }
  for (const auto& v : labels.views) segmented += v.segmented;
  std::printf("shadows: %zu interface candidates, %zu after the density filter, %zu pairs kept\n",
              labels.candidates.size(), labels.dense_candidates.size(), labels.interface_pairs.size());
  std::printf("shadows: %zu of %zu photos segmented; %zu shadow points, %zu lit, %zu undecided (%zu non-finite, "
              "%zu unseen)\n",
              segmented, photos.size(), in_shadow, lit, undecided, labels.non_finite, labels.unseen);
  pcl::PCLPointCloud2 result = appendFields(blob, byteBlob("shadow", labels.in_shadow));
  if (relight != "none") {
    correct.setInputCloud(cloud);
    correct.setShadowLabels(labels.in_shadow);
    correct.setProgressCallback(progressBar(a.has("quiet")));
    pcl::PointCloud<pcl::PointXYZRGBNormal> relit;
    correct.filter(relit);
    const ShadowCorrectionReport& r = correct.getReport();
    std::printf("relight (%s): sun-sky ratio %.3f (%s), %zu boundary points median-filtered\n", relight.c_str(),
                r.sun_sky_ratio,
                cp.sun_sky_ratio > 0 ? "given"
                : r.local_pairs ? ("estimated from " + std::to_string(r.local_pairs) + " local pairs").c_str()
                                : "estimated from the class means",
                r.filtered);
    result = appendFields(result, colourBlob(relit, field));
  }
  saveCloudAtomic(a.positional[2], result);
  std::printf("wrote %s\n", a.positional[2].c_str());
  return 0;
}

}  // namespace paps::cli
