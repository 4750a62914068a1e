#include "src/pipeline/drawn_tiles.h"

#include <GeographicLib/Geocentric.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <numbers>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include "src/geo/dem_on_globe_lanes.h"
#include "src/tin/measure_tin.h"

namespace terratiles {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kPoleDeg = 90 - 1e-9;

struct Geodetic {
  double lat_deg, lon_deg, h_m;
};

Geodetic geodeticOf(double x, double y, double z) {
  Geodetic g{};
  GeographicLib::Geocentric::WGS84().Reverse(x, y, z, g.lat_deg, g.lon_deg, g.h_m);
  return g;
}

#if defined(__x86_64__)
const bool kHasAvx2 = __builtin_cpu_supports("avx2");

__attribute__((target("avx2"))) inline __m256d mul(__m256d p, __m256d q) { return _mm256_mul_pd(p, q); }
__attribute__((target("avx2"))) inline __m256d add(__m256d p, __m256d q) { return _mm256_add_pd(p, q); }
__attribute__((target("avx2"))) inline __m256d sub(__m256d p, __m256d q) { return _mm256_sub_pd(p, q); }

// DrawnTriangle::meets for the four pixels from index i on (lane k: pixel i + k), as its
// scalar code computes it operation for operation (no fused multiply-add: AVX2 alone has
// none), so a lane's verdict and offset are the scalar ones bit for bit. Returns the lanes
// that meet (bit k: lane k); offsets[k] is lane k's offset where it meets.
__attribute__((target("avx2"))) unsigned meets4(const DemOnGlobe& globe, const DrawnTriangle& tri, std::int32_t col,
                                                std::int32_t row, std::size_t i, double offsets[4]) {
  constexpr double kTolerance = 1e-9;  // DrawnTriangle::meets's
  const PixelLanes pixels = pixelLanes(globe, col, row, i);
  const __m256d x = pixels.x, y = pixels.y, z = pixels.z, ux = pixels.ux, uy = pixels.uy, uz = pixels.uz;
  const __m256d ab0 = _mm256_set1_pd(tri.ab[0]), ab1 = _mm256_set1_pd(tri.ab[1]), ab2 = _mm256_set1_pd(tri.ab[2]);
  const __m256d ac0 = _mm256_set1_pd(tri.ac[0]), ac1 = _mm256_set1_pd(tri.ac[1]), ac2 = _mm256_set1_pd(tri.ac[2]);
  const __m256d ax = _mm256_set1_pd(tri.a.x), ay = _mm256_set1_pd(tri.a.y), az = _mm256_set1_pd(tri.a.z);
  const __m256d px = sub(mul(uy, ac2), mul(uz, ac1)), py = sub(mul(uz, ac0), mul(ux, ac2)),
                pz = sub(mul(ux, ac1), mul(uy, ac0));
  const __m256d det = add(add(mul(ab0, px), mul(ab1, py)), mul(ab2, pz));
  const __m256d sign = _mm256_set1_pd(-0.0);
  // det != 0 and finite (NaN fails both).
  __m256d ok = _mm256_and_pd(_mm256_cmp_pd(det, _mm256_setzero_pd(), _CMP_NEQ_OQ),
                             _mm256_cmp_pd(_mm256_andnot_pd(sign, det), _mm256_set1_pd(HUGE_VAL), _CMP_LT_OQ));
  const __m256d inverse = _mm256_div_pd(_mm256_set1_pd(1.0), det);
  const __m256d tx = sub(x, ax), ty = sub(y, ay), tz = sub(z, az);
  const __m256d u = mul(add(add(mul(tx, px), mul(ty, py)), mul(tz, pz)), inverse);
  const __m256d low = _mm256_set1_pd(-kTolerance), high = _mm256_set1_pd(1 + kTolerance);
  // The scalar code refuses u < low or u > high: a NaN goes on, as there.
  ok = _mm256_and_pd(ok, _mm256_and_pd(_mm256_cmp_pd(u, low, _CMP_NLT_UQ), _mm256_cmp_pd(u, high, _CMP_NGT_UQ)));
  const __m256d qx = sub(mul(ty, ab2), mul(tz, ab1)), qy = sub(mul(tz, ab0), mul(tx, ab2)),
                qz = sub(mul(tx, ab1), mul(ty, ab0));
  const __m256d v = mul(add(add(mul(ux, qx), mul(uy, qy)), mul(uz, qz)), inverse);
  ok = _mm256_and_pd(ok, _mm256_and_pd(_mm256_cmp_pd(v, low, _CMP_NLT_UQ), _mm256_cmp_pd(add(u, v), high, _CMP_NGT_UQ)));
  if (_mm256_movemask_pd(ok) == 0) return 0;
  // DrawnTriangle::offset: 0 at a corner's own point, else across / along (along = 0 gives an
  // infinity or NaN that fails the reach, as the scalar NaN does).
  const __m256d n0 = _mm256_set1_pd(tri.normal[0]), n1 = _mm256_set1_pd(tri.normal[1]),
                n2 = _mm256_set1_pd(tri.normal[2]);
  const __m256d along = add(add(mul(n0, ux), mul(n1, uy)), mul(n2, uz));
  const __m256d across = add(add(mul(n0, sub(ax, x)), mul(n1, sub(ay, y))), mul(n2, sub(az, z)));
  __m256d at_corner = _mm256_setzero_pd();
  for (int k = 0; k < 3; ++k) {
    const EcefPoint& c = tri.corner(k);
    at_corner = _mm256_or_pd(
        at_corner, _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(x, _mm256_set1_pd(c.x), _CMP_EQ_OQ),
                                               _mm256_cmp_pd(y, _mm256_set1_pd(c.y), _CMP_EQ_OQ)),
                                 _mm256_cmp_pd(z, _mm256_set1_pd(c.z), _CMP_EQ_OQ)));
  }
  const __m256d offset = _mm256_blendv_pd(_mm256_div_pd(across, along), _mm256_setzero_pd(), at_corner);
  ok = _mm256_and_pd(ok, _mm256_cmp_pd(_mm256_andnot_pd(sign, offset), _mm256_set1_pd(DrawnTriangle::kReach_m),
                                       _CMP_LE_OQ));
  _mm256_storeu_pd(offsets, offset);
  return static_cast<unsigned>(_mm256_movemask_pd(ok));
}
#endif

