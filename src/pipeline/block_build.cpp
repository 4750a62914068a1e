#include "src/pipeline/block_build.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <set>
#include <tuple>
#include <unordered_map>
#include <bit>

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <nlohmann/json.hpp>

#include "formats/geoid/read_geoid.h"
#include "formats/gltf/write_glb.h"
#include "formats/output_directory.h"
#include "src/base/block_record.h"
#include "src/base/error.h"
#include "src/base/freed_memory.h"
#include "src/base/largest_first.h"
#include "src/base/ranks.h"
#include "src/base/version.h"
#include "src/geo/crs_transform.h"
#include "src/geo/dem_on_globe.h"
#include "src/lod/build_levels.h"
#include "src/pipeline/block_tin.h"
#include "src/pipeline/drawn_tiles.h"
#include "src/pipeline/tile_output.h"
#include "tileset/implicit_tileset.h"

namespace terratiles {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

// A mosaic pixel coordinate on an overview of `factor` pixels a side per overview pixel
// (readDemOverview), and back; exact for a power-of-two factor and pixel centres.
double mosaicToOverview(double coordinate, std::int32_t factor) { return (coordinate + 0.5) / factor - 0.5; }
double overviewToMosaic(double coordinate, std::int32_t factor) { return (coordinate + 0.5) * factor - 0.5; }

// The smallest power of two f whose overview of the mosaic has at most `pixels` pixels.
std::int32_t overviewFactor(const DemMosaic& mosaic, std::int64_t pixels) {
  std::int32_t f = 1;
  while (((mosaic.width + f - 1) / f) * ((mosaic.height + f - 1) / f) > pixels) f *= 2;
  return f;
}

// The local scheme's extent: the mosaic's (whatever window a frame is made on).
TileBounds mosaicExtent(const DemMosaic& mosaic) {
  return {mosaic.origin_x, mosaic.origin_y - static_cast<double>(mosaic.height) * mosaic.pixel_size,
          mosaic.origin_x + static_cast<double>(mosaic.width) * mosaic.pixel_size, mosaic.origin_y};
}

// Pixel borders along the edges of one axis's tiles: `edge(k)` is the scheme coordinate of
// the k-th tile edge (k from k_first to k_last, increasing in pixels) and `pixel(value)` the
// axis's pixel coordinate of a scheme coordinate (pixel centres at whole numbers). A border
// goes to the nearest pixel line, at least 2 pixels from the mosaic's edges and from the
// previous border. `lines` and `values`: every border and the scheme coordinate it stands for,
// the outer ones included (with their own coordinates).
struct AxisBorders {
  std::vector<std::int64_t> borders;
  std::vector<double> lines, values;
};

AxisBorders tileBorders(std::int64_t length, const std::function<double(std::int64_t)>& edge,
                        const std::function<double(double)>& pixel, const std::function<double(double)>& coordinate,
                        std::int64_t k_first, std::int64_t k_last) {
  AxisBorders out;
  out.borders.push_back(0);
  out.values.push_back(coordinate(0));
  for (std::int64_t k = k_first; k <= k_last; ++k) {
    const double value = edge(k);
    const double at = pixel(value);
    if (!std::isfinite(at)) continue;
    const auto line = static_cast<std::int64_t>(std::llround(at));
    if (line >= out.borders.back() + 2 && line <= length - 3) {
      out.borders.push_back(line);
      out.values.push_back(value);
    }
  }
  const std::int64_t last = std::max<std::int64_t>(length - 1, 0);
  out.borders.push_back(last);
  out.values.push_back(coordinate(static_cast<double>(last)));
  for (const std::int64_t b : out.borders) out.lines.push_back(static_cast<double>(b));
  return out;
}

// Where the build's tiles meet the mosaic's pixels: the frame over the whole mosaic, and
// (when the scheme's tiles follow the DEM's rows and columns) each axis's pixel coordinate of
// a scheme coordinate.
struct BlockLayout {
  std::int32_t zoom = 0;  // Zb: a block is one tile of it
  BlockGrid grid;
  std::vector<TileKey> keys;  // per block, row-major: its tile at Zb
  AxisBorders columns, rows;  // for TileFrame::followBlocks
  void follow(TileFrame& frame) const { frame.followBlocks(columns.lines, columns.values, rows.lines, rows.values); }
  // The same for a frame on an overview of the mosaic (`factor` mosaic pixels a side each).
  void follow(TileFrame& frame, std::int32_t factor) const {
    const auto scaled = [&](std::vector<double> lines) {
      for (double& line : lines) line = mosaicToOverview(line, factor);
      return lines;
    };
    frame.followBlocks(scaled(columns.lines), columns.values, scaled(rows.lines), rows.values);
  }
};

// x (lon or CRS x) and y (lat or CRS y) of the scheme for pixel (col, row), and back.
double pixelColumnOf(const DemMosaic& mosaic, double x) { return (x - mosaic.origin_x) / mosaic.pixel_size - 0.5; }
double pixelRowOf(const DemMosaic& mosaic, double y) { return (mosaic.origin_y - y) / mosaic.pixel_size - 0.5; }

BlockLayout layBlocks(const BuildOptions& options, const DemMosaic& mosaic, const TileFrame& frame,
                      std::int32_t block_pixels) {
  const TileSchemeKind kind = options.scheme;
  if (kind != TileSchemeKind::Local && !CrsToWgs84(mosaic.crs_wkt).isWgs84LonLat()) {
    throw Error(ErrorCode::Usage,
                "the build in blocks needs the " + std::string(tileSchemeName(kind)) +
                    " tiles along the DEM's rows and columns, which " + mosaic.crs_name +
                    " pixels are not; use --scheme local, or reproject the DEM to WGS84 longitude and latitude "
                    "(gdalwarp -t_srs EPSG:4326), or pass --block-pixels larger than the mosaic (" +
                    std::to_string(mosaic.width) + " x " + std::to_string(mosaic.height) + ")");
  }
  // The data's extent in scheme coordinates (pixel centres at the corners).
  const double west = mosaic.origin_x + 0.5 * mosaic.pixel_size;
  const double east = mosaic.origin_x + (static_cast<double>(mosaic.width) - 0.5) * mosaic.pixel_size;
  const double north = mosaic.origin_y - 0.5 * mosaic.pixel_size;
  const double south = mosaic.origin_y - (static_cast<double>(mosaic.height) - 0.5) * mosaic.pixel_size;
  const double lat_limit = kind == TileSchemeKind::WebMercator ? kWebMercatorMaxLatitudeDeg : 90.0;
  const auto clampLat = [&](double lat) { return kind == TileSchemeKind::Local ? lat : std::clamp(lat, -lat_limit, lat_limit); };
  // Zb: the coarsest zoom whose tiles over the data span at most block_pixels pixels a side.
  BlockLayout layout;
  const auto tileAtPoint = [&](double x, double y, std::int32_t zoom) {
    return frame.tileAt({x, clampLat(y)}, zoom);
  };
  const auto boundsOf = [&](TileKey key) {
    return kind == TileSchemeKind::Local ? tileBounds(frame.local(), key) : tileBoundsDeg(kind, key);
  };
  const double equator_most = kind == TileSchemeKind::Local ? (south + north) / 2 : std::clamp(0.0, south, north);
  for (layout.zoom = 0; layout.zoom < kMaxTileZoom; ++layout.zoom) {
    const TileBounds b = boundsOf(tileAtPoint((west + east) / 2, equator_most, layout.zoom));
    if ((b.east - b.west) / mosaic.pixel_size <= block_pixels && (b.north - b.south) / mosaic.pixel_size <= block_pixels) {
      break;
    }
  }
  const std::int32_t z = layout.zoom;
  const TileKey nw = tileAtPoint(west, north, z), se = tileAtPoint(east, south, z);
  const std::int64_t x_first = std::min(nw.x, se.x), x_last = std::max(nw.x, se.x);
  const std::int64_t y_first = std::min(nw.y, se.y), y_last = std::max(nw.y, se.y);
  // Column borders at the tiles' west edges, row borders at their north (local: south) edges.
  const auto columnOf = [&](double x) { return pixelColumnOf(mosaic, x); };
  const auto rowOf = [&](double y) { return pixelRowOf(mosaic, y); };
  const auto xOf = [&](double col) { return mosaic.origin_x + (col + 0.5) * mosaic.pixel_size; };
  const auto yOf = [&](double row) { return mosaic.origin_y - (row + 0.5) * mosaic.pixel_size; };
  layout.columns = tileBorders(
      mosaic.width, [&](std::int64_t x) { return boundsOf({z, static_cast<std::int32_t>(x), nw.y}).west; }, columnOf,
      xOf, x_first + 1, x_last);
  if (kind == TileSchemeKind::Local) {
    // Rows from the south: walking north to south, tile y_last - k's south edge.
    layout.rows = tileBorders(
        mosaic.height, [&](std::int64_t k) { return boundsOf({z, nw.x, static_cast<std::int32_t>(y_last - k)}).south; },
        rowOf, yOf, 0, y_last - y_first - 1);
  } else {
    layout.rows = tileBorders(
        mosaic.height, [&](std::int64_t y) { return boundsOf({z, nw.x, static_cast<std::int32_t>(y)}).north; }, rowOf,
        yOf, y_first + 1, y_last);
  }
  layout.grid.cols = layout.columns.borders;
  layout.grid.rows = layout.rows.borders;
  for (std::size_t j = 0; j < layout.grid.rowCount(); ++j) {
    for (std::size_t i = 0; i < layout.grid.columnCount(); ++i) {
      const double col = 0.5 * static_cast<double>(layout.grid.cols[i] + layout.grid.cols[i + 1]);
      const double row = 0.5 * static_cast<double>(layout.grid.rows[j] + layout.grid.rows[j + 1]);
      layout.keys.push_back(tileAtPoint(mosaic.origin_x + (col + 0.5) * mosaic.pixel_size,
                                        mosaic.origin_y - (row + 0.5) * mosaic.pixel_size, z));
    }
  }
  return layout;
}

// The largest side of the ECEF box of the scheme box `b` (degrees for the web schemes, CRS
// units for local) between two heights, sampled on 17 x 17 points and grown by the most a
// chord between neighbouring samples can bow out (the box of a curved surface), in metres.
double ecefExtent(TileSchemeKind kind, const CrsToWgs84* to_wgs84, TileBounds b, double low_m, double high_m) {
  constexpr int n = 17;
  std::vector<GeodeticPoint> points;
  std::vector<CrsPoint> crs;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const double x = b.west + (b.east - b.west) * i / (n - 1), y = b.south + (b.north - b.south) * j / (n - 1);
      if (kind == TileSchemeKind::Local) {
        crs.push_back({x, y});
      } else {
        points.push_back({x, y, 0});
      }
    }
  }
  if (kind == TileSchemeKind::Local) {
    points.resize(crs.size());
    to_wgs84->transform(crs, points);
  }
  std::vector<GeodeticPoint> both;
  for (const double h : {low_m, high_m}) {
    for (GeodeticPoint p : points) {
      p.height_m = h;
      both.push_back(p);
    }
  }
  std::vector<EcefPoint> ecef(both.size());
  geodeticToEcef(both, ecef);
  EcefPoint lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const EcefPoint& p : ecef) {
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  // Neighbouring samples: at most the box's diagonal / (n - 1) apart on the Earth; a chord of
  // length L bows L^2 / 8R from the sphere, a sphere cap between samples at most as much.
  const double diagonal = std::hypot(hi.x - lo.x, hi.y - lo.y, hi.z - lo.z);
  const double spacing = std::min(diagonal, 2 * 6378137.0 * std::numbers::pi / 2) / (n - 1) * 2;
  const double bow = spacing * spacing / (8 * 6356752.0) + 1.0;
  return std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}) + 2 * bow;
}

