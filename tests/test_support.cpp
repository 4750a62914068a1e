#include "tests/test_support.h"

#include <doctest/doctest.h>
#include <gdal_priv.h>
#include <meshoptimizer.h>
#include <ogr_spatialref.h>
#include <stdlib.h>

#include <algorithm>
#include <random>
#include <numbers>
#include <cmath>
#include <array>
#include <map>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <cstring>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/tin/tin_file.h"
#include "src/base/progress.h"
#include "src/geo/dem_on_globe.h"
#include "src/tin/build_tin.h"
#include "src/tin/grid_tin.h"
#include "tools/terratiles/run_cli.h"

namespace terratiles::test {

std::string sharedData(const std::string& relative) {
  return std::string(TERRATILES_SHARED_DATA_DIR) + "/" + relative;
}

std::string sourceDir() { return TERRATILES_SOURCE_DIR; }

std::vector<std::vector<double>> lv95ReferenceRows() {
  std::ifstream in(sharedData("reference/lv95_reference_points.csv"));
  std::vector<std::vector<double>> rows;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("name,", 0) == 0) continue;
    std::stringstream fields(line);
    std::string field;
    std::getline(fields, field, ',');  // the point's name
    std::vector<double> row;
    while (std::getline(fields, field, ',')) row.push_back(std::stod(field));
    rows.push_back(row);
  }
  return rows;
}

TinErrorStatistics measureOnGlobe(const DemGrid& dem, const TinMesh& mesh, const std::string& geoid_path) {
  const GeoidGrid geoid = readGeoidGrid(geoid_path.empty() ? kDefaultGeoidPath : geoid_path);
  const DemOnGlobe globe(dem, &geoid);
  std::vector<EcefPoint> ecef(mesh.vertices.size());
  globe.place(mesh.vertices, {}, ecef);
  return measureTin(globe, mesh, ecef);
}

TempDir::TempDir() {
  std::string pattern = (std::filesystem::temp_directory_path() / "terratiles-test-XXXXXX").string();
  char* made = mkdtemp(pattern.data());
  if (!made) throw std::runtime_error("mkdtemp failed");
  path_ = made;
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

DemGrid makeDem(int width, int height, double pixel_m,
                const std::function<double(int col, int row)>& height_m) {
  DemGrid dem;
  dem.width = width;
  dem.height = height;
  dem.origin_x = 2600000.0;
  dem.origin_y = 1200000.0;
  dem.pixel_size_x = pixel_m;
  dem.pixel_size_y = pixel_m;
  OGRSpatialReference srs;
  srs.importFromEPSG(2056);
  char* wkt = nullptr;
  srs.exportToWkt(&wkt);
  dem.crs_wkt = wkt;
  CPLFree(wkt);
  dem.crs_name = "EPSG:2056";
  dem.heights_m.resize(dem.pixelCount());
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      dem.heights_m[dem.index(col, row)] = static_cast<float>(height_m(col, row));
    }
  }
  return dem;
}

void writeGeoTiff(const DemGrid& dem, const std::string& path, bool with_crs) {
  GDALAllRegister();
  GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
  GDALDataset* ds = driver->Create(path.c_str(), dem.width, dem.height, 1, GDT_Float32, nullptr);
  double gt[6] = {dem.origin_x, dem.pixel_size_x, 0, dem.origin_y, 0, -dem.pixel_size_y};
  ds->SetGeoTransform(gt);
  if (with_crs) {
    OGRSpatialReference srs;
    srs.SetFromUserInput(dem.crs_wkt.c_str());
    ds->SetSpatialRef(&srs);
  }
  std::vector<float> values = dem.heights_m;
  for (float& v : values) {
    if (std::isnan(v)) v = -9999.0f;
  }
  GDALRasterBand* band = ds->GetRasterBand(1);
  band->SetNoDataValue(-9999.0);
  if (band->RasterIO(GF_Write, 0, 0, dem.width, dem.height, values.data(), dem.width, dem.height,
                     GDT_Float32, 0, 0, nullptr) != CE_None) {
    throw std::runtime_error("cannot write test GeoTIFF " + path);
  }
  GDALClose(ds);
}

