#include "src/tin/build_tin.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <limits>
#include <map>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <tbb/parallel_for.h>

#include "src/base/error.h"
#include "src/geo/dem_on_globe.h"
#include "src/geo/dem_on_globe_lanes.h"
#include "src/geo/drawn_pixels.h"
#include "src/geo/drawn_triangle.h"

#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace terratiles {
namespace {

// The largest |gx * x + row_z - row[x]| for x in [x0, x1]. Every error is computed exactly as
// the scalar expression computes it (multiply, then add, no FMA), so the caller can find its
// position again by equality. x86-64: SSE2 (the baseline) four pixels per step, or AVX2 eight
// when the processor has it (chosen once at run time).
#if defined(__x86_64__)
__attribute__((target("avx2"))) double rowMaxErrorAvx2(const float* row, std::int64_t x0,
                                                       std::int64_t x1, double gx, double row_z) {
  std::int64_t x = x0;
  const __m256d sign = _mm256_set1_pd(-0.0);
  const __m256d vgx = _mm256_set1_pd(gx), vrow_z = _mm256_set1_pd(row_z), four = _mm256_set1_pd(4.0),
                eight = _mm256_set1_pd(8.0);
  __m256d vmax0 = _mm256_setzero_pd(), vmax1 = _mm256_setzero_pd();
  const double first = static_cast<double>(x0);
  __m256d vx0 = _mm256_set_pd(first + 3, first + 2, first + 1, first);
  __m256d vx1 = _mm256_add_pd(vx0, four);
  for (; x + 7 <= x1; x += 8) {
    const __m256d h0 = _mm256_cvtps_pd(_mm_loadu_ps(row + x));
    const __m256d h1 = _mm256_cvtps_pd(_mm_loadu_ps(row + x + 4));
    const __m256d z0 = _mm256_add_pd(_mm256_mul_pd(vgx, vx0), vrow_z);
    const __m256d z1 = _mm256_add_pd(_mm256_mul_pd(vgx, vx1), vrow_z);
    vmax0 = _mm256_max_pd(vmax0, _mm256_andnot_pd(sign, _mm256_sub_pd(z0, h0)));
    vmax1 = _mm256_max_pd(vmax1, _mm256_andnot_pd(sign, _mm256_sub_pd(z1, h1)));
    vx0 = _mm256_add_pd(vx0, eight);
    vx1 = _mm256_add_pd(vx1, eight);
  }
  const __m256d vmax = _mm256_max_pd(vmax0, vmax1);
  const __m128d half = _mm_max_pd(_mm256_castpd256_pd128(vmax), _mm256_extractf128_pd(vmax, 1));
  double row_max = std::max(_mm_cvtsd_f64(half), _mm_cvtsd_f64(_mm_unpackhi_pd(half, half)));
  for (; x <= x1; ++x) {
    row_max = std::max(row_max, std::fabs(gx * static_cast<double>(x) + row_z - row[x]));
  }
  return row_max;
}
const bool kHasAvx2 = __builtin_cpu_supports("avx2");

// The worst pixel of a narrow triangle: over the box [x_first, x_last] x [y_first, y_last]
// of a raster `width` pixels wide, the pixel inside the triangle (its three edge functions
// w_k = alpha_k * x + beta_step_k * y + c_k all >= 0; w_first holds them at (x_first,
// y_first)) with the largest |gx * x + (gy * y + z0) - h|, the first in row-major order on
// ties. Four pixels per step; each lane keeps its own best value and its first position,
// then the lanes are reduced (largest value, smallest position), which is the scalar
// scan's answer. Edge functions are integers below 2^40 here, exact in doubles. Returns
// false when no pixel of the box is inside.
__attribute__((target("avx2"))) bool boxWorstPixelInsideAvx2(const float* heights, std::int32_t width,
                                                            std::int32_t x_first, std::int32_t x_last,
                                                            std::int32_t y_first, std::int32_t y_last, double gx,
                                                            double gy, double z0, const std::int64_t w_first[3],
                                                            const std::int64_t alpha[3],
                                                            const std::int64_t beta_step[3], double* worst_error,
                                                            std::int32_t* worst_x, std::int32_t* worst_y) {
  const __m256d sign = _mm256_set1_pd(-0.0), zero = _mm256_setzero_pd(), outside = _mm256_set1_pd(-1.0);
  const __m256d vgx = _mm256_set1_pd(gx), four = _mm256_set1_pd(4.0);
  const __m256d lane = _mm256_set_pd(3, 2, 1, 0);
  const __m256d last_x = _mm256_set1_pd(static_cast<double>(x_last));
  __m256d step[3], row_start[3];
  for (int k = 0; k < 3; ++k) {
    step[k] = _mm256_set1_pd(4.0 * static_cast<double>(alpha[k]));
    row_start[k] = _mm256_add_pd(_mm256_set1_pd(static_cast<double>(w_first[k])),
                                 _mm256_mul_pd(lane, _mm256_set1_pd(static_cast<double>(alpha[k]))));
  }
  const __m256d first_x = _mm256_add_pd(_mm256_set1_pd(static_cast<double>(x_first)), lane);
  __m256d best = outside, best_position = zero;
  for (std::int32_t y = y_first; y <= y_last; ++y) {
    const float* row = heights + static_cast<std::size_t>(y) * static_cast<std::size_t>(width);
    const __m256d row_z = _mm256_set1_pd(gy * y + z0);
    const __m256d row_position = _mm256_set1_pd(static_cast<double>(y) * width);
    __m256d vx = first_x, w0 = row_start[0], w1 = row_start[1], w2 = row_start[2];
    for (std::int32_t x = x_first; x <= x_last; x += 4) {
      // The last step of a row may reach past the box (and, on the raster's last row, past
      // its end): those lanes are not loaded and not inside.
      const __m128 h4 = x + 3 <= x_last
                            ? _mm_loadu_ps(row + x)
                            : _mm_maskload_ps(row + x, _mm256_castsi256_si128(_mm256_castpd_si256(
                                                           _mm256_cmp_pd(vx, last_x, _CMP_LE_OQ))));
      const __m256d h = _mm256_cvtps_pd(h4);
      const __m256d z = _mm256_add_pd(_mm256_mul_pd(vgx, vx), row_z);
      const __m256d error = _mm256_andnot_pd(sign, _mm256_sub_pd(z, h));
      const __m256d inside = _mm256_and_pd(
          _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(w0, zero, _CMP_GE_OQ), _mm256_cmp_pd(w1, zero, _CMP_GE_OQ)),
                        _mm256_cmp_pd(w2, zero, _CMP_GE_OQ)),
          _mm256_cmp_pd(vx, last_x, _CMP_LE_OQ));
      const __m256d better = _mm256_and_pd(inside, _mm256_cmp_pd(error, best, _CMP_GT_OQ));
      best = _mm256_blendv_pd(best, error, better);
      best_position = _mm256_blendv_pd(best_position, _mm256_add_pd(row_position, vx), better);
      vx = _mm256_add_pd(vx, four);
      w0 = _mm256_add_pd(w0, step[0]);
      w1 = _mm256_add_pd(w1, step[1]);
      w2 = _mm256_add_pd(w2, step[2]);
    }
    for (int k = 0; k < 3; ++k) {
      row_start[k] = _mm256_add_pd(row_start[k], _mm256_set1_pd(static_cast<double>(beta_step[k])));
    }
  }
  alignas(32) double lane_best[4], lane_position[4];
  _mm256_store_pd(lane_best, best);
  _mm256_store_pd(lane_position, best_position);
  int winner = 0;
  for (int i = 1; i < 4; ++i) {
    if (lane_best[i] > lane_best[winner] ||
        (lane_best[i] == lane_best[winner] && lane_position[i] < lane_position[winner])) {
      winner = i;
    }
  }
  if (lane_best[winner] < 0) return false;
  const auto position = static_cast<std::int64_t>(lane_position[winner]);
  *worst_error = lane_best[winner];
  *worst_y = static_cast<std::int32_t>(position / width);
  *worst_x = static_cast<std::int32_t>(position % width);
  return true;
}
#endif

inline double rowMaxError(const float* row, std::int64_t x0, std::int64_t x1, double gx, double row_z) {
  double row_max = 0;
  std::int64_t x = x0;
#if defined(__x86_64__)
  if (kHasAvx2 && x1 - x0 >= 15) return rowMaxErrorAvx2(row, x0, x1, gx, row_z);
  const __m128d sign = _mm_set1_pd(-0.0);
  const __m128d vgx = _mm_set1_pd(gx), vrow_z = _mm_set1_pd(row_z), two = _mm_set1_pd(2.0),
                four = _mm_set1_pd(4.0);
  __m128d vmax0 = _mm_setzero_pd(), vmax1 = _mm_setzero_pd();
  __m128d vx0 = _mm_set_pd(static_cast<double>(x0 + 1), static_cast<double>(x0));
  __m128d vx1 = _mm_add_pd(vx0, two);
  for (; x + 3 <= x1; x += 4) {
    const __m128d h0 = _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(row + x))));
    const __m128d h1 = _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(row + x + 2))));
    const __m128d z0 = _mm_add_pd(_mm_mul_pd(vgx, vx0), vrow_z);
    const __m128d z1 = _mm_add_pd(_mm_mul_pd(vgx, vx1), vrow_z);
    vmax0 = _mm_max_pd(vmax0, _mm_andnot_pd(sign, _mm_sub_pd(z0, h0)));
    vmax1 = _mm_max_pd(vmax1, _mm_andnot_pd(sign, _mm_sub_pd(z1, h1)));
    vx0 = _mm_add_pd(vx0, four);
    vx1 = _mm_add_pd(vx1, four);
  }
  const __m128d vmax = _mm_max_pd(vmax0, vmax1);
  row_max = std::max(_mm_cvtsd_f64(vmax), _mm_cvtsd_f64(_mm_unpackhi_pd(vmax, vmax)));
#endif
  for (; x <= x1; ++x) {
    row_max = std::max(row_max, std::fabs(gx * static_cast<double>(x) + row_z - row[x]));
  }
  return row_max;
}

__extension__ typedef __int128 Int128;

constexpr std::int32_t kNone = -1;
// Triangles narrower than this many pixels are scanned over their bounding box.
constexpr std::int32_t kNarrowTriangle = 16;
// The error of a triangle whose plane runs along a pixel's vertical: above any bound.
constexpr double kWallError = 1e9;

// ---- Exact errors on the globe (DemOnGlobe), vectorised like the scans above ---------------
// The error of a drawn triangle at pixel i: |DrawnTriangle::offset| of the pixel's DEM point,
// computed with the same operations in the same order (so the scalar and vector forms agree
// bit for bit, and with measureTin), capped at kWallError (also where the offset is NaN).
inline double exactErrorAt(const DemOnGlobe& globe, const DrawnTriangle& drawn, std::int32_t col, std::int32_t row) {
  const double error = std::fabs(drawn.offset(globe.point(col, row), globe.up(col, row)));
  return error < kWallError ? error : kWallError;
}

#if defined(__x86_64__)
// Four pixels' errors from index i on (lane k is pixel i + k).
__attribute__((target("avx2"))) inline __m256d exactErrors4(const DemOnGlobe& globe, const DrawnTriangle& drawn,
                                                            std::int32_t col, std::int32_t row, std::size_t i) {
  const PixelLanes pixels = pixelLanes(globe, col, row, i);
  const __m256d px = pixels.x, py = pixels.y, pz = pixels.z, ux = pixels.ux, uy = pixels.uy, uz = pixels.uz;
  const __m256d nx = _mm256_set1_pd(drawn.normal[0]), ny = _mm256_set1_pd(drawn.normal[1]),
                nz = _mm256_set1_pd(drawn.normal[2]);
  const __m256d along =
      _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nx, ux), _mm256_mul_pd(ny, uy)), _mm256_mul_pd(nz, uz));
  const __m256d dx = _mm256_sub_pd(_mm256_set1_pd(drawn.a.x), px), dy = _mm256_sub_pd(_mm256_set1_pd(drawn.a.y), py),
                dz = _mm256_sub_pd(_mm256_set1_pd(drawn.a.z), pz);
  const __m256d across =
      _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nx, dx), _mm256_mul_pd(ny, dy)), _mm256_mul_pd(nz, dz));
  const __m256d error = _mm256_andnot_pd(_mm256_set1_pd(-0.0), _mm256_div_pd(across, along));
  // A corner's own point: 0, as DrawnTriangle::offset has it.
  __m256d at_corner = _mm256_setzero_pd();
  for (int k = 0; k < 3; ++k) {
    const EcefPoint& c = drawn.corner(k);
    at_corner = _mm256_or_pd(
        at_corner, _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(px, _mm256_set1_pd(c.x), _CMP_EQ_OQ),
                                               _mm256_cmp_pd(py, _mm256_set1_pd(c.y), _CMP_EQ_OQ)),
                                 _mm256_cmp_pd(pz, _mm256_set1_pd(c.z), _CMP_EQ_OQ)));
  }
  // min(NaN, cap) is the cap: vminpd returns its second operand when either is NaN.
  return _mm256_blendv_pd(_mm256_min_pd(error, _mm256_set1_pd(kWallError)), _mm256_setzero_pd(), at_corner);
}

// The largest exact error over pixels [x0, x1] of the row starting at pixel index row_start.
__attribute__((target("avx2"))) double rowMaxExactAvx2(const DemOnGlobe& globe, const DrawnTriangle& drawn,
                                                       std::int32_t y, std::int64_t x0, std::int64_t x1) {
  const std::size_t row_start = globe.dem().index(0, y);
  std::int64_t x = x0;
  __m256d vmax = _mm256_setzero_pd();
  for (; x + 3 <= x1; x += 4) {
    vmax = _mm256_max_pd(vmax, exactErrors4(globe, drawn, static_cast<std::int32_t>(x), y,
                                            row_start + static_cast<std::size_t>(x)));
  }
  const __m128d half = _mm_max_pd(_mm256_castpd256_pd128(vmax), _mm256_extractf128_pd(vmax, 1));
  double row_max = std::max(_mm_cvtsd_f64(half), _mm_cvtsd_f64(_mm_unpackhi_pd(half, half)));
  for (; x <= x1; ++x) row_max = std::max(row_max, exactErrorAt(globe, drawn, static_cast<std::int32_t>(x), y));
  return row_max;
}

