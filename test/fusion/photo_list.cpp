#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include <paps/core/error.h>
#include <paps/fusion/photo_list.h>

// Named, not anonymous: the module's test files are compiled as one unit (unity build).
namespace fusion_photo_list_test {

paps::PhotoListEntry entry(const std::string& image, double x) {
  paps::PhotoListEntry e;
  e.image = image;
  e.camera = paps::CameraIntrinsics::fromFieldOfView(320, 240, 80);
  e.camera.k1 = -0.08;
  e.pose = paps::lookAt({x, -1.5, 2.6}, {x + 0.3, 5, 3});
  return e;
}

std::string scratch(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("paps_photo_list_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

TEST(PhotoList, WriteThenReadGivesTheSameEntries) {
  const std::vector<paps::PhotoListEntry> in{entry("a.png", 0), entry("sub/b.jpg", 7.25)};
  const std::string path = scratch("list.txt");
  paps::savePhotoListAtomic(path, in);
  const auto out = paps::loadPhotoList(path);
  ASSERT_EQ(out.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(out[i].image, in[i].image);
    EXPECT_EQ(out[i].camera.width, 320);
    EXPECT_EQ(out[i].camera.fx, in[i].camera.fx);  // 17 digits: exact
    EXPECT_EQ(out[i].camera.k1, -0.08);
    EXPECT_TRUE(out[i].pose.matrix() == in[i].pose.matrix());
  }
}

TEST(PhotoList, CommentsAndBlankLinesAreSkipped) {
  std::ostringstream s;
  s << "# header\n\n   \nphoto.png 64 48 50 50 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 1 3 # trailing\n";
  const auto e = paps::parsePhotoList(s.str());
  ASSERT_EQ(e.size(), 1u);
  EXPECT_EQ(e[0].pose.translation(), Eigen::Vector3d(1, 2, 3));
}

TEST(PhotoList, BadLinesNameTheLineAndTheProblem) {
  const std::string good = "p.png 64 48 50 50 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 1 3\n";
  auto fails = [](const std::string& text, const std::string& mention) {
    try {
      paps::parsePhotoList(text, "t");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const paps::InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(mention), std::string::npos) << e.what();
    }
  };
  fails("\n" + good.substr(0, 20) + "\n", "t line 2: 6 fields");
  fails("p.png 64 48 50 nan 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 1 3\n", "'nan' is not a finite number");
  fails("p.png 64 48 50 50x 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 1 3\n", "'50x'");
  fails("p.png -2222222222224 48 50 50 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 1 3\n", "whole numbers");  // fuzzer
  fails("p.png 64.5 48 50 50 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 1 3\n", "whole numbers");
  fails("p.png 4 48 50 50 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 1 3\n", "camera width");
  fails("p.png 64 48 -50 50 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 1 3\n", "camera fx");
  fails("p.png 64 48 50 50 31.5 23.5 0 0 0 0 0  1 0 0 1  0 1 0 2  0 0 2 3\n", "not orthonormal");
  fails("p.png 64 48 50 50 31.5 23.5 0 0 0 0 0  -1 0 0 1  0 1 0 2  0 0 1 3\n", "determinant");
  fails("p.png 64 48 50 50 31.5 23.5 0 0 0 0 0  1 0 0 1e999  0 1 0 2  0 0 1 3\n", "finite");
  EXPECT_EQ(paps::parsePhotoList(good + good).size(), 2u);
}

TEST(PhotoList, MissingFilesAndImagesAreIoErrors) {
  EXPECT_THROW(paps::loadPhotoList(scratch("none.txt")), paps::IoError);
  const std::string path = scratch("images.txt");
  paps::savePhotoListAtomic(path, {entry("missing.png", 0)});
  EXPECT_THROW(paps::loadPhotos(path, paps::loadPhotoList(path)), paps::IoError);
  EXPECT_THROW(paps::savePhotoListAtomic(path, {entry("with space.png", 0)}), paps::InvalidInput);
  EXPECT_THROW(paps::savePhotoListAtomic(scratch("no/such/folder/list.txt"), {entry("a.png", 0)}), paps::IoError);
  EXPECT_EQ(paps::loadPhotoList(path).size(), 1u);  // the refused writes left the list alone
}

// Every input the fuzzer kept (test/fusion/photo_list_corpus) is parsed or refused cleanly.
TEST(PhotoList, FuzzCorpusReplays) {
  const std::filesystem::path corpus = std::filesystem::path(PAPS_SOURCE_DIR) / "test/fusion/photo_list_corpus";
  int files = 0;
  for (const auto& f : std::filesystem::directory_iterator(corpus)) {
    std::ifstream in(f.path(), std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    try {
      paps::parsePhotoList(s.str(), f.path().filename().string());
    } catch (const paps::Error&) {
    }
    ++files;
  }
  EXPECT_GT(files, 0);
}

}  // namespace fusion_photo_list_test