std::map<std::string, std::string> filesUnder(const std::filesystem::path& dir, const std::vector<std::string>& prefixes) {
  std::map<std::string, std::string> files;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    const std::string relative = std::filesystem::relative(entry.path(), dir).generic_string();
    bool wanted = prefixes.empty();
    for (const std::string& prefix : prefixes) wanted = wanted || relative.rfind(prefix, 0) == 0;
    if (!wanted) continue;
    std::ifstream in(entry.path(), std::ios::binary);
    files[relative] = std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  return files;
}

nlohmann::json withoutInnerRefine(nlohmann::json tileset) {
  const std::function<void(nlohmann::json&, bool)> drop = [&](nlohmann::json& tile, bool root) {
    if (!root) tile.erase("refine");
    if (tile.contains("children")) {
      for (nlohmann::json& child : tile["children"]) drop(child, false);
    }
  };
  drop(tileset["root"], true);
  return tileset;
}

CliResult runTerratiles(const std::vector<std::string>& args, const std::string& standard_input) {
  std::vector<std::string> argv{"terratiles"};
  argv.insert(argv.end(), args.begin(), args.end());
  std::istringstream in(standard_input);
  std::ostringstream out, err;
  CliResult result;
  result.exit_code = runCli(argv, in, out, err);
  result.out = out.str();
  result.err = err.str();
  return result;
}

GltfValidation validateGltfTree(const std::string& dir) {
  GltfValidation result;
  const std::string script = sourceDir() + "/tools/validators/validate_gltf.mjs";
  const std::string command = "node '" + script + "' '" + dir + "' 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return result;
  std::array<char, 4096> buffer;
  while (fgets(buffer.data(), buffer.size(), pipe)) result.report += buffer.data();
  const int status = pclose(pipe);
  // Last line: "files N errors E warnings W".
  const auto at = result.report.rfind("files ");
  if (at != std::string::npos &&
      std::sscanf(result.report.c_str() + at, "files %d errors %d warnings %d", &result.files,
                  &result.errors, &result.warnings) == 3) {
    result.ran = true;
  }
  if (status != 0 && result.errors == 0) result.ran = false;
  return result;
}

std::vector<nlohmann::json> decodeQuantizedMeshFiles(const std::vector<std::string>& files) {
  REQUIRE(!files.empty());
  const std::string errors = files.front() + ".decoder-stderr";
  std::string command = "node '" + sourceDir() + "/tools/validators/decode_quantized_mesh.mjs'";
  for (const std::string& file : files) command += " '" + file + "'";
  FILE* pipe = popen((command + " 2>'" + errors + "'").c_str(), "r");
  REQUIRE(pipe);
  std::string output;
  std::array<char, 65536> buffer;
  while (fgets(buffer.data(), buffer.size(), pipe)) output += buffer.data();
  const int status = pclose(pipe);
  std::ifstream error_file(errors);
  const std::string error_text((std::istreambuf_iterator<char>(error_file)), std::istreambuf_iterator<char>());
  std::filesystem::remove(errors);
  REQUIRE_MESSAGE(status == 0, "the loaders.gl decoder failed (run the README test set-up): "
                                   << error_text.substr(0, 2000) << output.substr(0, 2000));
  std::vector<nlohmann::json> decoded;
  std::size_t start = 0;
  while (start < output.size()) {
    const std::size_t end = output.find('\n', start);
    decoded.push_back(nlohmann::json::parse(output.substr(start, end - start)));
    start = end == std::string::npos ? output.size() : end + 1;
  }
  REQUIRE(decoded.size() == files.size());
  return decoded;
}

