#pragma once
// Shared helpers for the tests: real data paths, temporary directories, small DEMs built in
// code, GeoTIFF writing, running the CLI in-process, and the Khronos glTF validator.

#include <array>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <span>
#include <tuple>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "src/dem/dem_grid.h"
#include "src/geo/crs_transform.h"
#include "src/pipeline/check_output.h"
#include "src/tiling/clip_to_tile.h"
#include "tileset/implicit_tileset.h"
#include "src/tin/measure_tin.h"

namespace terratiles::test {

// Path of a file in ../shared/data (the real rasters; see its README).
std::string sharedData(const std::string& relative);
std::string sourceDir();

// ../shared/data/reference/lv95_reference_points.csv (PROJ 9.1.1), one row per point: the
// numeric columns after the name, 0 E, 1 N, 2 H_LN02, 3 lon, 4 lat, 5 merc_x, 6 merc_y,
// 7-9 ECEF without geoid, 10 N_chgeo2004, 11 h_wgs84_geoid, 12-14 ECEF with geoid,
// 15 N_egm96, 16 h_besselH.
std::vector<std::vector<double>> lv95ReferenceRows();

class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

// A DEM in EPSG:2056 near Bern with `pixel_m` pixels and heights from `height(col, row)`
// (return NaN for nodata).
DemGrid makeDem(int width, int height, double pixel_m,
                const std::function<double(int col, int row)>& height_m);

// Writes `dem` as a Float32 GeoTIFF (nodata -9999); `with_crs` false leaves the CRS out.
void writeGeoTiff(const DemGrid& dem, const std::string& path, bool with_crs = true);

// measureTin of `mesh` as the build measures it: on the globe of `dem` (DemOnGlobe), heights
// orthometric above EGM96 unless `geoid_path` names another geoid grid.
TinErrorStatistics measureOnGlobe(const DemGrid& dem, const TinMesh& mesh, const std::string& geoid_path = "");

// The checks of a TIN built in blocks, read back from its file: one stitched mesh (no vertex
// twice, no edge in more than two triangles, so no crack or overlap along a block border) that
// holds every valid pixel within the bound. Returns its triangles as corner positions, each
// starting at its smallest corner (orientation kept), for comparisons.
std::set<std::array<double, 6>> checkStitchedTin(const std::string& path, const DemGrid& dem, double bound_m,
                                                 std::size_t uncovered_expected);

// The doctest checks of a seamless, honest output (`terratiles check`, no tolerance): at least
// two zooms and 300 cuts, no hole, nothing left out, every shared vertex exactly one
// position, no error above its geometricError, regions holding their content.
void checkSeamless(const CheckReport& report);

// Every figure and problem of two check reports, exactly (doctest checks).
void checkSameReport(const CheckReport& a, const CheckReport& b);

// Every regular file below `dir` whose path relative to it starts with one of `prefixes`
// (all when empty), as relative path -> bytes.
std::map<std::string, std::string> filesUnder(const std::filesystem::path& dir,
                                              const std::vector<std::string>& prefixes = {});

// A tileset read back by readTilesetTree, without the refine REPLACE every external tileset's
// root says (its parent file's tiles inherit it anyway): comparable with a single file's tree.
nlohmann::json withoutInnerRefine(nlohmann::json tileset);

struct CliResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};
CliResult runTerratiles(const std::vector<std::string>& args, const std::string& standard_input = "");

struct GltfValidation {
  int files = 0;
  int errors = 0;
  int warnings = 0;
  std::string report;  // the validator's summary lines
  bool ran = false;    // false when node or the npm package is missing
};
// Runs the Khronos glTF validator (npm gltf-validator, installed by the test set-up) on
// every .glb below `dir`.
GltfValidation validateGltfTree(const std::string& dir);

// Decodes quantized-mesh tiles with loaders.gl (tools/validators/decode_quantized_mesh.mjs,
// npm @loaders.gl/terrain from the test set-up): one JSON object per file, in order (see the
// script). REQUIREs that the decoder ran and decoded every file.
std::vector<nlohmann::json> decodeQuantizedMeshFiles(const std::vector<std::string>& files);

// A quantized-mesh horizon occlusion point (ellipsoid-scaled) against the vertices it stands
// for (ECEF): from 4000 cameras that see the vertices near their horizon (1 m to 3 Earth
// radii up, from 2 degrees nearer to 2 degrees farther than the horizon seen from over the
// point, all round it), how many see the point, how many cannot (CesiumJS's
// EllipsoidalOccluder.isScaledSpacePointVisible), and how many vertices the latter see anyway
// (0 for a sound point).
// A terrain tile's vertices on one side of its rectangle, as (lon, lat, height): its west
// (meridian, low side), east, south or north side. Two tiles that share a side must hold the
// same set there, bit for bit.
std::set<std::array<double, 3>> verticesOnSide(const TerrainTileMesh& tile, bool meridian, bool low_side);

