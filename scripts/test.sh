#!/usr/bin/env bash
# Runs every test of firefly: installs the Debian packages the tests need when they are
# missing (as root; otherwise prints the apt-get line and stops), then the tests workflow.
# Usage: ./scripts/test.sh [--sanitize | --threads]   (--sanitize: the address/UB-sanitizer
# workflow; --threads: the unit tests under ThreadSanitizer)
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(cmake g++ clang g++-aarch64-linux-gnu qemu-user pkg-config catch2 libglm-dev libbenchmark-dev libopenexr-dev libdeflate-dev libpng-dev nlohmann-json3-dev libcli11-dev
          pybind11-dev python3-dev python3-numpy python3-pytest python3-openimageio libclang-rt-14-dev)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" -eq 0 ]; then
    echo "installing: ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}"
  else
    echo "missing packages: ${missing[*]}"
    echo "install them with:"
    echo "  sudo apt-get install -y ${missing[*]}"
    exit 1
  fi
fi

preset=tests
[ "${1:-}" = "--sanitize" ] && preset=sanitize
[ "${1:-}" = "--threads" ] && preset=threads
cmake --workflow --preset "$preset"
