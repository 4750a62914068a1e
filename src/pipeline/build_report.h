#pragma once
// The build report (OUTDIR/report.json and report.html, next to the tileset and not referenced
// by it): what a build produced and how good it is, in numbers and pictures (schema
// "terratiles-report/1", rendered by renderReportHtml).
//
// buildReportJson assembles it from what the build knows; regenerateReport rebuilds it from an
// existing output (`terratiles report OUTDIR`): from its report.json when there is one, else
// (an output written before reports existed) from tileset.json, build.json, the tiles and the
// DEM, without what only the build knew (cluster maps, stage times).

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "src/base/progress.h"
#include "src/pipeline/check_output.h"
#include "src/pipeline/report_maps.h"
#include "src/pipeline/run_pipeline.h"

namespace terratiles {

inline constexpr const char* kReportSchema = "terratiles-report/1";

nlohmann::json checkReportJson(const CheckReport& report);

nlohmann::json buildReportJson(const BuildOptions& options, const BuildSummary& summary,
                               const std::vector<StageRecord>& stages, const std::optional<CheckReport>& check,
                               const std::vector<ZoomMaps>& maps);

struct ReportOptions {
  std::size_t check_cuts = 200;  // 0: keep the recorded check (or none)
};

struct RegeneratedReport {
  std::string html_path;
  bool from_build_record = false;  // report.json was there (else rebuilt from the files)
  nlohmann::json report;
};

// Writes OUTDIR/report.json and report.html (each to a temporary name, then renamed).
// Throws Error(Input) naming what is missing when OUTDIR is not a terratiles output or was
// written before build.json existed (then: rebuild it).
RegeneratedReport regenerateReport(const std::string& output_dir, const ReportOptions& options, Progress& progress);

// Writes `text` to `path` through a temporary name in the same directory (no half-written
// file is ever visible). Throws Error(Output).
void writeFileAtomically(const std::string& path, const std::string& text);

}  // namespace terratiles
