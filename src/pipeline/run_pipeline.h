#pragma once
// runPipeline: the only code that knows the stage order of `terratiles build`:
// read DEM -> levels of detail -> reproject (CRS -> WGS84 -> ECEF) -> GLB tiles ->
// tileset.json, all written through an OutputDirectory that is moved into place at the end.

#include <cstdint>
#include <string>
#include <vector>

#include "src/base/progress.h"
#include "src/tiling/assign_clusters.h"
#include "src/tiling/tile_scheme.h"
#include "src/tin/build_tin.h"

namespace terratiles {

class DemOnGlobe;

enum class HeightReference {
  Orthometric,  // heights above a geoid (LN02, NAP, EGM96...): add the geoid undulation
  Ellipsoidal,  // heights already above the WGS84 ellipsoid: use as they are
};

// What a build writes: a 3D Tiles tileset of Draco GLBs, or a terrain layer that CesiumJS
// takes as the globe's terrain (src/pipeline/terrain_output.h): quantized-mesh-1.0 or 3D Tiles
// terrain.
enum class OutputFormat {
  Tileset,         // tileset.json and GLB tiles (the default)
  QuantizedMesh,   // layer.json and {z}/{x}/{y}.terrain (the geographic scheme, clusters only)
  TerrainTiles3d,  // 3D Tiles terrain: tileset.json, implicit quadtrees, meshopt GLB (likewise)
};
inline bool isTerrainLayer(OutputFormat format) { return format != OutputFormat::Tileset; }
// "tileset", "quantized-mesh", "terrain": the --format names.
const char* outputFormatName(OutputFormat format);

enum class LodMethod {
  Clusters,  // the paper's method: greedy TIN, cluster levels, clusters assigned to web tiles
  Grid,      // a decimated pixel grid per zoom in the local pixel scheme (for comparison)
};

struct BuildOptions {
  std::vector<std::string> inputs;
  std::string output_dir;
  bool force = false;
  OutputFormat format = OutputFormat::Tileset;
  // A terrain layer (--format quantized-mesh or terrain): outside the data, the terrain of this raster (WGS84 longitude
  // and latitude, heights as --heights says, for example ETOPO5) instead of the geoid surface.
  std::string fill_dem;
  LodMethod lod = LodMethod::Clusters;
  TileSchemeKind scheme = TileSchemeKind::WebMercator;  // clusters only
  Assignment assignment = Assignment::Merge;            // clusters only
  double tin_max_error_m = 0.5;        // clusters: the finest TIN's bound
  std::int32_t tile_triangles = 16384; // clusters: finest tiles hold about this many
  // clusters: a level is split into this many clusters per tile of its zoom. The paper says
  // about 4 (3.5); 16 measured: redundancy 1.33 at worst instead of 1.65, total bytes 10 %
  // smaller, level sizes within 5 % (Interlaken, Ontario, SRTM N57E011).
  std::int32_t clusters_per_tile = 16;
  // clusters, merge: simplify the clusters that cross the same tiles as one, so only borders
  // a tile outline follows stay locked (paper fig 34).
  bool join_tile_clusters = true;
  // clusters: METIS per tile neighbourhood, in parallel (tileNeighbourhoodRegions); true: one
  // METIS call per connected component over the whole level (slow; for comparison).
  bool global_partition = false;
  double level_ratio = 0.5;            // clusters: edges kept per simplification
  Simplifier simplifier = Simplifier::Native;  // clusters: the edge-collapse engine
  // clusters, native engine: SimplifyOptions::tail_stop. On ETOPO5 at 10 m it takes a quarter
  // off the simplification for up to 5 % more triangles per zoom (still 4-9 % fewer than CGAL's).
  TailStop tail_stop = kDefaultTailStop;
  double level_error_growth = 2;       // clusters: budget tin_max_error * G^level (0: none)
  std::string constraints;             // clusters: break lines (OGR file), or empty
  std::int32_t tile_cells = 128;       // grid: cells per tile side
  std::int32_t max_zoom = -1;          // -1: chosen from the data
  HeightReference heights = HeightReference::Orthometric;
  std::string geoid_path;              // empty: EGM96 from Debian's proj-data
  bool draco = true;
  // Geographic scheme: 3D Tiles implicit tiling (quadtrees, subtree files, every tile's
  // measured error and region as tile metadata) instead of an explicit tree.
  bool implicit_tiling = false;
  std::int32_t subtree_levels = 6;
  // Explicit tilesets: tree levels per JSON file, deeper tiles in external tilesets (tilesetFiles);
  // 0: one file up to kSingleFileTiles tiles, else 6 levels per file.
  std::int32_t tileset_levels = 0;
  // The build report (report.json, report.html): `terratiles check` with this many random
  // cuts runs on the output before it is moved into place (0: no check in the report).
  bool report = true;
  std::int32_t report_check_cuts = 200;
  // The Draco quantisation grid every tile shares (a power of two in metres): 1/128 m, or
  // (draco_position_bits > 0) the step at which the finest zoom's widest tile takes that
  // many bits. A zoom whose tiles are too wide for 2^23 steps uses a power-of-two multiple.
  double position_step_m = 1.0 / 128;
  std::int32_t draco_position_bits = 0;
  std::int32_t draco_normal_bits = 10;
  std::int32_t draco_speed = 3;
  // clusters: build in blocks of at most this many pixels a side (block_build.h), each a tile of
  // one zoom; 0: blocks of kBuildBlockPixels when the mosaic has more than
  // kBuildBlocksAbovePixels pixels, else the whole mosaic at once.
  std::int32_t block_pixels = 0;
  // Blocks: the zooms from the blocks' zoom up are measured against the DEM in strips of rows
  // of about this many pixels (28 bytes each), plus the rows their tallest triangle reaches.
  std::int64_t strip_pixels = 16'000'000;
  // Blocks: the levels from the blocks' zoom up are simplified against an overview of the DEM
  // of at most this many pixels (the mean of every f x f pixels, f a power of two; f = 1 when
  // the mosaic is no larger), so the coarse zooms never hold the whole DEM; their tiles are
  // still measured against every pixel, strip by strip.
  std::int64_t overview_pixels = 4'000'000;
  // Blocks: continue an interrupted build from the block files it left in OUTDIR.blocks/.
  bool resume = false;  // measured: 15-17 % smaller than 5 and within 3 % of 0, decoding 1.4x faster than 0
};

struct ZoomSummary {
  std::int32_t zoom = 0;
  std::int32_t step_pixels = 0;  // grid: pixels between samples; clusters: 0
  std::size_t clusters = 0;      // clusters: the level's own clusters
  std::size_t tiles = 0;
  std::size_t vertices = 0;
  std::size_t triangles = 0;       // of the level mesh
  std::size_t tile_triangles = 0;  // summed over the zoom's tiles: / triangles = redundancy
  std::size_t bytes = 0;
  double max_error_m = 0;   // measured against the DEM
  double rms_error_m = 0;
  double geometric_error_m = 0;  // the largest geometricError written at this zoom
  double position_step_m = 0;    // the Draco grid all its tiles share (0: plain GLB)
  int position_bits = 0;         // the most quantisation bits one of its tiles needed
};

struct BuildSummary {
  std::string output_dir;
  std::string generator;    // "terratiles <version>"
  std::string report_path;  // OUTDIR/report.html, or empty
  std::string entry_file = "tileset.json";  // what a client opens: tileset.json or layer.json
  OutputFormat format = OutputFormat::Tileset;
  std::string terrain_fill;  // a terrain layer: what covers the globe outside the data
  bool check_ran = false;
  bool check_ok = false;
  std::string crs_name;
  std::int32_t width = 0;
  std::int32_t height = 0;
  double pixel_size = 0;
  std::size_t valid_pixels = 0;
  double min_height_m = 0;
  double max_height_m = 0;
  double centre_lon_deg = 0;
  double centre_lat_deg = 0;
  std::string placement;  // the CRS -> WGS84 path, e.g. "EPSG:2056 -> WGS84 by the rigorous ..."
  std::vector<std::string> warnings;  // things the user should know (e.g. a missing grid)
  std::string geoid;  // which geoid turned heights ellipsoidal, or "none (ellipsoidal input)"
  std::string blocks;  // a build in blocks: how many, of which zoom, how many resumed; else empty
  std::vector<ZoomSummary> zooms;
  std::size_t tiles = 0;
  std::size_t triangles = 0;
  std::size_t bytes = 0;       // every file written
  std::size_t tile_bytes = 0;  // the GLB tiles only
  double worst_error_m = 0;  // over the non-leaf zooms (the leaves hold the DEM itself)
  double position_step_m = 0;  // the base quantisation grid (the finest zooms')
  double seconds = 0;
};

BuildSummary runPipeline(const BuildOptions& options, Progress& progress);

// The finest TIN (greedy insertion to max_error_m, measured on the globe when `globe` is not
// null) with the break lines of constraints_path (an OGR vector file; empty: none) as
// constrained edges; notes what was read on `progress`.
ConstrainedTin buildFinestTin(const DemGrid& dem, const DemOnGlobe* globe, double max_error_m,
                              const std::string& constraints_path, Progress& progress);

}  // namespace terratiles
