// The error budget of a collapse (cluster_collapse.h): whether a new triangle is within the
// budget on every DEM pixel it covers, by measureTin's rule. On the globe this scan is almost
// all of a level's simplification (95 % of the instructions of `terratiles levels` on SRTM
// N57E011), so exceedsBudgetOnGlobe does forEachCoveredPixelOnGlobe's work on fewer pixels and
// four at a time, with its arithmetic, so it decides exactly as that scan would.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include "src/geo/dem_on_globe.h"
#include "src/geo/dem_on_globe_lanes.h"
#include "src/geo/drawn_pixels.h"
#include "src/geo/drawn_triangle.h"
#include "src/simplify/cluster_collapse.h"
#include "src/tin/measure_tin.h"

namespace terratiles {
namespace cluster_collapse {
namespace {

// Whether the pixel is beyond the budget, given the offset the scan measures there (a nodata
// pixel never is; a NaN offset always is).
inline bool beyond(const DemGrid& dem, std::size_t pixel, double offset_m, double budget_m) {
  return !std::isnan(dem.heights_m[pixel]) && !(std::fabs(offset_m) <= budget_m);
}

// The scan of forEachCoveredPixelOnGlobe, visiting the same pixels in the same order with the
// same offsets, for a triangle that is not degenerate in ECEF (the caller takes the general
// scan otherwise).
struct GlobeScan {
  const DemOnGlobe& globe;
  const DemGrid& dem;
  const GridPoint &a, &b, &c;
  const DrawnTriangle& drawn;
  double budget_m;
  double area2, sign, size, eps;  // the doubled signed area in the grid, its sign, size and tolerance
  double reach[3];         // how far outside an edge a stray pixel may lie (edge function units)
  int min_col, max_col, min_row, max_row;  // the scan's box
  bool poles;                              // whether the DEM has pole rows

  // The three edge functions of the scan at (col, row), signed so that the inside is positive.
  void edges(double col, double row, double e[3]) const {
    e[0] = sign * ((b.col - col) * (c.row - row) - (b.row - row) * (c.col - col));
    e[1] = sign * ((c.col - col) * (a.row - row) - (c.row - row) * (a.col - col));
    e[2] = size - e[0] - e[1];
  }

  // One pixel as the scan treats it: true (and *pixel_out) when it is visited beyond the budget.
  // On a pole row, an inside pixel is measured in the grid and nothing strays.
  bool pixelBeyond(int col, int row, bool pole_row, std::size_t* pixel_out) const {
    double e[3];
    edges(col, row, e);
    const std::size_t pixel = dem.index(col, row);
    double offset_m;
    if (e[0] >= -eps && e[1] >= -eps && e[2] >= -eps) {
      if (pole_row) {
        const double wa = e[0] * sign / area2, wb = e[1] * sign / area2;
        offset_m = wa * a.height_m + wb * b.height_m + (1.0 - wa - wb) * c.height_m - dem.heights_m[pixel];
      } else {
        offset_m = drawn.offset(globe.point(col, row), globe.up(col, row));
      }
    } else if (pole_row || e[0] < reach[0] || e[1] < reach[1] || e[2] < reach[2] ||
               !drawn.meets(globe.point(col, row), globe.up(col, row), &offset_m)) {
      return false;
    }
    if (!beyond(dem, pixel, offset_m, budget_m)) return false;
    *pixel_out = pixel;
    return true;
  }

