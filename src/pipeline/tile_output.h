#pragma once
// What the build makes of one tile and of the tree of tiles, shared by the whole build
// (run_pipeline.cpp) and the build in blocks (block_build.cpp): a tile's content as a decoder
// gives it back (drawnContent), its GLB (encodeContent), the level normals every tile of a zoom
// takes its normals from, and the tileset files with build.json (writeTilesetOutput).

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include "formats/gltf/write_glb.h"
#include "formats/output_directory.h"
#include "src/dem/dem_grid.h"
#include "src/geo/crs_transform.h"
#include "src/geo/dem_on_globe.h"
#include "src/lod/grid_pyramid.h"
#include "src/pipeline/drawn_tiles.h"
#include "src/pipeline/run_pipeline.h"
#include "src/tin/tin_mesh.h"
#include "tileset/tileset.h"

namespace terratiles {

// The smallest multiple of a micrometre at or above `metres` (at least one micrometre).
double roundUpToMicrometre(double metres);

// A unit normal as the GLB stores it (glTF normals are floats).
using FloatNormal = std::array<float, 3>;

// Unit normals in ECEF of a level's vertices from the whole level mesh (area-weighted face
// normals), so shading is continuous across tiles; an unused vertex gets the ellipsoid normal.
// Summed and normalised in doubles, kept as floats.
std::vector<FloatNormal> levelNormals(const TinMesh& mesh, std::span<const EcefPoint> ecef);
// The same, letting the points go before the floats are made (48 bytes per vertex at most
// instead of 60).
std::vector<FloatNormal> levelNormals(const TinMesh& mesh, std::vector<EcefPoint>&& ecef);

// One tile's content exactly as a decoder gives it back: every vertex at its position on the
// zoom's quantisation grids (snapped), vertices that snap to one point welded into one (the
// pole of a geographic DEM, whose pixels are all one point) and the triangles that collapse
// with them left out. Measured, bounded (its region) and encoded from this.
struct DrawnContent {
  std::vector<EcefPoint> positions;  // snapped ECEF
  std::vector<FloatNormal> normals;
  std::vector<GridCorner> grid;      // where each vertex sits in the DEM's grid (before snapping)
  std::vector<std::uint32_t> triangle_indices;
};

// Marks a level vertex not (yet) in the tile drawnContent is making.
inline constexpr std::uint32_t kNotInTile = std::numeric_limits<std::uint32_t>::max();

// Per thread scratch for drawnContent and tileExtent, reused from tile to tile.
struct ContentScratch {
  // An entry per level vertex (at least), every entry kNotInTile between calls.
  std::vector<std::uint32_t> local_of;
  std::vector<std::uint32_t> seen;
  std::vector<EcefPoint> placed;     // per entry of seen
  std::vector<std::uint32_t> tile_vertex;
  std::vector<std::uint32_t> slots;  // open addressing over snapped points: an index into seen
  std::vector<GridPoint> grid;       // for a PlaceVertices
};

// Where a zoom's vertices are drawn, a tile's at a time: ecef[i] for the level vertex
// vertices[i] (`grid`: the caller's scratch). A tile's vertices are placed when it is made,
// instead of every vertex of the zoom at once (24 bytes per vertex of the finest zoom, 30 MB
// on SRTM Gabon, held while its tiles were made).
using PlaceVertices = std::function<void(std::span<const std::uint32_t> vertices, std::span<EcefPoint> ecef,
                                         std::vector<GridPoint>& grid)>;

// Places the level vertices with the DEM's globe, then snaps each to the grid of
// `step_m[grid_of[vertex]]` (nullptr: not snapped).
PlaceVertices placedOnGlobe(const DemOnGlobe& globe, const TinMesh& mesh,
                            const std::vector<std::uint8_t>* grid_of = nullptr,
                            const std::vector<double>* step_m = nullptr);
// The same from a zoom's vertices placed and snapped all at once.
PlaceVertices placedFrom(std::span<const EcefPoint> snapped);

// The largest side of the ECEF box of the tile's vertices, as `place` puts them.
double tileExtent(const PyramidTile& tile, const TinMesh& mesh, const PlaceVertices& place, ContentScratch& scratch);

// Vertices take their tile index in order of first appearance in the tile's triangles; one
// whose snapped point (from `snapped`) equals an earlier one's is welded to it (the first
// seen keeps its place and the others take it; found by hashing, which gives what a stable
// sort by point did).
DrawnContent drawnContent(const PyramidTile& tile, const TinMesh& mesh, const PlaceVertices& snapped,
                          std::span<const FloatNormal> normals, const DemOnGlobe& globe, ContentScratch& scratch);

struct EncodedTile {
  std::vector<std::uint8_t> glb;
  Region region;
  DrawnTileMeasure measure;
  std::size_t vertices = 0;
  int position_bits = 0;  // Draco position bits at the zoom's step
};

// One tile's GLB: its vertices relative to an origin on the quantisation grid, in the glTF
// y-up frame (glTF (x, y, z) = ECEF (X, Z, -Y); 3D Tiles rotates y-up back to z-up). Every
// position is on the grid before it is made relative, so the float offsets are exact and
// Draco gives them back bit for bit: a vertex two tiles share decodes to one position in both.
std::vector<std::uint8_t> encodeContent(const DrawnContent& content, const GlbOptions& glb, int* position_bits);

// Per vertex of a zoom's mesh: whether it is on the outline of some of its tiles (an edge of
// one of the tile's triangles that no other of its triangles has). Tiles in parallel.
std::vector<std::uint8_t> tileOutlineVertices(const TinMesh& mesh, const std::vector<PyramidTile>& tiles);

// Attaches every node under its parent in `nodes`, finest zoom first, creating content-less
// ancestors where needed, until one node (the common ancestor) is left: the root.
TileNode buildTree(std::map<std::tuple<int, int, int>, TileNode>& nodes);

// The summary's description of the input: its CRS, size, heights, centre, placement and geoid
// (`geoid_name`: empty for ellipsoidal heights).
void describeInput(BuildSummary& summary, const DemGrid& dem, const DemStatistics& stats, const CrsToWgs84& to_wgs84,
                   const std::string& geoid_name);

// The tileset of the written tiles (`nodes`: (zoom, y, x) -> node with its content, region and
// geometricError) and build.json (what `terratiles check` needs to find the source again),
// written last; records per zoom of `summary` the largest geometricError written.
void writeTilesetOutput(std::map<std::tuple<int, int, int>, TileNode> nodes, const BuildOptions& options,
                        const std::string& crs_name, bool orthometric, double widest_step_m, BuildSummary& summary,
                        OutputDirectory& output, Progress& progress);

}  // namespace terratiles
