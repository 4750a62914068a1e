#include "src/tiling/assign_clusters.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <string>

#include "src/base/error.h"
#include "src/geo/crs_transform.h"

namespace terratiles {

Assignment parseAssignment(std::string_view text) {
  if (text == "centroid") return Assignment::Centroid;
  if (text == "duplicate") return Assignment::Duplicate;
  if (text == "merge") return Assignment::Merge;
  throw Error(ErrorCode::Usage, "--assign is '" + std::string(text) + "'; expected merge, duplicate or centroid");
}

std::string_view assignmentName(Assignment assignment) {
  switch (assignment) {
    case Assignment::Centroid: return "centroid";
    case Assignment::Duplicate: return "duplicate";
    case Assignment::Merge: return "merge";
  }
  return "merge";
}

struct TileFrame::ThreadTransforms {
  explicit ThreadTransforms(std::string wkt) : crs_wkt(std::move(wkt)) {}
  std::string crs_wkt;
  tbb::enumerable_thread_specific<std::unique_ptr<CrsToWgs84>> transforms;
  const CrsToWgs84& local() {
    std::unique_ptr<CrsToWgs84>& transform = transforms.local();
    if (!transform) transform = std::make_unique<CrsToWgs84>(crs_wkt);
    return *transform;
  }
};

TileFrame::TileFrame(TileSchemeKind kind, const DemGrid& dem, const TileBounds* local_extent) : kind_(kind), dem_(dem) {
  if (kind == TileSchemeKind::Local) {
    const TileBounds extent = local_extent ? *local_extent
                                           : TileBounds{dem.origin_x, dem.origin_y - dem.height * dem.pixel_size_y,
                                                        dem.origin_x + dem.width * dem.pixel_size_x, dem.origin_y};
    local_ = makeLocalTileScheme(extent);
  } else {
    to_wgs84_ = std::make_unique<CrsToWgs84>(dem.crs_wkt);
    thread_transforms_ = std::make_unique<ThreadTransforms>(dem.crs_wkt);
  }
  // The lattice of approximateTileCoordinates over the pixel centres.
  constexpr int n = kLatticeCells + 1;
  std::vector<GridPoint> points(static_cast<std::size_t>(n) * n);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      points[static_cast<std::size_t>(j * n + i)] = {std::max(0, dem.width - 1) * static_cast<double>(i) / kLatticeCells,
                                                     std::max(0, dem.height - 1) * static_cast<double>(j) / kLatticeCells, 0};
    }
  }
  std::vector<std::array<double, 2>> scheme = toScheme(points);
  if (kind != TileSchemeKind::Local) {
    // Unwrap longitudes along the lattice, so interpolation never runs across the antimeridian.
    const auto unwrap = [](double lon_deg, double near_deg) {
      while (lon_deg - near_deg > 180) lon_deg -= 360;
      while (lon_deg - near_deg < -180) lon_deg += 360;
      return lon_deg;
    };
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        auto& lon = scheme[static_cast<std::size_t>(j * n + i)][0];
        if (i > 0) lon = unwrap(lon, scheme[static_cast<std::size_t>(j * n + i - 1)][0]);
        else if (j > 0) lon = unwrap(lon, scheme[static_cast<std::size_t>((j - 1) * n)][0]);
      }
    }
  }
  lattice_.resize(scheme.size());
  for (std::size_t k = 0; k < scheme.size(); ++k) lattice_[k] = tileCoordinates(scheme[k]);
}

TileFrame::~TileFrame() = default;

void TileFrame::keepInside(TileKey key) {
  inside_ = kind_ == TileSchemeKind::Local ? tileBounds(local_, key) : tileBoundsDeg(kind_, key);
  // A billionth of the tile inside every edge: the scheme's point-to-tile then gives `key` for
  // any point kept inside, whatever its own rounding (webmercator decides in metres).
  const double margin_x = (inside_.east - inside_.west) * 1e-9, margin_y = (inside_.north - inside_.south) * 1e-9;
  inside_ = {inside_.west + margin_x, inside_.south + margin_y, inside_.east - margin_x, inside_.north - margin_y};
  keep_inside_ = true;
}

