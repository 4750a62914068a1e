#include "tools/chord_check/run_chord_check.h"

#include <unistd.h>

#include <csignal>
#include <new>

#include "src/base/error.h"
#include "src/base/progress.h"
#include "tools/chord_check/chord_geometry.h"

namespace terratiles {
namespace {

constexpr const char* kUsage =
    "usage: terratiles_chord_check OUTDIR [--json] [--extra-margin-px N] [--convert-every-sample] [-q]\n"
    "  Decodes every tile of a terratiles output and measures, in ECEF, each tile's error at\n"
    "  the DEM pixel verticals against its geometricError, whether its region holds samples of\n"
    "  every triangle, and how far chords sag below the surface through their corners.\n"
    "  --json               one JSON object instead of the table\n"
    "  --extra-margin-px N  pixels added to every triangle's candidate margin (default 0)\n"
    "  --convert-every-sample  convert every region sample, also of triangles provably\n"
    "                       inside their region (slower; the same counts)\n"
    "  -q, --quiet          no progress on stderr\n"
    "  exit: 0 ok, 5 a tile over its geometricError or a sample outside its region,\n"
    "        2 usage, 3 bad input, 1 internal, 130 interrupted\n";

// A C-linkage name of its own (terratiles_cli has an onInterrupt of its own).
extern "C" void chordCheckOnInterrupt(int) { Progress::requestCancel(); }

struct InterruptGuard {
  InterruptGuard() { previous_ = std::signal(SIGINT, chordCheckOnInterrupt); }
  ~InterruptGuard() { std::signal(SIGINT, previous_); }
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;
  void (*previous_)(int) = nullptr;
};

}  // namespace

int runChordCheck(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  std::string output_dir;
  bool as_json = false, quiet = false;
  ChordOptions options;
  try {
    for (std::size_t i = 1; i < args.size(); ++i) {
      const std::string& arg = args[i];
      if (arg == "-h" || arg == "--help") {
        out << kUsage;
        return 0;
      } else if (arg == "--json") {
        as_json = true;
      } else if (arg == "--convert-every-sample") {
        options.convert_every_sample = true;
      } else if (arg == "-q" || arg == "--quiet") {
        quiet = true;
      } else if (arg == "--extra-margin-px") {
        if (i + 1 >= args.size()) throw Error(ErrorCode::Usage, "--extra-margin-px needs a number of pixels");
        std::size_t used = 0;
        double value = -1;
        try {
          value = std::stod(args[++i], &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != args[i].size() || !(value >= 0) || value > 1e6) {
          throw Error(ErrorCode::Usage, "--extra-margin-px " + args[i] + ": expected a number of pixels, 0 to 1e6");
        }
        options.extra_margin_px = value;
      } else if (!arg.empty() && arg[0] == '-') {
        throw Error(ErrorCode::Usage, "unknown option " + arg + " (see --help)");
      } else if (output_dir.empty()) {
        output_dir = arg;
      } else {
        throw Error(ErrorCode::Usage, "one OUTDIR expected, found a second: " + arg);
      }
    }
    if (output_dir.empty()) throw Error(ErrorCode::Usage, "no OUTDIR given (see --help)");
    InterruptGuard guard;
    Progress::resetCancel();
    Progress progress(!quiet && ::isatty(STDERR_FILENO) ? ProgressMode::Bar : ProgressMode::Quiet);
    const ChordReport report = measureChordGeometry(output_dir, options, progress);
    out << (as_json ? chordReportToJson(report) + "\n" : describeChordReport(report));
    return report.ok() ? 0 : kChordCheckFailedExitCode;
  } catch (const Error& e) {
    err << "terratiles_chord_check: error: " << e.what() << "\n";
    if (e.code() == ErrorCode::Usage) err << kUsage;
    return exitCodeFor(e.code());
  } catch (const std::bad_alloc&) {
    err << "terratiles_chord_check: error: out of memory\n";
    return exitCodeFor(ErrorCode::Internal);
  } catch (const std::exception& e) {
    err << "terratiles_chord_check: internal error: " << e.what() << "\n";
    return exitCodeFor(ErrorCode::Internal);
  }
}

}  // namespace terratiles
