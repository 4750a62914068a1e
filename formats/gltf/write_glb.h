#pragma once
// encodeGlb: a GlbMesh as a binary glTF 2.0 file (GLB), by default with
// KHR_draco_mesh_compression as a required extension (Draco encoder, tinygltf container).
//
// Quantisation is explicit and shared: positions are quantised on a grid of
// `position_step_m` anchored at the node translation's grid, so a vertex shared by two tiles
// whose translations are multiples of the step decodes to the same position in both.
// Throws Error(Internal) when Draco or tinygltf fail.

#include <cstdint>
#include <string>
#include <vector>

#include "formats/gltf/glb_mesh.h"

namespace terratiles {

struct GlbOptions {
  bool draco = true;
  // Draco position quantisation step in metres; must be a power of two so that grid origins
  // and decoded positions are exact in binary floating point.
  double position_step_m = 1.0 / 128.0;
  int normal_bits = 10;
  int encoding_speed = 5;  // Draco speed 0 (smallest) .. 10 (fastest)
  std::string generator = "terratiles";
};

std::vector<std::uint8_t> encodeGlb(const GlbMesh& mesh, const GlbOptions& options);

// Snaps a value to the quantisation grid (used for tile translations).
double snapToStep(double value, double step);

}  // namespace terratiles
