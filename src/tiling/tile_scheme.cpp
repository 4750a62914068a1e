#include "src/tiling/tile_scheme.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "src/base/error.h"

namespace terratiles {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kRadPerDeg = kPi / 180.0;
constexpr double kDegPerRad = 180.0 / kPi;

// Shortest round-trip text, independent of the locale.
std::string formatNumber(double value) {
  char buffer[64];
  const std::to_chars_result result = std::to_chars(buffer, buffer + sizeof buffer, value);
  return std::string(buffer, result.ptr);
}

std::string formatFixed(double value, int digits) {
  char buffer[64];
  const std::to_chars_result result =
      std::to_chars(buffer, buffer + sizeof buffer, value, std::chars_format::fixed, digits);
  return std::string(buffer, result.ptr);
}

std::string where(TileSchemeKind kind) {
  return "tile scheme " + std::string(tileSchemeName(kind));
}

bool isWebScheme(TileSchemeKind kind) {
  return kind == TileSchemeKind::WebMercator || kind == TileSchemeKind::Geographic;
}

void checkZoom(TileSchemeKind kind, std::int32_t zoom) {
  if (zoom < 0 || zoom > kMaxTileZoom) {
    throw Error(ErrorCode::Usage, where(kind) + ": zoom " + std::to_string(zoom) +
                                      " is outside the supported zooms 0.." +
                                      std::to_string(kMaxTileZoom) + "; choose a zoom from 0 to " +
                                      std::to_string(kMaxTileZoom));
  }
}

void checkKey(TileSchemeKind kind, TileKey key) {
  const TileGridSize grid = tileGridSize(kind, key.zoom);
  if (key.x < 0 || key.x >= grid.columns || key.y < 0 || key.y >= grid.rows) {
    throw Error(ErrorCode::Usage,
                where(kind) + ": tile " + key.path() + " is outside the zoom-" +
                    std::to_string(key.zoom) + " grid of " + std::to_string(grid.columns) + " x " +
                    std::to_string(grid.rows) + " tiles; expected x in 0.." +
                    std::to_string(grid.columns - 1) + " and y in 0.." +
                    std::to_string(grid.rows - 1));
  }
}

void checkFiniteLonLat(std::string_view place, double lon_deg, double lat_deg) {
  if (!std::isfinite(lon_deg) || !std::isfinite(lat_deg)) {
    throw Error(ErrorCode::Input, std::string(place) + ": point (lon " + formatNumber(lon_deg) +
                                      ", lat " + formatNumber(lat_deg) +
                                      ") is not a finite lon/lat; expected finite degrees "
                                      "(check the input for nodata or NaN values)");
  }
}

void checkWebMercatorLatitude(std::string_view place, double lon_deg, double lat_deg) {
  if (std::abs(lat_deg) > kWebMercatorMaxLatitudeDeg) {
    throw Error(ErrorCode::Input,
                std::string(place) + ": latitude " + formatNumber(lat_deg) + " deg (at lon " +
                    formatNumber(lon_deg) + " deg) is beyond the Web Mercator limit of +-" +
                    formatFixed(kWebMercatorMaxLatitudeDeg, 10) +
                    " deg; use the geographic tile scheme for polar data");
  }
}

// Checks a point of a web scheme: finite, and a latitude inside the scheme. (The message's
// place is only made for a point that fails: this runs for every face of every level.)
void checkWebPoint(TileSchemeKind kind, double lon_deg, double lat_deg) {
  if (!std::isfinite(lon_deg) || !std::isfinite(lat_deg)) checkFiniteLonLat(where(kind), lon_deg, lat_deg);
  if (kind == TileSchemeKind::WebMercator) {
    if (std::abs(lat_deg) > kWebMercatorMaxLatitudeDeg) checkWebMercatorLatitude(where(kind), lon_deg, lat_deg);
  } else if (std::abs(lat_deg) > 90.0) {
    throw Error(ErrorCode::Input, where(kind) + ": latitude " + formatNumber(lat_deg) +
                                      " deg (at lon " + formatNumber(lon_deg) +
                                      " deg) is outside [-90, 90] deg; expected lon/lat in "
                                      "degrees (check the CRS and the axis order)");
  }
}

// ---- Edges: one function per axis, so neighbours share their edges bit for bit ----------------
// `edge` is an edge index 0..cells. The products below are exact: every tile size is 360 or
// 180 divided by a power of two, and the indices have at most 31 bits.

double lonEdgeDeg(std::int64_t edge, std::int64_t columns) {
  return 360.0 * static_cast<double>(edge) / static_cast<double>(columns) - 180.0;
}

// Latitude of the north edge of row `edge` (edge == rows: the south edge of the last row).
double latEdgeDeg(TileSchemeKind kind, std::int64_t edge, std::int64_t rows) {
  if (kind == TileSchemeKind::Geographic) {
    return 90.0 - 180.0 * static_cast<double>(edge) / static_cast<double>(rows);
  }
  // Web Mercator: the inverse of y = ln(tan(pi/4 + lat/2)) at y = pi * (1 - 2 edge / rows).
  // The outer edges are pinned to the constant so that the limit check and the grid agree.
  if (edge == 0) return kWebMercatorMaxLatitudeDeg;
  if (edge == rows) return -kWebMercatorMaxLatitudeDeg;
  const double fraction = 1.0 - 2.0 * static_cast<double>(edge) / static_cast<double>(rows);
  return std::atan(std::sinh(kPi * fraction)) * kDegPerRad;
}

// Which side owns a point lying exactly on an edge shared by cells i - 1 and i.
enum class EdgeOwner { HigherIndex, LowerIndex };

// The cell of an axis of `cells` cells whose edges edge(0) < ... < edge(cells) increase with
// the index. HigherIndex: cell i is [edge(i), edge(i+1)); LowerIndex: (edge(i), edge(i+1)].
// The outer boundary is closed (clamped). `guess` is a closed-form estimate of the cell
// (fractional); it is corrected against the exact edges, so the answer agrees with the
// bounds even where the closed form rounds the other way. O(1) for a guess within a cell.
template <class EdgeFn>
std::int64_t cellContaining(double position, std::int64_t cells, double guess, EdgeOwner owner,
                            const EdgeFn& edge) {
  double guess_floor = std::floor(guess);
  if (!(guess_floor >= 0.0)) guess_floor = 0.0;  // also NaN
  guess_floor = std::min(guess_floor, static_cast<double>(cells - 1));
  std::int64_t cell = static_cast<std::int64_t>(guess_floor);
  if (owner == EdgeOwner::HigherIndex) {
    while (cell > 0 && position < edge(cell)) --cell;
    while (cell + 1 < cells && position >= edge(cell + 1)) ++cell;
  } else {
    while (cell > 0 && position <= edge(cell)) --cell;
    while (cell + 1 < cells && position > edge(cell + 1)) ++cell;
  }
  return cell;
}

struct CellRange {
  std::int64_t first = 0;
  std::int64_t last = 0;  // inclusive
  std::int64_t count() const { return last - first + 1; }
};

// The cells sharing length with [low, high] along an increasing axis; a zero-length interval
// (low == high) gives the cell that owns the point by `point_owner`.
template <class EdgeFn>
CellRange cellsOverlapping(double low, double high, std::int64_t cells, double guess_low,
                           double guess_high, EdgeOwner point_owner, const EdgeFn& edge) {
  if (low == high) {
    const std::int64_t cell = cellContaining(low, cells, guess_low, point_owner, edge);
    return {cell, cell};
  }
  // With low < high the first cell starts at or before low and the last one ends at or after
  // high, so first <= last.
  const CellRange range{cellContaining(low, cells, guess_low, EdgeOwner::HigherIndex, edge),
                        cellContaining(high, cells, guess_high, EdgeOwner::LowerIndex, edge)};
  TERRATILES_ASSERT(range.first <= range.last);
  return range;
}

// ---- Web scheme axes ---------------------------------------------------------------------------
// Columns: position = longitude in [-180, 180], increasing eastwards; the east owns edges.
// Rows: position = -latitude, increasing southwards (with y); the south owns edges.

double columnGuess(double lon_deg, std::int64_t columns) {
  return (lon_deg + 180.0) / 360.0 * static_cast<double>(columns);
}

double rowGuess(TileSchemeKind kind, double lat_deg, std::int64_t rows) {
  if (kind == TileSchemeKind::Geographic) {
    return (90.0 - lat_deg) / 180.0 * static_cast<double>(rows);
  }
  const double mercator_y = std::asinh(std::tan(lat_deg * kRadPerDeg));  // in units of a
  return (1.0 - mercator_y / kPi) / 2.0 * static_cast<double>(rows);
}

CellRange columnsOverlapping(double west_deg, double east_deg, std::int64_t columns,
                             EdgeOwner point_owner) {
  return cellsOverlapping(west_deg, east_deg, columns, columnGuess(west_deg, columns),
                          columnGuess(east_deg, columns), point_owner,
                          [columns](std::int64_t edge) { return lonEdgeDeg(edge, columns); });
}

CellRange rowsOverlapping(TileSchemeKind kind, double south_deg, double north_deg,
                          std::int64_t rows, EdgeOwner point_owner) {
  return cellsOverlapping(-north_deg, -south_deg, rows, rowGuess(kind, north_deg, rows),
                          rowGuess(kind, south_deg, rows), point_owner,
                          [kind, rows](std::int64_t edge) {
                            return -latEdgeDeg(kind, edge, rows);
                          });
}

std::vector<TileKey> listTiles(TileSchemeKind kind, std::int32_t zoom,
                               const std::vector<CellRange>& column_ranges, CellRange rows) {
  std::int64_t columns = 0;
  for (const CellRange& range : column_ranges) columns += range.count();
  const std::int64_t tiles = columns * rows.count();  // < 2^62
  if (tiles > kMaxListedTiles) {
    throw Error(ErrorCode::Usage, where(kind) + ": the box covers " + std::to_string(tiles) +
                                      " tiles at zoom " + std::to_string(zoom) +
                                      ", more than the " + std::to_string(kMaxListedTiles) +
                                      " a tile list may hold; choose a coarser zoom or a smaller "
                                      "box");
  }
  std::vector<TileKey> keys;
  keys.reserve(static_cast<std::size_t>(tiles));
  for (std::int64_t y = rows.first; y <= rows.last; ++y) {
    for (const CellRange& range : column_ranges) {
      for (std::int64_t x = range.first; x <= range.last; ++x) {
        keys.push_back({zoom, static_cast<std::int32_t>(x), static_cast<std::int32_t>(y)});
      }
    }
  }
  return keys;
}

// ---- Local scheme ------------------------------------------------------------------------------

const TileSchemeKind kLocal = TileSchemeKind::Local;

double localTileSize(const LocalTileScheme& scheme, std::int32_t zoom) {
  TERRATILES_ASSERT(scheme.root_size_crs > 0.0);
  return scheme.root_size_crs / static_cast<double>(std::int64_t{1} << zoom);  // exact
}

double localEdge(double origin_crs, double tile_size_crs, std::int64_t edge) {
  return origin_crs + tile_size_crs * static_cast<double>(edge);
}

void checkLocalPoint(const LocalTileScheme& scheme, double x_crs, double y_crs) {
  const double east_crs = scheme.origin_x_crs + scheme.root_size_crs;
  const double north_crs = scheme.origin_y_crs + scheme.root_size_crs;
  // Written so that NaN fails too.
  if (!(x_crs >= scheme.origin_x_crs && x_crs <= east_crs && y_crs >= scheme.origin_y_crs &&
        y_crs <= north_crs)) {
    throw Error(ErrorCode::Input,
                where(kLocal) + ": point (x " + formatNumber(x_crs) + ", y " +
                    formatNumber(y_crs) + ") is outside the zoom-0 tile [" +
                    formatNumber(scheme.origin_x_crs) + ", " + formatNumber(east_crs) + "] x [" +
                    formatNumber(scheme.origin_y_crs) + ", " + formatNumber(north_crs) +
                    "] (CRS units); expected a point inside the data's extent");
  }
}

CellRange localColumns(const LocalTileScheme& scheme, double west_crs, double east_crs,
                       std::int32_t zoom) {
  const double size_crs = localTileSize(scheme, zoom);
  const std::int64_t cells = std::int64_t{1} << zoom;
  return cellsOverlapping(
      west_crs, east_crs, cells, (west_crs - scheme.origin_x_crs) / size_crs,
      (east_crs - scheme.origin_x_crs) / size_crs, EdgeOwner::HigherIndex,
      [&](std::int64_t edge) { return localEdge(scheme.origin_x_crs, size_crs, edge); });
}

// y counted from the south: the south (lower index) owns a shared edge.
CellRange localRows(const LocalTileScheme& scheme, double south_crs, double north_crs,
                    std::int32_t zoom) {
  const double size_crs = localTileSize(scheme, zoom);
  const std::int64_t cells = std::int64_t{1} << zoom;
  return cellsOverlapping(
      south_crs, north_crs, cells, (south_crs - scheme.origin_y_crs) / size_crs,
      (north_crs - scheme.origin_y_crs) / size_crs, EdgeOwner::LowerIndex,
      [&](std::int64_t edge) { return localEdge(scheme.origin_y_crs, size_crs, edge); });
}

}  // namespace

