#include "src/pipeline/check_output.h"

#include <GeographicLib/Geocentric.hpp>
#include <nlohmann/json.hpp>
#include <ogr_spatialref.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <bit>
#include <climits>
#include <cmath>
#include <filesystem>
#include <map>
#include <fstream>
#include <iomanip>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <random>
#include <span>
#include <sstream>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/gltf/read_glb.h"
#include "src/base/error.h"
#include "src/geo/dem_on_globe.h"
#include "src/geo/geoid.h"
#include "src/pipeline/drawn_tiles.h"
#include "src/base/largest_first.h"
#include "src/tiling/tile_key.h"
#include "src/tin/measure_tin.h"
#include "tileset/implicit_tileset.h"
#include "tileset/read_tileset.h"

namespace terratiles {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kRadToDeg = 180.0 / std::numbers::pi;
constexpr std::size_t kMaxProblems = 12;
// A decoded outline vertex is put back on its pixel centre when it decodes as near it as
// quantisation can move a DEM point (the widest step's half diagonal, plus 1 cm for the
// round trip through PROJ), and never from farther than this many pixels (of the pixel's
// north-south size, in both directions). A vertex a level
// moved (a simplifier's placement) may lie a hundredth of a pixel from a pixel centre, tens
// of metres on a coarse DEM: put back, it would seem to sit on a straight line of lattice
// points it is not on.
constexpr double kLatticeTolerance_px = 0.1;
constexpr double kRoundTripTolerance_m = 0.01;
constexpr double kPoleDeg = 90 - 1e-9;
constexpr std::uint32_t kNotOnOutline = std::numeric_limits<std::uint32_t>::max();

struct CheckTile {
  TileKey key;
  std::string uri;                // empty: no content
  double geometric_error_m = 0;
  std::array<double, 6> region{};  // west, south, east, north (rad), min, max height (m)
  int parent = -1;
  std::vector<int> children;
  // The rows of the DEM's grid its triangles span (as decoded), and its tallest triangle's.
  std::array<double, 2> rows{1e300, -1e300};
  std::int64_t tallest_rows = 0;
  // The decoded content against the DEM and the finer zoom: the largest errors over the strips,
  // the pixels summed over them (each in its own strip).
  DrawnTileMeasure measure;
  bool region_holds_content = true;
  std::string region_excess;  // when not: the bound the content passes most, and by how much
  // The content's outline: its vertices on boundary edges (an edge of one triangle), numbered
  // 0, 1, ... in the order of their index in the decoded mesh, in the grid frame (outline
  // vertices back on their pixel centres) and as decoded (ECEF), and those edges (into the
  // outline vertices, ascending). Only these are kept of a decoded tile.
  std::vector<std::array<double, 2>> vertex_grid;
  std::vector<std::uint8_t> vertex_at_pole;
  std::vector<std::array<double, 3>> vertex_ecef;
  std::vector<std::array<std::uint32_t, 2>> boundary_edges;
  // Lookups over the outline (outlineLookups): its vertices off the pole by grid position
  // (the first of equal positions), and its edges off the pole by the 8-pixel cells they
  // cross (cells by row then column; a cell's edges ascending).
  struct OutlinePoint {
    std::array<double, 2> grid;
    std::uint32_t vertex;
  };
  std::vector<OutlinePoint> outline_by_position;
  struct CellEdge {
    std::array<std::int64_t, 2> cell;
    std::uint32_t edge;
  };
  std::vector<CellEdge> edges_by_cell;
  std::size_t off_lattice = 0;  // outline vertices off their pixel centre by more than quantisation explains
  std::size_t pole_vertices = 0;
};

json readJson(const fs::path& path) {
  std::ifstream in(path);
  if (!in) {
    throw Error(ErrorCode::Input, path.string() + " cannot be read; expected a terratiles output directory "
                                                  "(tileset.json and build.json)");
  }
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    throw Error(ErrorCode::Input, path.string() + " is not valid JSON (" + e.what() + ")");
  }
}

int addTile(const json& node, int parent, std::vector<CheckTile>& tiles) {
  const int index = static_cast<int>(tiles.size());
  tiles.emplace_back();
  tiles[static_cast<std::size_t>(index)].parent = parent;
  tiles[static_cast<std::size_t>(index)].geometric_error_m = node.at("geometricError").get<double>();
  const json& region = node.at("boundingVolume").at("region");
  for (std::size_t k = 0; k < 6; ++k) tiles[static_cast<std::size_t>(index)].region[k] = region.at(k).get<double>();
  if (node.contains("content")) {
    const std::string uri = node["content"].at("uri").get<std::string>();
    tiles[static_cast<std::size_t>(index)].uri = uri;
    if (!tileKeyFromContentUri(uri, tiles[static_cast<std::size_t>(index)].key)) {
      throw Error(ErrorCode::Input, "tileset.json: content " + uri + " is not named tiles/z/x/y.glb; expected a "
                                                                      "terratiles output");
    }
  }
  if (node.contains("children")) {
    for (const json& child : node["children"]) {
      const int c = addTile(child, index, tiles);
      tiles[static_cast<std::size_t>(index)].children.push_back(c);
    }
  }
  CheckTile& tile = tiles[static_cast<std::size_t>(index)];
  if (tile.uri.empty()) {
    if (tile.children.empty()) throw Error(ErrorCode::Input, "tileset.json: a tile has neither content nor children");
    tile.key = tiles[static_cast<std::size_t>(tile.children.front())].key.parent();
  }
  return index;
}

// One transformation from WGS84 to the DEM's CRS per thread (GDAL's are not thread-safe).
class ToDemCrs {
 public:
  explicit ToDemCrs(const DemGrid& dem) {
    dem_crs_.importFromWkt(dem.crs_wkt.c_str());
    dem_crs_.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    wgs84_.importFromEPSG(4326);
    wgs84_.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  }
  bool geographic() const { return dem_crs_.IsGeographic(); }
  OGRCoordinateTransformation& local() {
    std::unique_ptr<OGRCoordinateTransformation>& transform = per_thread_.local();
    if (!transform) transform.reset(OGRCreateCoordinateTransformation(&wgs84_, &dem_crs_));
    if (!transform) throw Error(ErrorCode::Internal, "no transformation from WGS84 to the DEM's CRS");
    return *transform;
  }

 private:
  OGRSpatialReference dem_crs_, wgs84_;
  tbb::enumerable_thread_specific<std::unique_ptr<OGRCoordinateTransformation>> per_thread_;
};