void TileFrame::followBlocks(std::vector<double> col_lines, std::vector<double> col_values,
                             std::vector<double> row_lines, std::vector<double> row_values) {
  TERRATILES_ASSERT(col_lines.size() >= 2 && col_lines.size() == col_values.size());
  TERRATILES_ASSERT(row_lines.size() >= 2 && row_lines.size() == row_values.size());
  col_lines_ = std::move(col_lines);
  col_values_ = std::move(col_values);
  row_lines_ = std::move(row_lines);
  row_values_ = std::move(row_values);
  follow_blocks_ = true;
}

namespace {

// Linear between the lines around `at` (the first or last two beyond them); a line's own value
// exactly on it.
double betweenLines(const std::vector<double>& lines, const std::vector<double>& values, double at) {
  const auto above = std::upper_bound(lines.begin(), lines.end(), at);
  const auto i = static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(above - lines.begin() - 1, 0,
                                                                     static_cast<std::ptrdiff_t>(lines.size()) - 2));
  if (at == lines[i]) return values[i];
  if (at == lines[i + 1]) return values[i + 1];
  return values[i] + (at - lines[i]) * (values[i + 1] - values[i]) / (lines[i + 1] - lines[i]);
}

}  // namespace

std::vector<std::array<double, 2>> TileFrame::toScheme(std::span<const GridPoint> points) const {
  std::vector<std::array<double, 2>> out;
  if (follow_blocks_) {
    out.resize(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) {
      const double col = static_cast<double>(dem_.col_offset) + points[i].col;
      const double row = static_cast<double>(dem_.row_offset) + points[i].row;
      const double y = betweenLines(row_lines_, row_values_, row);
      out[i] = {betweenLines(col_lines_, col_values_, col), kind_ == TileSchemeKind::Local ? y : insideLatitude(y)};
    }
  } else {
    out = unclampedScheme(points);
  }
  if (keep_inside_) {
    for (auto& p : out) {
      // (A web scheme's longitude is wrapped into [-180, 180) as the tile's edges are.)
      p = {std::clamp(p[0], inside_.west, inside_.east), std::clamp(p[1], inside_.south, inside_.north)};
    }
  }
  return out;
}

std::vector<std::array<double, 2>> TileFrame::unclampedScheme(std::span<const GridPoint> points) const {
  std::vector<std::array<double, 2>> out(points.size());
  if (kind_ == TileSchemeKind::Local) {
    for (std::size_t i = 0; i < points.size(); ++i) {
      const CrsPoint p = dem_.pixelCentre(points[i].col, points[i].row);
      out[i] = {p.x, p.y};
    }
    return out;
  }
  // Blocks in parallel; a transformation of a point does not depend on the others in its
  // call, so the blocks and threads do not change the result.
  constexpr std::size_t kBlock = 16384;
  const auto transformBlock = [&](const CrsToWgs84& transform, std::size_t begin, std::size_t end) {
    std::vector<CrsPoint> crs(end - begin);
    std::vector<GeodeticPoint> geodetic(end - begin);
    for (std::size_t i = begin; i < end; ++i) {
      crs[i - begin] = dem_.pixelCentre(points[i].col, points[i].row);
      geodetic[i - begin].height_m = points[i].height_m;
    }
    transform.transform(crs, geodetic);
    // Web Mercator ends at +-85.0511 deg: data beyond (a global DEM's polar caps) goes to
    // the tiles of the first and last rows, as web maps draw it.
    for (std::size_t i = begin; i < end; ++i) {
      out[i] = {geodetic[i - begin].lon_deg, insideLatitude(geodetic[i - begin].lat_deg)};
    }
  };
  if (points.size() <= 4 * kBlock) {
    transformBlock(*to_wgs84_, 0, points.size());
    return out;
  }
  tbb::parallel_for(std::size_t{0}, (points.size() + kBlock - 1) / kBlock, [&](std::size_t b) {
    transformBlock(thread_transforms_->local(), b * kBlock, std::min(points.size(), (b + 1) * kBlock));
  });
  return out;
}

std::array<double, 2> TileFrame::tileCoordinates(std::array<double, 2> scheme) const {
  switch (kind_) {
    case TileSchemeKind::WebMercator: {
      const double lat_rad = std::clamp(scheme[1], -kWebMercatorMaxLatitudeDeg, kWebMercatorMaxLatitudeDeg) * M_PI / 180;
      return {(scheme[0] + 180) / 360, (1 - std::asinh(std::tan(lat_rad)) / M_PI) / 2};
    }
    case TileSchemeKind::Geographic:
      return {(scheme[0] + 180) / 180, (90 - std::clamp(scheme[1], -90.0, 90.0)) / 180};
    case TileSchemeKind::Local:
      return {(scheme[0] - local_.origin_x_crs) / local_.root_size_crs, (scheme[1] - local_.origin_y_crs) / local_.root_size_crs};
  }
  return {0, 0};
}

