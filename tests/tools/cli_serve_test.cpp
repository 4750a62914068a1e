// `terratiles serve OUTDIR`: refuses what it cannot serve, with the fix; serves a real output
// on 127.0.0.1 through the CesiumJS viewer's server (a real HTTP request reads tileset.json).
#include <doctest/doctest.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "tests/test_support.h"

extern char** environ;
namespace fs = std::filesystem;

namespace {

std::string readText(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// GET path from 127.0.0.1:port; the whole response (headers and body), or empty.
std::string httpGet(int port, const std::string& path) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return {};
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string response;
  if (connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0) {
    const std::string request = "GET " + path + " HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
    if (write(fd, request.data(), request.size()) == static_cast<ssize_t>(request.size())) {
      char buffer[65536];
      for (ssize_t n; (n = read(fd, buffer, sizeof buffer)) > 0;) response.append(buffer, static_cast<std::size_t>(n));
    }
  }
  close(fd);
  return response;
}

}  // namespace

TEST_SUITE("cli") {
  TEST_CASE("serve refuses a directory without a tileset, a missing viewer and a bad port, each with the fix") {
    terratiles::test::TempDir dir;
    const auto no_tileset = terratiles::test::runTerratiles({"serve", dir.path().string()});
    CHECK(no_tileset.exit_code == 3);
    CHECK(no_tileset.err.find("no tileset.json") != std::string::npos);
    std::ofstream(dir / "tileset.json") << "{}";
    setenv("TERRATILES_VIEWER_DIR", (dir / "no-viewer-here").c_str(), 1);
    const auto no_viewer = terratiles::test::runTerratiles({"serve", dir.path().string()});
    unsetenv("TERRATILES_VIEWER_DIR");
    CHECK(no_viewer.exit_code == 3);
    CHECK(no_viewer.err.find("TERRATILES_VIEWER_DIR") != std::string::npos);
    CHECK(terratiles::test::runTerratiles({"serve", dir.path().string(), "--port", "70000"}).exit_code == 2);
  }

  TEST_CASE("serve prints the viewer's URL and serves the output on 127.0.0.1") {
    terratiles::test::TempDir dir;
    const std::string out = dir / "out";
    REQUIRE(terratiles::test::runTerratiles({"build", terratiles::test::sharedData("us_mn_lidar_dtm_1m_26915.tif"), "-o",
                                             out, "-q", "--no-report"})
                .exit_code == 0);
    const std::string out_path = dir / "stdout.txt";
    std::vector<std::string> args{TERRATILES_BINARY, "serve", out, "--port", "0"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_t pid = 0;
    REQUIRE(posix_spawn(&pid, TERRATILES_BINARY, &actions, nullptr, argv.data(), environ) == 0);
    posix_spawn_file_actions_destroy(&actions);

    // A safety net for a loaded machine, not a timing assertion.
    const std::regex url_line(R"(Viewer: http://127\.0\.0\.1:(\d+)/)");
    std::smatch match;
    std::string printed;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (std::chrono::steady_clock::now() < deadline) {
      printed = readText(out_path);
      if (std::regex_search(printed, match, url_line)) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    CAPTURE(printed);
    const bool announced = std::regex_search(printed, match, url_line);
    std::string tileset_response, page_response;
    if (announced) {
      const int port = std::stoi(match[1]);
      tileset_response = httpGet(port, "/data/tileset.json");
      page_response = httpGet(port, "/");
    }
    kill(pid, SIGTERM);
    int status = 0;
    waitpid(pid, &status, 0);
    REQUIRE(announced);
    CHECK(tileset_response.rfind("HTTP/1.1 200", 0) == 0);
    CHECK(tileset_response.find(readText(out + "/tileset.json")) != std::string::npos);
    CHECK(page_response.rfind("HTTP/1.1 200", 0) == 0);
    CHECK(page_response.find("<html") != std::string::npos);
  }
}
