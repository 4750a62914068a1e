#include "src/geo/place_on_globe.h"

#include <string>
#include <vector>

#include "src/base/error.h"

namespace terratiles {

void placeOnGlobe(const DemGrid& dem, std::span<const GridPoint> points, const CrsToWgs84& to_wgs84,
                  const GeoidGrid* geoid, std::span<GeodeticPoint> geodetic, std::span<EcefPoint> ecef) {
  TERRATILES_ASSERT(points.size() == geodetic.size() && points.size() == ecef.size());
  // One point (a vertex a collapse moves) without an allocation.
  CrsPoint one;
  std::vector<CrsPoint> many(points.size() == 1 ? 0 : points.size());
  const std::span<CrsPoint> crs = points.size() == 1 ? std::span<CrsPoint>(&one, 1) : std::span<CrsPoint>(many);
  for (std::size_t i = 0; i < points.size(); ++i) {
    crs[i] = dem.pixelCentre(points[i].col, points[i].row);
    geodetic[i].height_m = points[i].height_m;  // PROJ's datum shifts use it (see CrsToWgs84)
  }
  to_wgs84.transform(crs, geodetic);
  if (geoid) {  // orthometric -> WGS84 ellipsoidal: h = H + N(lon, lat)
    for (GeodeticPoint& p : geodetic) {
      const std::optional<double> undulation = geoid->undulationAt(p.lon_deg, p.lat_deg);
      if (!undulation) {
        throw Error(ErrorCode::Input,
                    "the point at " + std::to_string(p.lon_deg) + " E " + std::to_string(p.lat_deg) +
                        " N is outside the geoid grid " + geoid->name +
                        "; pass a grid that covers the data with --geoid FILE, or "
                        "--heights ellipsoidal when the DEM heights are ellipsoidal");
      }
      p.height_m += *undulation;
    }
  }
  geodeticToEcef(geodetic, ecef);
}

}  // namespace terratiles
