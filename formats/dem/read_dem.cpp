#include "formats/dem/read_dem.h"

#include <cpl_error.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <memory>
#include <sstream>

#include "formats/gdal_support.h"
#include "src/base/error.h"

namespace terratiles {
namespace {

std::string format(double value) {
  std::ostringstream out;
  out.imbue(std::locale::classic());
  out.precision(10);
  out << value;
  return out.str();
}

struct RasterInfo {
  std::string path;
  DatasetPtr dataset;
  std::array<double, 6> geotransform{};
  OGRSpatialReference srs;
  std::string crs_name;
};

std::string describeCrs(const OGRSpatialReference& srs) {
  const char* authority = srs.GetAuthorityName(nullptr);
  const char* code = srs.GetAuthorityCode(nullptr);
  if (authority && code) return std::string(authority) + ":" + code;
  const char* name = srs.GetName();
  return name ? name : "unnamed CRS";
}

RasterInfo openRaster(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    throw Error(ErrorCode::Input, path + ": no such file; check the path");
  }
  if (std::filesystem::is_directory(path, ec)) {
    throw Error(ErrorCode::Input, path + ": is a directory; expected a raster file such as a GeoTIFF");
  }
  GdalErrorCapture capture;
  RasterInfo info;
  info.path = path;
  info.dataset.reset(GDALDataset::FromHandle(
      GDALOpenEx(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr)));
  if (!info.dataset) {
    std::string gdal = capture.lastMessage();
    throw Error(ErrorCode::Input, path + ": not a raster that GDAL can read" +
                                      (gdal.empty() ? std::string() : " (GDAL: " + gdal + ")") +
                                      "; expected a DEM such as a GeoTIFF (check with gdalinfo)");
  }
  if (info.dataset->GetRasterCount() < 1) {
    throw Error(ErrorCode::Input, path + ": has no raster band; expected a single-band DEM");
  }
  const OGRSpatialReference* srs = info.dataset->GetSpatialRef();
  if (!srs || srs->IsEmpty()) {
    throw Error(ErrorCode::Input,
                path + ": raster has no coordinate reference system; assign one with "
                       "'gdal_edit.py -a_srs EPSG:<code> " + path + "'");
  }
  info.srs = *srs;
  if (info.srs.IsCompound()) info.srs.StripVertical();  // heights are handled on their own
  info.srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  if (!info.srs.GetAuthorityCode(nullptr)) info.srs.AutoIdentifyEPSG();
  info.crs_name = describeCrs(info.srs);
  if (!info.srs.IsProjected() && !info.srs.IsGeographic()) {
    throw Error(ErrorCode::Input, path + ": CRS " + info.crs_name +
                                      " is neither projected nor geographic; expected a map CRS "
                                      "such as EPSG:2056 or EPSG:4326 (reproject with gdalwarp -t_srs)");
  }
  if (info.dataset->GetGeoTransform(info.geotransform.data()) != CE_None) {
    throw Error(ErrorCode::Input, path + ": raster has no geotransform (pixel-to-CRS mapping); "
                                         "georeference it with gdal_translate -a_ullr");
  }
  const auto& gt = info.geotransform;
  if (gt[2] != 0.0 || gt[4] != 0.0) {
    throw Error(ErrorCode::Input, path + ": raster is rotated (geotransform terms " + format(gt[2]) +
                                      ", " + format(gt[4]) +
                                      "); expected north-up (resample with gdalwarp)");
  }
  if (!(gt[1] > 0.0) || !(gt[5] < 0.0)) {
    throw Error(ErrorCode::Input, path + ": pixel size is " + format(gt[1]) + " x " +
                                      format(gt[5]) +
                                      "; expected north-up with positive x and negative y "
                                      "(flip with gdalwarp)");
  }
  if (std::fabs(gt[1] + gt[5]) > 1e-9 * gt[1]) {
    throw Error(ErrorCode::Input, path + ": pixels are " + format(gt[1]) + " x " + format(-gt[5]) +
                                      "; non-square pixels are not supported (resample with "
                                      "gdalwarp -tr " + format(gt[1]) + " " + format(gt[1]) + ")");
  }
  return info;
}

// Reads band 1 as metres into `mosaic` at the given pixel offset. Returns valid pixel count.
std::size_t readInto(RasterInfo& info, DemGrid& mosaic, std::int64_t col0, std::int64_t row0) {
  GDALRasterBand* band = info.dataset->GetRasterBand(1);
  const int width = info.dataset->GetRasterXSize();
  const int height = info.dataset->GetRasterYSize();
  int has_nodata = 0;
  const double nodata = band->GetNoDataValue(&has_nodata);
  int has_scale = 0, has_offset = 0;
  double scale = band->GetScale(&has_scale);
  double offset = band->GetOffset(&has_offset);
  if (!has_scale) scale = 1.0;
  if (!has_offset) offset = 0.0;

  std::vector<double> row_values(static_cast<std::size_t>(width));
  std::size_t valid = 0;
  GdalErrorCapture capture;
  for (int row = 0; row < height; ++row) {
    if (band->RasterIO(GF_Read, 0, row, width, 1, row_values.data(), width, 1, GDT_Float64, 0, 0,
                       nullptr) != CE_None) {
      throw Error(ErrorCode::Input, info.path + ": cannot read row " + std::to_string(row) +
                                        " (GDAL: " + capture.lastMessage() +
                                        "); the file may be truncated");
    }
    float* out = &mosaic.heights_m[mosaic.index(static_cast<std::int32_t>(col0),
                                                 static_cast<std::int32_t>(row0 + row))];
    for (int col = 0; col < width; ++col) {
      const double raw = row_values[static_cast<std::size_t>(col)];
      if (!std::isnan(out[col])) continue;  // first valid value wins
      if (!std::isfinite(raw) || (has_nodata && raw == nodata)) continue;
      const double h = raw * scale + offset;
      // Values beyond any terrain on Earth are undeclared nodata markers (e.g. -3.4e38).
      if (!(std::fabs(h) < 1e5)) continue;
      out[col] = static_cast<float>(h);
      ++valid;
    }
  }
  return valid;
}

}  // namespace

