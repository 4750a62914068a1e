#include "src/geo/swiss_lv95.h"

#include <GeographicLib/Geocentric.hpp>
#include <GeographicLib/Math.hpp>

#include <cmath>
#include <numbers>

#include "src/base/error.h"

namespace terratiles {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDegToRad = kPi / 180.0;

// Bessel 1841 and the projection centre (Bern, old observatory).
constexpr double kBesselA_m = 6377397.155;
constexpr double kBesselInverseFlattening = 299.1528128;
constexpr double kCentreLatDeg = 46.0 + 57.0 / 60.0 + 8.66 / 3600.0;
constexpr double kCentreLonDeg = 7.0 + 26.0 / 60.0 + 22.50 / 3600.0;
constexpr double kFalseEasting_m = 2600000.0;
constexpr double kFalseNorthing_m = 1200000.0;
// CH1903+ -> ETRS89/WGS84 geocentric translation (EPSG:1676, swisstopo).
constexpr double kShiftX_m = 674.374;
constexpr double kShiftY_m = 15.056;
constexpr double kShiftZ_m = 405.346;

// Constants of the Gauss sphere, derived once (swisstopo formulas, section "rigorous").
struct SwissProjection {
  double e = 0;       // first eccentricity of Bessel
  double radius = 0;  // R: radius of the projection sphere
  double alpha = 0;   // ratio of longitudes sphere/ellipsoid
  double b0 = 0;      // latitude of the centre on the sphere
  double k = 0;       // integration constant of the latitude mapping
  double sin_b0 = 0, cos_b0 = 0;
  double lon0 = 0;    // centre longitude, radians

  SwissProjection() {
    const double f = 1.0 / kBesselInverseFlattening;
    const double e2 = f * (2 - f);
    e = std::sqrt(e2);
    const double phi0 = kCentreLatDeg * kDegToRad;
    const double sin_phi0 = std::sin(phi0);
    radius = kBesselA_m * std::sqrt(1 - e2) / (1 - e2 * sin_phi0 * sin_phi0);
    alpha = std::sqrt(1 + e2 / (1 - e2) * std::pow(std::cos(phi0), 4));
    b0 = std::asin(sin_phi0 / alpha);
    k = std::log(std::tan(kPi / 4 + b0 / 2)) - alpha * std::log(std::tan(kPi / 4 + phi0 / 2)) +
        alpha * e / 2 * std::log((1 + e * sin_phi0) / (1 - e * sin_phi0));
    sin_b0 = std::sin(b0);
    cos_b0 = std::cos(b0);
    lon0 = kCentreLonDeg * kDegToRad;
  }

  // (E, N) -> Bessel (lat, lon) in radians. The swisstopo formulas, with the latitude
  // iteration replaced by its closed equivalent: the sphere's latitude b gives the
  // ellipsoid's isometric latitude psi = (atanh(sin b) - K) / alpha, and tan(lat) follows
  // from the conformal latitude sinh(psi) by GeographicLib's Math::tauf (Karney 2011), which
  // converges to full precision in two Newton steps instead of ~6 fixed-point iterations.
  void inverse(double easting, double northing, double& lat, double& lon) const {
    const double t = (northing - kFalseNorthing_m) / radius;
    const double exp_t = std::exp(t);
    const double sinh_t = 0.5 * (exp_t - 1 / exp_t), cosh_t = 0.5 * (exp_t + 1 / exp_t);
    // b_bar = 2 (atan(exp t) - pi/4), the Gudermannian of t: sin = tanh t, cos = 1 / cosh t,
    // tan = sinh t.
    const double sin_b_bar = sinh_t / cosh_t, cos_b_bar = 1 / cosh_t, tan_b_bar = sinh_t;
    const double l_bar = (easting - kFalseEasting_m) / radius;
    const double sin_l_bar = std::sin(l_bar), cos_l_bar = std::cos(l_bar);
    const double sin_b = cos_b0 * sin_b_bar + sin_b0 * cos_b_bar * cos_l_bar;
    const double l = std::atan(sin_l_bar / (cos_b0 * cos_l_bar - sin_b0 * tan_b_bar));
    lon = lon0 + l / alpha;
    const double psi = (std::atanh(sin_b) - k) / alpha;
    lat = std::atan(GeographicLib::Math::tauf(std::sinh(psi), e));
  }

