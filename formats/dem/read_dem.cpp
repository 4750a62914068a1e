#include "formats/dem/read_dem.h"

#include <cpl_error.h>
#include <cpl_minixml.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <deque>
#include <optional>
#include <set>
#include <cmath>
#include <filesystem>
#include <memory>
#include <sstream>

#include "formats/dem/dem_inputs.h"
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
                                      "; expected a DEM such as a GeoTIFF (check with gdalinfo)" +
                                      (hasExtension(path, ".txt") || hasExtension(path, ".lst")
                                           ? std::string("; to name the inputs in a list, pass it with --input-list")
                                           : std::string()));
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

// A GDAL VRT that only places whole files on its own lattice (what gdalbuildvrt writes) is
// read through its source files, as if they had been listed: the same pixels, but on the
// sources' own georeferencing, which gdalbuildvrt recomputes with rounding (a VRT of SRTM
// pieces says 8.3333333333333252e-04 degrees where the pieces say 8.333333333333e-04), and
// without GDAL's pool of open sources. Anything else in a VRT (resampling, scaling, warping,
// other source kinds) is read through GDAL as one raster.
struct VrtLayout {
  std::string path;
  std::array<double, 6> geotransform{};
};

// One raster the scan opens: an input, or a source of a transparent VRT with where the VRT
// puts it (checked against the source's own georeferencing when it is opened).
struct ScanEntry {
  std::string path;
  const VrtLayout* vrt = nullptr;
  std::int64_t vrt_col = 0, vrt_row = 0;  // DstRect offset in the VRT's pixels
  std::int64_t width = 0, height = 0;     // SrcRect = DstRect size: the whole source
  std::optional<double> vrt_nodata;       // the VRT's NODATA for the source
};

// Thrown inside the scan when a VRT's source turns out not to sit where its own
// georeferencing says; the VRT is then read through GDAL.
struct VrtNotTransparent {
  std::string vrt_path;
};

std::optional<double> parseNumber(const char* text) {
  if (!text) return std::nullopt;
  std::istringstream in(text);
  in.imbue(std::locale::classic());
  double value = 0;
  if (!(in >> value)) return std::nullopt;
  return value;
}

struct XmlTree {
  CPLXMLNode* root = nullptr;
  ~XmlTree() {
    if (root) CPLDestroyXMLNode(root);
  }
};

