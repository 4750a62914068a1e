#pragma once
// Tile schemes (DESIGN.md section 3): exact tile bounds, point-to-tile, and the tiles a box
// touches, for three pyramids.
//
//   webmercator  EPSG:3857 XYZ tiles on the sphere a = 6378137 m: 2^z x 2^z tiles at zoom z,
//                x from the west (lon -180), y from the north (lat +85.0511287798 deg).
//                Latitudes beyond +-kWebMercatorMaxLatitudeDeg are outside the scheme.
//   geographic   EPSG:4326 tiles (OGC WorldCRS84Quad, Cesium GeographicTilingScheme):
//                2^(z+1) x 2^z tiles at zoom z, each 180 / 2^z deg square, x from the west
//                (lon -180), y from the north (lat +90).
//   local        the data's own CRS (LocalTileScheme): 2^z x 2^z square tiles, origin at the
//                data's lower-left corner, x from the west and y FROM THE SOUTH (unlike
//                TileKey's usual row-from-the-north).
//
// Conventions shared by all three schemes:
// - Zooms are 0..kMaxTileZoom; any other zoom is Error(Usage), and so is a TileKey whose x or
//   y is outside the grid of its zoom.
// - Every tile edge is computed by one function of (zoom, edge index), so neighbouring tiles
//   share their edges bit for bit, and point-to-tile decides by comparing with those very
//   doubles: the two always agree, even for points exactly on an edge.
// - A point exactly on an edge shared by two tiles belongs to the tile to the EAST (larger
//   longitude or CRS x) and to the SOUTH (smaller latitude or CRS y). A tile is thus the
//   half-open box [west, east) x (south, north]. The outer boundary of the grid is closed:
//   the east edge of the last column and the south edge of the last row (web schemes) or
//   the first row (local) still belong to those tiles.
// - Longitudes are wrapped into [-180, 180): lon 180 (and -180, 540, ...) is in column 0,
//   lon 179.9999999 in the last column. Tile bounds are not wrapped: the last column's east
//   edge is +180.
// - Latitudes are never wrapped or clamped: outside [-90, 90] (geographic) or outside
//   +-kWebMercatorMaxLatitudeDeg (webmercator) is Error(Input), as is a NaN or infinite
//   coordinate.

#include <cstdint>
#include <string_view>
#include <vector>

#include "src/tiling/tile_key.h"