  // Bessel (lat, lon) in radians -> (E, N).
  void forward(double lat, double lon, double& easting, double& northing) const {
    const double sin_phi = std::sin(lat);
    const double s = alpha * std::log(std::tan(kPi / 4 + lat / 2)) -
                     alpha * e / 2 * std::log((1 + e * sin_phi) / (1 - e * sin_phi)) + k;
    const double b = 2 * (std::atan(std::exp(s)) - kPi / 4);
    const double l = alpha * (lon - lon0);
    const double l_bar = std::atan(std::sin(l) / (sin_b0 * std::tan(b) + cos_b0 * std::cos(l)));
    const double b_bar = std::asin(cos_b0 * std::sin(b) - sin_b0 * std::cos(b) * std::cos(l));
    easting = kFalseEasting_m + radius * l_bar;
    northing = kFalseNorthing_m + radius / 2 * std::log((1 + std::sin(b_bar)) / (1 - std::sin(b_bar)));
  }
};

const SwissProjection& swissProjection() {
  static const SwissProjection projection;
  return projection;
}

const GeographicLib::Geocentric& bessel() {
  static const GeographicLib::Geocentric ellipsoid(kBesselA_m, 1.0 / kBesselInverseFlattening);
  return ellipsoid;
}

}  // namespace

void lv95ToWgs84(std::span<const CrsPoint> lv95, std::span<GeodeticPoint> inout) {
  TERRATILES_ASSERT(lv95.size() == inout.size());
  const SwissProjection& projection = swissProjection();
  const GeographicLib::Geocentric& bessel_ellipsoid = bessel();
  const GeographicLib::Geocentric& wgs84 = GeographicLib::Geocentric::WGS84();
  for (std::size_t i = 0; i < lv95.size(); ++i) {
    double lat_rad, lon_rad;
    projection.inverse(lv95[i].x, lv95[i].y, lat_rad, lon_rad);
    double x, y, z;
    bessel_ellipsoid.Forward(lat_rad / kDegToRad, lon_rad / kDegToRad, inout[i].height_m, x, y, z);
    double lat_deg, lon_deg, h_m;
    wgs84.Reverse(x + kShiftX_m, y + kShiftY_m, z + kShiftZ_m, lat_deg, lon_deg, h_m);
    inout[i].lat_deg = lat_deg;
    inout[i].lon_deg = lon_deg;
  }
}

void wgs84ToLv95(std::span<const GeodeticPoint> wgs84_points, std::span<CrsPoint> lv95) {
  TERRATILES_ASSERT(wgs84_points.size() == lv95.size());
  const SwissProjection& projection = swissProjection();
  const GeographicLib::Geocentric& bessel_ellipsoid = bessel();
  const GeographicLib::Geocentric& wgs84 = GeographicLib::Geocentric::WGS84();
  for (std::size_t i = 0; i < lv95.size(); ++i) {
    const GeodeticPoint& p = wgs84_points[i];
    double x, y, z;
    wgs84.Forward(p.lat_deg, p.lon_deg, p.height_m, x, y, z);
    double lat_deg, lon_deg, h_m;
    bessel_ellipsoid.Reverse(x - kShiftX_m, y - kShiftY_m, z - kShiftZ_m, lat_deg, lon_deg, h_m);
    projection.forward(lat_deg * kDegToRad, lon_deg * kDegToRad, lv95[i].x, lv95[i].y);
  }
}

}  // namespace terratiles
