#pragma once
// Adaptive range coder (carry-propagating, 32-bit range, byte output) with adaptive
// frequency models. The decoder never reads outside its buffer: past the end it sees zero
// bytes and records the overrun, so corrupted input gives wrong symbols, never a crash.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace paps::compression {

/// Adaptive frequency model over symbols 0..size-1 (size in [2, 4096]). Counts start at 1,
/// grow by `increment`, and are halved when their total exceeds 2^16.
class AdaptiveModel {
 public:
  explicit AdaptiveModel(int size, int increment = 24);
  int size() const { return static_cast<int>(freq_.size()); }
  std::uint32_t total() const { return total_; }
  std::uint32_t frequency(int s) const { return freq_[s]; }
  std::uint32_t cumulative(int s) const;
  /// Symbol s with cumulative(s) <= target < cumulative(s) + frequency(s); target < total.
  int find(std::uint32_t target, std::uint32_t& cum) const;
  void update(int s);

 private:
  std::vector<std::uint32_t> freq_;
  std::uint32_t total_;
  std::uint32_t increment_;
};

class RangeEncoder {
 public:
  /// Codes [cum, cum + freq) out of total (total <= 2^16, freq >= 1).
  void encode(std::uint32_t cum, std::uint32_t freq, std::uint32_t total);
  void encode(AdaptiveModel& m, int symbol);
  /// A value in [0, 2^bits) with a flat distribution, bits in [0, 32].
  void encodeBits(std::uint32_t value, int bits);
  /// Flushes and returns the bytes; the encoder is then spent.
  std::vector<std::uint8_t> finish();

 private:
  void shiftLow();
  std::uint64_t low_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFu;
  std::uint8_t cache_ = 0;
  std::uint64_t cache_size_ = 1;
  std::vector<std::uint8_t> out_;
};

class RangeDecoder {
 public:
  RangeDecoder(const std::uint8_t* data, std::size_t size);
  std::uint32_t decodeTarget(std::uint32_t total);
  void consume(std::uint32_t cum, std::uint32_t freq);
  int decode(AdaptiveModel& m);
  std::uint32_t decodeBits(int bits);
  /// True when the decoder had to read past the end of its buffer (by more than the
  /// encoder's flush bytes), i.e. the stream is truncated or corrupted.
  bool overrun() const { return pos_ > size_ + 4; }

 private:
  std::uint8_t next() { return pos_ < size_ ? data_[pos_++] : (++pos_, 0); }
  void normalize();
  const std::uint8_t* data_;
  std::size_t size_, pos_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFu, code_ = 0, r_ = 1;
};

}  // namespace paps::compression
