// The face dual graph and the partitioners, on real TINs and on small hand-made meshes for
// the error cases.
#include <doctest/doctest.h>

#include <tbb/global_control.h>

#include <algorithm>
#include <set>
#include <thread>

#include "formats/dem/read_dem.h"
#include "src/base/error.h"
#include "src/partition/face_graph.h"
#include "src/partition/partition_faces.h"
#include "src/tin/build_tin.h"
#include "tests/test_support.h"

using namespace terratiles;
using namespace terratiles::test;

namespace {

TinMesh realTin(const std::string& raster, double max_error_m) {
  const DemGrid dem = readDem({sharedData(raster)});
  Progress quiet(ProgressMode::Quiet);
  return buildTin(dem, TinOptions{max_error_m}, quiet);
}


// Faces in one cluster are in one connected component of the mesh.
bool clustersWithinComponents(const FaceGraph& graph, const FacePartition& partition) {
  std::vector<std::int32_t> component;
  faceComponents(graph, component);
  std::vector<std::int32_t> component_of_cluster(static_cast<std::size_t>(partition.cluster_count), -1);
  for (std::size_t t = 0; t < graph.faceCount(); ++t) {
    std::int32_t& c = component_of_cluster[static_cast<std::size_t>(partition.cluster_of_face[t])];
    if (c >= 0 && c != component[t]) return false;
    c = component[t];
  }
  return true;
}

// A regular grid of cols x rows squares, two triangles each, counter-clockwise seen from above
// (row grows south).
TinMesh gridMesh(int cols, int rows) {
  TinMesh mesh;
  for (int r = 0; r <= rows; ++r) {
    for (int c = 0; c <= cols; ++c) mesh.vertices.push_back({static_cast<double>(c), static_cast<double>(r), 0});
  }
  const auto at = [&](int c, int r) { return static_cast<std::uint32_t>(r * (cols + 1) + c); };
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      mesh.triangle_indices.insert(mesh.triangle_indices.end(), {at(c, r), at(c, r + 1), at(c + 1, r)});
      mesh.triangle_indices.insert(mesh.triangle_indices.end(), {at(c + 1, r), at(c, r + 1), at(c + 1, r + 1)});
    }
  }
  return mesh;
}

void checkIdsDense(const FacePartition& partition) {
  std::set<std::int32_t> ids(partition.cluster_of_face.begin(), partition.cluster_of_face.end());
  REQUIRE(!ids.empty());
  CHECK(*ids.begin() == 0);
  CHECK(*ids.rbegin() == partition.cluster_count - 1);
  CHECK(ids.size() == static_cast<std::size_t>(partition.cluster_count));
}

}  // namespace

