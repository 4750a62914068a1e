#pragma once
// Clusters to web tiles (DESIGN.md section 4, paper 3.5): which faces of each level of detail
// each tile of its zoom carries.
//
// Level l of the cluster LoD loop (src/lod/build_levels.h) is shown at zoom max_zoom - l. Its
// faces carry two cluster ids: `own`, the partition that split level l to make the coarser
// level (its borders are locked in level l - 1 ... and exist in the coarser level), and
// `inherited`, the finer level's partition carried over (its borders exist in the finer
// level). Strategies:
//   centroid   a tile carries the own clusters whose centroid it holds (the paper's first
//              idea; for comparison: it leaves holes where a cluster reaches into a tile
//              whose neighbour took it).
//   duplicate  a tile carries every own cluster that crosses it (paper 3.5.2).
//   merge      (default; paper 3.5.3, "boundaries merge") a tile carries the inherited
//              clusters that cross its square.
//              Its mesh holds both sets of borders (the inherited ones and its own, locked
//              for the next coarser level); its outline runs along the inherited ones, which
//              are edges of the finer level's mesh too. So the outlines of a zoom-z tile and
//              a zoom-(z+1) tile are both made of edges and vertices of level z+1's mesh and
//              meet vertex for vertex (no T-junction), and the outlines of zooms z and z - 1
//              are both edges of level z's mesh. The crossing clusters cover the square, so a
//              drawn tile never leaves a hole in any cut. The finest zoom has no inherited
//              clusters: there every face crossing the square is added (TIN edges). Taking
//              the own clusters by centroid as well (the paper's literal reading) adds
//              outline edges that exist in this level only, where a finer tile's outline
//              vertex can sit within millimetres of an edge (measured: one on Ontario).
// A cluster's centroid is the area-weighted centroid of its faces in scheme coordinates.

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

#include "src/dem/dem_grid.h"
#include "src/lod/build_levels.h"
#include "src/tiling/tile_key.h"
#include "src/tiling/tile_scheme.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

class CrsToWgs84;

enum class Assignment { Centroid, Duplicate, Merge };
// "centroid", "duplicate", "merge"; Error(Usage) otherwise.
Assignment parseAssignment(std::string_view text);
std::string_view assignmentName(Assignment assignment);

// Where a DEM's grid sits in a tile scheme: scheme coordinates of grid points (lon/lat
// degrees for the web schemes, through the same CRS -> WGS84 transformation as the
// placement; CRS units for local, whose zoom-0 tile is the DEM's extent) and tile lookups.
//
// The frame owns its latitude range: toScheme clamps latitudes into the scheme's
// (+-kWebMercatorMaxLatitudeDeg for webmercator, +-90 for geographic; a global DEM's polar
// caps go to the first and last rows, as web maps draw them), and tileAt / tilesIntersecting
// take points and boxes computed from toScheme's coordinates (cluster centroids, face and
// data boxes), clamping their latitudes into that same range. Such a point is inside the
// range in exact arithmetic and can leave it only by rounding. Boxes made of minima and maxima
// of toScheme's points are exact; an area-weighted centroid is not: a cluster whose faces all
// sit on the clamped edge (zero area, equal weights) can average to hundreds of ulps past it
// (ETOPO5 at 6000 x 3000 px, --tin-max-error 10: four clusters, 17 to 25 ulps, 3.6e-13 deg).
// So data the frame accepted never yields a latitude the scheme refuses, and points inside
// the range get exactly the tiles tile_scheme.h gives them. A NaN or infinite coordinate is
// still Error(Input) from tile_scheme.h.
class TileFrame {
 public:
  // `local_extent` (CRS units; local scheme only): the extent the zoom-0 tile is made for, when
  // `dem` is a window of a larger mosaic (a block); nullptr: dem's own extent.
  TileFrame(TileSchemeKind kind, const DemGrid& dem, const TileBounds* local_extent = nullptr);
  ~TileFrame();
  TileFrame(const TileFrame&) = delete;
  TileFrame& operator=(const TileFrame&) = delete;

