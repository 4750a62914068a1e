#pragma once
// renderReportHtml: report.html from a report.json document (schema terratiles-report/1,
// src/pipeline/report_schema.json): one self-contained page, inline CSS and SVG plots, the
// maps as data: URIs, no script and no reference to anything outside the file. Fields a
// report lacks (a report rebuilt from an older output's files) read "not recorded".
//
// errorColour and clusterColour are the colours of the report's maps (report_maps.h), so
// the page's colour bar and the map images agree.

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

namespace terratiles {

// Throws Error(Input) when report["schema"] is not "terratiles-report/1".
std::string renderReportHtml(const nlohmann::json& report);

// The error ramp, t in 0..1 (clamped): dark blue, teal, green, yellow (viridis-like,
// perceptually ordered, readable in grey).
std::array<std::uint8_t, 3> errorColour(double t);

// Well-separated colours for cluster ids: hues stepped by the golden angle, alternating
// lightness, never black or white (the borders).
std::array<std::uint8_t, 3> clusterColour(std::uint32_t cluster);

}  // namespace terratiles