// boxWorstPixelInsideAvx2 with exact errors: the worst pixel inside the triangle over the box
// (the first in row-major order on ties); false when no pixel of the box is inside. A row's
// last step may read up to three pixels past x_last (never chosen), so past the raster's end
// on its last row: DemOnGlobe's arrays hold kDemOnGlobePadding pixels more for that.
__attribute__((target("avx2"))) bool boxWorstPixelExactAvx2(const DemOnGlobe& globe, const DrawnTriangle& drawn,
                                                           std::int32_t width, std::int32_t x_first, std::int32_t x_last,
                                                           std::int32_t y_first, std::int32_t y_last,
                                                           const std::int64_t w_first[3], const std::int64_t alpha[3],
                                                           const std::int64_t beta_step[3], double* worst_error,
                                                           std::int32_t* worst_x, std::int32_t* worst_y) {
  const __m256d zero = _mm256_setzero_pd(), outside = _mm256_set1_pd(-1.0), four = _mm256_set1_pd(4.0);
  const __m256d lane = _mm256_set_pd(3, 2, 1, 0);
  const __m256d last_x = _mm256_set1_pd(static_cast<double>(x_last));
  __m256d step[3], row_start[3];
  for (int k = 0; k < 3; ++k) {
    step[k] = _mm256_set1_pd(4.0 * static_cast<double>(alpha[k]));
    row_start[k] = _mm256_add_pd(_mm256_set1_pd(static_cast<double>(w_first[k])),
                                 _mm256_mul_pd(lane, _mm256_set1_pd(static_cast<double>(alpha[k]))));
  }
  const __m256d first_x = _mm256_add_pd(_mm256_set1_pd(static_cast<double>(x_first)), lane);
  __m256d best = outside, best_position = zero;
  for (std::int32_t y = y_first; y <= y_last; ++y) {
    const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(width);
    const __m256d row_position = _mm256_set1_pd(static_cast<double>(row));
    __m256d vx = first_x, w0 = row_start[0], w1 = row_start[1], w2 = row_start[2];
    for (std::int32_t x = x_first; x <= x_last; x += 4) {
      const __m256d error = exactErrors4(globe, drawn, x, y, row + static_cast<std::size_t>(x));
      const __m256d inside = _mm256_and_pd(
          _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(w0, zero, _CMP_GE_OQ), _mm256_cmp_pd(w1, zero, _CMP_GE_OQ)),
                        _mm256_cmp_pd(w2, zero, _CMP_GE_OQ)),
          _mm256_cmp_pd(vx, last_x, _CMP_LE_OQ));
      const __m256d better = _mm256_and_pd(inside, _mm256_cmp_pd(error, best, _CMP_GT_OQ));
      best = _mm256_blendv_pd(best, error, better);
      best_position = _mm256_blendv_pd(best_position, _mm256_add_pd(row_position, vx), better);
      vx = _mm256_add_pd(vx, four);
      w0 = _mm256_add_pd(w0, step[0]);
      w1 = _mm256_add_pd(w1, step[1]);
      w2 = _mm256_add_pd(w2, step[2]);
    }
    for (int k = 0; k < 3; ++k) {
      row_start[k] = _mm256_add_pd(row_start[k], _mm256_set1_pd(static_cast<double>(beta_step[k])));
    }
  }
  alignas(32) double lane_best[4], lane_position[4];
  _mm256_store_pd(lane_best, best);
  _mm256_store_pd(lane_position, best_position);
  int winner = 0;
  for (int i = 1; i < 4; ++i) {
    if (lane_best[i] > lane_best[winner] ||
        (lane_best[i] == lane_best[winner] && lane_position[i] < lane_position[winner])) {
      winner = i;
    }
  }
  if (lane_best[winner] < 0) return false;
  const auto position = static_cast<std::int64_t>(lane_position[winner]);
  *worst_error = lane_best[winner];
  *worst_y = static_cast<std::int32_t>(position / width);
  *worst_x = static_cast<std::int32_t>(position % width);
  return true;
}
#endif


inline std::int32_t nextHalfedge(std::int32_t e) { return e % 3 == 2 ? e - 2 : e + 1; }
inline std::int32_t prevHalfedge(std::int32_t e) { return e % 3 == 0 ? e + 2 : e - 1; }

struct Pixel {
  std::int32_t x = 0;  // column
  std::int32_t y = 0;  // row (grows south)
};

// orient(p, q, r) > 0: r is to the left of p->q in the (col, row) plane. Exact.
inline std::int64_t orient(Pixel p, Pixel q, Pixel r) {
  return std::int64_t{q.x - p.x} * (r.y - p.y) - std::int64_t{q.y - p.y} * (r.x - p.x);
}

// > 0 when d lies strictly inside the circumcircle of the positively oriented (a, b, c). Exact.
inline bool inCircle(Pixel a, Pixel b, Pixel c, Pixel d) {
  const std::int64_t adx = a.x - d.x, ady = a.y - d.y;
  const std::int64_t bdx = b.x - d.x, bdy = b.y - d.y;
  const std::int64_t cdx = c.x - d.x, cdy = c.y - d.y;
  const std::int64_t ad = adx * adx + ady * ady;
  const std::int64_t bd = bdx * bdx + bdy * bdy;
  const std::int64_t cd = cdx * cdx + cdy * cdy;
  const Int128 det = Int128{adx} * (Int128{bdy} * cd - Int128{bd} * cdy) -
                     Int128{ady} * (Int128{bdx} * cd - Int128{bd} * cdx) +
                     Int128{ad} * (Int128{bdx} * cdy - Int128{bdy} * cdx);
  return det > 0;
}

// Greedy insertion state: a half-edge triangulation (Delaunator's layout: halfedge e of
// triangle e / 3 runs from vertex triangles[e] to triangles[next(e)], halfedges[e] is its
// twin or kNone on the hull), each triangle's candidate pixel and error, and a max-heap of
// the triangles whose error exceeds the bound.
// The pixels a triangulation covers: [x0, x1] x [y0, y1], inclusive.
struct Window {
  std::int32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

// A window's triangles in compact form (8 bytes per vertex: heights are the DEM's), kept
// until the stitch; TinMesh's GridPoint takes 24.
struct WindowMesh {
  std::vector<Pixel> pixels;
  std::vector<std::uint32_t> triangle_indices;  // counter-clockwise seen from above
  std::vector<std::array<std::uint32_t, 2>> constrained_edges;  // indices into pixels
  std::size_t constrained_edges_dropped = 0;
  std::size_t segments_bent = 0;
  std::size_t segments_bent_to_end = 0;
  // On the globe: pixels of the window's fixed outline that a triangle of the window, as
  // drawn, misses by more than the bound (the outline polylines' 1D test could not see the
  // triangle's cross slope); the build adds them to the outline and builds again.
  std::vector<Pixel> border_violations;
};

// A constraint segment in a window: two pixels.
struct WindowSegment {
  Pixel from, to;
};

inline std::uint64_t edgeKey(std::int32_t a, std::int32_t b) {
  const auto low = static_cast<std::uint32_t>(std::min(a, b)), high = static_cast<std::uint32_t>(std::max(a, b));
  return (static_cast<std::uint64_t>(low) << 32) | high;
}

inline int sign(std::int64_t value) { return (value > 0) - (value < 0); }

GridPoint gridPoint(const DemGrid& dem, Pixel p) {
  return {static_cast<double>(p.x), static_cast<double>(p.y), static_cast<double>(dem.heightAt(p.x, p.y))};
}

// What every window of one DEM shares.
struct DemFacts {
  bool has_nodata = false;
  double virtual_height = 0;  // the mean valid height, for virtual (nodata) corners
};

DemFacts demFacts(const DemGrid& dem) {
  double sum = 0;
  std::size_t valid = 0;
  for (const float h : dem.heights_m) {
    if (std::isnan(h)) continue;
    sum += h;
    ++valid;
  }
  return {valid < dem.pixelCount(), valid ? sum / static_cast<double>(valid) : 0.0};
}

class GreedyInsertion {
 public:
  // globe: measure the triangles as drawn on the globe (DemOnGlobe), exactly, or nullptr: in
  // the grid frame, heights interpolated linearly.
  GreedyInsertion(const DemGrid& dem, const DemOnGlobe* globe, double max_error_m, Window window,
                  const DemFacts& facts)
      : dem_(dem), globe_(globe), width_(dem.width), max_error_(max_error_m), window_(window),
        has_nodata_(facts.has_nodata), virtual_height_(facts.virtual_height) {}

  // fixed_border: the pixels of the window's outline inserted before any error-driven
  // insertion (the shared border polylines of a windowed build); with it, the outline is
  // final. Without it (one window over the whole grid), the outline is refined like the rest.
  // segments: break lines inserted as constrained edges after the outline, before any
  // error-driven insertion; each lies in the window's closed box, and its pixels on the
  // window's outline are among fixed_border's (or corners).
  // seeds: pixels inside the window made vertices before any error-driven insertion (the
  // inner neighbours of a block outline's pixels that a triangle missed).
  void run(Progress* progress, const std::vector<Pixel>* fixed_border = nullptr,
           const std::vector<WindowSegment>* segments = nullptr, const std::vector<Pixel>* seeds = nullptr) {
    const Pixel corners[4] = {{window_.x0, window_.y0}, {window_.x1, window_.y0},
                              {window_.x0, window_.y1}, {window_.x1, window_.y1}};
    for (const Pixel& corner : corners) addVertex(corner);
    // Two triangles over the grid, positively oriented in (col, row): (0, 3, 2) and (0, 1, 3),
    // sharing the diagonal 0-3.
    const std::int32_t t0 = addTriangle(0, 3, 2, kNone, kNone, kNone);
    const std::int32_t t1 = addTriangle(0, 1, 3, kNone, kNone, kNone);
    link(3 * t0 + 0, 3 * t1 + 2);  // edge 0->3 of t0 and 3->0 of t1
    if (fixed_border) {
      border_fixed_ = true;
      for (const Pixel& p : *fixed_border) insertBorderVertex(p);
    }
    if (segments && !segments->empty()) {
      tracking_ = true;
      bend_budget_ = 8 * segments->size() + 64;
      vertex_edge_.assign(coords_.size(), kNone);
      for (std::int32_t t = 0; t < static_cast<std::int32_t>(triangles_.size() / 3); ++t) noteCorners(t);
      for (const WindowSegment& segment : *segments) {
        const std::int32_t u = insertConstraintVertex(segment.from);
        const std::int32_t v = insertConstraintVertex(segment.to);
        insertSegment(u, v, 0);
      }
    }
    if (seeds) {
      for (const Pixel& p : *seeds) {
        const std::int32_t holder = locate(p);
        bool is_vertex = false;
        for (int k = 0; k < 3; ++k) {
          const Pixel v = vertex(3 * holder + k);
          is_vertex |= v.x == p.x && v.y == p.y;
        }
        if (!is_vertex) insert(p, holder);
      }
    }
    flushPending();

    const double total = static_cast<double>(dem_.pixelCount());
    std::uint64_t reported = 0;
    do {
      while (!heap_.empty()) {
        const std::int32_t t = heap_.front().triangle;
        insertCandidate(t);
        flushPending();
        // Progress by vertices relative to a rough budget; the stage total is the pixel count.
        const auto done = static_cast<std::uint64_t>(std::min(total, static_cast<double>(coords_.size()) * 8));
        if (progress && done - reported >= 4096) {
          progress->advance(done - reported);
          reported = done;
        }
      }
    } while (globe_ && strayCandidates());
    if (globe_ && border_fixed_) collectBorderViolations();
  }

  // When the greedy loop is done: the triangles not looked at since they last changed are
  // measured at the pixels outside them in the grid that they are drawn above (worstStray);
  // one beyond the bound makes its triangle a candidate again. Returns whether any did.
  bool strayCandidates() {
    bool again = false;
    const auto triangle_count = static_cast<std::int32_t>(triangles_.size() / 3);
    for (std::int32_t t = 0; t < triangle_count; ++t) {
      if (stray_checked_[static_cast<std::size_t>(t)]) continue;
      stray_checked_[static_cast<std::size_t>(t)] = 1;
      if (dropped_[static_cast<std::size_t>(t)]) continue;
      const Pixel a = vertex(3 * t), b = vertex(3 * t + 1), c = vertex(3 * t + 2);
      const DrawnTriangle drawn(globe_->point(pixelIndex(a)), globe_->point(pixelIndex(b)),
                                globe_->point(pixelIndex(c)));
      if (drawn.degenerate()) continue;
      Pixel stray;
      double stray_error = -1;
      worstStray(a, b, c, drawn, &stray, &stray_error);
      if (stray_error > max_error_) {
        candidate_[static_cast<std::size_t>(t)] = stray;
        error_[static_cast<std::size_t>(t)] = stray_error;
        heapPush(t);
        again = true;
      }
    }
    return again;
  }

  // Inserts triangle t's candidate: into t, or (a pixel t is drawn above from outside,
  // worstStray) into the triangle holding it; a pixel that is a vertex already is set aside.
  void insertCandidate(std::int32_t t) {
    const Pixel p = candidate_[static_cast<std::size_t>(t)];
    const Pixel a = vertex(3 * t), b = vertex(3 * t + 1), c = vertex(3 * t + 2);
    if (orient(a, b, p) >= 0 && orient(b, c, p) >= 0 && orient(c, a, p) >= 0) {
      insert(p, t);
      return;
    }
    const std::int32_t holder = locate(p);
    for (int k = 0; k < 3; ++k) {
      const Pixel v = vertex(3 * holder + k);
      if (v.x == p.x && v.y == p.y) {
        stray_vertices_.insert(pixelIndex(p));
        markPending(t);
        return;
      }
    }
    insert(p, holder);
  }