namespace terratiles {

inline constexpr std::int32_t kMaxTileZoom = 30;

// The Web Mercator sphere (EPSG:3857 uses the WGS84 semi-major axis as a sphere radius).
inline constexpr double kWebMercatorRadiusM = 6378137.0;
// pi * a: the map spans [-k, k] metres on both axes.
inline constexpr double kWebMercatorHalfExtentM = 20037508.342789244;
// atan(sinh(pi)) in degrees, rounded to the nearest double: the latitude at which the
// Web Mercator map is square. The north edge of row 0 and the south edge of the last row.
inline constexpr double kWebMercatorMaxLatitudeDeg = 85.05112877980659;

enum class TileSchemeKind { WebMercator, Geographic, Local };

// "webmercator", "geographic", "local" (exact, lower case). Throws Error(Usage) naming the
// text and the accepted names for anything else.
TileSchemeKind parseTileSchemeKind(std::string_view text);
// The name parseTileSchemeKind accepts.
std::string_view tileSchemeName(TileSchemeKind kind);

// A rectangle west <= east, south <= north. Units depend on the function that returns it:
// degrees (lon/lat), EPSG:3857 metres, or CRS units (local).
struct TileBounds {
  double west = 0;
  double south = 0;
  double east = 0;
  double north = 0;
};

// Tiles per axis at `zoom`: webmercator and local 2^z x 2^z, geographic 2^(z+1) x 2^z
// (2^31 columns at zoom 30, hence 64 bits). Throws Error(Usage) for a zoom outside 0..30.
struct TileGridSize {
  std::int64_t columns = 0;
  std::int64_t rows = 0;
};
TileGridSize tileGridSize(TileSchemeKind kind, std::int32_t zoom);

// ---- Web Mercator on the sphere a = kWebMercatorRadiusM -------------------------------------

struct LonLat {
  double lon_deg = 0;
  double lat_deg = 0;
};

// EPSG:3857 metres: x_m east of the prime meridian, y_m north of the equator.
struct WebMercatorPoint {
  double x_m = 0;
  double y_m = 0;
};

// x = a * lon_rad, y = a * ln(tan(pi/4 + lat_rad/2)). The longitude is NOT wrapped (lon 180
// gives +kWebMercatorHalfExtentM). Throws Error(Input) for |lat| > kWebMercatorMaxLatitudeDeg
// or a non-finite coordinate.
WebMercatorPoint lonLatToWebMercator(double lon_deg, double lat_deg);
// The inverse: lon = x / a, lat = atan(sinh(y / a)). Any finite input; not wrapped.
LonLat webMercatorToLonLat(WebMercatorPoint point);

// lon_deg wrapped into [-180, 180); values already in range are returned unchanged (bit for
// bit). Throws Error(Input) for a non-finite longitude.
double normalizeLongitudeDeg(double lon_deg);

// ---- The two web schemes (kind must be WebMercator or Geographic) ---------------------------

// Lon/lat bounds in degrees. For webmercator the latitudes are atan(sinh(pi*(1 - 2y/2^z)))
// with the outer edges exactly +-kWebMercatorMaxLatitudeDeg; for geographic every tile is
// 180/2^z deg square and all edges are exact doubles. Throws Error(Usage) for a key outside
// the grid.
TileBounds tileBoundsDeg(TileSchemeKind kind, TileKey key);
// Webmercator bounds in EPSG:3857 metres: k * (2x/2^z - 1) and k * (1 - 2y/2^z) with
// k = kWebMercatorHalfExtentM. Throws Error(Usage) for a key outside the grid.
TileBounds webMercatorTileBoundsM(TileKey key);

// The tile at `zoom` holding the point (edge and wrapping conventions above). O(1): a
// closed-form guess corrected against the exact edges. Throws Error(Usage) for the zoom and
// Error(Input) for a latitude outside the scheme (for webmercator the message names the
// limit and says to use the geographic scheme for polar data).
TileKey tileAt(TileSchemeKind kind, double lon_deg, double lat_deg, std::int32_t zoom);

// A lon/lat box in degrees. west > east (after wrapping longitudes) means the box crosses
// the antimeridian: it spans west..180 and -180..east. east - west >= 360 is the whole
// circle. south <= north, both inside the scheme's latitude range.
struct LonLatBox {
  double west_deg = 0;
  double south_deg = 0;
  double east_deg = 0;
  double north_deg = 0;
};

// Refuses lists longer than this (Error(Usage): choose a coarser zoom); 16.7 M tiles is the
// whole webmercator world at zoom 12.
inline constexpr std::int64_t kMaxListedTiles = std::int64_t{1} << 24;

// The tiles at `zoom` that share area with the box, ordered by y then x (ascending). A box
// edge lying on a tile edge does not pull in the neighbouring tile; a box of zero width or
// height gives the tiles tileAt gives for its points. Throws as tileAt for the zoom and the
// box's latitudes, Error(Input) for south > north, Error(Usage) beyond kMaxListedTiles.
std::vector<TileKey> tilesIntersecting(TileSchemeKind kind, const LonLatBox& box,
                                       std::int32_t zoom);

// ---- The local scheme ------------------------------------------------------------------------

// A square pyramid in the data's CRS (units are the CRS's, e.g. metres). The zoom-0 tile is
// [origin_x, origin_x + root_size] x [origin_y, origin_y + root_size]; tile (z, x, y) has
// side root_size / 2^z, x counted from the west and y from the SOUTH.
struct LocalTileScheme {
  double origin_x_crs = 0;   // the data's west edge
  double origin_y_crs = 0;   // the data's south edge
  double root_size_crs = 0;  // side of the zoom-0 tile
};

// The scheme for data covering `data_extent_crs` (west < east, south < north): origin at its
// lower-left corner, root tile side `root_size_crs`, or the extent's larger side when 0.
// Throws Error(Input) for an empty or non-finite extent and Error(Usage) for a root size
// smaller than the larger side (the data would not fit in the zoom-0 tile) or negative.
LocalTileScheme makeLocalTileScheme(const TileBounds& data_extent_crs, double root_size_crs = 0);

// Bounds in CRS units. Throws Error(Usage) for a key outside the grid.
TileBounds tileBounds(const LocalTileScheme& scheme, TileKey key);
// The tile at `zoom` holding (x_crs, y_crs) (edge conventions above). Throws Error(Input)
// for a point outside the zoom-0 tile.
TileKey tileAt(const LocalTileScheme& scheme, double x_crs, double y_crs, std::int32_t zoom);
// The tiles sharing area with `box_crs` (inside the zoom-0 tile), ordered by y then x, with
// the same rules and errors as the lon/lat tilesIntersecting.
std::vector<TileKey> tilesIntersecting(const LocalTileScheme& scheme, const TileBounds& box_crs,
                                       std::int32_t zoom);

}  // namespace terratiles
