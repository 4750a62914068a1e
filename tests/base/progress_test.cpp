#include <doctest/doctest.h>

#include <chrono>
#include <cstdio>
#include <thread>
#include <string>

#include "src/base/error.h"
#include "src/base/progress.h"

using namespace terratiles;

namespace {
std::string readAll(std::FILE* file) {
  std::rewind(file);
  std::string text;
  char buffer[256];
  while (std::fgets(buffer, sizeof buffer, file)) text += buffer;
  return text;
}
}  // namespace

TEST_SUITE("base") {
  TEST_CASE("json progress writes one object per line for stage steps and end") {
    std::FILE* file = std::tmpfile();
    {
      Progress progress(ProgressMode::Json, file);
      progress.beginStage("tiles \"x\"", 3);
      progress.advance();
      progress.advance(2);
      progress.endStage();
    }
    const std::string text = readAll(file);
    std::fclose(file);
    CHECK(text.find("{\"event\":\"stage\",\"stage\":\"tiles \\\"x\\\"\",\"total\":3}\n") == 0);
    CHECK(text.find("\"event\":\"progress\"") != std::string::npos);
    CHECK(text.find("\"event\":\"stage_done\"") != std::string::npos);
  }

  TEST_CASE("json progress gives the time a stage still needs at its rate so far") {
    std::FILE* file = std::tmpfile();
    {
      Progress progress(ProgressMode::Json, file);
      progress.beginStage("blocks", 4);
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
      progress.advance();  // a quarter done after 0.2 s: about 0.6 s left
    }
    const std::string text = readAll(file);
    std::fclose(file);
    const std::size_t at = text.find("\"eta_seconds\":");
    REQUIRE(at != std::string::npos);
    const double eta = std::stod(text.substr(at + 14));
    CHECK(eta >= 0.55);
    CHECK(eta < 10.0);
    CHECK(text.find("\"seconds\":") != std::string::npos);
  }

  TEST_CASE("quiet progress writes nothing") {
    std::FILE* file = std::tmpfile();
    {
      Progress progress(ProgressMode::Quiet, file);
      progress.beginStage("tiles", 10);
      progress.advance(10);
      progress.note("hello");
    }
    CHECK(readAll(file).empty());
    std::fclose(file);
  }

  TEST_CASE("a cancel request stops the next step with the cancelled code") {
    Progress progress(ProgressMode::Quiet);
    progress.beginStage("work", 10);
    Progress::requestCancel();
    try {
      progress.advance();
      FAIL("advance did not throw after a cancel request");
    } catch (const Error& e) {
      CHECK(e.code() == ErrorCode::Cancelled);
      CHECK(exitCodeFor(e.code()) == 130);
    }
    Progress::resetCancel();
    CHECK_NOTHROW(progress.advance());
  }

  TEST_CASE("exit codes follow the documented table") {
    CHECK(exitCodeFor(ErrorCode::Internal) == 1);
    CHECK(exitCodeFor(ErrorCode::Usage) == 2);
    CHECK(exitCodeFor(ErrorCode::Input) == 3);
    CHECK(exitCodeFor(ErrorCode::Output) == 4);
    CHECK(exitCodeFor(ErrorCode::OutOfMemory) == 6);
  }
}
