#include <paps/compression/bitstream.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>

#include <lzma.h>
#include <new>
#include <zstd.h>

namespace paps::compression {
namespace {
const std::uint8_t kMagic[8] = {0x89, 'P', 'A', 'P', 'S', 'C', '\r', '\n'};
constexpr std::uint32_t kMaxSections = 16;

struct CrcTable {
  std::uint32_t t[256];
  CrcTable() {
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
  }
};
}  // namespace

std::uint32_t crc32(const std::uint8_t* data, std::size_t size, std::uint32_t crc) {
  static const CrcTable table;
  crc = ~crc;
  for (std::size_t i = 0; i < size; ++i) crc = table.t[(crc ^ data[i]) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

void ByteWriter::f32(float v) {
  std::uint32_t u;
  std::memcpy(&u, &v, 4);
  u32(u);
}

void ByteReader::need(std::size_t n) const {
  if (n > size_ - pos_)
    throw CorruptStream(what_ + " is truncated (needs " + std::to_string(n) + " more bytes at offset " +
                        std::to_string(pos_) + " of " + std::to_string(size_) + ")");
}
std::uint16_t ByteReader::u16() {
  need(2);
  std::uint16_t v = std::uint16_t(data_[pos_] | data_[pos_ + 1] << 8);
  pos_ += 2;
  return v;
}
std::uint32_t ByteReader::u32() {
  need(4);
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | data_[pos_ + i];
  pos_ += 4;
  return v;
}
std::uint64_t ByteReader::u64() {
  need(8);
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | data_[pos_ + i];
  pos_ += 8;
  return v;
}
float ByteReader::f32() {
  const std::uint32_t u = u32();
  float v;
  std::memcpy(&v, &u, 4);
  return v;
}
float ByteReader::f32In(const char* field, float lo, float hi) {
  const float v = f32();
  if (!(std::isfinite(v) && v >= lo && v <= hi))
    throw CorruptStream(what_ + " field '" + field + "' = " + detail::toString(v) + " is out of [" +
                        detail::toString(lo) + ", " + detail::toString(hi) + "]");
  return v;
}

std::string tagName(std::uint32_t tag) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = char((tag >> (8 * i)) & 0xFF);
    s += (c >= 32 && c < 127) ? c : '?';
  }
  return s;
}

std::vector<std::uint8_t> writeContainer(const std::vector<Section>& sections) {
  ByteWriter w;
  for (const auto b : kMagic) w.u8(b);
  w.u32(kFormatVersion);
  w.u32(static_cast<std::uint32_t>(sections.size()));
  for (const auto& s : sections) {
    w.u32(s.tag);
    w.u64(s.payload.size());
    w.u32(crc32(s.payload.data(), s.payload.size()));
    w.raw(s.payload);
  }
  w.u32(crc32(w.bytes.data(), w.bytes.size()));
  return w.bytes;
}

std::vector<Section> readContainer(const std::uint8_t* data, std::size_t size, std::uint32_t* version_out) {
  if (size < 8 || std::memcmp(data, kMagic, 8) != 0)
    throw CorruptStream("not a PAPS compressed point cloud (bad magic bytes)");
  ByteReader r(data, size, "container");
  r.take(8);
  const std::uint32_t version = r.u32();
  if (version < kOldestReadableVersion || version > kFormatVersion)
    throw CorruptStream("format version " + std::to_string(version) + " is not supported (this build reads " +
                        std::to_string(kOldestReadableVersion) + " to " + std::to_string(kFormatVersion) + ")");
  if (version_out) *version_out = version;
  const std::uint32_t n = r.u32();
  if (n < 1 || n > kMaxSections)
    throw CorruptStream("section count " + std::to_string(n) + " is out of [1, " + std::to_string(kMaxSections) + "]");
  std::vector<Section> out(n);
  for (auto& s : out) {
    s.tag = r.u32();
    const std::uint64_t len = r.u64();
    const std::uint32_t crc = r.u32();
    if (len > r.left())
      throw CorruptStream("section '" + tagName(s.tag) + "' claims " + std::to_string(len) + " bytes but only " +
                          std::to_string(r.left()) + " remain (truncated file?)");
    const std::uint8_t* p = r.take(static_cast<std::size_t>(len));
    if (crc32(p, static_cast<std::size_t>(len)) != crc)
      throw CorruptStream("section '" + tagName(s.tag) + "' fails its checksum (corrupted data)");
    s.payload.assign(p, p + len);
  }
  const std::size_t body = r.position();
  const std::uint32_t file_crc = r.u32();
  if (crc32(data, body) != file_crc) throw CorruptStream("the file checksum does not match (corrupted data)");
  if (r.left() != 0) throw CorruptStream(std::to_string(r.left()) + " unexpected bytes after the end of the stream");
  return out;
}

const char* entropyMethodName(EntropyMethod m) {
  switch (m) {
    case EntropyMethod::kRange: return "adaptive range coder";
    case EntropyMethod::kZstd: return "zstd";
    case EntropyMethod::kLzma: return "lzma";
  }
  return "?";
}

void SymbolWriter::put(AdaptiveModel& m, int s) {
  raw_.push_back(std::uint8_t(s));
  raw_.push_back(std::uint8_t(s >> 8));
  range_.encode(m, s);
}

std::vector<std::uint8_t> SymbolWriter::finish(EntropyMethod* chosen, std::size_t* sizes) {
  std::vector<std::uint8_t> best = range_.finish();
  EntropyMethod m = EntropyMethod::kRange;
  // zstd and lzma with windows of at most 512 KB: the symbol streams are a few MB at most and
  // the range coder wins on every measured input, so the comparison need not cost the 40-50 MB
  // of lzma's default match finder (the decoder reads any window size).
  // The two general-purpose coders run one after the other, each result dropped as soon as it
  // has lost: side by side they held both match finders and both outputs at once (the
  // encoder's peak memory on 1M points).
  const std::size_t rsize = best.size();
  std::size_t zsize = 0, xsize = 0;
  {
    std::vector<std::uint8_t> z(ZSTD_compressBound(raw_.size()));
    ZSTD_CCtx* cctx = ZSTD_createCCtx();
    if (cctx) {
      ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, 9);
      ZSTD_CCtx_setParameter(cctx, ZSTD_c_windowLog, 19);
      ZSTD_CCtx_setParameter(cctx, ZSTD_c_hashLog, 17);
      ZSTD_CCtx_setParameter(cctx, ZSTD_c_chainLog, 17);
      const std::size_t zn = ZSTD_compress2(cctx, z.data(), z.size(), raw_.data(), raw_.size());
      ZSTD_freeCCtx(cctx);
      if (!ZSTD_isError(zn)) {
        zsize = zn;
        z.resize(zn);
        if (zsize < best.size()) { best.swap(z); m = EntropyMethod::kZstd; }
      }
    }
  }
  {
    std::vector<std::uint8_t> x(raw_.size() + raw_.size() / 2 + 1024);
    std::size_t xpos = 0;
    lzma_options_lzma opt;
    lzma_lzma_preset(&opt, 4);
    std::uint32_t dict = LZMA_DICT_SIZE_MIN;
    while (dict < raw_.size() && dict < (1u << 19)) dict <<= 1;
    opt.dict_size = dict;
    lzma_filter filters[2] = {{LZMA_FILTER_LZMA2, &opt}, {LZMA_VLI_UNKNOWN, nullptr}};
    if (lzma_stream_buffer_encode(filters, LZMA_CHECK_NONE, nullptr, raw_.data(), raw_.size(), x.data(), &xpos,
                                  x.size()) == LZMA_OK) {
      xsize = xpos;
      x.resize(xpos);
      if (xsize < best.size()) { best.swap(x); m = EntropyMethod::kLzma; }
    }
  }
  if (sizes) { sizes[0] = rsize; sizes[1] = zsize; sizes[2] = xsize; }
  if (chosen) *chosen = m;
  std::vector<std::uint8_t> out;
  out.reserve(best.size() + 1);
  out.push_back(static_cast<std::uint8_t>(m));
  out.insert(out.end(), best.begin(), best.end());
  return out;
}