DemGrid readDem(const std::vector<std::string>& paths, const ReadDemOptions& options) {
  if (paths.empty()) throw Error(ErrorCode::Usage, "no input raster given");
  GDALAllRegister();

  std::vector<RasterInfo> rasters;
  rasters.reserve(paths.size());
  for (const auto& path : paths) rasters.push_back(openRaster(path));

  const RasterInfo& first = rasters.front();
  const double pixel = first.geotransform[1];
  double west = first.geotransform[0], north = first.geotransform[3];
  double east = west + pixel * first.dataset->GetRasterXSize();
  double south = north - pixel * first.dataset->GetRasterYSize();
  for (std::size_t i = 1; i < rasters.size(); ++i) {
    const RasterInfo& r = rasters[i];
    const char* same_options[] = {"IGNORE_DATA_AXIS_TO_SRS_AXIS_MAPPING=YES", nullptr};
    if (!r.srs.IsSame(&first.srs, same_options)) {
      throw Error(ErrorCode::Input, r.path + ": CRS is " + r.crs_name + " but " + first.path +
                                        " is " + first.crs_name +
                                        "; all inputs of a mosaic must share one CRS (reproject "
                                        "with gdalwarp -t_srs " + first.crs_name + ")");
    }
    if (std::fabs(r.geotransform[1] - pixel) > 1e-9 * pixel) {
      throw Error(ErrorCode::Input, r.path + ": pixel size is " + format(r.geotransform[1]) +
                                        " but " + first.path + " has " + format(pixel) +
                                        "; all inputs of a mosaic must share one pixel size "
                                        "(resample with gdalwarp -tr)");
    }
    const double dx = (r.geotransform[0] - first.geotransform[0]) / pixel;
    const double dy = (first.geotransform[3] - r.geotransform[3]) / pixel;
    if (std::fabs(dx - std::round(dx)) > 1e-3 || std::fabs(dy - std::round(dy)) > 1e-3) {
      throw Error(ErrorCode::Input, r.path + ": is offset by " + format(dx) + ", " + format(dy) +
                                        " pixels from " + first.path +
                                        "; expected whole pixels (align with gdalwarp -tap)");
    }
    west = std::min(west, r.geotransform[0]);
    north = std::max(north, r.geotransform[3]);
    east = std::max(east, r.geotransform[0] + pixel * r.dataset->GetRasterXSize());
    south = std::min(south, r.geotransform[3] - pixel * r.dataset->GetRasterYSize());
  }

  const std::int64_t width = std::llround((east - west) / pixel);
  const std::int64_t height = std::llround((north - south) / pixel);
  if (width < 2 || height < 2) {
    throw Error(ErrorCode::Input, first.path + ": raster is " + std::to_string(width) + " x " +
                                      std::to_string(height) +
                                      " pixels; expected at least 2 x 2");
  }
  if (width > INT32_MAX || height > INT32_MAX ||
      (options.max_pixels > 0 &&
       static_cast<std::size_t>(width) * static_cast<std::size_t>(height) > options.max_pixels)) {
    throw Error(ErrorCode::Input, "the mosaic of the inputs is " + std::to_string(width) + " x " +
                                      std::to_string(height) + " pixels; at most " +
                                      std::to_string(options.max_pixels) +
                                      " pixels fit the in-memory path (split the input)");
  }

  DemGrid dem;
  dem.width = static_cast<std::int32_t>(width);
  dem.height = static_cast<std::int32_t>(height);
  dem.origin_x = west;
  dem.origin_y = north;
  dem.pixel_size_x = pixel;
  dem.pixel_size_y = pixel;
  dem.crs_name = first.crs_name;
  {
    char* wkt = nullptr;
    const char* wkt_options[] = {"FORMAT=WKT2_2019", nullptr};
    first.srs.exportToWkt(&wkt, wkt_options);
    dem.crs_wkt = wkt ? wkt : "";
    CPLFree(wkt);
  }
  dem.heights_m.assign(dem.pixelCount(), DemGrid::kNoData);

  std::size_t valid = 0;
  for (auto& r : rasters) {
    const std::int64_t col0 = std::llround((r.geotransform[0] - west) / pixel);
    const std::int64_t row0 = std::llround((north - r.geotransform[3]) / pixel);
    valid += readInto(r, dem, col0, row0);
  }
  if (valid == 0) {
    throw Error(ErrorCode::Input, first.path +
                                      ": every pixel is nodata; expected a DEM with at least "
                                      "some valid heights");
  }
  return dem;
}

}  // namespace terratiles
