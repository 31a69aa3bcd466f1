// paps compress IN OUT.paps [options] / paps decompress IN.paps OUT
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <cstring>
#include <sstream>

#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include <paps/compression/rate_distortion.h>
#include <paps/compression/self_similarity_codec.h>
#ifndef PAPS_CODEC_LEAN
#include <paps/core/cloud_io.h>
#endif
#include <paps/core/cloud_file_layout.h>
#include <paps/core/error.h>
#include <paps/core/interrupt_cleanup.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

const char* kCompressUsage =
    "usage: paps compress IN OUT.paps [options]\n"
    "  IN                      .pcd or .ply (only x y z are coded; NaN points are dropped)\n"
    "  --preset P              compact, balanced (default) or fine\n"
    "  --radius R              patch radius R in metres (default: from --patch-points)\n"
    "  --patch-points N        mean input points per patch when R is automatic (default 256)\n"
    "  --bins N                N_bins, radial pattern of N^2+1 samples, even in [4, 32] (default 16,\n"
    "                          compact: 12)\n"
    "  --atoms N               dictionary atoms in [1, 256] (default 24)\n"
    "  --sparsity T            non-zero coefficients per patch, T0 (default 4)\n"
    "  --seed-bits B           seed coordinate quantization in [4, 21] (default 16)\n"
    "  --coefficient-bits B    coefficient quantization in [2, 12] (default 8)\n"
    "  --angle-bits B          frame angle quantization in [3, 12] (default 8)\n"
    "  --dictionary-bits B     dictionary atom quantization in [3, 8] (default 6)\n"
    "  --seed-spacing S        seeds at least S x R apart, in [0.25, 2] (default 1, the manuscript's;\n"
    "                          1.25: about 30% fewer bytes for 3-7% more D2 error, see docs/compression.md)\n"
    "  --ksvd-iterations N     K-SVD rounds (default 10)\n"
    "  --spacing S             decoded point spacing in metres (default: the input's)\n"
    "  --error                 decode again and print D1/D2 errors against the input\n"
    "  --quiet                 no progress bar\n"
    "  --timings               print the wall time of each stage\n";

const char* kDecompressUsage =
    "usage: paps decompress IN.paps OUT [options]\n"
    "  OUT                     .pcd or .ply\n"
    "  --no-consolidate        keep each patch's points where that patch puts them\n"
    "  --no-regularise         skip the Poisson-disk thinning of the output\n"
    "  --quiet, --timings      as for compress\n";

