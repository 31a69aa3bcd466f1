// Counting replacements of the global operator new and delete. Each block carries its size in
// a header of max_align_t size, so that the sized and unsized deletes both know what they free.
#include "peak_allocation.h"

#include <atomic>
#include <cstdlib>
#include <new>

#if defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define PAPS_RUNTIME_OWNS_NEW 1  // Clang's TSan runtime defines operator new in the binary
#endif
#endif

#ifdef PAPS_RUNTIME_OWNS_NEW
namespace paps::test {
void resetAllocationPeak() {}
std::size_t allocationPeakSinceReset() { return 0; }
bool allocationCounted() { return false; }
}  // namespace paps::test
#else
namespace {
std::atomic<std::size_t> held{0}, peak{0}, base{0};
constexpr std::size_t kHeader = alignof(std::max_align_t);

void* allocate(std::size_t n) {
  void* raw = std::malloc(n + kHeader);
  if (!raw) throw std::bad_alloc();
  *static_cast<std::size_t*>(raw) = n;
  const std::size_t now = held.fetch_add(n) + n;
  std::size_t p = peak.load();
  while (now > p && !peak.compare_exchange_weak(p, now)) {
  }
  return static_cast<char*>(raw) + kHeader;
}
void release(void* ptr) noexcept {
  if (!ptr) return;
  void* raw = static_cast<char*>(ptr) - kHeader;
  held.fetch_sub(*static_cast<std::size_t*>(raw));
  std::free(raw);
}
}  // namespace

namespace paps::test {
void resetAllocationPeak() {
  base = held.load();
  peak = base.load();
}
std::size_t allocationPeakSinceReset() { return peak.load() - base.load(); }
bool allocationCounted() { return true; }
}  // namespace paps::test

void* operator new(std::size_t n) { return allocate(n); }
void* operator new[](std::size_t n) { return allocate(n); }
void operator delete(void* p) noexcept { release(p); }
void operator delete[](void* p) noexcept { release(p); }
void operator delete(void* p, std::size_t) noexcept { release(p); }
void operator delete[](void* p, std::size_t) noexcept { release(p); }
// The nothrow forms too (std::stable_sort's buffer): a runtime that defines them apart from the
// plain ones (AddressSanitizer's does) would otherwise hand us blocks without our header.
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return allocate(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return allocate(n);
  } catch (...) {
    return nullptr;
  }
}
void operator delete(void* p, const std::nothrow_t&) noexcept { release(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { release(p); }
#endif  // PAPS_RUNTIME_OWNS_NEW