#if defined(__x86_64__)

// (p.col - col) * (q.row - row) - (p.row - row) * (q.col - col), four columns at a time.
__attribute__((target("avx2"))) inline __m256d weightTerm(const GridPoint& p, const GridPoint& q, __m256d cols,
                                                          __m256d rows) {
  return _mm256_sub_pd(
      _mm256_mul_pd(_mm256_sub_pd(_mm256_set1_pd(p.col), cols), _mm256_sub_pd(_mm256_set1_pd(q.row), rows)),
      _mm256_mul_pd(_mm256_sub_pd(_mm256_set1_pd(p.row), rows), _mm256_sub_pd(_mm256_set1_pd(q.col), cols)));
}

// forEachCoveredPixel's test of four pixels (columns col .. col + 3 of `row`) as its scalar
// code computes it, operation for operation (AVX2 has no fused multiply-add): bit k set when
// column col + k is covered.
__attribute__((target("avx2"))) unsigned covered4(const GridPoint& a, const GridPoint& b, const GridPoint& c,
                                                  double area2, double eps, double col, double row) {
  const __m256d cols = _mm256_add_pd(_mm256_set1_pd(col), _mm256_set_pd(3, 2, 1, 0));
  const __m256d rows = _mm256_set1_pd(row);
  const __m256d area = _mm256_set1_pd(area2), size = _mm256_set1_pd(std::fabs(area2));
  const __m256d wa = _mm256_div_pd(weightTerm(b, c, cols, rows), area), wb = _mm256_div_pd(weightTerm(c, a, cols, rows), area);
  const __m256d wc = _mm256_sub_pd(_mm256_sub_pd(_mm256_set1_pd(1.0), wa), wb);
  const __m256d below = _mm256_set1_pd(-eps);
  const __m256d outside =
      _mm256_or_pd(_mm256_or_pd(_mm256_cmp_pd(_mm256_mul_pd(wa, size), below, _CMP_LT_OQ),
                                _mm256_cmp_pd(_mm256_mul_pd(wb, size), below, _CMP_LT_OQ)),
                   _mm256_cmp_pd(_mm256_mul_pd(wc, size), below, _CMP_LT_OQ));
  return static_cast<unsigned>(~_mm256_movemask_pd(outside)) & 15u;
}
#endif

// Pixels [first_col, last_col] of one row meeting the triangle, appended in order.
void rowMeeting(const DemOnGlobe& globe, const DrawnTriangle& triangle, std::int32_t row, std::int32_t first_col,
                std::int32_t last_col, std::vector<PixelOffset>& hits) {
  const std::size_t row_start = globe.dem().index(0, row);
#if defined(__x86_64__)
  if (kHasAvx2) {
    // The last step reads up to three pixels past `last_col` (never kept): past the raster's
    // end on its last row, DemOnGlobe's arrays hold kDemOnGlobePadding pixels more for that.
    static_assert(kDemOnGlobePadding >= 3);
    double offsets[4];
    for (std::int32_t col = first_col; col <= last_col; col += 4) {
      const std::size_t i = row_start + static_cast<std::size_t>(col);
      unsigned met = meets4(globe, triangle, col, row, i, offsets);
      if (last_col - col < 3) met &= (1u << (last_col - col + 1)) - 1;
      for (; met != 0; met &= met - 1) {
        const int lane = std::countr_zero(met);
        hits.push_back({i + static_cast<std::size_t>(lane), offsets[lane]});
      }
    }
    return;
  }
#endif
  for (std::int32_t col = first_col; col <= last_col; ++col) {
    double offset_m = 0;
    if (triangle.meets(globe.point(col, row), globe.up(col, row), &offset_m)) {
      hits.push_back({row_start + static_cast<std::size_t>(col), offset_m});
    }
  }
}

}  // namespace

