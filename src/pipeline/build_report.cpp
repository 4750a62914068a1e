#include "src/pipeline/build_report.h"

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "formats/dem/read_dem.h"
#include "formats/gltf/read_glb.h"
#include "formats/image/png_image.h"
#include "src/base/error.h"
#include "src/pipeline/report_html.h"
#include "tileset/implicit_tileset.h"
#include "tileset/read_tileset.h"

namespace terratiles {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const char* lodName(LodMethod lod) { return lod == LodMethod::Grid ? "grid" : "clusters"; }

json optionsJson(const BuildOptions& o) {
  json j;
  j["lod"] = lodName(o.lod);
  j["scheme"] = o.lod == LodMethod::Grid ? std::string("local pixels") : std::string(tileSchemeName(o.scheme));
  j["assign"] = std::string(assignmentName(o.assignment));
  j["tin_max_error_m"] = o.tin_max_error_m;
  j["tile_triangles"] = o.tile_triangles;
  j["clusters_per_tile"] = o.clusters_per_tile;
  j["join_tile_clusters"] = o.join_tile_clusters;
  j["level_ratio"] = o.level_ratio;
  j["simplifier"] = simplifierName(o.simplifier);
  j["tail_stop"] = tailStopName(o.tail_stop);
  j["level_error_growth"] = o.level_error_growth;
  j["constraints"] = o.constraints.empty() ? std::string("none") : fs::absolute(o.constraints).string();
  if (o.lod == LodMethod::Grid) j["tile_cells"] = o.tile_cells;
  j["max_zoom"] = o.max_zoom < 0 ? std::string("from the data") : std::to_string(o.max_zoom);
  j["heights"] = o.heights == HeightReference::Orthometric ? "orthometric" : "ellipsoidal";
  j["draco"] = o.draco;
  j["position_step_m"] = o.position_step_m;
  if (o.draco_position_bits > 0) j["draco_position_bits"] = o.draco_position_bits;
  j["draco_speed"] = o.draco_speed;
  j["draco_normal_bits"] = o.draco_normal_bits;
  j["implicit"] = o.implicit_tiling;
  if (o.implicit_tiling) j["subtree_levels"] = o.subtree_levels;
  j["report_check_cuts"] = o.report_check_cuts;
  return j;
}

json mapsJson(const std::vector<ZoomMaps>& maps) {
  json out = json::array();
  for (const ZoomMaps& m : maps) {
    out.push_back({{"zoom", m.zoom},
                   {"width", m.width},
                   {"height", m.height},
                   {"clusters", m.cluster_count},
                   {"error_scale_m", m.error_scale_m},
                   {"clusters_png", dataUri(m.clusters_png, "image/png")},
                   {"error_png", dataUri(m.error_png, "image/png")}});
  }
  return out;
}

json readJsonFile(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw Error(ErrorCode::Input, path.string() + " cannot be read");
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    throw Error(ErrorCode::Input, path.string() + " is not valid JSON (" + e.what() + ")");
  }
}

// The tiles of an output on disk, per zoom: count, bytes, decoded triangles and vertices,
// the largest geometricError (for outputs without report.json).
json zoomsFromDisk(const fs::path& dir, const json& root, Progress& progress) {
  struct ZoomFacts {
    std::size_t tiles = 0, bytes = 0, triangles = 0, vertices = 0;
    double geometric_error_m = 0;
  };
  std::map<int, ZoomFacts> zooms;
  std::vector<const json*> open{&root};
  std::vector<std::pair<std::string, double>> contents;
  while (!open.empty()) {
    const json* node = open.back();
    open.pop_back();
    if (node->contains("content")) contents.emplace_back((*node)["content"].at("uri").get<std::string>(),
                                                         node->at("geometricError").get<double>());
    if (node->contains("children")) {
      for (const json& child : (*node)["children"]) open.push_back(&child);
    }
  }
  progress.beginStage("reading tiles", contents.size());
  for (const auto& [uri, error] : contents) {
    TileKey key;
    if (!tileKeyFromContentUri(uri, key)) {
      throw Error(ErrorCode::Input, (dir / uri).string() + " is not named tiles/z/x/y.glb; expected a terratiles output");
    }
    std::ifstream in(dir / uri, std::ios::binary);
    if (!in) throw Error(ErrorCode::Input, (dir / uri).string() + " is missing; the output is incomplete (rebuild it)");
    const std::vector<std::uint8_t> bytes{std::istreambuf_iterator<char>(in), {}};
    const DecodedGlb decoded = decodeGlb(bytes, (dir / uri).string());
    ZoomFacts& z = zooms[key.zoom];
    ++z.tiles;
    z.bytes += bytes.size();
    z.triangles += decoded.mesh.triangle_indices.size() / 3;
    z.vertices += decoded.mesh.vertexCount();
    z.geometric_error_m = std::max(z.geometric_error_m, error);
    progress.advance();
  }
  progress.endStage();
  json out = json::array();
  for (const auto& [zoom, z] : zooms) {
    out.push_back({{"zoom", zoom},
                   {"tiles", z.tiles},
                   {"bytes", z.bytes},
                   {"tile_triangles", z.triangles},
                   {"tile_vertices", z.vertices},
                   {"geometric_error_m", z.geometric_error_m}});
  }
  return out;
}