std::array<double, 4> TileFrame::approximateTileExtent() const {
  std::array<double, 4> extent{1e300, 1e300, -1e300, -1e300};
  for (const auto& p : lattice_) {
    extent = {std::min(extent[0], p[0]), std::min(extent[1], p[1]), std::max(extent[2], p[0]), std::max(extent[3], p[1])};
  }
  return extent;
}

std::array<double, 2> TileFrame::approximateTileCoordinates(double col, double row) const {
  constexpr int n = kLatticeCells + 1;
  const auto cell = [](double at, int size, int& index) {
    const double t = size > 1 ? std::clamp(at / (size - 1), 0.0, 1.0) * kLatticeCells : 0.0;
    index = std::min(kLatticeCells - 1, static_cast<int>(t));
    return t - index;
  };
  int i = 0, j = 0;
  const double fx = cell(col, dem_.width, i), fy = cell(row, dem_.height, j);
  const auto& a = lattice_[static_cast<std::size_t>(j * n + i)];
  const auto& b = lattice_[static_cast<std::size_t>(j * n + i + 1)];
  const auto& c = lattice_[static_cast<std::size_t>((j + 1) * n + i)];
  const auto& d = lattice_[static_cast<std::size_t>((j + 1) * n + i + 1)];
  std::array<double, 2> out{};
  for (std::size_t k = 0; k < 2; ++k) out[k] = (1 - fy) * ((1 - fx) * a[k] + fx * b[k]) + fy * ((1 - fx) * c[k] + fx * d[k]);
  return out;
}

double TileFrame::insideLatitude(double lat_deg) const {
  const double limit_deg = kind_ == TileSchemeKind::WebMercator ? kWebMercatorMaxLatitudeDeg : 90.0;
  return std::isfinite(lat_deg) ? std::clamp(lat_deg, -limit_deg, limit_deg) : lat_deg;
}

TileKey TileFrame::tileAt(std::array<double, 2> point, std::int32_t zoom) const {
  if (kind_ == TileSchemeKind::Local) {
    // Centroids of clusters are inside the extent; clamp rounding at its edges.
    const TileBounds root = tileBounds(local_, {0, 0, 0});
    return terratiles::tileAt(local_, std::clamp(point[0], root.west, root.east),
                              std::clamp(point[1], root.south, root.north), zoom);
  }
  // The point is one of toScheme's or computed from them (a cluster centroid): its latitude
  // can be past the clamped edge by rounding only (see the class comment).
  return terratiles::tileAt(kind_, point[0], insideLatitude(point[1]), zoom);
}

std::vector<TileKey> TileFrame::tilesIntersecting(const TileBounds& box, std::int32_t zoom) const {
  if (kind_ == TileSchemeKind::Local) return terratiles::tilesIntersecting(local_, box, zoom);
  return terratiles::tilesIntersecting(
      kind_, LonLatBox{box.west, insideLatitude(box.south), box.east, insideLatitude(box.north)}, zoom);
}

namespace {

// The tiles each face's bounding box (in scheme coordinates) shares area with, in blocks of
// kBlock faces, each block its own CSR (joining them into one array held both copies at once:
// SRTM Gabon's assignment peaked about 30 MB higher).
class FaceTiles {
 public:
  FaceTiles(const TileFrame& frame, const TinMesh& mesh, const std::vector<std::array<double, 2>>& scheme,
            std::int32_t zoom) {
    const std::size_t face_count = mesh.triangleCount();
    const auto& idx = mesh.triangle_indices;
    // In parallel blocks of faces (the scheme's functions are pure).
    blocks_.resize((face_count + kBlock - 1) / kBlock);
    tbb::parallel_for(std::size_t{0}, blocks_.size(), [&](std::size_t b) {
      Block& block = blocks_[b];
      const std::size_t first = b * kBlock, last = std::min(face_count, first + kBlock);
      block.end.reserve(last - first);
      block.tiles.reserve((last - first) + (last - first) / 4);
      for (std::size_t f = first; f < last; ++f) {
        TileBounds box{1e300, 1e300, -1e300, -1e300};
        for (std::size_t k = 0; k < 3; ++k) {
          const auto& p = scheme[idx[3 * f + k]];
          box = {std::min(box.west, p[0]), std::min(box.south, p[1]), std::max(box.east, p[0]), std::max(box.north, p[1])};
        }
        for (const TileKey& key : frame.tilesIntersecting(box, zoom)) block.tiles.push_back(key);
        block.end.push_back(static_cast<std::uint32_t>(block.tiles.size()));
      }
      block.tiles.shrink_to_fit();
    });
  }

