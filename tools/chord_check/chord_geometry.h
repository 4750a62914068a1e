#pragma once
// measureChordGeometry: an independent check of what a renderer draws from a terratiles
// output. CesiumJS draws every decoded triangle as a straight 3D triangle (a chord) in ECEF;
// this decodes every tile and measures those chords against the source DEM and against the
// tile's bounding region, in ECEF and metres. It shares nothing with `terratiles check`
// (src/pipeline/check_output.cpp) but the readers (DEM, geoid, GLB) and placeOnGlobe.
//
// Reading an output: tileset.json (for an implicit output, build.json's explicit_tileset,
// the same tree as an explicit tileset); build.json's inputs (DEM paths), heights and geoid.
// Decoded positions: ECEF = (gx, -gz, gy), g = GLB node translation + position (glTF y-up),
// in double. Every tile with content is measured; content-less tiles are not.
//
// 1. Decoded error at pixel verticals (metres). A valid DEM pixel's point P is its centre at
//    its DEM height placed exactly as the build places vertices (placeOnGlobe: pixel -> CRS
//    -> WGS84 -> h = H + N with build.json's geoid for orthometric heights -> ECEF); its
//    vertical is the WGS84 ellipsoid normal n = (cos lat cos lon, cos lat sin lon, sin lat)
//    at P's geodetic lat/lon. The vertical meets triangle ABC when P + t n hits ABC's plane at
//    a point X inside the closed triangle (3D barycentric coordinates >= -1e-9); the error
//    is |t|. The vertical is the half-line of the points with P's latitude and longitude,
//    t > -(N + h), where it reaches the polar axis: the rest of the line crosses the Earth
//    (the vertical of a pixel at the north pole is the axis, which meets every south-pole
//    vertex 12,700 km away). A tile's worst error is the max over its triangles and the
//    pixels meeting them; its ratio is worst / geometricError (inf for geometricError 0);
//    a tile is "over" when worst > geometricError, with no tolerance. Nodata pixels are skipped; triangles whose plane holds the vertical
//    (degenerate or vertical faces) meet no pixel and are counted apart.
//    Candidate pixels of a triangle: the bounding box on the DEM grid of its vertices and its
//    edges' points of largest |geocentric latitude| (ECEF -> geodetic, GeographicLib, ->
//    DEM CRS, OGR from EPSG:4326; col = (x - origin_x) / pixel_size_x - 0.5, row likewise),
//    grown by 2 pixels plus the chord's sideways bulge L^2 (1 + |tan lat|) / (4 R)
//    (L the longest edge, lat the most poleward of those points, R = 6.37e6 m) in pixels of
//    the smallest ground size (angle between neighbouring pixels' normals x b^2/a, a lower
//    bound) among the rows it spans. A geographic DEM's columns need no bulge: a point's
//    geodetic longitude is atan2(y, x), which on a flat triangle not around the polar axis
//    stays between its vertices' longitudes (the short way round); they wrap round a DEM
//    spanning 360 degrees. Its rows also get the geodetic/geocentric latitude difference's
//    variation over the triangle's heights. A vertex at a pole (within max(0.11 m, 4 position
//    steps) of the axis) has no longitude: its triangle takes that pole's rows whole and, for
//    the other rows, the columns its other vertices span; a triangle around the axis takes
//    every column of the rows from the pole on.
// 2. Regions hold their content (metres). Samples of every triangle: its vertices, 15 points
//    on each edge, the 66 interior points of a barycentric lattice of step 1/13, the point
//    nearest the Earth's centre (foot of the perpendicular from the origin when inside, and
//    the point of each edge nearest the origin), and each edge's point of largest |z / |X||.
//    Each goes to geodetic (GeographicLib) and its excursion outside the tile's region
//    [west, south, east, north (rad), min, max height (m)] is the distance to the region box,
//    sqrt(dlat^2 + dlon^2 + dh^2) with dlat = latitude excess x 6.37e6, dlon = longitude
//    excess (on the circle; west > east crosses the antimeridian) x 6.37e6 x cos lat, dh the
//    height excess. A sample is outside when any excess is > 0 (no tolerance); a sample on
//    the polar axis (latitude +-90) has no longitude and is inside in longitude.
//    A triangle provably inside its region by more than rounding (its vertices' longitudes
//    the short way round, its vertices' and edge extremes' latitudes widened by the
//    geodetic/geocentric difference's variation, its highest vertex, and below that a lower
//    bound of its height: the distance under the tangent plane at its centroid's foot, since
//    geodetic height is the signed distance to the convex ellipsoid) has every sample inside;
//    they are counted without converting each (ChordOptions::convert_every_sample does).
// 3. Sag (metres). A triangle's sag: the mean of its corners' geodetic heights minus the
//    geodetic height of its centroid (ECEF mean of the corners). Per zoom: the largest sag and
//    that triangle's longest edge, and the longest edge of any triangle (ECEF chord length).
//
// Cost: every pixel is placed once (parallel in row blocks); tiles and their triangles run
// in parallel (TBB), each thread with its own CRS transformations. Memory: 48 bytes per DEM
// pixel, 1 per pixel and zoom (which pixels are met), and one tile's decoded mesh per
// thread (ETOPO5, 9.3 M pixels and 5 zooms: 0.7 GB). Deterministic for any thread count.
// Throws Error(Input) with a one-line message for a directory that is not a terratiles
// output, an unreadable DEM, geoid or tile, and Error(Cancelled) when progress is cancelled.

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "src/base/progress.h"
#include "src/tiling/tile_key.h"

