#include <paps/core/cloud_file_layout.h>

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>

#include <paps/core/error.h>

#include <fcntl.h>
#include <unistd.h>

namespace paps {

namespace {

// A header longer than this is not a header: garbage with no newline must not be read whole.
constexpr std::size_t kMaxHeaderBytes = 1 << 20;
// More points (or records) than this in one file is a corrupt count, not a scan.
constexpr std::uint64_t kMaxCount = std::uint64_t(1) << 40;

struct HeaderText {
  std::string bytes;  // the first kMaxHeaderBytes of the file (or all of it)
  std::uint64_t file_size = 0;
};

HeaderText readHead(const std::string& path) {
  std::error_code ec;
  checkInputPath(path);
  HeaderText h;
  h.file_size = std::filesystem::file_size(path, ec);
  if (ec) throw IoError("cannot read '" + path + "': " + ec.message());
  if (h.file_size == 0) throw IoError("cannot read '" + path + "': the file is empty");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError("cannot read '" + path + "': permission denied or unreadable");
  h.bytes.resize(std::size_t(std::min<std::uint64_t>(h.file_size, kMaxHeaderBytes)));
  f.read(h.bytes.data(), std::streamsize(h.bytes.size()));
  if (std::size_t(f.gcount()) != h.bytes.size()) throw IoError("cannot read '" + path + "': read failed");
  return h;
}

// Splits the next line off `text` at `pos` (without its "\n" or "\r\n"); false at the end of
// the text or when the line runs past it (a header line must end inside the header bytes).
bool nextLine(const std::string& text, std::size_t& pos, std::string& line) {
  if (pos >= text.size()) return false;
  const std::size_t end = text.find('\n', pos);
  if (end == std::string::npos) return false;
  line.assign(text, pos, end - pos);
  if (!line.empty() && line.back() == '\r') line.pop_back();
  pos = end + 1;
  return true;
}

// Words of a header line split on spaces and tabs, as PCL splits them. Any other control
// character (a form feed, a NUL...) is refused: PCL keeps it inside a word and then reads
// past its arrays (a crash found by fuzzing).
std::vector<std::string> tokens(const std::string& line, const std::string& path) {
  std::vector<std::string> t;
  std::string w;
  for (const char ch : line) {
    const unsigned char c = static_cast<unsigned char>(ch);
    if (c == ' ' || c == '\t' || c == '\r') {
      if (!w.empty()) t.push_back(std::move(w));
      w.clear();
    } else if (c < 0x20 || c == 0x7f) {
      static const char* hex = "0123456789abcdef";
      throw IoError("cannot read '" + path + "': control byte 0x" + hex[c >> 4] + hex[c & 15] +
                    " in the header (not a PCD or PLY header)");
    } else {
      w.push_back(ch);
    }
  }
  if (!w.empty()) t.push_back(std::move(w));
  return t;
}

bool parseUnsigned(const std::string& s, std::uint64_t& v) {
  const char* b = s.data();
  const char* e = b + s.size();
  const auto r = std::from_chars(b, e, v);
  return r.ec == std::errc() && r.ptr == e;
}

std::uint64_t readU32Le(const std::string& path, std::uint64_t offset) {
  std::ifstream f(path, std::ios::binary);
  f.seekg(std::streamoff(offset));
  unsigned char b[4];
  if (!f.read(reinterpret_cast<char*>(b), 4)) throw IoError("cannot read '" + path + "': truncated data");
  return std::uint64_t(b[0]) | std::uint64_t(b[1]) << 8 | std::uint64_t(b[2]) << 16 | std::uint64_t(b[3]) << 24;
}

// Size of a PLY scalar type name ("float", "uint8", ...), 0 when it is not one; `kind`
// receives 'i', 'u' or 'f'.
int plyScalarSize(const std::string& t, char& kind) {
  static const struct { const char* name; int size; char kind; } types[] = {
      {"char", 1, 'i'},   {"int8", 1, 'i'},   {"uchar", 1, 'u'},  {"uint8", 1, 'u'},    {"short", 2, 'i'},
      {"int16", 2, 'i'},  {"ushort", 2, 'u'}, {"uint16", 2, 'u'}, {"int", 4, 'i'},      {"int32", 4, 'i'},
      {"uint", 4, 'u'},   {"uint32", 4, 'u'}, {"float", 4, 'f'},  {"float32", 4, 'f'}, {"double", 8, 'f'},
      {"float64", 8, 'f'}};
  for (const auto& x : types)
    if (t == x.name) {
      kind = x.kind;
      return x.size;
    }
  return 0;
}

}  // namespace

int PcdLayout::field(const std::string& name) const {
  const auto it = std::find(fields.begin(), fields.end(), name);
  return it == fields.end() ? -1 : int(it - fields.begin());
}

std::uint64_t PcdLayout::offsetOf(int i) const {
  std::uint64_t off = 0;
  for (int j = 0; j < i; ++j) off += std::uint64_t(sizes[std::size_t(j)]) * std::uint64_t(counts[std::size_t(j)]);
  return off;
}

PcdLayout readPcdLayout(const std::string& path) {
  const HeaderText head = readHead(path);
  auto bad = [&](const std::string& what) { return IoError("cannot read '" + path + "': " + what); };
  PcdLayout L;
  L.file_size = head.file_size;
  bool have_width = false, have_height = false, have_points = false, have_counts = false, have_data = false;
  std::size_t pos = 0;
  std::string line;
  std::map<std::string, std::string> seen;  // list keyword -> its words
  for (std::size_t start = pos; !have_data && nextLine(head.bytes, pos, line); start = pos) {
    // An empty line is skipped, but PCL 1.13 crashes on a line of only spaces, tabs or a CR.
    const std::size_t raw_end = pos - 1;  // the '\n'
    if (raw_end > start && head.bytes.find_first_not_of(" \t\r", start) >= raw_end)
      throw bad("a line of only spaces, tabs or CR in the PCD header");
    if (line.empty() || line[0] == '#') continue;
    const std::vector<std::string> t = tokens(line, path);
    if (t.empty()) continue;  // cannot happen after the blank-line check; kept for safety
    const std::string& key = t[0];
    // PCL 1.13 crashes on a line it does not know: only the format's keywords are let
    // through, and FIELDS before its attributes (PCL refuses them before it).
    static const char* const known[] = {"VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT",
                                        "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA"};
    if (std::find(std::begin(known), std::end(known), key) == std::end(known))
      throw bad("unknown PCD header line '" + line.substr(0, 80) + "'");
    // A repeated WIDTH, HEIGHT, POINTS, VERSION or VIEWPOINT replaces the earlier one, and a
    // FIELDS, SIZE, TYPE or COUNT line may be repeated word for word (PCL reads such files);
    // a list that changes is refused (PCL would size its fields from one and read another).
    const bool list = key == "FIELDS" || key == "COLUMNS" || key == "SIZE" || key == "TYPE" || key == "COUNT";
    if (list) {
      const std::string name = key == "COLUMNS" ? "FIELDS" : key;
      std::string words;
      for (std::size_t i = 1; i < t.size(); ++i) words += t[i] + " ";
      const auto [it, first] = seen.emplace(name, words);
      if (!first && it->second != words) throw bad("two different " + name + " lines in the PCD header");
    }
    if ((key == "SIZE" || key == "TYPE" || key == "COUNT") && L.fields.empty())
      throw bad(key + " before FIELDS in the PCD header");
    auto count = [&](std::uint64_t& v, const char* what) {
      if (t.size() != 2 || !parseUnsigned(t[1], v) || v > kMaxCount)
        throw bad(std::string("bad ") + what + " line '" + line.substr(0, 80) + "'");
    };
    if (key == "FIELDS" || key == "COLUMNS") {
      L.fields.assign(t.begin() + 1, t.end());
    } else if (key == "SIZE") {
      L.sizes.clear();
      for (std::size_t i = 1; i < t.size(); ++i) {
        std::uint64_t s = 0;
        if (!parseUnsigned(t[i], s) || (s != 1 && s != 2 && s != 4 && s != 8))
          throw bad("SIZE '" + t[i] + "' is not 1, 2, 4 or 8");
        L.sizes.push_back(int(s));
      }
    } else if (key == "TYPE") {
      L.types.clear();
      for (std::size_t i = 1; i < t.size(); ++i) {
        if (t[i] != "I" && t[i] != "U" && t[i] != "F") throw bad("TYPE '" + t[i] + "' is not I, U or F");
        L.types.push_back(t[i][0]);
      }
    } else if (key == "COUNT") {
      L.counts.clear();
      have_counts = true;
      for (std::size_t i = 1; i < t.size(); ++i) {
        std::uint64_t c = 0;
        if (!parseUnsigned(t[i], c) || c < 1 || c > (1u << 20)) throw bad("COUNT '" + t[i] + "' is out of range");
        L.counts.push_back(int(c));
      }
    } else if (key == "WIDTH") {
      count(L.width, "WIDTH");
      have_width = true;
    } else if (key == "HEIGHT") {
      count(L.height, "HEIGHT");
      have_height = true;
    } else if (key == "POINTS") {
      count(L.points, "POINTS");
      have_points = true;
    } else if (key == "DATA") {
      if (t.size() != 2) throw bad("bad DATA line '" + line.substr(0, 80) + "'");
      if (t[1] == "ascii") L.data = PcdLayout::Data::Ascii;
      else if (t[1] == "binary") L.data = PcdLayout::Data::Binary;
      else if (t[1] == "binary_compressed") L.data = PcdLayout::Data::BinaryCompressed;
      else throw bad("DATA '" + t[1].substr(0, 40) + "' is not ascii, binary or binary_compressed");
      have_data = true;
    } else if (key == "VIEWPOINT") {
      bool numbers = t.size() == 8;
      for (std::size_t i = 1; numbers && i < t.size(); ++i) {
        char* end = nullptr;
        const double v = std::strtod(t[i].c_str(), &end);
        numbers = end == t[i].c_str() + t[i].size();
        if (i <= 3) L.origin[i - 1] = v;
      }
      if (!numbers) throw bad("bad VIEWPOINT line '" + line.substr(0, 80) + "' (expected 7 numbers)");
    }
    // VERSION is left to the reader.
  }
  if (!have_data) throw bad("no PCD header (no DATA line in its first bytes)");
  L.data_offset = pos;
  // PCL 1.13's header loop goes on after DATA: it skips empty lines and lines whose first word
  // starts with '#' or VERSION, reads a line whose first word starts with a keyword as header,
  // and stops at any other line. A keyword there (a FIELDS line, or binary data that happens
  // to start like one) replaces what the header said, or moves the data, and PCL then reads
  // past its arrays or its file (crashes found by fuzzing, session 16).
  for (std::size_t at = pos;;) {
    const std::size_t newline = head.bytes.find('\n', at);
    const std::size_t stop = newline == std::string::npos ? head.bytes.size() : newline;
    auto space = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; };
    std::size_t w = at;
    while (w < stop && space(head.bytes[w])) ++w;
    std::size_t e = w;
    while (e < stop && !space(head.bytes[e])) ++e;
    const std::string word = head.bytes.substr(w, e - w);
    if (stop > at && word.rfind('#', 0) != 0 && word.rfind("VERSION", 0) != 0) {
      for (const char* key : {"FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA"})
        if (word.rfind(key, 0) == 0)
          throw bad("the data after the DATA line starts with '" + std::string(key) +
                    "', which PCL would read as a header line (corrupt)");
      break;  // the first data line: PCL's header loop stops here
    }
    if (newline == std::string::npos) {
      if (head.bytes.size() < L.file_size) throw bad("blank or comment lines after DATA run past the header bytes");
      break;
    }
    at = newline + 1;
  }
  const std::size_t n = L.fields.size();
  if (n == 0) throw bad("the PCD header has no FIELDS");
  if (n > 4096) throw bad("the PCD header has more than 4096 fields");
  if (L.sizes.size() != n) throw bad("SIZE has " + std::to_string(L.sizes.size()) + " entries for " + std::to_string(n) + " fields");
  if (L.types.size() != n) throw bad("TYPE has " + std::to_string(L.types.size()) + " entries for " + std::to_string(n) + " fields");
  if (!have_counts) L.counts.assign(n, 1);
  if (L.counts.size() != n) throw bad("COUNT has " + std::to_string(L.counts.size()) + " entries for " + std::to_string(n) + " fields");
  std::uint64_t values = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (L.types[i] == 'F' && L.sizes[i] != 4 && L.sizes[i] != 8)
      throw bad("field '" + L.fields[i] + "' is a float of " + std::to_string(L.sizes[i]) + " bytes");
    L.point_step += std::uint64_t(L.sizes[i]) * std::uint64_t(L.counts[i]);
    values += std::uint64_t(L.counts[i]);
  }
  if (!have_width && !have_points) throw bad("the PCD header has neither WIDTH nor POINTS");
  if (!have_height) L.height = 1;
  if (!have_width) L.width = L.height ? L.points / L.height : 0;
  if (L.height != 0 && L.width > kMaxCount / L.height) throw bad("WIDTH x HEIGHT is out of range");
  if (!have_points) L.points = L.width * L.height;
  if (L.width * L.height != L.points)
    throw bad("WIDTH x HEIGHT (" + std::to_string(L.width) + " x " + std::to_string(L.height) +
              ") is not POINTS (" + std::to_string(L.points) + ")");
  const std::uint64_t left = L.file_size - L.data_offset;
  const std::string claim = "the header promises " + std::to_string(L.points) + " points";
  switch (L.data) {
    case PcdLayout::Data::Binary:
      if (L.points > left / L.point_step)
        throw bad(claim + " of " + std::to_string(L.point_step) + " bytes but the file holds " +
                  std::to_string(left) + " bytes of data (truncated or corrupt)");
      break;
    case PcdLayout::Data::BinaryCompressed: {
      // PCL reads the two size words even for an empty cloud, and allocates the second.
      if (left < 8) throw bad("truncated binary_compressed data");
      const std::uint64_t packed = readU32Le(path, L.data_offset);
      const std::uint64_t unpacked = readU32Le(path, L.data_offset + 4);
      if (packed > left - 8) throw bad("truncated binary_compressed data");
      if (L.points > std::numeric_limits<std::uint32_t>::max() / L.point_step || unpacked != L.points * L.point_step)
        throw bad("binary_compressed size does not match POINTS");
      // LZF turns 3 bytes into at most 264 (a back reference of maximal length).
      if (unpacked > packed * 88 + 1024) throw bad("corrupt binary_compressed data");
      break;
    }
    case PcdLayout::Data::Ascii:
      // A value takes at least a character and a separator.
      if (L.points > (left + 1) / (2 * values))
        throw bad(claim + " of " + std::to_string(values) + " values but the file holds " +
                  std::to_string(left) + " bytes of text (truncated or corrupt)");
      break;
  }
  return L;
}

