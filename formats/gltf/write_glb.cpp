#include "formats/gltf/write_glb.h"

#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "src/base/error.h"

// Draco's encoder weighs, for each attribute's symbols, entropy coding them raw against
// coding them tagged (symbol_encoding.cc), and counts the symbols for the raw estimate with
// draco::ComputeShannonEntropy in a table as long as their largest value. A tile's first
// vertex is coded as its offset from the tile's least coordinates, so that is 4 bytes per
// quantisation step of the tile's extent: 6-24 MB per tile of SRTM N57E011 at 1/128 m, on
// each encoding thread, more than the rest of the tile's encoding, and what glibc kept of it
// set the build's peak.
// This definition takes the library's place (the executable's exported function interposes
// libdraco's, as the dynamic linker does for any default-visibility function) and returns
// the same numbers: the same sum, term by term in ascending symbol order, of counts taken
// from a table no longer than twice the symbols (plus 1024), and of the few symbols beyond it
// sorted (glb_test.cpp compares it with libdraco's own; tiles are byte-identical). Sorting a
// copy of all the symbols instead took 4 % of the writing's CPU on SRTM Gabon.
namespace draco {
std::int64_t ComputeShannonEntropy(const std::uint32_t* symbols, int num_symbols, int max_value,
                                   int* out_num_unique_symbols) {
  int unique = 0;
  double total_bits = 0;
  const double count_d = num_symbols;
  const auto add = [&](int frequency) {
    ++unique;
    total_bits += frequency * std::log2(static_cast<double>(frequency) / count_d);
  };
  // Symbols below the table's length are counted in it, the rest (a tile's few first values
  // from zero) in a sorted list after it: ascending order throughout.
  const std::size_t table = static_cast<std::size_t>(
      std::min<std::int64_t>(static_cast<std::int64_t>(max_value) + 1, 2 * static_cast<std::int64_t>(num_symbols) + 1024));
  std::vector<int> frequencies(table, 0);
  std::vector<std::uint32_t> beyond;
  for (int i = 0; i < num_symbols; ++i) {
    if (symbols[i] < table) {
      ++frequencies[symbols[i]];
    } else {
      beyond.push_back(symbols[i]);
    }
  }
  for (const int frequency : frequencies) {
    if (frequency > 0) add(frequency);
  }
  std::sort(beyond.begin(), beyond.end());
  for (std::size_t i = 0; i < beyond.size();) {
    std::size_t end = i + 1;
    while (end < beyond.size() && beyond[end] == beyond[i]) ++end;
    add(static_cast<int>(end - i));
    i = end;
  }
  if (out_num_unique_symbols != nullptr) *out_num_unique_symbols = unique;
  return static_cast<std::int64_t>(-total_bits);
}
}  // namespace draco

