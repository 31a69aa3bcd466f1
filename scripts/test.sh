#!/usr/bin/env bash
# Installs what is missing, builds everything and runs all tests (unit tests, CLI tests and
# the find_package(PAPS) consumer project), then the file readers and the decoder under ASan.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
export PAPS_SAMPLES="${PAPS_SAMPLES:-$HOME/.cache/paps/samples}"
bash scripts/fetch_samples.sh >/dev/null || echo "warning: sample scans unavailable; tests that need them skip"
(cd build && ctest --output-on-failure -j"$(nproc)")
# The code that reads untrusted bytes (cloud readers, the codec's decoder) once more under
# AddressSanitizer and UBSan: a release build can read out of bounds and still pass.
bash scripts/address_sanitizer.sh --untrusted-input "$PWD/build-asan"