namespace {
// Whether a word of ascii data is a number as the readers parse them ("nan" and "inf" too).
bool isNumber(const std::string& word) {
  char* end = nullptr;
  std::strtod(word.c_str(), &end);
  return !word.empty() && end == word.c_str() + word.size();
}
}  // namespace

void checkPcdAsciiRows(const std::string& path, const PcdLayout& L) {
  if (L.data != PcdLayout::Data::Ascii) return;
  std::uint64_t values = 0;
  for (const int c : L.counts) values += std::uint64_t(c);
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError("cannot read '" + path + "': permission denied or unreadable");
  f.seekg(std::streamoff(L.data_offset));
  std::string line;
  std::uint64_t rows = 0, number = 0;
  auto separator = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  while (rows < L.points && std::getline(f, line)) {
    ++number;
    if (line.empty()) continue;  // PCL skips empty lines (and only those)
    std::uint64_t count = 0;
    for (std::size_t i = 0; i < line.size();) {
      while (i < line.size() && separator(line[i])) ++i;
      if (i == line.size()) break;
      std::size_t e = i;
      while (e < line.size() && !separator(line[e])) ++e;
      const std::string word = line.substr(i, e - i);
      if (!isNumber(word))
        throw IoError("cannot read '" + path + "': data line " + std::to_string(number) + " has '" +
                      word.substr(0, 40) + "', which is not a number");
      ++count;
      i = e;
    }
    if (count != values)
      throw IoError("cannot read '" + path + "': data line " + std::to_string(number) + " has " +
                    std::to_string(count) + " values, not " + std::to_string(values));
    ++rows;
  }
  if (rows < L.points)
    throw IoError("cannot read '" + path + "': " + std::to_string(rows) + " data lines where the header promises " +
                  std::to_string(L.points) + " points");
}