  // The tiles of face f.
  std::span<const TileKey> of(std::size_t f) const {
    const Block& block = blocks_[f / kBlock];
    const std::size_t i = f % kBlock;
    const std::uint32_t begin = i == 0 ? 0 : block.end[i - 1];
    return {block.tiles.data() + begin, block.end[i] - begin};
  }

 private:
  static constexpr std::size_t kBlock = 4096;
  struct Block {
    std::vector<std::uint32_t> end;  // per face of the block: the end of its tiles in `tiles`
    std::vector<TileKey> tiles;
  };
  std::vector<Block> blocks_;
};

}  // namespace

FacePartition groupClustersByTiles(const TileFrame& frame, const TinMesh& mesh, const FacePartition& partition,
                                   std::int32_t zoom) {
  const std::vector<std::array<double, 2>> scheme = frame.toScheme(mesh.vertices);
  const std::size_t face_count = mesh.triangleCount();
  const auto& idx = mesh.triangle_indices;
  // (y << 32 | x): sorts as (y, x).
  const auto keyOf = [](const TileKey& key) {
    return static_cast<std::uint64_t>(static_cast<std::uint32_t>(key.y)) << 32 | static_cast<std::uint32_t>(key.x);
  };
  constexpr std::size_t kBlock = 16384;
  std::vector<std::uint64_t> vertex_tile(scheme.size());
  tbb::parallel_for(std::size_t{0}, (scheme.size() + kBlock - 1) / kBlock, [&](std::size_t b) {
    for (std::size_t v = b * kBlock; v < std::min(scheme.size(), (b + 1) * kBlock); ++v) {
      vertex_tile[v] = keyOf(frame.tileAt(scheme[v], zoom));
    }
  });
  // A face whose corners lie in one tile lies in it alone (a tile is a rectangle in scheme
  // coordinates; a corner on its edge is where tileAt puts it, and an edge of the face's box
  // on a tile edge does not reach the neighbour), so only faces across tile edges need
  // tilesIntersecting. Those are listed per block, in face order.
  const std::size_t blocks = (face_count + kBlock - 1) / kBlock;
  std::vector<std::vector<std::pair<std::uint32_t, std::uint64_t>>> crossing(blocks);  // (face, tile)
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t b) {
    for (std::size_t f = b * kBlock; f < std::min(face_count, (b + 1) * kBlock); ++f) {
      const std::uint64_t t = vertex_tile[idx[3 * f]];
      if (vertex_tile[idx[3 * f + 1]] == t && vertex_tile[idx[3 * f + 2]] == t) continue;
      TileBounds box{1e300, 1e300, -1e300, -1e300};
      for (std::size_t k = 0; k < 3; ++k) {
        const auto& p = scheme[idx[3 * f + k]];
        box = {std::min(box.west, p[0]), std::min(box.south, p[1]), std::max(box.east, p[0]), std::max(box.north, p[1])};
      }
      for (const TileKey& key : frame.tilesIntersecting(box, zoom)) crossing[b].push_back({static_cast<std::uint32_t>(f), keyOf(key)});
    }
  });
  // Every cluster's tiles, sorted: each cluster remembers the tile it saw last, so a run of
  // its faces in one tile costs one comparison.
  const auto clusters = static_cast<std::size_t>(partition.cluster_count);
  std::vector<std::vector<std::uint64_t>> sets(clusters);
  std::vector<std::uint64_t> last(clusters, ~std::uint64_t{0});
  const auto add = [&](std::size_t cluster, std::uint64_t tile) {
    if (last[cluster] == tile) return;
    last[cluster] = tile;
    auto& set = sets[cluster];
    const auto at = std::lower_bound(set.begin(), set.end(), tile);
    if (at == set.end() || *at != tile) set.insert(at, tile);
  };
  for (std::size_t b = 0; b < blocks; ++b) {
    auto next = crossing[b].begin();
    for (std::size_t f = b * kBlock; f < std::min(face_count, (b + 1) * kBlock); ++f) {
      const auto cluster = static_cast<std::size_t>(partition.cluster_of_face[f]);
      if (next != crossing[b].end() && next->first == f) {
        for (; next != crossing[b].end() && next->first == f; ++next) add(cluster, next->second);
      } else {
        add(cluster, vertex_tile[idx[3 * f]]);
      }
    }
  }
  std::map<std::vector<std::uint64_t>, std::int32_t> group_of_set;
  std::vector<std::int32_t> group_of_cluster(clusters, -1);
  FacePartition grouped;
  grouped.cluster_of_face.resize(partition.cluster_of_face.size());
  for (std::size_t f = 0; f < grouped.cluster_of_face.size(); ++f) {
    const auto cluster = static_cast<std::size_t>(partition.cluster_of_face[f]);
    if (group_of_cluster[cluster] < 0) {
      const auto [it, inserted] = group_of_set.try_emplace(sets[cluster], static_cast<std::int32_t>(group_of_set.size()));
      group_of_cluster[cluster] = it->second;
    }
    grouped.cluster_of_face[f] = group_of_cluster[cluster];
  }
  grouped.cluster_count = static_cast<std::int32_t>(group_of_set.size());
  return grouped;
}

