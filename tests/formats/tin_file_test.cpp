#include <doctest/doctest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "formats/tin/tin_file.h"
#include "src/base/error.h"
#include "tests/test_support.h"

using namespace terratiles;
namespace fs = std::filesystem;

namespace {

struct Failure {
  bool thrown = false;
  ErrorCode code = ErrorCode::Internal;
  std::string message;
};

Failure failureOf(const std::function<void()>& action) {
  try {
    action();
  } catch (const Error& e) {
    return {true, e.code(), e.what()};
  }
  return {};
}

std::string writeBytes(const test::TempDir& dir, const std::string& name,
                       const std::string& bytes) {
  const std::string path = dir / name;
  std::ofstream out(path, std::ios::binary);
  out << bytes;
  return path;
}

// Reads `bytes` saved as `name` and checks for Error(Input) with a one-line message that
// names the file and holds every fragment.
void checkInputError(const test::TempDir& dir, const std::string& name, const std::string& bytes,
                     std::initializer_list<const char*> fragments) {
  const std::string path = writeBytes(dir, name, bytes);
  const Failure failure = failureOf([&] { readTinFile(path); });
  CAPTURE(name);
  CAPTURE(failure.message);
  REQUIRE(failure.thrown);
  CHECK(failure.code == ErrorCode::Input);
  CHECK(failure.message.starts_with(path + ": "));
  CHECK(failure.message.find('\n') == std::string::npos);
  for (const std::string fragment : fragments) {
    CAPTURE(fragment);
    CHECK(failure.message.find(fragment) != std::string::npos);
  }
}

bool sameBits(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

// Doubles that only survive text with full precision: LV95 coordinates with sub-millimetre
// digits, thirds, the neighbour of 1, negative zero, subnormals and extremes.
CrsTin awkwardTin() {
  CrsTin tin;
  tin.positions = {{2600000.123456789, 1199999.9999999998, 512.3},
                   {2600030.1, 1.0 / 3.0, -0.0},
                   {std::nextafter(2600060.0, 3e6), 1200030.0000000002, 4807.123456789012},
                   {5e-324, -1e300, 2.2250738585072014e-308},
                   {-123456.789e-7, std::numeric_limits<double>::max(), 0.1}};
  tin.triangle_indices = {0, 1, 2, 0, 2, 3, 1, 4, 3};
  return tin;
}

void checkSameTin(const CrsTin& read, const CrsTin& written) {
  REQUIRE(read.positions.size() == written.positions.size());
  for (std::size_t i = 0; i < read.positions.size(); ++i) {
    for (std::size_t k = 0; k < 3; ++k) {
      CAPTURE(i);
      CAPTURE(k);
      CHECK(sameBits(read.positions[i][k], written.positions[i][k]));
    }
  }
  CHECK(read.triangle_indices == written.triangle_indices);
}

// Little PLY body builder in either byte order.
class Bytes {
 public:
  explicit Bytes(bool big_endian) : big_endian_(big_endian) {}
  template <typename T>
  Bytes& put(T value) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    if (big_endian_ != (std::endian::native == std::endian::big)) {
      std::reverse(bytes, bytes + sizeof(T));
    }
    data_.append(bytes, sizeof(T));
    return *this;
  }
  const std::string& data() const { return data_; }

 private:
  bool big_endian_;
  std::string data_;
};

const char* const kBinaryPlyHeader =
    "ply\n"
    "format binary_little_endian 1.0\n"
    "comment written by hand: extra properties before between and after x y z\n"
    "element vertex 3\n"
    "property float confidence\n"
    "property double x\n"
    "property float y\n"
    "property short id\n"
    "property double z\n"
    "element face 1\n"
    "property uchar flags\n"
    "property list int uint vertex_index\n"
    "element edge 2\n"
    "property int a\n"
    "property int b\n"
    "end_header\n";

std::string binaryPly(bool big_endian, std::uint32_t last_index = 2) {
  std::string header = kBinaryPlyHeader;
  if (big_endian) {
    const std::string little = "binary_little_endian";
    header.replace(header.find(little), little.size(), "binary_big_endian");
  }
  Bytes body(big_endian);
  body.put(0.9f).put(2600000.25).put(1.5f).put(std::int16_t{-7}).put(500.125);
  body.put(0.8f).put(2600010.5).put(-2.25f).put(std::int16_t{8}).put(501.0);
  body.put(0.7f).put(2600020.75).put(3.0f).put(std::int16_t{9}).put(-502.5);
  body.put(std::uint8_t{1}).put(std::int32_t{3}).put(0u).put(1u).put(last_index);
  body.put(std::int32_t{0}).put(std::int32_t{1}).put(std::int32_t{1}).put(std::int32_t{2});
  return header + body.data();
}

// Whether a TIN returned by readTinFile keeps its guarantees.
void checkGuarantees(const CrsTin& tin) {
  CHECK(tin.triangleCount() > 0);
  CHECK(tin.triangle_indices.size() % 3 == 0);
  for (const std::uint32_t index : tin.triangle_indices) CHECK(index < tin.positions.size());
  for (const auto& p : tin.positions) {
    CHECK((std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])));
  }
}

}  // namespace

