#include "formats/tin/tin_file.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <string_view>
#include <system_error>

#include "src/base/error.h"

namespace terratiles {
namespace {

namespace fs = std::filesystem;

// Indices are uint32, so a file may address at most 2^32 vertices.
constexpr std::uint64_t kMaxVertices = std::uint64_t{1} << 32;

// ------------------------------------------------------------------------------------------
// Messages

[[noreturn]] void inputError(const std::string& path, const std::string& message) {
  throw Error(ErrorCode::Input, path + ": " + message);
}

[[noreturn]] void outputError(const std::string& path, const std::string& what,
                              const std::string& fix) {
  throw Error(ErrorCode::Output, path + ": " + what + "; " + fix);
}

// A token from the file, quoted for a one-line message: at most 32 characters, bytes that
// are not printable ASCII shown as '?', so binary garbage cannot break the line.
std::string shown(std::string_view token) {
  constexpr std::size_t kMaxShown = 32;
  std::string out = "'";
  for (std::size_t i = 0; i < token.size() && i < kMaxShown; ++i) {
    const auto c = static_cast<unsigned char>(token[i]);
    out += c < 0x20 || c >= 0x7f ? '?' : static_cast<char>(c);
  }
  if (token.size() > kMaxShown) out += "...";
  return out + "'";
}

std::string str(std::uint64_t value) { return std::to_string(value); }

// An integral value read as a double (PLY values), in full: 4294967296, not 4.29e+09.
std::string integerText(double value) {
  char text[400];
  const std::to_chars_result result =
      std::to_chars(text, text + sizeof text, value, std::chars_format::fixed);
  return std::string(text, result.ptr);
}

// What a 0-based vertex index must be: "0 to 4 (the file has 5 vertices)".
std::string indexRange(std::uint64_t vertex_count) {
  if (vertex_count == 0) return "a vertex, but the file has no vertices";
  return "0 to " + str(vertex_count - 1) + " (the file has " + str(vertex_count) + " vertices)";
}

const char* const kReexport = "fix the file or export the TIN again";
const char* const kTruncated = "the file is truncated; export the TIN again";

// ------------------------------------------------------------------------------------------
// Text scanning: locale-independent numbers, lines, tokens

bool isBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

std::optional<double> parseDouble(std::string_view token) {
  if (token.size() > 1 && token.front() == '+' && token[1] != '-') token.remove_prefix(1);
  double value = 0;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (token.empty() || ec != std::errc() || ptr != end) return std::nullopt;
  return value;
}

std::optional<std::int64_t> parseInteger(std::string_view token) {
  if (token.size() > 1 && token.front() == '+' && token[1] != '-') token.remove_prefix(1);
  std::int64_t value = 0;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (token.empty() || ec != std::errc() || ptr != end) return std::nullopt;
  return value;
}

// Lines of a text, without their '\n' or "\r\n", numbered from 1.
class Lines {
 public:
  explicit Lines(std::string_view text) : text_(text) {}