  // Inserts a pixel of the window's outline (not a corner) into the hull triangle whose
  // edge holds it. Linear search: only used while the triangulation is the outline.
  void insertBorderVertex(Pixel p) {
    for (std::int32_t t = 0; t < static_cast<std::int32_t>(triangles_.size() / 3); ++t) {
      const Pixel a = vertex(3 * t), b = vertex(3 * t + 1), c = vertex(3 * t + 2);
      if (orient(a, b, p) >= 0 && orient(b, c, p) >= 0 && orient(c, a, p) >= 0) {
        insert(p, t);
        return;
      }
    }
    TERRATILES_ASSERT(false);
  }

  // The triangulation without the triangles over nodata or at a virtual corner, and
  // without the vertices only those used.
  WindowMesh mesh() const {
    WindowMesh out;
    constexpr std::uint32_t kUnused = std::numeric_limits<std::uint32_t>::max();
    std::vector<std::uint32_t> output_index(coords_.size(), kUnused);
    out.triangle_indices.reserve(triangles_.size());
    for (std::size_t e = 0; e < triangles_.size(); e += 3) {
      if (dropped_[e / 3]) continue;
      // Positive in (col, row) is clockwise seen from above (row grows south): swap two
      // corners for TinMesh's counter-clockwise convention.
      for (const std::size_t k : {e, e + 2, e + 1}) {
        const auto v = static_cast<std::size_t>(triangles_[k]);
        if (output_index[v] == kUnused) {
          output_index[v] = static_cast<std::uint32_t>(out.pixels.size());
          out.pixels.push_back(coords_[v]);
        }
        out.triangle_indices.push_back(output_index[v]);
      }
    }
    out.pixels.shrink_to_fit();
    out.triangle_indices.shrink_to_fit();
    // Constrained edges that are still edges of a kept triangle, in a fixed order.
    std::vector<std::uint64_t> keys(constrained_.begin(), constrained_.end());
    std::sort(keys.begin(), keys.end());
    for (const std::uint64_t key : keys) {
      const auto u = static_cast<std::int32_t>(key >> 32), v = static_cast<std::int32_t>(key & 0xffffffffu);
      std::int32_t e = findHalfedge(u, v);
      if (e == kNone) e = findHalfedge(v, u);
      TERRATILES_ASSERT(e != kNone);
      const std::int32_t twin = halfedges_[static_cast<std::size_t>(e)];
      const bool kept = !dropped_[static_cast<std::size_t>(e / 3)] ||
                        (twin != kNone && !dropped_[static_cast<std::size_t>(twin / 3)]);
      if (!kept) {
        ++out.constrained_edges_dropped;
        continue;
      }
      out.constrained_edges.push_back({output_index[static_cast<std::size_t>(u)], output_index[static_cast<std::size_t>(v)]});
    }
    out.border_violations = border_violations_;
    out.segments_bent = segments_bent_;
    out.segments_bent_to_end = segments_bent_far_;
    out.constrained_edges_dropped += segments_dropped_;
    return out;
  }

 private:
  // A nodata corner becomes a virtual vertex (height: the mean of the valid pixels): its
  // triangles are refined like mixed ones and dropped at the end.
  std::int32_t addVertex(Pixel p) {
    coords_.push_back(p);
    if (tracking_) vertex_edge_.push_back(kNone);
    const float h = dem_.heightAt(p.x, p.y);
    vertex_virtual_.push_back(std::isnan(h) ? 1 : 0);
    vertex_height_.push_back(std::isnan(h) ? virtual_height_ : static_cast<double>(h));
    return static_cast<std::int32_t>(coords_.size()) - 1;
  }

  std::int32_t addTriangle(std::int32_t a, std::int32_t b, std::int32_t c, std::int32_t ab,
                           std::int32_t bc, std::int32_t ca) {
    const auto t = static_cast<std::int32_t>(triangles_.size() / 3);
    triangles_.insert(triangles_.end(), {a, b, c});
    halfedges_.insert(halfedges_.end(), {kNone, kNone, kNone});
    candidate_.push_back({});
    error_.push_back(0);
    dropped_.push_back(0);
    heap_position_.push_back(kNone);
    pending_flag_.push_back(0);
    stray_checked_.push_back(0);
    link(3 * t, ab);
    link(3 * t + 1, bc);
    link(3 * t + 2, ca);
    markPending(t);
    if (tracking_) noteCorners(t);
    return t;
  }

  // Rewrites triangle t in place (keeps its slot) and schedules it for a rescan.
  void setTriangle(std::int32_t t, std::int32_t a, std::int32_t b, std::int32_t c,
                   std::int32_t ab, std::int32_t bc, std::int32_t ca) {
    triangles_[static_cast<std::size_t>(3 * t)] = a;
    triangles_[static_cast<std::size_t>(3 * t + 1)] = b;
    triangles_[static_cast<std::size_t>(3 * t + 2)] = c;
    link(3 * t, ab);
    link(3 * t + 1, bc);
    link(3 * t + 2, ca);
    markPending(t);
    if (tracking_) noteCorners(t);
  }

  // With constraints: every vertex knows one halfedge leaving it (kept up to date by every
  // change of a triangle: its three corners are noted again).
  void noteCorners(std::int32_t t) {
    for (std::int32_t e = 3 * t; e < 3 * t + 3; ++e) {
      vertex_edge_[static_cast<std::size_t>(triangles_[static_cast<std::size_t>(e)])] = e;
    }
  }

  void link(std::int32_t a, std::int32_t b) {
    halfedges_[static_cast<std::size_t>(a)] = b;
    if (b != kNone) halfedges_[static_cast<std::size_t>(b)] = a;
  }

  void markPending(std::int32_t t) {
    heapRemove(t);
    stray_checked_[static_cast<std::size_t>(t)] = 0;
    if (!pending_flag_[static_cast<std::size_t>(t)]) {
      pending_flag_[static_cast<std::size_t>(t)] = 1;
      pending_.push_back(t);
    }
  }

  Pixel vertex(std::int32_t e) const { return coords_[static_cast<std::size_t>(triangles_[static_cast<std::size_t>(e)])]; }

  // Inserts pixel p, the candidate of triangle t, splitting t (or the edge p lies on).
  void insert(Pixel p, std::int32_t t) {
    const std::int32_t e0 = 3 * t, e1 = e0 + 1, e2 = e0 + 2;
    const std::int32_t a = triangles_[static_cast<std::size_t>(e0)];
    const std::int32_t b = triangles_[static_cast<std::size_t>(e1)];
    const std::int32_t c = triangles_[static_cast<std::size_t>(e2)];
    const Pixel pa = coords_[static_cast<std::size_t>(a)], pb = coords_[static_cast<std::size_t>(b)],
                pc = coords_[static_cast<std::size_t>(c)];
    // Which edge p lies on, if any (p is inside or on the closed triangle).
    std::int32_t on_edge = kNone;
    if (orient(pa, pb, p) == 0) on_edge = e0;
    else if (orient(pb, pc, p) == 0) on_edge = e1;
    else if (orient(pc, pa, p) == 0) on_edge = e2;
    const std::int32_t pv = addVertex(p);
    if (on_edge == kNone) {
      const std::int32_t h_ab = halfedges_[static_cast<std::size_t>(e0)];
      const std::int32_t h_bc = halfedges_[static_cast<std::size_t>(e1)];
      const std::int32_t h_ca = halfedges_[static_cast<std::size_t>(e2)];
      // t becomes (a, b, p); new (b, c, p) and (c, a, p).
      setTriangle(t, a, b, pv, h_ab, kNone, kNone);
      const std::int32_t t1 = addTriangle(b, c, pv, h_bc, kNone, 3 * t + 1);
      const std::int32_t t2 = addTriangle(c, a, pv, h_ca, 3 * t + 2, 3 * t1 + 1);
      legalize(3 * t);
      legalize(3 * t1);
      legalize(3 * t2);
      return;
    }
    splitEdge(on_edge, pv);
  }

  // p (vertex pv) lies on halfedge e of triangle (e / 3): split it and its twin's triangle.
  void splitEdge(std::int32_t e, std::int32_t pv) {
    const std::int32_t t = e / 3;
    const std::int32_t en = nextHalfedge(e), ep = prevHalfedge(e);
    const std::int32_t a = triangles_[static_cast<std::size_t>(e)];   // edge a -> b
    const std::int32_t b = triangles_[static_cast<std::size_t>(en)];
    const std::int32_t c = triangles_[static_cast<std::size_t>(ep)];  // opposite vertex
    const std::int32_t h_bc = halfedges_[static_cast<std::size_t>(en)];
    const std::int32_t h_ca = halfedges_[static_cast<std::size_t>(ep)];
    const std::int32_t twin = halfedges_[static_cast<std::size_t>(e)];
    if (!constrained_.empty() && constrained_.erase(edgeKey(a, b)) > 0) {
      constrained_.insert(edgeKey(a, pv));
      constrained_.insert(edgeKey(pv, b));
    }
    if (twin == kNone) {
      // Hull edge: t becomes (a, p, c) and new (p, b, c).
      setTriangle(t, a, pv, c, kNone, kNone, h_ca);
      const std::int32_t t1 = addTriangle(pv, b, c, kNone, h_bc, 3 * t + 1);
      legalize(3 * t + 2);
      legalize(3 * t1 + 1);
      return;
    }
    const std::int32_t u = twin / 3;  // twin runs b -> a; its opposite vertex is d
    const std::int32_t tn = nextHalfedge(twin), tp = prevHalfedge(twin);
    const std::int32_t d = triangles_[static_cast<std::size_t>(tp)];
    const std::int32_t h_ad = halfedges_[static_cast<std::size_t>(tn)];
    const std::int32_t h_db = halfedges_[static_cast<std::size_t>(tp)];
    // t -> (a, p, c), u -> (b, p, d), new (p, b, c) and (p, a, d).
    setTriangle(t, a, pv, c, kNone, kNone, h_ca);
    setTriangle(u, b, pv, d, kNone, kNone, h_db);
    const std::int32_t t1 = addTriangle(pv, b, c, 3 * u, h_bc, 3 * t + 1);
    const std::int32_t t2 = addTriangle(pv, a, d, 3 * t, h_ad, 3 * u + 1);
    legalize(3 * t + 2);
    legalize(3 * u + 2);
    legalize(3 * t1 + 1);
    legalize(3 * t2 + 1);
  }

  // Restores the Delaunay property across halfedge a, whose triangle's opposite vertex is
  // the newly inserted point; recurses on the two edges that become opposite it.
  void legalize(std::int32_t a) {
    const std::int32_t b = halfedges_[static_cast<std::size_t>(a)];
    if (b == kNone) return;
    if (!constrained_.empty() && isConstrained(a)) return;
    const std::int32_t P = triangles_[static_cast<std::size_t>(a)];
    const std::int32_t Q = triangles_[static_cast<std::size_t>(nextHalfedge(a))];
    const std::int32_t L = triangles_[static_cast<std::size_t>(prevHalfedge(a))];
    const std::int32_t R = triangles_[static_cast<std::size_t>(prevHalfedge(b))];
    if (!inCircle(coords_[static_cast<std::size_t>(P)], coords_[static_cast<std::size_t>(Q)],
                  coords_[static_cast<std::size_t>(L)], coords_[static_cast<std::size_t>(R)])) {
      return;
    }
    flipEdge(a);
    legalize(a);
    legalize(prevHalfedge(b));
  }

  // Flips the diagonal of the quad around halfedge a (P -> Q, opposite L) and its twin b
  // (opposite R): (P, Q, L) and (Q, P, R) become (P, R, L) and (Q, L, R); a runs P -> R and
  // next(a) is the new diagonal R -> L.
  void flipEdge(std::int32_t a) {
    const std::int32_t b = halfedges_[static_cast<std::size_t>(a)];
    const std::int32_t an = nextHalfedge(a), ap = prevHalfedge(a);
    const std::int32_t bn = nextHalfedge(b), bp = prevHalfedge(b);
    const std::int32_t L = triangles_[static_cast<std::size_t>(ap)];
    const std::int32_t R = triangles_[static_cast<std::size_t>(bp)];
    const std::int32_t h_pr = halfedges_[static_cast<std::size_t>(bn)];
    const std::int32_t h_ql = halfedges_[static_cast<std::size_t>(an)];
    triangles_[static_cast<std::size_t>(an)] = R;
    triangles_[static_cast<std::size_t>(bn)] = L;
    link(a, h_pr);
    link(b, h_ql);
    link(an, bn);
    markPending(a / 3);
    markPending(b / 3);
    if (tracking_) {
      noteCorners(a / 3);
      noteCorners(b / 3);
    }
  }

  // ---- break lines (constrained edges) ----

  bool isConstrained(std::int32_t e) const {
    return constrained_.count(edgeKey(triangles_[static_cast<std::size_t>(e)],
                                      triangles_[static_cast<std::size_t>(nextHalfedge(e))])) > 0;
  }

  // Calls visit(e) for the halfedges leaving vertex v (one per triangle around it) until it
  // returns true; returns whether one did.
  template <typename Visit>
  bool forEachOutgoing(std::int32_t v, Visit visit) const {
    const std::int32_t start = vertex_edge_[static_cast<std::size_t>(v)];
    TERRATILES_ASSERT(start != kNone);
    std::int32_t e = start;
    do {
      if (visit(e)) return true;
      e = halfedges_[static_cast<std::size_t>(prevHalfedge(e))];  // counter-clockwise
    } while (e != kNone && e != start);
    if (e == start) return false;
    // v is on the hull: the other way round from the start.
    e = start;
    while (true) {
      const std::int32_t twin = halfedges_[static_cast<std::size_t>(e)];
      if (twin == kNone) return false;
      e = nextHalfedge(twin);
      if (visit(e)) return true;
    }
  }

