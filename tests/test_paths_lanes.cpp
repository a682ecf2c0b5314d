// Paths (wave/path.h, wave/surface_hits.h): every SIMD lane of the two kernels paths add
// equals the scalar reference. continue_paths (throughput times the BSDF sample's weight,
// the eta scale of transmissions through a dielectric, Russian roulette, non-finite
// weights rejected and counted) on random shading points; bounce_hits (the bounce rays'
// hits compacted into the next vertex's shading points) on rays traced in a real scene,
// diffuse and with every kind of surface. Both compare every array the kernel writes, bit
// for bit, and bounce_hits is also checked against what compaction must do: the points
// that go on are exactly the traced rays that hit something, in order, with their lane,
// pixel, throughput and eta scale.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "accel/embree.h"
#include "render/views.h"
#include "render_util.h"
#include "wave/generate.h"
#include "wave/path.h"
#include "wave/sample_bsdf.h"
#include "wave/surface_hits.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// Surfaces of several kinds on floor strips (two dielectrics, so that transmissions change
// the eta scale) over a ground, a mesh with shading normals, a glass sphere and a mirror
// sphere on the floor, a back wall and a rectangle source; open above, so that bounce rays
// both hit and miss.
Scene materials_scene() {
  Scene s;
  s.source = "test:paths-lanes-materials";
  Material m;
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.5f, 0.4f}));  // 0
  m.kind = MaterialKind::conductor;
  m.eta_rgb = {0.2f, 0.9f, 1.1f};
  m.k_rgb = {3.9f, 2.4f, 2.1f};
  m.alpha_u.value = m.alpha_v.value = 0.2f;
  s.materials.push_back(m);  // 1: rough conductor
  m.alpha_u.value = m.alpha_v.value = 0.f;
  s.materials.push_back(m);  // 2: mirror
  m = Material{};
  m.kind = MaterialKind::dielectric;
  m.eta = 1.5f;
  s.materials.push_back(m);  // 3: glass
  m.eta = 1.33f;
  m.alpha_u.value = m.alpha_v.value = 0.3f;
  s.materials.push_back(m);  // 4: rough water
  m = Material{};
  m.kind = MaterialKind::thin_dielectric;
  s.materials.push_back(m);  // 5: transmits, but no eta scale
  m = Material{};
  m.kind = MaterialKind::diffuse_transmission;
  m.reflectance = {0.3f, 0.2f, 0.1f};
  m.transmittance = {0.4f, 0.5f, 0.6f};
  s.materials.push_back(m);  // 6
  m = Material{};
  m.kind = MaterialKind::coated_diffuse;
  m.reflectance = {0.2f, 0.4f, 0.6f};
  m.alpha_u.value = m.alpha_v.value = 0.1f;
  s.materials.push_back(m);  // 7
  for (int i = 0; i < static_cast<int>(s.materials.size()); ++i) {
    Mesh f;
    f.name = "floor";
    f.material = i;
    add_quad(f, {-2.f + 0.5f * static_cast<float>(i), 0, -2}, {0, 0, 5}, {0.5f, 0, 0});
    s.meshes.push_back(f);
  }
  Mesh ground;  // under the strips: where the rays they transmit go
  ground.name = "ground";
  ground.material = 0;
  add_quad(ground, {-5, -0.5f, -5}, {0, 0, 10}, {10, 0, 0});
  s.meshes.push_back(ground);
  Mesh bumpy;
  bumpy.name = "bumpy";
  bumpy.material = 1;
  add_quad(bumpy, {-2, 0.01f, 1}, {4, 0, 0}, {0, 0, 1});
  bumpy.normals = {0.3f, 0.95f, 0.f, 0.f, 1.f, 0.f, -0.2f, 0.9f, 0.3f, 0.f, 0.8f, -0.6f};
  s.meshes.push_back(bumpy);
  Mesh wall;
  wall.name = "wall";
  wall.material = 0;
  add_quad(wall, {-3, 0, -2}, {6, 0, 0}, {0, 2, 0});
  s.meshes.push_back(wall);
  Mesh light;
  light.name = "light";
  light.material = 0;
  light.emission = {4, 3, 2};
  add_quad(light, {-0.5f, 1.5f, -0.5f}, {1, 0, 0}, {0, 0, 1});
  s.meshes.push_back(light);
  Sphere glass;
  glass.center = {-0.6f, 0.4f, 0.2f};
  glass.radius = 0.4f;
  glass.material = 3;
  s.spheres.push_back(glass);
  Sphere mirror;
  mirror.center = {0.7f, 0.3f, -0.3f};
  mirror.radius = 0.3f;
  mirror.material = 2;
  s.spheres.push_back(mirror);
  s.camera.width = s.camera.height = 16;
  camera_look_at(s.camera, {0, 2.5f, 3}, {0, 0, -0.2f}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

// Diffuse surfaces only: a floor, a textured wall, a plain sphere, a sphere source and a
// rectangle source, open above.
Scene diffuse_scene() {
  Scene s;
  s.source = "test:paths-lanes-diffuse";
  s.materials.push_back(diffuse_material(Rgb{0.7f, 0.5f, 0.3f}));
  Texture tex;
  tex.name = "checker";
  tex.width = tex.height = 4;
  for (int k = 0; k < 16; ++k) tex.rgb.insert(tex.rgb.end(), {0.2f + 0.05f * k, (k % 3) * 0.4f, ((k / 4 + k) % 2) * 0.9f});
  s.textures.push_back(tex);
  s.materials.push_back(diffuse_material(Rgb{0.9f, 0.8f, 0.7f}, 0));
  Mesh floor;
  floor.name = "floor";
  floor.material = 0;
  add_quad(floor, {-5, 0, -5}, {0, 0, 10}, {10, 0, 0});
  s.meshes.push_back(floor);
  Mesh wall;
  wall.name = "wall";
  wall.material = 1;
  add_quad(wall, {-4, 0, -3}, {8, 0, 0}, {0, 3, 0});
  wall.uvs = {0, 0, 2.5f, 0, 2.5f, 1.5f, 0, 1.5f};
  s.meshes.push_back(wall);
  Mesh side;
  side.name = "side wall";
  side.material = 0;
  add_quad(side, {2.5f, 0, -3}, {0, 3, 0}, {0, 0, 6});
  s.meshes.push_back(side);
  Mesh light;
  light.name = "light";
  light.material = 0;
  light.emission = {3, 2, 1};
  add_quad(light, {-1, 1, -1}, {1, 0, 0}, {0, 0, 1});
  s.meshes.push_back(light);
  Sphere plain;
  plain.center = {-1.2f, 0.5f, 0.5f};
  plain.radius = 0.5f;
  plain.material = 0;
  s.spheres.push_back(plain);
  Sphere lamp;
  lamp.center = {1, 1.5f, 1};
  lamp.radius = 0.3f;
  lamp.material = 0;
  lamp.emission = {5, 5, 5};
  s.spheres.push_back(lamp);
  s.camera.width = s.camera.height = 16;
  camera_look_at(s.camera, {0, 2, 4}, {0, 0, 0}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

// Lanes [0, n) but those in `skip`.
template <class A>
void expect_same_bits(const A* a, const A* b, int n, const std::string& what, std::initializer_list<int> skip = {}) {
  for (int i = 0; i < n; ++i) {
    if (std::find(skip.begin(), skip.end(), i) != skip.end()) continue;
    ASSERT_TRUE(std::memcmp(a + i, b + i, sizeof(A)) == 0) << what << " lane " << i << ": " << a[i] << " vs " << b[i];
  }
}

vec3f random_unit(std::mt19937& rng) {
  std::normal_distribution<float> N(0.f, 1.f);
  for (;;) {
    const vec3f v{N(rng), N(rng), N(rng)};
    const float l2 = dot(v, v);
    if (l2 > 1e-4f) return v * (1.f / std::sqrt(l2));
  }
}

// Shading points as continue_paths reads them after a vertex's BSDF sample: throughput and
// eta scale, normal, material and side, the sample's direction (bounce packets), weight
// and validity. Random, with zeros, weights above 1, two NaNs (in the first and in the
// last channel) and an infinity in live lanes, an infinity in a dead lane, and the
// padding lanes filled too (the kernel runs whole packets).
void fill_path_points(TileBuffers& tb, std::mt19937& rng, int n, int materials) {
  std::uniform_real_distribution<float> U(0.f, 1.f);
  tb.points.count = n;
  auto weight = [&] {
    const float c = U(rng);
    return c < 0.1f ? 0.f : c < 0.7f ? U(rng) : c < 0.9f ? 1.f + 4.f * U(rng) : 1e-3f * U(rng);
  };
  for (int k = 0; k < max_tile_lanes; ++k) {
    const vec3f nn = random_unit(rng);
    tb.points.nx[k] = nn.x;
    tb.points.ny[k] = nn.y;
    tb.points.nz[k] = nn.z;
    const vec3f wi = random_unit(rng);
    RayHit16& r = tb.bounce[k / packet_width];
    r.ray.dir_x[k % packet_width] = wi.x;
    r.ray.dir_y[k % packet_width] = wi.y;
    r.ray.dir_z[k % packet_width] = wi.z;
    tb.points.mat[k] = static_cast<int32_t>(U(rng) * static_cast<float>(materials)) % materials;
    tb.points.side[k] = U(rng) < 0.4f ? -1.f : 1.f;
    const float t = U(rng);
    tb.path.throughput_r[k] = t < 0.2f ? 1.f : 0.05f + 2.f * U(rng);
    tb.path.throughput_g[k] = t < 0.2f ? 1.f : 0.05f + 2.f * U(rng);
    tb.path.throughput_b[k] = t < 0.2f ? 1.f : 0.05f + 2.f * U(rng);
    const float e = U(rng);
    tb.path.eta_scale[k] = e < 0.4f ? 1.f : e < 0.6f ? 2.25f : e < 0.8f ? 1.f / 2.25f : 0.2f + 4.f * U(rng);
    tb.points.pixel[k] = static_cast<uint32_t>(rng() % 4096u);
    tb.points.lane[k] = k;
    tb.tech.valid[k] = U(rng) < 0.8f ? -1 : 0;
    tb.tech.beta_r[k] = weight();
    tb.tech.beta_g[k] = U(rng) < 0.5f ? tb.tech.beta_r[k] : weight();
    tb.tech.beta_b[k] = U(rng) < 0.5f ? tb.tech.beta_r[k] : weight();
    tb.tech.u3[k] = U(rng);
  }
  // non-finite weights in live lanes: rejected and counted
  tb.tech.valid[17] = tb.tech.valid[50] = tb.tech.valid[51] = -1;
  tb.tech.beta_r[17] = std::numeric_limits<float>::quiet_NaN();
  tb.tech.beta_g[50] = std::numeric_limits<float>::infinity();
  tb.tech.beta_b[51] = std::numeric_limits<float>::quiet_NaN();
  // and in a dead lane: not counted
  tb.tech.valid[90] = 0;
  tb.tech.beta_g[90] = std::numeric_limits<float>::infinity();
}

}  // namespace

// continue_paths with SIMD batches against the scalar reference: the throughput, eta scale,
// validity (which paths go on) and the count of rejected weights, in every lane of the
// padded count, with and without Russian roulette, for diffuse and for every-surface
// pipelines. The inputs are chosen so that every branch runs: paths ended by a zero
// weight, by Russian roulette and by a non-finite weight, transmissions through glass from
// either side (eta scale times eta^2 or 1/eta^2), and throughputs above 1 (no roulette).
TEST(PathLanes, ContinuePathsEqualScalar) {
  Scene s = materials_scene();
  const SceneViews views = build_views(s, LightPick::power);
  const int materials = static_cast<int>(s.materials.size());
  const int n = 203, padded = packet_padded(n);
  std::mt19937 rng(23);
  int ended_by_roulette = 0, eta_changed = 0, reweighted = 0;
  for (bool mats : {false, true})
    for (bool roulette : {false, true})
      for (SamplerKind sampler : {SamplerKind::independent, SamplerKind::sobol})
      for (float thr : {1.f, 0.25f}) {
        Estimator est;
        est.max_depth = 5;
        est.rr_depth = 1;
        est.rr_threshold = thr;
        est.sampler = sampler;
        est.seed = 3;
        const int vertex = roulette ? 2 : 1;  // Russian roulette after vertex rr_depth
        const uint32_t rr_pair = SampleLayout{}.russian_roulette(static_cast<uint32_t>(vertex - 1));
        auto a = std::make_unique<TileBuffers>();
        fill_path_points(*a, rng, n, materials);
        a->stats.rejected_bsdf = 7;  // added to, not reset
        const auto before = std::make_unique<TileBuffers>(*a);
        auto b = std::make_unique<TileBuffers>(*a);
        if (mats) {
          continue_paths<true, vfloat>(views.geom, est, 5, rr_pair, vertex, *a);
          continue_paths<true, float>(views.geom, est, 5, rr_pair, vertex, *b);
        } else {
          continue_paths<false, vfloat>(views.geom, est, 5, rr_pair, vertex, *a);
          continue_paths<false, float>(views.geom, est, 5, rr_pair, vertex, *b);
        }
        const std::string what = std::string(mats ? "materials" : "diffuse") + (roulette ? ", roulette" : "") +
                                 (sampler == SamplerKind::sobol ? ", sobol" : ", independent") +
                                 (thr == 1.f ? ", threshold 1" : ", threshold 0.25");
        // (the lanes of non-finite weights apart: below)
        expect_same_bits(a->path.throughput_r, b->path.throughput_r, padded, what + " tr", {17, 51});
        expect_same_bits(a->path.throughput_g, b->path.throughput_g, padded, what + " tg", {17, 51});
        expect_same_bits(a->path.throughput_b, b->path.throughput_b, padded, what + " tbl", {17, 51});
        expect_same_bits(a->path.eta_scale, b->path.eta_scale, padded, what + " eta_scale");
        expect_same_bits(a->tech.valid, b->tech.valid, padded, what + " valid");
        if (roulette) expect_same_bits(a->tech.u3, b->tech.u3, padded, what + " u3");
        EXPECT_EQ(a->stats.rejected_bsdf, b->stats.rejected_bsdf) << what;
        // the three live non-finite lanes (and only those: the dead one is not counted)
        EXPECT_EQ(a->stats.rejected_bsdf, 7u + 3u) << what;
        for (int k : {17, 50, 51, 90}) EXPECT_EQ(a->tech.valid[k], 0) << what << " lane " << k;
        // The throughput a path ended by a NaN weight is left with: the same bits too, 0.
        // (It is never read again, but the lanes must still be the reference's. The largest
        // channel of a NaN throughput is not the same: std::max(NaN, x) is NaN and
        // std::max(x, NaN) is x, while the SIMD max returns its second operand when either
        // is NaN; so an ended path's throughput is stored as 0.)
        for (int k : {17, 51}) {
          const float* pa[3] = {a->path.throughput_r, a->path.throughput_g, a->path.throughput_b};
          const float* pb[3] = {b->path.throughput_r, b->path.throughput_g, b->path.throughput_b};
          for (int c = 0; c < 3; ++c)
          {
            EXPECT_EQ(std::memcmp(pa[c] + k, pb[c] + k, sizeof(float)), 0)
                << what << ": lane " << k << " (a NaN weight) channel " << c << ": SIMD " << pa[c][k] << " vs scalar "
                << pb[c][k];
            EXPECT_EQ(pb[c][k], 0.f) << what << ": lane " << k << " channel " << c;
          }
        }
        // what the kernel does, lane by lane, in its plainest terms
        const TileBuffers& o = *before;
        for (int k = 0; k < n; ++k) {
          const float br = o.path.throughput_r[k] * o.tech.beta_r[k], bg = o.path.throughput_g[k] * o.tech.beta_g[k],
                      bb = o.path.throughput_b[k] * o.tech.beta_b[k];
          const bool finite = std::isfinite(br) && std::isfinite(bg) && std::isfinite(bb);
          const bool live = o.tech.valid[k] != 0 && finite && std::max(br, std::max(bg, bb)) > 0.f;
          if (!live) {
            ASSERT_EQ(a->tech.valid[k], 0) << what << " lane " << k;
            continue;
          }
          const float eta_new = a->path.eta_scale[k];
          if (eta_new != o.path.eta_scale[k]) {
            ++eta_changed;
            ASSERT_TRUE(mats) << what << " lane " << k;
            ASSERT_EQ(s.materials[static_cast<size_t>(o.points.mat[k])].kind, MaterialKind::dielectric) << k;
          }
          if (!a->tech.valid[k]) {
            ++ended_by_roulette;
            ASSERT_TRUE(roulette) << what << " lane " << k;
            ASSERT_LT(std::max(br, std::max(bg, bb)) * eta_new, thr) << what << " lane " << k;
          } else if (a->path.throughput_r[k] != br || a->path.throughput_g[k] != bg || a->path.throughput_b[k] != bb) {
            ++reweighted;  // survived Russian roulette: divided by its probability m / threshold
            ASSERT_TRUE(roulette) << what << " lane " << k;
            const float m = std::max(br, std::max(bg, bb));
            const float now = std::max(a->path.throughput_r[k], std::max(a->path.throughput_g[k], a->path.throughput_b[k]));
            ASSERT_GT(now, m) << what << " lane " << k;
            const float p = m * eta_new / thr;
            ASSERT_LT(p, 1.f) << what << " lane " << k;
            ASSERT_NEAR(now, m / p, 1e-5f * m / p) << what << " lane " << k;
          } else if (roulette) {
            // went on untouched: its throughput was not below the threshold
            ASSERT_GE(std::max(br, std::max(bg, bb)) * eta_new, thr) << what << " lane " << k;
          }
        }
      }
  EXPECT_GT(ended_by_roulette, 20);
  EXPECT_GT(reweighted, 20);
  EXPECT_GT(eta_changed, 10);
}

// bounce_hits with SIMD batches against the scalar reference, on the bounce rays of camera
// hits traced through Embree (as run_tile does: camera hits, start_paths, a continuation
// BSDF sample, the bounce packets traced, continue_paths with Russian roulette): the
// count, every shading-point array the stage writes (positions, normals, offsets,
// reflectance with texels, throughput, eta scale, pixel, lane, and with materials the
// material, side and direction towards the viewer, shading normals), and the rejected
// count. Then the compaction itself: the new points are the old points whose traced ray
// hit something, in order, with their lane, pixel, throughput and eta scale, at the hit.
TEST(PathLanes, BounceHitsEqualScalar) {
  for (bool mats : {false, true}) {
    Scene s = mats ? materials_scene() : diffuse_scene();
    const SceneViews views = build_views(s, LightPick::power);
    ASSERT_EQ(views.has_materials(), mats);
    Accel accel(s);
    const SampleLayout layout;
    for (MisMode mode : {MisMode::multi, MisMode::one})
      for (int lanes : {256, 250}) {
        const std::string what = std::string(mats ? "materials" : "diffuse") +
                                 (mode == MisMode::one ? " one-sample" : " multi") + " lanes " + std::to_string(lanes);
        Estimator est;
        est.mode = mode;
        est.max_depth = 5;
        est.rr_threshold = 1.f;  // pbrt-v4's rule, so that roulette ends some of these paths
        est.sampler = SamplerKind::independent;
        est.seed = 9;
        auto a = std::make_unique<TileBuffers>();
        for (int i = 0; i < 256; ++i) {
          a->lanes.fx[i] = static_cast<float>(i % 16);
          a->lanes.fy[i] = static_cast<float>(i / 16);
          a->lanes.pixel[i] = static_cast<uint32_t>(i);
        }
        const uint32_t sample = 2;
        generate(views.camera, est, sample, SampleLayout::camera, lanes, *a);
        for (int p = 0; p < packets_for(lanes); ++p) accel.intersect16(a->lanes.cam_valid + p * packet_width, a->cam[p], true);
        if (mats) camera_hits<true, vfloat, true>(views.geom, views.lights, est, sample, layout.technique_choice(), lanes, *a);
        else camera_hits<true, vfloat, false>(views.geom, views.lights, est, sample, layout.technique_choice(), lanes, *a);
        ASSERT_GT(a->points.count, 64) << what;
        start_paths(*a);
        // vertex 2's step (the camera hits stand in for it): its continuation, with roulette
        if (mats) sample_bsdf<bsdf_all>(views.geom, est, sample, layout.bsdf(0, 1), layout.bsdf_lobe(0, 1), *a, false, true);
        else sample_bsdf<bsdf_diffuse>(views.geom, est, sample, layout.bsdf(0, 1), layout.bsdf_lobe(0, 1), *a, false, true);
        for (int p = 0; p < packets_for(a->points.count); ++p)
          accel.intersect16(a->tech.valid + p * packet_width, a->bounce[p], false);
        if (mats) continue_paths<true>(views.geom, est, sample, layout.russian_roulette(1), 2, *a);
        else continue_paths<false>(views.geom, est, sample, layout.russian_roulette(1), 2, *a);
        const auto old = std::make_unique<TileBuffers>(*a);
        auto b = std::make_unique<TileBuffers>(*a);
        int na, nb;
        if (mats) {
          na = bounce_hits<vfloat, true>(views.geom, views.lights, est, sample, layout.technique_choice(2), *a);
          nb = bounce_hits<float, true>(views.geom, views.lights, est, sample, layout.technique_choice(2), *b);
        } else {
          na = bounce_hits<vfloat, false>(views.geom, views.lights, est, sample, layout.technique_choice(2), *a);
          nb = bounce_hits<float, false>(views.geom, views.lights, est, sample, layout.technique_choice(2), *b);
        }
        ASSERT_EQ(na, a->points.count) << what;
        ASSERT_EQ(nb, b->points.count) << what;
        ASSERT_EQ(na, nb) << what;
        EXPECT_EQ(a->stats.rejected_bsdf, b->stats.rejected_bsdf) << what;
        const int n = na, padded = packet_padded(n);
        const struct {
          const char* name;
          float (ShadingPoints::*arr)[lane_array];
        } arrays[] = {{"px", &ShadingPoints::px},   {"py", &ShadingPoints::py},   {"pz", &ShadingPoints::pz},
                      {"nx", &ShadingPoints::nx},   {"ny", &ShadingPoints::ny},   {"nz", &ShadingPoints::nz},
                      {"eps", &ShadingPoints::eps}, {"ar", &ShadingPoints::ar},   {"ag", &ShadingPoints::ag},
                      {"ab", &ShadingPoints::ab},
                      {"snx", &ShadingPoints::snx}, {"sny", &ShadingPoints::sny}, {"snz", &ShadingPoints::snz},
                      {"wox", &ShadingPoints::wox}, {"woy", &ShadingPoints::woy}, {"woz", &ShadingPoints::woz},
                      {"side", &ShadingPoints::side}, {"choose_light", &ShadingPoints::choose_light}};
        for (const auto& f : arrays) expect_same_bits(a->points.*f.arr, b->points.*f.arr, padded, what + " " + f.name);
        const struct {
          const char* name;
          float (PathStates::*arr)[lane_array];
        } path_arrays[] = {{"throughput_r", &PathStates::throughput_r}, {"throughput_g", &PathStates::throughput_g},
                           {"throughput_b", &PathStates::throughput_b}, {"eta_scale", &PathStates::eta_scale}};
        for (const auto& f : path_arrays) expect_same_bits(a->path.*f.arr, b->path.*f.arr, padded, what + " " + f.name);
        expect_same_bits(a->radiance.r, b->radiance.r, padded, what + " radiance r");
        expect_same_bits(a->radiance.g, b->radiance.g, padded, what + " radiance g");
        expect_same_bits(a->radiance.b, b->radiance.b, padded, what + " radiance b");
        expect_same_bits(a->points.pixel, b->points.pixel, padded, what + " pixel");
        expect_same_bits(a->points.lane, b->points.lane, padded, what + " lane");
        if (mats) expect_same_bits(a->points.mat, b->points.mat, padded, what + " mat");
        if (views.geom.shading_normals) {  // (compress stores: the SIMD batch writes past the count)
          expect_same_bits(a->points.geom, b->points.geom, n, what + " geom");
          expect_same_bits(a->points.prim, b->points.prim, n, what + " prim");
          expect_same_bits(a->points.bu, b->points.bu, n, what + " bu");
          expect_same_bits(a->points.bv, b->points.bv, n, what + " bv");
        }
        if (mode == MisMode::one) expect_same_bits(a->tech.u0, b->tech.u0, padded, what + " u0");
        // the compaction: the old points whose ray was traced (still valid after Russian
        // roulette) and hit something, in order
        const TileBuffers& o = *old;
        std::vector<int> kept;
        int hits = 0, misses = 0, ended = 0;
        for (int k = 0; k < o.points.count; ++k) {
          const RayHit16& r = o.bounce[k / packet_width];
          const bool hit = r.geomID[k % packet_width] != invalid_id;
          if (!o.tech.valid[k]) {
            ++ended;
            continue;
          }
          (hit ? hits : misses)++;
          if (hit) kept.push_back(k);
        }
        std::printf("[ bounce hits ] %s: %d points, %d rays hit, %d missed, %d paths ended\n", what.c_str(),
                    o.points.count, hits, misses, ended);
        EXPECT_GT(hits, 20) << what;
        EXPECT_GT(misses, 20) << what;
        EXPECT_EQ(a->stats.rejected_bsdf, o.stats.rejected_bsdf) << what << ": degenerate hits in this scene?";
        ASSERT_EQ(n, static_cast<int>(kept.size())) << what;
        for (int j = 0; j < n; ++j) {
          const int k = kept[static_cast<size_t>(j)];
          ASSERT_EQ(a->points.lane[j], o.points.lane[k]) << what << " point " << j;
          ASSERT_GE(a->points.lane[j], 0) << what << " point " << j;
          ASSERT_LT(a->points.lane[j], lanes) << what << " point " << j;
          ASSERT_EQ(a->points.pixel[j], o.points.pixel[k]) << what << " point " << j;
          ASSERT_EQ(a->points.pixel[j], o.lanes.pixel[a->points.lane[j]]) << what << " point " << j;
          ASSERT_EQ(a->path.throughput_r[j], o.path.throughput_r[k]) << what << " point " << j;
          ASSERT_EQ(a->path.throughput_g[j], o.path.throughput_g[k]) << what << " point " << j;
          ASSERT_EQ(a->path.throughput_b[j], o.path.throughput_b[k]) << what << " point " << j;
          ASSERT_EQ(a->path.eta_scale[j], o.path.eta_scale[k]) << what << " point " << j;
          // at the ray's hit, the normal facing where the ray came from
          const RayHit16& r = o.bounce[k / packet_width];
          const int l = k % packet_width;
          const vec3f org{r.ray.org_x[l], r.ray.org_y[l], r.ray.org_z[l]}, dir{r.ray.dir_x[l], r.ray.dir_y[l], r.ray.dir_z[l]};
          const vec3f x = org + dir * r.ray.tfar[l], p{a->points.px[j], a->points.py[j], a->points.pz[j]};
          ASSERT_LT(length(p - x), 1e-4f * (1.f + length(x))) << what << " point " << j;
          const vec3f nn{a->points.nx[j], a->points.ny[j], a->points.nz[j]};
          ASSERT_LE(dot(nn, dir), 0.f) << what << " point " << j;
          if (mats) {
            ASSERT_EQ(a->points.wox[j], -dir.x) << what << " point " << j;
            ASSERT_EQ(a->points.mat[j], views.geom.geom_material[r.geomID[l]]) << what << " point " << j;
          }
        }
        // every new point's lane had one point at the vertex before: no lane twice
        std::vector<int> seen(256, 0);
        for (int j = 0; j < n; ++j) ASSERT_EQ(seen[static_cast<size_t>(a->points.lane[j])]++, 0) << what << " point " << j;
        for (int k = n; k < padded; ++k) ASSERT_EQ(a->points.lane[k], -1) << what << " padding " << k;
        EXPECT_GT(ended, 0) << what << ": Russian roulette ended no path";
      }
  }
}