  // The columns of `row` in [min_col, max_col] that may be visited: every edge function at
  // least min(-eps, reach) (inside, or a stray pixel within reach). The edge functions are
  // affine in the column with slopes sign (b.row - c.row), sign (c.row - a.row) and
  // sign (a.row - b.row); each bound is solved in doubles from the value at min_col and
  // widened by two columns, far more than its rounding (the scan tests each column of the
  // span exactly as before). An edge nearly along the rows (slope under 1e-3) does not narrow
  // the span.
  // A box at most kNarrowColumns wide is scanned whole (two steps of four columns cost less
  // than the bounds).
  static constexpr int kNarrowColumns = 8;
  void span(int row, int* first, int* last) const {
    if (max_col - min_col < kNarrowColumns) {
      *first = min_col;
      *last = max_col;
      return;
    }
    double lo = min_col, hi = max_col;
    double at[3];
    edges(min_col, row, at);
    const double slopes[3] = {sign * (b.row - c.row), sign * (c.row - a.row), sign * (a.row - b.row)};
    for (int k = 0; k < 3; ++k) {
      const double slope = slopes[k];
      const double threshold = std::min(-eps, reach[k]);
      if (std::fabs(slope) < 1e-3) continue;
      const double bound = min_col + (threshold - at[k]) / slope;  // the column where e_k = threshold
      if (slope > 0) lo = std::max(lo, bound - 2);
      else hi = std::min(hi, bound + 2);
    }
    if (!(lo <= hi)) {
      *first = 0;
      *last = -1;
      return;
    }
    *first = std::max(min_col, static_cast<int>(std::floor(lo)));
    *last = std::min(max_col, static_cast<int>(std::ceil(hi)));
  }
};

// The first pixel visited beyond the budget, in the scan's order (rows, then columns).
bool firstBeyond(const GlobeScan& s, std::size_t* pixel) {
  for (int row = s.min_row; row <= s.max_row; ++row) {
    const bool pole_row = s.poles && s.globe.poleRow(row);
    int first, last;
    s.span(row, &first, &last);
    for (int col = first; col <= last; ++col) {
      if (s.pixelBeyond(col, row, pole_row, pixel)) return true;
    }
  }
  return false;
}

#if defined(__x86_64__)
const bool kHasAvx2 = __builtin_cpu_supports("avx2");

// firstBeyond with each row (but a pole row) four columns at a time, as pixelBeyond computes
// it operation for operation (AVX2 has no fused multiply-add; DrawnTriangle::meets as
// drawn_tiles.cpp's meets4 computes it). A row's last four columns may start before the
// fourth from the row's end (down to the raster's width minus four, so the loads stay inside
// the raster): a column tested twice, or one outside the span, is not beyond (the span holds
// every visited column). Needs a raster at least four columns wide.
__attribute__((target("avx2"))) bool firstBeyondAvx2(const GlobeScan& s, std::size_t* pixel) {
  const __m256d lanes = _mm256_set_pd(3, 2, 1, 0);
  const __m256d sign = _mm256_set1_pd(s.sign);
  const __m256d b_col = _mm256_set1_pd(s.b.col), c_col = _mm256_set1_pd(s.c.col), a_col = _mm256_set1_pd(s.a.col);
  const __m256d size = _mm256_set1_pd(s.size), below = _mm256_set1_pd(-s.eps);
  const __m256d reach0 = _mm256_set1_pd(s.reach[0]), reach1 = _mm256_set1_pd(s.reach[1]), reach2 = _mm256_set1_pd(s.reach[2]);
  const __m256d budget = _mm256_set1_pd(s.budget_m), minus_zero = _mm256_set1_pd(-0.0);
  const DemOnGlobe& globe = s.globe;
  const DrawnTriangle& tri = s.drawn;
  const __m256d n0 = _mm256_set1_pd(tri.normal[0]), n1 = _mm256_set1_pd(tri.normal[1]), n2 = _mm256_set1_pd(tri.normal[2]);
  const __m256d ax = _mm256_set1_pd(tri.a.x), ay = _mm256_set1_pd(tri.a.y), az = _mm256_set1_pd(tri.a.z);
  __m256d corner_x[3], corner_y[3], corner_z[3];
  for (int k = 0; k < 3; ++k) {
    corner_x[k] = _mm256_set1_pd(tri.corner(k).x);
    corner_y[k] = _mm256_set1_pd(tri.corner(k).y);
    corner_z[k] = _mm256_set1_pd(tri.corner(k).z);
  }
  for (int row = s.min_row; row <= s.max_row; ++row) {
    int first, last;
    s.span(row, &first, &last);
    if (s.poles && globe.poleRow(row)) {
      for (int col = first; col <= last; ++col) {
        if (s.pixelBeyond(col, row, true, pixel)) return true;
      }
      continue;
    }
    // The edge functions' row terms (b.row - row and so on) are the same along the row.
    const __m256d rows = _mm256_set1_pd(row);
    const __m256d a_row = _mm256_sub_pd(_mm256_set1_pd(s.a.row), rows), b_row = _mm256_sub_pd(_mm256_set1_pd(s.b.row), rows),
                  c_row = _mm256_sub_pd(_mm256_set1_pd(s.c.row), rows);
    for (int col = first; col <= last; col += 4) {
      const int start = std::min(col, s.dem.width - 4);
      const __m256d cols = _mm256_add_pd(_mm256_set1_pd(start), lanes);
      // sign * ((b.col - col) * (c.row - row) - (b.row - row) * (c.col - col)), and for c, a.
      const __m256d ea = _mm256_mul_pd(sign, _mm256_sub_pd(_mm256_mul_pd(_mm256_sub_pd(b_col, cols), c_row),
                                                           _mm256_mul_pd(b_row, _mm256_sub_pd(c_col, cols))));
      const __m256d eb = _mm256_mul_pd(sign, _mm256_sub_pd(_mm256_mul_pd(_mm256_sub_pd(c_col, cols), a_row),
                                                           _mm256_mul_pd(c_row, _mm256_sub_pd(a_col, cols))));
      const __m256d ec = _mm256_sub_pd(_mm256_sub_pd(size, ea), eb);
      const __m256d inside = _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(ea, below, _CMP_GE_OQ), _mm256_cmp_pd(eb, below, _CMP_GE_OQ)),
                                           _mm256_cmp_pd(ec, below, _CMP_GE_OQ));
      const __m256d within = _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(ea, reach0, _CMP_NLT_UQ), _mm256_cmp_pd(eb, reach1, _CMP_NLT_UQ)),
                                           _mm256_cmp_pd(ec, reach2, _CMP_NLT_UQ));
      const __m256d stray = _mm256_andnot_pd(inside, within);
      const int inside_bits = _mm256_movemask_pd(inside), stray_bits = _mm256_movemask_pd(stray);
      if (inside_bits == 0 && stray_bits == 0) continue;
      // DrawnTriangle::offset: 0 at a corner's own point, else across / along (along = 0 gives an
      // infinity or NaN, beyond any budget and any reach as the scalar NaN is).
      const std::size_t i = s.dem.index(start, row);
      const PixelLanes pixels = pixelLanes(globe, start, row, i);
      const __m256d x = pixels.x, y = pixels.y, z = pixels.z, ux = pixels.ux, uy = pixels.uy, uz = pixels.uz;
      const __m256d along = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(n0, ux), _mm256_mul_pd(n1, uy)), _mm256_mul_pd(n2, uz));
      const __m256d across = _mm256_add_pd(
          _mm256_add_pd(_mm256_mul_pd(n0, _mm256_sub_pd(ax, x)), _mm256_mul_pd(n1, _mm256_sub_pd(ay, y))),
          _mm256_mul_pd(n2, _mm256_sub_pd(az, z)));
      __m256d at_corner = _mm256_setzero_pd();
      for (int k = 0; k < 3; ++k) {
        at_corner = _mm256_or_pd(at_corner, _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(x, corner_x[k], _CMP_EQ_OQ),
                                                                        _mm256_cmp_pd(y, corner_y[k], _CMP_EQ_OQ)),
                                                          _mm256_cmp_pd(z, corner_z[k], _CMP_EQ_OQ)));
      }
      const __m256d offset = _mm256_blendv_pd(_mm256_div_pd(across, along), _mm256_setzero_pd(), at_corner);
      const __m256d magnitude = _mm256_andnot_pd(minus_zero, offset);
      // Valid (the DEM height not NaN) and !(|offset| <= budget), NaN included.
      const __m128 heights = _mm_loadu_ps(s.dem.heights_m.data() + i);
      const __m256d valid = _mm256_castsi256_pd(_mm256_cvtepi32_epi64(_mm_castps_si128(_mm_cmpord_ps(heights, heights))));
      __m256d visited_beyond = _mm256_and_pd(inside, _mm256_cmp_pd(magnitude, budget, _CMP_NLE_UQ));
      if (stray_bits != 0) {
        // DrawnTriangle::meets (Moeller-Trumbore), whose offset is offset() above.
        constexpr double kTolerance = 1e-9;  // DrawnTriangle::meets's
        const __m256d ab0 = _mm256_set1_pd(tri.ab[0]), ab1 = _mm256_set1_pd(tri.ab[1]), ab2 = _mm256_set1_pd(tri.ab[2]);
        const __m256d ac0 = _mm256_set1_pd(tri.ac[0]), ac1 = _mm256_set1_pd(tri.ac[1]), ac2 = _mm256_set1_pd(tri.ac[2]);
        const __m256d px = _mm256_sub_pd(_mm256_mul_pd(uy, ac2), _mm256_mul_pd(uz, ac1)),
                      py = _mm256_sub_pd(_mm256_mul_pd(uz, ac0), _mm256_mul_pd(ux, ac2)),
                      pz = _mm256_sub_pd(_mm256_mul_pd(ux, ac1), _mm256_mul_pd(uy, ac0));
        const __m256d det = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ab0, px), _mm256_mul_pd(ab1, py)), _mm256_mul_pd(ab2, pz));
        // det != 0 and finite (NaN fails both).
        __m256d meets = _mm256_and_pd(_mm256_cmp_pd(det, _mm256_setzero_pd(), _CMP_NEQ_OQ),
                                      _mm256_cmp_pd(_mm256_andnot_pd(minus_zero, det), _mm256_set1_pd(HUGE_VAL), _CMP_LT_OQ));
        const __m256d inverse = _mm256_div_pd(_mm256_set1_pd(1.0), det);
        const __m256d tx = _mm256_sub_pd(x, ax), ty = _mm256_sub_pd(y, ay), tz = _mm256_sub_pd(z, az);
        const __m256d u = _mm256_mul_pd(
            _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(tx, px), _mm256_mul_pd(ty, py)), _mm256_mul_pd(tz, pz)), inverse);
        const __m256d low = _mm256_set1_pd(-kTolerance), high = _mm256_set1_pd(1 + kTolerance);
        // The scalar code refuses u < low or u > high: a NaN goes on, as there.
        meets = _mm256_and_pd(meets, _mm256_and_pd(_mm256_cmp_pd(u, low, _CMP_NLT_UQ), _mm256_cmp_pd(u, high, _CMP_NGT_UQ)));
        const __m256d qx = _mm256_sub_pd(_mm256_mul_pd(ty, ab2), _mm256_mul_pd(tz, ab1)),
                      qy = _mm256_sub_pd(_mm256_mul_pd(tz, ab0), _mm256_mul_pd(tx, ab2)),
                      qz = _mm256_sub_pd(_mm256_mul_pd(tx, ab1), _mm256_mul_pd(ty, ab0));
        const __m256d v = _mm256_mul_pd(
            _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ux, qx), _mm256_mul_pd(uy, qy)), _mm256_mul_pd(uz, qz)), inverse);
        meets = _mm256_and_pd(meets, _mm256_and_pd(_mm256_cmp_pd(v, low, _CMP_NLT_UQ),
                                                   _mm256_cmp_pd(_mm256_add_pd(u, v), high, _CMP_NGT_UQ)));
        meets = _mm256_and_pd(meets, _mm256_cmp_pd(magnitude, _mm256_set1_pd(DrawnTriangle::kReach_m), _CMP_LE_OQ));
        // A stray pixel met within reach is beyond when !(|offset| <= budget).
        visited_beyond = _mm256_or_pd(
            visited_beyond,
            _mm256_and_pd(_mm256_and_pd(stray, meets), _mm256_cmp_pd(magnitude, budget, _CMP_NLE_UQ)));
      }
      const unsigned over = static_cast<unsigned>(_mm256_movemask_pd(_mm256_and_pd(visited_beyond, valid)));
      if (over != 0) {
        *pixel = s.dem.index(start + std::countr_zero(over), row);  // the scan's order: the first
        return true;
      }
    }
  }
  return false;
}
#endif

}  // namespace

