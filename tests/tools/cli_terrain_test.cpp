// `terratiles build --format quantized-mesh` on a real raster: the layer a CesiumTerrainProvider
// reads, every tile decoded by loaders.gl, and the seams between tiles.
#include <doctest/doctest.h>
#include <GeographicLib/Geocentric.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <set>

#include <nlohmann/json.hpp>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/quantized_mesh/write_quantized_mesh.h"
#include "tileset/implicit_tileset.h"
#include "src/geo/crs_transform.h"
#include "tests/test_support.h"

using namespace terratiles;
using test::runTerratiles;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Key {
  int z = 0;
  long x = 0, y = 0;
  auto operator<=>(const Key&) const = default;
};

// A decoded tile's vertices on one side (u or v at 0 or 32767) as (position along the side,
// height) pairs: what must match the neighbour's.
std::set<std::pair<int, int>> sideOf(const json& tile, int side) {
  std::set<std::pair<int, int>> found;
  const auto& u = tile["u"];
  const auto& v = tile["v"];
  const auto& h = tile["height"];
  for (std::size_t i = 0; i < u.size(); ++i) {
    const int ui = u[i], vi = v[i];
    const bool on = side == 0 ? ui == 0 : side == 1 ? vi == 0 : side == 2 ? ui == 32767 : vi == 32767;
    if (on) found.insert({side % 2 == 0 ? vi : ui, h[i].get<int>()});
  }
  return found;
}

// SRTM N57E011 built as a quantized-mesh layer at 2 m into dir/terrain.
std::string buildLayer(const test::TempDir& dir) {
  const std::string out = dir / "terrain";
  const auto result = runTerratiles({"build", test::sharedData("srtm3_N57E011_4326.tif"), "-o", out, "--format",
                                     "quantized-mesh", "--tin-max-error", "2", "-q"});
  REQUIRE_MESSAGE(result.exit_code == 0, result.err);
  return out;
}

