#include <doctest/doctest.h>
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "tests/test_support.h"

using namespace terratiles;
using test::runTerratiles;
using test::sharedData;
namespace fs = std::filesystem;

namespace {
const std::string kInterlaken = sharedData("ch_dhm25_interlaken_25m_2056.tif");

// One line on stderr, starting with the program name.
void checkOneLineError(const test::CliResult& result, const std::string& expected_part) {
  CAPTURE(result.err);
  CHECK(result.err.rfind("terratiles: error: ", 0) == 0);
  CHECK(result.err.find('\n') == result.err.size() - 1);
  CHECK(result.err.find(expected_part) != std::string::npos);
}
}  // namespace

TEST_SUITE("cli") {
  TEST_CASE("version and help succeed and document units defaults and exit codes") {
    const auto version = runTerratiles({"--version"});
    CHECK(version.exit_code == 0);
    CHECK(version.out.rfind("terratiles 0.", 0) == 0);

    const auto help = runTerratiles({"build", "--help"});
    CHECK(help.exit_code == 0);
    CHECK(help.out.find("--tile-cells") != std::string::npos);
    CHECK(help.out.find("--tile-cells INT=128") != std::string::npos);  // default shown
    CHECK(help.out.find("metres") != std::string::npos);
    CHECK(help.out.find("Exit codes: 0 ok, 1 internal error, 2 usage, 3 bad input, 4 output") !=
          std::string::npos);
    CHECK(help.out.find("6 out of memory") != std::string::npos);
  }

  TEST_CASE("usage errors exit 2 with one line") {
    const auto unknown = runTerratiles({"build", kInterlaken, "-o", "x", "--frobnicate"});
    CHECK(unknown.exit_code == 2);
    checkOneLineError(unknown, "--frobnicate");

    const auto no_output = runTerratiles({"build", kInterlaken});
    CHECK(no_output.exit_code == 2);
    checkOneLineError(no_output, "--output");

    const auto no_command = runTerratiles({});
    CHECK(no_command.exit_code == 2);
    checkOneLineError(no_command, "subcommand");

    test::TempDir dir;
    const auto bad_value = runTerratiles({"build", kInterlaken, "-o", dir / "out", "--tile-cells", "1"});
    CHECK(bad_value.exit_code == 2);
    checkOneLineError(bad_value, "--tile-cells is 1; expected 2 to 4096");
    CHECK_FALSE(fs::exists(dir.path() / "out"));

    const auto bad_threads = runTerratiles({"build", kInterlaken, "-o", dir / "out", "--threads", "-1"});
    CHECK(bad_threads.exit_code == 2);
    checkOneLineError(bad_threads, "--threads: Value -1 not in range 0 to 1024");
    CHECK_FALSE(fs::exists(dir.path() / "out"));
  }

  TEST_CASE("bad inputs exit 3 and leave no output behind") {
    test::TempDir dir;
    const std::string out = dir / "out";

    const auto missing = runTerratiles({"build", "/nonexistent/dem.tif", "-o", out});
    CHECK(missing.exit_code == 3);
    checkOneLineError(missing, "/nonexistent/dem.tif: no such file or directory; check the path");

    std::ofstream(dir / "notes.txt") << "this is not a raster\n";
    const auto not_raster = runTerratiles({"build", dir / "notes.txt", "-o", out});
    CHECK(not_raster.exit_code == 3);
    checkOneLineError(not_raster, "notes.txt: not a raster that GDAL can read");

    const DemGrid dem = test::makeDem(16, 16, 2.0, [](int c, int r) { return 500.0 + c - r; });
    test::writeGeoTiff(dem, dir / "nocrs.tif", false);
    const auto no_crs = runTerratiles({"build", dir / "nocrs.tif", "-o", out});
    CHECK(no_crs.exit_code == 3);
    checkOneLineError(no_crs, "nocrs.tif: raster has no coordinate reference system");

    CHECK_FALSE(fs::exists(out));
    // Nothing else was left in the parent either (no staging directory).
    std::size_t entries = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir.path())) ++entries;
    CHECK(entries == 2);  // notes.txt and nocrs.tif
  }

  TEST_CASE("a build that runs out of memory exits 6 with one line and leaves nothing behind") {
    // The real binary under a 300 MiB address-space limit (Gabon's build peaks near 400 MB
    // of RSS): an allocation fails somewhere in the pipeline, whichever it is.
    test::TempDir dir;
    const std::string out = dir / "out";
    const std::string err_path = dir / "stderr.txt";
    std::vector<std::string> args{TERRATILES_BINARY, "build", sharedData("srtm3_N00E010-E011_4326.tif"), "-o", out,
                                  "--tin-max-error", "5", "--progress", "none"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const pid_t pid = fork();
    REQUIRE(pid >= 0);
    if (pid == 0) {
      const rlimit limit{300ull << 20, 300ull << 20};
      const int fd = open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd < 0 || dup2(fd, STDERR_FILENO) < 0 || setrlimit(RLIMIT_AS, &limit) != 0) _exit(99);
      execv(TERRATILES_BINARY, argv.data());
      _exit(98);
    }
    int status = 0;
    REQUIRE(waitpid(pid, &status, 0) == pid);
    REQUIRE(WIFEXITED(status));
    std::ifstream err_in(err_path);
    test::CliResult result;
    result.err.assign(std::istreambuf_iterator<char>(err_in), std::istreambuf_iterator<char>());
    CHECK(WEXITSTATUS(status) == 6);
    checkOneLineError(result, "out of memory; a build needs about 120 bytes per input pixel");
    CHECK_FALSE(fs::exists(out));
    std::size_t entries = 0;  // no staging directory either
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir.path())) ++entries;
    CHECK(entries == 1);  // stderr.txt
  }

  TEST_CASE("unwritable or occupied output directories exit 4") {
    test::TempDir dir;
    std::ofstream(dir / "file") << "x";
    const auto below_file = runTerratiles({"build", kInterlaken, "-o", dir / "file/out"});
    CHECK(below_file.exit_code == 4);
    checkOneLineError(below_file, "cannot create the parent directory");

    const auto in_proc = runTerratiles({"build", kInterlaken, "-o", "/proc/terratiles-out"});
    CHECK(in_proc.exit_code == 4);
    checkOneLineError(in_proc, "/proc/terratiles-out");

    fs::create_directories(dir.path() / "busy");
    std::ofstream(dir / "busy/data.txt") << "x";
    const auto busy = runTerratiles({"build", kInterlaken, "-o", dir / "busy"});
    CHECK(busy.exit_code == 4);
    checkOneLineError(busy, "output directory is not empty; use --force");
    CHECK_FALSE(fs::exists(dir.path() / "busy/tileset.json"));
  }
}
