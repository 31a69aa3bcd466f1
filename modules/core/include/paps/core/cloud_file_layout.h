#pragma once
// What the header of a .pcd or .ply file promises, parsed strictly and checked against the
// file's size before any reader allocates for it. PCL 1.13's readers trust the header: a
// 1 KB file that claims two billion points makes them allocate 24 GB, and a file with no
// FIELDS line crashes PCDReader (PCL #5854). Also the check of an output path. Every check
// here throws IoError naming the file and what is wrong; nothing here depends on PCL, so
// the lean codec binary can use it.
#include <cstdint>
#include <string>
#include <vector>

namespace paps {

/// A PCD header (PCD v0.5 to v0.7), validated.
struct PcdLayout {
  enum class Data { Ascii, Binary, BinaryCompressed };
  std::vector<std::string> fields;
  std::vector<int> sizes;    ///< bytes per value: 1, 2, 4 or 8
  std::vector<char> types;   ///< 'I', 'U' or 'F'
  std::vector<int> counts;   ///< values per field (1 when the header has no COUNT)
  std::uint64_t width = 0, height = 1, points = 0;
  Data data = Data::Ascii;
  std::uint64_t data_offset = 0;  ///< bytes from the start of the file to the data
  std::uint64_t point_step = 0;   ///< bytes of one point in binary data
  std::uint64_t file_size = 0;
  /// The sensor origin of the VIEWPOINT line (0 0 0 without one). PCL's reader leaves it
  /// undefined on "nan" or "inf" (garbage, not NaN): this is the value to trust.
  double origin[3] = {0, 0, 0};

  /// Index of a field by name, -1 when absent.
  int field(const std::string& name) const;
  /// Byte offset of field `i` inside a binary point (sum of the earlier fields' bytes).
  std::uint64_t offsetOf(int i) const;
};

/// Parses and checks a PCD header: the keyword lines, equal numbers of FIELDS, SIZE, TYPE
/// and COUNT entries, valid sizes and types, WIDTH x HEIGHT = POINTS, and data that can fit
/// in the rest of the file (binary: POINTS x point size bytes; binary_compressed: its two
/// size words, a packed size within the file and an unpacked size equal to POINTS x point
/// size; ascii: at least two characters per value).
PcdLayout readPcdLayout(const std::string& path);

/// Checks the rows of an ascii PCD (layout from readPcdLayout): each of the first POINTS
/// non-empty lines holds exactly one number per value of a point. PCL's reader turns a short
/// row or a word that is not a number into zeros without a word; this says which line.
void checkPcdAsciiRows(const std::string& path, const PcdLayout& layout);

/// A PLY header, validated.
struct PlyLayout {
  enum class Format { Ascii, BinaryLittleEndian, BinaryBigEndian };
  struct Property {
    std::string name;
    int size = 0;        ///< bytes of a scalar, or of each list item
    char kind = 'f';     ///< 'i' signed, 'u' unsigned, 'f' floating
    int count_size = 0;  ///< bytes of a list's length (0: not a list)
  };
  struct Element {
    std::string name;
    std::uint64_t count = 0;
    std::vector<Property> properties;
  };
  Format format = Format::Ascii;
  std::vector<Element> elements;
  std::uint64_t data_offset = 0;
  std::uint64_t file_size = 0;

  /// Index of an element by name, -1 when absent.
  int element(const std::string& name) const;
};

/// Parses and checks a PLY header: "ply", one format line, elements with known property
/// types, "end_header", and element counts whose smallest possible encoding fits in the rest
/// of the file (binary: the fixed bytes of each record; ascii: two characters per value).
PlyLayout readPlyLayout(const std::string& path);

/// readPlyLayout, then what PCL 1.13's PLYReader needs on top: no list property on the
/// vertices (it asserts when a list changes length from one vertex to the next).
PlyLayout readPlyLayoutForPcl(const std::string& path);

/// Throws IoError "cannot read <what>'path': ..." when `path` is a folder, does not exist or
/// cannot be opened for reading (`what`, e.g. "photo list ", names the kind of file).
void checkInputPath(const std::string& path, const std::string& what = "");

/// Moves a complete temporary file onto `path`: its data flushed to the disk, then renamed
/// (atomic), then the folder's entry flushed, so that `path` is the old file or the whole new
/// one even after a power loss. On failure removes `tmp` and throws IoError naming `what`
/// ("photo list ", or "" for a plain file) and `path`.
void commitTemporaryFile(const std::string& tmp, const std::string& path, const std::string& what = "");

/// Throws IoError naming what is wrong when `path` cannot be an output file: empty, a
/// folder, or in a folder that does not exist or does not take new files. Commands call it
/// before any work, so that a long run does not end on an unwritable path.
void checkOutputPath(const std::string& path);

}  // namespace paps
