#include "tools/chord_check/chord_geometry.h"

#include <GeographicLib/Geocentric.hpp>
#include <nlohmann/json.hpp>
#include <ogr_spatialref.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <optional>

#include "formats/dem/read_dem.h"
#include "formats/geoid/read_geoid.h"
#include "formats/gltf/read_glb.h"
#include "src/base/error.h"
#include "src/dem/dem_grid.h"
#include "src/geo/crs_transform.h"
#include "src/geo/geoid.h"
#include "src/geo/place_on_globe.h"
#include "src/tin/tin_mesh.h"
#include "tileset/implicit_tileset.h"
#include "tileset/read_tileset.h"

namespace terratiles {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kPi = std::numbers::pi;
constexpr double kDegToRad = kPi / 180;
constexpr double kInfinity = std::numeric_limits<double>::infinity();
// The radius the definitions convert angles with (header).
constexpr double kEarthRadiusM = 6.37e6;
// WGS84's smallest radius of curvature, b^2 / a: an angle between two normals times it is
// at most the ground distance between their feet.
constexpr double kMinCurvatureRadiusM = 6356752.314245 * 6356752.314245 / 6378137.0;
constexpr double kBarycentricTolerance = 1e-9;
constexpr int kEdgeSamples = 15;       // points inside each edge, at k / 16
constexpr int kLatticeDivisions = 13;  // interior lattice points (i, j, k >= 1): 66
constexpr double kBaseMarginPx = 2;
// Per triangle: 3 vertices, per edge 15 points, the point nearest the origin and the
// latitude extreme, 66 lattice points (and the foot of the perpendicular when inside).
constexpr std::size_t kSamplesPerTriangle = 3 + 3 * (kEdgeSamples + 2) + 66;
constexpr double kWgs84A = 6378137.0;
constexpr double kWgs84B = 6356752.314245179;
constexpr double kWgs84E2 = 1 - kWgs84B * kWgs84B / (kWgs84A * kWgs84A);
// What "provably inside" keeps clear of the region's faces (rounding of the conversions).
constexpr double kSafeHeightM = 1e-6;
constexpr double kSafeAngleRad = 1e-12;
// A vertex closer than this to the polar axis is at the pole (quantisation moves it off by
// up to a position step or so; 0.11 m is 1e-6 degree of latitude).
constexpr double kPoleRadiusFloorM = 0.11;
constexpr double kPoleSteps = 4;
// The geodetic minus geocentric latitude, about (e^2 / 2) sin 2 lat (1 - h / N): its change
// is at most e^2 (0.00669) times the change of latitude plus (e^2 / 2) / N per metre of height.
constexpr double kLatitudeDifferencePerLatitude = 0.0067;
constexpr double kLatitudeDifferencePerHeight = 0.0034;

}  // namespace

namespace detail {

RegionExcursion regionExcursion(const std::array<double, 6>& region, double lat_rad, double lon_rad, double h_m) {
  const double west = region[0], south = region[1], east = region[2], north = region[3];
  double dlat = 0, dlon = 0, dh = 0;
  if (lat_rad < south) dlat = south - lat_rad;
  if (lat_rad > north) dlat = lat_rad - north;
  // Longitude on the circle: the region runs east from west by `width` (crossing the
  // antimeridian when west > east).
  const double width = west <= east ? east - west : east - west + 2 * kPi;
  if (width < 2 * kPi) {
    double offset = std::fmod(lon_rad - west, 2 * kPi);
    if (offset < 0) offset += 2 * kPi;
    if (offset > width) dlon = std::min(offset - width, 2 * kPi - offset);
  }
  if (h_m < region[4]) dh = region[4] - h_m;
  if (h_m > region[5]) dh = h_m - region[5];
  RegionExcursion e;
  e.outside = dlat > 0 || dlon > 0 || dh > 0;
  if (e.outside) {
    const double lat_m = dlat * kEarthRadiusM, lon_m = dlon * kEarthRadiusM * std::cos(lat_rad);
    e.metres = std::sqrt(lat_m * lat_m + lon_m * lon_m + dh * dh);
  }
  return e;
}

}  // namespace detail

