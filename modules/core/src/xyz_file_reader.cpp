#include <paps/core/xyz_file_reader.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <paps/core/cloud_file_layout.h>
#include <paps/core/error.h>

namespace paps {

namespace {

// Reads `count` fixed-size binary records of `step` bytes by chunks (no whole-file buffer),
// appending fn(record) to `out`; the caller has checked that the file holds them.
template <typename Fn>
void readRecords(std::ifstream& f, std::size_t count, std::size_t step, const std::string& path, Positions& out, Fn fn) {
  out.reserve(out.size() + count);
  std::vector<char> buf;
  const std::size_t chunk = 65536;
  for (std::size_t done = 0; done < count;) {
    const std::size_t m = std::min(chunk, count - done);
    buf.resize(m * step);
    if (!f.read(buf.data(), std::streamsize(buf.size()))) throw IoError("cannot read '" + path + "': truncated data");
    for (std::size_t i = 0; i < m; ++i) out.push_back(fn(buf.data() + i * step));
    done += m;
  }
}

// LZF decompression (the format of PCD's binary_compressed data): control bytes below 32 start
// a literal run of ctrl + 1 bytes; others copy (ctrl >> 5) + 2 bytes (7 means a length byte
// follows) from ((ctrl & 31) << 8) + next byte + 1 bytes back. Every read and write is checked.
void lzfDecompress(const std::uint8_t* in, std::size_t in_size, std::uint8_t* out, std::size_t out_size,
                   const std::string& path) {
  auto bad = [&] { return IoError("cannot read '" + path + "': corrupt binary_compressed data"); };
  std::size_t ip = 0, op = 0;
  while (ip < in_size) {
    const unsigned ctrl = in[ip++];
    if (ctrl < 32) {
      const std::size_t len = ctrl + 1;
      if (ip + len > in_size || op + len > out_size) throw bad();
      std::memcpy(out + op, in + ip, len);
      ip += len;
      op += len;
    } else {
      std::size_t len = ctrl >> 5;
      if (len == 7) {
        if (ip >= in_size) throw bad();
        len += in[ip++];
      }
      len += 2;
      if (ip >= in_size) throw bad();
      const std::size_t back = ((std::size_t(ctrl) & 31u) << 8) + in[ip++] + 1;
      if (back > op || op + len > out_size) throw bad();
      for (std::size_t i = 0; i < len; ++i, ++op) out[op] = out[op - back];  // may overlap
    }
  }
  if (op != out_size) throw bad();
}

}  // namespace

bool readPcdXyz(const std::string& path, Positions& out) {
  if (std::filesystem::path(path).extension() != ".pcd") return false;
  const PcdLayout L = readPcdLayout(path);
  if (L.data == PcdLayout::Data::Ascii) return false;
  const bool packed = L.data == PcdLayout::Data::BinaryCompressed;
  // off: byte offset of x, y, z inside a point (binary) or of their column (packed).
  std::size_t off[3];
  const char* xyz[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    const int i = L.field(xyz[a]);
    if (i < 0 || L.types[std::size_t(i)] != 'F' || L.sizes[std::size_t(i)] != 4 || L.counts[std::size_t(i)] != 1)
      return false;
    off[a] = std::size_t(packed ? L.offsetOf(i) * L.points : L.offsetOf(i));
  }
  const std::size_t points = std::size_t(L.points), step = std::size_t(L.point_step);
  std::ifstream f(path, std::ios::binary);
  f.seekg(std::streamoff(L.data_offset));
  if (!f) throw IoError("cannot read '" + path + "': read failed");
  out.clear();
  if (packed) {
    if (points == 0) return true;
    std::uint32_t sz[2];  // packed and unpacked sizes, checked against the file by readPcdLayout
    if (!f.read(reinterpret_cast<char*>(sz), 8)) throw IoError("cannot read '" + path + "': truncated data");
    std::vector<std::uint8_t> packed_bytes(sz[0]), raw(sz[1]);
    if (!f.read(reinterpret_cast<char*>(packed_bytes.data()), std::streamsize(sz[0])))
      throw IoError("cannot read '" + path + "': truncated data");
    lzfDecompress(packed_bytes.data(), packed_bytes.size(), raw.data(), raw.size(), path);
    packed_bytes = {};
    out.resize(points);
    for (std::size_t i = 0; i < points; ++i)
      for (int a = 0; a < 3; ++a) std::memcpy(&out[i][a], raw.data() + off[a] + 4 * i, 4);
    return true;
  }
  readRecords(f, points, step, path, out, [&](const char* rec) {
    Eigen::Vector3f p;
    for (int a = 0; a < 3; ++a) std::memcpy(&p[a], rec + off[a], 4);
    return p;
  });
  return true;
}

bool readPlyXyz(const std::string& path, Positions& out) {
  if (std::filesystem::path(path).extension() != ".ply") return false;
  const PlyLayout L = readPlyLayout(path);
  if (L.elements.empty() || L.elements[0].name != "vertex") return false;
  const PlyLayout::Element& vertex = L.elements[0];
  int axis_of[3] = {-1, -1, -1};
  for (std::size_t i = 0; i < vertex.properties.size(); ++i) {
    const PlyLayout::Property& pr = vertex.properties[i];
    if (pr.count_size) return false;
    for (int a = 0; a < 3; ++a)
      if (pr.name == std::string(1, char('x' + a))) {
        if (pr.kind != 'f') return false;
        axis_of[a] = int(i);
      }
  }
  if (axis_of[0] < 0 || axis_of[1] < 0 || axis_of[2] < 0) return false;
  auto axisOf = [&](std::size_t i) {
    for (int a = 0; a < 3; ++a)
      if (axis_of[a] == int(i)) return a;
    return -1;
  };
  const std::size_t vertices = std::size_t(vertex.count);
  std::ifstream f(path, std::ios::binary);
  f.seekg(std::streamoff(L.data_offset));
  if (!f) throw IoError("cannot read '" + path + "': read failed");
  auto bad = [&](const char* what) { return IoError("cannot read '" + path + "': " + what); };
  out.clear();
  if (L.format == PlyLayout::Format::Ascii) {
    out.reserve(vertices);  // bounded by the file's size (readPlyLayout)
    std::string line;
    for (std::size_t v = 0; v < vertices; ++v) {
      if (!std::getline(f, line)) throw bad("truncated vertex list");
      std::istringstream vs(line);
      Eigen::Vector3f p;
      for (std::size_t i = 0; i < vertex.properties.size(); ++i) {
        double value;
        if (!(vs >> value)) throw bad("a vertex line has too few values");
        const int a = axisOf(i);
        if (a >= 0) p[a] = float(value);
      }
      out.push_back(p);
    }
    return true;
  }
  if (L.format != PlyLayout::Format::BinaryLittleEndian) return false;
  std::size_t step = 0;
  for (const auto& pr : vertex.properties) step += std::size_t(pr.size);
  readRecords(f, vertices, step, path, out, [&](const char* rec) {
    Eigen::Vector3f p;
    for (std::size_t i = 0; i < vertex.properties.size(); ++i) {
      const int a = axisOf(i);
      const int size = vertex.properties[i].size;
      if (a >= 0) {
        if (size == 4) { float v; std::memcpy(&v, rec, 4); p[a] = v; }
        else { double v; std::memcpy(&v, rec, 8); p[a] = float(v); }
      }
      rec += size;
    }
    return p;
  });
  return true;
}

}  // namespace paps
