#include "src/pipeline/run_pipeline.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <filesystem>
#include <cmath>
#include <map>
#include <memory>
#include <numbers>
#include <limits>
#include <optional>
#include <span>
#include <tuple>

#include <nlohmann/json.hpp>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/gltf/write_glb.h"
#include "formats/output_directory.h"
#include "src/base/error.h"
#include "src/base/freed_memory.h"
#include "src/base/version.h"
#include "src/geo/crs_transform.h"
#include "src/geo/geoid.h"
#include "src/geo/place_on_globe.h"
#include "formats/vector/read_break_lines.h"
#include "src/lod/build_levels.h"
#include "src/pipeline/block_build.h"
#include "src/pipeline/build_report.h"
#include "src/pipeline/report_html.h"
#include "src/pipeline/report_maps.h"
#include "src/lod/grid_pyramid.h"
#include "src/pipeline/drawn_tiles.h"
#include "src/pipeline/terrain_output.h"
#include "src/pipeline/tile_output.h"
#include "src/base/largest_first.h"
#include "src/base/ranks.h"
#include "src/simplify/simplify_clusters.h"
#include "src/tin/measure_tin.h"
#include "src/geo/dem_on_globe.h"
#include "tileset/implicit_tileset.h"
#include "tileset/tileset.h"