TEST_SUITE("partition") {

TEST_CASE("the face graph of a real TIN is symmetric and its border is the TIN's outline") {
  const TinMesh tin = realTin("ch_dhm25_interlaken_25m_2056.tif", 2.0);
  const FaceGraph graph = buildFaceGraph(tin);
  REQUIRE(graph.faceCount() == tin.triangleCount());
  std::size_t border_sides = 0;
  for (std::size_t s = 0; s < graph.across.size(); ++s) {
    const std::int32_t other = graph.across[s];
    if (other == kNoFace) {
      ++border_sides;
      continue;
    }
    // Symmetric: the other triangle has a side back to this one, over the same two vertices.
    bool back = false;
    for (std::size_t k = 0; k < 3; ++k) back |= graph.across[3 * static_cast<std::size_t>(other) + k] == static_cast<std::int32_t>(s / 3);
    CHECK(back);
  }
  // The grid TIN's outline runs along the raster's four sides: a closed polygon, so as many
  // border edges as border vertices, and Euler for a disc: V - E + F = 1.
  std::set<std::uint32_t> border_vertices;
  for (std::size_t s = 0; s < graph.across.size(); ++s) {
    if (graph.across[s] == kNoFace) border_vertices.insert(tin.triangle_indices[s]);
  }
  CHECK(border_sides == border_vertices.size());
  const std::size_t edges = (3 * tin.triangleCount() + border_sides) / 2;
  CHECK(static_cast<long>(tin.vertices.size()) - static_cast<long>(edges) + static_cast<long>(tin.triangleCount()) == 1);
  std::vector<std::int32_t> components;
  CHECK(faceComponents(graph, components) == 1);
}

TEST_CASE("METIS clusters are contiguous, dense, deterministic and cut fewer edges than random ones") {
  for (const auto& [raster, max_error] : {std::pair<const char*, double>{"ch_dhm25_interlaken_25m_2056.tif", 1.0},
                                          {"srtm3_N57E011_4326.tif", 10.0}}) {
    CAPTURE(raster);
    const TinMesh tin = realTin(raster, max_error);
    const FaceGraph graph = buildFaceGraph(tin);
    for (const std::int32_t k : {8, 64}) {
      CAPTURE(k);
      const FacePartition metis = partitionFaces(graph, {Partitioner::Metis, k, 7});
      const FacePartition random = partitionFaces(graph, {Partitioner::Random, k, 7});
      CHECK(metis.cluster_count == k);
      CHECK(random.cluster_count == k);
      checkIdsDense(metis);
      checkIdsDense(random);
      CHECK(clustersAreContiguous(graph, metis));
      CHECK(clustersAreContiguous(graph, random));
      CHECK(partitionFaces(graph, {Partitioner::Metis, k, 7}).cluster_of_face == metis.cluster_of_face);
      CHECK(partitionFaces(graph, {Partitioner::Random, k, 7}).cluster_of_face == random.cluster_of_face);
      CHECK(partitionFaces(graph, {Partitioner::Random, k, 8}).cluster_of_face != random.cluster_of_face);
      const std::size_t metis_cut = edgeCut(graph, metis.cluster_of_face);
      const std::size_t random_cut = edgeCut(graph, random.cluster_of_face);
      MESSAGE(std::string(raster) << " k=" << k << ": edge cut METIS " << metis_cut << ", random " << random_cut);
      CHECK(metis_cut < random_cut);
      // Balanced: METIS's default imbalance is 3 %; contiguity may cost a little more.
      std::vector<std::size_t> sizes(static_cast<std::size_t>(k), 0);
      for (const std::int32_t c : metis.cluster_of_face) ++sizes[static_cast<std::size_t>(c)];
      CHECK(*std::max_element(sizes.begin(), sizes.end()) <= graph.faceCount() / static_cast<std::size_t>(k) * 12 / 10);
    }
  }
}

TEST_CASE("clusters never span two components, and every component gets one") {
  // Two separate quads (two triangles each) and a lone triangle.
  TinMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {5, 0, 0}, {6, 0, 0}, {6, 1, 0}, {5, 1, 0},
                   {9, 0, 0}, {10, 0, 0}, {9, 1, 0}};
  mesh.triangle_indices = {0, 2, 1, 0, 3, 2, 4, 6, 5, 4, 7, 6, 8, 10, 9};
  const FaceGraph graph = buildFaceGraph(mesh);
  std::vector<std::int32_t> components;
  REQUIRE(faceComponents(graph, components) == 3);
  for (const Partitioner method : {Partitioner::Metis, Partitioner::Random}) {
    const FacePartition partition = partitionFaces(graph, {method, 1, 1});
    CHECK(partition.cluster_count == 3);
    CHECK(partition.cluster_of_face[0] == partition.cluster_of_face[1]);
    CHECK(partition.cluster_of_face[2] == partition.cluster_of_face[3]);
    CHECK(partition.cluster_of_face[0] != partition.cluster_of_face[2]);
    CHECK(partition.cluster_of_face[4] != partition.cluster_of_face[2]);
  }
}

TEST_CASE("a non-manifold or inconsistently oriented mesh is refused with the edge named") {
  TinMesh fan;
  fan.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {-1, 0, 0}};
  fan.triangle_indices = {0, 1, 2, 1, 0, 3, 0, 1, 4};  // edge 0-1 in three triangles
  CHECK_THROWS_WITH_AS(buildFaceGraph(fan), doctest::Contains("edge 0-1 is shared by 3 triangles"), Error);
  TinMesh flipped;
  flipped.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  flipped.triangle_indices = {0, 1, 2, 2, 1, 3};  // consistent: accepted
  CHECK_NOTHROW(buildFaceGraph(flipped));
  flipped.triangle_indices = {0, 1, 2, 1, 2, 3};  // both run 1->2
  CHECK_THROWS_WITH_AS(buildFaceGraph(flipped), doctest::Contains("same direction"), Error);
  flipped.triangle_indices = {0, 1, 1};
  CHECK_THROWS_WITH_AS(buildFaceGraph(flipped), doctest::Contains("repeats vertex"), Error);
  fan.triangle_indices = {0, 1, 2};
  CHECK_THROWS_AS(partitionFaces(buildFaceGraph(fan), {Partitioner::Metis, 0, 1}), Error);
}

TEST_CASE("the face graph of a real TIN does not depend on the thread count") {
  const TinMesh tin = realTin("srtm3_N57E011_4326.tif", 5.0);
  FaceGraph one, two;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    one = buildFaceGraph(tin);
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    two = buildFaceGraph(tin);
  }
  CHECK(one.across == two.across);
  CHECK(one.offsets == two.offsets);
  CHECK(one.neighbours == two.neighbours);
  // A graph reused for a smaller mesh holds that mesh's graph only.
  FaceGraph reused = one;
  const TinMesh small = gridMesh(3, 2);
  buildFaceGraph(small, reused);
  const FaceGraph fresh = buildFaceGraph(small);
  CHECK(reused.across == fresh.across);
  CHECK(reused.offsets == fresh.offsets);
  CHECK(reused.neighbours == fresh.neighbours);
}