  // The halfedge from u to v, or kNone (no such edge, or only v -> u on the hull).
  std::int32_t findHalfedge(std::int32_t u, std::int32_t v) const {
    std::int32_t found = kNone;
    forEachOutgoing(u, [&](std::int32_t e) {
      if (triangles_[static_cast<std::size_t>(nextHalfedge(e))] != v) return false;
      found = e;
      return true;
    });
    return found;
  }

  // The triangle containing p (inside or on its boundary), by a walk from the last one found;
  // the first edge tried turns with every step, so the walk cannot cycle for long.
  std::int32_t locate(Pixel p) {
    std::int32_t t = last_located_ < static_cast<std::int32_t>(triangles_.size() / 3) ? last_located_ : 0;
    const std::size_t limit = 4 * triangles_.size() + 64;
    for (std::size_t step = 0; step < limit; ++step) {
      bool moved = false;
      for (std::int32_t i = 0; i < 3 && !moved; ++i) {
        const std::int32_t e = 3 * t + static_cast<std::int32_t>((step + static_cast<std::size_t>(i)) % 3);
        if (orient(vertex(e), vertex(nextHalfedge(e)), p) >= 0) continue;
        const std::int32_t twin = halfedges_[static_cast<std::size_t>(e)];
        TERRATILES_ASSERT(twin != kNone);  // p lies in the window
        t = twin / 3;
        moved = true;
      }
      if (!moved) {
        last_located_ = t;
        return t;
      }
    }
    TERRATILES_ASSERT(false);
    return kNone;
  }

  // The vertex at pixel p, inserted if it is not one yet.
  std::int32_t insertConstraintVertex(Pixel p) {
    const std::int32_t t = locate(p);
    for (std::int32_t e = 3 * t; e < 3 * t + 3; ++e) {
      const Pixel corner = vertex(e);
      if (corner.x == p.x && corner.y == p.y) return triangles_[static_cast<std::size_t>(e)];
    }
    insert(p, t);
    return static_cast<std::int32_t>(coords_.size()) - 1;
  }

  // Where segment u - v crosses the constrained edge a - b away from a vertex: the pixel
  // nearest the crossing (of the four around it, the nearest valid one that may take a
  // vertex: not a new one on a fixed outline), made a vertex, with a - b's constraint
  // dropped so the caller can run it through the vertex; kNone when no pixel qualifies.
  std::int32_t crossingVertex(std::int32_t u, std::int32_t v, std::int32_t a, std::int32_t b) {
    const Pixel pu = coords_[static_cast<std::size_t>(u)], pv = coords_[static_cast<std::size_t>(v)];
    const Pixel pa = coords_[static_cast<std::size_t>(a)], pb = coords_[static_cast<std::size_t>(b)];
    const double su = static_cast<double>(orient(pa, pb, pu)), sv = static_cast<double>(orient(pa, pb, pv));
    const double t = su / (su - sv);
    const double x = pu.x + t * (pv.x - pu.x), y = pu.y + t * (pv.y - pu.y);
    Pixel around[4];
    for (int k = 0; k < 4; ++k) {
      around[k] = {static_cast<std::int32_t>(std::floor(x)) + (k & 1), static_cast<std::int32_t>(std::floor(y)) + (k >> 1)};
    }
    std::sort(around, around + 4, [&](Pixel l, Pixel r) {
      const double dl = std::hypot(l.x - x, l.y - y), dr = std::hypot(r.x - x, r.y - y);
      return dl < dr || (dl == dr && (l.y < r.y || (l.y == r.y && l.x < r.x)));
    });
    for (const Pixel& p : around) {
      if (p.x < window_.x0 || p.x > window_.x1 || p.y < window_.y0 || p.y > window_.y1) continue;
      if (std::isnan(dem_.heightAt(p.x, p.y))) continue;
      const bool on_outline = p.x == window_.x0 || p.x == window_.x1 || p.y == window_.y0 || p.y == window_.y1;
      const std::int32_t t_p = locate(p);
      bool is_vertex = false;
      for (std::int32_t e = 3 * t_p; e < 3 * t_p + 3; ++e) is_vertex |= vertex(e).x == p.x && vertex(e).y == p.y;
      if (on_outline && border_fixed_ && !is_vertex) continue;
      constrained_.erase(edgeKey(a, b));
      return insertConstraintVertex(p);
    }
    return kNone;
  }

  // Makes u - v a chain of constrained edges (Sloan 1993: the edges the segment crosses are
  // flipped until none is left, then Delaunay is restored around the new edges). A vertex on
  // the segment splits it. Crossing an earlier constrained edge away from a vertex bends the
  // segment through that edge's end nearer to the segment line.
  void insertSegment(std::int32_t u, std::int32_t v, int depth) {
    while (u != v) {
      const Pixel pu = coords_[static_cast<std::size_t>(u)], pv = coords_[static_cast<std::size_t>(v)];
      const auto ahead = [&](Pixel w) {
        return std::int64_t{w.x - pu.x} * (pv.x - pu.x) + std::int64_t{w.y - pu.y} * (pv.y - pu.y) > 0;
      };
      // Where the segment leaves u: along an edge (to a vertex on the segment), or across the
      // edge opposite u in the triangle whose wedge holds v.
      std::int32_t reached = kNone, crossed = kNone;
      forEachOutgoing(u, [&](std::int32_t e) {
        const std::int32_t w1 = triangles_[static_cast<std::size_t>(nextHalfedge(e))];
        const std::int32_t w2 = triangles_[static_cast<std::size_t>(prevHalfedge(e))];
        const Pixel p1 = coords_[static_cast<std::size_t>(w1)], p2 = coords_[static_cast<std::size_t>(w2)];
        const std::int64_t o1 = orient(pu, p1, pv), o2 = orient(pu, p2, pv);
        if (o1 == 0 && ahead(p1)) reached = w1;
        else if (o2 == 0 && ahead(p2)) reached = w2;
        else if (o1 > 0 && o2 < 0) crossed = nextHalfedge(e);
        return reached != kNone || crossed != kNone;
      });
      if (reached != kNone) {
        constrained_.insert(edgeKey(u, reached));
        u = reached;
        continue;
      }
      TERRATILES_ASSERT(crossed != kNone);
      // Walk across the triangles the segment passes, noting the crossed edges; stop at v or
      // at a vertex on the segment. Invariant: the crossed halfedge runs from the right of
      // u -> v to its left.
      std::vector<std::array<std::int32_t, 2>> crossing;
      std::int32_t stop = kNone;
      for (std::int32_t x = crossed; stop == kNone;) {
        if (isConstrained(x)) {
          if (depth >= kMaxBends || segments_bent_ >= bend_budget_) {
            ++segments_dropped_;
            return;
          }
          ++segments_bent_;
          const std::int32_t a = triangles_[static_cast<std::size_t>(x)];
          const std::int32_t b = triangles_[static_cast<std::size_t>(nextHalfedge(x))];
          std::int32_t through = crossingVertex(u, v, a, b);
          if (through != kNone) {
            // Both lines go through the pixel nearest their crossing.
            insertSegment(a, through, depth + 1);
            insertSegment(through, b, depth + 1);
          } else {
            // No pixel near the crossing can take a vertex: bend through the crossed edge's
            // end nearer to the segment.
            const std::int64_t da = std::abs(orient(pu, pv, coords_[static_cast<std::size_t>(a)]));
            const std::int64_t db = std::abs(orient(pu, pv, coords_[static_cast<std::size_t>(b)]));
            ++segments_bent_far_;
            through = da <= db ? a : b;
          }
          insertSegment(u, through, depth + 1);
          insertSegment(through, v, depth + 1);
          return;
        }
        crossing.push_back({triangles_[static_cast<std::size_t>(x)], triangles_[static_cast<std::size_t>(nextHalfedge(x))]});
        const std::int32_t twin = halfedges_[static_cast<std::size_t>(x)];
        TERRATILES_ASSERT(twin != kNone);
        const std::int32_t r = triangles_[static_cast<std::size_t>(prevHalfedge(twin))];
        const std::int64_t side = orient(pu, pv, coords_[static_cast<std::size_t>(r)]);
        if (r == v || side == 0) stop = r;
        else x = side > 0 ? nextHalfedge(twin) : prevHalfedge(twin);
      }
      // Flip the crossed edges away; a flip is possible where the quad is strictly convex,
      // and the others wait for their turn (Sloan's queue).
      std::deque<std::array<std::int32_t, 2>> queue(crossing.begin(), crossing.end());
      std::vector<std::array<std::int32_t, 2>> created;
      const std::size_t limit = 64 * crossing.size() * crossing.size() + 1024;
      for (std::size_t step = 0; !queue.empty(); ++step) {
        TERRATILES_ASSERT(step < limit);
        const std::array<std::int32_t, 2> edge = queue.front();
        queue.pop_front();
        const std::int32_t e = findHalfedge(edge[0], edge[1]);
        TERRATILES_ASSERT(e != kNone);
        const std::int32_t twin = halfedges_[static_cast<std::size_t>(e)];
        const std::int32_t L = triangles_[static_cast<std::size_t>(prevHalfedge(e))];
        const std::int32_t R = triangles_[static_cast<std::size_t>(prevHalfedge(twin))];
        const Pixel pl = coords_[static_cast<std::size_t>(L)], pr = coords_[static_cast<std::size_t>(R)];
        const int side_a = sign(orient(pl, pr, coords_[static_cast<std::size_t>(edge[0])]));
        const int side_b = sign(orient(pl, pr, coords_[static_cast<std::size_t>(edge[1])]));
        if (side_a * side_b >= 0) {  // not strictly convex
          queue.push_back(edge);
          continue;
        }
        flipEdge(e);
        const int side_l = sign(orient(pu, pv, pl)), side_r = sign(orient(pu, pv, pr));
        if (side_l * side_r < 0) queue.push_back({R, L});
        else created.push_back({R, L});
      }
      constrained_.insert(edgeKey(u, stop));
      restoreDelaunay(created);
      u = stop;
    }
  }

  // Lawson's flips from the given edges outwards, constrained edges never flipped.
  void restoreDelaunay(std::vector<std::array<std::int32_t, 2>> edges) {
    const std::size_t limit = 64 * edges.size() * edges.size() + 1024;
    for (std::size_t step = 0; !edges.empty(); ++step) {
      TERRATILES_ASSERT(step < limit);
      const std::array<std::int32_t, 2> edge = edges.back();
      edges.pop_back();
      const std::int32_t e = findHalfedge(edge[0], edge[1]);
      if (e == kNone || isConstrained(e)) continue;
      const std::int32_t twin = halfedges_[static_cast<std::size_t>(e)];
      if (twin == kNone) continue;
      const std::int32_t P = edge[0], Q = edge[1];
      const std::int32_t L = triangles_[static_cast<std::size_t>(prevHalfedge(e))];
      const std::int32_t R = triangles_[static_cast<std::size_t>(prevHalfedge(twin))];
      const Pixel pp = coords_[static_cast<std::size_t>(P)], pq = coords_[static_cast<std::size_t>(Q)];
      const Pixel pl = coords_[static_cast<std::size_t>(L)], pr = coords_[static_cast<std::size_t>(R)];
      if (!inCircle(pp, pq, pl, pr)) continue;
      if (sign(orient(pl, pr, pp)) * sign(orient(pl, pr, pq)) >= 0) continue;
      flipEdge(e);
      edges.insert(edges.end(), {{P, R}, {R, Q}, {Q, L}, {L, P}});
    }
  }

  // Finds the worst pixel of every changed triangle and queues those above the bound.
  void flushPending() {
    for (const std::int32_t t : pending_) {
      pending_flag_[static_cast<std::size_t>(t)] = 0;
      scanTriangle(t);
      if (error_[static_cast<std::size_t>(t)] > max_error_) heapPush(t);
    }
    pending_.clear();
  }

