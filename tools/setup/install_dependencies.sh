#!/usr/bin/env bash
# Installs what terratiles needs on Debian 12, only what is missing: the compiler and CMake,
# the Debian packages of every library (CGAL, METIS, tinygltf, Draco, GeographicLib, GDAL,
# doctest, nlohmann-json, CLI11, TBB, Open MPI, zlib), PROJ's grids, Node.js, and the npm validators.
# Usage: tools/setup/install_dependencies.sh [--viewer | --browser]
#   --viewer  adds the npm packages of samples/viewer (cesium), to view a tileset;
#   --browser adds what the browser test needs: the viewer, Debian's chromium, and the npm
#             packages of tools/render_check (playwright-core, which drives chromium).
set -euo pipefail
cd "$(dirname "$0")/../.."

packages=(g++ make cmake ccache pkg-config
  libcgal-dev libmetis-dev libtinygltf-dev libdraco-dev libgeographiclib-dev libgdal-dev
  doctest-dev nlohmann-json3-dev libcli11-dev libtbb-dev libproj-dev proj-data nodejs npm
  libmeshoptimizer-dev openmpi-bin libopenmpi-dev zlib1g-dev)
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

# npm packages, each folder with its own package-lock.json: the Khronos glTF validator
# (npm gltf-validator) that the tests run on every written GLB, and for the browser test the
# CesiumJS viewer and the render check.
npm_folders=(tools/validators)
if [[ "${1:-}" == "--viewer" ]]; then npm_folders+=(samples/viewer); fi
if [[ "${1:-}" == "--browser" ]]; then npm_folders+=(samples/viewer tools/render_check); fi
for folder in "${npm_folders[@]}"; do
  if [[ ! -d "$folder/node_modules" || "$folder/package-lock.json" -nt "$folder/node_modules" ]]; then
    echo "terratiles setup: installing the npm packages of $folder" >&2
    (cd "$folder" && npm ci --no-audit --no-fund --loglevel=error)
  fi
done