// A DEM round the whole circle of longitude: where its first and last columns meet (the
// antimeridian of a global raster), a vertex may decode on either side of it. Near a pole a
// position step spans more than a column (ETOPO5 at 2.5': 1.7 m between row 0's columns, 2 m
// steps at the coarse zooms): a vertex of the last column can decode at longitude 180 exactly,
// which the wrap into the DEM's 360 degrees puts at column -0.5, the raster's width from its
// pixel, and its outline edges and triangles then span the whole grid (no pixel of the seam
// row between them is inside them in the grid; as drawn, the chords bulge poleward past it).
// The TIN has no triangle across the seam, so the vertex is on the side of its triangles'
// other corners (votes: +1 for a corner in the eastern half, -1 for one in the western); a
// vertex past the last column (col > width - 1) or before the first (col < 0) is moved by the
// width to that side. One with no such corner is left where it decoded.
void unwrapSeamVertices(std::int32_t width, std::span<const std::uint32_t> indices,
                        std::span<const std::uint8_t> at_pole, std::span<GridCorner> grid, std::vector<int>& votes) {
  const double last = width - 1.0;
  const auto pastAnEnd = [&](std::uint32_t v) { return !at_pole[v] && (grid[v].col < 0 || grid[v].col > last); };
  bool any = false;
  for (std::size_t v = 0; v < grid.size() && !any; ++v) any = pastAnEnd(static_cast<std::uint32_t>(v));
  if (!any) return;
  votes.assign(grid.size(), 0);
  for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
    for (std::size_t k = 0; k < 3; ++k) {
      const std::uint32_t v = indices[t + k];
      if (!pastAnEnd(v)) continue;
      for (std::size_t j = 0; j < 3; ++j) {
        const std::uint32_t u = indices[t + j];
        if (j == k || at_pole[u] || pastAnEnd(u)) continue;
        votes[v] += grid[u].col > width / 2.0 ? 1 : -1;
      }
    }
  }
  for (std::size_t v = 0; v < grid.size(); ++v) {
    if (!pastAnEnd(static_cast<std::uint32_t>(v))) continue;
    if (votes[v] > 0 && grid[v].col < 0) grid[v].col += width;
    if (votes[v] < 0 && grid[v].col > last) grid[v].col -= width;
  }
}

// Per thread scratch for decoding tiles, reused from tile to tile: the decoded tile (decodeTile)
// and what a strip makes of it (measureInStrip).
struct DecodeScratch {
  std::vector<double> xs, ys, zs;
  std::vector<int> transformed;
  std::vector<int> seam_votes;
  OutlineScratch outline;
  // The tile as decoded: ECEF (what a renderer draws), WGS84 as decoded (before the geoid), its
  // place in the DEM's grid (rows of the whole raster), at a pole or not; its triangles; its
  // outline edges (mesh indices) and outline vertices numbered in the order of their index.
  std::vector<EcefPoint> ecef;
  std::vector<GeodeticOfVertex> geodetic;
  std::vector<GridCorner> grid;
  std::vector<std::uint8_t> at_pole;
  std::vector<std::uint32_t> indices;
  std::vector<std::array<std::uint32_t, 2>> edges;
  std::vector<std::uint32_t> outline_index;     // per vertex: its outline number, or kNotOnOutline
  std::vector<std::uint32_t> outline_vertices;  // per outline vertex: its mesh index
  // In a strip: grid positions in the window's rows, with the outline back on pixel centres;
  // the pixels of the strip's own rows covered or met, each once (from the strip's first
  // row), and a bit per pixel of those rows: set while it is in `covered` (all clear between
  // tiles); a triangle's pixels inside it in the grid.
  std::vector<GridCorner> window_grid;
  std::vector<GridPoint> lattice;
  std::vector<std::uint32_t> covered;
  std::vector<std::uint64_t> in_covered;
  std::vector<std::uint32_t> triangle_pixels;
};

// Decodes a tile into `s` (see DecodeScratch): every vertex back from ECEF to the DEM's grid
// (`frame`: the whole raster's, its heights unused).
void decodeTile(const fs::path& dir, const DemGrid& frame, bool wraps_longitude, const GeoidGrid* geoid,
                ToDemCrs& to_dem, const std::string& uri, DecodeScratch& s) {
  DecodedGlb decoded = readGlbFile((dir / uri).string());
  GlbMesh& mesh = decoded.mesh;
  const auto& earth = GeographicLib::Geocentric::WGS84();
  const std::size_t n = mesh.vertexCount();
  s.ecef.resize(n);
  s.xs.resize(n);
  s.ys.resize(n);
  s.zs.resize(n);
  s.at_pole.assign(n, 0);
  s.geodetic.resize(n);
  for (std::size_t v = 0; v < n; ++v) {
    // glTF y-up back to ECEF z-up: what a renderer draws, in double.
    const double gx = mesh.translation[0] + mesh.positions[3 * v];
    const double gy = mesh.translation[1] + mesh.positions[3 * v + 1];
    const double gz = mesh.translation[2] + mesh.positions[3 * v + 2];
    s.ecef[v] = {gx, -gz, gy};
    double lat = 0, lon = 0, h = 0;
    earth.Reverse(s.ecef[v].x, s.ecef[v].y, s.ecef[v].z, lat, lon, h);
    s.geodetic[v] = {lat, lon, h};
    s.at_pole[v] = std::fabs(lat) >= kPoleDeg;
    if (geoid) {
      const std::optional<double> undulation = geoid->undulationAt(lon, lat);
      if (!undulation) throw Error(ErrorCode::Input, uri + ": a vertex lies outside the geoid grid");
      h -= *undulation;
    }
    s.xs[v] = lon;
    s.ys[v] = lat;
    s.zs[v] = h;
  }
  s.transformed.assign(n, 1);
  if (n > 0 && !to_dem.local().Transform(n, s.xs.data(), s.ys.data(), s.zs.data(), s.transformed.data())) {
    throw Error(ErrorCode::Input, uri + ": vertices cannot be transformed back to " + frame.crs_name);
  }
  // A geographic DEM: longitudes back into the DEM's 360 degrees (lon 180 and -180 are one
  // meridian).
  s.grid.resize(n);
  for (std::size_t v = 0; v < n; ++v) {
    if (to_dem.geographic()) {
      while (s.xs[v] < frame.origin_x) s.xs[v] += 360;
      while (s.xs[v] >= frame.origin_x + 360) s.xs[v] -= 360;
    }
    s.grid[v] = {(s.xs[v] - frame.origin_x) / frame.pixel_size_x - 0.5,
                 (frame.origin_y - s.ys[v]) / frame.pixel_size_y - 0.5, s.at_pole[v] != 0};
    if (s.at_pole[v]) s.grid[v].row = std::round(s.grid[v].row);  // the pole row; its column means nothing
  }
  s.indices = std::move(mesh.triangle_indices);
  if (to_dem.geographic() && wraps_longitude) unwrapSeamVertices(frame.width, s.indices, s.at_pole, s.grid, s.seam_votes);
  // The outline, its vertices numbered in the order of their mesh index.
  outlineEdges(s.indices, n, s.outline, s.edges);
  s.outline_index.assign(n, kNotOnOutline);
  for (const auto& edge : s.edges) s.outline_index[edge[0]] = s.outline_index[edge[1]] = 0;
  s.outline_vertices.clear();
  for (std::uint32_t v = 0; v < n; ++v) {
    if (s.outline_index[v] == kNotOnOutline) continue;
    s.outline_index[v] = static_cast<std::uint32_t>(s.outline_vertices.size());
    s.outline_vertices.push_back(v);
  }
}

