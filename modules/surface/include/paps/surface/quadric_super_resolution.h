#pragma once
// Quadric super-resolution, QSR (manuscript 2.3.2). Every point of every input scan gets a
// quadric+height descriptor (paps/core/quadric_height_patch.h). The patches of the first scan
// query similar patches among all (kd-tree candidates in descriptor space, then exact
// re-ranking with the masked distance of equation 2.3 and the weights of 2.4); the points of
// the similar patches are aggregated on a finer grid (equation 2.5, l1 by IRLS), and the
// output is sampled by projecting Poisson-regularised seeds on the super-resolution patches
// with a robust partition of unity (equation 2.6). Noisy scans are first denoised by
// paps::SimilarityDenoising (denoise_input; not in the manuscript, measured in
// docs/superresolution.md).
#include <cstddef>
#include <cstdint>
#include <vector>

#include <pcl/surface/processing.h>

#include <paps/core/thread_count.h>
#include <paps/core/noise_estimation.h>
#include <paps/core/view_point_option.h>
#include <paps/core/positions.h>
#include <paps/core/progress.h>

namespace paps {

/// A thin ball (see widen_sparse_fits) is refitted on up to this many times target_neighbours
/// distinct positions: 8 x 36 reach the next scan line on the scan-line bench's far lines
/// (0.6 m apart, 6 cm along).
constexpr int kQsrThinWidening = 8;

/// Parameters of QSR. Only the patch radius and the similarity radius are the user's; zero
/// means "choose from the data" and the report says what was chosen.
struct QuadricSuperResolutionParameters {
  /// Patch radius R in metres (> 0), or 0: the radius holding `target_neighbours` points.
  float patch_radius = 0.f;
  /// Neighbour count of a typical (median) point that sets R when patch_radius is 0 (9 to 1000).
  int target_neighbours = 36;
  /// Similarity radius r_sim in metres (RMS height difference over the shared valid bins),
  /// or 0: the median over patches of the distance to their most similar other patch.
  float similarity_radius = 0.f;
  /// Multiplier of the automatic r_sim (> 0).
  float similarity_scale = 1.f;
  /// Output count = factor x finite count of the first scan when output_count is 0 (1 to 1000).
  float factor = 4.f;
  std::size_t output_count = 0;
  /// Low-resolution bins per side (0: round(sqrt(mean neighbour count at R)), 2 to 16).
  int grid_lr = 0;
  /// Super-resolution bins per side (0: round(grid_lr x sqrt(K)), K the mean summed
  /// similarity weight, at most 4 x grid_lr).
  int grid_sr = 0;
  /// Similar patches kept per patch at most (0 to 256; 0: none, each SR patch is built from its
  /// own data alone: a local interpolation).
  int similar_patches = 16;
  /// Kd-tree candidates per orientation before the exact masked re-ranking (1 to 1024).
  int candidates = 24;
  /// Descriptors compared per kd-tree query (0: exact). The tree splits the descriptors'
  /// principal axes: 64 checks there find closer patches than 128 on the given axes
  /// (docs/superresolution.md, "Similar patches on principal axes").
  int search_checks = 64;
  /// Width of the aggregation kernel (2.5) in units of s0 / sqrt(1 + K), s0 the input
  /// spacing and K - 1 the mean summed similarity weight (> 0), or 0: automatic, 0.7 without
  /// `adapt_to_noise`, else from the noise (0.7 to 1.4, see noiseAdaptedParameters).
  float kernel_scale = 0.f;
  /// IRLS passes of the aggregation (2.5) and of the projection (2.6) (0 to 10).
  int irls_iterations = 2;
  /// Radius of the tangent discs over which the output seeds are spread, in mean input
  /// spacings s0 (0.1 to 10). 1.2 (default) covers the rims and scores best on the bench's
  /// protocol (dense points to their nearest output); 0.68 is APSS/RIMLS's disc. On scans
  /// sampled much more finely along scan lines than across them, wide discs put seeds far
  /// into the gaps; thin_disc narrows the discs of such points by itself (scan-line bench:
  /// 1.534e-3 m to the ground at 1.2, 1.261e-3 at 0.6; docs/superresolution.md, "Scan-line
  /// sampling").
  float seed_disc = 1.2f;
  /// Scale of the seed disc of a point whose ball at R is too thin for a quadric (along one or
  /// two LiDAR scan lines, a strip, a sparse part; QuadricFit::conditioning < 1e-3), in (0, 1];
  /// 1 disables. Across such a ball the surface is an extrapolation, so its seeds stay nearer
  /// the returns. 0.5 (default) puts the default disc's output on the scan-line bench as close
  /// to the ground as a global seed_disc of 0.6, while evenly sampled parts keep the wide
  /// disc (docs/superresolution.md, "Narrower seed discs on thin balls").
  float thin_disc = 0.5f;
  /// Where the ball of radius R holds fewer distinct positions than the quadric's 6 unknowns,
  /// refit it on the nearest target_neighbours distinct positions
  /// (exact duplicates counted once), at the radius they need. Also where the ball is too
  /// thin for a quadric, whatever its count (points along one or two LiDAR scan lines, with
  /// the next line beyond R): refit on the nearest 36, 72, ... up to 288 distinct positions,
  /// the first that cover two directions. Off: such points keep their fit at R.
  bool widen_sparse_fits = true;
  /// With the automatic kernel_scale: measure the noise of the first scan and widen the kernel
  /// as q = noise sigma / R grows (R the patch radius), by the rule of noiseAdaptedParameters
  /// (measured, docs/superresolution.md "Noise-adaptive kernel"). Off (default): 0.7 whatever
  /// the noise. Opt-in because at 0.5% noise it brings the output 2-4% closer to the true
  /// surface on the bench shapes for 2.9x the time, and scores 5% worse on the bench's
  /// dense-to-output error. Scans denoised first (`denoise_input`) get the quiet kernel (0.7).
  bool adapt_to_noise = false;
  /// Noise standard deviation of the first scan (metres, >= 0) for `adapt_to_noise` and
  /// `denoise_input`; 0: estimated (paps::estimateNoiseLevel at the patch radius).
  float noise_sigma = 0.f;
  /// Denoise every scan with paps::SimilarityDenoising (its noise-adaptive radius and weight,
  /// one pass: the aggregation over similar patches is the second filter) before the
  /// patches are built. Auto (default): when the first scan's noise is at least 5% of the
  /// patch radius, where it was measured to bring the output 1.1x to 5x closer to the true
  /// surface (docs/superresolution.md, "Denoising noisy scans first"); from 0.5% of the patch
  /// radius too when the surface is smooth at that scale (the residual of quadric fits over
  /// balls of 2R is less than 1.3x that over balls of R: it is noise, not relief; measured on
  /// the scan-line bench, 17% closer to the ground). Otherwise patch similarity already
  /// separates relief from noise and the input is used as it is.
  using Denoise = DenoiseFirst;
  Denoise denoise_input = Denoise::Auto;
  std::uint64_t seed = 1;
  /// A first scan of more finite points than this is super-resolved in tiles of at most this
  /// many (0: one piece whatever the size, the first denoising included): 5M points x2 took
  /// 5.8 GB in one piece. The patch radius, the noise, the decision to denoise first (the
  /// denoising is the tiled SimilarityDenoising) and the low-resolution grid are chosen on the
  /// whole scan; each tile then finds its similar patches among its own points, and seeds the
  /// output from its core points only, its share of the output count in proportion to the
  /// surface its core covers. A tile's normals take the side of those of the tiles before it
  /// where they meet, so that the orientation runs on across tiles.
  std::size_t max_tile_points = 2000000;
  /// Halo of a tile in patch radii (1 to 10): a core point's seeds are projected on the patches
  /// of the points within about 1.5 R of it, whose fits read their own balls of R.
  float tile_margin = 3.f;
  void validate() const;
};

/// What a run chose and met.
struct QuadricSuperResolutionReport {
  float patch_radius = 0.f, similarity_radius = 0.f;
  int grid_lr = 0, grid_sr = 0;
  double mean_neighbours = 0;       ///< at the patch radius, first scan
  double mean_similar_weight = 0;   ///< K - 1: mean summed similarity weight of other patches
  std::size_t patches = 0;          ///< descriptors over all scans
  std::size_t plane_fallbacks = 0;  ///< fits that use the plane: flat_fits + ill_posed_fits
  /// Fits whose curvature is below the resolution of the patch (flat parts of the scene: the
  /// plane is the right answer there, not a failure).
  std::size_t flat_fits = 0;
  /// Fits with too few neighbours (< 6) or collinear / singular neighbourhoods, after widening.
  std::size_t ill_posed_fits = 0;
  /// Fits of sparse parts made on a wider support (widen_sparse_fits).
  std::size_t widened_fits = 0;
  /// Balls at R with 6 distinct positions or more that are too thin for a quadric (points
  /// along one or two scan lines of a LiDAR, a strip), all scans: their fit is remade on a
  /// wider support that reaches across (counted in widened_fits when kept).
  std::size_t thin_balls = 0;
  /// Points of the first scan whose ball at R is too thin for a quadric (sparse or not), which
  /// seed over discs narrowed by thin_disc.
  std::size_t narrowed_discs = 0;
  std::size_t without_similar = 0;  ///< patches of the first scan with no similar patch
  /// Points of the first scan that seed and anchor the output without a comparable descriptor
  /// (rims, sparse parts): their patch is their quadric alone.
  std::size_t quadric_only = 0;
  std::size_t output = 0;
  std::size_t unprojected = 0;      ///< output seeds with no usable patch nearby, left in place
  float spacing = 0.f;              ///< mean input spacing s0 of the first scan (metres)
  float disc_radius = 0.f;          ///< seed disc radius, seed_disc x spacing (metres)
  float noise_sigma = 0.f;          ///< noise the parameters were adapted to (metres; 0: none)
  bool noise_estimated = false;     ///< noise_sigma was measured (not given)
  float kernel_scale = 0.f;         ///< aggregation kernel scale used
  bool denoised = false;            ///< the scans were denoised first (denoise_input)
  /// Passes of that first denoising on the first scan (0: not denoised): one, or the
  /// denoiser's own count from q = 0.75 (noise / the denoiser's base radius; dense scans
  /// under heavy noise).
  int denoise_passes = 0;
  /// Interleaved subsets that first denoising cut the first scan into (1: none; 0: not
  /// denoised; SimilarityDenoisingParameters::max_noise_ratio).
  std::size_t denoise_subsets = 0;
  /// Noise measured over balls of 2R / over balls of R, first scan (0: not measured; it is
  /// measured with denoise_input Auto when the noise is between 0.5% and 5% of R). Near 1 on
  /// a surface smooth at the patch scale; well above 1 where relief finer than 2R shows.
  float noise_growth = 0.f;
  /// Tiles the first scan was cut into (1: one piece; max_tile_points) and the most points of
  /// the first scan a tile held, halo included. With tiles, the counts above add up every
  /// tile's (the fit and patch counts include the halos; narrowed_discs, quadric_only,
  /// without_similar, unprojected and output count each point once), and similarity_radius,
  /// mean_neighbours, mean_similar_weight, spacing, disc_radius and kernel_scale are means
  /// over the tiles weighted by their core points; grid_lr and grid_sr are those of the most
  /// core points.
  std::size_t tiles = 1, largest_tile = 0;
};

/// The noise-adaptive rule (measured on the distance from the output to the true surface, on
/// the bench's engraved plane and rs1 and on a small engraved plane, 0.01% to 1% noise,
/// docs/superresolution.md "Noise-adaptive kernel"): `params` with an automatic kernel_scale
/// (0) set from q = noise_sigma / patch_radius: 0.7 up to q = 0.05, growing linearly to 1.4 at
/// q = 0.25 and kept there; 0.7 when adapt_to_noise is off. An explicit kernel_scale and every
/// other field are kept. patch_radius > 0 and noise_sigma >= 0, else InvalidParameter.
QuadricSuperResolutionParameters noiseAdaptedParameters(const QuadricSuperResolutionParameters& params,
                                                        float patch_radius, float noise_sigma);

/// Super-resolves scans[0] using all scans (scans[0] included) as the source of similar
/// patches. NaN points are ignored. Throws InvalidInput when scans is empty or scans[0] has
/// fewer than 10 finite points, InvalidParameter for bad parameters. With `normals`, also the
/// unit normal of the SR surface at each output point (one per output point, NaN where the
/// point was not projected), oriented as the input's normals propagated over the scan. With
/// `curvature`, what PCL's MLS writes in the curvature field: the surface variation of the
/// patch ball of the point of scans[0] each output point was made from (of the denoised scan
/// when QSR denoises first; NaN where that ball has no normal). With `source`, the index in
/// scans[0] of that point (the PCL stage copies its other fields, colour or intensity, to the
/// new point, as PCL's MLS does).
Positions superResolveQuadric(const std::vector<Positions>& scans, const QuadricSuperResolutionParameters& params,
                              QuadricSuperResolutionReport* report = nullptr, const ProgressCallback& progress = {},
                              Normals* normals = nullptr, std::vector<float>* curvature = nullptr,
                              std::vector<int>* source = nullptr);

/// The pcl::CloudSurfaceProcessing stage: the input cloud (with its indices) is the scan to
/// super-resolve; addScan() adds other scans of the same object, already registered. An
/// output type with normals gets the SR surface's, turned towards setViewPoint()'s point, else
/// towards the input's sensor_origin_ when it is set (not 0 0 0), else propagated over the scan.
template <typename PointIn, typename PointOut = PointIn>
class QuadricSuperResolution : public pcl::CloudSurfaceProcessing<PointIn, PointOut>, public ThreadCountOption,
                               public ViewPointOption {
 public:
  void setParameters(const QuadricSuperResolutionParameters& p) { p.validate(); params_ = p; }
  const QuadricSuperResolutionParameters& getParameters() const { return params_; }
  /// Patch radius in metres; 0 chooses it.
  void setPatchRadius(float r) { auto p = params_; p.patch_radius = r; setParameters(p); }
  /// Similarity radius in metres; 0 chooses it.
  void setSimilarityRadius(float r) { auto p = params_; p.similarity_radius = r; setParameters(p); }
  void setUpsamplingFactor(float f) { auto p = params_; p.factor = f; setParameters(p); }
  /// The automatic kernel scale follows the measured noise (default off).
  void setAdaptToNoise(bool on) { auto p = params_; p.adapt_to_noise = on; setParameters(p); }
  /// Denoise the scans first: Off, Auto (default: when the measured noise is high) or On.
  void setDenoiseInput(QuadricSuperResolutionParameters::Denoise d) { auto p = params_; p.denoise_input = d; setParameters(p); }
  /// Noise standard deviation in metres for the adaptation; 0 estimates it.
  void setNoiseSigma(float s) { auto p = params_; p.noise_sigma = s; setParameters(p); }
  /// Seed disc radius in mean input spacings (default 1.2; about 0.6 for scan-line LiDAR).
  void setSeedDisc(float spacings) { auto p = params_; p.seed_disc = spacings; setParameters(p); }
  void setThinDisc(float scale) { auto p = params_; p.thin_disc = scale; setParameters(p); }
  /// Tiles of at most this many points of the input (0: one piece; default 2M).
  void setMaxTilePoints(std::size_t n) { auto p = params_; p.max_tile_points = n; setParameters(p); }
  void addScan(const typename pcl::PointCloud<PointIn>::ConstPtr& scan) { extra_.push_back(scan); }
  void clearScans() { extra_.clear(); }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const QuadricSuperResolutionReport& getReport() const { return report_; }

  /// As pcl::CloudSurfaceProcessing::process, but without an input cloud it throws
  /// InvalidInput (PCL's reads the missing cloud).
  void process(pcl::PointCloud<PointOut>& output) override {
    requireInputCloud(this->input_);
    pcl::CloudSurfaceProcessing<PointIn, PointOut>::process(output);
  }

 protected:
  void performProcessing(pcl::PointCloud<PointOut>& output) override;

 private:
  QuadricSuperResolutionParameters params_;
  QuadricSuperResolutionReport report_;
  ProgressCallback progress_;
  std::vector<typename pcl::PointCloud<PointIn>::ConstPtr> extra_;
};

}  // namespace paps

#ifdef PAPS_NO_PRECOMPILE
#include <paps/surface/impl/quadric_super_resolution.hpp>
#endif