// Per zoom, the Draco grid its tiles share (BuildOptions::position_step_m, or a power-of-two
// multiple where its tiles are too wide for 2^23 steps): from the ECEF size of three by three
// of its tiles (a tile's content reaches at most one tile past its square: the finer level's
// clusters come from partitions of tile neighbourhoods) or of the data, the smaller; known
// before any tile is made, so every block snaps alike.
std::map<std::int32_t, double> zoomSteps(const BuildOptions& options, const DemMosaic& mosaic, const TileFrame& frame,
                                         const TileBounds& data_box, std::int32_t min_zoom, std::int32_t max_zoom,
                                         double low_m, double high_m) {
  const TileSchemeKind kind = options.scheme;
  std::unique_ptr<CrsToWgs84> to_wgs84;
  if (kind == TileSchemeKind::Local) to_wgs84 = std::make_unique<CrsToWgs84>(mosaic.crs_wkt);
  const double data_extent = ecefExtent(kind, to_wgs84.get(), data_box, low_m, high_m);
  std::map<std::int32_t, double> steps;
  for (std::int32_t zoom = min_zoom; zoom <= max_zoom; ++zoom) {
    double widest = 0;
    // The tiles of the zoom nearest the equator (web) or at the data's corners and centre
    // (local) are the widest; three by three around them.
    std::vector<std::array<double, 2>> at;
    const double lat = kind == TileSchemeKind::Local ? (data_box.south + data_box.north) / 2
                                                     : std::clamp(0.0, data_box.south, data_box.north);
    at.push_back({(data_box.west + data_box.east) / 2, lat});
    if (kind == TileSchemeKind::Local) {
      at.push_back({data_box.west, data_box.south});
      at.push_back({data_box.east, data_box.north});
      at.push_back({data_box.west, data_box.north});
      at.push_back({data_box.east, data_box.south});
    }
    for (const auto& p : at) {
      const TileKey key = frame.tileAt(p, zoom);
      TileBounds b = kind == TileSchemeKind::Local ? tileBounds(frame.local(), key) : tileBoundsDeg(kind, key);
      const double w = b.east - b.west, h = b.north - b.south;
      b = {b.west - w, b.south - h, b.east + w, b.north + h};
      if (kind != TileSchemeKind::Local) {
        const double limit = kind == TileSchemeKind::WebMercator ? kWebMercatorMaxLatitudeDeg : 90.0;
        b.south = std::max(b.south, -limit);
        b.north = std::min(b.north, limit);
        if (b.east - b.west > 360) b.west = -180, b.east = 180;
      }
      widest = std::max(widest, ecefExtent(kind, to_wgs84.get(), b, low_m, high_m));
    }
    steps[zoom] = sharedPositionStep(std::min(widest, data_extent), options.position_step_m, kMaxExactPositionBits);
  }
  return steps;
}

// A unit normal at pixel (col, row) of `globe` from its four neighbours' DEM points (one side
// where a neighbour is missing or nodata; the ellipsoid normal where both are): what two blocks
// that share the pixel both compute, from the same pixels, for a vertex on their border.
FloatNormal pixelNormal(const DemOnGlobe& globe, std::int32_t col, std::int32_t row) {
  const DemGrid& dem = globe.dem();
  const auto valid = [&](std::int32_t c, std::int32_t r) {
    return c >= 0 && r >= 0 && c < dem.width && r < dem.height && dem.isValid(c, r);
  };
  const auto span = [&](std::int32_t c0, std::int32_t r0, std::int32_t c1, std::int32_t r1) {
    const std::int32_t ca = valid(c0, r0) ? c0 : col, ra = valid(c0, r0) ? r0 : row;
    const std::int32_t cb = valid(c1, r1) ? c1 : col, rb = valid(c1, r1) ? r1 : row;
    const EcefPoint a = globe.point(ca, ra), b = globe.point(cb, rb);
    return EcefPoint{b.x - a.x, b.y - a.y, b.z - a.z};
  };
  const EcefPoint east = span(col - 1, row, col + 1, row), south = span(col, row - 1, col, row + 1);
  // east x south points down (rows go south): north x east points up.
  EcefPoint n{south.y * east.z - south.z * east.y, south.z * east.x - south.x * east.z,
              south.x * east.y - south.y * east.x};
  double length = std::sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
  if (length == 0) {
    const UnitVector up = globe.up(col, row);
    return {static_cast<float>(up[0]), static_cast<float>(up[1]), static_cast<float>(up[2])};
  }
  const UnitVector up = globe.up(col, row);
  if (n.x * up[0] + n.y * up[1] + n.z * up[2] < 0) length = -length;
  return {static_cast<float>(n.x / length), static_cast<float>(n.y / length), static_cast<float>(n.z / length)};
}

// One zoom to write: a level mesh, its tiles, and per vertex the grid it snaps to.
struct ZoomToWrite {
  std::int32_t zoom = 0;
  std::size_t clusters = 0;
  const TinMesh* mesh = nullptr;
  std::vector<PyramidTile> tiles;
  std::vector<double> vertex_step;  // per vertex of mesh, a multiple of step
  double step = 0;                  // the zoom's own grid
};

// What a zoom's tiles added up to, over blocks and the rest.
struct ZoomTally {
  std::size_t clusters = 0, tiles = 0, vertices = 0, triangles = 0, tile_triangles = 0, bytes = 0;
  double max_error_m = 0, sum_squares = 0;
  std::size_t drawn_pixels = 0;
  int position_bits = 0;
  double step = 0;
  void add(const ZoomTally& other) {
    clusters += other.clusters;
    tiles += other.tiles;
    vertices += other.vertices;
    triangles += other.triangles;
    tile_triangles += other.tile_triangles;
    bytes += other.bytes;
    max_error_m = std::max(max_error_m, other.max_error_m);
    sum_squares += other.sum_squares;
    drawn_pixels += other.drawn_pixels;
    position_bits = std::max(position_bits, other.position_bits);
    step = other.step;
  }
};

// A tile's drawn triangles as the next coarser zoom measures against them (its grid positions
// in mosaic pixels).
struct DrawnTriangles {
  std::vector<EcefPoint> positions;
  std::vector<GridCorner> grid;
  std::vector<std::uint32_t> triangle_indices;
  double shift_m = 0;
};

// DrawnTriangles in a block file (the handover's and the strips' spill file alike).
void putDrawnTriangles(RecordWriter& out, const DrawnTriangles& t) {
  out.putArray(t.positions);
  out.putArray(t.grid);
  out.putArray(t.triangle_indices);
  out.put(t.shift_m);
}

DrawnTriangles getDrawnTriangles(RecordReader& in) {
  DrawnTriangles t;
  t.positions = in.getArray<EcefPoint>();
  t.grid = in.getArray<GridCorner>();
  t.triangle_indices = in.getArray<std::uint32_t>();
  t.shift_m = in.get<double>();
  return t;
}

// A tile's error over the strips it was measured in.
struct DrawTileMeasureSum {
  double max_error_m = 0, finer_difference_m = 0;
};

struct WrittenZooms {
  std::map<std::int32_t, ZoomTally> tallies;
  std::vector<TileNode> nodes;
  std::vector<DrawnTriangles> coarsest;  // the last zoom's tiles, when asked for
};

// Snaps each vertex of `zoom` (placed in `snapped`) to its own grid (ZoomToWrite::vertex_step);
// returns the coarsest step, the zoom's own included.
double snapToVertexSteps(const ZoomToWrite& zoom, std::vector<EcefPoint>& snapped) {
  double largest_step = zoom.step;
  for (std::size_t v = 0; v < snapped.size(); ++v) {
    const double step = zoom.vertex_step[v];
    largest_step = std::max(largest_step, step);
    EcefPoint& p = snapped[v];
    p = {snapToStep(p.x, step), snapToStep(p.y, step), snapToStep(p.z, step)};
  }
  return largest_step;
}

