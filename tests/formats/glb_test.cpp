#include <doctest/doctest.h>

#include <dlfcn.h>

#include <cmath>
#include <cstdint>
#include <set>

#include "formats/dem/read_dem.h"
#include "formats/gltf/read_glb.h"
#include "formats/gltf/write_glb.h"
#include "src/base/error.h"
#include "tests/test_support.h"

namespace draco {
std::int64_t ComputeShannonEntropy(const std::uint32_t* symbols, int num_symbols, int max_value,
                                   int* out_num_unique_symbols);
}

using namespace terratiles;

namespace {
// A small terrain-like patch of n x n vertices, translated far from the origin as ECEF is.
GlbMesh patch(int n, std::array<double, 3> translation) {
  GlbMesh mesh;
  mesh.translation = translation;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      mesh.positions.insert(mesh.positions.end(),
                            {i * 25.0f, static_cast<float>(std::sin(i * 0.3) * 40.0), j * -25.0f});
      mesh.normals.insert(mesh.normals.end(), {0.0f, 1.0f, 0.0f});
    }
  }
  for (int j = 0; j + 1 < n; ++j) {
    for (int i = 0; i + 1 < n; ++i) {
      const std::uint32_t a = j * n + i, b = a + 1, c = a + n, d = c + 1;
      mesh.triangle_indices.insert(mesh.triangle_indices.end(), {a, b, d, a, d, c});
    }
  }
  return mesh;
}
}  // namespace

