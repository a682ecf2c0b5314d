// Materials in the render pipeline (bsdf/material.h through the stages): every SIMD lane of
// the light-sampling and BSDF-sampling stages equals the scalar reference with a surface of
// every kind in one batch; a light seen in a smooth mirror has exactly the radiance Fresnel
// says (a delta lobe, weight 1, whatever the strategy); and on a glossy scene every
// strategy converges to the same image (unbiased, stated confidence), with several
// light and BSDF samples too.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <functional>
#include <cstring>
#include <memory>
#include <random>

#include "bsdf/coated.h"
#include "render/checkpoint.h"
#include "render/passes.h"
#include "render/views.h"
#include "render_util.h"
#include "wave/generate.h"
#include "wave/surface_hits.h"
#include "wave/sample_bsdf.h"
#include "wave/sample_lights.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// One material of every kind, rough and smooth variants, on a floor of quads, lit by a
// rectangle, a triangle, a sphere and a spot light.
Scene every_surface() {
  Scene s;
  s.source = "test:every-surface";
  Material m;
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.5f, 0.4f}));
  m.kind = MaterialKind::conductor;
  m.eta_rgb = {0.2f, 0.9f, 1.1f};
  m.k_rgb = {3.9f, 2.4f, 2.1f};
  m.alpha_u.value = 0.3f;
  m.alpha_v.value = 0.05f;
  s.materials.push_back(m);
  m.alpha_u.value = m.alpha_v.value = 0.f;
  s.materials.push_back(m);
  m = Material{};
  m.kind = MaterialKind::dielectric;
  m.eta = 1.5f;
  s.materials.push_back(m);
  m.alpha_u.value = m.alpha_v.value = 0.2f;
  s.materials.push_back(m);
  m = Material{};
  m.kind = MaterialKind::thin_dielectric;
  s.materials.push_back(m);
  m = Material{};
  m.kind = MaterialKind::diffuse_transmission;
  m.reflectance = {0.3f, 0.2f, 0.1f};
  m.transmittance = {0.4f, 0.5f, 0.6f};
  s.materials.push_back(m);
  m = Material{};
  m.kind = MaterialKind::coated_diffuse;
  m.reflectance = {0.2f, 0.4f, 0.6f};
  s.materials.push_back(m);
  m.alpha_u.value = m.alpha_v.value = 0.1f;
  s.materials.push_back(m);
  m = Material{};
  m.kind = MaterialKind::coated_conductor;
  m.eta_rgb = {0.2f, 0.9f, 1.1f};
  m.k_rgb = {3.9f, 2.4f, 2.1f};
  m.base_alpha_u.value = 0.2f;
  m.base_alpha_v.value = 0.1f;
  s.materials.push_back(m);
  m = Material{};
  m.kind = MaterialKind::hair;  // on a floor quad: the points carry random fiber axes and offsets
  m.eta = 1.55f;
  m.hair_sigma_a = {0.3f, 0.6f, 1.2f};
  m.beta_m = 0.25f;
  m.beta_n = 0.4f;
  s.materials.push_back(m);
  for (int i = 0; i < static_cast<int>(s.materials.size()); ++i) {
    Mesh f;
    f.name = "floor";
    f.material = i;
    add_quad(f, {-2.f + 0.5f * static_cast<float>(i), 0, -2}, {0, 0, 4}, {0.5f, 0, 0});
    s.meshes.push_back(f);
  }
  Mesh bumpy;  // a mesh with shading normals: the stages then read the points' shading normals
  bumpy.name = "bumpy";
  bumpy.material = 1;
  add_quad(bumpy, {-2, 0.01f, 2}, {4, 0, 0}, {0, 0, 1});
  bumpy.normals = {0.3f, 0.95f, 0.f, 0.f, 1.f, 0.f, -0.2f, 0.9f, 0.3f, 0.f, 0.8f, -0.6f};
  s.meshes.push_back(bumpy);
  Mesh rect;
  rect.name = "rect source";
  rect.material = 0;
  rect.emission = {4, 3, 2};
  add_quad(rect, {-0.5f, 1.f, -0.5f}, {1, 0, 0}, {0, 0, 1});
  s.meshes.push_back(rect);
  Mesh tri;
  tri.name = "triangle source";
  tri.material = 0;
  tri.emission = {1, 2, 3};
  add_triangle(tri, {1, 0.8f, 0}, {1.5f, 0.8f, 0.5f}, {1.5f, 0.8f, -0.5f});
  tri.two_sided = true;
  s.meshes.push_back(tri);
  Sphere lamp;
  lamp.center = {-1, 0.6f, 0.5f};
  lamp.radius = 0.1f;
  lamp.material = 0;
  lamp.emission = {5, 5, 5};
  s.spheres.push_back(lamp);
  Light spot;
  spot.type = LightKind::spot;
  spot.p0 = {0.2f, 1.5f, 0.3f};
  spot.e1 = normalize(vec3f{0.1f, -1, -0.2f});
  spot.e2 = {0.9f, 0.8f, 0};
  spot.radiance = {2, 1, 1};
  s.lights.push_back(spot);
  s.camera.width = s.camera.height = 16;
  return s;
}