  TileSchemeKind kind() const { return kind_; }
  const LocalTileScheme& local() const { return local_; }
  // Large inputs are transformed in parallel (TBB), each thread with its own transformation
  // (PROJ's objects are not shared between threads); every point gets the same coordinates as
  // on one thread.
  std::vector<std::array<double, 2>> toScheme(std::span<const GridPoint> points) const;
  // A block of the build in blocks (block_build.h) is one tile of some zoom, cut along pixel
  // rows and columns, so its pixels reach up to half a pixel past the tile's square: from now
  // on toScheme puts every point inside `key`'s square (moved by at most that half pixel, and a
  // billionth of the tile inside its edges), so that every tile the block's faces and clusters
  // go to is `key` or below it, whatever the rounding.
  void keepInside(TileKey key);
  // The build in blocks: the blocks' border pixel lines (mosaic columns and rows, ascending,
  // from the first pixel to the last) and the scheme coordinate each stands for (a tile edge; the
  // outer ones their own). From now on toScheme interpolates linearly between them, so a block
  // border is exactly its tile's edge, in every block and in the levels made of their joined
  // meshes alike (a point moves by at most half a pixel). Only for grids whose rows and columns
  // the scheme's axes follow (WGS84 longitude and latitude under a web scheme; local).
  void followBlocks(std::vector<double> col_lines, std::vector<double> col_values, std::vector<double> row_lines,
                    std::vector<double> row_values);
  // Approximate tile coordinates of a grid point (col, row) in units of zoom-0 tiles: x east
  // from the scheme's west edge (geographic: 0 to 2), y in the direction the scheme counts
  // rows (webmercator and geographic: south from the north edge; local: north from the south
  // edge), so the tile of zoom z is (floor(x 2^z), floor(y 2^z)) away from tile edges.
  // Bilinear in the exact values (toScheme at height 0, longitudes unwrapped) on a lattice of
  // 65 x 65 grid points over the DEM: O(1), pure, no transformation. For work that any smooth
  // approximation serves (partition regions), never for tile membership.
  std::array<double, 2> approximateTileCoordinates(double col, double row) const;
  // The smallest and largest approximateTileCoordinates over the DEM: {min x, min y, max x,
  // max y} (bilinear interpolation stays within its lattice's values).
  std::array<double, 4> approximateTileExtent() const;
  // The tile holding a point in scheme coordinates (latitude clamped as above; local: the
  // point clamped into the zoom-0 tile).
  TileKey tileAt(std::array<double, 2> point, std::int32_t zoom) const;
  // Tiles sharing area with the box (west, south, east, north in scheme coordinates; web
  // schemes: south and north clamped as above).
  std::vector<TileKey> tilesIntersecting(const TileBounds& box, std::int32_t zoom) const;

 private:
  // lat_deg clamped into the web scheme's latitude range; NaN and infinities unchanged, so
  // tile_scheme.h refuses them.
  double insideLatitude(double lat_deg) const;

  // toScheme without keepInside.
  std::vector<std::array<double, 2>> unclampedScheme(std::span<const GridPoint> points) const;
  // Tile coordinates (approximateTileCoordinates) of exact scheme coordinates.
  std::array<double, 2> tileCoordinates(std::array<double, 2> scheme) const;

  TileSchemeKind kind_;
  const DemGrid& dem_;
  LocalTileScheme local_;
  std::unique_ptr<CrsToWgs84> to_wgs84_;
  struct ThreadTransforms;  // per-thread CrsToWgs84 for toScheme
  std::unique_ptr<ThreadTransforms> thread_transforms_;
  static constexpr int kLatticeCells = 64;
  std::vector<std::array<double, 2>> lattice_;  // (kLatticeCells + 1)^2 tile coordinates, row-major
  bool keep_inside_ = false;
  bool follow_blocks_ = false;
  std::vector<double> col_lines_, col_values_, row_lines_, row_values_;  // followBlocks
  TileBounds inside_;  // keepInside: the square points are kept in, in scheme coordinates
};

struct ZoomPlan {
  std::int32_t max_zoom = 0;  // shows the finest TIN
  std::int32_t min_zoom = 0;  // the coarsest level
  // Clusters that split level l (zoom max_zoom - l): clusters_per_tile per tile of its zoom.
  std::vector<std::int32_t> clusters_per_level;
};

