#pragma once
// What a renderer draws from tiles, measured against the DEM (DESIGN.md 5): the build
// measures every tile this way on the positions its GLB will decode to, and `terratiles
// check` measures every decoded tile the same way, so a tile's geometricError bounds its
// decoded error with no slack, and the check agrees to the bit.
//
//   error      at every DEM pixel whose vertical meets one of the tile's triangles (as drawn,
//              straight in ECEF; forEachPixelMeeting): |offset| from the pixel's DEM point;
//   finer      where the next finer zoom is drawn over the same pixel too: the largest
//              difference between this tile's offsets and that zoom's there (ZoomSurface), so
//              that contents a viewer draws side by side agree within the coarser tile's
//              geometricError;
//   region     every point of every triangle: the vertices, the lowest point of each
//              triangle (a chord sags below its corners) and each edge's point nearest a pole
//              (a chord bulges poleward), and a pole itself when a triangle holds it.

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <vector>

#include "src/geo/dem_on_globe.h"
#include "src/geo/drawn_pixels.h"
#include "tileset/tileset.h"

namespace terratiles {

// Per DEM pixel of one zoom: the lowest and highest offset of the zoom's drawn surface above
// the pixel's DEM point (metres; over every triangle of every tile whose vertical meets the
// pixel), rounded outward to float; NaN where the zoom draws nothing there. A pixel's two
// floats side by side (one cache line for both). 8 bytes per pixel.
class ZoomSurface {
 public:
  explicit ZoomSurface(std::size_t pixels = 0) : bounds_(2 * pixels, std::numeric_limits<float>::quiet_NaN()) {}

  bool empty() const { return bounds_.empty(); }
  // Draws nothing anywhere again (keeps its memory).
  void clear() { std::fill(bounds_.begin(), bounds_.end(), std::numeric_limits<float>::quiet_NaN()); }
  bool drawn(std::size_t pixel) const { return !std::isnan(low(pixel)); }
  float low(std::size_t pixel) const { return bounds_[2 * pixel]; }
  float high(std::size_t pixel) const { return bounds_[2 * pixel + 1]; }
  // The largest |offset| there (0 where nothing is drawn).
  double error(std::size_t pixel) const {
    return drawn(pixel) ? std::max(std::fabs(static_cast<double>(low(pixel))), std::fabs(static_cast<double>(high(pixel))))
                        : 0.0;
  }
  // The largest |offset - o| over the offsets o drawn at the pixel (0 where none).
  double differenceTo(std::size_t pixel, double offset_m) const {
    if (!drawn(pixel)) return 0;
    return std::max(std::fabs(offset_m - low(pixel)), std::fabs(offset_m - high(pixel)));
  }
  // Adds an offset drawn at the pixel. Safe from several threads at once.
  void include(std::size_t pixel, double offset_m) {
    // The float at or below (above) the offset: it, or the next one out when it rounded in.
    float lower = static_cast<float>(offset_m), upper = lower;
    if (lower > offset_m) lower = nextFloatDown(lower);
    if (upper < offset_m) upper = nextFloatUp(upper);
    improve(bounds_[2 * pixel], lower, [](float p, float q) { return p < q; });
    improve(bounds_[2 * pixel + 1], upper, [](float p, float q) { return p > q; });
  }

 private:
  // std::nextafter towards -infinity and +infinity, for the finite floats an offset rounds to.
  static float nextFloatDown(float value) {
    if (value == 0) return -std::numeric_limits<float>::denorm_min();
    const auto bits = std::bit_cast<std::uint32_t>(value);
    return std::bit_cast<float>(value > 0 ? bits - 1 : bits + 1);
  }
  static float nextFloatUp(float value) { return -nextFloatDown(-value); }
  // Lowers (or raises) `slot` to `value` unless it already holds a lower (higher) one.
  template <typename Better>
  static void improve(float& slot, float value, Better better) {
    std::atomic_ref<float> ref(slot);
    float current = ref.load(std::memory_order_relaxed);
    while ((std::isnan(current) || better(value, current)) &&
           !ref.compare_exchange_weak(current, value, std::memory_order_relaxed)) {
    }
  }

  std::vector<float> bounds_;  // per pixel: low, high
};

// candidatePixels, mostly without strayMargin's per triangle work: per band of 64 rows, the
// least and largest |tan latitude| and row and column spacings bound strayMargin's margins
// from below and above; where the boxes with both bounds are one box (the margin then cannot
// move an edge of it, as every step from margin to box is monotone), that is the box; else
// (and near a pole, or in a band with a pole row) candidatePixels itself.
class PixelBoxes {
 public:
  explicit PixelBoxes(const DemOnGlobe& globe);
  // candidatePixels(globe, corners, longest_edge_m, shift_m), exactly.
  PixelBox box(const std::array<GridCorner, 3>& corners, double longest_edge_m, double shift_m) const;

