#pragma once
// Four neighbouring pixels of a row on the globe at once (AVX2), from either form DemOnGlobe
// keeps them in: with the same operations as DemOnGlobe::point and DemOnGlobe::up, so each
// lane is those bit for bit (no fused multiply-add: AVX2 alone has none).

#if defined(__x86_64__)
#include <immintrin.h>

#include <cstddef>
#include <cstdint>

#include "src/geo/dem_on_globe.h"

namespace terratiles {

struct PixelLanes {
  __m256d x, y, z;     // DEM points, ECEF
  __m256d ux, uy, uz;  // verticals
};

// Pixels (col .. col + 3, row); i = DemGrid::index(col, row). Lanes past the row's end read
// the next pixels of the arrays (padded past the raster's end by kDemOnGlobePadding): their
// values are finite and never meant.
__attribute__((target("avx2"))) inline PixelLanes pixelLanes(const DemOnGlobe& globe, std::int32_t col,
                                                             std::int32_t row, std::size_t i) {
  const DemOnGlobe::Factors* factors = globe.factors();
  if (!factors) {
    return {_mm256_loadu_pd(globe.pointX() + i), _mm256_loadu_pd(globe.pointY() + i),
            _mm256_loadu_pd(globe.pointZ() + i), _mm256_loadu_pd(globe.upX() + i),
            _mm256_loadu_pd(globe.upY() + i),    _mm256_loadu_pd(globe.upZ() + i)};
  }
  const DemOnGlobe::RowFactors& r = factors->rows[static_cast<std::size_t>(row)];
  const std::size_t c = static_cast<std::size_t>(col);
  const __m256d h = _mm256_loadu_pd(factors->height.data() + i);
  const __m256d across = _mm256_mul_pd(_mm256_add_pd(_mm256_set1_pd(r.n), h), _mm256_set1_pd(r.cphi));
  const __m256d cos_lat = _mm256_set1_pd(r.cos_lat);
  return {_mm256_mul_pd(across, _mm256_loadu_pd(factors->clam.data() + c)),
          _mm256_mul_pd(across, _mm256_loadu_pd(factors->slam.data() + c)),
          _mm256_mul_pd(_mm256_add_pd(_mm256_set1_pd(r.e2m_n), h), _mm256_set1_pd(r.sphi)),
          _mm256_mul_pd(cos_lat, _mm256_loadu_pd(factors->cos_lon.data() + c)),
          _mm256_mul_pd(cos_lat, _mm256_loadu_pd(factors->sin_lon.data() + c)),
          _mm256_set1_pd(r.sin_lat)};
}

}  // namespace terratiles
#endif
