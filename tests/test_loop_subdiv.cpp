// Loop subdivision (scene/loop_subdiv.h) against what is known of the limit surface: a
// tetrahedron's corners go to exactly a fifth of the way to its centre, a plane stays a
// plane (and a regular grid's interior points stay put: Loop's scheme reproduces linear
// functions), the subdivided mesh stays closed and consistently wound, and control meshes
// outside Loop's rules are refused with a reason. Through the pbrt-v4 reader: the
// triangles, the normals, and the fall-back to the control mesh with a warning.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "scene/loop_subdiv.h"
#include "scene/pbrt.h"
#include "scene/scene.h"

using namespace tuile;

namespace {

// A regular tetrahedron centred at the origin, wound counter-clockwise seen from outside.
const std::vector<float> tet_p = {1, 1, 1, 1, -1, -1, -1, 1, -1, -1, -1, 1};
const std::vector<uint32_t> tet_i = {0, 1, 2, 0, 2, 3, 0, 3, 1, 1, 3, 2};

// Every directed edge once (consistent winding); with `closed`, each with its reverse;
// and V - E + F (2 for a sphere, 1 for a disc).
void expect_manifold(const LoopMesh& m, bool closed, int euler) {
  std::set<std::pair<uint32_t, uint32_t>> dir, undirected;
  for (size_t f = 0; f < m.indices.size(); f += 3)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = m.indices[f + k], b = m.indices[f + (k + 1) % 3];
      EXPECT_TRUE(dir.emplace(a, b).second) << "edge " << a << "-" << b << " twice";
      undirected.emplace(std::min(a, b), std::max(a, b));
    }
  if (closed) {
    for (const auto& [a, b] : dir) EXPECT_TRUE(dir.count({b, a})) << "edge " << a << "-" << b << " open";
  }
  const long v = static_cast<long>(m.positions.size() / 3), e = static_cast<long>(undirected.size()),
             f = static_cast<long>(m.indices.size() / 3);
  EXPECT_EQ(v - e + f, euler);
}

}  // namespace

TEST(LoopSubdiv, TetrahedronCornersGoToAFifthAndTheMeshStaysClosed) {
  for (int levels = 0; levels <= 4; ++levels) {
    LoopMesh m;
    std::string why;
    ASSERT_TRUE(loop_subdivide(tet_p, tet_i, levels, m, why)) << why;
    EXPECT_EQ(m.indices.size(), tet_i.size() << (2 * levels));
    // valence 3 at every level: limit = (1 - 3/5) v + 1/5 (sum of the other three) = v / 5
    for (int v = 0; v < 4; ++v)
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(m.positions[3 * v + c], tet_p[3 * v + c] / 5.0, 1e-6) << levels << " " << v;
    expect_manifold(m, true, 2);
    // the corners' normals lie along their diagonals, all on the same side (pbrt-v4's
    // convention for a counter-clockwise outside: the tangents' cross product points in)
    for (int v = 0; v < 4; ++v) {
      double d = 0;
      for (int c = 0; c < 3; ++c) d += m.normals[3 * v + c] * tet_p[3 * v + c] / std::sqrt(3.0);
      EXPECT_NEAR(d, -1.0, 1e-5) << levels << " " << v;
    }
    // every vertex of the convex limit surface: unit normal, the same side
    for (size_t v = 0; v < m.positions.size() / 3; ++v) {
      double d = 0, l = 0;
      for (int c = 0; c < 3; ++c) d += m.normals[3 * v + c] * m.positions[3 * v + c], l += m.normals[3 * v + c] * m.normals[3 * v + c];
      EXPECT_NEAR(l, 1.0, 1e-5);
      EXPECT_LT(d, 0) << levels << " " << v;
    }
  }
}

// A control vertex's limit point does not depend on how far the mesh is refined before it
// is pushed to the limit: on a cube (valences 4, 5 and 6), the corners after 1..4 levels are
// where the limit rule puts them on the control mesh itself.
TEST(LoopSubdiv, ACubesCornersHaveTheSameLimitAtEveryLevel) {
  const std::vector<float> p = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1};
  const std::vector<uint32_t> idx = {0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4,
                                     1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6, 3, 0, 4, 3, 4, 7};
  LoopMesh base;
  std::string why;
  ASSERT_TRUE(loop_subdivide(p, idx, 0, base, why)) << why;
  for (int levels = 1; levels <= 4; ++levels) {
    LoopMesh m;
    ASSERT_TRUE(loop_subdivide(p, idx, levels, m, why)) << why;
    expect_manifold(m, true, 2);
    for (int i = 0; i < 24; ++i) EXPECT_NEAR(m.positions[static_cast<size_t>(i)], base.positions[static_cast<size_t>(i)], 1e-5) << levels << " " << i;
  }
}