std::vector<std::int32_t> tileNeighbourhoodRegions(const TileFrame& frame, const TinMesh& mesh, std::int32_t zoom) {
  const std::size_t face_count = mesh.triangleCount();
  const auto& idx = mesh.triangle_indices;
  const double tiles = std::ldexp(1.0, zoom);
  // The blocks over the DEM.
  const auto blockAt = [&](double x, double y) {
    const auto tile_x = static_cast<std::int64_t>(std::floor(x * tiles));
    const auto tile_y = static_cast<std::int64_t>(std::floor(y * tiles));
    return std::array<std::int64_t, 2>{(tile_x + 1) >> 1, (tile_y + 1) >> 1};
  };
  const std::array<double, 4> extent = frame.approximateTileExtent();
  const std::array<std::int64_t, 2> low = blockAt(extent[0], extent[1]), high = blockAt(extent[2], extent[3]);
  const std::int64_t columns = high[0] - low[0] + 1;
  std::vector<std::int32_t> region(face_count);
  constexpr std::size_t kBlock = 16384;
  tbb::parallel_for(std::size_t{0}, (face_count + kBlock - 1) / kBlock, [&](std::size_t b) {
    for (std::size_t f = b * kBlock; f < std::min(face_count, (b + 1) * kBlock); ++f) {
      const GridPoint &p = mesh.vertices[idx[3 * f]], &q = mesh.vertices[idx[3 * f + 1]], &r = mesh.vertices[idx[3 * f + 2]];
      const std::array<double, 2> at = frame.approximateTileCoordinates((p.col + q.col + r.col) / 3, (p.row + q.row + r.row) / 3);
      const auto block = blockAt(at[0], at[1]);
      const std::int64_t x = std::clamp(block[0], low[0], high[0]) - low[0];
      const std::int64_t y = std::clamp(block[1], low[1], high[1]) - low[1];
      region[f] = static_cast<std::int32_t>(y * columns + x);
    }
  });
  return region;
}

std::function<std::vector<std::int32_t>(const TinMesh&, std::size_t)> tileRegions(const TileFrame& frame,
                                                                                 std::int32_t max_zoom) {
  return [&frame, max_zoom](const TinMesh& mesh, std::size_t level) {
    return tileNeighbourhoodRegions(frame, mesh, max_zoom - static_cast<std::int32_t>(level));
  };
}

std::function<FacePartition(const TinMesh&, std::size_t, const FacePartition&)> joinTileClusters(
    const TileFrame& frame, std::int32_t max_zoom) {
  return [&frame, max_zoom](const TinMesh& mesh, std::size_t level, const FacePartition& partition) {
    return groupClustersByTiles(frame, mesh, partition, max_zoom - static_cast<std::int32_t>(level) - 1);
  };
}

