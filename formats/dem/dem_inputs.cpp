#include "formats/dem/dem_inputs.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>

#include "src/base/error.h"

namespace terratiles {
namespace {

namespace fs = std::filesystem;

bool hasRasterExtension(const fs::path& path) {
  for (const char* known : kRasterExtensions) {
    if (hasExtension(path.string(), known)) return true;
  }
  return false;
}

void addDirectory(const std::string& directory, std::vector<std::string>& files) {
  std::vector<std::string> found;
  std::error_code ec;
  for (fs::directory_iterator it(directory, ec), end; !ec && it != end; it.increment(ec)) {
    const fs::path& path = it->path();
    if (path.filename().string().front() == '.') continue;  // hidden files, editors' temporaries
    std::error_code type_ec;
    if (it->is_regular_file(type_ec) && hasRasterExtension(path)) found.push_back(path.string());
  }
  if (ec) {
    throw Error(ErrorCode::Input, directory + ": cannot list the directory (" + ec.message() +
                                      "); check its permissions");
  }
  if (found.empty()) {
    throw Error(ErrorCode::Input, directory +
                                      ": directory holds no raster files (.tif, .tiff, .vrt, .hgt, .asc, "
                                      ".img, ...); name the rasters, or list them with --input-list FILE");
  }
  std::sort(found.begin(), found.end());
  files.insert(files.end(), found.begin(), found.end());
}

void addInput(const std::string& input, const std::string& where, std::vector<std::string>& files) {
  std::error_code ec;
  const fs::file_status status = fs::status(input, ec);
  if (!fs::exists(status)) {
    throw Error(ErrorCode::Input, where + input + ": no such file or directory; check the path");
  }
  if (fs::is_directory(status)) {
    addDirectory(input, files);
  } else {
    files.push_back(input);
  }
}

}  // namespace

bool hasExtension(const std::string& path, const char* extension) {
  std::string found = fs::path(path).extension().string();
  std::transform(found.begin(), found.end(), found.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return found == extension;
}

std::vector<std::string> expandDemInputs(const std::vector<std::string>& arguments,
                                         const std::string& input_list_path) {
  std::vector<std::string> files;
  for (const std::string& argument : arguments) addInput(argument, {}, files);
  if (!input_list_path.empty()) {
    std::ifstream list(input_list_path);
    if (!list) {
      throw Error(ErrorCode::Input, input_list_path + ": cannot open the input list; check the path");
    }
    std::string line;
    for (std::size_t number = 1; std::getline(list, line); ++number) {
      while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.pop_back();
      std::size_t first = 0;
      while (first < line.size() && std::isspace(static_cast<unsigned char>(line[first]))) ++first;
      line.erase(0, first);
      if (line.empty() || line.front() == '#') continue;
      addInput(line, input_list_path + " line " + std::to_string(number) + ": ", files);
    }
    if (list.bad()) {
      throw Error(ErrorCode::Input, input_list_path + ": cannot read the input list; check the file");
    }
  }
  if (files.empty()) {
    throw Error(ErrorCode::Usage, input_list_path.empty()
                                      ? "no input raster given; name DEM rasters, a directory of them, or "
                                        "--input-list FILE"
                                      : input_list_path + ": the input list names no raster; expected one path per line");
  }
  return files;
}

}  // namespace terratiles
