#!/usr/bin/env bash
# Fuzzes the .paps decoder with libFuzzer for a fixed time (kept for the commands quoted in
# docs/compression.md):  scripts/fuzz_compression.sh [SECONDS=120] [BUILD_DIR=/tmp/paps_fuzz_build]
# is  scripts/fuzz.sh compression [SECONDS] [BUILD_DIR].
exec "$(dirname "$0")/fuzz.sh" compression "$@"