// Shading points on the floor with a random material each, random normals (some facing
// down), directions towards the viewer on the normal's side, and both sides of the surface.
void fill_points(const Scene& s, TileBuffers& tb, std::mt19937& rng, int n) {
  std::uniform_real_distribution<float> U(0.f, 1.f);
  tb.points.count = n;
  const int mats = static_cast<int>(s.materials.size());
  for (int k = 0; k < max_tile_lanes; ++k) {
    tb.points.px[k] = -2 + 4 * U(rng);
    tb.points.py[k] = U(rng) < 0.1f ? 0.8f : 0.f;
    tb.points.pz[k] = -2 + 4 * U(rng);
    vec3f nn = normalize(vec3f{0.4f * (U(rng) - 0.5f), 1.f, 0.4f * (U(rng) - 0.5f)});
    if (U(rng) < 0.15f) nn = -nn;
    tb.points.nx[k] = nn.x;
    tb.points.ny[k] = nn.y;
    tb.points.nz[k] = nn.z;
    // a shading normal up to ~50 degrees from the geometric one (some lanes: the same)
    vec3f sn = k % 4 == 0 ? nn : normalize(nn + vec3f{1.2f * (U(rng) - 0.5f), 0.f, 1.2f * (U(rng) - 0.5f)});
    if (dot(sn, nn) < 0) sn = nn;
    tb.points.snx[k] = sn.x;
    tb.points.sny[k] = sn.y;
    tb.points.snz[k] = sn.z;
    vec3f wo = normalize(vec3f{U(rng) - 0.5f, 0.05f + U(rng), U(rng) - 0.5f});
    if (dot(wo, nn) < 0) wo = -wo;
    tb.points.wox[k] = wo.x;
    tb.points.woy[k] = wo.y;
    tb.points.woz[k] = wo.z;
    tb.points.side[k] = U(rng) < 0.3f ? -1.f : 1.f;
    std::mt19937 frng(static_cast<uint32_t>(k) + 1000u);  // (its own stream: the other draws stay as they were)
    const vec3f fiber = normalize(vec3f{U(frng) - 0.5f, U(frng) - 0.5f, U(frng) - 0.5f});
    tb.points.fx[k] = fiber.x;
    tb.points.fy[k] = fiber.y;
    tb.points.fz[k] = fiber.z;
    tb.points.fh[k] = 2 * U(frng) - 1;
    tb.points.mat[k] = static_cast<int32_t>(U(rng) * static_cast<float>(mats)) % mats;
    tb.points.eps[k] = 1e-5f;
    tb.points.ar[k] = U(rng);
    tb.points.ag[k] = U(rng);
    tb.points.ab[k] = U(rng);
    tb.points.pixel[k] = static_cast<uint32_t>(k * 7);
    tb.points.lane[k] = k;
    tb.points.choose_light[k] = U(rng) < 0.5f ? 1.f : 0.f;
    tb.tech.u0[k] = U(rng);
    tb.tech.u1[k] = U(rng);
    tb.tech.u2[k] = k % 17 == 0 ? 0.f : U(rng);
    tb.tech.u3[k] = k % 13 == 0 ? 0.999999f : U(rng);
  }
}