  bool next(std::string_view& line) {
    if (pos_ >= text_.size()) return false;
    std::size_t end = text_.find('\n', pos_);
    if (end == std::string_view::npos) end = text_.size();
    line = text_.substr(pos_, end - pos_);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos_ = end + 1;
    ++number_;
    return true;
  }
  std::size_t number() const { return number_; }  // of the line last returned
  std::size_t offset() const { return std::min(pos_, text_.size()); }  // after that line

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t number_ = 0;
};

void splitTokens(std::string_view line, std::vector<std::string_view>& tokens) {
  tokens.clear();
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && isBlank(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !isBlank(line[i])) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
}

std::string_view withoutComment(std::string_view line) {
  return line.substr(0, line.find('#'));
}

std::string_view withoutByteOrderMark(std::string_view text) {
  if (text.starts_with("\xEF\xBB\xBF")) text.remove_prefix(3);
  return text;
}

// Appends the triangles of a polygon, fanned from its first corner.
void addPolygon(const std::vector<std::uint32_t>& corners, std::vector<std::uint32_t>& out) {
  for (std::size_t i = 1; i + 1 < corners.size(); ++i) {
    out.push_back(corners[0]);
    out.push_back(corners[i]);
    out.push_back(corners[i + 1]);
  }
}

// Capacity to reserve for `count` items of at least `min_bytes` each in `bytes` of file:
// never more than the file can hold, so a lying header cannot make us allocate.
std::size_t boundedReserve(std::uint64_t count, std::size_t bytes, std::size_t min_bytes) {
  return static_cast<std::size_t>(std::min<std::uint64_t>(count, bytes / min_bytes));
}

void requireTriangles(const std::string& path, const CrsTin& tin) {
  if (tin.triangle_indices.empty()) {
    inputError(path, "holds no faces, expected at least one triangle; export the TIN with its "
                     "faces");
  }
}

// ------------------------------------------------------------------------------------------
// OFF

enum class OffKeyword { None, Supported, Unsupported };

// The optional header keyword [ST][C][N][4][n]OFF. 4D and n-dimensional OFF are refused.
OffKeyword offKeyword(std::string_view token) {
  if (token == "off") return OffKeyword::Supported;
  if (!token.ends_with("OFF")) return OffKeyword::None;
  std::string_view prefix = token.substr(0, token.size() - 3);
  if (prefix.starts_with("ST")) prefix.remove_prefix(2);
  if (prefix.starts_with("C")) prefix.remove_prefix(1);
  if (prefix.starts_with("N")) prefix.remove_prefix(1);
  if (prefix.empty()) return OffKeyword::Supported;
  if (prefix == "4" || prefix == "n" || prefix == "4n") return OffKeyword::Unsupported;
  return OffKeyword::None;
}

CrsTin readOff(const std::string& path, std::string_view text) {
  Lines lines(text);
  std::vector<std::string_view> tokens;
  // Moves to the next line with tokens once comments are removed; false at the end.
  const auto nextContent = [&]() {
    std::string_view line;
    while (lines.next(line)) {
      splitTokens(withoutComment(line), tokens);
      if (!tokens.empty()) return true;
    }
    return false;
  };
  const auto line = [&]() { return "line " + str(lines.number()); };

  if (!nextContent()) {
    inputError(path, "holds no OFF data, expected the header 'OFF' and the counts line "
                     "'vertices faces edges'; " + std::string(kReexport));
  }
  std::size_t first_count = 0;
  const OffKeyword keyword = offKeyword(tokens[0]);
  if (keyword == OffKeyword::Unsupported) {
    inputError(path, "header " + shown(tokens[0]) + " at " + line() +
                         " is 4D or n-dimensional OFF, expected 3D OFF (OFF, COFF, NOFF, "
                         "STOFF); export the TIN as 3D OFF");
  }
  if (keyword == OffKeyword::Supported) {
    if (tokens.size() > 1 && tokens[1] == "BINARY") {
      inputError(path, "binary OFF at " + line() + " is not supported, expected ASCII OFF; "
                       "export the TIN as ASCII OFF or as PLY");
    }
    first_count = 1;
    if (tokens.size() == 1) {
      if (!nextContent()) {
        inputError(path, "ends after the OFF header at " + line() +
                             ", expected the counts line 'vertices faces edges'; " + kTruncated);
      }
      first_count = 0;  // the counts are on a line of their own
    }
  }
  const std::size_t counts_line = lines.number();
  std::optional<std::int64_t> vertex_count;
  std::optional<std::int64_t> face_count;
  if (tokens.size() >= first_count + 2) {
    vertex_count = parseInteger(tokens[first_count]);
    face_count = parseInteger(tokens[first_count + 1]);
  }
  if (!vertex_count || !face_count || *vertex_count < 0 || *face_count < 0) {
    const std::string found = tokens.size() > first_count ? shown(tokens[first_count]) : "''";
    inputError(path, "found " + found + " at line " + str(counts_line) +
                         ", expected " +
                         (keyword == OffKeyword::None ? "the header 'OFF' or " : "") +
                         "the counts line 'vertices faces edges' (non-negative integers); " +
                         kReexport);
  }
  if (static_cast<std::uint64_t>(*vertex_count) > kMaxVertices) {
    inputError(path, "counts line " + str(counts_line) + " gives " + str(*vertex_count) +
                         " vertices, expected at most " + str(kMaxVertices) +
                         " (32-bit indices); split the TIN");
  }
  const auto nv = static_cast<std::uint64_t>(*vertex_count);
  const auto nf = static_cast<std::uint64_t>(*face_count);

  CrsTin tin;
  tin.positions.reserve(boundedReserve(nv, text.size(), 6));  // "0 0 0\n"
  for (std::uint64_t v = 0; v < nv; ++v) {
    if (!nextContent()) {
      inputError(path, "ends at line " + str(lines.number()) + " after " + str(v) + " of " +
                           str(nv) + " vertices, expected " + str(nv) +
                           " vertex lines as line " + str(counts_line) + " says; " + kTruncated);
    }
    if (tokens.size() < 3) {
      inputError(path, "vertex " + str(v) + " at " + line() + " has " + str(tokens.size()) +
                           " value(s), expected three numbers 'x y z'; " + kReexport);
    }
    std::array<double, 3> position{};
    for (std::size_t k = 0; k < 3; ++k) {
      const std::optional<double> value = parseDouble(tokens[k]);
      if (!value || !std::isfinite(*value)) {
        inputError(path, "vertex " + str(v) + " at " + line() + ": found " + shown(tokens[k]) +
                             ", expected a finite number; " + kReexport);
      }
      position[k] = *value;
    }
    tin.positions.push_back(position);
  }

  tin.triangle_indices.reserve(3 * boundedReserve(nf, text.size(), 8));  // "3 0 1 2\n"
  std::vector<std::uint32_t> corners;
  for (std::uint64_t f = 0; f < nf; ++f) {
    if (!nextContent()) {
      inputError(path, "ends at line " + str(lines.number()) + " after " + str(f) + " of " +
                           str(nf) + " faces, expected " + str(nf) + " face lines as line " +
                           str(counts_line) + " says; " + kTruncated);
    }
    const std::optional<std::int64_t> n = parseInteger(tokens[0]);
    if (!n || *n < 3) {
      inputError(path, "face " + str(f) + " at " + line() + ": found " + shown(tokens[0]) +
                           " as its corner count, expected an integer of at least 3; " +
                           kReexport);
    }
    if (tokens.size() - 1 < static_cast<std::uint64_t>(*n)) {
      inputError(path, "face " + str(f) + " at " + line() + " lists " + str(tokens.size() - 1) +
                           " of its " + str(*n) + " corner indices, expected " + str(*n) + "; " +
                           kReexport);
    }
    corners.clear();
    for (std::size_t k = 1; k <= static_cast<std::size_t>(*n); ++k) {
      const std::optional<std::int64_t> index = parseInteger(tokens[k]);
      if (!index) {
        inputError(path, "face " + str(f) + " at " + line() + ": found " + shown(tokens[k]) +
                             ", expected an integer vertex index; " + kReexport);
      }
      if (*index < 0 || static_cast<std::uint64_t>(*index) >= nv) {
        inputError(path, "face " + str(f) + " at " + line() + ": vertex index " +
                             std::to_string(*index) + " is out of range, expected " +
                             indexRange(nv) + "; " + kReexport);
      }
      corners.push_back(static_cast<std::uint32_t>(*index));
    }
    addPolygon(corners, tin.triangle_indices);
  }
  // Anything after the faces (some writers add edges or trailing comments) is ignored.
  requireTriangles(path, tin);
  return tin;
}

// ------------------------------------------------------------------------------------------
// OBJ

CrsTin readObj(const std::string& path, std::string_view text) {
  Lines lines(text);
  std::vector<std::string_view> tokens;
  std::vector<std::uint32_t> corners;
  CrsTin tin;
  // Positive indices may refer to vertices defined further down, so the largest is checked
  // against the vertex count at the end.
  std::int64_t largest_index = 0;  // 1-based as written; 0: none yet
  std::size_t largest_line = 0;

  std::string_view text_line;
  while (lines.next(text_line)) {
    splitTokens(withoutComment(text_line), tokens);
    if (tokens.empty()) continue;
    const auto line = [&]() { return "line " + str(lines.number()); };
    if (tokens[0] == "v") {
      if (tokens.size() < 4) {
        inputError(path, "vertex at " + line() + " has " + str(tokens.size() - 1) +
                             " coordinate(s), expected 'v x y z'; " + kReexport);
      }
      if (tin.positions.size() == kMaxVertices) {
        inputError(path, "vertex at " + line() + " is one more than the " + str(kMaxVertices) +
                             " that 32-bit indices address; split the TIN");
      }
      std::array<double, 3> position{};
      for (std::size_t k = 0; k < 3; ++k) {
        const std::optional<double> value = parseDouble(tokens[k + 1]);
        if (!value || !std::isfinite(*value)) {
          inputError(path, "vertex at " + line() + ": found " + shown(tokens[k + 1]) +
                               ", expected a finite number; " + kReexport);
        }
        position[k] = *value;
      }
      tin.positions.push_back(position);
    } else if (tokens[0] == "f") {
      if (tokens.size() < 4) {
        inputError(path, "face at " + line() + " has " + str(tokens.size() - 1) +
                             " corner(s), expected at least 3; " + kReexport);
      }
      corners.clear();
      const auto defined = static_cast<std::int64_t>(tin.positions.size());
      for (std::size_t k = 1; k < tokens.size(); ++k) {
        // "7", "7/3", "7//5" or "7/3/5": the vertex index is before the first slash.
        const std::string_view reference = tokens[k].substr(0, tokens[k].find('/'));
        const std::optional<std::int64_t> index = parseInteger(reference);
        if (!index) {
          inputError(path, "face at " + line() + ": found " + shown(tokens[k]) +
                               ", expected a vertex reference like 7, -1 or 7/3/5; " + kReexport);
        }
        std::int64_t resolved = 0;
        if (*index < 0) {
          resolved = defined + *index;  // relative to the vertices defined so far
          if (resolved < 0) {
            inputError(path, "face at " + line() + ": relative vertex index " +
                                 std::to_string(*index) + " is out of range, expected -1 to " +
                                 std::to_string(-defined) + " (" + str(defined) +
                                 " vertices are defined above it); " + kReexport);
          }
        } else if (*index == 0 || static_cast<std::uint64_t>(*index) > kMaxVertices) {
          inputError(path, "face at " + line() + ": vertex index " + std::to_string(*index) +
                               " is out of range, expected 1 or more (OBJ indices start at 1) "
                               "or a negative relative index; " + kReexport);
        } else {
          resolved = *index - 1;
          if (*index > largest_index) {
            largest_index = *index;
            largest_line = lines.number();
          }
        }
        corners.push_back(static_cast<std::uint32_t>(resolved));
      }
      addPolygon(corners, tin.triangle_indices);
    }
    // Every other statement (vt, vn, g, o, s, usemtl, mtllib, l, p, ...) is not geometry we
    // need.
  }
  const std::uint64_t nv = tin.positions.size();
  if (static_cast<std::uint64_t>(largest_index) > nv) {
    inputError(path, "face at line " + str(largest_line) + ": vertex index " +
                         std::to_string(largest_index) + " is out of range, expected 1 to " +
                         str(nv) + " (the file has " + str(nv) + " vertices); " + kReexport);
  }
  requireTriangles(path, tin);
  return tin;
}

// ------------------------------------------------------------------------------------------
// PLY (http://paulbourke.net/dataformats/ply/)

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

std::optional<PlyType> plyType(std::string_view name) {
  if (name == "char" || name == "int8") return PlyType::Int8;
  if (name == "uchar" || name == "uint8") return PlyType::UInt8;
  if (name == "short" || name == "int16") return PlyType::Int16;
  if (name == "ushort" || name == "uint16") return PlyType::UInt16;
  if (name == "int" || name == "int32") return PlyType::Int32;
  if (name == "uint" || name == "uint32") return PlyType::UInt32;
  if (name == "float" || name == "float32") return PlyType::Float32;
  if (name == "double" || name == "float64") return PlyType::Float64;
  return std::nullopt;
}

std::size_t plySize(PlyType type) {
  switch (type) {
    case PlyType::Int8:
    case PlyType::UInt8: return 1;
    case PlyType::Int16:
    case PlyType::UInt16: return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
  }
  return 1;
}

bool isInteger(PlyType type) { return type != PlyType::Float32 && type != PlyType::Float64; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::Float32;  // the item type for a list
  bool list = false;
  PlyType count_type = PlyType::UInt8;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  std::size_t line = 0;
};

enum class PlyFormat { Ascii, BinaryLittleEndian, BinaryBigEndian };

struct PlyHeader {
  PlyFormat format = PlyFormat::Ascii;
  std::vector<PlyElement> elements;
  std::size_t body_offset = 0;  // byte offset of the data after end_header
  std::size_t body_line = 0;    // line number of the first data line (ASCII)
  // The roles we read: element indices and property indices, or npos.
  static constexpr std::size_t npos = std::numeric_limits<std::size_t>::max();
  std::size_t vertex = npos;
  std::array<std::size_t, 3> xyz{npos, npos, npos};
  std::size_t face = npos;
  std::size_t face_list = npos;
};

PlyHeader readPlyHeader(const std::string& path, std::string_view text) {
  Lines lines(text);
  std::vector<std::string_view> tokens;
  std::string_view line_text;
  const auto line = [&]() { return "line " + str(lines.number()); };
  if (!lines.next(line_text) || line_text != "ply") {
    inputError(path, "found " + shown(line_text) +
                         " at line 1, expected the PLY magic line 'ply'; check that the file "
                         "is a PLY file");
  }
  PlyHeader header;
  bool have_format = false;
  bool ended = false;
  while (!ended && lines.next(line_text)) {
    splitTokens(line_text, tokens);
    if (tokens.empty()) continue;
    const std::string_view keyword = tokens[0];
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "format") {
      const std::string_view format = tokens.size() > 1 ? tokens[1] : "";
      if (format == "ascii") {
        header.format = PlyFormat::Ascii;
      } else if (format == "binary_little_endian") {
        header.format = PlyFormat::BinaryLittleEndian;
      } else if (format == "binary_big_endian") {
        header.format = PlyFormat::BinaryBigEndian;
      } else {
        inputError(path, "format at " + line() + ": found " + shown(format) +
                             ", expected ascii, binary_little_endian or binary_big_endian; " +
                             kReexport);
      }
      have_format = true;
    } else if (keyword == "element") {
      const std::optional<std::int64_t> count =
          tokens.size() == 3 ? parseInteger(tokens[2]) : std::nullopt;
      if (!count || *count < 0) {
        inputError(path, "element at " + line() + ": found " + shown(line_text) +
                             ", expected 'element <name> <count>' with a non-negative count; " +
                             kReexport);
      }
      header.elements.push_back(
          {std::string(tokens[1]), static_cast<std::uint64_t>(*count), {}, lines.number()});
    } else if (keyword == "property") {
      if (header.elements.empty()) {
        inputError(path, "property at " + line() +
                             " comes before any element, expected 'element <name> <count>' "
                             "first; " + kReexport);
      }
      PlyProperty property;
      bool ok = false;
      if (tokens.size() == 5 && tokens[1] == "list") {
        const std::optional<PlyType> count_type = plyType(tokens[2]);
        const std::optional<PlyType> item_type = plyType(tokens[3]);
        if (count_type && item_type && isInteger(*count_type)) {
          property = {std::string(tokens[4]), *item_type, true, *count_type};
          ok = true;
        }
      } else if (tokens.size() == 3) {
        const std::optional<PlyType> type = plyType(tokens[1]);
        if (type) {
          property = {std::string(tokens[2]), *type, false, PlyType::UInt8};
          ok = true;
        }
      }
      if (!ok) {
        inputError(path, "property at " + line() + ": found " + shown(line_text) +
                             ", expected 'property <type> <name>' or 'property list "
                             "<integer type> <type> <name>' with PLY types (char uchar short "
                             "ushort int uint float double); " + kReexport);
      }
      header.elements.back().properties.push_back(property);
    } else if (keyword == "end_header") {
      ended = true;
    } else {
      inputError(path, "header " + line() + ": found " + shown(keyword) +
                           ", expected format, element, property, comment or end_header; " +
                           kReexport);
    }
  }
  if (!ended) {
    inputError(path, "the header has no end_header line (read to line " + str(lines.number()) +
                         "), expected the header to end with 'end_header'; " + kTruncated);
  }
  if (!have_format) {
    inputError(path, "the header has no format line, expected 'format ascii 1.0' or 'format "
                     "binary_little_endian 1.0'; " + std::string(kReexport));
  }
  header.body_offset = lines.offset();
  header.body_line = lines.number() + 1;