namespace terratiles {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

void validateOptions(const BuildOptions& options) {
  if (options.inputs.empty()) throw Error(ErrorCode::Usage, "no input raster given");
  if (options.output_dir.empty()) throw Error(ErrorCode::Usage, "no output directory given (-o OUTDIR)");
  if (options.tile_cells < 2 || options.tile_cells > 4096) {
    throw Error(ErrorCode::Usage, "--tile-cells is " + std::to_string(options.tile_cells) +
                                      "; expected 2 to 4096");
  }
  if (options.max_zoom > 24) {
    throw Error(ErrorCode::Usage,
                "--max-zoom is " + std::to_string(options.max_zoom) + "; expected 0 to 24 (or -1: from the data)");
  }
  if (!(options.tin_max_error_m > 0) || !std::isfinite(options.tin_max_error_m)) {
    throw Error(ErrorCode::Usage, "--tin-max-error is " + std::to_string(options.tin_max_error_m) +
                                      "; expected a positive number of metres");
  }
  if (options.clusters_per_tile < 1 || options.clusters_per_tile > 1024) {
    throw Error(ErrorCode::Usage, "--clusters-per-tile is " + std::to_string(options.clusters_per_tile) +
                                      "; expected 1 to 1024");
  }
  if (!(options.level_ratio >= 0.01 && options.level_ratio <= 0.99)) {
    throw Error(ErrorCode::Usage, "--level-ratio is " + std::to_string(options.level_ratio) + "; expected 0.01 to 0.99");
  }
  if (options.draco_position_bits != 0 &&
      (options.draco_position_bits < 8 || options.draco_position_bits > kMaxExactPositionBits)) {
    throw Error(ErrorCode::Usage, "--draco-position-bits is " + std::to_string(options.draco_position_bits) +
                                      "; expected 8 to " + std::to_string(kMaxExactPositionBits) +
                                      " (Draco quantises exactly within 2^23 steps)");
  }
  if (options.draco_normal_bits < 4 || options.draco_normal_bits > 16) {
    throw Error(ErrorCode::Usage, "--draco-normal-bits is " + std::to_string(options.draco_normal_bits) +
                                      "; expected 4 to 16");
  }
  if (options.draco_speed < 0 || options.draco_speed > 10) {
    throw Error(ErrorCode::Usage, "--draco-speed is " + std::to_string(options.draco_speed) +
                                      "; expected 0 (smallest) to 10 (fastest)");
  }
  if (isTerrainLayer(options.format) &&
      (options.lod != LodMethod::Clusters || options.scheme != TileSchemeKind::Geographic || options.implicit_tiling)) {
    throw Error(ErrorCode::Usage,
                std::string("--format ") + outputFormatName(options.format) +
                    " takes the clusters' levels on the geographic scheme (its quadtree); found " +
                    (options.lod == LodMethod::Grid ? std::string("--lod grid")
                     : options.implicit_tiling      ? std::string("--implicit")
                                                    : "--scheme " + std::string(tileSchemeName(options.scheme))) +
                    "; leave it out");
  }
  if (!options.fill_dem.empty() && !isTerrainLayer(options.format)) {
    throw Error(ErrorCode::Usage, "--fill " + options.fill_dem +
                                      " fills a terrain layer outside the data; add --format quantized-mesh or terrain");
  }
  if (options.implicit_tiling && (options.lod != LodMethod::Clusters || options.scheme != TileSchemeKind::Geographic)) {
    throw Error(ErrorCode::Usage, std::string("--implicit is for the geographic scheme; found --scheme ") +
                                      (options.lod == LodMethod::Grid ? std::string("local pixels (--lod grid)")
                                                                      : std::string(tileSchemeName(options.scheme))) +
                                      "; add --scheme geographic (its quadtree subdivides a region as 3D Tiles "
                                      "implicit tiling does)");
  }
  if (options.subtree_levels < 1 || options.subtree_levels > kMaxSubtreeLevels) {
    throw Error(ErrorCode::Usage, "--subtree-levels is " + std::to_string(options.subtree_levels) + "; expected 1 to " +
                                      std::to_string(kMaxSubtreeLevels));
  }
  const double bits = std::log2(options.position_step_m);
  if (!(options.position_step_m > 0) || bits != std::round(bits) || bits > 0 || bits < -16) {
    throw Error(ErrorCode::Usage, "--position-step must be a power of two between 1/65536 and 1 m");
  }
}

// The largest side of the ECEF box of the tiles' vertices: what their quantisation must span.
// Tiles in parallel (a maximum: the same for any order).
double widestTileExtent(const std::vector<PyramidTile>& tiles, const TinMesh& mesh, const PlaceVertices& place,
                        tbb::enumerable_thread_specific<ContentScratch>& scratch) {
  std::vector<double> widest(tiles.size(), 0.0);
  tbb::parallel_for(std::size_t{0}, tiles.size(),
                    [&](std::size_t i) { widest[i] = tileExtent(tiles[i], mesh, place, scratch.local()); });
  return widest.empty() ? 0.0 : *std::max_element(widest.begin(), widest.end());
}

// What one zoom shows: a level mesh and the triangles of each of its tiles.
struct ZoomContent {
  std::int32_t zoom = 0;
  std::int32_t step = 0;      // grid: pixels between samples
  std::size_t clusters = 0;   // clusters: the level's own clusters
  const TinMesh* mesh = nullptr;
  // Clusters: per vertex, its index in the next coarser zoom's mesh, or kRemovedVertex (the
  // locked vertices a tile outline runs along live on); nullptr on the coarsest zoom and for
  // the grid pyramid.
  const std::vector<std::uint32_t>* index_in_coarser = nullptr;
  // For the report (empty without one): its maps, the cluster map drawn when the tiles are
  // assigned (the clusters its tiles are made of: the finer level's, carried over; on the
  // finest level its own; none for the grid pyramid), the error map when they are written.
  ZoomMaps maps;
  std::vector<PyramidTile> tiles;
};

}  // namespace

ConstrainedTin buildFinestTin(const DemGrid& dem, const DemOnGlobe* globe, double max_error_m,
                              const std::string& constraints_path, Progress& progress) {
  BreakLines lines;
  if (!constraints_path.empty()) {
    progress.beginStage("reading break lines", 0);
    lines = readBreakLines(constraints_path, dem);
    progress.endStage();
    if (lines.segments.empty()) {
      throw Error(ErrorCode::Input, constraints_path + ": no line or polygon of it crosses the DEM's valid data (" +
                                        std::to_string(lines.features) + " features with lines, " +
                                        std::to_string(lines.segments_read) +
                                        " segments); expected break lines over the DEM (in any CRS)");
    }
  }
  TinOptions options;
  options.max_error_m = max_error_m;
  options.globe = globe;
  ConstrainedTin tin = buildConstrainedTin(dem, options, lines.segments, progress);
  if (!constraints_path.empty()) {
    progress.note("break lines from " + constraints_path + ": " + std::to_string(lines.features) + " features, " +
                  std::to_string(lines.segments_read) + " segments read, " + std::to_string(lines.pieces_left_out) +
                  " cut or left out (outside the grid or over nodata), " + std::to_string(tin.segments_bent) +
                  " bent where they crossed another line, " + std::to_string(tin.constrained_edges.size()) +
                  " constrained TIN edges");
  }
  return tin;
}

