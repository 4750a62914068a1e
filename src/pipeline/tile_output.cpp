#include "src/pipeline/tile_output.h"

#include <algorithm>
#include <atomic>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <bit>
#include <cmath>
#include <filesystem>
#include <numbers>

#include <nlohmann/json.hpp>

#include "formats/geoid/read_geoid.h"
#include "src/geo/drawn_pixels.h"
#include "src/geo/place_on_globe.h"
#include "tileset/implicit_tileset.h"

namespace terratiles {
namespace {

// The bits of a snapped point for hashing and equality as doubles (-0 is 0).
std::uint64_t pointHash(const EcefPoint& p) {
  const auto bits = [](double value) { return std::bit_cast<std::uint64_t>(value + 0.0); };
  std::uint64_t h = bits(p.x) * 0x9E3779B97F4A7C15ull;
  h = (h ^ (h >> 29) ^ bits(p.y)) * 0xBF58476D1CE4E5B9ull;
  h = (h ^ (h >> 31) ^ bits(p.z)) * 0x94D049BB133111EBull;
  return h ^ (h >> 32);
}

}  // namespace

// The smallest multiple of a micrometre at or above `metres` (at least one micrometre).
double roundUpToMicrometre(double metres) {
  double rounded = std::ceil(metres * 1e6) / 1e6;
  while (rounded < metres) rounded = std::nextafter(rounded, std::numeric_limits<double>::infinity());
  return std::max(rounded, 1e-6);
}

namespace {

// levelNormals (tile_output.h) in doubles: summed and normalised in them. In parallel over
// ranges of vertices, each range's task reading every triangle and summing the faces at its
// own vertices, so every vertex sums its faces in triangle order whatever the thread count.
std::vector<EcefPoint> unitNormals(const TinMesh& mesh, std::span<const EcefPoint> ecef) {
  const std::size_t n = mesh.vertices.size();
  std::vector<EcefPoint> normals(n, EcefPoint{});
  const auto& idx = mesh.triangle_indices;
  const auto ranges = static_cast<std::size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  tbb::parallel_for(std::size_t{0}, ranges, [&](std::size_t r) {
    const std::size_t lo = n * r / ranges, hi = n * (r + 1) / ranges;
    const auto mine = [&](std::uint32_t v) { return v >= lo && v < hi; };
    for (std::size_t t = 0; t < idx.size(); t += 3) {
      if (!mine(idx[t]) && !mine(idx[t + 1]) && !mine(idx[t + 2])) continue;
      const EcefPoint& a = ecef[idx[t]];
      const EcefPoint& b = ecef[idx[t + 1]];
      const EcefPoint& c = ecef[idx[t + 2]];
      const double ux = b.x - a.x, uy = b.y - a.y, uz = b.z - a.z;
      const double vx = c.x - a.x, vy = c.y - a.y, vz = c.z - a.z;
      const EcefPoint face{uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx};  // area-weighted
      for (std::size_t k = 0; k < 3; ++k) {
        if (!mine(idx[t + k])) continue;
        EcefPoint& nrm = normals[idx[t + k]];
        nrm.x += face.x;
        nrm.y += face.y;
        nrm.z += face.z;
      }
    }
    for (std::size_t i = lo; i < hi; ++i) {
      EcefPoint& nrm = normals[i];
      double length = std::sqrt(nrm.x * nrm.x + nrm.y * nrm.y + nrm.z * nrm.z);
      if (length == 0) {  // an unused vertex: the direction from the Earth's centre
        nrm = ecef[i];
        length = std::sqrt(nrm.x * nrm.x + nrm.y * nrm.y + nrm.z * nrm.z);
        if (length == 0) nrm = {0, 0, 1}, length = 1;
      }
      nrm.x /= length;
      nrm.y /= length;
      nrm.z /= length;
    }
  }, tbb::simple_partitioner());
  return normals;
}

std::vector<FloatNormal> asFloats(const std::vector<EcefPoint>& normals) {
  std::vector<FloatNormal> kept(normals.size());
  for (std::size_t i = 0; i < normals.size(); ++i) {
    kept[i] = {static_cast<float>(normals[i].x), static_cast<float>(normals[i].y), static_cast<float>(normals[i].z)};
  }
  return kept;
}

}  // namespace

std::vector<FloatNormal> levelNormals(const TinMesh& mesh, std::span<const EcefPoint> ecef) {
  return asFloats(unitNormals(mesh, ecef));
}

std::vector<FloatNormal> levelNormals(const TinMesh& mesh, std::vector<EcefPoint>&& ecef) {
  const std::vector<EcefPoint> normals = unitNormals(mesh, ecef);
  ecef = std::vector<EcefPoint>();
  return asFloats(normals);
}

PlaceVertices placedOnGlobe(const DemOnGlobe& globe, const TinMesh& mesh, const std::vector<std::uint8_t>* grid_of,
                            const std::vector<double>* step_m) {
  return [&globe, &mesh, grid_of, step_m](std::span<const std::uint32_t> vertices, std::span<EcefPoint> ecef,
                                          std::vector<GridPoint>& grid) {
    grid.resize(vertices.size());
    for (std::size_t i = 0; i < vertices.size(); ++i) grid[i] = mesh.vertices[vertices[i]];
    // Isolated: while it waits for its parallel parts, this thread must not take up another
    // tile, whose work would reuse the caller's per-thread scratch.
    tbb::this_task_arena::isolate([&] { globe.place(grid, {}, ecef); });
    if (!grid_of) return;
    for (std::size_t i = 0; i < vertices.size(); ++i) {
      const double step = (*step_m)[(*grid_of)[vertices[i]]];
      EcefPoint& p = ecef[i];
      p = {snapToStep(p.x, step), snapToStep(p.y, step), snapToStep(p.z, step)};
    }
  };
}

PlaceVertices placedFrom(std::span<const EcefPoint> snapped) {
  return [snapped](std::span<const std::uint32_t> vertices, std::span<EcefPoint> ecef, std::vector<GridPoint>&) {
    for (std::size_t i = 0; i < vertices.size(); ++i) ecef[i] = snapped[vertices[i]];
  };
}

namespace {

// The tile's level vertices in order of first appearance in its triangles (scratch.seen;
// scratch.local_of[v]: v's place there, until forgetTileVertices), placed (scratch.placed).
void placeTileVertices(const PyramidTile& tile, const TinMesh& mesh, const PlaceVertices& place,
                       ContentScratch& scratch) {
  std::vector<std::uint32_t>& local_of = scratch.local_of;
  if (local_of.size() < mesh.vertices.size()) local_of.resize(mesh.vertices.size(), kNotInTile);
  std::vector<std::uint32_t>& seen = scratch.seen;
  seen.clear();
  for (std::size_t c = 0; c < 3 * tile.triangleCount(); ++c) {
    const std::uint32_t v = tile.corner(mesh, c / 3, c % 3);
    if (local_of[v] != kNotInTile) continue;
    local_of[v] = static_cast<std::uint32_t>(seen.size());
    seen.push_back(v);
  }
  scratch.placed.resize(seen.size());
  place(seen, scratch.placed, scratch.grid);
}

void forgetTileVertices(ContentScratch& scratch) {
  for (const std::uint32_t v : scratch.seen) scratch.local_of[v] = kNotInTile;
}

}  // namespace

double tileExtent(const PyramidTile& tile, const TinMesh& mesh, const PlaceVertices& place, ContentScratch& scratch) {
  placeTileVertices(tile, mesh, place, scratch);
  forgetTileVertices(scratch);
  EcefPoint lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const EcefPoint& p : scratch.placed) {
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  return std::max({0.0, hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
}

// Vertices take their tile index in order of first appearance in the tile's triangles; one
// whose snapped point equals an earlier one's is welded to it (the first seen keeps its place
// and the others take it; found by hashing, which gives what a stable sort by point did).
DrawnContent drawnContent(const PyramidTile& tile, const TinMesh& mesh, const PlaceVertices& snapped,
                          std::span<const FloatNormal> normals, const DemOnGlobe& globe, ContentScratch& scratch) {
  DrawnContent out;
  const std::size_t triangles = tile.triangleCount();
  placeTileVertices(tile, mesh, snapped, scratch);
  const std::vector<std::uint32_t>& local_of = scratch.local_of;
  const std::vector<std::uint32_t>& seen = scratch.seen;
  std::size_t capacity = 16;
  while (capacity < 2 * seen.size()) capacity *= 2;
  std::vector<std::uint32_t>& slots = scratch.slots;
  slots.assign(capacity, kNotInTile);
  std::vector<std::uint32_t>& tile_vertex = scratch.tile_vertex;
  tile_vertex.resize(seen.size());
  out.positions.reserve(seen.size());
  out.normals.reserve(seen.size());
  out.grid.reserve(seen.size());
  for (std::size_t i = 0; i < seen.size(); ++i) {
    const std::uint32_t v = seen[i];
    const EcefPoint& p = scratch.placed[i];
    std::size_t slot = pointHash(p) & (capacity - 1);
    bool welded = false;
    for (; slots[slot] != kNotInTile; slot = (slot + 1) & (capacity - 1)) {
      const EcefPoint& q = scratch.placed[slots[slot]];
      if (p.x == q.x && p.y == q.y && p.z == q.z) {
        tile_vertex[i] = tile_vertex[slots[slot]];  // seen earlier
        welded = true;
        break;
      }
    }
    if (welded) continue;
    slots[slot] = static_cast<std::uint32_t>(i);
    const GridPoint& g = mesh.vertices[v];
    tile_vertex[i] = static_cast<std::uint32_t>(out.positions.size());
    out.positions.push_back(p);
    out.normals.push_back(normals[v]);
    out.grid.push_back(gridCornerOf(globe, g.col, g.row));
  }
  out.triangle_indices.reserve(3 * triangles);
  for (std::size_t t = 0; t < triangles; ++t) {
    const std::uint32_t a = tile_vertex[local_of[tile.corner(mesh, t, 0)]],
                        b = tile_vertex[local_of[tile.corner(mesh, t, 1)]],
                        c = tile_vertex[local_of[tile.corner(mesh, t, 2)]];
    if (a != b && b != c && c != a) out.triangle_indices.insert(out.triangle_indices.end(), {a, b, c});
  }
  forgetTileVertices(scratch);
  return out;
}

// One tile's GLB: its vertices relative to an origin on the quantisation grid, in the glTF
// y-up frame (glTF (x, y, z) = ECEF (X, Z, -Y); 3D Tiles rotates y-up back to z-up). Every
// position is on the grid before it is made relative, so the float offsets are exact and
// Draco gives them back bit for bit: a vertex two tiles share decodes to one position in both.
std::vector<std::uint8_t> encodeContent(const DrawnContent& content, const GlbOptions& glb, int* position_bits) {
  GlbMesh mesh;
  mesh.triangle_indices = content.triangle_indices;
  EcefPoint lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const EcefPoint& p : content.positions) {
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  const double step = glb.position_step_m;
  auto snap = [step](double value) { return snapToStep(value, step); };
  const EcefPoint origin{snap((lo.x + hi.x) / 2), snap((lo.y + hi.y) / 2), snap((lo.z + hi.z) / 2)};
  mesh.translation = {origin.x, origin.z, -origin.y};
  mesh.positions.reserve(content.positions.size() * 3);
  mesh.normals.reserve(content.positions.size() * 3);
  for (std::size_t v = 0; v < content.positions.size(); ++v) {
    const EcefPoint& p = content.positions[v];
    const FloatNormal& n = content.normals[v];
    mesh.positions.insert(mesh.positions.end(), {static_cast<float>(p.x - origin.x), static_cast<float>(p.z - origin.z),
                                                 static_cast<float>(-(p.y - origin.y))});
    mesh.normals.insert(mesh.normals.end(), {n[0], n[2], -n[1]});
  }
  EncodedGlb encoded = encodeGlb(mesh, glb);
  *position_bits = encoded.position_bits;
  return std::move(encoded.bytes);
}

// Per vertex of a zoom's mesh: whether it is on the outline of some tile of the zoom (an
// edge of one of the tile's triangles that no other of its triangles has). Tiles in parallel.
std::vector<std::uint8_t> tileOutlineVertices(const TinMesh& mesh, const std::vector<PyramidTile>& tiles) {
  std::vector<std::uint8_t> outline(mesh.vertices.size(), 0);
  struct Scratch {
    ContentScratch numbering;  // local_of: the tile's own vertex numbers
    std::vector<std::uint32_t> local;
    OutlineScratch outline;
    std::vector<std::array<std::uint32_t, 2>> edges;
  };
  tbb::enumerable_thread_specific<Scratch> scratch;
  tbb::parallel_for(std::size_t{0}, tiles.size(), [&](std::size_t i) {
    Scratch& s = scratch.local();
    const PyramidTile& tile = tiles[i];
    std::vector<std::uint32_t>& local_of = s.numbering.local_of;
    std::vector<std::uint32_t>& seen = s.numbering.seen;
    if (local_of.size() < outline.size()) local_of.resize(outline.size(), kNotInTile);
    seen.clear();
    s.local.resize(3 * tile.triangleCount());
    for (std::size_t k = 0; k < s.local.size(); ++k) {
      const std::uint32_t v = tile.corner(mesh, k / 3, k % 3);
      if (local_of[v] == kNotInTile) {
        local_of[v] = static_cast<std::uint32_t>(seen.size());
        seen.push_back(v);
      }
      s.local[k] = local_of[v];
    }
    outlineEdges(s.local, seen.size(), s.outline, s.edges);
    for (const auto& edge : s.edges) {
      for (const std::uint32_t end : edge) std::atomic_ref<std::uint8_t>(outline[seen[end]]).store(1, std::memory_order_relaxed);
    }
    for (const std::uint32_t v : seen) local_of[v] = kNotInTile;
  });
  return outline;
}

TileNode buildTree(std::map<std::tuple<int, int, int>, TileNode>& nodes) {
  while (nodes.size() > 1) {
    int zoom = 0;
    for (const auto& [key, node] : nodes) zoom = std::max(zoom, std::get<0>(key));
    if (zoom == 0) {
      // The geographic scheme's two zoom-0 tiles (data on both sides of the prime meridian):
      // a content-less root above them (zoom -1 marks it; it has no file).
      TileNode root;
      root.key = {-1, 0, 0};
      for (auto& [key, node] : nodes) root.children.push_back(std::move(node));
      nodes.clear();
      return root;
    }
    std::vector<std::tuple<int, int, int>> at_zoom;
    for (const auto& [key, node] : nodes) {
      if (std::get<0>(key) == zoom) at_zoom.push_back(key);
    }
    for (const auto& key : at_zoom) {
      TileNode child = std::move(nodes.at(key));
      nodes.erase(key);
      const TileKey parent_key = child.key.parent();
      TileNode& parent = nodes[{parent_key.zoom, parent_key.y, parent_key.x}];
      parent.key = parent_key;
      parent.children.push_back(std::move(child));
    }
  }
  TileNode root = std::move(nodes.begin()->second);
  return root;
}

void describeInput(BuildSummary& summary, const DemGrid& dem, const DemStatistics& stats, const CrsToWgs84& to_wgs84,
                   const std::string& geoid_name) {
  summary.crs_name = dem.crs_name;
  summary.geoid = !geoid_name.empty() ? geoid_name : "none (heights are ellipsoidal)";
  summary.placement = to_wgs84.pathDescription();
  summary.warnings = to_wgs84.warnings();
  summary.width = dem.width;
  summary.height = dem.height;
  summary.pixel_size = dem.pixel_size_x;
  summary.valid_pixels = stats.valid_pixels;
  summary.min_height_m = stats.min_height_m;
  summary.max_height_m = stats.max_height_m;
  GeodeticPoint centre;
  centre.height_m = (stats.min_height_m + stats.max_height_m) / 2;
  const CrsPoint c = dem.pixelCentre((dem.width - 1) / 2.0, (dem.height - 1) / 2.0);
  to_wgs84.transform(std::span<const CrsPoint>(&c, 1), std::span<GeodeticPoint>(&centre, 1));
  summary.centre_lon_deg = centre.lon_deg;
  summary.centre_lat_deg = centre.lat_deg;
}

void writeTilesetOutput(std::map<std::tuple<int, int, int>, TileNode> nodes, const BuildOptions& options,
                        const std::string& crs_name, bool orthometric, double widest_step_m, BuildSummary& summary,
                        OutputDirectory& output, Progress& progress) {
  constexpr double kDegToRad = std::numbers::pi / 180.0;
  progress.beginStage("writing the tileset", 0);
  Tileset tileset;
  tileset.generator = summary.generator;
  tileset.root = buildTree(nodes);
  finalizeTree(tileset.root);
  // The error of drawing nothing at all: at least the data's size, the larger of the
  // footprint's diagonal (chord between the root region's corners) and the relief. A value
  // as small as the relief alone would hide flat terrain from any distance (CesiumJS does
  // not draw a root whose error, seen through tileset.geometricError, is below the SSE).
  {
    const Region& r = tileset.root.region;
    const std::vector<GeodeticPoint> corners{
        {r.west_rad / kDegToRad, r.south_rad / kDegToRad, r.min_height_m},
        {r.east_rad / kDegToRad, r.north_rad / kDegToRad, r.min_height_m}};
    std::vector<EcefPoint> ends(2);
    geodeticToEcef(corners, ends);
    const double diagonal_m =
        std::hypot(ends[1].x - ends[0].x, ends[1].y - ends[0].y, ends[1].z - ends[0].z);
    tileset.geometric_error_m = std::max(
        {tileset.root.geometric_error_m, diagonal_m, r.max_height_m - r.min_height_m});
  }
  // A tile without content (a common ancestor above the coarsest zoom's tiles) draws nothing:
  // its error is that of drawing nothing, so a viewer always refines it.
  {
    std::vector<TileNode*> open{&tileset.root};
    while (!open.empty()) {
      TileNode* node = open.back();
      open.pop_back();
      if (node->content_uri.empty()) node->geometric_error_m = tileset.geometric_error_m;
      for (TileNode& child : node->children) open.push_back(&child);
    }
  }
  // Record per zoom the largest geometricError written (after finalizeTree raised them).
  std::vector<const TileNode*> stack{&tileset.root};
  while (!stack.empty()) {
    const TileNode* node = stack.back();
    stack.pop_back();
    for (ZoomSummary& z : summary.zooms) {
      if (z.zoom == node->key.zoom && !node->content_uri.empty()) {
        z.geometric_error_m = std::max(z.geometric_error_m, node->geometric_error_m);
      }
    }
    for (const TileNode& child : node->children) stack.push_back(&child);
  }

  // What `terratiles check` needs to find the source again (not referenced by tileset.json).
  {
    nlohmann::json facts;
    facts["generator"] = summary.generator;
    std::vector<std::string> inputs;
    for (const std::string& input : options.inputs) inputs.push_back(std::filesystem::absolute(input).lexically_normal().string());
    facts["inputs"] = inputs;
    facts["crs"] = crs_name;
    facts["lod"] = options.lod == LodMethod::Grid ? "grid" : "clusters";
    facts["scheme"] = options.lod == LodMethod::Grid ? "local pixels" : std::string(tileSchemeName(options.scheme));
    facts["assign"] = std::string(assignmentName(options.assignment));
    facts["tin_max_error_m"] = options.tin_max_error_m;
    facts["heights"] = orthometric ? "orthometric" : "ellipsoidal";
    facts["geoid"] = orthometric ? std::filesystem::absolute(options.geoid_path.empty() ? kDefaultGeoidPath
                                                                                 : options.geoid_path).string()
                           : std::string();
    facts["position_step_m"] = widest_step_m;  // the widest any zoom used
    nlohmann::json steps = nlohmann::json::object();
    for (const ZoomSummary& z : summary.zooms) steps[std::to_string(z.zoom)] = z.position_step_m;
    facts["position_step_m_by_zoom"] = steps;
    facts["tiling"] = options.implicit_tiling ? "implicit" : "explicit";
    // Implicit output: the same tree as an explicit tileset, for `terratiles check`.
    if (options.implicit_tiling) facts["explicit_tileset"] = nlohmann::json::parse(tilesetToJson(tileset));
    summary.bytes += output.writeFile("build.json", facts.dump(2) + "\n");
  }
  // tileset.json last, then the whole directory moves into place.
  if (options.implicit_tiling) {
    for (const ImplicitFile& file : writeImplicitTileset(tileset, options.subtree_levels)) {
      summary.bytes += output.writeFile(file.path, file.bytes);
    }
  } else {
    // Deep trees: external tilesets, then tileset.json (the last file written).
    std::vector<TilesetFile> files = tilesetFiles(tileset, options.tileset_levels);
    for (std::size_t f = files.size(); f-- > 0;) summary.bytes += output.writeFile(files[f].path, files[f].text);
    if (files.size() > 1) progress.note("tileset: " + std::to_string(files.size() - 1) + " external tilesets below tileset.json");
  }
  progress.endStage();

}

}  // namespace terratiles