  for (std::size_t e = 0; e < header.elements.size(); ++e) {
    const PlyElement& element = header.elements[e];
    const std::string where = "element '" + element.name + "' at line " + str(element.line);
    if (element.name == "vertex") {
      if (header.vertex != PlyHeader::npos) {
        inputError(path, "a second " + where + ", expected one vertex element; " + kReexport);
      }
      header.vertex = e;
      if (element.count > kMaxVertices) {
        inputError(path, where + " has " + str(element.count) + " vertices, expected at most " +
                             str(kMaxVertices) + " (32-bit indices); split the TIN");
      }
      for (std::size_t p = 0; p < element.properties.size(); ++p) {
        const std::string& name = element.properties[p].name;
        const std::size_t axis = name == "x" ? 0 : name == "y" ? 1 : name == "z" ? 2 : 3;
        if (axis == 3) continue;
        if (element.properties[p].list) {
          inputError(path, where + ": property '" + name +
                               "' is a list, expected a scalar coordinate; " + kReexport);
        }
        header.xyz[axis] = p;
      }
      for (std::size_t axis = 0; axis < 3; ++axis) {
        if (header.xyz[axis] == PlyHeader::npos) {
          inputError(path, where + " has no property '" + std::string(1, "xyz"[axis]) +
                               "', expected scalar properties x y z; " + kReexport);
        }
      }
    } else if (element.name == "face") {
      if (header.face != PlyHeader::npos) {
        inputError(path, "a second " + where + ", expected one face element; " + kReexport);
      }
      header.face = e;
      for (std::size_t p = 0; p < element.properties.size(); ++p) {
        const PlyProperty& property = element.properties[p];
        if (property.name != "vertex_indices" && property.name != "vertex_index") continue;
        if (!property.list || !isInteger(property.type)) {
          inputError(path, where + ": property '" + property.name +
                               "' is not a list of integers, expected 'property list uchar "
                               "uint " + property.name + "'; " + kReexport);
        }
        header.face_list = p;
      }
      if (header.face_list == PlyHeader::npos && element.count > 0) {
        inputError(path, where + " has no list property vertex_indices, expected 'property "
                                 "list uchar uint vertex_indices'; " + kReexport);
      }
    }
  }
  if (header.vertex == PlyHeader::npos) {
    inputError(path, "the header has no vertex element, expected 'element vertex <count>' with "
                     "properties x y z; " + std::string(kReexport));
  }
  return header;
}

// Reads the values of a PLY body one at a time, as doubles (every PLY type up to 32-bit
// integers is exact in a double). Returns false at the end of the data.
class PlyValues {
 public:
  PlyValues(std::string_view body, PlyFormat format, std::size_t first_line, std::size_t offset)
      : body_(body), format_(format), line_(first_line), scan_line_(first_line),
        base_offset_(offset) {}

