#pragma once
// encodeGlb: a GlbMesh as a binary glTF 2.0 file (GLB), by default with
// KHR_draco_mesh_compression as a required extension (Draco encoder, tinygltf container).
//
// Quantisation is explicit and shared: positions are quantised on a grid of
// `position_step_m` anchored at the node translation's grid, so a vertex shared by two tiles
// whose translations are multiples of the step decodes to the same position in both. A mesh
// whose positions are already multiples of the step (relative to a translation on the grid,
// as the pipeline writes them) decodes exactly: the step is a power of two and, within
// 2^23 steps, Draco's float quantisation (floor(x / step + 0.5f)) and dequantisation are exact.
// Throws Error(Internal) when Draco or tinygltf fail or the mesh needs more than
// max_position_bits at this step (choose the step with sharedPositionStep).

#include <cstdint>
#include <string>
#include <vector>

#include "formats/gltf/glb_mesh.h"

namespace terratiles {

// Draco quantises in float as floor(x / step + 0.5f): exact while x / step < 2^23 (above,
// the + 0.5f rounds to even and a shared vertex may land one step apart in two tiles).
constexpr int kMaxExactPositionBits = 23;
// Draco keeps explicit quantisation parameters as six-decimal text: a tile's quantisation
// origin is on this grid (or the step's, when coarser) and its range at least this many
// metres, so that both come back as the same floats (see encodeGlb).
constexpr double kDracoOriginGrid = 1.0 / 64;
constexpr double kDracoMinimumRange = 16;

struct GlbOptions {
  bool draco = true;
  // Draco position quantisation step in metres; must be a power of two so that grid origins
  // and decoded positions are exact in binary floating point.
  double position_step_m = 1.0 / 128.0;
  // Most quantisation bits a tile may use (Draco allows 30; 23 keeps it exact, see above).
  int max_position_bits = kMaxExactPositionBits;
  int normal_bits = 10;    // Draco octahedral normal quantisation
  int encoding_speed = 3;  // Draco speed 0 (smallest) .. 10 (fastest)
  std::string generator = "terratiles";
};

struct EncodedGlb {
  std::vector<std::uint8_t> bytes;
  // The quantisation step used (position_step_m; 0 without Draco): decoded positions are
  // within half of it per axis, so bounding volumes must be grown by it.
  double position_step_m = 0;
  int position_bits = 0;  // Draco position quantisation bits this tile needed
};

EncodedGlb encodeGlb(const GlbMesh& mesh, const GlbOptions& options);

// Snaps a value to the quantisation grid (used for tile translations and positions).
double snapToStep(double value, double step);

// Bits a mesh spanning extent_m needs at `step` (its origin snapped down to the grid).
int positionBitsFor(double extent_m, double step);

// The step a group of tiles shares so that each fits in max_bits: base_step times the
// smallest power of two at which a tile spanning widest_extent_m fits.
double sharedPositionStep(double widest_extent_m, double base_step, int max_bits);

}  // namespace terratiles