 private:
  static constexpr std::int32_t kBandRows = 64;
  struct Band {
    // strayMargin's tan of the least and the largest |sin latitude| of the band's pixels.
    double tan_lat_low = 0, tan_lat_high = 0;
    // The least and largest spacings of the band's rows (for rows: but the raster's last row).
    double row_spacing_low_m = 0, row_spacing_high_m = 0;
    double column_spacing_low_m = 0, column_spacing_high_m = 0;
    bool usable = false;  // no pole row, spacings positive and finite
  };
  const DemOnGlobe& globe_;
  std::vector<Band> bands_;
};

// A DEM pixel whose vertical meets a drawn triangle, and the triangle's signed offset there.
struct PixelOffset {
  std::size_t pixel = 0;
  double offset_m = 0;
};

// Appends to `hits` exactly what forEachPixelMeeting(globe, triangle, box, ...) visits (the
// same pixels in the same order, the same offsets bit for bit: the same arithmetic, four
// pixels of a row at a time where the CPU has AVX2). `hits` is not cleared.
void pixelsMeeting(const DemOnGlobe& globe, const DrawnTriangle& triangle, const PixelBox& box,
                   std::vector<PixelOffset>& hits);

// The valid (not nodata) pixels forEachCoveredPixel(dem, a, b, c, ...) visits (inside the
// triangle in the grid), appended to `out` in its order (its arithmetic, four pixels of a
// row at a time where the CPU has AVX2).
void coveredValidPixels(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                        std::vector<std::uint32_t>& out);

struct DrawnTileMeasure {
  double max_error_m = 0;
  std::size_t hits = 0;    // pixel and triangle pairs (a pixel on a shared edge counts twice)
  std::size_t finer_hits = 0;  // of those, where the finer zoom is drawn too
  double finer_difference_m = 0;
};

// Measures a tile's triangles (`indices`, 3 per triangle, into `vertices`: ECEF as decoded,
// and `grid`: their positions in the DEM's grid, at most `shift_m` from the drawn ones). Adds
// every offset to `surface` (when not null) and compares with `finer` (when not null); each
// valid pixel a triangle meets goes to `met` (when not empty; a pixel met by several
// triangles once for each). `boxes` (when not null, made from `globe`) finds the candidate
// pixels faster, with the same result.
using MetPixel = std::function<void(std::size_t pixel)>;
DrawnTileMeasure measureDrawnTile(const DemOnGlobe& globe, std::span<const EcefPoint> vertices,
                                  std::span<const GridCorner> grid, std::span<const std::uint32_t> indices,
                                  double shift_m, const ZoomSurface* finer, ZoomSurface* surface,
                                  const MetPixel& met = {}, const PixelBoxes* boxes = nullptr);

// The same on a strip of a mosaic's rows: `strip` is the globe of the mosaic's rows
// first_row ... (its whole width), `grid` in the mosaic's pixels, `finer` and `surface` the
// strip's. Each triangle's candidate pixels come from `rows` (the mosaic's, LatticeRows) and
// are cut to the strip, so a pixel of the strip gets exactly the offsets a measure on the
// whole mosaic gives it, whatever rows the triangle spans outside the strip.
DrawnTileMeasure measureDrawnTileInStrip(const DemOnGlobe& strip, std::int64_t first_row, const LatticeRows& rows,
                                         std::span<const EcefPoint> vertices, std::span<const GridCorner> grid,
                                         std::span<const std::uint32_t> indices, double shift_m,
                                         const ZoomSurface* finer, ZoomSurface* surface);

// The outline of a triangle list: its edges that exactly one triangle has (an undirected edge
// counted over all triangles, so an edge three triangles share is not on it), as (smaller
// vertex, larger vertex) pairs in ascending order. Vertices are 0 .. vertex_count - 1. Linear
// time (edges bucketed by their smaller vertex); `scratch` is reused between calls.
struct OutlineScratch {
  std::vector<std::uint32_t> start;
  std::vector<std::uint32_t> other;
};
void outlineEdges(std::span<const std::uint32_t> indices, std::size_t vertex_count, OutlineScratch& scratch,
                  std::vector<std::array<std::uint32_t, 2>>& edges);

// A lower bound of the height above the WGS84 ellipsoid over a (flat) triangle, within
// micrometres of its least: what drawnRegion takes for a triangle over 10 km long.
double lowestHeightBound(const DrawnTriangle& triangle);

// The region holding every drawn point of the triangles (see the header comment), grown by a
// millimetre and 1e-10 rad against rounding. A vertex at a pole (|lat| within 1e-9 deg of 90)
// adds no longitude; one within 0.001 deg of the antimeridian makes it every longitude (it may
// decode on either side). `geodetic` (when not empty): every vertex's WGS84 latitude, longitude
// (degrees) and height as GeographicLib::Geocentric::WGS84().Reverse gives them, which the
// region would otherwise compute.
struct GeodeticOfVertex {
  double lat_deg = 0, lon_deg = 0, h_m = 0;
};
Region drawnRegion(std::span<const EcefPoint> vertices, std::span<const std::uint32_t> indices,
                   std::span<const GeodeticOfVertex> geodetic = {});

}  // namespace terratiles
