#pragma once
// TileKey: a tile of a quadtree pyramid: zoom, column from the west, row from the north.

#include <cstdint>
#include <string>

namespace terratiles {

struct TileKey {
  std::int32_t zoom = 0;
  std::int32_t x = 0;
  std::int32_t y = 0;
  friend bool operator==(const TileKey&, const TileKey&) = default;

  TileKey parent() const { return {zoom - 1, x / 2, y / 2}; }
  // "z/x/y", the tile's path in the output.
  std::string path() const {
    return std::to_string(zoom) + "/" + std::to_string(x) + "/" + std::to_string(y);
  }
};

}  // namespace terratiles
