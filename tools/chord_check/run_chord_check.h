#pragma once
// runChordCheck: the terratiles_chord_check command line as a testable function (main.cpp
// is a thin wrapper).
//
//   terratiles_chord_check OUTDIR [--json] [--extra-margin-px N] [--convert-every-sample] [-q]
//
// Measures OUTDIR's decoded chords (tools/chord_check/chord_geometry.h) and prints the table,
// or with --json one JSON object, on `out`. Progress goes to stderr on a terminal (never with
// -q). Exit codes: 0 when no tile's error exceeds its geometricError and no region sample
// lies outside its region, 5 otherwise, 2 for a bad command line, 3 for bad input (not an
// output, unreadable DEM or tile), 1 for an internal error, 130 when interrupted. Errors are
// one line on `err`: "terratiles_chord_check: error: ...".

#include <ostream>
#include <string>
#include <vector>

namespace terratiles {

inline constexpr int kChordCheckFailedExitCode = 5;

// args[0] is the program name.
int runChordCheck(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace terratiles