void coveredValidPixels(const DemGrid& dem, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                        std::vector<std::uint32_t>& out) {
#if defined(__x86_64__)
  if (kHasAvx2) {
    // forEachCoveredPixel's box and tolerance.
    const CoveredPixelBox box = coveredPixelBox(dem, a, b, c);
    const double area2 = box.area2, eps = box.eps;
    if (area2 == 0) return;
    const int min_col = box.min_col, max_col = box.max_col;
    for (int row = box.min_row; row <= box.max_row; ++row) {
      for (int col = min_col; col <= max_col; col += 4) {
        unsigned inside = covered4(a, b, c, area2, eps, col, row);
        if (max_col - col < 3) inside &= (1u << (max_col - col + 1)) - 1;
        for (; inside != 0; inside &= inside - 1) {
          const std::size_t pixel = dem.index(col + std::countr_zero(inside), row);
          if (!std::isnan(dem.heights_m[pixel])) out.push_back(static_cast<std::uint32_t>(pixel));
        }
      }
    }
    return;
  }
#endif
  forEachCoveredPixel(dem, a, b, c, [&](std::size_t pixel, double) {
    if (!std::isnan(dem.heights_m[pixel])) out.push_back(static_cast<std::uint32_t>(pixel));
    return true;
  });
}

void pixelsMeeting(const DemOnGlobe& globe, const DrawnTriangle& triangle, const PixelBox& box,
                   std::vector<PixelOffset>& hits) {
  // forEachPixelMeeting's loops, a row's run of columns at a time.
  if (triangle.degenerate()) return;
  const DemGrid& dem = globe.dem();
  const std::int32_t first_row = std::max(0, box.row0), last_row = std::min(dem.height - 1, box.row1);
  if (box.col1 < box.col0) return;
  for (std::int32_t row = first_row; row <= last_row; ++row) {
    if (globe.wrapsLongitude()) {
      // Columns modulo the width, in the order c = col0 .. col1: runs split at the seam.
      for (std::int64_t c = box.col0; c <= box.col1;) {
        std::int64_t col = c % dem.width;
        if (col < 0) col += dem.width;
        const std::int64_t run = std::min<std::int64_t>(box.col1 - c, dem.width - 1 - col);
        rowMeeting(globe, triangle, row, static_cast<std::int32_t>(col), static_cast<std::int32_t>(col + run), hits);
        c += run + 1;
      }
      continue;
    }
    const std::int64_t first_col = std::max<std::int64_t>(0, box.col0);
    const std::int64_t last_col = std::min<std::int64_t>(dem.width - 1, box.col1);
    if (first_col > last_col) continue;
    rowMeeting(globe, triangle, row, static_cast<std::int32_t>(first_col), static_cast<std::int32_t>(last_col), hits);
  }
}

PixelBoxes::PixelBoxes(const DemOnGlobe& globe) : globe_(globe) {
  const DemGrid& dem = globe.dem();
  const std::int32_t bands = (dem.height + kBandRows - 1) / kBandRows;
  bands_.resize(static_cast<std::size_t>(bands));
  constexpr double kInfinity = std::numeric_limits<double>::infinity();
  tbb::parallel_for(std::int32_t{0}, bands, [&](std::int32_t b) {
    Band& band = bands_[static_cast<std::size_t>(b)];
    double sin_low = kInfinity, sin_high = 0;
    double row_low = kInfinity, row_high = -kInfinity, column_low = kInfinity, column_high = -kInfinity;
    bool pole = false;
    for (std::int32_t row = b * kBandRows; row < std::min(dem.height, (b + 1) * kBandRows); ++row) {
      pole = pole || globe.poleRow(row);
      if (row < dem.height - 1) {
        row_low = std::min(row_low, globe.rowSpacing(row));
        row_high = std::max(row_high, globe.rowSpacing(row));
      }
      column_low = std::min(column_low, globe.columnSpacing(row));
      column_high = std::max(column_high, globe.columnSpacing(row));
      for (std::int32_t col = 0; col < dem.width; ++col) {
        const double s = std::fabs(globe.sinLatitude(col, row));
        sin_low = std::min(sin_low, s);
        sin_high = std::max(sin_high, s);
      }
    }
    // As strayMargin computes it from a corner's sine: increasing in the sine.
    const auto tanOf = [](double sin_lat) {
      return std::min(1e6, sin_lat / std::sqrt(std::max(1e-12, 1 - sin_lat * sin_lat)));
    };
    band.tan_lat_low = tanOf(sin_low);
    band.tan_lat_high = tanOf(sin_high);
    band.row_spacing_low_m = row_low;
    band.row_spacing_high_m = row_high;
    band.column_spacing_low_m = column_low;
    band.column_spacing_high_m = column_high;
    band.usable = !pole && row_low > 0 && std::isfinite(row_high) && column_low > 0 && std::isfinite(column_high) &&
                  std::isfinite(band.tan_lat_low) && std::isfinite(band.tan_lat_high);
  });
}