  // `parse`: whether the caller uses the value (skipped ASCII values are not parsed).
  // Sets `numeric` false when an ASCII token is not a number.
  bool next(PlyType type, bool parse, double& value, bool& numeric) {
    numeric = true;
    if (format_ == PlyFormat::Ascii) {
      while (pos_ < body_.size() && (isBlank(body_[pos_]) || body_[pos_] == '\n')) {
        if (body_[pos_] == '\n') ++scan_line_;
        ++pos_;
      }
      const std::size_t start = pos_;
      while (pos_ < body_.size() && !isBlank(body_[pos_]) && body_[pos_] != '\n') ++pos_;
      token_ = body_.substr(start, pos_ - start);
      if (token_.empty()) return false;  // line_ stays on the last value, where the data ends
      line_ = scan_line_;
      if (!parse) return true;
      if (isInteger(type)) {
        const std::optional<std::int64_t> integer = parseInteger(token_);
        numeric = integer.has_value();
        value = integer ? static_cast<double>(*integer) : 0;
      } else {
        const std::optional<double> real = parseDouble(token_);
        numeric = real.has_value();
        value = real.value_or(0);
      }
      return true;
    }
    const std::size_t size = plySize(type);
    if (body_.size() - pos_ < size) return false;
    unsigned char bytes[8];
    std::memcpy(bytes, body_.data() + pos_, size);
    pos_ += size;
    const bool file_little = format_ == PlyFormat::BinaryLittleEndian;
    if (file_little != (std::endian::native == std::endian::little)) {
      std::reverse(bytes, bytes + size);
    }
    value = decode(type, bytes);
    return true;
  }

