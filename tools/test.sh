#!/usr/bin/env bash
# Builds terratiles and runs the whole test suite (doctest through ctest), after installing
# whatever is missing (with Debian's chromium and the npm packages of the browser test). The
# tests read the real rasters in ../shared/data; screenshots land in build/test-artifacts.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/setup/install_dependencies.sh --browser
tools/setup/build.sh
cd build
ctest --output-on-failure -j"${TERRATILES_JOBS:-2}"