  // Rasterises triangle t row by row (exact integer spans) and keeps its worst pixel.
  void scanTriangle(std::int32_t t) {
    const Pixel a = vertex(3 * t), b = vertex(3 * t + 1), c = vertex(3 * t + 2);
    const auto va = static_cast<std::size_t>(triangles_[static_cast<std::size_t>(3 * t)]);
    const auto vb = static_cast<std::size_t>(triangles_[static_cast<std::size_t>(3 * t + 1)]);
    const auto vc = static_cast<std::size_t>(triangles_[static_cast<std::size_t>(3 * t + 2)]);
    const double za = vertex_height_[va], zb = vertex_height_[vb], zc = vertex_height_[vc];
    const bool touches_virtual = vertex_virtual_[va] || vertex_virtual_[vb] || vertex_virtual_[vc];
    bool covers_nodata = false;
    const std::int64_t area2 = orient(a, b, c);
    TERRATILES_ASSERT(area2 > 0);
    // Plane z = gx * x + gy * y + z0 through the three vertices.
    const double ux = b.x - a.x, uy = b.y - a.y, vx = c.x - a.x, vy = c.y - a.y;
    const double dz1 = zb - za, dz2 = zc - za;
    const double inverse_area2 = 1.0 / static_cast<double>(area2);
    const double gx = (dz1 * vy - dz2 * uy) * inverse_area2;
    const double gy = (dz2 * ux - dz1 * vx) * inverse_area2;
    const double z0 = za - gx * a.x - gy * a.y;
    // On the globe: the triangle as drawn, straight in ECEF, measured exactly at every pixel
    // (it sags below the plane of its heights), but on a pole row (DemOnGlobe::poleRow), whose
    // pixels are all one point, in the grid. Degenerate in ECEF (two corners at a pole), it is
    // measured in the grid, as without a globe.
    if (globe_) {
      const DrawnTriangle drawn(globe_->point(pixelIndex(a)), globe_->point(pixelIndex(b)),
                                globe_->point(pixelIndex(c)));
      if (!drawn.degenerate()) {
        Pixel best;
        double best_error = -1;
        worstExact(a, b, c, drawn, gx, gy, z0, &best, &best_error, &covers_nodata);
        finishScan(t, a, b, c, best, best_error, covers_nodata, touches_virtual);
        return;
      }
    }

    // Edge functions w(x) = alpha * x + beta(y) >= 0 inside, for edges a->b, b->c, c->a.
    const Pixel from[3] = {a, b, c}, to[3] = {b, c, a};
    const std::int32_t min_y = std::min({a.y, b.y, c.y}), max_y = std::max({a.y, b.y, c.y});
    const std::int32_t min_x = std::min({a.x, b.x, c.x}), max_x = std::max({a.x, b.x, c.x});
    double best_error = -1;
    Pixel best{a.x, a.y};
    const float* heights = dem_.heights_m.data();
    // With nodata, pixel by pixel: note nodata, skip the vertices (valid or virtual), keep the
    // first largest error in row-major order.
    const auto considerWithNodata = [&](std::int32_t x, std::int32_t y, float h, double row_z) {
      if (std::isnan(h)) {
        covers_nodata = true;
        return;
      }
      if ((x == a.x && y == a.y) || (x == b.x && y == b.y) || (x == c.x && y == c.y)) return;
      const double error = std::fabs(gx * static_cast<double>(x) + row_z - h);
      if (error > best_error) {
        best_error = error;
        best = {x, y};
      }
    };
    // Per edge: alpha and beta(y) = beta_at_0 + beta_step * y; the span bound -beta / alpha is
    // estimated in floating point and then corrected with exact integer tests (an int64
    // division per edge and row cost more than the pixels of a small triangle).
    std::int64_t alpha[3], beta_step[3], beta_at_0[3];
    double inverse_alpha[3];
    for (int k = 0; k < 3; ++k) {
      alpha[k] = -std::int64_t{to[k].y - from[k].y};
      beta_step[k] = std::int64_t{to[k].x - from[k].x};
      beta_at_0[k] = -beta_step[k] * from[k].y + std::int64_t{to[k].y - from[k].y} * from[k].x;
    }
    if (max_x - min_x < kNarrowTriangle) {
      // Narrow: walk the bounding box with incremental edge functions; computing each row's
      // span would cost more than its few pixels. Same pixels, same order, same errors.
      std::int32_t x_first = min_x, x_last = max_x, y_first = min_y, y_last = max_y;
      if (border_fixed_) {  // as below: the fixed outline's pixels are never candidates
        x_first = std::max(x_first, window_.x0 + 1);
        x_last = std::min(x_last, window_.x1 - 1);
        y_first = std::max(y_first, window_.y0 + 1);
        y_last = std::min(y_last, window_.y1 - 1);
      }
      std::int64_t w_row[3];
      for (int k = 0; k < 3; ++k) w_row[k] = alpha[k] * x_first + beta_step[k] * y_first + beta_at_0[k];
#if defined(__x86_64__)
      const bool vectorised = !has_nodata_ && kHasAvx2;
      if (vectorised && x_first <= x_last) {
        boxWorstPixelInsideAvx2(heights, width_, x_first, x_last, y_first, y_last, gx, gy, z0, w_row, alpha,
                                beta_step, &best_error, &best.x, &best.y);
      }
#else
      const bool vectorised = false;
#endif
      for (std::int32_t y = y_first; y <= y_last && !vectorised; ++y) {
        const float* row = heights + static_cast<std::size_t>(y) * static_cast<std::size_t>(width_);
        const double row_z = gy * y + z0;
        std::int64_t w0 = w_row[0], w1 = w_row[1], w2 = w_row[2];
        if (!has_nodata_) {
          // Branch-free: a pixel outside (some edge function negative) scores -1.
          for (std::int32_t x = x_first; x <= x_last; ++x, w0 += alpha[0], w1 += alpha[1], w2 += alpha[2]) {
            const double error = std::fabs(gx * static_cast<double>(x) + row_z - row[x]);
            const double scored = (w0 | w1 | w2) < 0 ? -1.0 : error;
            const bool wins = scored > best_error;
            best_error = wins ? scored : best_error;
            best.x = wins ? x : best.x;
            best.y = wins ? y : best.y;
          }
        } else {
          for (std::int32_t x = x_first; x <= x_last; ++x, w0 += alpha[0], w1 += alpha[1], w2 += alpha[2]) {
            if ((w0 | w1 | w2) >= 0) considerWithNodata(x, y, row[x], row_z);  // inside the triangle
          }
        }
        for (int k = 0; k < 3; ++k) w_row[k] += beta_step[k];
      }
    }
    if (max_x - min_x >= kNarrowTriangle) {
      for (int k = 0; k < 3; ++k) inverse_alpha[k] = alpha[k] != 0 ? 1.0 / static_cast<double>(alpha[k]) : 0.0;
    }
    for (std::int32_t y = min_y; y <= max_y && max_x - min_x >= kNarrowTriangle; ++y) {
      std::int64_t x0 = min_x, x1 = max_x;
      if (!rowSpan(y, alpha, beta_step, beta_at_0, inverse_alpha, &x0, &x1)) continue;
      const float* row = heights + static_cast<std::size_t>(y) * static_cast<std::size_t>(width_);
      const double row_z = gy * y + z0;
      if (has_nodata_) {
        for (std::int64_t x = x0; x <= x1; ++x) considerWithNodata(static_cast<std::int32_t>(x), y, row[x], row_z);
        continue;
      }
      // First the row's largest error (vectorised), then its position only if it wins.
      const double row_max = rowMaxError(row, x0, x1, gx, row_z);
      if (row_max > best_error) {
        for (std::int64_t x = x0; x <= x1; ++x) {
          if (std::fabs(gx * static_cast<double>(x) + row_z - row[x]) == row_max) {
            best = {static_cast<std::int32_t>(x), y};
            best_error = row_max;
            break;
          }
        }
      }
    }
    finishScan(t, a, b, c, best, best_error, covers_nodata, touches_virtual);
  }

  // The span [x0, x1] of row y inside the triangle whose edge functions are
  // alpha * x + beta_at_0 + beta_step * y >= 0 (within the incoming [x0, x1]), without a
  // fixed outline's pixels; false when empty.
  bool rowSpan(std::int32_t y, const std::int64_t alpha[3], const std::int64_t beta_step[3],
               const std::int64_t beta_at_0[3], const double inverse_alpha[3], std::int64_t* x0,
               std::int64_t* x1) const {
    for (int k = 0; k < 3; ++k) {
      const std::int64_t beta = beta_at_0[k] + beta_step[k] * y;
      // Inside: alpha * x + beta >= 0.
      if (alpha[k] > 0) {
        // Truncation, not std::ceil (a library call without SSE4.1): the loops below make
        // it exact either way.
        std::int64_t bound = static_cast<std::int64_t>(static_cast<double>(-beta) * inverse_alpha[k]);
        while (alpha[k] * bound + beta < 0) ++bound;
        while (alpha[k] * (bound - 1) + beta >= 0) --bound;
        *x0 = std::max(*x0, bound);
      } else if (alpha[k] < 0) {
        std::int64_t bound = static_cast<std::int64_t>(static_cast<double>(-beta) * inverse_alpha[k]);
        while (alpha[k] * bound + beta < 0) --bound;
        while (alpha[k] * (bound + 1) + beta >= 0) ++bound;
        *x1 = std::min(*x1, bound);
      } else if (beta < 0) {
        return false;
      }
    }
    if (border_fixed_) {
      // A fixed outline's pixels are within the bound by its polyline (1D arithmetic that
      // the plane would only repeat up to rounding): never candidates, or a vertex could
      // appear on one side of a shared border only.
      if (y == window_.y0 || y == window_.y1) return false;
      *x0 = std::max<std::int64_t>(*x0, window_.x0 + 1);
      *x1 = std::min<std::int64_t>(*x1, window_.x1 - 1);
    }
    return *x0 <= *x1;
  }

  // Stores a scan's result: the candidate pixel and the triangle's error, or a drop mark for a
  // triangle over nodata.
  void finishScan(std::int32_t t, Pixel a, Pixel b, Pixel c, Pixel best, double best_error, bool covers_nodata,
                  bool touches_virtual) {
    // Never pick a vertex: its error is rounding noise, and inserting it twice would break
    // the triangulation.
    if ((best.x == a.x && best.y == a.y) || (best.x == b.x && best.y == b.y) ||
        (best.x == c.x && best.y == c.y)) {
      best_error = -1;  // no candidate
    }
    // A triangle over nodata or at a virtual corner is dropped from the result; while it
    // still holds a valid pixel other than its vertices it is "mixed" and refined before any
    // error-driven insertion (inserting its worst valid pixel), so the kept triangles end up
    // following the valid data's edge to within one pixel.
    const bool dropped = covers_nodata || touches_virtual;
    dropped_[static_cast<std::size_t>(t)] = dropped ? 1 : 0;
    if (dropped) best_error = best_error >= 0 ? kMixedPriority + best_error : 0;
    best_error = std::max(best_error, 0.0);
    candidate_[static_cast<std::size_t>(t)] = best;
    error_[static_cast<std::size_t>(t)] = best_error;
  }

  std::size_t pixelIndex(Pixel p) const {
    return static_cast<std::size_t>(p.y) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(p.x);
  }

  double exactError(const DrawnTriangle& drawn, Pixel p) const { return exactErrorAt(*globe_, drawn, p.x, p.y); }

  // Calls visit(x, y) for every pixel inside triangle (a, b, c), row by row, left to right,
  // within the box [x_first, x_last] x [y_first, y_last].
  template <typename Visit>
  static void forEachInside(Pixel a, Pixel b, Pixel c, std::int32_t x_first, std::int32_t x_last,
                            std::int32_t y_first, std::int32_t y_last, Visit&& visit) {
    const Pixel from[3] = {a, b, c}, to[3] = {b, c, a};
    std::int64_t alpha[3], beta_step[3], w_row[3];
    for (int k = 0; k < 3; ++k) {
      alpha[k] = -std::int64_t{to[k].y - from[k].y};
      beta_step[k] = std::int64_t{to[k].x - from[k].x};
      const std::int64_t beta_at_0 = -beta_step[k] * from[k].y + std::int64_t{to[k].y - from[k].y} * from[k].x;
      w_row[k] = alpha[k] * x_first + beta_step[k] * y_first + beta_at_0;
    }
    for (std::int32_t y = y_first; y <= y_last; ++y) {
      std::int64_t w0 = w_row[0], w1 = w_row[1], w2 = w_row[2];
      for (std::int32_t x = x_first; x <= x_last; ++x, w0 += alpha[0], w1 += alpha[1], w2 += alpha[2]) {
        if ((w0 | w1 | w2) >= 0) visit(x, y);
      }
      for (int k = 0; k < 3; ++k) w_row[k] += beta_step[k];
    }
  }

  // The worst pixel of triangle (a, b, c) by its exact error on the globe (on a pole row: by
  // the plane z = gx x + gy y + z0 of its heights), other than a fixed outline's pixels (the
  // first in row-major order on ties; best_error -1 when none); notes nodata. Vectorised
  // without nodata or a pole row, pixel by pixel with them.
  void worstExact(Pixel a, Pixel b, Pixel c, const DrawnTriangle& drawn, double gx, double gy, double z0, Pixel* best,
                  double* best_error, bool* covers_nodata) const {
    std::int32_t x_first = std::min({a.x, b.x, c.x}), x_last = std::max({a.x, b.x, c.x});
    std::int32_t y_first = std::min({a.y, b.y, c.y}), y_last = std::max({a.y, b.y, c.y});
    *best_error = -1;
    *best = a;
    const bool pole_rows = globe_->poleRow(y_first) || globe_->poleRow(y_last);
#if defined(__x86_64__)
    if (!has_nodata_ && !pole_rows && kHasAvx2) {
      const Pixel from[3] = {a, b, c}, to[3] = {b, c, a};
      std::int64_t alpha[3], beta_step[3], beta_at_0[3];
      for (int k = 0; k < 3; ++k) {
        alpha[k] = -std::int64_t{to[k].y - from[k].y};
        beta_step[k] = std::int64_t{to[k].x - from[k].x};
        beta_at_0[k] = -beta_step[k] * from[k].y + std::int64_t{to[k].y - from[k].y} * from[k].x;
      }
      if (x_last - x_first < kNarrowTriangle) {
        if (border_fixed_) {
          x_first = std::max(x_first, window_.x0 + 1);
          x_last = std::min(x_last, window_.x1 - 1);
          y_first = std::max(y_first, window_.y0 + 1);
          y_last = std::min(y_last, window_.y1 - 1);
        }
        if (x_first > x_last) return;
        std::int64_t w_row[3];
        for (int k = 0; k < 3; ++k) w_row[k] = alpha[k] * x_first + beta_step[k] * y_first + beta_at_0[k];
        boxWorstPixelExactAvx2(*globe_, drawn, width_, x_first, x_last, y_first, y_last, w_row, alpha, beta_step,
                               best_error, &best->x, &best->y);
        return;
      }
      double inverse_alpha[3];
      for (int k = 0; k < 3; ++k) inverse_alpha[k] = alpha[k] != 0 ? 1.0 / static_cast<double>(alpha[k]) : 0.0;
      for (std::int32_t y = y_first; y <= y_last; ++y) {
        std::int64_t x0 = x_first, x1 = x_last;
        if (!rowSpan(y, alpha, beta_step, beta_at_0, inverse_alpha, &x0, &x1)) continue;
        const double row_max = rowMaxExactAvx2(*globe_, drawn, y, x0, x1);
        if (row_max > *best_error) {
          for (std::int64_t x = x0; x <= x1; ++x) {
            if (exactErrorAt(*globe_, drawn, static_cast<std::int32_t>(x), y) == row_max) {
              *best = {static_cast<std::int32_t>(x), y};
              *best_error = row_max;
              break;
            }
          }
        }
      }
      return;
    }
#endif
    if (border_fixed_) {
      x_first = std::max(x_first, window_.x0 + 1);
      x_last = std::min(x_last, window_.x1 - 1);
      y_first = std::max(y_first, window_.y0 + 1);
      y_last = std::min(y_last, window_.y1 - 1);
    }
    if (x_first > x_last) return;
    forEachInside(a, b, c, x_first, x_last, y_first, y_last, [&](std::int32_t x, std::int32_t y) {
      const float h = dem_.heights_m[pixelIndex({x, y})];
      if (std::isnan(h)) {
        *covers_nodata = true;
        return;
      }
      const double error = pole_rows && globe_->poleRow(y) ? std::fabs(gx * static_cast<double>(x) + (gy * y + z0) - h)
                                                          : exactError(drawn, {x, y});
      if (error > *best_error) {
        *best_error = error;
        *best = {x, y};
      }
    });
  }

