// encodeTerrainGlb: 3D Tiles terrain tiles decoded the way CesiumJS's
// Cesium3DTilesTerrainGeometryProcessor decodes them (meshoptimizer's decoders, the node
// matrix, Y-up to Z-up), against the mesh they were made from; the Khronos glTF validator on
// the bytes. CesiumJS itself reads them in the browser test (tests/tools/cli_terrain_test.cpp).
#include <doctest/doctest.h>
#include <meshoptimizer.h>
#include <GeographicLib/Geocentric.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <set>

#include <nlohmann/json.hpp>

#include "formats/terrain_glb/write_terrain_glb.h"
#include "src/base/error.h"
#include "tests/test_support.h"

using namespace terratiles;
using nlohmann::json;
using test::decodeView;
using test::parseGlb;
using test::ParsedGlb;
using test::tileTransform;

namespace {

double distance(const EcefPoint& a, const EcefPoint& b) {
  return std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) + (a.z - b.z) * (a.z - b.z));
}

std::array<std::uint32_t, 3> canonical(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  // The same triangle, same winding, from its smallest index.
  if (b < a && b < c) return {b, c, a};
  if (c < a && c < b) return {c, a, b};
  return {a, b, c};
}

void checkTile(const test::SrtmTerrainTile& tile, const std::string& name) {
  CAPTURE(name);
  DecodedTerrainGlb written;
  const TerrainGlb result = encodeTerrainGlb(tile.mesh, "terratiles test", 0, &written);
  const ParsedGlb glb = parseGlb(result.bytes);
  const json& gltf = glb.gltf;
  CHECK(gltf["extensionsRequired"] == json({"EXT_meshopt_compression", "KHR_mesh_quantization"}));
  CHECK(std::find(gltf["extensionsUsed"].begin(), gltf["extensionsUsed"].end(), "CESIUM_tile_edges") !=
        gltf["extensionsUsed"].end());
  const json& primitive = gltf["meshes"][0]["primitives"][0];
  const std::size_t count = written.source_vertex.size();
  CHECK(result.vertices == count);

  // Positions: CesiumJS's arithmetic (value / 65535 as a float, the matrix in doubles) gives
  // what the encoder says, within half a step along each axis of the mesh's vertex.
  const std::vector<std::uint8_t> raw = decodeView(glb, primitive["attributes"]["POSITION"]);
  REQUIRE(raw.size() == count * 8);
  const auto t = tileTransform(gltf);
  for (int column = 0; column < 3; ++column) {
    const double length = std::hypot(t[0][column], t[1][column], t[2][column]);
    CHECK(length == doctest::Approx(result.position_step_m * 65535).epsilon(1e-9));
  }
  std::vector<GeodeticPoint> source(count);
  for (std::size_t i = 0; i < count; ++i) source[i] = tile.mesh.vertices[written.source_vertex[i]];
  std::vector<EcefPoint> source_ecef(count);
  geodeticToEcef(source, source_ecef);
  std::array<std::uint32_t, 3> q_min{65535, 65535, 65535}, q_max{0, 0, 0};
  for (std::size_t i = 0; i < count; ++i) {
    for (int a = 0; a < 3; ++a) {
      const std::uint32_t q = raw[8 * i + 2 * a] | raw[8 * i + 2 * a + 1] << 8;
      q_min[a] = std::min(q_min[a], q);
      q_max[a] = std::max(q_max[a], q);
    }
  }
  const test::TerrainGlbRead read = test::readTerrainGlb(result.bytes);
  const std::vector<EcefPoint>& positions = read.positions;
  REQUIRE(positions.size() == count);
  double worst_m = 0, worst_written_m = 0;
  for (std::size_t i = 0; i < count; ++i) {
    worst_m = std::max(worst_m, distance(positions[i], source_ecef[i]));
    worst_written_m = std::max(worst_written_m, distance(positions[i], written.positions[i]));
  }
  const json& position_accessor = gltf["accessors"][primitive["attributes"]["POSITION"].get<std::size_t>()];
  CHECK(position_accessor["min"] == json(q_min));
  CHECK(position_accessor["max"] == json(q_max));
  MESSAGE(name << ": step " << result.position_step_m << " m, farthest decoded vertex " << worst_m << " m");
  CHECK(worst_written_m < 1e-6);
  CHECK(worst_m <= result.position_step_m * std::sqrt(3.0) / 2 + 1e-6);

  // Triangles: the mesh's, each with its winding, in the written vertex order (the index
  // codec may start a triangle at another of its corners).
  const std::vector<std::uint32_t>& triangles = read.triangles;
  REQUIRE(triangles.size() == written.triangles.size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i + 2 < triangles.size(); i += 3) {
    differing += canonical(triangles[i], triangles[i + 1], triangles[i + 2]) !=
                 canonical(written.triangles[i], written.triangles[i + 1], written.triangles[i + 2]);
  }
  CHECK(differing == 0);
  CHECK(gltf["accessors"][primitive["indices"].get<std::size_t>()]["componentType"] ==
        (count <= 65535 ? 5123 : 5125));
  std::multiset<std::array<std::uint32_t, 3>> got, expected;
  for (std::size_t i = 0; i + 2 < triangles.size(); i += 3) {
    got.insert(canonical(written.source_vertex[triangles[i]], written.source_vertex[triangles[i + 1]],
                         written.source_vertex[triangles[i + 2]]));
  }
  for (std::size_t i = 0; i + 2 < tile.mesh.triangles.size(); i += 3) {
    expected.insert(canonical(tile.mesh.triangles[i], tile.mesh.triangles[i + 1], tile.mesh.triangles[i + 2]));
  }
  CHECK(got == expected);

  // Edges: exactly the vertices on each side, in the order CesiumJS's skirts take them.
  const char* names[4] = {"left", "bottom", "right", "top"};
  for (int side = 0; side < 4; ++side) {
    CAPTURE(names[side]);
    const std::vector<std::uint32_t>& edge = read.edges[side];
    CHECK(edge == written.edges[side]);
    std::set<std::uint32_t> on_side;
    for (const std::uint32_t v : edge) on_side.insert(written.source_vertex[v]);
    CHECK(on_side == tile.on_side[side]);
    CHECK(on_side.size() == edge.size());
    for (std::size_t i = 1; i < edge.size(); ++i) {
      const GeodeticPoint &a = source[edge[i - 1]], &b = source[edge[i]];
      if (side == 0) CHECK(a.lat_deg < b.lat_deg);  // south to north
      if (side == 1) CHECK(a.lon_deg > b.lon_deg);  // east to west
      if (side == 2) CHECK(a.lat_deg > b.lat_deg);  // north to south
      if (side == 3) CHECK(a.lon_deg < b.lon_deg);  // west to east
    }
  }

  // Normals as CesiumJS reads them (the octahedron's x and y in the first two bytes, turned
  // by the matrix), and as a glTF reader does through the OCTAHEDRAL filter: both within the
  // 8-bit octahedron's precision of the mesh's.
  std::vector<std::uint8_t> normals = decodeView(glb, primitive["attributes"]["NORMAL"]);
  REQUIRE(normals.size() == count * 4);
  double worst_cesium_deg = 0, worst_filter_deg = 0;
  const auto angle = [](const std::array<double, 3>& a, const std::array<float, 3>& b) {
    const double length = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    const double cosine = std::clamp((a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / length, -1.0, 1.0);
    return std::acos(cosine) * 180 / std::numbers::pi;
  };
  const auto turned = [&](double x, double y, double z) {
    return std::array<double, 3>{t[0][0] * x + t[0][1] * y + t[0][2] * z, t[1][0] * x + t[1][1] * y + t[1][2] * z,
                                 t[2][0] * x + t[2][1] * y + t[2][2] * z};
  };
  for (std::size_t i = 0; i < count; ++i) {
    double x = std::max(static_cast<std::int8_t>(normals[4 * i]) / 127.0, -1.0);
    double y = std::max(static_cast<std::int8_t>(normals[4 * i + 1]) / 127.0, -1.0);
    const double z = 1 - (std::fabs(x) + std::fabs(y));
    if (z < 0) {
      const double old_x = x;
      x = (1 - std::fabs(y)) * (old_x < 0 ? -1 : 1);
      y = (1 - std::fabs(old_x)) * (y < 0 ? -1 : 1);
    }
    worst_cesium_deg = std::max(worst_cesium_deg, angle(turned(x, y, z), tile.mesh.normals[written.source_vertex[i]]));
  }
  meshopt_decodeFilterOct(normals.data(), count, 4);
  for (std::size_t i = 0; i < count; ++i) {
    const auto* n = reinterpret_cast<const std::int8_t*>(normals.data() + 4 * i);
    worst_filter_deg = std::max(worst_filter_deg, angle(turned(n[0], n[1], n[2]), tile.mesh.normals[written.source_vertex[i]]));
  }
  MESSAGE(name << ": normals within " << worst_cesium_deg << " deg (CesiumJS), " << worst_filter_deg << " deg (filter)");
  CHECK(worst_cesium_deg < 1.0);
  CHECK(worst_filter_deg < 1.5);

  // The tile metadata holds what the tile decodes to.
  double low = 1e300, high = -1e300;
  for (const EcefPoint& p : positions) {
    CHECK(distance(p, result.culling.sphere_center) <= result.culling.sphere_radius_m);
    double lat = 0, lon = 0, h = 0;
    GeographicLib::Geocentric::WGS84().Reverse(p.x, p.y, p.z, lat, lon, h);
    low = std::min(low, h);
    high = std::max(high, h);
  }
  CHECK(std::fabs(result.minimum_height_m - low) < 1e-6);
  CHECK(std::fabs(result.maximum_height_m - high) < 1e-6);
  CHECK(result.minimum_height_m <= result.maximum_height_m);
  const test::HorizonCulling culling = test::cullByHorizonPoint(result.culling.horizon_occlusion_point, positions);
  CHECK(culling.cameras_culling > 1000);
  CHECK(culling.vertices_seen_when_culled == 0);

  // The Khronos validator: no error, no warning (it cannot decode meshopt, so it reads the
  // JSON: declarations, accessors, views, the matrix).
  test::TempDir dir;
  {
    std::ofstream out(dir / (name + ".glb"), std::ios::binary);
    out.write(reinterpret_cast<const char*>(result.bytes.data()), static_cast<std::streamsize>(result.bytes.size()));
  }
  const test::GltfValidation validation = test::validateGltfTree(dir.path().string());
  CAPTURE(validation.report);
  REQUIRE_MESSAGE(validation.ran, "the glTF validator did not run: run the README test set-up");
  CHECK(validation.errors == 0);
  CHECK(validation.warnings == 0);
}

}  // namespace

