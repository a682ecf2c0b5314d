// Shading normals (wave/shading_normals.h): apply_shading_normals interpolates the vertex
// normals in SIMD over whole packets; every lane must give the bits of the scalar
// definition below (the normals interpolated by the barycentrics in that order of
// operations, normalised, turned to the geometric normal's side, the geometric normal
// where the mesh has none or they cancel, then turned to wo's side; with materials, the
// side the viewer is on), for points on meshes with and without normals, at counts that
// leave a part of a packet, with and without materials.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <random>
#include <vector>

#include "render_util.h"
#include "wave/shading_normals.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// A mesh of n triangles with vertex normals (some vertices' opposite to their
// neighbours', so that some points' normals cancel, and some zero), and one without.
Scene normals_scene(std::mt19937& rng) {
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  Scene s;
  s.source = "test:shading-normals";
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  Mesh with;
  with.name = "with normals";
  with.material = 0;
  for (int t = 0; t < 40; ++t) {
    const vec3f a{u(rng), u(rng), u(rng)};
    add_triangle(with, a, a + vec3f{0.3f, u(rng) * 0.1f, 0.f}, a + vec3f{0.f, u(rng) * 0.1f, 0.3f});
  }
  const size_t verts = with.positions.size() / 3;
  for (size_t i = 0; i < verts; ++i) {
    vec3f n{u(rng), u(rng), u(rng)};
    if (i % 7 == 3) n = {0.f, 0.f, 0.f};
    const float l = length(n);
    if (l > 0) n = n * (1.f / l);
    if (i % 5 == 1 && i > 0) {  // the previous vertex's opposite
      const size_t p = i - 1;
      n = {-with.normals[3 * p], -with.normals[3 * p + 1], -with.normals[3 * p + 2]};
    }
    with.normals.insert(with.normals.end(), {n.x, n.y, n.z});
  }
  s.meshes.push_back(with);
  Mesh without;
  without.name = "without";
  without.material = 0;
  add_quad(without, {-1, -1, -1}, {2, 0, 0}, {0, 0, 2});
  s.meshes.push_back(without);
  add_named_quad(s, "light", 0, {-0.2f, 2.f, -0.2f}, {0.4f, 0, 0}, {0, 0, 0.4f}, 5);
  finalize_scene(s);
  return s;
}

struct Expected {
  float sx, sy, sz, side;
};

// The scalar definition.
Expected reference(const GeomView& G, const ShadingPoints& P, int k, bool materials) {
  const float gx = P.nx[k], gy = P.ny[k], gz = P.nz[k];
  float sx = gx, sy = gy, sz = gz, side = P.side[k];
  const float* N = G.normals[P.geom[k]];
  if (N) {
    const uint32_t* idx = G.indices[P.geom[k]] + 3 * static_cast<size_t>(P.prim[k]);
    const float b1 = P.bu[k], b2 = P.bv[k], b0 = 1.f - b1 - b2;
    const float* q[3] = {N + 3 * static_cast<size_t>(idx[0]), N + 3 * static_cast<size_t>(idx[1]),
                         N + 3 * static_cast<size_t>(idx[2])};
    const float x = b0 * q[0][0] + b1 * q[1][0] + b2 * q[2][0];
    const float y = b0 * q[0][1] + b1 * q[1][1] + b2 * q[2][1];
    const float z = b0 * q[0][2] + b1 * q[1][2] + b2 * q[2][2];
    const float l2 = x * x + y * y + z * z;
    if (l2 > 1e-20f && std::isfinite(l2)) {
      const float il = 1.f / std::sqrt(l2);
      sx = x * il;
      sy = y * il;
      sz = z * il;
      const float facing = sx * gx + sy * gy + sz * gz;
      if (materials) side = facing >= 0.f ? 1.f : -1.f;
      if (facing < 0.f) {
        sx = -sx;
        sy = -sy;
        sz = -sz;
      }
    }
  }
  if (sx * P.wox[k] + sy * P.woy[k] + sz * P.woz[k] < 0.f) {
    sx = -sx;
    sy = -sy;
    sz = -sz;
  }
  return {sx, sy, sz, side};
}

bool same_bits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

}  // namespace

TEST(ShadingNormals, EveryLaneGivesTheScalarDefinitionsBits) {
  std::mt19937 rng(17);
  const Scene s = normals_scene(rng);
  const SceneViews views = build_views(s, LightPick::power);
  const GeomView& G = views.geom;
  ASSERT_TRUE(G.shading_normals);
  ASSERT_FALSE(G.has_bump);
  std::uniform_real_distribution<float> u(-1.f, 1.f), b(0.f, 1.f);
  auto P = std::make_unique<ShadingPoints>();
  size_t checked = 0, interpolated = 0, cancelled = 0;
  for (const bool materials : {false, true})
    for (const int count : {1, 5, 16, 37, 200}) {
      P->count = count;
      for (int k = 0; k < count; ++k) {
        const bool on_normals = k % 4 != 0;
        P->geom[k] = on_normals ? 0 : 1;
        P->prim[k] = static_cast<int32_t>(rng() % (on_normals ? 40u : 2u));
        float b1 = b(rng), b2 = b(rng);
        if (b1 + b2 > 1.f) {
          b1 = 1.f - b1;
          b2 = 1.f - b2;
        }
        if (k % 11 == 2) b1 = b2 = 0.f;  // (at a vertex)
        P->bu[k] = b1;
        P->bv[k] = b2;
        const vec3f g = normalize(vec3f{u(rng), u(rng), u(rng)}), wo = normalize(vec3f{u(rng), u(rng), u(rng)});
        P->nx[k] = g.x;
        P->ny[k] = g.y;
        P->nz[k] = g.z;
        P->wox[k] = wo.x;
        P->woy[k] = wo.y;
        P->woz[k] = wo.z;
        P->side[k] = k % 3 == 0 ? -1.f : 1.f;
        P->mat[k] = 0;
        P->inst[k] = -1;
      }
      std::vector<Expected> want;
      for (int k = 0; k < count; ++k) want.push_back(reference(G, *P, k, materials));
      if (materials) apply_shading_normals<true>(G, *P);
      else apply_shading_normals<false>(G, *P);
      for (int k = 0; k < count; ++k) {
        SCOPED_TRACE(::testing::Message() << "count " << count << " point " << k << " materials " << materials);
        EXPECT_TRUE(same_bits(P->snx[k], want[static_cast<size_t>(k)].sx)) << P->snx[k] << " vs " << want[static_cast<size_t>(k)].sx;
        EXPECT_TRUE(same_bits(P->sny[k], want[static_cast<size_t>(k)].sy));
        EXPECT_TRUE(same_bits(P->snz[k], want[static_cast<size_t>(k)].sz));
        EXPECT_TRUE(same_bits(P->side[k], want[static_cast<size_t>(k)].side));
        ++checked;
        const Expected& e = want[static_cast<size_t>(k)];
        const bool geometric = (e.sx == P->nx[k] && e.sy == P->ny[k] && e.sz == P->nz[k]) ||
                               (e.sx == -P->nx[k] && e.sy == -P->ny[k] && e.sz == -P->nz[k]);
        if (P->geom[k] == 0) (geometric ? cancelled : interpolated) += 1;
      }
    }
  EXPECT_EQ(checked, 2u * (1 + 5 + 16 + 37 + 200));
  EXPECT_GT(interpolated, 100u);  // (the cases the test is for all occurred)
  EXPECT_GT(cancelled, 0u);
}