void expect_same(const float* a, const float* b, int n, const std::string& what) {
  for (int i = 0; i < n; ++i)
    ASSERT_TRUE(std::memcmp(a + i, b + i, sizeof(float)) == 0) << what << " lane " << i << ": " << a[i] << " vs " << b[i];
}
void expect_same(const int32_t* a, const int32_t* b, int n, const std::string& what) {
  for (int i = 0; i < n; ++i) ASSERT_EQ(a[i], b[i]) << what << " lane " << i;
}

}  // namespace

// Both sampling stages with a surface of every kind in one batch: vfloat, vfloat2 and
// vfloat4 give the scalar reference's bits in every lane.
// The material table's coat internal reflectance (mp_ri_*, computed once per material) is
// coat_internal_reflectance_rgb of the row's own eta, thickness and albedo, bit for bit, for
// every coated diffuse material (their thickness and albedo varied here); other kinds hold 0.
TEST(MaterialStages, CoatInternalReflectanceIsTheRowsOwn) {
  Scene s = every_surface();
  int coated = 0;
  for (Material& m : s.materials)
    if (m.kind == MaterialKind::coated_diffuse) {
      m.thickness = 0.05f * static_cast<float>(++coated);
      m.albedo = {0.1f * static_cast<float>(coated), 0.f, 0.5f};
      m.eta = 1.2f + 0.3f * static_cast<float>(coated);
    }
  ASSERT_GE(coated, 2);
  const SceneViews v = build_views(s, LightPick::power);
  const GeomView& G = v.geom;
  int checked = 0;
  for (size_t m = 0; m < v.mat_kind.size(); ++m) {
    const float* p[mp_count];
    for (int i = 0; i < mp_count; ++i) p[i] = G.mat_param[i] + m;
    if (v.mat_kind[m] != static_cast<int32_t>(MaterialKind::coated_diffuse)) {
      EXPECT_EQ(*p[mp_ri_r] + *p[mp_ri_g] + *p[mp_ri_b], 0.f) << m;
      continue;
    }
    const Rgb3<float> want = coat_internal_reflectance_rgb(*p[mp_eta], *p[mp_thickness], Rgb3<float>{*p[mp_alb_r], *p[mp_alb_g], *p[mp_alb_b]});
    EXPECT_EQ(std::memcmp(&want.r, p[mp_ri_r], 4), 0) << m;
    EXPECT_EQ(std::memcmp(&want.g, p[mp_ri_g], 4), 0) << m;
    EXPECT_EQ(std::memcmp(&want.b, p[mp_ri_b], 4), 0) << m;
    EXPECT_GT(want.r, 0.f);
    EXPECT_NE(want.r, want.b) << "the albedo's channels differ";
    ++checked;
  }
  EXPECT_GE(checked, coated);  // (and regularization's twins)
}

