// The build report: every build writes report.json (checked against
// src/pipeline/report_schema.json and against the files on disk) and report.html;
// `terratiles report` regenerates them, also for an output written before reports existed;
// --progress json ends with a summary line.
#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "formats/gltf/read_glb.h"
#include "tests/test_support.h"
#include "tileset/implicit_tileset.h"

using namespace terratiles;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

json readJson(const fs::path& path) {
  std::ifstream in(path);
  REQUIRE(in.good());
  return json::parse(in);
}

// The part of JSON Schema (2020-12) report_schema.json uses: type, enum, required,
// properties, items, minItems, minimum, maximum, exclusiveMinimum.
void validate(const json& value, const json& schema, const std::string& where, std::vector<std::string>& errors) {
  const auto typeMatches = [&](const std::string& type) {
    if (type == "object") return value.is_object();
    if (type == "array") return value.is_array();
    if (type == "string") return value.is_string();
    if (type == "integer") return value.is_number_integer();
    if (type == "number") return value.is_number();
    if (type == "boolean") return value.is_boolean();
    if (type == "null") return value.is_null();
    return false;
  };
  if (schema.contains("type")) {
    bool matched = false;
    if (schema["type"].is_array()) {
      for (const json& type : schema["type"]) matched |= typeMatches(type.get<std::string>());
    } else {
      matched = typeMatches(schema["type"].get<std::string>());
    }
    if (!matched) {
      errors.push_back(where + ": " + value.dump().substr(0, 40) + " is not " + schema["type"].dump());
      return;
    }
  }
  if (schema.contains("enum") && std::find(schema["enum"].begin(), schema["enum"].end(), value) == schema["enum"].end()) {
    errors.push_back(where + ": " + value.dump() + " not in " + schema["enum"].dump());
  }
  if (value.is_number()) {
    const double v = value.get<double>();
    if (schema.contains("minimum") && v < schema["minimum"].get<double>()) errors.push_back(where + ": below minimum");
    if (schema.contains("maximum") && v > schema["maximum"].get<double>()) errors.push_back(where + ": above maximum");
    if (schema.contains("exclusiveMinimum") && v <= schema["exclusiveMinimum"].get<double>()) {
      errors.push_back(where + ": not above exclusiveMinimum");
    }
  }
  if (value.is_object()) {
    for (const json& key : schema.value("required", json::array())) {
      if (!value.contains(key.get<std::string>())) errors.push_back(where + ": missing " + key.get<std::string>());
    }
    if (schema.contains("properties")) {
      for (const auto& [key, sub] : schema["properties"].items()) {
        if (value.contains(key)) validate(value[key], sub, where + "." + key, errors);
      }
    }
  }
  if (value.is_array()) {
    if (schema.contains("minItems") && value.size() < schema["minItems"].get<std::size_t>()) {
      errors.push_back(where + ": fewer than minItems");
    }
    if (schema.contains("items")) {
      for (std::size_t i = 0; i < value.size(); ++i) validate(value[i], schema["items"], where + "[" + std::to_string(i) + "]", errors);
    }
  }
}

void checkAgainstSchema(const json& report) {
  std::vector<std::string> errors;
  validate(report, readJson(fs::path(test::sourceDir()) / "src/pipeline/report_schema.json"), "report", errors);
  for (const std::string& error : errors) MESSAGE(error);
  CHECK(errors.empty());
}

// What the files say per zoom: tiles, bytes, decoded triangles, largest geometricError.
struct DiskZoom {
  std::size_t tiles = 0, bytes = 0, triangles = 0;
  double geometric_error_m = 0;
};

std::map<int, DiskZoom> zoomsOnDisk(const fs::path& dir) {
  const json tileset = readJson(dir / "tileset.json");
  std::map<int, DiskZoom> zooms;
  std::vector<json> open{tileset["root"]};
  while (!open.empty()) {
    const json node = open.back();
    open.pop_back();
    if (node.contains("content")) {
      const std::string uri = node["content"]["uri"];
      TileKey key;
      REQUIRE(tileKeyFromContentUri(uri, key));
      std::ifstream in(dir / uri, std::ios::binary);
      const std::vector<std::uint8_t> bytes{std::istreambuf_iterator<char>(in), {}};
      DiskZoom& z = zooms[key.zoom];
      ++z.tiles;
      z.bytes += bytes.size();
      z.triangles += decodeGlb(bytes, uri).mesh.triangle_indices.size() / 3;
      z.geometric_error_m = std::max(z.geometric_error_m, node["geometricError"].get<double>());
    }
    for (const json& child : node.value("children", json::array())) open.push_back(child);
  }
  return zooms;
}

