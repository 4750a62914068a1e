#pragma once
// readTilesetTree: a tileset.json with its external tilesets (tilesetFiles) put back in place,
// as one tree, for the programs that walk an output (check, report, chord check, tests).

#include <filesystem>

#include <nlohmann/json.hpp>

namespace terratiles {

// The tileset at `tileset_path`, where every tile whose content is a .json file (an external
// tileset) is replaced by that tileset's root, its content uris made relative to
// `tileset_path`'s directory again. Throws Error(Input) naming the file that cannot be read,
// is not JSON, or is referenced again below itself.
nlohmann::json readTilesetTree(const std::filesystem::path& tileset_path);

}  // namespace terratiles
