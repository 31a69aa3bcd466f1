// Tests of paps/core/cloud_file_layout.h and of paps::loadCloud on damaged files: the layout
// of files PCL writes is read exactly (data offset, point size, counts); empty, foreign,
// inconsistent and over-promising headers are refused with a clear IoError before PCL's
// readers see them; and every truncation or header byte flip of valid PCD and PLY files
// either loads or throws a paps::Error (a crash or a runaway allocation fails the test run).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_types.h>

#include <paps/core/cloud_file_layout.h>
#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/random.h>
#include <paps/core/triangle_mesh.h>
#include <paps/core/xyz_file_reader.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace core_cloud_file_layout_test {

namespace fs = std::filesystem;

fs::path scratch(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / "paps_cloud_file_layout";
  fs::create_directories(dir);
  return dir / name;
}

std::string readBytes(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

void writeBytes(const fs::path& p, const std::string& b) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(b.data(), std::streamsize(b.size()));
}

pcl::PointCloud<pcl::PointXYZI> smallCloud(int n) {
  paps::Random rng(7);
  pcl::PointCloud<pcl::PointXYZI> c;
  for (int i = 0; i < n; ++i) {
    pcl::PointXYZI p;
    p.x = rng.uniform();
    p.y = rng.uniform();
    p.z = 0.1f * rng.uniform();
    p.intensity = float(i);
    c.push_back(p);
  }
  return c;
}

enum class Kind { PcdAscii, PcdBinary, PcdCompressed, PlyAscii, PlyBinary };

fs::path writeValid(Kind k, int n) {
  const auto c = smallCloud(n);
  const char* names[] = {"ascii.pcd", "binary.pcd", "compressed.pcd", "ascii.ply", "binary.ply"};
  const fs::path p = scratch(names[int(k)]);
  switch (k) {
    case Kind::PcdAscii: pcl::io::savePCDFileASCII(p.string(), c); break;
    case Kind::PcdBinary: pcl::io::savePCDFileBinary(p.string(), c); break;
    case Kind::PcdCompressed: pcl::io::savePCDFileBinaryCompressed(p.string(), c); break;
    case Kind::PlyAscii: pcl::io::savePLYFileASCII(p.string(), c); break;
    case Kind::PlyBinary: pcl::io::savePLYFileBinary(p.string(), c); break;
  }
  return p;
}

// The error of a refused file, or "" when it loads.
std::string loadError(const fs::path& p) {
  try {
    paps::loadCloud(p.string());
    return "";
  } catch (const paps::Error& e) {
    return e.what();
  }
}

// The cloud at `p` holds smallCloud(n): coordinates and intensity, bit for bit from binary
// files, to the writer's printed precision from ascii ones.
void expectSmallCloud(const fs::path& p, int n, bool exact) {
  pcl::PointCloud<pcl::PointXYZI> back;
  pcl::fromPCLPointCloud2(paps::loadCloud(p.string()), back);
  const auto want = smallCloud(n);
  ASSERT_EQ(back.size(), want.size()) << p;
  for (std::size_t i = 0; i < want.size(); ++i) {
    const float got[4] = {back[i].x, back[i].y, back[i].z, back[i].intensity};
    const float ref[4] = {want[i].x, want[i].y, want[i].z, want[i].intensity};
    for (int k = 0; k < 4; ++k) {
      if (exact) ASSERT_EQ(got[k], ref[k]) << p << " point " << i << " value " << k;
      else ASSERT_NEAR(got[k], ref[k], 1e-6f * std::max(1.f, std::abs(ref[k]))) << p << " point " << i;
    }
  }
}