// What a tile is apart from the DEM, from its decoding: its vertices at a pole, the rows its
// triangles span (and the tallest triangle's), whether its region holds its content, and its
// outline (vertex_grid as decoded; measureInStrip puts each vertex back on its pixel centre).
void describeTile(const fs::path& dir, const DemGrid& frame, bool wraps_longitude, const GeoidGrid* geoid,
                  ToDemCrs& to_dem, CheckTile& tile, DecodeScratch& s) {
  decodeTile(dir, frame, wraps_longitude, geoid, to_dem, tile.uri, s);
  tile.pole_vertices = static_cast<std::size_t>(std::count(s.at_pole.begin(), s.at_pole.end(), 1));
  // The rows every triangle spans (as writeZoomsInStrips takes them: the grid positions the
  // measure is given).
  double low = 1e300, high = -1e300;
  for (std::size_t t = 0; t + 2 < s.indices.size(); t += 3) {
    double a = 1e300, b = -1e300;
    for (std::size_t c = 0; c < 3; ++c) {
      a = std::min(a, s.grid[s.indices[t + c]].row);
      b = std::max(b, s.grid[s.indices[t + c]].row);
    }
    tile.tallest_rows = std::max(tile.tallest_rows, static_cast<std::int64_t>(std::ceil(b - a)));
    low = std::min(low, a);
    high = std::max(high, b);
  }
  tile.rows = {low, high};

  const Region content = drawnRegion(s.ecef, s.indices, s.geodetic);
  const auto& r = tile.region;
  tile.region_holds_content = content.empty || (content.west_rad >= r[0] && content.south_rad >= r[1] &&
                                                content.east_rad <= r[2] && content.north_rad <= r[3] &&
                                                content.min_height_m >= r[4] && content.max_height_m <= r[5]);
  if (!tile.region_holds_content) {
    // Metres on the ground for the angles (the mean radius), to name the worst bound.
    constexpr double kMetresPerRad = 6371000.0;
    const std::array<std::pair<const char*, double>, 6> excess{{{"west", (r[0] - content.west_rad) * kMetresPerRad},
                                                                {"south", (r[1] - content.south_rad) * kMetresPerRad},
                                                                {"east", (content.east_rad - r[2]) * kMetresPerRad},
                                                                {"north", (content.north_rad - r[3]) * kMetresPerRad},
                                                                {"lowest height", r[4] - content.min_height_m},
                                                                {"highest height", content.max_height_m - r[5]}}};
    const auto worst = std::max_element(excess.begin(), excess.end(),
                                        [](const auto& a, const auto& b) { return a.second < b.second; });
    char text[160];
    std::snprintf(text, sizeof text, " (%.6g m past its %s bound)", worst->second, worst->first);
    tile.region_excess = text;
  }

  const std::size_t m = s.outline_vertices.size();
  tile.boundary_edges.reserve(s.edges.size());
  for (const auto& edge : s.edges) tile.boundary_edges.push_back({s.outline_index[edge[0]], s.outline_index[edge[1]]});
  tile.vertex_grid.resize(m);
  tile.vertex_ecef.resize(m);
  tile.vertex_at_pole.resize(m);
  for (std::size_t k = 0; k < m; ++k) {
    const std::uint32_t v = s.outline_vertices[k];
    tile.vertex_grid[k] = {s.grid[v].col, s.grid[v].row};
    tile.vertex_ecef[k] = {s.ecef[v].x, s.ecef[v].y, s.ecef[v].z};
    tile.vertex_at_pole[k] = s.at_pole[v];
  }
}

// One strip of the DEM's rows, [first_row, end_row) of the raster, and the window read for it
// (from window_row; every row a triangle meeting the strip spans, and one more either side).
struct Strip {
  const DemOnGlobe& globe;  // the window's
  const PixelBoxes& boxes;
  std::int32_t raster_height = 0;
  std::int64_t window_row = 0;
  std::int64_t first_row = 0, end_row = 0;
  double widest_step_m = 0;
};

// A tile drawn over a strip (see the header): its outline back on pixel centres, its coverage
// in the grid and as drawn, its drawn error against the DEM and against the finer zoom's
// surface (adding its own to `surface`), each pixel counted in its own strip only. The outline
// vertices whose pixel row is the strip's are recorded in the tile (tile.vertex_grid,
// off_lattice). Leaves the covered pixels of the strip's own rows in s.covered (indices from
// the strip's first row, each once). Needs the finer zoom's surface of the window complete.
// `decoded`: the tile is in `s` already (describeTile has just decoded it).
void measureInStrip(const fs::path& dir, const DemGrid& frame, const GeoidGrid* geoid, ToDemCrs& to_dem,
                    const Strip& strip, const ZoomSurface* finer, ZoomSurface& surface, CheckTile& tile,
                    DecodeScratch& s, bool decoded) {
  const DemOnGlobe& globe = strip.globe;
  const DemGrid& dem = globe.dem();  // the window
  if (!decoded) decodeTile(dir, frame, globe.wrapsLongitude(), geoid, to_dem, tile.uri, s);
  const std::size_t n = s.grid.size();
  const double shift = static_cast<double>(strip.window_row);
  s.window_grid.resize(n);
  s.lattice.resize(n);
  for (std::size_t v = 0; v < n; ++v) {
    s.window_grid[v] = {s.grid[v].col, s.grid[v].row - shift, s.grid[v].at_pole};
    s.lattice[v] = {s.grid[v].col, s.grid[v].row - shift, 0};
  }

  // The outline back on its pixel centres, where the window has the spacings the tolerance
  // takes: the pixel's row and the next one (the window's last row has no row spacing), which
  // it has for every vertex of a triangle meeting the strip's rows.
  const std::int64_t height = strip.raster_height;
  const std::int64_t window_end = strip.window_row + dem.height;
  const double tolerance_m = 0.5 * std::sqrt(3.0) * strip.widest_step_m + kRoundTripTolerance_m;
  for (std::size_t k = 0; k < s.outline_vertices.size(); ++k) {
    const std::uint32_t v = s.outline_vertices[k];
    if (s.at_pole[v]) continue;
    // The nearest pixel centre: one inside the grid (a vertex half a column or row outside
    // it, as quantisation can decode one of the data's border vertices, is not put on a
    // column or row the DEM does not have).
    const double col = std::clamp(std::round(s.grid[v].col), 0.0, frame.width - 1.0);
    const double row = std::clamp(std::round(s.grid[v].row), 0.0, height - 1.0);
    const auto spacing_row = static_cast<std::int64_t>(row);
    const std::int64_t below = std::min(spacing_row, height - 2);  // the last row has none below
    if (spacing_row < strip.window_row || below + 1 >= window_end) continue;
    const bool own = spacing_row >= strip.first_row && spacing_row < strip.end_row;
    // The cap is a tenth of the pixel's north-south size in both directions: near a pole a
    // geographic DEM's columns are metres apart (6.8 m at 89.96 deg for 5'), closer than the
    // grid of a coarse zoom's outline snaps a vertex (half a step's diagonal), so a cap of a
    // tenth of a column would leave the data's own border vertices off their pixel centres.
    const double north_south_m = globe.rowSpacing(static_cast<std::int32_t>(below - strip.window_row));
    const auto window_spacing_row = static_cast<std::int32_t>(spacing_row - strip.window_row);
    const double column_tolerance_px =
        std::min(kLatticeTolerance_px * north_south_m, tolerance_m) / globe.columnSpacing(window_spacing_row);
    const double row_tolerance_px = std::min(kLatticeTolerance_px, tolerance_m / globe.rowSpacing(window_spacing_row));
    if (std::fabs(s.grid[v].col - col) > column_tolerance_px || std::fabs(s.grid[v].row - row) > row_tolerance_px) {
      if (own) ++tile.off_lattice;
      continue;
    }
    s.lattice[v].col = col;
    s.lattice[v].row = row - shift;
    if (own) tile.vertex_grid[k] = {col, row};
  }

  // Coverage: the pixels inside its triangles in the grid and the pixels whose verticals
  // meet its triangles as drawn (a triangle with a pole vertex has no place in the grid; a
  // long chord strays from its grid triangle by its bulge, far from a pole too). Only the
  // strip's own rows count, each pixel once: a finest zoom's pixel is met by several small
  // triangles, and a list with the repeats held 3-4 entries per pixel.
  const std::size_t first = static_cast<std::size_t>(strip.first_row - strip.window_row) * static_cast<std::size_t>(dem.width);
  const std::size_t end = static_cast<std::size_t>(strip.end_row - strip.window_row) * static_cast<std::size_t>(dem.width);
  std::vector<std::uint32_t>& covered = s.covered;
  covered.clear();
  if (s.in_covered.size() < (end - first + 63) / 64) s.in_covered.resize((end - first + 63) / 64, 0);
  const auto cover = [&](std::size_t pixel) {
    if (pixel < first || pixel >= end) return;
    const std::size_t own = pixel - first;
    std::uint64_t& word = s.in_covered[own / 64];
    const std::uint64_t bit = std::uint64_t{1} << (own % 64);
    if (word & bit) return;
    word |= bit;
    covered.push_back(static_cast<std::uint32_t>(own));
  };
  const auto rasterise = [&](const GridPoint& a, const GridPoint& b, const GridPoint& c) {
    s.triangle_pixels.clear();
    coveredValidPixels(dem, a, b, c, s.triangle_pixels);
    for (const std::uint32_t pixel : s.triangle_pixels) cover(pixel);
  };
  const auto& idx = s.indices;
  for (std::size_t t = 0; t + 2 < idx.size(); t += 3) {
    const std::uint32_t corner[3] = {idx[t], idx[t + 1], idx[t + 2]};
    const int poles = s.at_pole[corner[0]] + s.at_pole[corner[1]] + s.at_pole[corner[2]];
    if (poles == 0) {
      rasterise(s.lattice[corner[0]], s.lattice[corner[1]], s.lattice[corner[2]]);
      continue;
    }
    if (poles > 1) continue;
    // One corner at a pole: in the grid, the triangle is the quad between the other two
    // corners' meridians, from their edge to the pole row (a chord from a pole runs along a
    // meridian).
    int k = 0;
    while (!s.at_pole[corner[k]]) ++k;
    const GridPoint& v1 = s.lattice[corner[(k + 1) % 3]];
    const GridPoint& v2 = s.lattice[corner[(k + 2) % 3]];
    if (std::fabs(v1.col - v2.col) > dem.width / 2.0) continue;  // across the seam: left to the verticals
    const double pole_row = s.lattice[corner[k]].row;
    rasterise({v1.col, pole_row, 0}, {v2.col, pole_row, 0}, v2);
    rasterise({v1.col, pole_row, 0}, v2, v1);
  }
  // Errors as drawn, from the decoded corners (1 mm: PROJ's round trip of them); the pixels
  // met join its coverage, and those of the strip's own rows count as its hits.
  const DrawnTileMeasure measure =
      measureDrawnTile(globe, s.ecef, s.window_grid, idx, 1e-3, finer, &surface,
                       [&](std::size_t pixel) {
                         if (pixel < first || pixel >= end) return;
                         ++tile.measure.hits;
                         if (finer && finer->drawn(pixel)) ++tile.measure.finer_hits;
                         cover(pixel);
                       },
                       &strip.boxes);
  // The largest errors over the window are the tile's over the strip's rows or below them
  // (the window's other rows see part of the finer zoom's surface, whose difference is no
  // larger than all of it); its pixels are counted in their own strip.
  tile.measure.max_error_m = std::max(tile.measure.max_error_m, measure.max_error_m);
  tile.measure.finer_difference_m = std::max(tile.measure.finer_difference_m, measure.finer_difference_m);
  for (const std::uint32_t own : covered) s.in_covered[own / 64] &= ~(std::uint64_t{1} << (own % 64));
}

