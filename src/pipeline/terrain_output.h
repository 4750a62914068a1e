#pragma once
// writeTerrainLayer: the cluster levels as a terrain layer that CesiumJS takes as the globe's
// terrain (`terratiles build --format quantized-mesh` or `--format terrain`; issue 17).
//
// quantized-mesh-1.0 (CesiumTerrainProvider; the TMS geographic quadtree, EPSG:4326, as
// Cesium World Terrain's):
//   layer.json          tilejson 2.1.0, format quantized-mesh-1.0, scheme tms, the tile URL
//                       template, extensions ["octvertexnormals"] and `available`: per zoom,
//                       the rectangles of tiles that exist; and `terratiles.zooms`: per zoom,
//                       its level's measured error against the DEM and the error a client
//                       assumes for it (clientLevelError)
//   {z}/{x}/{y}.terrain one gzip'd quantized-mesh tile (formats/quantized_mesh)
//
// 3D Tiles terrain (Cesium3DTilesTerrainProvider): the same tiles as meshopt GLBs
// (formats/terrain_glb) in two implicit quadtrees, one per hemisphere (tileset/
// implicit_tileset's layout: tiles/H/{level}/{x}/{y}.glb, subtrees/H/...), each tile's
// heights, culling volumes and its zoom's measured error as tile metadata; tileset.json's
// extras.terratiles repeats layer.json's per-zoom figures and `available`.
//
// Zoom z shows level max_zoom - z (level 0, the finest TIN, at max_zoom); the zooms coarser
// than the coarsest level show the coarsest level. Each level's vertices are placed on the
// globe as the tileset's are (DemOnGlobe: longitude, latitude, ellipsoidal height), its
// normals from the whole level (shading continuous across tiles), then every tile the level
// meets is cut from it (clipToTile: neighbours share their sides' vertices bit for bit) and
// covered whole (fillTile: where the data is not, the geoid surface, height 0 above it, or
// the ellipsoid without a geoid; or a coarser DEM, `--fill`). Both zoom-0 tiles exist, so a client has terrain
// everywhere; deeper, the tiles the data meets (and so their parents). Tiles in parallel,
// written in a fixed order: the layer does not depend on the thread count.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "formats/output_directory.h"
#include "src/base/progress.h"
#include "src/geo/dem_on_globe.h"
#include "src/geo/geoid.h"
#include "src/lod/build_levels.h"
#include "src/pipeline/run_pipeline.h"

namespace terratiles {

// Fill grid: cells along each side of a tile, so that the straight triangles of a zoom-0 tile
// (180 degrees a side) follow the ellipsoid to within about 8 km, a zoom-5 tile's to 8 m.
inline constexpr std::int32_t kFillGridCells = 16;

// The geometric error CesiumTerrainProvider assumes for a zoom of a quantized-mesh layer
// (TerrainProvider.getEstimatedLevelZeroGeometricErrorForAHeightmap: the equatorial
// circumference x 0.25 / (65 x 2) at zoom 0, halved per zoom): about 77 km at zoom 0.
double clientLevelError(std::int32_t zoom);

// The fill's ellipsoidal height at (longitude, latitude) in degrees.
using FillHeight = std::function<double(double lon_deg, double lat_deg)>;

// The geoid surface (height 0 above `geoid`; the ellipsoid without one), or with `fill_dem`
// (a raster in WGS84 longitude and latitude, heights above `geoid` when given) its heights,
// bilinear between pixel centres and the geoid surface where it has no data. `description`
// says which, for the summary. Throws Error(Input) for a fill raster in another CRS.
FillHeight terrainFill(const GeoidGrid* geoid, const std::string& fill_dem, std::string& description,
                       Progress& progress);

// levels[0] is the finest; zoom max_zoom shows it. `format` is QuantizedMesh or
// TerrainTiles3d. Adds to summary (zooms, tiles, triangles, bytes) and writes through `output`.
void writeTerrainLayer(const std::vector<Level>& levels, std::int32_t max_zoom, const DemOnGlobe& globe,
                       const FillHeight& fill_height, OutputFormat format, OutputDirectory& output,
                       BuildSummary& summary, Progress& progress);

}  // namespace terratiles
