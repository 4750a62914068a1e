#!/usr/bin/env bash
# Runs the paper's cluster-to-tile comparison (terratiles_tiling_experiments) on the shared
# real rasters and prints the table: merge vs duplicate redundancy at 128 and 256 clusters
# per TIN and at 4, 8, 16 clusters per tile, with every level's max error (paper 3.5.4,
# figs 29, 31, 33). Usage: tools/experiments/run_tiling_experiments.sh [--scheme S]
set -euo pipefail
cd "$(dirname "$0")/../.."
data="${TERRATILES_SHARED_DATA_DIR:-../shared/data}"
[[ -x build/terratiles_tiling_experiments ]] || bash tools/setup/build.sh
exec build/terratiles_tiling_experiments \
  "$data/ch_dhm25_interlaken_25m_2056.tif:0.5" \
  "$data/ca_on_lidar_dtm_1m_26917.tif:0.1" "$data/us_mn_lidar_dtm_1m_26915.tif:0.1" \
  "$data/srtm3_N57E011_4326.tif:2" "$@"
