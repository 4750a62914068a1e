#include <doctest/doctest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <random>
#include <set>

#include <nlohmann/json.hpp>

#include "formats/dem/read_dem.h"
#include "formats/quantized_mesh/write_quantized_mesh.h"
#include "src/base/error.h"
#include "src/base/progress.h"
#include "src/tin/build_tin.h"
#include "src/tin/grid_tin.h"
#include "tests/test_support.h"

using namespace terratiles;

namespace {

void writeFile(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

// CesiumJS's AttributeCompression.octDecodeInRange(x, y, 255).
std::array<double, 3> octDecode(int x, int y) {
  double ox = x / 255.0 * 2 - 1, oy = y / 255.0 * 2 - 1;
  const double oz = 1 - (std::fabs(ox) + std::fabs(oy));
  if (oz < 0) {
    const double px = ox;
    ox = (1 - std::fabs(oy)) * (px < 0 ? -1 : 1);
    oy = (1 - std::fabs(px)) * (oy < 0 ? -1 : 1);
  }
  const double length = std::sqrt(ox * ox + oy * oy + oz * oz);
  return {ox / length, oy / length, oz / length};
}

// Everything loaders.gl decodes from the tile matches what was encoded, and holds what a
// client relies on.
void checkDecoded(const nlohmann::json& got, const test::SrtmTerrainTile& tile, const DecodedTerrainTile& written,
                  const std::string& metadata) {
  INFO(got.value("file", std::string()));
  REQUIRE_FALSE(got.contains("error"));
  const std::size_t count = written.quantized.size();
  CHECK(got["end"].get<std::size_t>() == got["bytes"].get<std::size_t>());  // nothing left over
  // The header.
  const auto& header = got["header"];
  CHECK(header["centerX"].get<double>() == written.center.x);
  CHECK(header["centerZ"].get<double>() == written.center.z);
  CHECK(header["minHeight"].get<float>() == written.minimum_height_m);
  CHECK(header["maxHeight"].get<float>() == written.maximum_height_m);
  CHECK(header["boundingSphereRadius"].get<double>() == written.sphere_radius_m);
  CHECK(header["horizonOcclusionPointY"].get<double>() == written.horizon_occlusion_point.y);
  // Vertices and triangles, as written.
  REQUIRE(got["u"].size() == count);
  for (std::size_t i = 0; i < count; ++i) {
    REQUIRE(got["u"][i].get<int>() == written.quantized[i][0]);
    REQUIRE(got["v"][i].get<int>() == written.quantized[i][1]);
    REQUIRE(got["height"][i].get<int>() == written.quantized[i][2]);
  }
  REQUIRE(got["triangles"].get<std::vector<std::uint32_t>>() == written.triangles);
  CHECK(got["loader"]["vertices"].get<std::size_t>() == count);
  CHECK(got["loader"]["indices"].get<std::size_t>() == written.triangles.size());
  // Every mesh vertex is written once (the TIN uses them all) and decodes within half a
  // quantisation step of where it was.
  CHECK(count == tile.mesh.vertices.size());
  const TileBounds& r = tile.mesh.rectangle;
  const double step_lon = (r.east - r.west) / kQuantizedMax, step_lat = (r.north - r.south) / kQuantizedMax;
  const double step_h = (written.maximum_height_m - written.minimum_height_m) / static_cast<double>(kQuantizedMax);
  double worst_lon = 0, worst_lat = 0, worst_h = 0;
  std::vector<GeodeticPoint> decoded(count);
  for (std::size_t i = 0; i < count; ++i) {
    const std::array<std::uint16_t, 3> q{got["u"][i].get<std::uint16_t>(), got["v"][i].get<std::uint16_t>(),
                                         got["height"][i].get<std::uint16_t>()};
    decoded[i] = decodedPosition(r, header["minHeight"].get<float>(), header["maxHeight"].get<float>(), q);
    const GeodeticPoint& source = tile.mesh.vertices[written.source_vertex[i]];
    worst_lon = std::max(worst_lon, std::fabs(decoded[i].lon_deg - source.lon_deg) / step_lon);
    worst_lat = std::max(worst_lat, std::fabs(decoded[i].lat_deg - source.lat_deg) / step_lat);
    worst_h = std::max(worst_h, std::fabs(decoded[i].height_m - source.height_m) / step_h);
  }
  CHECK(worst_lon <= 0.5 + 1e-6);
  CHECK(worst_lat <= 0.5 + 1e-6);
  CHECK(worst_h <= 0.5 + 1e-6);
  // Triangles counter-clockwise seen from above in (u, v), none degenerate.
  std::size_t clockwise_or_flat = 0;
  for (std::size_t t = 0; t < written.triangles.size(); t += 3) {
    const auto& a = written.quantized[written.triangles[t]];
    const auto& b = written.quantized[written.triangles[t + 1]];
    const auto& c = written.quantized[written.triangles[t + 2]];
    const std::int64_t area2 = (std::int64_t{b[0]} - a[0]) * (std::int64_t{c[1]} - a[1]) -
                               (std::int64_t{b[1]} - a[1]) * (std::int64_t{c[0]} - a[0]);
    clockwise_or_flat += area2 <= 0;
  }
  CHECK(clockwise_or_flat == 0);
  // Each edge list holds exactly the mesh's vertices on that side, in order along it.
  const char* sides[] = {"west", "south", "east", "north"};
  for (int side = 0; side < 4; ++side) {
    INFO(sides[side]);
    const auto list = got[sides[side]].get<std::vector<std::uint32_t>>();
    std::set<std::uint32_t> listed;
    for (const std::uint32_t i : list) listed.insert(written.source_vertex[i]);
    CHECK(listed.size() == list.size());
    CHECK(listed == tile.on_side[static_cast<std::size_t>(side)]);
    const int along = side % 2 == 0 ? 1 : 0;
    for (std::size_t k = 1; k < list.size(); ++k) {
      CHECK(written.quantized[list[k - 1]][along] < written.quantized[list[k]][along]);
    }
    CHECK(list.size() >= 2);
  }
  // The bounding sphere holds every decoded vertex.
  std::vector<EcefPoint> ecef(count);
  geodeticToEcef(decoded, ecef);
  const EcefPoint centre{header["boundingSphereCenterX"].get<double>(), header["boundingSphereCenterY"].get<double>(),
                         header["boundingSphereCenterZ"].get<double>()};
  double farthest = 0;
  for (const EcefPoint& p : ecef) {
    farthest = std::max(farthest, std::hypot(p.x - centre.x, p.y - centre.y, p.z - centre.z));
  }
  CHECK(farthest <= header["boundingSphereRadius"].get<double>());
  // Horizon culling: from no camera that cannot see the occlusion point is a vertex in view
  // (tested on the sides' vertices and every 50th).
  const EcefPoint occlusion{header["horizonOcclusionPointX"].get<double>(),
                            header["horizonOcclusionPointY"].get<double>(),
                            header["horizonOcclusionPointZ"].get<double>()};
  std::vector<EcefPoint> tested;
  for (std::size_t i = 0; i < count; ++i) {
    const auto& q = written.quantized[i];
    if (i % 50 == 0 || q[0] == 0 || q[1] == 0 || q[0] == kQuantizedMax || q[1] == kQuantizedMax) {
      tested.push_back(ecef[i]);
    }
  }
  const test::HorizonCulling culling = test::cullByHorizonPoint(occlusion, tested);
  CHECK(culling.cameras_culling > 1000);
  CHECK(culling.cameras_seeing > 1000);
  CHECK(culling.vertices_seen_when_culled == 0);
  // Normals: within the 8-bit octahedron's precision (about 1 degree) of the given ones.
  REQUIRE(got["normals"].size() == 2 * count);
  double worst_degrees = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const auto n = octDecode(got["normals"][2 * i].get<int>(), got["normals"][2 * i + 1].get<int>());
    const auto& given = tile.mesh.normals[written.source_vertex[i]];
    const double cosine = std::clamp(n[0] * given[0] + n[1] * given[1] + n[2] * given[2], -1.0, 1.0);
    worst_degrees = std::max(worst_degrees, std::acos(cosine) * 180 / std::numbers::pi);
  }
  CHECK(worst_degrees < 1.0);
  // The extensions: the normals (1) and the metadata (4), its JSON as given.
  REQUIRE(got["extensions"].size() == 2);
  CHECK(got["extensions"][0]["id"] == 1);
  CHECK(got["extensions"][1]["id"] == 4);
  CHECK(got["extensions"][1]["json"] == nlohmann::json::parse(metadata));
}

}  // namespace

