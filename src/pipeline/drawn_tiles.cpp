#include "src/pipeline/drawn_tiles.h"

#include <GeographicLib/Geocentric.hpp>

#include <algorithm>
#include <atomic>
#include <numbers>

namespace terratiles {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kPoleDeg = 90 - 1e-9;

// Lowers (or raises) `slot` to `value` unless it already holds a lower (higher) one.
template <typename Better>
void atomicImprove(float& slot, float value, Better better) {
  std::atomic_ref<float> ref(slot);
  float current = ref.load(std::memory_order_relaxed);
  while ((std::isnan(current) || better(value, current)) &&
         !ref.compare_exchange_weak(current, value, std::memory_order_relaxed)) {
  }
}

struct Geodetic {
  double lat_deg, lon_deg, h_m;
};

Geodetic geodeticOf(double x, double y, double z) {
  Geodetic g{};
  GeographicLib::Geocentric::WGS84().Reverse(x, y, z, g.lat_deg, g.lon_deg, g.h_m);
  return g;
}

}  // namespace

void ZoomSurface::include(std::size_t pixel, double offset_m) {
  float low = static_cast<float>(offset_m), high = low;
  if (low > offset_m) low = std::nextafter(low, -std::numeric_limits<float>::infinity());
  if (high < offset_m) high = std::nextafter(high, std::numeric_limits<float>::infinity());
  atomicImprove(low_[pixel], low, [](float a, float b) { return a < b; });
  atomicImprove(high_[pixel], high, [](float a, float b) { return a > b; });
}

DrawnTileMeasure measureDrawnTile(const DemOnGlobe& globe, std::span<const EcefPoint> vertices,
                                  std::span<const GridCorner> grid, std::span<const std::uint32_t> indices,
                                  double shift_m, const ZoomSurface* finer, ZoomSurface* surface,
                                  std::vector<std::uint32_t>* met) {
  DrawnTileMeasure measure;
  const DemGrid& dem = globe.dem();
  for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
    const DrawnTriangle triangle(vertices[indices[t]], vertices[indices[t + 1]], vertices[indices[t + 2]]);
    if (triangle.degenerate()) continue;
    const PixelBox box =
        candidatePixels(globe, {grid[indices[t]], grid[indices[t + 1]], grid[indices[t + 2]]}, triangle.longestEdge(), shift_m);
    forEachPixelMeeting(globe, triangle, box, [&](std::size_t pixel, double offset_m) {
      if (std::isnan(dem.heights_m[pixel])) return;
      const double error = std::fabs(offset_m);
      measure.max_error_m = std::max(measure.max_error_m, error);
      ++measure.hits;
      if (finer && finer->drawn(pixel)) {
        ++measure.finer_hits;
        measure.finer_difference_m = std::max(measure.finer_difference_m, finer->differenceTo(pixel, offset_m));
      }
      if (surface) surface->include(pixel, offset_m);
      if (met) met->push_back(static_cast<std::uint32_t>(pixel));
    });
  }
  return measure;
}

