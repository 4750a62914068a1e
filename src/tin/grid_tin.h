#pragma once
// triangulateGrid: a regular grid mesh of a DemGrid, sampled every `step` pixels.
//
// Vertex columns are 0, step, 2*step, ... plus the last column (width - 1), the same for
// rows, so every level of a pyramid covers the full footprint and shares its outer border
// positions with the finer levels. Each grid cell gives two triangles split along the
// north-west/south-east diagonal; a triangle with a nodata corner is left out. With step 1
// the mesh passes through every valid pixel centre (zero vertical error at the pixels).
//
// This is the end-to-end slice's triangulation; the greedy-insertion TIN (paper 3.2.1)
// replaces it as the finest level of detail.

#include <cstdint>
#include <vector>

#include "src/dem/dem_grid.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

// The sample positions along one axis of `length` pixels at `step`: 0, step, ..., length-1.
std::vector<std::int32_t> gridSamplePositions(std::int32_t length, std::int32_t step);

TinMesh triangulateGrid(const DemGrid& dem, std::int32_t step);

// Height of `mesh`'s surface at a pixel inside a grid cell, by the same diagonal split as
// triangulateGrid; NaN where that half-cell has a nodata corner.
double interpolateCell(const DemGrid& dem, std::int32_t col0, std::int32_t row0, std::int32_t col1,
                       std::int32_t row1, std::int32_t col, std::int32_t row);

}  // namespace terratiles