// Draws, measures, encodes and writes `zooms` (finest first) against `globe`: as the whole
// build does, each tile's error against the DEM pixels under it and against the next finer
// zoom's drawn surface (for the first zoom: `finer_surface`, when not null; taken). `normals_fix` may replace
// level normals (blocks: their border vertices'). `keep_coarsest`: the last zoom's drawn
// triangles are returned, grid positions moved by (col0, row0) into the mosaic's pixels.
WrittenZooms writeZooms(std::vector<ZoomToWrite>& zooms, const DemOnGlobe& globe, ZoomSurface* finer_surface,
                        const GlbOptions& glb_base, bool implicit_tiling, OutputDirectory& output,
                        const std::function<void(const TinMesh&, std::vector<FloatNormal>&)>& normals_fix,
                        bool keep_coarsest, std::int64_t col0, std::int64_t row0) {
  WrittenZooms out;
  const DemGrid& dem = globe.dem();
  const PixelBoxes boxes(globe);
  tbb::enumerable_thread_specific<ContentScratch> content_scratch;
  // Two surfaces in turn: the zoom's own and the finer one's (the first zoom's finer one is
  // `finer_surface`, whose memory then serves the second zoom).
  std::array<ZoomSurface, 2> surfaces;
  const ZoomSurface* finer = nullptr;
  if (finer_surface) {
    surfaces[1] = std::move(*finer_surface);
    finer = &surfaces[1];
  }
  for (std::size_t k = 0; k < zooms.size(); ++k) {
    ZoomToWrite& zoom = zooms[k];
    const TinMesh& mesh = *zoom.mesh;
    std::vector<EcefPoint> snapped(mesh.vertices.size());
    globe.place(mesh.vertices, {}, snapped);
    std::vector<FloatNormal> normals = levelNormals(mesh, snapped);
    if (normals_fix) normals_fix(mesh, normals);
    const double largest_step = snapToVertexSteps(zoom, snapped);
    const PlaceVertices snapped_of = placedFrom(snapped);
    const double shift_m = 0.87 * largest_step;
    ZoomSurface& surface = surfaces[k % 2];
    if (surface.empty()) {
      surface = ZoomSurface(dem.pixelCount());
    } else {
      surface.clear();
    }
    GlbOptions glb = glb_base;
    glb.position_step_m = zoom.step;
    struct Encoded {
      std::vector<std::uint8_t> glb;
      Region region;
      DrawnTileMeasure measure;
      int position_bits = 0;
      DrawnTriangles kept;
    };
    std::vector<Encoded> encoded(zoom.tiles.size());
    std::vector<std::size_t> order(encoded.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
      return zoom.tiles[i].triangleCount() > zoom.tiles[j].triangleCount();
    });
    const bool keep = keep_coarsest && k + 1 == zooms.size();
    forEachLargestFirst(order, [&](std::size_t i) {
      DrawnContent content = drawnContent(zoom.tiles[i], mesh, snapped_of, normals, globe, content_scratch.local());
      Encoded& e = encoded[i];
      e.measure = measureDrawnTile(globe, content.positions, content.grid, content.triangle_indices, shift_m, finer,
                                   &surface, {}, &boxes);
      e.region = drawnRegion(content.positions, content.triangle_indices);
      e.glb = encodeContent(content, glb, &e.position_bits);
      if (keep) {
        for (GridCorner& g : content.grid) {
          g.col += static_cast<double>(col0);
          g.row += static_cast<double>(row0);
        }
        e.kept = {std::move(content.positions), std::move(content.grid), std::move(content.triangle_indices), shift_m};
      }
    });
    ZoomTally& tally = out.tallies[zoom.zoom];
    tally.step = zoom.step;
    tally.clusters = zoom.clusters;
    tally.tiles = zoom.tiles.size();
    tally.vertices = mesh.vertices.size();
    tally.triangles = mesh.triangleCount();
    for (std::size_t i = 0; i < encoded.size(); ++i) {
      Encoded& e = encoded[i];
      const PyramidTile& tile = zoom.tiles[i];
      tally.tile_triangles += tile.triangleCount();
      tally.bytes += output.writeFile(contentUri(tile.key, implicit_tiling), e.glb);
      tally.max_error_m = std::max(tally.max_error_m, e.measure.max_error_m);
      tally.position_bits = std::max(tally.position_bits, e.position_bits);
      TileNode node;
      node.key = tile.key;
      node.content_uri = contentUri(tile.key, implicit_tiling);
      node.region = e.region;
      node.geometric_error_m = roundUpToMicrometre(std::max(e.measure.max_error_m, e.measure.finer_difference_m));
      out.nodes.push_back(std::move(node));
      if (keep) out.coarsest.push_back(std::move(e.kept));
    }
    for (std::size_t p = 0; p < dem.pixelCount(); ++p) {
      if (!surface.drawn(p)) continue;
      tally.sum_squares += surface.error(p) * surface.error(p);
      ++tally.drawn_pixels;
    }
    finer = &surface;
  }
  return out;
}

// The mosaic rows of the candidate pixels of a tile's triangles (LatticeRows::box); {max, -1}
// for none.
std::array<std::int64_t, 2> candidateRows(const LatticeRows& rows, const std::vector<EcefPoint>& positions,
                                          const std::vector<GridCorner>& grid,
                                          const std::vector<std::uint32_t>& indices, double shift_m) {
  std::array<std::int64_t, 2> span{std::numeric_limits<std::int64_t>::max(), -1};
  for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
    const DrawnTriangle triangle(positions[indices[t]], positions[indices[t + 1]], positions[indices[t + 2]]);
    if (triangle.degenerate()) continue;
    const PixelBox box =
        rows.box({grid[indices[t]], grid[indices[t + 1]], grid[indices[t + 2]]}, triangle.longestEdge(), shift_m);
    if (box.row1 < box.row0) continue;
    span = {std::min<std::int64_t>(span[0], box.row0), std::max<std::int64_t>(span[1], box.row1)};
  }
  return span;
}

// Drawn triangles kept in a file until the strips that measure them (the blocks' tiles of the
// zoom below the joined ones: otherwise the largest thing the coarse zooms hold), each with the
// mosaic rows of its candidate pixels. load() may run on several threads at once. The file
// goes when this does.
class SpilledTiles {
 public:
  explicit SpilledTiles(std::filesystem::path path) : path_(std::move(path)) {
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd_ < 0) fail("cannot create");
  }
  ~SpilledTiles() {
    ::close(fd_);
    std::error_code ec;
    std::filesystem::remove(path_, ec);
  }
  SpilledTiles(const SpilledTiles&) = delete;
  SpilledTiles& operator=(const SpilledTiles&) = delete;

  void add(const DrawnTriangles& t, std::array<std::int64_t, 2> rows) {
    RecordWriter out;
    putDrawnTriangles(out, t);
    for (std::size_t done = 0; done < out.bytes.size();) {
      const ssize_t n = ::pwrite(fd_, out.bytes.data() + done, out.bytes.size() - done, static_cast<off_t>(end_ + done));
      if (n <= 0) fail("cannot write");
      done += static_cast<std::size_t>(n);
    }
    tiles_.push_back({end_, out.bytes.size(), rows});
    end_ += out.bytes.size();
  }
  std::size_t size() const { return tiles_.size(); }
  const std::array<std::int64_t, 2>& rows(std::size_t i) const { return tiles_[i].rows; }
  DrawnTriangles load(std::size_t i) const {
    const Tile& tile = tiles_[i];
    std::string bytes(tile.size, '\0');
    for (std::size_t done = 0; done < bytes.size();) {
      const ssize_t n = ::pread(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(tile.offset + done));
      if (n <= 0) fail("cannot read");
      done += static_cast<std::size_t>(n);
    }
    const std::string path = path_.string();
    RecordReader in{path, bytes};
    DrawnTriangles t = getDrawnTriangles(in);
    in.expectEnd();
    return t;
  }

 private:
  struct Tile {
    std::uint64_t offset = 0, size = 0;
    std::array<std::int64_t, 2> rows;
  };
  [[noreturn]] void fail(const char* what) const {
    throw Error(ErrorCode::Output, path_.string() + ": " + what + " the file of drawn triangles waiting for their strips (" +
                                       std::strerror(errno) + "); expected a writable disk with room for it");
  }
  std::filesystem::path path_;
  int fd_ = -1;
  std::uint64_t end_ = 0;
  std::vector<Tile> tiles_;
};

// The zooms from the blocks' zoom up. Each piece's tiles are drawn on the top stage's globe
// (the whole DEM, or its overview of `overview_factor` pixels a side), encoded and written at
// once (draw), their drawn triangles kept in files in `spill_dir`; then, once that globe is
// gone, every zoom is measured against the DEM strip by strip (measure): each strip of about
// `window_pixels` is read and placed on the globe, and every triangle whose candidate pixels
// (`rows`: the mosaic's LatticeRows) meet it is measured on its pixels, however far the
// triangle reaches past it (`finer_drawn`: the drawn triangles of the zoom below the first,
// the blocks'). A tile's error is the largest over the strips, each pixel measured and counted
// (for the RMS) in its own strip, so the figures are those of a measure on the whole DEM.
// Memory: one strip (28 bytes per pixel), the tiles of one strip and every tile's key and
// region, whatever the mosaic's size.
class CoarseZooms {
 public:
  CoarseZooms(const DemMosaic& mosaic, const GeoidGrid* geoid, const LatticeRows& rows, std::int32_t overview_factor,
              std::filesystem::path spill_dir, const GlbOptions& glb, bool implicit_tiling, OutputDirectory& output)
      : mosaic_(mosaic), geoid_(geoid), rows_(rows), factor_(overview_factor), spill_dir_(std::move(spill_dir)),
        glb_(glb), implicit_tiling_(implicit_tiling), output_(output) {
    if (factor_ > 1) {
      // On an overview, a vertex at a pole is one on a pole row of the mosaic (an overview's
      // rows lie off the poles).
      const auto poleRow = [&](std::int64_t row) {
        const DemGrid line = readDemWindow(mosaic, {0, row, static_cast<std::int32_t>(mosaic.width), 1});
        return DemOnGlobe(line, geoid, nullptr).poleRow(0);
      };
      first_pole_ = poleRow(0);
      last_pole_ = poleRow(mosaic.height - 1);
    }
  }

