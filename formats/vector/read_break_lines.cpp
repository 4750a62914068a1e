#include "formats/vector/read_break_lines.h"

#include <gdal_priv.h>
#include <ogr_geometry.h>
#include <ogr_spatialref.h>
#include <ogrsf_frmts.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <memory>

#include "formats/gdal_support.h"
#include "src/base/error.h"

namespace terratiles {
namespace {

struct PixelPoint {
  double col = 0;
  double row = 0;
};

// The lines of a geometry: line strings, polygon rings, the parts of multi-geometries and
// collections; curves linearised; points and surfaces without rings give none.
void collectLines(const OGRGeometry& geometry, std::vector<const OGRSimpleCurve*>& lines,
                  std::vector<std::unique_ptr<OGRGeometry>>& keep_alive) {
  if (geometry.hasCurveGeometry()) {
    keep_alive.emplace_back(geometry.getLinearGeometry());
    if (keep_alive.back()) collectLines(*keep_alive.back(), lines, keep_alive);
    return;
  }
  switch (wkbFlatten(geometry.getGeometryType())) {
    case wkbLineString:
    case wkbLinearRing:
      lines.push_back(geometry.toSimpleCurve());
      break;
    case wkbPolygon: {
      const OGRPolygon* polygon = geometry.toPolygon();
      for (const OGRLinearRing* ring : *polygon) lines.push_back(ring);
      break;
    }
    case wkbMultiLineString:
    case wkbMultiPolygon:
    case wkbGeometryCollection: {
      const OGRGeometryCollection* collection = geometry.toGeometryCollection();
      for (const OGRGeometry* part : *collection) collectLines(*part, lines, keep_alive);
      break;
    }
    default:
      break;  // points carry no line
  }
}

// Clips the segment a-b to the box of pixel centres [0, width - 1] x [0, height - 1]
// (Liang-Barsky); false when nothing is left.
bool clipToGrid(PixelPoint& a, PixelPoint& b, const DemGrid& dem) {
  double t0 = 0, t1 = 1;
  const double dc = b.col - a.col, dr = b.row - a.row;
  const double p[4] = {-dc, dc, -dr, dr};
  const double q[4] = {a.col, dem.width - 1 - a.col, a.row, dem.height - 1 - a.row};
  for (int k = 0; k < 4; ++k) {
    if (p[k] == 0) {
      if (q[k] < 0) return false;
      continue;
    }
    const double t = q[k] / p[k];
    if (p[k] < 0) t0 = std::max(t0, t);
    else t1 = std::min(t1, t);
    if (t0 > t1) return false;
  }
  const PixelPoint start = a;
  a = {start.col + t0 * dc, start.row + t0 * dr};
  b = {start.col + t1 * dc, start.row + t1 * dr};
  return true;
}

// Adds the pieces of the segment a-b (pixel frame) that run over valid pixels only, their
// ends snapped to pixel centres.
void addSegment(PixelPoint a, PixelPoint b, const DemGrid& dem, BreakLines& out) {
  ++out.segments_read;
  const bool finite = std::isfinite(a.col) && std::isfinite(a.row) && std::isfinite(b.col) && std::isfinite(b.row);
  if (!finite || !clipToGrid(a, b, dem)) {
    ++out.pieces_left_out;
    return;
  }
  const auto c0 = static_cast<std::int32_t>(std::lround(a.col)), r0 = static_cast<std::int32_t>(std::lround(a.row));
  const auto c1 = static_cast<std::int32_t>(std::lround(b.col)), r1 = static_cast<std::int32_t>(std::lround(b.row));
  const std::int32_t steps = std::max(std::abs(c1 - c0), std::abs(r1 - r0));
  if (steps == 0) return;  // shorter than a pixel: its neighbours carry the line
  const auto sample = [&](std::int32_t k) {
    const double t = static_cast<double>(k) / steps;
    return std::array<std::int32_t, 2>{c0 + static_cast<std::int32_t>(std::lround(t * (c1 - c0))),
                                       r0 + static_cast<std::int32_t>(std::lround(t * (r1 - r0)))};
  };
  // Runs of valid samples become pieces from their first to their last pixel.
  const auto flush = [&](std::int32_t first, std::int32_t last) {
    if (first < 0 || last <= first) return;
    const auto from = sample(first), to = sample(last);
    out.segments.push_back({from[0], from[1], to[0], to[1]});
  };
  bool cut = false;
  std::int32_t run_start = -1;
  for (std::int32_t k = 0; k <= steps; ++k) {
    const auto p = sample(k);
    if (dem.isValid(p[0], p[1])) {
      if (run_start < 0) run_start = k;
      continue;
    }
    cut = true;
    flush(run_start, k - 1);
    run_start = -1;
  }
  flush(run_start, steps);
  if (cut) ++out.pieces_left_out;
}

}  // namespace

BreakLines readBreakLines(const std::string& path, const DemGrid& dem) {
  GDALAllRegister();
  GdalErrorCapture capture;
  if (!std::filesystem::exists(path)) {
    throw Error(ErrorCode::Input, "constraints file " + path +
                                      " does not exist; expected a vector file (GeoJSON, GeoPackage, Shapefile, ...)");
  }
  DatasetPtr dataset(static_cast<GDALDataset*>(
      GDALOpenEx(path.c_str(), GDAL_OF_VECTOR | GDAL_OF_READONLY, nullptr, nullptr, nullptr)));
  if (!dataset) {
    throw Error(ErrorCode::Input, path + ": GDAL cannot read it as vector data (" + capture.lastMessage() +
                                      "); expected lines or polygons in GeoJSON, GeoPackage, Shapefile or another "
                                      "OGR format");
  }
  OGRSpatialReference target;
  if (target.importFromWkt(dem.crs_wkt.c_str()) != OGRERR_NONE) {
    throw Error(ErrorCode::Internal, "the DEM's CRS (" + dem.crs_name + ") cannot be read back from its WKT");
  }
  target.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  BreakLines out;
  std::vector<const OGRSimpleCurve*> lines;
  std::vector<std::unique_ptr<OGRGeometry>> keep_alive;
  std::vector<double> xs, ys;
  std::vector<int> transformed;
  for (OGRLayer* layer : dataset->GetLayers()) {
    const std::string layer_name = layer->GetName();
    const OGRSpatialReference* layer_crs = layer->GetSpatialRef();
    if (!layer_crs) {
      throw Error(ErrorCode::Input, path + ": layer '" + layer_name +
                                        "' has no CRS; expected one (assign it, e.g. ogr2ogr -a_srs EPSG:4326 "
                                        "fixed.gpkg " + path + ")");
    }
    OGRSpatialReference source(*layer_crs);
    source.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    std::unique_ptr<OGRCoordinateTransformation> transform;
    if (!source.IsSame(&target)) {
      transform.reset(OGRCreateCoordinateTransformation(&source, &target));
      if (!transform) {
        throw Error(ErrorCode::Input, path + ": layer '" + layer_name + "' cannot be transformed to the DEM's CRS " +
                                          dem.crs_name + " (" + capture.lastMessage() +
                                          "); expected a CRS that PROJ can transform");
      }
    }
    layer->ResetReading();
    for (const auto& feature : *layer) {
      const OGRGeometry* geometry = feature->GetGeometryRef();
      if (!geometry) continue;
      lines.clear();
      keep_alive.clear();
      collectLines(*geometry, lines, keep_alive);
      if (!lines.empty()) ++out.features;
      for (const OGRSimpleCurve* line : lines) {
        const int count = line->getNumPoints();
        xs.resize(static_cast<std::size_t>(count));
        ys.resize(static_cast<std::size_t>(count));
        transformed.assign(static_cast<std::size_t>(count), 1);
        for (int i = 0; i < count; ++i) {
          xs[static_cast<std::size_t>(i)] = line->getX(i);
          ys[static_cast<std::size_t>(i)] = line->getY(i);
        }
        // Points the transformation cannot reach (far outside the DEM's CRS area) are left
        // out with their segments (their success flag is 0).
        if (transform && count > 0) transform->Transform(count, xs.data(), ys.data(), nullptr, transformed.data());
        for (int i = 0; i + 1 < count; ++i) {
          const auto k = static_cast<std::size_t>(i);
          if (!transformed[k] || !transformed[k + 1]) {
            ++out.segments_read;
            ++out.pieces_left_out;
            continue;
          }
          const PixelPoint a{(xs[k] - dem.origin_x) / dem.pixel_size_x - 0.5, (dem.origin_y - ys[k]) / dem.pixel_size_y - 0.5};
          const PixelPoint b{(xs[k + 1] - dem.origin_x) / dem.pixel_size_x - 0.5,
                             (dem.origin_y - ys[k + 1]) / dem.pixel_size_y - 0.5};
          addSegment(a, b, dem, out);
        }
      }
    }
  }
  return out;
}

}  // namespace terratiles