TileBounds schemeBounds(const std::vector<std::array<double, 2>>& points) {
  TileBounds box{1e300, 1e300, -1e300, -1e300};
  for (const auto& p : points) {
    box.west = std::min(box.west, p[0]);
    box.east = std::max(box.east, p[0]);
    box.south = std::min(box.south, p[1]);
    box.north = std::max(box.north, p[1]);
  }
  return box;
}

ZoomPlan planZooms(const TileFrame& frame, const TinMesh& finest, std::int32_t tile_triangles,
                   std::int32_t forced_max_zoom, std::int32_t clusters_per_tile, std::int32_t forced_min_zoom) {
  return planZooms(frame, schemeBounds(frame.toScheme(finest.vertices)), finest.triangleCount(), tile_triangles,
                   forced_max_zoom, clusters_per_tile, forced_min_zoom);
}

ZoomPlan planZooms(const TileFrame& frame, const TileBounds& box, std::size_t finest_triangles,
                   std::int32_t tile_triangles, std::int32_t forced_max_zoom, std::int32_t clusters_per_tile,
                   std::int32_t forced_min_zoom) {
  if (tile_triangles < 64) {
    throw Error(ErrorCode::Usage, "--tile-triangles is " + std::to_string(tile_triangles) + "; expected at least 64");
  }
  const auto tilesAt = [&](std::int32_t zoom) { return frame.tilesIntersecting(box, zoom).size(); };
  // The finest zoom at which the data fits in at most two tiles: the coarsest zoom worth
  // showing, and the finest one for data that one tile holds.
  std::int32_t fit_zoom = 0;
  while (fit_zoom < 24 && tilesAt(fit_zoom + 1) <= 2) ++fit_zoom;
  ZoomPlan plan;
  if (forced_max_zoom >= 0) {
    plan.max_zoom = forced_max_zoom;
  } else {
    plan.max_zoom = fit_zoom;
    while (plan.max_zoom < 24 &&
           static_cast<double>(finest_triangles) / static_cast<double>(tilesAt(plan.max_zoom)) > tile_triangles) {
      ++plan.max_zoom;
    }
  }
  plan.min_zoom = std::min(forced_min_zoom >= 0 ? forced_min_zoom : fit_zoom, plan.max_zoom);
  for (std::int32_t zoom = plan.max_zoom; zoom > plan.min_zoom; --zoom) {
    plan.clusters_per_level.push_back(clusters_per_tile * static_cast<std::int32_t>(tilesAt(zoom)));
  }
  return plan;
}

