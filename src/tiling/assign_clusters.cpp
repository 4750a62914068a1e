#include "src/tiling/assign_clusters.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
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

TileFrame::TileFrame(TileSchemeKind kind, const DemGrid& dem) : kind_(kind), dem_(dem) {
  if (kind == TileSchemeKind::Local) {
    const TileBounds extent{dem.origin_x, dem.origin_y - dem.height * dem.pixel_size_y,
                            dem.origin_x + dem.width * dem.pixel_size_x, dem.origin_y};
    local_ = makeLocalTileScheme(extent);
  } else {
    to_wgs84_ = std::make_unique<CrsToWgs84>(dem.crs_wkt);
  }
}

TileFrame::~TileFrame() = default;

std::vector<std::array<double, 2>> TileFrame::toScheme(std::span<const GridPoint> points) const {
  std::vector<std::array<double, 2>> out(points.size());
  if (kind_ == TileSchemeKind::Local) {
    for (std::size_t i = 0; i < points.size(); ++i) {
      const CrsPoint p = dem_.pixelCentre(points[i].col, points[i].row);
      out[i] = {p.x, p.y};
    }
    return out;
  }
  std::vector<CrsPoint> crs(points.size());
  std::vector<GeodeticPoint> geodetic(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    crs[i] = dem_.pixelCentre(points[i].col, points[i].row);
    geodetic[i].height_m = points[i].height_m;
  }
  to_wgs84_->transform(crs, geodetic);
  // Web Mercator ends at +-85.0511 deg: data beyond (a global DEM's polar caps) goes to the
  // tiles of the first and last rows, as web maps draw it.
  for (std::size_t i = 0; i < points.size(); ++i) {
    out[i] = {geodetic[i].lon_deg, insideLatitude(geodetic[i].lat_deg)};
  }
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

TileBounds boundsOf(const std::vector<std::array<double, 2>>& points) {
  TileBounds box{1e300, 1e300, -1e300, -1e300};
  for (const auto& p : points) {
    box.west = std::min(box.west, p[0]);
    box.east = std::max(box.east, p[0]);
    box.south = std::min(box.south, p[1]);
    box.north = std::max(box.north, p[1]);
  }
  return box;
}

// The tiles each face's bounding box (in scheme coordinates) shares area with, as CSR.
struct FaceTiles {
  std::vector<std::size_t> offset;
  std::vector<TileKey> tiles;
};

FaceTiles faceTiles(const TileFrame& frame, const TinMesh& mesh, const std::vector<std::array<double, 2>>& scheme,
                    std::int32_t zoom) {
  const std::size_t face_count = mesh.triangleCount();
  const auto& idx = mesh.triangle_indices;
  // In parallel blocks of faces (the scheme's functions are pure), joined in face order.
  constexpr std::size_t kBlock = 4096;
  const std::size_t blocks = (face_count + kBlock - 1) / kBlock;
  std::vector<FaceTiles> parts(blocks);
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t b) {
    FaceTiles& part = parts[b];
    const std::size_t first = b * kBlock, last = std::min(face_count, first + kBlock);
    part.offset.reserve(last - first);
    part.tiles.reserve((last - first) + (last - first) / 4);
    for (std::size_t f = first; f < last; ++f) {
      TileBounds box{1e300, 1e300, -1e300, -1e300};
      for (std::size_t k = 0; k < 3; ++k) {
        const auto& p = scheme[idx[3 * f + k]];
        box = {std::min(box.west, p[0]), std::min(box.south, p[1]), std::max(box.east, p[0]), std::max(box.north, p[1])};
      }
      for (const TileKey& key : frame.tilesIntersecting(box, zoom)) part.tiles.push_back(key);
      part.offset.push_back(part.tiles.size());  // this face's end within the block
    }
  });
  FaceTiles out;
  out.offset.assign(face_count + 1, 0);
  std::size_t total = 0;
  for (const FaceTiles& part : parts) total += part.tiles.size();
  out.tiles.reserve(total);
  for (std::size_t b = 0; b < blocks; ++b) {
    const std::size_t base = out.tiles.size();
    for (std::size_t i = 0; i < parts[b].offset.size(); ++i) out.offset[b * kBlock + i + 1] = base + parts[b].offset[i];
    out.tiles.insert(out.tiles.end(), parts[b].tiles.begin(), parts[b].tiles.end());
  }
  return out;
}

}  // namespace