PixelBox PixelBoxes::box(const std::array<GridCorner, 3>& corners, double longest_edge_m, double shift_m) const {
  const DemGrid& dem = globe_.dem();
  double row_min = 1e300, row_max = -1e300, col_min = 1e300, col_max = -1e300;
  for (const GridCorner& corner : corners) {
    if (corner.at_pole) return candidatePixels(globe_, corners, longest_edge_m, shift_m);
    row_min = std::min(row_min, corner.row);
    row_max = std::max(row_max, corner.row);
    col_min = std::min(col_min, corner.col);
    col_max = std::max(col_max, corner.col);
  }
  if (!(col_min <= col_max) || !(row_min <= row_max)) return candidatePixels(globe_, corners, longest_edge_m, shift_m);
  // strayMargin's rows (its corners' sines come from rows among them), by band; at least one
  // of them has a row spacing (else its margin in rows is 0).
  const auto first_row = static_cast<std::int32_t>(std::clamp(std::floor(row_min) - 1, 0.0, dem.height - 1.0));
  const auto last_row = static_cast<std::int32_t>(std::clamp(std::ceil(row_max) + 1, 0.0, dem.height - 1.0));
  if (first_row >= dem.height - 1) return candidatePixels(globe_, corners, longest_edge_m, shift_m);
  constexpr double kInfinity = std::numeric_limits<double>::infinity();
  double tan_low = kInfinity, tan_high = 0;
  double row_low = kInfinity, row_high = 0, column_low = kInfinity, column_high = 0;
  for (std::int32_t b = first_row / kBandRows; b <= last_row / kBandRows; ++b) {
    const Band& band = bands_[static_cast<std::size_t>(b)];
    if (!band.usable) return candidatePixels(globe_, corners, longest_edge_m, shift_m);
    tan_low = std::min(tan_low, band.tan_lat_low);
    tan_high = std::max(tan_high, band.tan_lat_high);
    row_low = std::min(row_low, band.row_spacing_low_m);
    row_high = std::max(row_high, band.row_spacing_high_m);
    column_low = std::min(column_low, band.column_spacing_low_m);
    column_high = std::max(column_high, band.column_spacing_high_m);
  }
  // strayMargin's arithmetic with the bounds in: each step is monotone, so its margins lie
  // between these.
  constexpr double kRadius_m = 6.3e6;  // strayMargin's
  const auto marginOf = [&](double tan_lat) {
    const double bulge_m = longest_edge_m * longest_edge_m * (1 + tan_lat) / (2 * kRadius_m);
    return bulge_m + shift_m;
  };
  const double least_m = marginOf(tan_low), most_m = marginOf(tan_high);
  const double least_rows = least_m / row_high, least_columns = least_m / column_high;
  const double most_rows = most_m / row_low, most_columns = most_m / column_low;
  if (!(least_rows >= 0 && least_columns >= 0 && most_rows < 1e9 && most_columns < 1e9)) {
    return candidatePixels(globe_, corners, longest_edge_m, shift_m);
  }
  // strayMargin's longitude_columns (no pole row here): the box grows by the smaller margin.
  double least_box_columns = least_columns, most_box_columns = most_columns;
  const double degrees = globe_.degreesPerColumn();
  if (longitudeBoundHolds(col_max - col_min, degrees)) {
    const double least_shift = shiftColumns(shift_m, column_high), most_shift = shiftColumns(shift_m, column_low);
    const bool least_bounds = shiftColumnsHold(least_shift, degrees), most_bounds = shiftColumnsHold(most_shift, degrees);
    if (least_bounds != most_bounds) return candidatePixels(globe_, corners, longest_edge_m, shift_m);
    if (least_bounds) {
      least_box_columns = std::min(least_columns, least_shift);
      most_box_columns = std::min(most_columns, most_shift);
    }
  }
  // candidatePixels's box (no corner at a pole) for both margins: an edge is the same for
  // both when the value rounded for the smaller margin rounds (up or down) to the value
  // rounded for the larger one (every value between then rounds there too).
  const double row_first_most = std::ceil(row_min - most_rows - 1e-9);
  const double row_last_most = std::floor(row_max + most_rows + 1e-9);
  const double col_first_most = std::ceil(col_min - most_box_columns - 1e-9);
  const double col_last_most = std::floor(col_max + most_box_columns + 1e-9);
  if (row_min - least_rows - 1e-9 <= row_first_most && row_max + least_rows + 1e-9 >= row_last_most &&
      col_min - least_box_columns - 1e-9 <= col_first_most && col_max + least_box_columns + 1e-9 >= col_last_most) {
    PixelBox out;
    out.row0 = static_cast<std::int32_t>(std::max(0.0, row_first_most));
    out.row1 = static_cast<std::int32_t>(std::min(dem.height - 1.0, row_last_most));
    double first = col_first_most, last = col_last_most;
    if (last - first + 1 >= dem.width) {
      first = 0;
      last = dem.width - 1;
    }
    if (!globe_.wrapsLongitude()) {
      first = std::max(first, 0.0);
      last = std::min(last, dem.width - 1.0);
    }
    out.col0 = static_cast<std::int64_t>(first);
    out.col1 = static_cast<std::int64_t>(last);
    return out;
  }
  return candidatePixels(globe_, corners, longest_edge_m, shift_m);
}