TileSchemeKind parseTileSchemeKind(std::string_view text) {
  for (TileSchemeKind kind :
       {TileSchemeKind::WebMercator, TileSchemeKind::Geographic, TileSchemeKind::Local}) {
    if (text == tileSchemeName(kind)) return kind;
  }
  throw Error(ErrorCode::Usage, "unknown tile scheme '" + std::string(text) +
                                    "'; expected webmercator, geographic or local");
}

std::string_view tileSchemeName(TileSchemeKind kind) {
  switch (kind) {
    case TileSchemeKind::WebMercator: return "webmercator";
    case TileSchemeKind::Geographic: return "geographic";
    case TileSchemeKind::Local: return "local";
  }
  return "unknown";
}

TileGridSize tileGridSize(TileSchemeKind kind, std::int32_t zoom) {
  checkZoom(kind, zoom);
  const std::int64_t rows = std::int64_t{1} << zoom;
  return {kind == TileSchemeKind::Geographic ? 2 * rows : rows, rows};
}

WebMercatorPoint lonLatToWebMercator(double lon_deg, double lat_deg) {
  constexpr std::string_view kPlace = "Web Mercator (EPSG:3857)";
  checkFiniteLonLat(kPlace, lon_deg, lat_deg);
  checkWebMercatorLatitude(kPlace, lon_deg, lat_deg);
  const double lat_rad = lat_deg * kRadPerDeg;
  return {kWebMercatorRadiusM * lon_deg * kRadPerDeg,
          kWebMercatorRadiusM * std::log(std::tan(kPi / 4.0 + lat_rad / 2.0))};
}

