#include "src/pipeline/run_pipeline.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <cmath>
#include <map>
#include <memory>
#include <numbers>
#include <optional>

#include <nlohmann/json.hpp>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/gltf/write_glb.h"
#include "formats/output_directory.h"
#include "src/base/error.h"
#include "src/base/version.h"
#include "src/geo/crs_transform.h"
#include "src/geo/geoid.h"
#include "src/geo/place_on_globe.h"
#include "formats/vector/read_break_lines.h"
#include "src/lod/build_levels.h"
#include "src/pipeline/build_report.h"
#include "src/pipeline/report_html.h"
#include "src/pipeline/report_maps.h"
#include "src/lod/grid_pyramid.h"
#include "src/tin/measure_tin.h"
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

// A level's vertices on the globe: geodetic for bounding regions, ECEF for the meshes,
// unit normals in ECEF from the whole level mesh so shading is continuous across tiles.
struct PlacedLevel {
  std::vector<GeodeticPoint> geodetic;
  std::vector<EcefPoint> ecef;
  std::vector<EcefPoint> normals;
};

PlacedLevel placeLevel(const DemGrid& dem, const TinMesh& mesh, const CrsToWgs84& to_wgs84,
                       const GeoidGrid* geoid) {
  PlacedLevel placed;
  const std::size_t n = mesh.vertices.size();
  placed.geodetic.resize(n);
  placed.ecef.resize(n);
  placeOnGlobe(dem, mesh.vertices, to_wgs84, geoid, placed.geodetic, placed.ecef);

  placed.normals.assign(n, EcefPoint{});
  const auto& idx = mesh.triangle_indices;
  for (std::size_t t = 0; t < idx.size(); t += 3) {
    const EcefPoint& a = placed.ecef[idx[t]];
    const EcefPoint& b = placed.ecef[idx[t + 1]];
    const EcefPoint& c = placed.ecef[idx[t + 2]];
    const double ux = b.x - a.x, uy = b.y - a.y, uz = b.z - a.z;
    const double vx = c.x - a.x, vy = c.y - a.y, vz = c.z - a.z;
    const EcefPoint face{uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx};  // area-weighted
    for (std::size_t k = 0; k < 3; ++k) {
      EcefPoint& nrm = placed.normals[idx[t + k]];
      nrm.x += face.x;
      nrm.y += face.y;
      nrm.z += face.z;
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    EcefPoint& nrm = placed.normals[i];
    double length = std::sqrt(nrm.x * nrm.x + nrm.y * nrm.y + nrm.z * nrm.z);
    if (length == 0) {  // an unused vertex: the ellipsoid normal
      const double lat = placed.geodetic[i].lat_deg * kDegToRad;
      const double lon = placed.geodetic[i].lon_deg * kDegToRad;
      nrm = {std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
      length = 1;
    }
    nrm.x /= length;
    nrm.y /= length;
    nrm.z /= length;
  }
  return placed;
}

struct EncodedTile {
  std::vector<std::uint8_t> glb;
  Region region;
  std::size_t vertices = 0;
  int position_bits = 0;  // Draco position bits at the zoom's step
};

// The largest side of a tile's ECEF box: what its quantisation must span.
double tileExtent(const PyramidTile& tile, const PlacedLevel& placed) {
  EcefPoint lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (std::uint32_t v : tile.triangle_indices) {
    const EcefPoint& p = placed.ecef[v];
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  return std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z, 0.0});
}

double widestTileExtent(const std::vector<PyramidTile>& tiles, const PlacedLevel& placed) {
  double widest = 0;
  for (const PyramidTile& tile : tiles) widest = std::max(widest, tileExtent(tile, placed));
  return widest;
}

// One tile's content: its vertices relative to an origin on the quantisation grid, in the
// glTF y-up frame (glTF (x, y, z) = ECEF (X, Z, -Y); 3D Tiles rotates y-up back to z-up).
// Every position is snapped to the grid before it is made relative, so the float offsets are
// exact and Draco gives them back bit for bit: a vertex two tiles of a zoom share decodes to
// one position in both.
EncodedTile encodeTile(const PyramidTile& tile, const PlacedLevel& placed, const GlbOptions& glb) {
  EncodedTile out;
  std::map<std::uint32_t, std::uint32_t> local_of;  // level vertex -> tile vertex
  std::vector<std::uint32_t> level_vertex;
  GlbMesh mesh;
  mesh.triangle_indices.reserve(tile.triangle_indices.size());
  for (std::uint32_t v : tile.triangle_indices) {
    auto [it, inserted] = local_of.try_emplace(v, static_cast<std::uint32_t>(level_vertex.size()));
    if (inserted) level_vertex.push_back(v);
    mesh.triangle_indices.push_back(it->second);
  }
  EcefPoint lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (std::uint32_t v : level_vertex) {
    const EcefPoint& p = placed.ecef[v];
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    const GeodeticPoint& g = placed.geodetic[v];
    out.region.include(g.lon_deg * kDegToRad, g.lat_deg * kDegToRad, g.height_m);
  }
  // Plain GLBs too: their float offsets are then exact as well.
  const double step = glb.position_step_m;
  auto snap = [step](double value) { return snapToStep(value, step); };
  const EcefPoint origin{snap((lo.x + hi.x) / 2), snap((lo.y + hi.y) / 2), snap((lo.z + hi.z) / 2)};
  mesh.translation = {origin.x, origin.z, -origin.y};
  mesh.positions.reserve(level_vertex.size() * 3);
  mesh.normals.reserve(level_vertex.size() * 3);
  for (std::uint32_t v : level_vertex) {
    const EcefPoint& p = placed.ecef[v];
    const EcefPoint& n = placed.normals[v];
    mesh.positions.insert(mesh.positions.end(), {static_cast<float>(snap(p.x) - origin.x),
                                                 static_cast<float>(snap(p.z) - origin.z),
                                                 static_cast<float>(-(snap(p.y) - origin.y))});
    mesh.normals.insert(mesh.normals.end(),
                        {static_cast<float>(n.x), static_cast<float>(n.z), static_cast<float>(-n.y)});
  }
  out.vertices = level_vertex.size();
  EncodedGlb encoded = encodeGlb(mesh, glb);
  out.glb = std::move(encoded.bytes);
  out.position_bits = encoded.position_bits;
  // The region must hold the decoded content: grow it by the quantisation step (decoded
  // positions are within half a step per axis, sqrt(3)/2 step in all).
  const double grow_m = encoded.position_step_m;
  if (grow_m > 0) {
    constexpr double kMinimumRadius_m = 6.3e6;  // below any WGS84 radius of curvature
    const double grow_lat = grow_m / kMinimumRadius_m;
    const double widest = std::max(std::fabs(out.region.south_rad), std::fabs(out.region.north_rad));
    const double grow_lon = grow_lat / std::max(std::cos(std::min(widest, 1.5707)), 1e-6);
    Region& r = out.region;
    r.west_rad = std::max(r.west_rad - grow_lon, -std::numbers::pi);
    r.east_rad = std::min(r.east_rad + grow_lon, std::numbers::pi);
    r.south_rad = std::max(r.south_rad - grow_lat, -std::numbers::pi / 2);
    r.north_rad = std::min(r.north_rad + grow_lat, std::numbers::pi / 2);
    r.min_height_m -= grow_m;
    r.max_height_m += grow_m;
  }
  return out;
}

// Attaches every node under its parent in `nodes`, finest zoom first, creating content-less
// ancestors where needed, until one node (the common ancestor) is left: the root.
TileNode buildTree(std::map<std::tuple<int, int, int>, TileNode>& nodes) {
  while (nodes.size() > 1) {
    int zoom = 0;
    for (const auto& [key, node] : nodes) zoom = std::max(zoom, std::get<0>(key));
    if (zoom == 0) {
      // The geographic scheme's two zoom-0 tiles (data on both sides of the prime meridian):
      // a content-less root above them (zoom -1 marks it; it has no file).
      TileNode root;
      root.key = {-1, 0, 0};
      for (auto& [key, node] : nodes) root.children.push_back(std::move(node));
      nodes.clear();
      return root;
    }
    std::vector<std::tuple<int, int, int>> at_zoom;
    for (const auto& [key, node] : nodes) {
      if (std::get<0>(key) == zoom) at_zoom.push_back(key);
    }
    for (const auto& key : at_zoom) {
      TileNode child = std::move(nodes.at(key));
      nodes.erase(key);
      const TileKey parent_key = child.key.parent();
      TileNode& parent = nodes[{parent_key.zoom, parent_key.y, parent_key.x}];
      parent.key = parent_key;
      parent.children.push_back(std::move(child));
    }
  }
  TileNode root = std::move(nodes.begin()->second);
  return root;
}

// What one zoom shows: a level mesh and the triangles of each of its tiles.
struct ZoomContent {
  std::int32_t zoom = 0;
  std::int32_t step = 0;      // grid: pixels between samples
  std::size_t clusters = 0;   // clusters: the level's own clusters
  const TinMesh* mesh = nullptr;
  // For the report's map: the clusters its tiles are made of (the finer level's, carried
  // over; on the finest level its own); nullptr for the grid pyramid.
  const FacePartition* map_clusters = nullptr;
  std::vector<PyramidTile> tiles;
  double max_error_m = 0;
  double rms_error_m = 0;
};

// Per tile: max and RMS |content - DEM| over the valid pixels its triangles cover (a pixel on
// an edge between two of its triangles counts twice in the RMS).
// finer_surface: the next finer zoom's height at every pixel (NaN where it has none), or
// empty.
void measureTiles(const DemGrid& dem, const TinMesh& mesh, std::vector<PyramidTile>& tiles,
                  const std::vector<float>& finer_surface) {
  tbb::parallel_for(std::size_t{0}, tiles.size(), [&](std::size_t i) {
    PyramidTile& tile = tiles[i];
    double max_error = 0, sum_squares = 0, finer_difference = 0;
    std::size_t count = 0;
    const auto& idx = tile.triangle_indices;
    for (std::size_t t = 0; t + 2 < idx.size(); t += 3) {
      forEachCoveredPixel(dem, mesh.vertices[idx[t]], mesh.vertices[idx[t + 1]], mesh.vertices[idx[t + 2]],
                          [&](std::size_t pixel, double surface_m) {
                            const float h = dem.heights_m[pixel];
                            if (std::isnan(h)) return true;
                            if (!finer_surface.empty() && !std::isnan(finer_surface[pixel])) {
                              finer_difference = std::max(finer_difference, std::fabs(surface_m - finer_surface[pixel]));
                            }
                            const double error = std::fabs(surface_m - h);
                            max_error = std::max(max_error, error);
                            sum_squares += error * error;
                            ++count;
                            return true;
                          });
    }
    tile.max_error_m = max_error;
    tile.rms_error_m = count ? std::sqrt(sum_squares / static_cast<double>(count)) : 0;
    tile.measured_pixels = count;
    tile.finer_difference_m = finer_difference;
  });
}

// A level's height at every pixel centre it covers (NaN elsewhere).
std::vector<float> levelSurface(const DemGrid& dem, const TinMesh& mesh) {
  std::vector<float> surface(dem.pixelCount(), std::nanf(""));
  const auto& idx = mesh.triangle_indices;
  for (std::size_t t = 0; t + 2 < idx.size(); t += 3) {
    forEachCoveredPixel(dem, mesh.vertices[idx[t]], mesh.vertices[idx[t + 1]], mesh.vertices[idx[t + 2]],
                        [&](std::size_t pixel, double surface_m) {
                          surface[pixel] = static_cast<float>(surface_m);
                          return true;
                        });
  }
  return surface;
}

}  // namespace

