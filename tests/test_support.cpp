#include "tests/test_support.h"

#include <doctest/doctest.h>
#include <gdal_priv.h>
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

}  // namespace terratiles::test
