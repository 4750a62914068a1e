#include "formats/output_directory.h"

#include <unistd.h>

#include <fstream>
#include <system_error>

#include "src/base/error.h"

namespace fs = std::filesystem;

namespace terratiles {
namespace {

[[noreturn]] void outputError(const fs::path& path, const std::string& what, const std::string& fix) {
  throw Error(ErrorCode::Output, path.string() + ": " + what + "; " + fix);
}

}  // namespace

OutputDirectory::OutputDirectory(const fs::path& target, bool force, const std::string& marker)
    : target_(target) {
  const fs::path absolute = checkTarget(force, marker);
  const fs::path parent = absolute.parent_path();
  std::error_code ec;
  staging_ = parent / ("." + absolute.filename().string() + ".terratiles-partial-" + std::to_string(::getpid()));
  fs::remove_all(staging_, ec);
  fs::create_directory(staging_, ec);
  if (ec) {
    outputError(target_, "cannot write in " + parent.string() + " (" + ec.message() + ")",
                "check the path and permissions");
  }
}

OutputDirectory::OutputDirectory(const fs::path& target, bool force, const KeptStaging& kept_staging,
                                 const std::string& marker)
    : target_(target), staging_(kept_staging.path), kept_(true) {
  checkTarget(force, marker);
  std::error_code ec;
  fs::create_directories(staging_, ec);
  if (ec) {
    outputError(staging_, "cannot create the staging directory (" + ec.message() + ")",
                "check the path and permissions");
  }
}

fs::path OutputDirectory::checkTarget(bool force, const std::string& marker) {
  std::error_code ec;
  if (target_.empty()) throw Error(ErrorCode::Usage, "the output directory name is empty");
  const fs::file_status status = fs::status(target_, ec);
  if (fs::exists(status)) {
    if (!fs::is_directory(status)) {
      outputError(target_, "exists and is not a directory", "choose another output directory");
    }
    if (!fs::is_empty(target_, ec)) {
      if (!force) {
        outputError(target_, "output directory is not empty",
                    "use --force to replace a previous output or choose another directory");
      }
      if (!fs::exists(target_ / marker, ec)) {
        outputError(target_, "is not empty and holds no " + marker,
                    "refusing to replace it even with --force; choose another directory");
      }
    }
  }
  fs::path absolute = fs::absolute(target_, ec);
  if (ec) outputError(target_, "cannot resolve the path (" + ec.message() + ")", "check the path");
  absolute = absolute.lexically_normal();
  if (!absolute.has_filename()) absolute = absolute.parent_path();
  const fs::path parent = absolute.parent_path();
  fs::create_directories(parent, ec);
  if (ec) {
    outputError(target_, "cannot create the parent directory " + parent.string() + " (" +
                             ec.message() + ")",
                "check the path and permissions");
  }
  return absolute;
}

OutputDirectory::~OutputDirectory() {
  if (committed_ || kept_) return;
  std::error_code ec;
  fs::remove_all(staging_, ec);
}

std::size_t OutputDirectory::writeFile(const std::string& relative_path,
                                       std::span<const std::uint8_t> bytes) {
  const fs::path final_path = staging_ / relative_path;
  const fs::path temporary = final_path.string() + ".tmp";
  std::error_code ec;
  fs::create_directories(final_path.parent_path(), ec);
  if (ec) outputError(final_path.parent_path(), "cannot create directory (" + ec.message() + ")",
                      "check free space and permissions");
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) {
      outputError(temporary, "cannot write " + std::to_string(bytes.size()) + " bytes",
                  "check free space and permissions");
    }
  }
  fs::rename(temporary, final_path, ec);
  if (ec) outputError(final_path, "cannot rename the finished file (" + ec.message() + ")",
                      "check permissions");
  return bytes.size();
}

std::size_t OutputDirectory::writeFile(const std::string& relative_path, const std::string& text) {
  return writeFile(relative_path, std::span<const std::uint8_t>(
                                      reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
}

void OutputDirectory::commit() {
  std::error_code ec;
  fs::path previous;
  if (fs::exists(target_, ec)) {
    previous = staging_.string() + "-previous";
    fs::rename(target_, previous, ec);
    if (ec) {
      outputError(target_, "cannot move the previous output aside (" + ec.message() + ")",
                  "remove it by hand or choose another directory");
    }
  }
  fs::rename(staging_, target_, ec);
  if (ec) {
    if (!previous.empty()) fs::rename(previous, target_, ec);  // put the old output back
    outputError(target_, "cannot move the finished output into place (" + ec.message() + ")",
                "check permissions");
  }
  committed_ = true;
  if (!previous.empty()) fs::remove_all(previous, ec);
}

}  // namespace terratiles