bool exceedsBudgetOnGlobe(const DemOnGlobe& globe, const GridPoint& a, const GridPoint& b, const GridPoint& c,
                          const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc, double budget_m,
                          std::size_t* violating_pixel) {
  const DemGrid& dem = globe.dem();
  const double area2 = (b.col - a.col) * (c.row - a.row) - (b.row - a.row) * (c.col - a.col);
  if (area2 == 0) return false;
  const DrawnTriangle drawn(pa, pb, pc);
  if (drawn.degenerate()) {
    bool exceeds = false;
    forEachCoveredPixelOnGlobe(globe, a, b, c, pa, pb, pc, [&](std::size_t i, double offset_m) {
      exceeds = beyond(dem, i, offset_m, budget_m);
      if (exceeds && violating_pixel) *violating_pixel = i;
      return !exceeds;
    });
    return exceeds;
  }
  // forEachCoveredPixelOnGlobe's margin, tolerance, reach and box.
  const bool poles = globe.hasPoleRows();
  const PixelMargin margin = scanMargin(globe, a, b, c, pa, pb, pc, drawn.longestEdge());
  const double margin_px = std::max(margin.columns, margin.rows);
  GlobeScan scan{globe, dem, a, b, c, drawn, budget_m, area2, area2 > 0 ? 1.0 : -1.0, std::fabs(area2), 1e-9 * std::fabs(area2),
                 {}, 0, 0, 0, 0, poles};
  const double edge_length[3] = {std::sqrt((c.col - b.col) * (c.col - b.col) + (c.row - b.row) * (c.row - b.row)),
                                 std::sqrt((a.col - c.col) * (a.col - c.col) + (a.row - c.row) * (a.row - c.row)),
                                 std::sqrt((b.col - a.col) * (b.col - a.col) + (b.row - a.row) * (b.row - a.row))};
  for (int k = 0; k < 3; ++k) scan.reach[k] = -margin_px * edge_length[k];
  scan.min_col = static_cast<int>(std::max(0.0, std::ceil(std::min({a.col, b.col, c.col}) - margin.boxColumns() - 1e-9)));
  scan.max_col = static_cast<int>(std::min(dem.width - 1.0, std::floor(std::max({a.col, b.col, c.col}) + margin.boxColumns() + 1e-9)));
  scan.min_row = static_cast<int>(std::max(0.0, std::ceil(std::min({a.row, b.row, c.row}) - margin.rows - 1e-9)));
  scan.max_row = static_cast<int>(std::min(dem.height - 1.0, std::floor(std::max({a.row, b.row, c.row}) + margin.rows + 1e-9)));
  std::size_t pixel = 0;
  bool exceeds;
#if defined(__x86_64__)
  if (kHasAvx2 && dem.width >= 4) exceeds = firstBeyondAvx2(scan, &pixel);
  else exceeds = firstBeyond(scan, &pixel);
#else
  exceeds = firstBeyond(scan, &pixel);
#endif
  if (exceeds && violating_pixel) *violating_pixel = pixel;
  return exceeds;
}

}  // namespace cluster_collapse
}  // namespace terratiles