int PlyLayout::element(const std::string& name) const {
  for (std::size_t i = 0; i < elements.size(); ++i)
    if (elements[i].name == name) return int(i);
  return -1;
}

PlyLayout readPlyLayout(const std::string& path) {
  const HeaderText head = readHead(path);
  auto bad = [&](const std::string& what) { return IoError("cannot read '" + path + "': " + what); };
  PlyLayout L;
  L.file_size = head.file_size;
  std::size_t pos = 0;
  std::string line;
  if (!nextLine(head.bytes, pos, line) || line != "ply") throw bad("not a PLY file (no 'ply' first line)");
  bool have_format = false, ended = false;
  while (!ended && nextLine(head.bytes, pos, line)) {
    const std::vector<std::string> t = tokens(line, path);
    if (t.empty()) continue;
    const std::string& key = t[0];
    const std::string shown = "'" + line.substr(0, 80) + "'";
    if (key == "comment" || key == "obj_info") continue;
    if (key == "format") {
      if (have_format || t.size() != 3) throw bad("bad format line " + shown);
      if (t[1] == "ascii") L.format = PlyLayout::Format::Ascii;
      else if (t[1] == "binary_little_endian") L.format = PlyLayout::Format::BinaryLittleEndian;
      else if (t[1] == "binary_big_endian") L.format = PlyLayout::Format::BinaryBigEndian;
      else throw bad("unknown PLY format " + shown);
      have_format = true;
    } else if (key == "element") {
      PlyLayout::Element e;
      if (t.size() != 3 || !parseUnsigned(t[2], e.count) || e.count > kMaxCount) throw bad("bad element line " + shown);
      e.name = t[1];
      L.elements.push_back(e);
    } else if (key == "property") {
      if (L.elements.empty()) throw bad("a property before any element: " + shown);
      PlyLayout::Property p;
      if (t.size() == 3) {
        p.size = plyScalarSize(t[1], p.kind);
        p.name = t[2];
      } else if (t.size() == 5 && t[1] == "list") {
        char count_kind = 'f';
        p.count_size = plyScalarSize(t[2], count_kind);
        if (p.count_size == 0 || count_kind == 'f') throw bad("a list's length is not an integer type: " + shown);
        p.size = plyScalarSize(t[3], p.kind);
        p.name = t[4];
      } else {
        throw bad("bad property line " + shown);
      }
      if (p.size == 0) throw bad("unknown property type in " + shown);
      L.elements.back().properties.push_back(p);
    } else if (key == "end_header") {
      ended = true;
    } else {
      throw bad("unknown PLY header line " + shown);
    }
  }
  if (!ended) throw bad("no end_header line in the PLY header");
  if (!have_format) throw bad("no format line in the PLY header");
  L.data_offset = pos;
  // The fewest bytes the elements can take: binary, each record's scalars and list lengths
  // (a list may be empty); ascii, two characters per value.
  const std::uint64_t left = L.file_size - L.data_offset;
  std::uint64_t need = 0;
  for (const auto& e : L.elements) {
    if (e.count == 0) continue;
    if (e.properties.empty()) throw bad("element '" + e.name + "' has no properties");
    std::uint64_t record = 0;
    for (const auto& p : e.properties)
      record += L.format == PlyLayout::Format::Ascii ? 2 : std::uint64_t(p.count_size ? p.count_size : p.size);
    if (e.count > (left + 1) / record)
      throw bad("the header promises " + std::to_string(e.count) + " " + e.name + " records but the file holds " +
                std::to_string(left) + " bytes of data (truncated or corrupt)");
    need += e.count * record;
  }
  if (need > left + 1) throw bad("the header promises more data than the file holds (truncated or corrupt)");
  return L;
}