namespace {
// CesiumJS's EllipsoidalOccluder.isScaledSpacePointVisible, seen from `camera` (scaled).
bool visibleFrom(const EcefPoint& camera, const EcefPoint& point) {
  const double vh_squared = camera.x * camera.x + camera.y * camera.y + camera.z * camera.z - 1;
  const EcefPoint vt{point.x - camera.x, point.y - camera.y, point.z - camera.z};
  const double vt_dot_vc = -(vt.x * camera.x + vt.y * camera.y + vt.z * camera.z);
  const double vt_squared = vt.x * vt.x + vt.y * vt.y + vt.z * vt.z;
  const bool occluded = vh_squared < 0 ? vt_dot_vc > 0
                                       : vt_dot_vc > vh_squared && vt_dot_vc * vt_dot_vc / vt_squared > vh_squared;
  return !occluded;
}
}  // namespace

std::set<std::array<double, 3>> verticesOnSide(const TerrainTileMesh& tile, bool meridian, bool low_side) {
  const TileBounds& r = tile.rectangle;
  const double line = meridian ? (low_side ? r.west : r.east) : (low_side ? r.south : r.north);
  std::set<std::array<double, 3>> found;
  for (const GeodeticPoint& p : tile.vertices) {
    if ((meridian ? p.lon_deg : p.lat_deg) == line) found.insert({p.lon_deg, p.lat_deg, p.height_m});
  }
  return found;
}

HorizonCulling cullByHorizonPoint(const EcefPoint& occlusion, const std::vector<EcefPoint>& vertices) {
  std::vector<EcefPoint> scaled;
  for (const EcefPoint& p : vertices) scaled.push_back({p.x / 6378137.0, p.y / 6378137.0, p.z / 6356752.3142451793});
  const double length = std::hypot(occlusion.x, occlusion.y, occlusion.z);
  const std::array<double, 3> d{occlusion.x / length, occlusion.y / length, occlusion.z / length};
  const std::array<double, 3> a =
      std::fabs(d[2]) < 0.9 ? std::array<double, 3>{0, 0, 1} : std::array<double, 3>{1, 0, 0};
  std::array<double, 3> e1{d[1] * a[2] - d[2] * a[1], d[2] * a[0] - d[0] * a[2], d[0] * a[1] - d[1] * a[0]};
  const double n = std::hypot(e1[0], e1[1], e1[2]);
  e1 = {e1[0] / n, e1[1] / n, e1[2] / n};
  const std::array<double, 3> e2{d[1] * e1[2] - d[2] * e1[1], d[2] * e1[0] - d[0] * e1[2], d[0] * e1[1] - d[1] * e1[0]};
  std::mt19937 random(7);
  std::uniform_real_distribution<double> up(1.0 + 1.0 / 6378137.0, 3.0), turn(0, 2 * std::numbers::pi),
      off(-2 * std::numbers::pi / 180, 2 * std::numbers::pi / 180);
  HorizonCulling result;
  for (int c = 0; c < 4000; ++c) {
    const double radius = up(random), azimuth = turn(random), theta = std::acos(1 / radius) + off(random);
    const double s = std::sin(theta), k = std::cos(theta);
    EcefPoint camera;
    camera.x = radius * (k * d[0] + s * (std::cos(azimuth) * e1[0] + std::sin(azimuth) * e2[0]));
    camera.y = radius * (k * d[1] + s * (std::cos(azimuth) * e1[1] + std::sin(azimuth) * e2[1]));
    camera.z = radius * (k * d[2] + s * (std::cos(azimuth) * e1[2] + std::sin(azimuth) * e2[2]));
    if (visibleFrom(camera, occlusion)) {
      ++result.cameras_seeing;
      continue;
    }
    ++result.cameras_culling;
    for (const EcefPoint& p : scaled) result.vertices_seen_when_culled += visibleFrom(camera, p);
  }
  return result;
}