namespace {

struct Vec3 {
  double x = 0, y = 0, z = 0;
};
Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec3 operator*(double s, Vec3 a) { return {s * a.x, s * a.y, s * a.z}; }
double dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec3 cross(Vec3 a, Vec3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double norm(Vec3 a) { return std::sqrt(dot(a, a)); }

std::string keyText(const TileKey& key) { return key.zoom < 0 ? std::string("-") : key.path(); }

// ---- reading an output ----

struct ChordTile {
  TileKey key;
  std::string uri;
  double geometric_error_m = 0;
  std::array<double, 6> region{};  // west, south, east, north (rad), min, max height (m)
};

json readJsonFile(const fs::path& path, const std::string& output_dir) {
  std::ifstream in(path);
  if (!in) {
    throw Error(ErrorCode::Input, output_dir + ": no readable " + path.filename().string() +
                                      "; expected a terratiles output directory (tileset.json and build.json "
                                      "from terratiles build)");
  }
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    throw Error(ErrorCode::Input, path.string() + " is not valid JSON (" + e.what() + "); rebuild the output");
  }
}

void collectTiles(const json& node, std::vector<ChordTile>& tiles) {
  if (node.contains("content")) {
    ChordTile tile;
    tile.uri = node["content"].at("uri").get<std::string>();
    if (!tileKeyFromContentUri(tile.uri, tile.key)) {
      throw Error(ErrorCode::Input, "tileset.json: content " + tile.uri +
                                        " is not named tiles/z/x/y.glb or tiles/west|east/level/x/y.glb; expected a "
                                        "terratiles output");
    }
    tile.geometric_error_m = node.at("geometricError").get<double>();
    const json& region = node.at("boundingVolume").at("region");
    if (region.size() != 6) throw Error(ErrorCode::Input, "tileset.json: tile " + tile.uri + " has a region of " +
                                                              std::to_string(region.size()) + " numbers; expected 6");
    for (std::size_t k = 0; k < 6; ++k) tile.region[k] = region.at(k).get<double>();
    tiles.push_back(tile);
  }
  if (node.contains("children")) {
    for (const json& child : node.at("children")) collectTiles(child, tiles);
  }
}

// ---- DEM pixels on the globe ----

struct PlacedPixels {
  std::vector<Vec3> ecef;    // per pixel; NaN for nodata
  std::vector<Vec3> normal;  // the ellipsoid normal at the pixel's geodetic lat/lon
  // Per row: the smallest ground distance (lower bound) from a valid pixel to its valid
  // neighbour in the next column, and to its valid neighbours in the rows above and below.
  std::vector<double> column_spacing_m;
  std::vector<double> row_spacing_m;
  std::size_t valid = 0;
};

PlacedPixels placePixels(const DemGrid& dem, const GeoidGrid* geoid, Progress& progress) {
  PlacedPixels placed;
  const Vec3 nan{std::nan(""), std::nan(""), std::nan("")};
  placed.ecef.assign(dem.pixelCount(), nan);
  placed.normal.assign(dem.pixelCount(), nan);
  progress.beginStage("placing DEM pixels on the globe", static_cast<std::uint64_t>(dem.height));
  // CrsToWgs84 is not thread-safe: one per thread.
  tbb::enumerable_thread_specific<std::unique_ptr<CrsToWgs84>> transforms;
  constexpr std::int32_t kBlockRows = 16;
  for (std::int32_t first = 0; first < dem.height; first += 256) {
    const std::int32_t last = std::min(dem.height, first + 256);
    tbb::parallel_for(tbb::blocked_range<std::int32_t>(first, last, kBlockRows),
                      [&](const tbb::blocked_range<std::int32_t>& rows) {
      std::unique_ptr<CrsToWgs84>& to_wgs84 = transforms.local();
      if (!to_wgs84) to_wgs84 = std::make_unique<CrsToWgs84>(dem.crs_wkt);
      std::vector<GridPoint> points;
      std::vector<std::size_t> index;
      for (std::int32_t row = rows.begin(); row < rows.end(); ++row) {
        for (std::int32_t col = 0; col < dem.width; ++col) {
          if (!dem.isValid(col, row)) continue;
          points.push_back({static_cast<double>(col), static_cast<double>(row), dem.heightAt(col, row)});
          index.push_back(dem.index(col, row));
        }
      }
      std::vector<GeodeticPoint> geodetic(points.size());
      std::vector<EcefPoint> ecef(points.size());
      placeOnGlobe(dem, points, *to_wgs84, geoid, geodetic, ecef);
      for (std::size_t i = 0; i < points.size(); ++i) {
        const double lat = geodetic[i].lat_deg * kDegToRad, lon = geodetic[i].lon_deg * kDegToRad;
        placed.ecef[index[i]] = {ecef[i].x, ecef[i].y, ecef[i].z};
        placed.normal[index[i]] = {std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
      }
    });
    progress.advance(static_cast<std::uint64_t>(last - first));
  }
  progress.endStage();

  placed.column_spacing_m.assign(static_cast<std::size_t>(dem.height), kInfinity);
  placed.row_spacing_m.assign(static_cast<std::size_t>(dem.height), kInfinity);
  std::vector<std::uint8_t> has_valid(static_cast<std::size_t>(dem.height), 0);
  tbb::parallel_for(std::int32_t{0}, dem.height, [&](std::int32_t row) {
    double column = kInfinity, across = kInfinity;
    for (std::int32_t col = 0; col < dem.width; ++col) {
      if (!dem.isValid(col, row)) continue;
      has_valid[static_cast<std::size_t>(row)] = 1;
      const Vec3 n = placed.normal[dem.index(col, row)];
      if (col + 1 < dem.width && dem.isValid(col + 1, row)) {
        column = std::min(column, norm(n - placed.normal[dem.index(col + 1, row)]) * kMinCurvatureRadiusM);
      }
      for (const std::int32_t other : {row - 1, row + 1}) {
        if (other < 0 || other >= dem.height || !dem.isValid(col, other)) continue;
        across = std::min(across, norm(n - placed.normal[dem.index(col, other)]) * kMinCurvatureRadiusM);
      }
    }
    placed.column_spacing_m[static_cast<std::size_t>(row)] = column;
    placed.row_spacing_m[static_cast<std::size_t>(row)] = across;
  });
  // A row with valid pixels but no valid neighbour pair takes the smallest of the grid.
  double min_column = kInfinity, min_row = kInfinity;
  for (std::int32_t row = 0; row < dem.height; ++row) {
    if (placed.column_spacing_m[static_cast<std::size_t>(row)] > 0) {
      min_column = std::min(min_column, placed.column_spacing_m[static_cast<std::size_t>(row)]);
    }
    min_row = std::min(min_row, placed.row_spacing_m[static_cast<std::size_t>(row)]);
    placed.valid += static_cast<std::size_t>(std::count_if(
        dem.heights_m.begin() + static_cast<std::ptrdiff_t>(dem.index(0, row)),
        dem.heights_m.begin() + static_cast<std::ptrdiff_t>(dem.index(0, row)) + dem.width,
        [](float h) { return !std::isnan(h); }));
  }
  // No pair anywhere (a one-pixel DEM): a nominal metre, clipped to the grid anyway.
  if (!std::isfinite(min_column)) min_column = 1;
  if (!std::isfinite(min_row)) min_row = 1;
  for (std::int32_t row = 0; row < dem.height; ++row) {
    if (!has_valid[static_cast<std::size_t>(row)]) continue;
    double& column = placed.column_spacing_m[static_cast<std::size_t>(row)];
    double& across = placed.row_spacing_m[static_cast<std::size_t>(row)];
    if (!std::isfinite(column)) column = min_column;
    if (!std::isfinite(across)) across = min_row;
  }
  return placed;
}

// ---- per tile ----

struct Context {
  const DemGrid* dem = nullptr;
  const PlacedPixels* pixels = nullptr;
  fs::path dir;
  bool geographic = false;
  // A geographic DEM spanning 360 degrees: columns wrap every wrap_columns.
  std::int32_t wrap_columns = 0;
  std::vector<std::uint8_t> pole_row;  // geographic: the row's centres are at a pole
  std::map<std::int32_t, double> step_by_zoom;
  double default_step_m = 1.0 / 128;
  double extra_margin_px = 0;
  bool convert_every_sample = false;
};

// A tile's (or one triangle's) figures; merged in a fixed order.
struct Figures {
  std::size_t triangles = 0;
  std::size_t vertical_triangles = 0;
  std::size_t pole_triangles = 0;
  std::size_t meetings = 0;
  std::size_t candidates = 0;
  double worst_below_m = 0;
  double worst_above_m = 0;
  std::size_t samples = 0;
  std::size_t outside = 0;
  std::size_t vertices_outside = 0;
  double worst_excursion_m = 0;
  double largest_sag_m = -kInfinity;
  double largest_sag_edge_m = 0;
  double longest_edge_m = 0;

  void add(const Figures& o) {
    triangles += o.triangles;
    vertical_triangles += o.vertical_triangles;
    pole_triangles += o.pole_triangles;
    meetings += o.meetings;
    candidates += o.candidates;
    worst_below_m = std::max(worst_below_m, o.worst_below_m);
    worst_above_m = std::max(worst_above_m, o.worst_above_m);
    samples += o.samples;
    outside += o.outside;
    vertices_outside += o.vertices_outside;
    worst_excursion_m = std::max(worst_excursion_m, o.worst_excursion_m);
    if (o.largest_sag_m > largest_sag_m) {
      largest_sag_m = o.largest_sag_m;
      largest_sag_edge_m = o.largest_sag_edge_m;
    }
    longest_edge_m = std::max(longest_edge_m, o.longest_edge_m);
  }
  double worstError() const { return std::max(worst_below_m, worst_above_m); }
};

// The mu in [0, 1] of A + mu (B - A) where z / |X| is stationary (the edge's extreme of
// geocentric latitude; the endpoints are sampled apart): the derivative's numerator is
// linear in mu.
double latitudeExtremeMu(Vec3 a, Vec3 b) {
  const Vec3 d = b - a;
  const double ad = dot(a, d), aa = dot(a, a), dd = dot(d, d);
  const double slope = d.z * ad - a.z * dd;
  if (slope == 0) return 0;
  const double mu = (a.z * ad - d.z * aa) / slope;
  return std::isfinite(mu) ? std::clamp(mu, 0.0, 1.0) : 0.0;
}

struct Geodetic {
  double lat_deg = 0, lon_deg = 0, h_m = 0;
};

Geodetic toGeodetic(Vec3 p) {
  Geodetic g;
  GeographicLib::Geocentric::WGS84().Reverse(p.x, p.y, p.z, g.lat_deg, g.lon_deg, g.h_m);
  return g;
}

Vec3 normalAt(const Geodetic& g) {
  const double lat = g.lat_deg * kDegToRad, lon = g.lon_deg * kDegToRad;
  return {std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
}

// Whether the triangle's shadow on the equatorial plane holds the polar axis (closed), so
// that it spans every longitude; a shadow of no area holds it only through a vertex.
bool aroundAxis(Vec3 a, Vec3 b, Vec3 c) {
  const auto side = [](Vec3 p, Vec3 q) { return p.x * q.y - p.y * q.x; };
  const double s0 = side(a, b), s1 = side(b, c), s2 = side(c, a);
  return s0 + s1 + s2 != 0 && ((s0 >= 0 && s1 >= 0 && s2 >= 0) || (s0 <= 0 && s1 <= 0 && s2 <= 0));
}

// A candidate rectangle of the grid: rows [row0, row1], columns [col0, col1] in unwrapped
// column units (a geographic DEM spanning 360 degrees wraps them).
struct CandidateBox {
  std::int32_t row0 = 0, row1 = -1;
  std::int64_t col0 = 0, col1 = -1;
};

double wrap180(double degrees) {
  double d = std::fmod(degrees + 180, 360);
  if (d < 0) d += 360;
  return d - 180;
}

class TileMeasure {
 public:
  // met: one byte per DEM pixel, set (atomically) for every pixel a triangle meets.
  TileMeasure(const Context& context, const ChordTile& tile, std::vector<std::uint8_t>& met)
      : c_(context), tile_(tile), met_(met) {}

  Figures run(OGRCoordinateTransformation& to_dem) {
    const DecodedGlb decoded = readGlbFile((c_.dir / tile_.uri).string());
    const GlbMesh& mesh = decoded.mesh;
    const std::size_t n = mesh.vertexCount();
    vertices_.resize(n);
    vertex_geo_.resize(n);
    for (std::size_t v = 0; v < n; ++v) {
      const double gx = mesh.translation[0] + static_cast<double>(mesh.positions[3 * v]);
      const double gy = mesh.translation[1] + static_cast<double>(mesh.positions[3 * v + 1]);
      const double gz = mesh.translation[2] + static_cast<double>(mesh.positions[3 * v + 2]);
      vertices_[v] = {gx, -gz, gy};  // glTF y-up back to ECEF z-up
      vertex_geo_[v] = toGeodetic(vertices_[v]);
    }
    indices_ = &mesh.triangle_indices;
    const std::size_t triangles = mesh.triangle_indices.size() / 3;
    auto step = c_.step_by_zoom.find(tile_.key.zoom);
    pole_radius_m_ = std::max(kPoleRadiusFloorM,
                              kPoleSteps * (step == c_.step_by_zoom.end() ? c_.default_step_m : step->second));

    // The grid positions of every vertex and every edge's latitude extreme, in one batch.
    const std::size_t points = n + 3 * triangles;
    std::vector<double> xs(points), ys(points), zs(points);
    extremes_.resize(3 * triangles);
    extreme_geo_.resize(3 * triangles);
    for (std::size_t v = 0; v < n; ++v) {
      xs[v] = vertex_geo_[v].lon_deg;
      ys[v] = vertex_geo_[v].lat_deg;
      zs[v] = vertex_geo_[v].h_m;
    }
    for (std::size_t t = 0; t < triangles; ++t) {
      for (std::size_t k = 0; k < 3; ++k) {
        const Vec3 a = vertices_[(*indices_)[3 * t + k]], b = vertices_[(*indices_)[3 * t + (k + 1) % 3]];
        const Vec3 p = a + latitudeExtremeMu(a, b) * (b - a);
        extremes_[3 * t + k] = p;
        const Geodetic g = toGeodetic(p);
        extreme_geo_[3 * t + k] = g;
        xs[n + 3 * t + k] = g.lon_deg;
        ys[n + 3 * t + k] = g.lat_deg;
        zs[n + 3 * t + k] = g.h_m;
      }
    }
    std::vector<int> ok(points, 1);
    if (points > 0 && !to_dem.Transform(points, xs.data(), ys.data(), zs.data(), ok.data())) {
      throw Error(ErrorCode::Input, tile_.uri + ": decoded vertices cannot be transformed back to the DEM's CRS " +
                                        c_.dem->crs_name + "; expected content over the DEM");
    }
    grid_.resize(points);
    const DemGrid& dem = *c_.dem;
    for (std::size_t i = 0; i < points; ++i) {
      if (!ok[i]) {
        throw Error(ErrorCode::Input, tile_.uri + ": a decoded point cannot be transformed back to the DEM's CRS " +
                                          dem.crs_name + "; expected content over the DEM");
      }
      double x = xs[i];
      if (c_.geographic) {  // into the DEM's 360 degrees (lon 180 and -180 are one meridian)
        while (x < dem.origin_x) x += 360;
        while (x >= dem.origin_x + 360) x -= 360;
      }
      grid_[i] = {(x - dem.origin_x) / dem.pixel_size_x - 0.5, (dem.origin_y - ys[i]) / dem.pixel_size_y - 0.5};
    }
    n_vertices_ = n;

    std::vector<Figures> per_triangle(triangles);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, triangles, 16),
                      [&](const tbb::blocked_range<std::size_t>& range) {
      std::vector<CandidateBox> boxes;
      for (std::size_t t = range.begin(); t < range.end(); ++t) measureTriangle(t, per_triangle[t], boxes);
    });
    Figures figures;
    for (const Figures& f : per_triangle) figures.add(f);
    return figures;
  }

 private:
  void sample(Vec3 p, bool vertex, Figures& f) const {
    const Geodetic g = toGeodetic(p);
    // A point on the polar axis has no longitude (every meridian meets there): it is inside
    // in longitude, whatever the one Reverse gives.
    const double lon_rad = std::fabs(g.lat_deg) == 90 ? tile_.region[0] : g.lon_deg * kDegToRad;
    const detail::RegionExcursion e = detail::regionExcursion(tile_.region, g.lat_deg * kDegToRad, lon_rad, g.h_m);
    ++f.samples;
    if (e.outside) {
      ++f.outside;
      if (vertex) ++f.vertices_outside;
      f.worst_excursion_m = std::max(f.worst_excursion_m, e.metres);
    }
  }

  bool atPole(Vec3 p) const { return std::hypot(p.x, p.y) <= pole_radius_m_; }

  // Whether every point of triangle t lies inside the tile's region by more than rounding,
  // from its vertices and edge extremes (low_h: a lower bound of its height, high_h its
  // vertices' highest, which is its highest: geodetic height is convex on it). False when
  // unsure (then every sample is converted).
  bool surelyInside(std::size_t t, double low_h, double high_h) const {
    const std::array<double, 6>& region = tile_.region;
    if (high_h > region[5] - kSafeHeightM || low_h < region[4] + kSafeHeightM) return false;
    const std::array<std::uint32_t, 3> v{(*indices_)[3 * t], (*indices_)[3 * t + 1], (*indices_)[3 * t + 2]};
    for (const std::uint32_t i : v) {
      if (atPole(vertices_[i])) return false;
    }
    if (aroundAxis(vertices_[v[0]], vertices_[v[1]], vertices_[v[2]])) return false;
    // Longitudes: the vertices' span the short way round (exact: see the header).
    const double west = region[0], east = region[2];
    const double width = west <= east ? east - west : east - west + 2 * kPi;
    if (width < 2 * kPi) {
      const double reference = vertex_geo_[v[0]].lon_deg;
      double low = 0, high = 0;
      for (std::size_t k = 1; k < 3; ++k) {
        const double rel = wrap180(vertex_geo_[v[k]].lon_deg - reference);
        low = std::min(low, rel);
        high = std::max(high, rel);
      }
      double offset = std::fmod((reference + low) * kDegToRad - west, 2 * kPi);
      if (offset < 0) offset += 2 * kPi;
      if (offset + (high - low) * kDegToRad > width - kSafeAngleRad) return false;
    }
    // Latitudes: geocentric extremes are at the vertices and edge extremes (a spherical
    // triangle); geodetic ones differ by the variation of the latitude difference.
    double low_lat = kInfinity, high_lat = -kInfinity;
    for (const std::uint32_t i : v) {
      low_lat = std::min(low_lat, vertex_geo_[i].lat_deg);
      high_lat = std::max(high_lat, vertex_geo_[i].lat_deg);
    }
    for (std::size_t k = 0; k < 3; ++k) {
      low_lat = std::min(low_lat, extreme_geo_[3 * t + k].lat_deg);
      high_lat = std::max(high_lat, extreme_geo_[3 * t + k].lat_deg);
    }
    low_lat *= kDegToRad;
    high_lat *= kDegToRad;
    const double slack = kLatitudeDifferencePerLatitude * (high_lat - low_lat) +
                         kLatitudeDifferencePerHeight * (high_h - low_h) / kWgs84B + kSafeAngleRad;
    return high_lat + slack <= region[3] && low_lat - slack >= region[1];
  }

  // The smallest ground spacing of pixels (rows only, or rows and columns) in rows row0..row1.
  double smallestSpacing(std::int32_t row0, std::int32_t row1, bool columns_too) const {
    const DemGrid& dem = *c_.dem;
    row0 = std::max(0, row0);
    row1 = std::min(dem.height - 1, row1);
    double spacing = kInfinity;
    for (std::int32_t row = row0; row <= row1; ++row) {
      spacing = std::min(spacing, c_.pixels->row_spacing_m[static_cast<std::size_t>(row)]);
      if (columns_too) spacing = std::min(spacing, c_.pixels->column_spacing_m[static_cast<std::size_t>(row)]);
    }
    return spacing;
  }

  // The candidate rectangles of triangle t (see the header).
  void candidateBoxes(std::size_t t, double longest_m, double low_h_m, double high_h_m,
                      std::vector<CandidateBox>& boxes, bool& pole) const {
    const DemGrid& dem = *c_.dem;
    boxes.clear();
    const std::array<std::size_t, 6> points{(*indices_)[3 * t], (*indices_)[3 * t + 1], (*indices_)[3 * t + 2],
                                            n_vertices_ + 3 * t, n_vertices_ + 3 * t + 1, n_vertices_ + 3 * t + 2};
    const std::array<Vec3, 6> ecef{vertices_[points[0]], vertices_[points[1]], vertices_[points[2]],
                                   extremes_[3 * t], extremes_[3 * t + 1], extremes_[3 * t + 2]};
    double row_min = kInfinity, row_max = -kInfinity, col_min = kInfinity, col_max = -kInfinity;
    double max_abs_lat = 0;
    for (std::size_t k = 0; k < 6; ++k) {
      row_min = std::min(row_min, grid_[points[k]][1]);
      row_max = std::max(row_max, grid_[points[k]][1]);
      const Vec3 p = ecef[k];
      max_abs_lat = std::max(max_abs_lat, std::atan2(std::fabs(p.z), std::hypot(p.x, p.y)));
    }
    // The chord's sideways bulge (the header's bound), and for a geographic grid the
    // variation of geodetic minus geocentric latitude over the triangle.
    const double tan_lat = std::tan(std::min(max_abs_lat, 89.9 * kDegToRad));
    const double bulge_m = longest_m * longest_m * (1 + tan_lat) / (4 * kEarthRadiusM);
    std::array<bool, 3> at_pole{};
    pole = false;
    for (std::size_t k = 0; k < 3; ++k) {
      at_pole[k] = atPole(ecef[k]);
      pole |= at_pole[k];
    }
    if (!c_.geographic) {
      for (std::size_t k = 0; k < 6; ++k) {
        col_min = std::min(col_min, grid_[points[k]][0]);
        col_max = std::max(col_max, grid_[points[k]][0]);
      }
      double margin = kBaseMarginPx + c_.extra_margin_px;
      for (int pass = 0; pass < 3; ++pass) {
        const double spacing = smallestSpacing(static_cast<std::int32_t>(std::floor(row_min - margin)),
                                               static_cast<std::int32_t>(std::ceil(row_max + margin)), true);
        if (!std::isfinite(spacing)) return;  // no valid pixel in those rows
        margin = kBaseMarginPx + c_.extra_margin_px + bulge_m / std::max(spacing, 1e-9);
      }
      pushBox(row_min - margin, row_max + margin, col_min - margin, col_max + margin, boxes);
      return;
    }
    // Geographic grid. Rows: all six points (a pole point's row is right; only its
    // longitude is lost), grown by the bulge and the latitude difference's variation.
    const bool around_axis = aroundAxis(ecef[0], ecef[1], ecef[2]);
    // The pole it reaches: that of its pole vertex, or where the axis crosses its plane.
    bool north = true;
    if (pole) {
      for (std::size_t k = 0; k < 3; ++k) {
        if (at_pole[k]) north = ecef[k].z > 0;
      }
    } else if (around_axis) {
      const Vec3 n = cross(ecef[1] - ecef[0], ecef[2] - ecef[0]);
      north = n.z != 0 ? dot(n, ecef[0]) / n.z > 0 : ecef[0].z > 0;
    }
    if (around_axis || pole) {  // reaches the pole row on its side
      const double pole_row = (dem.origin_y - (north ? 90.0 : -90.0)) / dem.pixel_size_y - 0.5;
      row_min = std::min(row_min, pole_row);
      row_max = std::max(row_max, pole_row);
    }
    const double lat_extent_m = (row_max - row_min) * dem.pixel_size_y * kDegToRad * kEarthRadiusM;
    const double latitude_m = kLatitudeDifferencePerLatitude * lat_extent_m +
                              kLatitudeDifferencePerHeight * std::max(0.0, high_h_m - low_h_m);
    double row_margin = kBaseMarginPx + c_.extra_margin_px;
    for (int pass = 0; pass < 3; ++pass) {
      const double spacing = smallestSpacing(static_cast<std::int32_t>(std::floor(row_min - row_margin)),
                                             static_cast<std::int32_t>(std::ceil(row_max + row_margin)), false);
      if (!std::isfinite(spacing)) return;
      row_margin = kBaseMarginPx + c_.extra_margin_px + (bulge_m + latitude_m) / std::max(spacing, 1e-9);
    }
    const double r0 = row_min - row_margin, r1 = row_max + row_margin;
    const double col_margin = kBaseMarginPx + c_.extra_margin_px;
    const double all0 = -1e18, all1 = 1e18;  // every column
    if (around_axis && !pole) {
      pushBox(r0, r1, all0, all1, boxes);
      return;
    }
    // Columns: the vertices' longitudes the short way round (pole vertices have none).
    double reference = kInfinity, rel_min = 0, rel_max = 0;
    for (std::size_t k = 0; k < 3; ++k) {
      if (at_pole[k]) continue;
      const double col = grid_[points[k]][0];
      if (!std::isfinite(reference)) {
        reference = col;
        continue;
      }
      const double rel = wrap180((col - reference) * dem.pixel_size_x) / dem.pixel_size_x;
      rel_min = std::min(rel_min, rel);
      rel_max = std::max(rel_max, rel);
    }
    if (!pole) {
      pushBox(r0, r1, reference + rel_min - col_margin, reference + rel_max + col_margin, boxes);
      return;
    }
    // With a vertex at a pole: that pole's rows whole, the other rows the others' columns.
    std::int32_t first_pole = -1, last_pole = -1;
    for (std::int32_t row = std::max<std::int32_t>(0, static_cast<std::int32_t>(std::floor(r0)));
         row <= std::min<std::int32_t>(dem.height - 1, static_cast<std::int32_t>(std::ceil(r1))); ++row) {
      if (!c_.pole_row[static_cast<std::size_t>(row)] || row < r0 || row > r1) continue;
      if ((dem.pixelCentre(0, row).y > 0) != north) continue;
      if (first_pole < 0) first_pole = row;
      last_pole = row;
    }
    if (first_pole >= 0) pushBox(first_pole, last_pole, all0, all1, boxes);
    if (!std::isfinite(reference)) return;  // every vertex at the pole
    const double c0 = reference + rel_min - col_margin, c1 = reference + rel_max + col_margin;
    if (first_pole < 0) {
      pushBox(r0, r1, c0, c1, boxes);
      return;
    }
    if (r0 < first_pole) pushBox(r0, first_pole - 1, c0, c1, boxes);
    if (r1 > last_pole) pushBox(last_pole + 1, r1, c0, c1, boxes);
  }

  // Rows and columns (real, inclusive) to whole pixels, clipped (rows; columns unless they
  // wrap).
  void pushBox(double r0, double r1, double c0, double c1, std::vector<CandidateBox>& boxes) const {
    const DemGrid& dem = *c_.dem;
    CandidateBox box;
    box.row0 = static_cast<std::int32_t>(std::max(0.0, std::ceil(r0)));
    box.row1 = static_cast<std::int32_t>(std::min(static_cast<double>(dem.height - 1), std::floor(r1)));
    if (box.row0 > box.row1) return;
    const double limit = c_.wrap_columns > 0 ? 4.0 * dem.width : dem.width - 1;
    const double lower = c_.wrap_columns > 0 ? -2.0 * dem.width : 0.0;
    box.col0 = static_cast<std::int64_t>(std::max(lower, std::ceil(c0)));
    box.col1 = static_cast<std::int64_t>(std::min(limit, std::floor(c1)));
    if (c_.wrap_columns > 0 && box.col1 - box.col0 + 1 >= c_.wrap_columns) {
      box.col0 = 0;  // every meridian once (a repeated one is visited through its first column)
      box.col1 = c_.wrap_columns - 1;
    }
    if (box.col0 > box.col1) return;
    boxes.push_back(box);
  }

  void measureTriangle(std::size_t t, Figures& f, std::vector<CandidateBox>& boxes) const {
    const std::uint32_t ia = (*indices_)[3 * t], ib = (*indices_)[3 * t + 1], ic = (*indices_)[3 * t + 2];
    const Vec3 a = vertices_[ia], b = vertices_[ib], c = vertices_[ic];
    f.triangles = 1;
    const Vec3 e1 = b - a, e2 = c - a, e3 = c - b;
    const double longest = std::max({norm(e1), norm(e2), norm(e3)});
    f.longest_edge_m = longest;

    // 3. Sag.
    const Geodetic centroid = toGeodetic((1.0 / 3) * (a + b + c));
    f.largest_sag_m = (vertex_geo_[ia].h_m + vertex_geo_[ib].h_m + vertex_geo_[ic].h_m) / 3 - centroid.h_m;
    f.largest_sag_edge_m = longest;

    // 2. Region samples. A triangle provably inside its region by more than rounding has
    // every sample inside: they are counted without converting each (the same counts).
    const double high_h = std::max({vertex_geo_[ia].h_m, vertex_geo_[ib].h_m, vertex_geo_[ic].h_m});
    // A lower bound of the height over the triangle: geodetic height is the signed distance
    // to the (convex) ellipsoid, at least the distance below the tangent plane at the
    // centroid's foot, which is linear and so lowest at a vertex.
    const Vec3 tangent = normalAt(centroid);
    const double support = std::sqrt(kWgs84A * kWgs84A * (tangent.x * tangent.x + tangent.y * tangent.y) +
                                     kWgs84B * kWgs84B * tangent.z * tangent.z);
    const double low_h = std::min({dot(tangent, a), dot(tangent, b), dot(tangent, c)}) - support;
    const Vec3 normal = cross(e1, e2);
    const double normal2 = dot(normal, normal);
    const double d00 = dot(e1, e1), d01 = dot(e1, e2), d11 = dot(e2, e2);
    const double denominator = d00 * d11 - d01 * d01;
    std::optional<Vec3> foot;  // of the perpendicular from the origin, when inside
    if (normal2 > 0 && denominator > 0) {
      const Vec3 p = (dot(normal, a) / normal2) * normal;
      const Vec3 r = p - a;
      const double r1 = dot(r, e1), r2 = dot(r, e2);
      const double v = (d11 * r1 - d01 * r2) / denominator, w = (d00 * r2 - d01 * r1) / denominator;
      if (v >= 0 && w >= 0 && v + w <= 1) foot = p;
    }
    if (!c_.convert_every_sample && surelyInside(t, low_h, high_h)) {
      f.samples += kSamplesPerTriangle + (foot ? 1 : 0);
    } else {
      sample(a, true, f);
      sample(b, true, f);
      sample(c, true, f);
      const std::array<Vec3, 3> corner{a, b, c};
      for (std::size_t k = 0; k < 3; ++k) {
        const Vec3 p = corner[k], q = corner[(k + 1) % 3], d = q - p;
        for (int s = 1; s <= kEdgeSamples; ++s) sample(p + (static_cast<double>(s) / (kEdgeSamples + 1)) * d, false, f);
        // The edge's point nearest the origin, and its latitude extreme.
        const double dd = dot(d, d);
        const double mu = dd > 0 ? std::clamp(-dot(p, d) / dd, 0.0, 1.0) : 0.0;
        sample(p + mu * d, false, f);
        sample(extremes_[3 * t + k], false, f);
      }
      for (int i = 1; i < kLatticeDivisions; ++i) {
        for (int j = 1; i + j < kLatticeDivisions; ++j) {
          const double u = static_cast<double>(i) / kLatticeDivisions, v = static_cast<double>(j) / kLatticeDivisions;
          sample(a + u * e1 + v * e2, false, f);
        }
      }
      if (foot) sample(*foot, false, f);
    }

    // 1. Pixel verticals.
    bool pole = false;
    candidateBoxes(t, longest, low_h, high_h, boxes, pole);
    f.pole_triangles = pole ? 1 : 0;
    if (!(normal2 > 0) || !(denominator > 0)) {
      f.vertical_triangles = 1;
      return;
    }
    const double inverse = 1 / denominator;
    const double normal_length = std::sqrt(normal2);
    const DemGrid& dem = *c_.dem;
    const std::vector<Vec3>& pixel_ecef = c_.pixels->ecef;
    const std::vector<Vec3>& pixel_normal = c_.pixels->normal;
    bool parallel = false;
    for (const CandidateBox& box : boxes) {
      for (std::int32_t row = box.row0; row <= box.row1; ++row) {
        for (std::int64_t unwrapped = box.col0; unwrapped <= box.col1; ++unwrapped) {
          std::int64_t col = unwrapped;
          if (c_.wrap_columns > 0) {
            col %= c_.wrap_columns;
            if (col < 0) col += c_.wrap_columns;
          }
          // A 360-degree DEM with a repeated meridian holds a column twice: visit both.
          for (; col < dem.width; col += c_.wrap_columns > 0 ? c_.wrap_columns : dem.width) {
            const std::size_t pixel = dem.index(static_cast<std::int32_t>(col), row);
            const Vec3 p = pixel_ecef[pixel];
            if (std::isnan(p.x)) continue;  // nodata
            ++f.candidates;
            const Vec3 up = pixel_normal[pixel];
            const double along = dot(normal, up);
            if (std::fabs(along) <= 1e-12 * normal_length) {
              parallel = true;
              continue;
            }
            const Vec3 w = a - p;
            const double height = dot(normal, w) / along;  // t: P + t n is on the plane
            // The vertical ends where it reaches the polar axis, t = -(N + h) (beyond, its
            // points have other latitudes and longitudes: it crosses the Earth). Only a far
            // point can be there (N + h > 6300 km).
            if (height < -1e6) {
              const double sin2 = up.z * up.z;
              const double radius = kWgs84A / std::sqrt(1 - kWgs84E2 * sin2);  // N
              if (height <= -(dot(p, up) + radius * kWgs84E2 * sin2)) continue;
            }
            const Vec3 x = (p - a) + height * up;           // X - A
            const double x1 = dot(x, e1), x2 = dot(x, e2);
            const double bv = (d11 * x1 - d01 * x2) * inverse, bw = (d00 * x2 - d01 * x1) * inverse;
            const double bu = 1 - bv - bw;
            if (bu < -kBarycentricTolerance || bv < -kBarycentricTolerance || bw < -kBarycentricTolerance) continue;
            ++f.meetings;
            std::atomic_ref<std::uint8_t>(met_[pixel]).store(1, std::memory_order_relaxed);
            if (height > 0) {
              f.worst_above_m = std::max(f.worst_above_m, height);
            } else {
              f.worst_below_m = std::max(f.worst_below_m, -height);
            }
          }
        }
      }
    }
    if (parallel && f.meetings == 0) f.vertical_triangles = 1;
  }

  const Context& c_;
  const ChordTile& tile_;
  std::vector<std::uint8_t>& met_;
  std::vector<Vec3> vertices_;
  std::vector<Geodetic> vertex_geo_;
  std::vector<Vec3> extremes_;  // 3 per triangle: each edge's latitude extreme
  std::vector<Geodetic> extreme_geo_;
  std::vector<std::array<double, 2>> grid_;  // vertices, then extremes: (col, row)
  const std::vector<std::uint32_t>* indices_ = nullptr;
  std::size_t n_vertices_ = 0;
  double pole_radius_m_ = kPoleRadiusFloorM;
};

std::unique_ptr<OGRCoordinateTransformation> wgs84ToDem(const OGRSpatialReference& dem_crs, const std::string& name) {
  OGRSpatialReference wgs84;
  wgs84.importFromEPSG(4326);
  wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  std::unique_ptr<OGRCoordinateTransformation> transform(OGRCreateCoordinateTransformation(&wgs84, &dem_crs));
  if (!transform) {
    throw Error(ErrorCode::Input, "no transformation from WGS84 (EPSG:4326) to the DEM's CRS " + name +
                                      "; expected a CRS PROJ can transform to");
  }
  return transform;
}

void addTileToRow(const ChordTile& tile, const Figures& f, ChordZoomRow& row) {
  const std::size_t tiles_before = row.tiles;
  ++row.tiles;
  row.triangles += f.triangles;
  row.vertical_triangles += f.vertical_triangles;
  row.pole_triangles += f.pole_triangles;
  row.pixel_meetings += f.meetings;
  row.min_tile_meetings = tiles_before == 0 ? f.meetings : std::min(row.min_tile_meetings, f.meetings);
  row.candidate_pixels += f.candidates;
  row.worst_below_m = std::max(row.worst_below_m, f.worst_below_m);
  row.worst_above_m = std::max(row.worst_above_m, f.worst_above_m);
  row.worst_error_m = std::max(row.worst_error_m, f.worstError());
  const double worst = f.worstError();
  const double ratio = tile.geometric_error_m > 0 ? worst / tile.geometric_error_m : (worst > 0 ? kInfinity : 0.0);
  if (tiles_before == 0 || ratio > row.worst_ratio) {
    row.worst_ratio = ratio;
    row.worst_ratio_tile = tile.key;
    row.worst_ratio_tile_error_m = worst;
    row.worst_ratio_tile_geometric_error_m = tile.geometric_error_m;
  }
  if (worst > tile.geometric_error_m) ++row.tiles_over;
  if (tile.geometric_error_m > 0) {
    row.worst_finite_ratio = std::max(row.worst_finite_ratio, ratio);
  } else {
    ++row.zero_error_tiles;
  }
  row.region_samples += f.samples;
  row.samples_outside += f.outside;
  row.vertices_outside += f.vertices_outside;
  if (f.outside > 0) ++row.tiles_outside;
  if (f.outside > 0 && (row.worst_excursion_tile.zoom < 0 || f.worst_excursion_m > row.worst_excursion_m)) {
    row.worst_excursion_m = f.worst_excursion_m;
    row.worst_excursion_tile = tile.key;
  }
  if (f.triangles > 0 && (row.triangles == f.triangles || f.largest_sag_m > row.largest_sag_m)) {
    row.largest_sag_m = f.largest_sag_m;
    row.largest_sag_edge_m = f.largest_sag_edge_m;
  }
  row.longest_edge_m = std::max(row.longest_edge_m, f.longest_edge_m);
}

void addRowToTotals(const ChordZoomRow& row, ChordZoomRow& totals) {
  const bool first = totals.tiles == 0;
  totals.tiles += row.tiles;
  const bool first_triangles = totals.triangles == 0;
  totals.triangles += row.triangles;
  totals.vertical_triangles += row.vertical_triangles;
  totals.pole_triangles += row.pole_triangles;
  totals.pixel_meetings += row.pixel_meetings;
  totals.min_tile_meetings = first ? row.min_tile_meetings : std::min(totals.min_tile_meetings, row.min_tile_meetings);
  totals.candidate_pixels += row.candidate_pixels;
  totals.unmet_pixels += row.unmet_pixels;
  totals.unmet_edge_pixels += row.unmet_edge_pixels;
  totals.worst_error_m = std::max(totals.worst_error_m, row.worst_error_m);
  totals.worst_below_m = std::max(totals.worst_below_m, row.worst_below_m);
  totals.worst_above_m = std::max(totals.worst_above_m, row.worst_above_m);
  if (first || row.worst_ratio > totals.worst_ratio) {
    totals.worst_ratio = row.worst_ratio;
    totals.worst_ratio_tile = row.worst_ratio_tile;
    totals.worst_ratio_tile_error_m = row.worst_ratio_tile_error_m;
    totals.worst_ratio_tile_geometric_error_m = row.worst_ratio_tile_geometric_error_m;
  }
  totals.tiles_over += row.tiles_over;
  totals.zero_error_tiles += row.zero_error_tiles;
  totals.worst_finite_ratio = std::max(totals.worst_finite_ratio, row.worst_finite_ratio);
  totals.region_samples += row.region_samples;
  totals.samples_outside += row.samples_outside;
  totals.vertices_outside += row.vertices_outside;
  totals.tiles_outside += row.tiles_outside;
  if (row.samples_outside > 0 &&
      (totals.worst_excursion_tile.zoom < 0 || row.worst_excursion_m > totals.worst_excursion_m)) {
    totals.worst_excursion_m = row.worst_excursion_m;
    totals.worst_excursion_tile = row.worst_excursion_tile;
  }
  if (row.triangles > 0 && (first_triangles || row.largest_sag_m > totals.largest_sag_m)) {
    totals.largest_sag_m = row.largest_sag_m;
    totals.largest_sag_edge_m = row.largest_sag_edge_m;
  }
  totals.longest_edge_m = std::max(totals.longest_edge_m, row.longest_edge_m);
}

}  // namespace