// CesiumJS (CesiumTerrainProvider or Cesium3DTilesTerrainProvider, as `format` says, in headless chromium through samples/viewer and
// tools/render_check/terrain_check.mjs, NaturalEarthII draped) takes the layer built from
// `raster` with `build_args` as its terrain: no tile fails, a clampToGround polyline renders,
// and sampleTerrainMostDetailed at 200 random valid pixels gives the DEM height plus the
// geoid within the finest zoom's measured error (layer.json or tileset.json) plus 5 cm: the
// quantisation of heights (range / 32767: under 1 cm on N57E011, 5 cm at Interlaken's zoom 12)
// and positions, and the straight triangles' sag, which a client's interpolation in longitude and
// latitude does not follow. A screenshot goes to test-artifacts/`name`.png.
void checkInCesium(const std::string& format, const std::string& raster, const std::vector<std::string>& build_args,
                   const std::string& geoid_path, const std::string& name) {
  test::TempDir dir;
  const std::string out = dir / "terrain";
  std::vector<std::string> args{"build", raster, "-o", out, "--format", format, "-q"};
  args.insert(args.end(), build_args.begin(), build_args.end());
  const auto built = runTerratiles(args);
  REQUIRE_MESSAGE(built.exit_code == 0, built.err);
  const bool quantized_mesh = format == "quantized-mesh";
  std::ifstream layer_file(out + (quantized_mesh ? "/layer.json" : "/tileset.json"));
  const json layer = json::parse(layer_file);
  const json& zooms = quantized_mesh ? layer["terratiles"]["zooms"] : layer["extras"]["terratiles"]["zooms"];
  // 3D Tiles terrain adds its position quantisation (the finest zoom's step: half a step up
  // or down, and half a step's diagonal sideways on slopes up to 1:1.4).
  const double bound_m = zooms.back()["max_error_m"].get<double>() + 0.05 +
                         (quantized_mesh ? 0.0 : zooms.back()["position_step_m"].get<double>());
  const DemGrid dem = readDem({raster});
  const GeoidGrid geoid = readGeoidGrid(geoid_path);
  const CrsToWgs84 to_wgs84(dem.crs_wkt);
  std::mt19937 random(17);
  std::uniform_int_distribution<int> col(0, dem.width - 1), row(0, dem.height - 1);
  json points = json::array();
  std::vector<double> expected;
  while (expected.size() < 200) {
    const int c = col(random), r = row(random);
    if (!dem.isValid(c, r)) continue;
    const CrsPoint at = dem.pixelCentre(c, r);
    GeodeticPoint place;
    to_wgs84.transform({&at, 1}, {&place, 1});
    points.push_back({place.lon_deg, place.lat_deg});
    expected.push_back(dem.heightAt(c, r) + geoid.undulationAt(place.lon_deg, place.lat_deg).value());
  }
  {
    std::ofstream(dir / "points.json") << points.dump();
  }
  const fs::path artifacts = fs::path(TERRATILES_BINARY).parent_path() / "test-artifacts";
  fs::create_directories(artifacts);
  const std::string command = "node '" + test::sourceDir() + "/tools/render_check/terrain_check.mjs' '" + out +
                              "' --points '" + dir / "points.json" + "' --json '" + dir / "result.json" +
                              "' --screenshot '" + (artifacts / (name + ".png")).string() + "' > /dev/null";
  REQUIRE_MESSAGE(std::system(command.c_str()) == 0, "terrain_check.mjs failed (run the README test set-up)");
  std::ifstream result_file(dir / "result.json");
  const json result = json::parse(result_file);
  json summary = result;
  summary.erase("heights");
  INFO(summary.dump());
  REQUIRE(result["ready"] == true);
  CHECK(result["error"].is_null());
  CHECK(result["failedTiles"].empty());
  CHECK(result["consoleErrors"].empty());
  CHECK(result["httpErrors"].empty());
  CHECK(result["renderError"].is_null());
  CHECK(result["polyline"]["show"] == true);
  CHECK(result["polyline"]["frames"].get<int>() >= 30);
  REQUIRE(result["heights"].size() == expected.size());
  std::size_t missing = 0;
  double worst = 0;
  for (std::size_t i = 0; i < expected.size(); ++i) {
    if (result["heights"][i].is_null()) {
      ++missing;
      continue;
    }
    worst = std::max(worst, std::fabs(result["heights"][i].get<double>() - expected[i]));
  }
  CHECK(missing == 0);
  MESSAGE(name << ": largest difference to DEM + geoid at 200 pixels: " << worst << " m (bound " << bound_m << " m)");
  CHECK(worst <= bound_m);
}

}  // namespace

