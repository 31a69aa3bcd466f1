#!/bin/bash
# The whole test suite under AddressSanitizer, LeakSanitizer and UndefinedBehaviorSanitizer
# (GCC). Not part of CI: on 2 cores, rebuilding session 47's sanitizer build after session
# 48's changes took about 45 minutes beside a bench run, and ctest 37 minutes (session 49).
# A report makes its test fail (ASan and LSan exit 1, UBSan halts on the first).
#   bash scripts/address_sanitizer.sh [BUILD_DIR] [ctest arguments, e.g. -R Wavejet]
#   bash scripts/address_sanitizer.sh --untrusted-input [BUILD_DIR]
# --untrusted-input builds only paps::core and paps::compression and runs the tests of the
# code that reads bytes from outside: the cloud file readers (with their fuzz corpus) and the
# codec's decoder (truncations, bit flips, garbage, the fuzz corpus). About 4 minutes on 2
# cores (237 s in session 56, 528 s before its lighter flags and Ninja); scripts/test.sh runs
# it after the suite.
# Notes (docs/architecture.md, "The whole test suite under ASan/UBSan"):
#  - EIGEN_MALLOC_ALREADY_ALIGNED=1: without it Eigen switches to its own aligned allocator
#    under ASan while Debian's PCL keeps malloc, and frees across the two look like overflows;
#  - alloc_dealloc_mismatch=0: a pcl::MovingLeastSquares (the peer in some benches) allocates
#    with its class operator new inside the C++14 PCL library and is freed by the global
#    delete in our C++17 code; glibc's delete is free, so release builds are unaffected;
#  - scripts/lsan.supp: leaks inside libraries we do not build (PCL's Poisson, ...).
set -euo pipefail
SRC=$(cd "$(dirname "$0")/.." && pwd)
UNTRUSTED=0
if [ "${1:-}" = "--untrusted-input" ]; then UNTRUSTED=1; shift; fi
BUILD=${1:-/tmp/paps_asan_build}
[ $# -gt 0 ] && shift
FLAGS="-O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=undefined -DEIGEN_MALLOC_ALREADY_ALIGNED=1"
# Set for the build too: gtest_discover_tests runs each test binary to list its tests.
export ASAN_OPTIONS="detect_leaks=1:alloc_dealloc_mismatch=0"
export LSAN_OPTIONS="suppressions=$SRC/scripts/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
MODULES=()
if [ $UNTRUSTED = 1 ]; then
  # Lighter, for CI: line tables only (-g1) and no vptr check (the readers and the decoder
  # make no polymorphic casts). GCC's full -g and vptr instrumentation of the Eigen-heavy core
  # files doubled the build: quadric_height_patch.cpp 149 s -> 75 s.
  FLAGS="${FLAGS/ -g / -g1 } -fno-sanitize=vptr"
  # Ninja compiles the compression module and the tests while the core library is still
  # building; make waits for each library before its dependants.
  command -v ninja >/dev/null && MODULES+=(-G Ninja)
  MODULES+=(-DPAPS_BUILD_APPS=OFF -DPAPS_BUILD_EXAMPLES=OFF -DPAPS_MODULE_FILTERS=OFF -DPAPS_MODULE_FEATURES=OFF
           -DPAPS_MODULE_SURFACE=OFF -DPAPS_MODULE_FUSION=OFF)
fi
mkdir -p "$(dirname "$BUILD")"
rm -f "$BUILD/CMakeCache.txt"  # a build folder of the other generator or mode
cmake -S "$SRC" -B "$BUILD" -DCMAKE_BUILD_TYPE=None -DCMAKE_C_FLAGS="$FLAGS" -DCMAKE_CXX_FLAGS="$FLAGS" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
  "${MODULES[@]}" > "$BUILD.cmake.log"
if [ $UNTRUSTED = 1 ]; then
  TESTS=(test_core_cloud_file_layout test_compression)
  cmake --build "$BUILD" -j"$(nproc)" --target "${TESTS[@]}"
  cd "$BUILD"
  # The tests of the targets built; ctest lists the others as *_NOT_BUILT.
  exec ctest -j"$(nproc)" --timeout 900 --output-on-failure -E '_NOT_BUILT$|^consumer_find_package$'
fi
cmake --build "$BUILD" -j"$(nproc)"
cd "$BUILD"
# Left out: the consumer project is built without the sanitizer (its link misses the
# runtime), and the file bench limits its workers' address space to 8 GB, which ASan's
# shadow memory cannot fit in.
ctest -j"$(nproc)" --timeout 1500 --output-on-failure -E '^(consumer_find_package|apps_cli_bench_files)$' "$@"