std::set<std::array<double, 6>> checkStitchedTin(const std::string& path, const DemGrid& dem, double bound_m,
                                              std::size_t uncovered_expected) {
  const CrsTin tin = readTinFile(path);
  std::vector<std::array<double, 3>> positions = tin.positions;
  std::sort(positions.begin(), positions.end());
  CHECK(std::adjacent_find(positions.begin(), positions.end()) == positions.end());
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> uses;
  std::set<std::array<double, 6>> triangles;
  const auto& idx = tin.triangle_indices;
  for (std::size_t t = 0; t < idx.size(); t += 3) {
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = idx[t + k], b = idx[t + (k + 1) % 3];
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
    std::array<std::array<double, 2>, 3> corners;
    for (int k = 0; k < 3; ++k) corners[k] = {tin.positions[idx[t + k]][0], tin.positions[idx[t + k]][1]};
    const auto first = std::min_element(corners.begin(), corners.end()) - corners.begin();
    std::array<double, 6> key;
    for (int k = 0; k < 3; ++k) {
      key[2 * k] = corners[(first + k) % 3][0];
      key[2 * k + 1] = corners[(first + k) % 3][1];
    }
    triangles.insert(key);
  }
  std::size_t overused = 0;
  for (const auto& [edge, count] : uses) overused += count > 2;
  CHECK(overused == 0);
  const TinMesh mesh = toGridTin(tin, dem.origin_x, dem.origin_y, dem.pixel_size_x);
  const TinErrorStatistics errors = test::measureOnGlobe(dem, mesh);
  CHECK(errors.max_error_m <= bound_m + 1e-6);
  CHECK(errors.uncovered_valid_pixels == uncovered_expected);
  CHECK(errors.covered_nodata_pixels == 0);
  return triangles;
}


void checkSeamless(const CheckReport& report) {
  CHECK(report.zooms >= 2);
  CHECK(report.cuts >= 300);
  CHECK(report.cuts_with_holes == 0);
  CHECK(report.left_out_pixels == 0);
  CHECK(report.neighbour_pairs > 0);
  CHECK(report.missing_border_vertices == 0);
  // Outline vertices touching tiles share decode to exactly one position, whatever grid
  // each zoom uses.
  CHECK(report.shared_border_vertices > 0);
  CHECK(report.shared_vertex_gaps == 0);
  CHECK(report.worst_shared_vertex_gap_m == 0);
  CHECK(report.measured_pixels > 0);
  CHECK(report.overlap_pixels > 0);
  CHECK(report.overlap_disagreements == 0);
  CHECK(report.dishonest_errors == 0);
  CHECK(report.worst_error_ratio <= 1);
  CHECK(report.error_order_violations == 0);
  CHECK(report.region_violations == 0);
  CHECK(report.content_region_violations == 0);
  CHECK(report.ok());
}

// Every figure and problem of two check reports, exactly.
void checkSameReport(const CheckReport& a, const CheckReport& b) {
  CHECK(a.tiles == b.tiles);
  CHECK(a.zooms == b.zooms);
  CHECK(a.footprint_pixels == b.footprint_pixels);
  CHECK(a.uncovered_valid_pixels == b.uncovered_valid_pixels);
  CHECK(a.left_out_pixels == b.left_out_pixels);
  CHECK(a.pole_vertices == b.pole_vertices);
  CHECK(a.cuts == b.cuts);
  CHECK(a.cuts_with_holes == b.cuts_with_holes);
  CHECK(a.hole_pixels == b.hole_pixels);
  CHECK(a.unbalanced_cuts == b.unbalanced_cuts);
  CHECK(a.unbalanced_cuts_with_holes == b.unbalanced_cuts_with_holes);
  CHECK(a.unbalanced_hole_pixels == b.unbalanced_hole_pixels);
  CHECK(a.neighbour_pairs == b.neighbour_pairs);
  CHECK(a.missing_border_vertices == b.missing_border_vertices);
  CHECK(a.moved_outline_vertices == b.moved_outline_vertices);
  CHECK(a.shared_border_vertices == b.shared_border_vertices);
  CHECK(a.shared_vertex_gaps == b.shared_vertex_gaps);
  CHECK(a.worst_shared_vertex_gap_m == b.worst_shared_vertex_gap_m);
  CHECK(a.measured_pixels == b.measured_pixels);
  CHECK(a.overlap_pixels == b.overlap_pixels);
  CHECK(a.overlap_disagreements == b.overlap_disagreements);
  CHECK(a.worst_overlap_ratio == b.worst_overlap_ratio);
  CHECK(a.dishonest_errors == b.dishonest_errors);
  CHECK(a.worst_error_ratio == b.worst_error_ratio);
  CHECK(a.error_order_violations == b.error_order_violations);
  CHECK(a.region_violations == b.region_violations);
  CHECK(a.content_region_violations == b.content_region_violations);
  CHECK(a.problems == b.problems);
}

