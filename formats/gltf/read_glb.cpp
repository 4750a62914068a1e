#include "formats/gltf/read_glb.h"

#include <draco/compression/decode.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <vector>

#include "src/base/error.h"

namespace terratiles {
namespace {

using nlohmann::json;

std::uint32_t readU32(std::span<const std::uint8_t> bytes, std::size_t offset) {
  std::uint32_t value;
  std::memcpy(&value, bytes.data() + offset, 4);
  return value;
}

[[noreturn]] void malformed(const std::string& name, const std::string& what) {
  throw Error(ErrorCode::Input, name + ": malformed GLB: " + what);
}

// Plain (non-Draco) accessor read as floats or indices.
template <typename Out>
std::vector<Out> readAccessor(const json& gltf, std::span<const std::uint8_t> bin, int index,
                              const std::string& name) {
  const json& accessor = gltf.at("accessors").at(static_cast<std::size_t>(index));
  const json& view = gltf.at("bufferViews").at(accessor.at("bufferView").get<std::size_t>());
  const std::size_t count = accessor.at("count").get<std::size_t>();
  const int component = accessor.at("componentType").get<int>();
  const std::string type = accessor.at("type").get<std::string>();
  const std::size_t components = type == "VEC3" ? 3 : type == "SCALAR" ? 1 : 0;
  if (components == 0) malformed(name, "unsupported accessor type " + type);
  const std::size_t offset =
      view.value("byteOffset", std::size_t{0}) + accessor.value("byteOffset", std::size_t{0});
  const std::size_t size = component == 5126 || component == 5125 ? 4 : component == 5123 ? 2 : 1;
  const std::size_t stride = view.value("byteStride", components * size);
  std::vector<Out> out;
  out.reserve(count * components);
  for (std::size_t i = 0; i < count; ++i) {
    for (std::size_t k = 0; k < components; ++k) {
      const std::size_t at = offset + i * stride + k * size;
      if (at + size > bin.size()) malformed(name, "accessor reads past the binary chunk");
      if (component == 5126) {
        float v;
        std::memcpy(&v, bin.data() + at, 4);
        out.push_back(static_cast<Out>(v));
      } else if (component == 5125) {
        out.push_back(static_cast<Out>(readU32(bin, at)));
      } else if (component == 5123) {
        std::uint16_t v;
        std::memcpy(&v, bin.data() + at, 2);
        out.push_back(static_cast<Out>(v));
      } else if (component == 5121) {
        out.push_back(static_cast<Out>(bin[at]));
      } else {
        malformed(name, "unsupported component type " + std::to_string(component));
      }
    }
  }
  return out;
}

void decodeDracoPrimitive(const json& extension, const json& gltf, std::span<const std::uint8_t> bin,
                          GlbMesh& out, const std::string& name) {
  const json& view = gltf.at("bufferViews").at(extension.at("bufferView").get<std::size_t>());
  const std::size_t offset = view.value("byteOffset", std::size_t{0});
  const std::size_t length = view.at("byteLength").get<std::size_t>();
  if (offset + length > bin.size()) malformed(name, "Draco buffer view past the binary chunk");
  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(bin.data() + offset), length);
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) malformed(name, std::string("Draco: ") + decoded.status().error_msg());
  const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();

  const auto base = static_cast<std::uint32_t>(out.vertexCount());
  const json& attributes = extension.at("attributes");
  const draco::PointAttribute* position =
      mesh->GetAttributeByUniqueId(attributes.at("POSITION").get<std::uint32_t>());
  if (!position) malformed(name, "Draco data has no POSITION attribute");
  const draco::PointAttribute* normal =
      attributes.contains("NORMAL")
          ? mesh->GetAttributeByUniqueId(attributes.at("NORMAL").get<std::uint32_t>())
          : nullptr;
  for (draco::PointIndex p(0); p < mesh->num_points(); ++p) {
    float value[3];
    position->GetMappedValue(p, value);
    out.positions.insert(out.positions.end(), value, value + 3);
    if (normal) {
      normal->GetMappedValue(p, value);
      out.normals.insert(out.normals.end(), value, value + 3);
    }
  }
  for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f) {
    const auto& face = mesh->face(f);
    for (int k = 0; k < 3; ++k) out.triangle_indices.push_back(base + face[k].value());
  }
}

}  // namespace

DecodedGlb decodeGlb(std::span<const std::uint8_t> bytes, const std::string& name) {
  if (bytes.size() < 20) malformed(name, "shorter than a GLB header");
  if (readU32(bytes, 0) != 0x46546C67u) malformed(name, "no 'glTF' magic");
  if (readU32(bytes, 4) != 2) malformed(name, "GLB version is not 2");
  if (readU32(bytes, 8) != bytes.size()) malformed(name, "header length differs from file size");
  const std::uint32_t json_length = readU32(bytes, 12);
  if (readU32(bytes, 16) != 0x4E4F534Au || 20 + std::size_t{json_length} > bytes.size()) {
    malformed(name, "first chunk is not a JSON chunk");
  }
  DecodedGlb result;
  result.json.assign(reinterpret_cast<const char*>(bytes.data() + 20), json_length);
  std::span<const std::uint8_t> bin;
  const std::size_t bin_header = 20 + std::size_t{json_length};
  if (bin_header + 8 <= bytes.size()) {
    const std::uint32_t bin_length = readU32(bytes, bin_header);
    if (readU32(bytes, bin_header + 4) != 0x004E4942u || bin_header + 8 + bin_length > bytes.size()) {
      malformed(name, "second chunk is not a BIN chunk");
    }
    bin = bytes.subspan(bin_header + 8, bin_length);
  }
  try {
    const json gltf = json::parse(result.json);
    const json& node = gltf.at("nodes").at(0);
    if (node.contains("translation")) {
      for (std::size_t k = 0; k < 3; ++k) result.mesh.translation[k] = node["translation"][k];
    }
    for (const json& primitive : gltf.at("meshes").at(0).at("primitives")) {
      if (primitive.value("mode", 4) != 4) malformed(name, "primitive is not triangles");
      const auto extensions = primitive.find("extensions");
      if (extensions != primitive.end() && extensions->contains("KHR_draco_mesh_compression")) {
        result.draco = true;
        decodeDracoPrimitive(extensions->at("KHR_draco_mesh_compression"), gltf, bin, result.mesh,
                             name);
        continue;
      }
      const auto base = static_cast<std::uint32_t>(result.mesh.vertexCount());
      const json& attributes = primitive.at("attributes");
      auto positions = readAccessor<float>(gltf, bin, attributes.at("POSITION").get<int>(), name);
      result.mesh.positions.insert(result.mesh.positions.end(), positions.begin(), positions.end());
      if (attributes.contains("NORMAL")) {
        auto normals = readAccessor<float>(gltf, bin, attributes.at("NORMAL").get<int>(), name);
        result.mesh.normals.insert(result.mesh.normals.end(), normals.begin(), normals.end());
      }
      auto indices = readAccessor<std::uint32_t>(gltf, bin, primitive.at("indices").get<int>(), name);
      for (auto index : indices) result.mesh.triangle_indices.push_back(base + index);
    }
  } catch (const json::exception& e) {
    malformed(name, e.what());
  }
  return result;
}

DecodedGlb readGlbFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorCode::Input, path + ": cannot open GLB file");
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return decodeGlb(bytes, path);
}

}  // namespace terratiles
