#pragma once
// runCli: the whole `terratiles` command line as a testable function. Parses `args`
// (args[0] is the program name), runs the command reading `in` where it takes standard
// input (transform), prints help, results and the summary to `out`/`err`, and returns the
// process exit code:
//   0 ok, 1 internal error, 2 usage, 3 bad input, 4 output not writable, 6 out of memory,
//   130 interrupted; `check` returns 5 when it finds a violation.
// Errors are one line on `err`: "terratiles: error: ...". Never throws.

#include <iosfwd>
#include <string>
#include <vector>

namespace terratiles {

int runCli(const std::vector<std::string>& args, std::istream& in, std::ostream& out,
           std::ostream& err);

}  // namespace terratiles
