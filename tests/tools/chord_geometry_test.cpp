// terratiles_chord_check (tools/chord_check): the decoded chords of real builds against the
// DEM at every pixel vertical and against every tile's region.
//
// The acceptance cases on SRTM N57E011 (both schemes) and ETOPO5 assert that no tile's
// decoded triangles, straight chords in ECEF, leave the DEM by more than the tile's
// geometricError at any pixel vertical, and that every region holds every drawn point; the
// ETOPO5 build must also pass `terratiles check` with no tolerance, polar caps included. (On
// the code before the drawn-surface errors, coarse chords sagged up to 217 m below tiles that
// declared 1-10 m.) The self-tests do not depend on that: the tool measures every Interlaken
// tile, a larger candidate margin finds nothing more, and a damaged tileset.json (a squeezed
// region, shrunk errors) makes it fail.
#include <doctest/doctest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "src/base/error.h"
#include "src/pipeline/check_output.h"
#include "tests/test_support.h"
#include "tools/chord_check/chord_geometry.h"
#include "tools/chord_check/run_chord_check.h"

using namespace terratiles;

namespace {

namespace fs = std::filesystem;

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Builds `raster` with `options` into dir/name; returns the output path.
std::string build(const std::string& raster, const std::vector<std::string>& options, const test::TempDir& dir,
                  const std::string& name) {
  std::vector<std::string> args{"build", test::sharedData(raster), "-o", dir / name, "-q", "--no-report"};
  args.insert(args.end(), options.begin(), options.end());
  const auto start = std::chrono::steady_clock::now();
  const auto built = test::runTerratiles(args);
  MESSAGE(raster << " " << name << ": built in " << secondsSince(start) << " s");
  CAPTURE(built.err);
  REQUIRE(built.exit_code == 0);
  return dir / name;
}

ChordReport measure(const std::string& output, const ChordOptions& options = {}) {
  Progress quiet(ProgressMode::Quiet);
  const ChordReport report = measureChordGeometry(output, options, quiet);
  MESSAGE(describeChordReport(report));
  return report;
}

nlohmann::json readJson(const std::string& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

void writeJson(const std::string& path, const nlohmann::json& json) { std::ofstream(path) << json.dump(); }

// Calls visit on every tile with content, depth first.
void forEachContentTile(nlohmann::json& node, const std::function<void(nlohmann::json&)>& visit) {
  if (node.contains("content")) visit(node);
  if (node.contains("children")) {
    for (nlohmann::json& child : node["children"]) forEachContentTile(child, visit);
  }
}

// A copy of an output's tileset.json and build.json beside the original, its tiles linked.
std::string copyOutput(const std::string& from, const std::string& to) {
  fs::create_directories(to);
  fs::copy_file(fs::path(from) / "tileset.json", fs::path(to) / "tileset.json");
  fs::copy_file(fs::path(from) / "build.json", fs::path(to) / "build.json");
  fs::create_directory_symlink(fs::path(from) / "tiles", fs::path(to) / "tiles");
  return to;
}

// One Interlaken build (CHGeo2004) for the self-tests, made on first use.
const std::string& interlakenOutput() {
  static test::TempDir dir;
  static const std::string output =
      build("ch_dhm25_interlaken_25m_2056.tif",
            {"--geoid", test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif")}, dir, "interlaken");
  return output;
}

// The acceptance criterion of the chords: no tile's decoded error over its geometricError,
// no drawn point outside its tile's region.
void checkChordsHonest(const ChordReport& report) {
  CHECK(report.totals.tiles > 0);
  CHECK(report.totals.min_tile_meetings > 0);
  CHECK(report.totals.tiles_over == 0);
  CHECK(report.totals.samples_outside == 0);
  CHECK(report.ok());
}

}  // namespace

TEST_SUITE("chord") {
  TEST_CASE("the chord check measures every Interlaken tile at its pixel verticals") {
    const std::string& output = interlakenOutput();
    const auto start = std::chrono::steady_clock::now();
    const ChordReport report = measure(output);
    MESSAGE("measured in " << secondsSince(start) << " s");
    REQUIRE(report.zooms.size() >= 2);
    CHECK(report.dem_pixels == 350u * 240u);
    for (const ChordZoomRow& row : report.zooms) {
      CAPTURE(row.zoom);
      CHECK(row.tiles > 0);
      CHECK(row.min_tile_meetings > 0);  // every tile meets pixels
      // Every pixel is met at every zoom but a few on the data's outline (decoded vertices
      // move by millimetres; a centre right on the outline may fall outside).
      CHECK(row.unmet_pixels == row.unmet_edge_pixels);
      CHECK(row.pixel_meetings >= report.dem_pixels - row.unmet_pixels);
      CHECK(std::isfinite(row.worst_error_m));
      CHECK(row.worst_error_m > 0);
      CHECK(row.worst_error_m < 100);
      CHECK(row.region_samples > 0);
      // A chord's centroid sags by (|AB|^2 + |BC|^2 + |CA|^2) / (18 R) <= L^2 / (6 R) (2 km: 10 cm).
      CHECK(row.largest_sag_m > 0);
      CHECK(row.largest_sag_m <= row.largest_sag_edge_m * row.largest_sag_edge_m / (6 * 6.3e6) + 0.01);
      CHECK(row.longest_edge_m >= row.largest_sag_edge_m);
    }
    CHECK(report.totals.pole_triangles == 0);

    // The margin is enough: 6 more pixels round every triangle find the same meetings.
    ChordOptions wider;
    wider.extra_margin_px = 6;
    const ChordReport widened = measure(output, wider);
    CHECK(widened.totals.candidate_pixels > report.totals.candidate_pixels);
    CHECK(widened.totals.pixel_meetings == report.totals.pixel_meetings);
    CHECK(widened.totals.worst_error_m == report.totals.worst_error_m);
    CHECK(widened.totals.unmet_pixels == report.totals.unmet_pixels);

    // Triangles counted inside their region without converting their samples: converting
    // every sample gives the same counts.
    ChordOptions every;
    every.convert_every_sample = true;
    const ChordReport converted = measure(output, every);
    CHECK(converted.totals.region_samples == report.totals.region_samples);
    CHECK(converted.totals.samples_outside == report.totals.samples_outside);
    CHECK(converted.totals.worst_excursion_m == report.totals.worst_excursion_m);

    // The command line prints the same table and JSON.
    std::ostringstream out, err;
    const int code = runChordCheck({"terratiles_chord_check", output, "--json", "-q"}, out, err);
    CHECK(code == (report.ok() ? 0 : kChordCheckFailedExitCode));
    const nlohmann::json json = nlohmann::json::parse(out.str());
    CHECK(json["totals"]["pixel_meetings"].get<std::size_t>() == report.totals.pixel_meetings);
    CHECK(json["zooms"].size() == report.zooms.size());
  }

  TEST_CASE("the chord check fails on a squeezed region and on shrunk geometric errors") {
    test::TempDir dir;
    const std::string& output = interlakenOutput();
    const ChordReport original = measure(output);

    // One tile's region squeezed to half its height range and half its latitudes.
    const std::string squeezed = copyOutput(output, dir / "squeezed");
    nlohmann::json tileset = readJson(squeezed + "/tileset.json");
    std::string squeezed_uri;
    forEachContentTile(tileset["root"], [&](nlohmann::json& tile) {
      if (!squeezed_uri.empty()) return;
      nlohmann::json& region = tile["boundingVolume"]["region"];
      const double south = region[1], north = region[3], low = region[4], high = region[5];
      region[3] = south + 0.5 * (north - south);
      region[5] = low + 0.5 * (high - low);
      squeezed_uri = tile["content"]["uri"];
    });
    REQUIRE(!squeezed_uri.empty());
    writeJson(squeezed + "/tileset.json", tileset);
    const ChordReport bad_region = measure(squeezed);
    CHECK(bad_region.totals.samples_outside > original.totals.samples_outside);
    CHECK(bad_region.totals.vertices_outside > 0);
    CHECK(bad_region.totals.worst_excursion_m > 10);
    CHECK(bad_region.totals.tiles_outside <= original.totals.tiles_outside + 1);
    CHECK(squeezed_uri.find(bad_region.totals.worst_excursion_tile.path()) != std::string::npos);
    CHECK_FALSE(bad_region.ok());
    ChordOptions every;
    every.convert_every_sample = true;
    const ChordReport bad_region_converted = measure(squeezed, every);
    CHECK(bad_region_converted.totals.samples_outside == bad_region.totals.samples_outside);
    CHECK(bad_region_converted.totals.worst_excursion_m == bad_region.totals.worst_excursion_m);
    std::ostringstream out, err;
    CHECK(runChordCheck({"terratiles_chord_check", squeezed, "-q"}, out, err) == kChordCheckFailedExitCode);
    CHECK(out.str().find("chord check: FAILED") != std::string::npos);

    // Every geometricError a millimetre: every tile is over.
    const std::string shrunk = copyOutput(output, dir / "shrunk");
    tileset = readJson(shrunk + "/tileset.json");
    forEachContentTile(tileset["root"], [](nlohmann::json& tile) { tile["geometricError"] = 0.001; });
    writeJson(shrunk + "/tileset.json", tileset);
    const ChordReport bad_error = measure(shrunk);
    CHECK(bad_error.totals.tiles_over == bad_error.totals.tiles);
    CHECK(bad_error.totals.worst_ratio > 100);
    CHECK(bad_error.totals.pixel_meetings == original.totals.pixel_meetings);
    CHECK_FALSE(bad_error.ok());
  }

  TEST_CASE("the chord check reads an implicit output through build.json's explicit tree") {
    test::TempDir dir;
    const std::string output = build("ch_dhm25_interlaken_25m_2056.tif",
                                     {"--scheme", "geographic", "--implicit", "--geoid",
                                      test::sharedData("geoid/ch_swisstopo_chgeo2004_ETRS89_LN02.tif")},
                                     dir, "implicit");
    REQUIRE(fs::exists(output + "/tiles/east"));
    std::size_t tiles = 0;
    nlohmann::json build_json = readJson(output + "/build.json");
    forEachContentTile(build_json["explicit_tileset"]["root"], [&](nlohmann::json&) { ++tiles; });
    const ChordReport report = measure(output);
    CHECK(report.totals.tiles == tiles);
    CHECK(report.totals.min_tile_meetings > 0);
    CHECK(report.totals.unmet_pixels == report.totals.unmet_edge_pixels);
    CHECK(std::isfinite(report.totals.worst_error_m));
    CHECK(report.totals.worst_error_m > 0);
  }

  TEST_CASE("the chord check refuses what is not an output with exit code 3") {
    test::TempDir dir;
    Progress quiet(ProgressMode::Quiet);
    try {
      measureChordGeometry(dir.path().string(), quiet);
      FAIL("no error");
    } catch (const Error& e) {
      CHECK(e.code() == ErrorCode::Input);
      const std::string message = e.what();
      CHECK(message.find("tileset.json") != std::string::npos);
      CHECK(message.find("expected a terratiles output directory") != std::string::npos);
      CHECK(message.find('\n') == std::string::npos);
    }
    std::ostringstream out, err;
    CHECK(runChordCheck({"terratiles_chord_check", dir / "missing"}, out, err) == 3);
    CHECK(err.str().rfind("terratiles_chord_check: error: ", 0) == 0);
    std::ostringstream out2, err2;
    CHECK(runChordCheck({"terratiles_chord_check"}, out2, err2) == 2);
    std::ostringstream out3, err3;
    CHECK(runChordCheck({"terratiles_chord_check", dir.path().string(), "--extra-margin-px", "x"}, out3, err3) == 2);
  }

  TEST_CASE("a region's excursion is measured on the circle of longitudes and in metres") {
    constexpr double kDeg = std::numbers::pi / 180;
    // Across the antimeridian: 170 E .. 170 W, 10..20 N, 0..100 m.
    const std::array<double, 6> across{170 * kDeg, 10 * kDeg, -170 * kDeg, 20 * kDeg, 0, 100};
    CHECK_FALSE(detail::regionExcursion(across, 15 * kDeg, 180 * kDeg, 50).outside);
    CHECK_FALSE(detail::regionExcursion(across, 15 * kDeg, -175 * kDeg, 50).outside);
    CHECK_FALSE(detail::regionExcursion(across, 15 * kDeg, 175 * kDeg, 50).outside);
    const auto west = detail::regionExcursion(across, 0, 169 * kDeg, 50);  // 1 degree west, 10 south
    CHECK(west.outside);
    CHECK(west.metres == doctest::Approx(std::hypot(6.37e6 * kDeg, 6.37e6 * 10 * kDeg)).epsilon(1e-9));
    const auto east = detail::regionExcursion(across, 15 * kDeg, -168 * kDeg, 50);  // 2 degrees east
    CHECK(east.metres == doctest::Approx(6.37e6 * 2 * kDeg * std::cos(15 * kDeg)).epsilon(1e-9));
    // The far side of the globe: the nearer end.
    const auto far = detail::regionExcursion(across, 15 * kDeg, 0, 50);
    CHECK(far.metres == doctest::Approx(6.37e6 * 170 * kDeg * std::cos(15 * kDeg)).epsilon(1e-9));
    // Heights, with no tolerance.
    CHECK(detail::regionExcursion(across, 15 * kDeg, 180 * kDeg, 100.001).outside);
    CHECK(detail::regionExcursion(across, 15 * kDeg, 180 * kDeg, -3).metres == doctest::Approx(3));
    // A normal region and the whole circle.
    const std::array<double, 6> normal{0.1, 0.5, 0.2, 0.6, -10, 10};
    CHECK_FALSE(detail::regionExcursion(normal, 0.55, 0.15, 0).outside);
    CHECK(detail::regionExcursion(normal, 0.55, 0.2 + 1e-12, 0).outside);
    const std::array<double, 6> world{-std::numbers::pi, -0.5 * std::numbers::pi, std::numbers::pi,
                                      0.5 * std::numbers::pi, -1e4, 1e4};
    CHECK_FALSE(detail::regionExcursion(world, 0.3, 3.0, 0).outside);
  }

  // ---- The acceptance tests of the drawn-surface errors ----

  TEST_CASE("SRTM N57E011 in web mercator has no tile over its geometricError at the chords") {
    test::TempDir dir;
    const std::string output = build("srtm3_N57E011_4326.tif", {}, dir, "webmercator");
    const auto start = std::chrono::steady_clock::now();
    const ChordReport report = measure(output);
    MESSAGE("measured in " << secondsSince(start) << " s");
    checkChordsHonest(report);
  }

  TEST_CASE("SRTM N57E011 in the geographic scheme has no tile over its geometricError at the chords") {
    test::TempDir dir;
    const std::string output = build("srtm3_N57E011_4326.tif", {"--scheme", "geographic"}, dir, "geographic");
    const auto start = std::chrono::steady_clock::now();
    const ChordReport report = measure(output);
    MESSAGE("measured in " << secondsSince(start) << " s");
    checkChordsHonest(report);
  }

  TEST_CASE("ETOPO5 at 20 m in web mercator has no tile over its geometricError at the chords and passes the check") {
    test::TempDir dir;
    const std::string output = build("etopo5_global_4326.tif", {"--tin-max-error", "20"}, dir, "webmercator");
    const auto start = std::chrono::steady_clock::now();
    const ChordReport report = measure(output);
    MESSAGE("measured in " << secondsSince(start) << " s");
    checkChordsHonest(report);
    CHECK(report.totals.pole_triangles > 0);

    // The same output passes `terratiles check` with no tolerance: no polar cap left out.
    Progress quiet(ProgressMode::Quiet);
    CheckOptions options;
    options.cuts = 300;
    const auto check_start = std::chrono::steady_clock::now();
    const CheckReport check = checkOutput(output, options, quiet);
    MESSAGE("checked in " << secondsSince(check_start) << " s\n" << describeCheck(check));
    test::checkSeamless(check);
    CHECK(check.uncovered_valid_pixels == 0);  // ETOPO5 has no nodata
    CHECK(check.pole_vertices > 0);
  }
}