  // Draws, encodes and writes `zoom`'s tiles (64 at a time), keeping their triangles for
  // measure(); `zoom.tiles` is emptied.
  void draw(ZoomToWrite& zoom, const DemOnGlobe& globe) {
    const TinMesh& mesh = *zoom.mesh;
    std::vector<EcefPoint> snapped(mesh.vertices.size());
    globe.place(mesh.vertices, {}, snapped);
    const std::vector<FloatNormal> normals = levelNormals(mesh, snapped);
    const double shift_m = 0.87 * snapToVertexSteps(zoom, snapped);
    const PlaceVertices snapped_of = placedFrom(snapped);
    GlbOptions glb = glb_;
    glb.position_step_m = zoom.step;
    ZoomTiles& tiles = zooms_[zoom.zoom];
    if (!tiles.spilled) {
      tiles.spilled = std::make_unique<SpilledTiles>(spill_dir_ / ("drawn_zoom_" + std::to_string(zoom.zoom)));
    }
    const std::size_t n = zoom.tiles.size(), before = tiles.keys.size();
    tiles.regions.resize(before + n);
    tiles.measures.resize(before + n);
    ZoomTally& tally = tiles.tally;
    tally.step = zoom.step;
    tally.clusters += zoom.clusters;
    tally.tiles += n;
    tally.vertices += mesh.vertices.size();
    tally.triangles += mesh.triangleCount();
    const std::int64_t height = mosaic_.height;
    constexpr std::size_t kChunk = 64;
    std::vector<DrawnTriangles> kept(kChunk);
    std::vector<std::array<std::int64_t, 2>> spans(kChunk);
    std::vector<std::vector<std::uint8_t>> bytes(kChunk);
    std::vector<int> bits(kChunk);
    for (std::size_t first = 0; first < n; first += kChunk) {
      const std::size_t count = std::min(kChunk, n - first);
      tbb::parallel_for(std::size_t{0}, count, [&](std::size_t j) {
        const std::size_t i = first + j;
        DrawnContent c = drawnContent(zoom.tiles[i], mesh, snapped_of, normals, globe, content_scratch_.local());
        tiles.regions[before + i] = drawnRegion(c.positions, c.triangle_indices);
        bytes[j] = encodeContent(c, glb, &bits[j]);
        if (factor_ > 1) {
          for (GridCorner& g : c.grid) {
            g.col = overviewToMosaic(g.col, factor_);
            g.row = overviewToMosaic(g.row, factor_);
            g.at_pole = (g.row == 0 && first_pole_) || (g.row == static_cast<double>(height - 1) && last_pole_);
          }
        }
        spans[j] = candidateRows(rows_, c.positions, c.grid, c.triangle_indices, shift_m);
        kept[j] = {std::move(c.positions), std::move(c.grid), std::move(c.triangle_indices), shift_m};
      });
      for (std::size_t j = 0; j < count; ++j) {
        const PyramidTile& tile = zoom.tiles[first + j];
        tiles.keys.push_back(tile.key);
        tally.tile_triangles += tile.triangleCount();
        tally.bytes += output_.writeFile(contentUri(tile.key, implicit_tiling_), bytes[j]);
        tally.position_bits = std::max(tally.position_bits, bits[j]);
        tiles.spilled->add(kept[j], spans[j]);
      }
    }
    std::vector<PyramidTile>().swap(zoom.tiles);
  }

  // Every zoom drawn, measured strip by strip: their tallies and tile nodes.
  WrittenZooms measure(const SpilledTiles& finer_drawn, std::int64_t window_pixels, DemStatistics& stats,
                       Progress& progress) {
    WrittenZooms out;
    const std::int64_t width = mosaic_.width, height = mosaic_.height;
    std::vector<ZoomTiles*> zooms;  // finest first
    for (auto it = zooms_.rbegin(); it != zooms_.rend(); ++it) zooms.push_back(&it->second);
    const std::int64_t strip_rows = std::max<std::int64_t>(16, window_pixels / std::max<std::int64_t>(width, 1));
    stats = DemStatistics();
    float low_height = std::numeric_limits<float>::infinity(), high_height = -low_height;
    progress.beginStage("measuring zooms " + std::to_string(zooms_.begin()->first) + " to " +
                            std::to_string(zooms_.rbegin()->first) + " strip by strip (" + std::to_string(strip_rows) +
                            " rows each)",
                        static_cast<std::uint64_t>((height + strip_rows - 1) / strip_rows));
    for (std::int64_t r0 = 0; r0 < height; r0 += strip_rows) {
      const std::int64_t r1 = std::min(height, r0 + strip_rows);
      const DemGrid window =
          readDemWindow(mosaic_, {0, r0, static_cast<std::int32_t>(width), static_cast<std::int32_t>(r1 - r0)});
      for (std::int32_t row = 0; row < window.height; ++row) {
        for (std::int32_t col = 0; col < window.width; ++col) {
          const float h = window.heightAt(col, row);
          if (std::isnan(h)) continue;
          ++stats.valid_pixels;
          low_height = std::min(low_height, h);
          high_height = std::max(high_height, h);
        }
      }
      const DemOnGlobe strip(window, geoid_, nullptr);
      const auto inStrip = [&](const std::array<std::int64_t, 2>& span) { return span[1] >= r0 && span[0] < r1; };
      std::array<ZoomSurface, 2> surfaces{ZoomSurface(window.pixelCount()), ZoomSurface(window.pixelCount())};
      tbb::parallel_for(std::size_t{0}, finer_drawn.size(), [&](std::size_t i) {
        if (!inStrip(finer_drawn.rows(i))) return;
        const DrawnTriangles t = finer_drawn.load(i);
        measureDrawnTileInStrip(strip, r0, rows_, t.positions, t.grid, t.triangle_indices, t.shift_m, nullptr,
                                &surfaces[1]);
      });
      for (std::size_t k = 0; k < zooms.size(); ++k) {
        ZoomSurface& surface = surfaces[k % 2];
        const ZoomSurface& finer = surfaces[(k + 1) % 2];
        if (k > 0) surface.clear();
        ZoomTiles& tiles = *zooms[k];
        const SpilledTiles& spilled = *tiles.spilled;
        tbb::parallel_for(std::size_t{0}, spilled.size(), [&](std::size_t i) {
          if (!inStrip(spilled.rows(i))) return;
          const DrawnTriangles t = spilled.load(i);
          const DrawnTileMeasure m = measureDrawnTileInStrip(strip, r0, rows_, t.positions, t.grid, t.triangle_indices,
                                                             t.shift_m, &finer, &surface);
          DrawTileMeasureSum& sum = tiles.measures[i];
          sum.max_error_m = std::max(sum.max_error_m, m.max_error_m);
          sum.finer_difference_m = std::max(sum.finer_difference_m, m.finer_difference_m);
        });
        for (std::size_t p = 0; p < window.pixelCount(); ++p) {
          if (!surface.drawn(p)) continue;
          tiles.tally.sum_squares += surface.error(p) * surface.error(p);
          ++tiles.tally.drawn_pixels;
        }
      }
      progress.advance();
    }
    progress.endStage();
    if (stats.valid_pixels > 0) {
      stats.min_height_m = low_height;
      stats.max_height_m = high_height;
    }
    for (auto& [zoom, tiles] : zooms_) {
      ZoomTally& tally = tiles.tally;
      for (std::size_t i = 0; i < tiles.keys.size(); ++i) {
        const DrawTileMeasureSum& m = tiles.measures[i];
        tally.max_error_m = std::max(tally.max_error_m, m.max_error_m);
        TileNode node;
        node.key = tiles.keys[i];
        node.content_uri = contentUri(node.key, implicit_tiling_);
        node.region = tiles.regions[i];
        node.geometric_error_m = roundUpToMicrometre(std::max(m.max_error_m, m.finer_difference_m));
        out.nodes.push_back(std::move(node));
      }
      out.tallies[zoom] = tally;
    }
    return out;
  }

 private:
  struct ZoomTiles {
    std::unique_ptr<SpilledTiles> spilled;
    std::vector<TileKey> keys;
    std::vector<Region> regions;
    std::vector<DrawTileMeasureSum> measures;
    ZoomTally tally;
  };
  const DemMosaic& mosaic_;
  const GeoidGrid* geoid_;
  const LatticeRows& rows_;
  std::int32_t factor_;
  std::filesystem::path spill_dir_;
  GlbOptions glb_;
  bool implicit_tiling_;
  OutputDirectory& output_;
  bool first_pole_ = false, last_pole_ = false;
  std::map<std::int32_t, ZoomTiles> zooms_;
  tbb::enumerable_thread_specific<ContentScratch> content_scratch_;
};

// Per vertex of each zoom (finest first), the grid it snaps to: its zoom's own, or where it is
// on a tile outline of its zoom and of the next coarser one (the same vertex, unmoved) the
// coarser one's, down the chain of outlines (what the whole build does). The coarsest zoom's
// outline vertices that live on, unmoved, in `next_level` (the level shown at the zoom below
// it, not written here) take `next_step`.
void chainSteps(std::vector<ZoomToWrite>& zooms, const std::vector<const std::vector<std::uint32_t>*>& index_in_coarser,
                const TinMesh* next_level, double next_step) {
  std::vector<std::uint8_t> coarser_outline;
  for (std::size_t k = zooms.size(); k-- > 0;) {
    ZoomToWrite& zoom = zooms[k];
    const TinMesh& mesh = *zoom.mesh;
    std::vector<std::uint8_t> outline = tileOutlineVertices(mesh, zoom.tiles);
    zoom.vertex_step.assign(mesh.vertices.size(), zoom.step);
    const std::vector<std::uint32_t>* map = index_in_coarser[k];
    const TinMesh* coarser = k + 1 < zooms.size() ? zooms[k + 1].mesh : next_level;
    if (map && coarser) {
      for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
        const std::uint32_t w = (*map)[v];
        if (!outline[v] || w == kRemovedVertex) continue;
        if (k + 1 < zooms.size() && !coarser_outline[w]) continue;
        const GridPoint& here = mesh.vertices[v];
        const GridPoint& there = coarser->vertices[w];
        if (here.col != there.col || here.row != there.row || here.height_m != there.height_m) continue;
        const double inherited = k + 1 < zooms.size() ? zooms[k + 1].vertex_step[w] : next_step;
        zoom.vertex_step[v] = std::max(zoom.step, inherited);
      }
    }
    coarser_outline = std::move(outline);
  }
}