FacePartition groupClustersByTiles(const TileFrame& frame, const TinMesh& mesh, const FacePartition& partition,
                                   std::int32_t zoom) {
  const FaceTiles face_tiles = faceTiles(frame, mesh, frame.toScheme(mesh.vertices), zoom);
  std::vector<std::set<std::pair<std::int32_t, std::int32_t>>> sets(static_cast<std::size_t>(partition.cluster_count));
  for (std::size_t f = 0; f < mesh.triangleCount(); ++f) {
    auto& set = sets[static_cast<std::size_t>(partition.cluster_of_face[f])];
    for (std::size_t i = face_tiles.offset[f]; i < face_tiles.offset[f + 1]; ++i) {
      set.insert({face_tiles.tiles[i].y, face_tiles.tiles[i].x});
    }
  }
  std::map<std::set<std::pair<std::int32_t, std::int32_t>>, std::int32_t> group_of_set;
  std::vector<std::int32_t> group_of_cluster(sets.size(), -1);
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

std::function<FacePartition(const TinMesh&, std::size_t, const FacePartition&)> joinTileClusters(
    const TileFrame& frame, std::int32_t max_zoom) {
  return [&frame, max_zoom](const TinMesh& mesh, std::size_t level, const FacePartition& partition) {
    return groupClustersByTiles(frame, mesh, partition, max_zoom - static_cast<std::int32_t>(level) - 1);
  };
}

ZoomPlan planZooms(const TileFrame& frame, const TinMesh& finest, std::int32_t tile_triangles,
                   std::int32_t forced_max_zoom, std::int32_t clusters_per_tile) {
  if (tile_triangles < 64) {
    throw Error(ErrorCode::Usage, "--tile-triangles is " + std::to_string(tile_triangles) + "; expected at least 64");
  }
  const TileBounds box = boundsOf(frame.toScheme(finest.vertices));
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
           static_cast<double>(finest.triangleCount()) / static_cast<double>(tilesAt(plan.max_zoom)) > tile_triangles) {
      ++plan.max_zoom;
    }
  }
  plan.min_zoom = std::min(fit_zoom, plan.max_zoom);
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

  const FaceTiles face_tiles_csr = faceTiles(frame, mesh, scheme, zoom);
  const std::vector<std::size_t>& tile_offset = face_tiles_csr.offset;
  const std::vector<TileKey>& face_tiles = face_tiles_csr.tiles;

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
      for (std::size_t i = tile_offset[f]; i < tile_offset[f + 1]; ++i) set.insert({face_tiles[i].y, face_tiles[i].x});
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
  const auto append = [](std::vector<TileKey>& to, const std::vector<TileKey>& from) {
    to.insert(to.end(), from.begin(), from.end());
  };

  std::map<std::pair<std::int32_t, std::int32_t>, std::vector<std::uint32_t>> faces_of_tile;  // (y, x)
  std::vector<TileKey> targets;
  for (std::size_t f = 0; f < face_count; ++f) {
    targets.clear();
    if (by_face) {
      targets.insert(targets.end(), face_tiles.begin() + static_cast<std::ptrdiff_t>(tile_offset[f]),
                     face_tiles.begin() + static_cast<std::ptrdiff_t>(tile_offset[f + 1]));
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
          targets.insert(targets.end(), face_tiles.begin() + static_cast<std::ptrdiff_t>(tile_offset[f]),
                         face_tiles.begin() + static_cast<std::ptrdiff_t>(tile_offset[f + 1]));
        }
        break;
    }
    std::sort(targets.begin(), targets.end(), [](const TileKey& l, const TileKey& r) {
      return std::tie(l.y, l.x) < std::tie(r.y, r.x);
    });
    targets.erase(std::unique(targets.begin(), targets.end()), targets.end());
    for (const TileKey& key : targets) {
      auto& list = faces_of_tile[{key.y, key.x}];
      list.insert(list.end(), {idx[3 * f], idx[3 * f + 1], idx[3 * f + 2]});
    }
  }
  std::vector<TileFaces> tiles;
  tiles.reserve(faces_of_tile.size());
  for (auto& [yx, triangles] : faces_of_tile) tiles.push_back({TileKey{zoom, yx.second, yx.first}, std::move(triangles)});
  return tiles;
}

}  // namespace terratiles
