// paps compress IN OUT.paps [options] / paps decompress IN.paps OUT
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>

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
#include <paps/core/xyz_file_reader.h>

#include "cli_common.h"
#include "commands.h"

namespace paps::cli {

const char* kCompressUsage =
    "usage: paps compress IN OUT.paps [options]\n"
    "  IN                      .pcd or .ply (only x y z are coded; NaN and Inf points are dropped)\n"
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
    "  --dictionary-bits B     dictionary atom quantization in [3, 8] (default 6; compact: 5)\n"
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
  checkInputPath(path);
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
  commitTemporaryFile(tmp, path);
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
  if (!ok) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw IoError("cannot write '" + path + "'");
  }
  commitTemporaryFile(tmp, path);
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
  // A stream named .pcd or .ply would later be taken for a cloud by every reader.
  a.requireFileOutput(".paps");
  using namespace paps::compression;
  CompressionParameters p = compressionPreset(a.text("preset", "balanced"));
  p.patch_radius = a.real("radius", p.patch_radius);
  p.patch_points = a.integer("patch-points", p.patch_points);
  p.bins = a.integer("bins", p.bins);
  p.atoms = a.integer("atoms", p.atoms);
  p.sparsity = a.integer("sparsity", p.sparsity);
  p.seed_bits = a.integer("seed-bits", p.seed_bits);
  p.coefficient_bits = a.integer("coefficient-bits", p.coefficient_bits);
  p.angle_bits = a.integer("angle-bits", p.angle_bits);
  p.dictionary_bits = a.integer("dictionary-bits", p.dictionary_bits);
  p.seed_spacing = a.real("seed-spacing", p.seed_spacing);
  p.ksvd_iterations = a.integer("ksvd-iterations", p.ksvd_iterations);
  p.output_spacing = a.real("spacing", p.output_spacing);
  p.validate();

  Positions in;
  if (!readPcdXyz(a.positional[0], in) && !readPlyXyz(a.positional[0], in)) {
#ifdef PAPS_CODEC_LEAN
    throw InvalidInput(a.positional[0] + ": paps-codec reads binary or binary_compressed PCD files with float x y z "
                       "fields and ascii or binary_little_endian PLY files whose first element is the vertices; "
                       "'paps compress' reads any PCD or PLY");
#else
    in = loadPositions(a.positional[0]);
#endif
  }
  printRead(a.positional[0], in);
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
  a.requireCloudOutput();
  using namespace paps::compression;
  const std::string& out_path = a.positional[1];
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