namespace terratiles {
namespace {

constexpr const char* kDracoExtension = "KHR_draco_mesh_compression";

struct Bounds {
  std::vector<double> min{std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                          std::numeric_limits<double>::max()};
  std::vector<double> max{-std::numeric_limits<double>::max(), -std::numeric_limits<double>::max(),
                          -std::numeric_limits<double>::max()};
};

Bounds positionBounds(const std::vector<float>& positions) {
  Bounds b;
  for (std::size_t i = 0; i < positions.size(); i += 3) {
    for (std::size_t k = 0; k < 3; ++k) {
      b.min[k] = std::min(b.min[k], static_cast<double>(positions[i + k]));
      b.max[k] = std::max(b.max[k], static_cast<double>(positions[i + k]));
    }
  }
  return b;
}

int addAccessor(tinygltf::Model& model, int buffer_view, int component_type, int type,
                std::size_t count) {
  tinygltf::Accessor accessor;
  accessor.bufferView = buffer_view;
  accessor.componentType = component_type;
  accessor.type = type;
  accessor.count = count;
  model.accessors.push_back(accessor);
  return static_cast<int>(model.accessors.size()) - 1;
}

int appendBufferView(tinygltf::Model& model, const void* data, std::size_t bytes, int target) {
  auto& buffer = model.buffers[0].data;
  while (buffer.size() % 4 != 0) buffer.push_back(0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = buffer.size();
  view.byteLength = bytes;
  view.target = target;
  const auto* begin = static_cast<const unsigned char*>(data);
  buffer.insert(buffer.end(), begin, begin + bytes);
  model.bufferViews.push_back(view);
  return static_cast<int>(model.bufferViews.size()) - 1;
}

struct DracoEncoded {
  std::vector<char> bytes;
  int position_id = -1;  // Draco unique attribute ids, as KHR_draco_mesh_compression names them
  int normal_id = -1;
  std::size_t points = 0;  // as the decoder will produce them (Edgebreaker may split vertices)
  std::size_t faces = 0;
  double position_step_m = 0;
  int position_bits = 0;
};

DracoEncoded encodeDraco(const GlbMesh& mesh, const GlbOptions& options, const Bounds& bounds) {
  int position_id = -1, normal_id = -1;
  const std::size_t vertex_count = mesh.vertexCount();
  draco::Mesh draco_mesh;
  draco_mesh.set_num_points(static_cast<std::uint32_t>(vertex_count));

  draco::GeometryAttribute position;
  position.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_FLOAT32, false,
                sizeof(float) * 3, 0);
  position_id = draco_mesh.AddAttribute(position, true, static_cast<std::uint32_t>(vertex_count));
  normal_id = -1;
  if (!mesh.normals.empty()) {
    draco::GeometryAttribute normal;
    normal.Init(draco::GeometryAttribute::NORMAL, nullptr, 3, draco::DT_FLOAT32, false,
                sizeof(float) * 3, 0);
    normal_id = draco_mesh.AddAttribute(normal, true, static_cast<std::uint32_t>(vertex_count));
  }
  for (std::uint32_t v = 0; v < vertex_count; ++v) {
    draco_mesh.attribute(position_id)
        ->SetAttributeValue(draco::AttributeValueIndex(v), &mesh.positions[3 * v]);
    if (normal_id >= 0) {
      draco_mesh.attribute(normal_id)
          ->SetAttributeValue(draco::AttributeValueIndex(v), &mesh.normals[3 * v]);
    }
  }
  for (std::size_t t = 0; t < mesh.triangle_indices.size(); t += 3) {
    draco::Mesh::Face face;
    for (int k = 0; k < 3; ++k) face[k] = draco::PointIndex(mesh.triangle_indices[t + k]);
    draco_mesh.AddFace(face);
  }

  // Explicit quantisation on the shared grid: origin on a multiple of the step (the mesh
  // translation is on the grid too), range = step * (2^bits - 1) covering the extent.
  // Draco keeps both in its options as text with six decimals (std::to_string), so they must
  // come back from that text as the same floats, or every decoded position moves: the origin
  // is a multiple of 1/64 (six decimals write it exactly) and the range at least 16 (its
  // seventh decimal is then below half a float step). Measured before this rule: tiles
  // under about 16 m across decoded 1 ulp (1 um) off the grid.
  const double step = options.position_step_m;
  const double origin_grid = std::max(step, kDracoOriginGrid);
  float origin[3];
  double extent = 0;
  for (int k = 0; k < 3; ++k) {
    origin[k] = static_cast<float>(std::floor(bounds.min[k] / origin_grid) * origin_grid);
    extent = std::max(extent, bounds.max[k] - origin[k]);
  }
  const int bits = std::max({1, positionBitsFor(extent, step), positionBitsFor(kDracoMinimumRange, step)});
  if (bits > std::min(options.max_position_bits, 30)) {
    throw Error(ErrorCode::Internal, "a tile spans " + std::to_string(extent) + " m: " + std::to_string(bits) +
                                         " quantisation bits at a step of " + std::to_string(step) +
                                         " m, more than the " + std::to_string(options.max_position_bits) +
                                         " allowed; the step should have been widened (sharedPositionStep)");
  }
  const float range = static_cast<float>(step * (std::ldexp(1.0, bits) - 1));
  for (const float value : {origin[0], origin[1], origin[2], range}) {
    TERRATILES_ASSERT(std::stof(std::to_string(value)) == value);
  }

  draco::Encoder encoder;
  encoder.SetAttributeExplicitQuantization(draco::GeometryAttribute::POSITION, bits, 3, origin,
                                           range);
  if (normal_id >= 0) {
    encoder.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, options.normal_bits);
  }
  encoder.SetSpeedOptions(options.encoding_speed, options.encoding_speed);  // decoding speed does not change the size
  encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  encoder.SetTrackEncodedProperties(true);  // accessor counts must match the decoded mesh
  draco::EncoderBuffer out;
  const draco::Status status = encoder.EncodeMeshToBuffer(draco_mesh, &out);
  if (!status.ok()) {
    throw Error(ErrorCode::Internal, std::string("Draco encoding failed: ") + status.error_msg());
  }
  DracoEncoded encoded;
  encoded.bytes.assign(out.data(), out.data() + out.size());
  encoded.position_id = static_cast<int>(draco_mesh.attribute(position_id)->unique_id());
  if (normal_id >= 0) encoded.normal_id = static_cast<int>(draco_mesh.attribute(normal_id)->unique_id());
  encoded.points = encoder.num_encoded_points();
  encoded.faces = encoder.num_encoded_faces();
  encoded.position_step_m = step;
  encoded.position_bits = bits;
  return encoded;
}

}  // namespace

double snapToStep(double value, double step) { return std::round(value / step) * step; }

int positionBitsFor(double extent_m, double step) {
  int bits = 0;
  while (bits < 62 && step * (std::ldexp(1.0, bits) - 1) < extent_m) ++bits;
  return bits;
}

double sharedPositionStep(double widest_extent_m, double base_step, int max_bits) {
  double step = base_step;
  // A margin: a tile's quantisation origin is its minimum snapped down to the grid of its
  // origins (encodeGlb).
  while (positionBitsFor(widest_extent_m + std::max(step, kDracoOriginGrid), step) > max_bits) step *= 2;
  return step;
}