LonLat webMercatorToLonLat(WebMercatorPoint point) {
  return {point.x_m / kWebMercatorRadiusM * kDegPerRad,
          std::atan(std::sinh(point.y_m / kWebMercatorRadiusM)) * kDegPerRad};
}

double normalizeLongitudeDeg(double lon_deg) {
  if (!std::isfinite(lon_deg)) {
    throw Error(ErrorCode::Input, "longitude " + formatNumber(lon_deg) +
                                      " deg is not finite; expected a finite longitude in degrees "
                                      "(check the input for nodata or NaN values)");
  }
  if (lon_deg >= -180.0 && lon_deg < 180.0) return lon_deg;
  // fmod is exact, and so are the +-360 steps (Sterbenz): no rounding anywhere.
  double wrapped_deg = std::fmod(lon_deg, 360.0);
  if (wrapped_deg >= 180.0) wrapped_deg -= 360.0;
  if (wrapped_deg < -180.0) wrapped_deg += 360.0;
  return wrapped_deg;
}

TileBounds tileBoundsDeg(TileSchemeKind kind, TileKey key) {
  TERRATILES_ASSERT(isWebScheme(kind));
  checkKey(kind, key);
  const TileGridSize grid = tileGridSize(kind, key.zoom);
  // 64-bit edge indices: x + 1 is 2^31 for the last geographic column at zoom 30.
  return {lonEdgeDeg(key.x, grid.columns), latEdgeDeg(kind, std::int64_t{key.y} + 1, grid.rows),
          lonEdgeDeg(std::int64_t{key.x} + 1, grid.columns), latEdgeDeg(kind, key.y, grid.rows)};
}

