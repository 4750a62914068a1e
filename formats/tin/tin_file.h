#pragma once
// TIN files: reading and writing a triangulated surface as OFF, OBJ or PLY, for exchanging
// TINs with other tools (MeshLab, CloudCompare, CGAL, Blender) and for comparing ours with
// theirs. Files hold CRS coordinates; the pipeline's TinMesh is in the DEM's grid frame, so
// toCrsTin and toGridTin convert with the DEM's north-up georeference.
//
// Formats, chosen by the file's extension (case-insensitive):
//   .off  ASCII OFF.  Read: optional header keyword (OFF, COFF, NOFF, STOFF, ...; alone on its
//         line or followed by the counts), '#' comments, blank lines, one vertex or face per
//         line; values after x y z or after a face's indices (colours, normals) are ignored.
//   .obj  ASCII OBJ.  Read: "v x y z", "f a b c" with 1-based or negative (relative) indices
//         and a/b/c, a//c, a/b references; every other line is ignored.
//   .ply  PLY.  Write: binary little-endian, x y z as double, faces as uchar count + uint
//         indices. Read: ascii, binary_little_endian and binary_big_endian; the vertex
//         element's x y z may be of any scalar type and stand among other properties; the
//         face element's list vertex_indices (or vertex_index) may have any integer count
//         and index types; other elements and properties are skipped.
// Polygons with more than three corners are fan-triangulated (0 i i+1) on reading; the
// orientation is taken as stored.
//
// Numbers are written with std::to_chars (shortest representation that reads back to the
// same double, so at most 17 significant digits) and read with std::from_chars: both are
// locale-independent, and a written file reads back bit for bit.
//
// Failures: an unknown extension is Error(Usage). A file that cannot be read or is malformed
// is Error(Input) with the file, the line (ASCII) or the element (binary PLY), what was
// found and what was expected; reading never crashes or allocates without bound on bad
// input. A file that cannot be written is Error(Output); the writer goes through
// path + ".tmp", renamed when complete, so a failed write leaves neither a partial file nor
// the temporary one.

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "src/tin/tin_mesh.h"

namespace terratiles {

// A TIN in CRS coordinates as stored in files: x east, y north (CRS units), z height in
// metres; triangles counter-clockwise seen from above (3 indices each).
struct CrsTin {
  std::vector<std::array<double, 3>> positions;
  std::vector<std::uint32_t> triangle_indices;

  std::size_t triangleCount() const { return triangle_indices.size() / 3; }
};

enum class TinFileFormat { Off, Obj, Ply };

// The format for `path`'s extension (.off, .obj, .ply, any case). Throws Error(Usage) naming
// the accepted extensions for anything else.
TinFileFormat tinFileFormatFor(const std::string& path);

// Writes `tin` in the format of `path`'s extension, replacing an existing file. Precondition
// (asserted): whole triangles and every index below positions.size(). Throws Error(Usage)
// for an unknown extension and Error(Output) when the file cannot be written.
void writeTinFile(const CrsTin& tin, const std::string& path);
// The same for a grid-frame TinMesh with the georeference of toCrsTin (below), converting
// vertex by vertex: writes the file toCrsTin's result would give, without that copy.
void writeTinFile(const TinMesh& mesh, double origin_x, double origin_y, double pixel_size,
                  const std::string& path);

// Writes a TIN piece by piece, for one too large to hold (a TIN built block by block):
// vertices and triangles go to two temporary files beside `path` (path + ".vertices.tmp",
// ".triangles.tmp"), which commit() joins behind the header into `path` (through
// path + ".tmp", renamed when complete). Without commit() nothing is left behind. The file is
// the one writeTinFile would write for the same vertices and triangles. Error(Usage) for an
// unknown extension, Error(Output) when a file cannot be written or past 2^32 - 1 vertices.
class TinFileStream {
 public:
  explicit TinFileStream(const std::string& path);
  ~TinFileStream();
  TinFileStream(const TinFileStream&) = delete;
  TinFileStream& operator=(const TinFileStream&) = delete;

  // A vertex in CRS coordinates (finite); returns its index.
  std::uint32_t addVertex(const std::array<double, 3>& position);
  // A triangle of vertices added before (asserted), counter-clockwise seen from above.
  void addTriangle(std::uint32_t a, std::uint32_t b, std::uint32_t c);
  std::uint64_t vertexCount() const { return vertex_count_; }
  std::uint64_t triangleCount() const { return triangle_count_; }
  void commit();

 private:
  struct Part;
  std::string path_;
  TinFileFormat format_;
  std::unique_ptr<Part> vertices_, triangles_;
  std::uint64_t vertex_count_ = 0, triangle_count_ = 0;
};

// Reads a TIN from `path` in the format of its extension. Guarantees on return: at least one
// triangle, every index below positions.size(), every coordinate finite. Throws Error(Usage)
// for an unknown extension and Error(Input) for anything unreadable or malformed.
CrsTin readTinFile(const std::string& path);

// Grid frame <-> CRS with a north-up georeference: (origin_x, origin_y) is the north-west
// corner of the raster and pixel_size (> 0, asserted) the side of its square pixels, in CRS
// units; pixel centres are at whole (col, row), as in DemGrid::pixelCentre:
//   x = origin_x + (col + 0.5) * pixel_size,  y = origin_y - (row + 0.5) * pixel_size.
// Heights and triangles are copied unchanged. toGridTin is the inverse (vertices need not be
// on pixel centres); a round trip agrees to rounding, not bit for bit.
CrsTin toCrsTin(const TinMesh& mesh, double origin_x, double origin_y, double pixel_size);
TinMesh toGridTin(const CrsTin& tin, double origin_x, double origin_y, double pixel_size);

}  // namespace terratiles