  // The worst pixel outside triangle (a, b, c) in the grid whose vertical meets the triangle
  // as drawn (its footprint strays from the grid triangle by its chord's bulge, strayMargin):
  // only pixels strictly inside the window's own ground (a fixed outline's pixels and other
  // windows' are not its to refine), off a pole row, with data, and not yet vertices (a
  // pixel the mesh already has as a vertex cannot be inserted again: its vertical is left to
  // the tiles' measure). A triangle's corners are lattice points, so a lattice point outside
  // it lies at least 1 / (its longest edge) pixels off: a smaller margin strays over none.
  void worstStray(Pixel a, Pixel b, Pixel c, const DrawnTriangle& drawn, Pixel* best, double* best_error) const {
    const auto corner = [&](Pixel p) { return GridCorner{double(p.x), double(p.y), globe_->poleRow(p.y)}; };
    const PixelMargin margin = strayMargin(*globe_, {corner(a), corner(b), corner(c)}, drawn.longestEdge(), 0.0);
    const double edge[3] = {std::sqrt(static_cast<double>(squaredLength(b, c))),
                            std::sqrt(static_cast<double>(squaredLength(c, a))),
                            std::sqrt(static_cast<double>(squaredLength(a, b)))};
    const double margin_px = std::max(margin.columns, margin.rows);
    if (margin_px * std::max({edge[0], edge[1], edge[2]}) < 1) return;
    const bool fixed = border_fixed_;
    const std::int32_t x0 = window_.x0 + (fixed ? 1 : 0), x1 = window_.x1 - (fixed ? 1 : 0);
    const std::int32_t y0 = window_.y0 + (fixed ? 1 : 0), y1 = window_.y1 - (fixed ? 1 : 0);
    const auto first = [](double value) { return static_cast<std::int64_t>(std::ceil(value - 1e-9)); };
    const auto last = [](double value) { return static_cast<std::int64_t>(std::floor(value + 1e-9)); };
    const std::int64_t col0 = std::max<std::int64_t>(x0, first(std::min({a.x, b.x, c.x}) - margin.boxColumns()));
    const std::int64_t col1 = std::min<std::int64_t>(x1, last(std::max({a.x, b.x, c.x}) + margin.boxColumns()));
    const std::int64_t row0 = std::max<std::int64_t>(y0, first(std::min({a.y, b.y, c.y}) - margin.rows));
    const std::int64_t row1 = std::min<std::int64_t>(y1, last(std::max({a.y, b.y, c.y}) + margin.rows));
    for (std::int64_t row = row0; row <= row1; ++row) {
      if (globe_->poleRow(static_cast<std::int32_t>(row))) continue;
      for (std::int64_t col = col0; col <= col1; ++col) {
        const Pixel p{static_cast<std::int32_t>(col), static_cast<std::int32_t>(row)};
        const std::int64_t wa = orient(b, c, p), wb = orient(c, a, p), wc = orient(a, b, p);
        if (wa >= 0 && wb >= 0 && wc >= 0) continue;  // inside: worstExact's
        // How far outside, beyond the edge it is farthest past, in pixels.
        const double beyond = std::min({static_cast<double>(wa) / edge[0], static_cast<double>(wb) / edge[1],
                                        static_cast<double>(wc) / edge[2]});
        if (beyond < -margin_px) continue;
        const std::size_t i = pixelIndex(p);
        if (std::isnan(dem_.heights_m[i]) || stray_vertices_.count(i)) continue;
        double offset = 0;
        if (!drawn.meets(globe_->point(i), globe_->up(i), &offset)) continue;
        const double error = std::min(std::fabs(offset), kWallError);
        if (error > *best_error) {
          *best_error = error;
          *best = p;
        }
      }
    }
  }

  static std::int64_t squaredLength(Pixel p, Pixel q) {
    return std::int64_t{q.x - p.x} * (q.x - p.x) + std::int64_t{q.y - p.y} * (q.y - p.y);
  }

  // A fixed outline (a windowed build's shared border polylines) is chosen in 1D, before the
  // windows' triangles exist: the pixels on it that a triangle of this window, as drawn,
  // misses by more than the bound are collected for the build to add to the outline.
  void collectBorderViolations() {
    const auto triangle_count = static_cast<std::int32_t>(triangles_.size() / 3);
    for (std::int32_t t = 0; t < triangle_count; ++t) {
      if (dropped_[static_cast<std::size_t>(t)]) continue;
      const Pixel corner[3] = {vertex(3 * t), vertex(3 * t + 1), vertex(3 * t + 2)};
      const DrawnTriangle drawn(globe_->point(pixelIndex(corner[0])), globe_->point(pixelIndex(corner[1])),
                                globe_->point(pixelIndex(corner[2])));
      if (drawn.degenerate()) continue;
      for (int k = 0; k < 3; ++k) {
        const Pixel p = corner[k], q = corner[(k + 1) % 3];
        const bool along_column = p.x == q.x && (p.x == window_.x0 || p.x == window_.x1);
        const bool along_row = p.y == q.y && (p.y == window_.y0 || p.y == window_.y1);
        if (!along_column && !along_row) continue;
        const std::int32_t steps = std::max(std::abs(q.x - p.x), std::abs(q.y - p.y));
        const std::int32_t dx = (q.x > p.x) - (q.x < p.x), dy = (q.y > p.y) - (q.y < p.y);
        for (std::int32_t i = 1; i < steps; ++i) {
          const Pixel r{p.x + dx * i, p.y + dy * i};
          if (std::isnan(dem_.heights_m[pixelIndex(r)]) || globe_->poleRow(r.y)) continue;
          if (exactError(drawn, r) > max_error_) border_violations_.push_back(r);
        }
      }
    }
  }

  // ---- max-heap of triangles by error, with positions for removal ----
  // Entries carry their error so comparisons stay inside the heap's own memory.
  struct HeapEntry {
    double error;
    std::int32_t triangle;
  };
  static bool higher(const HeapEntry& l, const HeapEntry& r) {
    // Ties broken by triangle index: the result never depends on the heap's history.
    return l.error > r.error || (l.error == r.error && l.triangle < r.triangle);
  }
  void place(std::int32_t i, const HeapEntry& entry) {
    heap_[static_cast<std::size_t>(i)] = entry;
    heap_position_[static_cast<std::size_t>(entry.triangle)] = i;
  }
  void siftUp(std::int32_t i) {
    const HeapEntry entry = heap_[static_cast<std::size_t>(i)];
    while (i > 0) {
      const std::int32_t parent = (i - 1) / 2;
      if (!higher(entry, heap_[static_cast<std::size_t>(parent)])) break;
      place(i, heap_[static_cast<std::size_t>(parent)]);
      i = parent;
    }
    place(i, entry);
  }
  void siftDown(std::int32_t i) {
    const auto n = static_cast<std::int32_t>(heap_.size());
    const HeapEntry entry = heap_[static_cast<std::size_t>(i)];
    while (true) {
      std::int32_t child = 2 * i + 1;
      if (child >= n) break;
      if (child + 1 < n && higher(heap_[static_cast<std::size_t>(child + 1)], heap_[static_cast<std::size_t>(child)])) ++child;
      if (!higher(heap_[static_cast<std::size_t>(child)], entry)) break;
      place(i, heap_[static_cast<std::size_t>(child)]);
      i = child;
    }
    place(i, entry);
  }
  void heapPush(std::int32_t t) {
    heap_.push_back({error_[static_cast<std::size_t>(t)], t});
    heap_position_[static_cast<std::size_t>(t)] = static_cast<std::int32_t>(heap_.size()) - 1;
    siftUp(static_cast<std::int32_t>(heap_.size()) - 1);
  }
  void heapRemove(std::int32_t t) {
    const std::int32_t i = heap_position_[static_cast<std::size_t>(t)];
    if (i == kNone) return;
    heap_position_[static_cast<std::size_t>(t)] = kNone;
    const HeapEntry last = heap_.back();
    heap_.pop_back();
    if (i == static_cast<std::int32_t>(heap_.size())) return;
    place(i, last);
    if (i > 0 && higher(last, heap_[static_cast<std::size_t>((i - 1) / 2)])) siftUp(i);
    else siftDown(i);
  }

  const DemGrid& dem_;
  const DemOnGlobe* globe_;
  const std::int32_t width_;
  const double max_error_;
  static constexpr double kMixedPriority = 1e12;  // above any height error on Earth

  const Window window_;
  bool border_fixed_ = false;
  const bool has_nodata_;
  const double virtual_height_;
  std::vector<Pixel> coords_;
  std::vector<double> vertex_height_;
  std::vector<std::uint8_t> vertex_virtual_;
  std::vector<std::uint8_t> dropped_;
  std::vector<std::int32_t> triangles_;
  std::vector<std::int32_t> halfedges_;
  std::vector<Pixel> candidate_;
  std::vector<double> error_;
  std::vector<std::int32_t> heap_position_;
  std::vector<std::uint8_t> pending_flag_;
  std::vector<HeapEntry> heap_;
  std::vector<std::int32_t> pending_;
  std::vector<Pixel> border_violations_;
  std::unordered_set<std::size_t> stray_vertices_;  // pixels worstStray found as vertices
  std::vector<std::uint8_t> stray_checked_;  // per triangle: strayCandidates looked at it as it is
  // Break lines: only used when the window has some.
  static constexpr int kMaxBends = 16;
  bool tracking_ = false;
  std::vector<std::int32_t> vertex_edge_;  // a halfedge leaving each vertex
  std::unordered_set<std::uint64_t> constrained_;  // edgeKey of the constrained edges
  std::int32_t last_located_ = 0;
  std::size_t segments_bent_ = 0, segments_bent_far_ = 0, segments_dropped_ = 0;
  std::size_t bend_budget_ = 0;  // bends allowed in a window, against pathological inputs
};

}  // namespace