TEST_CASE("METIS draws its random numbers per thread so concurrent calls agree with one call") {
  REQUIRE(detail::metisRandomIsPerThread());
  const TinMesh tin = realTin("ch_dhm25_interlaken_25m_2056.tif", 2.0);
  const FaceGraph graph = buildFaceGraph(tin);
  const FacePartition alone = partitionFaces(graph, {Partitioner::Metis, 64, 3});
  // Two threads partition the same graph at the same time, several times: glibc's one rand()
  // state would interleave their draws.
  std::vector<FacePartition> results(4);
  std::thread first([&] { results[0] = partitionFaces(graph, {Partitioner::Metis, 64, 3}); results[1] = partitionFaces(graph, {Partitioner::Metis, 64, 3}); });
  std::thread second([&] { results[2] = partitionFaces(graph, {Partitioner::Metis, 64, 3}); results[3] = partitionFaces(graph, {Partitioner::Metis, 64, 3}); });
  first.join();
  second.join();
  for (const FacePartition& result : results) CHECK(result.cluster_of_face == alone.cluster_of_face);
}

TEST_CASE("regional METIS clusters on real TINs are contiguous dense deterministic and cut about as few edges as global ones") {
  for (const auto& [raster, max_error] : {std::pair<const char*, double>{"ch_dhm25_interlaken_25m_2056.tif", 1.0},
                                          {"srtm3_N57E011_4326.tif", 5.0}}) {
    CAPTURE(std::string(raster));
    const TinMesh tin = realTin(raster, max_error);
    const FaceGraph graph = buildFaceGraph(tin);
    const std::int32_t clusters = static_cast<std::int32_t>(tin.triangleCount() / 512);
    // Square cells of about 64 clusters each.
    double width = 0, height = 0;
    for (const GridPoint& v : tin.vertices) {
      width = std::max(width, v.col);
      height = std::max(height, v.row);
    }
    const double cell_px = std::sqrt(width * height * 64 / clusters);
    const std::vector<std::int32_t> regions = gridCellRegions(tin, cell_px, {0, 0});
    const FacePartition regional = partitionFaces(graph, {Partitioner::Metis, clusters, 7}, regions);
    const FacePartition global = partitionFaces(graph, {Partitioner::Metis, clusters, 7});
    const FacePartition random = partitionFaces(graph, {Partitioner::Random, clusters, 7}, regions);
    checkIdsDense(regional);
    checkIdsDense(random);
    CHECK(clustersAreContiguous(graph, regional));
    CHECK(clustersAreContiguous(graph, random));
    CHECK(clustersWithinComponents(graph, regional));
    CHECK(std::abs(regional.cluster_count - clusters) <= clusters / 20);
    CHECK(partitionFaces(graph, {Partitioner::Metis, clusters, 7}, regions).cluster_of_face == regional.cluster_of_face);
    const std::size_t regional_cut = edgeCut(graph, regional.cluster_of_face);
    const std::size_t global_cut = edgeCut(graph, global.cluster_of_face);
    const std::size_t random_cut = edgeCut(graph, random.cluster_of_face);
    MESSAGE(std::string(raster) << " " << clusters << " clusters: edge cut regional " << regional_cut << ", global " << global_cut
                   << ", random " << random_cut);
    CHECK(regional_cut < random_cut);
    CHECK(static_cast<double>(regional_cut) <= 1.15 * static_cast<double>(global_cut));
    // Balanced within 60 %: a piece gets a whole number of clusters (a cell of 1.49 clusters'
    // faces gets one), plus METIS's 3 % and the fragments it takes in.
    std::vector<std::size_t> sizes(static_cast<std::size_t>(regional.cluster_count), 0);
    for (const std::int32_t c : regional.cluster_of_face) ++sizes[static_cast<std::size_t>(c)];
    CHECK(*std::max_element(sizes.begin(), sizes.end()) <= graph.faceCount() / static_cast<std::size_t>(regional.cluster_count) * 8 / 5);
  }
}

TEST_CASE("the regional partition does not depend on the thread count") {
  const TinMesh tin = realTin("srtm3_N57E011_4326.tif", 5.0);
  const FaceGraph graph = buildFaceGraph(tin);
  const std::vector<std::int32_t> regions = gridCellRegions(tin, 150, {0, 0});
  const auto partitionWith = [&](std::size_t threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    return partitionFaces(graph, {Partitioner::Metis, static_cast<std::int32_t>(tin.triangleCount() / 600), 1}, regions);
  };
  const FacePartition one = partitionWith(1);
  CHECK(one.cluster_count > 64);
  for (int run = 0; run < 3; ++run) CHECK(partitionWith(2).cluster_of_face == one.cluster_of_face);
}

