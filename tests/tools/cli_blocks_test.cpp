// Blocks as units of work (src/pipeline/block_tin.h, block_build.h): spread over MPI ranks,
// and kept by an interrupted run for --resume. Either way the TIN file, or the tiles and
// tileset, are the ones a single uninterrupted process writes, byte for byte.
#include <doctest/doctest.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>

#include "tests/test_support.h"

extern char** environ;
namespace fs = std::filesystem;
using namespace terratiles;

namespace {

std::string fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// SRTM Gabon (2401 x 1201 px) at 2 m in blocks of 128 px: 190 blocks.
std::vector<std::string> gabonTin(const std::string& output) {
  return {"tin", test::sharedData("srtm3_N00E010-E011_4326.tif"), "-o", output, "--tin-max-error", "2",
          "--block-pixels", "128"};
}

// SRTM Gabon (2401 x 1201 px) built at 5 m in blocks of at most 256 px: 13 x 6 tiles of
// zoom 11, each writing zoom 12.
std::vector<std::string> gabonBuild(const std::string& output) {
  return {"build", test::sharedData("srtm3_N00E010-E011_4326.tif"), "-o", output, "--tin-max-error", "5",
          "--block-pixels", "256", "--no-report"};
}

// `args` under mpirun with `ranks` ranks; what it said goes to `said`. Returns the exit status.
int runUnderMpirun(const char* mpirun, int ranks, const std::vector<std::string>& args, const std::string& said) {
  std::string command = std::string(mpirun) + " --allow-run-as-root --oversubscribe -np " + std::to_string(ranks) + " " +
                        TERRATILES_BINARY;
  for (const std::string& arg : args) command += " '" + arg + "'";
  command += " 2> '" + said + "'";
  return std::system(command.c_str());
}

// Runs terratiles with `args` and kills it with SIGKILL once `folder` holds `count` files ending
// in `extension` (a safety net of 600 s, not a timing assertion); it must not have finished.
// Returns how many such files it left.
std::size_t killWhenDone(std::vector<std::string> args, const fs::path& folder, const std::string& extension,
                         std::size_t count) {
  args.insert(args.begin(), TERRATILES_BINARY);
  args.push_back("-q");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  REQUIRE(posix_spawn(&pid, TERRATILES_BINARY, nullptr, nullptr, argv.data(), environ) == 0);
  const auto done = [&] {
    std::size_t found = 0;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(folder, ec)) found += entry.path().extension() == extension;
    return found;
  };
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(600);
  int status = 0;
  bool exited = false;
  while (done() < count && std::chrono::steady_clock::now() < deadline) {
    exited = waitpid(pid, &status, WNOHANG) == pid;
    if (exited) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  REQUIRE_FALSE(exited);
  kill(pid, SIGKILL);
  REQUIRE(waitpid(pid, &status, 0) == pid);
  CHECK(WIFSIGNALED(status));
  return done();
}

}  // namespace

