// Ctrl-C during a build: the process exits 130 with one line and leaves nothing behind.
#include <doctest/doctest.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "tests/test_support.h"

extern char** environ;
namespace fs = std::filesystem;

TEST_SUITE("cli") {
  TEST_CASE("an interrupted build exits 130 and leaves no output or staging directory") {
    terratiles::test::TempDir dir;
    const std::string out = dir / "out";
    const std::string err_path = dir / "stderr.txt";
    // The 2401 x 1201 SRTM raster at 10 m takes about 15 s: long enough to interrupt.
    std::vector<std::string> args{TERRATILES_BINARY, "build",
                                  terratiles::test::sharedData("srtm3_N00E010-E011_4326.tif"),
                                  "-o", out, "--progress", "json", "--tin-max-error", "10"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_t pid = 0;
    REQUIRE(posix_spawn(&pid, TERRATILES_BINARY, &actions, nullptr, argv.data(), environ) == 0);
    posix_spawn_file_actions_destroy(&actions);

    // Interrupt once the tiles are being written (the staging directory holds files).
    // A generous safety net, not a timing assertion: a loaded machine may take minutes.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(900);
    bool writing = false;
    while (!writing && std::chrono::steady_clock::now() < deadline) {
      std::ifstream progress(err_path);
      const std::string text((std::istreambuf_iterator<char>(progress)), std::istreambuf_iterator<char>());
      writing = text.find("\"stage\":\"writing tiles\"") != std::string::npos;
      if (!writing) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    REQUIRE(writing);
    kill(pid, SIGINT);
    int status = 0;
    REQUIRE(waitpid(pid, &status, 0) == pid);
    REQUIRE(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 130);

    std::ifstream err_in(err_path);
    const std::string err((std::istreambuf_iterator<char>(err_in)), std::istreambuf_iterator<char>());
    CHECK(err.find("terratiles: error: interrupted; no output was written\n") != std::string::npos);
    CHECK_FALSE(fs::exists(out));
    for (const auto& entry : fs::directory_iterator(dir.path())) {
      CHECK(entry.path().filename() == "stderr.txt");  // no staging directory left
    }
  }
}