TEST_CASE("build --format quantized-mesh: a whole-globe layer whose tiles decode and meet bit for bit") {
  test::TempDir dir;
  const std::string out = buildLayer(dir);
  std::ifstream layer_file(out + "/layer.json");
  const json layer = json::parse(layer_file);
  CHECK(layer["format"] == "quantized-mesh-1.0");
  CHECK(layer["scheme"] == "tms");
  CHECK(layer["projection"] == "EPSG:4326");
  CHECK(layer["tiles"][0] == "{z}/{x}/{y}.terrain?v={version}");
  const int max_zoom = layer["maxzoom"];
  REQUIRE(layer["available"].size() == static_cast<std::size_t>(max_zoom) + 1);
  CHECK(max_zoom >= 8);
  // Every zoom's level measured against the DEM: the finest within the TIN's bound, every one
  // within the error CesiumJS assumes for its zoom.
  const json& zooms = layer["terratiles"]["zooms"];
  REQUIRE(zooms.size() == static_cast<std::size_t>(max_zoom) + 1);
  for (int z = 0; z <= max_zoom; ++z) {
    const json& zoom = zooms[static_cast<std::size_t>(z)];
    CHECK(zoom["zoom"] == z);
    CHECK(zoom["measured_pixels"].get<std::size_t>() == 1201u * 1201u);
    CHECK(zoom["max_error_m"].get<double>() > 0);
    CHECK(zoom["max_error_m"].get<double>() <= zoom["client_geometric_error_m"].get<double>());
  }
  CHECK(zooms.back()["max_error_m"].get<double>() <= 2.0);
  CHECK(zooms.front()["max_error_m"].get<double>() > zooms.back()["max_error_m"].get<double>());

  // The tiles written are exactly those `available` lists; zoom 0 has both; every other tile's
  // parent is there.
  std::set<Key> available, written;
  for (int z = 0; z <= max_zoom; ++z) {
    for (const json& r : layer["available"][static_cast<std::size_t>(z)]) {
      for (long y = r["startY"]; y <= r["endY"].get<long>(); ++y) {
        for (long x = r["startX"]; x <= r["endX"].get<long>(); ++x) available.insert({z, x, y});
      }
    }
  }
  std::vector<std::string> files;
  std::vector<Key> file_keys;
  for (const auto& entry : fs::recursive_directory_iterator(out)) {
    if (entry.path().extension() != ".terrain") continue;
    const fs::path relative = fs::relative(entry.path(), out);
    auto part = relative.begin();
    const Key key{std::stoi(part->string()), std::stol((++part)->string()), std::stol((++part)->stem().string())};
    written.insert(key);
    files.push_back(entry.path().string());
    file_keys.push_back(key);
  }
  CHECK(written == available);
  CHECK(available.count({0, 0, 0}) == 1);
  CHECK(available.count({0, 1, 0}) == 1);
  std::size_t orphans = 0;
  for (const Key& key : available) orphans += key.z > 0 && !available.count({key.z - 1, key.x / 2, key.y / 2});
  CHECK(orphans == 0);

  // Every tile decodes (gzip'd), covers its square exactly once with counter-clockwise
  // triangles, lists exactly its side vertices as edges, and shares its zoom's height range.
  const std::vector<json> decoded = test::decodeQuantizedMeshFiles(files);
  std::map<Key, const json*> tiles;
  std::map<int, std::pair<double, double>> range_of_zoom;
  std::size_t outside_sphere = 0, seen_when_culled = 0, far_points = 0, far_points_beyond_zoom_1 = 0;
  std::size_t folded = 0, folded_further = 0, triangles = 0, wrong_edges = 0, other_range = 0, not_covered = 0;
  std::size_t no_normals = 0;
  for (std::size_t i = 0; i < decoded.size(); ++i) {
    const json& tile = decoded[i];
    INFO(tile.value("file", std::string()));
    REQUIRE_FALSE(tile.contains("error"));
    CHECK(tile["gzip"] == true);
    tiles[file_keys[i]] = &tile;
    const auto& u = tile["u"];
    const auto& v = tile["v"];
    const auto& t = tile["triangles"];
    std::int64_t area2 = 0;
    triangles += t.size() / 3;
    for (std::size_t k = 0; k < t.size(); k += 3) {
      const std::size_t a = t[k], b = t[k + 1], c = t[k + 2];
      const std::int64_t ua = u[a], va = v[a], ub = u[b], vb = v[b], uc = u[c], vc = v[c];
      const std::int64_t cross = (ub - ua) * (vc - va) - (vb - va) * (uc - ua);
      // Clockwise only by rounding: a sliver whose altitude is under one quantisation step
      // (twice its area below its longest side) may fold; nothing folds further.
      const double longest = std::max({std::hypot(ub - ua, vb - va), std::hypot(uc - ub, vc - vb),
                                       std::hypot(ua - uc, va - vc)});
      folded_further += cross < 0 && static_cast<double>(-cross) > longest;
      folded += cross < 0;
      area2 += cross;
    }
    not_covered += area2 != std::int64_t{2} * 32767 * 32767;
    const char* names[] = {"west", "south", "east", "north"};
    for (int side = 0; side < 4; ++side) {
      std::set<std::size_t> listed, on_side;
      for (const auto& index : tile[names[side]]) listed.insert(index.get<std::size_t>());
      for (std::size_t k = 0; k < u.size(); ++k) {
        const int ui = u[k], vi = v[k];
        if (side == 0 ? ui == 0 : side == 1 ? vi == 0 : side == 2 ? ui == 32767 : vi == 32767) on_side.insert(k);
      }
      wrong_edges += listed != on_side;
    }
    const std::pair<double, double> range{tile["header"]["minHeight"], tile["header"]["maxHeight"]};
    other_range += range_of_zoom.try_emplace(file_keys[i].z, range).first->second != range;
    no_normals += tile["extensions"].empty() || tile["extensions"][0]["id"] != 1;
    // The header holds the vertices as decoded: the bounding sphere all of them, the horizon
    // occlusion point culls none that a camera could see (where the tile is small enough for
    // one: a zoom-0 or zoom-1 tile gets a point far out instead).
    const json& header = tile["header"];
    const Key& key = file_keys[i];
    const TileBounds bounds = terrainTileBounds({key.z, key.x, key.y});
    std::vector<GeodeticPoint> positions;
    for (std::size_t k = 0; k < u.size(); ++k) {
      positions.push_back(decodedPosition(bounds, header["minHeight"].get<float>(), header["maxHeight"].get<float>(),
                                          {u[k].get<std::uint16_t>(), v[k].get<std::uint16_t>(),
                                           tile["height"][k].get<std::uint16_t>()}));
    }
    std::vector<EcefPoint> ecef(positions.size());
    geodeticToEcef(positions, ecef);
    const EcefPoint centre{header["boundingSphereCenterX"], header["boundingSphereCenterY"],
                           header["boundingSphereCenterZ"]};
    for (const EcefPoint& p : ecef) {
      outside_sphere += std::hypot(p.x - centre.x, p.y - centre.y, p.z - centre.z) >
                        header["boundingSphereRadius"].get<double>();
    }
    const EcefPoint occlusion{header["horizonOcclusionPointX"], header["horizonOcclusionPointY"],
                              header["horizonOcclusionPointZ"]};
    if (std::hypot(occlusion.x, occlusion.y, occlusion.z) > 100) {
      far_points += 1;
      far_points_beyond_zoom_1 += key.z > 1;
      continue;
    }
    std::vector<EcefPoint> tested;
    for (std::size_t k = 0; k < ecef.size(); k += 7) tested.push_back(ecef[k]);
    seen_when_culled += test::cullByHorizonPoint(occlusion, tested).vertices_seen_when_culled;
  }
  CHECK(outside_sphere == 0);
  CHECK(seen_when_culled == 0);
  CHECK(far_points_beyond_zoom_1 == 0);
  MESSAGE(far_points << " tiles with the far occlusion point");
  CHECK(folded_further == 0);
  MESSAGE(folded << " of " << triangles << " triangles folded by rounding");
  CHECK(not_covered == 0);
  CHECK(wrong_edges == 0);
  CHECK(other_range == 0);
  CHECK(no_normals == 0);

  // Neighbours of one zoom hold the same vertices on their common side (same quantised
  // position and height against the same range: the same decoded bits in any client).
  std::size_t sides = 0, mismatched = 0;
  for (const auto& [key, tile] : tiles) {
    for (const bool east : {true, false}) {
      const auto other = tiles.find({key.z, key.x + (east ? 1 : 0), key.y + (east ? 0 : 1)});
      if (other == tiles.end()) continue;
      ++sides;
      mismatched += sideOf(*tile, east ? 2 : 3) != sideOf(*other->second, east ? 0 : 1);
    }
  }
  CHECK(sides >= 20);
  CHECK(mismatched == 0);
}

