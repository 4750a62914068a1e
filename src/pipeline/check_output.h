#pragma once
// checkOutput: proves (or disproves) that a written tileset is seamless and honest, from what
// is on disk: tileset.json, every GLB decoded (Draco), and the source DEM named in build.json
// (DESIGN.md section 5; `terratiles check OUTDIR`). No tolerance anywhere: the measures are
// those of the build (src/pipeline/drawn_tiles.h) on the decoded numbers.
//
// Every decoded vertex goes back from ECEF to the DEM's grid (WGS84 -> the DEM's CRS through
// PROJ, the geoid undulation taken off for orthometric heights). A vertex on a tile's outline
// that decodes as near a pixel centre as quantisation can move a DEM point (half the widest
// step's diagonal plus 1 cm, at most a tenth of a pixel) is a DEM point (the finest TIN's
// vertices, and the data's outer border at every zoom, never move): it is put back on that
// centre, so outlines meet exactly in the grid. (An outline vertex a coarser level moved
// before it was locked is not one; counted.) A vertex at a pole (a geographic DEM's first or
// last row) has no column. Then:
//   1. coverage: every tile's content covers the pixels inside its triangles in the grid and
//      the pixels whose verticals meet its triangles as drawn (a triangle with a pole vertex
//      has no place in the grid; a long chord strays from its grid triangle by its bulge,
//      poleward: at high latitudes by several columns). `cuts` random cuts of
//      the tile tree (a set of tiles whose squares tile the data, as a viewer draws them)
//      whose neighbours are at most one zoom apart, and one cut per zoom made of that zoom
//      alone, must cover every footprint pixel (a valid pixel the finest zoom covers); cuts
//      with neighbours two or more zooms apart are reported only. Every valid pixel the
//      finest zoom leaves out must touch nodata (the TIN follows ragged data to a pixel).
//   2. honest errors: at every DEM pixel whose vertical meets a decoded triangle (as drawn,
//      straight in ECEF), the vertical error must not exceed the tile's geometricError by any
//      amount; nor may the tile differ there from the next finer zoom's drawn surface by more
//      (overlap agreement, so contents drawn side by side agree); every geometricError must
//      be at least its children's, every region must hold its content (drawnRegion of the
//      decoded triangles) and its children's regions.
//   3. vertex correspondence (paper 5.2.3): for every pair of touching tiles one zoom apart
//      (not parent and child), an outline vertex of one that lies on an outline edge of the
//      other must be a vertex of it: no T-junction where the two contents meet; and every
//      outline vertex two touching tiles (also neighbours at one zoom) both hold must decode
//      to exactly the same position in both.
// Violations are counted, with the first few described.
//
// Memory: the DEM is read and measured in strips of rows (CheckOptions::strip_pixels), as the
// build measures its coarse zooms (writeZoomsInStrips): every tile is decoded once for its
// outline, region and rows, then again in every strip whose window (the strip's rows and the
// rows the tallest triangle reaches above and below) its rows meet, and measured there with
// the window's DemOnGlobe; each pixel is counted in its own strip only, a tile's errors are
// the largest over the strips, and its outline vertices are put back on their pixel centres
// in the strip of their row. So a report is the same for any strip size, and memory is one
// window and the tiles' outlines, whatever the raster's size. The time grows with the strips'
// count (a tile is decoded in each strip it meets). A raster the strip budget holds whole is
// one strip, its window the raster: each tile is decoded once there, for both.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "src/base/progress.h"

namespace terratiles {

struct CheckOptions {
  std::size_t cuts = 1000;
  std::uint32_t seed = 1;
  // The DEM is read and measured in strips of rows of about this many pixels (each with the
  // rows the tallest triangle reaches above and below it); the report is the same for any
  // strip size. Memory: 33 bytes per pixel of a strip for a DEM in WGS84 longitude and
  // latitude, 73 for another CRS, plus each tile's outline. Positive; else Error(Usage).
  std::int64_t strip_pixels = 16'000'000;
};

struct CheckReport {
  std::size_t tiles = 0;
  std::size_t zooms = 0;
  std::size_t footprint_pixels = 0;
  // Valid pixels the finest zoom leaves out: those next to nodata (the TIN's ragged edge,
  // reported), and those that are not (left out: a violation).
  std::size_t uncovered_valid_pixels = 0;
  std::size_t left_out_pixels = 0;
  std::size_t pole_vertices = 0;  // decoded vertices at a pole (no column; measured as drawn)
  std::size_t cuts = 0;           // balanced cuts checked (random + one per zoom)
  std::size_t cuts_with_holes = 0;
  std::size_t hole_pixels = 0;    // summed over the balanced cuts
  std::size_t unbalanced_cuts = 0;  // random cuts with neighbours >= 2 zooms apart
  std::size_t unbalanced_cuts_with_holes = 0;
  std::size_t unbalanced_hole_pixels = 0;
  std::size_t neighbour_pairs = 0;  // touching tiles one zoom apart (not parent and child)
  std::size_t missing_border_vertices = 0;
  std::size_t moved_outline_vertices = 0;  // outline vertices more than 0.1 px off a pixel centre (moved by a level)
  // Outline vertices that touching tiles (one zoom apart, or neighbours at one zoom) both
  // hold, and how far apart they decode: exactly nothing, or it is a gap.
  std::size_t shared_border_vertices = 0;
  std::size_t shared_vertex_gaps = 0;
  double worst_shared_vertex_gap_m = 0;
  std::size_t measured_pixels = 0;  // pixel and triangle pairs where a vertical meets a triangle
  std::size_t overlap_pixels = 0;   // of those, where the next finer zoom is drawn too
  std::size_t overlap_disagreements = 0;  // tiles differing from the finer zoom by more than their geometricError
  double worst_overlap_ratio = 0;         // max difference / geometricError
  std::size_t dishonest_errors = 0;       // tiles whose decoded error exceeds their geometricError
  double worst_error_ratio = 0;           // max decoded error / geometricError
  std::size_t error_order_violations = 0; // a child's geometricError above its parent's
  std::size_t region_violations = 0;      // a child's region outside its parent's
  std::size_t content_region_violations = 0;  // a tile's content outside its own region
  std::vector<std::string> problems;      // the first few violations, one line each

  bool ok() const {
    return cuts_with_holes == 0 && left_out_pixels == 0 && overlap_disagreements == 0 && missing_border_vertices == 0 &&
           shared_vertex_gaps == 0 && dishonest_errors == 0 &&
           error_order_violations == 0 && region_violations == 0 && content_region_violations == 0;
  }
};

// Throws Error(Input) when OUTDIR is not a terratiles output (no tileset.json or build.json)
// or a file in it is malformed.
CheckReport checkOutput(const std::string& output_dir, const CheckOptions& options, Progress& progress);

// One screen: the figures and the first problems.
std::string describeCheck(const CheckReport& report);

}  // namespace terratiles