// A report for an output written before reports existed: what its files tell.
json reportFromDisk(const fs::path& dir, Progress& progress) {
  if (!fs::exists(dir / "tileset.json")) {
    throw Error(ErrorCode::Input, (dir / "tileset.json").string() +
                                      " is missing; expected a terratiles output directory (terratiles build -o DIR)");
  }
  if (!fs::exists(dir / "build.json")) {
    throw Error(ErrorCode::Input, dir.string() +
                                      " has no build.json: it was written by a terratiles older than build records, "
                                      "so its source DEM is unknown; rebuild it with `terratiles build` to get a report");
  }
  const json build = readJsonFile(dir / "build.json");
  const json tileset = readTilesetTree(dir / "tileset.json");
  json report;
  report["schema"] = kReportSchema;
  report["generator"] = build.value("generator", std::string("terratiles (unknown version)"));
  report["output_dir"] = fs::absolute(dir).string();
  report["rebuilt_from_files"] = true;
  json options;
  for (const char* key : {"lod", "scheme", "assign", "tin_max_error_m", "heights", "tiling"}) {
    if (build.contains(key)) options[key] = build[key];
  }
  report["options"] = options;

  const std::vector<std::string> inputs = build.at("inputs").get<std::vector<std::string>>();
  const DemGrid dem = readDem(inputs, "reading the DEM", progress);
  progress.endStage();
  const DemStatistics stats = computeStatistics(dem);
  report["input"] = {{"files", inputs},
                     {"crs", build.value("crs", dem.crs_name)},
                     {"width", dem.width},
                     {"height", dem.height},
                     {"pixel_size", dem.pixel_size_x},
                     {"valid_pixels", stats.valid_pixels},
                     {"nodata_share", 1.0 - static_cast<double>(stats.valid_pixels) / static_cast<double>(dem.pixelCount())},
                     {"min_height_m", stats.min_height_m},
                     {"max_height_m", stats.max_height_m},
                     {"heights", build.value("heights", std::string("orthometric"))},
                     {"geoid", build.value("geoid", std::string())}};
  const json& root = build.contains("explicit_tileset") ? build["explicit_tileset"].at("root") : tileset.at("root");
  report["zooms"] = zoomsFromDisk(dir, root, progress);
  json totals = {{"tiles", 0}, {"tile_triangles", 0}, {"bytes", 0}};
  std::size_t tiles = 0, triangles = 0, bytes = 0;
  for (const json& z : report["zooms"]) {
    tiles += z["tiles"].get<std::size_t>();
    triangles += z["tile_triangles"].get<std::size_t>();
    bytes += z["bytes"].get<std::size_t>();
  }
  report["totals"] = {{"tiles", tiles},
                      {"tile_triangles", triangles},
                      {"bytes", bytes},
                      {"bytes_per_triangle", triangles ? static_cast<double>(bytes) / static_cast<double>(triangles) : 0.0}};
  report["stages"] = json::array();
  report["maps"] = json::array();
  report["check"] = nullptr;
  return report;
}

}  // namespace

json checkReportJson(const CheckReport& r) {
  return {{"ok", r.ok()},
          {"tiles", r.tiles},
          {"zooms", r.zooms},
          {"footprint_pixels", r.footprint_pixels},
          {"uncovered_valid_pixels", r.uncovered_valid_pixels},
          {"left_out_pixels", r.left_out_pixels},
          {"pole_vertices", r.pole_vertices},
          {"cuts", r.cuts},
          {"cuts_with_holes", r.cuts_with_holes},
          {"hole_pixels", r.hole_pixels},
          {"unbalanced_cuts", r.unbalanced_cuts},
          {"unbalanced_cuts_with_holes", r.unbalanced_cuts_with_holes},
          {"neighbour_pairs", r.neighbour_pairs},
          {"missing_border_vertices", r.missing_border_vertices},
          {"moved_outline_vertices", r.moved_outline_vertices},
          {"shared_border_vertices", r.shared_border_vertices},
          {"shared_vertex_gaps", r.shared_vertex_gaps},
          {"worst_shared_vertex_gap_m", r.worst_shared_vertex_gap_m},
          {"measured_pixels", r.measured_pixels},
          {"overlap_pixels", r.overlap_pixels},
          {"overlap_disagreements", r.overlap_disagreements},
          {"worst_overlap_ratio", r.worst_overlap_ratio},
          {"dishonest_errors", r.dishonest_errors},
          {"worst_error_ratio", r.worst_error_ratio},
          {"error_order_violations", r.error_order_violations},
          {"region_violations", r.region_violations},
          {"content_region_violations", r.content_region_violations},
          {"problems", r.problems},
          {"summary", describeCheck(r)}};
}