// Vertex correspondence (paper 5.2.3) between the contents of two tiles one zoom apart that
// a viewer may draw side by side: an outline vertex of one that lies on an outline edge of
// the other (in the grid, back on their pixel centres) must be a vertex of it. Returns the
// outline vertices that are not; vertices at a pole are left out (they have no column, and
// every pole triangle shares the one pole vertex).
constexpr double kOnEdge_px = 1e-6;
constexpr double kCell = 8;

// The lookups missingBorderVertices and sharedVertexGaps use (CheckTile::outline_by_position,
// edges_by_cell), built once per tile.
void outlineLookups(CheckTile& tile) {
  tile.outline_by_position.clear();
  for (std::uint32_t v = 0; v < tile.vertex_grid.size(); ++v) {
    if (!tile.vertex_at_pole[v]) tile.outline_by_position.push_back({tile.vertex_grid[v], v});
  }
  std::stable_sort(tile.outline_by_position.begin(), tile.outline_by_position.end(),
                   [](const CheckTile::OutlinePoint& p, const CheckTile::OutlinePoint& q) { return p.grid < q.grid; });
  tile.edges_by_cell.clear();
  for (std::size_t e = 0; e < tile.boundary_edges.size(); ++e) {
    if (tile.vertex_at_pole[tile.boundary_edges[e][0]] || tile.vertex_at_pole[tile.boundary_edges[e][1]]) continue;
    const auto& a = tile.vertex_grid[tile.boundary_edges[e][0]];
    const auto& b = tile.vertex_grid[tile.boundary_edges[e][1]];
    const auto c0 = static_cast<std::int64_t>(std::floor((std::min(a[0], b[0]) - kOnEdge_px) / kCell));
    const auto c1 = static_cast<std::int64_t>(std::floor((std::max(a[0], b[0]) + kOnEdge_px) / kCell));
    const auto r0 = static_cast<std::int64_t>(std::floor((std::min(a[1], b[1]) - kOnEdge_px) / kCell));
    const auto r1 = static_cast<std::int64_t>(std::floor((std::max(a[1], b[1]) + kOnEdge_px) / kCell));
    if ((c1 - c0 + 1) * (r1 - r0 + 1) > 4096) continue;  // a degenerate outline edge spanning the world
    for (std::int64_t r = r0; r <= r1; ++r) {
      for (std::int64_t c = c0; c <= c1; ++c) tile.edges_by_cell.push_back({{c, r}, static_cast<std::uint32_t>(e)});
    }
  }
  std::stable_sort(tile.edges_by_cell.begin(), tile.edges_by_cell.end(),
                   [](const CheckTile::CellEdge& p, const CheckTile::CellEdge& q) { return p.cell < q.cell; });
}