// What a block hands over: its level at Zb in mosaic pixels, and what it wrote.
struct BlockHandover {
  std::size_t column = 0, row = 0;
  PixelWindow window;
  TinMesh level;  // the level shown at Zb, in the window's grid
  std::vector<std::int32_t> inherited;  // per face of `level`: its cluster of the level at Zb + 1
  std::vector<TileKey> cluster_tiles;   // per such cluster: its tile at Zb + 1
  WrittenZooms written;
};

// A piece of the merge tree from Zb up: the level shown at key.zoom over the tile `key`, in the
// top stage's grid (the mosaic's pixels or its overview's), with the clusters it inherited.
struct MergePiece {
  TileKey key;
  TinMesh level;
  std::vector<std::int32_t> inherited;  // per face: its cluster of the level at key.zoom + 1
  std::vector<TileKey> cluster_tiles;   // per such cluster: its tile at key.zoom + 1
  // Where a piece waits until its parent merges it: its key, and how to load it.
  struct Source {
    TileKey key;
    std::function<MergePiece()> load;
  };
};

constexpr char kMergeMagic[8] = {'T', 'T', 'M', 'E', 'R', 'G', 'E', '1'};

void writeMergePieceFile(const MergePiece& piece, const std::string& path) {
  RecordWriter out;
  out.bytes.assign(kMergeMagic, sizeof kMergeMagic);
  out.put(piece.key);
  out.putArray(piece.level.vertices);
  out.putArray(piece.level.triangle_indices);
  out.putArray(piece.inherited);
  out.putArray(piece.cluster_tiles);
  writeRecordFile(path, out.bytes);
}

MergePiece readMergePieceFile(const std::string& path) {
  const std::string bytes = readRecordFile(path);
  RecordReader in{path, bytes};
  in.expectMagic(kMergeMagic);
  MergePiece piece;
  piece.key = in.get<TileKey>();
  piece.level.vertices = in.getArray<GridPoint>();
  piece.level.triangle_indices = in.getArray<std::uint32_t>();
  piece.inherited = in.getArray<std::int32_t>();
  piece.cluster_tiles = in.getArray<TileKey>();
  in.expectEnd();
  return piece;
}

// Up to four pieces as one mesh over `parent`: a vertex two of them share (on their common
// border, locked in both, so at the very same position) becomes one; clusters renumbered.
MergePiece joinPieces(std::vector<MergePiece> children, TileKey parent) {
  MergePiece joined;
  joined.key = parent;
  struct Hash {
    std::size_t operator()(const std::pair<std::uint64_t, std::uint64_t>& p) const {
      return std::hash<std::uint64_t>()(p.first * 0x9e3779b97f4a7c15ull ^ p.second);
    }
  };
  std::unordered_map<std::pair<std::uint64_t, std::uint64_t>, std::uint32_t, Hash> number_of;
  for (MergePiece& child : children) {
    std::vector<std::uint32_t> numbers(child.level.vertices.size());
    for (std::size_t v = 0; v < numbers.size(); ++v) {
      const GridPoint& p = child.level.vertices[v];
      const auto [it, added] = number_of.try_emplace(
          {std::bit_cast<std::uint64_t>(p.col), std::bit_cast<std::uint64_t>(p.row)},
          static_cast<std::uint32_t>(joined.level.vertices.size()));
      if (added) joined.level.vertices.push_back(p);
      numbers[v] = it->second;
    }
    for (const std::uint32_t v : child.level.triangle_indices) joined.level.triangle_indices.push_back(numbers[v]);
    const auto offset = static_cast<std::int32_t>(joined.cluster_tiles.size());
    for (const std::int32_t c : child.inherited) joined.inherited.push_back(offset + c);
    joined.cluster_tiles.insert(joined.cluster_tiles.end(), child.cluster_tiles.begin(), child.cluster_tiles.end());
  }
  return joined;
}

// The level options of the build (as runPipeline sets them) for levels shown from `top_zoom` down.
LevelOptions buildLevelOptions(const BuildOptions& options, const DemOnGlobe& globe, const TileFrame& frame,
                               std::int32_t top_zoom, std::int32_t levels_below, std::vector<std::int32_t> clusters) {
  LevelOptions level_options;
  level_options.globe = &globe;
  level_options.clusters_per_level = std::move(clusters);
  level_options.level_ratio = options.level_ratio;
  level_options.simplifier = options.simplifier;
  level_options.tail_stop = options.tail_stop;
  level_options.measure = false;
  if (options.level_error_growth > 0) {
    level_options.level_error_growth = options.level_error_growth;
    level_options.first_budget_m = options.tin_max_error_m * options.level_error_growth *
                                   std::pow(options.level_error_growth, static_cast<double>(levels_below));
  }
  level_options.seed += static_cast<std::uint32_t>(levels_below);
  if (options.assignment == Assignment::Merge && options.join_tile_clusters) {
    level_options.regroup_clusters = joinTileClusters(frame, top_zoom);
  }
  if (!options.global_partition) level_options.partition_regions = tileRegions(frame, top_zoom);
  return level_options;
}

// Assigns the clusters of levels[0 .. count - 1] (level l shown at top_zoom - l) to tiles.
std::vector<ZoomToWrite> assignZooms(const BuildOptions& options, const TileFrame& frame, const std::vector<Level>& levels,
                                     std::size_t count, std::int32_t top_zoom, std::vector<TileKey>& cluster_tiles,
                                     const std::map<std::int32_t, double>& steps) {
  std::vector<ZoomToWrite> zooms;
  std::vector<TileKey> own;
  for (std::size_t l = 0; l < count; ++l) {
    ZoomToWrite zoom;
    zoom.zoom = top_zoom - static_cast<std::int32_t>(l);
    zoom.clusters = static_cast<std::size_t>(levels[l].partition.cluster_count);
    zoom.mesh = &levels[l].mesh;
    zoom.step = steps.at(zoom.zoom);
    for (TileFaces& tile : assignClusters(frame, levels[l], zoom.zoom, options.assignment, cluster_tiles, own)) {
      PyramidTile t;
      t.key = tile.key;
      t.faces = std::move(tile.faces);
      zoom.tiles.push_back(std::move(t));
    }
    cluster_tiles = std::move(own);
    zooms.push_back(std::move(zoom));
  }
  return zooms;
}


constexpr char kStatsMagic[8] = {'T', 'T', 'B', 'S', 'T', 'A', 'T', '1'};
constexpr char kHandoverMagic[8] = {'T', 'T', 'B', 'U', 'I', 'L', 'D', '1'};

// What the zooms are chosen from: a block's TIN's triangles, scheme box and heights.
struct BlockStats {
  std::uint64_t triangles = 0;
  TileBounds box{1e300, 1e300, -1e300, -1e300};
  double low_m = 1e300, high_m = -1e300;
};

void writeStatsFile(const BlockStats& stats, const std::string& path) {
  RecordWriter out;
  out.bytes.assign(kStatsMagic, sizeof kStatsMagic);
  out.put(stats);
  writeRecordFile(path, out.bytes);
}

BlockStats readStatsFile(const std::string& path) {
  const std::string bytes = readRecordFile(path);
  RecordReader in{path, bytes};
  in.expectMagic(kStatsMagic);
  const auto stats = in.get<BlockStats>();
  in.expectEnd();
  return stats;
}

void writeHandoverFile(const BlockHandover& h, const std::string& path) {
  RecordWriter out;
  out.bytes.assign(kHandoverMagic, sizeof kHandoverMagic);
  out.put(static_cast<std::uint64_t>(h.column));
  out.put(static_cast<std::uint64_t>(h.row));
  out.put(h.window);
  out.putArray(h.level.vertices);
  out.putArray(h.level.triangle_indices);
  out.putArray(h.inherited);
  out.putArray(h.cluster_tiles);
  out.put(static_cast<std::uint64_t>(h.written.tallies.size()));
  for (const auto& [zoom, tally] : h.written.tallies) {
    out.put(zoom);
    out.put(tally);
  }
  out.put(static_cast<std::uint64_t>(h.written.nodes.size()));
  for (const TileNode& node : h.written.nodes) {
    out.put(node.key);
    out.put(node.region);
    out.put(node.geometric_error_m);
  }
  out.put(static_cast<std::uint64_t>(h.written.coarsest.size()));
  for (const DrawnTriangles& t : h.written.coarsest) putDrawnTriangles(out, t);
  writeRecordFile(path, out.bytes);
}