json buildReportJson(const BuildOptions& options, const BuildSummary& s, const std::vector<StageRecord>& stages,
                     const std::optional<CheckReport>& check, const std::vector<ZoomMaps>& maps) {
  json report;
  report["schema"] = kReportSchema;
  report["generator"] = s.generator;
  report["output_dir"] = fs::absolute(s.output_dir).string();
  report["options"] = optionsJson(options);
  std::vector<std::string> files;
  for (const std::string& input : options.inputs) files.push_back(fs::absolute(input).lexically_normal().string());
  const double pixels = static_cast<double>(s.width) * static_cast<double>(s.height);
  report["input"] = {{"files", files},
                     {"crs", s.crs_name},
                     {"width", s.width},
                     {"height", s.height},
                     {"pixel_size", s.pixel_size},
                     {"valid_pixels", s.valid_pixels},
                     {"nodata_share", pixels > 0 ? 1.0 - static_cast<double>(s.valid_pixels) / pixels : 0.0},
                     {"min_height_m", s.min_height_m},
                     {"max_height_m", s.max_height_m},
                     {"centre_lon_deg", s.centre_lon_deg},
                     {"centre_lat_deg", s.centre_lat_deg},
                     {"placement", s.placement},
                     {"heights", options.heights == HeightReference::Orthometric ? "orthometric" : "ellipsoidal"},
                     {"geoid", s.geoid},
                     {"warnings", s.warnings}};
  json zooms = json::array();
  std::size_t tile_triangles = 0;
  for (const ZoomSummary& z : s.zooms) {
    tile_triangles += z.tile_triangles;
    zooms.push_back({{"zoom", z.zoom},
                     {"clusters", z.clusters},
                     {"tiles", z.tiles},
                     {"vertices", z.vertices},
                     {"triangles", z.triangles},
                     {"tile_triangles", z.tile_triangles},
                     {"redundancy", z.triangles ? static_cast<double>(z.tile_triangles) / static_cast<double>(z.triangles) : 0.0},
                     {"bytes", z.bytes},
                     {"max_error_m", z.max_error_m},
                     {"rms_error_m", z.rms_error_m},
                     {"geometric_error_m", z.geometric_error_m},
                     {"position_step_m", z.position_step_m}});
  }
  report["zooms"] = zooms;
  report["totals"] = {{"tiles", s.tiles},
                      {"triangles", s.triangles},
                      {"tile_triangles", tile_triangles},
                      {"bytes", s.tile_bytes},
                      {"bytes_per_triangle", tile_triangles ? static_cast<double>(s.tile_bytes) / static_cast<double>(tile_triangles) : 0.0},
                      {"redundancy", s.triangles ? static_cast<double>(tile_triangles) / static_cast<double>(s.triangles) : 0.0},
                      {"worst_error_m", s.worst_error_m},
                      {"seconds", s.seconds}};
  json stage_list = json::array();
  for (const StageRecord& stage : stages) {
    stage_list.push_back({{"name", stage.name}, {"seconds", stage.seconds}, {"peak_rss_bytes", stage.peak_rss_bytes}});
  }
  report["stages"] = stage_list;
  report["check"] = check ? checkReportJson(*check) : json(nullptr);
  report["maps"] = mapsJson(maps);
  return report;
}

void writeFileAtomically(const std::string& path, const std::string& text) {
  const std::string temporary = path + ".tmp";
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out << text;
    out.close();
    if (!out) {
      std::error_code ignored;
      fs::remove(temporary, ignored);
      throw Error(ErrorCode::Output, temporary + " cannot be written; check the disk space and permissions");
    }
  }
  std::error_code error;
  fs::rename(temporary, path, error);
  if (error) {
    fs::remove(temporary, error);
    throw Error(ErrorCode::Output, path + " cannot be replaced (" + error.message() + ")");
  }
}

RegeneratedReport regenerateReport(const std::string& output_dir, const ReportOptions& options, Progress& progress) {
  const fs::path dir(output_dir);
  RegeneratedReport result;
  if (fs::exists(dir / "report.json")) {
    try {
      result.report = readJsonFile(dir / "report.json");
    } catch (const Error& e) {
      throw Error(ErrorCode::Input, std::string(e.what()) + "; delete it to rebuild the report from the output's files");
    }
    if (result.report.value("schema", std::string()) != kReportSchema) {
      throw Error(ErrorCode::Input, (dir / "report.json").string() + " has schema '" +
                                        result.report.value("schema", std::string("none")) + "'; expected " +
                                        kReportSchema + " (delete it to rebuild the report from the files)");
    }
    result.from_build_record = true;
  } else {
    result.report = reportFromDisk(dir, progress);
  }
  if (options.check_cuts > 0) {
    CheckOptions check;
    check.cuts = options.check_cuts;
    result.report["check"] = checkReportJson(checkOutput(output_dir, check, progress));
  }
  writeFileAtomically((dir / "report.json").string(), result.report.dump(1) + "\n");
  result.html_path = (dir / "report.html").string();
  writeFileAtomically(result.html_path, renderReportHtml(result.report));
  return result;
}

}  // namespace terratiles