ChordReport measureChordGeometry(const std::string& output_dir, Progress& progress) {
  return measureChordGeometry(output_dir, ChordOptions{}, progress);
}

ChordReport measureChordGeometry(const std::string& output_dir, const ChordOptions& options, Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  const fs::path dir(output_dir);
  if (!fs::is_directory(dir)) {
    throw Error(ErrorCode::Input, output_dir + ": not a directory; expected a terratiles output directory "
                                               "(tileset.json and build.json from terratiles build)");
  }
  readJsonFile(dir / "tileset.json", output_dir);  // names a missing or broken file
  const json tileset = readTilesetTree(dir / "tileset.json");  // external tilesets put in place
  const json build = readJsonFile(dir / "build.json", output_dir);
  ChordReport report;
  report.output_dir = output_dir;
  std::vector<ChordTile> tiles;
  std::vector<std::string> inputs;
  std::string heights, geoid_path;
  Context context;
  try {
    // An implicit output: build.json holds the same tree as an explicit tileset.
    collectTiles(build.contains("explicit_tileset") ? build.at("explicit_tileset").at("root") : tileset.at("root"),
                 tiles);
    inputs = build.at("inputs").get<std::vector<std::string>>();
    heights = build.value("heights", std::string("orthometric"));
    if (heights == "orthometric") geoid_path = build.at("geoid").get<std::string>();
    context.default_step_m = build.value("position_step_m", 1.0 / 128);
    if (build.contains("position_step_m_by_zoom")) {
      for (const auto& [zoom, step] : build.at("position_step_m_by_zoom").items()) {
        context.step_by_zoom[std::stoi(zoom)] = step.get<double>();
      }
    }
  } catch (const json::exception& e) {
    throw Error(ErrorCode::Input, output_dir + ": tileset.json or build.json lacks what a terratiles output holds (" +
                                      e.what() + "); rebuild it with terratiles build");
  }
  if (tiles.empty()) throw Error(ErrorCode::Input, output_dir + ": tileset.json has no tile with content");
  if (inputs.empty()) throw Error(ErrorCode::Input, output_dir + ": build.json names no input DEM");
  for (std::size_t i = 0; i < inputs.size(); ++i) report.dem += (i ? ", " : "") + inputs[i];

  const DemGrid dem = readDem(inputs, "reading the DEM", progress);
  std::optional<GeoidGrid> geoid;
  if (heights == "orthometric") {
    geoid = readGeoidGrid(geoid_path);
    report.heights = "orthometric, geoid " + geoid->name;
  } else {
    report.heights = "ellipsoidal";
  }
  progress.endStage();

  const PlacedPixels pixels = placePixels(dem, geoid ? &*geoid : nullptr, progress);
  report.dem_pixels = pixels.valid;

  OGRSpatialReference dem_crs;
  if (dem_crs.importFromWkt(dem.crs_wkt.c_str()) != OGRERR_NONE) {
    throw Error(ErrorCode::Input, report.dem + ": the DEM's CRS cannot be read back (" + dem.crs_name + ")");
  }
  dem_crs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  context.dem = &dem;
  context.pixels = &pixels;
  context.dir = dir;
  context.geographic = dem_crs.IsGeographic();
  context.extra_margin_px = options.extra_margin_px;
  context.convert_every_sample = options.convert_every_sample;
  if (context.geographic) {
    const double columns = 360 / dem.pixel_size_x;
    if (dem.width * dem.pixel_size_x >= 360 - 1e-6 * dem.pixel_size_x &&
        std::fabs(columns - std::round(columns)) < 1e-6) {
      context.wrap_columns = static_cast<std::int32_t>(std::round(columns));
    }
    context.pole_row.assign(static_cast<std::size_t>(dem.height), 0);
    for (std::int32_t row = 0; row < dem.height; ++row) {
      context.pole_row[static_cast<std::size_t>(row)] = std::fabs(dem.pixelCentre(0, row).y) >= 90 - 1e-9;
    }
  }

  // Largest tiles first, so the parallel loop ends evenly.
  std::vector<std::size_t> order(tiles.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::vector<std::uintmax_t> sizes(tiles.size(), 0);
  for (std::size_t i = 0; i < tiles.size(); ++i) {
    std::error_code ec;
    sizes[i] = fs::file_size(dir / tiles[i].uri, ec);
  }
  std::stable_sort(order.begin(), order.end(), [&](std::size_t l, std::size_t r) { return sizes[l] > sizes[r]; });

  progress.beginStage("measuring tiles", tiles.size());
  std::vector<Figures> figures(tiles.size());
  std::map<std::int32_t, std::vector<std::uint8_t>> met;  // per zoom: pixels some triangle meets
  for (const ChordTile& tile : tiles) met[tile.key.zoom].resize(dem.pixelCount(), 0);
  tbb::enumerable_thread_specific<std::unique_ptr<OGRCoordinateTransformation>> to_dem;
  constexpr std::size_t kBatch = 64;
  for (std::size_t first = 0; first < order.size(); first += kBatch) {
    const std::size_t last = std::min(order.size(), first + kBatch);
    tbb::parallel_for(first, last, [&](std::size_t i) {
      progress.throwIfCancelled();
      std::unique_ptr<OGRCoordinateTransformation>& transform = to_dem.local();
      if (!transform) transform = wgs84ToDem(dem_crs, dem.crs_name);
      const ChordTile& tile = tiles[order[i]];
      figures[order[i]] = TileMeasure(context, tile, met.at(tile.key.zoom)).run(*transform);
    });
    progress.advance(last - first);
  }
  progress.endStage();

  std::map<std::int32_t, ChordZoomRow> rows;
  for (std::size_t i = 0; i < tiles.size(); ++i) {
    ChordZoomRow& row = rows[tiles[i].key.zoom];
    row.zoom = tiles[i].key.zoom;
    addTileToRow(tiles[i], figures[i], row);
  }
  for (auto& [zoom, row] : rows) {
    const std::vector<std::uint8_t>& zoom_met = met.at(zoom);
    for (std::int32_t r = 0; r < dem.height; ++r) {
      for (std::int32_t col = 0; col < dem.width; ++col) {
        if (zoom_met[dem.index(col, r)] || !dem.isValid(col, r)) continue;
        ++row.unmet_pixels;
        const bool edge = r == 0 || col == 0 || r == dem.height - 1 || col == dem.width - 1 ||
                          !dem.isValid(col - 1, r) || !dem.isValid(col + 1, r) || !dem.isValid(col, r - 1) ||
                          !dem.isValid(col, r + 1);
        row.unmet_edge_pixels += edge;
      }
    }
    report.zooms.push_back(row);
    addRowToTotals(row, report.totals);
  }
  report.totals.zoom = -1;
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

namespace {

std::string format(const char* pattern, double value) {
  char text[64];
  std::snprintf(text, sizeof text, pattern, value);
  return text;
}

std::string tableRow(const ChordZoomRow& row) {
  char text[512];
  const std::string zoom = row.zoom < 0 ? std::string("all") : std::to_string(row.zoom);
  const std::string ratio_tile = keyText(row.worst_ratio_tile);
  const std::string excursion_tile = row.samples_outside > 0 ? keyText(row.worst_excursion_tile) : std::string("-");
  std::snprintf(text, sizeof text,
                "%4s %6zu %9zu %11zu %9zu %9zu %9.3f %9.3f %9.3f %8.3f %-12s %5zu %9zu %6zu %10.3f %-12s %9.3f %10.1f %10.1f\n",
                zoom.c_str(), row.tiles, row.triangles, row.pixel_meetings, row.unmet_pixels, row.unmet_edge_pixels, row.worst_error_m,
                row.worst_below_m,
                row.worst_above_m, row.worst_ratio, ratio_tile.c_str(), row.tiles_over, row.samples_outside,
                row.vertices_outside, row.worst_excursion_m, excursion_tile.c_str(), row.largest_sag_m,
                row.largest_sag_edge_m, row.longest_edge_m);
  return text;
}

json rowJson(const ChordZoomRow& row) {
  json j;
  if (row.zoom >= 0) j["zoom"] = row.zoom;
  j["tiles"] = row.tiles;
  j["triangles"] = row.triangles;
  j["vertical_triangles"] = row.vertical_triangles;
  j["pole_triangles"] = row.pole_triangles;
  j["pixel_meetings"] = row.pixel_meetings;
  j["min_tile_meetings"] = row.min_tile_meetings;
  j["candidate_pixels"] = row.candidate_pixels;
  j["unmet_pixels"] = row.unmet_pixels;
  j["unmet_edge_pixels"] = row.unmet_edge_pixels;
  j["worst_error_m"] = row.worst_error_m;
  j["worst_below_m"] = row.worst_below_m;
  j["worst_above_m"] = row.worst_above_m;
  j["worst_ratio"] = std::isfinite(row.worst_ratio) ? json(row.worst_ratio) : json("inf");
  j["worst_ratio_tile"] = keyText(row.worst_ratio_tile);
  j["worst_ratio_tile_error_m"] = row.worst_ratio_tile_error_m;
  j["worst_ratio_tile_geometric_error_m"] = row.worst_ratio_tile_geometric_error_m;
  j["tiles_over"] = row.tiles_over;
  j["zero_error_tiles"] = row.zero_error_tiles;
  j["worst_finite_ratio"] = row.worst_finite_ratio;
  j["region_samples"] = row.region_samples;
  j["samples_outside"] = row.samples_outside;
  j["vertices_outside"] = row.vertices_outside;
  j["tiles_outside"] = row.tiles_outside;
  j["worst_excursion_m"] = row.worst_excursion_m;
  j["worst_excursion_tile"] = row.samples_outside > 0 ? keyText(row.worst_excursion_tile) : std::string("-");
  j["largest_sag_m"] = row.largest_sag_m;
  j["largest_sag_edge_m"] = row.largest_sag_edge_m;
  j["longest_edge_m"] = row.longest_edge_m;
  return j;
}

}  // namespace

std::string describeChordReport(const ChordReport& report) {
  std::string text;
  text += "output: " + report.output_dir + "\n";
  text += "DEM: " + report.dem + " (" + std::to_string(report.dem_pixels) + " valid pixels), heights " +
          report.heights + "\n";
  text += "errors at pixel verticals against the decoded chords (m), regions against samples of every chord (m), "
          "sag below the corners' surface (m)\n";
  text += "zoom  tiles triangles    meetings  unmet px   on edge worst err   below m   above m    ratio ratio tile   over  samp out "
          "vert out  excursion excurs tile     sag m   @edge m  longest m\n";
  for (const ChordZoomRow& row : report.zooms) text += tableRow(row);
  text += tableRow(report.totals);
  const ChordZoomRow& t = report.totals;
  if (t.vertical_triangles > 0 || t.pole_triangles > 0) {
    text += std::to_string(t.vertical_triangles) + " triangles hold the vertical (meet no pixel), " +
            std::to_string(t.pole_triangles) + " have a vertex at a pole\n";
  }
  if (t.zero_error_tiles > 0) {
    text += std::to_string(t.zero_error_tiles) + " tiles have geometricError 0; the worst ratio of the others: " +
            format("%.3f", t.worst_finite_ratio) + "\n";
  }
  text += "fewest meetings in a tile: " + std::to_string(t.min_tile_meetings) + "; " +
          std::to_string(t.candidate_pixels) + " candidate pixels tested; " + format("%.1f", report.seconds) + " s\n";
  if (report.ok()) {
    text += "chord check: OK (no tile's error over its geometricError, no sample outside its region)\n";
  } else {
    text += "chord check: FAILED (" + std::to_string(t.tiles_over) + " of " + std::to_string(t.tiles) +
            " tiles over their geometricError, worst ratio " + format("%.3f", t.worst_ratio) + " at tile " +
            keyText(t.worst_ratio_tile) + "; " + std::to_string(t.samples_outside) + " of " +
            std::to_string(t.region_samples) + " region samples outside in " + std::to_string(t.tiles_outside) +
            " tiles, worst " + format("%.3f", t.worst_excursion_m) + " m)\n";
  }
  return text;
}

std::string chordReportToJson(const ChordReport& report) {
  json j;
  j["output"] = report.output_dir;
  j["dem"] = report.dem;
  j["heights"] = report.heights;
  j["dem_pixels"] = report.dem_pixels;
  j["ok"] = report.ok();
  j["seconds"] = report.seconds;
  j["zooms"] = json::array();
  for (const ChordZoomRow& row : report.zooms) j["zooms"].push_back(rowJson(row));
  j["totals"] = rowJson(report.totals);
  return j.dump();
}

}  // namespace terratiles