TileBounds webMercatorTileBoundsM(TileKey key) {
  checkKey(TileSchemeKind::WebMercator, key);
  const double tiles = static_cast<double>(std::int64_t{1} << key.zoom);
  const auto x_edge_m = [tiles](std::int64_t edge) {
    return kWebMercatorHalfExtentM * (2.0 * static_cast<double>(edge) / tiles - 1.0);
  };
  const auto y_edge_m = [tiles](std::int64_t edge) {
    return kWebMercatorHalfExtentM * (1.0 - 2.0 * static_cast<double>(edge) / tiles);
  };
  return {x_edge_m(key.x), y_edge_m(std::int64_t{key.y} + 1), x_edge_m(std::int64_t{key.x} + 1),
          y_edge_m(key.y)};
}

TileKey tileAt(TileSchemeKind kind, double lon_deg, double lat_deg, std::int32_t zoom) {
  TERRATILES_ASSERT(isWebScheme(kind));
  const TileGridSize grid = tileGridSize(kind, zoom);
  checkWebPoint(kind, lon_deg, lat_deg);
  const double wrapped_lon_deg = normalizeLongitudeDeg(lon_deg);
  const CellRange column =
      columnsOverlapping(wrapped_lon_deg, wrapped_lon_deg, grid.columns, EdgeOwner::HigherIndex);
  const CellRange row = rowsOverlapping(kind, lat_deg, lat_deg, grid.rows, EdgeOwner::HigherIndex);
  return {zoom, static_cast<std::int32_t>(column.first), static_cast<std::int32_t>(row.first)};
}