PlyLayout readPlyLayoutForPcl(const std::string& path) {
  PlyLayout ply = readPlyLayout(path);
  if (ply.format == PlyLayout::Format::Ascii) {
    // PCL's reader turns a word that is not a number into NaN without a word.
    std::ifstream f(path, std::ios::binary);
    f.seekg(std::streamoff(ply.data_offset));
    std::string word;
    for (std::uint64_t k = 0; f >> word; ++k)
      if (!isNumber(word))
        throw IoError("cannot read '" + path + "': value " + std::to_string(k + 1) + " of the data is '" +
                      word.substr(0, 40) + "', not a number");
  }
  const int v = ply.element("vertex");
  if (v >= 0)
    for (const auto& p : ply.elements[std::size_t(v)].properties)
      if (p.count_size)
        throw IoError("cannot read '" + path + "': vertex property '" + p.name.substr(0, 40) +
                      "' is a list (not supported)");
  return ply;
}

void checkInputPath(const std::string& path, const std::string& what) {
  std::error_code ec;
  const std::string head = "cannot read " + what + "'" + path + "': ";
  if (std::filesystem::is_directory(path, ec)) throw IoError(head + "it is a folder");
  if (!std::filesystem::is_regular_file(path, ec)) throw IoError(head + "no such file");
  if (::access(path.c_str(), R_OK) != 0) throw IoError(head + std::strerror(errno));
}

