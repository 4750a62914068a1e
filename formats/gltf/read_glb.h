#pragma once
// decodeGlb: reads back a GLB tile written by encodeGlb (or any single-mesh GLB with
// triangles, with or without KHR_draco_mesh_compression) into a GlbMesh, decoding Draco.
// Used by the tests and by the output checks: everything we assert about tiles is asserted
// on decoded data. Throws Error(Input) naming what is malformed.

#include <cstdint>
#include <span>
#include <string>

#include "formats/gltf/glb_mesh.h"

namespace terratiles {

struct DecodedGlb {
  GlbMesh mesh;             // all primitives of the first mesh, concatenated
  bool draco = false;       // whether the primitives used KHR_draco_mesh_compression
  std::string json;         // the GLB's JSON chunk
};

DecodedGlb decodeGlb(std::span<const std::uint8_t> bytes, const std::string& name);
DecodedGlb readGlbFile(const std::string& path);

}  // namespace terratiles
