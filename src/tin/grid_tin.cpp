#include "src/tin/grid_tin.h"

#include <cmath>
#include <limits>

#include "src/base/error.h"

namespace terratiles {

std::vector<std::int32_t> gridSamplePositions(std::int32_t length, std::int32_t step) {
  TERRATILES_ASSERT(length >= 2 && step >= 1);
  std::vector<std::int32_t> positions;
  for (std::int32_t p = 0; p < length - 1; p += step) positions.push_back(p);
  positions.push_back(length - 1);
  return positions;
}

TinMesh triangulateGrid(const DemGrid& dem, std::int32_t step) {
  const std::vector<std::int32_t> cols = gridSamplePositions(dem.width, step);
  const std::vector<std::int32_t> rows = gridSamplePositions(dem.height, step);
  const std::size_t ncols = cols.size();

  TinMesh mesh;
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> vertex_of(ncols * rows.size(), kNone);
  for (std::size_t j = 0; j < rows.size(); ++j) {
    for (std::size_t i = 0; i < ncols; ++i) {
      const float h = dem.heightAt(cols[i], rows[j]);
      if (std::isnan(h)) continue;
      vertex_of[j * ncols + i] = static_cast<std::uint32_t>(mesh.vertices.size());
      mesh.vertices.push_back({static_cast<double>(cols[i]), static_cast<double>(rows[j]), h});
    }
  }
  mesh.triangle_indices.reserve((ncols - 1) * (rows.size() - 1) * 6);
  for (std::size_t j = 0; j + 1 < rows.size(); ++j) {
    for (std::size_t i = 0; i + 1 < ncols; ++i) {
      const std::uint32_t tl = vertex_of[j * ncols + i];
      const std::uint32_t tr = vertex_of[j * ncols + i + 1];
      const std::uint32_t bl = vertex_of[(j + 1) * ncols + i];
      const std::uint32_t br = vertex_of[(j + 1) * ncols + i + 1];
      // Counter-clockwise seen from above: row grows south, so (tl, bl, br) turns left.
      if (tl != kNone && bl != kNone && br != kNone) {
        mesh.triangle_indices.insert(mesh.triangle_indices.end(), {tl, bl, br});
      }
      if (tl != kNone && br != kNone && tr != kNone) {
        mesh.triangle_indices.insert(mesh.triangle_indices.end(), {tl, br, tr});
      }
    }
  }
  return mesh;
}

double interpolateCell(const DemGrid& dem, std::int32_t col0, std::int32_t row0, std::int32_t col1,
                       std::int32_t row1, std::int32_t col, std::int32_t row) {
  const double u = static_cast<double>(col - col0) / (col1 - col0);
  const double v = static_cast<double>(row - row0) / (row1 - row0);
  const double tl = dem.heightAt(col0, row0);
  const double br = dem.heightAt(col1, row1);
  if (v >= u) {  // triangle (tl, bl, br)
    const double bl = dem.heightAt(col0, row1);
    return tl + v * (bl - tl) + u * (br - bl);
  }
  const double tr = dem.heightAt(col1, row0);  // triangle (tl, br, tr)
  return tl + u * (tr - tl) + v * (br - tr);
}

}  // namespace terratiles
