#!/usr/bin/env bash
# Browser tests: build a real output with the CLI, then have CesiumJS render it in headless
# Debian chromium (SwiftShader) through samples/viewer (tools/render_check), which asserts: no
# tile failed, every zoom was drawn while zooming in, CesiumJS used the tileset's own
# geometricErrors, and the tileset sits where the data is.
#
#   interlaken     the DHM25 tile (web mercator). Also: the surface height CesiumJS samples
#                  at the data centre is the DEM's. Reference height at the root region
#                  centre (7.87184 E, 46.70738 N = LV95 2633127.2, 1172998.5): bilinear
#                  between the DEM pixels (174..175, 119..120) = 1372.2, 1364.3, 1354.1,
#                  1348.0 m at weights from pixel position (174.59, 119.56) gives 1359.1 m
#                  LN02, plus the CHGeo2004 undulation there, 50.54 m: 1409.6 m above the
#                  WGS84 ellipsoid.
#   report         the Interlaken build's report.html (tools/render_check/report_check.mjs):
#                  no request leaves the page, no console error, the plots and both maps per
#                  zoom are there and decode; a full-page screenshot.
#   interlaken_external
#                  the same tile written with --tileset-levels 2: tileset.json holds two
#                  levels, the rest are external tilesets (tilesets/z/x/y.json) CesiumJS must
#                  descend into; the same expectations.
#   gabon_blocks   SRTM Gabon built in blocks of at most 512 px (21 tiles of zoom 10 that write
#                  zoom 11 on their own; zooms 8-10 from their joined levels): CesiumJS draws
#                  the blocks' tiles and the coarse zooms alike, and no JSON file passes 16 MiB.
#   srtm_implicit  SRTM N57E011, geographic, --implicit: CesiumJS must expand the subtrees
#                  and take every tile's measured error from the tile metadata (without it,
#                  it halves the root's error per level); the explicit root frames the data,
#                  not the hemisphere its implicit root squares.
#
# Usage: render_output.sh CASE TERRATILES SOURCE_DIR SHARED_DATA_DIR ARTIFACT_DIR
set -euo pipefail
case_name=$1 terratiles=$2 source_dir=$3 data_dir=$4 artifacts=$5
mkdir -p "$artifacts"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

case "$case_name" in
  interlaken)
    "$terratiles" build "$data_dir/ch_dhm25_interlaken_25m_2056.tif" -o "$work/out" -q \
      --geoid "$data_dir/geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif"
    expectations=(--expect-lon 7.872 --expect-lat 46.707 --expect-height 1409.6 --height-tolerance 5
                  --screenshot-close "$artifacts/interlaken_close.png")
    ;;
  report)
    "$terratiles" build "$data_dir/ch_dhm25_interlaken_25m_2056.tif" -o "$work/out" -q \
      --geoid "$data_dir/geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif"
    node "$source_dir/tools/render_check/report_check.mjs" "$work/out" \
      --screenshot "$artifacts/interlaken_report.png"
    exit 0
    ;;
  interlaken_external)
    "$terratiles" build "$data_dir/ch_dhm25_interlaken_25m_2056.tif" -o "$work/out" -q \
      --geoid "$data_dir/geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif" --tileset-levels 2
    ls "$work/out/tilesets"/*/*/*.json >/dev/null  # the tree was split
    expectations=(--expect-lon 7.872 --expect-lat 46.707 --expect-height 1409.6 --height-tolerance 5)
    ;;
  gabon_blocks)
    "$terratiles" build "$data_dir/srtm3_N00E010-E011_4326.tif" -o "$work/out" -q --tin-max-error 20 \
      --block-pixels 512
    if [ -n "$(find "$work/out" -name '*.json' -size +16M)" ]; then
      echo "render_output.sh: a JSON file of the output passes 16 MiB" >&2
      exit 1
    fi
    expectations=(--expect-lon 11.0 --expect-lat 0.5)
    ;;
  srtm_implicit)
    "$terratiles" build "$data_dir/srtm3_N57E011_4326.tif" -o "$work/out" -q \
      --scheme geographic --implicit --tin-max-error 2
    expectations=(--expect-lon 11.5 --expect-lat 57.5)
    ;;
  *)
    echo "render_output.sh: unknown case '$case_name'; expected interlaken, interlaken_external, report, gabon_blocks or srtm_implicit" >&2
    exit 2
    ;;
esac
node "$source_dir/tools/render_check/render_check.mjs" "$work/out" --quiet \
  --json "$artifacts/${case_name}_render.json" --screenshot "$artifacts/${case_name}_overview.png" \
  --tolerance-deg 0.01 --timeout 240 "${expectations[@]}" >/dev/null
echo "render check passed; screenshots in $artifacts"