namespace terratiles {

// One zoom's figures (or the totals of all zooms: zoom = -1).
struct ChordZoomRow {
  std::int32_t zoom = -1;
  std::size_t tiles = 0;
  std::size_t triangles = 0;
  std::size_t vertical_triangles = 0;  // triangles whose plane holds the vertical (no pixel)
  std::size_t pole_triangles = 0;      // triangles with a vertex at a pole
  // 1. pixel verticals
  std::size_t pixel_meetings = 0;        // (pixel, triangle) pairs: a vertical meeting a triangle
  std::size_t min_tile_meetings = 0;     // the fewest meetings of any tile
  std::size_t candidate_pixels = 0;      // pixels tested
  // Valid pixels whose vertical meets no triangle of any tile of the zoom (not measured:
  // outside the scheme's latitudes, or where a chord's footprint pulls away from the pixel
  // lattice, e.g. under a long border edge); totals: the sum over zooms.
  std::size_t unmet_pixels = 0;
  // Of those, pixels on the data's edge (the grid's outer rows and columns, or next to
  // nodata): quantisation moves the outline's decoded vertices by millimetres, so a pixel
  // centre right on the outline may fall just outside it.
  std::size_t unmet_edge_pixels = 0;
  double worst_error_m = 0;              // max |t|
  double worst_below_m = 0;              // max -t: a chord below a DEM point
  double worst_above_m = 0;              // max t: a chord above a DEM point
  double worst_ratio = 0;                // max over tiles of worst / geometricError
  TileKey worst_ratio_tile{-1, 0, 0};
  double worst_ratio_tile_error_m = 0;   // that tile's worst error
  double worst_ratio_tile_geometric_error_m = 0;
  std::size_t tiles_over = 0;            // tiles with worst error > geometricError
  std::size_t zero_error_tiles = 0;      // tiles with geometricError 0 (ratio inf once they err)
  double worst_finite_ratio = 0;         // max ratio over tiles with geometricError > 0
  // 2. regions
  std::size_t region_samples = 0;
  std::size_t samples_outside = 0;
  std::size_t vertices_outside = 0;      // of those, triangle vertices
  std::size_t tiles_outside = 0;         // tiles with a sample outside their region
  double worst_excursion_m = 0;
  TileKey worst_excursion_tile{-1, 0, 0};
  // 3. sag
  double largest_sag_m = 0;
  double largest_sag_edge_m = 0;         // the longest edge of the triangle with the largest sag
  double longest_edge_m = 0;
};

struct ChordReport {
  std::string output_dir;
  std::string dem;                 // the inputs, as build.json names them
  std::string heights;             // "orthometric (geoid ...)" or "ellipsoidal"
  std::size_t dem_pixels = 0;      // valid pixels placed
  std::vector<ChordZoomRow> zooms; // coarsest first
  ChordZoomRow totals;
  double seconds = 0;
  // No tile's error over its geometricError and no sample outside its region.
  bool ok() const { return totals.tiles_over == 0 && totals.samples_outside == 0; }
};

struct ChordOptions {
  // Added to every triangle's candidate margin, in pixels (to test that the margin is enough:
  // a larger one must find the same meetings).
  double extra_margin_px = 0;
  // Convert every region sample to geodetic, also for triangles provably inside their region
  // (whose samples are otherwise counted without conversion: the counts are the same).
  bool convert_every_sample = false;
};

ChordReport measureChordGeometry(const std::string& output_dir, Progress& progress);
ChordReport measureChordGeometry(const std::string& output_dir, const ChordOptions& options, Progress& progress);

// A readable table: one row per zoom and the totals, then the verdict.
std::string describeChordReport(const ChordReport& report);
// One JSON object (every field of the report, per zoom and totals, and "ok").
std::string chordReportToJson(const ChordReport& report);

namespace detail {

// How far a geodetic point (radians, metres) lies outside a region [west, south, east, north
// (rad), min, max height (m)], as in 2. above; outside when any excess is > 0.
struct RegionExcursion {
  double metres = 0;
  bool outside = false;
};
RegionExcursion regionExcursion(const std::array<double, 6>& region, double lat_rad, double lon_rad, double h_m);

}  // namespace detail
}  // namespace terratiles