  // Skips `count` fixed-size binary rows of `row_bytes`; false if the data ends first.
  bool skipBinary(std::uint64_t count, std::size_t row_bytes) {
    if (row_bytes != 0 && count > (body_.size() - pos_) / row_bytes) return false;
    pos_ += static_cast<std::size_t>(count * row_bytes);
    return true;
  }
  bool binaryRowsFit(std::uint64_t count, std::size_t row_bytes) const {
    return row_bytes == 0 || count <= (body_.size() - pos_) / row_bytes;
  }

  std::string_view token() const { return token_; }
  // "line N" (ASCII) or "byte N" (binary), for messages.
  std::string where() const {
    return format_ == PlyFormat::Ascii ? "line " + str(line_) : "byte " + str(base_offset_ + pos_);
  }

 private:
  static double decode(PlyType type, const unsigned char* bytes) {
    switch (type) {
      case PlyType::Int8: return load<std::int8_t>(bytes);
      case PlyType::UInt8: return load<std::uint8_t>(bytes);
      case PlyType::Int16: return load<std::int16_t>(bytes);
      case PlyType::UInt16: return load<std::uint16_t>(bytes);
      case PlyType::Int32: return load<std::int32_t>(bytes);
      case PlyType::UInt32: return load<std::uint32_t>(bytes);
      case PlyType::Float32: return load<float>(bytes);
      case PlyType::Float64: return load<double>(bytes);
    }
    return 0;
  }
  template <typename T>
  static double load(const unsigned char* bytes) {
    T value;
    std::memcpy(&value, bytes, sizeof(T));
    return static_cast<double>(value);
  }