SymbolReader::SymbolReader(const std::vector<std::uint8_t>& payload, std::size_t max_symbols, const char* what)
    : what_(what) {
  if (payload.empty()) throw CorruptStream(what_ + " stream is empty");
  if (payload[0] > 2) throw CorruptStream(what_ + " stream has unknown coding method " + std::to_string(payload[0]));
  method_ = static_cast<EntropyMethod>(payload[0]);
  const std::uint8_t* p = payload.data() + 1;
  const std::size_t n = payload.size() - 1;
  // Two bytes per symbol, and never more than 512 MiB whatever the header claims (a real
  // stream that large would be range-coded: the range coder wins on every measured input).
  const std::size_t max_raw = std::min<std::size_t>(2 * max_symbols, std::size_t(512) << 20);
  if (method_ == EntropyMethod::kRange) {
    range_ = std::make_unique<RangeDecoder>(p, n);
  } else if (method_ == EntropyMethod::kZstd) {
    const unsigned long long len = ZSTD_getFrameContentSize(p, n);
    if (len == ZSTD_CONTENTSIZE_ERROR || len == ZSTD_CONTENTSIZE_UNKNOWN || len > max_raw)
      throw CorruptStream(what_ + " zstd frame has an invalid or excessive size");
    raw_.resize(static_cast<std::size_t>(len));
    const std::size_t got = ZSTD_decompress(raw_.data(), raw_.size(), p, n);
    if (ZSTD_isError(got) || got != len) throw CorruptStream(what_ + " zstd data does not decode");
  } else {
    raw_.resize(max_raw);
    std::uint64_t memlimit = 256ull << 20;
    std::size_t in_pos = 0, out_pos = 0;
    const lzma_ret rc = lzma_stream_buffer_decode(&memlimit, 0, nullptr, p, &in_pos, n, raw_.data(), &out_pos, raw_.size());
    if (rc != LZMA_OK || in_pos != n) throw CorruptStream(what_ + " lzma data does not decode");
    raw_.resize(out_pos);
  }
}

int SymbolReader::get(AdaptiveModel& m) {
  if (range_) {
    if (range_->overrun()) throw CorruptStream(what_ + " stream ends too early");
    return range_->decode(m);
  }
  if (raw_pos_ + 2 > raw_.size()) throw CorruptStream(what_ + " stream ends too early");
  const int s = raw_[raw_pos_] | raw_[raw_pos_ + 1] << 8;
  raw_pos_ += 2;
  if (s >= m.size()) throw CorruptStream(what_ + " symbol " + std::to_string(s) + " is out of range");
  return s;
}

void SymbolReader::checkEnd() const {
  if (range_ && range_->overrun()) throw CorruptStream(what_ + " stream ends too early");
  if (!range_ && raw_pos_ != raw_.size()) throw CorruptStream(what_ + " stream has trailing symbols");
}

}  // namespace paps::compression