// The sources of `path` if it is a transparent VRT (see above), in GDAL's drawing order.
std::optional<std::vector<ScanEntry>> transparentVrtSources(const std::string& path, std::deque<VrtLayout>& layouts) {
  GdalErrorCapture capture;
  XmlTree tree{CPLParseXMLFile(path.c_str())};
  const CPLXMLNode* dataset = tree.root ? CPLGetXMLNode(tree.root, "=VRTDataset") : nullptr;
  if (!dataset || CPLGetXMLValue(dataset, "subClass", nullptr)) return std::nullopt;
  VrtLayout layout{path, {}};
  {
    std::string text = CPLGetXMLValue(dataset, "GeoTransform", "");
    std::replace(text.begin(), text.end(), ',', ' ');
    std::istringstream in(text);
    in.imbue(std::locale::classic());
    for (double& term : layout.geotransform) {
      if (!(in >> term)) return std::nullopt;
    }
  }
  const CPLXMLNode* band = nullptr;
  for (const CPLXMLNode* node = dataset->psChild; node; node = node->psNext) {
    if (node->eType == CXT_Element && std::strcmp(node->pszValue, "VRTRasterBand") == 0 &&
        std::strcmp(CPLGetXMLValue(node, "band", "1"), "1") == 0) {
      band = node;
      break;
    }
  }
  if (!band || CPLGetXMLValue(band, "subClass", nullptr)) return std::nullopt;
  if (parseNumber(CPLGetXMLValue(band, "Offset", "0")).value_or(1) != 0.0 ||
      parseNumber(CPLGetXMLValue(band, "Scale", "1")).value_or(0) != 1.0) {
    return std::nullopt;
  }
  const std::filesystem::path directory = std::filesystem::path(path).parent_path();
  std::vector<ScanEntry> sources;
  for (const CPLXMLNode* node = band->psChild; node; node = node->psNext) {
    if (node->eType != CXT_Element) continue;
    const std::string kind = node->pszValue;
    const bool simple = kind == "SimpleSource", complex = kind == "ComplexSource";
    if (!simple && !complex) {
      if (kind.size() >= 6 && kind.compare(kind.size() - 6, 6, "Source") == 0) return std::nullopt;
      continue;  // NoDataValue, ColorInterp, Metadata, ...
    }
    if (complex) {
      for (const char* transform : {"LUT", "Exponent", "ColorTableComponent", "SrcMin", "SrcMax", "DstMin", "DstMax"}) {
        if (CPLGetXMLNode(node, transform)) return std::nullopt;
      }
      if (parseNumber(CPLGetXMLValue(node, "ScaleOffset", "0")).value_or(1) != 0.0 ||
          parseNumber(CPLGetXMLValue(node, "ScaleRatio", "1")).value_or(0) != 1.0) {
        return std::nullopt;
      }
    }
    const char* file = CPLGetXMLValue(node, "SourceFilename", nullptr);
    const CPLXMLNode* src = CPLGetXMLNode(node, "SrcRect");
    const CPLXMLNode* dst = CPLGetXMLNode(node, "DstRect");
    if (!file || !*file || !src || !dst || std::strcmp(CPLGetXMLValue(node, "SourceBand", "1"), "1") != 0) {
      return std::nullopt;
    }
    ScanEntry entry;
    const bool relative = std::strcmp(CPLGetXMLValue(node, "SourceFilename.relativeToVRT", "0"), "1") == 0;
    entry.path = relative ? (directory / file).string() : std::string(file);
    if (hasExtension(entry.path, ".vrt")) return std::nullopt;  // nested VRTs: GDAL reads them
    const auto number = [](const CPLXMLNode* rect, const char* name) {
      return parseNumber(CPLGetXMLValue(rect, name, nullptr));
    };
    const auto sx = number(src, "xOff"), sy = number(src, "yOff"), sw = number(src, "xSize"), sh = number(src, "ySize");
    const auto dx = number(dst, "xOff"), dy = number(dst, "yOff"), dw = number(dst, "xSize"), dh = number(dst, "ySize");
    if (!sx || !sy || !sw || !sh || !dx || !dy || !dw || !dh || *sx != 0 || *sy != 0 || *sw != *dw || *sh != *dh ||
        *dx != std::floor(*dx) || *dy != std::floor(*dy) || *sw != std::floor(*sw) || *sh != std::floor(*sh)) {
      return std::nullopt;
    }
    entry.vrt_col = static_cast<std::int64_t>(*dx);
    entry.vrt_row = static_cast<std::int64_t>(*dy);
    entry.width = static_cast<std::int64_t>(*sw);
    entry.height = static_cast<std::int64_t>(*sh);
    if (complex) entry.vrt_nodata = parseNumber(CPLGetXMLValue(node, "NODATA", nullptr));
    sources.push_back(std::move(entry));
  }
  if (sources.empty()) return std::nullopt;
  layouts.push_back(std::move(layout));
  for (ScanEntry& entry : sources) entry.vrt = &layouts.back();
  return sources;
}

// The rasters the scan opens for `paths`. GDAL draws a VRT's sources in order, later valid
// pixels over earlier ones; the mosaic keeps the first valid value, so the sources are taken
// last first.
std::vector<ScanEntry> scanEntries(const std::vector<std::string>& paths, const std::set<std::string>& opaque_vrts,
                                   std::deque<VrtLayout>& layouts) {
  std::vector<ScanEntry> entries;
  for (const std::string& path : paths) {
    if (hasExtension(path, ".vrt") && !opaque_vrts.count(path)) {
      if (auto sources = transparentVrtSources(path, layouts)) {
        entries.insert(entries.end(), std::make_move_iterator(sources->rbegin()),
                       std::make_move_iterator(sources->rend()));
        continue;
      }
    }
    ScanEntry entry;
    entry.path = path;
    entries.push_back(std::move(entry));
  }
  return entries;
}