TEST_CASE("build --format quantized-mesh refuses what it cannot write, with exit 2") {
  test::TempDir dir;
  for (const std::vector<std::string>& extra : std::vector<std::vector<std::string>>{
           {"--scheme", "webmercator"}, {"--lod", "grid"}, {"--scheme", "geographic", "--implicit"}}) {
    std::vector<std::string> args{"build", test::sharedData("srtm3_N57E011_4326.tif"), "-o", dir / "out",
                                  "--format", "quantized-mesh"};
    args.insert(args.end(), extra.begin(), extra.end());
    const auto result = runTerratiles(args);
    CHECK(result.exit_code == 2);
    CHECK_MESSAGE(result.err.find("--format quantized-mesh takes the clusters' levels on the geographic scheme") !=
                      std::string::npos,
                  result.err);
    CHECK_FALSE(fs::exists(dir / "out"));
  }
}

namespace {

// checkInCesium on both rasters: N57E011 at 2 m (EGM96), Interlaken at 1 m (CHGeo2004).
void checkBothRastersInCesium(const std::string& format, const std::string& screenshot_suffix) {
  checkInCesium(format, test::sharedData("srtm3_N57E011_4326.tif"), {"--tin-max-error", "2"},
                "/usr/share/proj/egm96_15.gtx", "srtm_terrain" + screenshot_suffix);
  const std::string chgeo = test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif");
  checkInCesium(format, test::sharedData("ch_dhm25_interlaken_25m_2056.tif"), {"--tin-max-error", "1", "--geoid", chgeo},
                chgeo, "interlaken_terrain" + screenshot_suffix);
}

}  // namespace