TEST_CASE("3D Tiles terrain tiles of a real TIN decode as CesiumJS decodes them") {
  checkTile(test::srtmTerrainTile(2, 0), "tin");
  checkTile(test::srtmTerrainTile(0, 4), "grid");  // 90601 vertices: 32-bit indices
}

TEST_CASE("3D Tiles terrain: bad tiles are refused with one line saying what and where") {
  const test::SrtmTerrainTile tile = test::srtmTerrainTile(20, 0);
  const auto refused = [](const TerrainTileMesh& mesh, const std::string& expected) {
    try {
      encodeTerrainGlb(mesh, "test");
      FAIL("accepted: " << expected);
    } catch (const Error& e) {
      CHECK(e.code() == ErrorCode::Input);
      CHECK_MESSAGE(std::string(e.what()).find(expected) != std::string::npos, e.what());
    }
  };
  TerrainTileMesh empty = tile.mesh;
  empty.triangles.clear();
  refused(empty, "3D Tiles terrain tile: 0 triangle indices; expected a positive multiple of 3");
  TerrainTileMesh bad_index = tile.mesh;
  bad_index.triangles[4] = static_cast<std::uint32_t>(bad_index.vertices.size());
  refused(bad_index, "triangle index " + std::to_string(bad_index.vertices.size()) + " for ");
  TerrainTileMesh outside = tile.mesh;
  outside.vertices[0].lon_deg = outside.rectangle.east + 1;
  refused(outside, "outside the rectangle");
  TerrainTileMesh normals = tile.mesh;
  normals.normals.pop_back();
  refused(normals, "normals for");
}