// Throws VrtNotTransparent unless the source `r` of entry's VRT is the whole file, at the
// place its own georeferencing gives, with the nodata value the VRT assumes.
void checkVrtSource(const ScanEntry& entry, const RasterInfo& r) {
  const VrtLayout& vrt = *entry.vrt;
  const double pixel = vrt.geotransform[1];
  const double col = (r.geotransform[0] - vrt.geotransform[0]) / pixel;
  const double row = (vrt.geotransform[3] - r.geotransform[3]) / pixel;
  int has_nodata = 0;
  const double nodata = r.dataset->GetRasterBand(1)->GetNoDataValue(&has_nodata);
  const bool nodata_agrees = !entry.vrt_nodata || (has_nodata && nodata == *entry.vrt_nodata);
  if (r.dataset->GetRasterXSize() != entry.width || r.dataset->GetRasterYSize() != entry.height ||
      std::fabs(r.geotransform[1] - pixel) > 1e-9 * pixel || std::fabs(r.geotransform[5] + pixel) > 1e-9 * pixel ||
      vrt.geotransform[2] != 0 || vrt.geotransform[4] != 0 || std::fabs(col - entry.vrt_col) > 1e-3 ||
      std::fabs(row - entry.vrt_row) > 1e-3 || !nodata_agrees) {
    throw VrtNotTransparent{vrt.path};
  }
}

// Reads band 1 of `raster` as metres into `out` where the window `out_window` (in mosaic pixels)
// and the raster overlap; pixels that already hold a value keep it (the first valid value
// wins). Returns how many pixels it filled.
std::size_t readInto(const MosaicRaster& raster, const PixelWindow& out_window, DemGrid& out) {
  const std::int64_t col_begin = std::max(raster.col0, out_window.col0);
  const std::int64_t row_begin = std::max(raster.row0, out_window.row0);
  const std::int64_t col_end = std::min(raster.col0 + raster.width, out_window.col0 + out_window.width);
  const std::int64_t row_end = std::min(raster.row0 + raster.height, out_window.row0 + out_window.height);
  if (col_begin >= col_end || row_begin >= row_end) return 0;

  GdalErrorCapture capture;
  const DatasetPtr dataset(GDALDataset::FromHandle(
      GDALOpenEx(raster.path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr)));
  if (!dataset || dataset->GetRasterXSize() != raster.width || dataset->GetRasterYSize() != raster.height) {
    throw Error(ErrorCode::Input, raster.path + ": cannot be opened again, or changed size since it was scanned" +
                                      (dataset ? std::string() : " (GDAL: " + capture.lastMessage() + ")") +
                                      "; keep the inputs unchanged during a build");
  }
  GDALRasterBand* band = dataset->GetRasterBand(1);
  int has_nodata = 0;
  const double nodata = band->GetNoDataValue(&has_nodata);
  int has_scale = 0, has_offset = 0;
  double scale = band->GetScale(&has_scale);
  double offset = band->GetOffset(&has_offset);
  if (!has_scale) scale = 1.0;
  if (!has_offset) offset = 0.0;

  const int width = static_cast<int>(col_end - col_begin);
  // Strips of rows bound the buffer (8 MB) whatever the raster's size.
  const int strip_rows = static_cast<int>(std::clamp<std::int64_t>((1 << 20) / width, 1, row_end - row_begin));
  std::vector<double> values(static_cast<std::size_t>(width) * static_cast<std::size_t>(strip_rows));
  std::size_t valid = 0;
  for (std::int64_t strip = row_begin; strip < row_end; strip += strip_rows) {
    const int rows = static_cast<int>(std::min<std::int64_t>(strip_rows, row_end - strip));
    if (band->RasterIO(GF_Read, static_cast<int>(col_begin - raster.col0), static_cast<int>(strip - raster.row0),
                       width, rows, values.data(), width, rows, GDT_Float64, 0, 0, nullptr) != CE_None) {
      throw Error(ErrorCode::Input, raster.path + ": cannot read rows " + std::to_string(strip - raster.row0) +
                                        " to " + std::to_string(strip - raster.row0 + rows - 1) + " (GDAL: " +
                                        capture.lastMessage() + "); the file may be truncated");
    }
    for (int r = 0; r < rows; ++r) {
      const double* in = &values[static_cast<std::size_t>(r) * static_cast<std::size_t>(width)];
      float* row_out = &out.heights_m[out.index(static_cast<std::int32_t>(col_begin - out_window.col0),
                                                static_cast<std::int32_t>(strip + r - out_window.row0))];
      for (int col = 0; col < width; ++col) {
        const double raw = in[col];
        if (!std::isnan(row_out[col])) continue;  // first valid value wins
        if (!std::isfinite(raw) || (has_nodata && raw == nodata)) continue;
        const double h = raw * scale + offset;
        // Values beyond any terrain on Earth are undeclared nodata markers (e.g. -3.4e38).
        if (!(std::fabs(h) < 1e5)) continue;
        row_out[col] = static_cast<float>(h);
        ++valid;
      }
    }
  }
  return valid;
}