TEST(CloudFileLayout, ReadsThePcdLayoutPclWrites) {
  for (Kind k : {Kind::PcdAscii, Kind::PcdBinary, Kind::PcdCompressed}) {
    const fs::path p = writeValid(k, 500);
    const paps::PcdLayout L = paps::readPcdLayout(p.string());
    const std::string bytes = readBytes(p);
    ASSERT_GE(L.fields.size(), 4u);
    EXPECT_EQ(L.field("x"), 0);
    EXPECT_EQ(L.field("intensity"), 3);
    EXPECT_EQ(L.field("nope"), -1);
    EXPECT_EQ(L.points, 500u);
    EXPECT_EQ(L.width * L.height, 500u);
    EXPECT_EQ(L.file_size, bytes.size());
    // The data starts right after the DATA line.
    const std::size_t data_line = bytes.find("\nDATA ");
    ASSERT_NE(data_line, std::string::npos);
    EXPECT_EQ(L.data_offset, bytes.find('\n', data_line + 1) + 1);
    EXPECT_EQ(L.offsetOf(L.field("y")), 4u);
    if (k == Kind::PcdBinary) {
      EXPECT_EQ(L.data, paps::PcdLayout::Data::Binary);
      EXPECT_EQ(L.data_offset + L.points * L.point_step, L.file_size);
    }
    if (k == Kind::PcdCompressed) EXPECT_EQ(L.data, paps::PcdLayout::Data::BinaryCompressed);
    if (k == Kind::PcdAscii) EXPECT_EQ(L.data, paps::PcdLayout::Data::Ascii);
    expectSmallCloud(p, 500, k != Kind::PcdAscii);
  }
}

TEST(CloudFileLayout, ReadsThePlyLayoutPclWrites) {
  for (Kind k : {Kind::PlyAscii, Kind::PlyBinary}) {
    const fs::path p = writeValid(k, 300);
    const paps::PlyLayout L = paps::readPlyLayout(p.string());
    const std::string bytes = readBytes(p);
    const int v = L.element("vertex");
    ASSERT_GE(v, 0);
    EXPECT_EQ(L.elements[std::size_t(v)].count, 300u);
    EXPECT_EQ(L.data_offset, bytes.find("end_header\n") + 11);
    EXPECT_EQ(L.format, k == Kind::PlyAscii ? paps::PlyLayout::Format::Ascii
                                            : paps::PlyLayout::Format::BinaryLittleEndian);
    expectSmallCloud(p, 300, k == Kind::PlyBinary);
  }
}

TEST(CloudIo, PlyOutputThatPclWouldWriteWrongIsRefused) {
  // An integer rgb (PCL's writer puts 4 bytes where its header says 3) and a field of several
  // values (written as a list property no point-cloud PLY reader takes) are refused, and no
  // file is left; a float rgb, as PCL's own point types have it, is written and reads back.
  auto cloudWith = [](const std::string& name, std::uint8_t type, std::uint32_t count) {
    pcl::PCLPointCloud2 c;
    pcl::toPCLPointCloud2(smallCloud(50), c);
    pcl::PCLPointField f;
    f.name = name;
    f.offset = c.point_step;
    f.datatype = type;
    f.count = count;
    c.fields.push_back(f);
    const std::uint32_t extra = 4 * count;
    std::vector<std::uint8_t> data;
    for (std::size_t i = 0; i < 50; ++i) {
      data.insert(data.end(), c.data.begin() + i * c.point_step, c.data.begin() + (i + 1) * c.point_step);
      data.insert(data.end(), extra, std::uint8_t(0x40));
    }
    c.point_step += extra;
    c.row_step = c.point_step * c.width;
    c.data = data;
    return c;
  };
  const fs::path out = scratch("out.ply");
  fs::remove(out);
  for (const auto& bad : {cloudWith("rgb", pcl::PCLPointField::UINT32, 1), cloudWith("vec", pcl::PCLPointField::FLOAT32, 3)}) {
    EXPECT_THROW(paps::saveCloudAtomic(out.string(), bad), paps::IoError);
    EXPECT_FALSE(fs::exists(out));
  }
  paps::saveCloudAtomic(out.string(), cloudWith("rgb", pcl::PCLPointField::FLOAT32, 1));
  const paps::Positions back = paps::loadPositions(out.string());
  ASSERT_EQ(back.size(), 50u);
  EXPECT_EQ(back[7], smallCloud(50)[7].getVector3fMap());  // binary PLY: bit for bit
  // The same clouds go to PCD whole.
  const fs::path pcd = scratch("out.pcd");
  paps::saveCloudAtomic(pcd.string(), cloudWith("vec", pcl::PCLPointField::FLOAT32, 3));
  EXPECT_EQ(paps::loadCloud(pcd.string()).fields.back().count, 3u);
}