BlockHandover readHandoverFile(const std::string& path, bool implicit_tiling) {
  const std::string bytes = readRecordFile(path);
  RecordReader in{path, bytes};
  in.expectMagic(kHandoverMagic);
  BlockHandover h;
  h.column = in.get<std::uint64_t>();
  h.row = in.get<std::uint64_t>();
  h.window = in.get<PixelWindow>();
  h.level.vertices = in.getArray<GridPoint>();
  h.level.triangle_indices = in.getArray<std::uint32_t>();
  h.inherited = in.getArray<std::int32_t>();
  h.cluster_tiles = in.getArray<TileKey>();
  for (auto n = in.get<std::uint64_t>(); n > 0; --n) {
    const auto zoom = in.get<std::int32_t>();
    h.written.tallies[zoom] = in.get<ZoomTally>();
  }
  for (auto n = in.get<std::uint64_t>(); n > 0; --n) {
    TileNode node;
    node.key = in.get<TileKey>();
    node.region = in.get<Region>();
    node.geometric_error_m = in.get<double>();
    node.content_uri = contentUri(node.key, implicit_tiling);
    h.written.nodes.push_back(std::move(node));
  }
  for (auto n = in.get<std::uint64_t>(); n > 0; --n) h.written.coarsest.push_back(getDrawnTriangles(in));
  in.expectEnd();
  if (h.level.triangle_indices.size() % 3 != 0 || h.inherited.size() != h.level.triangle_indices.size() / 3) in.damaged();
  for (const std::uint32_t v : h.level.triangle_indices) {
    if (v >= h.level.vertices.size()) in.damaged();
  }
  for (const std::int32_t c : h.inherited) {
    if (c < 0 || static_cast<std::size_t>(c) >= h.cluster_tiles.size()) in.damaged();
  }
  return h;
}

// Everything a block's files depend on: a resumed run keeps them only when this is the same.
nlohmann::json blockManifest(const BuildOptions& options, std::int32_t block_pixels) {
  nlohmann::json m;
  m["generator"] = std::string("terratiles ") + kVersion;
  std::vector<std::string> inputs;
  for (const std::string& input : options.inputs) inputs.push_back(std::filesystem::absolute(input).lexically_normal().string());
  m["inputs"] = inputs;
  m["block_pixels"] = block_pixels;
  m["scheme"] = std::string(tileSchemeName(options.scheme));
  m["assign"] = std::string(assignmentName(options.assignment));
  m["tin_max_error_m"] = options.tin_max_error_m;
  m["tile_triangles"] = options.tile_triangles;
  m["clusters_per_tile"] = options.clusters_per_tile;
  m["join_tile_clusters"] = options.join_tile_clusters;
  m["global_partition"] = options.global_partition;
  m["level_ratio"] = options.level_ratio;
  m["simplifier"] = simplifierName(options.simplifier);
  m["tail_stop"] = tailStopName(options.tail_stop);
  m["level_error_growth"] = options.level_error_growth;
  m["heights"] = options.heights == HeightReference::Orthometric ? "orthometric" : "ellipsoidal";
  m["geoid"] = options.geoid_path;
  m["draco"] = options.draco;
  m["implicit"] = options.implicit_tiling;
  m["position_step_m"] = options.position_step_m;
  m["draco_normal_bits"] = options.draco_normal_bits;
  m["draco_speed"] = options.draco_speed;
  return m;
}

}  // namespace

std::int32_t buildBlockPixels(const BuildOptions& options, const DemMosaic& mosaic) {
  if (options.lod != LodMethod::Clusters) return 0;
  const std::int32_t block = options.block_pixels > 0                                   ? options.block_pixels
                             : mosaic.width * mosaic.height > kBuildBlocksAbovePixels ? kBuildBlockPixels
                                                                                      : 0;
  if (block == 0 || (mosaic.width <= block + 2 && mosaic.height <= block + 2)) return 0;
  return block;
}