// The window's grid, every pixel nodata until read.
DemGrid emptyWindow(const DemMosaic& mosaic, const PixelWindow& window) {
  DemGrid dem = mosaicWindowGrid(mosaic, window);
  dem.heights_m.assign(dem.pixelCount(), DemGrid::kNoData);
  return dem;
}

DemMosaic scanEntriesIntoMosaic(const std::vector<ScanEntry>& entries, Progress* progress) {
  const bool show = progress && entries.size() > 1;
  if (show) progress->beginStage("scanning " + std::to_string(entries.size()) + " inputs", entries.size());

  // The first raster sets the CRS, pixel size and lattice; every later one is compared with
  // it as it is opened, so a mismatch is named before any pixel is read. Datasets are closed
  // at once: a country's tens of thousands of files never stay open together.
  DemMosaic mosaic;
  mosaic.rasters.reserve(entries.size());
  RasterInfo first;
  double west = 0, north = 0, east = 0, south = 0;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    RasterInfo r = openRaster(entries[i].path);
    if (entries[i].vrt) checkVrtSource(entries[i], r);
    const int raster_width = r.dataset->GetRasterXSize(), raster_height = r.dataset->GetRasterYSize();
    r.dataset.reset();
    if (i == 0) {
      first = std::move(r);
      const double pixel = first.geotransform[1];
      west = first.geotransform[0];
      north = first.geotransform[3];
      east = west + pixel * raster_width;
      south = north - pixel * raster_height;
      mosaic.rasters.push_back({first.path, 0, 0, raster_width, raster_height});
      if (show) progress->advance();
      continue;
    }
    const double pixel = first.geotransform[1];
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
    east = std::max(east, r.geotransform[0] + pixel * raster_width);
    south = std::min(south, r.geotransform[3] - pixel * raster_height);
    // Offsets from the first input for now; made relative to the mosaic's corner below.
    mosaic.rasters.push_back({r.path, std::llround(dx), std::llround(dy), raster_width, raster_height});
    if (show) progress->advance();
  }
  if (show) progress->endStage();

  const double pixel = first.geotransform[1];
  const std::int64_t first_col = std::llround((first.geotransform[0] - west) / pixel);
  const std::int64_t first_row = std::llround((north - first.geotransform[3]) / pixel);
  for (MosaicRaster& raster : mosaic.rasters) {
    raster.col0 += first_col;
    raster.row0 += first_row;
  }
  mosaic.width = std::llround((east - west) / pixel);
  mosaic.height = std::llround((north - south) / pixel);
  mosaic.origin_x = west;
  mosaic.origin_y = north;
  mosaic.pixel_size = pixel;
  mosaic.crs_name = first.crs_name;
  char* wkt = nullptr;
  const char* wkt_options[] = {"FORMAT=WKT2_2019", nullptr};
  first.srs.exportToWkt(&wkt, wkt_options);
  mosaic.crs_wkt = wkt ? wkt : "";
  CPLFree(wkt);
  if (mosaic.width < 2 || mosaic.height < 2) {
    throw Error(ErrorCode::Input, first.path + ": raster is " + std::to_string(mosaic.width) + " x " +
                                      std::to_string(mosaic.height) + " pixels; expected at least 2 x 2");
  }
  return mosaic;
}

}  // namespace