  std::string_view body_;
  PlyFormat format_;
  std::size_t pos_ = 0;
  std::size_t line_;       // of the last value read
  std::size_t scan_line_;  // of the scan position
  std::size_t base_offset_;
  std::string_view token_;
};

CrsTin readPly(const std::string& path, std::string_view text) {
  const PlyHeader header = readPlyHeader(path, text);
  const bool ascii = header.format == PlyFormat::Ascii;
  PlyValues values(text.substr(header.body_offset), header.format, header.body_line,
                   header.body_offset);
  const std::uint64_t nv = header.elements[header.vertex].count;
  const std::size_t body_bytes = text.size() - header.body_offset;

  CrsTin tin;
  std::vector<std::uint32_t> corners;
  bool vertices_read = false;
  // When faces come before vertices, their largest index is checked at the end.
  std::uint64_t largest_index = 0;
  bool any_index = false;
  std::string largest_where;

  for (std::size_t e = 0; e < header.elements.size(); ++e) {
    const PlyElement& element = header.elements[e];
    if (element.properties.empty()) continue;  // holds no data, whatever its count
    const bool is_vertex = e == header.vertex;
    const bool is_face = e == header.face;
    std::size_t row_bytes = 0;
    bool fixed_size = true;
    for (const PlyProperty& property : element.properties) {
      fixed_size = fixed_size && !property.list;
      row_bytes += plySize(property.type);
    }
    if (!ascii && fixed_size && !values.binaryRowsFit(element.count, row_bytes)) {
      inputError(path, "element '" + element.name + "' needs " + str(element.count) + " x " +
                           str(row_bytes) + " bytes from " + values.where() + " but the file has " +
                           str(text.size()) + " bytes; " + kTruncated);
    }
    if (!ascii && fixed_size && !is_vertex) {
      values.skipBinary(element.count, row_bytes);
      continue;
    }
    if (is_vertex) tin.positions.reserve(boundedReserve(element.count, body_bytes, 3));
    if (is_face) tin.triangle_indices.reserve(3 * boundedReserve(element.count, body_bytes, 4));

    for (std::uint64_t i = 0; i < element.count; ++i) {
      const auto item = [&]() { return element.name + " " + str(i); };
      std::array<double, 3> position{};
      for (std::size_t p = 0; p < element.properties.size(); ++p) {
        const PlyProperty& property = element.properties[p];
        double value = 0;
        bool numeric = true;
        const auto truncated = [&]() {
          inputError(path, "the data ends at " + values.where() + " inside " + item() + " of " +
                               str(element.count) + ", expected property '" + property.name +
                               "'; " + kTruncated);
        };
        const auto notNumeric = [&](const std::string& expected) {
          inputError(path, item() + " at " + values.where() + ": found " +
                               shown(values.token()) + " for property '" + property.name +
                               "', expected " + expected + "; " + kReexport);
        };
        if (!property.list) {
          const bool used = is_vertex && (p == header.xyz[0] || p == header.xyz[1] ||
                                          p == header.xyz[2]);
          if (!values.next(property.type, used, value, numeric)) truncated();
          if (!used) continue;
          if (!numeric || !std::isfinite(value)) notNumeric("a finite number");
          const std::size_t axis = p == header.xyz[0] ? 0 : p == header.xyz[1] ? 1 : 2;
          position[axis] = value;
          continue;
        }
        if (!values.next(property.count_type, true, value, numeric)) truncated();
        if (!numeric || value < 0) notNumeric("a non-negative integer list length");
        const auto length = static_cast<std::uint64_t>(value);
        const bool used = is_face && p == header.face_list;
        if (used && length < 3) {
          inputError(path, item() + " at " + values.where() + " has " + str(length) +
                               " corner(s), expected at least 3; " + kReexport);
        }
        if (used) corners.clear();
        // Each item consumes at least one byte or token, so a lying length ends in the
        // truncation error rather than a long loop.
        for (std::uint64_t k = 0; k < length; ++k) {
          if (!values.next(property.type, used, value, numeric)) truncated();
          if (!used) continue;
          if (!numeric) notNumeric("an integer vertex index");
          if (value < 0 || value >= static_cast<double>(kMaxVertices) ||
              (vertices_read && value >= static_cast<double>(nv))) {
            inputError(path, item() + " at " + values.where() + ": vertex index " +
                                 integerText(value) +
                                 " is out of range, expected " + indexRange(nv) + "; " +
                                 kReexport);
          }
          const auto index = static_cast<std::uint64_t>(value);
          if (!vertices_read && (!any_index || index > largest_index)) {
            any_index = true;
            largest_index = index;
            largest_where = item() + " at " + values.where();
          }
          corners.push_back(static_cast<std::uint32_t>(index));
        }
        if (used) addPolygon(corners, tin.triangle_indices);
      }
      if (is_vertex) tin.positions.push_back(position);
    }
    if (is_vertex) vertices_read = true;
  }
  if (any_index && largest_index >= nv) {
    inputError(path, largest_where + ": vertex index " + str(largest_index) +
                         " is out of range, expected " + indexRange(nv) + "; " + kReexport);
  }
  requireTriangles(path, tin);
  return tin;
}

// ------------------------------------------------------------------------------------------
// Writing

// A file written through path + ".tmp" and renamed by commit(); the temporary file is
// removed when the writer is destroyed without commit (an exception unwinding).
class AtomicFile {
 public:
  explicit AtomicFile(const std::string& path) : path_(path), temporary_(path + ".tmp") {
    file_ = std::fopen(temporary_.c_str(), "wb");
    if (!file_) {
      outputError(path_, "cannot create " + temporary_ + " (" + std::strerror(errno) + ")",
                  "check that the directory exists and is writable");
    }
    buffer_.reserve(kFlushBytes);
  }
  ~AtomicFile() {
    if (file_) std::fclose(file_);
    if (!committed_) {
      std::error_code ignored;
      fs::remove(temporary_, ignored);
    }
  }
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::string& buffer() { return buffer_; }
  void maybeFlush() {
    if (buffer_.size() >= kFlushBytes) flush();
  }

  void commit() {
    flush();
    std::FILE* file = file_;
    file_ = nullptr;
    if (std::fclose(file) != 0) {
      outputError(path_, std::string("cannot write (") + std::strerror(errno) + ")",
                  "check the free space and permissions");
    }
    std::error_code ec;
    fs::rename(temporary_, path_, ec);
    if (ec) {
      outputError(path_, "cannot rename " + temporary_ + " to it (" + ec.message() + ")",
                  "check that the path is not a directory and is writable");
    }
    committed_ = true;
  }

 private:
  static constexpr std::size_t kFlushBytes = std::size_t{1} << 20;