TEST_CASE("a region's fragment joins a neighbouring cluster and regions never merge components") {
  // A 20 x 10 grid split into a left and a right region, with one triangle of the left region
  // inside the right one, and a separate quad as a second component in the left region.
  TinMesh mesh = gridMesh(20, 10);
  const std::size_t grid_faces = mesh.triangleCount();
  const auto base = static_cast<std::uint32_t>(mesh.vertices.size());
  mesh.vertices.insert(mesh.vertices.end(), {{40, 0, 0}, {41, 0, 0}, {40, 1, 0}, {41, 1, 0}});
  mesh.triangle_indices.insert(mesh.triangle_indices.end(), {base, base + 2, base + 1, base + 1, base + 2, base + 3});
  const FaceGraph graph = buildFaceGraph(mesh);
  std::vector<std::int32_t> regions(mesh.triangleCount());
  for (std::size_t t = 0; t < grid_faces; ++t) regions[t] = (t / 2) % 20 < 10 ? 5 : 9;  // any region values
  const std::size_t stray = 2 * (4 * 20 + 15);  // a triangle in the right half
  regions[stray] = 5;
  regions[grid_faces] = regions[grid_faces + 1] = 5;
  const FacePartition partition = partitionFaces(graph, {Partitioner::Metis, 8, 1}, regions);
  checkIdsDense(partition);
  CHECK(clustersAreContiguous(graph, partition));
  CHECK(clustersWithinComponents(graph, partition));
  // The stray triangle is in a cluster of the right half; the quad is a cluster of its own.
  std::set<std::int32_t> left, right;
  for (std::size_t t = 0; t < grid_faces; ++t) {
    if (t == stray) continue;
    ((t / 2) % 20 < 10 ? left : right).insert(partition.cluster_of_face[t]);
  }
  for (const std::int32_t c : left) CHECK(right.count(c) == 0);  // the region border is a cluster border
  CHECK(right.count(partition.cluster_of_face[stray]) == 1);
  CHECK(partition.cluster_of_face[grid_faces] == partition.cluster_of_face[grid_faces + 1]);
  CHECK(left.count(partition.cluster_of_face[grid_faces]) == 0);
  CHECK(right.count(partition.cluster_of_face[grid_faces]) == 0);
}

TEST_CASE("partition regions of the wrong size or below zero are usage errors") {
  const TinMesh mesh = gridMesh(4, 4);
  const FaceGraph graph = buildFaceGraph(mesh);
  std::vector<std::int32_t> regions(mesh.triangleCount() - 1, 0);
  CHECK_THROWS_WITH_AS(partitionFaces(graph, {Partitioner::Metis, 2, 1}, regions),
                       doctest::Contains("partition regions are given for 31 faces; expected one per face (32)"), Error);
  regions.assign(mesh.triangleCount(), 0);
  regions[7] = -2;
  CHECK_THROWS_WITH_AS(partitionFaces(graph, {Partitioner::Metis, 2, 1}, regions),
                       doctest::Contains("partition region of face 7 is -2"), Error);
  CHECK_THROWS_WITH_AS(gridCellRegions(mesh, 0, {0, 0}), doctest::Contains("expected a width > 0"), Error);
}

TEST_CASE("grid cell regions hold each face by its centroid") {
  const TinMesh mesh = gridMesh(12, 8);
  const std::vector<std::int32_t> regions = gridCellRegions(mesh, 4, {-2, 0});
  REQUIRE(regions.size() == mesh.triangleCount());
  std::set<std::int32_t> distinct(regions.begin(), regions.end());
  CHECK(distinct.size() == 4 * 2);  // columns -2..2, 2..6, 6..10, 10..14; rows 0..4, 4..8
  CHECK(*distinct.begin() == 0);
  CHECK(*distinct.rbegin() == 7);
  for (std::size_t a = 0; a < mesh.triangleCount(); ++a) {
    for (std::size_t b = a + 1; b < mesh.triangleCount(); b += 7) {
      const auto cell = [&](std::size_t t) {
        double col = 0, row = 0;
        for (std::size_t k = 0; k < 3; ++k) {
          col += mesh.vertices[mesh.triangle_indices[3 * t + k]].col / 3;
          row += mesh.vertices[mesh.triangle_indices[3 * t + k]].row / 3;
        }
        return std::pair{std::floor((col + 2) / 4), std::floor(row / 4)};
      };
      CHECK((regions[a] == regions[b]) == (cell(a) == cell(b)));
    }
  }
}

}  // TEST_SUITE
