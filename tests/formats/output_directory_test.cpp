#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>

#include "formats/output_directory.h"
#include "src/base/error.h"
#include "tests/test_support.h"

using namespace terratiles;
namespace fs = std::filesystem;

namespace {
std::string slurp(const fs::path& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
ErrorCode openError(const fs::path& target, bool force, std::string& message) {
  try {
    OutputDirectory output(target, force);
  } catch (const Error& e) {
    message = e.what();
    return e.code();
  }
  return ErrorCode::Internal;
}
}  // namespace

TEST_SUITE("formats") {
  TEST_CASE("nothing appears at the target until commit") {
    test::TempDir dir;
    const fs::path target = dir.path() / "out";
    {
      OutputDirectory output(target, false);
      output.writeFile("tiles/0/0/0.glb", std::string("abc"));
      output.writeFile("tileset.json", std::string("{}"));
      CHECK_FALSE(fs::exists(target));
      output.commit();
    }
    CHECK(slurp(target / "tileset.json") == "{}");
    CHECK(slurp(target / "tiles/0/0/0.glb") == "abc");
    // No staging directory and no temporary file is left behind.
    std::size_t entries = 0;
    for (const auto& entry : fs::recursive_directory_iterator(dir.path())) {
      CHECK(entry.path().string().find(".tmp") == std::string::npos);
      CHECK(entry.path().string().find("partial") == std::string::npos);
      ++entries;
    }
    CHECK(entries == 6);  // out, out/tiles, tiles/0, tiles/0/0, 0.glb, tileset.json
  }

  TEST_CASE("a failed run leaves neither the target nor the staging directory") {
    test::TempDir dir;
    const fs::path target = dir.path() / "out";
    {
      OutputDirectory output(target, false);
      output.writeFile("tileset.json", std::string("{}"));
    }  // destroyed without commit, as when an exception unwinds
    CHECK(fs::is_empty(dir.path()));
  }

  TEST_CASE("a non-empty target is refused without force and replaced with force") {
    test::TempDir dir;
    const fs::path target = dir.path() / "out";
    fs::create_directories(target);
    std::ofstream(target / "tileset.json") << "old";
    std::ofstream(target / "stale.glb") << "old";
    std::string message;
    CHECK(openError(target, false, message) == ErrorCode::Output);
    CHECK(message.find("output directory is not empty; use --force") != std::string::npos);
    {
      OutputDirectory output(target, true);
      output.writeFile("tileset.json", std::string("new"));
      output.commit();
    }
    CHECK(slurp(target / "tileset.json") == "new");
    CHECK_FALSE(fs::exists(target / "stale.glb"));
  }

  TEST_CASE("force never replaces a directory that holds no previous output") {
    test::TempDir dir;
    std::ofstream(dir.path() / "precious.txt") << "keep";
    std::string message;
    CHECK(openError(dir.path(), true, message) == ErrorCode::Output);
    CHECK(message.find("holds no tileset.json") != std::string::npos);
    CHECK(slurp(dir.path() / "precious.txt") == "keep");
  }

  TEST_CASE("an output below a regular file is an output error") {
    test::TempDir dir;
    std::ofstream(dir.path() / "file") << "x";
    std::string message;
    CHECK(openError(dir.path() / "file" / "out", false, message) == ErrorCode::Output);
    CHECK(message.find("cannot create the parent directory") != std::string::npos);
    CHECK(openError(dir.path() / "file", false, message) == ErrorCode::Output);
    CHECK(message.find("exists and is not a directory") != std::string::npos);
  }
}
