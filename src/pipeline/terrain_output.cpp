#include "src/pipeline/terrain_output.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <string>

#include <nlohmann/json.hpp>

#include "formats/quantized_mesh/write_quantized_mesh.h"
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

void writeQuantizedMeshLayer(const std::vector<Level>& levels, std::int32_t max_zoom, const DemOnGlobe& globe,
                             const GeoidGrid* geoid, OutputDirectory& output, BuildSummary& summary,
                             Progress& progress) {
  const auto fill_height = [geoid](double lon, double lat) {
    return geoid ? geoid->undulationAt(lon, lat).value_or(0.0) : 0.0;
  };
  progress.beginStage("writing terrain tiles", static_cast<std::size_t>(max_zoom) + 1);
  nlohmann::json available = nlohmann::json::array();
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
  summary.bytes += output.writeFile("layer.json", layer.dump(1) + "\n");
  for (auto z = zoom_summaries.rbegin(); z != zoom_summaries.rend(); ++z) {
    summary.tiles += z->tiles;
    summary.triangles += z->triangles;
    summary.bytes += z->bytes;
    summary.tile_bytes += z->bytes;
    summary.zooms.push_back(*z);
  }
}

}  // namespace terratiles
