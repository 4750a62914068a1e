#include "src/pipeline/terrain_output.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <span>
#include <string>

#include <nlohmann/json.hpp>

#include "formats/dem/read_dem.h"
#include "formats/quantized_mesh/write_quantized_mesh.h"
#include "formats/terrain_glb/write_terrain_glb.h"
#include "src/base/error.h"
#include "src/geo/crs_transform.h"
#include "src/base/version.h"
#include "src/pipeline/tile_output.h"
#include "src/tiling/clip_to_tile.h"
#include "src/tiling/fill_tile.h"
#include "src/tin/measure_tin.h"
#include "tileset/implicit_tileset.h"

namespace terratiles {
namespace {

// A level on the globe: longitude, latitude, ellipsoidal height and the level's normals;
// `ecef` receives its vertices in ECEF.
GeodeticMesh levelOnGlobe(const TinMesh& level, const DemOnGlobe& globe, std::vector<EcefPoint>& ecef) {
  GeodeticMesh mesh;
  mesh.vertices.resize(level.vertices.size());
  ecef.resize(level.vertices.size());
  globe.place(level.vertices, mesh.vertices, ecef);
  mesh.normals = levelNormals(level, ecef);
  mesh.triangles = level.triangle_indices;
  return mesh;
}

// Per tile of `zoom` holding valid DEM pixels: the level's error there, the largest vertical
// offset of the level as drawn from the DEM at those pixels (measureTin's scan, each pixel
// binned by the longitude and latitude of its vertical).
std::map<TerrainTileKey, double> tileErrors(const DemOnGlobe& globe, const TinMesh& level,
                                            std::span<const EcefPoint> ecef, std::int32_t zoom) {
  const DemGrid& dem = globe.dem();
  const double size = 180.0 / std::ldexp(1.0, zoom);
  const std::int64_t columns = std::int64_t{2} << zoom, rows = std::int64_t{1} << zoom;
  const std::size_t triangles = level.triangle_indices.size() / 3;
  tbb::enumerable_thread_specific<std::map<TerrainTileKey, double>> per_thread;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, triangles, 4096), [&](const tbb::blocked_range<std::size_t>& range) {
    std::map<TerrainTileKey, double>& errors = per_thread.local();
    const auto& idx = level.triangle_indices;
    for (std::size_t t = range.begin(); t != range.end(); ++t) {
      const std::uint32_t a = idx[3 * t], b = idx[3 * t + 1], c = idx[3 * t + 2];
      forEachCoveredPixelOnGlobe(globe, level.vertices[a], level.vertices[b], level.vertices[c], ecef[a], ecef[b],
                                 ecef[c], [&](std::size_t pixel, double offset_m) {
                                   if (std::isnan(dem.heights_m[pixel])) return true;
                                   const UnitVector up = globe.up(pixel);
                                   const double lat = std::asin(std::clamp(up[2], -1.0, 1.0)) * 180 / std::numbers::pi;
                                   const double lon = std::atan2(up[1], up[0]) * 180 / std::numbers::pi;
                                   const TerrainTileKey key{
                                       zoom, std::clamp<std::int64_t>(static_cast<std::int64_t>((lon + 180) / size), 0, columns - 1),
                                       std::clamp<std::int64_t>(static_cast<std::int64_t>((lat + 90) / size), 0, rows - 1)};
                                   double& error = errors[key];
                                   error = std::max(error, std::fabs(offset_m));
                                   return true;
                                 });
    }
  });
  std::map<TerrainTileKey, double> errors;
  for (const auto& part : per_thread) {
    for (const auto& [key, error] : part) errors[key] = std::max(errors[key], error);
  }
  return errors;
}

// layer.json's `available` for one zoom: the tiles as rectangles (runs of x per row, rows with
// the same run joined).
nlohmann::json availableRectangles(const std::vector<TerrainTileKey>& keys) {
  std::map<std::pair<std::int64_t, std::int64_t>, std::vector<std::int64_t>> rows_of_run;  // (x0, x1) -> rows
  for (std::size_t i = 0; i < keys.size();) {
    std::size_t j = i;
    while (j + 1 < keys.size() && keys[j + 1].y == keys[i].y && keys[j + 1].x == keys[j].x + 1) ++j;
    rows_of_run[{keys[i].x, keys[j].x}].push_back(keys[i].y);
    i = j + 1;
  }
  nlohmann::json rectangles = nlohmann::json::array();
  for (const auto& [run, rows] : rows_of_run) {
    for (std::size_t i = 0; i < rows.size();) {
      std::size_t j = i;
      while (j + 1 < rows.size() && rows[j + 1] == rows[j] + 1) ++j;
      rectangles.push_back({{"startX", run.first}, {"startY", rows[i]}, {"endX", run.second}, {"endY", rows[j]}});
      i = j + 1;
    }
  }
  return rectangles;
}