namespace {

// How far a run's chord from pixel p to pixel q misses pixel r on the globe: the signed
// distance along r's vertical from r's DEM point to the point of the chord nearest to that
// vertical (positive: the chord is above), plus what a triangle holding the chord may add
// across it: the gap between the vertical and the chord times twice the local slope.
// gap_m (when not null): how far r's vertical passes from the chord, metres.
double chordError(const DemOnGlobe& globe, std::size_t p, std::size_t q, std::size_t r, double slope,
                  double* gap_m = nullptr) {
  const EcefPoint& a = globe.point(p);
  const EcefPoint& b = globe.point(q);
  const EcefPoint& point = globe.point(r);
  const UnitVector& up = globe.up(r);
  const double d[3] = {b.x - a.x, b.y - a.y, b.z - a.z};
  const double w[3] = {point.x - a.x, point.y - a.y, point.z - a.z};
  const double nd = up[0] * d[0] + up[1] * d[1] + up[2] * d[2];
  const double wn = up[0] * w[0] + up[1] * w[1] + up[2] * w[2];
  const double wd = w[0] * d[0] + w[1] * d[1] + w[2] * d[2];
  const double dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  const double denominator = dd - nd * nd;
  if (!(denominator > 0)) return kWallError;
  const double s = (wd - wn * nd) / denominator;  // along the chord
  const double t = s * nd - wn;                   // along the vertical
  double gap2 = 0;
  for (int k = 0; k < 3; ++k) {
    const double g = w[k] + t * up[k] - s * d[k];
    gap2 += g * g;
  }
  if (gap_m) *gap_m = std::sqrt(gap2);
  return std::fabs(t) + 2 * slope * std::sqrt(gap2);
}

// Border polylines for the windowed build: the positions along one straight run of pixels
// (a window side, endpoints included) that make it within max_error of the DEM, by recursive
// worst-pixel insertion, keeping the `forced` positions (break line ends on the border, and
// pixels a window's triangles missed). Without a globe the error is linear interpolation of
// the heights; on the globe it is chordError. A run with nodata keeps every valid pixel (and
// its endpoints, which become virtual when nodata). A run along a pole row is measured in the
// grid (its pixels are one point).
// shared: the run is a block's side that a neighbouring block shares, which may not take
// pixels a triangle misses later (TinOptions::shared_sides). On the globe its chords are also
// kept close to its pixels' verticals: a chord whose vertical passes a pixel farther than a
// quarter of the pixels' spacing is split there (a chord along a parallel bows towards the
// pole by about L^2 tan(lat) / 8R, and a triangle's plane through it can tilt more than the
// terrain: on ETOPO5 at 48 deg a 700 km chord passes 10 km from the pixels).
std::vector<Pixel> simplifyRun(const DemGrid& dem, const DemOnGlobe* globe, Pixel from, Pixel to,
                               double max_error_m, const std::vector<Pixel>& forced, bool shared = false) {
  const std::int32_t length = std::max(std::abs(to.x - from.x), std::abs(to.y - from.y));
  const std::int32_t dx = (to.x > from.x) - (to.x < from.x), dy = (to.y > from.y) - (to.y < from.y);
  auto at = [&](std::int32_t i) { return Pixel{from.x + dx * i, from.y + dy * i}; };
  auto height = [&](std::int32_t i) { const Pixel p = at(i); return dem.heightAt(p.x, p.y); };
  auto index = [&](std::int32_t i) { const Pixel p = at(i); return dem.index(p.x, p.y); };
  // The DEM's slope along and across the run at position i (rise over run between the
  // neighbouring pixels' points on the globe), for chordError.
  auto slope = [&](std::int32_t i) {
    const Pixel p = at(i);
    double worst = 0;
    for (const auto& [ox, oy] : {std::pair{1, 0}, std::pair{0, 1}}) {
      const Pixel u{std::max(0, p.x - ox), std::max(0, p.y - oy)};
      const Pixel v{std::min(dem.width - 1, p.x + ox), std::min(dem.height - 1, p.y + oy)};
      const float hu = dem.heightAt(u.x, u.y), hv = dem.heightAt(v.x, v.y);
      if (std::isnan(hu) || std::isnan(hv) || (u.x == v.x && u.y == v.y)) continue;
      const EcefPoint& pu = globe->point(u.x, u.y);
      const EcefPoint& pv = globe->point(v.x, v.y);
      const double distance = std::hypot(pv.x - pu.x, pv.y - pu.y, pv.z - pu.z);
      if (distance > 0) worst = std::max(worst, std::fabs(static_cast<double>(hv) - hu) / distance);
    }
    return worst;
  };
  std::vector<std::uint8_t> keep(static_cast<std::size_t>(length) + 1, 0);
  keep.front() = keep.back() = 1;
  bool has_nodata = false;
  for (std::int32_t i = 0; i <= length; ++i) has_nodata |= std::isnan(height(i));
  if (has_nodata) {
    for (std::int32_t i = 1; i < length; ++i) keep[static_cast<std::size_t>(i)] = !std::isnan(height(i));
  } else {
    for (const Pixel& p : forced) keep[static_cast<std::size_t>(std::max(std::abs(p.x - from.x), std::abs(p.y - from.y)))] = 1;
    // A run along a pole row is one point on the globe: measured in the grid.
    const bool on_globe = globe && !(from.y == to.y && globe->poleRow(from.y));
    std::vector<double> slopes;
    // A shared side (below): per position, the steepest rise to a neighbouring pixel (one-sided,
    // not the central difference above) and the ground distance to the nearest pixel across
    // the run, the nearest a triangle's third vertex can be.
    std::vector<double> steepest, across;
    if (on_globe) {
      slopes.resize(static_cast<std::size_t>(length) + 1);
      for (std::int32_t i = 0; i <= length; ++i) slopes[static_cast<std::size_t>(i)] = slope(i);
      if (shared) {
        steepest.assign(slopes.size(), 0.0);
        across.assign(slopes.size(), std::numeric_limits<double>::infinity());
        for (std::int32_t i = 0; i <= length; ++i) {
          const Pixel p = at(i);
          const EcefPoint& pp = globe->point(p.x, p.y);
          for (const auto& [ox, oy] : {std::pair{1, 0}, std::pair{-1, 0}, std::pair{0, 1}, std::pair{0, -1}}) {
            const Pixel n{p.x + ox, p.y + oy};
            if (n.x < 0 || n.y < 0 || n.x >= dem.width || n.y >= dem.height || std::isnan(dem.heightAt(n.x, n.y))) continue;
            const EcefPoint& pn = globe->point(n.x, n.y);
            const double distance = std::hypot(pn.x - pp.x, pn.y - pp.y, pn.z - pp.z);
            if (!(distance > 0)) continue;
            const auto k = static_cast<std::size_t>(i);
            steepest[k] = std::max(steepest[k], std::fabs(static_cast<double>(dem.heightAt(n.x, n.y)) - height(i)) / distance);
            if ((ox != 0) == (dx == 0)) across[k] = std::min(across[k], distance);
          }
        }
      }
    }
    std::vector<std::pair<std::int32_t, std::int32_t>> segments;
    for (std::int32_t i0 = 0, i = 1; i <= length; ++i) {
      if (!keep[static_cast<std::size_t>(i)]) continue;
      segments.push_back({i0, i});
      i0 = i;
    }
    while (!segments.empty()) {
      const auto [i0, i1] = segments.back();
      segments.pop_back();
      const double h0 = height(i0), h1 = height(i1);
      double worst = max_error_m;
      std::int32_t worst_i = -1;
      double widest_gap = 0;
      std::int32_t widest_i = -1;
      for (std::int32_t i = i0 + 1; i < i1; ++i) {
        double gap = 0;
        double error = on_globe ? chordError(*globe, index(i0), index(i1), index(i),
                                             slopes[static_cast<std::size_t>(i)], shared ? &gap : nullptr)
                                : std::fabs(h0 + (h1 - h0) * (i - i0) / (i1 - i0) - height(i));
        if (on_globe && shared) {
          // A triangle's plane through the chord meets the pixel's vertical `gap` away from
          // the chord: it may tilt as steeply as the rise to a neighbour, and by the chord's
          // own miss over the distance to the nearest third vertex.
          const auto k = static_cast<std::size_t>(i);
          const double miss = std::max(0.0, error - 2 * slopes[k] * gap);
          const double tilt = std::isfinite(across[k]) ? miss / across[k] : 0.0;
          error = miss + gap * (2 * std::max(slopes[k], steepest[k]) + tilt);
        }
        if (error > worst) worst = error, worst_i = i;
        if (gap > widest_gap) widest_gap = gap, widest_i = i;
      }
      if (worst_i < 0 && shared && widest_i >= 0) {
        const EcefPoint& a = globe->point(index(i0));
        const EcefPoint& b = globe->point(index(i0 + 1));
        if (widest_gap > 0.25 * std::hypot(b.x - a.x, b.y - a.y, b.z - a.z)) worst_i = widest_i;
      }
      if (worst_i < 0) continue;
      keep[static_cast<std::size_t>(worst_i)] = 1;
      segments.push_back({i0, worst_i});
      segments.push_back({worst_i, i1});
    }
  }
  std::vector<Pixel> kept;
  for (std::int32_t i = 1; i < length; ++i) {
    if (keep[static_cast<std::size_t>(i)]) kept.push_back(at(i));
  }
  return kept;  // interior positions only; the endpoints are window corners
}

std::vector<std::int32_t> blockEdges(std::int32_t length, std::int32_t block) {
  std::vector<std::int32_t> edges;
  for (std::int32_t p = 0; p < length - 1; p += block) edges.push_back(p);
  edges.push_back(length - 1);
  return edges;
}

}  // namespace

namespace {

// Splits segments where they cross the windows' border lines (column xs[i] or row ys[j]
// strictly between their ends), at the border pixel nearest to the crossing. Pieces whose
// new end is nodata are dropped (counted).
std::vector<WindowSegment> splitAtWindowBorders(const DemGrid& dem, const std::vector<PixelSegment>& segments,
                                                const std::vector<std::int32_t>& xs,
                                                const std::vector<std::int32_t>& ys, std::size_t& dropped) {
  std::vector<WindowSegment> pieces;
  for (const PixelSegment& segment : segments) {
    pieces.push_back({{segment.col0, segment.row0}, {segment.col1, segment.row1}});
  }
  // Columns first, then rows: a row split keeps a piece's columns between its ends.
  for (const bool columns : {true, false}) {
    const std::vector<std::int32_t>& lines = columns ? xs : ys;
    std::vector<WindowSegment> split;
    for (const WindowSegment& piece : pieces) {
      const std::int32_t a = columns ? piece.from.x : piece.from.y, b = columns ? piece.to.x : piece.to.y;
      const std::int32_t low = std::min(a, b), high = std::max(a, b);
      Pixel start = piece.from;
      bool valid = true;
      // The lines strictly between the ends, in order from `from` to `to`.
      std::vector<std::int32_t> crossed;
      for (auto it = std::upper_bound(lines.begin(), lines.end(), low); it != lines.end() && *it < high; ++it) {
        crossed.push_back(*it);
      }
      if (a > b) std::reverse(crossed.begin(), crossed.end());
      for (const std::int32_t line : crossed) {
        const double t = static_cast<double>(line - a) / static_cast<double>(b - a);
        const double other = columns ? piece.from.y + t * (piece.to.y - piece.from.y)
                                     : piece.from.x + t * (piece.to.x - piece.from.x);
        const auto snapped = static_cast<std::int32_t>(std::lround(other));
        const Pixel cut = columns ? Pixel{line, snapped} : Pixel{snapped, line};
        const bool cut_valid = dem.isValid(cut.x, cut.y);
        if (valid && cut_valid && (cut.x != start.x || cut.y != start.y)) split.push_back({start, cut});
        if (valid && !cut_valid) ++dropped;
        start = cut;
        valid = cut_valid;
      }
      if (valid && (piece.to.x != start.x || piece.to.y != start.y)) split.push_back({start, piece.to});
    }
    pieces = std::move(split);
  }
  return pieces;
}

// Builds every window of a windowed TIN (their outlines given: vertical[i][j] is column
// xs[i] between ys[j] and ys[j+1], horizontal[j][i] row ys[j] between xs[i] and xs[i+1]) and
// stitches them into result. Every batch of windows is built in parallel, then stitched into
// the mesh and released, so memory holds the DEM, the mesh and one batch. Stitch: vertices on
// shared borders have the same pixel position in both windows; only those (on a window's
// outline) need looking up, every other vertex is new. Returns the outline pixels the
// windows' triangles miss on the globe (WindowMesh::border_violations), sorted, unique.
std::vector<Pixel> buildWindows(const DemGrid& dem, const TinOptions& options, const DemFacts& facts,
                                const std::vector<std::int32_t>& xs, const std::vector<std::int32_t>& ys,
                                const std::vector<std::vector<std::vector<Pixel>>>& vertical,
                                const std::vector<std::vector<std::vector<Pixel>>>& horizontal,
                                const std::vector<std::vector<WindowSegment>>& window_segments,
                                const std::vector<std::vector<Pixel>>& window_seeds, Progress* progress,
                                ConstrainedTin& result) {
  const std::size_t nx = xs.size() - 1, ny = ys.size() - 1;
  if (progress) progress->beginStage("TIN (greedy insertion, windowed)", nx * ny);
  const std::size_t window_count = nx * ny;
  std::vector<WindowMesh> batch;
  TinMesh& mesh = result.mesh;
  std::unordered_map<std::uint64_t, std::uint32_t> outline_index;
  std::vector<std::uint32_t> remap;
  std::vector<Pixel> violations;
  constexpr std::size_t kBatch = 64;  // report progress and check Ctrl-C between batches
  for (std::size_t first = 0; first < window_count; first += kBatch) {
    const std::size_t end = std::min(window_count, first + kBatch);
    batch.assign(end - first, WindowMesh{});
    tbb::parallel_for(first, end, [&](std::size_t b) {
      const std::size_t i = b % nx, j = b / nx;
      std::vector<Pixel> border;
      for (const auto* run : {&horizontal[j][i], &horizontal[j + 1][i], &vertical[i][j], &vertical[i + 1][j]}) {
        border.insert(border.end(), run->begin(), run->end());
      }
      GreedyInsertion insertion(dem, options.globe, options.max_error_m, {xs[i], ys[j], xs[i + 1], ys[j + 1]}, facts);
      insertion.run(nullptr, &border, window_segments.empty() ? nullptr : &window_segments[b],
                    window_seeds.empty() ? nullptr : &window_seeds[b]);
      batch[b - first] = insertion.mesh();
    });
    // Grow the mesh once per batch to the size projected from the windows done so far (plus
    // 10 %), instead of doubling: a doubling of the final arrays would need 3x their size.
    std::size_t batch_vertices = 0, batch_indices = 0;
    for (const WindowMesh& window : batch) {
      batch_vertices += window.pixels.size();
      batch_indices += window.triangle_indices.size();
    }
    const double projection = 1.1 * static_cast<double>(window_count) / static_cast<double>(end);
    const auto projected = [&](std::size_t size) {
      return std::max(size, static_cast<std::size_t>(static_cast<double>(size) * projection));
    };
    if (mesh.vertices.size() + batch_vertices > mesh.vertices.capacity()) {
      mesh.vertices.reserve(projected(mesh.vertices.size() + batch_vertices));
    }
    if (mesh.triangle_indices.size() + batch_indices > mesh.triangle_indices.capacity()) {
      mesh.triangle_indices.reserve(projected(mesh.triangle_indices.size() + batch_indices));
    }
    for (std::size_t b = first; b < end; ++b) {
      WindowMesh& window = batch[b - first];
      const std::size_t i = b % nx, j = b / nx;
      remap.resize(window.pixels.size());
      for (std::size_t v = 0; v < window.pixels.size(); ++v) {
        const Pixel p = window.pixels[v];
        const bool on_outline = p.x == xs[i] || p.x == xs[i + 1] || p.y == ys[j] || p.y == ys[j + 1];
        if (!on_outline) {
          remap[v] = static_cast<std::uint32_t>(mesh.vertices.size());
          mesh.vertices.push_back(gridPoint(dem, p));
          continue;
        }
        const std::uint64_t key = (static_cast<std::uint64_t>(p.y) << 32) | static_cast<std::uint32_t>(p.x);
        const auto [it, inserted] = outline_index.try_emplace(key, static_cast<std::uint32_t>(mesh.vertices.size()));
        if (inserted) mesh.vertices.push_back(gridPoint(dem, p));
        remap[v] = it->second;
      }
      for (const std::uint32_t v : window.triangle_indices) mesh.triangle_indices.push_back(remap[v]);
      for (const auto& edge : window.constrained_edges) {
        const std::uint32_t u = remap[edge[0]], v = remap[edge[1]];
        result.constrained_edges.push_back({std::min(u, v), std::max(u, v)});
      }
      result.edges_dropped += window.constrained_edges_dropped;
      result.segments_bent += window.segments_bent;
      result.segments_bent_to_end += window.segments_bent_to_end;
      violations.insert(violations.end(), window.border_violations.begin(), window.border_violations.end());
      window = WindowMesh{};
    }
    if (progress) progress->advance(end - first);
  }
  if (progress) progress->endStage();
  std::sort(violations.begin(), violations.end(),
            [](const Pixel& l, const Pixel& r) { return l.y != r.y ? l.y < r.y : l.x < r.x; });
  violations.erase(std::unique(violations.begin(), violations.end(),
                               [](const Pixel& l, const Pixel& r) { return l.x == r.x && l.y == r.y; }),
                   violations.end());
  return violations;
}

}  // namespace

