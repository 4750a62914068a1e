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

// A mesh's corners grouped by their vertex (CSR), each with the vertex it runs to: corner c
// runs from triangle_indices[c] to the next corner's vertex. leaving[start[v] .. start[v + 1])
// are the corners leaving v, in corner order; end[i] is where leaving[i] runs to. Linear time.
struct CornersLeaving {
  std::vector<std::uint32_t> start, leaving, end;
};
inline CornersLeaving cornersLeaving(const TinMesh& mesh) {
  const std::vector<std::uint32_t>& idx = mesh.triangle_indices;
  CornersLeaving out;
  out.start.assign(mesh.vertices.size() + 1, 0);
  for (const std::uint32_t v : idx) ++out.start[v + 1];
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) out.start[v + 1] += out.start[v];
  out.leaving.resize(idx.size());
  out.end.resize(idx.size());
  std::vector<std::uint32_t> fill(out.start.begin(), out.start.end() - 1);
  for (std::size_t c = 0; c < idx.size(); ++c) {
    const std::uint32_t i = fill[idx[c]]++;
    out.leaving[i] = static_cast<std::uint32_t>(c);
    out.end[i] = idx[c % 3 == 2 ? c - 2 : c + 1];
  }
  return out;
}

}  // namespace terratiles
