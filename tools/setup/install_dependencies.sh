#!/usr/bin/env bash
# Installs what terratiles needs on Debian 12, only what is missing: the compiler and CMake,
# the Debian packages of every library (CGAL, METIS, tinygltf, Draco, GeographicLib, GDAL,
# doctest, nlohmann-json, CLI11, TBB), PROJ's grids, Node.js, and the npm validators.
# Usage: tools/setup/install_dependencies.sh [--browser]   (--browser adds Debian's chromium)
set -euo pipefail
cd "$(dirname "$0")/../.."

packages=(g++ make cmake ccache pkg-config
  libcgal-dev libmetis-dev libtinygltf-dev libdraco-dev libgeographiclib-dev libgdal-dev
  doctest-dev nlohmann-json3-dev libcli11-dev libtbb-dev proj-data nodejs npm)
if [[ "${1:-}" == "--browser" ]]; then packages+=(chromium); fi

missing=()
for package in "${packages[@]}"; do
  # Node.js and npm may come from elsewhere than Debian (a newer install): accept them.
  if [[ "$package" == nodejs ]] && command -v node >/dev/null; then continue; fi
  if [[ "$package" == npm ]] && command -v npm >/dev/null; then continue; fi
  if ! dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$package")
  fi
done
if ((${#missing[@]})); then
  echo "terratiles setup: installing ${missing[*]}" >&2
  sudo_cmd=()
  if [[ $(id -u) -ne 0 ]]; then sudo_cmd=(sudo); fi
  "${sudo_cmd[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends \
    "${missing[@]}" >/dev/null
fi

# The Khronos glTF validator (npm gltf-validator) that the tests run on every written GLB.
if [[ ! -d tools/validators/node_modules/gltf-validator ]]; then
  echo "terratiles setup: installing the npm validators" >&2
  (cd tools/validators && npm ci --no-audit --no-fund --loglevel=error)
fi