namespace {

// measureDrawnTile with the candidate pixels of each triangle from `boxOf(corners, triangle)`.
template <typename BoxOf>
DrawnTileMeasure measureTriangles(const DemOnGlobe& globe, std::span<const EcefPoint> vertices,
                                  std::span<const GridCorner> grid, std::span<const std::uint32_t> indices,
                                  const ZoomSurface* finer, ZoomSurface* surface, const MetPixel& met,
                                  BoxOf&& boxOf) {
  DrawnTileMeasure measure;
  const DemGrid& dem = globe.dem();
  std::vector<PixelOffset> hits;
  for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
    const DrawnTriangle triangle(vertices[indices[t]], vertices[indices[t + 1]], vertices[indices[t + 2]]);
    if (triangle.degenerate()) continue;
    const std::array<GridCorner, 3> corners{grid[indices[t]], grid[indices[t + 1]], grid[indices[t + 2]]};
    const PixelBox box = boxOf(corners, triangle);
    if (box.row1 < box.row0) continue;
    hits.clear();
    pixelsMeeting(globe, triangle, box, hits);
    for (const auto& [pixel, offset_m] : hits) {
      if (std::isnan(dem.heights_m[pixel])) continue;
      const double error = std::fabs(offset_m);
      measure.max_error_m = std::max(measure.max_error_m, error);
      ++measure.hits;
      if (finer && finer->drawn(pixel)) {
        ++measure.finer_hits;
        measure.finer_difference_m = std::max(measure.finer_difference_m, finer->differenceTo(pixel, offset_m));
      }
      if (surface) surface->include(pixel, offset_m);
      if (met) met(pixel);
    }
  }
  return measure;
}

}  // namespace

DrawnTileMeasure measureDrawnTile(const DemOnGlobe& globe, std::span<const EcefPoint> vertices,
                                  std::span<const GridCorner> grid, std::span<const std::uint32_t> indices,
                                  double shift_m, const ZoomSurface* finer, ZoomSurface* surface,
                                  const MetPixel& met, const PixelBoxes* boxes) {
  return measureTriangles(globe, vertices, grid, indices, finer, surface, met,
                          [&](const std::array<GridCorner, 3>& corners, const DrawnTriangle& triangle) {
                            return boxes ? boxes->box(corners, triangle.longestEdge(), shift_m)
                                         : candidatePixels(globe, corners, triangle.longestEdge(), shift_m);
                          });
}

DrawnTileMeasure measureDrawnTileInStrip(const DemOnGlobe& strip, std::int64_t first_row, const LatticeRows& rows,
                                         std::span<const EcefPoint> vertices, std::span<const GridCorner> grid,
                                         std::span<const std::uint32_t> indices, double shift_m,
                                         const ZoomSurface* finer, ZoomSurface* surface) {
  const std::int64_t strip_rows = strip.dem().height;
  return measureTriangles(strip, vertices, grid, indices, finer, surface, {},
                          [&](const std::array<GridCorner, 3>& corners, const DrawnTriangle& triangle) {
                            PixelBox box = rows.box(corners, triangle.longestEdge(), shift_m);
                            const std::int64_t row0 = std::max<std::int64_t>(box.row0 - first_row, 0);
                            const std::int64_t row1 = std::min<std::int64_t>(box.row1 - first_row, strip_rows - 1);
                            box.row0 = static_cast<std::int32_t>(row0);
                            box.row1 = static_cast<std::int32_t>(std::max<std::int64_t>(row1, row0 - 1));
                            return box;
                          });
}

void outlineEdges(std::span<const std::uint32_t> indices, std::size_t vertex_count, OutlineScratch& scratch,
                  std::vector<std::array<std::uint32_t, 2>>& edges) {
  edges.clear();
  // Edges bucketed by their smaller vertex (a counting sort), each bucket holding the larger
  // ones; a bucket is sorted on its own (a handful of edges, but thousands round a pole).
  std::vector<std::uint32_t>& start = scratch.start;
  std::vector<std::uint32_t>& other = scratch.other;
  start.assign(vertex_count + 1, 0);
  const std::size_t triangles = indices.size() / 3;
  for (std::size_t t = 0; t < triangles; ++t) {
    const std::uint32_t a = indices[3 * t], b = indices[3 * t + 1], c = indices[3 * t + 2];
    ++start[std::min(a, b) + 1];
    ++start[std::min(b, c) + 1];
    ++start[std::min(c, a) + 1];
  }
  for (std::size_t v = 0; v < vertex_count; ++v) start[v + 1] += start[v];
  other.resize(3 * triangles);
  for (std::size_t t = 0; t < triangles; ++t) {
    const std::uint32_t corner[3] = {indices[3 * t], indices[3 * t + 1], indices[3 * t + 2]};
    for (std::size_t k = 0; k < 3; ++k) {
      const std::uint32_t a = corner[k], b = corner[(k + 1) % 3];
      other[start[std::min(a, b)]++] = std::max(a, b);
    }
  }
  // start[v] now ends bucket v: bucket v is [start[v - 1], start[v]).
  std::uint32_t begin = 0;
  for (std::size_t v = 0; v < vertex_count; ++v) {
    const std::uint32_t end = start[v];
    std::uint32_t* first = other.data() + begin;
    std::uint32_t* last = other.data() + end;
    if (end - begin <= 16) {
      for (std::uint32_t* i = first + 1; i < last; ++i) {  // insertion sort
        const std::uint32_t value = *i;
        std::uint32_t* j = i;
        for (; j > first && *(j - 1) > value; --j) *j = *(j - 1);
        *j = value;
      }
    } else {
      std::sort(first, last);
    }
    for (std::uint32_t* i = first; i < last;) {
      std::uint32_t* j = i + 1;
      while (j < last && *j == *i) ++j;
      if (j - i == 1) edges.push_back({static_cast<std::uint32_t>(v), *i});
      i = j;
    }
    begin = end;
  }
}

