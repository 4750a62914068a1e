#include "src/base/block_record.h"

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <system_error>

#include "src/base/error.h"

namespace terratiles {

void RecordReader::expectMagic(const char (&magic)[8]) {
  need(sizeof magic);
  if (std::memcmp(bytes.data(), magic, sizeof magic) != 0) damaged();
  at = sizeof magic;
}

void RecordReader::damaged() const {
  throw Error(ErrorCode::Input, path + ": not a whole terratiles block file (damaged, or from another version); "
                                       "expected one this version wrote; run again without --resume");
}

void writeRecordFile(const std::string& path, const std::string& bytes) {
  const std::string temporary = path + ".tmp";
  std::FILE* file = std::fopen(temporary.c_str(), "wb");
  const bool written = file && std::fwrite(bytes.data(), 1, bytes.size(), file) == bytes.size();
  const bool closed = file && std::fclose(file) == 0;
  std::error_code ec;
  if (!written || !closed) {
    std::filesystem::remove(temporary, ec);
    throw Error(ErrorCode::Output, temporary + ": cannot write a block file (" + std::strerror(errno) +
                                       "); check the free space and permissions");
  }
  std::filesystem::rename(temporary, path, ec);
  if (ec) throw Error(ErrorCode::Output, path + ": cannot rename the block file into place (" + ec.message() + ")");
}

std::string readRecordFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace terratiles