TEST(MaterialStages, LanesEqualScalar) {
  Scene s = every_surface();
  // and a medium (a sphere of it, off the floor), so that some points are a medium's: the
  // phase function, with no normal (wave/surface_hits.h point_media)
  Medium md;
  md.name = "fog";
  md.type = "homogeneous";
  md.supported = true;
  md.g = 0.6f;
  s.media.push_back(md);
  Sphere fog;
  fog.center = {0, 3, 0};
  fog.radius = 0.5f;
  fog.medium_inside = 0;
  s.spheres.push_back(fog);
  finalize_scene(s);
  const SceneViews views = build_views(s, LightPick::power);
  ASSERT_TRUE(views.geom.has_media);
  ASSERT_EQ(views.bsdf_kinds, bsdf_all);  // every kind of surface, and the phase function
  const int32_t phase_material = views.geom.geom_material[views.geom.media.geom0];
  ASSERT_EQ(views.mat_kind[static_cast<size_t>(phase_material)], static_cast<int32_t>(MaterialKind::phase));
  ASSERT_TRUE(views.geom.has_normals);
  ASSERT_TRUE(views.geom.has_hair);
  std::mt19937 rng(11);
  for (Strategy st : {Strategy::mis, Strategy::light, Strategy::bsdf}) {
    Estimator est;
    est.strategy = st;
    auto a = std::make_unique<TileBuffers>();
    fill_points(s, *a, rng, 256);
    for (int k = 5; k < 256; k += 9) {  // points in the medium
      a->points.mat[k] = phase_material;
      a->points.nx[k] = a->points.ny[k] = a->points.nz[k] = 0.f;
    }
    auto b = std::make_unique<TileBuffers>(*a), c = std::make_unique<TileBuffers>(*a), d = std::make_unique<TileBuffers>(*a);
    const int n = 256;
    LightPass pass;
    for (int k = 0; k < n; ++k) sample_lights_lanes<float, kind_all, true, bsdf_all>(views.geom, views.lights, est, pass, *a, k);
    for (int k = 0; k < n; k += simd_width)
      sample_lights_lanes<vfloat, kind_all, true, bsdf_all>(views.geom, views.lights, est, pass, *b, k);
    for (int k = 0; k < n; k += 2 * simd_width)
      sample_lights_lanes<vfloat2, kind_all, true, bsdf_all>(views.geom, views.lights, est, pass, *c, k);
    for (int k = 0; k < n; k += 4 * simd_width)
      sample_lights_lanes<vfloat4, kind_all, true, bsdf_all>(views.geom, views.lights, est, pass, *d, k);
    int lit = 0;
    for (int k = 0; k < n; ++k) lit += a->tech.valid[k] != 0;
    // (BSDF sampling alone: only the spot light is sampled)
    EXPECT_GT(lit, st == Strategy::bsdf ? 2 : n / 4) << "too few lanes see a light to test anything";
    for (const TileBuffers* t : {b.get(), c.get(), d.get()}) {
      const std::string what = "light sample, " + describe(est);
      expect_same(t->tech.cr, a->tech.cr, n, what);
      expect_same(t->tech.cg, a->tech.cg, n, what);
      expect_same(t->tech.cb, a->tech.cb, n, what);
      expect_same(t->tech.valid, a->tech.valid, n, what);
      for (int k = 0; k < n; ++k) {
        if (!a->tech.valid[k]) continue;
        const Ray16 &ra = a->shadow[k / packet_width], &rt = t->shadow[k / packet_width];
        const int l = k % packet_width;
        ASSERT_EQ(std::memcmp(&ra.dir_x[l], &rt.dir_x[l], 4), 0) << what << " lane " << k;
        ASSERT_EQ(std::memcmp(&ra.org_y[l], &rt.org_y[l], 4), 0) << what << " lane " << k;
        ASSERT_EQ(std::memcmp(&ra.tfar[l], &rt.tfar[l], 4), 0) << what << " lane " << k;
      }
    }
    for (int k = 0; k < n; ++k) sample_bsdf_lanes<float, bsdf_all>(views.geom, est, *a, k, st == Strategy::light);
    for (int k = 0; k < n; k += simd_width) sample_bsdf_lanes<vfloat, bsdf_all>(views.geom, est, *b, k, st == Strategy::light);
    for (int k = 0; k < n; k += 2 * simd_width) sample_bsdf_lanes<vfloat2, bsdf_all>(views.geom, est, *c, k, st == Strategy::light);
    int traced = 0, delta = 0, below = 0;
    for (int k = 0; k < n; ++k) {
      traced += a->tech.valid[k] != 0;
      delta += a->tech.valid[k] && a->tech.delta[k];
      const RayHit16& r = a->bounce[k / packet_width];
      const int l = k % packet_width;
      below += a->tech.valid[k] && r.ray.dir_x[l] * a->points.nx[k] + r.ray.dir_y[l] * a->points.ny[k] +
                                           r.ray.dir_z[l] * a->points.nz[k] < 0.f;
    }
    EXPECT_GT(delta, 0);
    if (st != Strategy::light) {
      EXPECT_GT(traced, n / 2);
      EXPECT_GT(below, 0) << "no transmitted direction";
    } else {
      EXPECT_EQ(traced, delta) << "--strategy light traces the specular samples only";
    }
    for (const TileBuffers* t : {b.get(), c.get()}) {
      const std::string what = "BSDF sample, " + describe(est);
      expect_same(t->tech.beta_r, a->tech.beta_r, n, what);
      expect_same(t->tech.beta_g, a->tech.beta_g, n, what);
      expect_same(t->tech.beta_b, a->tech.beta_b, n, what);
      expect_same(t->tech.pdf, a->tech.pdf, n, what);
      expect_same(t->tech.valid, a->tech.valid, n, what);
      expect_same(t->tech.delta, a->tech.delta, n, what);
      for (int k = 0; k < n; ++k) {
        const RayHit16 &ra = a->bounce[k / packet_width], &rt = t->bounce[k / packet_width];
        const int l = k % packet_width;
        ASSERT_EQ(std::memcmp(&ra.ray.dir_x[l], &rt.ray.dir_x[l], 4), 0) << what << " lane " << k;
        ASSERT_EQ(std::memcmp(&ra.ray.dir_z[l], &rt.ray.dir_z[l], 4), 0) << what << " lane " << k;
        ASSERT_EQ(std::memcmp(&ra.ray.org_y[l], &rt.ray.org_y[l], 4), 0) << what << " lane " << k;
      }
    }
  }
}

