#include <paps/compression/range_coder.h>

#include <algorithm>

#include <paps/core/error.h>

namespace paps::compression {
namespace {
constexpr std::uint32_t kTop = 1u << 24;
constexpr std::uint32_t kMaxTotal = 1u << 16;
}  // namespace

AdaptiveModel::AdaptiveModel(int size, int increment)
    : freq_(static_cast<std::size_t>(std::max(size, 0)), 1u), total_(0), increment_(increment) {
  requireInRange("model size", size, 2, 4096);
  requireInRange("model increment", increment, 1, 1024);
  total_ = static_cast<std::uint32_t>(size);
}

std::uint32_t AdaptiveModel::cumulative(int s) const {
  std::uint32_t c = 0;
  for (int i = 0; i < s; ++i) c += freq_[i];
  return c;
}

int AdaptiveModel::find(std::uint32_t target, std::uint32_t& cum) const {
  std::uint32_t c = 0;
  const int n = size();
  for (int i = 0; i < n - 1; ++i) {
    if (target < c + freq_[i]) { cum = c; return i; }
    c += freq_[i];
  }
  cum = c;
  return n - 1;
}

void AdaptiveModel::update(int s) {
  freq_[s] += increment_;
  total_ += increment_;
  if (total_ > kMaxTotal) {
    total_ = 0;
    for (auto& f : freq_) { f = (f + 1) / 2; total_ += f; }
  }
}

void RangeEncoder::shiftLow() {
  if (static_cast<std::uint32_t>(low_) < 0xFF000000u || (low_ >> 32) != 0) {
    const std::uint8_t carry = static_cast<std::uint8_t>(low_ >> 32);
    std::uint8_t temp = cache_;
    do {
      out_.push_back(static_cast<std::uint8_t>(temp + carry));
      temp = 0xFF;
    } while (--cache_size_ != 0);
    cache_ = static_cast<std::uint8_t>(low_ >> 24);
  }
  ++cache_size_;
  low_ = (low_ & 0x00FFFFFFu) << 8;
}

void RangeEncoder::encode(std::uint32_t cum, std::uint32_t freq, std::uint32_t total) {
  const std::uint32_t r = range_ / total;
  low_ += static_cast<std::uint64_t>(r) * cum;
  range_ = r * freq;
  while (range_ < kTop) { range_ <<= 8; shiftLow(); }
}

void RangeEncoder::encode(AdaptiveModel& m, int s) {
  encode(m.cumulative(s), m.frequency(s), m.total());
  m.update(s);
}

void RangeEncoder::encodeBits(std::uint32_t value, int bits) {
  while (bits > 0) {
    const int b = std::min(bits, 16);
    bits -= b;
    const std::uint32_t part = (value >> bits) & ((1u << b) - 1u);
    encode(part, 1, 1u << b);
  }
}

std::vector<std::uint8_t> RangeEncoder::finish() {
  for (int i = 0; i < 5; ++i) shiftLow();
  std::vector<std::uint8_t> r;
  r.swap(out_);
  // The first byte is always the initial zero cache byte; drop it.
  if (!r.empty()) r.erase(r.begin());
  return r;
}

RangeDecoder::RangeDecoder(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {
  for (int i = 0; i < 4; ++i) code_ = (code_ << 8) | next();
}

void RangeDecoder::normalize() {
  while (range_ < kTop) { code_ = (code_ << 8) | next(); range_ <<= 8; }
}

std::uint32_t RangeDecoder::decodeTarget(std::uint32_t total) {
  r_ = range_ / total;
  const std::uint32_t v = code_ / r_;
  return v < total ? v : total - 1;
}

void RangeDecoder::consume(std::uint32_t cum, std::uint32_t freq) {
  code_ -= r_ * cum;
  range_ = r_ * freq;
  normalize();
}

int RangeDecoder::decode(AdaptiveModel& m) {
  std::uint32_t cum = 0;
  const int s = m.find(decodeTarget(m.total()), cum);
  consume(cum, m.frequency(s));
  m.update(s);
  return s;
}

std::uint32_t RangeDecoder::decodeBits(int bits) {
  std::uint32_t v = 0;
  while (bits > 0) {
    const int b = std::min(bits, 16);
    bits -= b;
    const std::uint32_t part = decodeTarget(1u << b);
    consume(part, 1);
    v = (v << b) | part;
  }
  return v;
}

}  // namespace paps::compression
