#include "formats/geoid/read_geoid.h"

#include <cpl_error.h>
#include <gdal_priv.h>

#include <cmath>
#include <filesystem>
#include <memory>

#include "src/base/error.h"

namespace terratiles {

GeoidGrid readGeoidGrid(const std::string& path) {
  GDALAllRegister();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    throw Error(ErrorCode::Input,
                path + ": geoid grid not found; install proj-data for EGM96, pass --geoid FILE, "
                       "or --heights ellipsoidal when the DEM heights are ellipsoidal");
  }
  CPLPushErrorHandler(CPLQuietErrorHandler);
  std::unique_ptr<GDALDataset, void (*)(GDALDataset*)> dataset(
      GDALDataset::FromHandle(GDALOpenEx(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr,
                                         nullptr, nullptr)),
      [](GDALDataset* d) { GDALClose(d); });
  CPLPopErrorHandler();
  if (!dataset || dataset->GetRasterCount() < 1) {
    throw Error(ErrorCode::Input, path + ": not a geoid grid GDAL can read; expected a raster "
                                         "such as a .gtx or GeoTIFF geoid model");
  }
  const OGRSpatialReference* srs = dataset->GetSpatialRef();
  if (srs && !srs->IsEmpty() && !srs->IsGeographic()) {
    throw Error(ErrorCode::Input, path + ": geoid grid is in a projected CRS; expected a "
                                         "longitude/latitude grid");
  }
  double gt[6];
  if (dataset->GetGeoTransform(gt) != CE_None || gt[2] != 0 || gt[4] != 0 || !(gt[1] > 0) ||
      !(gt[5] < 0)) {
    throw Error(ErrorCode::Input, path + ": geoid grid is not a north-up longitude/latitude "
                                         "raster; expected a .gtx or GeoTIFF geoid model");
  }
  GeoidGrid grid;
  grid.name = std::filesystem::path(path).filename().string();
  grid.width = dataset->GetRasterXSize();
  grid.height = dataset->GetRasterYSize();
  grid.step_deg = gt[1];
  grid.step_lat_deg = -gt[5];
  grid.first_lon_deg = gt[0] + gt[1] / 2;
  grid.first_lat_deg = gt[3] + gt[5] / 2;
  grid.wraps_longitude = std::fabs(grid.width * grid.step_deg - 360.0) < grid.step_deg * 1e-6;
  grid.undulation_m.resize(static_cast<std::size_t>(grid.width) * grid.height);
  GDALRasterBand* band = dataset->GetRasterBand(1);
  if (band->RasterIO(GF_Read, 0, 0, grid.width, grid.height, grid.undulation_m.data(), grid.width,
                     grid.height, GDT_Float32, 0, 0, nullptr) != CE_None) {
    throw Error(ErrorCode::Input, path + ": cannot read the geoid grid (" +
                                      std::string(CPLGetLastErrorMsg()) + ")");
  }
  int has_nodata = 0;
  const double nodata = band->GetNoDataValue(&has_nodata);
  for (float& value : grid.undulation_m) {
    if ((has_nodata && value == static_cast<float>(nodata)) || !std::isfinite(value)) {
      value = std::nanf("");
    }
  }
  return grid;
}

}  // namespace terratiles
