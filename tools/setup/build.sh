#!/usr/bin/env bash
# Configures and builds terratiles (Release, 2 jobs) into build/.
set -euo pipefail
cd "$(dirname "$0")/../.."
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"${TERRATILES_JOBS:-2}"
