// terratiles_chord_check OUTDIR [--json]: the decoded chords of an output against the DEM and
// the tiles' regions (tools/chord_check/chord_geometry.h).
#include <iostream>

#include "tools/chord_check/run_chord_check.h"

int main(int argc, char** argv) {
  return terratiles::runChordCheck(std::vector<std::string>(argv, argv + argc), std::cout, std::cerr);
}