TEST_SUITE("formats") {
  TEST_CASE("a TIN survives a round trip through OFF OBJ and PLY bit for bit") {
    test::TempDir dir;
    const CrsTin tin = awkwardTin();
    for (const std::string name : {"tin.off", "tin.obj", "tin.ply", "TIN.PLY"}) {
      CAPTURE(name);
      const std::string path = dir / name;
      writeTinFile(tin, path);
      checkSameTin(readTinFile(path), tin);
      // Writing again replaces the file, through the temporary name that is then gone.
      writeTinFile(tin, path);
      checkSameTin(readTinFile(path), tin);
      CHECK_FALSE(fs::exists(path + ".tmp"));
    }
  }

  TEST_CASE("a TIN streamed piece by piece is the file writeTinFile writes, and nothing is left without commit") {
    test::TempDir dir;
    const CrsTin tin = awkwardTin();
    const auto bytes = [](const std::string& path) {
      std::ifstream in(path, std::ios::binary);
      return std::string(std::istreambuf_iterator<char>(in), {});
    };
    for (const std::string name : {"tin.off", "tin.obj", "tin.ply"}) {
      CAPTURE(name);
      writeTinFile(tin, dir / ("whole." + name));
      {
        TinFileStream stream(dir / name);
        for (std::size_t v = 0; v < tin.positions.size(); ++v) CHECK(stream.addVertex(tin.positions[v]) == v);
        const auto& idx = tin.triangle_indices;
        for (std::size_t t = 0; t < idx.size(); t += 3) stream.addTriangle(idx[t], idx[t + 1], idx[t + 2]);
        CHECK(stream.triangleCount() == tin.triangleCount());
        CHECK_FALSE(fs::exists(dir / name));  // nothing at the final name before commit
        stream.commit();
      }
      CHECK(bytes(dir / name) == bytes(dir / ("whole." + name)));
      {
        TinFileStream abandoned(dir / ("abandoned." + name));
        abandoned.addVertex({1, 2, 3});
      }
      for (const auto& entry : fs::directory_iterator(dir.path())) {
        CHECK(entry.path().filename().string().find("abandoned") == std::string::npos);
        CHECK(entry.path().extension() != ".tmp");
      }
    }
  }

  TEST_CASE("OFF and OBJ files are plain text with one vertex or face per line") {
    test::TempDir dir;
    CrsTin tin;
    tin.positions = {{2600000.5, 1200000.25, 500}, {2600001, 1200000, 0.1}, {0, 1, -2}};
    tin.triangle_indices = {0, 1, 2};
    writeTinFile(tin, dir / "t.off");
    writeTinFile(tin, dir / "t.obj");
    std::ifstream off(dir / "t.off");
    CHECK(std::string(std::istreambuf_iterator<char>(off), {}) ==
          "OFF\n3 1 0\n2600000.5 1200000.25 500\n2600001 1200000 0.1\n0 1 -2\n3 0 1 2\n");
    std::ifstream obj(dir / "t.obj");
    const std::string obj_text(std::istreambuf_iterator<char>(obj), {});
    CHECK(obj_text.starts_with("# terratiles TIN"));
    CHECK(obj_text.ends_with("\nv 2600000.5 1200000.25 500\nv 2600001 1200000 0.1\nv 0 1 -2\n"
                             "f 1 2 3\n"));
  }

  TEST_CASE("OFF written by hand with comments and a quad is read as two triangles") {
    test::TempDir dir;
    const std::string path = writeBytes(dir, "hand.off",
                                        "# a hand-made OFF\n"
                                        "OFF\n"
                                        "# counts follow\n"
                                        "4 1 0   # vertices faces edges\n"
                                        "\n"
                                        "0 0 10\n"
                                        "1 0 11  # east\n"
                                        "1.5e0 1 12\n"
                                        "0 +1 -13.25\n"
                                        "4  0 1 2 3   255 0 0\n");
    const CrsTin tin = readTinFile(path);
    REQUIRE(tin.positions.size() == 4);
    CHECK(tin.positions[2] == std::array<double, 3>{1.5, 1, 12});
    CHECK(tin.positions[3] == std::array<double, 3>{0, 1, -13.25});
    CHECK(tin.triangle_indices == std::vector<std::uint32_t>{0, 1, 2, 0, 2, 3});
  }

  TEST_CASE("OFF header variants are read") {
    test::TempDir dir;
    const std::vector<std::uint32_t> triangle{0, 1, 2};
    const std::string body = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    SUBCASE("the header and the counts on one line") {
      CHECK(readTinFile(writeBytes(dir, "a.off", "OFF 3 1 0\n" + body)).triangle_indices ==
            triangle);
    }
    SUBCASE("no header and two counts") {
      CHECK(readTinFile(writeBytes(dir, "b.off", "3 1\n" + body)).triangle_indices == triangle);
    }
    SUBCASE("COFF with colours on vertices and faces") {
      const CrsTin tin = readTinFile(writeBytes(dir, "c.off",
                                                "COFF\n3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 "
                                                "255\n0 1 5 0 0 255 255\n3 0 1 2 9 9 9\n"));
      CHECK(tin.positions[2][2] == 5);
      CHECK(tin.triangle_indices == triangle);
    }
    SUBCASE("NOFF with CRLF line endings and a byte order mark") {
      const CrsTin tin = readTinFile(writeBytes(
          dir, "d.off",
          "\xEF\xBB\xBFNOFF\r\n3 1 0\r\n0 0 0 0 0 1\r\n1 0 0 0 0 1\r\n0 1 0 0 0 1\r\n3 0 1 2\r\n"));
      CHECK(tin.triangle_indices == triangle);
    }
    SUBCASE("an upper-case extension") {
      CHECK(readTinFile(writeBytes(dir, "E.OFF", "OFF\n3 1 0\n" + body)).triangle_indices ==
            triangle);
    }
  }

  TEST_CASE("OBJ with slash references and negative indices is read") {
    test::TempDir dir;
    const std::string path = writeBytes(dir, "hand.obj",
                                        "# exported by hand\n"
                                        "mtllib terrain.mtl\n"
                                        "o terrain\n"
                                        "v 0 0 1\n"
                                        "v 1 0 2\n"
                                        "vt 0 0\n"
                                        "vn 0 0 1\n"
                                        "v 1 1 3\n"
                                        "v 0 1 4 0.5 0.5 0.5\n"
                                        "g ground\n"
                                        "usemtl grass\n"
                                        "s off\n"
                                        "f 1/1/1 2/2/2 3/3/3\n"
                                        "f -4//1 -2//1 -1//1\n"
                                        "f 1/1 2/1 3/1 4/1\n"
                                        "l 1 2\n");
    const CrsTin tin = readTinFile(path);
    REQUIRE(tin.positions.size() == 4);
    CHECK(tin.positions[3] == std::array<double, 3>{0, 1, 4});
    CHECK(tin.triangle_indices ==
          std::vector<std::uint32_t>{0, 1, 2, 0, 2, 3, 0, 1, 2, 0, 2, 3});
  }

  TEST_CASE("ASCII PLY with extra properties and elements is read") {
    test::TempDir dir;
    const std::string path = writeBytes(dir, "hand.ply",
                                        "ply\n"
                                        "format ascii 1.0\n"
                                        "comment written by hand\n"
                                        "obj_info nothing to see\n"
                                        "element vertex 4\n"
                                        "property uchar red\n"
                                        "property float x\n"
                                        "property int flags\n"
                                        "property double y\n"
                                        "property float z\n"
                                        "property float confidence\n"
                                        "element face 2\n"
                                        "property uchar flags\n"
                                        "property list uchar int vertex_indices\n"
                                        "property float quality\n"
                                        "element edge 1\n"
                                        "property list int int vertex_pair\n"
                                        "end_header\n"
                                        "255 0 7 0 10 0.5\n"
                                        "0 1 7 0 11 0.5\n"
                                        "0 1 7 1 12 0.5\n"
                                        "0 0 7 1.5 13.25 0.5\n"
                                        "1 3 0 1 2 0.9\n"
                                        "0 4 0 1 2 3 0.8\n"
                                        "2 0 1\n");
    const CrsTin tin = readTinFile(path);
    REQUIRE(tin.positions.size() == 4);
    CHECK(tin.positions[0] == std::array<double, 3>{0, 0, 10});
    CHECK(tin.positions[3] == std::array<double, 3>{0, 1.5, 13.25});
    CHECK(tin.triangle_indices == std::vector<std::uint32_t>{0, 1, 2, 0, 1, 2, 0, 2, 3});
  }

  TEST_CASE("binary PLY with extra properties is read in both byte orders") {
    test::TempDir dir;
    for (const bool big_endian : {false, true}) {
      CAPTURE(big_endian);
      const CrsTin tin = readTinFile(writeBytes(dir, "hand.ply", binaryPly(big_endian)));
      REQUIRE(tin.positions.size() == 3);
      CHECK(tin.positions[0] == std::array<double, 3>{2600000.25, 1.5, 500.125});
      CHECK(tin.positions[1] == std::array<double, 3>{2600010.5, -2.25, 501.0});
      CHECK(tin.positions[2] == std::array<double, 3>{2600020.75, 3.0, -502.5});
      CHECK(tin.triangle_indices == std::vector<std::uint32_t>{0, 1, 2});
    }
  }

  TEST_CASE("a truncated file is an input error naming the file and the line") {
    test::TempDir dir;
    checkInputError(dir, "vertices.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n",
                    {"ends at line 4 after 2 of 4 vertices", "line 2", "truncated"});
    checkInputError(dir, "faces.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
                    {"ends at line 6 after 1 of 2 faces", "truncated"});
    checkInputError(dir, "counts.off", "OFF\n# only a comment\n",
                    {"ends after the OFF header at line 2", "truncated"});
    checkInputError(dir, "face.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n",
                    {"face 0 at line 6 lists 3 of its 4 corner indices"});
    checkInputError(dir, "cut.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2",
                    {"face at line 4 has 2 corner(s), expected at least 3"});
    checkInputError(dir, "cut.obj", "v 0 0 0\nv 1 0",
                    {"vertex at line 2 has 2 coordinate(s), expected 'v x y z'"});
    checkInputError(dir, "ascii.ply",
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 1\nproperty list uchar uint vertex_indices\n"
                    "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n",
                    {"the data ends at line 13 inside face 0 of 1", "truncated"});
    checkInputError(dir, "header.ply", "ply\nformat ascii 1.0\nelement vertex 3\n",
                    {"no end_header line", "truncated"});
    const std::string binary = binaryPly(false);
    checkInputError(dir, "binary.ply", binary.substr(0, binary.size() - 20),
                    {"inside face 0 of 1", "byte", "truncated"});
    checkInputError(dir, "vertices.ply",
                    binary.substr(0, std::string(kBinaryPlyHeader).size() + 40),
                    {"element 'vertex' needs 3 x 26 bytes", "truncated"});
  }

  TEST_CASE("a vertex index out of range is an input error naming the line") {
    test::TempDir dir;
    checkInputError(dir, "range.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
                    {"face 0 at line 6: vertex index 3 is out of range",
                     "expected 0 to 2 (the file has 3 vertices)"});
    checkInputError(dir, "negative.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n",
                    {"line 6: vertex index -1 is out of range"});
    checkInputError(dir, "range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n",
                    {"face at line 5: vertex index 9 is out of range", "expected 1 to 3"});
    checkInputError(dir, "relative.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n",
                    {"face at line 3: relative vertex index -3 is out of range",
                     "expected -1 to -2"});
    checkInputError(dir, "zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
                    {"line 4: vertex index 0 is out of range", "OBJ indices start at 1"});
    checkInputError(dir, "range.ply",
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 1\nproperty list uchar uint vertex_indices\n"
                    "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
                    {"face 0 at line 13: vertex index 3 is out of range", "expected 0 to 2"});
    checkInputError(dir, "faces_first.ply",
                    "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar uint "
                    "vertex_indices\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n3 0 5 1\n0 0 0\n1 0 0\n0 1 0\n",
                    {"face 0 at line 10: vertex index 5 is out of range", "expected 0 to 2"});
    checkInputError(dir, "binary.ply", binaryPly(false, 99),
                    {"face 0 at byte", "vertex index 99 is out of range", "expected 0 to 2"});
  }

  TEST_CASE("a non-numeric value is an input error naming the line") {
    test::TempDir dir;
    checkInputError(dir, "value.off", "OFF\n3 1 0\n0 0 0\n1 abc 0\n0 1 0\n3 0 1 2\n",
                    {"vertex 1 at line 4: found 'abc', expected a finite number"});
    checkInputError(dir, "counts.off", "OFF\nthree 1 0\n",
                    {"found 'three' at line 2", "counts line 'vertices faces edges'"});
    checkInputError(dir, "index.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 one 2\n",
                    {"face 0 at line 6: found 'one', expected an integer vertex index"});
    checkInputError(dir, "comma.obj", "v 0 0 0\nv 1 0 0,5\nv 0 1 0\nf 1 2 3\n",
                    {"vertex at line 2: found '0,5', expected a finite number"});
    checkInputError(dir, "index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 b/2 3\n",
                    {"face at line 4: found 'b/2', expected a vertex reference"});
    checkInputError(dir, "nan.obj", "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n",
                    {"vertex at line 2: found 'nan', expected a finite number"});
    checkInputError(dir, "inf.off", "OFF\n3 1 0\n0 0 0\n1 0 0\ninf 1 0\n3 0 1 2\n",
                    {"vertex 2 at line 5: found 'inf', expected a finite number"});
    checkInputError(dir, "value.ply",
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 1\nproperty list uchar uint vertex_indices\n"
                    "end_header\n0 0 0\n1 two 0\n0 1 0\n3 0 1 2\n",
                    {"vertex 1 at line 11: found 'two' for property 'y'", "a finite number"});
  }

  TEST_CASE("a file without faces is an input error") {
    test::TempDir dir;
    for (const auto& [name, bytes] : std::vector<std::pair<std::string, std::string>>{
             {"none.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n"},
             {"none.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"},
             {"empty.obj", ""},
             {"none.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty "
                          "float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n"},
             {"zero.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty "
                          "float y\nproperty float z\nelement face 0\nproperty list uchar int "
                          "vertex_indices\nend_header\n0 0 0\n"}}) {
      checkInputError(dir, name, bytes, {"holds no faces, expected at least one triangle"});
    }
    checkInputError(dir, "empty.off", "# nothing\n", {"holds no OFF data"});
  }

  TEST_CASE("unsupported variants are input errors that say what is supported") {
    test::TempDir dir;
    checkInputError(dir, "four.off", "4OFF\n3 1 0\n", {"4D or n-dimensional", "expected 3D OFF"});
    checkInputError(dir, "binary.off", "OFF BINARY\n", {"binary OFF", "expected ASCII OFF"});
    checkInputError(dir, "line.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
                    {"face 0 at line 6: found '2' as its corner count",
                     "expected an integer of at least 3"});
    checkInputError(dir, "magic.ply", "PLY\n", {"found 'PLY' at line 1", "expected the PLY magic"});
    checkInputError(dir, "format.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n",
                    {"format at line 2: found 'binary_middle_endian'"});
    checkInputError(dir, "noz.ply",
                    "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float "
                    "y\nend_header\n",
                    {"element 'vertex' at line 3 has no property 'z'"});
    checkInputError(dir, "type.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty real x\n",
                    {"property at line 4: found 'property real x'"});
    checkInputError(dir, "nolist.ply",
                    "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float "
                    "y\nproperty float z\nelement face 1\nproperty int vertex_indices\n"
                    "end_header\n",
                    {"property 'vertex_indices' is not a list of integers"});
  }

  TEST_CASE("a missing or unreadable file is an input error") {
    test::TempDir dir;
    Failure failure = failureOf([&] { readTinFile(dir / "missing.ply"); });
    CHECK(failure.code == ErrorCode::Input);
    CHECK(failure.message == dir / "missing.ply" + ": cannot open (No such file or directory); "
                                                   "check the path and permissions");
    fs::create_directory(dir / "folder.off");
    failure = failureOf([&] { readTinFile(dir / "folder.off"); });
    CHECK(failure.code == ErrorCode::Input);
    CHECK(failure.message.find("folder.off: cannot") != std::string::npos);
  }

  TEST_CASE("an unknown extension is a usage error naming the accepted extensions") {
    test::TempDir dir;
    CHECK(tinFileFormatFor("a.off") == TinFileFormat::Off);
    CHECK(tinFileFormatFor("dir.ply/B.Obj") == TinFileFormat::Obj);
    CHECK(tinFileFormatFor("C.PLY") == TinFileFormat::Ply);
    const std::string stl = dir / "tin.stl";
    for (const auto& action : std::vector<std::function<void()>>{
             [&] { readTinFile(stl); }, [&] { writeTinFile(awkwardTin(), stl); }}) {
      const Failure failure = failureOf(action);
      CHECK(failure.code == ErrorCode::Usage);
      CHECK(failure.message == stl + ": unknown TIN file type, found extension '.stl', expected "
                                     ".off, .obj or .ply; name the file with one of these "
                                     "extensions");
    }
    CHECK(fs::is_empty(dir.path()));
    const Failure failure = failureOf([] { tinFileFormatFor("tin"); });
    CHECK(failure.code == ErrorCode::Usage);
    CHECK(failure.message.find("found no extension, expected .off, .obj or .ply") !=
          std::string::npos);
  }

  TEST_CASE("writing below a regular file is an output error and leaves no temporary file") {
    test::TempDir dir;
    writeBytes(dir, "blocker", "not a directory");
    const std::string path = dir / "blocker/tin.off";
    Failure failure = failureOf([&] { writeTinFile(awkwardTin(), path); });
    CHECK(failure.code == ErrorCode::Output);
    CHECK(failure.message == path + ": cannot create " + path +
                                 ".tmp (Not a directory); check that the directory exists and is "
                                 "writable");
    // The rename fails when the target is a directory: the temporary file is removed.
    fs::create_directory(dir / "taken.ply");
    failure = failureOf([&] { writeTinFile(awkwardTin(), dir / "taken.ply"); });
    CHECK(failure.code == ErrorCode::Output);
    CHECK(failure.message.starts_with(dir / "taken.ply" + ": cannot rename "));
    std::vector<std::string> left;
    for (const auto& entry : fs::directory_iterator(dir.path())) {
      left.push_back(entry.path().filename().string());
    }
    std::sort(left.begin(), left.end());
    CHECK(left == std::vector<std::string>{"blocker", "taken.ply"});
    CHECK(fs::is_empty(dir / "taken.ply"));
  }

  TEST_CASE("damaged files never crash the reader") {
    // Every truncation and a few byte substitutions at every position of a small file in
    // each format: the reader either returns a TIN that keeps its guarantees or throws
    // Error(Input).
    test::TempDir dir;
    const CrsTin tin = awkwardTin();
    for (const std::string name : {"fuzz.off", "fuzz.obj", "fuzz.ply"}) {
      CAPTURE(name);
      writeTinFile(tin, dir / name);
      std::ifstream in(dir / name, std::ios::binary);
      const std::string good(std::istreambuf_iterator<char>(in), {});
      std::vector<std::string> damaged;
      for (std::size_t size = 0; size < good.size(); ++size) damaged.push_back(good.substr(0, size));
      for (std::size_t at = 0; at < good.size(); ++at) {
        for (const char byte : {'\0', '9', '-', ' ', '\n', '\xff'}) {
          std::string copy = good;
          copy[at] = byte;
          damaged.push_back(copy);
        }
      }
      int accepted = 0;
      for (const std::string& bytes : damaged) {
        const std::string path = writeBytes(dir, name, bytes);
        try {
          checkGuarantees(readTinFile(path));
          ++accepted;
        } catch (const Error& e) {
          if (e.code() != ErrorCode::Input) FAIL("unexpected error code: " << e.what());
          const std::string message = e.what();
          if (message.find('\n') != std::string::npos) FAIL("multi-line message: " << message);
        }
      }
      MESSAGE(name << ": " << damaged.size() << " damaged files, " << accepted << " accepted");
      CHECK(accepted > 0);
    }
  }

  TEST_CASE("grid and CRS coordinates convert both ways through pixel centres") {
    TinMesh mesh;
    mesh.vertices = {{0, 0, 500.5}, {2, 0, 501}, {0.25, 3.75, 502}};
    mesh.triangle_indices = {0, 2, 1};
    const CrsTin tin = toCrsTin(mesh, 2600000.0, 1200000.0, 2.0);
    REQUIRE(tin.positions.size() == 3);
    CHECK(tin.positions[0] == std::array<double, 3>{2600001.0, 1199999.0, 500.5});
    CHECK(tin.positions[1] == std::array<double, 3>{2600005.0, 1199999.0, 501});
    CHECK(tin.positions[2] == std::array<double, 3>{2600001.5, 1199991.5, 502});
    CHECK(tin.triangle_indices == mesh.triangle_indices);
    const TinMesh back = toGridTin(tin, 2600000.0, 1200000.0, 2.0);
    REQUIRE(back.vertices.size() == 3);
    for (std::size_t i = 0; i < 3; ++i) {
      CHECK(back.vertices[i].col == doctest::Approx(mesh.vertices[i].col));
      CHECK(back.vertices[i].row == doctest::Approx(mesh.vertices[i].row));
      CHECK(back.vertices[i].height_m == mesh.vertices[i].height_m);
    }
    CHECK(back.triangle_indices == mesh.triangle_indices);
  }
}
