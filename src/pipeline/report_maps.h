#pragma once
// Pictures of one zoom for the build report, like the paper's figures: a map of the clusters
// the zoom's tiles are made of (each its colour, cluster borders black: the edges that stayed
// locked, tile outlines white) and a map of the vertical error against the DEM (of the tiles
// as decoded and drawn), both on the
// DEM's grid reduced to at most `max_side_px` pixels a side (a map pixel shows the cluster
// at its centre and the largest error in its block, in ten classes of a tenth of the scale).

#include <cstdint>

#include "formats/image/png_image.h"
#include "src/dem/dem_grid.h"
#include "src/partition/partition_faces.h"
#include "src/pipeline/drawn_tiles.h"
#include "src/tiling/assign_clusters.h"
#include "src/tin/tin_mesh.h"

namespace terratiles {

// The two maps as PNG files, each encoded as soon as it is drawn (a zoom's raw pixels would
// otherwise wait beside the build's largest stages until the report is written).
struct ZoomMaps {
  std::int32_t zoom = 0;
  int width = 0, height = 0, scale = 1;  // the maps' pixels, and the DEM pixels a side of one covers
  std::vector<std::uint8_t> clusters_png;
  std::vector<std::uint8_t> error_png;
  double error_scale_m = 0;  // the error drawn in the ramp's last colour
  std::int32_t cluster_count = 0;
};

// The cluster map's content, taken from a zoom's mesh and partition as soon as its tiles are
// assigned, so that the partition (4 bytes per face of every level) need not wait for the
// error map: per map pixel, the cluster of the mesh's face covering its centre (the face
// with the largest index), -1 where none does, 0 where one does and `partition` is nullptr
// (then faces are coloured by tile).
struct ClusterMap {
  int width = 0, height = 0, scale = 1;  // the map's pixels, and the DEM pixels a side of one covers
  std::vector<std::int32_t> cluster;     // per map pixel, row by row
  std::int32_t cluster_count = 0;
  bool by_cluster = false;  // false: coloured by tile
};
ClusterMap mapClusters(const DemGrid& dem, const TinMesh& mesh, const FacePartition* partition, int max_side_px = 640);

// The cluster map of a zoom (error_png still empty). frame: draws the zoom's tile outlines
// (nullptr: none).
ZoomMaps drawClusterMap(const DemGrid& dem, const ClusterMap& clusters, const TileFrame* frame, std::int32_t zoom);
// Adds the error map: surface is the zoom's drawn surface (its tiles as decoded, measured
// along every pixel's vertical).
void drawErrorMap(const DemGrid& dem, double error_scale_m, const ZoomSurface& surface, ZoomMaps& maps);

}  // namespace terratiles