// The least and greatest height of a zoom's tiles, rounded outwards to float.
std::array<float, 2> zoomHeightRange(const std::vector<TerrainTileMesh>& tiles) {
  double low = std::numeric_limits<double>::infinity(), high = -low;
  for (const TerrainTileMesh& tile : tiles) {
    for (const GeodeticPoint& p : tile.vertices) {
      low = std::min(low, p.height_m);
      high = std::max(high, p.height_m);
    }
  }
  if (low > high) return {0, 0};
  return floatRangeAround(low, high);
}

// The tile metadata of 3D Tiles terrain (3D Metadata Semantic Reference), what
// Cesium3DTilesTerrainProvider reads per tile, and the tile's measured error.
const std::vector<ImplicitTileProperty>& terrainTileProperties() {
  static const std::vector<ImplicitTileProperty> properties = {
      {"minimumHeight", "TILE_MINIMUM_HEIGHT", "least ellipsoidal height of the tile's decoded vertices, metres"},
      {"maximumHeight", "TILE_MAXIMUM_HEIGHT", "greatest ellipsoidal height of the tile's decoded vertices, metres"},
      {"boundingSphere", "TILE_BOUNDING_SPHERE",
       "sphere holding the tile's decoded vertices: centre (ECEF) and radius, metres", "SCALAR", 4},
      {"horizonOcclusionPoint", "TILE_HORIZON_OCCLUSION_POINT",
       "horizon occlusion point of the tile's decoded vertices, ellipsoid-scaled ECEF", "VEC3", 0},
      {"geometricError", "TILE_GEOMETRIC_ERROR",
       "the largest distance, in metres, between the DEM and the level the tile's zoom shows, measured along "
       "the vertical at every valid pixel in the tile; a tile without DEM pixels (fill only, not measured) "
       "carries the level's error"}};
  return properties;
}

// tileset.json and the subtrees of 3D Tiles terrain: a root over the globe whose two
// children, the hemispheres, are the implicit quadtrees Cesium3DTilesTerrainProvider reads
// (children[0] west, children[1] east). Returns the bytes written.
std::size_t writeTerrainTileset(const std::array<std::vector<ImplicitTileRecord>, 2>& hemisphere_tiles,
                                std::int32_t max_zoom, const std::string& generator, nlohmann::json zoom_errors,
                                nlohmann::json available, OutputDirectory& output) {
  constexpr double kPi = std::numbers::pi;
  const std::span<const ImplicitTileProperty> properties = terrainTileProperties();
  nlohmann::json json;
  json["asset"] = {{"version", "1.1"}, {"generator", generator}};
  // With nothing drawn, the error is the relief itself; what a client assumes at zoom 0 is larger.
  json["geometricError"] = clientLevelError(0);
  json["schema"] = implicitTileSchema(properties, "3D Tiles terrain: per-tile heights, culling volumes and error");
  // terratiles' own figures (clients ignore them): per zoom its level's measured error, and
  // the tiles per zoom as rectangles of TMS columns and rows (layer.json's `available`).
  json["extras"]["terratiles"] = {{"format", "3d-tiles-terrain"},
                                  {"zooms", std::move(zoom_errors)},
                                  {"available", std::move(available)}};
  nlohmann::json& root = json["root"];
  root["geometricError"] = clientLevelError(0);
  root["refine"] = "REPLACE";
  root["children"] = nlohmann::json::array();
  double globe_low = std::numeric_limits<double>::infinity(), globe_high = -globe_low;
  std::size_t bytes = 0;
  for (std::int32_t hemisphere = 0; hemisphere < 2; ++hemisphere) {
    const std::vector<ImplicitTileRecord>& tiles = hemisphere_tiles[hemisphere];
    double low = std::numeric_limits<double>::infinity(), high = -low, zoom0_error = 0;
    for (const ImplicitTileRecord& tile : tiles) {
      low = std::min(low, tile.metadata[0]);
      high = std::max(high, tile.metadata[1]);
      if (tile.coordinates.level == 0) zoom0_error = tile.metadata.back();
    }
    globe_low = std::min(globe_low, low);
    globe_high = std::max(globe_high, high);
    const double west = hemisphere == 0 ? -kPi : 0.0;
    nlohmann::json child;
    child["boundingVolume"]["region"] = {west, -kPi / 2, west + kPi, kPi / 2, low, high};
    child["geometricError"] = zoom0_error;
    child["content"]["uri"] = implicitTemplatePath("tiles", hemisphere, "glb");
    nlohmann::json& implicit = child["implicitTiling"];
    implicit["subdivisionScheme"] = "QUADTREE";
    implicit["subtreeLevels"] = kDefaultSubtreeLevels;
    implicit["availableLevels"] = max_zoom + 1;
    implicit["subtrees"]["uri"] = implicitTemplatePath("subtrees", hemisphere, "subtree");
    root["children"].push_back(std::move(child));
    for (const ImplicitFile& file : implicitSubtreeFiles(hemisphere, tiles, properties, kDefaultSubtreeLevels)) {
      bytes += output.writeFile(file.path, file.bytes);
    }
  }
  root["boundingVolume"]["region"] = {-kPi, -kPi / 2, kPi, kPi / 2, globe_low, globe_high};
  bytes += output.writeFile("tileset.json", json.dump(1, '\t') + "\n");
  return bytes;
}

}  // namespace