void checkZoomsAgreeWithDisk(const json& report, const fs::path& dir) {
  const std::map<int, DiskZoom> disk = zoomsOnDisk(dir);
  REQUIRE(report["zooms"].size() == disk.size());
  std::size_t tiles = 0, bytes = 0, triangles = 0;
  for (const json& z : report["zooms"]) {
    const int zoom = z["zoom"];
    CAPTURE(zoom);
    REQUIRE(disk.count(zoom) == 1);
    const DiskZoom& d = disk.at(zoom);
    CHECK(z["tiles"].get<std::size_t>() == d.tiles);
    CHECK(z["bytes"].get<std::size_t>() == d.bytes);
    CHECK(z["tile_triangles"].get<std::size_t>() == d.triangles);
    CHECK(z["geometric_error_m"].get<double>() == doctest::Approx(d.geometric_error_m).epsilon(1e-12));
    if (z.contains("max_error_m")) CHECK(z["max_error_m"].get<double>() <= d.geometric_error_m);
    tiles += d.tiles;
    bytes += d.bytes;
    triangles += d.triangles;
  }
  CHECK(report["totals"]["tiles"].get<std::size_t>() == tiles);
  CHECK(report["totals"]["bytes"].get<std::size_t>() == bytes);
  CHECK(report["totals"]["tile_triangles"].get<std::size_t>() == triangles);
}

std::string readText(const fs::path& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

}  // namespace

