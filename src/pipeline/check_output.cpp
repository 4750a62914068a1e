#include "src/pipeline/check_output.h"

#include <GeographicLib/Geocentric.hpp>
#include <nlohmann/json.hpp>
#include <ogr_spatialref.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <fstream>
#include <memory>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/gltf/read_glb.h"
#include "src/base/error.h"
#include "src/geo/geoid.h"
#include "src/lod/build_levels.h"
#include "src/tiling/tile_key.h"
#include "src/tin/measure_tin.h"
#include "tileset/implicit_tileset.h"

namespace terratiles {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kRadToDeg = 180.0 / std::numbers::pi;
constexpr std::size_t kMaxProblems = 12;

// The pixels of triangle (a, b, c) (grid frame) whose centre lies inside it or within
// `tolerance_px` of it, clipped to the grid: visit(pixel index, the triangle's plane height
// there, whether the centre is inside). The tolerance absorbs the quantisation and the round trip through ECEF, which
// move a vertex by far less than a pixel but decide whether a pixel centre exactly on an
// outline is inside.
template <typename Visit>
void forEachPixelNear(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                      double tolerance_px, Visit&& visit) {
  const double area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
  if (area2 == 0) return;
  const int min_col = std::max(0, static_cast<int>(std::ceil(std::min({a.col, b.col, c.col}) - tolerance_px)));
  const int max_col = std::min(dem.width - 1, static_cast<int>(std::floor(std::max({a.col, b.col, c.col}) + tolerance_px)));
  const int min_row = std::max(0, static_cast<int>(std::ceil(std::min({a.row, b.row, c.row}) - tolerance_px)));
  const int max_row = std::min(dem.height - 1, static_cast<int>(std::floor(std::max({a.row, b.row, c.row}) + tolerance_px)));
  for (int row = min_row; row <= max_row; ++row) {
    for (int col = min_col; col <= max_col; ++col) {
      const double wa = ((b.col - col) * (c.row - row) - (b.row - row) * (c.col - col)) / area2;
      const double wb = ((c.col - col) * (a.row - row) - (c.row - row) * (a.col - col)) / area2;
      const double wc = 1.0 - wa - wb;
      const double eps = -1e-9;
      if (wa >= eps && wb >= eps && wc >= eps) {
        visit(dem.index(col, row), wa * a.height_m + wb * b.height_m + wc * c.height_m, true);
        continue;
      }
      // Outside: covered when within the tolerance of an edge, with the height of the nearest
      // point of that edge (no extrapolation past a sliver's sharp corner).
      double nearest = tolerance_px, height = 0;
      bool near = false;
      for (const auto& [p, q] : {std::pair{&a, &b}, std::pair{&b, &c}, std::pair{&c, &a}}) {
        const double ex = q->col - p->col, ey = q->row - p->row;
        const double length2 = ex * ex + ey * ey;
        const double t = length2 > 0 ? std::clamp(((col - p->col) * ex + (row - p->row) * ey) / length2, 0.0, 1.0) : 0;
        const double distance = std::hypot(col - (p->col + t * ex), row - (p->row + t * ey));
        if (distance <= nearest) {
          nearest = distance;
          height = p->height_m + t * (q->height_m - p->height_m);
          near = true;
        }
      }
      if (near) visit(dem.index(col, row), height, false);
    }
  }
}

struct CheckTile {
  TileKey key;
  std::string uri;                // empty: no content
  double geometric_error_m = 0;
  std::array<double, 6> region{};  // west, south, east, north (rad), min, max height (m)
  int parent = -1;
  std::vector<int> children;
  std::vector<std::uint32_t> pixels;  // valid DEM pixels the content covers, sorted
  std::vector<float> heights;         // the content's height at those pixels
  std::vector<float> slack;           // what quantisation may move that height by
  double measured_error_m = 0;        // max |content - DEM|
  double excess_error_m = 0;          // max |content - DEM| - slack
  // The content's outline: its vertices on boundary edges (an edge of one triangle), in the
  // grid frame and as decoded (ECEF), and those edges.
  std::vector<std::array<double, 2>> vertex_grid;
  std::vector<std::array<double, 3>> vertex_ecef;
  std::vector<std::array<std::uint32_t, 2>> boundary_edges;
  std::vector<std::uint32_t> boundary_vertices;
  double polar_cap_deg = 90;  // triangles at a pole reach down to this |latitude| (left out)
  double position_step_m = 0; // the position grid of its zoom (build.json)
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

// The content's triangles rasterised on the DEM's pixel centres: covered valid pixels, the
// content's height there, and the max |content - DEM|.
void rasteriseTile(const fs::path& dir, const DemGrid& dem, const OGRSpatialReference& dem_crs,
                   const GeoidGrid* geoid, double step_m, std::array<double, 2> metres_per_pixel, CheckTile& tile) {
  const DecodedGlb decoded = readGlbFile((dir / tile.uri).string());
  const GlbMesh& mesh = decoded.mesh;
  const auto& earth = GeographicLib::Geocentric::WGS84();
  const std::size_t n = mesh.vertexCount();
  std::vector<double> xs(n), ys(n), zs(n);
  std::vector<std::array<double, 3>> ecef(n), up(n);
  for (std::size_t v = 0; v < n; ++v) {
    const double gx = mesh.translation[0] + mesh.positions[3 * v];
    const double gy = mesh.translation[1] + mesh.positions[3 * v + 1];
    const double gz = mesh.translation[2] + mesh.positions[3 * v + 2];
    double lat = 0, lon = 0, h = 0;
    earth.Reverse(gx, -gz, gy, lat, lon, h);  // glTF y-up back to ECEF z-up
    ecef[v] = {gx, -gz, gy};
    const double lat_rad = lat / kRadToDeg, lon_rad = lon / kRadToDeg;
    up[v] = {std::cos(lat_rad) * std::cos(lon_rad), std::cos(lat_rad) * std::sin(lon_rad), std::sin(lat_rad)};
    if (geoid) {
      const std::optional<double> undulation = geoid->undulationAt(lon, lat);
      if (!undulation) throw Error(ErrorCode::Input, tile.uri + ": a vertex lies outside the geoid grid");
      h -= *undulation;
    }
    xs[v] = lon;
    ys[v] = lat;
    zs[v] = h;
  }
  OGRSpatialReference wgs84;
  wgs84.importFromEPSG(4326);
  wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  std::unique_ptr<OGRCoordinateTransformation> to_dem(OGRCreateCoordinateTransformation(&wgs84, &dem_crs));
  if (!to_dem) throw Error(ErrorCode::Internal, "no transformation from WGS84 to the DEM's CRS " + dem.crs_name);
  std::vector<double> heights = zs;  // the transformation may touch z
  std::vector<int> ok(n, 1);
  if (n > 0 && !to_dem->Transform(n, xs.data(), ys.data(), heights.data(), ok.data())) {
    throw Error(ErrorCode::Input, tile.uri + ": vertices cannot be transformed back to " + dem.crs_name);
  }
  // A geographic DEM: longitudes back into the DEM's 360 degrees (lon 180 and -180 are one
  // meridian), and vertices at a pole, whose longitude no decoding can give back, marked.
  const bool geographic = dem_crs.IsGeographic();
  std::vector<std::uint8_t> at_pole(n, 0);
  std::vector<GridPoint> grid(n);
  for (std::size_t v = 0; v < n; ++v) {
    if (geographic) {
      while (xs[v] < dem.origin_x) xs[v] += 360;
      while (xs[v] >= dem.origin_x + 360) xs[v] -= 360;
      // Quantisation moves a pole vertex off the pole by up to a step or so.
      at_pole[v] = std::fabs(ys[v]) > 90 - std::max(1e-6, 4 * step_m / 111000.0);
    }
    grid[v] = {(xs[v] - dem.origin_x) / dem.pixel_size_x - 0.5, (dem.origin_y - ys[v]) / dem.pixel_size_y - 0.5, zs[v]};
  }
  struct Sample {
    std::uint32_t pixel;
    float height;  // NaN: only near the content (covered, but not measured)
    float slack;
    float error;   // |content - DEM| by this triangle (its nearest edge point when only near)
  };
  std::vector<Sample> covered;
  double max_error = 0, max_excess = -1e300;
  const auto& idx = mesh.triangle_indices;
  // Quantisation moves a vertex by at most sqrt(3)/2 step in 3D: a plane's height at a fixed
  // pixel by at most that times (1 + its slope).
  // A geographic DEM's columns narrow with the cosine of the latitude (groundMetresPerPixel
  // is at the centre latitude).
  const double centre_cos = geographic ? std::cos(dem.pixelCentre(0, (dem.height - 1) / 2.0).y / kRadToDeg) : 1.0;
  for (std::size_t t = 0; t + 2 < idx.size(); t += 3) {
    if (at_pole[idx[t]] || at_pole[idx[t + 1]] || at_pole[idx[t + 2]]) {
      // Its place on the grid is unknown: leave it out, and the cap it reaches out of the check.
      for (std::size_t k = 0; k < 3; ++k) {
        if (!at_pole[idx[t + k]]) tile.polar_cap_deg = std::min(tile.polar_cap_deg, std::fabs(ys[idx[t + k]]));
      }
      continue;
    }
    const GridPoint &a = grid[idx[t]], &b = grid[idx[t + 1]], &c = grid[idx[t + 2]];
    // The decoded triangle's slope, from its normal and the local vertical (right at any
    // latitude, where metres per grid column vary).
    const auto& pa = ecef[idx[t]];
    const auto& pb = ecef[idx[t + 1]];
    const auto& pc = ecef[idx[t + 2]];
    const std::array<double, 3> u{pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
    const std::array<double, 3> w{pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2]};
    const std::array<double, 3> normal{u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    const auto& vertical = up[idx[t]];
    const double along = std::fabs(normal[0] * vertical[0] + normal[1] * vertical[1] + normal[2] * vertical[2]);
    const double length = std::hypot(normal[0], normal[1], normal[2]);
    const double across = std::sqrt(std::max(0.0, length * length - along * along));
    const double slope = along > 0 ? across / along : 1e6;
    const double column_m =
        geographic ? metres_per_pixel[0] * std::sqrt(std::max(1e-12, 1 - vertical[2] * vertical[2])) / centre_cos
                   : metres_per_pixel[0];
    const double tolerance_px = 2 * step_m / std::min(column_m, metres_per_pixel[1]) + 1e-6;
    const auto slack = static_cast<float>(0.87 * step_m * (1 + slope));
    forEachPixelNear(dem, a, b, c, tolerance_px, [&](std::size_t pixel, double h, bool inside) {
      const float dem_h = dem.heights_m[pixel];
      if (std::isnan(dem_h)) return;
      const auto error = static_cast<float>(std::fabs(h - dem_h));
      covered.push_back({static_cast<std::uint32_t>(pixel), inside ? static_cast<float>(h) : std::nanf(""), slack,
                         error});
    });
  }
  // By pixel, measured samples first.
  std::sort(covered.begin(), covered.end(), [](const Sample& l, const Sample& r) {
    return l.pixel < r.pixel || (l.pixel == r.pixel && !std::isnan(l.height) && std::isnan(r.height));
  });
  tile.pixels.clear();
  tile.heights.clear();
  tile.slack.clear();
  // A pixel's error: the smallest among the triangles it is in or within the tolerance of.
  // Decoding moves vertices by up to a step, so a pixel within a step of an edge may belong
  // to either side: next to a steep face, the wrong side's plane is far from the DEM.
  for (std::size_t i = 0; i < covered.size();) {
    std::size_t j = i;
    float error = covered[i].error, slack = covered[i].slack;
    bool measured = false;
    for (; j < covered.size() && covered[j].pixel == covered[i].pixel; ++j) {
      error = std::min(error, covered[j].error);
      slack = std::max(slack, covered[j].slack);
      measured |= !std::isnan(covered[j].height);
    }
    if (measured) {
      max_error = std::max(max_error, static_cast<double>(error));
      max_excess = std::max(max_excess, static_cast<double>(error) - slack);
    }
    tile.pixels.push_back(covered[i].pixel);
    tile.heights.push_back(covered[i].height);
    tile.slack.push_back(slack);
    i = j;
  }
  tile.measured_error_m = max_error;
  tile.excess_error_m = std::max(0.0, max_excess);

  // The outline, for vertex correspondence.
  tile.vertex_grid.resize(n);
  tile.vertex_ecef.resize(n);
  for (std::size_t v = 0; v < n; ++v) {
    tile.vertex_grid[v] = {grid[v].col, grid[v].row};
    tile.vertex_ecef[v] = {mesh.translation[0] + mesh.positions[3 * v], mesh.translation[1] + mesh.positions[3 * v + 1],
                           mesh.translation[2] + mesh.positions[3 * v + 2]};
  }
  std::vector<std::uint64_t> edges;
  edges.reserve(idx.size());
  for (std::size_t t = 0; t + 2 < idx.size(); t += 3) {
    for (std::size_t k = 0; k < 3; ++k) {
      const std::uint32_t a = idx[t + k], b = idx[t + (k + 1) % 3];
      edges.push_back((static_cast<std::uint64_t>(std::min(a, b)) << 32) | std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) {
      const auto a = static_cast<std::uint32_t>(edges[i] >> 32), b = static_cast<std::uint32_t>(edges[i] & 0xffffffffu);
      tile.boundary_edges.push_back({a, b});
      tile.boundary_vertices.insert(tile.boundary_vertices.end(), {a, b});
    }
    i = j;
  }
  std::sort(tile.boundary_vertices.begin(), tile.boundary_vertices.end());
  tile.boundary_vertices.erase(std::unique(tile.boundary_vertices.begin(), tile.boundary_vertices.end()),
                               tile.boundary_vertices.end());
}

// Vertex correspondence (paper 5.2.3) between the contents of two tiles one zoom apart that
// a viewer may draw side by side: an outline vertex of one that lies on an outline edge of
// the other (within `tolerance_px`) must be a vertex of it, at the same decoded position
// (within `same_position_m`). Returns the outline vertices that are not.
// The polar caps a geographic DEM's check leaves out (see CheckReport::polar_cap_deg), on
// the grid: rows poleward of cap_deg.
struct PolarCaps {
  const DemGrid* dem = nullptr;
  double cap_deg = 90;
  bool contain(const std::array<double, 2>& grid_point) const {
    return cap_deg < 90 && std::fabs(dem->pixelCentre(grid_point[0], grid_point[1]).y) >= cap_deg;
  }
};

std::size_t missingBorderVertices(const CheckTile& from, const CheckTile& to, double tolerance_px,
                                  double same_position_m, const PolarCaps& caps,
                                  std::array<double, 2>* first_missing = nullptr) {
  // The other tile's outline edges by 8-pixel cell.
  constexpr double kCell = 8;
  std::map<std::pair<std::int64_t, std::int64_t>, std::vector<std::size_t>> cells;
  for (std::size_t e = 0; e < to.boundary_edges.size(); ++e) {
    const auto& a = to.vertex_grid[to.boundary_edges[e][0]];
    const auto& b = to.vertex_grid[to.boundary_edges[e][1]];
    const auto c0 = static_cast<std::int64_t>(std::floor((std::min(a[0], b[0]) - tolerance_px) / kCell));
    const auto c1 = static_cast<std::int64_t>(std::floor((std::max(a[0], b[0]) + tolerance_px) / kCell));
    const auto r0 = static_cast<std::int64_t>(std::floor((std::min(a[1], b[1]) - tolerance_px) / kCell));
    const auto r1 = static_cast<std::int64_t>(std::floor((std::max(a[1], b[1]) + tolerance_px) / kCell));
    if ((c1 - c0 + 1) * (r1 - r0 + 1) > 4096) continue;  // a degenerate outline edge spanning the world
    for (std::int64_t r = r0; r <= r1; ++r) {
      for (std::int64_t c = c0; c <= c1; ++c) cells[{c, r}].push_back(e);
    }
  }
  std::size_t missing = 0;
  for (const std::uint32_t v : from.boundary_vertices) {
    const auto& p = from.vertex_grid[v];
    if (caps.contain(p)) continue;
    const auto found = cells.find({static_cast<std::int64_t>(std::floor(p[0] / kCell)),
                                   static_cast<std::int64_t>(std::floor(p[1] / kCell))});
    if (found == cells.end()) continue;
    bool on_edge = false, matched = false;
    for (const std::size_t e : found->second) {
      const std::uint32_t ia = to.boundary_edges[e][0], ib = to.boundary_edges[e][1];
      const auto& a = to.vertex_grid[ia];
      const auto& b = to.vertex_grid[ib];
      const double ex = b[0] - a[0], ey = b[1] - a[1];
      const double length2 = ex * ex + ey * ey;
      const double t = length2 > 0 ? std::clamp(((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / length2, 0.0, 1.0) : 0;
      if (std::hypot(p[0] - (a[0] + t * ex), p[1] - (a[1] + t * ey)) > tolerance_px) continue;
      on_edge = true;
      for (const std::uint32_t end : {ia, ib}) {
        const auto& q = to.vertex_ecef[end];
        const auto& w = from.vertex_ecef[v];
        if (std::hypot(q[0] - w[0], q[1] - w[1], q[2] - w[2]) <= same_position_m) matched = true;
      }
    }
    if (on_edge && !matched && missing++ == 0 && first_missing) *first_missing = p;
  }
  return missing;
}

// Outline vertices two touching contents share (the same DEM point: back on the grid within a
// quarter pixel of one pixel centre in both) and how far apart they decode.
constexpr double kSharedVertexGap_m = 1e-3;

struct SharedVertexGaps {
  std::size_t shared = 0;
  std::size_t too_far = 0;  // further apart than allowed_m
  double worst_m = 0;
};

SharedVertexGaps sharedVertexGaps(const CheckTile& a, const CheckTile& b, double allowed_m) {
  const auto pixelOf = [](const std::array<double, 2>& p, std::pair<std::int64_t, std::int64_t>& key) {
    const double col = std::round(p[0]), row = std::round(p[1]);
    if (std::fabs(p[0] - col) > 0.25 || std::fabs(p[1] - row) > 0.25) return false;
    key = {static_cast<std::int64_t>(col), static_cast<std::int64_t>(row)};
    return true;
  };
  std::map<std::pair<std::int64_t, std::int64_t>, std::uint32_t> outline_of_b;
  std::pair<std::int64_t, std::int64_t> key;
  for (const std::uint32_t v : b.boundary_vertices) {
    if (pixelOf(b.vertex_grid[v], key)) outline_of_b.emplace(key, v);
  }
  SharedVertexGaps gaps;
  for (const std::uint32_t v : a.boundary_vertices) {
    if (!pixelOf(a.vertex_grid[v], key)) continue;
    const auto found = outline_of_b.find(key);
    if (found == outline_of_b.end()) continue;
    const auto& p = a.vertex_ecef[v];
    const auto& q = b.vertex_ecef[found->second];
    const double gap = std::hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]);
    ++gaps.shared;
    gaps.worst_m = std::max(gaps.worst_m, gap);
    if (gap > allowed_m) ++gaps.too_far;
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
  const json tileset = readJson(dir / "tileset.json");
  const json build = readJson(dir / "build.json");
  CheckReport report;
  std::vector<CheckTile> tiles;
  // Implicit output: build.json holds the same tree as an explicit tileset.
  addTile(build.contains("explicit_tileset") ? build["explicit_tileset"].at("root") : tileset.at("root"), -1, tiles);

  std::vector<std::string> inputs = build.at("inputs").get<std::vector<std::string>>();
  progress.beginStage("reading the DEM", 0);
  const DemGrid dem = readDem(inputs);
  std::optional<GeoidGrid> geoid;
  if (build.value("heights", std::string("orthometric")) == "orthometric") {
    geoid = readGeoidGrid(build.at("geoid").get<std::string>());
  }
  // The quantisation grid of each zoom (older outputs: the widest for all).
  const double step_m = build.value("position_step_m", 1.0 / 128);
  for (CheckTile& tile : tiles) {
    tile.position_step_m = step_m;
    if (build.contains("position_step_m_by_zoom")) {
      tile.position_step_m = build["position_step_m_by_zoom"].value(std::to_string(tile.key.zoom), step_m);
    }
  }
  progress.endStage();
  const std::array<double, 2> metres_per_pixel = groundMetresPerPixel(dem);
  OGRSpatialReference dem_crs;
  dem_crs.importFromWkt(dem.crs_wkt.c_str());
  dem_crs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);

  progress.beginStage("decoding and rasterising tiles", tiles.size());
  tbb::parallel_for(std::size_t{0}, tiles.size(), [&](std::size_t i) {
    if (!tiles[i].uri.empty()) {
      rasteriseTile(dir, dem, dem_crs, geoid ? &*geoid : nullptr, std::max(tiles[i].position_step_m, 1e-9),
                    metres_per_pixel, tiles[i]);
    }
  });
  progress.advance(tiles.size());
  progress.endStage();
  const auto problem = [&](const std::string& text) {
    if (report.problems.size() < kMaxProblems) report.problems.push_back(text);
  };

  // ---- 3. honest errors and regions ----
  std::int32_t min_zoom = 1 << 30, max_zoom = -1;
  for (const CheckTile& tile : tiles) {
    if (tile.uri.empty()) continue;
    ++report.tiles;
    min_zoom = std::min(min_zoom, tile.key.zoom);
    max_zoom = std::max(max_zoom, tile.key.zoom);
    // Decoded positions are within sqrt(3)/2 step of the written ones (see rasteriseTile).
    if (tile.geometric_error_m > 0) {
      report.worst_error_ratio = std::max(report.worst_error_ratio, tile.excess_error_m / tile.geometric_error_m);
    }
    if (tile.excess_error_m > tile.geometric_error_m) {
      ++report.dishonest_errors;
      problem("tile " + keyText(tile.key) + ": measured error " + std::to_string(tile.measured_error_m) +
              " m > geometricError " + std::to_string(tile.geometric_error_m) + " m");
    }
  }
  if (report.tiles == 0) throw Error(ErrorCode::Input, output_dir + ": tileset.json has no content");
  report.zooms = static_cast<std::size_t>(max_zoom - min_zoom + 1);
  for (const CheckTile& tile : tiles) {
    if (tile.parent < 0) continue;
    const CheckTile& parent = tiles[static_cast<std::size_t>(tile.parent)];
    if (tile.geometric_error_m > parent.geometric_error_m) {
      ++report.error_order_violations;
      problem("tile " + keyText(tile.key) + ": geometricError above its parent's");
    }
    const auto& r = tile.region;
    const auto& p = parent.region;
    constexpr double kTolerance = 1e-12;
    if (r[0] < p[0] - kTolerance || r[1] < p[1] - kTolerance || r[2] > p[2] + kTolerance ||
        r[3] > p[3] + kTolerance || r[4] < p[4] - 1e-6 || r[5] > p[5] + 1e-6) {
      ++report.region_violations;
      problem("tile " + keyText(tile.key) + ": region outside its parent's");
    }
  }

  // ---- 1. coverage ----
  std::vector<std::uint8_t> footprint(dem.pixelCount(), 0);
  for (const CheckTile& tile : tiles) {
    if (tile.uri.empty() || tile.key.zoom != max_zoom) continue;
    for (const std::uint32_t p : tile.pixels) footprint[p] = 1;
  }
  // Triangles at a pole were left out (their grid position is unknown): so is the cap they
  // reach.
  double polar_cap_deg = 90;
  for (const CheckTile& tile : tiles) polar_cap_deg = std::min(polar_cap_deg, tile.polar_cap_deg);
  if (polar_cap_deg < 90) {
    report.polar_cap_deg = polar_cap_deg;
    for (std::int32_t row = 0; row < dem.height; ++row) {
      if (std::fabs(dem.pixelCentre(0, row).y) < polar_cap_deg) continue;
      for (std::int32_t col = 0; col < dem.width; ++col) footprint[dem.index(col, row)] = 0;
    }
  }
  for (const std::uint8_t f : footprint) report.footprint_pixels += f;
  std::vector<std::uint32_t> stamp(dem.pixelCount(), 0);
  std::uint32_t cut_id = 0;
  const auto holesOf = [&](const std::vector<int>& cut) {
    ++cut_id;
    for (const int t : cut) {
      for (const std::uint32_t p : tiles[static_cast<std::size_t>(t)].pixels) stamp[p] = cut_id;
    }
    std::size_t holes = 0;
    for (std::size_t p = 0; p < footprint.size(); ++p) holes += footprint[p] && stamp[p] != cut_id;
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
    // Like coverage, leave out the polar caps where triangles at a pole could not be put
    // back on the grid (their outlines there are the check's cut, not the tiles').
    const PolarCaps caps{&dem, report.polar_cap_deg};
    tbb::parallel_for(std::size_t{0}, pairs.size(), [&](std::size_t k) {
      const CheckTile& a = tiles[static_cast<std::size_t>(pairs[k][0])];
      const CheckTile& b = tiles[static_cast<std::size_t>(pairs[k][1])];
      // A vertex both contents hold decodes to one position when both zooms share a grid:
      // allow 1 mm. Where a wide zoom uses a coarser grid, the coarser tile rounds it to
      // its own step: allow twice that.
      const double step = std::max(a.position_step_m, b.position_step_m);
      const double allowed_m = a.position_step_m == b.position_step_m ? kSharedVertexGap_m
                                                                      : std::max(kSharedVertexGap_m, 2 * step);
      gaps[k] = sharedVertexGaps(a, b, allowed_m);
      if (a.key.zoom != b.key.zoom) {
        // On an edge: within one quantisation step of it. Decoding moves a vertex and an edge by
        // up to 0.87 step each, so an exact T-junction may read up to 1.7 steps off and a lattice
        // point passing an edge within a step reads as one: the figure is exact to a step.
        const double tolerance_px = step / std::max(metres_per_pixel[0], metres_per_pixel[1]);
        missing[k] = missingBorderVertices(a, b, tolerance_px, allowed_m, caps, &first_missing[k]);
        missing[k] += missingBorderVertices(b, a, tolerance_px, allowed_m, caps, missing[k] ? nullptr : &first_missing[k]);
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
      report.shared_vertex_gaps += gaps[k].too_far;
      if (a.position_step_m == b.position_step_m) {
        report.worst_shared_vertex_gap_m = std::max(report.worst_shared_vertex_gap_m, gaps[k].worst_m);
      } else {
        report.worst_shared_vertex_gap_coarser_grid_m =
            std::max(report.worst_shared_vertex_gap_coarser_grid_m, gaps[k].worst_m);
      }
      if (gaps[k].too_far > 0) {
        problem("tiles " + keyText(a.key) + " and " + keyText(b.key) + ": " + std::to_string(gaps[k].too_far) +
                " shared outline vertices decode " + std::to_string(gaps[k].worst_m * 1000) + " mm apart");
      }
    }
    progress.endStage();
  }

  // ---- 2. overlap agreement between adjacent zooms ----
  progress.beginStage("overlap agreement", 0);
  const std::size_t zoom_count = report.zooms;
  std::vector<std::vector<float>> height_at(zoom_count, std::vector<float>(dem.pixelCount(), std::nanf("")));
  std::vector<std::vector<float>> error_at(zoom_count, std::vector<float>(dem.pixelCount(), 1e30f));
  std::vector<std::vector<float>> slack_at(zoom_count, std::vector<float>(dem.pixelCount(), 0.0f));
  for (const CheckTile& tile : tiles) {
    if (tile.uri.empty()) continue;
    const auto z = static_cast<std::size_t>(tile.key.zoom - min_zoom);
    for (std::size_t i = 0; i < tile.pixels.size(); ++i) {
      if (std::isnan(tile.heights[i])) continue;
      height_at[z][tile.pixels[i]] = tile.heights[i];
      slack_at[z][tile.pixels[i]] = std::max(slack_at[z][tile.pixels[i]], tile.slack[i]);
      error_at[z][tile.pixels[i]] = std::min(error_at[z][tile.pixels[i]], static_cast<float>(tile.geometric_error_m));
    }
  }
  for (std::size_t z = 0; z + 1 < zoom_count; ++z) {
    for (std::size_t p = 0; p < dem.pixelCount(); ++p) {
      const float coarse = height_at[z][p], fine = height_at[z + 1][p];
      if (std::isnan(coarse) || std::isnan(fine)) continue;
      ++report.overlap_pixels;
      const double difference =
          std::max(0.0, std::fabs(static_cast<double>(coarse) - fine) - slack_at[z][p] - slack_at[z + 1][p]);
      const double allowed = error_at[z][p];
      if (allowed > 0) report.worst_overlap_ratio = std::max(report.worst_overlap_ratio, difference / allowed);
      if (difference > allowed) {
        ++report.overlap_disagreements;
        problem("zooms " + std::to_string(min_zoom + static_cast<std::int32_t>(z)) + " and " +
                std::to_string(min_zoom + static_cast<std::int32_t>(z) + 1) + " differ by " +
                std::to_string(difference) + " m at pixel (" + std::to_string(p % dem.width) + ", " +
                std::to_string(p / dem.width) + "), geometricError " + std::to_string(allowed) + " m");
      }
    }
  }
  progress.endStage();
  return report;
}

std::string describeCheck(const CheckReport& r) {
  std::ostringstream text;
  text << "terratiles check: " << (r.ok() ? "ok" : "FAILED") << "\n";
  text << "  " << r.tiles << " tiles over " << r.zooms << " zooms; footprint " << r.footprint_pixels << " pixels";
  if (r.polar_cap_deg < 90) text << " (poleward of +-" << r.polar_cap_deg << " deg left out: triangles at a pole)";
  text << "\n";
  text << "  coverage: " << r.cuts << " cuts with neighbours at most one zoom apart, " << r.cuts_with_holes
       << " with holes (" << r.hole_pixels << " pixels)\n";
  text << "            " << r.unbalanced_cuts << " random cuts with neighbours two or more zooms apart, "
       << r.unbalanced_cuts_with_holes << " with holes (" << r.unbalanced_hole_pixels << " pixels; reported only)\n";
  text << "  vertices: " << r.neighbour_pairs << " pairs of touching tiles one zoom apart, "
       << r.missing_border_vertices << " outline vertices missing where their contents meet\n";
  text << "  shared:   " << r.shared_border_vertices << " outline vertices two touching tiles share (same zoom or "
       << "one apart), worst gap " << r.worst_shared_vertex_gap_m * 1000 << " mm on one grid";
  if (r.worst_shared_vertex_gap_coarser_grid_m > 0) {
    text << ", " << r.worst_shared_vertex_gap_coarser_grid_m * 1000 << " mm where a zoom uses a coarser grid";
  }
  text << "; " << r.shared_vertex_gaps << " too far apart\n";
  text << "  overlap:  " << r.overlap_pixels << " pixels covered at two adjacent zooms, " << r.overlap_disagreements
       << " differ by more than the coarser geometricError (worst " << r.worst_overlap_ratio << " of it)\n";
  text << "  errors:   " << r.dishonest_errors << " tiles whose measured error exceeds their geometricError (worst "
       << r.worst_error_ratio << " of it), " << r.error_order_violations << " above their parent's, "
       << r.region_violations << " regions outside their parent's\n";
  for (const std::string& problem : r.problems) text << "  problem:  " << problem << "\n";
  return text.str();
}

}  // namespace terratiles