// The height is the signed distance to the ellipsoid, a convex function whose gradient is the
// up vector n of the point's latitude and longitude, so from any point x of the triangle every
// point y of it is at least h(x) + n(x).(y - x) high, and the least of that over the triangle is
// at a corner (Frank and Wolfe's gap: zero at the lowest point). x runs through Newton's steps
// from the centroid (the height curves by about 1 / |x| across n) and, when they leave the
// triangle, along each edge from its middle, until the bound is within 0.1 mm of the lowest
// height seen: usually two or three conversions, where a lattice every 10 km took up to 2,000.
double lowestHeightBound(const DrawnTriangle& triangle) {
  constexpr double kGap_m = 1e-4;  // stop once the bound is this close to a height found
  struct Sample {
    double x[3]{}, n[3]{};
  };
  const auto dot = [](const double* p, const double* q) { return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]; };
  const double origin[3] = {triangle.a.x, triangle.a.y, triangle.a.z};
  double lowest_found = HUGE_VAL, bound = -HUGE_VAL;
  // Samples the point a + u ab + w ac: its height, up vector and the bound from it.
  const auto sample = [&](double u, double w) {
    Sample s;
    for (int i = 0; i < 3; ++i) s.x[i] = origin[i] + u * triangle.ab[i] + w * triangle.ac[i];
    const Geodetic g = geodeticOf(s.x[0], s.x[1], s.x[2]);
    const double lat = g.lat_deg * kDegToRad, lon = g.lon_deg * kDegToRad;
    s.n[0] = std::cos(lat) * std::cos(lon);
    s.n[1] = std::cos(lat) * std::sin(lon);
    s.n[2] = std::sin(lat);
    double least = 0;  // n.(corner - x) over the corners, at most 0 (x is in the triangle)
    for (int k = 0; k < 3; ++k) {
      const EcefPoint& c = triangle.corner(k);
      least = std::min(least, s.n[0] * (c.x - s.x[0]) + s.n[1] * (c.y - s.x[1]) + s.n[2] * (c.z - s.x[2]));
    }
    lowest_found = std::min(lowest_found, g.h_m);
    bound = std::max(bound, g.h_m + least);
    return s;
  };
  const auto tight = [&] { return lowest_found - bound <= kGap_m; };
  const auto radius = [&](const Sample& s) { return std::sqrt(dot(s.x, s.x)); };
  constexpr int kSteps = 4;
  // Inside: Newton on (u, w), from the centroid.
  double u = 1.0 / 3, w = 1.0 / 3;
  for (int step = 0; step < kSteps; ++step) {
    const Sample s = sample(u, w);
    if (tight()) return bound;
    const double g0 = dot(s.n, triangle.ab.data()), g1 = dot(s.n, triangle.ac.data());
    const double r = radius(s);
    const double h00 = (dot(triangle.ab.data(), triangle.ab.data()) - g0 * g0) / r;
    const double h11 = (dot(triangle.ac.data(), triangle.ac.data()) - g1 * g1) / r;
    const double h01 = (dot(triangle.ab.data(), triangle.ac.data()) - g0 * g1) / r;
    const double det = h00 * h11 - h01 * h01;
    if (!(det > 0)) break;
    u -= (h11 * g0 - h01 * g1) / det;
    w -= (h00 * g1 - h01 * g0) / det;
    if (!(u >= 0 && w >= 0 && u + w <= 1)) break;  // the lowest point is on the outline
  }
  // Along each edge p + t (q - p): Newton on t, held in [0, 1], from its middle.
  const double corner_uw[3][2] = {{0, 0}, {1, 0}, {0, 1}};
  for (int k = 0; k < 3; ++k) {
    const double* p = corner_uw[k];
    const double* q = corner_uw[(k + 1) % 3];
    double d[3];
    for (int i = 0; i < 3; ++i) d[i] = (q[0] - p[0]) * triangle.ab[i] + (q[1] - p[1]) * triangle.ac[i];
    const double dd = dot(d, d);
    double t = 0.5;
    for (int step = 0; step < kSteps; ++step) {
      const Sample s = sample(p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]));
      if (tight()) return bound;
      const double slope = dot(s.n, d), curvature = (dd - slope * slope) / radius(s);
      if (!(curvature > 0)) break;
      const double next = std::clamp(t - slope / curvature, 0.0, 1.0);
      if (next == t) break;
      t = next;
    }
  }
  return bound;
}