// min_zoom: the finest zoom at which the data spans at most two tiles (or `forced_min_zoom`
// when >= 0: a terrain layer has a level for every zoom down to 0; never above max_zoom);
// max_zoom: the first zoom from there whose tiles over the data hold at most
// `tile_triangles` of the finest TIN's triangles each (or `forced_max_zoom` when >= 0).
ZoomPlan planZooms(const TileFrame& frame, const TinMesh& finest, std::int32_t tile_triangles,
                   std::int32_t forced_max_zoom, std::int32_t clusters_per_tile = 4,
                   std::int32_t forced_min_zoom = -1);
// The same from the box of the finest TIN's vertices in scheme coordinates and its triangle
// count (the build in blocks adds them up over its blocks).
ZoomPlan planZooms(const TileFrame& frame, const TileBounds& data_box, std::size_t finest_triangles,
                   std::int32_t tile_triangles, std::int32_t forced_max_zoom, std::int32_t clusters_per_tile = 4,
                   std::int32_t forced_min_zoom = -1);
// The box of points in scheme coordinates (toScheme's), west, south, east, north.
TileBounds schemeBounds(const std::vector<std::array<double, 2>>& points);

struct TileFaces {
  TileKey key;
  std::vector<std::uint32_t> faces;  // of the level's mesh, ascending
};

// Joins the clusters of `partition` (of `mesh`, a level shown at zoom + 1) that cross
// exactly the same tiles of `zoom`, where they will be inherited clusters: merge puts them in
// the same tiles, so the borders between them are on no tile outline and need no lock (paper
// fig 34: a tile's inner cluster borders are unlocked). The result numbers the groups 0..k-1
// in order of first appearance.
FacePartition groupClustersByTiles(const TileFrame& frame, const TinMesh& mesh, const FacePartition& partition,
                                   std::int32_t zoom);

// Regions for partitionFaces (src/partition/partition_faces.h) of a level shown at `zoom`,
// whose clusters groupClustersByTiles will join by the tiles of zoom - 1: a region per block
// of 2 x 2 tiles of `zoom` offset by one tile, that is a tile of zoom - 1 shifted by half a
// tile east and south (tiles x, y of `zoom` with equal (x + 1) / 2 and (y + 1) / 2), holding
// each face's centroid (the mean of its corners in scheme coordinates). The region outlines,
// which become cluster borders, run along the middle lines of the zoom - 1 tiles, where the
// clusters on both sides cross the same tiles of zoom - 1 and are joined again: no tile outline
// follows them and they are not locked. Outlines along the zoom - 1 tile borders instead (a
// region per tile) would make every cluster next to a tile border cross it (the faces the
// border runs through are split by their centroids), and merge would carry twice the
// overlap in every coarser tile. The centroid's tile comes from
// TileFrame::approximateTileCoordinates (no transformation per face; a face within a hundredth
// of a tile of an edge may land on either side, which only moves a region outline by a face).
// Region ids number the blocks over the DEM row by row (many may hold no face).
// O(T), parallel over faces.
std::vector<std::int32_t> tileNeighbourhoodRegions(const TileFrame& frame, const TinMesh& mesh, std::int32_t zoom);

// LevelOptions::partition_regions for levels shown from max_zoom down: level l (zoom
// max_zoom - l) by tileNeighbourhoodRegions. `frame` must outlive the levels' build.
std::function<std::vector<std::int32_t>(const TinMesh&, std::size_t)> tileRegions(const TileFrame& frame,
                                                                                 std::int32_t max_zoom);

// LevelOptions::regroup_clusters for levels shown from max_zoom down (level l at zoom
// max_zoom - l): level l's clusters are inherited at zoom max_zoom - l - 1, so they are
// grouped by the tiles of that zoom. `frame` must outlive the levels' build.
std::function<FacePartition(const TinMesh&, std::size_t, const FacePartition&)> joinTileClusters(
    const TileFrame& frame, std::int32_t max_zoom);

// The tiles of one zoom, sorted by (y, x). own_cluster_tiles: per cluster of level.partition
// (this zoom's own clusters), the tile holding its centroid, filled here for the next coarser
// zoom; finer_cluster_tiles: the same from the finer zoom (for level.inherited_partition),
// empty for the finest zoom.
std::vector<TileFaces> assignClusters(const TileFrame& frame, const Level& level, std::int32_t zoom,
                                      Assignment assignment, const std::vector<TileKey>& finer_cluster_tiles,
                                      std::vector<TileKey>& own_cluster_tiles);

}  // namespace terratiles
