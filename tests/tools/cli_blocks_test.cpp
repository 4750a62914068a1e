// Blocks as units of work (src/pipeline/block_tin.h): spread over MPI ranks, and kept by an
// interrupted run for --resume. Either way the file is the one a single uninterrupted process
// writes, byte for byte.
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
      std::string command = std::string(mpirun) + " --allow-run-as-root --oversubscribe -np " + std::to_string(ranks) +
                            " " + TERRATILES_BINARY;
      for (const std::string& arg : gabonTin(output)) command += " '" + arg + "'";
      command += " 2> '" + (dir / "mpirun.txt") + "'";
      const int status = std::system(command.c_str());
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
    std::vector<std::string> args = gabonTin(output);
    args.insert(args.begin(), TERRATILES_BINARY);
    args.push_back("-q");
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_t pid = 0;
    REQUIRE(posix_spawn(&pid, TERRATILES_BINARY, nullptr, nullptr, argv.data(), environ) == 0);
    // SIGKILL once about a third of the blocks are done (a safety net, not a timing assertion).
    const auto done = [&] {
      std::size_t count = 0;
      std::error_code ec;
      for (const auto& entry : fs::directory_iterator(blocks, ec)) count += entry.path().extension() == ".bin";
      return count;
    };
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(600);
    int status = 0;
    bool exited = false;
    while (done() < 60 && std::chrono::steady_clock::now() < deadline) {
      exited = waitpid(pid, &status, WNOHANG) == pid;
      if (exited) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    REQUIRE_FALSE(exited);
    kill(pid, SIGKILL);
    REQUIRE(waitpid(pid, &status, 0) == pid);
    CHECK(WIFSIGNALED(status));
    CHECK_FALSE(fs::exists(output));  // nothing at the output's name
    const std::size_t kept = done();
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
}