std::vector<TileFaces> assignClusters(const TileFrame& frame, const Level& level, std::int32_t zoom,
                                      Assignment assignment, const std::vector<TileKey>& finer_cluster_tiles,
                                      std::vector<TileKey>& own_cluster_tiles) {
  const TinMesh& mesh = level.mesh;
  const std::vector<std::array<double, 2>> scheme = frame.toScheme(mesh.vertices);
  const std::size_t face_count = mesh.triangleCount();
  const auto& idx = mesh.triangle_indices;
  const auto corner = [&](std::size_t f, int k) { return scheme[idx[3 * f + static_cast<std::size_t>(k)]]; };

  const FaceTiles face_tiles(frame, mesh, scheme, zoom);

  // Own clusters: the tile of each one's centroid.
  const FacePartition& own = level.partition;
  own_cluster_tiles.assign(static_cast<std::size_t>(own.cluster_count), TileKey{});
  if (own.cluster_count > 0) {
    std::vector<std::array<double, 3>> sums(static_cast<std::size_t>(own.cluster_count), {0, 0, 0});
    for (std::size_t f = 0; f < face_count; ++f) {
      const auto a = corner(f, 0), b = corner(f, 1), c = corner(f, 2);
      // Area weight, with a floor so that a cluster of slivers still has a centroid.
      const double area = std::fabs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])) + 1e-30;
      auto& sum = sums[static_cast<std::size_t>(own.cluster_of_face[f])];
      sum[0] += area * (a[0] + b[0] + c[0]) / 3;
      sum[1] += area * (a[1] + b[1] + c[1]) / 3;
      sum[2] += area;
    }
    // A cluster whose faces all sit on the clamped Web Mercator edge has zero-area faces
    // (weight 1e-30 each): its mean latitude can round hundreds of ulps past the edge, which
    // frame.tileAt takes back into the first or last row.
    for (std::size_t c = 0; c < sums.size(); ++c) {
      own_cluster_tiles[c] = frame.tileAt({sums[c][0] / sums[c][2], sums[c][1] / sums[c][2]}, zoom);
    }
  }
  // Inherited clusters: the parent of the finer tile that took them.
  const FacePartition& inherited = level.inherited_partition;
  const bool has_own = own.cluster_count > 0;
  const bool has_inherited = inherited.cluster_count > 0 && !finer_cluster_tiles.empty();
  // A single level (no coarser, no finer zoom) has no clusters: faces go by themselves.
  const bool by_face = !has_own && !has_inherited;
  const auto inheritedTile = [&](std::size_t f) {
    return finer_cluster_tiles[static_cast<std::size_t>(inherited.cluster_of_face[f])].parent();
  };
  // Every tile a cluster's faces touch, per cluster of a partition.
  const auto crossedTiles = [&](const FacePartition& clusters) {
    std::vector<std::set<std::pair<std::int32_t, std::int32_t>>> sets(static_cast<std::size_t>(clusters.cluster_count));
    for (std::size_t f = 0; f < face_count; ++f) {
      auto& set = sets[static_cast<std::size_t>(clusters.cluster_of_face[f])];
      for (const TileKey& key : face_tiles.of(f)) set.insert({key.y, key.x});
    }
    std::vector<std::vector<TileKey>> crossed(sets.size());
    for (std::size_t c = 0; c < sets.size(); ++c) {
      for (const auto& [y, x] : sets[c]) crossed[c].push_back({zoom, x, y});
    }
    return crossed;
  };
  std::vector<std::vector<TileKey>> own_crossed, inherited_crossed;
  if (!by_face && assignment == Assignment::Duplicate) {
    if (has_own) own_crossed = crossedTiles(own);
    else inherited_crossed = crossedTiles(inherited);
  }
  if (!by_face && assignment == Assignment::Merge && has_inherited) inherited_crossed = crossedTiles(inherited);
  const auto append = [](std::vector<TileKey>& to, std::span<const TileKey> from) {
    to.insert(to.end(), from.begin(), from.end());
  };

  std::map<std::pair<std::int32_t, std::int32_t>, std::vector<std::uint32_t>> faces_of_tile;  // (y, x)
  std::vector<TileKey> targets;
  for (std::size_t f = 0; f < face_count; ++f) {
    targets.clear();
    if (by_face) {
      append(targets, face_tiles.of(f));
    } else switch (assignment) {
      case Assignment::Centroid:
        targets.push_back(has_own ? own_cluster_tiles[static_cast<std::size_t>(own.cluster_of_face[f])] : inheritedTile(f));
        break;
      case Assignment::Duplicate:
        if (has_own) append(targets, own_crossed[static_cast<std::size_t>(own.cluster_of_face[f])]);
        else append(targets, inherited_crossed[static_cast<std::size_t>(inherited.cluster_of_face[f])]);
        break;
      case Assignment::Merge:
        // The inherited clusters, in every tile they cross:
        // they cover the square (no holes), and every outline edge is a locked border of the
        // finer level, so the outlines of neighbouring zooms are edges of one mesh and meet
        // vertex for vertex. The finest zoom has no inherited clusters: there every face
        // crossing the square is added (its edges are the TIN's own).
        if (has_inherited) {
          append(targets, inherited_crossed[static_cast<std::size_t>(inherited.cluster_of_face[f])]);
        } else {
          append(targets, face_tiles.of(f));
        }
        break;
    }
    std::sort(targets.begin(), targets.end(), [](const TileKey& l, const TileKey& r) {
      return std::tie(l.y, l.x) < std::tie(r.y, r.x);
    });
    targets.erase(std::unique(targets.begin(), targets.end()), targets.end());
    for (const TileKey& key : targets) {
      auto& list = faces_of_tile[{key.y, key.x}];
      list.push_back(static_cast<std::uint32_t>(f));
    }
  }
  std::vector<TileFaces> tiles;
  tiles.reserve(faces_of_tile.size());
  for (auto& [yx, triangles] : faces_of_tile) {
    triangles.shrink_to_fit();  // held until the zoom is written: without the growth's slack
    tiles.push_back({TileKey{zoom, yx.second, yx.first}, std::move(triangles)});
  }
  return tiles;
}

}  // namespace terratiles
