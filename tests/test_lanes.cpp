// Every SIMD lane equals the scalar reference, for every stage kernel: the samplers,
// camera rays, the camera-hit stage, light point sampling and its pdf, the light-sampling
// stage, the cosine stage, the MIS weight stage and the film accumulation (the whole
// per-lane state they write is compared).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <set>
#include <vector>

#include "wave/accumulate.h"
#include "wave/generate.h"
#include "wave/instances.h"
#include "wave/surface_hits.h"
#include "accel/embree.h"
#include "wave/sample_bsdf.h"
#include "wave/sample_lights.h"
#include "wave/emitter_hits.h"
#include "wave/ris.h"
#include "render/render.h"
#include "scene/sky_map.h"
#include "render_util.h"

using namespace tuile;

namespace {

// A scene with every light type: triangles, parallelograms (rectangle and sheared),
// a sphere, point, spot and distant lights. Extras (for the camera-hit stage): a
// textured wall, a plain sphere and a two-sided emitter.
Scene all_lights_scene(bool extras = false, bool sky = false) {
  Scene s;
  s.source = "test:all-lights";
  s.materials.push_back(diffuse_material(Rgb{0.7f, 0.5f, 0.3f}, -1));
  Mesh floor;
  floor.name = "floor";
  floor.material = 0;
  test::add_quad(floor, {-5, 0, -5}, {0, 0, 10}, {10, 0, 0});
  s.meshes.push_back(floor);
  Mesh lights;
  lights.name = "emitters";
  lights.material = 0;
  lights.emission = {3, 2, 1};
  test::add_quad(lights, {-1, 1, -1}, {1, 0, 0}, {0, 0, 1});
  test::add_quad(lights, {0.5f, 1.2f, 0}, {0.4f, 0, 0}, {0.2f, 0.1f, 0.5f});
  test::add_triangle(lights, {0, 2, 0}, {0.5f, 2, 0.5f}, {0.2f, 2.5f, 0});
  s.meshes.push_back(lights);
  Sphere sp;
  sp.center = {1, 1.5f, 1};
  sp.radius = 0.3f;
  sp.material = 0;
  sp.emission = {5, 5, 5};
  s.spheres.push_back(sp);
  s.lights.push_back(test::point_light({0, 3, 0}, {2, 2, 2}));
  s.lights.push_back(test::spot_light({1, 3, 1}, {0, -1, 0.2f}, 0.95f, 0.85f, {4, 4, 4}));
  s.lights.push_back(test::distant_light({0.3f, 1, 0.2f}, {1, 1, 1}));
  if (sky) {  // a constant sky and one with a map in a turned frame (light/kinds/infinite.h)
    Light inf;
    inf.type = LightKind::infinite;
    inf.radiance = {0.3f, 0.5f, 0.7f};
    s.lights.push_back(inf);
    RgbImage img;
    img.width = img.height = 8;
    for (int t = 0; t < 64; ++t)
      for (int c = 0; c < 3; ++c) img.rgb.push_back(static_cast<float>((t * 7 + c * 3) % 11) * (t == 19 ? 30.f : 0.1f));
    test::add_map_sky(s, img, {0.5f, 0.5f, 0.5f}, {1, 0.2f, 0});
  }
  if (extras) {
    Texture tex;
    tex.name = "checker";
    tex.width = tex.height = 4;
    for (int k = 0; k < 16; ++k) tex.rgb.insert(tex.rgb.end(), {0.2f + 0.05f * k, (k % 3) * 0.4f, ((k / 4 + k) % 2) * 0.9f});
    s.textures.push_back(tex);
    s.materials.push_back(diffuse_material(Rgb{0.9f, 0.8f, 0.7f}, 0));
    Mesh wall;
    wall.name = "wall";
    wall.material = 1;
    test::add_quad(wall, {-4, 0, -3}, {8, 0, 0}, {0, 3, 0});
    wall.uvs = {0, 0, 2.5f, 0, 2.5f, 1.5f, 0, 1.5f};
    s.meshes.push_back(wall);
    Sphere plain;
    plain.center = {-1.2f, 0.5f, 0.5f};
    plain.radius = 0.5f;
    s.spheres.push_back(plain);
    Mesh both;
    both.name = "two-sided emitter";
    both.emission = {0.5f, 1, 2};
    both.two_sided = true;
    test::add_triangle(both, {1.5f, 0.2f, -1}, {2.5f, 0.2f, -1}, {2, 0.2f, 0});
    s.meshes.push_back(both);
  }
  s.camera.width = s.camera.height = 16;
  camera_look_at(s.camera, {0, 2, 4}, {0, 0, 0}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

void fill_shading_points(TileBuffers& tb, std::mt19937& rng, int n) {
  std::uniform_real_distribution<float> U(0.f, 1.f);
  tb.points.count = n;
  for (int k = 0; k < max_tile_lanes; ++k) {
    tb.points.px[k] = -2 + 4 * U(rng);
    tb.points.py[k] = U(rng) < 0.2f ? 1.0f : 0.f;  // some points in the plane of a source
    tb.points.pz[k] = -2 + 4 * U(rng);
    vec3f nn = normalize(vec3f{0.2f * (U(rng) - 0.5f), 1.f, 0.2f * (U(rng) - 0.5f)});
    if (U(rng) < 0.1f) nn = -nn;
    tb.points.nx[k] = nn.x;
    tb.points.ny[k] = nn.y;
    tb.points.nz[k] = nn.z;
    tb.points.eps[k] = 1e-5f;
    tb.points.ar[k] = U(rng);
    tb.points.ag[k] = U(rng);
    tb.points.ab[k] = U(rng);
    tb.points.pixel[k] = static_cast<uint32_t>(k * 7);
    tb.points.lane[k] = k;
    tb.points.choose_light[k] = U(rng) < 0.5f ? 1.f : 0.f;
    tb.tech.u0[k] = U(rng);
    tb.tech.u1[k] = U(rng);
    tb.tech.u2[k] = U(rng);
    tb.tech.u3[k] = U(rng);
  }
}

template <class F> void expect_same_floats(const float* a, const float* b, int n, F name) {
  for (int i = 0; i < n; ++i)
    ASSERT_TRUE(std::memcmp(a + i, b + i, sizeof(float)) == 0) << name() << " lane " << i << ": " << a[i] << " vs " << b[i];
}

}  // namespace

// Every sampler's SIMD path against the scalar reference, with sample counts that are
// squares (stratified: an n x n grid), not squares (Latin hypercube), 1, and indices past
// the planned count; 67 lanes leave a scalar tail.
TEST(Lanes, Samplers) {
  uint32_t pix[67];
  for (int i = 0; i < 67; ++i) pix[i] = static_cast<uint32_t>(i * 131 + 5);
  for (int kind = 0; kind < 3; ++kind)
    for (uint32_t spp : {16u, 10u, 1u, 7u, 1024u, 1000u})
      for (uint32_t pair : {0u, 3u, 17u})
        for (uint32_t idx : {0u, 1u, 6u, 15u, 999u, 1000u, 5000u}) {
          float u[67], v[67];
          sample_pairs(static_cast<SamplerKind>(kind), 9, pix, idx, spp, pair, 67, u, v);
          for (int i = 0; i < 67; ++i) {
            float su, sv;
            sample_pair_scalar(static_cast<SamplerKind>(kind), 9, pix[i], idx, spp, pair, su, sv);
            ASSERT_EQ(u[i], su) << kind << " spp " << spp << " index " << idx << " lane " << i;
            ASSERT_EQ(v[i], sv) << kind << " spp " << spp << " index " << idx << " lane " << i;
            ASSERT_GE(u[i], 0.f);
            ASSERT_LT(u[i], 1.f);
            ASSERT_GE(v[i], 0.f);
            ASSERT_LT(v[i], 1.f);
          }
          float u1[67];  // the first dimension alone (v = nullptr): the same u
          sample_pairs(static_cast<SamplerKind>(kind), 9, pix, idx, spp, pair, 67, u1, nullptr);
          ASSERT_EQ(std::memcmp(u, u1, sizeof(u)), 0) << kind << " spp " << spp << " index " << idx;
        }
}

// The SIMD fast path of the hash-based samplers against the scalar reference: random
// pixels, seeds and pairs, indices across the 32-bit range, counts with a scalar tail.
TEST(Lanes, SamplerPairsEqualScalarMany) {
  std::mt19937 rng(7);
  std::vector<uint32_t> pix(203);
  std::vector<float> u(pix.size()), v(pix.size());
  std::vector<uint32_t> indices;
  for (uint32_t k = 0; k < 70; ++k) indices.push_back(k);
  for (uint32_t k : {255u, 256u, 1023u, 65535u, 65536u, 0x7fffffffu, 0x80000000u, 0xfffffffeu, 0xffffffffu})
    indices.push_back(k);
  for (int k = 0; k < 40; ++k) indices.push_back(static_cast<uint32_t>(rng()));
  for (int kind : {0, 2})
    for (int trial = 0; trial < 6; ++trial) {
      for (auto& p : pix) p = trial < 2 ? static_cast<uint32_t>(&p - pix.data()) + 4096u * trial : static_cast<uint32_t>(rng());
      const uint32_t seed = trial == 0 ? 0u : static_cast<uint32_t>(rng());
      for (uint32_t pair : {0u, 1u, 2u, 3u, 4u, 9u, 31u, static_cast<uint32_t>(rng())})
        for (uint32_t index : indices) {
          const int count = index % 7 == 5 ? static_cast<int>(index % 61)
                                           : static_cast<int>(pix.size()) - (index % 3 == 0 ? 0 : static_cast<int>(index % 29));
          sample_pairs(static_cast<SamplerKind>(kind), seed, pix.data(), index, 64, pair, count, u.data(), v.data());
          for (int i = 0; i < count; ++i) {
            float su, sv;
            sample_pair_scalar(static_cast<SamplerKind>(kind), seed, pix[i], index, 64, pair, su, sv);
            ASSERT_TRUE(std::memcmp(&u[i], &su, sizeof(float)) == 0 && std::memcmp(&v[i], &sv, sizeof(float)) == 0)
                << "kind " << kind << " seed " << seed << " pixel " << pix[i] << " index " << index << " pair " << pair;
          }
          // the first dimension alone (v = nullptr): the same u
          std::vector<float> u1(pix.size(), -1.f);
          sample_pairs(static_cast<SamplerKind>(kind), seed, pix.data(), index, 64, pair, count, u1.data(), nullptr);
          ASSERT_EQ(std::memcmp(u.data(), u1.data(), count * sizeof(float)), 0) << "kind " << kind << " index " << index;
        }
    }
}

// Keys cached per pixel and pair (made once per tile) give the bits of hashing the pixel
// every sample, for both hash-based samplers.
TEST(Lanes, CachedKeysGiveTheSamePairs) {
  std::mt19937 rng(5);
  for (int count : {256, 203, 5})  // whole batches, and a partial one
    for (SamplerKind kind : {SamplerKind::independent, SamplerKind::sobol})
      for (int trial = 0; trial < 4; ++trial) {
        std::vector<uint32_t> pix(count), key(count), ku(count), kv(count);
        std::vector<float> u(count), v(count), ku_u(count), ku_v(count);
        const PairKeys keys{key.data(), ku.data(), kv.data()};
        for (auto& p : pix) p = trial == 0 ? static_cast<uint32_t>(&p - pix.data()) : static_cast<uint32_t>(rng());
        const uint32_t seed = trial == 0 ? 0u : static_cast<uint32_t>(rng());
        for (uint32_t pair : {0u, 1u, 4u, 77u}) {
          make_pair_keys(seed, pix.data(), pair, count, keys);
          for (uint32_t index : {0u, 1u, 2u, 15u, 16u, 1000u, 0xffffffffu, static_cast<uint32_t>(rng())}) {
            sample_pairs(kind, seed, pix.data(), index, 64, pair, count, u.data(), v.data());
            sample_pairs_keyed(kind, seed, index, pair, keys, count, ku_u.data(), ku_v.data());
            ASSERT_EQ(std::memcmp(u.data(), ku_u.data(), count * sizeof(float)), 0) << count << " pair " << pair << " index " << index;
            ASSERT_EQ(std::memcmp(v.data(), ku_v.data(), count * sizeof(float)), 0) << count << " pair " << pair << " index " << index;
            std::vector<float> u1(count, -1.f);  // the first dimension alone: the same u
            sample_pairs_keyed(kind, seed, index, pair, keys, count, u1.data(), nullptr);
            ASSERT_EQ(std::memcmp(u.data(), u1.data(), count * sizeof(float)), 0) << count << " pair " << pair << " index " << index;
          }
        }
      }
}

// The SIMD bit-manipulation helpers equal their scalar definitions on every lane.
TEST(Lanes, SamplerBitHelpersEqualScalar) {
  std::mt19937 rng(11);
  alignas(64) uint32_t in[simd_width], rev[simd_width], rev8[simd_width], sup[simd_width];
  for (int n = 0; n < 20000; ++n) {
    for (int l = 0; l < simd_width; ++l) in[l] = n < 64 ? (n < 32 ? 1u << n : ~(1u << (n - 32))) : static_cast<uint32_t>(rng());
    const vuint x = vuint::load_aligned(in);
    rng_simd::reverse_bits(x).store_aligned(rev);
    rng_simd::reverse_bits_shr8(x).store_aligned(rev8);
    rng_simd::superset_sum(x).store_aligned(sup);
    for (int l = 0; l < simd_width; ++l) {
      ASSERT_EQ(rev[l], reverse_bits(in[l])) << in[l];
      ASSERT_EQ(rev8[l], reverse_bits(in[l]) >> 8) << in[l];
      ASSERT_EQ(sup[l], reverse_bits(sobol_dim1(in[l]))) << in[l];
    }
  }
}

// The light and MIS weight stages of rectangle-only scenes (kind_rects: no dispatch on the
// kind of source) equal the general stages and their own scalar reference, lane for lane,
// with one-sided sources (two_sided is not read) and two-sided ones.
TEST(Lanes, RectangleStagesEqualGeneral) {
  std::mt19937 rng(5);
  constexpr unsigned R = kind_area | kind_rects;
  for (bool two_sided : {false, true})
  for (LightPick pick : {LightPick::all, LightPick::power})
    for (LightPoint point : {LightPoint::area, LightPoint::solid_angle})
      for (MisMode mode : {MisMode::multi, MisMode::one}) {
        Scene s = builtin_scene("two-panels");
        for (Mesh& m : s.meshes)
          if (m.emissive()) m.two_sided = two_sided;
        finalize_scene(s);
        SceneViews views = build_views(s, pick);
        ASSERT_TRUE(views.all_rects());
        ASSERT_EQ(views.lights.any_two_sided, two_sided);
        ASSERT_TRUE(views.lights.one_radiance);  // every source has L = 4
        // the reference reads every field per lane
        LightView ref = views.lights;
        ref.any_two_sided = true;
        ref.one_radiance = false;
        ASSERT_EQ(views.lights.tier, tier_medium);  // 101 sources: permutes of the 128-entry tables
        Estimator est;
        est.pick = pick;
        est.point = point;
        est.mode = mode;
        auto a = std::make_unique<TileBuffers>();
        fill_shading_points(*a, rng, 200);
        for (int k = 0; k < max_tile_lanes; ++k) {
          a->points.py[k] *= 0.8f;  // some points in the sources' plane
          if (two_sided && k % 3 == 0) {  // some points above the sources, facing their backs
            a->points.py[k] = 1.6f;
            a->points.ny[k] = -std::abs(a->points.ny[k]);
          }
        }
        auto b = std::make_unique<TileBuffers>(*a), c = std::make_unique<TileBuffers>(*a),
             d = std::make_unique<TileBuffers>(*a), e = std::make_unique<TileBuffers>(*a);
        const int n = 208;
        auto name = [&] { return describe(est) + (two_sided ? " two-sided" : ""); };
        LightPass pass;
        pass.fixed_light = pick == LightPick::all ? 37 : -1;
        const bool fixed = pass.fixed_light >= 0;
        for (int k = 0; k < n; k += simd_width) sample_lights_lanes<vfloat>(views.geom, ref, est, pass, *a, k);
        for (int k = 0; k < n; ++k) {
          if (fixed) sample_lights_lanes<float, R, false>(views.geom, views.lights, est, pass, *b, k);
          else sample_lights_lanes<float, R, true>(views.geom, views.lights, est, pass, *b, k);
        }
        for (int k = 0; k < n; k += simd_width) {
          if (fixed) sample_lights_lanes<vfloat, R, false>(views.geom, views.lights, est, pass, *c, k);
          else sample_lights_lanes<vfloat, R, true>(views.geom, views.lights, est, pass, *c, k);
        }
        for (int k = 0; k < n; k += 2 * simd_width) {
          if (fixed) sample_lights_lanes<vfloat2, R, false>(views.geom, views.lights, est, pass, *d, k);
          else sample_lights_lanes<vfloat2, R, true>(views.geom, views.lights, est, pass, *d, k);
        }
        for (int k = 0; k < n; k += 4 * simd_width) {
          if (fixed) sample_lights_lanes<vfloat4, R, false>(views.geom, views.lights, est, pass, *e, k);
          else sample_lights_lanes<vfloat4, R, true>(views.geom, views.lights, est, pass, *e, k);
        }
        int lit = 0;
        for (const TileBuffers* t : {b.get(), c.get(), d.get(), e.get()}) {
          expect_same_floats(t->tech.cr, a->tech.cr, n, name);
          expect_same_floats(t->tech.cb, a->tech.cb, n, name);
          for (int k = 0; k < n; ++k) {
            ASSERT_EQ(t->tech.valid[k], a->tech.valid[k]) << name() << " lane " << k;
            if (!a->tech.valid[k]) continue;
            const Ray16 &rt = t->shadow[k / packet_width], &ra = a->shadow[k / packet_width];
            const int l = k % packet_width;
            expect_same_floats(&rt.org_y[l], &ra.org_y[l], 1, name);
            expect_same_floats(&rt.dir_x[l], &ra.dir_x[l], 1, name);
            expect_same_floats(&rt.dir_z[l], &ra.dir_z[l], 1, name);
            expect_same_floats(&rt.tfar[l], &ra.tfar[l], 1, name);
            lit += t == b.get();
          }
        }
        EXPECT_GT(lit, 20) << name();
        // the MIS weight of hits of every source, on a synthetic queue
        for (Strategy strategy : {Strategy::light, Strategy::bsdf, Strategy::mis}) {
          est.strategy = strategy;
          a->queue.count = n - 3;
          for (int j = 0; j < n; ++j) {
            a->queue.light[j] = static_cast<int32_t>(rng() % 101);
            a->queue.x[j] = a->points.px[j];
            a->queue.y[j] = 0.f;
            a->queue.z[j] = a->points.pz[j];
            const vec3f dq = normalize(vec3f{a->tech.u0[j] - 0.5f, 1.f, a->tech.u1[j] - 0.5f});
            a->queue.dx[j] = dq.x;
            a->queue.dy[j] = dq.y;
            a->queue.dz[j] = dq.z;
            a->queue.dist[j] = 0.8f / dq.y;
            a->queue.beta_r[j] = a->queue.beta_g[j] = a->queue.beta_b[j] = 0.5f;
            a->queue.pdf[j] = pdf_cosine_hemisphere(dq.y);  // Lambert on a floor (normal +y)
            a->queue.vis[j] = 1.f;
          }
          *b = *a;
          *c = *a;
          *d = *a;
          for (int j = 0; j < n; j += simd_width) weight_lanes<vfloat>(ref, est, 1.f, 1.f, *a, j);
          for (int j = 0; j < n; j += simd_width) weight_lanes<vfloat, R>(views.lights, est, 1.f, 1.f, *b, j);
          for (int j = 0; j < n; ++j) weight_lanes<float, R>(views.lights, est, 1.f, 1.f, *c, j);
          for (int j = 0; j < n; j += 2 * simd_width) weight_lanes<vfloat2, R>(views.lights, est, 1.f, 1.f, *d, j);
          for (const TileBuffers* t : {b.get(), c.get(), d.get()}) {
            expect_same_floats(t->tech.cr, a->tech.cr, n, name);
            expect_same_floats(t->tech.wb, a->tech.wb, n, name);
          }
        }
      }
}

TEST(Lanes, StagesEqualScalar) {
  Scene s = all_lights_scene(false, true);  // every kind of source, a constant sky and a map too
  ASSERT_EQ(s.lights.size(), 9u);
  s.spheres[0].alpha = 0.6f;  // a cut-out emitter: its light samples' radiance times its alpha (wave/alpha.h)
  std::mt19937 rng(3);
  for (LightPick pick : {LightPick::all, LightPick::uniform, LightPick::area, LightPick::power, LightPick::bvh}) {
    SceneViews views = build_views(s, pick);
    ASSERT_EQ(views.lights.bvh != nullptr, pick == LightPick::bvh);
    ASSERT_EQ(views.lights.tier, tier_small);
    ASSERT_FALSE(views.lights.one_radiance);
    // the tables (padded for permutes) read with permutes, then with gathers
    for (int tier : {tier_small, tier_gather})
    for (LightPoint point : {LightPoint::area, LightPoint::solid_angle})
      for (Strategy strategy : {Strategy::light, Strategy::bsdf, Strategy::mis})
        for (MisMode mode : {MisMode::multi, MisMode::one})
        for (Heuristic heuristic : {Heuristic::power, Heuristic::optimal}) {
          if (heuristic == Heuristic::optimal && strategy != Strategy::mis) continue;
          Estimator est;
          est.pick = pick;
          est.point = point;
          est.strategy = strategy;
          est.mode = mode;
          est.heuristic = heuristic;
          auto a = std::make_unique<TileBuffers>();
          fill_shading_points(*a, rng, 200);
          auto b = std::make_unique<TileBuffers>(*a);
          auto d = std::make_unique<TileBuffers>(*a);
          const int n = 208;  // whole packets
          views.lights.tier = tier;
          // the maps' compensated distribution under MIS, their full one otherwise
          views.lights.sky_dist = strategy == Strategy::mis ? sky_dist_compensated : sky_dist_full;
          auto name = [&] { return describe(est) + " tier " + std::to_string(tier) + " sky dist " + std::to_string(views.lights.sky_dist); };
          // light sampling stage
          LightPass pass;
          pass.fixed_light = pick == LightPick::all ? 2 : -1;
          for (int k = 0; k < n; k += simd_width) sample_lights_lanes<vfloat>(views.geom, views.lights, est, pass, *a, k);
          for (int k = 0; k < n; ++k) sample_lights_lanes<float>(views.geom, views.lights, est, pass, *b, k);
          if (pass.fixed_light >= 0) {  // the specialised broadcast path gives the same bits
            auto c = std::make_unique<TileBuffers>(*b);
            for (int k = 0; k < n; k += simd_width)
              sample_lights_lanes<vfloat, kind_all, false>(views.geom, views.lights, est, pass, *c, k);
            expect_same_floats(a->tech.cr, c->tech.cr, n, name);
          }
          // four batches at a time (vfloat4), then two (vfloat2), then one, as the stage runs them
          {
            int k = 0;
            for (; k + 4 * simd_width <= n; k += 4 * simd_width)
              sample_lights_lanes<vfloat4>(views.geom, views.lights, est, pass, *d, k);
            for (; k + 2 * simd_width <= n; k += 2 * simd_width)
              sample_lights_lanes<vfloat2>(views.geom, views.lights, est, pass, *d, k);
            for (; k < n; k += simd_width) sample_lights_lanes<vfloat>(views.geom, views.lights, est, pass, *d, k);
          }
          for (const TileBuffers* t : {a.get(), d.get()}) {
            expect_same_floats(t->tech.cr, b->tech.cr, n, name);
            expect_same_floats(t->tech.cg, b->tech.cg, n, name);
            expect_same_floats(t->tech.cb, b->tech.cb, n, name);
            EXPECT_EQ(t->stats.rejected_light, b->stats.rejected_light) << name();
            for (int k = 0; k < n; ++k) ASSERT_EQ(t->tech.valid[k], b->tech.valid[k]) << name() << " lane " << k;
            if (heuristic == Heuristic::optimal)  // the densities optimal MIS reads (wave/optimal_mis.h)
              for (int k = 0; k < n; ++k)
                if (b->tech.valid[k]) {
                  expect_same_floats(&t->tech.pl[k], &b->tech.pl[k], 1, name);
                  expect_same_floats(&t->tech.pb[k], &b->tech.pb[k], 1, name);
                }
            for (int p = 0; p < n / packet_width; ++p) {
              const Ray16 &ra = t->shadow[p], &rb = b->shadow[p];
              for (int l = 0; l < packet_width; ++l) {
                if (!t->tech.valid[p * packet_width + l]) continue;
                expect_same_floats(&ra.org_x[l], &rb.org_x[l], 1, name);
                expect_same_floats(&ra.org_y[l], &rb.org_y[l], 1, name);
                expect_same_floats(&ra.org_z[l], &rb.org_z[l], 1, name);
                expect_same_floats(&ra.dir_x[l], &rb.dir_x[l], 1, name);
                expect_same_floats(&ra.dir_y[l], &rb.dir_y[l], 1, name);
                expect_same_floats(&ra.dir_z[l], &rb.dir_z[l], 1, name);
                expect_same_floats(&ra.tfar[l], &rb.tfar[l], 1, name);
              }
            }
          }
          // shadow accumulation (some lanes occluded, as Embree marks them)
          for (int k = 0; k < n; k += 3) a->shadow[k / packet_width].tfar[k % packet_width] = -INFINITY;
          for (int k = 0; k < n; ++k) b->shadow[k / packet_width].tfar[k % packet_width] = a->shadow[k / packet_width].tfar[k % packet_width];
          for (TileBuffers* t : {a.get(), b.get()}) {
            std::fill_n(t->radiance.r, max_tile_lanes, 0.25f);
            std::fill_n(t->radiance.g, max_tile_lanes, 0.f);
            std::fill_n(t->radiance.b, max_tile_lanes, 1.f);
          }
          accumulate_shadow<vfloat>(*a);
          accumulate_shadow<float>(*b);
          expect_same_floats(a->radiance.r, b->radiance.r, max_tile_lanes, name);
          expect_same_floats(a->radiance.g, b->radiance.g, max_tile_lanes, name);
          expect_same_floats(a->radiance.b, b->radiance.b, max_tile_lanes, name);
          // an occluded lane adds nothing, a lit one its contribution
          for (int k = 0; k < n; ++k) {
            const bool lit = a->tech.valid[k] && k % 3 != 0;
            ASSERT_EQ(a->radiance.r[k], lit ? 0.25f + a->tech.cr[k] : 0.25f) << name() << " lane " << k;
          }
          // cosine stage: one batch at a time, two at a time (vfloat2, as the stage runs
          // them), and the scalar reference
          auto d2 = std::make_unique<TileBuffers>(*a);
          for (int k = 0; k < n; k += simd_width) sample_bsdf_lanes<vfloat>(views.geom, est, *a, k);
          for (int k = 0; k < n; ++k) sample_bsdf_lanes<float>(views.geom, est, *b, k);
          {
            int k = 0;
            for (; k + 2 * simd_width <= n; k += 2 * simd_width) sample_bsdf_lanes<vfloat2>(views.geom, est, *d2, k);
            for (; k < n; k += simd_width) sample_bsdf_lanes<vfloat>(views.geom, est, *d2, k);
          }
          for (const TileBuffers* t : {a.get(), d2.get()})
            for (int p = 0; p < n / packet_width; ++p)
              for (int l = 0; l < packet_width; ++l) {
                const int k = p * packet_width + l;
                ASSERT_EQ(t->tech.valid[k], b->tech.valid[k]) << name() << " lane " << k;
                const Ray16 &ra = t->bounce[p].ray, &rb = b->bounce[p].ray;
                for (auto f : {&Ray16::org_x, &Ray16::org_y, &Ray16::org_z, &Ray16::dir_x, &Ray16::dir_y,
                               &Ray16::dir_z, &Ray16::tfar})
                  ASSERT_TRUE(std::memcmp(&(ra.*f)[l], &(rb.*f)[l], sizeof(float)) == 0) << name() << " lane " << k;
              }
          // MIS weight stage on a synthetic queue of hits of every area light
          a->queue.count = b->queue.count = n - 5;
          for (int k = 0; k < n; ++k) {
            const int32_t li = static_cast<int32_t>(rng() % 4);
            a->queue.light[k] = b->queue.light[k] = li;
            a->queue.point[k] = b->queue.point[k] = k;  // the light BVH's pmf reads its normal
            a->queue.x[k] = b->queue.x[k] = a->points.px[k];
            a->queue.y[k] = b->queue.y[k] = a->points.py[k];
            a->queue.z[k] = b->queue.z[k] = a->points.pz[k];
            const vec3f d = normalize(vec3f{a->tech.u0[k] - 0.5f, 1.f, a->tech.u1[k] - 0.5f});
            const vec3f nk{a->points.nx[k], a->points.ny[k], a->points.nz[k]};
            a->queue.pdf[k] = b->queue.pdf[k] = pdf_cosine_hemisphere(dot(nk, d));
            a->queue.dx[k] = b->queue.dx[k] = d.x;
            a->queue.dy[k] = b->queue.dy[k] = d.y;
            a->queue.dz[k] = b->queue.dz[k] = d.z;
            a->queue.dist[k] = b->queue.dist[k] = 0.1f + static_cast<float>(rng() % 1000) * 0.003f;
            a->queue.beta_r[k] = b->queue.beta_r[k] = a->points.ar[k];
            a->queue.beta_g[k] = b->queue.beta_g[k] = a->points.ag[k];
            a->queue.beta_b[k] = b->queue.beta_b[k] = a->points.ab[k];
          }
          auto w2 = std::make_unique<TileBuffers>(*a);
          for (int k = 0; k < n; k += simd_width) weight_lanes<vfloat>(views.lights, est, 1.f, 1.f, *a, k);
          for (int k = 0; k < n; ++k) weight_lanes<float>(views.lights, est, 1.f, 1.f, *b, k);
          // two batches at a time (vfloat2) for the whole ones, as weight_queue runs them
          {
            int k = 0;
            for (; k + 2 * simd_width <= n; k += 2 * simd_width) weight_lanes<vfloat2>(views.lights, est, 1.f, 1.f, *w2, k);
            for (; k < n; k += simd_width) weight_lanes<vfloat>(views.lights, est, 1.f, 1.f, *w2, k);
          }
          for (const TileBuffers* t : {a.get(), w2.get()}) {
            expect_same_floats(t->tech.cr, b->tech.cr, n, name);
            expect_same_floats(t->tech.cb, b->tech.cb, n, name);
            expect_same_floats(t->tech.wb, b->tech.wb, n, name);
          }
        }
  }
}

// Resampled importance sampling's stages (wave/ris.h): light candidates (one batch, two,
// four at a time, as the stage runs them), BSDF candidates on synthetic emitter hits, and
// the kept candidates' shadow rays equal the scalar reference in every lane, reservoirs
// included; with the alias table and the light BVH, M and K of several sizes.
TEST(Lanes, RisStagesEqualScalar) {
  Scene s = all_lights_scene();
  std::mt19937 rng(17);
  for (LightPick pick : {LightPick::power, LightPick::bvh})
    for (int mk : {0, 1, 2}) {
      SceneViews views = build_views(s, pick);
      Estimator est;
      est.pick = pick;
      est.strategy = Strategy::ris;
      est.ris_light = mk == 0 ? 1 : mk == 1 ? 4 : 32;
      est.ris_bsdf = mk == 0 ? 0 : mk == 1 ? 1 : 3;
      const int n = 208;
      auto name = [&] { return describe(est); };
      auto a = std::make_unique<TileBuffers>();
      fill_shading_points(*a, rng, 200);
      auto b = std::make_unique<TileBuffers>(*a);
      auto d = std::make_unique<TileBuffers>(*a);
      std::vector<TileBuffers*> all{a.get(), b.get(), d.get()};
      for (TileBuffers* t : all) ris_clear(*t);
      LightPass pass;
      for (int j = 0; j < 3; ++j) {  // three light candidates
        for (int k = 0; k < n; k += simd_width) ris_light_lanes<vfloat>(views.geom, views.lights, est, pass, *a, k);
        for (int k = 0; k < n; ++k) ris_light_lanes<float>(views.geom, views.lights, est, pass, *b, k);
        int k = 0;
        for (; k + 4 * simd_width <= n; k += 4 * simd_width) ris_light_lanes<vfloat4>(views.geom, views.lights, est, pass, *d, k);
        for (; k + 2 * simd_width <= n; k += 2 * simd_width) ris_light_lanes<vfloat2>(views.geom, views.lights, est, pass, *d, k);
        for (; k < n; k += simd_width) ris_light_lanes<vfloat>(views.geom, views.lights, est, pass, *d, k);
        for (int i = 0; i < max_tile_lanes; ++i) {  // the next candidate's numbers
          const float u[4] = {std::generate_canonical<float, 24>(rng), std::generate_canonical<float, 24>(rng),
                              std::generate_canonical<float, 24>(rng), std::generate_canonical<float, 24>(rng)};
          for (TileBuffers* t : all) {
            t->tech.u0[i] = std::min(u[0], 0x1.fffffep-1f);
            t->tech.u1[i] = std::min(u[1], 0x1.fffffep-1f);
            t->tech.u2[i] = std::min(u[2], 0x1.fffffep-1f);
            t->tech.u3[i] = std::min(u[3], 0x1.fffffep-1f);
          }
        }
      }
      // a BSDF candidate: cosine directions, their hits made up (some on every emitter
      // triangle and the emitting sphere, some on the floor, some missed)
      for (int k = 0; k < n; ++k) sample_bsdf_lanes<float>(views.geom, est, *a, k);
      for (int k = 0; k < n; ++k) {
        RayHit16& h = a->bounce[k / packet_width];
        const int l = k % packet_width;
        const uint32_t r = rng() % 8;
        h.geomID[l] = r < 5 ? 1u : r == 5 ? static_cast<uint32_t>(s.meshes.size()) : r == 6 ? 0u : ~0u;  // (5: the first sphere)
        h.primID[l] = r < 5 ? r : 0u;
        h.ray.tfar[l] = 0.2f + static_cast<float>(rng() % 100) * 0.05f;
      }
      for (TileBuffers* t : {b.get(), d.get()}) {
        std::memcpy(t->bounce, a->bounce, sizeof(a->bounce));
        std::memcpy(t->tech.valid, a->tech.valid, sizeof(a->tech.valid));
        std::memcpy(t->tech.pdf, a->tech.pdf, sizeof(a->tech.pdf));
        std::memcpy(t->tech.beta_r, a->tech.beta_r, sizeof(a->tech.beta_r));
        std::memcpy(t->tech.beta_g, a->tech.beta_g, sizeof(a->tech.beta_g));
        std::memcpy(t->tech.beta_b, a->tech.beta_b, sizeof(a->tech.beta_b));
      }
      for (int k = 0; k < n; k += simd_width) ris_bsdf_lanes<vfloat>(views.geom, views.lights, est, *a, k);
      for (int k = 0; k < n; ++k) ris_bsdf_lanes<float>(views.geom, views.lights, est, *b, k);
      for (int k = 0; k < n; k += simd_width) ris_bsdf_lanes<vfloat>(views.geom, views.lights, est, *d, k);
      for (TileBuffers* t : all) t->points.count = 200;
      for (int k = 0; k < n; k += simd_width) ris_finish_lanes<vfloat>(*a, k);
      for (int k = 0; k < n; ++k) ris_finish_lanes<float>(*b, k);
      for (int k = 0; k < n; k += simd_width) ris_finish_lanes<vfloat>(*d, k);
      int kept = 0;
      for (int k = 0; k < n; ++k) kept += b->tech.valid[k] != 0;
      EXPECT_GT(kept, 50) << name();
      for (const TileBuffers* t : {a.get(), d.get()}) {
        expect_same_floats(t->ris.wsum, b->ris.wsum, n, name);
        expect_same_floats(t->ris.cr, b->ris.cr, n, name);
        expect_same_floats(t->ris.cg, b->ris.cg, n, name);
        expect_same_floats(t->ris.cb, b->ris.cb, n, name);
        expect_same_floats(t->tech.cr, b->tech.cr, n, name);
        expect_same_floats(t->tech.cg, b->tech.cg, n, name);
        expect_same_floats(t->tech.cb, b->tech.cb, n, name);
        EXPECT_EQ(t->stats.rejected_light, b->stats.rejected_light) << name();
        EXPECT_EQ(t->stats.rejected_bsdf, b->stats.rejected_bsdf) << name();
        for (int k = 0; k < n; ++k) {
          ASSERT_EQ(t->tech.valid[k], b->tech.valid[k]) << name() << " lane " << k;
          if (!b->tech.valid[k]) continue;
          const Ray16 &ra = t->shadow[k / packet_width], &rb = b->shadow[k / packet_width];
          const int l = k % packet_width;
          for (auto f : {&Ray16::org_x, &Ray16::org_y, &Ray16::org_z, &Ray16::dir_x, &Ray16::dir_y, &Ray16::dir_z,
                         &Ray16::tfar})
            ASSERT_TRUE(std::memcmp(&(ra.*f)[l], &(rb.*f)[l], sizeof(float)) == 0) << name() << " lane " << k;
        }
      }
    }
}

// Table lookups by permutes (small: 32 entries, medium: 128) and by gathers give every
// lane the table's entry.
TEST(Lanes, TableLookupsEqualScalar) {
  std::mt19937 rng(9);
  alignas(64) float tf[medium_table_size];
  alignas(64) int32_t ti[medium_table_size];
  for (int e = 0; e < medium_table_size; ++e) {
    tf[e] = static_cast<float>(rng()) * 0x1p-20f - 1000.f;
    ti[e] = static_cast<int32_t>(rng());
  }
  alignas(64) int32_t idx[simd_width];
  alignas(64) float of[simd_width];
  alignas(64) int32_t oi[simd_width];
  for (int trial = 0; trial < 2000; ++trial) {
    for (int tier : {tier_small, tier_medium, tier_gather}) {
      const int size = tier == tier_small ? small_table_size : medium_table_size;
      for (int l = 0; l < simd_width; ++l)  // every entry in turn, then random ones
        idx[l] = trial * simd_width + l < size ? trial * simd_width + l : static_cast<int32_t>(rng() % size);
      const vint i = vint::load_aligned(idx);
      if (tier == tier_small) {
        store(of, lget<tier_small>(tf, i));
        store(oi, lget<tier_small>(ti, i));
      } else if (tier == tier_medium) {
        store(of, lget<tier_medium>(tf, i));
        store(oi, lget<tier_medium>(ti, i));
      } else {
        store(of, lget<tier_gather>(tf, i));
        store(oi, lget<tier_gather>(ti, i));
      }
      for (int l = 0; l < simd_width; ++l) {
        ASSERT_EQ(of[l], tf[idx[l]]) << "tier " << tier << " index " << idx[l];
        ASSERT_EQ(oi[l], ti[idx[l]]) << "tier " << tier << " index " << idx[l];
      }
    }
  }
  EXPECT_EQ(table_tier(1), tier_small);
  EXPECT_EQ(table_tier(32), tier_small);
  EXPECT_EQ(table_tier(33), tier_medium);
  EXPECT_EQ(table_tier(128), tier_medium);
  EXPECT_EQ(table_tier(129), tier_gather);
}

TEST(Lanes, CameraRays) {
  Scene s = all_lights_scene();
  SceneViews views = build_views(s, LightPick::power);
  auto a = std::make_unique<TileBuffers>();
  auto b = std::make_unique<TileBuffers>();
  for (int i = 0; i < 256; ++i) {
    a->lanes.fx[i] = b->lanes.fx[i] = static_cast<float>(i % 16);
    a->lanes.fy[i] = b->lanes.fy[i] = static_cast<float>(i / 16);
    a->tech.u0[i] = b->tech.u0[i] = static_cast<float>((i * 37) % 101) / 101.f;
    a->tech.u1[i] = b->tech.u1[i] = static_cast<float>((i * 53) % 97) / 97.f;
  }
  for (int i = 0; i < 256; i += simd_width) generate_lanes<vfloat>(views.camera, *a, i);
  for (int i = 0; i < 256; ++i) generate_lanes<float>(views.camera, *b, i);
  for (int p = 0; p < 16; ++p)
    for (int l = 0; l < 16; ++l) {
      ASSERT_EQ(a->cam[p].ray.dir_x[l], b->cam[p].ray.dir_x[l]);
      ASSERT_EQ(a->cam[p].ray.dir_y[l], b->cam[p].ray.dir_y[l]);
      ASSERT_EQ(a->cam[p].ray.dir_z[l], b->cam[p].ray.dir_z[l]);
    }
}

TEST(Lanes, SobolFastMatchesGeneratorMatrix) {
  for (uint64_t i = 0; i < (1ull << 32); i += 65521) {
    const uint32_t x = static_cast<uint32_t>(i);
    ASSERT_EQ(sobol_dim1(x), sobol_dim1_reference(x)) << x;
  }
  // first points of the (0,2)-sequence: every elementary interval of 2^k points holds one
  for (int k = 1; k <= 10; ++k) {
    const uint32_t n = 1u << k;
    for (int a = 0; a <= k; ++a) {
      std::vector<int> count(n, 0);
      for (uint32_t i = 0; i < n; ++i) {
        const uint32_t xs = a == 0 ? 0 : sobol_dim0(i) >> (32 - a), ys = a == k ? 0 : sobol_dim1(i) >> (32 - (k - a));
        ++count[(xs << (k - a)) | ys];
      }
      for (int c : count) ASSERT_EQ(c, 1) << "k " << k << " a " << a;
    }
  }
}

TEST(Lanes, FusedSobolEqualsTextbookComposition) {
  for (uint32_t key : {1u, 0x9e3779b9u, 12345u})
    for (uint32_t index = 0; index < 5000; index += 7) {
      const uint32_t i = nested_uniform_scramble(index, key);
      const uint32_t u = nested_uniform_scramble(sobol_dim0(i), hash_u32(key ^ 0x1b873593u));
      const uint32_t v = nested_uniform_scramble(sobol_dim1_reference(i), hash_u32(key ^ 0xcc9e2d51u));
      uint32_t fu, fv;
      sobol_pair_bits(reverse_bits(index), key, fu, fv);
      ASSERT_EQ(u, fu);
      ASSERT_EQ(v, fv);
    }
}

// The whole camera-hit stage (hit points, error offsets, compaction, emitters seen
// directly, textures, rejections, one-sample choice) against the scalar reference.
TEST(Lanes, CameraHitsEqualScalar) {
  Scene s = all_lights_scene(true);
  // curves of each type across the view (geometry kind curve: the point on the ray)
  for (int i = 0; i < 3; ++i) {
    Curves c;
    c.name = "curve";
    c.type = static_cast<CurveType>(i);
    c.points.assign(16, 0.08f);  // x y z r per control point
    if (c.type == CurveType::ribbon) c.normals.assign(12, 0.f);
    for (int k = 0; k < 4; ++k) {
      c.points[size_t(4 * k)] = -2.f + 4.f * k / 3.f;
      c.points[size_t(4 * k + 1)] = 0.4f + 0.3f * i;
      c.points[size_t(4 * k + 2)] = 1.f - 0.3f * k;
      if (c.type == CurveType::ribbon) {
        c.normals[size_t(3 * k + 1)] = 0.6f;
        c.normals[size_t(3 * k + 2)] = 0.8f;
      }
    }
    s.curves.push_back(c);
  }
  // an instanced object (a mesh with vertex normals, a sphere and a curve, in object space)
  // placed twice across the view, once mirrored and squashed: the lanes place the point,
  // its error bound and its normal by each lane's instance
  s.objects.push_back("thing");
  {
    Mesh m;
    m.name = "instanced";
    m.material = 0;
    test::add_quad(m, {-0.6f, 0, -0.6f}, {0, 0.5f, 1.2f}, {1.2f, 0, 0});  // tilted: its normal is no axis of the placements
    m.normals = {0, 1, 0, 0.3f, 0.9f, 0, 0, 1, 0.2f, 0, 1, 0};
    m.object = 0;
    s.meshes.push_back(m);
    Sphere sp;
    sp.center = {0, 0.4f, 0};
    sp.radius = 0.3f;
    sp.material = 0;
    sp.object = 0;
    s.spheres.push_back(sp);
    Curves c = test::straight_curve(CurveType::flat, 0.3f, 0.6f, 0.03f);
    c.object = 0;
    s.curves.push_back(c);
    Instance a;
    a.world_from_object[0][3] = -0.4f;
    a.world_from_object[1][3] = 0.1f;
    a.world_from_object[2][3] = 2.f;
    s.instances.push_back(a);
    Instance b;
    b.world_from_object[0][0] = -1.5f;  // mirrored
    b.world_from_object[1][1] = 0.7f;
    b.world_from_object[0][2] = 0.3f;
    b.world_from_object[0][3] = 1.1f;
    b.world_from_object[1][3] = 0.1f;
    b.world_from_object[2][3] = 1.5f;
    s.instances.push_back(b);
  }
  finalize_scene(s);
  SceneViews views = build_views(s, LightPick::power);
  ASSERT_TRUE(views.geom.has_textures);
  ASSERT_TRUE(views.geom.has_instances);
  // the flattened triangle table holds every mesh's vertices and lights
  for (size_t m = 0; m < s.meshes.size(); ++m)
    for (size_t t = 0; t < s.meshes[m].triangle_count(); ++t) {
      const int32_t tri = views.geom.geom_first[m] + static_cast<int32_t>(t);
      for (int k = 0; k < 9; ++k)
        ASSERT_EQ(views.geom.tri_pos[9 * tri + k], s.meshes[m].positions[3 * s.meshes[m].indices[3 * t + k / 3] + k % 3]);
      ASSERT_EQ(views.geom.tri_light[tri], s.meshes[m].prim_light.empty() ? -1 : s.meshes[m].prim_light[t]);
    }
  Accel accel(s);
  for (MisMode mode : {MisMode::multi, MisMode::one})
    for (int lanes : {256, 250}) {
      auto a = std::make_unique<TileBuffers>();
      for (int i = 0; i < 256; ++i) {
        a->lanes.fx[i] = static_cast<float>(i % 16);
        a->lanes.fy[i] = static_cast<float>(i / 16);
        a->lanes.pixel[i] = static_cast<uint32_t>(i);
      }
      Estimator est;
      est.mode = mode;
      generate(views.camera, est, 0, SampleLayout::camera, 256, *a);
      for (int p = 0; p < 16; ++p) accel.intersect16(a->lanes.cam_valid + p * packet_width, a->cam[p], true);
      int curve_hits = 0;
      for (int i = 0; i < 256; ++i)
        curve_hits += a->cam[i / 16].geomID[i % 16] != invalid_id &&
                      a->cam[i / 16].geomID[i % 16] >= s.meshes.size() + s.spheres.size();
      ASSERT_GT(curve_hits, 4);
      int inst_hits[2] = {0, 0};
      for (int i = 0; i < 256; ++i)
        if (a->cam[i / 16].geomID[i % 16] != invalid_id && a->cam[i / 16].instID[0][i % 16] != invalid_id)
          ++inst_hits[a->cam[i / 16].instID[0][i % 16]];
      ASSERT_GT(inst_hits[0], 4);
      ASSERT_GT(inst_hits[1], 4);
      // degenerate hits: counted as rejected, no shading point
      for (int i : {3, 40, 41, 130, 200}) {
        RayHit16& p = a->cam[i / 16];
        p.Ng_x[i % 16] = p.Ng_y[i % 16] = p.Ng_z[i % 16] = 0.f;
      }
      a->cam[7].ray.tfar[9] = std::numeric_limits<float>::infinity();
      // cached sampler keys of pairs 1..4, compacted with the shading points
      a->keys.keyed = (1u << SamplerKeys::pairs) - 1u;
      for (int p = 0; p < SamplerKeys::pairs; ++p) make_pair_keys(est.seed, a->lanes.pixel, p, 256, a->keys.lane_keys(p));
      auto b = std::make_unique<TileBuffers>(*a);
      auto c = std::make_unique<TileBuffers>(*a);
      camera_hits<true, vfloat>(views.geom, views.lights, est, 0, SampleLayout{}.technique_choice(), lanes, *a);
      camera_hits<true, float>(views.geom, views.lights, est, 0, SampleLayout{}.technique_choice(), lanes, *b);
      // without the flattened triangle table (large scenes): the same points, bit for bit
      GeomView unflat = views.geom;
      unflat.flat_triangles = false;
      camera_hits<true, vfloat>(unflat, views.lights, est, 0, SampleLayout{}.technique_choice(), lanes, *c);
      ASSERT_EQ(c->points.count, a->points.count);
      for (auto arr : {&ShadingPoints::px, &ShadingPoints::py, &ShadingPoints::pz, &ShadingPoints::eps, &ShadingPoints::nx})
        ASSERT_EQ(std::memcmp(c->points.*arr, a->points.*arr, sizeof(float) * size_t(a->points.count)), 0);
      auto name = [&] { return std::string(mode == MisMode::one ? "one" : "multi") + " lanes " + std::to_string(lanes); };
      ASSERT_EQ(a->points.count, b->points.count) << name();
      ASSERT_EQ(a->stats.rejected_camera, b->stats.rejected_camera) << name();
      EXPECT_GE(a->stats.rejected_camera, 5u) << name();
      const int n = a->points.count, padded = packet_padded(n);
      const struct {
        const char* what;
        float (ShadingPoints::*arr)[lane_array];
      } arrays[] = {{"px", &ShadingPoints::px}, {"py", &ShadingPoints::py}, {"pz", &ShadingPoints::pz},
                    {"nx", &ShadingPoints::nx}, {"ny", &ShadingPoints::ny}, {"nz", &ShadingPoints::nz},
                    {"eps", &ShadingPoints::eps}, {"ar", &ShadingPoints::ar}, {"ag", &ShadingPoints::ag},
                    {"ab", &ShadingPoints::ab}};
      for (const auto& f : arrays)
        expect_same_floats(a->points.*f.arr, b->points.*f.arr, padded, [&] { return name() + " " + f.what; });
      for (int k = 0; k < padded; ++k) {
        ASSERT_EQ(a->points.pixel[k], b->points.pixel[k]) << name() << " point " << k;
        ASSERT_EQ(a->points.lane[k], b->points.lane[k]) << name() << " point " << k;
      }
      // shade_of inverts the compaction: lane i has point k exactly where points.lane[k] == i
      for (int i = 0; i < 256; ++i) {
        ASSERT_EQ(a->lanes.shade_of[i], b->lanes.shade_of[i]) << name() << " lane " << i;
        if (a->lanes.shade_of[i] >= 0) {
          ASSERT_EQ(a->points.lane[a->lanes.shade_of[i]], i) << name() << " lane " << i;
        }
      }
      for (int k = 0; k < n; ++k) ASSERT_EQ(a->lanes.shade_of[a->points.lane[k]], k) << name() << " point " << k;
      // an instance's triangle hits: the point on the placed triangle's plane and the
      // normal across its edges (the normal turned by the inverse transpose, not the matrix)
      int placed = 0;
      for (int k = 0; k < n; ++k) {
        const int i = a->points.lane[k];
        const RayHit16& p = a->cam[i / 16];
        const uint32_t g = p.geomID[i % 16], inst = p.instID[0][i % 16];
        if (inst == invalid_id || !is_mesh(views.geom, int32_t(g))) continue;
        const uint32_t* idx = views.geom.indices[g] + 3 * p.primID[i % 16];
        vec3f w[3];
        for (int c = 0; c < 3; ++c) {
          const float* q = views.geom.positions[g] + 3 * idx[c];
          w[c] = instance_point(views.geom, int32_t(inst), {q[0], q[1], q[2]});
        }
        const vec3f nn{a->points.nx[k], a->points.ny[k], a->points.nz[k]};
        const vec3f e1 = w[1] - w[0], e2 = w[2] - w[0], x{a->points.px[k], a->points.py[k], a->points.pz[k]};
        EXPECT_LT(std::fabs(dot(nn, e1)), 1e-5f * length(e1)) << name() << " point " << k;
        EXPECT_LT(std::fabs(dot(nn, e2)), 1e-5f * length(e2)) << name() << " point " << k;
        EXPECT_LT(std::fabs(dot(nn, x - w[0])), 1e-5f) << name() << " point " << k;
        ++placed;
      }
      EXPECT_GT(placed, 4) << name();
      // each point's cached keys are its pixel's, and the pairs drawn from them are too
      for (int p = 1; p < SamplerKeys::pairs; ++p) {
        std::vector<uint32_t> key(padded), ku(padded), kv(padded);
        make_pair_keys(est.seed, a->points.pixel, p, padded, PairKeys{key.data(), ku.data(), kv.data()});
        const PairKeys pa = a->keys.point_keys(p), pb = b->keys.point_keys(p);
        for (int k = 0; k < padded; ++k) {
          ASSERT_EQ(pa.key[k], key[k]) << name() << " pair " << p << " point " << k;
          ASSERT_EQ(pa.ku[k], ku[k]) << name() << " pair " << p << " point " << k;
          ASSERT_EQ(pa.kv[k], kv[k]) << name() << " pair " << p << " point " << k;
          ASSERT_EQ(pb.key[k], key[k]) << name() << " scalar, pair " << p << " point " << k;
        }
        std::vector<float> u1(padded), v1(padded), u2(padded), v2(padded);
        point_pairs(est, *a, 3, p, padded, u1.data(), v1.data());
        sample_pairs(est.sampler, est.seed, a->points.pixel, 3, est.spp, p, padded, u2.data(), v2.data());
        ASSERT_EQ(std::memcmp(u1.data(), u2.data(), padded * sizeof(float)), 0) << name() << " pair " << p;
        ASSERT_EQ(std::memcmp(v1.data(), v2.data(), padded * sizeof(float)), 0) << name() << " pair " << p;
      }
      expect_same_floats(a->lanes.Lr, b->lanes.Lr, 256, name);
      expect_same_floats(a->lanes.Lg, b->lanes.Lg, 256, name);
      expect_same_floats(a->lanes.Lb, b->lanes.Lb, 256, name);
      if (mode == MisMode::one) {
        expect_same_floats(a->tech.u0, b->tech.u0, padded, name);
        expect_same_floats(a->points.choose_light, b->points.choose_light, padded, name);
      }
      // the scene exercises every path: spheres, emitters seen from the front, textures
      int hits = 0, spheres = 0, emitted = 0, textured = 0;
      for (int i = 0; i < lanes; ++i) {
        const uint32_t g = a->cam[i / 16].geomID[i % 16];
        hits += g != invalid_id;
        spheres += g != invalid_id && views.geom.geom_kind[g] == static_cast<int32_t>(GeomKind::sphere);
        textured += g == 2;
        emitted += a->lanes.Lr[i] > 0.f;
      }
      // and both the broadcast path (one triangle per batch) and the gathers
      int one = 0, mixed = 0;
      for (int i = 0; i < lanes; i += simd_width) {
        std::set<std::pair<uint32_t, uint32_t>> tris;
        for (int k = i; k < i + simd_width; ++k)
          if (a->cam[k / 16].geomID[k % 16] != invalid_id) tris.insert({a->cam[k / 16].geomID[k % 16], a->cam[k / 16].primID[k % 16]});
        one += tris.size() == 1;
        mixed += tris.size() > 1;
      }
      EXPECT_GT(one, 0) << name();
      EXPECT_GT(mixed, 0) << name();
      EXPECT_EQ(n, hits - static_cast<int>(a->stats.rejected_camera)) << name();
      EXPECT_GT(hits, 100) << name();
      EXPECT_GT(spheres, 0) << name();
      EXPECT_GT(emitted, 0) << name();
      EXPECT_GT(textured, 0) << name();
      // each textured point's albedo is its material's times the texel its uv falls in
      // (nearest, wrap; the wall's uv are (0, 0) (2.5, 0) (2.5, 1.5) (0, 1.5))
      const Texture& tex = s.textures[0];
      int checked = 0;
      for (int k = 0; k < n; ++k) {
        const int i = a->points.lane[k];
        const RayHit16& p = a->cam[i / 16];
        if (p.geomID[i % 16] != 2) continue;
        const uint32_t* idx = &s.meshes[2].indices[3 * p.primID[i % 16]];
        const float bu = p.u[i % 16], bv = p.v[i % 16];
        float uu = 0, vv = 0;
        const float w[3] = {1.f - bu - bv, bu, bv};
        for (int c = 0; c < 3; ++c) {
          uu += w[c] * s.meshes[2].uvs[2 * idx[c]];
          vv += w[c] * s.meshes[2].uvs[2 * idx[c] + 1];
        }
        uu -= std::floor(uu);
        vv -= std::floor(vv);
        const int tx = std::clamp(static_cast<int>(uu * 4), 0, 3), ty = std::clamp(static_cast<int>((1 - vv) * 4), 0, 3);
        const float* texel = &tex.rgb[3 * (ty * 4 + tx)];
        // the texel replaces the material's constant (0.9, 0.8, 0.7 here)
        EXPECT_EQ(a->points.ar[k], texel[0]) << name() << " point " << k;
        EXPECT_EQ(a->points.ag[k], texel[1]) << name() << " point " << k;
        EXPECT_EQ(a->points.ab[k], texel[2]) << name() << " point " << k;
        ++checked;
      }
      EXPECT_GT(checked, 0) << name();
    }
}

// In a closed room every camera ray hits, so shading point k is tile lane k and the points
// read the lanes' cached keys without copying them; the pairs are still their pixels'.
TEST(Lanes, CachedKeysWhereEveryLaneHits) {
  Scene s = load_scene("built-in:cornell");
  SceneViews views = build_views(s, LightPick::power);
  Accel accel(s);
  auto a = std::make_unique<TileBuffers>();
  for (int i = 0; i < 256; ++i) {
    a->lanes.fx[i] = static_cast<float>(200 + i % 16);
    a->lanes.fy[i] = static_cast<float>(200 + i / 16);
    a->lanes.pixel[i] = static_cast<uint32_t>(200 + i / 16) * 512u + static_cast<uint32_t>(200 + i % 16);
  }
  Estimator est;
  est.seed = 3;
  a->keys.keyed = (1u << SamplerKeys::pairs) - 1u;
  for (int p = 0; p < SamplerKeys::pairs; ++p) make_pair_keys(est.seed, a->lanes.pixel, p, 256, a->keys.lane_keys(p));
  generate(views.camera, est, 0, SampleLayout::camera, 256, *a);
  for (int p = 0; p < 16; ++p) accel.intersect16(a->lanes.cam_valid + p * packet_width, a->cam[p], true);
  camera_hits<true, vfloat>(views.geom, views.lights, est, 0, SampleLayout{}.technique_choice(), 256, *a);
  ASSERT_EQ(a->points.count, 256);
  EXPECT_TRUE(a->keys.points_are_lanes);
  for (int p = 1; p < SamplerKeys::pairs; ++p) {
    std::vector<float> u1(256), v1(256), u2(256), v2(256);
    point_pairs(est, *a, 5, p, 256, u1.data(), v1.data());
    sample_pairs(est.sampler, est.seed, a->points.pixel, 5, est.spp, p, 256, u2.data(), v2.data());
    ASSERT_EQ(std::memcmp(u1.data(), u2.data(), 256 * sizeof(float)), 0) << "pair " << p;
    ASSERT_EQ(std::memcmp(v1.data(), v2.data(), 256 * sizeof(float)), 0) << "pair " << p;
  }
}

// The MIS weight stage on traced bounce rays: the SIMD emitter queue (gathers of the
// triangle and sphere light tables, front test, compress stores) and the radiance it adds
// equal the scalar reference, with rays that miss, hit plain surfaces, hit emitters from
// behind and from the front, triangles, parallelograms and the sphere; and on two-panels
// (rectangles only) the rectangle pipeline's queue (no sphere tests) against the scalar
// general one.
TEST(Lanes, EmitterQueueEqualScalar) {
  for (bool rects : {false, true}) {
  Scene s = rects ? builtin_scene("two-panels") : all_lights_scene(true);
  if (rects) finalize_scene(s);
  SceneViews views = build_views(s, LightPick::power);
  ASSERT_EQ(views.all_rects(), rects);
  Accel accel(s);
  std::mt19937 rng(5);
  int queued = 0, two_sided_hits = 0;
  for (Strategy strategy : {Strategy::mis, Strategy::bsdf})
    for (Heuristic heuristic : {Heuristic::power, Heuristic::optimal})
    for (int count : {200, 256, 13}) {
      if (heuristic == Heuristic::optimal && strategy != Strategy::mis) continue;
      Estimator est;
      est.strategy = strategy;
      est.heuristic = heuristic;
      auto a = std::make_unique<TileBuffers>();
      fill_shading_points(*a, rng, count);
      for (int k = 0; k < max_tile_lanes; ++k) {  // points under the sources, facing them
        a->points.py[k] = 0.f;
        a->points.nx[k] = a->points.nz[k] = 0.f;
        a->points.ny[k] = 1.f;
        if (!rects && k % 4 == 0) {  // and some above the two-sided triangle (y = 0.2), facing its back
          a->points.px[k] = 2.f + 0.1f * a->points.px[k];
          a->points.py[k] = 0.4f;
          a->points.pz[k] = -0.6f + 0.1f * a->points.pz[k];
          a->points.ny[k] = -1.f;
        }
      }
      sample_bsdf(views.geom, est, 0, SampleLayout{}.bsdf(0), SampleLayout{}.bsdf_lobe(0), *a);
      const int padded = packet_padded(count);
      for (int p = 0; p < padded / packet_width; ++p) accel.intersect16(a->tech.valid + p * packet_width, a->bounce[p], false);
      std::fill_n(a->radiance.r, max_tile_lanes, 0.f);
      std::fill_n(a->radiance.g, max_tile_lanes, 0.f);
      std::fill_n(a->radiance.b, max_tile_lanes, 0.f);
      std::fill_n(a->opt.pl, max_tile_lanes, 0.f);  // (optimal MIS: what weight_queue fills)
      auto b = std::make_unique<TileBuffers>(*a);
      if (rects) weight_bounce<vfloat, kind_area | kind_rects>(views.geom, views.lights, est, 1.f, 1.f, *a);
      else weight_bounce<vfloat>(views.geom, views.lights, est, 1.f, 1.f, *a);
      weight_bounce<float>(views.geom, views.lights, est, 1.f, 1.f, *b);
      auto name = [&] { return describe(est) + " count " + std::to_string(count) + (rects ? " rects" : ""); };
      ASSERT_EQ(a->queue.count, b->queue.count) << name();
      const int nq = a->queue.count;
      queued += nq;
      for (auto arr : {&EmitterHitQueue::x, &EmitterHitQueue::y, &EmitterHitQueue::z, &EmitterHitQueue::dx,
                       &EmitterHitQueue::dy, &EmitterHitQueue::dz, &EmitterHitQueue::dist, &EmitterHitQueue::beta_r,
                       &EmitterHitQueue::beta_g, &EmitterHitQueue::beta_b, &EmitterHitQueue::pdf})
        expect_same_floats(a->queue.*arr, b->queue.*arr, nq, name);
      for (int j = 0; j < nq; ++j) {
        ASSERT_EQ(a->queue.light[j], b->queue.light[j]) << name() << " entry " << j;
        ASSERT_EQ(a->queue.point[j], b->queue.point[j]) << name() << " entry " << j;
      }
      expect_same_floats(a->radiance.r, b->radiance.r, count, name);
      expect_same_floats(a->radiance.g, b->radiance.g, count, name);
      expect_same_floats(a->radiance.b, b->radiance.b, count, name);
      if (heuristic == Heuristic::optimal) {  // the light technique's density of each hit, for optimal MIS
        expect_same_floats(a->tech.pl, b->tech.pl, nq, name);
        for (int j = 0; j < nq; ++j) expect_same_floats(&a->opt.pl[a->queue.point[j]], &b->opt.pl[b->queue.point[j]], 1, name);
      }
      // every queued entry is a traced ray that hit the front of an emitter, and every such
      // ray is queued; planar fronts from the scene's own sources (two-sided: either side)
      int expected = 0;
      for (int k = 0; k < count; ++k) {
        const RayHit16& r = b->bounce[k / packet_width];
        const int l = k % packet_width;
        if (!b->tech.valid[k]) continue;
        const int32_t li = light_of_hit(views.geom, r.geomID[l], r.primID[l]);
        if (li < 0) continue;
        const Light& src = s.lights[static_cast<size_t>(li)];
        const vec3f d{r.ray.dir_x[l], r.ray.dir_y[l], r.ray.dir_z[l]};
        if (src.type == LightKind::sphere)
          expected += light_front(views.lights, li, r.ray.org_x[l], r.ray.org_y[l], r.ray.org_z[l], d.x, d.y, d.z);
        else {
          expected += src.two_sided || dot(d, cross(src.e1, src.e2)) < 0.f;
          two_sided_hits += src.two_sided && dot(d, cross(src.e1, src.e2)) > 0.f;
        }
      }
      EXPECT_EQ(nq, expected) << name();
    }
  EXPECT_GT(queued, 20);
  if (!rects) {
    EXPECT_GT(two_sided_hits, 5);  // backs of the two-sided source were seen
  }
  }
}

// The escaped-ray stage (wave/escaped.h): camera and bounce rays that leave the scene see
// the sky, MIS-weighted against light sampling of it; every lane equals the scalar
// reference, with every pick (the BVH's pmf reads the point) and the MIS-weight AOV.
TEST(Lanes, EscapedRaysEqualScalar) {
  Scene s = all_lights_scene(true, true);
  Accel accel(s);
  std::mt19937 rng(9);
  int escaped = 0;
  for (LightPick pick : {LightPick::power, LightPick::uniform, LightPick::bvh})
    for (Strategy strategy : {Strategy::mis, Strategy::bsdf, Strategy::light})
      for (MisMode mode : {MisMode::multi, MisMode::one})
        for (int count : {200, 13}) {
          SceneViews views = build_views(s, pick);
          ASSERT_EQ(views.lights.sky_count, 2);  // the constant sky and the map
          views.lights.sky_dist = strategy == Strategy::mis ? sky_dist_compensated : sky_dist_full;
          Estimator est;
          est.pick = pick;
          est.strategy = strategy;
          est.mode = mode;
          est.heuristic = mode == MisMode::one ? Heuristic::balance : Heuristic::power;
          if (strategy == Strategy::mis && count == 13) est.heuristic = Heuristic::optimal;  // (wave/optimal_mis.h)
          est.aov_mis_weight = true;
          auto a = std::make_unique<TileBuffers>();
          fill_shading_points(*a, rng, count);
          for (int k = 0; k < max_tile_lanes; ++k) {  // on the floor, facing up: half the rays escape
            a->points.py[k] = 0.f;
            a->points.nx[k] = a->points.nz[k] = 0.f;
            a->points.ny[k] = 1.f;
            a->points.choose_light[k] = k % 3 == 0 ? 1.f : 0.f;
          }
          sample_bsdf(views.geom, est, 0, SampleLayout{}.bsdf(0), SampleLayout{}.bsdf_lobe(0), *a);
          const int padded = packet_padded(count);
          for (int p = 0; p < padded / packet_width; ++p) accel.intersect16(a->tech.valid + p * packet_width, a->bounce[p], false);
          // the same rays as camera rays
          for (int p = 0; p < padded / packet_width; ++p) a->cam[p] = a->bounce[p];
          std::copy_n(a->tech.valid, padded, a->lanes.cam_valid);
          std::fill_n(a->lanes.Lr, max_tile_lanes, 0.f);
          std::fill_n(a->lanes.Lg, max_tile_lanes, 0.f);
          std::fill_n(a->lanes.Lb, max_tile_lanes, 0.f);
          std::fill_n(a->lanes.wsum, max_tile_lanes, 0.f);
          std::fill_n(a->lanes.wcnt, max_tile_lanes, 0.f);
          std::fill_n(a->radiance.r, max_tile_lanes, 0.f);
          std::fill_n(a->radiance.g, max_tile_lanes, 0.f);
          std::fill_n(a->radiance.b, max_tile_lanes, 0.f);
          for (int k = 0; k < max_tile_lanes; ++k) a->points.lane[k] = k;
          // no point's sample has met an emitter yet (as optimal_bsdf_clear leaves them)
          std::fill_n(a->opt.hit, max_tile_lanes, 0);
          for (float* arr : {a->opt.pl, a->opt.ur, a->opt.ug, a->opt.ub, a->opt.wb}) std::fill_n(arr, max_tile_lanes, 0.f);
          auto b = std::make_unique<TileBuffers>(*a);
          const bool chosen_only = mode == MisMode::one;
          escaped_camera<vfloat>(views.lights, *a, count);
          escaped_camera<float>(views.lights, *b, count);
          escaped_bounce<vfloat, true>(views.lights, est, 1.f, 1.f, *a, chosen_only);
          escaped_bounce<float, true>(views.lights, est, 1.f, 1.f, *b, chosen_only);
          auto name = [&] { return describe(est) + " count " + std::to_string(count); };
          expect_same_floats(a->lanes.Lr, b->lanes.Lr, count, name);
          expect_same_floats(a->lanes.Lb, b->lanes.Lb, count, name);
          expect_same_floats(a->radiance.r, b->radiance.r, count, name);
          expect_same_floats(a->radiance.g, b->radiance.g, count, name);
          expect_same_floats(a->radiance.b, b->radiance.b, count, name);
          expect_same_floats(a->lanes.wsum, b->lanes.wsum, count, name);
          expect_same_floats(a->lanes.wcnt, b->lanes.wcnt, count, name);
          EXPECT_EQ(a->stats.rejected_bsdf, b->stats.rejected_bsdf) << name();
          if (est.heuristic == Heuristic::optimal)  // what optimal MIS reads of each escaped sample
            for (int k = 0; k < count; ++k) {
              ASSERT_EQ(a->opt.hit[k], b->opt.hit[k]) << name() << " lane " << k;
              if (!b->opt.hit[k]) continue;
              expect_same_floats(&a->opt.pl[k], &b->opt.pl[k], 1, name);
              expect_same_floats(&a->opt.ur[k], &b->opt.ur[k], 1, name);
              expect_same_floats(&a->opt.wb[k], &b->opt.wb[k], 1, name);
            }
          // a camera ray that escaped sees the sky's radiance; one that hit sees none of it
          for (int k = 0; k < count; ++k) {
            const bool out = b->tech.valid[k] && static_cast<int32_t>(b->bounce[k / packet_width].geomID[k % packet_width]) < 0;
            escaped += out;
            // the constant sky's 0.5 and the map's texel along the ray (in the map's frame,
            // nearest texel), times its 0.5
            float want = 0.f;
            if (out) {
              const Light& env = *std::find_if(s.lights.begin(), s.lights.end(), [](const Light& l) { return l.sky_map >= 0; });
              const vec3f d{b->bounce[k / packet_width].ray.dir_x[k % packet_width], b->bounce[k / packet_width].ray.dir_y[k % packet_width],
                            b->bounce[k / packet_width].ray.dir_z[k % packet_width]};
              float pu, pv;
              equal_area_sphere_to_square(vec3f{dot(d, env.e1), dot(d, env.e2), dot(d, env.p0)}, pu, pv);
              want = 0.5f + 0.5f * s.sky_maps[0].texel(static_cast<size_t>(sky_texel(8, pu, pv))).g;
            }
            EXPECT_EQ(b->lanes.Lg[k], want) << name() << " lane " << k;
          }
        }
  EXPECT_GT(escaped, 500);
}

// Film accumulation into the tile's double sums, with non-finite samples and padding.
TEST(Lanes, AccumulateEqualScalar) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> U(0.f, 4.f);
  for (int lanes : {256, 250, 7}) {
    auto a = std::make_unique<TileBuffers>();
    clear_tile_sums(*a, lanes);
    auto b = std::make_unique<TileBuffers>(*a);
    for (int pass = 0; pass < 5; ++pass) {
      for (int i = 0; i < 256; ++i) {
        float r = U(rng), g = U(rng), bl = U(rng);
        if (rng() % 17 == 0) r = std::numeric_limits<float>::quiet_NaN();
        if (rng() % 23 == 0) bl = -std::numeric_limits<float>::infinity();
        if (rng() % 5 == 0) g = 0.f;
        a->lanes.Lr[i] = b->lanes.Lr[i] = r;
        a->lanes.Lg[i] = b->lanes.Lg[i] = g;
        a->lanes.Lb[i] = b->lanes.Lb[i] = bl;
        a->lanes.wsum[i] = b->lanes.wsum[i] = U(rng);
        a->lanes.wcnt[i] = b->lanes.wcnt[i] = static_cast<float>(rng() % 3);
      }
      // shading points of some lanes, compacted in lane order, with their sums
      for (int i = 0, k = 0; i < 256; ++i) {
        a->lanes.shade_of[i] = b->lanes.shade_of[i] = rng() % 4 == 0 ? -1 : k++;
        a->radiance.r[i] = b->radiance.r[i] = U(rng);
        a->radiance.g[i] = b->radiance.g[i] = U(rng);
        a->radiance.b[i] = b->radiance.b[i] = U(rng);
      }
      accumulate_samples<vfloat>(*a, lanes, true);
      accumulate_samples<float>(*b, lanes, true);
    }
    ASSERT_EQ(a->stats.rejected_camera, b->stats.rejected_camera) << lanes;
    EXPECT_GT(a->stats.rejected_camera, 0u) << lanes;
    for (auto arr : {&TileSums::r, &TileSums::g, &TileSums::b, &TileSums::rr,
                     &TileSums::gg, &TileSums::bb, &TileSums::w, &TileSums::wc})
      for (int i = 0; i < lanes; ++i)
        ASSERT_TRUE(std::memcmp(&(a->sums.*arr)[i], &(b->sums.*arr)[i], sizeof(double)) == 0) << lanes << " lane " << i;
    expect_same_floats(a->sums.max, b->sums.max, lanes, [&] { return "max lanes " + std::to_string(lanes); });
  }
}

// Batches whose lanes have no shading point and no emission (camera rays that missed) are
// skipped; the sums, squares, weights and maxima are those of adding every lane.
TEST(Lanes, AccumulateSkipsEmptyBatchesExactly) {
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> U(0.f, 4.f);
  for (bool aov : {false, true}) {
    auto a = std::make_unique<TileBuffers>();
    const int lanes = 200;
    clear_tile_sums(*a, lanes);
    std::vector<double> sr(lanes, 0.0), srr(lanes, 0.0), sw(lanes, 0.0), swc(lanes, 0.0);
    std::vector<float> mx(lanes, 0.f);
    for (int pass = 0; pass < 6; ++pass) {
      for (int i = 0, k = 0; i < 256; ++i) {
        // batch kinds by batch and pass: empty; empty but for emission or a weight; shaded
        const int kind = (i / simd_width + pass) % 4;
        const bool shaded = kind == 3 && rng() % 3 != 0;
        a->lanes.shade_of[i] = shaded ? k++ : -1;
        a->lanes.Lr[i] = kind == 1 && i % 5 == 0 ? U(rng) : 0.f;
        a->lanes.Lg[i] = a->lanes.Lb[i] = 0.f;
        a->lanes.wsum[i] = kind == 2 && i % 7 == 0 ? U(rng) : 0.f;
        a->lanes.wcnt[i] = a->lanes.wsum[i] > 0.f ? 1.f : 0.f;
        if (shaded) {
          a->radiance.r[a->lanes.shade_of[i]] = U(rng);
          a->radiance.g[a->lanes.shade_of[i]] = a->radiance.b[a->lanes.shade_of[i]] = 0.f;
        }
      }
      for (int i = 0; i < lanes; ++i) {  // the reference: every lane added
        const float r = a->lanes.Lr[i] + (a->lanes.shade_of[i] >= 0 ? a->radiance.r[a->lanes.shade_of[i]] : 0.f);
        sr[i] += static_cast<double>(r);
        srr[i] += static_cast<double>(r) * static_cast<double>(r);
        if (aov) {
          sw[i] += static_cast<double>(a->lanes.wsum[i]);
          swc[i] += static_cast<double>(a->lanes.wcnt[i]);
        }
        mx[i] = std::max(mx[i], luminance(r, 0.f, 0.f));
      }
      accumulate_samples<vfloat>(*a, lanes, aov);
    }
    for (int i = 0; i < lanes; ++i) {
      ASSERT_EQ(a->sums.r[i], sr[i]) << "lane " << i;
      ASSERT_EQ(a->sums.rr[i], srr[i]) << "lane " << i;
      ASSERT_EQ(a->sums.g[i], 0.0) << "lane " << i;
      ASSERT_EQ(a->sums.w[i], aov ? sw[i] : 0.0) << "lane " << i;
      ASSERT_EQ(a->sums.wc[i], aov ? swc[i] : 0.0) << "lane " << i;
      ASSERT_EQ(a->sums.max[i], mx[i]) << "lane " << i;
    }
  }
}

// A tile written into a film of zeros with streaming stores (16-pixel rows of 4x4 blocks)
// equals adding it lane by lane, and touches no other pixel.
TEST(Lanes, StreamedTileEqualsAddedTile) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> U(0.f, 4.f);
  const int width = 64, height = 48;
  for (int th : {16, 8, 4})
    for (bool aov : {false, true}) {
      auto tb = std::make_unique<TileBuffers>();
      const int x0 = 32, y0 = 16, lanes = 16 * th;
      // lanes in 4x4 blocks, as run_tile orders them
      int i = 0;
      for (int by = y0; by < y0 + th; by += 4)
        for (int bx = x0; bx < x0 + 16; bx += 4)
          for (int j = 0; j < 16; ++j)
            tb->lanes.pixel[i++] = static_cast<uint32_t>((by + j / 4) * width + bx + j % 4);
      for (int k = 0; k < lanes; ++k) {
        tb->sums.r[k] = U(rng), tb->sums.g[k] = U(rng), tb->sums.b[k] = rng() % 4 ? U(rng) : 0.0;
        tb->sums.rr[k] = U(rng), tb->sums.gg[k] = U(rng), tb->sums.bb[k] = U(rng);
        tb->sums.w[k] = U(rng), tb->sums.wc[k] = static_cast<double>(rng() % 5);
        tb->sums.max[k] = rng() % 3 ? U(rng) : 0.f;
      }
      Film a, b;
      a.reset(width, height);
      b.reset(width, height);
      const FilmSums fa{a.sum.data(), a.sum_sq.data(), a.w_sum.data(), a.w_cnt.data(), a.max_sample.data(), size_t(width)};
      const FilmSums fb{b.sum.data(), b.sum_sq.data(), b.w_sum.data(), b.w_cnt.data(), b.max_sample.data(), size_t(width)};
      add_tile_to_film(*tb, lanes, fa, aov);
      if (!can_stream_tile(x0, 16, th, fb)) GTEST_SKIP() << "no AVX-512 in this build: tiles are always added";
      stream_tile_to_film(*tb, x0, y0, th, fb, aov);
      ASSERT_EQ(std::memcmp(a.sum.data(), b.sum.data(), a.sum.size() * sizeof(double)), 0) << th << " " << aov;
      ASSERT_EQ(std::memcmp(a.sum_sq.data(), b.sum_sq.data(), a.sum.size() * sizeof(double)), 0) << th;
      ASSERT_EQ(std::memcmp(a.w_sum.data(), b.w_sum.data(), a.w_sum.size() * sizeof(double)), 0) << th;
      ASSERT_EQ(std::memcmp(a.w_cnt.data(), b.w_cnt.data(), a.w_cnt.size() * sizeof(double)), 0) << th;
      ASSERT_EQ(std::memcmp(a.max_sample.data(), b.max_sample.data(), a.max_sample.size() * sizeof(float)), 0) << th;
      EXPECT_GT(a.sum[3 * (y0 * width + x0) + 1], 0.0);  // the tile landed where expected
    }
  // not streamable: a tile narrower than 16, an x0 or a width that is not a multiple of 16
  Film f;
  f.reset(40, 8);
  const FilmSums ff{f.sum.data(), f.sum_sq.data(), f.w_sum.data(), f.w_cnt.data(), f.max_sample.data(), 40};
  EXPECT_FALSE(can_stream_tile(0, 16, 8, ff));
  f.reset(64, 8);
  const FilmSums fg{f.sum.data(), f.sum_sq.data(), f.w_sum.data(), f.w_cnt.data(), f.max_sample.data(), 64};
  EXPECT_FALSE(can_stream_tile(8, 16, 8, fg));
  EXPECT_FALSE(can_stream_tile(0, 12, 8, fg));
}