EncodedGlb encodeGlb(const GlbMesh& mesh, const GlbOptions& options) {
  TERRATILES_ASSERT(mesh.positions.size() % 3 == 0 && mesh.triangle_indices.size() % 3 == 0);
  TERRATILES_ASSERT(mesh.normals.empty() || mesh.normals.size() == mesh.positions.size());
  const std::size_t vertex_count = mesh.vertexCount();
  const Bounds bounds = positionBounds(mesh.positions);

  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = options.generator;
  model.buffers.resize(1);

  tinygltf::Material material;
  material.name = "terrain";
  material.pbrMetallicRoughness.baseColorFactor = {0.78, 0.74, 0.66, 1.0};
  material.pbrMetallicRoughness.metallicFactor = 0.0;
  material.pbrMetallicRoughness.roughnessFactor = 1.0;
  model.materials.push_back(material);

  EncodedGlb result;
  tinygltf::Primitive primitive;
  primitive.mode = TINYGLTF_MODE_TRIANGLES;
  primitive.material = 0;
  const bool wide_indices = vertex_count > 65535;
  const int index_type =
      wide_indices ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT : TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;

  if (options.draco) {
    const DracoEncoded draco = encodeDraco(mesh, options, bounds);
    result.position_step_m = draco.position_step_m;
    result.position_bits = draco.position_bits;
    const int view = appendBufferView(model, draco.bytes.data(), draco.bytes.size(), 0);
    primitive.attributes["POSITION"] =
        addAccessor(model, -1, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, draco.points);
    tinygltf::Value::Object draco_attributes;
    draco_attributes["POSITION"] = tinygltf::Value(draco.position_id);
    if (draco.normal_id >= 0) {
      primitive.attributes["NORMAL"] =
          addAccessor(model, -1, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, draco.points);
      draco_attributes["NORMAL"] = tinygltf::Value(draco.normal_id);
    }
    const int draco_index_type = draco.points > 65535 ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT
                                                      : TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
    primitive.indices =
        addAccessor(model, -1, draco_index_type, TINYGLTF_TYPE_SCALAR, draco.faces * 3);
    tinygltf::Value::Object extension;
    extension["bufferView"] = tinygltf::Value(view);
    extension["attributes"] = tinygltf::Value(draco_attributes);
    primitive.extensions[kDracoExtension] = tinygltf::Value(extension);
    model.extensionsUsed.push_back(kDracoExtension);
    model.extensionsRequired.push_back(kDracoExtension);
  } else {
    const int position_view =
        appendBufferView(model, mesh.positions.data(), mesh.positions.size() * sizeof(float),
                         TINYGLTF_TARGET_ARRAY_BUFFER);
    primitive.attributes["POSITION"] = addAccessor(
        model, position_view, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, vertex_count);
    if (!mesh.normals.empty()) {
      const int normal_view =
          appendBufferView(model, mesh.normals.data(), mesh.normals.size() * sizeof(float),
                           TINYGLTF_TARGET_ARRAY_BUFFER);
      primitive.attributes["NORMAL"] = addAccessor(
          model, normal_view, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, vertex_count);
    }
    int index_view;
    if (wide_indices) {
      index_view = appendBufferView(model, mesh.triangle_indices.data(),
                                    mesh.triangle_indices.size() * sizeof(std::uint32_t),
                                    TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
    } else {
      std::vector<std::uint16_t> narrow(mesh.triangle_indices.begin(), mesh.triangle_indices.end());
      index_view = appendBufferView(model, narrow.data(), narrow.size() * sizeof(std::uint16_t),
                                    TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
    }
    primitive.indices = addAccessor(model, index_view, index_type, TINYGLTF_TYPE_SCALAR,
                                    mesh.triangle_indices.size());
  }
  model.accessors[static_cast<std::size_t>(primitive.attributes["POSITION"])].minValues = bounds.min;
  model.accessors[static_cast<std::size_t>(primitive.attributes["POSITION"])].maxValues = bounds.max;
  while (model.buffers[0].data.size() % 4 != 0) model.buffers[0].data.push_back(0);

  tinygltf::Mesh gltf_mesh;
  gltf_mesh.name = "terrain";
  gltf_mesh.primitives.push_back(primitive);
  model.meshes.push_back(gltf_mesh);

  tinygltf::Node node;
  node.mesh = 0;
  node.translation = {mesh.translation[0], mesh.translation[1], mesh.translation[2]};
  model.nodes.push_back(node);
  tinygltf::Scene scene;
  scene.nodes.push_back(0);
  model.scenes.push_back(scene);
  model.defaultScene = 0;

  std::ostringstream stream;
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model, stream, false, true)) {
    throw Error(ErrorCode::Internal, "tinygltf could not serialise a GLB tile");
  }
  const std::string bytes = stream.str();
  result.bytes.assign(bytes.begin(), bytes.end());
  return result;
}

}  // namespace terratiles