const char* outputFormatName(OutputFormat format) {
  switch (format) {
    case OutputFormat::Tileset: return "tileset";
    case OutputFormat::QuantizedMesh: return "quantized-mesh";
    case OutputFormat::TerrainTiles3d: return "terrain";
  }
  return "tileset";
}

BuildSummary runPipeline(const BuildOptions& options, Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  validateOptions(options);
  const DemMosaic mosaic = scanDemMosaic(options.inputs, &progress);
  if (const std::int32_t block_pixels = buildBlockPixels(options, mosaic); block_pixels > 0) {
    if (isTerrainLayer(options.format)) {
      throw Error(ErrorCode::Usage, std::string("--format ") + outputFormatName(options.format) +
                                        " builds the mosaic in one piece, and this one (" +
                                        std::to_string(mosaic.width) + " x " + std::to_string(mosaic.height) +
                                        " pixels) would be built in blocks; build a smaller area, or a tileset");
    }
    return runBlockedPipeline(options, mosaic, block_pixels, progress);
  }
  if (options.resume) {
    throw Error(ErrorCode::Usage, "--resume continues a build in blocks; this build is not in blocks (the mosaic has " +
                                      std::to_string(mosaic.width) + " x " + std::to_string(mosaic.height) +
                                      " pixels; pass --block-pixels N to build in blocks)");
  }
  if (Ranks::rank() != 0) return {};  // under mpirun, a whole build is rank 0's alone
  const bool terrain = isTerrainLayer(options.format);
  OutputDirectory output(options.output_dir, options.force,
                         options.format == OutputFormat::QuantizedMesh ? "layer.json" : "tileset.json");

  DemGrid dem = readDem(mosaic, "reading DEM", progress);  // its pixels let go before the report's check
  const DemStatistics stats = computeStatistics(dem);
  const CrsToWgs84 to_wgs84(dem.crs_wkt);
  std::optional<GeoidGrid> geoid;
  if (options.heights == HeightReference::Orthometric) {
    geoid = readGeoidGrid(options.geoid_path.empty() ? kDefaultGeoidPath : options.geoid_path);
  }
  progress.endStage();
  // Every pixel's DEM point on the globe and its vertical: every error is measured on the
  // surface a renderer draws, along these.
  std::optional<DemOnGlobe> globe_storage;  // let go before the report's check, which places the DEM itself
  const DemOnGlobe& globe = globe_storage.emplace(dem, geoid ? &*geoid : nullptr, &progress);
  progress.note("placement: " + to_wgs84.pathDescription());
  for (const std::string& warning : to_wgs84.warnings()) progress.note("warning: " + warning);
  progress.note(geoid ? "heights: orthometric, geoid " + geoid->name
                      : std::string("heights: ellipsoidal (no geoid)"));

  BuildSummary summary;
  summary.output_dir = options.output_dir;
  // A terrain layer's fill, read (and refused) before the long work.
  const FillHeight terrain_fill =
      terrain ? terrainFill(geoid ? &*geoid : nullptr, options.fill_dem, summary.terrain_fill, progress) : FillHeight();
  // Everything written: into place, and the summary's time.
  const auto finish = [&] {
    progress.throwIfCancelled();
    progress.beginStage("moving the output into place", 0);
    output.commit();
    progress.endStage();
    summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return summary;
  };
  describeInput(summary, dem, stats, to_wgs84, geoid ? geoid->name : std::string());

  // Levels of detail and the triangles of every tile, coarsest zoom first.
  std::vector<ZoomContent> zooms;
  GridPyramid pyramid;               // grid: owns the meshes
  std::vector<Level> levels;         // clusters: owns the meshes
  std::unique_ptr<TileFrame> frame;  // clusters: the tile scheme over the DEM
  if (options.lod == LodMethod::Grid) {
    GridPyramidOptions pyramid_options;
    pyramid_options.tile_cells = options.tile_cells;
    pyramid_options.max_zoom = options.max_zoom;
    pyramid = buildGridPyramid(dem, pyramid_options, progress);
    if (pyramid.levels.back().tiles.empty()) {
      throw Error(ErrorCode::Input, options.inputs.front() +
                                        ": no triangle can be built; expected at least one 2 x 2 "
                                        "block of valid (not nodata) pixels");
    }
    for (PyramidLevel& level : pyramid.levels) {
      ZoomContent content;
      content.zoom = level.zoom;
      content.step = level.step;
      content.mesh = &level.mesh;
      content.tiles = std::move(level.tiles);
      if (options.report) {
        content.maps = drawClusterMap(dem, mapClusters(dem, level.mesh, nullptr), nullptr, level.zoom);
      }
      zooms.push_back(std::move(content));
    }
  } else {
    ConstrainedTin finest = buildFinestTin(dem, &globe, options.tin_max_error_m, options.constraints, progress);
    frame = std::make_unique<TileFrame>(options.scheme, dem);
    const ZoomPlan plan =
        planZooms(*frame, finest.mesh, options.tile_triangles, options.max_zoom, options.clusters_per_tile,
                  terrain ? 0 : -1);
    progress.note("zooms " + std::to_string(plan.min_zoom) + " to " + std::to_string(plan.max_zoom) + " (" +
                  std::string(tileSchemeName(options.scheme)) + "), clusters assigned by " +
                  std::string(assignmentName(options.assignment)));
    LevelOptions level_options;
    level_options.globe = &globe;
    level_options.clusters_per_level = plan.clusters_per_level;
    level_options.level_ratio = options.level_ratio;
    level_options.simplifier = options.simplifier;
    level_options.tail_stop = options.tail_stop;
    // A tileset's tiles are measured as drawn; a terrain layer's tiles show the levels
    // themselves (cut and filled), so the levels are measured.
    level_options.measure = terrain;
    if (options.level_error_growth > 0) {
      level_options.level_error_growth = options.level_error_growth;
      level_options.first_budget_m = options.tin_max_error_m * options.level_error_growth;
    }
    if (options.assignment == Assignment::Merge && options.join_tile_clusters) {
      // Level l's clusters are inherited at zoom max_zoom - l - 1: join those that merge puts
      // in the same tiles, so only borders that some tile outline follows stay locked.
      level_options.regroup_clusters = joinTileClusters(*frame, plan.max_zoom);
    }
    if (!options.global_partition) level_options.partition_regions = tileRegions(*frame, plan.max_zoom);
    if (plan.max_zoom > plan.min_zoom) {
      level_options.coarser_levels = plan.max_zoom - plan.min_zoom;
      levels = buildLevels(dem, std::move(finest.mesh), level_options, std::move(finest.constrained_edges), progress);
    } else {
      levels.emplace_back();
      levels[0].mesh = std::move(finest.mesh);
      if (terrain) {  // measured as buildLevels measures a level
        std::vector<EcefPoint> ecef(levels[0].mesh.vertices.size());
        globe.place(levels[0].mesh.vertices, {}, ecef);
        levels[0].error = measureTin(globe, levels[0].mesh, ecef);
      }
    }
    returnFreedMemory();  // what building the levels freed
    if (terrain) {
      writeTerrainLayer(levels, plan.max_zoom, globe, terrain_fill, options.format, output, summary, progress);
      summary.format = options.format;
      summary.entry_file = options.format == OutputFormat::QuantizedMesh ? "layer.json" : "tileset.json";
      progress.note(std::string("report: not written for --format ") + outputFormatName(options.format) +
                    " (the check reads tilesets of Draco GLBs)");
      return finish();
    }
    progress.beginStage("assigning clusters to tiles", levels.size());
    std::vector<TileKey> finer_cluster_tiles, own_cluster_tiles;
    for (std::size_t l = 0; l < levels.size(); ++l) {
      const auto zoom = static_cast<std::int32_t>(plan.max_zoom - static_cast<std::int32_t>(l));
      ZoomContent content;
      content.zoom = zoom;
      content.clusters = static_cast<std::size_t>(levels[l].partition.cluster_count);
      content.mesh = &levels[l].mesh;
      if (l + 1 < levels.size()) content.index_in_coarser = &levels[l].index_in_coarser;
      const FacePartition* map_clusters =
          !levels[l].inherited_partition.cluster_of_face.empty() ? &levels[l].inherited_partition
          : !levels[l].partition.cluster_of_face.empty()      ? &levels[l].partition
                                                               : nullptr;
      for (TileFaces& tile : assignClusters(*frame, levels[l], zoom, options.assignment, finer_cluster_tiles,
                                            own_cluster_tiles)) {
        PyramidTile pyramid_tile;
        pyramid_tile.key = tile.key;
        pyramid_tile.faces = std::move(tile.faces);
        content.tiles.push_back(std::move(pyramid_tile));
      }
      // The level's partitions served the assignment and, for the report, the cluster map.
      if (options.report) {
        content.maps = drawClusterMap(dem, mapClusters(dem, levels[l].mesh, map_clusters), frame.get(), zoom);
      }
      for (FacePartition* partition : {&levels[l].partition, &levels[l].inherited_partition}) {
        partition->cluster_of_face = std::vector<std::int32_t>();
      }
      finer_cluster_tiles = std::move(own_cluster_tiles);
      zooms.push_back(std::move(content));
      progress.advance();
    }
    progress.endStage();
    std::reverse(zooms.begin(), zooms.end());
  }
  const int max_zoom = zooms.back().zoom;

  GlbOptions glb;
  glb.draco = options.draco;
  glb.normal_bits = options.draco_normal_bits;
  glb.encoding_speed = options.draco_speed;
  glb.generator = std::string("terratiles ") + kVersion;
  summary.generator = glb.generator;
  std::size_t total_tiles = 0;
  for (const ZoomContent& level : zooms) total_tiles += level.tiles.size();
  returnFreedMemory();  // what the levels and the assignment freed
  progress.beginStage("writing tiles", total_tiles);
  const std::size_t zoom_count = zooms.size();
  // vertex_grid[k][v] (below): the zoom whose grid vertex v of zoom k snaps to, as a byte.
  constexpr std::uint8_t kOwnGrid = 255;  // while the chain is followed: not inherited
  TERRATILES_ASSERT(zoom_count < kOwnGrid);
  // Each zoom's outline and widest tile on its own (zooms in parallel). A tile's vertices are
  // placed on the globe when it needs them (placing a lattice vertex is a look-up).
  tbb::enumerable_thread_specific<ContentScratch> content_scratch;
  std::vector<std::vector<std::uint8_t>> outline(zoom_count);
  std::vector<double> widest_m(zoom_count);
  tbb::parallel_for(std::size_t{0}, zoom_count, [&](std::size_t k) {
    outline[k] = tileOutlineVertices(*zooms[k].mesh, zooms[k].tiles);
    widest_m[k] =
        widestTileExtent(zooms[k].tiles, *zooms[k].mesh, placedOnGlobe(globe, *zooms[k].mesh), content_scratch);
  });
  // The shared quantisation grid: --position-step, or the step at which the finest zoom's
  // widest tile takes --draco-position-bits.
  double base_step_m = options.position_step_m;
  if (options.draco_position_bits > 0) {
    base_step_m = sharedPositionStep(widest_m.back(), std::ldexp(1.0, -30), options.draco_position_bits);
  }
  summary.position_step_m = base_step_m;

  // The grids, coarsest zoom first. A zoom's own grid is the base step, unless its widest
  // tile needs more than the 2^23 steps Draco quantises exactly (tiles wider than about
  // 65 km at 1/128 m): then a power-of-two multiple. A vertex on a tile outline at this zoom
  // and at the next coarser one (a locked vertex the two zooms' outlines share) is snapped to
  // the coarser of the two grids in both, and so on down the chain of outlines: every vertex
  // two touching tiles share decodes to the same position in both, whatever grid each zoom
  // uses. Every error is measured after this snap, on what the GLBs decode to.
  std::vector<double> zoom_step_m(zoom_count);
  std::vector<std::vector<std::uint8_t>> vertex_grid(zoom_count);
  for (std::size_t k = 0; k < zoom_count; ++k) {
    const ZoomContent& zoom = zooms[k];
    std::vector<std::uint8_t>& grid = vertex_grid[k];
    grid.assign(zoom.mesh->vertices.size(), kOwnGrid);  // the inherited grids first
    double largest_inherited = 0;
    if (k > 0) {
      const ZoomContent& coarser = zooms[k - 1];
      const std::vector<std::uint8_t>& coarser_outline = outline[k - 1];
      const std::vector<std::uint32_t>* map = zoom.index_in_coarser;
      for (std::size_t v = 0; map && v < grid.size(); ++v) {
        const std::uint32_t w = (*map)[v];
        if (!outline[k][v] || w == kRemovedVertex || !coarser_outline[w]) continue;
        const GridPoint& here = zoom.mesh->vertices[v];
        const GridPoint& there = coarser.mesh->vertices[w];
        if (here.col != there.col || here.row != there.row || here.height_m != there.height_m) continue;
        grid[v] = vertex_grid[k - 1][w];
        largest_inherited = std::max(largest_inherited, zoom_step_m[grid[v]]);
      }
    }
    // A coarser snap moves a vertex by up to half that step: room for it in the extent.
    zoom_step_m[k] = sharedPositionStep(widest_m[k] + 2 * largest_inherited, base_step_m, kMaxExactPositionBits);
    for (std::uint8_t& g : grid) {
      if (g == kOwnGrid || zoom_step_m[g] < zoom_step_m[k]) g = static_cast<std::uint8_t>(k);
    }
    if (k > 0) outline[k - 1] = std::vector<std::uint8_t>();  // the chain needs only the last two
  }
  outline = {};
  for (std::size_t l = 0; l < levels.size(); ++l) levels[l].index_in_coarser = std::vector<std::uint32_t>();

  double widest_step_m = 0;
  std::vector<ZoomSummary> zoom_summaries(zoom_count);
  std::vector<ZoomMaps> maps(options.report ? zoom_count : 0);
  // Per zoom and tile: what is written and what the tileset needs. Workers write into these
  // pre-sized slots; the files are written in a fixed order.
  std::vector<std::vector<EncodedTile>> written(zoom_count);
  // Per zoom: its vertices' normals (from the whole level, placed on the globe for them and
  // let go) and the largest grid step they snap to. Its tiles place and snap their own.
  struct ZoomVertices {
    std::vector<FloatNormal> normals;
    double largest_step_m = 0;
  };
  const auto zoomVertices = [&](std::size_t k) {
    const ZoomContent& level = zooms[k];
    ZoomVertices out;
    std::vector<EcefPoint> ecef(level.mesh->vertices.size());
    globe.place(level.mesh->vertices, {}, ecef);
    out.normals = levelNormals(*level.mesh, std::move(ecef));
    for (const std::uint8_t g : vertex_grid[k]) out.largest_step_m = std::max(out.largest_step_m, zoom_step_m[g]);
    return out;
  };
  std::vector<GlbOptions> zoom_glb(zoom_count, glb);
  const PixelBoxes boxes(globe);
  // A zoom's tiles made: its mesh and tiles' faces are let go (the tile keys stay for the
  // tileset), so that the finest zooms' memory serves the coarser ones and is not held beside
  // both zoom surfaces while the next zoom is made.
  const auto releaseMesh = [&](std::size_t k) {
    for (PyramidTile& tile : zooms[k].tiles) tile.faces = std::vector<std::uint32_t>();
    zooms[k].mesh = nullptr;
    if (options.lod == LodMethod::Grid) {
      pyramid.levels[k].mesh = TinMesh();
    } else {
      Level& level = levels[zoom_count - 1 - k];
      level.mesh = TinMesh();
      level.partition = FacePartition();
      level.inherited_partition = FacePartition();
    }
  };
  // In the background: the next coarser zoom's vertices while a zoom's files are written; a
  // zoom's files (one zoom after the other, in tile order) and its RMS error and maps while
  // the next is made. Declared after everything their tasks use: their destructors wait.
  tbb::task_group preparing, writing, finishing;
  try {
    // Finest zoom first: a tile's geometricError covers its difference to the finer zoom's
    // drawn surface (where a viewer draws both), measured on that zoom's surface. Two
    // surfaces' memory, taken in turn (the second from the second zoom on, when the finest
    // zoom's vertices are gone).
    ZoomVertices vertices = zoomVertices(zoom_count - 1), coarser_vertices;
    std::array<ZoomSurface, 2> surfaces;
    for (std::size_t k = zoom_count; k-- > 0;) {
      const ZoomContent& level = zooms[k];
      zoom_glb[k].position_step_m = zoom_step_m[k];
      widest_step_m = std::max(widest_step_m, zoom_step_m[k]);
      // The grid positions measured from are those before the snap: a vertex moves by up to
      // sqrt(3)/2 of its step.
      const double shift_m = 0.87 * vertices.largest_step_m;
      // The zoom two finer was the last to use this memory (its maps are drawn by now).
      ZoomSurface& surface = surfaces[k % 2];
      if (surface.empty()) {
        surface = ZoomSurface(dem.pixelCount());
      } else {
        surface.clear();
      }
      const ZoomSurface* finer = k + 1 < zoom_count ? &surfaces[(k + 1) % 2] : nullptr;
      ZoomSummary& zoom_summary = zoom_summaries[k];
      zoom_summary.position_step_m = zoom_step_m[k];
      zoom_summary.zoom = level.zoom;
      zoom_summary.step_pixels = level.step;
      zoom_summary.clusters = level.clusters;
      zoom_summary.tiles = level.tiles.size();
      zoom_summary.vertices = level.mesh->vertices.size();
      zoom_summary.triangles = level.mesh->triangleCount();
      for (const PyramidTile& tile : level.tiles) zoom_summary.tile_triangles += tile.triangleCount();

      // Every tile on its own: its drawn content, measured, bounded and encoded; the largest
      // first.
      std::vector<EncodedTile>& tiles = written[k];
      tiles.resize(level.tiles.size());
      std::vector<std::size_t> order(tiles.size());
      for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
      std::stable_sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
        return level.tiles[i].triangleCount() > level.tiles[j].triangleCount();
      });
      const PlaceVertices snapped = placedOnGlobe(globe, *level.mesh, &vertex_grid[k], &zoom_step_m);
      forEachLargestFirst(order, [&](std::size_t i) {
        const DrawnContent content =
            drawnContent(level.tiles[i], *level.mesh, snapped, vertices.normals, globe, content_scratch.local());
        EncodedTile& out = tiles[i];
        out.measure = measureDrawnTile(globe, content.positions, content.grid, content.triangle_indices, shift_m, finer,
                                       &surface, {}, &boxes);
        out.region = drawnRegion(content.positions, content.triangle_indices);
        out.vertices = content.positions.size();
        out.glb = encodeContent(content, zoom_glb[k], &out.position_bits);
      });
      for (const EncodedTile& tile : tiles) {
        zoom_summary.max_error_m = std::max(zoom_summary.max_error_m, tile.measure.max_error_m);
        zoom_summary.position_bits = std::max(zoom_summary.position_bits, tile.position_bits);
      }
      vertices = {};
      vertex_grid[k] = std::vector<std::uint8_t>();
      releaseMesh(k);
      if (k > 0) preparing.run([&, k] { coarser_vertices = zoomVertices(k - 1); });
      writing.wait();  // the finer zoom's files
      writing.run([&, k] {
        ZoomSummary& written_summary = zoom_summaries[k];
        for (std::size_t i = 0; i < zooms[k].tiles.size(); ++i) {
          EncodedTile& tile = written[k][i];
          written_summary.bytes += output.writeFile(contentUri(zooms[k].tiles[i].key, options.implicit_tiling), tile.glb);
          tile.glb = std::vector<std::uint8_t>();  // (= {} would keep its memory)
        }
      });
      finishing.wait();  // the finer zoom's: done with its surface, which the next zoom takes
      finishing.run([&, k] {
        const ZoomSurface& drawn = surfaces[k % 2];
        ZoomSummary& finished_summary = zoom_summaries[k];
        // The zoom's RMS error over the DEM pixels it draws (each once, at its largest offset).
        double sum_squares = 0;
        std::size_t drawn_pixels = 0;
        for (std::size_t p = 0; p < dem.pixelCount(); ++p) {
          if (!drawn.drawn(p)) continue;
          sum_squares += drawn.error(p) * drawn.error(p);
          ++drawn_pixels;
        }
        finished_summary.rms_error_m = drawn_pixels ? std::sqrt(sum_squares / static_cast<double>(drawn_pixels)) : 0.0;
        if (options.report) {
          drawErrorMap(dem, finished_summary.max_error_m, drawn, zooms[k].maps);
          maps[k] = std::move(zooms[k].maps);
        }
      });
      preparing.wait();
      vertices = std::move(coarser_vertices);
      coarser_vertices = {};
      progress.advance(level.tiles.size());
    }
    writing.wait();
    finishing.wait();
  } catch (...) {
    preparing.cancel();
    writing.cancel();
    finishing.cancel();
    preparing.wait();
    writing.wait();
    finishing.wait();
    throw;
  }
  std::map<std::tuple<int, int, int>, TileNode> nodes;  // (zoom, y, x) -> node
  for (std::size_t k = zoom_count; k-- > 0;) {
    const ZoomContent& level = zooms[k];
    for (std::size_t i = 0; i < level.tiles.size(); ++i) {
      const PyramidTile& tile = level.tiles[i];
      const EncodedTile& tile_out = written[k][i];
      TileNode node;
      node.key = tile.key;
      node.content_uri = contentUri(tile.key, options.implicit_tiling);
      node.region = tile_out.region;
      // Measured on the decoded content: against the DEM and against the next finer zoom
      // where both are drawn; rounded up to the micrometre, what another implementation of
      // the same measure may differ by in its last bits.
      node.geometric_error_m =
          roundUpToMicrometre(std::max(tile_out.measure.max_error_m, tile_out.measure.finer_difference_m));
      nodes[{tile.key.zoom, tile.key.y, tile.key.x}] = std::move(node);
    }
  }
  written = {};
  progress.endStage();
  for (const ZoomSummary& zoom_summary : zoom_summaries) {
    summary.tiles += zoom_summary.tiles;
    summary.triangles += zoom_summary.triangles;
    summary.bytes += zoom_summary.bytes;
    summary.tile_bytes += zoom_summary.bytes;
    if (zoom_summary.zoom < max_zoom) summary.worst_error_m = std::max(summary.worst_error_m, zoom_summary.max_error_m);
    summary.zooms.push_back(zoom_summary);
  }

  writeTilesetOutput(std::move(nodes), options, dem.crs_name, geoid.has_value(), widest_step_m, summary, output,
                     progress);
  progress.throwIfCancelled();

  // The report: maps per zoom, the check of what was written, then report.json and .html.
  if (options.report) {
    // The levels are written and drawn: free them (and the pixels on the globe, the DEM's
    // heights and the geoid) before the check, which reads the DEM and the geoid itself and
    // decodes every tile.
    progress.beginStage("letting the levels go", 0);
    zooms = {};
    levels = {};
    pyramid = {};
    frame.reset();
    globe_storage.reset();
    dem.heights_m = std::vector<float>();
    geoid.reset();
    returnFreedMemory();  // the levels' many mid-sized arrays, which the check does not reuse
    progress.endStage();
    std::optional<CheckReport> check;
    if (options.report_check_cuts > 0) {
      CheckOptions check_options;
      check_options.cuts = static_cast<std::size_t>(options.report_check_cuts);
      check = checkOutput(output.staging().string(), check_options, progress);
      summary.check_ran = true;
      summary.check_ok = check->ok();
    }
    progress.beginStage("writing the report", 0);
    summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const nlohmann::json report = buildReportJson(options, summary, progress.stages(), check, maps);
    summary.bytes += output.writeFile("report.json", report.dump(1) + "\n");
    summary.bytes += output.writeFile("report.html", renderReportHtml(report));
    summary.report_path = (std::filesystem::path(options.output_dir) / "report.html").string();
    progress.endStage();
  }
  return finish();
}

}  // namespace terratiles