TEST_CASE("CesiumJS takes the quantized-mesh layers of SRTM N57E011 and Interlaken as its terrain") {
  checkBothRastersInCesium("quantized-mesh", "");
}

TEST_CASE("CesiumJS takes the 3D Tiles terrain of SRTM N57E011 and Interlaken as its terrain") {
  checkBothRastersInCesium("terrain", "_3dtiles");
}

TEST_CASE("build --format quantized-mesh --fill ETOPO5: outside the data, ETOPO5's heights above EGM96") {
  test::TempDir dir;
  const std::string etopo5 = test::sharedData("etopo5_global_4326.tif");
  const std::string out = dir / "terrain";
  const auto built = runTerratiles({"build", test::sharedData("srtm3_N57E011_4326.tif"), "-o", out, "--format",
                                    "quantized-mesh", "--tin-max-error", "2", "--fill", etopo5, "-q"});
  REQUIRE_MESSAGE(built.exit_code == 0, built.err);
  // Zoom 0's eastern tile, far from the data: its fill grid point at 90 E 22.5 N (Bangladesh's
  // coast) against the four ETOPO5 pixels around it plus EGM96 there.
  const json tile = test::decodeQuantizedMeshFiles({out + "/0/1/0.terrain"}).front();
  const json& header = tile["header"];
  const TileBounds bounds = terrainTileBounds({0, 1, 0});
  std::size_t nearest = 0;
  double nearest_distance = 1e9;
  for (std::size_t k = 0; k < tile["u"].size(); ++k) {
    const GeodeticPoint p = decodedPosition(bounds, header["minHeight"], header["maxHeight"],
                                            {tile["u"][k].get<std::uint16_t>(), tile["v"][k].get<std::uint16_t>(),
                                             tile["height"][k].get<std::uint16_t>()});
    const double distance = std::hypot(p.lon_deg - 90, p.lat_deg - 22.5);
    if (distance < nearest_distance) {
      nearest_distance = distance;
      nearest = k;
    }
  }
  REQUIRE(nearest_distance < 0.01);
  const GeodeticPoint got = decodedPosition(bounds, header["minHeight"], header["maxHeight"],
                                            {tile["u"][nearest].get<std::uint16_t>(),
                                             tile["v"][nearest].get<std::uint16_t>(),
                                             tile["height"][nearest].get<std::uint16_t>()});
  const DemGrid dem = readDem({etopo5});
  const double x = (90 - dem.origin_x) / dem.pixel_size_x - 0.5, y = (dem.origin_y - 22.5) / dem.pixel_size_y - 0.5;
  double low = 1e9, high = -1e9;
  for (const int c : {static_cast<int>(std::floor(x)), static_cast<int>(std::floor(x)) + 1}) {
    for (const int r : {static_cast<int>(std::floor(y)), static_cast<int>(std::floor(y)) + 1}) {
      low = std::min(low, static_cast<double>(dem.heightAt(c, r)));
      high = std::max(high, static_cast<double>(dem.heightAt(c, r)));
    }
  }
  const double undulation = readGeoidGrid("/usr/share/proj/egm96_15.gtx").undulationAt(90, 22.5).value();
  const double step = (header["maxHeight"].get<double>() - header["minHeight"].get<double>()) / 32767;
  CHECK(got.height_m >= low + undulation - step);
  CHECK(got.height_m <= high + undulation + step);
  // The fill reaches the Himalaya: the zoom's heights span far more than the geoid's.
  CHECK(header["maxHeight"].get<double>() > 4000);

  // Refused: a fill without a terrain layer (exit 2), a fill raster not in longitude and
  // latitude (exit 3), before anything is written.
  const auto tileset = runTerratiles({"build", test::sharedData("srtm3_N57E011_4326.tif"), "-o", dir / "a", "--fill",
                                      etopo5});
  CHECK(tileset.exit_code == 2);
  CHECK(tileset.err.find("add --format quantized-mesh") != std::string::npos);
  const auto projected = runTerratiles({"build", test::sharedData("srtm3_N57E011_4326.tif"), "-o", dir / "b",
                                        "--format", "quantized-mesh", "--fill",
                                        test::sharedData("ch_dhm25_interlaken_25m_2056.tif")});
  CHECK(projected.exit_code == 3);
  CHECK(projected.err.find("the fill DEM is in EPSG:2056; expected WGS84 longitude and latitude") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "a"));
  CHECK_FALSE(fs::exists(dir / "b"));
}