Region drawnRegion(std::span<const EcefPoint> vertices, std::span<const std::uint32_t> indices) {
  Region region;
  std::vector<Geodetic> geodetic(vertices.size());
  std::vector<std::uint8_t> used(vertices.size(), 0);
  for (const std::uint32_t v : indices) used[v] = 1;
  bool all_longitudes = false;
  const auto geocentric = [](double x, double y, double z) { return std::atan2(z, std::hypot(x, y)); };
  // Per vertex, its geocentric latitude (radians): what every triangle round it takes.
  std::vector<double> geocentric_lat(vertices.size(), 0.0);
  // Vertices; one at a pole adds no longitude (it has none).
  std::vector<std::size_t> poles;
  for (std::size_t v = 0; v < vertices.size(); ++v) {
    if (!used[v]) continue;
    geodetic[v] = geodeticOf(vertices[v].x, vertices[v].y, vertices[v].z);
    geocentric_lat[v] = geocentric(vertices[v].x, vertices[v].y, vertices[v].z);
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
  for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
    const EcefPoint& a = vertices[indices[t]];
    const EcefPoint& b = vertices[indices[t + 1]];
    const EcefPoint& c = vertices[indices[t + 2]];
    const DrawnTriangle triangle(a, b, c);
    if (triangle.degenerate()) continue;
    const double edge_m = triangle.longestEdge();
    // The lowest point: the height is a convex function on the triangle (a signed distance to
    // a convex body), curved by at most 1 / kRadius_m, so on a lattice of n x n
    // sub-triangles of side s it is at least the lowest lattice point minus s^2 / (6 R).
    const int n = std::clamp(static_cast<int>(std::ceil(edge_m / 10e3)), 1, 64);
    const double side_m = edge_m / n;
    double lowest = std::min({geodetic[indices[t]].h_m, geodetic[indices[t + 1]].h_m, geodetic[indices[t + 2]].h_m});
    for (int i = 0; i <= n && n > 1; ++i) {
      for (int j = 0; i + j <= n; ++j) {
        if ((i == 0 && j == 0) || (i == n) || (j == n)) continue;  // the corners are known
        const double u = static_cast<double>(i) / n, w = static_cast<double>(j) / n;
        const EcefPoint& o = triangle.a;  // the triangle's own first corner: the same bits in build and check
        const Geodetic g = geodeticOf(o.x + u * triangle.ab[0] + w * triangle.ac[0], o.y + u * triangle.ab[1] + w * triangle.ac[1],
                                      o.z + u * triangle.ab[2] + w * triangle.ac[2]);
        lowest = std::min(lowest, g.h_m);
      }
    }
    low = std::min(low, lowest - side_m * side_m / (6 * kRadius_m));
    // The pole, when the axis pierces the triangle: every longitude.
    for (const double direction : {1.0, -1.0}) {
      double offset = 0;
      if (triangle.meets(EcefPoint{0, 0, 0}, std::array<double, 3>{0, 0, direction}, &offset) && offset > 0) {
        all_longitudes = true;
        (direction > 0 ? north : south) = direction * std::numbers::pi / 2;
      }
    }
    // Latitudes: the geocentric latitude on a flat triangle not pierced by the polar axis is
    // extreme on its edges, where the extreme of z / |X| on A + mu (B - A) is at the mu that
    // zeroes its derivative (a linear equation); the geodetic latitude of a point is
    // atan(tan(geocentric) * F) with F = (N + h) / (N (1 - e^2) + h), which grows with |tan|
    // and shrinks with h and (for h above 0) with N: so the extremes over the triangle are
    // bounded by its geocentric extremes with F at its lowest height (for the latitude away
    // from the equator) or its highest (towards it), N at either end of its range.
    double lowest_c = 1e300, highest_c = -1e300;  // geocentric latitude, radians
    for (std::size_t k = 0; k < 3; ++k) {
      const double lat = geocentric_lat[indices[t + k]];
      lowest_c = std::min(lowest_c, lat);
      highest_c = std::max(highest_c, lat);
    }
    const EcefPoint corner[3] = {a, b, c};
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
      const double lat = geocentric(p.x + mu * d[0], p.y + mu * d[1], p.z + mu * d[2]);
      lowest_c = std::min(lowest_c, lat);
      highest_c = std::max(highest_c, lat);
    }
    const double highest_h =
        std::max({geodetic[indices[t]].h_m, geodetic[indices[t + 1]].h_m, geodetic[indices[t + 2]].h_m});
    const double lowest_h = lowest - side_m * side_m / (6 * kRadius_m);
    // N runs from a (equator) to a / sqrt(1 - e^2) (poles).
    const auto& earth = GeographicLib::Geocentric::WGS84();
    const double semi_major = earth.EquatorialRadius(), e2 = earth.Flattening() * (2 - earth.Flattening());
    const auto factor = [e2](double radius, double h) { return (radius + h) / (radius * (1 - e2) + h); };
    const double polar_n = semi_major / std::sqrt(1 - e2);
    const double f_low_h = std::max(factor(semi_major, lowest_h), factor(polar_n, lowest_h));
    const double f_high_h = std::min(factor(semi_major, highest_h), factor(polar_n, highest_h));
    const auto geodeticBound = [&](double lat_c, bool poleward) {
      return std::atan(std::tan(lat_c) * (poleward ? f_low_h : f_high_h));
    };
    north = std::max(north, geodeticBound(highest_c, highest_c >= 0));
    south = std::min(south, geodeticBound(lowest_c, lowest_c <= 0));
  }
  if (region.empty && !all_longitudes) {
    // Only pole vertices: a degenerate content; take the whole circle.
    all_longitudes = true;
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