ConstrainedTin buildFinestTin(const DemGrid& dem, double max_error_m, const std::string& constraints_path,
                              Progress& progress) {
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

BuildSummary runPipeline(const BuildOptions& options, Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  validateOptions(options);
  OutputDirectory output(options.output_dir, options.force);

  progress.beginStage("reading DEM", 0);
  const DemGrid dem = readDem(options.inputs);
  const DemStatistics stats = computeStatistics(dem);
  const CrsToWgs84 to_wgs84(dem.crs_wkt);
  std::optional<GeoidGrid> geoid;
  if (options.heights == HeightReference::Orthometric) {
    geoid = readGeoidGrid(options.geoid_path.empty() ? kDefaultGeoidPath : options.geoid_path);
  }
  progress.endStage();
  progress.note("placement: " + to_wgs84.pathDescription());
  for (const std::string& warning : to_wgs84.warnings()) progress.note("warning: " + warning);
  progress.note(geoid ? "heights: orthometric, geoid " + geoid->name
                      : std::string("heights: ellipsoidal (no geoid)"));

  BuildSummary summary;
  summary.output_dir = options.output_dir;
  summary.crs_name = dem.crs_name;
  summary.geoid = geoid ? geoid->name : "none (heights are ellipsoidal)";
  summary.placement = to_wgs84.pathDescription();
  summary.warnings = to_wgs84.warnings();
  summary.width = dem.width;
  summary.height = dem.height;
  summary.pixel_size = dem.pixel_size_x;
  summary.valid_pixels = stats.valid_pixels;
  summary.min_height_m = stats.min_height_m;
  summary.max_height_m = stats.max_height_m;
  {
    GeodeticPoint centre;
    centre.height_m = (stats.min_height_m + stats.max_height_m) / 2;
    const CrsPoint c = dem.pixelCentre((dem.width - 1) / 2.0, (dem.height - 1) / 2.0);
    to_wgs84.transform(std::span<const CrsPoint>(&c, 1), std::span<GeodeticPoint>(&centre, 1));
    summary.centre_lon_deg = centre.lon_deg;
    summary.centre_lat_deg = centre.lat_deg;
  }

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
      zooms.push_back({level.zoom, level.step, 0, &level.mesh, nullptr, std::move(level.tiles), level.max_error_m,
                       level.rms_error_m});
    }
  } else {
    ConstrainedTin finest = buildFinestTin(dem, options.tin_max_error_m, options.constraints, progress);
    frame = std::make_unique<TileFrame>(options.scheme, dem);
    const ZoomPlan plan =
        planZooms(*frame, finest.mesh, options.tile_triangles, options.max_zoom, options.clusters_per_tile);
    progress.note("zooms " + std::to_string(plan.min_zoom) + " to " + std::to_string(plan.max_zoom) + " (" +
                  std::string(tileSchemeName(options.scheme)) + "), clusters assigned by " +
                  std::string(assignmentName(options.assignment)));
    LevelOptions level_options;
    level_options.clusters_per_level = plan.clusters_per_level;
    level_options.level_ratio = options.level_ratio;
    if (options.level_error_growth > 0) {
      level_options.level_error_growth = options.level_error_growth;
      level_options.first_budget_m = options.tin_max_error_m * options.level_error_growth;
    }
    if (options.assignment == Assignment::Merge && options.join_tile_clusters) {
      // Level l's clusters are inherited at zoom max_zoom - l - 1: join those that merge puts
      // in the same tiles, so only borders that some tile outline follows stay locked.
      level_options.regroup_clusters = joinTileClusters(*frame, plan.max_zoom);
    }
    if (plan.max_zoom > plan.min_zoom) {
      level_options.coarser_levels = plan.max_zoom - plan.min_zoom;
      levels = buildLevels(dem, std::move(finest.mesh), level_options, std::move(finest.constrained_edges), progress);
    } else {
      levels.emplace_back();
      levels[0].mesh = std::move(finest.mesh);
      levels[0].error = measureTin(dem, levels[0].mesh);
    }
    progress.beginStage("assigning clusters to tiles", levels.size());
    std::vector<TileKey> finer_cluster_tiles, own_cluster_tiles;
    std::vector<float> finer_surface;
    for (std::size_t l = 0; l < levels.size(); ++l) {
      const auto zoom = static_cast<std::int32_t>(plan.max_zoom - static_cast<std::int32_t>(l));
      ZoomContent content;
      content.zoom = zoom;
      content.clusters = static_cast<std::size_t>(levels[l].partition.cluster_count);
      content.mesh = &levels[l].mesh;
      content.map_clusters = !levels[l].inherited_partition.cluster_of_face.empty() ? &levels[l].inherited_partition
                             : !levels[l].partition.cluster_of_face.empty()      ? &levels[l].partition
                                                                                  : nullptr;
      content.max_error_m = levels[l].error.max_error_m;
      content.rms_error_m = levels[l].error.rms_error_m;
      for (TileFaces& tile : assignClusters(*frame, levels[l], zoom, options.assignment, finer_cluster_tiles,
                                            own_cluster_tiles)) {
        PyramidTile pyramid_tile;
        pyramid_tile.key = tile.key;
        pyramid_tile.triangle_indices = std::move(tile.triangle_indices);
        content.tiles.push_back(std::move(pyramid_tile));
      }
      measureTiles(dem, levels[l].mesh, content.tiles, finer_surface);
      if (l + 1 < levels.size()) finer_surface = levelSurface(dem, levels[l].mesh);
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
  // The shared quantisation grid: --position-step, or the step at which the finest zoom's
  // widest tile takes --draco-position-bits.
  double base_step_m = options.position_step_m;
  if (options.draco_position_bits > 0) {
    const ZoomContent& finest = zooms.back();
    const PlacedLevel placed = placeLevel(dem, *finest.mesh, to_wgs84, geoid ? &*geoid : nullptr);
    base_step_m =
        sharedPositionStep(widestTileExtent(finest.tiles, placed), std::ldexp(1.0, -30), options.draco_position_bits);
  }
  summary.position_step_m = base_step_m;

  std::size_t total_tiles = 0;
  for (const ZoomContent& level : zooms) total_tiles += level.tiles.size();
  progress.beginStage("writing tiles", total_tiles);
  std::map<std::tuple<int, int, int>, TileNode> nodes;  // (zoom, y, x) -> node
  double widest_step_m = 0;
  for (const ZoomContent& level : zooms) {
    const PlacedLevel placed = placeLevel(dem, *level.mesh, to_wgs84, geoid ? &*geoid : nullptr);
    // One grid per zoom: the base step, unless the zoom's widest tile needs more than the
    // 2^23 steps Draco quantises exactly (tiles wider than about 65 km at 1/128 m).
    glb.position_step_m = sharedPositionStep(widestTileExtent(level.tiles, placed), base_step_m, kMaxExactPositionBits);
    widest_step_m = std::max(widest_step_m, glb.position_step_m);
    ZoomSummary zoom_summary;
    zoom_summary.position_step_m = glb.position_step_m;
    zoom_summary.zoom = level.zoom;
    zoom_summary.step_pixels = level.step;
    zoom_summary.clusters = level.clusters;
    zoom_summary.tiles = level.tiles.size();
    zoom_summary.vertices = level.mesh->vertices.size();
    zoom_summary.triangles = level.mesh->triangleCount();
    for (const PyramidTile& tile : level.tiles) zoom_summary.tile_triangles += tile.triangle_indices.size() / 3;
    zoom_summary.max_error_m = level.max_error_m;
    zoom_summary.rms_error_m = level.rms_error_m;

    // Encode in parallel batches into pre-sized slots (output identical for any thread
    // count), write and report progress from this thread.
    constexpr std::size_t kBatch = 16;
    for (std::size_t begin = 0; begin < level.tiles.size(); begin += kBatch) {
      const std::size_t end = std::min(level.tiles.size(), begin + kBatch);
      std::vector<EncodedTile> encoded(end - begin);
      tbb::parallel_for(begin, end, [&](std::size_t i) {
        encoded[i - begin] = encodeTile(level.tiles[i], placed, glb);
      });
      for (std::size_t i = begin; i < end; ++i) {
        const PyramidTile& tile = level.tiles[i];
        TileNode node;
        node.key = tile.key;
        node.content_uri = contentUri(tile.key, options.implicit_tiling);
        node.region = encoded[i - begin].region;
        // Measured: against the DEM and against the next finer zoom where both are drawn.
        node.geometric_error_m = std::max(tile.max_error_m, tile.finer_difference_m);
        zoom_summary.bytes += output.writeFile(node.content_uri, encoded[i - begin].glb);
        zoom_summary.position_bits = std::max(zoom_summary.position_bits, encoded[i - begin].position_bits);
        nodes[{tile.key.zoom, tile.key.y, tile.key.x}] = std::move(node);
        progress.advance();
      }
    }
    summary.tiles += zoom_summary.tiles;
    summary.triangles += zoom_summary.triangles;
    summary.bytes += zoom_summary.bytes;
    summary.tile_bytes += zoom_summary.bytes;
    if (level.zoom < max_zoom) summary.worst_error_m = std::max(summary.worst_error_m, level.max_error_m);
    summary.zooms.push_back(zoom_summary);
  }
  progress.endStage();

  Tileset tileset;
  tileset.generator = glb.generator;
  tileset.root = buildTree(nodes);
  finalizeTree(tileset.root);
  // The error of drawing nothing at all: at least the data's size, the larger of the
  // footprint's diagonal (chord between the root region's corners) and the relief. A value
  // as small as the relief alone would hide flat terrain from any distance (CesiumJS does
  // not draw a root whose error, seen through tileset.geometricError, is below the SSE).
  {
    const Region& r = tileset.root.region;
    const std::vector<GeodeticPoint> corners{
        {r.west_rad / kDegToRad, r.south_rad / kDegToRad, r.min_height_m},
        {r.east_rad / kDegToRad, r.north_rad / kDegToRad, r.min_height_m}};
    std::vector<EcefPoint> ends(2);
    geodeticToEcef(corners, ends);
    const double diagonal_m =
        std::hypot(ends[1].x - ends[0].x, ends[1].y - ends[0].y, ends[1].z - ends[0].z);
    tileset.geometric_error_m = std::max(
        {tileset.root.geometric_error_m, diagonal_m, r.max_height_m - r.min_height_m});
  }
  // A tile without content (a common ancestor above the coarsest zoom's tiles) draws nothing:
  // its error is that of drawing nothing, so a viewer always refines it.
  {
    std::vector<TileNode*> open{&tileset.root};
    while (!open.empty()) {
      TileNode* node = open.back();
      open.pop_back();
      if (node->content_uri.empty()) node->geometric_error_m = tileset.geometric_error_m;
      for (TileNode& child : node->children) open.push_back(&child);
    }
  }
  // Record per zoom the largest geometricError written (after finalizeTree raised them).
  std::vector<const TileNode*> stack{&tileset.root};
  while (!stack.empty()) {
    const TileNode* node = stack.back();
    stack.pop_back();
    for (ZoomSummary& z : summary.zooms) {
      if (z.zoom == node->key.zoom && !node->content_uri.empty()) {
        z.geometric_error_m = std::max(z.geometric_error_m, node->geometric_error_m);
      }
    }
    for (const TileNode& child : node->children) stack.push_back(&child);
  }

  // What `terratiles check` needs to find the source again (not referenced by tileset.json).
  {
    nlohmann::json facts;
    facts["generator"] = glb.generator;
    std::vector<std::string> inputs;
    for (const std::string& input : options.inputs) inputs.push_back(std::filesystem::absolute(input).string());
    facts["inputs"] = inputs;
    facts["crs"] = dem.crs_name;
    facts["lod"] = options.lod == LodMethod::Grid ? "grid" : "clusters";
    facts["scheme"] = options.lod == LodMethod::Grid ? "local pixels" : std::string(tileSchemeName(options.scheme));
    facts["assign"] = std::string(assignmentName(options.assignment));
    facts["tin_max_error_m"] = options.tin_max_error_m;
    facts["heights"] = geoid ? "orthometric" : "ellipsoidal";
    facts["geoid"] = geoid ? std::filesystem::absolute(options.geoid_path.empty() ? kDefaultGeoidPath
                                                                                 : options.geoid_path).string()
                           : std::string();
    facts["position_step_m"] = widest_step_m;  // the widest any zoom used
    nlohmann::json steps = nlohmann::json::object();
    for (const ZoomSummary& z : summary.zooms) steps[std::to_string(z.zoom)] = z.position_step_m;
    facts["position_step_m_by_zoom"] = steps;
    facts["tiling"] = options.implicit_tiling ? "implicit" : "explicit";
    // Implicit output: the same tree as an explicit tileset, for `terratiles check`.
    if (options.implicit_tiling) facts["explicit_tileset"] = nlohmann::json::parse(tilesetToJson(tileset));
    summary.bytes += output.writeFile("build.json", facts.dump(2) + "\n");
  }
  // tileset.json last, then the whole directory moves into place.
  if (options.implicit_tiling) {
    for (const ImplicitFile& file : writeImplicitTileset(tileset, options.subtree_levels)) {
      summary.bytes += output.writeFile(file.path, file.bytes);
    }
  } else {
    summary.bytes += output.writeFile("tileset.json", tilesetToJson(tileset));
  }
  progress.throwIfCancelled();

  // The report: maps per zoom, the check of what was written, then report.json and .html.
  if (options.report) {
    std::vector<ZoomMaps> maps;
    progress.beginStage("drawing report maps", zooms.size());
    for (const ZoomContent& level : zooms) {
      maps.push_back(drawZoomMaps(dem, *level.mesh, level.map_clusters, frame.get(), level.zoom, level.max_error_m));
      progress.advance();
    }
    progress.endStage();
    // The levels are written and drawn: free them before the check decodes every tile.
    zooms = {};
    levels = {};
    pyramid = {};
    std::optional<CheckReport> check;
    if (options.report_check_cuts > 0) {
      CheckOptions check_options;
      check_options.cuts = static_cast<std::size_t>(options.report_check_cuts);
      check = checkOutput(output.staging().string(), check_options, progress);
      summary.check_ran = true;
      summary.check_ok = check->ok();
    }
    summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const nlohmann::json report = buildReportJson(options, summary, progress.stages(), check, maps);
    summary.bytes += output.writeFile("report.json", report.dump(1) + "\n");
    summary.bytes += output.writeFile("report.html", renderReportHtml(report));
    summary.report_path = (std::filesystem::path(options.output_dir) / "report.html").string();
  }
  progress.throwIfCancelled();
  output.commit();
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace terratiles
