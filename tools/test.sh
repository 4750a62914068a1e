#!/usr/bin/env bash
# Builds terratiles and runs the whole test suite (doctest through ctest), after installing
# whatever is missing. The tests read the real rasters in ../shared/data.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/setup/install_dependencies.sh
tools/setup/build.sh
cd build
ctest --output-on-failure -j"${TERRATILES_JOBS:-2}"