TEST_CASE("quantized-mesh tiles of a real TIN decode with loaders.gl as written") {
  test::TempDir dir;
  const std::string metadata = R"({"available":[[{"startX":0,"startY":0,"endX":1,"endY":1}]]})";
  QuantizedMeshOptions options;
  options.metadata_json = metadata;
  // SRTM N57E011's TIN at 5 m (16-bit indices), served gzip'd; its pixel grid every 4th pixel
  // (90601 vertices: 32-bit indices, with the padding before them), not compressed.
  const test::SrtmTerrainTile tin = test::srtmTerrainTile(5, 0), grid = test::srtmTerrainTile(0, 4);
  DecodedTerrainTile tin_written, grid_written;
  const auto tin_bytes = encodeQuantizedMesh(tin.mesh, options, &tin_written);
  const auto grid_bytes = encodeQuantizedMesh(grid.mesh, options, &grid_written);
  REQUIRE(tin_written.quantized.size() < 65536);
  REQUIRE(grid_written.quantized.size() > 65536);
  const auto tin_gzip = gzipBytes(tin_bytes);
  CHECK(tin_gzip.size() < tin_bytes.size());
  writeFile(dir / "tin.terrain", tin_gzip);
  writeFile(dir / "grid.terrain", grid_bytes);
  const auto decoded = test::decodeQuantizedMeshFiles({dir / "tin.terrain", dir / "grid.terrain"});
  REQUIRE(decoded.size() == 2);
  CHECK(decoded[0]["gzip"] == true);
  CHECK(decoded[0]["bytes"].get<std::size_t>() == tin_bytes.size());
  checkDecoded(decoded[0], tin, tin_written, metadata);
  checkDecoded(decoded[1], grid, grid_written, metadata);
}