TEST_SUITE("formats") {
  TEST_CASE("a Draco GLB decodes to the same triangles within half a quantisation step") {
    const GlbMesh mesh = patch(20, {4325000.0, 4638000.0, -564000.0});
    GlbOptions options;
    const EncodedGlb encoded = encodeGlb(mesh, options);
    CHECK(encoded.position_step_m == options.position_step_m);
    const std::vector<std::uint8_t>& bytes = encoded.bytes;
    const DecodedGlb decoded = decodeGlb(bytes, "patch.glb");
    CHECK(decoded.draco);
    CHECK(decoded.json.find("\"extensionsRequired\":[\"KHR_draco_mesh_compression\"]") !=
          std::string::npos);
    CHECK(decoded.mesh.translation == mesh.translation);
    REQUIRE(decoded.mesh.triangle_indices.size() == mesh.triangle_indices.size());
    // Draco reorders vertices: compare triangles as position triples.
    std::multiset<std::array<long, 9>> expected, found;
    auto key = [&](const GlbMesh& m, std::size_t t) {
      std::array<long, 9> k{};
      for (int c = 0; c < 3; ++c) {
        for (int a = 0; a < 3; ++a) {
          k[3 * c + a] = std::lround(m.positions[3 * m.triangle_indices[t + c] + a] / options.position_step_m);
        }
      }
      // Rotate so the smallest corner comes first (Draco may rotate a face's corners).
      std::array<long, 9> best = k;
      for (int r = 1; r < 3; ++r) {
        std::array<long, 9> rotated{};
        for (int i = 0; i < 9; ++i) rotated[i] = k[(i + 3 * r) % 9];
        best = std::min(best, rotated);
      }
      return best;
    };
    for (std::size_t t = 0; t < mesh.triangle_indices.size(); t += 3) expected.insert(key(mesh, t));
    for (std::size_t t = 0; t < decoded.mesh.triangle_indices.size(); t += 3) {
      found.insert(key(decoded.mesh, t));
    }
    CHECK(found == expected);
    double worst = 0;
    for (std::size_t v = 0; v < decoded.mesh.positions.size(); ++v) {
      const double q = decoded.mesh.positions[v] / options.position_step_m;
      worst = std::max(worst, std::fabs(q - std::round(q)));  // on the shared grid
    }
    CHECK(worst < 1e-3);
  }

  TEST_CASE("a vertex shared by two tiles decodes to one position in both") {
    // Two tiles with different translations (both on the quantisation grid) hold the same
    // absolute point; after Draco both must give it back bit for bit.
    const double step = 1.0 / 128;
    const std::array<double, 3> a_origin{4325000.0, 4638000.0, -564000.0};
    const std::array<double, 3> b_origin{4325000.0 + 1000 * step * 128, 4638000.0, -564000.0 + 7.5};
    const std::array<double, 3> shared{4325433.123, 4638021.987, -564100.456};
    GlbMesh a = patch(3, a_origin), b = patch(3, b_origin);
    for (int k = 0; k < 3; ++k) {
      a.positions[k] = static_cast<float>(shared[k] - a_origin[k]);
      b.positions[k] = static_cast<float>(shared[k] - b_origin[k]);
    }
    GlbOptions options;
    const DecodedGlb da = decodeGlb(encodeGlb(a, options).bytes, "a.glb");
    const DecodedGlb db = decodeGlb(encodeGlb(b, options).bytes, "b.glb");
    auto nearest = [&](const DecodedGlb& d) {
      std::array<double, 3> best{};
      double best_distance = 1e300;
      for (std::size_t v = 0; v < d.mesh.vertexCount(); ++v) {
        std::array<double, 3> p;
        for (int k = 0; k < 3; ++k) p[k] = d.mesh.translation[k] + d.mesh.positions[3 * v + k];
        const double distance = std::hypot(p[0] - shared[0], p[1] - shared[1], p[2] - shared[2]);
        if (distance < best_distance) best_distance = distance, best = p;
      }
      return best;
    };
    const auto pa = nearest(da), pb = nearest(db);
    CHECK(pa == pb);
    CHECK(std::hypot(pa[0] - shared[0], pa[1] - shared[1], pa[2] - shared[2]) < step);
  }

  TEST_CASE("tiles too wide for the bit budget share a coarser power-of-two step") {
    const double base = 1.0 / 128;
    // 50 km takes 23 bits at 1/128 m: within 23 bits the base step stays.
    CHECK(positionBitsFor(50000, base) == 23);
    CHECK(sharedPositionStep(50000, base, 23) == base);
    // Within 20 bits it must widen to 1/16 m (2^20 - 1 steps of 1/32 m are 32.8 km).
    CHECK(sharedPositionStep(50000, base, 20) == base * 8);
    CHECK(positionBitsFor(50000 + base * 8, base * 8) <= 20);
    CHECK(positionBitsFor(50000 + base * 4, base * 4) > 20);

    GlbMesh wide = patch(4, {0, 0, 0});
    wide.positions[0] = 50000.0f;
    GlbOptions options;
    options.max_position_bits = 20;
    CHECK_THROWS_AS(encodeGlb(wide, options), Error);  // the caller must widen the step first
    options.position_step_m = sharedPositionStep(50000, base, 20);
    const EncodedGlb encoded = encodeGlb(wide, options);
    CHECK(encoded.position_step_m == base * 8);
    CHECK(encoded.position_bits <= 20);
    const DecodedGlb decoded = decodeGlb(encoded.bytes, "wide.glb");
    // Draco reorders vertices; the extreme vertex still decodes within half the step used.
    bool found = false;
    for (std::size_t v = 0; v < decoded.mesh.vertexCount(); ++v) {
      found |= std::fabs(decoded.mesh.positions[3 * v] - 50000.0f) <= encoded.position_step_m / 2;
    }
    CHECK(found);
  }

  TEST_CASE("the symbol entropy estimate write_glb gives Draco is the library's own, without its table") {
    // write_glb.cpp defines draco::ComputeShannonEntropy in the executable, which the dynamic
    // linker binds libdraco's calls to; the library's definition is the next one.
    using Entropy = std::int64_t (*)(const std::uint32_t*, int, int, int*);
    const auto library = reinterpret_cast<Entropy>(dlsym(RTLD_NEXT, "_ZN5draco21ComputeShannonEntropyEPKjiiPi"));
    const bool found = library != nullptr;
    REQUIRE(found);
    const auto ours = reinterpret_cast<Entropy>(dlsym(RTLD_DEFAULT, "_ZN5draco21ComputeShannonEntropyEPKjiiPi"));
    const Entropy defined = &draco::ComputeShannonEntropy;
    const bool exported = ours == defined;  // libdraco's calls come here
    REQUIRE(exported);
    const bool distinct = ours != library;
    REQUIRE(distinct);
    // Symbols as Draco makes them of positions at 1/128 m (zigzag of the difference to the
    // previous value, the first from zero), from rows of a real raster's heights (each row
    // read from its own column on, round to it): a large first symbol then small ones (the
    // library counts them in a long table, ours in a sorted copy), every row's first from
    // zero and the first again (several large ones, one twice), and small symbols alone
    // (both count them in a table).
    const DemGrid dem = readDem({test::sharedData("srtm3_N57E011_4326.tif")});
    const auto zigzag = [](std::int64_t v) { return static_cast<std::uint32_t>(v < 0 ? -2 * v - 1 : 2 * v); };
    enum class Start { first_from_zero, rows_from_zero, none_from_zero };
    for (const int rows : {1, 7, 40}) {
      for (const Start start : {Start::first_from_zero, Start::rows_from_zero, Start::none_from_zero}) {
        CAPTURE(rows);
        CAPTURE(static_cast<int>(start));
        std::vector<std::uint32_t> symbols;
        std::int64_t previous = 0;
        for (int row = 0; row < rows; ++row) {
          bool row_start = true;
          for (int k = 0; k < dem.width; ++k) {
            const int col = (k + 97 * row) % dem.width;  // rows start at different heights
            const float h = dem.heightAt(col, 300 + row);
            if (std::isnan(h)) continue;
            const std::int64_t q = std::llround((h + 1000.0) * 128.0);
            if (row_start && start == Start::rows_from_zero) previous = 0;
            if (symbols.empty() && start == Start::none_from_zero) previous = q;
            symbols.push_back(zigzag(q - previous));
            previous = q;
            row_start = false;
          }
        }
        if (start == Start::rows_from_zero) symbols.push_back(symbols.front());
        const int max_value = static_cast<int>(*std::max_element(symbols.begin(), symbols.end()));
        // Which way ours counts: sorted (the table would be longer than 2 per symbol + 1024) or
        // in the table.
        const std::int64_t table = 2 * static_cast<std::int64_t>(symbols.size()) + 1024;
        CHECK((max_value >= table) == (start != Start::none_from_zero));
        int unique_ours = -1, unique_library = -2;
        CHECK(ours(symbols.data(), static_cast<int>(symbols.size()), max_value, &unique_ours) ==
              library(symbols.data(), static_cast<int>(symbols.size()), max_value, &unique_library));
        CHECK(unique_ours == unique_library);
        CHECK(unique_ours > 10);
      }
    }
  }

  TEST_CASE("a plain GLB keeps positions and indices exactly") {
    const GlbMesh mesh = patch(5, {1.0, 2.0, 3.0});
    GlbOptions options;
    options.draco = false;
    const DecodedGlb decoded = decodeGlb(encodeGlb(mesh, options).bytes, "plain.glb");
    CHECK_FALSE(decoded.draco);
    CHECK(decoded.mesh.positions == mesh.positions);
    CHECK(decoded.mesh.normals == mesh.normals);
    CHECK(decoded.mesh.triangle_indices == mesh.triangle_indices);
  }

  TEST_CASE("a truncated GLB is an input error not a crash") {
    const std::vector<std::uint8_t> bytes = encodeGlb(patch(4, {0, 0, 0}), GlbOptions{}).bytes;
    for (std::size_t cut : {std::size_t{0}, std::size_t{11}, std::size_t{40}, bytes.size() - 7}) {
      const std::vector<std::uint8_t> truncated(bytes.begin(), bytes.begin() + static_cast<long>(cut));
      CHECK_THROWS_WITH(decodeGlb(truncated, "cut.glb"), doctest::Contains("cut.glb: malformed GLB"));
    }
  }
}