namespace {

std::vector<std::uint8_t> readFile(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw IoError("cannot read '" + path + "': no such file");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError("cannot open '" + path + "'");
  std::vector<std::uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (f.bad()) throw IoError("reading '" + path + "' failed");
  return b;
}

void writeFileAtomic(const std::string& path, const std::vector<std::uint8_t>& b) {
  checkOutputPath(path);
  const std::string tmp = path + ".tmp-paps";
  const TemporaryFileGuard guard(tmp);  // removed on Ctrl-C
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
    f.flush();
    if (!f) {
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      throw IoError("cannot write '" + path + "'");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw IoError("cannot write '" + path + "': " + ec.message());
  }
}

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

// Reads the x y z of a binary or binary_compressed PCD file whose x, y and z are float
// fields, without PCL's whole-cloud copies, so the peak memory of `compress` stays near the
// cloud's own 12 bytes per point (binary_compressed needs its unpacked data once more).
// The header is parsed and checked against the file's size by paps::readPcdLayout (a bad
// one throws). Returns false for another layout (the caller then uses PCL, or paps-codec
// says why not).
bool readBinaryPcdXyz(const std::string& path, Positions& out) {
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

// Reads the vertex x y z of an ascii or binary_little_endian PLY file whose first element is
// the vertices (as scanners and mesh tools write them) and whose x, y, z are float or double;
// other vertex properties are skipped and later elements (faces) are not read. The header is
// parsed and checked by paps::readPlyLayout (a bad one throws). Returns false for another
// layout (the caller then uses PCL, or paps-codec says why not).
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

// Writes float x y z as binary PCD or PLY straight from Positions (no PCL copies of the
// cloud), atomically: a temporary file renamed at the end, removed on failure.
void writeXyzAtomic(const std::string& path, const Positions& pts) {
  checkOutputPath(path);
  const bool pcd = std::filesystem::path(path).extension() == ".pcd";
  std::string header;
  const std::string n = std::to_string(pts.size());
  if (pcd) {
    header = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"
             "COUNT 1 1 1\nWIDTH " + n + "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + n + "\nDATA binary\n";
  } else {
    header = "ply\nformat binary_little_endian 1.0\nelement vertex " + n +
             "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  }
  const std::string tmp = path + ".tmp-paps";
  const TemporaryFileGuard guard(tmp);  // removed on Ctrl-C
  bool ok = true;
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    ok = bool(f);
    f.write(header.data(), std::streamsize(header.size()));
    std::vector<float> buf;
    for (std::size_t i = 0; i < pts.size() && f; i += 65536) {
      const std::size_t m = std::min<std::size_t>(65536, pts.size() - i);
      buf.resize(3 * m);
      for (std::size_t j = 0; j < m; ++j)
        for (int a = 0; a < 3; ++a) buf[3 * j + a] = pts[i + j][a];
      f.write(reinterpret_cast<const char*>(buf.data()), std::streamsize(buf.size() * 4));
    }
    f.flush();
    ok = ok && bool(f);
  }
  std::error_code ec;
  if (ok) std::filesystem::rename(tmp, path, ec);
  if (!ok || ec) {
    std::filesystem::remove(tmp, ec);
    throw IoError("cannot write '" + path + "'");
  }
}

double seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int runCompress(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"quiet", "help", "timings", "error"});
  if (a.has("help")) { std::fputs(kCompressUsage, stdout); return 0; }
  a.allowOnly({"preset", "radius", "patch-points", "bins", "atoms", "sparsity", "seed-bits", "coefficient-bits",
               "angle-bits", "dictionary-bits", "seed-spacing", "ksvd-iterations", "spacing", "error", "quiet", "timings"});
  if (a.positional.size() != 2) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "IN and OUT.paps");
  a.requireOutputApart();
  using namespace paps::compression;
  CompressionParameters p = compressionPreset(a.text("preset", "balanced"));
  p.patch_radius = float(a.number("radius", p.patch_radius));
  p.patch_points = a.integer("patch-points", p.patch_points);
  p.bins = a.integer("bins", p.bins);
  p.atoms = a.integer("atoms", p.atoms);
  p.sparsity = a.integer("sparsity", p.sparsity);
  p.seed_bits = a.integer("seed-bits", p.seed_bits);
  p.coefficient_bits = a.integer("coefficient-bits", p.coefficient_bits);
  p.angle_bits = a.integer("angle-bits", p.angle_bits);
  p.dictionary_bits = a.integer("dictionary-bits", p.dictionary_bits);
  p.seed_spacing = float(a.number("seed-spacing", p.seed_spacing));
  p.ksvd_iterations = a.integer("ksvd-iterations", p.ksvd_iterations);
  p.output_spacing = float(a.number("spacing", p.output_spacing));
  p.validate();

  Positions in;
  if (!readBinaryPcdXyz(a.positional[0], in) && !readPlyXyz(a.positional[0], in)) {
#ifdef PAPS_CODEC_LEAN
    throw InvalidInput(a.positional[0] + ": paps-codec reads binary or binary_compressed PCD files with float x y z "
                       "fields and ascii or binary_little_endian PLY files whose first element is the vertices; "
                       "'paps compress' reads any PCD or PLY");
#else
    in = loadPositions(a.positional[0]);
#endif
  }
  std::printf("read %s: %zu points (%zu finite)\n", a.positional[0].c_str(), in.size(), countFinite(in));
  const ProgressCallback progress = progressBar(a.has("quiet"), a.has("timings"));
  EncodeReport r;
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<std::uint8_t> bytes = compressPositions(in, p, &r, progress);
  const double t_enc = seconds(t0);
  if (r.dropped_non_finite) std::printf("dropped %zu non-finite (NaN) points\n", r.dropped_non_finite);
  std::printf("patch radius %g m%s, output spacing %g m%s, %zu seeds, N_bins %d, %d atoms, T0 %d, "
              "%.2f non-zero coefficients per patch, sparse-code RMSE %.3g m, %.1f%% of pattern samples with data\n",
              r.patch_radius, p.patch_radius > 0 ? "" : " (chosen)", r.output_spacing,
              p.output_spacing > 0 ? "" : " (measured)", r.seeds, p.bins, p.atoms, p.sparsity, r.mean_nonzeros,
              r.ksvd_rmse, 100.0 * r.valid_fraction);
  const std::size_t n = in.size() - r.dropped_non_finite;
  std::printf("bytes: header %zu, seeds %zu, frames %zu (%s), dictionary %zu, patches %zu (%s; range %zu, zstd %zu, "
              "lzma %zu)\n",
              r.bytes_header, r.bytes_seeds, r.bytes_frames, entropyMethodName(r.frames_method), r.bytes_dictionary,
              r.bytes_patches, entropyMethodName(r.patches_method), r.patches_sizes[0], r.patches_sizes[1],
              r.patches_sizes[2]);
  std::printf("compressed %zu points to %zu bytes: %.4f bits per point (%.1fx smaller than float xyz), %.2f s "
              "(%.0f points/s)\n",
              n, bytes.size(), bytes.size() * 8.0 / double(n), 12.0 * double(n) / double(bytes.size()), t_enc,
              double(n) / t_enc);
  std::printf("patch stream: masks %.0f, atom indices %.0f, values %.0f bytes (estimated); "
              "stages: setup %.2f s, seeds %.2f s, frames+descriptors %.2f s, dictionary+codes %.2f s, coding %.2f s\n",
              r.bits_masks / 8, r.bits_atoms / 8, r.bits_values / 8, r.seconds_setup, r.seconds_seeds,
              r.seconds_descriptors, r.seconds_dictionary, r.seconds_coding);
  if (a.has("error")) {
    const Positions out = decompressPositions(bytes.data(), bytes.size(), {}, nullptr, {});
    const CloudErrors e = compareClouds(in, out, r.output_spacing);
    std::printf("error vs input: D1 RMSE %.4g m (PSNR %.2f dB), D2 RMSE %.4g m (PSNR %.2f dB), peak %.4g m; "
                "%.2f%% of input points farther than the spacing from the decoded surface\n",
                e.d1_rmse, e.d1_psnr, e.d2_rmse, e.d2_psnr, e.peak, 100.0 * e.share_above_tolerance);
  }
  writeFileAtomic(a.positional[1], bytes);
  std::printf("wrote %s\n", a.positional[1].c_str());
  return 0;
}

