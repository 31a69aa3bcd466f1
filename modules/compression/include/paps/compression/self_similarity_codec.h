#pragma once
// Self-similarity point-cloud codec (manuscript 2.2.3): seeds by dart throwing, plane+height
// patches on a radial pattern, a K-SVD dictionary and sparse, quantized, entropy-coded
// coefficients. The non-template core works on Positions; see point_cloud_compression.h for
// the pcl::PointCloud<PointT> stream API.
#include <cstdint>
#include <string>
#include <vector>

#include <paps/compression/bitstream.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps::compression {

/// The five parameters of the manuscript, plus the few that an expert may tune.
struct CompressionParameters {
  /// R, patch radius in metres. 0 = automatic: the radius whose ball around a typical point
  /// (the median) holds `patch_points` input points. Valid: 0 or a finite value > 0.
  float patch_radius = 0.f;
  /// Mean number of input points in a patch when the radius is automatic, in [8, 100000].
  int patch_points = 256;
  /// N_bins: the radial pattern has N_bins/2 rings of 2 N_bins samples plus the centre
  /// (N_bins^2 + 1 samples, Fig. 2.4). Even, in [4, 32]. Manuscript: 16.
  int bins = 16;
  /// Number of dictionary atoms, in [1, 256]. Manuscript: 16 to 32.
  int atoms = 24;
  /// T0, non-zero coefficients per patch, in [1, atoms].
  int sparsity = 4;
  /// Seed coordinate quantization, bits per axis over the largest bounding-box side, in
  /// [4, 21]. Manuscript: 16.
  int seed_bits = 16;
  /// Coefficient quantization in bits (sign included), in [2, 12]. Manuscript: 8.
  int coefficient_bits = 8;
  /// Frame correction angle quantization in bits, in [3, 12]. Manuscript: 8.
  int angle_bits = 8;
  /// Dictionary atom quantization in bits (sign included, one scale per atom), in [3, 8].
  /// OMP codes on the quantized atoms, so coarse atoms cost little error: 5 and 6 bits gave
  /// the D2 of 8 bits on the LMS400 scan and on rs1 (format 1 always used 8).
  int dictionary_bits = 6;
  /// Dart-throwing radius of the seeds, as a fraction of R, in [0.25, 2]. 1 = no two seeds
  /// closer than R (manuscript).
  float seed_spacing = 1.f;
  /// K-SVD rounds, in [0, 200].
  int ksvd_iterations = 10;
  /// At most this many patches (a seeded random subset) train the dictionary; all are
  /// coded. In [16, 10^7].
  int max_training_patches = 4096;
  /// Spacing of the decoded points in metres. 0 = the measured input spacing (sqrt of the
  /// area per input point). Valid: 0 or a finite value > 0.
  float output_spacing = 0.f;
  /// Seed of the random choices (seed order, training subset, initial atoms).
  std::uint64_t random_seed = 1;

  /// Throws InvalidParameter naming the first parameter out of range.
  void validate() const;
};

/// Named presets: "compact" (lowest rate), "balanced" (default), "fine" (lowest error).
CompressionParameters compressionPreset(const std::string& name);
std::vector<std::string> compressionPresetNames();

/// What the encoder did and where the bytes went.
struct EncodeReport {
  std::size_t input_points = 0, dropped_non_finite = 0, seeds = 0;
  float patch_radius = 0, output_spacing = 0;
  std::size_t bytes_total = 0, bytes_header = 0, bytes_seeds = 0, bytes_frames = 0,
              bytes_dictionary = 0, bytes_patches = 0;
  EntropyMethod frames_method = EntropyMethod::kRange, patches_method = EntropyMethod::kRange;
  /// Sizes of the patch symbol stream with each back end: range, zstd, lzma (bytes).
  std::size_t patches_sizes[3] = {0, 0, 0}, frames_sizes[3] = {0, 0, 0};
  double mean_nonzeros = 0;     ///< non-zero quantized coefficients per patch
  double ksvd_rmse = 0;         ///< RMSE of the sparse codes on the heights (metres)
  double valid_fraction = 0;    ///< share of pattern samples with data
  /// Estimated bits of the patch stream spent on validity masks, atom indices, values.
  double bits_masks = 0, bits_atoms = 0, bits_values = 0;
  /// Wall time of the encoder stages (seconds): index and radius, seeds, frames and
  /// descriptors, dictionary, coding.
  double seconds_setup = 0, seconds_seeds = 0, seconds_descriptors = 0, seconds_dictionary = 0, seconds_coding = 0;
};

/// Compresses the finite points of `points` (non-finite ones are dropped and counted).
/// Throws InvalidParameter for a bad parameter, InvalidInput when the cloud cannot be coded
/// (empty, fewer points than one patch, all identical, on a line).
std::vector<std::uint8_t> compressPositions(const Positions& points, const CompressionParameters& parameters,
                                            EncodeReport* report = nullptr, const ProgressCallback& progress = {});

struct DecodeOptions {
  bool consolidate = true;   ///< move each point to where the nearby patches agree
  bool regularise = true;    ///< Poisson-disk thinning of the output at half the spacing
  /// Refuse streams that would decode to more points than this (guards memory).
  std::size_t max_points = 400000000;
  /// Refuse streams with more seeds than this.
  std::size_t max_seeds = std::size_t(1) << 22;
};

struct DecodeReport {
  std::size_t seeds = 0, points = 0, removed_by_regularisation = 0;
  float patch_radius = 0, output_spacing = 0;
  std::size_t encoded_points = 0;  ///< number of points the encoder saw
};

/// Decodes a stream produced by compressPositions. Throws CorruptStream (a paps::Error)
/// with the reason for any truncated, corrupted or foreign input; never reads out of bounds.
Positions decompressPositions(const std::uint8_t* data, std::size_t size, const DecodeOptions& options = {},
                              DecodeReport* report = nullptr, const ProgressCallback& progress = {});

}  // namespace paps::compression