  void flush() {
    if (!buffer_.empty() &&
        std::fwrite(buffer_.data(), 1, buffer_.size(), file_) != buffer_.size()) {
      outputError(path_, std::string("cannot write (") + std::strerror(errno) + ")",
                  "check the free space and permissions");
    }
    buffer_.clear();
  }

  std::string path_;
  std::string temporary_;
  std::FILE* file_ = nullptr;
  std::string buffer_;
  bool committed_ = false;
};

// Shortest text that reads back to the same double (at most 17 significant digits),
// independent of the locale.
void appendNumber(std::string& out, double value) {
  char text[32];
  const std::to_chars_result result = std::to_chars(text, text + sizeof text, value);
  out.append(text, result.ptr);
}

void appendNumber(std::string& out, std::uint64_t value) {
  char text[24];
  const std::to_chars_result result = std::to_chars(text, text + sizeof text, value);
  out.append(text, result.ptr);
}

template <typename T>
void appendLittleEndian(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
  out.append(bytes, sizeof(T));
}

const char* const kFrameComment =
    "terratiles TIN: x east y north (CRS units) z height (m); triangles counter-clockwise "
    "seen from above";

// What the writers need of a TIN: its CRS positions one by one, so a TinMesh is written
// without a second copy in memory.
struct TinView {
  std::size_t vertex_count = 0;
  std::function<std::array<double, 3>(std::size_t)> position;
  const std::vector<std::uint32_t>& triangle_indices;
};

// One vertex and one triangle as each format stores them (OBJ indices count from 1).
void appendVertexRecord(TinFileFormat format, std::string& out, const std::array<double, 3>& p) {
  if (format == TinFileFormat::Ply) {
    for (const double value : p) appendLittleEndian(out, value);
    return;
  }
  if (format == TinFileFormat::Obj) out += "v ";
  appendNumber(out, p[0]);
  out += ' ';
  appendNumber(out, p[1]);
  out += ' ';
  appendNumber(out, p[2]);
  out += '\n';
}

void appendTriangleRecord(TinFileFormat format, std::string& out, std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  if (format == TinFileFormat::Ply) {
    appendLittleEndian(out, std::uint8_t{3});
    for (const std::uint32_t index : {a, b, c}) appendLittleEndian(out, index);
    return;
  }
  const std::uint64_t base = format == TinFileFormat::Obj ? 1 : 0;
  out += format == TinFileFormat::Obj ? 'f' : '3';
  for (const std::uint32_t index : {a, b, c}) {
    out += ' ';
    appendNumber(out, std::uint64_t{index} + base);
  }
  out += '\n';
}

// What comes before the vertices: OFF's and PLY's counts, OBJ's comment.
void appendHeader(TinFileFormat format, std::string& out, std::uint64_t vertex_count, std::uint64_t triangle_count) {
  switch (format) {
    case TinFileFormat::Off:
      out += "OFF\n";
      appendNumber(out, vertex_count);
      out += ' ';
      appendNumber(out, triangle_count);
      out += " 0\n";
      break;
    case TinFileFormat::Obj:
      out += "# ";
      out += kFrameComment;
      out += '\n';
      break;
    case TinFileFormat::Ply:
      out += "ply\nformat binary_little_endian 1.0\ncomment ";
      out += kFrameComment;
      out += "\nelement vertex ";
      appendNumber(out, vertex_count);
      out += "\nproperty double x\nproperty double y\nproperty double z\nelement face ";
      appendNumber(out, triangle_count);
      out += "\nproperty list uchar uint vertex_indices\nend_header\n";
      break;
  }
}

void writeTinBody(TinFileFormat format, const TinView& tin, AtomicFile& file) {
  std::string& out = file.buffer();
  appendHeader(format, out, tin.vertex_count, tin.triangle_indices.size() / 3);
  for (std::size_t v = 0; v < tin.vertex_count; ++v) {
    appendVertexRecord(format, out, tin.position(v));
    file.maybeFlush();
  }
  for (std::size_t i = 0; i < tin.triangle_indices.size(); i += 3) {
    appendTriangleRecord(format, out, tin.triangle_indices[i], tin.triangle_indices[i + 1], tin.triangle_indices[i + 2]);
    file.maybeFlush();
  }
}

std::string lowercase(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

void writeTinView(const TinView& tin, const std::string& path) {
  TERRATILES_ASSERT(tin.triangle_indices.size() % 3 == 0);
  for (const std::uint32_t index : tin.triangle_indices) {
    TERRATILES_ASSERT(index < tin.vertex_count);
  }
  for (std::size_t v = 0; v < tin.vertex_count; ++v) {
    const std::array<double, 3> p = tin.position(v);
    TERRATILES_ASSERT(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]));
  }
  const TinFileFormat format = tinFileFormatFor(path);
  AtomicFile file(path);
  writeTinBody(format, tin, file);
  file.commit();
}

}  // namespace

// A body file of TinFileStream: written through a buffer, removed with the stream.
struct TinFileStream::Part {
  std::string path;
  std::FILE* file = nullptr;
  std::string buffer;