TEST(CloudIo, SensorOriginReadAndWrittenBack) {
  // A PCD's VIEWPOINT origin is read, and written back by saveCloudAtomic; one that is not
  // finite is read as none (0 0 0). PCL's own reader leaves garbage there on "nan": the value
  // comes from our header check instead.
  pcl::PCLPointCloud2 c;
  pcl::toPCLPointCloud2(smallCloud(50), c);
  const fs::path out = scratch("viewpoint.pcd");
  paps::saveCloudAtomic(out.string(), c, Eigen::Vector3f(0.5f, -2.f, 1e30f));
  Eigen::Vector3f origin;
  paps::loadCloud(out.string(), &origin);
  EXPECT_EQ(origin, Eigen::Vector3f(0.5f, -2.f, 1e30f));
  EXPECT_THROW(paps::saveCloudAtomic(out.string(), c, Eigen::Vector3f(NAN, 0.f, 0.f)), paps::InvalidParameter);
  std::string bytes = readBytes(out);
  const std::size_t at = bytes.find("VIEWPOINT");
  ASSERT_NE(at, std::string::npos);
  const std::size_t eol = bytes.find('\n', at);
  for (const std::string vp : {"VIEWPOINT nan 1 2 1 0 0 0", "VIEWPOINT 1 inf 2 1 0 0 0", "VIEWPOINT 1 2 1e39 1 0 0 0"}) {
    const fs::path bad = scratch("viewpoint_bad.pcd");
    std::ofstream(bad, std::ios::binary) << bytes.substr(0, at) + vp + bytes.substr(eol);
    origin.setConstant(7.f);
    EXPECT_EQ(paps::loadCloud(bad.string(), &origin).width, 50u) << vp;
    EXPECT_EQ(origin, Eigen::Vector3f::Zero()) << vp;
  }
}

TEST(CloudFileLayout, AsciiDataThatIsNotNumbersIsRefused) {
  // PCL's readers turn a word that is not a number, or a short row, into zeros or NaN without
  // a word: the file is refused and the line named. Empty lines are skipped, as PCL does, and
  // "nan" is a number.
  const std::string pcd = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                          "WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n";
  const fs::path p = scratch("rows.pcd");
  struct Case { std::string rows; const char* says; };
  for (const Case& c : {Case{"1 2 3\nfoo bar baz\n7 8 9\n", "data line 2 has 'foo'"},
                        Case{"1.5 2.5 3.5\n7.5 8.5\n4.5 5.5 6.5\n", "data line 2 has 2 values, not 3"},
                        Case{"1 2 3\n  \n4 5 6\n7 8 9\n", "data line 2 has 0 values"},
                        Case{"1 2 3 4\n4 5 6\n7 8 9\n", "data line 1 has 4 values"},
                        Case{"1.25 2.25 3.25\n4.25 5.25 6.25\n", "2 data lines where the header promises 3 points"}}) {
    writeBytes(p, pcd + c.rows);
    EXPECT_NE(loadError(p).find(c.says), std::string::npos) << loadError(p);
  }
  writeBytes(p, pcd + "1 2 3\n\n4 nan 6\n7 8 9\n");
  const paps::Positions ok = paps::loadPositions(p.string());
  ASSERT_EQ(ok.size(), 3u);
  EXPECT_EQ(ok[2], Eigen::Vector3f(7, 8, 9));
  EXPECT_TRUE(std::isnan(ok[1].y()));
  const fs::path q = scratch("words.ply");
  writeBytes(q, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                "end_header\n1 2 3\n4 five 6\n7 8 9\n");
  EXPECT_NE(loadError(q).find("value 5 of the data is 'five'"), std::string::npos) << loadError(q);
  // A folder is said to be one, with or without an extension-like name.
  EXPECT_NE(loadError(q.parent_path()).find("it is a folder"), std::string::npos) << loadError(q.parent_path());
  fs::create_directories(scratch("folder.pcd"));
  EXPECT_NE(loadError(scratch("folder.pcd")).find("it is a folder"), std::string::npos);
}

