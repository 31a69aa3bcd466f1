#!/usr/bin/env bash
# Fuzzes one libFuzzer target for a fixed time.
#   scripts/fuzz.sh TARGET [SECONDS=120] [BUILD_DIR=/tmp/paps_fuzz_build]
# TARGET: compression  the .paps decoder (test/compression/fuzz_decoder.cpp)
#         cloud_io     paps::loadCloud: our PCD/PLY header checks, then PCL's readers
#                      (test/core/fuzz_cloud_io.cpp; PCL itself is not instrumented, so
#                      coverage guides through our checks and a crash anywhere is caught)
#         photo_list   paps::parsePhotoList, the photo lists of paps register (test/fusion/fuzz_photo_list.cpp)
#         stages       every algorithm (the optimal-transport stages too) on small clouds of awkward geometry (copies, lines,
#                      planes, tiny and UTM-like scales; test/fuzz_stages.cpp)
# CHECK=asan (default) builds the libraries with clang and ASan/UBSan; CHECK=malloc builds
# them with coverage only and runs under glibc's malloc checks (libc_malloc_debug,
# MALLOC_CHECK_=3), which catch heap writes out of bounds inside PCL, whose code ASan does not
# instrument (session 16: two PCL crashes that ASan only saw as a corrupted heap later).
# Either way it seeds the corpus from the target's corpus
# folder, runs the fuzzer, and copies any crash/timeout/oom input into that folder (as
# regression-<hash>) so that the target's corpus test replays it in CI. New corpus entries
# are not copied back (keep the committed corpus tiny).
set -euo pipefail
TARGET=${1:?usage: scripts/fuzz.sh compression|cloud_io|photo_list|stages [SECONDS] [BUILD_DIR]}
SECONDS_TO_RUN=${2:-120}
CHECK=${CHECK:-asan}
case "$CHECK" in
  asan) BUILD=${3:-/tmp/paps_fuzz_build}; SANITIZE=",address,undefined -fno-sanitize-recover=undefined"; LINKED="address,undefined"
        RUN_ENV=(ASAN_OPTIONS=detect_leaks=0:allocator_may_return_null=1) ;;
  malloc) BUILD=${3:-/tmp/paps_fuzz_build_malloc}; SANITIZE=""; LINKED=none
          RUN_ENV=(LD_PRELOAD=/usr/lib/x86_64-linux-gnu/libc_malloc_debug.so.0 MALLOC_CHECK_=3) ;;
  *) echo "unknown CHECK '$CHECK' (asan or malloc)" >&2; exit 2 ;;
esac
ROOT=$(cd "$(dirname "$0")/.." && pwd)
case "$TARGET" in
  compression) BIN=test/compression/fuzz_compression_decoder; CORPUS_SRC="$ROOT/test/compression/corpus"; MAX_LEN=65536 ;;
  cloud_io) BIN=test/core/fuzz_cloud_io; CORPUS_SRC="$ROOT/test/core/cloud_io_corpus"; MAX_LEN=8192 ;;
  photo_list) BIN=test/fusion/fuzz_photo_list; CORPUS_SRC="$ROOT/test/fusion/photo_list_corpus"; MAX_LEN=4096 ;;
  stages) BIN=test/fuzz_stages; CORPUS_SRC="$ROOT/test/stages_corpus"; MAX_LEN=1202 ;;
  *) echo "unknown fuzz target '$TARGET' (compression, cloud_io, photo_list or stages)" >&2; exit 2 ;;
esac
# The readers' targets need the core (and the codec) only; the stage target every module.
MODULES=(-DPAPS_MODULE_FILTERS=OFF -DPAPS_MODULE_SURFACE=OFF -DPAPS_MODULE_FEATURES=OFF)
[ "$TARGET" = stages ] && MODULES=(-DPAPS_MODULE_FILTERS=ON -DPAPS_MODULE_SURFACE=ON -DPAPS_MODULE_FEATURES=ON)
CC=${CC:-clang-14}
CXX=${CXX:-clang++-14}
JOBS=${JOBS:-2}

FLAGS="-O1 -g -fsanitize=fuzzer-no-link$SANITIZE"
cmake -S "$ROOT" -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER="$CC" -DCMAKE_CXX_COMPILER="$CXX" \
  -DCMAKE_C_FLAGS="$FLAGS" -DCMAKE_CXX_FLAGS="$FLAGS" \
  -DPAPS_BUILD_FUZZERS=ON -DPAPS_FUZZ_SANITIZERS="$LINKED" -DPAPS_BUILD_APPS=OFF "${MODULES[@]}" > "$BUILD.cmake.log"
nice cmake --build "$BUILD" --target "$(basename "$BIN")" -j "$JOBS"

WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
mkdir -p "$WORK/corpus" "$WORK/artifacts"
cp "$CORPUS_SRC"/* "$WORK/corpus/"
set +e
env "${RUN_ENV[@]}" \
  nice "$BUILD/$BIN" "$WORK/corpus" \
  -max_total_time="$SECONDS_TO_RUN" -rss_limit_mb=2048 -timeout=20 -max_len="$MAX_LEN" \
  -artifact_prefix="$WORK/artifacts/" -print_final_stats=1
STATUS=$?
set -e
found=0
for f in "$WORK"/artifacts/*; do
  [ -e "$f" ] || continue
  # libFuzzer also writes the slowest unit when it passes 10 s: worth a look, not a failure
  # (a unit over -timeout is written as timeout-*, and kept below).
  case "$(basename "$f")" in slow-unit-*) echo "slow unit (not kept): $(basename "$f")"; continue ;; esac
  found=1
  h=$(sha1sum "$f" | cut -c1-12)
  cp "$f" "$CORPUS_SRC/regression-$h"
  echo "kept $(basename "$f") as ${CORPUS_SRC#$ROOT/}/regression-$h"
done
echo "fuzzer exit status $STATUS; corpus grew to $(ls "$WORK/corpus" | wc -l) entries (not kept)"
[ $found -eq 0 ] || { echo "fuzzing found failures (see above)"; exit 1; }
exit $STATUS
