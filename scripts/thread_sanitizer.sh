#!/bin/bash
# The whole test suite under ThreadSanitizer: Clang with LLVM's OpenMP runtime and its Archer
# tool, which tells TSan how OpenMP's barriers and loops order our threads (GCC's libgomp is
# not instrumented, and every parallel loop would look racy). Not part of CI: on 2 cores the
# build took about 13 minutes and ctest 19 to 25. Any race report makes its test exit 66.
#   bash scripts/thread_sanitizer.sh [BUILD_DIR] [ctest arguments, e.g. -R Random]
# Needs: clang, libomp-dev (apt-get install clang libomp-dev) besides the usual dependencies.
set -euo pipefail
SRC=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-/tmp/paps_tsan_build}
[ $# -gt 0 ] && shift
ARCHER=$(ls /usr/lib/llvm-*/lib/libarcher.so 2>/dev/null | sort -V | tail -1 || true)
if [ -z "$ARCHER" ] || ! command -v clang++ > /dev/null; then
  echo "thread_sanitizer.sh: needs clang and LLVM's OpenMP with Archer: apt-get install clang libomp-dev" >&2
  exit 2
fi
# Set for the build too: gtest_discover_tests runs each test binary to list its tests.
export TSAN_OPTIONS="suppressions=$SRC/scripts/tsan.supp ignore_noninstrumented_modules=1 halt_on_error=0 history_size=4"
export OMP_TOOL_LIBRARIES=$ARCHER
cmake -S "$SRC" -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_C_FLAGS="-fsanitize=thread -O1 -g" -DCMAKE_CXX_FLAGS="-fsanitize=thread -O1 -g" \
  -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=thread -DCMAKE_SHARED_LINKER_FLAGS=-fsanitize=thread > "$BUILD.cmake.log"
cmake --build "$BUILD" -j"$(nproc)"
cd "$BUILD"
# Left out: the consumer project is built without the sanitizer, and the file bench limits
# its workers' address space to 8 GB, which TSan's shadow memory cannot fit in.
ctest -j"$(nproc)" --output-on-failure -E '^(consumer_find_package|apps_cli_bench_files)$' "$@"