SrtmTerrainTile srtmTerrainTile(double max_error_m, std::int32_t grid_step) {
  const DemGrid dem = readDem({sharedData("srtm3_N57E011_4326.tif")});
  TinMesh tin;
  if (grid_step > 0) {
    tin = triangulateGrid(dem, grid_step);
  } else {
    Progress progress;
    TinOptions options;
    options.max_error_m = max_error_m;
    tin = buildTin(dem, options, progress);
  }
  SrtmTerrainTile tile;
  double last_col = 0, last_row = 0;
  for (const GridPoint& p : tin.vertices) {
    last_col = std::max(last_col, p.col);
    last_row = std::max(last_row, p.row);
  }
  for (std::uint32_t i = 0; i < tin.vertices.size(); ++i) {
    const GridPoint& p = tin.vertices[i];
    const CrsPoint at = dem.pixelCentre(p.col, p.row);
    tile.mesh.vertices.push_back({at.x, at.y, p.height_m});
    const double lon = at.x * std::numbers::pi / 180, lat = at.y * std::numbers::pi / 180;
    tile.mesh.normals.push_back({static_cast<float>(std::cos(lat) * std::cos(lon)),
                                 static_cast<float>(std::cos(lat) * std::sin(lon)), static_cast<float>(std::sin(lat))});
    if (p.col == 0) tile.on_side[0].insert(i);
    if (p.row == last_row) tile.on_side[1].insert(i);
    if (p.col == last_col) tile.on_side[2].insert(i);
    if (p.row == 0) tile.on_side[3].insert(i);
  }
  const CrsPoint north_west = dem.pixelCentre(0, 0), south_east = dem.pixelCentre(last_col, last_row);
  tile.mesh.rectangle = {north_west.x, south_east.y, south_east.x, north_west.y};
  tile.mesh.triangles = tin.triangle_indices;
  return tile;
}

std::uint64_t readLittleEndian(const std::vector<std::uint8_t>& bytes, std::size_t offset,
                               int size) {
  std::uint64_t value = 0;
  for (int i = size - 1; i >= 0; --i) value = value * 256 + bytes.at(offset + i);
  return value;
}

// Checks the binary subtree layout (spec "Subtree Binary Format") and splits it.
Subtree decodeSubtree(const std::vector<std::uint8_t>& bytes) {
  REQUIRE(bytes.size() >= 24);
  CHECK(std::string(bytes.begin(), bytes.begin() + 4) == "subt");
  CHECK(readLittleEndian(bytes, 4, 4) == 1);
  const std::uint64_t json_length = readLittleEndian(bytes, 8, 8);
  const std::uint64_t binary_length = readLittleEndian(bytes, 16, 8);
  CHECK(json_length % 8 == 0);
  CHECK(binary_length % 8 == 0);
  REQUIRE(24 + json_length + binary_length == bytes.size());
  Subtree subtree;
  const std::string text(bytes.begin() + 24, bytes.begin() + 24 + json_length);
  subtree.json = nlohmann::json::parse(text);
  subtree.binary.assign(bytes.begin() + 24 + json_length, bytes.end());
  // One internal buffer (no uri): the binary chunk.
  REQUIRE(subtree.json["buffers"].size() == 1);
  CHECK_FALSE(subtree.json["buffers"][0].contains("uri"));
  CHECK(subtree.json["buffers"][0]["byteLength"] == binary_length);
  for (const nlohmann::json& view : subtree.json["bufferViews"]) {
    CHECK(view["buffer"] == 0);
    CHECK(view["byteOffset"].get<std::uint64_t>() % 8 == 0);
    CHECK(view["byteOffset"].get<std::uint64_t>() + view["byteLength"].get<std::uint64_t>() <=
          binary_length);
  }
  return subtree;
}

