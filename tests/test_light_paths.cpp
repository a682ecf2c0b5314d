// --light-paths (src/render/light_paths.h): the light tracer takes the caustic paths (the
// vertex next to an area light scatters by a delta lobe, the first vertex from the camera
// is diffuse or in a medium) and the path tracer leaves them out. The split is unbiased: images with and
// without it have the same mean, in a room with a glass sphere and a mirror (caustics on
// the floor and the walls, seen directly and through the mirror; a light seen through the
// glass; a coat with a delta and a diffuse lobe), with shading normals on the glass ball's
// mesh, a sphere source and the triangle filter, and
// in a medium whose caustic the glass throws (the light tracer's vertices in the medium,
// joined to a camera outside it through an interface). The means are compared over
// independent seeds (the light paths' splats are not in the per-pixel variance), quarter by
// quarter and channel by channel; and under a sun whose glints off glossy things (a metal
// plate, a coated ball, a mix with a glazed coat) light a wall in its own shade, with and
// without an area light and a glass ball beside it (the light tracer's distant source, its
// discs, and the path tracer's light samples left out); and under point and spot sources,
// whose caustics the path tracer has no sample of, against bdpt. Also: the same bits on any
// thread count, and an image that
// differs from the path tracer's alone (the light paths were traced).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "app/cli.h"
#include "media_util.h"
#include "output_files.h"
#include "render/light_paths.h"
#include "render/options.h"
#include "wave/generate.h"
#include "caustic_room.h"
#include "render_util.h"

using namespace tuile;
using namespace tuile::test;

namespace {

RenderOptions options(bool light_paths, uint32_t spp, uint32_t seed) {
  RenderOptions o = independent_options(Strategy::mis, LightPick::power, MisMode::multi, 6, spp, seed);
  o.est.light_paths = light_paths;
  return o;
}

}  // namespace

TEST(LightPaths, RendersThePathTracersMean) {
  const Scene s = caustic_room(24);
  const uint32_t spp = static_cast<uint32_t>(scaled(96));
  expect_same_mean_over_seeds(s, options(true, spp, 0), options(false, spp, 0), 24, "caustic room");
}

// An emitter with an alpha cut-out (a constant 0.5: the rays that meet it pass half the
// time): the light paths' points on it emit half its radiance, as the path tracer's light
// samples weigh it (emitter_alpha). Without the alpha, z reaches 46.
TEST(LightPaths, RendersThePathTracersMeanUnderACutOutEmitter) {
  Scene s = caustic_room(24, false, false);
  for (Mesh& m : s.meshes)
    if (m.name == "light") m.alpha.value = 0.5f;
  finalize_scene(s);
  const uint32_t spp = static_cast<uint32_t>(scaled(96));
  expect_same_mean_over_seeds(s, options(true, spp, 0), options(false, spp, 0), 24, "caustic room, cut-out emitter");
}

TEST(LightPaths, RendersThePathTracersMeanWithShadingNormalsASphereSourceAndATriangleFilter) {
  const Scene s = caustic_room(24, true, true, true);
  const uint32_t spp = static_cast<uint32_t>(scaled(96));
  RenderOptions with = options(true, spp, 0), without = options(false, spp, 0);
  with.filter = without.filter = default_filter(FilterKind::triangle);
  expect_same_mean_over_seeds(s, with, without, 24, "shading normals, triangle filter");
}

TEST(LightPaths, RendersThePathTracersMeanInAMedium) {
  const Scene s = caustic_fog_room(20, {0.4f, 0.35f, 0.3f});
  const uint32_t spp = static_cast<uint32_t>(scaled(64));
  expect_same_mean_over_seeds(s, options(true, spp, 0), options(false, spp, 0), 24, "fog");
}

// A glass slab seen from below, lit from above: its top is smooth, its other faces diffuse
// transmitters, so light that entered by the top (a delta lobe) leaves by the bottom, where
// the light tracer's vertex inside the glass joins the camera. Its throughput must carry the
// entry's etap^2 (importance is not scaled by 1 / eta^2 as radiance is): without it this
// image is 2.25 times too dark.
TEST(LightPaths, RendersThePathTracersMeanThroughAGlassSlab) {
  const Scene s = glass_slab_scene();
  const uint32_t spp = static_cast<uint32_t>(scaled(64));
  expect_same_mean_over_seeds(s, options(true, spp, 0), options(false, spp, 0), 24, "glass slab");
}

