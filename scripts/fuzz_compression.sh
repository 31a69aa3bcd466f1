#!/usr/bin/env bash
# Fuzzes the .paps decoder with libFuzzer for a fixed time.
#   scripts/fuzz_compression.sh [SECONDS=120] [BUILD_DIR=/tmp/paps_fuzz_build]
# Builds paps::core and paps::compression with clang and ASan/UBSan, seeds the corpus from
# test/compression/corpus, runs the fuzzer, and copies any crash/timeout/oom input into
# test/compression/corpus/ (as regression-<hash>) so that test_compression_corpus replays it
# in CI. New corpus entries are not copied back (keep the committed corpus tiny).
set -euo pipefail
SECONDS_TO_RUN=${1:-120}
BUILD=${2:-/tmp/paps_fuzz_build}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
CORPUS_SRC="$ROOT/test/compression/corpus"
CC=${CC:-clang-14}
CXX=${CXX:-clang++-14}
JOBS=${JOBS:-2}

FLAGS="-O1 -g -fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined"
cmake -S "$ROOT" -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER="$CC" -DCMAKE_CXX_COMPILER="$CXX" \
  -DCMAKE_C_FLAGS="$FLAGS" -DCMAKE_CXX_FLAGS="$FLAGS" \
  -DPAPS_BUILD_FUZZERS=ON -DPAPS_BUILD_APPS=OFF -DPAPS_MODULE_FILTERS=OFF > "$BUILD.cmake.log"
nice cmake --build "$BUILD" --target fuzz_compression_decoder -j "$JOBS"

WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
mkdir -p "$WORK/corpus" "$WORK/artifacts"
cp "$CORPUS_SRC"/* "$WORK/corpus/"
set +e
ASAN_OPTIONS=detect_leaks=0:allocator_may_return_null=1 \
  nice "$BUILD/test/compression/fuzz_compression_decoder" "$WORK/corpus" \
  -max_total_time="$SECONDS_TO_RUN" -rss_limit_mb=2048 -timeout=20 -max_len=65536 \
  -artifact_prefix="$WORK/artifacts/" -print_final_stats=1
STATUS=$?
set -e
found=0
for f in "$WORK"/artifacts/*; do
  [ -e "$f" ] || continue
  found=1
  h=$(sha1sum "$f" | cut -c1-12)
  cp "$f" "$CORPUS_SRC/regression-$h"
  echo "kept $(basename "$f") as test/compression/corpus/regression-$h"
done
echo "fuzzer exit status $STATUS; corpus grew to $(ls "$WORK/corpus" | wc -l) entries (not kept)"
[ $found -eq 0 ] || { echo "fuzzing found failures (see above)"; exit 1; }
exit $STATUS
