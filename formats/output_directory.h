#pragma once
// OutputDirectory: writes a whole output (tileset.json, tiles, report) into a staging
// directory beside the target and moves it into place only when everything is written, so
// a failed or interrupted run never leaves a tileset.json that points at missing or
// half-written tiles.
//
// The target must not exist, be empty, or (with force) hold a previous output (a
// tileset.json); any other non-empty directory is refused even with force, so a typo in -o
// cannot delete unrelated data. Throws Error(Output) with the path and the fix.

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

namespace terratiles {

class OutputDirectory {
 public:
  // marker: the file that identifies a previous output of the same command, which force may
  // replace (tileset.json for build, levels.json for levels).
  OutputDirectory(const std::filesystem::path& target, bool force, const std::string& marker = "tileset.json");
  // The build in blocks: the staging directory is `kept_staging` (created when missing, what it
  // holds kept), which another rank or a resumed run finds again; it is not removed when the
  // output is not committed.
  struct KeptStaging {
    std::filesystem::path path;
  };
  OutputDirectory(const std::filesystem::path& target, bool force, const KeptStaging& kept_staging,
                  const std::string& marker = "tileset.json");
  ~OutputDirectory();  // removes the staging directory unless committed or kept
  OutputDirectory(const OutputDirectory&) = delete;
  OutputDirectory& operator=(const OutputDirectory&) = delete;

  // Writes `relative_path` (e.g. "tiles/3/4/2.glb") inside the staging directory, through
  // a temporary name renamed when complete. Returns the number of bytes written.
  std::size_t writeFile(const std::string& relative_path, std::span<const std::uint8_t> bytes);
  std::size_t writeFile(const std::string& relative_path, const std::string& text);

  // Moves the staged output into place (replacing a previous output when forced).
  void commit();

  const std::filesystem::path& target() const { return target_; }
  const std::filesystem::path& staging() const { return staging_; }

 private:
  // Refuses a target that is no output to replace; returns its absolute path (its parent created).
  std::filesystem::path checkTarget(bool force, const std::string& marker);

  std::filesystem::path target_;
  std::filesystem::path staging_;
  bool kept_ = false;
  bool committed_ = false;
};

}  // namespace terratiles