TEST(LoopSubdiv, APlaneStaysAPlaneAndARegularGridsInteriorStaysPut) {
  // a 6 x 6 grid of unit squares in z = 0, each split along the same diagonal (valence 6 inside)
  const int n = 7;
  std::vector<float> p;
  std::vector<uint32_t> idx;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) p.insert(p.end(), {float(x), float(y), 0.f});
  for (int y = 0; y + 1 < n; ++y)
    for (int x = 0; x + 1 < n; ++x) {
      const uint32_t a = uint32_t(y * n + x), b = a + 1, c = a + uint32_t(n), d = c + 1;
      idx.insert(idx.end(), {a, b, d, a, d, c});
    }
  LoopMesh m;
  std::string why;
  ASSERT_TRUE(loop_subdivide(p, idx, 2, m, why)) << why;
  EXPECT_EQ(m.indices.size(), idx.size() * 16);
  expect_manifold(m, false, 1);  // a disc
  float side = 0;
  for (size_t v = 0; v < m.positions.size() / 3; ++v) {
    EXPECT_EQ(m.positions[3 * v + 2], 0.f);
    EXPECT_EQ(m.normals[3 * v], 0.f);
    EXPECT_EQ(m.normals[3 * v + 1], 0.f);
    EXPECT_EQ(std::fabs(m.normals[3 * v + 2]), 1.f);
    if (v == 0) side = m.normals[2];
    EXPECT_EQ(m.normals[3 * v + 2], side) << v;
    // the boundary polygon is straight: its points stay on it
    const float x = m.positions[3 * v], y = m.positions[3 * v + 1];
    EXPECT_TRUE(x >= -1e-5f && x <= n - 1 + 1e-5f && y >= -1e-5f && y <= n - 1 + 1e-5f) << x << " " << y;
  }
  for (int y = 1; y + 1 < n; ++y)
    for (int x = 1; x + 1 < n; ++x) {
      const size_t v = size_t(y * n + x);
      EXPECT_NEAR(m.positions[3 * v], x, 1e-5);
      EXPECT_NEAR(m.positions[3 * v + 1], y, 1e-5);
    }
}

TEST(LoopSubdiv, RefusesWhatLoopsRulesDoNotCover) {
  LoopMesh m;
  std::string why;
  // three triangles on one edge
  const std::vector<float> p = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1};
  EXPECT_FALSE(loop_subdivide(p, {0, 1, 2, 1, 0, 3, 0, 1, 4}, 1, m, why));
  EXPECT_NE(why.find("same direction"), std::string::npos) << why;
  // two triangles wound against each other
  EXPECT_FALSE(loop_subdivide(p, {0, 1, 2, 0, 1, 3}, 1, m, why));
  EXPECT_NE(why.find("same direction"), std::string::npos) << why;
  // two fans touching at one vertex (a bow tie)
  const std::vector<float> bow = {0, 0, 0, 1, 0, 0, 1, 1, 0, -1, 0, 0, -1, -1, 0};
  EXPECT_FALSE(loop_subdivide(bow, {0, 1, 2, 0, 3, 4}, 1, m, why));
  EXPECT_NE(why.find("more than one fan"), std::string::npos) << why;
  // a repeated vertex, a bad index, too many triangles
  EXPECT_FALSE(loop_subdivide(p, {0, 0, 1}, 1, m, why));
  EXPECT_NE(why.find("repeats"), std::string::npos) << why;
  EXPECT_FALSE(loop_subdivide(p, {0, 1, 9}, 1, m, why));
  EXPECT_FALSE(loop_subdivide(tet_p, tet_i, 3, m, why, 100));
  EXPECT_EQ(why.rfind("levels", 0), 0u) << why;
  // an unused vertex is left where it is
  std::vector<float> extra = tet_p;
  extra.insert(extra.end(), {5, 5, 5});
  ASSERT_TRUE(loop_subdivide(extra, tet_i, 1, m, why)) << why;
  EXPECT_EQ(m.positions[12], 5.f);
}

TEST(LoopSubdiv, ThePbrtReaderSubdividesAndFallsBack) {
  const std::string tet = "\"point3 P\" [ 1 1 1  1 -1 -1  -1 1 -1  -1 -1 1 ] \"integer indices\" [ 0 1 2 0 2 3 0 3 1 1 3 2 ]";
  {
    const Scene s = load_pbrt_string("WorldBegin\nShape \"loopsubdiv\" \"integer levels\" 2 " + tet + "\n", "t.pbrt", ".");
    ASSERT_EQ(s.meshes.size(), 1u);
    EXPECT_EQ(s.meshes[0].triangle_count(), 4u * 16u);
    EXPECT_EQ(s.meshes[0].normals.size(), s.meshes[0].positions.size());
    for (const std::string& w : s.warnings) EXPECT_EQ(w.find("loopsubdiv"), std::string::npos) << w;
  }
  {  // pbrt-v4's default: 3 levels
    const Scene s = load_pbrt_string("WorldBegin\nShape \"loopsubdiv\" " + tet + "\n", "t.pbrt", ".");
    EXPECT_EQ(s.meshes[0].triangle_count(), 4u * 64u);
  }
  {  // a bow tie: the control mesh, with the reason
    const Scene s = load_pbrt_string(
        "WorldBegin\nShape \"loopsubdiv\" \"point3 P\" [0 0 0 1 0 0 1 1 0 -1 0 0 -1 -1 0] \"integer indices\" [0 1 2 0 3 4]\n",
        "t.pbrt", ".");
    EXPECT_EQ(s.meshes[0].triangle_count(), 2u);
    bool warned = false;
    for (const std::string& w : s.warnings) warned |= w.find("more than one fan") != std::string::npos;
    EXPECT_TRUE(warned);
  }
  EXPECT_THROW(load_pbrt_string("WorldBegin\nShape \"loopsubdiv\" \"integer levels\" 40 " + tet + "\n", "t.pbrt", "."),
               SceneError);
}