TEST_SUITE("cli") {
  TEST_CASE("tin in blocks under mpirun -np 2 and -np 4 writes the very file of one process") {
    const char* mpirun = "/usr/bin/mpirun";
    if (!fs::exists(mpirun)) {
      MESSAGE("skipped: no " << mpirun << " (Debian's openmpi-bin; tools/setup/install_dependencies.sh installs it)");
      return;
    }
    test::TempDir dir;
    std::vector<std::string> one = gabonTin(dir / "one.ply");
    one.push_back("-q");
    REQUIRE(test::runTerratiles(one).exit_code == 0);
    for (const int ranks : {2, 4}) {
      CAPTURE(ranks);
      const std::string output = dir / ("ranks" + std::to_string(ranks) + ".ply");
      const int status = runUnderMpirun(mpirun, ranks, gabonTin(output), dir / "mpirun.txt");
      const std::string said = fileBytes(dir / "mpirun.txt");
      CAPTURE(said);
      REQUIRE(status == 0);
      CHECK(said.find("(190 blocks on " + std::to_string(ranks) + " ranks;") != std::string::npos);
      CHECK(fileBytes(output) == fileBytes(dir / "one.ply"));
      CHECK_FALSE(fs::exists(output + ".blocks"));
    }
  }

  TEST_CASE("tin in blocks killed half-way and run again with --resume writes the very file of an uninterrupted run") {
    test::TempDir dir;
    std::vector<std::string> whole = gabonTin(dir / "whole.ply");
    whole.push_back("-q");
    REQUIRE(test::runTerratiles(whole).exit_code == 0);

    const std::string output = dir / "resumed.ply", blocks = output + ".blocks";
    // SIGKILL once about a third of the blocks are done.
    const std::size_t kept = killWhenDone(gabonTin(output), blocks, ".bin", 60);
    CHECK_FALSE(fs::exists(output));  // nothing at the output's name
    CHECK(kept >= 60);
    CHECK(kept < 190);

    // Other options do not resume these blocks; without --resume they are dropped and made
    // again.
    std::vector<std::string> other = gabonTin(output);
    other[5] = "3";  // --tin-max-error
    other.push_back("--resume");
    const auto refused = test::runTerratiles(other);
    CHECK(refused.exit_code == 2);
    CHECK(refused.err.find("holds the blocks of another run") != std::string::npos);

    std::vector<std::string> resume = gabonTin(output);
    resume.push_back("--resume");
    const auto resumed = test::runTerratiles(resume);
    REQUIRE(resumed.exit_code == 0);
    CHECK(resumed.err.find(", " + std::to_string(kept) + " resumed;") != std::string::npos);
    CHECK(fileBytes(output) == fileBytes(dir / "whole.ply"));
    CHECK_FALSE(fs::exists(blocks));
  }

  TEST_CASE("build in blocks under mpirun -np 2 and -np 4 writes the very tiles and tileset of one process") {
    const char* mpirun = "/usr/bin/mpirun";
    if (!fs::exists(mpirun)) {
      MESSAGE("skipped: no " << mpirun << " (Debian's openmpi-bin; tools/setup/install_dependencies.sh installs it)");
      return;
    }
    test::TempDir dir;
    std::vector<std::string> one = gabonBuild(dir / "one");
    one.push_back("-q");
    REQUIRE(test::runTerratiles(one).exit_code == 0);
    const auto expected = test::filesUnder(dir.path() / "one", {"tileset.json", "tiles/"});
    REQUIRE(expected.size() > 300);
    for (const int ranks : {2, 4}) {
      CAPTURE(ranks);
      const std::string output = dir / ("ranks" + std::to_string(ranks));
      const int status = runUnderMpirun(mpirun, ranks, gabonBuild(output), dir / "mpirun.txt");
      const std::string said = fileBytes(dir / "mpirun.txt");
      CAPTURE(said);
      REQUIRE(status == 0);
      CHECK(said.find("  blocks   78 (13 x 6 tiles of zoom 11, at most 256 px a side, on " + std::to_string(ranks) +
                      " ranks) wrote zooms 12 to 12\n") != std::string::npos);
      CHECK(test::filesUnder(output, {"tileset.json", "tiles/"}) == expected);
      CHECK_FALSE(fs::exists(output + ".blocks"));
    }
  }

  TEST_CASE("build in blocks killed half-way and run again with --resume writes the very output of an uninterrupted run") {
    test::TempDir dir;
    std::vector<std::string> whole = gabonBuild(dir / "whole");
    whole.push_back("-q");
    REQUIRE(test::runTerratiles(whole).exit_code == 0);
    const auto expected = test::filesUnder(dir.path() / "whole", {"tileset.json", "tiles/"});

    // SIGKILL once 30 of the 78 blocks have written their tiles and handed over their levels.
    const std::string output = dir / "resumed", blocks = output + ".blocks";
    const std::size_t kept = killWhenDone(gabonBuild(output), blocks, ".build", 30);
    CHECK_FALSE(fs::exists(output));  // nothing at the output's name
    CHECK(kept >= 30);
    CHECK(kept < 78);

    std::vector<std::string> other = gabonBuild(output);
    other[5] = "6";  // --tin-max-error
    other.push_back("--resume");
    const auto refused = test::runTerratiles(other);
    CHECK(refused.exit_code == 2);
    CHECK(refused.err.find("holds the blocks of another build") != std::string::npos);

    std::vector<std::string> resume = gabonBuild(output);
    resume.push_back("--resume");
    const auto resumed = test::runTerratiles(resume);
    CAPTURE(resumed.err);
    REQUIRE(resumed.exit_code == 0);
    CHECK(resumed.err.find("wrote zooms 12 to 12; resumed: of rank 0's 78 blocks, 78 had their TIN and " +
                           std::to_string(kept) + " their levels and tiles already\n") != std::string::npos);
    CHECK(test::filesUnder(output, {"tileset.json", "tiles/"}) == expected);
    CHECK_FALSE(fs::exists(blocks));
  }

  TEST_CASE("blocks too small for the zooms are refused with the --block-pixels that fits") {
    // Gabon at 5 m has zooms up to 12; blocks of 128 px are tiles of zoom 12, which leaves the
    // blocks no finer zoom to write. Blocks of 256 px (zoom 11) are what the tests above build.
    test::TempDir dir;
    std::vector<std::string> args = gabonBuild(dir / "out");
    args[7] = "128";  // --block-pixels
    const auto refused = test::runTerratiles(args);
    CAPTURE(refused.err);
    CHECK(refused.exit_code == 2);
    CHECK(refused.err.find("blocks of 128 pixels are tiles of zoom 12, but the zooms are") != std::string::npos);
    CHECK(refused.err.find("pass a --block-pixels of about 256 ") != std::string::npos);
    CHECK_FALSE(fs::exists(dir / "out"));
  }
}