namespace {

// Fresnel reflectance of a conductor, unpolarised, in double (the textbook formula with
// complex eta = n + i k; the kernels use pbrt-v4's, an algebraic rearrangement).
double fresnel_conductor(double cos_i, double eta, double k) {
  using C = std::complex<double>;
  const C n(eta, k);
  const double sin2 = 1 - cos_i * cos_i;
  const C cos_t = std::sqrt(C(1) - C(sin2) / (n * n));
  const C rs = (C(cos_i) - n * cos_t) / (C(cos_i) + n * cos_t);
  const C rp = (n * C(cos_i) - cos_t) / (n * C(cos_i) + cos_t);
  return 0.5 * (std::norm(rs) + std::norm(rp));
}

}  // namespace

// A smooth mirror floor seen from above, and above the camera a large emitting ceiling:
// every pixel is the ceiling's radiance times the conductor's Fresnel reflectance at that
// pixel's angle, with no noise, for every strategy (the lobe is a delta: only BSDF
// samples see it, and they get weight 1). Tolerance: float rounding of the direction and
// of the Fresnel terms, 1e-4 relative (the kernels' formula is accurate to ~1e-6).
TEST(Materials, LightSeenInSmoothMirrorHasFresnelRadiance) {
  PlaneScene p = plane_scene({0, 1, 0}, 60, 24);
  Scene& s = p.scene;
  Material mirror;
  mirror.kind = MaterialKind::conductor;
  mirror.eta_rgb = {0.2f, 0.9f, 1.1f};
  mirror.k_rgb = {3.9f, 2.4f, 2.1f};
  s.materials[0] = mirror;
  s.materials.push_back(diffuse_material(Rgb{0, 0, 0}));
  Mesh ceiling;
  ceiling.name = "ceiling";
  ceiling.material = 1;
  ceiling.emission = {2, 3, 4};
  add_quad(ceiling, {-100, 2, -100}, {200, 0, 0}, {0, 0, 200});  // cross(x, z) = -y: emits down
  s.meshes.push_back(ceiling);
  finalize_scene(s);
  Accel accel(s);
  const float L[3] = {2, 3, 4}, eta[3] = {0.2f, 0.9f, 1.1f}, k[3] = {3.9f, 2.4f, 2.1f};
  const SceneViews views = build_views(s, LightPick::power);
  for (Strategy st : {Strategy::mis, Strategy::light, Strategy::bsdf}) {
      RenderOptions o;
      o.est.strategy = st;
      o.est.spp = 4;
      Renderer r(s, accel, o);
      Film f;
      r.render(f, 0, o.est.spp);
      const std::vector<float> m = f.mean();
      const CameraView& cv = views.camera;
      for (int y = 0; y < s.camera.height; ++y)
        for (int x = 0; x < s.camera.width; ++x) {
          // the pixel's rays span a small range of angles: compare with the centre's
          // Fresnel, within what the angle range changes it (checked below 1e-3)
          Vec3<float> o3, d;
          camera_ray(cv, static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f, o3, d);
          const double cos_i = -d.y;
          const size_t i = 3 * (static_cast<size_t>(y) * s.camera.width + x);
          for (int c = 0; c < 3; ++c) {
            const double want = L[c] * fresnel_conductor(cos_i, eta[c], k[c]);
            ASSERT_NEAR(m[i + c], want, 2e-3 * want) << describe(o.est) << " pixel " << x << "," << y << " channel " << c;
          }
        }
    }
}

