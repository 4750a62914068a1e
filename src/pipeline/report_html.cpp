#include "src/pipeline/report_html.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

#include "src/base/error.h"

namespace terratiles {
namespace {

using nlohmann::json;

std::string escape(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string number(double value, int digits) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", digits, value);
  return buffer;
}

// 1234567 -> "1 234 567" (thin spaces group the digits).
std::string grouped(std::uint64_t value) {
  std::string digits = std::to_string(value), out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += "&#8201;";
    out += digits[i];
  }
  return out;
}

std::string bytesText(double bytes) {
  if (bytes >= 1024.0 * 1024.0) return number(bytes / (1024.0 * 1024.0), 1) + " MiB";
  if (bytes >= 1024.0) return number(bytes / 1024.0, 1) + " KiB";
  return number(bytes, 0) + " B";
}

// A field as text: numbers with `digits` decimals (integers grouped), strings escaped,
// booleans yes/no, anything missing "not recorded".
std::string field(const json& object, const std::string& key, int digits = 3) {
  if (!object.is_object() || !object.contains(key) || object[key].is_null()) return "<i>not recorded</i>";
  const json& v = object[key];
  if (v.is_number_unsigned()) return grouped(v.get<std::uint64_t>());
  if (v.is_number_integer()) {
    const auto i = v.get<std::int64_t>();
    return i < 0 ? "&minus;" + grouped(static_cast<std::uint64_t>(-i)) : grouped(static_cast<std::uint64_t>(i));
  }
  if (v.is_number()) return number(v.get<double>(), digits);
  if (v.is_boolean()) return v.get<bool>() ? "yes" : "no";
  if (v.is_string()) return escape(v.get<std::string>());
  if (v.is_array()) {
    // A country's thousands of input files: the first and last few, and how many between.
    constexpr std::size_t kShown = 4;
    std::string out;
    for (std::size_t i = 0; i < v.size(); ++i) {
      if (v.size() > 3 * kShown && i == kShown) {
        out += "<br>&hellip; " + grouped(v.size() - 2 * kShown) + " more &hellip;";
        i = v.size() - kShown;
      }
      const json& item = v[i];
      out += (out.empty() ? "" : "<br>") + escape(item.is_string() ? item.get<std::string>() : item.dump());
    }
    return out.empty() ? "none" : out;
  }
  return escape(v.dump());
}

double numberOr(const json& object, const std::string& key, double fallback) {
  return object.is_object() && object.contains(key) && object[key].is_number() ? object[key].get<double>() : fallback;
}

// ---- plots (inline SVG) ---------------------------------------------------------------

struct Series {
  std::string name;
  std::string colour;
  std::vector<double> values;  // NaN: none
};

constexpr int kPlotWidth = 560, kPlotHeight = 260, kLeft = 70, kRight = 150, kTop = 30, kBottom = 40;

struct Axis {
  double lo = 0, hi = 1;
  bool log = false;
  double at(double v) const {  // 0..1 from the bottom
    if (log) return (std::log10(std::max(v, lo)) - std::log10(lo)) / (std::log10(hi) - std::log10(lo));
    return (v - lo) / (hi - lo);
  }
};

Axis axisFor(const std::vector<Series>& series) {
  double lo = 1e300, hi = -1e300;
  for (const Series& s : series) {
    for (const double v : s.values) {
      if (std::isnan(v)) continue;
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  }
  Axis axis;
  if (hi < lo) return axis;
  const double positive_lo = [&] {
    double m = 1e300;
    for (const Series& s : series) {
      for (const double v : s.values) {
        if (v > 0) m = std::min(m, v);
      }
    }
    return m;
  }();
  if (positive_lo < 1e300 && hi / positive_lo > 100) {  // values span decades: log scale
    axis.log = true;
    axis.lo = std::pow(10.0, std::floor(std::log10(positive_lo)));
    axis.hi = std::pow(10.0, std::ceil(std::log10(hi)));
    if (axis.hi <= axis.lo) axis.hi = axis.lo * 10;
    return axis;
  }
  axis.lo = 0;
  const double step = std::pow(10.0, std::floor(std::log10(std::max(hi, 1e-12))));
  axis.hi = std::ceil(hi / step) * step;
  if (axis.hi <= 0) axis.hi = 1;
  return axis;
}

std::string tickText(double v) {
  if (v == 0) return "0";
  if (std::fabs(v) >= 1e6) return number(v / 1e6, v >= 1e7 ? 0 : 1) + "M";
  if (std::fabs(v) >= 1e3) return number(v / 1e3, v >= 1e4 ? 0 : 1) + "k";
  if (std::fabs(v) >= 1) return number(v, v == std::round(v) ? 0 : 1);
  return number(v, 3);
}

// Categories along x (zooms or stages), one value per series per category; lines or bars.
std::string plot(const std::string& title, const std::string& unit, const std::vector<std::string>& categories,
                 const std::vector<Series>& series, bool bars) {
  std::ostringstream svg;
  const int w = kPlotWidth, h = kPlotHeight, pw = w - kLeft - kRight, ph = h - kTop - kBottom;
  svg << "<svg class=\"plot\" width=\"" << w << "\" height=\"" << h << "\" viewBox=\"0 0 " << w << ' ' << h
      << "\" role=\"img\" aria-label=\"" << escape(title) << "\">";
  svg << "<text x=\"" << kLeft << "\" y=\"18\" class=\"title\">" << escape(title) << "</text>";
  if (categories.empty()) return svg.str() + "<text x=\"80\" y=\"120\">not recorded</text></svg>";
  const Axis axis = axisFor(series);
  // Grid and y ticks.
  std::vector<double> ticks;
  if (axis.log) {
    for (double t = axis.lo; t <= axis.hi * 1.0001; t *= 10) ticks.push_back(t);
  } else {
    for (int i = 0; i <= 4; ++i) ticks.push_back(axis.lo + (axis.hi - axis.lo) * i / 4);
  }
  for (const double t : ticks) {
    const double y = kTop + ph * (1 - axis.at(t));
    svg << "<line x1=\"" << kLeft << "\" x2=\"" << kLeft + pw << "\" y1=\"" << y << "\" y2=\"" << y
        << "\" class=\"grid\"/><text x=\"" << kLeft - 6 << "\" y=\"" << y + 4 << "\" class=\"tick\" text-anchor=\"end\">"
        << tickText(t) << "</text>";
  }
  svg << "<text x=\"14\" y=\"" << kTop + ph / 2 << "\" class=\"tick\" transform=\"rotate(-90 14 " << kTop + ph / 2
      << ")\" text-anchor=\"middle\">" << escape(unit) << (axis.log ? " (log)" : "") << "</text>";
  svg << "<line x1=\"" << kLeft << "\" x2=\"" << kLeft << "\" y1=\"" << kTop << "\" y2=\"" << kTop + ph
      << "\" class=\"axis\"/><line x1=\"" << kLeft << "\" x2=\"" << kLeft + pw << "\" y1=\"" << kTop + ph << "\" y2=\""
      << kTop + ph << "\" class=\"axis\"/>";
  const double slot = static_cast<double>(pw) / static_cast<double>(categories.size());
  for (std::size_t c = 0; c < categories.size(); ++c) {
    svg << "<text x=\"" << kLeft + slot * (static_cast<double>(c) + 0.5) << "\" y=\"" << kTop + ph + 16
        << "\" class=\"tick\" text-anchor=\"middle\">" << escape(categories[c]) << "</text>";
  }
  for (std::size_t s = 0; s < series.size(); ++s) {
    const Series& ser = series[s];
    std::string path;
    for (std::size_t c = 0; c < categories.size() && c < ser.values.size(); ++c) {
      const double v = ser.values[c];
      if (std::isnan(v)) continue;
      const double y = kTop + ph * (1 - std::clamp(axis.at(v), 0.0, 1.0));
      if (bars) {
        const double bar = slot * 0.8 / static_cast<double>(series.size());
        const double x = kLeft + slot * static_cast<double>(c) + slot * 0.1 + bar * static_cast<double>(s);
        svg << "<rect x=\"" << x << "\" y=\"" << y << "\" width=\"" << bar * 0.95 << "\" height=\""
            << kTop + ph - y << "\" fill=\"" << ser.colour << "\"><title>" << escape(ser.name) << ": "
            << tickText(v) << "</title></rect>";
      } else {
        const double x = kLeft + slot * (static_cast<double>(c) + 0.5);
        path += (path.empty() ? "M" : " L") + number(x, 1) + " " + number(y, 1);
        svg << "<circle cx=\"" << x << "\" cy=\"" << y << "\" r=\"3.5\" fill=\"" << ser.colour << "\"><title>"
            << escape(ser.name) << ": " << tickText(v) << "</title></circle>";
      }
    }
    if (!bars && !path.empty()) {
      svg << "<path d=\"" << path << "\" fill=\"none\" stroke=\"" << ser.colour << "\" stroke-width=\"2\"/>";
    }
    const int ly = kTop + 10 + static_cast<int>(s) * 18;
    svg << "<rect x=\"" << kLeft + pw + 14 << "\" y=\"" << ly - 9 << "\" width=\"12\" height=\"12\" fill=\""
        << ser.colour << "\"/><text x=\"" << kLeft + pw + 32 << "\" y=\"" << ly + 1 << "\" class=\"tick\">"
        << escape(ser.name) << "</text>";
  }
  svg << "</svg>";
  return svg.str();
}

// Horizontal bars: seconds per stage, with the peak memory at the end of each.
std::string stagePlot(const json& stages) {
  if (!stages.is_array() || stages.empty()) return "<p><i>Stage times not recorded</i> (this report was rebuilt from an output's files).</p>";
  double longest = 1e-9;
  for (const json& s : stages) longest = std::max(longest, numberOr(s, "seconds", 0));
  const int row = 20, label = 230, bar_width = 300;
  const int h = 30 + row * static_cast<int>(stages.size());
  std::ostringstream svg;
  svg << "<svg class=\"plot\" width=\"" << label + bar_width + 190 << "\" height=\"" << h << "\" role=\"img\" "
      << "aria-label=\"time per stage\"><text x=\"0\" y=\"16\" class=\"title\">Time per stage (s) and peak memory</text>";
  int y = 30;
  for (const json& s : stages) {
    const double seconds = numberOr(s, "seconds", 0);
    const double width = std::max(1.0, bar_width * seconds / longest);
    svg << "<text x=\"" << label - 6 << "\" y=\"" << y + 13 << "\" class=\"tick\" text-anchor=\"end\">"
        << escape(s.value("name", std::string("?"))) << "</text><rect x=\"" << label << "\" y=\"" << y + 3
        << "\" width=\"" << width << "\" height=\"" << row - 6 << "\" fill=\"#4c78a8\"/><text x=\"" << label + width + 6
        << "\" y=\"" << y + 13 << "\" class=\"tick\">" << number(seconds, seconds < 10 ? 2 : 1) << " s, "
        << bytesText(numberOr(s, "peak_rss_bytes", 0)) << "</text>";
    y += row;
  }
  svg << "</svg>";
  return svg.str();
}

std::string colourHex(const std::array<std::uint8_t, 3>& c) {
  char buffer[8];
  std::snprintf(buffer, sizeof buffer, "#%02x%02x%02x", c[0], c[1], c[2]);
  return buffer;
}

std::string colourBar(double scale_m) {
  std::ostringstream svg;
  svg << "<svg width=\"260\" height=\"34\" role=\"img\" aria-label=\"error colour scale\">";
  for (int i = 0; i < 50; ++i) {
    svg << "<rect x=\"" << 5 + i * 5 << "\" y=\"2\" width=\"5.5\" height=\"14\" fill=\"" << colourHex(errorColour(i / 49.0))
        << "\"/>";
  }
  svg << "<text x=\"5\" y=\"30\" class=\"tick\">0 m</text><text x=\"255\" y=\"30\" class=\"tick\" text-anchor=\"end\">&#8805; "
      << number(scale_m, scale_m < 10 ? 2 : 1) << " m</text></svg>";
  return svg.str();
}

std::string table(const json& object, const std::vector<std::pair<std::string, std::string>>& rows) {
  std::string out = "<table class=\"facts\">";
  for (const auto& [key, label] : rows) out += "<tr><th>" + escape(label) + "</th><td>" + field(object, key) + "</td></tr>";
  return out + "</table>";
}

constexpr const char* kStyle = R"(
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:24px auto;max-width:1220px;color:#1d2329;padding:0 16px}
h1{font-size:22px;margin:0 0 4px}h2{font-size:17px;margin:28px 0 8px;border-bottom:1px solid #d0d7de;padding-bottom:4px}
.sub{color:#57606a;margin:0 0 12px}.verdict{background:#f6f8fa;border:1px solid #d0d7de;border-radius:6px;padding:10px 14px}
.ok{color:#1a7f37;font-weight:600}.bad{color:#cf222e;font-weight:600}.none{color:#57606a;font-weight:600}
table{border-collapse:collapse;font-variant-numeric:tabular-nums}td,th{padding:3px 10px;white-space:nowrap;border-bottom:1px solid #eaeef2;text-align:right;vertical-align:top}
table.facts th{text-align:left;font-weight:500;color:#57606a}table.facts td{text-align:left;white-space:normal;max-width:520px;overflow-wrap:anywhere}
thead th{background:#f6f8fa;border-bottom:1px solid #d0d7de}.cols{display:flex;flex-wrap:wrap;gap:28px}
svg.plot text{font:11px system-ui,sans-serif;fill:#1d2329}svg text.title{font-weight:600;font-size:12px}
svg .grid{stroke:#eaeef2}svg .axis{stroke:#57606a}svg .tick{font-size:11px;fill:#57606a}
figure{margin:0}figcaption{color:#57606a;font-size:12px;max-width:620px}.map img{image-rendering:pixelated;border:1px solid #d0d7de;max-width:600px}
pre{background:#f6f8fa;border:1px solid #d0d7de;padding:8px;overflow-x:auto;font-size:12px}
@media print{body{margin:0}h2{break-after:avoid}figure,svg{break-inside:avoid}}
)";

}  // namespace

std::array<std::uint8_t, 3> errorColour(double t) {
  // Viridis at nine stops, linearly interpolated.
  static constexpr std::array<std::array<double, 3>, 9> kStops{{{68, 1, 84},
                                                               {71, 44, 122},
                                                               {59, 81, 139},
                                                               {44, 113, 142},
                                                               {33, 144, 141},
                                                               {39, 173, 129},
                                                               {92, 200, 99},
                                                               {170, 220, 50},
                                                               {253, 231, 37}}};
  const double x = std::clamp(std::isnan(t) ? 0.0 : t, 0.0, 1.0) * (kStops.size() - 1);
  const auto i = std::min(static_cast<std::size_t>(x), kStops.size() - 2);
  const double f = x - static_cast<double>(i);
  std::array<std::uint8_t, 3> c{};
  for (int k = 0; k < 3; ++k) {
    c[k] = static_cast<std::uint8_t>(std::lround(kStops[i][k] * (1 - f) + kStops[i + 1][k] * f));
  }
  return c;
}

std::array<std::uint8_t, 3> clusterColour(std::uint32_t cluster) {
  // Hue by the golden angle; saturation and lightness alternate so neighbours in id differ.
  const double hue = std::fmod(static_cast<double>(cluster) * 137.50776405, 360.0);
  const double saturation = cluster % 2 ? 0.55 : 0.75;
  const double lightness = (cluster / 2) % 3 == 0 ? 0.55 : (cluster / 2) % 3 == 1 ? 0.68 : 0.45;
  const double chroma = (1 - std::fabs(2 * lightness - 1)) * saturation;
  const double h = hue / 60;
  const double x = chroma * (1 - std::fabs(std::fmod(h, 2.0) - 1));
  double r = 0, g = 0, b = 0;
  if (h < 1) r = chroma, g = x;
  else if (h < 2) r = x, g = chroma;
  else if (h < 3) g = chroma, b = x;
  else if (h < 4) g = x, b = chroma;
  else if (h < 5) r = x, b = chroma;
  else r = chroma, b = x;
  const double m = lightness - chroma / 2;
  return {static_cast<std::uint8_t>(std::lround((r + m) * 255)), static_cast<std::uint8_t>(std::lround((g + m) * 255)),
          static_cast<std::uint8_t>(std::lround((b + m) * 255))};
}

std::string renderReportHtml(const json& report) {
  if (!report.is_object() || report.value("schema", std::string()) != "terratiles-report/1") {
    throw Error(ErrorCode::Input, "report.json has schema '" +
                                      (report.is_object() ? report.value("schema", std::string("none")) : std::string("none")) +
                                      "'; expected terratiles-report/1");
  }
  const json& input = report.contains("input") ? report["input"] : json::object();
  const json& totals = report.contains("totals") ? report["totals"] : json::object();
  const json& zooms = report.contains("zooms") && report["zooms"].is_array() ? report["zooms"] : json::array();
  const json& check = report.contains("check") ? report["check"] : json();
  std::ostringstream html;
  html << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>terratiles report: "
       << escape(report.value("output_dir", std::string())) << "</title><style>" << kStyle << "</style></head><body>";
  html << "<h1>terratiles build report</h1><p class=\"sub\">" << escape(report.value("generator", std::string()))
       << " &middot; " << escape(report.value("output_dir", std::string())) << "</p>";
  if (report.value("rebuilt_from_files", false)) {
    html << "<p class=\"sub\">Rebuilt by <code>terratiles report</code> from the files of an output written before "
            "reports existed: cluster maps, stage times and per-level errors are not recorded.</p>";
  }

  // Verdict.
  std::string check_text = "<span class=\"none\">check not run</span>";
  if (check.is_object()) {
    check_text = check.value("ok", false) ? "<span class=\"ok\">check ok: seamless, errors honest</span>"
                                          : "<span class=\"bad\">check FAILED (see below)</span>";
  }
  html << "<div class=\"verdict\">" << field(totals, "tiles") << " tiles, " << field(totals, "tile_triangles")
       << " triangles in tiles, " << bytesText(numberOr(totals, "bytes", 0)) << " ("
       << field(totals, "bytes_per_triangle", 2) << " bytes per triangle), worst measured error "
       << field(totals, "worst_error_m", 2) << " m, " << field(totals, "seconds", 1) << " s. " << check_text << "</div>";

  html << "<div class=\"cols\"><div><h2>Input</h2>"
       << table(input, {{"files", "files"},
                        {"crs", "CRS"},
                        {"width", "width (px)"},
                        {"height", "height (px)"},
                        {"pixel_size", "pixel size"},
                        {"valid_pixels", "valid pixels"},
                        {"nodata_share", "nodata share"},
                        {"min_height_m", "lowest (m)"},
                        {"max_height_m", "highest (m)"},
                        {"centre_lat_deg", "centre latitude"},
                        {"centre_lon_deg", "centre longitude"},
                        {"heights", "heights"},
                        {"geoid", "geoid"},
                        {"placement", "placement"},
                        {"warnings", "warnings"}})
       << "</div><div><h2>Options</h2><table class=\"facts\">";
  if (report.contains("options") && report["options"].is_object()) {
    for (const auto& [key, value] : report["options"].items()) {
      html << "<tr><th>" << escape(key) << "</th><td>" << field(report["options"], key, 4) << "</td></tr>";
    }
  }
  html << "</table></div></div>";

  // Per zoom.
  html << "<h2>Zooms</h2><table><thead><tr><th>zoom</th><th>clusters</th><th>tiles</th><th>vertices</th><th>triangles</th>"
          "<th>in tiles</th><th>redundancy</th><th>bytes</th><th>B/tri</th><th>max error (m)</th><th>RMS error (m)</th>"
          "<th>geometricError (m)</th><th>step (mm)</th></tr></thead><tbody>";
  std::vector<std::string> zoom_names;
  Series max_error{"max error", "#e45756", {}}, rms_error{"RMS error", "#4c78a8", {}}, geometric{"geometricError", "#54a24b", {}};
  Series level_triangles{"level triangles", "#9ecae9", {}}, tile_triangles{"tile triangles", "#4c78a8", {}};
  Series bytes{"bytes", "#f58518", {}};
  for (const json& z : zooms) {
    const double tiles_bytes = numberOr(z, "bytes", NAN), in_tiles = numberOr(z, "tile_triangles", NAN);
    html << "<tr><td>" << field(z, "zoom") << "</td><td>" << field(z, "clusters") << "</td><td>" << field(z, "tiles")
         << "</td><td>" << field(z, "vertices") << "</td><td>" << field(z, "triangles") << "</td><td>"
         << field(z, "tile_triangles") << "</td><td>" << field(z, "redundancy", 3) << "</td><td>" << field(z, "bytes")
         << "</td><td>" << (in_tiles > 0 ? number(tiles_bytes / in_tiles, 2) : "&ndash;") << "</td><td>"
         << field(z, "max_error_m") << "</td><td>" << field(z, "rms_error_m") << "</td><td>"
         << field(z, "geometric_error_m") << "</td><td>"
         << (z.contains("position_step_m") ? number(numberOr(z, "position_step_m", 0) * 1000, 1) : "<i>not recorded</i>")
         << "</td></tr>";
    zoom_names.push_back(std::to_string(z.value("zoom", 0)));
    max_error.values.push_back(numberOr(z, "max_error_m", NAN));
    rms_error.values.push_back(numberOr(z, "rms_error_m", NAN));
    geometric.values.push_back(numberOr(z, "geometric_error_m", NAN));
    level_triangles.values.push_back(numberOr(z, "triangles", NAN));
    tile_triangles.values.push_back(in_tiles);
    bytes.values.push_back(tiles_bytes);
  }
  html << "</tbody><tfoot><tr><th>all</th><td></td><td>" << field(totals, "tiles") << "</td><td></td><td>"
       << field(totals, "triangles") << "</td><td>" << field(totals, "tile_triangles") << "</td><td>"
       << field(totals, "redundancy", 3) << "</td><td>" << field(totals, "bytes") << "</td><td>"
       << field(totals, "bytes_per_triangle", 2) << "</td><td>" << field(totals, "worst_error_m")
       << "</td><td></td><td></td><td></td></tr></tfoot></table>";

  html << "<h2>Plots</h2><div class=\"cols\">"
       << plot("Vertical error per zoom", "metres", zoom_names, {max_error, rms_error, geometric}, false)
       << plot("Triangles per zoom", "triangles", zoom_names, {level_triangles, tile_triangles}, true)
       << plot("Bytes per zoom", "bytes", zoom_names, {bytes}, true) << stagePlot(report.value("stages", json::array()))
       << "</div>";

  // The check.
  html << "<h2>Check (<code>terratiles check</code>)</h2>";
  if (!check.is_object()) {
    html << "<p><span class=\"none\">not run</span> (build with <code>--report-check-cuts N</code> or run "
            "<code>terratiles report OUTDIR</code>).</p>";
  } else {
    html << "<p>" << check_text << "</p>"
         << table(check, {{"cuts", "balanced cuts checked"},
                          {"cuts_with_holes", "cuts with holes"},
                          {"hole_pixels", "hole pixels"},
                          {"left_out_pixels", "valid pixels left out (not next to nodata)"},
                          {"neighbour_pairs", "touching tile pairs one zoom apart"},
                          {"missing_border_vertices", "outline vertices missing (T-junctions)"},
                          {"shared_border_vertices", "outline vertices shared by touching tiles"},
                          {"shared_vertex_gaps", "shared vertices decoding apart"},
                          {"worst_shared_vertex_gap_m", "worst gap between shared vertices (m)"},
                          {"measured_pixels", "pixel verticals meeting a decoded triangle"},
                          {"dishonest_errors", "tiles whose decoded error exceeds their geometricError"},
                          {"worst_error_ratio", "worst decoded error / geometricError"},
                          {"overlap_pixels", "of them also drawn at the finer zoom"},
                          {"overlap_disagreements", "tiles differing from the finer zoom by more"},
                          {"worst_overlap_ratio", "worst difference / geometricError"},
                          {"error_order_violations", "errors above their parent's"},
                          {"region_violations", "regions outside their parent's"},
                          {"content_region_violations", "contents outside their region"}});
    if (check.contains("summary") && check["summary"].is_string()) {
      html << "<pre>" << escape(check["summary"].get<std::string>()) << "</pre>";
    }
  }

  // Maps.
  html << "<h2>Maps per zoom</h2>";
  const json& maps = report.contains("maps") && report["maps"].is_array() ? report["maps"] : json::array();
  if (maps.empty()) {
    html << "<p><i>Maps not recorded</i> (only a build draws them: it knows the clusters).</p>";
  } else {
    html << "<p>Left: the clusters the zoom's tiles are made of, each its colour; black lines are cluster borders "
            "(locked while the level was simplified), white lines tile outlines. Right: the largest vertical error "
            "against the DEM in each map pixel (viridis ramp; grey: no data).</p>";
  }
  for (const json& map : maps) {
    const std::string zoom = std::to_string(map.value("zoom", 0));
    html << "<div class=\"cols map\"><figure><img alt=\"clusters of zoom " << zoom << "\" src=\""
         << escape(map.value("clusters_png", std::string())) << "\"><figcaption>zoom " << zoom << ": "
         << field(map, "clusters") << " clusters, " << field(map, "width") << " &times; " << field(map, "height")
         << " px</figcaption></figure><figure><img alt=\"vertical error of zoom " << zoom << "\" src=\""
         << escape(map.value("error_png", std::string())) << "\"><figcaption>zoom " << zoom
         << ": |surface &minus; DEM|" << colourBar(numberOr(map, "error_scale_m", 0)) << "</figcaption></figure></div>";
  }
  html << "</body></html>\n";
  return html.str();
}

}  // namespace terratiles