std::size_t missingBorderVertices(const CheckTile& from, const CheckTile& to, std::array<double, 2>* first_missing = nullptr) {
  // The other tile's outline edges by 8-pixel cell.
  const auto byCell = [](const CheckTile::CellEdge& p, const std::array<std::int64_t, 2>& cell) { return p.cell < cell; };
  std::size_t missing = 0;
  for (std::uint32_t v = 0; v < from.vertex_grid.size(); ++v) {
    if (from.vertex_at_pole[v]) continue;
    const auto& p = from.vertex_grid[v];
    const std::array<std::int64_t, 2> cell{static_cast<std::int64_t>(std::floor(p[0] / kCell)),
                                           static_cast<std::int64_t>(std::floor(p[1] / kCell))};
    bool on_edge = false, matched = false;
    for (auto it = std::lower_bound(to.edges_by_cell.begin(), to.edges_by_cell.end(), cell, byCell);
         it != to.edges_by_cell.end() && it->cell == cell; ++it) {
      const std::uint32_t ia = to.boundary_edges[it->edge][0], ib = to.boundary_edges[it->edge][1];
      const auto& a = to.vertex_grid[ia];
      const auto& b = to.vertex_grid[ib];
      const double ex = b[0] - a[0], ey = b[1] - a[1];
      const double length2 = ex * ex + ey * ey;
      const double t = length2 > 0 ? std::clamp(((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / length2, 0.0, 1.0) : 0;
      if (std::hypot(p[0] - (a[0] + t * ex), p[1] - (a[1] + t * ey)) > kOnEdge_px) continue;
      on_edge = true;
      for (const std::uint32_t end : {ia, ib}) {
        if (to.vertex_grid[end][0] == p[0] && to.vertex_grid[end][1] == p[1]) matched = true;
      }
    }
    if (on_edge && !matched && missing++ == 0 && first_missing) *first_missing = p;
  }
  return missing;
}

// Outline vertices two touching contents share (the same DEM point: back on one pixel centre
// in both) and how far apart they decode: nothing at all, or it is a gap.
struct SharedVertexGaps {
  std::size_t shared = 0;
  std::size_t apart = 0;
  double worst_m = 0;
};

SharedVertexGaps sharedVertexGaps(const CheckTile& a, const CheckTile& b) {
  SharedVertexGaps gaps;
  const auto byPosition = [](const CheckTile::OutlinePoint& p, const std::array<double, 2>& grid) { return p.grid < grid; };
  for (std::uint32_t v = 0; v < a.vertex_grid.size(); ++v) {
    if (a.vertex_at_pole[v]) continue;
    const auto found = std::lower_bound(b.outline_by_position.begin(), b.outline_by_position.end(), a.vertex_grid[v],
                                        byPosition);
    if (found == b.outline_by_position.end() || a.vertex_grid[v] < found->grid) continue;
    const auto& p = a.vertex_ecef[v];
    const auto& q = b.vertex_ecef[found->vertex];
    ++gaps.shared;
    if (p != q) {
      ++gaps.apart;
      gaps.worst_m = std::max(gaps.worst_m, std::hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]));
    }
  }
  return gaps;
}

bool touching(const TileKey& a, const TileKey& b) {
  const std::int32_t zoom = std::max(a.zoom, b.zoom);
  const auto span = [zoom](const TileKey& k, std::int32_t v) {
    const std::int64_t scale = std::int64_t{1} << (zoom - k.zoom);
    return std::array<std::int64_t, 2>{v * scale, (v + 1) * scale};
  };
  const auto ax = span(a, a.x), ay = span(a, a.y), bx = span(b, b.x), by = span(b, b.y);
  return ax[0] <= bx[1] && bx[0] <= ax[1] && ay[0] <= by[1] && by[0] <= ay[1];
}

// The first pair of drawn tiles that touch and are two or more zooms apart (indices into
// `cut`), or {-1, -1}.
std::array<int, 2> unbalancedPair(const std::vector<int>& cut, const std::vector<CheckTile>& tiles) {
  for (std::size_t i = 0; i < cut.size(); ++i) {
    for (std::size_t j = 0; j < cut.size(); ++j) {
      const TileKey& a = tiles[static_cast<std::size_t>(cut[i])].key;
      const TileKey& b = tiles[static_cast<std::size_t>(cut[j])].key;
      if (b.zoom >= a.zoom + 2 && touching(a, b)) return {static_cast<int>(i), static_cast<int>(j)};
    }
  }
  return {-1, -1};
}

// The pixels by the set of tiles covering them, refined one tile at a time (in any order).
// Class 0 is the empty set; class c > 0 is the set of class parent[c] (created before it)
// with tile[c] added. footprint_pixels[c]: the footprint pixels whose set is exactly class c's.
struct PixelClasses {
  explicit PixelClasses(std::size_t pixels) : class_of(pixels, 0) {}

  // Adds tile t, covering `pixels` (repeats allowed).
  void add(std::size_t t, const std::vector<std::uint32_t>& pixels) {
    const auto stamp = static_cast<std::uint32_t>(++tiles_added);
    for (const std::uint32_t p : pixels) {
      const std::uint32_t old = class_of[p];
      if (created_in[old] == stamp) continue;  // a repeat: moved by this tile already
      if (refined_in[old] != stamp) {
        refined_in[old] = stamp;
        refined[old] = static_cast<std::uint32_t>(parent.size());
        parent.push_back(old);
        tile.push_back(static_cast<std::uint32_t>(t));
        refined.push_back(0);
        refined_in.push_back(0);
        created_in.push_back(stamp);
      }
      class_of[p] = refined[old];
    }
  }

  // Counts the footprint's pixels per class and lets the per-pixel classes go.
  void countFootprint(const std::vector<std::uint8_t>& footprint) {
    footprint_pixels.assign(parent.size(), 0);
    for (std::size_t p = 0; p < footprint.size(); ++p) {
      if (footprint[p]) ++footprint_pixels[class_of[p]];
    }
    class_of = std::vector<std::uint32_t>();
  }

  std::vector<std::uint32_t> parent{0};
  std::vector<std::uint32_t> tile{0};
  std::vector<std::size_t> footprint_pixels;

 private:
  std::vector<std::uint32_t> class_of;
  // Per class: the class it became in the tile being added (valid where refined_in is its
  // stamp), and the stamp of the tile that created it.
  std::vector<std::uint32_t> refined{0}, refined_in{0}, created_in{0};
  std::size_t tiles_added = 0;
};

// The coverage classes of all strips (PixelClasses::countFootprint's figures of each), one
// strip's after the other's: class 0 is the empty set, each strip's other classes keep their
// parents (created before them) and tiles; a cut's holes are summed over them all.
struct CoverageClasses {
  void append(const PixelClasses& strip) {
    const std::size_t base = parent.size() - 1;  // a strip's class c > 0 becomes base + c
    footprint_pixels[0] += strip.footprint_pixels[0];
    for (std::size_t c = 1; c < strip.parent.size(); ++c) {
      parent.push_back(strip.parent[c] == 0 ? 0 : base + strip.parent[c]);
      tile.push_back(strip.tile[c]);
      footprint_pixels.push_back(strip.footprint_pixels[c]);
    }
  }

  std::vector<std::size_t> parent{0};
  std::vector<std::size_t> tile{0};
  std::vector<std::size_t> footprint_pixels{0};
};

bool isAncestor(int ancestor, int tile, const std::vector<CheckTile>& tiles) {
  for (int t = tile; t >= 0; t = tiles[static_cast<std::size_t>(t)].parent) {
    if (t == ancestor) return true;
  }
  return false;
}

std::string keyText(const TileKey& key) { return key.path(); }

}  // namespace