// MIS with glossy BSDFs: light sampling alone, BSDF sampling alone, MIS (balance and power,
// multi- and one-sample, 2 light and 3 BSDF samples) estimate the same image. A rough
// conductor and a rough coated floor under a rectangle and a sphere; independent random numbers, so that each
// pixel's variance estimate is honest. Compared per 8x8 block of pixels against the
// balance-heuristic render: z = difference / combined standard error; with (16 blocks + 3
// channels) x 5 renders and |z| < 5, a correct renderer fails with probability ~6e-5 (normal tails;
// 1024 samples per pixel x 64 pixels per block make the block means close to normal).
// A 5% bias of the BSDF technique's weight in one channel fails it (checked by hand).
TEST(Materials, EveryStrategyConvergesToTheSameGlossyImage) {
  PlaneScene p = plane_scene({0, 1.2f, 0}, 70, 32);
  Scene& s = p.scene;
  Material metal;
  metal.kind = MaterialKind::conductor;
  metal.eta_rgb = {0.2f, 0.9f, 1.1f};
  metal.k_rgb = {3.9f, 2.4f, 2.1f};
  metal.alpha_u.value = 0.3f;
  metal.alpha_v.value = 0.2f;
  s.materials[0] = metal;
  Material coat;
  coat.kind = MaterialKind::coated_diffuse;
  coat.reflectance = {0.6f, 0.3f, 0.2f};
  coat.alpha_u.value = coat.alpha_v.value = 0.3f;
  s.materials.push_back(coat);
  Mesh half;
  half.name = "coated half";
  half.material = 1;
  add_quad(half, {0, 0.001f, -100}, {0, 0, 200}, {100, 0, 0});
  s.meshes.push_back(half);
  add_source_quad(p, {-0.6f, 1.6f, -0.2f}, {1.0f, 0, 0}, {0, 0, 0.8f}, 3.f);
  Sphere lamp;
  lamp.center = {0.3f, 0.7f, -0.4f};
  lamp.radius = 0.25f;
  lamp.material = 0;
  lamp.emission = {4, 3, 2};
  s.spheres.push_back(lamp);
  finalize_scene(s);
  Accel accel(s);
  struct Result {
    std::string name;
    std::vector<float> mean, var;
  };
  auto render = [&](Strategy st, Heuristic h, MisMode mode, int light_samples = 1, int bsdf_samples = 1) {
    RenderOptions o;
    o.est.light_samples = light_samples;
    o.est.bsdf_samples = bsdf_samples;
    o.est.strategy = st;
    o.est.heuristic = h;
    o.est.mode = mode;
    o.est.sampler = SamplerKind::independent;
    o.est.spp = scaled(1024u);  // the z-scores below come from these samples' own variance
    o.est.seed = 7;
    Renderer r(s, accel, o);
    Film f;
    r.render(f, 0, o.est.spp);
    return Result{describe(o.est), f.mean(), f.variance_of_mean()};
  };
  const Result ref = render(Strategy::mis, Heuristic::balance, MisMode::multi);
  const Result others[] = {render(Strategy::light, Heuristic::balance, MisMode::multi),
                           render(Strategy::bsdf, Heuristic::balance, MisMode::multi),
                           render(Strategy::mis, Heuristic::power, MisMode::multi),
                           render(Strategy::mis, Heuristic::balance, MisMode::one),
                           render(Strategy::mis, Heuristic::power, MisMode::multi, 2, 3)};
  // per 8x8 block (all channels), and per channel over the whole image (a bias in one
  // channel or a small one everywhere): 16 x 4 + 3 x 4 comparisons at |z| < 5
  const int W = s.camera.width, B = 8;
  double total = 0;
  for (const Result& o : others) {
    double ca[3] = {0, 0, 0}, cb[3] = {0, 0, 0}, cva[3] = {0, 0, 0}, cvb[3] = {0, 0, 0};
    for (int by = 0; by < W; by += B)
      for (int bx = 0; bx < W; bx += B) {
        double a = 0, b = 0, va = 0, vb = 0;
        for (int y = by; y < by + B; ++y)
          for (int x = bx; x < bx + B; ++x)
            for (int c = 0; c < 3; ++c) {
              const size_t i = 3 * (static_cast<size_t>(y) * W + x) + c;
              a += ref.mean[i];
              b += o.mean[i];
              va += ref.var[i];
              vb += o.var[i];
              ca[c] += ref.mean[i];
              cb[c] += o.mean[i];
              cva[c] += ref.var[i];
              cvb[c] += o.var[i];
            }
        total += a;
        const double z = (b - a) / std::sqrt(va + vb);
        EXPECT_LT(std::abs(z), 5.0) << o.name << " block " << bx << "," << by << ": " << b << " vs " << a;
      }
    for (int c = 0; c < 3; ++c) {
      const double z = (cb[c] - ca[c]) / std::sqrt(cva[c] + cvb[c]);
      EXPECT_LT(std::abs(z), 5.0) << o.name << " channel " << c << ": " << cb[c] << " vs " << ca[c];
    }
  }
  EXPECT_GT(total, 0.0);
}

