#!/usr/bin/env bash
# Installs what PAPS needs to build and test on Debian 12 (run as root, or with sudo).
set -euo pipefail
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
PKGS=(cmake g++ make ninja-build pkg-config libpcl-dev libeigen3-dev libflann-dev libboost-dev
      libgtest-dev libzstd-dev liblzma-dev libcgal-dev draco libdraco-dev clang
      libclang-rt-14-dev coinor-libclp-dev libopencv-dev libnlopt-dev)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