DemMosaic scanDemMosaic(const std::vector<std::string>& paths, Progress* progress) {
  if (paths.empty()) throw Error(ErrorCode::Usage, "no input raster given");
  GDALAllRegister();
  std::set<std::string> opaque_vrts;
  for (;;) {
    std::deque<VrtLayout> layouts;
    try {
      return scanEntriesIntoMosaic(scanEntries(paths, opaque_vrts, layouts), progress);
    } catch (const VrtNotTransparent& vrt) {
      opaque_vrts.insert(vrt.vrt_path);  // read it through GDAL instead
    }
  }
}

DemGrid mosaicWindowGrid(const DemMosaic& mosaic, const PixelWindow& window) {
  DemGrid dem;
  dem.width = window.width;
  dem.height = window.height;
  dem.origin_x = mosaic.origin_x + static_cast<double>(window.col0) * mosaic.pixel_size;
  dem.origin_y = mosaic.origin_y - static_cast<double>(window.row0) * mosaic.pixel_size;
  dem.pixel_size_x = mosaic.pixel_size;
  dem.pixel_size_y = mosaic.pixel_size;
  dem.col_offset = window.col0;
  dem.row_offset = window.row0;
  dem.lattice_origin_x = mosaic.origin_x;
  dem.lattice_origin_y = mosaic.origin_y;
  dem.crs_name = mosaic.crs_name;
  dem.crs_wkt = mosaic.crs_wkt;
  return dem;
}

DemGrid readDemWindow(const DemMosaic& mosaic, const PixelWindow& window) {
  TERRATILES_ASSERT(window.width >= 0 && window.height >= 0);
  DemGrid dem = emptyWindow(mosaic, window);
  for (const MosaicRaster& raster : mosaic.rasters) readInto(raster, window, dem);
  return dem;
}

namespace {

// Mosaic rows per readDemOverview strip: a multiple of the factor.
std::int64_t overviewStripRows(const DemMosaic& mosaic, std::int32_t factor, std::int64_t strip_pixels) {
  const std::int64_t rows = std::max<std::int64_t>(1, strip_pixels / std::max<std::int64_t>(1, mosaic.width));
  return std::max<std::int64_t>(1, rows / factor) * factor;
}

}  // namespace

std::int64_t overviewStrips(const DemMosaic& mosaic, std::int32_t factor, std::int64_t strip_pixels) {
  const std::int64_t rows = overviewStripRows(mosaic, factor, strip_pixels);
  return (mosaic.height + rows - 1) / rows;
}

