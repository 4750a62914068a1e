#include <doctest/doctest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "src/base/error.h"
#include "src/tiling/tile_scheme.h"

using namespace terratiles;

namespace {

constexpr double kPi = std::numbers::pi;
constexpr TileSchemeKind kWebSchemes[] = {TileSchemeKind::WebMercator, TileSchemeKind::Geographic};
constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Expected values, computed here from the published formulas rather than with the code under
// test: OSM slippy-map tiles for EPSG:3857 and 180/2^z degree squares for WorldCRS84Quad.
double expectedLonEdgeDeg(std::int64_t x, std::int64_t columns) {
  return -180.0 + static_cast<double>(x) * (360.0 / static_cast<double>(columns));
}
double expectedWebMercatorLatEdgeDeg(std::int64_t y, int zoom) {
  const double n = std::pow(2.0, zoom);
  return std::atan(std::sinh(kPi * (1.0 - 2.0 * static_cast<double>(y) / n))) * 180.0 / kPi;
}
double expectedGeographicLatEdgeDeg(std::int64_t y, int zoom) {
  return 90.0 - static_cast<double>(y) * (180.0 / std::pow(2.0, zoom));
}

bool sameBits(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

// Grid corners, centre tiles and random tiles (fixed seed) of a grid.
std::vector<TileKey> sampleTiles(std::int64_t columns, std::int64_t rows, int zoom) {
  const auto key = [zoom](std::int64_t x, std::int64_t y) {
    return TileKey{zoom, static_cast<std::int32_t>(x), static_cast<std::int32_t>(y)};
  };
  std::vector<TileKey> keys = {key(0, 0),           key(columns - 1, 0),
                               key(0, rows - 1),    key(columns - 1, rows - 1),
                               key(columns / 2, rows / 2),
                               key((columns - 1) / 2, (rows - 1) / 2)};
  std::mt19937_64 random(20240601u + static_cast<unsigned>(zoom));
  for (int i = 0; i < 24; ++i) {
    keys.push_back(key(static_cast<std::int64_t>(random() % static_cast<std::uint64_t>(columns)),
                       static_cast<std::int64_t>(random() % static_cast<std::uint64_t>(rows))));
  }
  return keys;
}

std::vector<TileKey> sampleTiles(TileSchemeKind kind, int zoom) {
  const TileGridSize grid = tileGridSize(kind, zoom);
  return sampleTiles(grid.columns, grid.rows, zoom);
}

template <class F>
std::optional<Error> thrownError(F&& f) {
  try {
    f();
  } catch (const Error& error) {
    return error;
  }
  return std::nullopt;
}

void checkError(const std::optional<Error>& error, ErrorCode code, const std::string& message) {
  REQUIRE(error.has_value());
  CHECK(error->code() == code);
  CHECK(std::string(error->what()) == message);
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// The tiles a box shares area with (or holds its point), by testing every tile of the grid.
std::vector<TileKey> bruteForceTiles(TileSchemeKind kind, double west_deg, double south_deg,
                                     double east_deg, double north_deg, int zoom) {
  std::vector<std::pair<double, double>> lon_ranges;
  if (east_deg >= west_deg) {
    lon_ranges = {{west_deg, east_deg}};
  } else {
    lon_ranges = {{west_deg, 180.0}, {-180.0, east_deg}};
  }
  const TileGridSize grid = tileGridSize(kind, zoom);
  std::vector<TileKey> keys;
  for (std::int32_t y = 0; y < grid.rows; ++y) {
    for (std::int32_t x = 0; x < grid.columns; ++x) {
      const TileBounds b = tileBoundsDeg(kind, {zoom, x, y});
      const bool rows_overlap = std::min(north_deg, b.north) > std::max(south_deg, b.south);
      bool columns_overlap = false;
      for (const auto& [w, e] : lon_ranges) {
        columns_overlap |= std::min(e, b.east) > std::max(w, b.west);
      }
      if (rows_overlap && columns_overlap) keys.push_back({zoom, x, y});
    }
  }
  return keys;
}

}  // namespace

TEST_SUITE("tiling") {
  TEST_CASE("tile scheme names parse and format both ways") {
    for (TileSchemeKind kind :
         {TileSchemeKind::WebMercator, TileSchemeKind::Geographic, TileSchemeKind::Local}) {
      CHECK(parseTileSchemeKind(tileSchemeName(kind)) == kind);
    }
    CHECK(parseTileSchemeKind("webmercator") == TileSchemeKind::WebMercator);
    CHECK(parseTileSchemeKind("geographic") == TileSchemeKind::Geographic);
    CHECK(parseTileSchemeKind("local") == TileSchemeKind::Local);
  }

  TEST_CASE("an unknown tile scheme name is a usage error naming the accepted names") {
    checkError(thrownError([] { parseTileSchemeKind("WebMercator"); }), ErrorCode::Usage,
               "unknown tile scheme 'WebMercator'; expected webmercator, geographic or local");
    checkError(thrownError([] { parseTileSchemeKind(""); }), ErrorCode::Usage,
               "unknown tile scheme ''; expected webmercator, geographic or local");
  }

  TEST_CASE("tile grids have 2 to the zoom rows and geographic has twice the columns") {
    for (int zoom = 0; zoom <= kMaxTileZoom; ++zoom) {
      const std::int64_t n = std::int64_t{1} << zoom;
      CHECK(tileGridSize(TileSchemeKind::WebMercator, zoom).columns == n);
      CHECK(tileGridSize(TileSchemeKind::WebMercator, zoom).rows == n);
      CHECK(tileGridSize(TileSchemeKind::Geographic, zoom).columns == 2 * n);
      CHECK(tileGridSize(TileSchemeKind::Geographic, zoom).rows == n);
      CHECK(tileGridSize(TileSchemeKind::Local, zoom).columns == n);
      CHECK(tileGridSize(TileSchemeKind::Local, zoom).rows == n);
    }
  }

  TEST_CASE("the Web Mercator constants are atan of sinh of pi and pi times a") {
    CHECK(kWebMercatorMaxLatitudeDeg ==
          doctest::Approx(std::atan(std::sinh(kPi)) * 180.0 / kPi).epsilon(1e-15));
    CHECK(std::abs(kWebMercatorMaxLatitudeDeg - 85.0511287798) < 1e-10);
    CHECK(kWebMercatorHalfExtentM == doctest::Approx(kPi * 6378137.0).epsilon(1e-15));
    CHECK(kWebMercatorRadiusM == 6378137.0);
  }

  TEST_CASE("Web Mercator metres follow the spherical formulas and round trip") {
    const WebMercatorPoint origin = lonLatToWebMercator(0.0, 0.0);
    CHECK(origin.x_m == 0.0);
    CHECK(origin.y_m == doctest::Approx(0.0));
    const WebMercatorPoint corner = lonLatToWebMercator(180.0, kWebMercatorMaxLatitudeDeg);
    CHECK(corner.x_m == doctest::Approx(kWebMercatorHalfExtentM).epsilon(1e-14));
    CHECK(corner.y_m == doctest::Approx(kWebMercatorHalfExtentM).epsilon(1e-12));
    const WebMercatorPoint south_west = lonLatToWebMercator(-180.0, -kWebMercatorMaxLatitudeDeg);
    CHECK(south_west.x_m == doctest::Approx(-kWebMercatorHalfExtentM).epsilon(1e-14));
    CHECK(south_west.y_m == doctest::Approx(-kWebMercatorHalfExtentM).epsilon(1e-12));
    // Bern, against x = a lon, y = a ln(tan(pi/4 + lat/2)).
    const double lon_deg = 7.4474;
    const double lat_deg = 46.948;
    const WebMercatorPoint bern = lonLatToWebMercator(lon_deg, lat_deg);
    CHECK(bern.x_m == doctest::Approx(6378137.0 * lon_deg * kPi / 180.0).epsilon(1e-14));
    CHECK(bern.y_m ==
          doctest::Approx(6378137.0 * std::log(std::tan(kPi / 4 + lat_deg * kPi / 360.0)))
              .epsilon(1e-14));
    const LonLat back = webMercatorToLonLat(bern);
    CHECK(back.lon_deg == doctest::Approx(lon_deg).epsilon(1e-14));
    CHECK(back.lat_deg == doctest::Approx(lat_deg).epsilon(1e-13));
    checkError(thrownError([] { lonLatToWebMercator(10.0, 86.0); }), ErrorCode::Input,
               "Web Mercator (EPSG:3857): latitude 86 deg (at lon 10 deg) is beyond the Web "
               "Mercator limit of +-85.0511287798 deg; use the geographic tile scheme for polar "
               "data");
  }

  TEST_CASE("tile bounds match the closed form formulas at zooms 0 to 20") {
    for (int zoom = 0; zoom <= 20; ++zoom) {
      CAPTURE(zoom);
      const std::int64_t n = std::int64_t{1} << zoom;
      for (const TileKey& key : sampleTiles(TileSchemeKind::WebMercator, zoom)) {
        CAPTURE(key.path());
        const TileBounds b = tileBoundsDeg(TileSchemeKind::WebMercator, key);
        CHECK(b.west == expectedLonEdgeDeg(key.x, n));
        CHECK(b.east == expectedLonEdgeDeg(key.x + 1, n));
        CHECK(std::abs(b.north - expectedWebMercatorLatEdgeDeg(key.y, zoom)) < 1e-12);
        CHECK(std::abs(b.south - expectedWebMercatorLatEdgeDeg(key.y + 1, zoom)) < 1e-12);
        const TileBounds m = webMercatorTileBoundsM(key);
        const double size_m = 2.0 * kPi * 6378137.0 / static_cast<double>(n);
        CHECK(std::abs(m.west - (-kPi * 6378137.0 + key.x * size_m)) < 1e-7);
        CHECK(std::abs(m.east - (-kPi * 6378137.0 + (key.x + 1) * size_m)) < 1e-7);
        CHECK(std::abs(m.north - (kPi * 6378137.0 - key.y * size_m)) < 1e-7);
        CHECK(std::abs(m.south - (kPi * 6378137.0 - (key.y + 1) * size_m)) < 1e-7);
        // The metre bounds are the degree bounds projected.
        const WebMercatorPoint north_west = lonLatToWebMercator(b.west, b.north);
        CHECK(std::abs(north_west.x_m - m.west) < 1e-6);
        CHECK(std::abs(north_west.y_m - m.north) < 1e-6);
      }
      for (const TileKey& key : sampleTiles(TileSchemeKind::Geographic, zoom)) {
        CAPTURE(key.path());
        const TileBounds b = tileBoundsDeg(TileSchemeKind::Geographic, key);
        // Every geographic edge is an exact double.
        CHECK(b.west == expectedLonEdgeDeg(key.x, 2 * n));
        CHECK(b.east == expectedLonEdgeDeg(key.x + 1, 2 * n));
        CHECK(b.north == expectedGeographicLatEdgeDeg(key.y, zoom));
        CHECK(b.south == expectedGeographicLatEdgeDeg(key.y + 1, zoom));
        CHECK(b.east - b.west == 180.0 / static_cast<double>(n));
        CHECK(b.north - b.south == 180.0 / static_cast<double>(n));
      }
    }
  }

  TEST_CASE("the centre of a tile maps back to that tile at zooms 0 to 20") {
    for (TileSchemeKind kind : kWebSchemes) {
      for (int zoom = 0; zoom <= 20; ++zoom) {
        for (const TileKey& key : sampleTiles(kind, zoom)) {
          CAPTURE(key.path());
          const TileBounds b = tileBoundsDeg(kind, key);
          CHECK(tileAt(kind, (b.west + b.east) / 2, (b.south + b.north) / 2, zoom) == key);
        }
      }
    }
  }

  TEST_CASE("adjacent tiles share their edges bit for bit at zooms 0 to 20") {
    for (TileSchemeKind kind : kWebSchemes) {
      for (int zoom = 0; zoom <= 20; ++zoom) {
        const TileGridSize grid = tileGridSize(kind, zoom);
        for (const TileKey& key : sampleTiles(kind, zoom)) {
          CAPTURE(key.path());
          const TileBounds b = tileBoundsDeg(kind, key);
          if (key.x + 1 < grid.columns) {
            const TileKey east{zoom, key.x + 1, key.y};
            CHECK(sameBits(b.east, tileBoundsDeg(kind, east).west));
            if (kind == TileSchemeKind::WebMercator) {
              CHECK(sameBits(webMercatorTileBoundsM(key).east,
                             webMercatorTileBoundsM(east).west));
            }
          }
          if (key.y + 1 < grid.rows) {
            const TileKey south{zoom, key.x, key.y + 1};
            CHECK(sameBits(b.south, tileBoundsDeg(kind, south).north));
            if (kind == TileSchemeKind::WebMercator) {
              CHECK(sameBits(webMercatorTileBoundsM(key).south,
                             webMercatorTileBoundsM(south).north));
            }
          }
          // The four children tile the parent exactly.
          if (zoom < 20) {
            const TileBounds first = tileBoundsDeg(kind, {zoom + 1, 2 * key.x, 2 * key.y});
            const TileBounds last = tileBoundsDeg(kind, {zoom + 1, 2 * key.x + 1, 2 * key.y + 1});
            CHECK(sameBits(first.west, b.west));
            CHECK(sameBits(first.north, b.north));
            CHECK(sameBits(last.east, b.east));
            CHECK(sameBits(last.south, b.south));
          }
        }
      }
    }
  }

  TEST_CASE("a point on a shared edge belongs to the tile to the east and south") {
    for (TileSchemeKind kind : kWebSchemes) {
      for (int zoom = 0; zoom <= 20; ++zoom) {
        const TileGridSize grid = tileGridSize(kind, zoom);
        for (const TileKey& key : sampleTiles(kind, zoom)) {
          CAPTURE(key.path());
          const TileBounds b = tileBoundsDeg(kind, key);
          const double lon_deg = (b.west + b.east) / 2;
          const double lat_deg = (b.south + b.north) / 2;
          const TileKey east{zoom, static_cast<std::int32_t>((key.x + 1) % grid.columns), key.y};
          const TileKey south{zoom, key.x, key.y + 1 < grid.rows ? key.y + 1 : key.y};
          CHECK(tileAt(kind, b.west, lat_deg, zoom) == key);
          CHECK(tileAt(kind, b.east, lat_deg, zoom) == east);  // the last column wraps to x 0
          CHECK(tileAt(kind, std::nextafter(b.east, -kInfinity), lat_deg, zoom) == key);
          CHECK(tileAt(kind, lon_deg, b.north, zoom) == key);
          CHECK(tileAt(kind, lon_deg, b.south, zoom) == south);  // the last row keeps its edge
          CHECK(tileAt(kind, lon_deg, std::nextafter(b.south, kInfinity), zoom) == key);
          CHECK(tileAt(kind, b.west, b.north, zoom) == key);
        }
      }
    }
  }

  TEST_CASE("known tiles have the published bounds") {
    // Web Mercator zoom 1 tile 0/0 is the north-west quarter.
    const TileBounds nw = tileBoundsDeg(TileSchemeKind::WebMercator, {1, 0, 0});
    CHECK(nw.west == -180.0);
    CHECK(nw.east == 0.0);
    CHECK(nw.south == 0.0);
    CHECK(std::abs(nw.north - 85.0511287798) < 1e-10);
    const TileBounds root_m = webMercatorTileBoundsM({0, 0, 0});
    CHECK(root_m.west == -20037508.342789244);
    CHECK(root_m.east == 20037508.342789244);
    CHECK(root_m.north == 20037508.342789244);
    // Bern is OSM tile 10/533/360.
    CHECK(tileAt(TileSchemeKind::WebMercator, 7.4474, 46.948, 10) == TileKey{10, 533, 360});
    // Geographic zoom 0: x 0 is the western hemisphere and x 1 the eastern one.
    const TileBounds west = tileBoundsDeg(TileSchemeKind::Geographic, {0, 0, 0});
    const TileBounds east = tileBoundsDeg(TileSchemeKind::Geographic, {0, 1, 0});
    CHECK((west.west == -180.0 && west.east == 0.0 && west.south == -90.0 && west.north == 90.0));
    CHECK((east.west == 0.0 && east.east == 180.0 && east.south == -90.0 && east.north == 90.0));
    CHECK(tileAt(TileSchemeKind::Geographic, -10.0, 45.0, 0) == TileKey{0, 0, 0});
    CHECK(tileAt(TileSchemeKind::Geographic, 10.0, -45.0, 0) == TileKey{0, 1, 0});
    CHECK(tileAt(TileSchemeKind::Geographic, 0.0, 0.0, 0) == TileKey{0, 1, 0});
    // Bern at geographic zoom 1: 90 deg squares, the third column of the northern row.
    CHECK(tileAt(TileSchemeKind::Geographic, 7.4474, 46.948, 1) == TileKey{1, 2, 0});
  }

  TEST_CASE("longitudes 180 and -180 are in the first column and wrap exactly") {
    for (TileSchemeKind kind : kWebSchemes) {
      for (int zoom = 0; zoom <= 20; ++zoom) {
        const TileGridSize grid = tileGridSize(kind, zoom);
        const std::int32_t last = static_cast<std::int32_t>(grid.columns - 1);
        CHECK(tileAt(kind, 180.0, 10.0, zoom).x == 0);
        CHECK(tileAt(kind, -180.0, 10.0, zoom).x == 0);
        CHECK(tileAt(kind, 540.0, 10.0, zoom).x == 0);
        CHECK(tileAt(kind, 179.9999999, 10.0, zoom).x == last);
        CHECK(tileAt(kind, -180.0000001, 10.0, zoom).x == last);
        CHECK(tileAt(kind, 190.0, 10.0, zoom) == tileAt(kind, -170.0, 10.0, zoom));
        CHECK(tileAt(kind, -190.0, 10.0, zoom) == tileAt(kind, 170.0, 10.0, zoom));
      }
    }
    CHECK(normalizeLongitudeDeg(180.0) == -180.0);
    CHECK(normalizeLongitudeDeg(-180.0) == -180.0);
    CHECK(normalizeLongitudeDeg(360.0) == 0.0);
    CHECK(normalizeLongitudeDeg(-540.0) == -180.0);
    CHECK(normalizeLongitudeDeg(190.25) == -169.75);
    CHECK(normalizeLongitudeDeg(-190.25) == 169.75);
    CHECK(normalizeLongitudeDeg(179.9999999) == 179.9999999);
    CHECK(normalizeLongitudeDeg(std::nextafter(-180.0, -kInfinity)) ==
          std::nextafter(180.0, -kInfinity));
  }

  TEST_CASE("Web Mercator accepts latitudes up to the limit and rejects beyond it with the fix") {
    for (int zoom = 0; zoom <= 20; ++zoom) {
      const std::int32_t last = (std::int32_t{1} << zoom) - 1;
      CHECK(tileAt(TileSchemeKind::WebMercator, 0.0, kWebMercatorMaxLatitudeDeg, zoom).y == 0);
      CHECK(tileAt(TileSchemeKind::WebMercator, 0.0, -kWebMercatorMaxLatitudeDeg, zoom).y == last);
      for (double lat_deg : {85.05, -85.05}) {
        const TileKey key = tileAt(TileSchemeKind::WebMercator, 0.0, lat_deg, zoom);
        const TileBounds b = tileBoundsDeg(TileSchemeKind::WebMercator, key);
        CHECK(b.south < lat_deg);
        CHECK(lat_deg <= b.north);
      }
    }
    checkError(thrownError([] { tileAt(TileSchemeKind::WebMercator, 10.0, 85.06, 5); }),
               ErrorCode::Input,
               "tile scheme webmercator: latitude 85.06 deg (at lon 10 deg) is beyond the Web "
               "Mercator limit of +-85.0511287798 deg; use the geographic tile scheme for polar "
               "data");
    checkError(thrownError([] { tileAt(TileSchemeKind::WebMercator, -20.5, -90.0, 0); }),
               ErrorCode::Input,
               "tile scheme webmercator: latitude -90 deg (at lon -20.5 deg) is beyond the Web "
               "Mercator limit of +-85.0511287798 deg; use the geographic tile scheme for polar "
               "data");
    const std::optional<Error> at_pole =
        thrownError([] { tileAt(TileSchemeKind::WebMercator, 0.0, 90.0, 3); });
    REQUIRE(at_pole.has_value());
    CHECK(at_pole->code() == ErrorCode::Input);
    CHECK(contains(at_pole->what(), "latitude 90 deg"));
    const double just_beyond = std::nextafter(kWebMercatorMaxLatitudeDeg, kInfinity);
    CHECK(thrownError([&] { tileAt(TileSchemeKind::WebMercator, 0.0, just_beyond, 3); }));
    // The same latitudes are fine in the geographic scheme.
    CHECK(tileAt(TileSchemeKind::Geographic, 10.0, 85.06, 5) == TileKey{5, 33, 0});
  }

  TEST_CASE("geographic latitude 90 is in the first row and -90 in the last row") {
    for (int zoom = 0; zoom <= 20; ++zoom) {
      const std::int32_t last = (std::int32_t{1} << zoom) - 1;
      CHECK(tileAt(TileSchemeKind::Geographic, 45.0, 90.0, zoom).y == 0);
      CHECK(tileAt(TileSchemeKind::Geographic, 45.0, -90.0, zoom).y == last);
    }
    checkError(thrownError([] { tileAt(TileSchemeKind::Geographic, 5.0, 90.5, 2); }),
               ErrorCode::Input,
               "tile scheme geographic: latitude 90.5 deg (at lon 5 deg) is outside [-90, 90] deg; "
               "expected lon/lat in degrees (check the CRS and the axis order)");
    CHECK(thrownError([] { tileAt(TileSchemeKind::Geographic, 5.0, -91.0, 2); }));
  }

  TEST_CASE("zooms outside 0 to 30 and tiles outside the grid are usage errors") {
    checkError(thrownError([] { tileAt(TileSchemeKind::WebMercator, 0.0, 0.0, 31); }),
               ErrorCode::Usage,
               "tile scheme webmercator: zoom 31 is outside the supported zooms 0..30; choose a "
               "zoom from 0 to 30");
    checkError(thrownError([] { tileAt(TileSchemeKind::Geographic, 0.0, 0.0, -1); }),
               ErrorCode::Usage,
               "tile scheme geographic: zoom -1 is outside the supported zooms 0..30; choose a "
               "zoom from 0 to 30");
    checkError(thrownError([] { tileBoundsDeg(TileSchemeKind::WebMercator, {3, 8, 0}); }),
               ErrorCode::Usage,
               "tile scheme webmercator: tile 3/8/0 is outside the zoom-3 grid of 8 x 8 tiles; "
               "expected x in 0..7 and y in 0..7");
    CHECK(thrownError([] { tileBoundsDeg(TileSchemeKind::Geographic, {3, 0, 8}); }));
    CHECK(thrownError([] { tileBoundsDeg(TileSchemeKind::Geographic, {3, -1, 0}); }));
    CHECK(thrownError([] { tileBoundsDeg(TileSchemeKind::Geographic, {31, 0, 0}); }));
    CHECK_FALSE(thrownError([] { tileBoundsDeg(TileSchemeKind::Geographic, {3, 15, 7}); }));
    CHECK(thrownError([] { webMercatorTileBoundsM({2, 0, 4}); }));
    CHECK(thrownError([] { tileGridSize(TileSchemeKind::Local, 31); }).value().code() ==
          ErrorCode::Usage);
  }

  TEST_CASE("non finite coordinates are input errors") {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    checkError(thrownError([&] { tileAt(TileSchemeKind::Geographic, nan, 10.0, 2); }),
               ErrorCode::Input,
               "tile scheme geographic: point (lon nan, lat 10) is not a finite lon/lat; expected "
               "finite degrees (check the input for nodata or NaN values)");
    CHECK(thrownError([&] { tileAt(TileSchemeKind::WebMercator, 0.0, nan, 2); }).value().code() ==
          ErrorCode::Input);
    CHECK(thrownError([&] {
            tileAt(TileSchemeKind::WebMercator, kInfinity, 0.0, 2);
          }).value().code() ==
          ErrorCode::Input);
    CHECK(thrownError([&] { normalizeLongitudeDeg(nan); }).value().code() == ErrorCode::Input);
    CHECK(thrownError([&] { lonLatToWebMercator(nan, 0.0); }).value().code() == ErrorCode::Input);
  }

  TEST_CASE("the deepest zoom 30 still maps points and bounds consistently") {
    for (TileSchemeKind kind : kWebSchemes) {
      const TileGridSize grid = tileGridSize(kind, 30);
      for (const TileKey& key : sampleTiles(kind, 30)) {
        CAPTURE(key.path());
        const TileBounds b = tileBoundsDeg(kind, key);
        CHECK(b.west < b.east);
        CHECK(b.south < b.north);
        CHECK(tileAt(kind, (b.west + b.east) / 2, (b.south + b.north) / 2, 30) == key);
        CHECK(tileAt(kind, b.west, b.north, 30) == key);
      }
      const std::int32_t last = static_cast<std::int32_t>(grid.columns - 1);
      CHECK(tileBoundsDeg(kind, {30, last, 0}).east == 180.0);
      CHECK(tileAt(kind, 179.9999999999, 0.0, 30).x == last);
    }
    CHECK(tileGridSize(TileSchemeKind::Geographic, 30).columns == std::int64_t{1} << 31);
  }

  TEST_CASE("tiles intersecting a box agree with a brute force search") {
    std::mt19937_64 random(7);
    const auto uniform = [&random](double low, double high) {
      return low + (high - low) * static_cast<double>(random() >> 11) * 0x1.0p-53;
    };
    for (TileSchemeKind kind : kWebSchemes) {
      const double lat_limit_deg =
          kind == TileSchemeKind::WebMercator ? kWebMercatorMaxLatitudeDeg : 90.0;
      for (int zoom = 0; zoom <= 4; ++zoom) {
        const TileGridSize grid = tileGridSize(kind, zoom);
        // A tile edge of this zoom, to put box edges exactly on tile edges.
        const auto edge_of = [&](bool longitude) {
          const TileKey key{zoom, static_cast<std::int32_t>(random() % grid.columns),
                            static_cast<std::int32_t>(random() % grid.rows)};
          const TileBounds b = tileBoundsDeg(kind, key);
          return longitude ? b.west : (random() % 2 ? b.north : b.south);
        };
        for (int i = 0; i < 200; ++i) {
          const bool snap = i % 2 == 1;
          const double west_deg = snap ? edge_of(true) : uniform(-180.0, 180.0);
          double east_deg = snap ? edge_of(true) : uniform(-180.0, 180.0);
          if (east_deg == west_deg) east_deg = 180.0;
          double south_deg = snap ? edge_of(false) : uniform(-lat_limit_deg, lat_limit_deg);
          double north_deg = snap ? edge_of(false) : uniform(-lat_limit_deg, lat_limit_deg);
          if (south_deg > north_deg) std::swap(south_deg, north_deg);
          if (south_deg == north_deg) north_deg = lat_limit_deg;
          if (south_deg == north_deg) south_deg = -lat_limit_deg;
          CAPTURE(zoom);
          CAPTURE(west_deg);
          CAPTURE(south_deg);
          CAPTURE(east_deg);
          CAPTURE(north_deg);
          const std::vector<TileKey> expected =
              bruteForceTiles(kind, west_deg, south_deg, east_deg, north_deg, zoom);
          CHECK(tilesIntersecting(kind, {west_deg, south_deg, east_deg, north_deg}, zoom) ==
                expected);
          // The same box with its east edge unwrapped past 180.
          if (east_deg < west_deg) {
            CHECK(tilesIntersecting(kind, {west_deg, south_deg, east_deg + 360.0, north_deg},
                                    zoom) == expected);
          }
        }
      }
    }
  }

  TEST_CASE("a box crossing the antimeridian lists the tiles on both sides") {
    // Geographic zoom 2: 45 deg tiles, 8 x 4.
    const std::vector<TileKey> expected = {{2, 0, 1}, {2, 7, 1}, {2, 0, 2}, {2, 7, 2}};
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {170.0, -10.0, -170.0, 10.0}, 2) ==
          expected);
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {170.0, -10.0, 190.0, 10.0}, 2) ==
          expected);
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {-190.0, -10.0, -170.0, 10.0}, 2) ==
          expected);
    // A box ending at the antimeridian stays on its side, whichever sign 180 has.
    const std::vector<TileKey> east_only = {{2, 7, 1}};
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {170.0, 10.0, 180.0, 20.0}, 2) ==
          east_only);
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {170.0, 10.0, -180.0, 20.0}, 2) ==
          east_only);
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {-180.0, 10.0, -170.0, 20.0}, 2) ==
          std::vector<TileKey>{{2, 0, 1}});
    // The whole world, and nearly the whole world across the antimeridian.
    CHECK(tilesIntersecting(TileSchemeKind::WebMercator, {-180.0, -85.0, 180.0, 85.0}, 3).size() ==
          64u);
    CHECK(tilesIntersecting(TileSchemeKind::WebMercator, {-170.0, -85.0, -170.5, 85.0}, 3).size() ==
          64u);
    CHECK(tilesIntersecting(TileSchemeKind::WebMercator, {0.0, 0.0, 720.0, 1.0}, 3).size() == 8u);
  }

  TEST_CASE("a box with edges on tile edges does not pull in the neighbours") {
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {-90.0, 0.0, 0.0, 90.0}, 1) ==
          std::vector<TileKey>{{1, 1, 0}});
    CHECK(tilesIntersecting(TileSchemeKind::WebMercator, {-180.0, 0.0, 0.0, 85.0}, 1) ==
          std::vector<TileKey>{{1, 0, 0}});
    // Zero width or height: the tiles tileAt gives, east and south of the edges.
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {0.0, 0.0, 0.0, 0.0}, 1) ==
          std::vector<TileKey>{{1, 2, 1}});
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {0.0, -10.0, 0.0, 10.0}, 1) ==
          std::vector<TileKey>{{1, 2, 0}, {1, 2, 1}});
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {180.0, 0.0, 180.0, 0.0}, 1) ==
          std::vector<TileKey>{{1, 0, 1}});
  }

  TEST_CASE("listing more tiles than the limit or an inverted box is an error") {
    checkError(
        thrownError([] {
          tilesIntersecting(TileSchemeKind::WebMercator,
                            {-180.0, -kWebMercatorMaxLatitudeDeg, 180.0,
                             kWebMercatorMaxLatitudeDeg},
                            20);
        }),
        ErrorCode::Usage,
        "tile scheme webmercator: the box covers 1099511627776 tiles at zoom 20, more than the "
        "16777216 a tile list may hold; choose a coarser zoom or a smaller box");
    // The whole geographic world at zoom 12 is twice the limit.
    CHECK(thrownError([] {
            tilesIntersecting(TileSchemeKind::Geographic, {-180.0, -90.0, 180.0, 90.0}, 12);
          }).value().code() == ErrorCode::Usage);
    CHECK(tilesIntersecting(TileSchemeKind::Geographic, {-180.0, -90.0, 180.0, 90.0}, 6).size() ==
          8192u);
    checkError(thrownError([] {
                 tilesIntersecting(TileSchemeKind::Geographic, {0.0, 10.0, 1.0, 5.0}, 3);
               }),
               ErrorCode::Input,
               "tile scheme geographic: box south 10 deg is north of its north 5 deg; expected "
               "south <= north");
    CHECK(thrownError([] {
            tilesIntersecting(TileSchemeKind::WebMercator, {0.0, 80.0, 1.0, 86.0}, 3);
          }).value().code() == ErrorCode::Input);
  }

  TEST_CASE("the local scheme puts the origin at the lower left corner with y from the south") {
    // 3 km x 5 km of EPSG:2056: the zoom-0 tile is 5 km square.
    const LocalTileScheme scheme =
        makeLocalTileScheme({2600000.0, 1200000.0, 2603000.0, 1205000.0});
    CHECK(scheme.origin_x_crs == 2600000.0);
    CHECK(scheme.origin_y_crs == 1200000.0);
    CHECK(scheme.root_size_crs == 5000.0);
    const TileBounds root = tileBounds(scheme, {0, 0, 0});
    CHECK((root.west == 2600000.0 && root.south == 1200000.0 && root.east == 2605000.0 &&
           root.north == 1205000.0));
    const TileBounds south_west = tileBounds(scheme, {1, 0, 0});
    CHECK((south_west.west == 2600000.0 && south_west.south == 1200000.0 &&
           south_west.east == 2602500.0 && south_west.north == 1202500.0));
    CHECK(tileAt(scheme, 2600100.0, 1204900.0, 1) == TileKey{1, 0, 1});
    CHECK(tileAt(scheme, 2602600.0, 1200100.0, 1) == TileKey{1, 1, 0});
    // The data's corners; the root tile's outer boundary is closed.
    CHECK(tileAt(scheme, 2600000.0, 1200000.0, 3) == TileKey{3, 0, 0});
    CHECK(tileAt(scheme, 2603000.0, 1205000.0, 3) == TileKey{3, 4, 7});
    CHECK(tileAt(scheme, 2605000.0, 1205000.0, 3) == TileKey{3, 7, 7});
    // A given root size.
    const LocalTileScheme wide = makeLocalTileScheme({0.0, 0.0, 3000.0, 5000.0}, 8192.0);
    CHECK(tileBounds(wide, {13, 8191, 8191}).east == 8192.0);
    CHECK(tileBounds(wide, {13, 8191, 8191}).west == 8191.0);
  }

  TEST_CASE("local tiles round trip and share edges at zooms 0 to 20") {
    const LocalTileScheme scheme = makeLocalTileScheme({-1234.5, 6789.25, 8000.125, 9000.0});
    for (int zoom = 0; zoom <= 20; ++zoom) {
      const std::int64_t n = std::int64_t{1} << zoom;
      for (const TileKey& key : sampleTiles(n, n, zoom)) {
        CAPTURE(key.path());
        const TileBounds b = tileBounds(scheme, key);
        const double size = scheme.root_size_crs / static_cast<double>(n);
        CHECK(b.west == doctest::Approx(scheme.origin_x_crs + key.x * size).epsilon(1e-15));
        CHECK(b.south == doctest::Approx(scheme.origin_y_crs + key.y * size).epsilon(1e-15));
        CHECK(tileAt(scheme, (b.west + b.east) / 2, (b.south + b.north) / 2, zoom) == key);
        if (key.x + 1 < n) {
          CHECK(sameBits(b.east, tileBounds(scheme, {zoom, key.x + 1, key.y}).west));
        }
        if (key.y + 1 < n) {
          CHECK(sameBits(b.north, tileBounds(scheme, {zoom, key.x, key.y + 1}).south));
        }
      }
    }
  }

  TEST_CASE("a local point on a shared edge belongs to the tile to the east and south") {
    const LocalTileScheme scheme = makeLocalTileScheme({100.0, 200.0, 300.0, 400.0});
    for (int zoom = 0; zoom <= 20; ++zoom) {
      const std::int64_t n = std::int64_t{1} << zoom;
      for (const TileKey& key : sampleTiles(n, n, zoom)) {
        CAPTURE(key.path());
        const TileBounds b = tileBounds(scheme, key);
        const double x = (b.west + b.east) / 2;
        const double y = (b.south + b.north) / 2;
        const TileKey east{zoom, key.x + 1 < n ? key.x + 1 : key.x, key.y};
        const TileKey south{zoom, key.x, key.y > 0 ? key.y - 1 : key.y};
        CHECK(tileAt(scheme, b.west, y, zoom) == key);
        CHECK(tileAt(scheme, b.east, y, zoom) == east);
        CHECK(tileAt(scheme, x, b.north, zoom) == key);
        CHECK(tileAt(scheme, x, b.south, zoom) == south);
        CHECK(tileAt(scheme, x, std::nextafter(b.south, kInfinity), zoom) == key);
      }
    }
  }

  TEST_CASE("a local extent whose width rounds still fits in its zoom 0 tile") {
    // -981.59 + (372.97 - -981.59) rounds below 372.97.
    const TileBounds extent{-981.5901228912301, 0.0, 372.9677083581595, 1.0};
    REQUIRE(extent.west + (extent.east - extent.west) < extent.east);
    const LocalTileScheme scheme = makeLocalTileScheme(extent);
    CHECK(scheme.origin_x_crs + scheme.root_size_crs >= extent.east);
    CHECK(tileAt(scheme, extent.east, extent.north, 10).x == 1023);
  }

  TEST_CASE("local scheme errors say what is wrong and how to fix it") {
    checkError(thrownError([] { makeLocalTileScheme({0.0, 0.0, 3000.0, 5000.0}, 4000.0); }),
               ErrorCode::Usage,
               "tile scheme local: zoom-0 tile size 4000 is smaller than the data's larger side "
               "5000 (CRS units); give a size of at least that, or 0 for the larger side");
    CHECK(thrownError([] {
            makeLocalTileScheme({0.0, 0.0, 3000.0, 5000.0}, -1.0);
          }).value().code() ==
          ErrorCode::Usage);
    checkError(thrownError([] { makeLocalTileScheme({10.0, 0.0, 10.0, 5.0}); }), ErrorCode::Input,
               "tile scheme local: data extent [10, 10] x [0, 5] (CRS units) is empty or not "
               "finite; expected west < east and south < north (check the raster's "
               "geotransform)");
    const LocalTileScheme scheme = makeLocalTileScheme({0.0, 0.0, 10.0, 10.0});
    checkError(thrownError([&] { tileAt(scheme, 10.5, 3.0, 2); }), ErrorCode::Input,
               "tile scheme local: point (x 10.5, y 3) is outside the zoom-0 tile [0, 10] x "
               "[0, 10] (CRS units); expected a point inside the data's extent");
    CHECK(thrownError([&] {
            tileAt(scheme, std::numeric_limits<double>::quiet_NaN(), 3.0, 2);
          }).value().code() == ErrorCode::Input);
    CHECK(thrownError([&] { tileAt(scheme, 1.0, 1.0, 31); }).value().code() == ErrorCode::Usage);
    CHECK(thrownError([&] { tileBounds(scheme, {1, 2, 0}); }).value().code() == ErrorCode::Usage);
    CHECK(thrownError([&] { tilesIntersecting(scheme, {5.0, 0.0, 4.0, 1.0}, 1); }).value().code() ==
          ErrorCode::Input);
  }

  TEST_CASE("local tiles intersecting a box follow the same edge rules") {
    const LocalTileScheme scheme = makeLocalTileScheme({0.0, 0.0, 12.0, 16.0});  // 4 x 4 at zoom 2
    CHECK(tilesIntersecting(scheme, {0.0, 0.0, 12.0, 16.0}, 2).size() == 12u);
    CHECK(tilesIntersecting(scheme, {4.0, 4.0, 8.0, 8.0}, 2) == std::vector<TileKey>{{2, 1, 1}});
    CHECK(tilesIntersecting(scheme, {3.0, 3.0, 5.0, 5.0}, 2) ==
          std::vector<TileKey>{{2, 0, 0}, {2, 1, 0}, {2, 0, 1}, {2, 1, 1}});
    // A point on a corner: east of the vertical edge, south of the horizontal one.
    CHECK(tilesIntersecting(scheme, {4.0, 4.0, 4.0, 4.0}, 2) == std::vector<TileKey>{{2, 1, 0}});
    CHECK(tileAt(scheme, 4.0, 4.0, 2) == TileKey{2, 1, 0});
  }
}