int runDecompress(int argc, char** argv) {
  const Arguments a = Arguments::parse(argc, argv, 2, {"quiet", "help", "timings", "no-consolidate", "no-regularise"});
  if (a.has("help")) { std::fputs(kDecompressUsage, stdout); return 0; }
  a.allowOnly({"no-consolidate", "no-regularise", "quiet", "timings"});
  if (a.positional.size() != 2) throw InvalidParameter("arguments", std::to_string(a.positional.size()), "IN.paps and OUT");
  a.requireOutputApart();
  using namespace paps::compression;
  const std::string& out_path = a.positional[1];
  const std::string ext = std::filesystem::path(out_path).extension().string();
  if (ext != ".pcd" && ext != ".ply") throw InvalidParameter("OUT", out_path, "a .pcd or .ply path");
  const std::vector<std::uint8_t> bytes = readFile(a.positional[0]);
  DecodeOptions o;
  o.consolidate = !a.has("no-consolidate");
  o.regularise = !a.has("no-regularise");
  DecodeReport r;
  const auto t0 = std::chrono::steady_clock::now();
  const Positions out = decompressPositions(bytes.data(), bytes.size(), o, &r, progressBar(a.has("quiet"), a.has("timings")));
  const double t = seconds(t0);
  std::printf("read %s: %zu bytes; %zu seeds, patch radius %g m, spacing %g m\n", a.positional[0].c_str(), bytes.size(),
              r.seeds, r.patch_radius, r.output_spacing);
  std::printf("decoded %zu points (the encoder saw %zu; %.4f bits per encoded point), %zu removed by Poisson-disk "
              "regularisation, %.2f s (%.0f points/s)\n",
              r.points, r.encoded_points, bytes.size() * 8.0 / double(std::max<std::size_t>(1, r.encoded_points)),
              r.removed_by_regularisation, t, double(r.points) / t);
  writeXyzAtomic(out_path, out);
  std::printf("wrote %s\n", out_path.c_str());
  return 0;
}

}  // namespace paps::cli