DemGrid readDemOverview(const DemMosaic& mosaic, std::int32_t factor, std::int64_t strip_pixels, Progress* progress,
                        const std::function<void(const DemGrid&, std::int64_t)>& each_strip) {
  TERRATILES_ASSERT(factor >= 1);
  const std::int64_t f = factor;
  DemGrid overview;
  overview.width = static_cast<std::int32_t>((mosaic.width + f - 1) / f);
  overview.height = static_cast<std::int32_t>((mosaic.height + f - 1) / f);
  overview.origin_x = mosaic.origin_x;
  overview.origin_y = mosaic.origin_y;
  overview.pixel_size_x = mosaic.pixel_size * static_cast<double>(f);
  overview.pixel_size_y = overview.pixel_size_x;
  overview.crs_name = mosaic.crs_name;
  overview.crs_wkt = mosaic.crs_wkt;
  overview.heights_m.assign(overview.pixelCount(), DemGrid::kNoData);
  const std::int64_t strip_rows = overviewStripRows(mosaic, factor, strip_pixels);
  std::vector<double> sums(static_cast<std::size_t>(overview.width));
  std::vector<std::uint32_t> counts(sums.size());
  for (std::int64_t r0 = 0; r0 < mosaic.height; r0 += strip_rows) {
    const auto rows = static_cast<std::int32_t>(std::min(strip_rows, mosaic.height - r0));
    const DemGrid strip = readDemWindow(mosaic, {0, r0, static_cast<std::int32_t>(mosaic.width), rows});
    for (std::int32_t r = 0; r < rows; r += factor) {
      std::fill(sums.begin(), sums.end(), 0.0);
      std::fill(counts.begin(), counts.end(), 0u);
      for (std::int32_t dr = 0; dr < factor && r + dr < rows; ++dr) {
        for (std::int32_t col = 0; col < strip.width; ++col) {
          const float h = strip.heightAt(col, r + dr);
          if (std::isnan(h)) continue;
          sums[static_cast<std::size_t>(col / factor)] += h;
          ++counts[static_cast<std::size_t>(col / factor)];
        }
      }
      const std::size_t out_row = static_cast<std::size_t>((r0 + r) / f) * static_cast<std::size_t>(overview.width);
      for (std::size_t c = 0; c < sums.size(); ++c) {
        if (counts[c] > 0) overview.heights_m[out_row + c] = static_cast<float>(sums[c] / counts[c]);
      }
    }
    if (each_strip) each_strip(strip, r0);
    if (progress) progress->advance();
  }
  return overview;
}

DemGrid readDem(const DemMosaic& mosaic, const ReadDemOptions& options) {
  if (mosaic.width > INT32_MAX || mosaic.height > INT32_MAX ||
      (options.max_pixels > 0 &&
       static_cast<std::size_t>(mosaic.width) * static_cast<std::size_t>(mosaic.height) > options.max_pixels)) {
    throw Error(ErrorCode::Input, "the mosaic of the inputs is " + std::to_string(mosaic.width) + " x " +
                                      std::to_string(mosaic.height) + " pixels; at most " +
                                      std::to_string(options.max_pixels) +
                                      " pixels fit the in-memory path (split the input)");
  }
  const PixelWindow whole{0, 0, static_cast<std::int32_t>(mosaic.width), static_cast<std::int32_t>(mosaic.height)};
  DemGrid dem = emptyWindow(mosaic, whole);
  std::size_t valid = 0;
  for (const MosaicRaster& raster : mosaic.rasters) {
    valid += readInto(raster, whole, dem);
    if (options.progress) options.progress->advance();
  }
  if (valid == 0) {
    throw Error(ErrorCode::Input, mosaic.rasters.front().path +
                                      ": every pixel is nodata; expected a DEM with at least "
                                      "some valid heights");
  }
  return dem;
}

DemGrid readDem(const std::vector<std::string>& paths, const ReadDemOptions& options) {
  return readDem(scanDemMosaic(paths), options);
}

DemGrid readDem(const std::vector<std::string>& paths, const std::string& stage, Progress& progress) {
  return readDem(scanDemMosaic(paths, &progress), stage, progress);
}

DemGrid readDem(const DemMosaic& mosaic, const std::string& stage, Progress& progress) {
  const bool several = mosaic.rasters.size() > 1;
  progress.beginStage(stage, several ? mosaic.rasters.size() : 0);
  ReadDemOptions options;
  if (several) options.progress = &progress;
  return readDem(mosaic, options);
}

}  // namespace terratiles
