#include <paps/core/cloud_io.h>

#include <cstdio>
#include <cstring>
#include <algorithm>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <pcl/common/io.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>

#include <paps/core/cloud_file_layout.h>
#include <paps/core/error.h>
#include <paps/core/interrupt_cleanup.h>

#include "quiet_pcl_io.h"

namespace paps {

namespace {

std::string extensionOf(const std::string& path) {
  std::string e = std::filesystem::path(path).extension().string();
  for (auto& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

struct XyzFields {
  int offset[3];
  std::uint8_t datatype[3];
};

XyzFields findXyz(const pcl::PCLPointCloud2& cloud) {
  XyzFields f{};
  const char* names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    const auto it = std::find_if(cloud.fields.begin(), cloud.fields.end(),
                                 [&](const pcl::PCLPointField& pf) { return pf.name == names[a]; });
    if (it == cloud.fields.end())
      throw InvalidInput(std::string("the cloud has no '") + names[a] + "' field");
    if (it->datatype != pcl::PCLPointField::FLOAT32 && it->datatype != pcl::PCLPointField::FLOAT64)
      throw InvalidInput(std::string("field '") + names[a] + "' is not float32 or float64");
    f.offset[a] = static_cast<int>(it->offset);
    f.datatype[a] = it->datatype;
    if (std::uint64_t(it->offset) + (it->datatype == pcl::PCLPointField::FLOAT32 ? 4 : 8) > cloud.point_step)
      throw InvalidInput(std::string("field '") + names[a] + "' lies past the end of a point");
  }
  const std::uint64_t n = std::uint64_t(cloud.width) * cloud.height;
  if (n > 0 && cloud.data.size() / n < cloud.point_step)
    throw InvalidInput("the cloud holds " + std::to_string(cloud.data.size()) + " bytes for " + std::to_string(n) +
                       " points of " + std::to_string(cloud.point_step) + " bytes");
  return f;
}

// The temporary beside `path` that a write goes to before its rename; it keeps the extension
// (PCL's writers choose the format from it).
std::string temporaryPathFor(const std::string& path, const std::string& ext) {
  const std::filesystem::path target(path);
  const std::filesystem::path dir = target.has_parent_path() ? target.parent_path() : ".";
  return (dir / ("." + target.stem().string() + ".tmp" + std::to_string(::getpid()) + ext)).string();
}

}  // namespace

using detail::quietPclIo;

pcl::PCLPointCloud2 loadCloud(const std::string& path, Eigen::Vector3f* origin) {
  if (origin) origin->setZero();
  const std::string ext = extensionOf(path);
  // PCL's readers trust the header (allocation from its counts, a crash without FIELDS):
  // the header is checked against the file first, and a bad one is one clear error.
  PcdLayout layout;
  if (ext == ".pcd") {
    layout = readPcdLayout(path);
    checkPcdAsciiRows(path, layout);
  }
  else if (ext == ".ply") readPlyLayoutForPcl(path);
  else {
    checkInputPath(path);
    throw IoError("cannot read '" + path + "': unknown format '" + ext + "' (expected .pcd or .ply)");
  }
  // PCL's readers also throw, e.g. std::out_of_range on an ASCII row with too few values:
  // that is a damaged file too, and reaches the caller as IoError like every other.
  pcl::PCLPointCloud2 cloud;
  std::string thrown;
  const int rc = quietPclIo([&] {
    if (ext == ".ply") return pcl::PLYReader().read(path, cloud);
    Eigen::Vector4f o = Eigen::Vector4f::Zero();
    Eigen::Quaternionf q;
    int version = 0;
    return pcl::PCDReader().read(path, cloud, o, q, version);
  }, thrown);
  if (rc < 0)
    throw IoError("cannot read '" + path + "': not a valid " + ext.substr(1) + " file" +
                  (thrown.empty() ? "" : " (" + thrown + ")"));
  if (cloud.data.size() < static_cast<std::size_t>(cloud.row_step) * cloud.height)
    throw IoError("cannot read '" + path + "': truncated data");
  // The VIEWPOINT as our header check read it (PCL's reader leaves garbage on "nan"); one
  // that is not finite in float tells nothing: read as none.
  const Eigen::Vector3d o(layout.origin[0], layout.origin[1], layout.origin[2]);
  if (origin && o.allFinite() && o.cwiseAbs().maxCoeff() < 3e38) *origin = o.cast<float>();
  try {
    findXyz(cloud);
  } catch (const InvalidInput& e) {
    throw IoError("cannot use '" + path + "': " + e.what());
  }
  return cloud;
}

void checkCloudOutputPath(const std::string& path) {
  checkOutputPath(path);
  const std::string ext = extensionOf(path);
  if (ext != ".pcd" && ext != ".ply")
    throw IoError("cannot write '" + path + "': unknown format '" + ext + "' (expected .pcd or .ply)");
}

void saveCloudAtomic(const std::string& path, const pcl::PCLPointCloud2& cloud, const Eigen::Vector3f& sensor_origin) {
  checkCloudOutputPath(path);
  const std::string ext = extensionOf(path);
  // PCL's PLY writer turns a field of several values into a list property (which PLY readers
  // of point clouds, ours and PCL's own, refuse), and writes an integer "rgb" in 4 bytes where
  // its header declares 3 (every later record misaligned): refused, not written wrong.
  if (ext == ".ply")
    for (const auto& f : cloud.fields) {
      if (f.count > 1)
        throw IoError("cannot write '" + path + "' as PLY: field '" + f.name + "' holds " + std::to_string(f.count) +
                      " values a point; write .pcd to keep every field");
      if ((f.name == "rgb") && f.datatype != pcl::PCLPointField::FLOAT32)
        throw IoError("cannot write '" + path + "' as PLY: PCL's PLY writer misaligns an integer 'rgb' field; "
                      "write .pcd to keep every field");
    }
  std::error_code ec;
  const std::string tmp = temporaryPathFor(path, ext);
  const TemporaryFileGuard guard(tmp);  // removed on Ctrl-C (installInterruptCleanup)
  if (!sensor_origin.allFinite()) throw InvalidParameter("sensor_origin", "non-finite", "finite coordinates");
  const Eigen::Vector4f origin(sensor_origin.x(), sensor_origin.y(), sensor_origin.z(), 0.f);
  const Eigen::Quaternionf orient = Eigen::Quaternionf::Identity();
  std::string thrown;
  const int rc = quietPclIo([&] {
    return ext == ".pcd" ? pcl::PCDWriter().writeBinary(tmp, cloud, origin, orient)
                         : pcl::PLYWriter().writeBinary(tmp, cloud, origin, orient, false);
  }, thrown);
  if (rc < 0) {
    std::filesystem::remove(tmp, ec);
    throw IoError("cannot write '" + path + "': the writer failed" + (thrown.empty() ? "" : " (" + thrown + ")"));
  }
  commitTemporaryFile(tmp, path);
}

Positions positionsOf(const pcl::PCLPointCloud2& cloud) {
  const XyzFields f = findXyz(cloud);
  const std::size_t n = static_cast<std::size_t>(cloud.width) * cloud.height;
  Positions out(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* base = cloud.data.data() + i * cloud.point_step;
    for (int a = 0; a < 3; ++a) {
      if (f.datatype[a] == pcl::PCLPointField::FLOAT32) {
        float v;
        std::memcpy(&v, base + f.offset[a], 4);
        out[i][a] = v;
      } else {
        double v;
        std::memcpy(&v, base + f.offset[a], 8);
        out[i][a] = static_cast<float>(v);
      }
    }
  }
  return out;
}

void writePositions(const Positions& p, pcl::PCLPointCloud2& cloud) {
  const XyzFields f = findXyz(cloud);
  const std::size_t n = static_cast<std::size_t>(cloud.width) * cloud.height;
  if (p.size() != n) throw InvalidInput("positions and cloud differ in size");
  bool dense = true;
  for (std::size_t i = 0; i < n; ++i) {
    std::uint8_t* base = cloud.data.data() + i * cloud.point_step;
    dense = dense && isFinite(p[i]);
    for (int a = 0; a < 3; ++a) {
      if (f.datatype[a] == pcl::PCLPointField::FLOAT32) {
        const float v = p[i][a];
        std::memcpy(base + f.offset[a], &v, 4);
      } else {
        const double v = p[i][a];
        std::memcpy(base + f.offset[a], &v, 8);
      }
    }
  }
  cloud.is_dense = dense;
}

Positions loadPositions(const std::string& path) { return positionsOf(loadCloud(path)); }

pcl::PCLPointCloud2 gatherPoints(const pcl::PCLPointCloud2& cloud, const std::vector<int>& rows) {
  const std::size_t n = static_cast<std::size_t>(cloud.width) * cloud.height;
  pcl::PCLPointCloud2 out;
  out.header = cloud.header;
  out.fields = cloud.fields;
  out.is_bigendian = cloud.is_bigendian;
  out.point_step = cloud.point_step;
  out.width = static_cast<std::uint32_t>(rows.size());
  out.height = 1;
  out.row_step = out.point_step * out.width;
  out.is_dense = cloud.is_dense;
  out.data.resize(rows.size() * cloud.point_step);
  for (std::size_t q = 0; q < rows.size(); ++q) {
    if (rows[q] < 0 || static_cast<std::size_t>(rows[q]) >= n)
      throw InvalidParameter("rows", std::to_string(rows[q]), "an index of the cloud's " + std::to_string(n) + " points");
    std::memcpy(out.data.data() + q * cloud.point_step, cloud.data.data() + static_cast<std::size_t>(rows[q]) * cloud.point_step,
                cloud.point_step);
  }
  return out;
}

CloudRows appendedRows(const pcl::PCLPointCloud2& cloud, const std::vector<pcl::PCLPointField>& extra_fields,
                       std::uint32_t extra_step, std::function<void(std::size_t, std::uint8_t*)> fill_extra) {
  // Fields of `cloud` that `extra` does not replace (padding "_" fields are dropped: they
  // carry nothing), packed one after the other; then every field of `extra` but its padding.
  auto named = [&](const std::string& name) {
    for (const auto& f : extra_fields)
      if (f.name == name) return true;
    return false;
  };
  struct Copy { bool from_extra; std::uint32_t src, dst, bytes; };
  std::vector<Copy> copies;
  CloudRows rows;
  pcl::PCLPointCloud2& out = rows.layout;
  out.header = cloud.header;
  out.width = cloud.width;
  out.height = cloud.height;
  out.is_bigendian = cloud.is_bigendian;
  out.is_dense = cloud.is_dense;
  std::uint32_t step = 0;
  auto add = [&](const pcl::PCLPointField& f, bool from_extra, std::uint32_t source_step) {
    const std::uint32_t bytes = std::uint32_t(pcl::getFieldSize(f.datatype)) * std::max<std::uint32_t>(f.count, 1);
    if (std::uint64_t(f.offset) + bytes > source_step)
      throw InvalidInput("appendFields: field '" + f.name + "' lies past the end of a point");
    pcl::PCLPointField g = f;
    g.offset = step;
    out.fields.push_back(g);
    copies.push_back({from_extra, f.offset, step, bytes});
    step += bytes;
  };
  for (const auto& f : cloud.fields)
    if (f.name != "_" && !named(f.name)) add(f, false, cloud.point_step);
  for (const auto& f : extra_fields)
    if (f.name != "_") add(f, true, extra_step);
  out.point_step = step;
  out.row_step = step * out.width;
  rows.fill = [&cloud, copies = std::move(copies), step, extra_step, fill_extra = std::move(fill_extra)](
                  std::size_t first, std::size_t count, std::uint8_t* dst) {
    std::vector<std::uint8_t> extra(extra_step);
    for (std::size_t q = 0; q < count; ++q) {
      const std::size_t i = first + q;
      fill_extra(i, extra.data());
      const std::uint8_t* src = cloud.data.data() + i * cloud.point_step;
      for (const Copy& c : copies)
        std::memcpy(dst + q * step + c.dst, (c.from_extra ? extra.data() : src) + c.src, c.bytes);
    }
  };
  return rows;
}

pcl::PCLPointCloud2 appendFields(const pcl::PCLPointCloud2& cloud, const pcl::PCLPointCloud2& extra) {
  const std::size_t n = static_cast<std::size_t>(cloud.width) * cloud.height;
  if (static_cast<std::size_t>(extra.width) * extra.height != n)
    throw InvalidInput("appendFields: the clouds differ in size");
  CloudRows rows = appendedRows(cloud, extra.fields, extra.point_step, [&](std::size_t i, std::uint8_t* row) {
    std::memcpy(row, extra.data.data() + i * extra.point_step, extra.point_step);
  });
  rows.layout.is_dense = cloud.is_dense && extra.is_dense;
  return gatherRows(rows);
}

pcl::PCLPointCloud2 gatherRows(const CloudRows& rows) {
  pcl::PCLPointCloud2 out = rows.layout;
  const std::size_t n = static_cast<std::size_t>(out.width) * out.height;
  out.data.resize(n * out.point_step);
  if (n) rows.fill(0, n, out.data.data());
  return out;
}

void saveCloudAtomic(const std::string& path, const CloudRows& rows, const Eigen::Vector3f& sensor_origin) {
  const pcl::PCLPointCloud2& layout = rows.layout;
  const std::size_t n = static_cast<std::size_t>(layout.width) * layout.height;
  const bool padded = std::any_of(layout.fields.begin(), layout.fields.end(),
                                  [](const pcl::PCLPointField& f) { return f.name == "_"; });
  if (extensionOf(path) != ".pcd" || padded || n == 0) {
    saveCloudAtomic(path, gatherRows(rows), sensor_origin);
    return;
  }
  checkCloudOutputPath(path);
  if (!sensor_origin.allFinite()) throw InvalidParameter("sensor_origin", "non-finite", "finite coordinates");
  const std::string tmp = temporaryPathFor(path, ".pcd");
  const TemporaryFileGuard guard(tmp);  // removed on Ctrl-C (installInterruptCleanup)
  const Eigen::Vector4f origin(sensor_origin.x(), sensor_origin.y(), sensor_origin.z(), 0.f);
  const std::string header = pcl::PCDWriter().generateHeaderBinary(layout, origin, Eigen::Quaternionf::Identity());
  std::error_code ec;
  try {
    std::ofstream os(tmp, std::ios::binary | std::ios::trunc);
    os << header << "DATA binary\n";
    // Blocks of about 4 MB: the rows never exist whole.
    const std::size_t block = std::max<std::size_t>(1, (std::size_t(4) << 20) / std::max<std::uint32_t>(layout.point_step, 1));
    std::vector<std::uint8_t> buffer;
    for (std::size_t first = 0; first < n && os; first += block) {
      const std::size_t count = std::min(block, n - first);
      buffer.resize(count * layout.point_step);
      rows.fill(first, count, buffer.data());
      os.write(reinterpret_cast<const char*>(buffer.data()), static_cast<std::streamsize>(buffer.size()));
    }
    os.flush();
    if (!os) throw IoError("cannot write '" + path + "': writing the temporary file failed");
  } catch (...) {
    // A failed write or a throwing fill: the target stays as it was, no temporary is left.
    std::filesystem::remove(tmp, ec);
    throw;
  }
  commitTemporaryFile(tmp, path);
}

}  // namespace paps