std::vector<TileKey> tilesIntersecting(TileSchemeKind kind, const LonLatBox& box,
                                       std::int32_t zoom) {
  TERRATILES_ASSERT(isWebScheme(kind));
  const TileGridSize grid = tileGridSize(kind, zoom);
  checkWebPoint(kind, box.west_deg, box.south_deg);
  checkWebPoint(kind, box.east_deg, box.north_deg);
  if (box.south_deg > box.north_deg) {
    throw Error(ErrorCode::Input, where(kind) + ": box south " + formatNumber(box.south_deg) +
                                      " deg is north of its north " +
                                      formatNumber(box.north_deg) +
                                      " deg; expected south <= north");
  }
  const CellRange rows =
      rowsOverlapping(kind, box.south_deg, box.north_deg, grid.rows, EdgeOwner::HigherIndex);

  const CellRange all_columns{0, grid.columns - 1};
  std::vector<CellRange> columns;
  const double west_deg = normalizeLongitudeDeg(box.west_deg);
  double east_deg = normalizeLongitudeDeg(box.east_deg);
  if (!(box.east_deg - box.west_deg < 360.0)) {
    columns = {all_columns};
  } else if (west_deg == east_deg) {  // zero width (after wrapping)
    columns = {columnsOverlapping(west_deg, west_deg, grid.columns, EdgeOwner::HigherIndex)};
  } else {
    if (east_deg == -180.0) east_deg = 180.0;  // an east edge at the antimeridian ends the map
    if (west_deg < east_deg) {
      columns = {columnsOverlapping(west_deg, east_deg, grid.columns, EdgeOwner::HigherIndex)};
    } else {  // crosses the antimeridian: west..180 and -180..east
      const CellRange western =
          columnsOverlapping(west_deg, 180.0, grid.columns, EdgeOwner::HigherIndex);
      const CellRange eastern =
          columnsOverlapping(-180.0, east_deg, grid.columns, EdgeOwner::HigherIndex);
      if (eastern.last + 1 >= western.first) {
        columns = {all_columns};
      } else {
        columns = {eastern, western};  // ascending x
      }
    }
  }
  return listTiles(kind, zoom, columns, rows);
}