std::span<const std::uint8_t> viewBytes(const Subtree& subtree, std::size_t view) {
  const nlohmann::json& json = subtree.json["bufferViews"].at(view);
  return std::span<const std::uint8_t>(subtree.binary)
      .subspan(json["byteOffset"].get<std::size_t>(), json["byteLength"].get<std::size_t>());
}

// Bit `index` of an availability of `length_bits` bits: a constant or a bitstream of
// exactly ceil(length_bits / 8) bytes, least significant bit first, trailing bits 0.
bool availabilityBit(const Subtree& subtree, const nlohmann::json& availability,
                     std::uint64_t length_bits, std::uint64_t index) {
  if (availability.contains("constant")) {
    CHECK_FALSE(availability.contains("bitstream"));
    return availability["constant"] == 1;
  }
  const auto bytes = viewBytes(subtree, availability["bitstream"].get<std::size_t>());
  REQUIRE(bytes.size() == (length_bits + 7) / 8);
  if (index == 0 && length_bits % 8 != 0) {
    CHECK((bytes.back() >> (length_bits % 8)) == 0);
  }
  return ((bytes[index / 8] >> (index % 8)) & 1) != 0;
}

double float64At(const Subtree& subtree, std::size_t view, std::size_t element) {
  const auto bytes = viewBytes(subtree, view);
  REQUIRE((element + 1) * 8 <= bytes.size());
  double value = 0;
  std::memcpy(&value, bytes.data() + element * 8, 8);  // the test host is little-endian
  return value;
}

// Column and row of a Morton index within its level: x takes the even bits, y the odd.
std::pair<std::int64_t, std::int64_t> fromMorton(std::uint64_t morton, int level) {
  std::int64_t x = 0;
  std::int64_t y = 0;
  for (int bit = level - 1; bit >= 0; --bit) {
    x = 2 * x + static_cast<std::int64_t>((morton >> (2 * bit)) & 1);
    y = 2 * y + static_cast<std::int64_t>((morton >> (2 * bit + 1)) & 1);
  }
  return {x, y};
}

