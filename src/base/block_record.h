#pragma once
// Block files: the records a build or TIN in blocks keeps between its stages and hands from
// rank to rank (src/pipeline/block_tin.h, block_build.h). Binary, every number as in memory
// (doubles bit for bit: the same machine and build read them back), written through
// path + ".tmp" and renamed when complete, so a file that exists is whole (what --resume
// relies on after a SIGKILL).

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace terratiles {

// Appends values and arrays (a count, then the elements) of trivially copyable types.
struct RecordWriter {
  std::string bytes;
  template <typename T>
  void put(const T& value) {
    bytes.append(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  template <typename T>
  void putArray(const std::vector<T>& values) {
    put(static_cast<std::uint64_t>(values.size()));
    bytes.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
  }
};

// Reads what RecordWriter wrote, refusing to run past the end: Error(Input) naming the file
// ("not a whole terratiles block file ... run again without --resume").
struct RecordReader {
  const std::string& path;
  const std::string& bytes;
  std::size_t at = 0;
  template <typename T>
  T get() {
    need(sizeof(T));
    T value;
    std::memcpy(&value, bytes.data() + at, sizeof(T));
    at += sizeof(T);
    return value;
  }
  template <typename T>
  std::vector<T> getArray() {
    const auto count = get<std::uint64_t>();
    if (count > (bytes.size() - at) / sizeof(T)) damaged();
    std::vector<T> values(count);
    std::memcpy(values.data(), bytes.data() + at, count * sizeof(T));
    at += count * sizeof(T);
    return values;
  }
  void need(std::size_t size) const {
    if (bytes.size() - at < size) damaged();
  }
  // The file starts with `magic` (8 bytes); reads past it.
  void expectMagic(const char (&magic)[8]);
  // Everything was read.
  void expectEnd() const {
    if (at != bytes.size()) damaged();
  }
  [[noreturn]] void damaged() const;
};

// Writes `bytes` to `path` through path + ".tmp", renamed when whole. Error(Output) naming the
// file when it cannot.
void writeRecordFile(const std::string& path, const std::string& bytes);
// The whole file (empty when missing: the reader then finds it damaged).
std::string readRecordFile(const std::string& path);

}  // namespace terratiles
