#!/usr/bin/env bash
# Runs the paper's LoD experiments (terratiles_lod_experiments) on the shared real rasters and
# prints the tables: METIS vs random partition, re-partition vs fixed borders over five
# rounds, constrained edges vs error. The TINs are the paper's 0.5 m (SRTM: 2 m, its 90 m
# pixels), and the lidar rasters also at 0.1 m, where their TINs are large enough for five
# rounds of halving. Usage: tools/experiments/run_lod_experiments.sh [--runs 5]
set -euo pipefail
cd "$(dirname "$0")/../.."
data="${TERRATILES_SHARED_DATA_DIR:-../shared/data}"
[[ -x build/terratiles_lod_experiments ]] || bash tools/setup/build.sh
exec build/terratiles_lod_experiments \
  "$data/ch_dhm25_interlaken_25m_2056.tif:0.5" \
  "$data/us_mn_lidar_dtm_1m_26915.tif:0.5" "$data/us_mn_lidar_dtm_1m_26915.tif:0.1" \
  "$data/ca_on_lidar_dtm_1m_26917.tif:0.5" "$data/ca_on_lidar_dtm_1m_26917.tif:0.1" \
  "$data/srtm3_N57E011_4326.tif:2" "$@"