TinMesh buildTin(const DemGrid& dem, const TinOptions& options, Progress& progress) {
  return buildConstrainedTin(dem, options, {}, progress).mesh;
}

ConstrainedTin buildConstrainedTin(const DemGrid& dem, const TinOptions& options,
                                   const std::vector<PixelSegment>& segments, Progress& progress) {
  if (!(options.max_error_m > 0) || !std::isfinite(options.max_error_m)) {
    throw Error(ErrorCode::Usage, "--tin-max-error is " + std::to_string(options.max_error_m) +
                                      "; expected a positive number of metres");
  }
  if (dem.width < 2 || dem.height < 2) {
    throw Error(ErrorCode::Input, "the DEM is " + std::to_string(dem.width) + " x " +
                                      std::to_string(dem.height) + " pixels; expected at least 2 x 2");
  }
  for (const PixelSegment& segment : segments) {
    for (const Pixel p : {Pixel{segment.col0, segment.row0}, Pixel{segment.col1, segment.row1}}) {
      if (p.x < 0 || p.y < 0 || p.x >= dem.width || p.y >= dem.height || !dem.isValid(p.x, p.y)) {
        throw Error(ErrorCode::Internal, "a break line ends at pixel (" + std::to_string(p.x) + ", " +
                                             std::to_string(p.y) + "), outside the grid's valid pixels");
      }
    }
  }
  const bool in_region = !options.region.empty();
  if (in_region) {
    const TinOptions::Box& box = options.region;
    if (box.x0 < 0 || box.y0 < 0 || box.x1 >= dem.width || box.y1 >= dem.height || box.x1 == box.x0 ||
        box.y1 == box.y0 || options.block_pixels < 1 || !segments.empty()) {
      throw Error(ErrorCode::Internal, "TIN: a block's box must hold at least 2 x 2 pixels of the grid, with windows "
                                       "and without break lines");
    }
  }
  const DemFacts facts = demFacts(dem);
  ConstrainedTin result;
  const bool windowed = in_region || (options.block_pixels > 0 && (dem.width > options.block_pixels + 1 ||
                                                                    dem.height > options.block_pixels + 1));
  if (!windowed) {
    progress.beginStage("TIN (greedy insertion)", dem.pixelCount());
    std::vector<WindowSegment> window_segments;
    for (const PixelSegment& segment : segments) {
      if (segment.col0 == segment.col1 && segment.row0 == segment.row1) continue;
      window_segments.push_back({{segment.col0, segment.row0}, {segment.col1, segment.row1}});
    }
    GreedyInsertion insertion(dem, options.globe, options.max_error_m, {0, 0, dem.width - 1, dem.height - 1}, facts);
    insertion.run(&progress, nullptr, &window_segments);
    progress.endStage();
    WindowMesh window_mesh = insertion.mesh();
    TinMesh& mesh = result.mesh;
    mesh.vertices.reserve(window_mesh.pixels.size());
    for (const Pixel& p : window_mesh.pixels) mesh.vertices.push_back(gridPoint(dem, p));
    mesh.triangle_indices = std::move(window_mesh.triangle_indices);
    if (mesh.triangleCount() == 0) {
      throw Error(ErrorCode::Input, "no triangle can be built: the DEM has no three neighbouring "
                                    "valid pixels; expected a DEM with some contiguous data");
    }
    result.constrained_edges = std::move(window_mesh.constrained_edges);
    result.edges_dropped = window_mesh.constrained_edges_dropped;
    result.segments_bent = window_mesh.segments_bent;
    result.segments_bent_to_end = window_mesh.segments_bent_to_end;
    return result;
  }

  // Windowed: the shared border polylines first, then every window on its own (in parallel),
  // then an exact stitch by pixel position.
  // The windows' border lines: from the box's corner in a block, else from the grid's.
  const TinOptions::Box box = in_region ? options.region : TinOptions::Box{0, 0, dem.width - 1, dem.height - 1};
  std::vector<std::int32_t> xs = blockEdges(box.x1 - box.x0 + 1, options.block_pixels);
  std::vector<std::int32_t> ys = blockEdges(box.y1 - box.y0 + 1, options.block_pixels);
  for (std::int32_t& x : xs) x += box.x0;
  for (std::int32_t& y : ys) y += box.y0;
  const std::size_t nx = xs.size() - 1, ny = ys.size() - 1;
  // vertical[i][j]: column xs[i] between ys[j] and ys[j+1]; horizontal[j][i]: row ys[j]
  // between xs[i] and xs[i+1]. First the break line ends on them (which must be border
  // vertices of both windows), then the simplified runs that keep them.
  std::vector<std::vector<std::vector<Pixel>>> vertical(xs.size(), std::vector<std::vector<Pixel>>(ny));
  std::vector<std::vector<std::vector<Pixel>>> horizontal(ys.size(), std::vector<std::vector<Pixel>>(nx));
  // Break lines: split at the border lines, and each piece goes to the windows whose closed
  // box holds it (two when it runs along a border).
  std::vector<std::vector<WindowSegment>> window_segments(segments.empty() ? 0 : nx * ny);
  if (!segments.empty()) {
    const std::vector<WindowSegment> pieces = splitAtWindowBorders(dem, segments, xs, ys, result.edges_dropped);
    // The windows along one axis whose closed span [lines[k], lines[k + 1]] holds [low, high]:
    // one, or two for a piece on their common line.
    const auto spans = [](const std::vector<std::int32_t>& lines, std::int32_t low, std::int32_t high) {
      const auto windows = static_cast<std::int64_t>(lines.size()) - 1;
      const std::int64_t at = std::upper_bound(lines.begin(), lines.end(), low) - lines.begin() - 1;
      std::array<std::size_t, 2> range{1, 0};  // empty
      for (std::int64_t k = std::max<std::int64_t>(0, at - 1); k <= std::min(at, windows - 1); ++k) {
        if (lines[static_cast<std::size_t>(k)] > low || lines[static_cast<std::size_t>(k + 1)] < high) continue;
        if (range[0] > range[1]) range[0] = static_cast<std::size_t>(k);
        range[1] = static_cast<std::size_t>(k);
      }
      return range;
    };
    for (const WindowSegment& piece : pieces) {
      for (const Pixel p : {piece.from, piece.to}) {
        const auto column = std::lower_bound(xs.begin(), xs.end(), p.x);
        const auto row = std::lower_bound(ys.begin(), ys.end(), p.y);
        const bool on_column = column != xs.end() && *column == p.x, on_row = row != ys.end() && *row == p.y;
        if (on_column && on_row) continue;  // a window corner
        if (on_column) {
          const auto j = static_cast<std::size_t>(std::upper_bound(ys.begin(), ys.end(), p.y) - ys.begin()) - 1;
          vertical[static_cast<std::size_t>(column - xs.begin())][j].push_back(p);
        } else if (on_row) {
          const auto i = static_cast<std::size_t>(std::upper_bound(xs.begin(), xs.end(), p.x) - xs.begin()) - 1;
          horizontal[static_cast<std::size_t>(row - ys.begin())][i].push_back(p);
        }
      }
      const auto [i0, i1] = spans(xs, std::min(piece.from.x, piece.to.x), std::max(piece.from.x, piece.to.x));
      const auto [j0, j1] = spans(ys, std::min(piece.from.y, piece.to.y), std::max(piece.from.y, piece.to.y));
      for (std::size_t j = j0; j <= j1; ++j) {
        for (std::size_t i = i0; i <= i1; ++i) window_segments[j * nx + i].push_back(piece);
      }
    }
  }
  // On the globe, a window's triangles may miss a pixel of its fixed outline (the 1D test of
  // the outline cannot see a triangle's cross slope): such pixels join the outline and the
  // windows are built again. Rare; each round adds vertices, so it ends.
  std::vector<std::vector<std::vector<Pixel>>> forced_vertical = vertical, forced_horizontal = horizontal;
  // A block's shared sides never change: a pixel of one that a triangle misses makes the pixels
  // next to it on the inner side vertices of its window instead, more of them (along the side,
  // then deeper) each time it is missed again.
  std::vector<std::vector<Pixel>> window_seeds;
  std::map<std::pair<std::int32_t, std::int32_t>, std::int32_t> times_missed;
  const auto onSharedSide = [&](const Pixel& p, Pixel* inward) {
    const std::uint8_t sides = options.shared_sides;
    if ((sides & TinOptions::kWestSide) && p.x == box.x0) return *inward = {1, 0}, true;
    if ((sides & TinOptions::kEastSide) && p.x == box.x1) return *inward = {-1, 0}, true;
    if ((sides & TinOptions::kNorthSide) && p.y == box.y0) return *inward = {0, 1}, true;
    if ((sides & TinOptions::kSouthSide) && p.y == box.y1) return *inward = {0, -1}, true;
    return false;
  };
  const std::size_t split_dropped = result.edges_dropped;
  for (int round = 0;; ++round) {
    for (std::size_t i = 0; i < xs.size(); ++i) {
      for (std::size_t j = 0; j < ny; ++j) {
        const bool shared = (i == 0 && (options.shared_sides & TinOptions::kWestSide)) ||
                            (i + 1 == xs.size() && (options.shared_sides & TinOptions::kEastSide));
        vertical[i][j] = simplifyRun(dem, options.globe, {xs[i], ys[j]}, {xs[i], ys[j + 1]}, options.max_error_m,
                                     forced_vertical[i][j], shared);
      }
    }
    for (std::size_t j = 0; j < ys.size(); ++j) {
      for (std::size_t i = 0; i < nx; ++i) {
        const bool shared = (j == 0 && (options.shared_sides & TinOptions::kNorthSide)) ||
                            (j + 1 == ys.size() && (options.shared_sides & TinOptions::kSouthSide));
        horizontal[j][i] = simplifyRun(dem, options.globe, {xs[i], ys[j]}, {xs[i + 1], ys[j]}, options.max_error_m,
                                       forced_horizontal[j][i], shared);
      }
    }
    result.mesh = {};
    result.constrained_edges.clear();
    result.edges_dropped = split_dropped;
    result.segments_bent = result.segments_bent_to_end = 0;
    std::vector<Pixel> violations = buildWindows(dem, options, facts, xs, ys, vertical, horizontal, window_segments,
                                                 window_seeds, round == 0 ? &progress : nullptr, result);
    if (violations.empty()) break;
    if (round >= 16 && std::all_of(violations.begin(), violations.end(), [&](const Pixel& p) {
          Pixel inward;
          return onSharedSide(p, &inward);
        })) {
      result.shared_outline_misses = violations.size();  // left as they are, and said
      break;
    }
    if (round >= 16) {
      throw Error(ErrorCode::Internal, "TIN: window outlines still miss " + std::to_string(violations.size()) +
                                           " pixels by more than the bound after 16 rounds, the first at pixel (" +
                                           std::to_string(dem.col_offset + violations.front().x) + ", " +
                                           std::to_string(dem.row_offset + violations.front().y) + ")");
    }
    progress.note("TIN: " + std::to_string(violations.size()) +
                  " window outline pixels added where a triangle as drawn missed them; building again");
    for (const Pixel& p : violations) {
      Pixel inward;
      if (onSharedSide(p, &inward)) {
        // The window holding the pixels next to p on the inner side; depth d and spread k grow
        // with the times p was missed (1: the neighbour; 2: and its two neighbours along the
        // side; 3: two pixels deep; ...).
        const std::int32_t missed = ++times_missed[{p.x, p.y}];
        const std::int32_t depth = 1 + (missed - 1) / 2, spread = missed > 1 ? 1 : 0;
        if (window_seeds.empty()) window_seeds.resize(nx * ny);
        for (std::int32_t k = -spread; k <= spread; ++k) {
          const Pixel seed{p.x + inward.x * depth + (inward.x == 0 ? k : 0), p.y + inward.y * depth + (inward.y == 0 ? k : 0)};
          const auto i = static_cast<std::size_t>(std::upper_bound(xs.begin(), xs.end(), seed.x) - xs.begin()) - 1;
          const auto j = static_cast<std::size_t>(std::upper_bound(ys.begin(), ys.end(), seed.y) - ys.begin()) - 1;
          // Strictly inside a window and on data (a seed on a window border line is not
          // needed: the 1D choice of that line measures it).
          if (i >= nx || j >= ny || seed.x <= xs[i] || seed.x >= xs[i + 1] || seed.y <= ys[j] || seed.y >= ys[j + 1] ||
              !dem.isValid(seed.x, seed.y)) {
            continue;
          }
          window_seeds[j * nx + i].push_back(seed);
        }
        continue;
      }
      const auto column = std::lower_bound(xs.begin(), xs.end(), p.x);
      const auto row = std::lower_bound(ys.begin(), ys.end(), p.y);
      if (column != xs.end() && *column == p.x) {
        const auto j = static_cast<std::size_t>(std::upper_bound(ys.begin(), ys.end(), p.y) - ys.begin()) - 1;
        forced_vertical[static_cast<std::size_t>(column - xs.begin())][std::min(j, ny - 1)].push_back(p);
      } else if (row != ys.end() && *row == p.y) {
        const auto i = static_cast<std::size_t>(std::upper_bound(xs.begin(), xs.end(), p.x) - xs.begin()) - 1;
        forced_horizontal[static_cast<std::size_t>(row - ys.begin())][std::min(i, nx - 1)].push_back(p);
      }
    }
  }
  result.shared_outline_repairs = times_missed.size();
  TinMesh& mesh = result.mesh;
  if (mesh.triangleCount() == 0 && !in_region) {  // a block may lie over nodata only
    throw Error(ErrorCode::Input, "no triangle can be built: the DEM has no three neighbouring "
                                  "valid pixels; expected a DEM with some contiguous data");
  }
  // A piece along a window border is an edge of both windows.
  std::sort(result.constrained_edges.begin(), result.constrained_edges.end());
  result.constrained_edges.erase(std::unique(result.constrained_edges.begin(), result.constrained_edges.end()),
                                 result.constrained_edges.end());
  return result;
}

}  // namespace terratiles