double clientLevelError(std::int32_t zoom) {
  return 6378137.0 * 2 * std::numbers::pi * 0.25 / (65.0 * 2) / std::ldexp(1.0, zoom);
}

FillHeight terrainFill(const GeoidGrid* geoid, const std::string& fill_dem, std::string& description,
                       Progress& progress) {
  const auto undulation = [geoid](double lon, double lat) {
    return geoid ? geoid->undulationAt(lon, lat).value_or(0.0) : 0.0;
  };
  if (fill_dem.empty()) {
    description = geoid ? "the geoid surface (" + geoid->name + ", height 0)" : std::string("the ellipsoid");
    return undulation;
  }
  auto dem = std::make_shared<DemGrid>(readDem({fill_dem}, "reading the fill DEM", progress));
  if (!CrsToWgs84(dem->crs_wkt).isWgs84LonLat() || dem->col_offset != 0 || dem->row_offset != 0) {
    throw Error(ErrorCode::Input, fill_dem + ": the fill DEM is in " + dem->crs_name +
                                      "; expected WGS84 longitude and latitude (EPSG:4326, for example ETOPO5); "
                                      "gdalwarp -t_srs EPSG:4326 makes one");
  }
  description = fill_dem + " (" + std::to_string(dem->width) + " x " + std::to_string(dem->height) +
                " px), the geoid surface where it has no data";
  return [dem, undulation](double lon, double lat) {
    // Bilinear between the four pixel centres around the point (clamped at the raster's
    // edges), over the valid ones.
    const double x = (lon - dem->origin_x) / dem->pixel_size_x - 0.5, y = (dem->origin_y - lat) / dem->pixel_size_y - 0.5;
    const double fx = std::floor(x), fy = std::floor(y);
    double sum = 0, weight = 0;
    for (int dy = 0; dy <= 1; ++dy) {
      for (int dx = 0; dx <= 1; ++dx) {
        const auto col = static_cast<std::int32_t>(std::clamp(fx + dx, 0.0, dem->width - 1.0));
        const auto row = static_cast<std::int32_t>(std::clamp(fy + dy, 0.0, dem->height - 1.0));
        const double w = (dx ? x - fx : 1 - (x - fx)) * (dy ? y - fy : 1 - (y - fy));
        if (w > 0 && dem->isValid(col, row)) {
          sum += w * dem->heightAt(col, row);
          weight += w;
        }
      }
    }
    return (weight > 0 ? sum / weight : 0.0) + undulation(lon, lat);
  };
}

