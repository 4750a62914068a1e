#include "src/geo/geoid.h"

#include <algorithm>
#include <cmath>

namespace terratiles {

std::optional<double> GeoidGrid::undulationAt(double lon_deg, double lat_deg) const {
  // A latitude past a pole names the point on the other side of it (geodeticToEcef puts it
  // there): the centre of a DEM overview's last row, whose pixels run half a pixel past a pole.
  if (std::abs(lat_deg) > 90.0 && std::abs(lat_deg) <= 180.0) {
    lat_deg = std::copysign(180.0, lat_deg) - lat_deg;
    lon_deg += lon_deg < 0 ? 180.0 : -180.0;
  }
  double x = (lon_deg - first_lon_deg) / step_deg;
  const double y = (first_lat_deg - lat_deg) / step_lat_deg;
  if (wraps_longitude) {
    x = std::fmod(x, static_cast<double>(width));
    if (x < 0) x += width;
  }
  constexpr double kEdge = 1e-9;  // points on the last node row or column are inside
  if (x < -kEdge || y < -kEdge || x > width - 1 + kEdge + (wraps_longitude ? 1 : 0) ||
      y > height - 1 + kEdge) {
    return std::nullopt;
  }
  auto column = [&](std::int64_t c) {
    return wraps_longitude ? static_cast<std::int32_t>(((c % width) + width) % width)
                           : static_cast<std::int32_t>(std::clamp<std::int64_t>(c, 0, width - 1));
  };
  const std::int64_t c0 = static_cast<std::int64_t>(std::floor(x));
  const std::int32_t r0 = std::clamp(static_cast<std::int32_t>(std::floor(y)), 0, height - 1);
  const std::int32_t r1 = std::min(r0 + 1, height - 1);
  const double fx = x - static_cast<double>(c0);
  const double fy = y - r0;
  const std::int32_t ca = column(c0), cb = column(c0 + 1);
  const double v00 = undulation_m[static_cast<std::size_t>(r0) * width + ca];
  const double v01 = undulation_m[static_cast<std::size_t>(r0) * width + cb];
  const double v10 = undulation_m[static_cast<std::size_t>(r1) * width + ca];
  const double v11 = undulation_m[static_cast<std::size_t>(r1) * width + cb];
  const double value = (1 - fy) * ((1 - fx) * v00 + fx * v01) + fy * ((1 - fx) * v10 + fx * v11);
  if (std::isnan(value)) return std::nullopt;
  return value;
}

}  // namespace terratiles
