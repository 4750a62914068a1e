#pragma once
// TinMesh: a triangulated surface over a DemGrid, in the grid's frame.
//
// Vertices are GridPoints: (col, row) in pixel units of the DemGrid (pixel centres at whole
// numbers, row growing south) and the height in metres. Triangles are counter-clockwise seen
// from above in the CRS (x east, y north), so their normals point up.

#include <cstdint>
#include <vector>

namespace terratiles {

struct GridPoint {
  double col = 0;
  double row = 0;
  double height_m = 0;
};

struct TinMesh {
  std::vector<GridPoint> vertices;
  std::vector<std::uint32_t> triangle_indices;  // 3 per triangle

  std::size_t triangleCount() const { return triangle_indices.size() / 3; }
};

}  // namespace terratiles
