// Inputs at scale: a raster cut into many files (as gdal_translate -srcwin cuts it), given as
// the files, a directory, an input list or a GDAL VRT of the pieces, builds the same bytes
// as the raster in one file, and `terratiles check` reads the pieces back.
#include <doctest/doctest.h>

#include <gdal_priv.h>
#include <gdal_utils.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "src/base/progress.h"
#include "src/pipeline/check_output.h"
#include "tests/test_support.h"

using namespace terratiles;
namespace fs = std::filesystem;

namespace {

// gdal_translate -srcwin x y w h, in-process: the window of `dataset` as the GeoTIFF `path`.
void cutWindow(GDALDatasetH dataset, int x, int y, int w, int h, const std::string& path) {
  const std::vector<std::string> words{"-q", "-srcwin", std::to_string(x), std::to_string(y), std::to_string(w),
                                       std::to_string(h)};
  std::vector<char*> argv;
  for (const std::string& word : words) argv.push_back(const_cast<char*>(word.c_str()));
  argv.push_back(nullptr);
  GDALTranslateOptions* options = GDALTranslateOptionsNew(argv.data(), nullptr);
  int failed = 0;
  GDALDatasetH piece = GDALTranslate(path.c_str(), dataset, options, &failed);
  GDALTranslateOptionsFree(options);
  REQUIRE(piece != nullptr);
  REQUIRE(failed == 0);
  GDALClose(piece);
}

// Cuts `source` into a columns x rows grid of GeoTIFFs in `dir` (the last column and row take
// the remainder). Returns their paths, row by row.
std::vector<std::string> cutIntoPieces(const std::string& source, int columns, int rows, const fs::path& dir) {
  GDALAllRegister();
  GDALDatasetH dataset = GDALOpen(source.c_str(), GA_ReadOnly);
  REQUIRE(dataset != nullptr);
  const int width = GDALGetRasterXSize(dataset), height = GDALGetRasterYSize(dataset);
  const int piece_width = width / columns, piece_height = height / rows;
  std::vector<std::string> pieces;
  for (int row = 0; row < rows; ++row) {
    for (int column = 0; column < columns; ++column) {
      const int x = column * piece_width, y = row * piece_height;
      const int w = column + 1 == columns ? width - x : piece_width;
      const int h = row + 1 == rows ? height - y : piece_height;
      const std::string path = (dir / ("piece_" + std::to_string(row) + "_" + std::to_string(column) + ".tif")).string();
      cutWindow(dataset, x, y, w, h, path);
      pieces.push_back(path);
    }
  }
  GDALClose(dataset);
  return pieces;
}

// gdalbuildvrt, in-process.
void buildVrt(const std::string& path, const std::vector<std::string>& sources) {
  std::vector<const char*> names;
  for (const std::string& source : sources) names.push_back(source.c_str());
  int failed = 0;
  GDALDatasetH vrt = GDALBuildVRT(path.c_str(), static_cast<int>(names.size()), nullptr, names.data(), nullptr, &failed);
  REQUIRE(vrt != nullptr);
  REQUIRE(failed == 0);
  GDALClose(vrt);
}

// SRTM Gabon cut into 8 x 6 GeoTIFFs in dir/pieces and their VRT, dir/pieces.vrt; the pieces.
std::vector<std::string> gabonPieces(const test::TempDir& dir) {
  fs::create_directories(dir.path() / "pieces");
  const std::vector<std::string> pieces =
      cutIntoPieces(test::sharedData("srtm3_N00E010-E011_4326.tif"), 8, 6, dir.path() / "pieces");
  REQUIRE(pieces.size() == 48);
  // gdalbuildvrt recomputes the pixel size (8.3333333333333252e-04 instead of the pieces'
  // 8.333333333333e-04 degrees): the build reads such a VRT through its sources.
  buildVrt(dir / "pieces.vrt", pieces);
  return pieces;
}

// The tiles and tileset.json of an output (build.json and the report name the inputs).
std::map<std::string, std::string> tileBytes(const fs::path& out) { return test::filesUnder(out, {"tileset.json", "tiles/"}); }

void checkSameBytes(const std::map<std::string, std::string>& expected, const std::map<std::string, std::string>& found) {
  REQUIRE(expected.size() == found.size());
  for (const auto& [path, bytes] : expected) {
    CAPTURE(path);
    REQUIRE(found.count(path) == 1);
    CHECK(found.at(path) == bytes);
  }
}

}  // namespace

