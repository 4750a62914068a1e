#include "src/pipeline/terrain_output.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <string>

#include <nlohmann/json.hpp>

#include "formats/dem/read_dem.h"
#include "formats/quantized_mesh/write_quantized_mesh.h"
#include "src/base/error.h"
#include "src/geo/crs_transform.h"
#include "src/base/version.h"
#include "src/pipeline/tile_output.h"
#include "src/tiling/clip_to_tile.h"
#include "src/tiling/fill_tile.h"

namespace terratiles {
namespace {

// A level on the globe: longitude, latitude, ellipsoidal height and the level's normals.
GeodeticMesh levelOnGlobe(const TinMesh& level, const DemOnGlobe& globe) {
  GeodeticMesh mesh;
  mesh.vertices.resize(level.vertices.size());
  std::vector<EcefPoint> ecef(level.vertices.size());
  globe.place(level.vertices, mesh.vertices, ecef);
  mesh.normals = levelNormals(level, std::move(ecef));
  mesh.triangles = level.triangle_indices;
  return mesh;
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

void writeQuantizedMeshLayer(const std::vector<Level>& levels, std::int32_t max_zoom, const DemOnGlobe& globe,
                             const FillHeight& fill_height, OutputDirectory& output, BuildSummary& summary,
                             Progress& progress) {
  progress.beginStage("writing terrain tiles", static_cast<std::size_t>(max_zoom) + 1);
  nlohmann::json available = nlohmann::json::array();
  nlohmann::json zoom_errors = nlohmann::json::array();
  std::vector<ZoomSummary> zoom_summaries;
  std::size_t shown_level = levels.size();
  GeodeticMesh mesh;
  for (std::int32_t zoom = max_zoom; zoom >= 0; --zoom) {
    const std::size_t l = std::min(levels.size() - 1, static_cast<std::size_t>(max_zoom - zoom));
    if (l != shown_level) {
      mesh = levelOnGlobe(levels[l].mesh, globe);
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
    QuantizedMeshOptions encoding;
    encoding.height_range = zoomHeightRange(tiles);
    std::vector<std::vector<std::uint8_t>> files(keys.size());
    std::vector<std::size_t> triangles(keys.size());
    tbb::parallel_for(std::size_t{0}, keys.size(), [&](std::size_t i) {
      triangles[i] = tiles[i].triangles.size() / 3;
      files[i] = gzipBytes(encodeQuantizedMesh(tiles[i], encoding));
      tiles[i] = TerrainTileMesh();
    });
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
    if (levels[l].error.max_error_m > clientLevelError(zoom)) {
      progress.note("warning: zoom " + std::to_string(zoom) + " is " + std::to_string(levels[l].error.max_error_m) +
                    " m off the DEM, more than the " + std::to_string(clientLevelError(zoom)) +
                    " m CesiumTerrainProvider assumes for it");
    }
    zoom_summary.tiles = keys.size();
    zoom_summary.vertices = levels[l].mesh.vertices.size();
    zoom_summary.triangles = levels[l].mesh.triangleCount();
    for (std::size_t i = 0; i < keys.size(); ++i) {
      zoom_summary.tile_triangles += triangles[i];
      zoom_summary.bytes += output.writeFile(std::to_string(zoom) + "/" + std::to_string(keys[i].x) + "/" +
                                                 std::to_string(keys[i].y) + ".terrain",
                                             files[i]);
    }
    zoom_summaries.push_back(zoom_summary);
    available.insert(available.begin(), availableRectangles(keys));
    progress.advance();
    progress.throwIfCancelled();
  }
  progress.endStage();

  nlohmann::json layer;
  layer["tilejson"] = "2.1.0";
  layer["name"] = "terratiles";
  layer["description"] = "terrain from " + summary.crs_name + " by " + std::string("terratiles ") + kVersion;
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
  layer["terratiles"] = {{"generator", std::string("terratiles ") + kVersion}, {"zooms", std::move(zoom_errors)}};
  summary.bytes += output.writeFile("layer.json", layer.dump(1) + "\n");
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
