#pragma once
// Stream API in the shape of pcl::io::OctreePointCloudCompression: an object configured once
// (parameters or a named preset) that encodes a pcl::PointCloud<PointT> into a std::ostream
// and decodes it back from a std::istream. Only x, y, z are coded; other fields of decoded
// points are default-constructed.
//
//   paps::compression::PointCloudCompression<pcl::PointXYZ> codec(
//       paps::compression::compressionPreset("balanced"));
//   codec.encodePointCloud(cloud, file);      // cloud: pcl::PointCloud<PointXYZ>::ConstPtr
//   codec.decodePointCloud(file, decoded);    // decoded: pcl::PointCloud<PointXYZ>::Ptr
#include <istream>
#include <iterator>
#include <ostream>

#include <pcl/point_cloud.h>

#include <paps/compression/self_similarity_codec.h>
#include <paps/core/thread_count.h>

namespace paps::compression {

template <typename PointT>
class PointCloudCompression : public ThreadCountOption {
 public:
  using PointCloudConstPtr = typename pcl::PointCloud<PointT>::ConstPtr;
  using PointCloudPtr = typename pcl::PointCloud<PointT>::Ptr;

  explicit PointCloudCompression(const CompressionParameters& parameters = {}) : parameters_(parameters) {
    parameters_.validate();
  }
  const CompressionParameters& parameters() const { return parameters_; }
  void setDecodeOptions(const DecodeOptions& o) { decode_options_ = o; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }

  /// Encodes the finite points of `cloud` and appends the stream to `out`.
  /// Throws InvalidInput / InvalidParameter (see compressPositions), IoError when writing fails.
  void encodePointCloud(const PointCloudConstPtr& cloud, std::ostream& out) {
    if (!cloud) throw InvalidInput("no input cloud");
    const ScopedThreadCount threads(threads_);
    const std::vector<std::uint8_t> b = compressPositions(positionsOf(*cloud), parameters_, &encode_report_, progress_);
    const std::uint64_t n = b.size();
    char len[8];
    for (int i = 0; i < 8; ++i) len[i] = char((n >> (8 * i)) & 0xFF);
    out.write(len, 8);
    out.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
    if (!out) throw IoError("writing the compressed stream failed");
  }

  /// Reads one stream written by encodePointCloud from `in` into `cloud`, which is replaced
  /// as a whole: a cloud that held other points keeps none of their fields, header or sensor
  /// pose (the stream has none of them). Throws CorruptStream for truncated, corrupted or
  /// foreign data; `cloud` is then left as it was.
  void decodePointCloud(std::istream& in, PointCloudPtr& cloud) {
    char len[8];
    if (!in.read(len, 8)) throw CorruptStream("the stream is empty or truncated");
    std::uint64_t n = 0;
    for (int i = 7; i >= 0; --i) n = (n << 8) | std::uint8_t(len[i]);
    if (n > (std::uint64_t(1) << 34)) throw CorruptStream("the stream length prefix is absurd");
    std::vector<std::uint8_t> b;
    // Read in chunks so a lying length prefix cannot make us allocate more than exists.
    char chunk[65536];
    while (b.size() < n) {
      const std::size_t want = std::size_t(std::min<std::uint64_t>(sizeof chunk, n - b.size()));
      in.read(chunk, std::streamsize(want));
      const std::size_t got = std::size_t(in.gcount());
      b.insert(b.end(), chunk, chunk + got);
      if (got < want) throw CorruptStream("the stream is truncated");
    }
    const ScopedThreadCount threads(threads_);
    const Positions p = decompressPositions(b.data(), b.size(), decode_options_, &decode_report_, progress_);
    if (!cloud) cloud.reset(new pcl::PointCloud<PointT>);
    pcl::PointCloud<PointT> decoded;  // default header, pose and fields
    writePositions(p, decoded);
    cloud->swap(decoded);
  }

  const EncodeReport& encodeReport() const { return encode_report_; }
  const DecodeReport& decodeReport() const { return decode_report_; }

 private:
  CompressionParameters parameters_;
  DecodeOptions decode_options_;
  ProgressCallback progress_;
  EncodeReport encode_report_;
  DecodeReport decode_report_;
};

}  // namespace paps::compression