ImplicitTiles readImplicitTiles(const std::function<std::vector<std::uint8_t>(const std::string&)>& file,
                                const std::string& hemisphere, int subtree_levels,
                                const std::map<std::string, std::size_t>& property_components,
                                std::set<std::string>& read) {
  ImplicitTiles tiles;
  std::uint64_t tile_bits = 0;
  for (int level = 0; level < subtree_levels; ++level) tile_bits += std::uint64_t{1} << (2 * level);
  const std::uint64_t child_bits = std::uint64_t{1} << (2 * subtree_levels);
  std::vector<std::tuple<int, std::int64_t, std::int64_t>> open{{0, 0, 0}};
  while (!open.empty()) {
    const auto [root_level, root_x, root_y] = open.back();
    open.pop_back();
    const std::string path = "subtrees/" + hemisphere + "/" + std::to_string(root_level) + "/" +
                             std::to_string(root_x) + "/" + std::to_string(root_y) + ".subtree";
    INFO(path);
    CHECK(read.insert(path).second);
    const Subtree subtree = decodeSubtree(file(path));
    const nlohmann::json& json = subtree.json;
    const nlohmann::json& table = json["propertyTables"].at(json["tileMetadata"].get<std::size_t>());
    CHECK(table["class"] == "tile");
    const bool has_content = json.contains("contentAvailability");
    // A subtree's root tile is available (it was reached as an available child subtree).
    CHECK(availabilityBit(subtree, json["tileAvailability"], tile_bits, 0));

    std::uint64_t bit = 0;
    std::size_t entity = 0;
    for (int level = 0; level < subtree_levels; ++level) {
      for (std::uint64_t morton = 0; morton < (std::uint64_t{1} << (2 * level)); ++morton, ++bit) {
        const bool available = availabilityBit(subtree, json["tileAvailability"], tile_bits, bit);
        const bool content = has_content && availabilityBit(subtree, json["contentAvailability"][0], tile_bits, bit);
        CHECK((available || !content));
        if (!available) continue;
        const auto [x, y] = fromMorton(morton, level);
        ImplicitTileRead tile;
        tile.content = content;
        for (const auto& [name, components] : property_components) {
          const std::size_t view = table["properties"][name]["values"];
          for (std::size_t i = 0; i < components; ++i) {
            tile.properties[name].push_back(float64At(subtree, view, components * entity + i));
          }
        }
        ++entity;
        const ImplicitTileCoordinates c{hemisphere == "east" ? 1 : 0, root_level + level, (root_x << level) + x,
                                        (root_y << level) + y};
        CHECK(tiles.emplace(c, std::move(tile)).second);
      }
    }
    CHECK(table["count"] == entity);
    for (const auto& [name, components] : property_components) {
      CHECK(viewBytes(subtree, table["properties"][name]["values"]).size() == 8 * components * entity);
    }
    for (std::uint64_t morton = 0; morton < child_bits; ++morton) {
      if (!availabilityBit(subtree, json["childSubtreeAvailability"], child_bits, morton)) continue;
      const auto [x, y] = fromMorton(morton, subtree_levels);
      open.emplace_back(root_level + subtree_levels, (root_x << subtree_levels) + x, (root_y << subtree_levels) + y);
    }
  }
  return tiles;
}

namespace {
std::uint32_t readUint32LittleEndian(const std::vector<std::uint8_t>& bytes, std::size_t at) {
  return bytes[at] | bytes[at + 1] << 8 | bytes[at + 2] << 16 | static_cast<std::uint32_t>(bytes[at + 3]) << 24;
}

}  // namespace

ParsedGlb parseGlb(const std::vector<std::uint8_t>& bytes) {
  REQUIRE(bytes.size() >= 28);
  REQUIRE(readUint32LittleEndian(bytes, 0) == 0x46546C67u);
  REQUIRE(readUint32LittleEndian(bytes, 4) == 2);
  REQUIRE(readUint32LittleEndian(bytes, 8) == bytes.size());
  const std::uint32_t json_length = readUint32LittleEndian(bytes, 12);
  REQUIRE(readUint32LittleEndian(bytes, 16) == 0x4E4F534Au);
  REQUIRE(json_length % 4 == 0);
  ParsedGlb glb;
  glb.gltf = nlohmann::json::parse(bytes.begin() + 20, bytes.begin() + 20 + json_length);
  const std::size_t bin = 20 + json_length;
  REQUIRE(readUint32LittleEndian(bytes, bin + 4) == 0x004E4942u);
  glb.binary.assign(bytes.begin() + static_cast<std::ptrdiff_t>(bin + 8),
                    bytes.begin() + static_cast<std::ptrdiff_t>(bin + 8 + readUint32LittleEndian(bytes, bin)));
  REQUIRE(bin + 8 + glb.binary.size() == bytes.size());
  return glb;
}

