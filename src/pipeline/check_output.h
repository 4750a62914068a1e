#pragma once
// checkOutput: proves (or disproves) that a written tileset is seamless and honest, from what
// is on disk: tileset.json, every GLB decoded (Draco), and the source DEM named in build.json
// (DESIGN.md section 5; `terratiles check OUTDIR`).
//
// Every decoded vertex goes back from ECEF to the DEM's grid (WGS84 -> the DEM's CRS through
// PROJ, the geoid undulation taken off for orthometric heights), and every tile's triangles
// are rasterised on the DEM's pixel centres (measureTin's rule). Then:
//   1. coverage: `cuts` random cuts of the tile tree (a set of tiles whose squares tile the
//      data, as a viewer draws them) whose neighbours are at most one zoom apart, and one
//      cut per zoom made of that zoom alone: every footprint pixel (a valid pixel the finest
//      zoom covers) must be covered by some drawn tile's content; the same for random cuts
//      with neighbours two or more zooms apart, reported but not a violation;
//   2. overlap agreement: where zoom z and zoom z + 1 contents cover the same pixel, their
//      heights differ by no more than the geometricError of every zoom-z tile covering it;
//   3. vertex correspondence (paper 5.2.3): for every pair of touching tiles one zoom apart
//      (not parent and child), an outline vertex of one that lies on an outline edge of the
//      other must be a vertex of it, at the same decoded position (within 1 mm, or twice
//      the widest quantisation step used): no T-junction where the two contents meet;
//      Every outline vertex two touching tiles (also neighbours at one zoom) both hold must
//      decode to one position in both: within 1 mm where their zooms share a grid;
//   4. honest errors: every tile's geometricError >= the max vertical error of its decoded
//      content against the DEM (to the quantisation step) and >= its children's; every
//      parent's region contains its children's.
// Violations are counted, with the first few described.

#include <cstddef>
#include <string>
#include <vector>

#include "src/base/progress.h"

namespace terratiles {

struct CheckOptions {
  std::size_t cuts = 1000;
  std::uint32_t seed = 1;
};

struct CheckReport {
  std::size_t tiles = 0;
  std::size_t zooms = 0;
  std::size_t footprint_pixels = 0;
  // A geographic DEM with rows at a pole: triangles with a vertex there are left out (no
  // decoding gives its longitude back), with the caps beyond this |latitude| (coverage and
  // vertex correspondence both); 90: none.
  double polar_cap_deg = 90;
  std::size_t cuts = 0;                   // balanced cuts checked (random + one per zoom)
  std::size_t cuts_with_holes = 0;
  std::size_t hole_pixels = 0;            // summed over the balanced cuts
  std::size_t unbalanced_cuts = 0;        // random cuts with neighbours >= 2 zooms apart
  std::size_t unbalanced_cuts_with_holes = 0;
  std::size_t unbalanced_hole_pixels = 0;
  std::size_t neighbour_pairs = 0;        // touching tiles one zoom apart (not parent and child)
  std::size_t missing_border_vertices = 0;
  // Outline vertices that touching tiles (one zoom apart, or neighbours at one zoom) both
  // hold, and how far apart they decode: within 1 mm where both zooms share a grid, within
  // two of the coarser steps where a wide zoom uses a coarser one.
  std::size_t shared_border_vertices = 0;
  std::size_t shared_vertex_gaps = 0;  // pairs further apart than that
  double worst_shared_vertex_gap_m = 0;              // between tiles on one grid
  double worst_shared_vertex_gap_coarser_grid_m = 0; // where the two zooms' grids differ
  std::size_t overlap_pixels = 0;         // pixels covered at two adjacent zooms
  std::size_t overlap_disagreements = 0;
  double worst_overlap_ratio = 0;         // max |dh| / geometricError over the overlaps
  std::size_t dishonest_errors = 0;       // geometricError below the measured error
  std::size_t error_order_violations = 0; // a child's geometricError above its parent's
  std::size_t region_violations = 0;      // a child's region outside its parent's
  double worst_error_ratio = 0;           // max measured error / geometricError
  std::vector<std::string> problems;      // the first few violations, one line each

  bool ok() const {
    return cuts_with_holes == 0 && overlap_disagreements == 0 && missing_border_vertices == 0 && shared_vertex_gaps == 0 &&
           dishonest_errors == 0 &&
           error_order_violations == 0 && region_violations == 0;
  }
};

// Throws Error(Input) when OUTDIR is not a terratiles output (no tileset.json or build.json)
// or a file in it is malformed.
CheckReport checkOutput(const std::string& output_dir, const CheckOptions& options, Progress& progress);

// One screen: the figures and the first problems.
std::string describeCheck(const CheckReport& report);

}  // namespace terratiles