// A wall in its own shade: a distant source behind it and a dim constant sky over dark
// ground, so that the wall's face is lit mostly by the sun's glints off near-specular things
// in front of it (light_paths.h, "Distant sources"): a metal plate of alpha 0.1 tilted to
// throw the sun back onto the wall, a coated ball of alpha 0.08 (a sphere: its disc from the
// sphere) and a plate whose material is a mix of a coat of alpha 0.06 and a diffuse one
// (lobes wide enough that the path tracer's image, the reference, is not all noise). With
// `more`, a glass ball and an area light before the wall too (the light tracer picks
// between the two kinds of source), and the metal plate rougher than the flag's bound (its
// glints stay the path tracer's). With `coated_wall`, the wall a coated diffuse of alpha 0.3
// (the camera's first vertex a coat: its glints from the sun are the light tracer's,
// sun_traced_material, and an area light's caustics through the glass stay the path tracer's).
Scene sun_wall(int res, bool more, bool sphere_sun = false, bool coated_wall = false) {
  Scene s;
  s.source = "test:sun-wall";
  s.materials.push_back(diffuse_material(Rgb{0.7f, 0.7f, 0.7f}));  // 0
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.3f, 0.2f}));  // 1
  Material metal;
  metal.kind = MaterialKind::conductor;
  metal.eta_rgb = {0.2f, 0.9f, 1.1f};
  metal.k_rgb = {3.9f, 2.4f, 2.1f};
  metal.alpha_u.value = metal.alpha_v.value = more ? 0.3f : 0.1f;
  s.materials.push_back(metal);  // 2
  Material coat;
  coat.kind = MaterialKind::coated_diffuse;
  coat.reflectance = {0.3f, 0.5f, 0.6f};
  coat.alpha_u.value = coat.alpha_v.value = 0.08f;
  s.materials.push_back(coat);  // 3
  Material glaze = coat;
  glaze.alpha_u.value = glaze.alpha_v.value = 0.06f;
  s.materials.push_back(glaze);  // 4
  Material mix;
  mix.mix[0] = 4;
  mix.mix[1] = 0;
  mix.mix_amount.value = 0.4f;
  s.materials.push_back(mix);  // 5
  s.materials.push_back(glass_material());  // 6
  s.materials.push_back(diffuse_material(Rgb{0.02f, 0.02f, 0.02f}));  // 7
  Material wall_coat = coat;
  wall_coat.reflectance = {0.7f, 0.7f, 0.7f};
  wall_coat.alpha_u.value = wall_coat.alpha_v.value = 0.3f;
  s.materials.push_back(wall_coat);  // 8
  add_named_quad(s, "ground", 7, {-3, 0, -2.5f}, {0, 0, 6}, {6, 0, 0});  // dark: the wall's light is the glints'
  add_named_quad(s, "wall", coated_wall ? 8 : 0, {-2, 0, -2.5f}, {4, 0, 0}, {0, 1.5f, 0});
  // facing (0, 0.48, -0.88): they throw the sun from behind the wall back onto its shaded face
  add_named_quad(s, "plate", 2, {-0.45f, 0.14f, 0.36f}, {0, 0.528f, 0.288f}, {0.9f, 0, 0});
  add_named_quad(s, "glazed", 5, {-1.7f, 0.1f, 0.2f}, {0, 0.44f, 0.24f}, {0.7f, 0, 0});
  Sphere ball;
  ball.center = {1.1f, 0.3f, 0.3f};
  ball.radius = 0.3f;
  ball.material = 3;
  s.spheres.push_back(ball);
  if (more) {
    Sphere g = ball;
    g.center = {-0.8f, 0.3f, -1.6f};
    g.radius = 0.3f;
    g.material = 6;
    s.spheres.push_back(g);
    add_named_quad(s, "light", 0, {-1.2f, 1.2f, -1.9f}, {0.5f, 0, 0}, {0, 0, 0.5f}, 3);  // facing down
  }
  if (sphere_sun) {  // an area source where the sun would be: behind the wall, above it
    Sphere lamp;
    lamp.center = {0, 6.2f, -5.6f};  // (out of the camera's view)
    lamp.radius = 0.3f;
    lamp.material = 0;
    lamp.emission = {750, 750, 650};
    s.spheres.push_back(lamp);
  } else {
    s.lights.push_back(distant_light({0.f, 1.f, -1.2f}, {3, 3, 2.6f}));  // behind the wall
  }
  Light sky;
  sky.type = LightKind::infinite;
  sky.radiance = {0.03f, 0.04f, 0.06f};
  s.lights.push_back(sky);
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 60;
  camera_look_at(s.camera, {0, 0.8f, 2.5f}, {0, 0.6f, -2.5f}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

// The sun's glints: the path tracer leaves them to the light tracer at near-specular
// vertices after a rough first one, and the light tracer emits towards those surfaces.
TEST(LightPaths, RendersThePathTracersMeanUnderASun) {
  const Scene s = sun_wall(24, false);
  const uint32_t spp = static_cast<uint32_t>(scaled(384));  // (the path tracer's glints: its error)
  expect_same_mean_over_seeds(s, options(true, spp, 0), options(false, spp, 0), 24, "sun");
  // the light tracer ran (the scene has no area light): the same seed renders otherwise
  Accel accel(s);
  EXPECT_NE(render_mean(s, accel, options(true, 4, 3), 4), render_mean(s, accel, options(false, 4, 3), 4));
}

// A coated wall: the glints the sun throws on it are the light tracer's, joined to the camera
// at the coat; with the glass ball and the area light too, whose caustics on the coat stay
// the path tracer's (an area source's split takes rough first vertices alone).
TEST(LightPaths, RendersThePathTracersMeanUnderASunOnACoatedWall) {
  const uint32_t spp = static_cast<uint32_t>(scaled(384));
  const Scene s = sun_wall(24, false, false, true);
  expect_same_mean_over_seeds(s, options(true, spp / 2, 0), options(false, spp / 2, 0), 24, "sun, coated wall");
  const Scene more = sun_wall(24, true, false, true);
  expect_same_mean_over_seeds(more, options(true, spp, 0), options(false, spp, 0), 24, "sun, area light, coated wall");
}

// --light-paths=glossy: the same wall lit by an area source in the sun's place, its light
// off the near-specular surfaces (the plate, the coated ball, the mix) now the light
// tracer's, both of the path tracer's techniques at those vertices left out.
TEST(LightPaths, GlossyRendersThePathTracersMeanUnderASphereSource) {
  const Scene s = sun_wall(24, false, true);
  const uint32_t spp = static_cast<uint32_t>(scaled(256));
  RenderOptions glossy = options(true, spp, 0);
  glossy.est.light_paths_glossy = true;
  expect_same_mean_over_seeds(s, glossy, options(false, spp, 0), 24, "sphere source, glossy");
  // the split ran: the same seed renders otherwise than with --light-paths alone (which has
  // nothing to trace here: no delta lobe, no distant source)
  Accel accel(s);
  glossy.est.spp = 4;
  glossy.est.seed = 3;
  EXPECT_NE(render_mean(s, accel, glossy, 4), render_mean(s, accel, options(true, 4, 3), 4));
  EXPECT_EQ(render_mean(s, accel, options(true, 4, 3), 4), render_mean(s, accel, options(false, 4, 3), 4));
}

TEST(LightPaths, RendersThePathTracersMeanUnderASunAndAnAreaLight) {
  const Scene s = sun_wall(24, true);
  const uint32_t spp = static_cast<uint32_t>(scaled(96));
  expect_same_mean_over_seeds(s, options(true, spp, 0), options(false, spp, 0), 24, "sun and area light");
}

// Point and spot sources in the caustic room without its glass ball and slab: the mirror
// and the smooth coat on the back wall throw their light on the floor and the walls. The
// path tracer has no sample of those paths (a light sample stops at the delta lobe, no BSDF
// sample meets a point), so its image alone is darker where they fall; with the light
// tracer's paths from those sources it renders bdpt's mean (tests/test_bdpt.cpp checks bdpt
// against the path tracer where both sample everything). The camera, by the back wall,
// sees no delta lobe (a caustic seen in a mirror is neither estimator's: the light tracer
// joins the camera directly), but a rough metal right wall and a rough coat on the front
// wall, at which the light paths of these sources join the camera too. The area light
// dimmed a hundred times, so that these caustics are a large share of the image.
Scene point_and_spot_room() {
  Scene s = caustic_room(20, false, false);
  s.spheres.clear();
  std::vector<Mesh> kept;
  for (Mesh& m : s.meshes) {
    if (m.name == "slab" || m.name == "slab top") continue;
    if (m.name == "light") m.emission = {m.emission.r * 0.01f, m.emission.g * 0.01f, m.emission.b * 0.01f};
    kept.push_back(m);
  }
  s.meshes = kept;
  Material metal;
  metal.kind = MaterialKind::conductor;
  metal.eta_rgb = {0.2f, 0.9f, 1.1f};
  metal.k_rgb = {3.9f, 2.4f, 2.1f};
  metal.alpha_u.value = metal.alpha_v.value = 0.3f;
  Material coat;
  coat.kind = MaterialKind::coated_diffuse;
  coat.reflectance = {0.5f, 0.4f, 0.3f};
  coat.alpha_u.value = coat.alpha_v.value = 0.2f;
  const int metal_m = static_cast<int>(s.materials.size()), coat_m = metal_m + 1;
  s.materials.push_back(metal);
  s.materials.push_back(coat);
  for (Mesh& m : s.meshes) {
    if (m.name == "right") m.material = metal_m;
    if (m.name == "front") m.material = coat_m;
  }
  s.lights.push_back(point_light({0.6f, 1.5f, -0.2f}, {0.6f, 0.5f, 0.4f}));
  // a spot at the back wall's smooth coat
  s.lights.push_back(spot_light({-0.4f, 1.8f, 0.6f}, {0.1f, -0.6f, -1}, std::cos(0.3f), std::cos(0.5f), {2, 2, 2.5f}));
  camera_look_at(s.camera, {0, 1.6f, -1.4f}, {0, 0, 1.0f}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

// A sun over a thin glass pane above a diffuse floor, the camera under the pane looking down
// (SunThroughAWindowPaneIsExact).
Scene sun_window(vec3f sun_dir) {
  Scene s;
  s.source = "test:sun-window";
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  Material pane;
  pane.kind = MaterialKind::thin_dielectric;
  pane.eta = 1.5f;
  s.materials.push_back(pane);
  add_named_quad(s, "floor", 0, {-3, 0, -3}, {0, 0, 6}, {6, 0, 0});
  add_named_quad(s, "pane", 1, {-1, 1, -1}, {2, 0, 0}, {0, 0, 2});
  s.lights.push_back(distant_light(sun_dir, {2, 2, 2}));
  s.camera.width = s.camera.height = 16;
  s.camera.fov_deg = 60;
  camera_look_at(s.camera, {0, 0.9f, 0}, {0, 0, 0}, {0, 0, 1});
  finalize_scene(s);
  return s;
}

TEST(LightPaths, RendersBdptsMeanUnderPointAndSpotSources) {
  const Scene s = point_and_spot_room();
  RenderOptions lp = options(true, static_cast<uint32_t>(scaled(96)), 0), bdpt = options(false, static_cast<uint32_t>(scaled(32)), 0);
  lp.est.max_depth = bdpt.est.max_depth = 4;
  bdpt.est.bdpt = true;
  expect_same_mean_over_seeds(s, lp, bdpt, 24, "point and spot sources, light paths against bdpt");
}

// auto turns the light tracer on for a point or spot source's caustics: a positional source
// and a surface with a delta lobe, in a scene without media; not where every surface is
// rough (the path tracer samples everything there).
TEST(LightPaths, AutoIsOnForAPointOrSpotSourcesCaustics) {
  auto resolved = [](Scene s) {
    RenderFlags f;
    f.max_depth = 5;
    f.max_depth_given = true;
    return resolve_options(f, s).est.light_paths;
  };
  Scene s = caustic_room(16, false, false);
  for (Mesh& m : s.meshes)
    if (m.name == "light") m.emission = {0, 0, 0};  // (its own caustics: off, AutoIsOnForASmallLampsCausticsOnSurfaces)
  s.lights.push_back(spot_light({0.6f, 1.8f, 0.8f}, {-0.5f, -1, -0.6f}, std::cos(0.3f), std::cos(0.5f), {2, 2, 2}));
  Scene rough = s;
  finalize_scene(s);
  EXPECT_TRUE(resolved(s));
  for (Material& m : rough.materials)
    if (m.kind != MaterialKind::diffuse) m.alpha_u.value = m.alpha_v.value = std::max(m.alpha_u.value, 0.3f);
  finalize_scene(rough);
  EXPECT_FALSE(resolved(rough));
  Scene dark = s;  // a source of no intensity
  dark.lights.back().radiance = {0, 0, 0};
  finalize_scene(dark);
  EXPECT_FALSE(resolved(dark));
  // a sun through a window pane: on; the pane made rough glass: off
  EXPECT_TRUE(resolved(sun_window(vec3f{0.2f, 1, 0.1f})));
  Scene frosted = sun_window(vec3f{0.2f, 1, 0.1f});
  frosted.materials[1] = glass_material();
  frosted.materials[1].alpha_u.value = frosted.materials[1].alpha_v.value = 0.3f;
  finalize_scene(frosted);
  EXPECT_FALSE(resolved(frosted));
}

// The transmittance of pbrt-v4's thin dielectric (ThinDielectricBxDF) at incidence cos c:
// 1 - R, R = F + (1 - F)^2 F / (1 - F^2) with the inner reflections, F Fresnel's.
double thin_pane_transmittance(double c, double eta) {
  const double st = std::sqrt(1 - c * c) / eta, ct = std::sqrt(1 - st * st);
  const double rs = (c - eta * ct) / (c + eta * ct), rp = (eta * c - ct) / (eta * c + ct);
  const double F = 0.5 * (rs * rs + rp * rp);
  return 1 - (F + (1 - F) * (1 - F) * F / (1 - F * F));
}

// The image mean (over pixels and channels) of 12 seeds of o with light paths, at depth 2,
// against `expected` at |z| < 5 (a false failure about once in 10^6 runs); the standard
// error below rel times expected at full size (the test's power; the bound grows as the
// test scale shrinks the samples); and the path tracer alone black.
void expect_light_paths_mean(const Scene& s, double expected, double rel, const char* what) {
  Accel accel(s);
  RenderOptions o = options(true, static_cast<uint32_t>(scaled(256)), 0);
  o.est.max_depth = 2;
  const int seeds = 12;
  std::vector<double> means;
  for (int k = 0; k < seeds; ++k) {
    o.est.seed = static_cast<uint32_t>(k + 1);
    const std::vector<float> m = render_mean(s, accel, o, o.est.spp);
    double sum = 0;
    for (float val : m) sum += val;
    means.push_back(sum / static_cast<double>(m.size()));
  }
  double mean = 0, var = 0;
  for (double m : means) mean += m / seeds;
  for (double m : means) var += (m - mean) * (m - mean) / (seeds - 1);
  const double se = std::sqrt(var / seeds), z = (mean - expected) / se;
  std::printf("[ %s ] mean %.6f, expected %.6f, z %.2f, std. error %.2g\n", what, mean, expected, z, se);
  EXPECT_LT(std::abs(z), 5.0) << what;
  EXPECT_LT(se, rel * expected * std::sqrt(256.0 / o.est.spp)) << what;
  o.est.light_paths = false;
  for (float val : render_mean(s, accel, o, 4)) ASSERT_EQ(val, 0.f) << what;
}

// A sun through a window: a thin glass pane (pbrt-v4's thindielectric) between a distant
// source and a diffuse floor, seen from under the pane at depth 2 (the light through the
// pane and nothing else). The path tracer has no sample of it (its light sample stops at the
// pane, no BSDF sample meets a direction), so its image is black; the light tracer's paths
// from the sun through the pane's delta lobe render it. Every pixel's expectation is
// rho / pi E cos(theta) T(theta), T the pane's transmittance with its inner reflections
// (pbrt-v4's ThinDielectricBxDF: R = F + (1 - F)^2 F / (1 - F^2)). The image means of 12
// seeds against it, at |z| < 5 (a false failure about once in 10^6 runs).
TEST(LightPaths, SunThroughAWindowPaneIsExact) {
  const vec3f dir = normalize(vec3f{0.2f, 1, 0.1f});
  const double c = dir.y;
  // (3% off fails at full size)
  expect_light_paths_mean(sun_window(dir), 0.5 / 3.14159265358979323846 * 2 * c * thin_pane_transmittance(c, 1.5), 0.005,
                          "sun through a pane");
}

TEST(LightPaths, PointSourceThroughAPaneInAnAbsorbingMediumIsExact) {
  PlaneScene p = plane_scene({0, 0.9f, 0}, 50, 12);
  Scene& s = p.scene;
  const float sigma = 0.4f;
  s.media.push_back(homogeneous({sigma, sigma, sigma}, {0, 0, 0}));
  Material pane;
  pane.kind = MaterialKind::thin_dielectric;
  pane.eta = 1.5f;
  s.materials.push_back(pane);
  add_named_quad(s, "pane", 1, {-3, 1, -3}, {6, 0, 0}, {0, 0, 6});
  for (Mesh& m : s.meshes) m.medium_inside = m.medium_outside = 0;
  s.camera_medium = 0;
  const Light light = point_light({0.2f, 1.6f, 0.1f}, {2, 2, 2});
  s.lights.push_back(light);
  s.lights.back().medium = 0;
  finalize_scene(s);
  // the pixels' expectations
  double expected = 0;
  for (const double e : floor_pixel_means(s, 8, [&](double x, double z, double cam) {
         const double w[3] = {light.p0.x - x, light.p0.y, light.p0.z - z};
         const double r = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]), c = w[1] / r;
         return p.rho / 3.14159265358979323846 * 2 * c / (r * r) * thin_pane_transmittance(c, 1.5) *
                std::exp(-sigma * (r + cam));
       }))
    expected += e;
  expected /= static_cast<double>(s.camera.width) * s.camera.height;
  expect_light_paths_mean(s, expected, 0.02, "point source through a pane in an absorbing medium");
}

TEST(LightPaths, SameBitsOnAnyThreadCount) {
  expect_same_bits_on_any_thread_count(caustic_room(20), options(true, 12, 5), options(false, 12, 5), 12);
}

TEST(LightPaths, RefusesWhatItCannotDo) {
  RenderOptions o = options(true, 4, 0);
  o.est.max_depth = 1;
  EXPECT_THROW(validate(o), std::invalid_argument);
  o = options(true, 4, 0);
  o.aov_variance = true;
  EXPECT_THROW(validate(o), std::invalid_argument);
  // a part of the tiles (a distributed render)
  const Scene s = caustic_room(16);
  Accel accel(s);
  Renderer r(s, accel, options(true, 4, 0));
  Film f;
  f.reset(16, 16);
  const std::vector<int> tiles{0};
  EXPECT_THROW(r.render(f, 0, 4, nullptr, &tiles), std::invalid_argument);
  // nothing to trace without a delta lobe: the path tracer renders alone, the same bits
  Scene plain = caustic_room(16, false, false);
  for (Material& m : plain.materials) m = diffuse_material(Rgb{0.5f, 0.5f, 0.5f});
  finalize_scene(plain);
  Accel pa(plain);
  EXPECT_EQ(render_mean(plain, pa, options(true, 4, 0), 4), render_mean(plain, pa, options(false, 4, 0), 4));
  // nothing the light tracer could join to the camera (every surface a coat or glass, the
  // light's own material black diffuse): inactive, no light path traced
  auto active = [](const Scene& sc) {
    SceneViews v = build_views(sc, LightPick::power);
    const float lo[3] = {-2, -1, -2}, hi[3] = {2, 3, 4};
    return LightPaths(sc, v, options(true, 4, 0).est, 16, 16, lo, hi).active();
  };
  EXPECT_TRUE(active(caustic_room(16)));
  Scene coats = caustic_room(16, false, false);
  for (Material& m : coats.materials)
    if (m.kind == MaterialKind::diffuse) {
      m.kind = MaterialKind::coated_diffuse;
      m.alpha_u.value = m.alpha_v.value = 0.3f;
    }
  const int black = static_cast<int>(coats.materials.size());
  coats.materials.push_back(diffuse_material(Rgb{0, 0, 0}));
  for (Mesh& m : coats.meshes)
    if (m.name == "light") m.material = black;
  finalize_scene(coats);
  EXPECT_FALSE(active(coats));
  coats.materials[static_cast<size_t>(black)].reflectance = {0.1f, 0.1f, 0.1f};  // a grey light housing: something to join
  EXPECT_TRUE(active(coats));
}

// The default, auto: on where the scene holds paths only the light tracer finds at a steady
// rate (a sun's glints off near-specular surfaces; an area light's caustics through smooth
// glass or a mirror into a fog), off where the path tracer has them (glints of a rougher
// lobe, caustics on surfaces alone or in a fog that only absorbs) and wherever a flag or the
// scene refuses the light tracer.
TEST(LightPaths, AutoIsOnWhereOnlyTheLightTracerFindsThePaths) {
  auto resolved = [](Scene s, const std::string& value, int max_depth = 5, const std::string& aov = "",
                     double target_error = 0) {
    RenderFlags f;
    f.light_paths = value;
    f.max_depth = max_depth;
    f.max_depth_given = true;
    f.aov = aov;
    f.target_error = target_error;
    return resolve_options(f, s).est.light_paths;
  };
  const Scene sun = sun_wall(16, false);
  EXPECT_TRUE(resolved(sun, ""));
  EXPECT_TRUE(resolved(sun, "auto"));
  EXPECT_TRUE(resolved(sun, "on"));
  EXPECT_TRUE(resolved(sun, "true"));
  EXPECT_FALSE(resolved(sun, "off"));
  EXPECT_FALSE(resolved(sun, "false"));
  EXPECT_THROW(resolved(sun, "sometimes"), std::invalid_argument);
  {
    RenderFlags f;
    f.light_paths = "glossy";
    f.max_depth = 5;
    f.max_depth_given = true;
    Scene s = sun;
    const RenderOptions o = resolve_options(f, s);
    EXPECT_TRUE(o.est.light_paths && o.est.light_paths_glossy);
    EXPECT_NE(describe(o.est).find("light-paths=glossy"), std::string::npos);
    f.strategy = "ris";
    EXPECT_THROW(resolve_options(f, s), std::invalid_argument);
    f.light_paths = "on";
    EXPECT_FALSE(resolve_options(f, s).est.light_paths_glossy);
  }
  // what refuses the light tracer turns auto off, and makes on an error
  EXPECT_FALSE(resolved(sun, "", 1));
  EXPECT_THROW(resolved(sun, "on", 1), std::invalid_argument);
  EXPECT_FALSE(resolved(sun, "", 5, "variance"));
  EXPECT_THROW(resolved(sun, "on", 5, "variance"), std::invalid_argument);
  EXPECT_FALSE(resolved(sun, "", 5, "", 0.01));
  {  // with --guide too (under mpirun as in one process: tests/test_mpi.cpp)
    RenderFlags f;
    f.max_depth = 5;
    f.max_depth_given = true;
    f.guide = true;
    Scene s = sun;
    EXPECT_TRUE(resolve_options(f, s).est.light_paths);
  }
  EXPECT_TRUE(resolved(sun, "", 5, "mis_weight"));
  // the glossy surfaces rougher than the light tracer's bound, or smooth metals and coats (a
  // delta lobe: their light from a delta source is no path of the path tracer's, but left
  // out: LightPaths' comment), the path tracer's; smooth glass (a window) the light tracer's
  for (const float alpha : {0.3f, 5e-4f}) {
    Scene s = sun;
    for (Material& m : s.materials)
      if (m.kind != MaterialKind::diffuse) m.alpha_u.value = m.alpha_v.value = alpha;
    EXPECT_FALSE(resolved(s, "")) << alpha;
    EXPECT_TRUE(resolved(s, "on")) << alpha;
    s.materials[2] = glass_material();
    s.materials[2].alpha_u.value = s.materials[2].alpha_v.value = alpha;
    EXPECT_EQ(resolved(s, ""), alpha < 1e-3f) << alpha;
  }
  // a glossy material no surface carries
  {
    Scene s = sun;
    for (Mesh& m : s.meshes)
      if (m.material != 0 && m.material != 7) m.material = 0;
    for (Sphere& sp : s.spheres) sp.material = 0;
    EXPECT_FALSE(resolved(s, ""));
  }
  // an area light, glass and a mirror: caustics on surfaces, the path tracer's
  EXPECT_FALSE(resolved(caustic_room(16), ""));
  // ... and in a fog that scatters: the light tracer's; in one that only absorbs, not
  const Scene fog = caustic_fog_room(16, {0.4f, 0.35f, 0.3f});
  EXPECT_TRUE(resolved(fog, ""));
  EXPECT_FALSE(resolved(caustic_fog_room(16, {0, 0, 0}), ""));
  {  // the fog room without a delta lobe (the glass, the mirror and the coat rough)
    Scene s = fog;
    for (Material& m : s.materials)
      if (m.kind != MaterialKind::diffuse) m.alpha_u.value = m.alpha_v.value = 0.2f;
    EXPECT_FALSE(resolved(s, ""));
  }
  {  // an emitter with an alpha cut-out: the light tracer's too
    Scene s = fog;
    for (Mesh& m : s.meshes)
      if (m.name == "light") m.alpha.value = 0.5f;
    EXPECT_TRUE(resolved(s, ""));
  }
}

// A small bright lamp over a near-mirror (alpha 0.01), a wall catching its glint: the
// paths wall -> mirror -> lamp that the path tracer finds only by chance (veach-mis's back
// wall under its smallest lamp). `lamp_radius` 0.01 at 1.5 above the mirror's centre.
Scene glint_room(float lamp_radius, float mirror_alpha, float mirror_size = 2) {
  Scene s;
  s.source = "test:glint-room";
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.6f, 0.6f}));  // 0
  Material metal;
  metal.kind = MaterialKind::conductor;
  metal.eta_rgb = {0.2f, 0.9f, 1.1f};
  metal.k_rgb = {3.9f, 2.4f, 2.1f};
  metal.alpha_u.value = metal.alpha_v.value = mirror_alpha;
  s.materials.push_back(metal);  // 1
  const float h = 0.5f * mirror_size;
  add_named_quad(s, "mirror", 1, {-h, 0, -h}, {0, 0, mirror_size}, {mirror_size, 0, 0});  // facing up
  add_named_quad(s, "wall", 0, {-3, -1, -3}, {6, 0, 0}, {0, 5, 0});
  Sphere lamp;
  lamp.center = {0, 1.5f, 0};
  lamp.radius = lamp_radius;
  lamp.material = 0;
  lamp.emission = {5000, 5000, 5000};
  s.spheres.push_back(lamp);
  s.camera.width = s.camera.height = 16;
  camera_look_at(s.camera, {0, 1, 6}, {0, 1, 0}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

// auto's third choice, glossy: where at least 1% of the area sources' power falls on
// near-specular surfaces from a source that looks small from them (light_paths_pay).
TEST(LightPaths, AutoIsGlossyUnderASmallLampOverANearMirror) {
  auto resolved = [](Scene s, const std::string& strategy = "") {
    RenderFlags f;
    f.max_depth = 5;
    f.max_depth_given = true;
    if (!strategy.empty()) f.strategy = strategy;
    const RenderOptions o = resolve_options(f, s);
    return o.est.light_paths_glossy ? std::string("glossy") : o.est.light_paths ? std::string("on") : std::string("off");
  };
  EXPECT_EQ(resolved(glint_room(0.01f, 0.01f)), "glossy");
  EXPECT_EQ(resolved(glint_room(0.01f, 0.01f), "light"), "glossy");
  EXPECT_EQ(resolved(glint_room(0.01f, 0.01f), "ris"), "off");  // (--light-paths=glossy refuses ris)
  // a larger lamp (solid angle 0.014 sr), a rougher mirror (a lobe of 0.03 sr), or a mirror
  // that catches a thousandth of the light: the path tracer's; a smooth one (a delta lobe):
  // the light tracer's caustics, on (AutoIsOnForASmallLampsCausticsOnSurfaces)
  EXPECT_EQ(resolved(glint_room(0.1f, 0.01f)), "off");
  EXPECT_EQ(resolved(glint_room(0.01f, 0.05f)), "off");
  EXPECT_EQ(resolved(glint_room(0.01f, 5e-4f)), "on");
  EXPECT_EQ(resolved(glint_room(0.01f, 0.01f, 0.15f)), "off");
  // the share itself: a mirror of area A straight under a lamp at distance d receives
  // A / (4 pi d^2) of a sphere's power, A / (pi d^2) of a small square facing it
  const double pi = 3.14159265358979323846;
  const double A = 0.1 * 0.1, d2 = 1.5 * 1.5;
  EXPECT_NEAR(area_glint_share(glint_room(0.01f, 0.01f, 0.1f)), A / (4 * pi * d2), 0.01 * A / (4 * pi * d2));
  Scene square = glint_room(0.01f, 0.01f, 0.1f);
  square.spheres.clear();
  add_named_quad(square, "lamp", 0, {-0.005f, 1.5f, -0.005f}, {0.01f, 0, 0}, {0, 0, 0.01f}, 5000);  // facing down
  finalize_scene(square);
  EXPECT_NEAR(area_glint_share(square), A / (pi * d2), 0.01 * A / (pi * d2));
  EXPECT_EQ(area_glint_share(glint_room(0.1f, 0.01f, 0.1f)), 0);  // (not small)
  // no area source: no share
  Scene dark = glint_room(0.01f, 0.01f);
  dark.spheres.clear();
  Light sun;
  sun.type = LightKind::distant;
  sun.e1 = vec3f{0, 1, 0};
  sun.radiance = {3, 3, 3};
  dark.lights.push_back(sun);
  finalize_scene(dark);
  EXPECT_EQ(area_glint_share(dark), 0);
  EXPECT_EQ(resolved(dark), "on");  // (the sun's glints)
}

// auto's caustics onto surfaces: on where at least 0.3% of the area sources' power falls
// on smooth glass or mirrors from a source that looks small from them (veach-bidir's spot
// lamp over its glass egg), off where the sources look large from them (staircase2's panels
// behind their panes, the rooms' windows and mirrors).
TEST(LightPaths, AutoIsOnForASmallLampsCausticsOnSurfaces) {
  auto resolved = [](Scene s) {
    RenderFlags f;
    f.max_depth = 5;
    f.max_depth_given = true;
    const RenderOptions o = resolve_options(f, s);
    return o.est.light_paths_glossy ? std::string("glossy") : o.est.light_paths ? std::string("on") : std::string("off");
  };
  // the share: a smooth mirror of area A straight under a sphere lamp at distance d
  // receives A / (4 pi d^2) of its power; near-specular lobes are the glints' share, not this
  const double pi = 3.14159265358979323846;
  const double A = 0.1 * 0.1, d2 = 1.5 * 1.5;
  EXPECT_NEAR(area_caustic_share(glint_room(0.01f, 5e-4f, 0.1f)), A / (4 * pi * d2), 0.01 * A / (4 * pi * d2));
  EXPECT_EQ(area_glint_share(glint_room(0.01f, 5e-4f, 0.1f)), 0);
  EXPECT_EQ(area_caustic_share(glint_room(0.01f, 0.01f, 0.1f)), 0);
  EXPECT_EQ(area_caustic_share(glint_room(0.1f, 5e-4f)), 0);  // (the lamp not small: 0.014 sr)
  // a 2 x 2 mirror takes 0.14 of the power: on; a larger lamp, or a mirror of 0.15 x 0.15
  // (8e-4 of it): off
  EXPECT_EQ(resolved(glint_room(0.01f, 5e-4f)), "on");
  EXPECT_EQ(resolved(glint_room(0.1f, 5e-4f)), "off");
  EXPECT_EQ(resolved(glint_room(0.01f, 5e-4f, 0.15f)), "off");
  // thin glass is a delta lobe too; a rough conductor is not
  Scene pane = glint_room(0.01f, 5e-4f);
  pane.materials[1] = Material{};
  pane.materials[1].kind = MaterialKind::thin_dielectric;
  EXPECT_NEAR(area_caustic_share(pane), area_caustic_share(glint_room(0.01f, 5e-4f)), 1e-9);
  EXPECT_EQ(resolved(pane), "on");
  // the caustic room's large lamp over its glass, mirror and smooth coat: the path tracer's
  EXPECT_LT(area_caustic_share(caustic_room(16)), 0.003);
  EXPECT_EQ(resolved(caustic_room(16)), "off");
  // where something refuses the light tracer (direct light alone), auto stays off
  RenderFlags direct;
  direct.max_depth = 1;
  direct.max_depth_given = true;
  Scene small = glint_room(0.01f, 5e-4f);
  EXPECT_FALSE(resolve_options(direct, small).est.light_paths);
}

// `tuile info` says what auto chose and the figure it rests on: veach-mis's layout in a
// pbrt-v4 file (a sphere lamp of radius 0.01 at 1.5 over a conductor of alpha 0.01).
TEST(LightPaths, InfoSaysGlossyAndTheGlintShare) {
  using tuile::testing::CmdResult;
  using tuile::testing::run_command;
  using tuile::testing::TempDir;
  TempDir dir;
  const std::string scene = dir / "glint.pbrt";
  std::ofstream(scene) << "LookAt 0 1 6  0 1 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 45 ]\n"
                          "Integrator \"path\" \"integer maxdepth\" [ 5 ]\nWorldBegin\n"
                          "Material \"diffuse\" \"rgb reflectance\" [ 0.6 0.6 0.6 ]\n"
                          "Shape \"trianglemesh\" \"point3 P\" [ -3 -1 -3  3 -1 -3  3 4 -3  -3 4 -3 ] "
                          "\"integer indices\" [ 0 1 2  0 2 3 ]\n"
                          "AttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [ 5000 5000 5000 ]\n"
                          "Translate 0 1.5 0\nShape \"sphere\" \"float radius\" [ 0.01 ]\nAttributeEnd\n"
                          "Material \"conductor\" \"float roughness\" [ 0.01 ] \"bool remaproughness\" false\n"
                          "Shape \"trianglemesh\" \"point3 P\" [ -1 0 -1  -1 0 1  1 0 1  1 0 -1 ] "
                          "\"integer indices\" [ 0 1 2  0 2 3 ]\n";
  const CmdResult r = run_command(TUILE_BINARY, "info " + scene);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("light-paths=glossy"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("light paths: glossy, a light path per pixel"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("glints: 0.1"), std::string::npos) << r.out;  // (about 0.11: A / (4 pi d^2) over the mirror)
  const CmdResult off = run_command(TUILE_BINARY, "info " + scene + " --light-paths=off");
  ASSERT_EQ(off.code, 0) << off.out;
  EXPECT_EQ(off.out.find("light paths:"), std::string::npos) << off.out;
  EXPECT_NE(off.out.find("glints: 0.1"), std::string::npos) << off.out;
  // the same mirror smooth: the caustics' share, and on
  std::ifstream in(scene);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  text.replace(text.find("\"float roughness\" [ 0.01 ]"), std::string("\"float roughness\" [ 0.01 ]").size(),
               "\"float roughness\" [ 0 ]");
  const std::string smooth = dir / "caustic.pbrt";
  std::ofstream(smooth) << text;
  const CmdResult c = run_command(TUILE_BINARY, "info " + smooth);
  ASSERT_EQ(c.code, 0) << c.out;
  EXPECT_NE(c.out.find("light-paths=on"), std::string::npos) << c.out;
  EXPECT_NE(c.out.find("caustics: 0.1"), std::string::npos) << c.out;
  EXPECT_EQ(c.out.find("glints:"), std::string::npos) << c.out;
}