TEST(CloudFileLayout, RefusesEmptyForeignAndInconsistentHeaders) {
  const std::string head = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
  struct Case { const char* name; std::string bytes; const char* says; };
  const Case cases[] = {
      {"empty.pcd", "", "empty"},
      {"text.pcd", "hello\nworld\n", "unknown PCD header line 'hello'"},
      {"binary.pcd", std::string(3000, '\x01'), "no PCD header"},
      {"blank.pcd", "FIELDS x y z\n\t \nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "only spaces"},
      {"order.pcd", "SIZE 4 4 4\nFIELDS x y z\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "SIZE before FIELDS"},
      {"twice.pcd", head + "SIZE 4 4 8\nWIDTH 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "two different SIZE lines"},
      {"nofields.pcd", "VERSION 0.7\nWIDTH 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "no FIELDS"},
      {"size.pcd", "FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "SIZE has 2"},
      {"type.pcd", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F Q\nWIDTH 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "TYPE 'Q'"},
      {"float2.pcd", "FIELDS x y z\nSIZE 4 4 2\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "float of 2"},
      {"wh.pcd", head + "WIDTH 10\nHEIGHT 2\nPOINTS 10\nDATA ascii\n", "is not POINTS"},
      {"datatype.pcd", head + "WIDTH 1\nPOINTS 1\nDATA gzip\n", "DATA 'gzip'"},
      {"negative.pcd", head + "WIDTH -1\nPOINTS 1\nDATA ascii\n0 0 0\n", "bad WIDTH"},
      // Two billion points promised by a few bytes: refused before any allocation.
      {"bomb.pcd", head + "WIDTH 2000000000\nHEIGHT 1\nPOINTS 2000000000\nDATA binary\n0123456789ab", "promises"},
      {"bomb_ascii.pcd", head + "WIDTH 2000000000\nPOINTS 2000000000\nDATA ascii\n1 2 3\n", "promises"},
      {"bomb_packed.pcd", head + "WIDTH 1000\nPOINTS 1000\nDATA binary_compressed\n" +
                              std::string("\x04\x00\x00\x00\xe0\x2e\x00\x00\x01\x02\x03\x04", 12),
       "corrupt"},
      {"short_packed.pcd", head + "WIDTH 1000\nPOINTS 1000\nDATA binary_compressed\n\x04\x00", "truncated"},
      // PCL's header loop goes on after DATA: a keyword there is read as header. A FIELDS line
      // made it read past its field list (ascii) or crash (binary); binary data starting
      // with "COLUMNS" did too; a second DATA line would move the data.
      {"empty_then_fields.pcd", head + "WIDTH 0\nPOINTS 0\nDATA ascii\n\n\nFIELDS0330", "starts with 'FIELDS'"},
      {"empty_then_fields_bin.pcd", head + "WIDTH 0\nPOINTS 0\nDATA binary\nFIELDS x\n", "starts with 'FIELDS'"},
      {"columns_bin.pcd", head + "POINTS 1\nDATA binary\nCOLUMNS\xfe\xff\xff\xf6\x00\x00", "starts with 'COLUMNS'"},
      {"data_twice.pcd", head + "WIDTH 1\nPOINTS 1\nDATA ascii\n# note\n  DATA binary\n0 0 0\n", "starts with 'DATA'"},
      {"empty.ply", "", "empty"},
      {"text.ply", "plyx\nformat ascii 1.0\n", "not a PLY file"},
      {"noend.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "no end_header"},
      {"noformat.ply", "ply\nelement vertex 1\nproperty float x\nend_header\n0\n", "no format"},
      {"orphan.ply", "ply\nformat ascii 1.0\nproperty float x\nend_header\n", "before any element"},
      {"type.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n0\n", "unknown property type"},
      {"listf.ply", "ply\nformat ascii 1.0\nelement face 1\nproperty list float int v\nend_header\n0\n", "not an integer"},
      {"junk.ply", "ply\nformat ascii 1.0\nelephant 3\nend_header\n", "unknown PLY header line"},
      {"bomb.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\n"
                   "property float y\nproperty float z\nend_header\n0123456789ab", "promises"},
      {"bomb_ascii.ply", "ply\nformat ascii 1.0\nelement vertex 900000000000\nproperty float x\nproperty float y\n"
                         "property float z\nend_header\n0 0 0\n", "promises"},
      {"bomb_faces.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                         "property float z\nelement face 100000000\nproperty list uchar int vertex_indices\n"
                         "end_header\n0123456789ab\x03", "promises"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path p = scratch(c.name);
    writeBytes(p, c.bytes);
    const std::string original = readBytes(p);
    const std::string e = loadError(p);
    EXPECT_NE(e.find(c.says), std::string::npos) << "error was: " << e;
    EXPECT_NE(e.find(p.string()), std::string::npos) << "the error names the file: " << e;
    EXPECT_EQ(readBytes(p), original) << "the input is never modified";
  }
}

TEST(CloudFileLayout, EveryTruncationLoadsOrThrows) {
  for (Kind k : {Kind::PcdAscii, Kind::PcdBinary, Kind::PcdCompressed, Kind::PlyAscii, Kind::PlyBinary}) {
    const fs::path good = writeValid(k, 200);
    const std::string bytes = readBytes(good);
    const fs::path cut = scratch(std::string("cut") + good.extension().string());
    int refused = 0, tried = 0;
    // Every length through the header and the first data bytes, then 60 lengths spread over
    // the rest.
    const std::size_t header_end = bytes.find(good.extension() == ".pcd" ? "\nDATA" : "end_header") + 40;
    for (std::size_t len = 0; len < bytes.size(); len += (len < header_end ? 1 : 1 + bytes.size() / 60)) {
      writeBytes(cut, bytes.substr(0, len));
      ++tried;
      if (!loadError(cut).empty()) ++refused;
    }
    // Binary data cut anywhere is refused; ascii data cut at a line end is a smaller valid file
    // for PCL, so only most cuts are refused there.
    if (k == Kind::PcdBinary || k == Kind::PcdCompressed || k == Kind::PlyBinary) EXPECT_EQ(refused, tried) << int(k);
    else EXPECT_GT(refused, tried / 2) << int(k);
  }
}

TEST(CloudFileLayout, EveryHeaderByteFlipLoadsOrThrows) {
  paps::Random rng(11);
  for (Kind k : {Kind::PcdBinary, Kind::PcdCompressed, Kind::PlyBinary, Kind::PcdAscii}) {
    const fs::path good = writeValid(k, 100);
    const std::string bytes = readBytes(good);
    const fs::path bad = scratch(std::string("flip") + good.extension().string());
    const std::size_t header_end = bytes.find(good.extension() == ".pcd" ? "\nDATA" : "end_header") + 30;
    for (std::size_t i = 0; i < header_end; ++i) {
      for (const std::uint8_t v : {std::uint8_t('9'), std::uint8_t(' '), std::uint8_t('\n'),
                                   std::uint8_t(rng.uniform() * 255.0f)}) {
        std::string b = bytes;
        b[i] = char(v);
        writeBytes(bad, b);
        const std::string e = loadError(bad);  // a crash or a throw of another type fails here
        if (!e.empty()) EXPECT_NE(e.find(bad.string()), std::string::npos) << e;
      }
    }
  }
}

TEST(CloudIo, AppendFieldsKeepsTheOrganisationAndReplacesNamesakes) {
  pcl::PointCloud<pcl::PointXYZI> a = smallCloud(12);
  a.width = 4;
  a.height = 3;
  pcl::PointCloud<pcl::Normal> n(4, 3);
  pcl::PointCloud<pcl::Intensity> again(4, 3);
  for (std::size_t i = 0; i < 12; ++i) {
    n[i].normal_x = float(i);
    n[i].curvature = -float(i);
    again[i].intensity = 100.f + float(i);
  }
  pcl::PCLPointCloud2 ba, bn, bi;
  pcl::toPCLPointCloud2(a, ba);
  pcl::toPCLPointCloud2(n, bn);
  pcl::toPCLPointCloud2(again, bi);
  const pcl::PCLPointCloud2 out = paps::appendFields(ba, bn);
  EXPECT_EQ(out.width, 4u);
  EXPECT_EQ(out.height, 3u);
  std::vector<std::string> names;
  for (const auto& f : out.fields) names.push_back(f.name);
  EXPECT_EQ(names, (std::vector<std::string>{"x", "y", "z", "intensity", "normal_x", "normal_y", "normal_z", "curvature"}));
  pcl::PointCloud<pcl::PointXYZINormal> back;
  pcl::fromPCLPointCloud2(out, back);
  for (std::size_t i = 0; i < 12; ++i) {
    EXPECT_EQ(back[i].getVector3fMap(), a[i].getVector3fMap());
    EXPECT_EQ(back[i].intensity, a[i].intensity);
    EXPECT_EQ(back[i].normal_x, float(i));
    EXPECT_EQ(back[i].curvature, -float(i));
  }
  // A field of the same name is replaced, not doubled.
  const pcl::PCLPointCloud2 replaced = paps::appendFields(ba, bi);
  EXPECT_EQ(replaced.fields.size(), 4u);
  pcl::PointCloud<pcl::PointXYZI> r;
  pcl::fromPCLPointCloud2(replaced, r);
  for (std::size_t i = 0; i < 12; ++i) {
    EXPECT_EQ(r[i].intensity, 100.f + float(i));
    EXPECT_EQ(r[i].getVector3fMap(), a[i].getVector3fMap());
  }
  pcl::PointCloud<pcl::Normal> wrong(5, 1);
  pcl::PCLPointCloud2 bw;
  pcl::toPCLPointCloud2(wrong, bw);
  EXPECT_THROW(paps::appendFields(ba, bw), paps::InvalidInput);
}

TEST(CloudIo, RowsWrittenByBlocksAreTheBlobPclWrites) {
  // A cloud given by rows (appendedRows) is written a block at a time: the file holds the
  // bytes PCL's binary writer gives for the whole blob (PCL pads its file to a page with
  // zeros: our file is that file without the zero tail), and loads back to the same blob.
  // 40,001 points of 272 bytes are three blocks of 4 MB, the last one partial.
  const std::size_t n = 40001;
  pcl::PointCloud<pcl::PointXYZI> a = smallCloud(static_cast<int>(n));
  pcl::PCLPointCloud2 ba;
  pcl::toPCLPointCloud2(a, ba);
  pcl::PCLPointField vec;
  vec.name = "vec";
  vec.offset = 0;
  vec.datatype = pcl::PCLPointField::FLOAT32;
  vec.count = 64;
  pcl::PCLPointCloud2 extra;
  extra.fields = {vec};
  extra.width = std::uint32_t(n);
  extra.height = 1;
  extra.point_step = 256;
  extra.row_step = extra.point_step * extra.width;
  extra.data.resize(n * 256);
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 64; ++k) {
      const float v = float(i) + 0.01f * float(k);
      std::memcpy(&extra.data[i * 256 + 4 * k], &v, 4);
    }
  const pcl::PCLPointCloud2 whole = paps::appendFields(ba, extra);
  EXPECT_EQ(whole.point_step, 16u + 256u);  // x y z intensity packed, then vec
  const paps::CloudRows rows = paps::appendedRows(ba, extra.fields, extra.point_step,
                                                  [&](std::size_t i, std::uint8_t* row) {
                                                    std::memcpy(row, &extra.data[i * 256], 256);
                                                  });
  EXPECT_EQ(paps::gatherRows(rows).data, whole.data);
  const fs::path ours = scratch("rows.pcd"), pcls = scratch("rows_pcl.pcd");
  paps::saveCloudAtomic(ours.string(), rows, Eigen::Vector3f(1.f, 2.f, 3.f));
  ASSERT_EQ(pcl::PCDWriter().writeBinary(pcls.string(), whole, Eigen::Vector4f(1.f, 2.f, 3.f, 0.f),
                                         Eigen::Quaternionf::Identity()), 0);
  const std::string b_ours = readBytes(ours), b_pcl = readBytes(pcls);
  ASSERT_LE(b_ours.size(), b_pcl.size());
  EXPECT_GT(b_ours.size(), whole.data.size());
  EXPECT_EQ(b_pcl.substr(0, b_ours.size()), b_ours);
  EXPECT_EQ(b_pcl.find_first_not_of('\0', b_ours.size()), std::string::npos);
  Eigen::Vector3f origin;
  const pcl::PCLPointCloud2 back = paps::loadCloud(ours.string(), &origin);
  EXPECT_EQ(back.data, whole.data);
  EXPECT_EQ(back.point_step, whole.point_step);
  EXPECT_EQ(origin, Eigen::Vector3f(1.f, 2.f, 3.f));
  // As .ply, the same rows (gathered whole for PCL's writer).
  const fs::path ply = scratch("rows.ply");
  const paps::CloudRows scalar = paps::appendedRows(ba, {}, 0, [](std::size_t, std::uint8_t*) {});
  paps::saveCloudAtomic(ply.string(), scalar);
  EXPECT_EQ(paps::loadPositions(ply.string())[40000], a[40000].getVector3fMap());
}

TEST(CloudIo, RowsThatFailMidwayLeaveTheTargetAsItWas) {
  // A fill that throws in the second block, and a folder that cannot be written: the error
  // reaches the caller, the earlier file is intact and no temporary file is left.
  const std::size_t n = 300000;
  pcl::PCLPointCloud2 ba;
  pcl::toPCLPointCloud2(smallCloud(static_cast<int>(n)), ba);
  const fs::path dir = scratch("rows_fail");
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path target = dir / "out.pcd";
  { std::ofstream(target) << "earlier"; }
  pcl::PCLPointField f;
  f.name = "label";
  f.datatype = pcl::PCLPointField::UINT32;
  f.count = 1;
  const paps::CloudRows rows = paps::appendedRows(ba, {f}, 4, [](std::size_t i, std::uint8_t* row) {
    if (i == 299999) throw paps::InvalidInput("planted failure");
    const std::uint32_t v = std::uint32_t(i);
    std::memcpy(row, &v, 4);
  });
  EXPECT_THROW(paps::saveCloudAtomic(target.string(), rows), paps::InvalidInput);
  EXPECT_EQ(readBytes(target), "earlier");
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1);
  EXPECT_THROW(paps::saveCloudAtomic((dir / "missing" / "out.pcd").string(), rows), paps::IoError);
  EXPECT_THROW(paps::saveCloudAtomic(target.string(), rows, Eigen::Vector3f(NAN, 0.f, 0.f)), paps::InvalidParameter);
  EXPECT_EQ(readBytes(target), "earlier");
}

// The fuzzing corpus (test/core/cloud_io_corpus, see fuzz_cloud_io.cpp): the seeds are five
// points each, (0,0,0) (1,0,0) (0,1,0) (1,1,0.5) (0.5,0.5,0.25), in every format and
// encoding, and load to exactly those; the regression-* inputs the fuzzer kept load or throw.
TEST(CloudFileLayout, FuzzCorpusReplays) {
  const fs::path dir = PAPS_CLOUD_IO_CORPUS_DIR;
  ASSERT_TRUE(fs::is_directory(dir)) << dir;
  int seeds = 0, direct_seeds = 0, mesh_seeds = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    SCOPED_TRACE(name);
    const bool seed = name.rfind("seed-", 0) == 0;
    ASSERT_TRUE(seed || name.rfind("regression-", 0) == 0) << "a corpus file is a seed-* or a regression-*";
    const std::string bytes = readBytes(entry.path());
    ASSERT_FALSE(bytes.empty());
    // The fuzz target's mesh readers on the same bytes: PLY as a mesh (odd first byte), OBJ
    // (bit 1). A mesh seed is a 5-vertex OBJ.
    if (bytes[0] & 2) {
      const fs::path obj = scratch("corpus.obj");
      writeBytes(obj, bytes.substr(1));
      if (name.find(".obj") != std::string::npos) {
        const paps::TriangleMesh m = paps::loadTriangleMesh(obj.string());
        EXPECT_EQ(m.vertices.size(), 5u);
        EXPECT_EQ(m.triangles.size(), 4u);
        ++mesh_seeds;
        continue;
      }
      try {
        paps::loadTriangleMesh(obj.string());
      } catch (const paps::Error&) {
      }
    }
    const fs::path file = scratch(std::string("corpus") + ((bytes[0] & 1) ? ".ply" : ".pcd"));
    if (bytes[0] & 1) {
      writeBytes(file, bytes.substr(1));
      try {
        paps::loadTriangleMesh(file.string());
      } catch (const paps::Error&) {
      }
    }
    writeBytes(file, bytes.substr(1));
    // The direct x y z readers (the lean codec binary's) on the same bytes.
    paps::Positions xyz;
    bool direct = false;
    std::string direct_error;
    try {
      direct = paps::readPcdXyz(file.string(), xyz) || paps::readPlyXyz(file.string(), xyz);
    } catch (const paps::Error& e) {
      direct_error = e.what();
    }
    if (!seed) {
      loadError(file);  // either outcome; a crash fails the run
      continue;
    }
    ++seeds;
    const paps::Positions p = paps::loadPositions(file.string());
    ASSERT_EQ(p.size(), 5u);
    EXPECT_EQ(p[0], Eigen::Vector3f(0, 0, 0));
    EXPECT_EQ(p[3], Eigen::Vector3f(1, 1, 0.5f));
    EXPECT_EQ(p[4], Eigen::Vector3f(0.5f, 0.5f, 0.25f));
    EXPECT_TRUE(direct_error.empty()) << direct_error;
    if (direct) EXPECT_EQ(xyz, p);  // binary PCD and PLY seeds; ascii PCD is left to PCL
    direct_seeds += direct;
  }
  EXPECT_EQ(seeds, 5);
  EXPECT_EQ(direct_seeds, 4);  // all but the ascii PCD
  EXPECT_EQ(mesh_seeds, 1);
}

// A complete temporary replaces the target whole and is gone; a target that cannot be written
// leaves the old file as it was and no temporary behind; the checks name the path and why.
TEST(CloudFileLayout, CommitTemporaryFileReplacesWholeOrLeavesAsItWas) {
  const fs::path target = scratch("commit_target.txt"), tmp = scratch(".commit_target.tmp");
  writeBytes(target, "old");
  writeBytes(tmp, "new contents");
  paps::commitTemporaryFile(tmp.string(), target.string());
  EXPECT_EQ(readBytes(target), "new contents");
  EXPECT_FALSE(fs::exists(tmp));
  writeBytes(tmp, "never");
  const fs::path missing = scratch("no_such_folder") / "x.txt";
  EXPECT_THROW(paps::commitTemporaryFile(tmp.string(), missing.string(), "photo list "), paps::IoError);
  EXPECT_FALSE(fs::exists(tmp));
  EXPECT_EQ(readBytes(target), "new contents");
  EXPECT_THROW(paps::commitTemporaryFile(scratch("no_such_tmp").string(), target.string()), paps::IoError);
  EXPECT_EQ(readBytes(target), "new contents");
  try {
    paps::checkOutputPath(missing.string());
    ADD_FAILURE() << "a missing folder was accepted";
  } catch (const paps::IoError& e) {
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
  try {
    paps::checkInputPath(scratch("").string(), "mesh ");
    ADD_FAILURE() << "a folder was accepted as input";
  } catch (const paps::IoError& e) {
    EXPECT_NE(std::string(e.what()).find("cannot read mesh '"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("it is a folder"), std::string::npos) << e.what();
  }
}

}  // namespace core_cloud_file_layout_test
