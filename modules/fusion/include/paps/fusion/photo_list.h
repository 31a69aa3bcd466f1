#pragma once
// A list of photos with their cameras and poses, as a text file: what `paps register` reads
// (approximate poses) and writes (refined poses), and what colorization and shadow detection
// read. One photo per line, blank lines and '#' comments ignored, 24 fields:
//   image width height fx fy cx cy k1 k2 p1 p2 k3 r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz
// `image` is a path relative to the list's folder (no spaces); the 3x4 matrix is the
// camera-to-world pose [R | t] with OpenCV's camera axes (x right, y down, z forward).
#include <string>
#include <vector>

#include <paps/fusion/camera_model.h>
#include <paps/fusion/registered_photo.h>

namespace paps {

struct PhotoListEntry {
  std::string image;          ///< as written in the list (relative to the list's folder)
  CameraIntrinsics camera;
  CameraPose pose = CameraPose::Identity();
};

/// Parses a list. Throws IoError when the file cannot be read, InvalidInput naming the line
/// for a wrong field count, a non-number, a non-finite value, a bad camera, or a rotation that
/// is not orthonormal (to 1e-4).
std::vector<PhotoListEntry> loadPhotoList(const std::string& path);
/// The same from text (`where` names it in messages).
std::vector<PhotoListEntry> parsePhotoList(const std::string& text, const std::string& where = "photo list");
/// Writes a list atomically (temporary file, then rename); throws IoError on failure.
void savePhotoListAtomic(const std::string& path, const std::vector<PhotoListEntry>& entries);
/// Reads the image of every entry (relative to the folder of `list_path`); throws IoError for
/// an unreadable image, InvalidInput for one whose size is not its camera's.
std::vector<RegisteredPhoto> loadPhotos(const std::string& list_path, const std::vector<PhotoListEntry>& entries);

}  // namespace paps