TEST_SUITE("cli") {
  TEST_CASE("SRTM Gabon cut into 48 files builds the same tiles as one file, from a directory, a list or a VRT") {
    test::TempDir dir;
    const std::string gabon = test::sharedData("srtm3_N00E010-E011_4326.tif");
    const std::vector<std::string> pieces = gabonPieces(dir);
    {
      std::ofstream list(dir / "pieces.txt");
      list << "# the pieces, one per line\n\n";
      for (const std::string& piece : pieces) list << piece << "\n";
    }

    // 20 m keeps each build to a few seconds; the report (and its check) only where it is
    // asserted below.
    const auto build = [&](std::vector<std::string> inputs, const std::string& name, bool report) {
      std::vector<std::string> args{"build"};
      args.insert(args.end(), inputs.begin(), inputs.end());
      for (const char* option : {"-q", "--tin-max-error", "20"}) args.push_back(option);
      if (!report) args.push_back("--no-report");
      args.push_back("-o");
      args.push_back(dir / name);
      const auto result = test::runTerratiles(args);
      CAPTURE(result.err);
      REQUIRE(result.exit_code == 0);
      return tileBytes(dir.path() / name);
    };
    const auto whole = build({gabon}, "whole", false);
    REQUIRE(whole.size() > 50);
    checkSameBytes(whole, build(pieces, "files", false));
    checkSameBytes(whole, build({dir / "pieces"}, "directory", true));
    checkSameBytes(whole, build({"--input-list", dir / "pieces.txt"}, "list", false));
    checkSameBytes(whole, build({dir / "pieces.vrt"}, "vrt", false));

    // The check reads the 48 pieces the build recorded, and finds the output seamless.
    Progress quiet;
    CheckOptions options;
    options.cuts = 300;
    test::checkSeamless(checkOutput(dir / "directory", options, quiet));
  }

  TEST_CASE("SRTM Gabon cut into 48 files builds in blocks the same tiles as one file and as a VRT, and they check") {
    test::TempDir dir;
    const std::string gabon = test::sharedData("srtm3_N00E010-E011_4326.tif");
    const std::vector<std::string> pieces = gabonPieces(dir);
    // Blocks of at most 512 px: tiles of zoom 10 (about 420 px), 7 x 3 of them over the
    // raster's 2401 x 1201 px, which write zoom 11 on their own; zooms 8 to 10 are made from
    // their joined levels at zoom 10.
    const auto build = [&](std::vector<std::string> inputs, const std::string& name) {
      std::vector<std::string> args{"build"};
      args.insert(args.end(), inputs.begin(), inputs.end());
      for (const char* option : {"--tin-max-error", "20", "--no-report", "--block-pixels", "512"}) args.push_back(option);
      args.push_back("-o");
      args.push_back(dir / name);
      const auto result = test::runTerratiles(args);
      CAPTURE(result.err);
      REQUIRE(result.exit_code == 0);
      CHECK(result.err.find("  blocks   21 (7 x 3 tiles of zoom 10, at most 512 px a side) wrote zooms 11 to 11\n") !=
            std::string::npos);
      CHECK_FALSE(fs::exists(dir.path() / (name + ".blocks")));
      return tileBytes(dir.path() / name);
    };
    const auto whole = build({gabon}, "whole");
    REQUIRE(whole.size() > 50);
    checkSameBytes(whole, build(pieces, "files"));
    checkSameBytes(whole, build({dir / "pieces.vrt"}, "vrt"));
    // Zooms 8 to 10 measured against the DEM in strips of about 40 rows (plus the rows their
    // tallest triangle reaches) instead of the whole raster at once: the same bytes.
    checkSameBytes(whole, build({gabon, "--strip-pixels", "100000"}, "strips"));
    // Zooms 8 to 10 simplified against an overview of the DEM (1 pixel of 8 x 8, 301 x 151)
    // instead of the DEM: other levels, the same zoom 11, and still measured on every pixel.
    const auto overview = build({gabon, "--overview-pixels", "80000", "--strip-pixels", "100000"}, "overview");
    REQUIRE(overview.size() == whole.size());
    std::size_t same = 0;
    for (const auto& [name, bytes] : whole) same += overview.at(name) == bytes ? 1 : 0;
    CHECK(same >= 78);          // zoom 11's tiles
    CHECK(same < whole.size());  // and not the coarser ones

    // Seamless within and across zooms, every decoded error within its geometricError: the
    // blocks' tiles meet their neighbours' and the coarser zooms' vertex for vertex.
    Progress quiet;
    CheckOptions options;
    options.cuts = 300;
    test::checkSeamless(checkOutput(dir / "files", options, quiet));
    test::checkSeamless(checkOutput(dir / "overview", options, quiet));
  }

  TEST_CASE("a polar cut of ETOPO5 builds in blocks over an overview whose last row runs past the pole") {
    // ETOPO5's rows are centred on whole multiples of 5' down to -90 exactly. 121 of them
    // (-80 to -90), 174,240 px against --overview-pixels 20000, make an overview of 1 pixel of
    // 4 x 4 (360 x 31): rows of 4 mosaic rows and a last one of the pole row alone,
    // centred 1.5 mosaic rows past the pole: its geoid undulation is the one across the pole
    // (this build stopped with "outside the geoid grid" before).
    test::TempDir dir;
    GDALAllRegister();
    GDALDatasetH etopo5 = GDALOpen(test::sharedData("etopo5_global_4326.tif").c_str(), GA_ReadOnly);
    REQUIRE(etopo5 != nullptr);
    REQUIRE(GDALGetRasterYSize(etopo5) == 2161);
    const std::string polar = dir / "etopo5_south_pole.tif";
    cutWindow(etopo5, 0, 2040, 1440, 121, polar);
    GDALClose(etopo5);
    const auto result = test::runTerratiles({"build", polar, "-o", dir / "out", "--scheme", "geographic",
                                             "--tin-max-error", "5", "--block-pixels", "256", "--overview-pixels",
                                             "20000", "--no-report"});
    INFO(result.err);
    REQUIRE(result.exit_code == 0);
    Progress quiet;
    CheckOptions options;
    options.cuts = 300;
    test::checkSeamless(checkOutput(dir / "out", options, quiet));
  }

  TEST_CASE("inputs that are no mosaic are refused before anything is written") {
    test::TempDir dir;
    fs::create_directories(dir.path() / "empty");
    {
      std::ofstream(dir / "empty/readme.txt") << "no rasters here\n";
    }
    auto result = test::runTerratiles({"build", dir / "empty", "-o", dir / "out"});
    CHECK(result.exit_code == 3);
    CHECK(result.err.find("empty: directory holds no raster files") != std::string::npos);
    CHECK(result.err.find("--input-list") != std::string::npos);

    {
      std::ofstream list(dir / "list.txt");
      list << test::sharedData("srtm3_N57E011_4326.tif") << "\n" << dir / "missing.tif" << "\n";
    }
    result = test::runTerratiles({"build", "--input-list", dir / "list.txt", "-o", dir / "out"});
    CHECK(result.exit_code == 3);
    CHECK(result.err.find("list.txt line 2: " + dir / "missing.tif" + ": no such file or directory") !=
          std::string::npos);

    // A raster in another CRS among the pieces: the first offending file is named.
    result = test::runTerratiles({"build", test::sharedData("srtm3_N57E011_4326.tif"),
                                  test::sharedData("ch_dhm25_interlaken_25m_2056.tif"), "-o", dir / "out"});
    CHECK(result.exit_code == 3);
    CHECK(result.err.find("ch_dhm25_interlaken_25m_2056.tif: CRS is EPSG:2056 but") != std::string::npos);

    result = test::runTerratiles({"build", "-o", dir / "out"});
    CHECK(result.exit_code == 2);
    CHECK(result.err.find("no input raster given") != std::string::npos);
    CHECK(!fs::exists(dir.path() / "out"));
  }
}
