#!/usr/bin/env bash
# Browser test: builds the Interlaken DHM25 tileset with the CLI, then has CesiumJS render it
# in headless Debian chromium (SwiftShader) through samples/viewer, and asserts: no tile
# failed, every depth was drawn while zooming in, the tileset sits at 46.707 N 7.872 E, and
# the surface height CesiumJS samples at the data centre is the DEM's.
#
# Reference height at the root region centre (7.87184 E, 46.70738 N = LV95 2633127.2,
# 1172998.5): bilinear between the DEM pixels (174..175, 119..120) = 1372.2, 1364.3, 1354.1,
# 1348.0 m at weights from pixel position (174.59, 119.56) gives 1359.1 m LN02, plus the
# CHGeo2004 undulation there, 50.54 m: 1409.6 m above the WGS84 ellipsoid.
#
# Usage: render_interlaken.sh TERRATILES SOURCE_DIR SHARED_DATA_DIR ARTIFACT_DIR
set -euo pipefail
terratiles=$1 source_dir=$2 data_dir=$3 artifacts=$4
mkdir -p "$artifacts"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

"$terratiles" build "$data_dir/ch_dhm25_interlaken_25m_2056.tif" -o "$work/interlaken" -q \
  --geoid "$data_dir/geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif"
node "$source_dir/tools/render_check/render_check.mjs" "$work/interlaken" --quiet \
  --json "$artifacts/interlaken_render.json" \
  --screenshot "$artifacts/interlaken_overview.png" \
  --screenshot-close "$artifacts/interlaken_close.png" \
  --expect-lon 7.872 --expect-lat 46.707 --tolerance-deg 0.01 \
  --expect-height 1409.6 --height-tolerance 5 --timeout 240 >/dev/null
echo "render check passed; screenshots in $artifacts"
