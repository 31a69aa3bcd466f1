#pragma once
// The container of a .paps compressed point cloud, and the symbol streams inside it.
//
// File layout (all integers little-endian):
//   magic      8 bytes  0x89 'P' 'A' 'P' 'S' 'C' '\r' '\n'
//   version    u32      kFormatVersion
//   sections   u32      number of sections (1..16)
//   per section: tag u32 (four ASCII letters), length u64, crc32 u32 (of the payload), payload
//   crc32      u32      of every byte before it
// A reader checks the magic, the version, every length against the bytes left, every
// checksum, and that nothing follows the final checksum.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <paps/compression/range_coder.h>
#include <paps/core/error.h>

namespace paps::compression {

/// Version 2 codes each patch's validity mask only where the patch owns the surface (see
/// self_similarity_codec.cpp); version 1 streams are still read.
constexpr std::uint32_t kFormatVersion = 2;
constexpr std::uint32_t kOldestReadableVersion = 1;

/// The compressed data is truncated, corrupted, foreign or of an unsupported version.
class CorruptStream : public paps::Error {
 public:
  explicit CorruptStream(const std::string& what) : Error("corrupt or foreign compressed stream: " + what) {}
};

/// CRC-32 (IEEE 802.3, reflected, as in zlib).
std::uint32_t crc32(const std::uint8_t* data, std::size_t size, std::uint32_t crc = 0);

/// Little-endian serialisation into a byte vector.
class ByteWriter {
 public:
  void u8(std::uint8_t v) { bytes.push_back(v); }
  void u16(std::uint16_t v) { for (int i = 0; i < 2; ++i) bytes.push_back(std::uint8_t(v >> (8 * i))); }
  void u32(std::uint32_t v) { for (int i = 0; i < 4; ++i) bytes.push_back(std::uint8_t(v >> (8 * i))); }
  void u64(std::uint64_t v) { for (int i = 0; i < 8; ++i) bytes.push_back(std::uint8_t(v >> (8 * i))); }
  void f32(float v);
  void raw(const std::vector<std::uint8_t>& b) { bytes.insert(bytes.end(), b.begin(), b.end()); }
  std::vector<std::uint8_t> bytes;
};

/// Little-endian reads that throw CorruptStream (naming `what`) instead of overrunning.
class ByteReader {
 public:
  ByteReader(const std::uint8_t* data, std::size_t size, std::string what)
      : data_(data), size_(size), what_(std::move(what)) {}
  std::uint8_t u8() { need(1); return data_[pos_++]; }
  std::uint16_t u16();
  std::uint32_t u32();
  std::uint64_t u64();
  float f32();
  /// A float that must be finite and within [lo, hi].
  float f32In(const char* field, float lo, float hi);
  const std::uint8_t* take(std::size_t n) { need(n); const std::uint8_t* p = data_ + pos_; pos_ += n; return p; }
  std::size_t left() const { return size_ - pos_; }
  std::size_t position() const { return pos_; }

 private:
  void need(std::size_t n) const;
  const std::uint8_t* data_;
  std::size_t size_, pos_ = 0;
  std::string what_;
};

struct Section {
  std::uint32_t tag = 0;
  std::vector<std::uint8_t> payload;
};
/// Four ASCII letters as a tag.
constexpr std::uint32_t sectionTag(const char (&s)[5]) {
  return std::uint32_t(std::uint8_t(s[0])) | std::uint32_t(std::uint8_t(s[1])) << 8 |
         std::uint32_t(std::uint8_t(s[2])) << 16 | std::uint32_t(std::uint8_t(s[3])) << 24;
}
std::string tagName(std::uint32_t tag);

std::vector<std::uint8_t> writeContainer(const std::vector<Section>& sections);
/// Parses and validates a container; throws CorruptStream with the reason. `version`, when
/// given, receives the stream's format version (kOldestReadableVersion..kFormatVersion).
std::vector<Section> readContainer(const std::uint8_t* data, std::size_t size, std::uint32_t* version = nullptr);

/// Back end that stores a symbol stream.
enum class EntropyMethod : std::uint8_t { kRange = 0, kZstd = 1, kLzma = 2 };
const char* entropyMethodName(EntropyMethod m);

/// Writes symbols (each drawn from an AdaptiveModel) both through the adaptive range coder
/// and as raw 16-bit values, then keeps the smallest of: range coder, zstd(raw), lzma(raw).
class SymbolWriter {
 public:
  void put(AdaptiveModel& m, int symbol);
  /// Returns method byte + payload, and which method won (sizes of all in `sizes` if given:
  /// range, zstd, lzma in bytes; 0 for a back end that is not compiled in).
  std::vector<std::uint8_t> finish(EntropyMethod* chosen = nullptr, std::size_t* sizes = nullptr);

 private:
  RangeEncoder range_;
  std::vector<std::uint8_t> raw_;
};

/// Reads what SymbolWriter wrote. `max_symbols` bounds the raw stream a zstd/lzma payload
/// may expand to. Throws CorruptStream when a symbol does not fit its model or the data
/// runs out.
class SymbolReader {
 public:
  SymbolReader(const std::vector<std::uint8_t>& payload, std::size_t max_symbols, const char* what);
  int get(AdaptiveModel& m);
  /// Throws CorruptStream when the stream was overrun (call after the last symbol).
  void checkEnd() const;
  EntropyMethod method() const { return method_; }

 private:
  EntropyMethod method_;
  std::vector<std::uint8_t> raw_;
  std::size_t raw_pos_ = 0;
  std::unique_ptr<RangeDecoder> range_;
  std::string what_;
};

}  // namespace paps::compression