CheckReport checkOutput(const std::string& output_dir, const CheckOptions& options, Progress& progress) {
  const fs::path dir(output_dir);
  readJson(dir / "tileset.json");  // names a missing or broken file as the check always did
  const json tileset = readTilesetTree(dir / "tileset.json");  // external tilesets put in place
  const json build = readJson(dir / "build.json");
  CheckReport report;
  std::vector<CheckTile> tiles;
  // Implicit output: build.json holds the same tree as an explicit tileset.
  addTile(build.contains("explicit_tileset") ? build["explicit_tileset"].at("root") : tileset.at("root"), -1, tiles);

  if (options.strip_pixels <= 0) {
    throw Error(ErrorCode::Usage, "--strip-pixels is " + std::to_string(options.strip_pixels) +
                                      ", expected a positive number of pixels per strip (default 16000000)");
  }
  const std::vector<std::string> inputs = build.at("inputs").get<std::vector<std::string>>();
  const DemMosaic mosaic = scanDemMosaic(inputs, &progress);
  if (mosaic.width > INT32_MAX || mosaic.height > INT32_MAX) {
    throw Error(ErrorCode::Input, "the mosaic of the inputs is " + std::to_string(mosaic.width) + " x " +
                                      std::to_string(mosaic.height) + " pixels; at most 2^31 - 1 either way");
  }
  const auto width = static_cast<std::int32_t>(mosaic.width), height = static_cast<std::int32_t>(mosaic.height);
  // The whole raster's frame (where its grid lies, without its heights).
  DemGrid frame = readDemWindow(mosaic, {0, 0, width, 0});
  frame.height = height;
  progress.beginStage("reading the geoid", 0);
  std::optional<GeoidGrid> geoid;
  if (build.value("heights", std::string("orthometric")) == "orthometric") {
    geoid = readGeoidGrid(build.at("geoid").get<std::string>());
  }
  const GeoidGrid* geoid_grid = geoid ? &*geoid : nullptr;
  // Whether the DEM spans the whole circle of longitude, as DemOnGlobe decides it for the
  // whole raster: on its middle row.
  const bool wraps_longitude = [&] {
    const DemGrid middle = readDemWindow(mosaic, {0, height / 2, width, 1});
    return DemOnGlobe(middle, geoid_grid).wrapsLongitude();
  }();
  ToDemCrs to_dem(frame);
  progress.endStage();
  // The widest quantisation step any zoom used (an output without one: the lattice tolerance
  // alone bounds where a vertex is put back on its pixel centre).
  const double widest_step_m = build.value("position_step_m", 1e9);
  const auto problem = [&](const std::string& text) {
    if (report.problems.size() < kMaxProblems) report.problems.push_back(text);
  };

  // ---- 2. every tile decoded: its outline, region and rows; then measured strip by strip,
  //      finest zoom first (each against the finer zoom's drawn surface) ----
  std::int32_t min_zoom = 1 << 30, max_zoom = -1;
  for (const CheckTile& tile : tiles) {
    if (tile.uri.empty()) continue;
    ++report.tiles;
    min_zoom = std::min(min_zoom, tile.key.zoom);
    max_zoom = std::max(max_zoom, tile.key.zoom);
  }
  if (report.tiles == 0) throw Error(ErrorCode::Input, output_dir + ": tileset.json has no content");
  report.zooms = static_cast<std::size_t>(max_zoom - min_zoom + 1);
  // Per zoom, its tiles, the largest files first (a tile's work grows with its size).
  std::vector<std::vector<std::size_t>> at_zoom(static_cast<std::size_t>(max_zoom + 1));
  {
    std::vector<std::uintmax_t> bytes(tiles.size(), 0);
    for (std::size_t i = 0; i < tiles.size(); ++i) {
      if (tiles[i].uri.empty()) continue;
      std::error_code error;
      bytes[i] = fs::file_size(dir / tiles[i].uri, error);
      at_zoom[static_cast<std::size_t>(tiles[i].key.zoom)].push_back(i);
    }
    for (std::vector<std::size_t>& here : at_zoom) {
      std::stable_sort(here.begin(), here.end(), [&](std::size_t i, std::size_t j) { return bytes[i] > bytes[j]; });
    }
  }
  tbb::enumerable_thread_specific<DecodeScratch> scratch;
  // A raster whose pixels the strip budget holds is one strip, its window the whole raster
  // whatever the tallest triangle: every tile is then decoded once, described and measured
  // from the same decoding. Else every tile is described first (its rows, and the tallest
  // triangle's, size the strips' windows) and decoded again in every strip it meets.
  const bool one_strip = static_cast<std::int64_t>(width) * height <= options.strip_pixels;
  if (!one_strip) {
    progress.beginStage("decoding tiles", report.tiles);
    for (std::int32_t zoom = max_zoom; zoom >= min_zoom; --zoom) {
      const std::vector<std::size_t>& here = at_zoom[static_cast<std::size_t>(zoom)];
      forEachLargestFirst(here, [&](std::size_t i) {
        describeTile(dir, frame, wraps_longitude, geoid_grid, to_dem, tiles[i], scratch.local());
      });
      progress.advance(here.size());
    }
    progress.endStage();
  }

  // The strips, as writeZoomsInStrips makes them for the build: each strip of rows read with
  // every row a triangle meeting it spans (the tallest triangle's rows above and below, and
  // one more for the rows' spacings), placed on the globe, and every tile whose rows meet the
  // window drawn over it. Memory: the window's heights, points on the globe and two zooms'
  // surfaces (33 bytes per pixel for a WGS84 longitude and latitude DEM, 73 for another), and
  // per pixel of the strip its coverage (5 bytes), whatever the raster's size.
  // (One strip: its rows and window are the raster's, the tiles not yet described.)
  std::int64_t reach = height, strip_rows = height;
  if (!one_strip) {
    std::int64_t tallest = 0;
    for (const CheckTile& tile : tiles) tallest = std::max(tallest, tile.tallest_rows);
    reach = tallest + 2;
    strip_rows = std::max<std::int64_t>(16, options.strip_pixels / std::max(width, 1) - 2 * reach);
  }
  // The coverage classes of every strip, one after the other (class 0, the empty set, shared).
  CoverageClasses classes;
  std::size_t valid_pixels = 0;
  std::optional<std::array<std::int32_t, 2>> first_left_out;
  std::mutex classes_mutex;
  if (one_strip) {
    progress.beginStage("decoding and measuring tiles", report.tiles);
  } else {
    progress.beginStage("measuring tiles strip by strip", static_cast<std::uint64_t>((height + strip_rows - 1) / strip_rows));
  }
  for (std::int64_t r0 = 0; r0 < height; r0 += strip_rows) {
    const std::int64_t r1 = std::min<std::int64_t>(height, r0 + strip_rows);
    const std::int64_t w0 = std::max<std::int64_t>(0, r0 - reach), w1 = std::min<std::int64_t>(height, r1 + reach);
    const DemGrid window = readDemWindow(mosaic, {0, w0, width, static_cast<std::int32_t>(w1 - w0)});
    const DemOnGlobe globe(window, geoid_grid);
    const PixelBoxes boxes(globe);
    const Strip strip{globe, boxes, height, w0, r0, r1, widest_step_m};
    const std::size_t own_pixels = static_cast<std::size_t>(r1 - r0) * static_cast<std::size_t>(width);
    // The footprint: the valid pixels the finest zoom covers. The coverage classes take in each
    // zoom's tiles as soon as they are measured.
    std::vector<std::uint8_t> footprint(own_pixels, 0);
    PixelClasses strip_classes(own_pixels);
    const auto inWindow = [&](const std::array<double, 2>& rows) {
      return rows[1] >= static_cast<double>(w0) - 1 && rows[0] <= static_cast<double>(w1);
    };
    // Two surfaces' memory, swapped from zoom to zoom.
    std::array<ZoomSurface, 2> surfaces{ZoomSurface(window.pixelCount()), ZoomSurface(window.pixelCount())};
    for (std::int32_t zoom = max_zoom; zoom >= min_zoom; --zoom) {
      const auto k = static_cast<std::size_t>(max_zoom - zoom);
      ZoomSurface& surface = surfaces[k % 2];
      const ZoomSurface* finer = zoom < max_zoom ? &surfaces[(k + 1) % 2] : nullptr;
      if (k > 0) surface.clear();
      std::vector<std::size_t> here;
      for (const std::size_t i : at_zoom[static_cast<std::size_t>(zoom)]) {
        if (one_strip || inWindow(tiles[i].rows)) here.push_back(i);
      }
      forEachLargestFirst(here, [&](std::size_t i) {
        CheckTile& tile = tiles[i];
        DecodeScratch& s = scratch.local();
        if (one_strip) {
          describeTile(dir, frame, wraps_longitude, geoid_grid, to_dem, tile, s);
          if (!inWindow(tile.rows)) return;
        }
        measureInStrip(dir, frame, geoid_grid, to_dem, strip, finer, surface, tile, s, one_strip);
        // Into the classes in the order tiles finish: the classes differ in their numbering
        // only, every count made from them is the same.
        const std::lock_guard<std::mutex> lock(classes_mutex);
        if (zoom == max_zoom) {
          for (const std::uint32_t p : s.covered) footprint[p] = 1;
        }
        strip_classes.add(i, s.covered);
      });
      if (one_strip) progress.advance(at_zoom[static_cast<std::size_t>(zoom)].size());
    }
    // ---- 1. coverage of the strip's rows by the finest zoom ----
    for (std::int64_t row = r0; row < r1; ++row) {
      const auto window_row = static_cast<std::int32_t>(row - w0);
      for (std::int32_t col = 0; col < width; ++col) {
        const std::size_t p = static_cast<std::size_t>(row - r0) * static_cast<std::size_t>(width) + static_cast<std::size_t>(col);
        if (!window.isValid(col, window_row)) continue;
        ++valid_pixels;
        if (footprint[p]) {
          ++report.footprint_pixels;
          continue;
        }
        ++report.uncovered_valid_pixels;
        bool touches_nodata = false;
        for (int dr = -1; dr <= 1 && !touches_nodata; ++dr) {
          for (int dc = -1; dc <= 1; ++dc) {
            const std::int64_t r = row + dr;
            const int c = col + dc;
            if (r >= 0 && c >= 0 && r < height && c < width && !window.isValid(c, static_cast<std::int32_t>(r - w0))) {
              touches_nodata = true;
            }
          }
        }
        if (!touches_nodata && report.left_out_pixels++ == 0) first_left_out = {{col, static_cast<std::int32_t>(row)}};
      }
    }
    strip_classes.countFootprint(footprint);
    classes.append(strip_classes);
    if (!one_strip) progress.advance();
  }
  progress.endStage();
  if (valid_pixels == 0) {
    throw Error(ErrorCode::Input, mosaic.rasters.front().path +
                                      ": every pixel is nodata; expected a DEM with at least some valid heights");
  }

  for (const CheckTile& tile : tiles) {
    if (tile.uri.empty()) continue;
    report.measured_pixels += tile.measure.hits;
    report.overlap_pixels += tile.measure.finer_hits;
    report.pole_vertices += tile.pole_vertices;
    report.moved_outline_vertices += tile.off_lattice;
    if (tile.geometric_error_m > 0) {
      report.worst_error_ratio = std::max(report.worst_error_ratio, tile.measure.max_error_m / tile.geometric_error_m);
      report.worst_overlap_ratio =
          std::max(report.worst_overlap_ratio, tile.measure.finer_difference_m / tile.geometric_error_m);
    }
    if (tile.measure.max_error_m > tile.geometric_error_m) {
      ++report.dishonest_errors;
      problem("tile " + keyText(tile.key) + ": decoded error " + std::to_string(tile.measure.max_error_m) +
              " m > geometricError " + std::to_string(tile.geometric_error_m) + " m");
    }
    if (tile.measure.finer_difference_m > tile.geometric_error_m) {
      ++report.overlap_disagreements;
      problem("tile " + keyText(tile.key) + ": differs from the finer zoom by " +
              std::to_string(tile.measure.finer_difference_m) + " m where both are drawn, geometricError " +
              std::to_string(tile.geometric_error_m) + " m");
    }
    if (!tile.region_holds_content) {
      ++report.content_region_violations;
      problem("tile " + keyText(tile.key) + ": its content reaches outside its region" + tile.region_excess);
    }
  }
  for (const CheckTile& tile : tiles) {
    if (tile.parent < 0) continue;
    const CheckTile& parent = tiles[static_cast<std::size_t>(tile.parent)];
    if (tile.geometric_error_m > parent.geometric_error_m) {
      ++report.error_order_violations;
      problem("tile " + keyText(tile.key) + ": geometricError above its parent's");
    }
    const auto& r = tile.region;
    const auto& p = parent.region;
    if (r[0] < p[0] || r[1] < p[1] || r[2] > p[2] || r[3] > p[3] || r[4] < p[4] || r[5] > p[5]) {
      ++report.region_violations;
      problem("tile " + keyText(tile.key) + ": region outside its parent's");
    }
  }
  if (first_left_out) {
    problem("the finest zoom leaves out valid pixel (" + std::to_string((*first_left_out)[0]) + ", " +
            std::to_string((*first_left_out)[1]) + "), which does not touch nodata");
  }

  // ---- 1. coverage of cuts ----
  // The footprint pixels by the set of tiles whose content covers them, exactly (partition
  // refinement: a class is a set of tiles, made from its parent class by one tile more), so a
  // cut is counted per class instead of per pixel: a pixel is a hole of a cut when no tile of
  // its class is in the cut.
  std::vector<std::uint8_t> in_cut(tiles.size(), 0), class_covered(classes.parent.size(), 0);
  const auto holesOf = [&](const std::vector<int>& cut) {
    for (const int t : cut) in_cut[static_cast<std::size_t>(t)] = 1;
    std::size_t holes = 0;
    for (std::size_t c = 0; c < classes.parent.size(); ++c) {
      class_covered[c] = c > 0 && (class_covered[classes.parent[c]] || in_cut[classes.tile[c]]);
      if (!class_covered[c]) holes += classes.footprint_pixels[c];
    }
    for (const int t : cut) in_cut[static_cast<std::size_t>(t)] = 0;
    return holes;
  };
  const auto describeCut = [&](const std::vector<int>& cut) {
    std::map<std::int32_t, int> per_zoom;
    for (const int t : cut) ++per_zoom[tiles[static_cast<std::size_t>(t)].key.zoom];
    std::string text;
    for (const auto& [zoom, count] : per_zoom) text += (text.empty() ? "" : ", ") + std::to_string(count) + " at zoom " + std::to_string(zoom);
    return text;
  };
  const auto balancedHoles = [&](const std::vector<int>& cut) {
    const std::size_t holes = holesOf(cut);
    ++report.cuts;
    if (holes > 0) {
      ++report.cuts_with_holes;
      report.hole_pixels += holes;
      problem("a cut (" + describeCut(cut) + ") leaves " + std::to_string(holes) + " footprint pixels uncovered");
    }
  };
  progress.beginStage("coverage of cuts", options.cuts + report.zooms);
  for (std::int32_t zoom = min_zoom; zoom <= max_zoom; ++zoom) {
    std::vector<int> cut;
    for (std::size_t t = 0; t < tiles.size(); ++t) {
      if (!tiles[t].uri.empty() && tiles[t].key.zoom == zoom) cut.push_back(static_cast<int>(t));
    }
    balancedHoles(cut);
    progress.advance();
  }
  std::mt19937 random(options.seed);
  for (std::size_t c = 0; c < options.cuts; ++c) {
    const double refine = std::uniform_real_distribution<double>(0.2, 0.9)(random);
    std::vector<int> cut, open{0};
    while (!open.empty()) {
      const int t = open.back();
      open.pop_back();
      const CheckTile& tile = tiles[static_cast<std::size_t>(t)];
      const bool must_refine = tile.uri.empty();
      if (!tile.children.empty() && (must_refine || std::uniform_real_distribution<double>(0, 1)(random) < refine)) {
        open.insert(open.end(), tile.children.begin(), tile.children.end());
      } else if (!tile.uri.empty()) {
        cut.push_back(t);
      }
    }
    if (unbalancedPair(cut, tiles)[0] >= 0) {
      const std::size_t holes = holesOf(cut);
      ++report.unbalanced_cuts;
      report.unbalanced_cuts_with_holes += holes > 0;
      report.unbalanced_hole_pixels += holes;
    }
    // Balance: where a tile touches one two or more zooms finer, draw the finer one's
    // ancestor one zoom below the coarse tile instead of everything under it.
    for (std::array<int, 2> pair = unbalancedPair(cut, tiles); pair[0] >= 0; pair = unbalancedPair(cut, tiles)) {
      const std::int32_t coarse_zoom = tiles[static_cast<std::size_t>(cut[static_cast<std::size_t>(pair[0])])].key.zoom;
      int ancestor = cut[static_cast<std::size_t>(pair[1])];
      while (tiles[static_cast<std::size_t>(ancestor)].key.zoom > coarse_zoom + 1) {
        ancestor = tiles[static_cast<std::size_t>(ancestor)].parent;
      }
      std::erase_if(cut, [&](int t) { return isAncestor(ancestor, t, tiles); });
      cut.push_back(ancestor);
    }
    balancedHoles(cut);
    progress.advance();
  }
  progress.endStage();

  // ---- 3. vertex correspondence between touching tiles one zoom apart, and the decoded
  //      positions of the outline vertices touching tiles share ----
  {
    progress.beginStage("vertex correspondence", 0);
    tbb::parallel_for(std::size_t{0}, tiles.size(), [&](std::size_t i) { outlineLookups(tiles[i]); });
    std::vector<std::array<int, 2>> pairs;  // one zoom apart (not parent and child) or neighbours at one zoom
    for (std::size_t i = 0; i < tiles.size(); ++i) {
      for (std::size_t j = 0; j < tiles.size(); ++j) {
        if (tiles[i].uri.empty() || tiles[j].uri.empty() || !touching(tiles[i].key, tiles[j].key)) continue;
        const bool one_zoom_apart = tiles[j].key.zoom == tiles[i].key.zoom + 1 &&
                                    !isAncestor(static_cast<int>(i), static_cast<int>(j), tiles);
        const bool same_zoom = tiles[j].key.zoom == tiles[i].key.zoom && i < j;
        if (one_zoom_apart || same_zoom) pairs.push_back({static_cast<int>(i), static_cast<int>(j)});
      }
    }
    std::vector<std::size_t> missing(pairs.size(), 0);
    std::vector<SharedVertexGaps> gaps(pairs.size());
    std::vector<std::array<double, 2>> first_missing(pairs.size());
    tbb::parallel_for(std::size_t{0}, pairs.size(), [&](std::size_t k) {
      const CheckTile& a = tiles[static_cast<std::size_t>(pairs[k][0])];
      const CheckTile& b = tiles[static_cast<std::size_t>(pairs[k][1])];
      gaps[k] = sharedVertexGaps(a, b);
      if (a.key.zoom != b.key.zoom) {
        missing[k] = missingBorderVertices(a, b, &first_missing[k]);
        missing[k] += missingBorderVertices(b, a, missing[k] ? nullptr : &first_missing[k]);
      }
    });
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      const CheckTile& a = tiles[static_cast<std::size_t>(pairs[k][0])];
      const CheckTile& b = tiles[static_cast<std::size_t>(pairs[k][1])];
      if (a.key.zoom != b.key.zoom) ++report.neighbour_pairs;
      report.missing_border_vertices += missing[k];
      if (missing[k] > 0) {
        problem("tiles " + keyText(a.key) + " and " + keyText(b.key) + ": " + std::to_string(missing[k]) +
                " outline vertices of one lie on an outline edge of the other without a vertex there (first at pixel " +
                std::to_string(first_missing[k][0]) + ", " + std::to_string(first_missing[k][1]) + ")");
      }
      report.shared_border_vertices += gaps[k].shared;
      report.shared_vertex_gaps += gaps[k].apart;
      report.worst_shared_vertex_gap_m = std::max(report.worst_shared_vertex_gap_m, gaps[k].worst_m);
      if (gaps[k].apart > 0) {
        problem("tiles " + keyText(a.key) + " and " + keyText(b.key) + ": " + std::to_string(gaps[k].apart) +
                " shared outline vertices decode apart (up to " + std::to_string(gaps[k].worst_m * 1000) + " mm)");
      }
    }
    progress.endStage();
  }
  return report;
}