Region drawnRegion(std::span<const EcefPoint> vertices, std::span<const std::uint32_t> indices,
                   std::span<const GeodeticOfVertex> known) {
  Region region;
  std::vector<Geodetic> geodetic(vertices.size());
  std::vector<std::uint8_t> used(vertices.size(), 0);
  for (const std::uint32_t v : indices) used[v] = 1;
  bool all_longitudes = false;
  // The tangent of a point's geocentric latitude (infinite at a pole), which grows with it.
  const auto geocentricTan = [](double x, double y, double z) { return z / std::sqrt(x * x + y * y); };
  // Per vertex: what every triangle round it takes.
  std::vector<double> geocentric_tan(vertices.size(), 0.0);
  // Vertices; one at a pole adds no longitude (it has none).
  std::vector<std::size_t> poles;
  for (std::size_t v = 0; v < vertices.size(); ++v) {
    if (!used[v]) continue;
    geodetic[v] = known.empty() ? geodeticOf(vertices[v].x, vertices[v].y, vertices[v].z)
                                : Geodetic{known[v].lat_deg, known[v].lon_deg, known[v].h_m};
    geocentric_tan[v] = geocentricTan(vertices[v].x, vertices[v].y, vertices[v].z);
    if (std::fabs(geodetic[v].lat_deg) >= kPoleDeg) {
      poles.push_back(v);
      continue;
    }
    region.include(geodetic[v].lon_deg * kDegToRad, geodetic[v].lat_deg * kDegToRad, geodetic[v].h_m);
  }
  double south = region.empty ? 1e300 : region.south_rad, north = region.empty ? -1e300 : region.north_rad;
  double low = region.empty ? 1e300 : region.min_height_m, high = region.empty ? -1e300 : region.max_height_m;
  const auto extend = [&](const Geodetic& g) {
    south = std::min(south, g.lat_deg * kDegToRad);
    north = std::max(north, g.lat_deg * kDegToRad);
    low = std::min(low, g.h_m);
    high = std::max(high, g.h_m);
  };
  for (const std::size_t v : poles) extend(geodetic[v]);
  constexpr double kRadius_m = 6.3e6;  // below every radius of curvature of WGS84's level surfaces we meet
  struct LongTriangle {
    double lowest;         // the curvature's bound
    double lowest_corner;  // its lowest corner's height
    std::size_t t;         // its first index
  };
  std::vector<LongTriangle> long_triangles, may_lower;  // may_lower: those whose bound is below low
  // Latitudes: the geocentric latitude on a flat triangle not pierced by the polar axis is
  // extreme on its edges, where the extreme of z / |X| on A + mu (B - A) is at the mu that
  // zeroes its derivative (a linear equation); the geodetic latitude of a point is
  // atan(tan(geocentric) * F) with F = (N + h) / (N (1 - e^2) + h), which grows with |tan|
  // and shrinks with h and (for h above 0) with N: so the extremes over the triangle are
  // bounded by its geocentric extremes with F at a height at most its lowest (for the latitude
  // away from the equator) or its highest (towards it), N at either end of its range.
  // N runs from a (equator) to a / sqrt(1 - e^2) (poles).
  const auto& earth = GeographicLib::Geocentric::WGS84();
  const double semi_major = earth.EquatorialRadius(), e2 = earth.Flattening() * (2 - earth.Flattening());
  const auto factor = [e2](double radius, double h) { return (radius + h) / (radius * (1 - e2) + h); };
  const double polar_n = semi_major / std::sqrt(1 - e2);
  double north_tan = -HUGE_VAL, south_tan = HUGE_VAL;  // tangents of the bounds (atan is monotone)
  const auto boundLatitudes = [&](std::size_t t, double lowest_h) {
    double lowest_c = HUGE_VAL, highest_c = -HUGE_VAL;  // tangents of geocentric latitudes
    for (std::size_t k = 0; k < 3; ++k) {
      const double tan_c = geocentric_tan[indices[t + k]];
      lowest_c = std::min(lowest_c, tan_c);
      highest_c = std::max(highest_c, tan_c);
    }
    const EcefPoint corner[3] = {vertices[indices[t]], vertices[indices[t + 1]], vertices[indices[t + 2]]};
    for (int k = 0; k < 3; ++k) {
      const EcefPoint& p = corner[k];
      const EcefPoint& q = corner[(k + 1) % 3];
      const double d[3] = {q.x - p.x, q.y - p.y, q.z - p.z};
      const double pd = p.x * d[0] + p.y * d[1] + p.z * d[2];
      const double pp = p.x * p.x + p.y * p.y + p.z * p.z, dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
      const double denominator = d[2] * pd - p.z * dd;
      if (denominator == 0) continue;
      const double mu = (p.z * pd - d[2] * pp) / denominator;
      if (!(mu > 0 && mu < 1)) continue;
      const double tan_c = geocentricTan(p.x + mu * d[0], p.y + mu * d[1], p.z + mu * d[2]);
      lowest_c = std::min(lowest_c, tan_c);
      highest_c = std::max(highest_c, tan_c);
    }
    const double highest_h =
        std::max({geodetic[indices[t]].h_m, geodetic[indices[t + 1]].h_m, geodetic[indices[t + 2]].h_m});
    const double f_low_h = std::max(factor(semi_major, lowest_h), factor(polar_n, lowest_h));
    const double f_high_h = std::min(factor(semi_major, highest_h), factor(polar_n, highest_h));
    north_tan = std::max(north_tan, highest_c * (highest_c >= 0 ? f_low_h : f_high_h));
    south_tan = std::min(south_tan, lowest_c * (lowest_c <= 0 ? f_low_h : f_high_h));
  };
  for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
    const EcefPoint& a = vertices[indices[t]];
    const EcefPoint& b = vertices[indices[t + 1]];
    const EcefPoint& c = vertices[indices[t + 2]];
    const DrawnTriangle triangle(a, b, c);
    if (triangle.degenerate()) continue;
    const double edge_m = triangle.longestEdge();
    // The lowest point: the height is a convex function on the triangle (a signed distance to
    // a convex body), curved by at most 1 / kRadius_m, so it lies at most L^2 / (6 R) below
    // the corners' plane (L the longest edge; 2.6 m at 10 km). A longer triangle, when that
    // bound may lower the region, is bounded closely (lowestHeightBound, below).
    const double lowest_corner = std::min({geodetic[indices[t]].h_m, geodetic[indices[t + 1]].h_m, geodetic[indices[t + 2]].h_m});
    const double lowest = lowest_corner - edge_m * edge_m / (6 * kRadius_m);
    if (edge_m <= 10e3) {
      low = std::min(low, lowest);
    } else {
      long_triangles.push_back({lowest, lowest_corner, t});
      if (lowest < low) may_lower.push_back(long_triangles.back());
    }
    // The pole, when the axis pierces the triangle: every longitude. (It cannot when the
    // corners lie clearly on one side of a plane through it, x = 0 or y = 0: further than
    // meets's tolerance, 1e-9 of an edge, reaches.)
    const double side = 1e-8 * edge_m + 1e-6;
    const bool may_hold_axis = !((a.x > side && b.x > side && c.x > side) || (a.x < -side && b.x < -side && c.x < -side) ||
                                 (a.y > side && b.y > side && c.y > side) || (a.y < -side && b.y < -side && c.y < -side));
    for (const double direction : {1.0, -1.0}) {
      if (!may_hold_axis) break;
      double offset = 0;
      if (triangle.meets(EcefPoint{0, 0, 0}, std::array<double, 3>{0, 0, direction}, &offset) && offset > 0) {
        all_longitudes = true;
        (direction > 0 ? north : south) = direction * std::numbers::pi / 2;
      }
    }
    // Its latitudes (boundLatitudes); a long triangle's wait until the region's low is known.
    if (edge_m <= 10e3) boundLatitudes(t, lowest);
  }
  // The long triangles that may lower the region, lowest bound first, closely bounded until
  // none may: whichever are, the region's low is the least of every triangle's close bound.
  std::sort(may_lower.begin(), may_lower.end(),
            [](const LongTriangle& p, const LongTriangle& q) { return p.lowest < q.lowest; });
  for (const LongTriangle& triangle : may_lower) {
    if (triangle.lowest >= low) break;
    const std::size_t t = triangle.t;
    const double close = lowestHeightBound(DrawnTriangle(vertices[indices[t]], vertices[indices[t + 1]], vertices[indices[t + 2]]));
    low = std::min(low, std::clamp(close, triangle.lowest, triangle.lowest_corner));
  }
  // Whichever triangles were: low is at most each one's least height.
  for (const LongTriangle& triangle : long_triangles) boundLatitudes(triangle.t, std::max(triangle.lowest, low));
  if (north_tan > -HUGE_VAL) north = std::max(north, std::atan(north_tan));
  if (south_tan < HUGE_VAL) south = std::min(south, std::atan(south_tan));
  if (region.empty && !all_longitudes) {
    // Only pole vertices: a degenerate content; take the whole circle.
    all_longitudes = true;
  }
  // A content at the antimeridian (a global DEM's last column, or a triangle across it): a
  // vertex within a position step of it may decode on its other side (lon 180 as -179.99999),
  // where no region from west to east holds it, so it takes every longitude.
  constexpr double kSeamDeg = 1e-3;  // 110 m, more than any position step moves a vertex
  for (std::size_t v = 0; v < vertices.size() && !all_longitudes; ++v) {
    if (used[v] && std::fabs(geodetic[v].lat_deg) < kPoleDeg && std::fabs(geodetic[v].lon_deg) > 180 - kSeamDeg) {
      all_longitudes = true;
    }
  }
  if (all_longitudes) {
    region.west_rad = -std::numbers::pi;
    region.east_rad = std::numbers::pi;
  }
  region.empty = false;
  constexpr double kAngle = 1e-10, kHeight = 1e-3;
  region.south_rad = std::max(-std::numbers::pi / 2, south - kAngle);
  region.north_rad = std::min(std::numbers::pi / 2, north + kAngle);
  region.west_rad = std::max(-std::numbers::pi, region.west_rad - kAngle);
  region.east_rad = std::min(std::numbers::pi, region.east_rad + kAngle);
  region.min_height_m = low - kHeight;
  region.max_height_m = high + kHeight;
  return region;
}

}  // namespace terratiles