// An accessor's elements decoded from its view's EXT_meshopt_compression data, without the
// filter (as CesiumJS reads them): count x byteStride bytes.
std::vector<std::uint8_t> decodeView(const ParsedGlb& glb, std::size_t accessor_index) {
  const nlohmann::json& accessor = glb.gltf["accessors"][accessor_index];
  const nlohmann::json& meshopt = glb.gltf["bufferViews"][accessor["bufferView"].get<std::size_t>()]["extensions"]
                                ["EXT_meshopt_compression"];
  REQUIRE(meshopt["buffer"] == 0);
  const std::size_t count = meshopt["count"], stride = meshopt["byteStride"];
  CHECK(count == accessor["count"].get<std::size_t>());
  const std::uint8_t* data = glb.binary.data() + meshopt["byteOffset"].get<std::size_t>();
  const std::size_t size = meshopt["byteLength"];
  std::vector<std::uint8_t> out(count * stride);
  int status = -1;
  if (meshopt["mode"] == "ATTRIBUTES") status = meshopt_decodeVertexBuffer(out.data(), count, stride, data, size);
  if (meshopt["mode"] == "TRIANGLES") status = meshopt_decodeIndexBuffer(out.data(), count, stride, data, size);
  if (meshopt["mode"] == "INDICES") status = meshopt_decodeIndexSequence(out.data(), count, stride, data, size);
  REQUIRE(status == 0);
  return out;
}

std::vector<std::uint32_t> indicesOf(const ParsedGlb& glb, std::size_t accessor_index) {
  const std::vector<std::uint8_t> raw = decodeView(glb, accessor_index);
  const bool short_indices = glb.gltf["accessors"][accessor_index]["componentType"] == 5123;
  std::vector<std::uint32_t> indices(raw.size() / (short_indices ? 2 : 4));
  for (std::size_t i = 0; i < indices.size(); ++i) {
    indices[i] = short_indices ? static_cast<std::uint32_t>(raw[2 * i] | raw[2 * i + 1] << 8) : readUint32LittleEndian(raw, 4 * i);
  }
  return indices;
}

// The node matrix after CesiumJS's Y-up to Z-up turn, (x, y, z) -> (x, -z, y): rows of 4.
std::array<std::array<double, 4>, 3> tileTransform(const nlohmann::json& gltf) {
  const nlohmann::json& m = gltf["nodes"][0]["matrix"];  // column-major
  std::array<std::array<double, 4>, 3> t{};
  for (int column = 0; column < 4; ++column) {
    t[0][column] = m[4 * column + 0];
    t[1][column] = -m[4 * column + 2].get<double>();
    t[2][column] = m[4 * column + 1];
  }
  return t;
}

TerrainGlbRead readTerrainGlb(const std::vector<std::uint8_t>& bytes) {
  TerrainGlbRead tile;
  tile.glb = parseGlb(bytes);
  const nlohmann::json& primitive = tile.glb.gltf["meshes"][0]["primitives"][0];
  const std::vector<std::uint8_t> raw = decodeView(tile.glb, primitive["attributes"]["POSITION"]);
  const auto t = tileTransform(tile.glb.gltf);
  tile.positions.resize(raw.size() / 8);
  for (std::size_t i = 0; i < tile.positions.size(); ++i) {
    double f[3];
    for (int a = 0; a < 3; ++a) f[a] = static_cast<float>((raw[8 * i + 2 * a] | raw[8 * i + 2 * a + 1] << 8) / 65535.0);
    double p[3];
    for (int r = 0; r < 3; ++r) p[r] = t[r][0] * f[0] + t[r][1] * f[1] + t[r][2] * f[2] + t[r][3];
    tile.positions[i] = {p[0], p[1], p[2]};
  }
  tile.triangles = indicesOf(tile.glb, primitive["indices"]);
  const char* names[4] = {"left", "bottom", "right", "top"};
  for (int side = 0; side < 4; ++side) tile.edges[side] = indicesOf(tile.glb, primitive["extensions"]["CESIUM_tile_edges"][names[side]]);
  return tile;
}

}  // namespace terratiles::test
