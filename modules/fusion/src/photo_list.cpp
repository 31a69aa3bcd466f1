#include <paps/fusion/photo_list.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

#include <unistd.h>

#include <opencv2/imgcodecs.hpp>

#include <paps/core/cloud_file_layout.h>
#include <paps/core/error.h>

namespace paps {

std::vector<PhotoListEntry> parsePhotoList(const std::string& text, const std::string& where) {
  std::vector<PhotoListEntry> entries;
  std::istringstream in(text);
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream fields(line);
    std::vector<std::string> tokens;
    for (std::string t; fields >> t;) tokens.push_back(t);
    if (tokens.empty()) continue;
    const std::string at = where + " line " + std::to_string(number) + ": ";
    if (tokens.size() != 24)
      throw InvalidInput(at + std::to_string(tokens.size()) + " fields (expected 24: image width height fx fy cx cy k1 k2 p1 p2 k3 and a 3x4 pose)");
    double v[23];
    for (int i = 0; i < 23; ++i) {
      const std::string& t = tokens[i + 1];
      std::size_t used = 0;
      try {
        v[i] = std::stod(t, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != t.size() || !std::isfinite(v[i])) throw InvalidInput(at + "field " + std::to_string(i + 2) + " '" + t + "' is not a finite number");
    }
    PhotoListEntry e;
    e.image = tokens[0];
    // Checked before the casts: a value outside int's range makes the cast undefined (found by the fuzzer).
    if (v[0] != std::floor(v[0]) || v[1] != std::floor(v[1]) || !(v[0] >= 0 && v[0] <= 1e6) || !(v[1] >= 0 && v[1] <= 1e6))
      throw InvalidInput(at + "width and height must be whole numbers from 0 to 1000000");
    e.camera.width = static_cast<int>(v[0]);
    e.camera.height = static_cast<int>(v[1]);
    e.camera.fx = v[2];
    e.camera.fy = v[3];
    e.camera.cx = v[4];
    e.camera.cy = v[5];
    e.camera.k1 = v[6];
    e.camera.k2 = v[7];
    e.camera.p1 = v[8];
    e.camera.p2 = v[9];
    e.camera.k3 = v[10];
    try {
      e.camera.validate();
    } catch (const InvalidParameter& error) {
      throw InvalidInput(at + error.what());
    }
    Eigen::Matrix3d r;
    Eigen::Vector3d t;
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) r(row, col) = v[11 + row * 4 + col];
      t[row] = v[11 + row * 4 + 3];
    }
    if (!((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-4) || !(r.determinant() > 0))
      throw InvalidInput(at + "the pose's rotation is not orthonormal with determinant +1");
    e.pose.linear() = r;
    e.pose.translation() = t;
    entries.push_back(e);
  }
  return entries;
}

std::vector<PhotoListEntry> loadPhotoList(const std::string& path) {
  checkInputPath(path, "photo list ");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError("cannot read photo list '" + path + "'");
  std::ostringstream s;
  s << f.rdbuf();
  if (f.bad()) throw IoError("error reading photo list '" + path + "'");
  return parsePhotoList(s.str(), path);
}

void savePhotoListAtomic(const std::string& path, const std::vector<PhotoListEntry>& entries) {
  checkOutputPath(path);
  std::ostringstream s;
  s << "# paps photo list: image width height fx fy cx cy k1 k2 p1 p2 k3, then the camera-to-world pose\n"
       "# r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz (OpenCV camera axes: x right, y down, z forward)\n";
  s << std::setprecision(17);
  for (const auto& e : entries) {
    if (e.image.empty() || e.image.find_first_of(" \t\n#") != std::string::npos)
      throw InvalidInput("photo list: image path '" + e.image + "' is empty or holds a space or '#'");
    const auto& c = e.camera;
    s << e.image << ' ' << c.width << ' ' << c.height << ' ' << c.fx << ' ' << c.fy << ' ' << c.cx << ' ' << c.cy << ' '
      << c.k1 << ' ' << c.k2 << ' ' << c.p1 << ' ' << c.p2 << ' ' << c.k3;
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) s << ' ' << e.pose.linear()(row, col);
      s << ' ' << e.pose.translation()[row];
    }
    s << '\n';
  }
  const std::string tmp = path + ".tmp" + std::to_string(::getpid());
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f << s.str();
    f.flush();
    if (!f) {
      std::remove(tmp.c_str());
      throw IoError("cannot write photo list '" + path + "'");
    }
  }
  commitTemporaryFile(tmp, path, "photo list ");
}

std::vector<RegisteredPhoto> loadPhotos(const std::string& list_path, const std::vector<PhotoListEntry>& entries) {
  const std::filesystem::path folder = std::filesystem::path(list_path).parent_path();
  std::vector<RegisteredPhoto> photos;
  for (const auto& e : entries) {
    const std::string file = (folder / e.image).string();
    RegisteredPhoto p;
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec)) throw IoError("cannot read image '" + file + "': no such file");
    p.image = cv::imread(file, cv::IMREAD_COLOR);
    if (p.image.empty()) throw IoError("cannot read image '" + file + "'");
    if (p.image.cols != e.camera.width || p.image.rows != e.camera.height)
      throw InvalidInput("image '" + file + "' is " + std::to_string(p.image.cols) + "x" + std::to_string(p.image.rows) +
                         ", its camera " + std::to_string(e.camera.width) + "x" + std::to_string(e.camera.height));
    p.camera = e.camera;
    p.pose = e.pose;
    photos.push_back(p);
  }
  return photos;
}

}  // namespace paps
