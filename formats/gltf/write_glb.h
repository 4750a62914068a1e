#pragma once
// encodeGlb: a GlbMesh as a binary glTF 2.0 file (GLB), by default with
// KHR_draco_mesh_compression as a required extension (Draco encoder, tinygltf container).
//
// Quantisation is explicit and shared: positions are quantised on a grid of
// `position_step_m` anchored at the node translation's grid, so a vertex shared by two tiles
// whose translations are multiples of the step decodes to the same position in both
// (for tiles no wider than position_step_m * 2^max_position_bits; see GlbOptions).
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
  // Most quantisation bits a tile may use; wider tiles quantise on a coarser power-of-two
  // multiple of position_step_m (Draco's encoding time and memory grow as 2^bits).
  int max_position_bits = 20;
  int normal_bits = 10;
  int encoding_speed = 5;  // Draco speed 0 (smallest) .. 10 (fastest)
  std::string generator = "terratiles";
};

struct EncodedGlb {
  std::vector<std::uint8_t> bytes;
  // The quantisation step actually used (position_step_m, or a power-of-two multiple for a
  // wide tile; 0 without Draco): decoded positions are within half of it per axis, so
  // bounding volumes must be grown by it.
  double position_step_m = 0;
};

EncodedGlb encodeGlb(const GlbMesh& mesh, const GlbOptions& options);

// Snaps a value to the quantisation grid (used for tile translations).
double snapToStep(double value, double step);

}  // namespace terratiles