void commitTemporaryFile(const std::string& tmp, const std::string& path, const std::string& what) {
  const std::string head = "cannot write " + what + "'" + path + "': ";
  const int fd = ::open(tmp.c_str(), O_RDONLY);
  const bool synced = fd >= 0 && ::fsync(fd) == 0;
  const int sync_errno = errno;
  if (fd >= 0) ::close(fd);
  std::error_code ec;
  if (!synced) {
    std::filesystem::remove(tmp, ec);
    throw IoError(head + "flushing the data failed (" + std::strerror(sync_errno) + ")");
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw IoError(head + ec.message());
  }
  // The new directory entry: without this a power loss can bring back the old file.
  const std::filesystem::path target(path);
  const std::string dir = target.has_parent_path() ? target.parent_path().string() : ".";
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

void checkOutputPath(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (path.empty()) throw IoError("cannot write '': the output path is empty");
  if (fs::is_directory(path, ec)) throw IoError("cannot write '" + path + "': it is a folder");
  const fs::path dir = fs::path(path).has_parent_path() ? fs::path(path).parent_path() : fs::path(".");
  if (!fs::is_directory(dir, ec)) throw IoError("cannot write '" + path + "': folder '" + dir.string() + "' does not exist");
  // The temporary file is created beside the target, so the folder itself must take new files.
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    throw IoError("cannot write '" + path + "': folder '" + dir.string() + "' is not writable (" + std::strerror(errno) + ")");
}

}  // namespace paps
