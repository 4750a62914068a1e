// The face dual graph and the partitioners, on real TINs and on small hand-made meshes for
// the error cases.
#include <doctest/doctest.h>

#include <algorithm>
#include <set>

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

// Faces of each cluster form one connected piece through shared edges.
bool clustersContiguous(const FaceGraph& graph, const FacePartition& partition) {
  std::vector<std::uint8_t> seen(graph.faceCount(), 0);
  std::vector<std::uint8_t> cluster_started(static_cast<std::size_t>(partition.cluster_count), 0);
  for (std::size_t start = 0; start < graph.faceCount(); ++start) {
    if (seen[start]) continue;
    const std::int32_t cluster = partition.cluster_of_face[start];
    if (cluster_started[static_cast<std::size_t>(cluster)]) return false;  // a second piece
    cluster_started[static_cast<std::size_t>(cluster)] = 1;
    std::vector<std::size_t> stack{start};
    seen[start] = 1;
    while (!stack.empty()) {
      const std::size_t t = stack.back();
      stack.pop_back();
      for (std::int32_t n = graph.offsets[t]; n < graph.offsets[t + 1]; ++n) {
        const auto other = static_cast<std::size_t>(graph.neighbours[static_cast<std::size_t>(n)]);
        if (!seen[other] && partition.cluster_of_face[other] == cluster) {
          seen[other] = 1;
          stack.push_back(other);
        }
      }
    }
  }
  return true;
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
      CHECK(clustersContiguous(graph, metis));
      CHECK(clustersContiguous(graph, random));
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

}  // TEST_SUITE