TEST_SUITE("report") {
  TEST_CASE("builds of Interlaken and SRTM N57E011 write a report that matches the schema and the files") {
    test::TempDir dir;
    const std::vector<std::pair<std::string, std::vector<std::string>>> builds{
        {"interlaken",
         {test::sharedData("ch_dhm25_interlaken_25m_2056.tif"), "--geoid",
          test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif")}},
        {"srtm", {test::sharedData("srtm3_N57E011_4326.tif"), "--tin-max-error", "2"}}};
    for (const auto& [name, inputs] : builds) {
      CAPTURE(name);
      std::vector<std::string> args{"build", "-o", dir / name, "-q"};
      args.insert(args.end(), inputs.begin(), inputs.end());
      const auto built = test::runTerratiles(args);
      CAPTURE(built.err);
      REQUIRE(built.exit_code == 0);
      const json report = readJson(fs::path(dir / name) / "report.json");
      checkAgainstSchema(report);
      checkZoomsAgreeWithDisk(report, dir / name);
      CHECK(report["zooms"].size() >= 3);
      // What only the build knows: stages with times and memory, maps of every zoom, the check.
      CHECK(report["stages"].size() >= 5);
      for (const json& stage : report["stages"]) CHECK(stage["peak_rss_bytes"].get<std::uint64_t>() > 0);
      REQUIRE(report["maps"].size() == report["zooms"].size());
      for (const json& map : report["maps"]) {
        CHECK(map["width"].get<int>() <= 640);
        // "iVBORw0KGgo" is base64 of the PNG signature.
        CHECK(map["clusters_png"].get<std::string>().rfind("data:image/png;base64,iVBORw0KGgo", 0) == 0);
        CHECK(map["error_png"].get<std::string>().rfind("data:image/png;base64,iVBORw0KGgo", 0) == 0);
      }
      CHECK(report["maps"][0]["clusters"].get<int>() > 1);
      REQUIRE(report["check"].is_object());
      CHECK(report["check"]["ok"] == true);
      CHECK(report["check"]["cuts"].get<int>() >= 200);
      const std::string html = readText(fs::path(dir / name) / "report.html");
      CHECK(html.rfind("<!DOCTYPE html>", 0) == 0);
      CHECK(html.find("http://") == std::string::npos);
      CHECK(html.find("https://") == std::string::npos);
      // Not part of the tileset.
      CHECK(readText(fs::path(dir / name) / "tileset.json").find("report") == std::string::npos);
    }
  }

  TEST_CASE("terratiles report regenerates a report, also for an output older than reports, and refuses what it cannot") {
    test::TempDir dir;
    const std::string out = dir / "n57";
    REQUIRE(test::runTerratiles({"build", test::sharedData("srtm3_N57E011_4326.tif"), "--tin-max-error", "5", "-o",
                                 out, "-q", "--no-report"})
                .exit_code == 0);
    CHECK_FALSE(fs::exists(fs::path(out) / "report.json"));
    // As an output from before reports: rebuilt from its files, with the check re-run.
    const auto rebuilt = test::runTerratiles({"report", out, "--cuts", "50"});
    CAPTURE(rebuilt.err);
    REQUIRE(rebuilt.exit_code == 0);
    CHECK(rebuilt.err.find("rebuilt from the files") != std::string::npos);
    const json report = readJson(fs::path(out) / "report.json");
    checkAgainstSchema(report);
    checkZoomsAgreeWithDisk(report, out);
    CHECK(report["rebuilt_from_files"] == true);
    CHECK(report["check"]["ok"] == true);
    CHECK(report["maps"].empty());
    CHECK(fs::exists(fs::path(out) / "report.html"));

    // A build's own report: report.html comes back from report.json, maps and all.
    const std::string il = dir / "interlaken";
    REQUIRE(test::runTerratiles({"build", test::sharedData("ch_dhm25_interlaken_25m_2056.tif"), "-o", il, "-q"})
                .exit_code == 0);
    const std::string first = readText(fs::path(il) / "report.html");
    fs::remove(fs::path(il) / "report.html");
    const auto again = test::runTerratiles({"report", il, "--cuts", "0"});
    CAPTURE(again.err);
    REQUIRE(again.exit_code == 0);
    CHECK(again.err.find("from the build's report.json") != std::string::npos);
    CHECK(readText(fs::path(il) / "report.html") == first);

    // A damaged report.json: refused with the way out, and nothing half-written.
    {
      std::ofstream damaged(fs::path(il) / "report.json");
      damaged << "{broken";
    }
    const auto damaged = test::runTerratiles({"report", il, "--cuts", "0"});
    CHECK(damaged.exit_code == 3);
    CHECK(damaged.err.find("not valid JSON") != std::string::npos);
    CHECK(damaged.err.find("delete it") != std::string::npos);
    CHECK(readText(fs::path(il) / "report.html") == first);

    // Without build.json the source DEM is unknown: a clear refusal, exit 3.
    fs::remove(fs::path(out) / "build.json");
    fs::remove(fs::path(out) / "report.json");
    const auto refused = test::runTerratiles({"report", out});
    CHECK(refused.exit_code == 3);
    CHECK(refused.err.find("build.json") != std::string::npos);
    CHECK(refused.err.find("rebuild") != std::string::npos);
    const auto missing = test::runTerratiles({"report", dir / "nothing-here"});
    CHECK(missing.exit_code == 3);
  }

  TEST_CASE("--progress json ends with a summary line naming the report") {
    test::TempDir dir;
    const auto built = test::runTerratiles(
        {"build", test::sharedData("us_mn_lidar_dtm_1m_26915.tif"), "-o", dir / "mn", "--progress", "json"});
    REQUIRE(built.exit_code == 0);
    std::istringstream lines(built.err);
    std::string line, last;
    std::size_t count = 0;
    while (std::getline(lines, line)) {
      CAPTURE(line);
      const bool parses = json::accept(line);
      CHECK(parses);
      last = line;
      ++count;
    }
    // The progress lines go to the process's stderr (tests/base/progress_test.cpp checks
    // them); the CLI's own stream gets the summary, as one JSON line too.
    CHECK(count >= 1);
    const json summary = json::parse(last);
    CHECK(summary["event"] == "summary");
    CHECK(summary["report"].get<std::string>().find("report.html") != std::string::npos);
    CHECK(summary["check"] == "ok");
    CHECK(summary["tiles"].get<int>() >= 1);
  }
}