LocalTileScheme makeLocalTileScheme(const TileBounds& data_extent_crs, double root_size_crs) {
  const TileBounds& extent = data_extent_crs;
  if (!std::isfinite(extent.west) || !std::isfinite(extent.south) ||
      !std::isfinite(extent.east) || !std::isfinite(extent.north) || !(extent.west < extent.east) ||
      !(extent.south < extent.north)) {
    throw Error(ErrorCode::Input,
                where(kLocal) + ": data extent [" + formatNumber(extent.west) + ", " +
                    formatNumber(extent.east) + "] x [" + formatNumber(extent.south) + ", " +
                    formatNumber(extent.north) +
                    "] (CRS units) is empty or not finite; expected west < east and south < "
                    "north (check the raster's geotransform)");
  }
  const double width_crs = extent.east - extent.west;
  const double height_crs = extent.north - extent.south;
  const auto covers = [&](double size_crs) {
    return extent.west + size_crs >= extent.east && extent.south + size_crs >= extent.north;
  };
  LocalTileScheme scheme{extent.west, extent.south, root_size_crs};
  if (root_size_crs == 0.0) {
    scheme.root_size_crs = std::max(width_crs, height_crs);
    // east - west can round down so that west + width < east; grow by ulps until it fits.
    while (!covers(scheme.root_size_crs)) {
      scheme.root_size_crs =
          std::nextafter(scheme.root_size_crs, std::numeric_limits<double>::infinity());
    }
  } else if (!std::isfinite(root_size_crs) || root_size_crs < 0.0 || !covers(root_size_crs)) {
    throw Error(ErrorCode::Usage,
                where(kLocal) + ": zoom-0 tile size " + formatNumber(root_size_crs) +
                    " is smaller than the data's larger side " +
                    formatNumber(std::max(width_crs, height_crs)) +
                    " (CRS units); give a size of at least that, or 0 for the larger side");
  }
  return scheme;
}

TileBounds tileBounds(const LocalTileScheme& scheme, TileKey key) {
  checkKey(kLocal, key);
  const double size_crs = localTileSize(scheme, key.zoom);
  return {localEdge(scheme.origin_x_crs, size_crs, key.x),
          localEdge(scheme.origin_y_crs, size_crs, key.y),
          localEdge(scheme.origin_x_crs, size_crs, std::int64_t{key.x} + 1),
          localEdge(scheme.origin_y_crs, size_crs, std::int64_t{key.y} + 1)};
}

TileKey tileAt(const LocalTileScheme& scheme, double x_crs, double y_crs, std::int32_t zoom) {
  checkZoom(kLocal, zoom);
  checkLocalPoint(scheme, x_crs, y_crs);
  return {zoom, static_cast<std::int32_t>(localColumns(scheme, x_crs, x_crs, zoom).first),
          static_cast<std::int32_t>(localRows(scheme, y_crs, y_crs, zoom).first)};
}

std::vector<TileKey> tilesIntersecting(const LocalTileScheme& scheme, const TileBounds& box_crs,
                                       std::int32_t zoom) {
  checkZoom(kLocal, zoom);
  checkLocalPoint(scheme, box_crs.west, box_crs.south);
  checkLocalPoint(scheme, box_crs.east, box_crs.north);
  if (box_crs.west > box_crs.east || box_crs.south > box_crs.north) {
    throw Error(ErrorCode::Input,
                where(kLocal) + ": box [" + formatNumber(box_crs.west) + ", " +
                    formatNumber(box_crs.east) + "] x [" + formatNumber(box_crs.south) + ", " +
                    formatNumber(box_crs.north) +
                    "] (CRS units) is inverted; expected west <= east and south <= north");
  }
  return listTiles(kLocal, zoom, {localColumns(scheme, box_crs.west, box_crs.east, zoom)},
                   localRows(scheme, box_crs.south, box_crs.north, zoom));
}

}  // namespace terratiles
