#!/usr/bin/env bash
# Installs what is missing, builds everything and runs all tests (unit tests, CLI tests and
# the find_package(PAPS) consumer project), then the file readers and the decoder under ASan.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each phase prints its wall time: the whole run must stay well under 30 minutes on 2 cores.
phase() {
  local name=$1 start=$SECONDS
  shift
  "$@"
  echo "test.sh: $name took $((SECONDS - start)) s (total $SECONDS s)"
}
phase "install" bash scripts/install_deps.sh
# The examples are compiled and run by the consumer test, against the installed package:
# compiling them in the tree too cost about 100 s of CPU.
phase "build" bash scripts/build.sh -DPAPS_BUILD_EXAMPLES=OFF
export PAPS_SAMPLES="${PAPS_SAMPLES:-$HOME/.cache/paps/samples}"
phase "samples" bash -c 'bash scripts/fetch_samples.sh >/dev/null || echo "warning: sample scans unavailable; tests that need them skip"'
# Both ctest slots run OpenMP code on 2 threads each: with libgomp's default spin-waiting,
# the idle threads of one test burn the core the other test needs (17 of the slowest tests:
# 123-176 s with spinning, 86-87 s with passive waiting).
export OMP_WAIT_POLICY=passive
phase "tests" bash -c 'cd build && ctest --output-on-failure -j"$(nproc)"'
# The code that reads untrusted bytes (cloud readers, the codec's decoder) once more under
# AddressSanitizer and UBSan: a release build can read out of bounds and still pass.
phase "sanitizer tests" bash scripts/address_sanitizer.sh --untrusted-input "$PWD/build-asan"