TEST_CASE("build --format terrain: the quantized-mesh layer's tiles as 3D Tiles terrain, metadata true to each tile") {
  test::TempDir dir;
  const std::string raster = test::sharedData("srtm3_N57E011_4326.tif");
  const std::string out = dir / "terrain", layer = dir / "layer";
  const auto built = runTerratiles({"build", raster, "-o", out, "--format", "terrain", "--tin-max-error", "2", "-q"});
  REQUIRE_MESSAGE(built.exit_code == 0, built.err);
  REQUIRE(runTerratiles({"build", raster, "-o", layer, "--format", "quantized-mesh", "--tin-max-error", "2", "-q"})
              .exit_code == 0);
  std::ifstream tileset_file(out + "/tileset.json");
  const json tileset = json::parse(tileset_file);
  const json& zooms = tileset["extras"]["terratiles"]["zooms"];
  CHECK(tileset["asset"]["version"] == "1.1");
  // What Cesium3DTilesTerrainProvider reads: the two hemispheres' implicit quadtrees as the
  // root's children, west first, and the tile metadata by semantic.
  REQUIRE(tileset["root"]["children"].size() == 2);
  const char* hemispheres[2] = {"west", "east"};
  for (int h = 0; h < 2; ++h) {
    const json& child = tileset["root"]["children"][h];
    CHECK(child["implicitTiling"]["subdivisionScheme"] == "QUADTREE");
    CHECK(child["implicitTiling"]["availableLevels"] == zooms.size());
    CHECK(child["content"]["uri"] == std::string("tiles/") + hemispheres[h] + "/{level}/{x}/{y}.glb");
    CHECK(child["boundingVolume"]["region"][0].get<double>() == (h == 0 ? -std::numbers::pi : 0.0));
  }
  const json& properties = tileset["schema"]["classes"]["tile"]["properties"];
  const std::map<std::string, std::string> semantics{{"minimumHeight", "TILE_MINIMUM_HEIGHT"},
                                                     {"maximumHeight", "TILE_MAXIMUM_HEIGHT"},
                                                     {"boundingSphere", "TILE_BOUNDING_SPHERE"},
                                                     {"horizonOcclusionPoint", "TILE_HORIZON_OCCLUSION_POINT"},
                                                     {"geometricError", "TILE_GEOMETRIC_ERROR"}};
  for (const auto& [name, semantic] : semantics) CHECK(properties[name]["semantic"] == semantic);
  const std::map<std::string, std::size_t> components{
      {"minimumHeight", 1}, {"maximumHeight", 1}, {"boundingSphere", 4}, {"horizonOcclusionPoint", 3}, {"geometricError", 1}};
  const auto bytesOf = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    REQUIRE_MESSAGE(in, "no file " << path);
    return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
  };
  std::set<std::string> read;
  test::ImplicitTiles tiles;
  for (const char* h : hemispheres) {
    tiles.merge(test::readImplicitTiles([&](const std::string& path) { return bytesOf(out + "/" + path); }, h, 6,
                                        components, read));
  }

  // The same tiles as the quantized-mesh layer (TMS keys), each with content.
  std::set<std::string> layer_tiles, glb_tiles, implicit_tiles;
  for (const auto& entry : fs::recursive_directory_iterator(layer)) {
    if (entry.path().extension() == ".terrain") layer_tiles.insert(fs::relative(entry.path(), layer).replace_extension().string());
  }
  for (const auto& entry : fs::recursive_directory_iterator(out + "/tiles")) {
    if (entry.path().extension() == ".glb") glb_tiles.insert(fs::relative(entry.path(), out).string());
  }
  std::map<std::tuple<int, std::int64_t, std::int64_t>, test::TerrainGlbRead> decoded;  // TMS key -> tile
  for (const auto& [c, tile] : tiles) {
    CHECK(tile.content);
    const std::int64_t x = c.x + (c.hemisphere << c.level);
    implicit_tiles.insert(std::to_string(c.level) + "/" + std::to_string(x) + "/" + std::to_string(c.y));
    decoded.emplace(std::tuple{c.level, x, c.y}, test::readTerrainGlb(bytesOf(out + "/" + implicitFilePath("tiles", c, "glb"))));
  }
  CHECK(implicit_tiles == layer_tiles);
  const test::GltfValidation validation = test::validateGltfTree(out + "/tiles");
  CAPTURE(validation.report);
  REQUIRE_MESSAGE(validation.ran, "the glTF validator did not run: run the README test set-up");
  CHECK(validation.files == static_cast<int>(glb_tiles.size()));
  CHECK(validation.errors == 0);
  CHECK(validation.warnings == 0);
  CHECK(glb_tiles.size() == tiles.size());
  CHECK(tiles.size() == 33);

  // Every tile's metadata holds what it decodes to.
  const GeographicLib::Geocentric& earth = GeographicLib::Geocentric::WGS84();
  std::size_t tiles_culled_from_somewhere = 0;
  std::map<int, double> worst_tile_error, least_tile_error;
  for (const auto& [c, tile] : tiles) {
    CAPTURE(c.level);
    CAPTURE(c.x);
    CAPTURE(c.y);
    const test::TerrainGlbRead& glb = decoded.at({c.level, c.x + (c.hemisphere << c.level), c.y});
    const auto& p = tile.properties;
    double low = 1e300, high = -1e300;
    const EcefPoint centre{p.at("boundingSphere")[0], p.at("boundingSphere")[1], p.at("boundingSphere")[2]};
    for (const EcefPoint& v : glb.positions) {
      double lat = 0, lon = 0, h = 0;
      earth.Reverse(v.x, v.y, v.z, lat, lon, h);
      low = std::min(low, h);
      high = std::max(high, h);
      CHECK(std::hypot(v.x - centre.x, v.y - centre.y, v.z - centre.z) <= p.at("boundingSphere")[3]);
    }
    CHECK(std::fabs(p.at("minimumHeight")[0] - low) < 1e-6);
    CHECK(std::fabs(p.at("maximumHeight")[0] - high) < 1e-6);
    // Each tile's own measured error: within its zoom's (the level's); the zoom's worst tile
    // holds the level's worst pixel.
    const double zoom_error = zooms[c.level]["max_error_m"].get<double>();
    CHECK(p.at("geometricError")[0] <= zoom_error + 1e-9);
    double& worst_tile = worst_tile_error[c.level];
    worst_tile = std::max(worst_tile, p.at("geometricError")[0]);
    least_tile_error[c.level] = std::min(least_tile_error.count(c.level) ? least_tile_error[c.level] : 1e300,
                                         p.at("geometricError")[0]);
    const EcefPoint occlusion{p.at("horizonOcclusionPoint")[0], p.at("horizonOcclusionPoint")[1],
                              p.at("horizonOcclusionPoint")[2]};
    const test::HorizonCulling culling = test::cullByHorizonPoint(occlusion, glb.positions);
    CHECK(culling.vertices_seen_when_culled == 0);
    tiles_culled_from_somewhere += culling.cameras_culling > 0;
  }
  for (const auto& [zoom, worst] : worst_tile_error) {
    CAPTURE(zoom);
    CHECK(worst == doctest::Approx(zooms[zoom]["max_error_m"].get<double>()).epsilon(1e-12));
  }
  // Per tile, not per zoom: the finest zoom's tiles differ (1.48 .. 2.00 m at 2 m).
  const int finest = static_cast<int>(zooms.size()) - 1;
  MESSAGE("finest zoom's tile errors " << least_tile_error[finest] << " .. " << worst_tile_error[finest] << " m");
  CHECK(least_tile_error[finest] < worst_tile_error[finest] - 0.1);
  // Most points cull their tile from some of the cameras (a tile spanning too much of the globe
  // is seen by every camera near its horizon): not a far point everywhere.
  MESSAGE(tiles_culled_from_somewhere << " of " << tiles.size() << " tiles culled by their point from some camera");
  CHECK(tiles_culled_from_somewhere >= tiles.size() / 2);

  // Neighbours meet: the vertices on a shared side pair up in the edge lists' order and
  // decode to the same point (one lattice per zoom) up to the float32 rounding of q / 65535:
  // within 1 % of a step.
  std::size_t shared_sides = 0;
  double worst_m = 0;
  for (const auto& [key, glb] : decoded) {
    const auto [zoom, x, y] = key;
    const auto step = [](const test::TerrainGlbRead& t) {
      const auto m = test::tileTransform(t.glb.gltf);
      return std::hypot(m[0][0], m[1][0], m[2][0]) / 65535;
    };
    for (const auto& [other_key, mine, theirs] :
         {std::tuple{std::tuple{zoom, x + 1, y}, 2, 0}, std::tuple{std::tuple{zoom, x, y + 1}, 3, 1}}) {
      const auto neighbour = decoded.find(other_key);
      if (neighbour == decoded.end()) continue;
      ++shared_sides;
      const std::vector<std::uint32_t>& a = glb.edges[mine];  // east N->S, north W->E
      const std::vector<std::uint32_t>& b = neighbour->second.edges[theirs];  // west S->N, south E->W
      REQUIRE(a.size() == b.size());
      CHECK(step(glb) == doctest::Approx(step(neighbour->second)).epsilon(1e-12));
      const double tolerance = 0.01 * step(glb);
      for (std::size_t i = 0; i < a.size(); ++i) {
        const EcefPoint& pa = glb.positions[a[i]];
        const EcefPoint& pb = neighbour->second.positions[b[b.size() - 1 - i]];
        const double d = std::hypot(pa.x - pb.x, pa.y - pb.y, pa.z - pb.z);
        worst_m = std::max(worst_m, d / tolerance);
        CHECK(d <= tolerance);
      }
    }
  }
  MESSAGE("shared sides " << shared_sides << ", farthest pair at " << worst_m << " of its tolerance");
  CHECK(shared_sides >= 20);
}