std::string describeCheck(const CheckReport& r) {
  std::ostringstream text;
  text << "terratiles check: " << (r.ok() ? "ok" : "FAILED") << "\n";
  text << "  " << r.tiles << " tiles over " << r.zooms << " zooms; footprint " << r.footprint_pixels << " pixels";
  if (r.pole_vertices > 0) text << " (" << r.pole_vertices << " vertices at a pole, measured as drawn)";
  text << "\n";
  text << "  coverage: " << r.cuts << " cuts with neighbours at most one zoom apart, " << r.cuts_with_holes
       << " with holes (" << r.hole_pixels << " pixels); " << r.uncovered_valid_pixels
       << " valid pixels outside the footprint, " << r.left_out_pixels << " of them not next to nodata\n";
  text << "            " << r.unbalanced_cuts << " random cuts with neighbours two or more zooms apart, "
       << r.unbalanced_cuts_with_holes << " with holes (" << r.unbalanced_hole_pixels << " pixels; reported only)\n";
  text << "  vertices: " << r.neighbour_pairs << " pairs of touching tiles one zoom apart, "
       << r.missing_border_vertices << " outline vertices missing where their contents meet, "
       << r.moved_outline_vertices << " off the pixel lattice (moved by a level before it was locked)\n";
  text << "  shared:   " << r.shared_border_vertices << " outline vertices two touching tiles share (same zoom or "
       << "one apart), " << r.shared_vertex_gaps << " decoding apart (worst " << r.worst_shared_vertex_gap_m * 1000
       << " mm)\n";
  // Ratios to nine digits: with no tolerance, 0.9999999 and 1.0000001 must read apart.
  text << std::setprecision(9);
  text << "  errors:   " << r.measured_pixels << " pixel verticals meeting a decoded triangle; " << r.dishonest_errors
       << " tiles whose decoded error exceeds their geometricError (worst " << r.worst_error_ratio << " of it)\n";
  text << "  overlap:  " << r.overlap_pixels << " of them also drawn at the finer zoom, " << r.overlap_disagreements
       << " tiles differing from it by more than their geometricError (worst " << r.worst_overlap_ratio << " of it)\n";
  text << "  tree:     " << r.error_order_violations << " geometricErrors above their parent's, " << r.region_violations
       << " regions outside their parent's, " << r.content_region_violations << " contents outside their region\n";
  for (const std::string& problem : r.problems) text << "  problem:  " << problem << "\n";
  return text.str();
}

}  // namespace terratiles
