#pragma once
// fillTile: a terrain tile covered whole (issue 17: a terrain provider covers the globe).
//
// Where the data does not reach (outside the DEM, its nodata holes), the tile gets a fill
// surface: a regular grid of points over its rectangle (`grid_cells` cells a side, so that the
// straight triangles a client draws follow the Earth's curvature) at heights a function gives
// (the geoid, as ellipsoidal heights), triangulated (CGAL's constrained Delaunay
// triangulation) together with the data mesh's outline, which stays as it is: every fill
// triangle outside the data, none inside, and the data's outline vertices shared by both, so
// no crack opens between them. Grid points on or inside the data are left out. Two tiles of a
// zoom that share a side put the same grid points on it (the same fractions of it) and the
// same data vertices (clipToTile), so they meet there vertex for vertex.
//
// Fill vertices get the ellipsoid's normal when the tile has normals. A tile the data covers
// whole (its triangles' area is the rectangle's to 1e-12) comes back as it is, untriangulated.

#include <cstdint>
#include <functional>

#include "src/tiling/clip_to_tile.h"

namespace terratiles {

// `data`: the tile's clipped data mesh (may be empty). `height_at(lon, lat)`: the fill's
// ellipsoidal height in metres. Returns the data mesh (its vertices and triangles first, in
// order) with the fill's vertices and triangles after them.
TerrainTileMesh fillTile(const TerrainTileMesh& data, std::int32_t grid_cells,
                         const std::function<double(double lon_deg, double lat_deg)>& height_at);

}  // namespace terratiles