// A real terrain tile: SRTM N57E011's TIN to `max_error_m` (or its grid every `grid_step`
// pixels when grid_step > 0) in longitude, latitude and the DEM's heights, with the
// ellipsoid's normals, in the rectangle of its outermost pixel centres (so the raster's
// border vertices lie on the tile's sides).
struct SrtmTerrainTile {
  TerrainTileMesh mesh;
  std::array<std::set<std::uint32_t>, 4> on_side;  // mesh vertices on the west, south, east, north side
};
SrtmTerrainTile srtmTerrainTile(double max_error_m, std::int32_t grid_step);

// Implicit tiling read back: the binary subtree layout (spec "Subtree Binary Format") checked
// and split, a view's bytes, availability bits, FLOAT64 property values.
struct Subtree {
  nlohmann::json json;
  std::vector<std::uint8_t> binary;
};
Subtree decodeSubtree(const std::vector<std::uint8_t>& bytes);
std::span<const std::uint8_t> viewBytes(const Subtree& subtree, std::size_t view);
// Bit `index` of an availability of `length_bits` bits: a constant or a bitstream of exactly
// ceil(length_bits / 8) bytes, least significant bit first, trailing bits 0.
bool availabilityBit(const Subtree& subtree, const nlohmann::json& availability, std::uint64_t length_bits,
                     std::uint64_t index);
double float64At(const Subtree& subtree, std::size_t view, std::size_t element);

// Every available tile of one hemisphere ("west", "east") and its FLOAT64 tile properties
// (name -> values per tile), read by walking its subtrees from the root subtree through child
// subtree availability; `file` gives a subtree's bytes by its path, `read` collects the paths.
struct ImplicitTileRead {
  bool content = false;
  std::map<std::string, std::vector<double>> properties;
};
struct ImplicitTileOrder {
  bool operator()(const ImplicitTileCoordinates& a, const ImplicitTileCoordinates& b) const {
    return std::tie(a.hemisphere, a.level, a.x, a.y) < std::tie(b.hemisphere, b.level, b.x, b.y);
  }
};
using ImplicitTiles = std::map<ImplicitTileCoordinates, ImplicitTileRead, ImplicitTileOrder>;
ImplicitTiles readImplicitTiles(const std::function<std::vector<std::uint8_t>(const std::string&)>& file,
                                const std::string& hemisphere, int subtree_levels,
                                const std::map<std::string, std::size_t>& property_components,
                                std::set<std::string>& read);

// A GLB read back: its JSON and binary chunks (the layout checked).
struct ParsedGlb {
  nlohmann::json gltf;
  std::vector<std::uint8_t> binary;
};
ParsedGlb parseGlb(const std::vector<std::uint8_t>& bytes);
// An accessor's elements decoded from its view's EXT_meshopt_compression data, without the
// filter (as CesiumJS reads them): count x byteStride bytes.
std::vector<std::uint8_t> decodeView(const ParsedGlb& glb, std::size_t accessor_index);
// An index accessor (meshopt-coded, 16 or 32 bits) decoded.
std::vector<std::uint32_t> indicesOf(const ParsedGlb& glb, std::size_t accessor_index);
// The first node's matrix after CesiumJS's Y-up to Z-up turn, (x, y, z) -> (x, -z, y): 3 rows.
std::array<std::array<double, 4>, 3> tileTransform(const nlohmann::json& gltf);
// A 3D Tiles terrain tile (encodeTerrainGlb's layout) decoded as Cesium3DTilesTerrainProvider
// decodes it: ECEF positions (value / 65535 as a float, then the matrix), triangles, and the
// CESIUM_tile_edges lists (west, south, east, north).
struct TerrainGlbRead {
  ParsedGlb glb;
  std::vector<EcefPoint> positions;
  std::vector<std::uint32_t> triangles;
  std::array<std::vector<std::uint32_t>, 4> edges;
};
TerrainGlbRead readTerrainGlb(const std::vector<std::uint8_t>& bytes);

struct HorizonCulling {
  std::size_t cameras_seeing = 0;
  std::size_t cameras_culling = 0;
  std::size_t vertices_seen_when_culled = 0;
};
HorizonCulling cullByHorizonPoint(const EcefPoint& occlusion_point, const std::vector<EcefPoint>& vertices);

}  // namespace terratiles::test