TEST_CASE("quantized-mesh: a tile spanning a hemisphere still gets an occlusion point") {
  // Zoom 0's western tile, with vertices above the ellipsoid on its meridians 90 degrees from
  // its middle: no point every vertex is in front of exists; the fallback sits far out.
  TerrainTileMesh mesh;
  mesh.rectangle = {-180, -90, 0, 90};
  mesh.vertices = {{-180, -90, 0}, {0, -90, 0},     {0, 90, 0},  {-180, 90, 0},
                   {-180, 0, 1000}, {0, 0, 1000}, {-90, 0, 500}};
  mesh.triangles = {0, 1, 6, 1, 5, 6, 5, 2, 6, 2, 3, 6, 3, 4, 6, 4, 0, 6};
  DecodedTerrainTile written;
  encodeQuantizedMesh(mesh, {}, &written);
  EcefPoint unused;
  std::vector<EcefPoint> ecef(written.positions.size());
  geodeticToEcef(written.positions, ecef);
  CHECK_FALSE(horizonOcclusionPoint(written.sphere_center, ecef, unused));
  const EcefPoint& point = written.horizon_occlusion_point;
  CHECK(std::hypot(point.x, point.y, point.z) > 100);
  CHECK(written.edges[0].size() == 3);  // west: (-180, -90), (-180, 0), (-180, 90)
  CHECK(written.edges[3].size() == 2);  // north: (0, 90) and (-180, 90)
}

TEST_CASE("quantized-mesh: bad tiles are refused with one line saying what and where") {
  TerrainTileMesh mesh;
  mesh.rectangle = {11, 57, 12, 58};
  mesh.vertices = {{11, 57, 10}, {12, 57, 20}, {12, 58, 30}};
  mesh.triangles = {0, 1, 2};
  CHECK_NOTHROW(encodeQuantizedMesh(mesh, {}));
  const auto refused = [](const TerrainTileMesh& bad, const std::string& words) {
    try {
      encodeQuantizedMesh(bad, {});
      FAIL("not refused: " << words);
    } catch (const Error& error) {
      CHECK(error.code() == ErrorCode::Input);
      const std::string message = error.what();
      CHECK_MESSAGE(message.find(words) != std::string::npos, message);
      CHECK(message.find('\n') == std::string::npos);
    }
  };
  TerrainTileMesh outside = mesh;
  outside.vertices[2].lon_deg = 12.000001;
  refused(outside, "vertex 2 at (12.000001, 58, 30) is outside the tile's rectangle [11, 57, 12, 58]");
  TerrainTileMesh not_finite = mesh;
  not_finite.vertices[1].height_m = std::nan("");
  refused(not_finite, "vertex 1");
  TerrainTileMesh index = mesh;
  index.triangles[1] = 3;
  refused(index, "triangle 0 uses vertex 3; expected below the vertex count 3");
  TerrainTileMesh empty = mesh;
  empty.rectangle.east = 11;
  refused(empty, "is empty or outside the globe");
  TerrainTileMesh normals = mesh;
  normals.normals = {{0, 0, 1}};
  refused(normals, "1 normals for 3 vertices");
}