// Textured roughness (pbrt's "texture roughness"): looked up per shading point at the hit's
// uv, bilinearly with wrap, through RoughnessToAlpha where the material remaps. Checked
// against the texture's bilinear value computed here in double at the analytic uv, and at
// the render level: a one-texel texture renders as its constant (to rounding).
TEST(Materials, TexturedRoughnessIsLookedUpPerHit) {
  Scene s;
  s.source = "test:textured-roughness";
  Material m;
  m.kind = MaterialKind::conductor;
  m.remap_roughness = true;
  m.alpha_u.texture = 0;  // u: the ramp
  m.alpha_v.value = 0.3f;  // v: a constant
  s.materials.push_back(m);
  FloatTexture t;
  t.width = 4;
  t.height = 1;
  t.value = {0.01f, 0.04f, 0.25f, 0.64f};
  s.float_textures.push_back(t);
  Mesh f;
  f.name = "floor";
  f.material = 0;
  add_quad(f, {0, 0, 0}, {1, 0, 0}, {0, 0, 1});  // vertices (0,0,0) (1,0,0) (1,0,1) (0,0,1)
  f.uvs = {0, 0, 1, 0, 1, 1, 0, 1};
  s.meshes.push_back(f);
  Mesh lamp;
  lamp.name = "lamp";
  lamp.material = 0;
  lamp.emission = {1, 1, 1};
  add_quad(lamp, {-0.5f, 2, -0.5f}, {2, 0, 0}, {0, 0, 2});  // cross(x, z) = -y: emits down
  s.meshes.push_back(lamp);
  finalize_scene(s);
  const SceneViews views = build_views(s, LightPick::power);
  ASSERT_TRUE(views.geom.has_rough_tex);
  auto tb = std::make_unique<TileBuffers>();
  ShadingPoints& P = tb->points;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  P.count = 64;
  for (int k = 0; k < P.count; ++k) {
    P.mat[k] = 0;
    P.geom[k] = 0;
    P.prim[k] = k % 2;  // triangles (0 1 2) and (0 2 3)
    const float a = U(rng), b = U(rng) * (1.f - a);
    P.bu[k] = a;
    P.bv[k] = b;
  }
  apply_roughness_textures(views.geom, P);
  for (int k = 0; k < P.count; ++k) {
    // uv of the hit: triangle 0 has uv (0,0) (1,0) (1,1), triangle 1 (0,0) (1,1) (0,1)
    const double b1 = P.bu[k], b2 = P.bv[k];
    const double u = k % 2 == 0 ? b1 + b2 : b1;
    const double v = k % 2 == 0 ? b2 : b1 + b2;
    (void)v;  // one row: v does not matter
    double x = u * 4 - 0.5;
    const double fx = x - std::floor(x);
    int x0 = static_cast<int>(std::floor(x)), x1 = x0 + 1;
    x0 = (x0 + 4) % 4;
    x1 = x1 % 4;
    const double r = (1 - fx) * t.value[static_cast<size_t>(x0)] + fx * t.value[static_cast<size_t>(x1)];
    EXPECT_NEAR(P.ax[k], std::sqrt(r), 2e-6) << "point " << k << " u " << u;
    EXPECT_EQ(P.ay[k], 0.3f);
  }
  // a one-texel texture renders as the constant alpha it remaps to (0.0625 -> 0.25)
  auto render = [&](bool textured) {
    Scene c = s;
    c.materials[0].alpha_u = textured ? FloatParam{0.f, 0} : FloatParam{0.25f, -1};
    c.float_textures[0].width = 1;
    c.float_textures[0].value = {0.0625f};
    c.camera.width = c.camera.height = 16;
    camera_look_at(c.camera, {0.5f, 1.5f, -0.8f}, {0.5f, 0, 0.5f}, {0, 1, 0});
    finalize_scene(c);
    Accel accel(c);
    RenderOptions o;
    o.est.spp = 16;
    Renderer r(c, accel, o);
    Film film;
    r.render(film, 0, o.est.spp);
    return film.mean();
  };
  const std::vector<float> a = render(true), b = render(false);
  double sum = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_NEAR(a[i], b[i], 1e-5 * (std::abs(b[i]) + 1e-3)) << i;
    sum += b[i];
  }
  EXPECT_GT(sum, 0.0);
}

