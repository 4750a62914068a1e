#pragma once
// GlbMesh: one triangle mesh as it goes into (and comes out of) a GLB tile.
//
// Positions and normals are in the glTF frame (y-up, metres) relative to `translation`,
// the node translation that places the mesh (for 3D Tiles content: ECEF rotated to y-up,
// i.e. glTF (x, y, z) = ECEF (X, Z, -Y)).

#include <array>
#include <cstdint>
#include <vector>

namespace terratiles {

struct GlbMesh {
  std::array<double, 3> translation{0, 0, 0};
  std::vector<float> positions;  // xyz per vertex
  std::vector<float> normals;    // xyz per vertex, unit length; may be empty
  std::vector<std::uint32_t> triangle_indices;

  std::size_t vertexCount() const { return positions.size() / 3; }
};

}  // namespace terratiles
