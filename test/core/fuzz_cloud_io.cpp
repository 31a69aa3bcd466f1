// libFuzzer target: paps::loadCloud (our header checks, then PCL's PCD and PLY readers), our
// own x y z readers (paps::readPcdXyz, readPlyXyz: the lean codec binary's) and
// paps::loadTriangleMesh (PLY through PCL, OBJ our own) must load any input or reject it with
// paps::Error: never crash, hang or allocate without bound.
// The first byte chooses the format (even: .pcd, odd: .ply, also read as a mesh; bit 1: the
// same bytes read as an .obj mesh too); the rest is the file.
// Built and run by `scripts/fuzz.sh cloud_io`; crash inputs land in test/core/cloud_io_corpus,
// which test_core_cloud_file_layout replays in CI.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include <unistd.h>

#include <paps/core/cloud_io.h>
#include <paps/core/error.h>
#include <paps/core/triangle_mesh.h>
#include <paps/core/xyz_file_reader.h>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  // PCL's readers take a path: the input goes to a file in memory-backed /dev/shm.
  static const std::string base = "/dev/shm/paps_fuzz_cloud_io_" + std::to_string(::getpid());
  const std::string path = base + ((data[0] & 1) ? ".ply" : ".pcd");
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data + 1, 1, size - 1, f);
  std::fclose(f);
  try {
    paps::loadCloud(path);
  } catch (const paps::Error&) {
  }
  try {
    paps::Positions xyz;
    if (!paps::readPcdXyz(path, xyz)) paps::readPlyXyz(path, xyz);
  } catch (const paps::Error&) {
  }
  if (data[0] & 1) {
    try {
      paps::loadTriangleMesh(path);
    } catch (const paps::Error&) {
    }
  }
  std::remove(path.c_str());
  if (data[0] & 2) {
    const std::string obj = base + ".obj";
    if (std::FILE* o = std::fopen(obj.c_str(), "wb")) {
      std::fwrite(data + 1, 1, size - 1, o);
      std::fclose(o);
      try {
        paps::loadTriangleMesh(obj);
      } catch (const paps::Error&) {
      }
      std::remove(obj.c_str());
    }
  }
  return 0;
}