// rcp_nr / rsqrt_nr (an estimate + one Newton step): every SIMD lane equal to the scalar
// function, and within a bound of the correctly rounded 1/x and 1/sqrt(x) from the smallest
// normal float to 1e37 that holds for any estimate within twice the documented error
// (|e| <= 2^-13; the test builds perturb the hardware's by 2^-14 both ways). In ulps of
// the result, whose relative ulp u lies in [2^-24, 2^-23]:
//   rcp:   e^2 <= 2^-26 (<= 0.25 u) + the fma's rounding of 2 - x r (~1, so <= 2^-24 <= 1 u)
//          + the product's (0.5 u) + the reference's (0.5 u): 2.25 ulps;
//   rsqrt: 1.5 e^2 (<= 0.375 u) + (0.5 x) r rounded and multiplied by r (0.5 u) + the fma's
//          rounding (1 u) + the product's (0.5 u) + the reference's (0.5 u): 2.875 ulps.
// (Measured with the hardware estimates of the machines seen: 2 ulps or less.)
TEST(Lanes, ReciprocalEstimatesWithinTheirErrorBound) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> E(-125.f, 122.f);
  std::uniform_real_distribution<float> M(1.f, 2.f);
  alignas(64) float x[simd_width], r[simd_width], s[simd_width];
  double worst_r = 0, worst_s = 0;
  for (int it = 0; it < 20000; ++it) {
    for (int l = 0; l < simd_width; ++l) x[l] = std::ldexp(M(rng), static_cast<int>(E(rng)));
    store(r, rcp_nr(load<vfloat>(x)));
    store(s, rsqrt_nr(load<vfloat>(x)));
    for (int l = 0; l < simd_width; ++l) {
      const float rs = rcp_nr(x[l]), ss = rsqrt_nr(x[l]);
      ASSERT_EQ(std::memcmp(&rs, r + l, 4), 0) << x[l];
      ASSERT_EQ(std::memcmp(&ss, s + l, 4), 0) << x[l];
      const float er = 1.f / x[l], es = static_cast<float>(1.0 / std::sqrt(static_cast<double>(x[l])));
      worst_r = std::max(worst_r, std::fabs(double(rs) - er) / (std::nextafter(er, INFINITY) - er));
      worst_s = std::max(worst_s, std::fabs(double(ss) - es) / (std::nextafter(es, INFINITY) - es));
    }
  }
  EXPECT_LE(worst_r, 2.25);
  EXPECT_LE(worst_s, 2.875);
}