BuildSummary runBlockedPipeline(const BuildOptions& options, const DemMosaic& mosaic, std::int32_t block_pixels,
                                Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  const auto refuse = [&](const std::string& option) {
    throw Error(ErrorCode::Usage, option + " is not available with blocks yet (the mosaic has " +
                                      std::to_string(mosaic.width) + " x " + std::to_string(mosaic.height) +
                                      " pixels, built in blocks of " + std::to_string(block_pixels) +
                                      "); pass --block-pixels larger than its sides");
  };
  if (!options.constraints.empty()) refuse("--constraints");
  if (options.draco_position_bits > 0) refuse("--draco-position-bits");
  if (options.max_zoom >= 0) refuse("--max-zoom");
  if (options.strip_pixels <= 0) {
    throw Error(ErrorCode::Usage, "--strip-pixels is " + std::to_string(options.strip_pixels) +
                                      ", expected a positive number of pixels per strip (default 16000000)");
  }
  const bool leader = Ranks::rank() == 0;
  const auto ranks = static_cast<std::size_t>(Ranks::size()), rank = static_cast<std::size_t>(Ranks::rank());
  Progress quiet_progress;
  Progress& shown = leader ? progress : quiet_progress;

  std::optional<GeoidGrid> geoid;
  if (options.heights == HeightReference::Orthometric) {
    geoid = readGeoidGrid(options.geoid_path.empty() ? kDefaultGeoidPath : options.geoid_path);
  }
  const GeoidGrid* geoid_grid = geoid ? &*geoid : nullptr;
  const DemGrid frame_grid = mosaicGrid(mosaic);
  const TileBounds extent = mosaicExtent(mosaic);
  const TileFrame frame(options.scheme, frame_grid, &extent);
  const BlockLayout layout = layBlocks(options, mosaic, frame, block_pixels);
  const BlockGrid& grid = layout.grid;
  const std::size_t block_count = grid.blockCount();
  shown.note("blocks: " + std::to_string(grid.columnCount()) + " x " + std::to_string(grid.rowCount()) +
             " tiles of zoom " + std::to_string(layout.zoom) + " (at most " + std::to_string(block_pixels) +
             " pixels a side)" + (ranks > 1 ? " on " + std::to_string(ranks) + " ranks" : std::string()));

  // 0. Rank 0 prepares OUTDIR.blocks: kept for --resume when it holds the same work, else new.
  // It holds the block files and the output's staging directory, which every rank writes into.
  const std::filesystem::path blocks_dir = options.output_dir + ".blocks";
  const std::filesystem::path staging = blocks_dir / "output";
  const nlohmann::json manifest = blockManifest(options, block_pixels);
  std::exception_ptr failure;
  if (leader) {
    try {
      OutputDirectory check_target(options.output_dir, options.force, OutputDirectory::KeptStaging{staging});  // refuses a wrong target first
      prepareBlocksFolder(blocks_dir, manifest.dump(2) + "\n", options.resume, "output", "build", shown);
    } catch (...) {
      failure = std::current_exception();
    }
  }
  Ranks::meet(failure);
  OutputDirectory output(options.output_dir, options.force, OutputDirectory::KeptStaging{staging});
  const auto blockPath = [&](std::size_t i, std::size_t j, const char* kind) {
    return (blocks_dir / ("block_" + std::to_string(j) + "_" + std::to_string(i) + kind)).string();
  };
  std::size_t mine = 0, resumed_tins = 0, resumed_blocks = 0;
  for (std::size_t b = rank; b < block_count; b += ranks) ++mine;

  // 1. Every block's TIN, kept as a file while the zooms are chosen (block b on rank b mod N).
  BlockTinOptions tin_options;
  tin_options.max_error_m = options.tin_max_error_m;
  tin_options.geoid = geoid_grid;
  tin_options.measure = false;
  // Runs `work(i, j, b)` for every block b of this rank (rank b mod N) as a stage of `shown`;
  // the ranks meet after it, so one rank's failure stops them all.
  const auto forMyBlocks = [&](const std::string& stage,
                               const std::function<void(std::size_t, std::size_t, std::size_t)>& work) {
    shown.beginStage(stage + " in " + std::to_string(block_count) + " blocks" +
                         (ranks > 1 ? ", " + std::to_string(mine) + " on rank 0 of " + std::to_string(ranks) : std::string()),
                     mine);
    std::exception_ptr failed;
    try {
      for (std::size_t b = rank; b < block_count; b += ranks) {
        work(b % grid.columnCount(), b / grid.columnCount(), b);
        shown.advance();
      }
      shown.endStage();
    } catch (...) {
      failed = std::current_exception();
    }
    Ranks::meet(failed);
  };
  forMyBlocks("TIN", [&](std::size_t i, std::size_t j, std::size_t) {
    std::error_code ec;
    if (options.resume && (std::filesystem::exists(blockPath(i, j, ".tin"), ec) ||
                           std::filesystem::exists(blockPath(i, j, ".build"), ec))) {
      ++resumed_tins;
      return;
    }
    const BlockTin tin = buildBlockTin(mosaic, grid, i, j, tin_options);
    BlockStats stats;
    if (tin.mesh.triangleCount() > 0) {
      stats.triangles = tin.mesh.triangleCount();
      const DemGrid window = mosaicWindowGrid(mosaic, tin.window);
      TileFrame block_frame(options.scheme, window, &extent);
      layout.follow(block_frame);
      stats.box = schemeBounds(block_frame.toScheme(tin.mesh.vertices));
      for (const GridPoint& p : tin.mesh.vertices) {
        stats.low_m = std::min(stats.low_m, p.height_m);
        stats.high_m = std::max(stats.high_m, p.height_m);
      }
    }
    writeStatsFile(stats, blockPath(i, j, ".stats"));  // before the TIN: a TIN file means both are whole
    writeBlockTinFile(tin, blockPath(i, j, ".tin"));
  });

  // The zooms, from every block's figures (every rank alike).
  std::size_t finest_triangles = 0;
  TileBounds data_box{1e300, 1e300, -1e300, -1e300};
  double low_m = 1e300, high_m = -1e300;
  for (std::size_t j = 0; j < grid.rowCount(); ++j) {
    for (std::size_t i = 0; i < grid.columnCount(); ++i) {
      const BlockStats stats = readStatsFile(blockPath(i, j, ".stats"));
      if (stats.triangles == 0) continue;
      finest_triangles += stats.triangles;
      data_box = {std::min(data_box.west, stats.box.west), std::min(data_box.south, stats.box.south),
                  std::max(data_box.east, stats.box.east), std::max(data_box.north, stats.box.north)};
      low_m = std::min(low_m, stats.low_m);
      high_m = std::max(high_m, stats.high_m);
    }
  }
  if (finest_triangles == 0) {
    throw Error(ErrorCode::Input, options.inputs.front() + ": no triangle can be built: the DEM has no three "
                                  "neighbouring valid pixels; expected a DEM with some contiguous data");
  }
  const ZoomPlan plan = planZooms(frame, data_box, finest_triangles, options.tile_triangles, -1, options.clusters_per_tile);
  // The blocks write zooms Zb + 1 .. max; the rest from Zb up is built from their levels at Zb.
  const std::int32_t block_zoom = layout.zoom;
  if (plan.max_zoom <= block_zoom || block_zoom < plan.min_zoom) {
    // Larger blocks are tiles of coarser zooms: double the side once per zoom too fine.
    const std::int64_t suggested = block_zoom >= plan.max_zoom
                                       ? std::int64_t{block_pixels} << (block_zoom - plan.max_zoom + 1)
                                       : std::int64_t{block_pixels} >> (plan.min_zoom - block_zoom);
    throw Error(ErrorCode::Usage, "blocks of " + std::to_string(block_pixels) + " pixels are tiles of zoom " +
                                      std::to_string(block_zoom) + ", but the zooms are " +
                                      std::to_string(plan.min_zoom) + " to " + std::to_string(plan.max_zoom) +
                                      "; expected blocks of a zoom between them: pass a --block-pixels of about " +
                                      std::to_string(suggested) +
                                      " (or larger than the mosaic's sides)");
  }
  shown.note("zooms " + std::to_string(plan.min_zoom) + " to " + std::to_string(plan.max_zoom) + " (" +
             std::string(tileSchemeName(options.scheme)) + "), " + std::to_string(plan.max_zoom - block_zoom) +
             " of them written block by block");
  const double margin_m = options.tin_max_error_m + 200;  // geoid and the surface between vertices
  const std::map<std::int32_t, double> steps =
      zoomSteps(options, mosaic, frame, data_box, plan.min_zoom, plan.max_zoom, low_m - margin_m, high_m + margin_m);
  double top_step = 0;  // the grid of zooms min .. Zb
  for (std::int32_t z = plan.min_zoom; z <= block_zoom; ++z) top_step = std::max(top_step, steps.at(z));
  std::map<std::int32_t, double> top_steps;
  for (std::int32_t z = plan.min_zoom; z <= block_zoom; ++z) top_steps[z] = top_step;

  GlbOptions glb;
  glb.draco = options.draco;
  glb.normal_bits = options.draco_normal_bits;
  glb.encoding_speed = options.draco_speed;
  glb.generator = std::string("terratiles ") + kVersion;

  // 2. Every block's levels down to Zb, its tiles of the zooms below Zb written, what it hands
  // over kept as a file (written last: one that exists is whole, and so are the block's tiles).
  const auto block_levels = static_cast<std::size_t>(plan.max_zoom - block_zoom);
  forMyBlocks("levels and tiles", [&](std::size_t i, std::size_t j, std::size_t b) {
    std::error_code ec;
    if (options.resume && std::filesystem::exists(blockPath(i, j, ".build"), ec)) {
      ++resumed_blocks;
      return;
    }
    BlockTin tin = readBlockTinFile(blockPath(i, j, ".tin"));
    BlockHandover handover;
    handover.column = i;
    handover.row = j;
    handover.window = tin.window;
    if (tin.mesh.triangleCount() > 0) {
      const BlockGround ground = readBlock(mosaic, grid, i, j, geoid_grid);
      TileFrame block_frame(options.scheme, ground.dem, &extent);
      layout.follow(block_frame);
      block_frame.keepInside(layout.keys[b]);
      const TileBounds box = schemeBounds(block_frame.toScheme(tin.mesh.vertices));
      std::vector<std::int32_t> clusters;
      for (std::int32_t z = plan.max_zoom; z > block_zoom; --z) {
        clusters.push_back(options.clusters_per_tile *
                           static_cast<std::int32_t>(block_frame.tilesIntersecting(box, z).size()));
      }
      LevelOptions level_options = buildLevelOptions(options, *ground.globe, block_frame, plan.max_zoom, 0, clusters);
      level_options.coarser_levels = static_cast<std::int32_t>(block_levels);
      std::vector<Level> levels = buildBlockLevels(ground, std::move(tin), level_options);
      if (levels.size() != block_levels + 1) {
        throw Error(ErrorCode::Internal, "block " + std::to_string(i) + ", " + std::to_string(j) + " made " +
                                             std::to_string(levels.size()) + " levels; expected " +
                                             std::to_string(block_levels + 1));
      }
      std::vector<TileKey> cluster_tiles;
      std::vector<ZoomToWrite> zooms =
          assignZooms(options, block_frame, levels, block_levels, plan.max_zoom, cluster_tiles, steps);
      std::vector<const std::vector<std::uint32_t>*> maps;
      for (std::size_t l = 0; l < block_levels; ++l) maps.push_back(&levels[l].index_in_coarser);
      chainSteps(zooms, maps, &levels[block_levels].mesh, top_step);
      // A vertex on the block's outline is shared with the neighbouring block: its normal
      // from the pixels around it, which both blocks hold.
      const PixelWindow& window = ground.window;
      const double c0 = static_cast<double>(grid.cols[i] - window.col0), c1 = static_cast<double>(grid.cols[i + 1] - window.col0);
      const double r0 = static_cast<double>(grid.rows[j] - window.row0), r1 = static_cast<double>(grid.rows[j + 1] - window.row0);
      const DemOnGlobe& globe = *ground.globe;
      const auto fixNormals = [&](const TinMesh& mesh, std::vector<FloatNormal>& normals) {
        for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
          const GridPoint& p = mesh.vertices[v];
          const bool on_column = (p.col == c0 || p.col == c1) && p.row == std::round(p.row);
          const bool on_row = (p.row == r0 || p.row == r1) && p.col == std::round(p.col);
          if (on_column || on_row) {
            normals[v] = pixelNormal(globe, static_cast<std::int32_t>(p.col), static_cast<std::int32_t>(p.row));
          }
        }
      };
      handover.written = writeZooms(zooms, globe, nullptr, glb, options.implicit_tiling, output, fixNormals, true,
                                    window.col0, window.row0);
      Level& last = levels[block_levels];
      handover.level = std::move(last.mesh);
      handover.inherited = std::move(last.inherited_partition.cluster_of_face);
      handover.cluster_tiles = std::move(cluster_tiles);
    }
    writeHandoverFile(handover, blockPath(i, j, ".build"));
    std::filesystem::remove(blockPath(i, j, ".tin"), ec);
  });
  if (!leader) return {};
  std::string blocks_said = std::to_string(block_count) + " (" + std::to_string(grid.columnCount()) + " x " +
                           std::to_string(grid.rowCount()) + " tiles of zoom " + std::to_string(block_zoom) +
                           ", at most " + std::to_string(block_pixels) + " px a side" +
                           (ranks > 1 ? ", on " + std::to_string(ranks) + " ranks" : std::string()) + ") wrote zooms " +
                           std::to_string(block_zoom + 1) + " to " + std::to_string(plan.max_zoom) +
                           (resumed_tins > 0 ? "; resumed: of rank 0's " + std::to_string(mine) + " blocks, " +
                                                   std::to_string(resumed_tins) + " had their TIN and " +
                                                   std::to_string(resumed_blocks) + " their levels and tiles already"
                                             : std::string());
  progress.note("blocks: " + blocks_said);

  // The DEM on the globe while the coarse levels are simplified under their budgets and their
  // tiles' contents made, let go before they are measured strip by strip: the whole DEM, or
  // when it has more than --overview-pixels its overview (the levels then live on the
  // overview's grid until their contents go back to the mosaic's pixels to be measured).
  if (options.overview_pixels <= 0) {
    throw Error(ErrorCode::Usage, "--overview-pixels is " + std::to_string(options.overview_pixels) +
                                      ", expected a positive number of pixels (default 4000000)");
  }
  const std::int32_t factor = overviewFactor(mosaic, options.overview_pixels);
  const std::string top_zooms = "zooms " + std::to_string(plan.min_zoom) + " to " + std::to_string(block_zoom);
  std::optional<DemGrid> dem_storage;
  const DemGrid dem_header = mosaicGrid(mosaic);
  // What the strips need to know of rows outside them (from the whole globe or the overview's strips).
  LatticeRows lattice_rows(static_cast<std::int32_t>(mosaic.width), mosaic.height);
  DemGrid top_grid = dem_header;  // the grid the levels live on, without heights
  if (factor == 1) {
    dem_storage = readDem(mosaic, "reading the DEM for " + top_zooms, progress);
  } else {
    progress.beginStage("reading the DEM's overview (1 pixel of " + std::to_string(factor) + " x " +
                            std::to_string(factor) + ") for " + top_zooms,
                        static_cast<std::uint64_t>(overviewStrips(mosaic, factor, options.strip_pixels)));
    dem_storage = readDemOverview(mosaic, factor, options.strip_pixels, &progress,
                                  [&](const DemGrid& strip, std::int64_t first_row) {
                                    lattice_rows.collect(DemOnGlobe(strip, geoid_grid, nullptr), first_row);
                                  });
    lattice_rows.finish();
    progress.endStage();
    top_grid.width = dem_storage->width;
    top_grid.height = dem_storage->height;
    top_grid.pixel_size_x = dem_storage->pixel_size_x;
    top_grid.pixel_size_y = dem_storage->pixel_size_y;
  }
  const DemGrid& dem = *dem_storage;
  std::optional<DemOnGlobe> globe_storage;
  globe_storage.emplace(dem, geoid_grid, &progress);
  const DemOnGlobe& globe = *globe_storage;
  if (factor == 1) {
    lattice_rows.collect(globe, 0);
    lattice_rows.finish();
  }
  // 3. What the blocks wrote (tallies, tile nodes, their tiles at Zb + 1, which the strips
  // measure zoom Zb against), then the rest of the pyramid by 2 x 2 merges: the pieces of a
  // zoom (first the blocks, tiles of Zb) are joined four by four into their parent tile, whose
  // mesh is re-partitioned (the borders between the four move), simplified one level with the
  // parent's outline locked, and its clusters assigned to the four tiles, which are written;
  // the parent's coarser level is the piece of the next zoom, up to the root.
  progress.beginStage("reading what the blocks wrote", block_count);
  SpilledTiles drawn_below(blocks_dir / "drawn_below");  // the blocks' tiles at Zb + 1
  std::map<std::int32_t, ZoomTally> tallies;
  std::map<std::tuple<int, int, int>, TileNode> nodes;
  const auto addNodes = [&](std::vector<TileNode>& list) {
    for (TileNode& node : list) {
      const TileKey key = node.key;
      nodes[{key.zoom, key.y, key.x}] = std::move(node);
    }
  };
  std::vector<MergePiece::Source> pieces;  // of the zoom being merged, ordered by (y, x)
  for (std::size_t b = 0; b < block_count; ++b) {
    const std::size_t i = b % grid.columnCount(), j = b / grid.columnCount();
    BlockHandover h = readHandoverFile(blockPath(i, j, ".build"), options.implicit_tiling);
    for (const auto& [zoom, tally] : h.written.tallies) tallies[zoom].add(tally);
    addNodes(h.written.nodes);
    for (const DrawnTriangles& t : h.written.coarsest) {
      drawn_below.add(t, candidateRows(lattice_rows, t.positions, t.grid, t.triangle_indices, t.shift_m));
    }
    if (h.level.triangleCount() > 0) {
      pieces.push_back({layout.keys[b], [&, i, j, b] {
                          BlockHandover block = readHandoverFile(blockPath(i, j, ".build"), options.implicit_tiling);
                          MergePiece piece;
                          piece.key = layout.keys[b];
                          piece.level = std::move(block.level);
                          for (GridPoint& p : piece.level.vertices) {
                            p.col = mosaicToOverview(static_cast<double>(block.window.col0) + p.col, factor);
                            p.row = mosaicToOverview(static_cast<double>(block.window.row0) + p.row, factor);
                          }
                          piece.inherited = std::move(block.inherited);
                          piece.cluster_tiles = std::move(block.cluster_tiles);
                          return piece;
                        }});
    }
    progress.advance();
  }
  progress.endStage();
  const auto byPlace = [](const MergePiece::Source& p, const MergePiece::Source& q) {
    return std::tie(p.key.y, p.key.x) < std::tie(q.key.y, q.key.x);
  };
  std::sort(pieces.begin(), pieces.end(), byPlace);

  CoarseZooms coarse(mosaic, geoid_grid, lattice_rows, factor, blocks_dir, glb, options.implicit_tiling, output);
  std::size_t merges = 0;  // every piece of every zoom from Zb up
  {
    std::set<std::tuple<int, int, int>> parents;
    for (const MergePiece::Source& piece : pieces) {
      for (std::int32_t z = block_zoom; z >= plan.min_zoom; --z) {
        const int shift = block_zoom - z;
        parents.insert({z, piece.key.y >> shift, piece.key.x >> shift});
      }
    }
    merges = parents.size();
  }
  progress.beginStage("merging the blocks 2 x 2 from zoom " + std::to_string(block_zoom) + " to " +
                          std::to_string(plan.min_zoom),
                      merges);
  for (std::int32_t z = block_zoom;; --z) {
    // A piece's zoom z, assigned to its tiles, and (`coarser`: z is not the root) its level at
    // z - 1, the parent's piece. Pieces are made a batch at a time in parallel (each on its
    // own, so in any order), then written in order.
    struct Made {
      TileKey parent;
      std::vector<Level> levels;
      std::vector<TileKey> cluster_tiles;  // then: those of the level at z's clusters
      std::vector<ZoomToWrite> zooms;
    };
    const bool coarser = z > plan.min_zoom;
    const auto make = [&](MergePiece piece, TileKey parent, Made& made) {
      TileFrame tile_frame(options.scheme, top_grid, &extent);
      layout.follow(tile_frame, factor);
      tile_frame.keepInside(coarser ? parent : piece.key);
      made.parent = parent;
      std::vector<Level>& levels = made.levels;
      const FacePartition inherited{std::move(piece.inherited), static_cast<std::int32_t>(piece.cluster_tiles.size())};
      if (coarser) {
        const TileBounds piece_box = schemeBounds(tile_frame.toScheme(piece.level.vertices));
        const std::size_t tiles = tile_frame.tilesIntersecting(piece_box, z).size();
        LevelOptions level_options =
            buildLevelOptions(options, globe, tile_frame, z, plan.max_zoom - z,
                              {options.clusters_per_tile * static_cast<std::int32_t>(std::max<std::size_t>(tiles, 1))});
        level_options.coarser_levels = 1;
        Progress quiet;
        levels = buildLevels(dem, std::move(piece.level), level_options, {}, quiet);
      } else {
        levels.emplace_back();
        levels[0].mesh = std::move(piece.level);
      }
      levels[0].inherited_partition = inherited;
      if (coarser && levels.size() < 2) {  // too small to split: kept whole, one cluster
        levels[0].partition = {std::vector<std::int32_t>(levels[0].mesh.triangleCount(), 0), 1};
        levels.emplace_back();
        levels[1].mesh = levels[0].mesh;
        levels[1].inherited_partition = levels[0].partition;
      }
      made.cluster_tiles = std::move(piece.cluster_tiles);
      made.zooms = assignZooms(options, tile_frame, levels, 1, z, made.cluster_tiles, top_steps);
      made.zooms[0].vertex_step.assign(made.zooms[0].mesh->vertices.size(), top_step);
    };
    // The pieces of the next zoom: (y, x) of a parent and its children's indices.
    std::map<std::pair<std::int32_t, std::int32_t>, std::vector<std::size_t>> children_of;
    for (std::size_t k = 0; k < pieces.size(); ++k) {
      const int shift = coarser ? 1 : 0;
      children_of[{pieces[k].key.y >> shift, pieces[k].key.x >> shift}].push_back(k);
    }
    const std::vector<std::pair<std::pair<std::int32_t, std::int32_t>, std::vector<std::size_t>>> groups(
        children_of.begin(), children_of.end());
    std::vector<MergePiece::Source> parents;
    constexpr std::size_t kBatch = 8;
    for (std::size_t first = 0; first < groups.size(); first += kBatch) {
      std::vector<Made> batch(std::min(kBatch, groups.size() - first));
      tbb::parallel_for(std::size_t{0}, batch.size(), [&](std::size_t g) {
        const auto& [place, kids] = groups[first + g];
        if (!coarser) {
          make(pieces[kids[0]].load(), pieces[kids[0]].key, batch[g]);
          return;
        }
        const TileKey parent{z - 1, place.second, place.first};
        std::vector<MergePiece> children;
        for (const std::size_t k : kids) children.push_back(pieces[k].load());
        make(joinPieces(std::move(children), parent), parent, batch[g]);
      });
      for (Made& made : batch) {
        coarse.draw(made.zooms[0], globe);
        progress.advance();
        if (!coarser) continue;
        MergePiece up;
        up.key = made.parent;
        up.level = std::move(made.levels[1].mesh);
        up.inherited = std::move(made.levels[1].inherited_partition.cluster_of_face);
        up.cluster_tiles = std::move(made.cluster_tiles);
        const std::string path = (blocks_dir / ("merge_" + std::to_string(up.key.zoom) + "_" + std::to_string(up.key.x) +
                                                "_" + std::to_string(up.key.y)))
                                     .string();
        writeMergePieceFile(up, path);
        parents.push_back({up.key, [path] { return readMergePieceFile(path); }});
        made = Made();
      }
    }
    if (!coarser) break;
    pieces = std::move(parents);  // ordered by (y, x), as the groups
  }
  progress.endStage();
  globe_storage.reset();
  dem_storage.reset();
  returnFreedMemory();
  DemStatistics stats;
  WrittenZooms top = coarse.measure(drawn_below, options.strip_pixels, stats, progress);
  for (const auto& [zoom, tally] : top.tallies) tallies[zoom] = tally;
  addNodes(top.nodes);

  // The summary and the tileset.
  BuildSummary summary;
  summary.output_dir = options.output_dir;
  summary.generator = glb.generator;
  summary.blocks = blocks_said;
  describeInput(summary, dem_header, stats, CrsToWgs84(mosaic.crs_wkt), geoid ? geoid->name : std::string());
  double widest_step_m = 0;
  for (const auto& [zoom, tally] : tallies) {
    ZoomSummary z;
    z.zoom = zoom;
    z.clusters = tally.clusters;
    z.tiles = tally.tiles;
    z.vertices = tally.vertices;
    z.triangles = tally.triangles;
    z.tile_triangles = tally.tile_triangles;
    z.bytes = tally.bytes;
    z.max_error_m = tally.max_error_m;
    z.rms_error_m = tally.drawn_pixels ? std::sqrt(tally.sum_squares / static_cast<double>(tally.drawn_pixels)) : 0.0;
    z.position_step_m = tally.step;
    z.position_bits = tally.position_bits;
    widest_step_m = std::max(widest_step_m, tally.step);
    summary.tiles += z.tiles;
    summary.triangles += z.triangles;
    summary.bytes += z.bytes;
    summary.tile_bytes += z.bytes;
    if (zoom < plan.max_zoom) summary.worst_error_m = std::max(summary.worst_error_m, z.max_error_m);
    summary.zooms.push_back(z);
  }
  summary.position_step_m = steps.at(plan.max_zoom);
  writeTilesetOutput(std::move(nodes), options, mosaic.crs_name, geoid.has_value(), widest_step_m, summary, output,
                     progress);
  if (options.report) {
    progress.note("report: not written for a build in blocks yet; `terratiles check " + options.output_dir +
                  "` checks the output");
  }
  progress.throwIfCancelled();
  progress.beginStage("moving the output into place", 0);
  output.commit();
  std::error_code ec;
  std::filesystem::remove_all(blocks_dir, ec);
  progress.endStage();
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace terratiles