// A checkpoint refuses another scene's render: the fingerprint follows every parameter a
// surface renders with (roughness, indices, normals, float textures), while a plain diffuse
// scene keeps the fingerprint of earlier releases (no new fields enter it).
TEST(Materials, CheckpointFingerprintFollowsTheSurfaces) {
  Scene s = every_surface();
  finalize_scene(s);
  RenderOptions o;
  const PassPlan plan = fixed_passes(16 * 16);
  const std::string base = render_fingerprint(s, o, plan);
  std::vector<std::function<void(Scene&)>> changes = {
      [](Scene& c) { c.materials[1].alpha_u.value += 0.01f; },
      [](Scene& c) { c.materials[3].eta = 1.33f; },
      [](Scene& c) { c.materials[1].k_rgb.g = 1.f; },
      [](Scene& c) { c.materials[6].transmittance.b = 0.1f; },
      [](Scene& c) { c.materials[2].kind = MaterialKind::dielectric; },
      [](Scene& c) { c.meshes.back().normals.assign(c.meshes.back().positions.size() - 1, 0.5f); }};
  for (size_t i = 0; i < changes.size(); ++i) {
    Scene c = s;
    changes[i](c);
    EXPECT_NE(render_fingerprint(c, o, plan), base) << "change " << i;
  }
}

// ... and the media (their coefficients, which shapes bound them, the camera's), the skies'
// maps and the shapes' alpha: a resume after any of them changed was accepted, and averaged
// two scenes' samples.
TEST(Materials, CheckpointFingerprintFollowsMediaSkiesAndAlpha) {
  Scene s = every_surface();
  Medium fog;
  fog.supported = true;
  fog.sigma_s = {0.5f, 0.5f, 0.5f};
  s.media.push_back(fog);
  s.meshes[0].medium_inside = 0;
  SkyMap sky;
  sky.res = 2;
  sky.texels.assign(4 * 4, 1.f);
  s.sky_maps.push_back(sky);
  Light l;
  l.type = LightKind::infinite;
  l.radiance = {1, 1, 1};
  l.sky_map = 0;
  s.lights.push_back(l);
  s.lights.push_back(point_light({0, 1, 0}, {1, 1, 1}));
  finalize_scene(s);
  RenderOptions o;
  const PassPlan plan = fixed_passes(16 * 16);
  const std::string base = render_fingerprint(s, o, plan);
  std::vector<std::function<void(Scene&)>> changes = {
      [](Scene& c) { c.media[0].sigma_s.g = 0.25f; },
      [](Scene& c) { c.media[0].g = 0.3f; },
      [](Scene& c) { c.media[0].Le.r = 1.f; },
      [](Scene& c) { c.camera_medium = 0; },
      [](Scene& c) { c.meshes[0].medium_inside = -1; },
      [](Scene& c) {  // the point source in the medium
        for (Light& pl : c.lights)
          if (pl.type == LightKind::point) pl.medium = 0;
      },
      [](Scene& c) { c.sky_maps[0].texels[5] = 2.f; },
      [](Scene& c) { c.meshes[0].alpha.value = 0.5f; }};
  for (size_t i = 0; i < changes.size(); ++i) {
    Scene c = s;
    changes[i](c);
    EXPECT_NE(render_fingerprint(c, o, plan), base) << "change " << i;
  }
}