  explicit Part(std::string part_path) : path(std::move(part_path)) {
    file = std::fopen(path.c_str(), "wb+");
    if (!file) {
      outputError(path, std::string("cannot create (") + std::strerror(errno) + ")",
                  "check that the directory exists and is writable");
    }
  }
  ~Part() {
    if (file) std::fclose(file);
    std::error_code ignored;
    fs::remove(path, ignored);
  }
  void flush() {
    if (!buffer.empty() && std::fwrite(buffer.data(), 1, buffer.size(), file) != buffer.size()) {
      outputError(path, std::string("cannot write (") + std::strerror(errno) + ")", "check the free space");
    }
    buffer.clear();
  }
  void maybeFlush() {
    if (buffer.size() >= (std::size_t{1} << 20)) flush();
  }
  // Appends the whole part to `out`.
  void copyTo(AtomicFile& out) {
    flush();
    std::rewind(file);
    char chunk[1 << 16];
    std::size_t got = 0;
    while ((got = std::fread(chunk, 1, sizeof chunk, file)) > 0) {
      out.buffer().append(chunk, got);
      out.maybeFlush();
    }
    if (std::ferror(file)) {
      outputError(path, std::string("cannot read back (") + std::strerror(errno) + ")", "check the disk");
    }
  }
};

TinFileStream::TinFileStream(const std::string& path) : path_(path), format_(tinFileFormatFor(path)) {
  vertices_ = std::make_unique<Part>(path + ".vertices.tmp");
  triangles_ = std::make_unique<Part>(path + ".triangles.tmp");
}

TinFileStream::~TinFileStream() = default;

std::uint32_t TinFileStream::addVertex(const std::array<double, 3>& position) {
  TERRATILES_ASSERT(std::isfinite(position[0]) && std::isfinite(position[1]) && std::isfinite(position[2]));
  if (vertex_count_ >= std::numeric_limits<std::uint32_t>::max()) {
    outputError(path_, "more than 4,294,967,295 vertices, the most 32-bit indices can count",
                "raise --tin-max-error or split the input");
  }
  appendVertexRecord(format_, vertices_->buffer, position);
  vertices_->maybeFlush();
  return static_cast<std::uint32_t>(vertex_count_++);
}

void TinFileStream::addTriangle(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  TERRATILES_ASSERT(a < vertex_count_ && b < vertex_count_ && c < vertex_count_);
  appendTriangleRecord(format_, triangles_->buffer, a, b, c);
  triangles_->maybeFlush();
  ++triangle_count_;
}

void TinFileStream::commit() {
  AtomicFile file(path_);
  appendHeader(format_, file.buffer(), vertex_count_, triangle_count_);
  vertices_->copyTo(file);
  triangles_->copyTo(file);
  file.commit();
  vertices_.reset();
  triangles_.reset();
}

TinFileFormat tinFileFormatFor(const std::string& path) {
  const std::string extension = lowercase(fs::path(path).extension().string());
  if (extension == ".off") return TinFileFormat::Off;
  if (extension == ".obj") return TinFileFormat::Obj;
  if (extension == ".ply") return TinFileFormat::Ply;
  const std::string found = extension.empty() ? "no extension" : "extension " + shown(extension);
  throw Error(ErrorCode::Usage, path + ": unknown TIN file type, found " + found +
                                    ", expected .off, .obj or .ply; name the file with one of "
                                    "these extensions");
}

void writeTinFile(const CrsTin& tin, const std::string& path) {
  writeTinView({tin.positions.size(), [&](std::size_t v) { return tin.positions[v]; }, tin.triangle_indices},
               path);
}

void writeTinFile(const TinMesh& mesh, double origin_x, double origin_y, double pixel_size,
                  const std::string& path) {
  TERRATILES_ASSERT(pixel_size > 0);
  writeTinView({mesh.vertices.size(),
                [&](std::size_t v) {
                  const GridPoint& p = mesh.vertices[v];
                  return std::array<double, 3>{origin_x + (p.col + 0.5) * pixel_size,
                                               origin_y - (p.row + 0.5) * pixel_size, p.height_m};
                },
                mesh.triangle_indices},
               path);
}

CrsTin readTinFile(const std::string& path) {
  const TinFileFormat format = tinFileFormatFor(path);
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) {
    inputError(path, std::string("cannot open (") + std::strerror(errno) +
                         "); check the path and permissions");
  }
  std::string bytes;
  char chunk[1 << 16];
  std::size_t got = 0;
  while ((got = std::fread(chunk, 1, sizeof chunk, file)) > 0) bytes.append(chunk, got);
  const bool failed = std::ferror(file) != 0;
  const int read_errno = errno;
  std::fclose(file);
  if (failed) {
    inputError(path, std::string("cannot read (") + std::strerror(read_errno) +
                         "); check that it is a readable file");
  }
  switch (format) {
    case TinFileFormat::Off: return readOff(path, withoutByteOrderMark(bytes));
    case TinFileFormat::Obj: return readObj(path, withoutByteOrderMark(bytes));
    case TinFileFormat::Ply: return readPly(path, bytes);
  }
  TERRATILES_ASSERT(false);
  return {};
}

CrsTin toCrsTin(const TinMesh& mesh, double origin_x, double origin_y, double pixel_size) {
  TERRATILES_ASSERT(pixel_size > 0);
  CrsTin tin;
  tin.positions.reserve(mesh.vertices.size());
  for (const GridPoint& v : mesh.vertices) {
    tin.positions.push_back({origin_x + (v.col + 0.5) * pixel_size,
                             origin_y - (v.row + 0.5) * pixel_size, v.height_m});
  }
  tin.triangle_indices = mesh.triangle_indices;
  return tin;
}

TinMesh toGridTin(const CrsTin& tin, double origin_x, double origin_y, double pixel_size) {
  TERRATILES_ASSERT(pixel_size > 0);
  TinMesh mesh;
  mesh.vertices.reserve(tin.positions.size());
  for (const std::array<double, 3>& p : tin.positions) {
    mesh.vertices.push_back(
        {(p[0] - origin_x) / pixel_size - 0.5, (origin_y - p[1]) / pixel_size - 0.5, p[2]});
  }
  mesh.triangle_indices = tin.triangle_indices;
  return mesh;
}

}  // namespace terratiles
