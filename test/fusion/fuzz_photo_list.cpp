// libFuzzer target: paps::parsePhotoList must parse any text or reject it with paps::Error
// (never crash, hang or allocate without bound), and what it accepts must survive a write and
// a read unchanged. Built and run by `scripts/fuzz.sh photo_list`; crash inputs land in
// test/fusion/photo_list_corpus, which test_fusion (the photo list tests) replays in CI.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include <unistd.h>

#include <paps/core/error.h>
#include <paps/fusion/photo_list.h>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<paps::PhotoListEntry> entries;
  try {
    entries = paps::parsePhotoList(std::string(reinterpret_cast<const char*>(data), size), "fuzz");
  } catch (const paps::Error&) {
    return 0;
  }
  static const std::string path = "/dev/shm/paps_fuzz_photo_list_" + std::to_string(::getpid()) + ".txt";
  try {
    paps::savePhotoListAtomic(path, entries);
  } catch (const paps::InvalidInput&) {
    return 0;  // an image path the writer refuses (none the parser accepts should be)
  }
  const auto again = paps::loadPhotoList(path);
  if (again.size() != entries.size()) std::abort();
  for (std::size_t i = 0; i < again.size(); ++i)
    if (again[i].image != entries[i].image || !again[i].pose.isApprox(entries[i].pose, 1e-12) ||
        again[i].camera.fx != entries[i].camera.fx || again[i].camera.width != entries[i].camera.width)
      std::abort();
  return 0;
}