void writeTerrainLayer(const std::vector<Level>& levels, std::int32_t max_zoom, const DemOnGlobe& globe,
                       const FillHeight& fill_height, OutputFormat format, OutputDirectory& output,
                       BuildSummary& summary, Progress& progress) {
  const bool quantized_mesh = format == OutputFormat::QuantizedMesh;
  const std::string generator = std::string("terratiles ") + kVersion;
  std::array<std::vector<ImplicitTileRecord>, 2> hemisphere_tiles;  // 3D Tiles terrain
  progress.beginStage("writing terrain tiles", static_cast<std::size_t>(max_zoom) + 1);
  nlohmann::json available = nlohmann::json::array();
  nlohmann::json zoom_errors = nlohmann::json::array();
  std::vector<ZoomSummary> zoom_summaries;
  std::size_t shown_level = levels.size();
  GeodeticMesh mesh;
  std::vector<EcefPoint> mesh_ecef;
  for (std::int32_t zoom = max_zoom; zoom >= 0; --zoom) {
    const std::size_t l = std::min(levels.size() - 1, static_cast<std::size_t>(max_zoom - zoom));
    if (l != shown_level) {
      mesh = levelOnGlobe(levels[l].mesh, globe, mesh_ecef);
      shown_level = l;
    }
    GeodeticMesh snapped = mesh;
    snapToTileSides(snapped.vertices, zoom, kQuantizedMax);
    std::map<TerrainTileKey, std::vector<std::uint32_t>> candidates = trianglesPerTerrainTile(snapped, zoom);
    if (zoom == 0) {
      candidates.try_emplace({0, 0, 0});
      candidates.try_emplace({0, 1, 0});
    }
    std::vector<TerrainTileKey> keys;
    for (const auto& [key, unused] : candidates) keys.push_back(key);
    std::sort(keys.begin(), keys.end(), [](const TerrainTileKey& a, const TerrainTileKey& b) {
      return std::tie(a.y, a.x) < std::tie(b.y, b.x);
    });
    // The tiles, then their zoom's height range, which all of them quantise against.
    std::vector<TerrainTileMesh> tiles(keys.size());
    tbb::parallel_for(std::size_t{0}, keys.size(), [&](std::size_t i) {
      tiles[i] = fillTile(clipToTile(snapped, candidates.at(keys[i]), terrainTileBounds(keys[i])), kFillGridCells,
                          fill_height);
    });
    std::vector<std::vector<std::uint8_t>> files(keys.size());
    std::vector<std::size_t> triangles(keys.size());
    std::vector<std::string> paths(keys.size());
    double position_step_m = 0;  // 3D Tiles terrain: the zoom's coarsest position quantisation
    if (quantized_mesh) {
      QuantizedMeshOptions encoding;
      encoding.height_range = zoomHeightRange(tiles);
      tbb::parallel_for(std::size_t{0}, keys.size(), [&](std::size_t i) {
        triangles[i] = tiles[i].triangles.size() / 3;
        files[i] = gzipBytes(encodeQuantizedMesh(tiles[i], encoding));
        tiles[i] = TerrainTileMesh();
      });
      for (std::size_t i = 0; i < keys.size(); ++i) {
        paths[i] = std::to_string(zoom) + "/" + std::to_string(keys[i].x) + "/" + std::to_string(keys[i].y) + ".terrain";
      }
    } else {
      // One lattice for the zoom: its step holds the widest tile.
      std::vector<double> extents(keys.size());
      tbb::parallel_for(std::size_t{0}, keys.size(), [&](std::size_t i) { extents[i] = terrainTileExtent(tiles[i]); });
      const double step = std::max(*std::max_element(extents.begin(), extents.end()), 1e-3) / (65535 - 1);
      std::vector<TerrainGlb> glbs(keys.size());
      tbb::parallel_for(std::size_t{0}, keys.size(), [&](std::size_t i) {
        glbs[i] = encodeTerrainGlb(tiles[i], generator, step);
        triangles[i] = tiles[i].triangles.size() / 3;
        files[i] = std::move(glbs[i].bytes);
        tiles[i] = TerrainTileMesh();
      });
      for (const TerrainGlb& glb : glbs) position_step_m = std::max(position_step_m, glb.position_step_m);
      // Each tile's own error where it holds DEM pixels; elsewhere (fill only, not measured)
      // the level's.
      const std::map<TerrainTileKey, double> errors = tileErrors(globe, levels[l].mesh, mesh_ecef, zoom);
      for (std::size_t i = 0; i < keys.size(); ++i) {
        // Implicit coordinates: the hemisphere's column, the row from the south (as TMS).
        const std::int64_t rows = std::int64_t{1} << zoom;
        const ImplicitTileCoordinates c{static_cast<std::int32_t>(keys[i].x / rows), zoom, keys[i].x % rows, keys[i].y};
        paths[i] = implicitFilePath("tiles", c, "glb");
        const TerrainGlb& t = glbs[i];
        const TerrainTileCulling& k = t.culling;
        hemisphere_tiles[c.hemisphere].push_back(
            {c, true,
             {t.minimum_height_m, t.maximum_height_m, k.sphere_center.x, k.sphere_center.y, k.sphere_center.z,
              k.sphere_radius_m, k.horizon_occlusion_point.x, k.horizon_occlusion_point.y, k.horizon_occlusion_point.z,
              errors.count(keys[i]) ? errors.at(keys[i]) : levels[l].error.max_error_m}});
      }
    }
    ZoomSummary zoom_summary;
    zoom_summary.zoom = zoom;
    zoom_summary.max_error_m = levels[l].error.max_error_m;
    zoom_summary.rms_error_m = levels[l].error.rms_error_m;
    zoom_summary.geometric_error_m = clientLevelError(zoom);
    const TinErrorStatistics& error = levels[l].error;
    zoom_errors.insert(zoom_errors.begin(), nlohmann::json::object({{"zoom", zoom},
                                                                    {"level", l},
                                                                    {"max_error_m", error.max_error_m},
                                                                    {"rms_error_m", error.rms_error_m},
                                                                    {"measured_pixels", error.measured_pixels},
                                                                    {"client_geometric_error_m", clientLevelError(zoom)}}));
    if (!quantized_mesh) zoom_errors.front()["position_step_m"] = position_step_m;
    if (levels[l].error.max_error_m > clientLevelError(zoom)) {
      progress.note("warning: zoom " + std::to_string(zoom) + " is " + std::to_string(levels[l].error.max_error_m) +
                    " m off the DEM, more than the " + std::to_string(clientLevelError(zoom)) +
                    " m CesiumJS assumes for it");
    }
    zoom_summary.tiles = keys.size();
    zoom_summary.vertices = levels[l].mesh.vertices.size();
    zoom_summary.triangles = levels[l].mesh.triangleCount();
    for (std::size_t i = 0; i < keys.size(); ++i) {
      zoom_summary.tile_triangles += triangles[i];
      zoom_summary.bytes += output.writeFile(paths[i], files[i]);
    }
    zoom_summaries.push_back(zoom_summary);
    available.insert(available.begin(), availableRectangles(keys));
    progress.advance();
    progress.throwIfCancelled();
  }
  progress.endStage();

  if (quantized_mesh) {
    nlohmann::json layer;
    layer["tilejson"] = "2.1.0";
    layer["name"] = "terratiles";
    layer["description"] = "terrain from " + summary.crs_name + " by " + generator;
    layer["version"] = "1.0.0";
    layer["format"] = "quantized-mesh-1.0";
    layer["attribution"] = "";
    layer["scheme"] = "tms";
    layer["tiles"] = {"{z}/{x}/{y}.terrain?v={version}"};
    layer["projection"] = "EPSG:4326";
    layer["bounds"] = {-180.0, -90.0, 180.0, 90.0};
    layer["minzoom"] = 0;
    layer["maxzoom"] = max_zoom;
    layer["extensions"] = {"octvertexnormals"};
    layer["available"] = std::move(available);
    // terratiles' own figures (clients ignore them): per zoom, its level's error against the DEM
    // (measured on the triangles as drawn, at every valid pixel) and the error CesiumJS assumes.
    layer["terratiles"] = {{"generator", generator}, {"zooms", std::move(zoom_errors)}};
    summary.bytes += output.writeFile("layer.json", layer.dump(1) + "\n");
  } else {
    summary.bytes += writeTerrainTileset(hemisphere_tiles, max_zoom, generator, std::move(zoom_errors),
                                         std::move(available), output);
  }
  for (auto z = zoom_summaries.rbegin(); z != zoom_summaries.rend(); ++z) {
    if (z->zoom < max_zoom) summary.worst_error_m = std::max(summary.worst_error_m, z->max_error_m);
    summary.tiles += z->tiles;
    summary.triangles += z->triangles;
    summary.bytes += z->bytes;
    summary.tile_bytes += z->bytes;
    summary.zooms.push_back(*z);
  }
}

}  // namespace terratiles
