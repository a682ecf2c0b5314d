// Participating media rendered (wave/media.h): Beer-Lambert through an absorbing slab and
// the emission of an absorbing slab, exact per channel; a sphere of medium that scatters
// without absorbing is invisible under a uniform sky (a white furnace) for every strategy;
// with absorption, its image against an independent random walk in double; light-only,
// phase-only and MIS agree in a foggy room the camera sits in; shadow rays walked only
// where they meet an interface give the bits of walking them all, and the free flights'
// first round in SIMD the scalar bits; and stiff media.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "accel/embree.h"
#include "render/render.h"
#include "render/views.h"
#include "wave/media.h"
#include "media_util.h"
#include "render_util.h"
#include "scene/pbrt.h"
#include "test_scale.h"

using namespace tuile;
using namespace tuile::test;

namespace {

const MediaEst media_estimators[] = {
    {"mis", Strategy::mis, MisMode::multi},
    {"mis one-sample", Strategy::mis, MisMode::one},
    {"light", Strategy::light, MisMode::multi},
    {"bsdf", Strategy::bsdf, MisMode::multi},
    {"ris", Strategy::ris, MisMode::multi},
};

struct ImageMean {
  double mean[3] = {0, 0, 0}, se[3] = {0, 0, 0};
};
ImageMean media_image_mean(const RenderResult& r) {
  const std::vector<float> var = r.film.variance_of_mean();
  ImageMean m;
  const double n = static_cast<double>(r.mean.size() / 3);
  for (int c = 0; c < 3; ++c) {
    double v = 0;
    for (size_t i = static_cast<size_t>(c); i < r.mean.size(); i += 3) {
      m.mean[c] += r.mean[i];
      v += var[i];
    }
    m.mean[c] /= n;
    m.se[c] = std::sqrt(v) / n;
  }
  return m;
}

// Henyey-Greenstein in double, written from the formula (not the renderer's code): cos theta
// between the incoming direction's continuation and the new one, g > 0 forward.
double hg_cos_forward(double g, double u) {
  if (std::fabs(g) < 1e-3) return 1 - 2 * u;
  const double sq = (1 - g * g) / (1 - g + 2 * g * u);
  return (1 + g * g - sq * sq) / (2 * g);
}

}  // namespace

// Beer-Lambert: an emitter of radiance L seen through a slab of absorbing medium of
// thickness d is L exp(-sigma_a d) in each channel, for every estimator and depth (an
// absorbing medium draws nothing: the transmittance is exact), from sigma_a d = 5e-7 (the
// slab hardly there) to 5e2 (nothing passes); to 1e-4 relative (the chord's 2e-5 across
// the field, and float). The slab bounded by an interface, and by glass of index 1 (a
// medium inside a dielectric: the path's medium changes where it is transmitted; three
// vertices to the emitter, so depth 5 only).
TEST(MediaRender, BeerLambertThroughAnAbsorbingSlab) {
  const Rgb L{1, 2, 3};
  const float d = 0.5f;
  Material glass;
  glass.kind = MaterialKind::dielectric;
  glass.eta = 1.f;
  for (const bool dielectric : {false, true})
    for (float scale : {1e-6f, 1.f, 3.f, 1e3f}) {
      const Rgb sa{1.f * scale, 2.f * scale, 0.5f * scale};
      const Scene s = dielectric ? slab_scene(homogeneous(sa, {0, 0, 0}), d, L, glass) : slab_scene(homogeneous(sa, {0, 0, 0}), d, L);
      ASSERT_TRUE(s.features & feat_media);
      for (const MediaEst& e : media_estimators)
        for (int depth : {1, 5}) {
          // (one-sample MIS counts a glass vertex's transmission on the points that chose the
          // BSDF technique: unbiased, not exact, so left out behind glass)
          if (dielectric && (depth < 5 || e.mode == MisMode::one)) continue;
          const RenderResult r = render_scene(s, media_options(e, depth, 2, 3));
          const double want[3] = {L.r * std::exp(-double(sa.r) * d), L.g * std::exp(-double(sa.g) * d),
                                  L.b * std::exp(-double(sa.b) * d)};
          for (size_t i = 0; i < r.mean.size(); ++i) {
            const double w = want[i % 3];
            ASSERT_NEAR(r.mean[i], w, 1e-4 * w + 1e-30)
                << (dielectric ? "glass " : "interface ") << e.name << " depth " << depth << " scale " << scale << " channel " << i % 3;
          }
        }
    }
}

// An absorbing slab that emits (sigma_a Le per unit length, pbrt-v4's medium emission) seen
// against nothing: Le (1 - exp(-sigma_a d)) per channel, in closed form along the ray.
TEST(MediaRender, EmissionOfAnAbsorbingSlab) {
  const float d = 0.7f;
  const Rgb sa{0.2f, 1.f, 4.f}, Le{3, 2, 1};
  const Scene s = slab_scene(homogeneous(sa, {0, 0, 0}, 0, Le), d, {0, 0, 0});
  const RenderResult r = render_scene(s, media_options(media_estimators[0], 5, 2, 4));
  const double want[3] = {Le.r * (1 - std::exp(-double(sa.r) * d)), Le.g * (1 - std::exp(-double(sa.g) * d)),
                          Le.b * (1 - std::exp(-double(sa.b) * d))};
  for (size_t i = 0; i < r.mean.size(); ++i) ASSERT_NEAR(r.mean[i], want[i % 3], 1e-4 * want[i % 3]) << "channel " << i % 3;
}

// A white furnace in a medium: a sphere of medium that scatters and does not absorb (albedo
// 1) under a uniform sky L is invisible: the uniform radiance L solves the transport
// equation inside it, so every pixel's expectation is L once paths are long enough (up to
// 1000 vertices; a path leaves the sphere of optical radius 2 after a few collisions). Where
// the BSDF (phase) technique alone takes the constant sky (BSDF sampling, multi-sample MIS:
// pbrt-v4's rule for a constant sky) every path carries exactly L: the image is L to 1e-5.
// Elsewhere each estimator's image mean within 4 standard errors, its standard error below
// 1% (3% with colour-varying sigma_s, whose hero-channel weights spread), so that a lost or
// doubled weight (the sky counted by both techniques at a medium vertex, or by neither; a
// phase function off by a cosine) shows; for g = 0, 0.7 and -0.999 and colour-varying
// sigma_s (the hero channel's MIS). Light sampling alone is left out at g = -0.999: its
// phase function is a spike of 1.6e5 per steradian, which uniform sky samples meet once in
// millions (unbiased, but no sample variance can state its error).
TEST(MediaRender, WhiteFurnaceSphereIsInvisible) {
  const float L = 0.5f;
  const uint32_t spp = scaled(128u, 16u);
  struct Case {
    Rgb ss;
    float g;
    double se_max;
  } cases[] = {{{2, 2, 2}, 0.f, 0.01}, {{1, 2, 4}, 0.7f, 0.03}, {{2, 2, 2}, -0.999f, 0.01}};
  for (const Case& cs : cases) {
    const Scene s = furnace_scene(homogeneous({0, 0, 0}, cs.ss, cs.g), L, 30, 12);
    for (const MediaEst& e : media_estimators) {
      if (e.strategy == Strategy::light && std::fabs(cs.g) > 0.9f) continue;
      const RenderResult r = render_scene(s, media_options(e, 1000, spp, 5));
      const ImageMean m = media_image_mean(r);
      for (int c = 0; c < 3; ++c) {
        const bool exact = m.se[c] < 1e-6 * L;
        const double z = exact ? 0.0 : (m.mean[c] - L) / m.se[c];
        std::printf("[ medium furnace ] g %.3f %s channel %d: mean %.6f (z %.2f, se/L %.2g)\n", cs.g, e.name, c, m.mean[c], z,
                    m.se[c] / L);
        if (exact) {
          EXPECT_NEAR(m.mean[c], L, 1e-5 * L) << e.name << " g " << cs.g << " channel " << c;
        }
        EXPECT_LT(std::fabs(z), 4.0) << e.name << " g " << cs.g << " channel " << c;
        EXPECT_LE(m.se[c], cs.se_max * sigma_growth(128u, 16u) * L) << e.name;
      }
      EXPECT_EQ(r.stats.rejected_camera + r.stats.rejected_light + r.stats.rejected_bsdf, 0u) << e.name;
    }
  }
}

// With absorption (albedo 0.7, g = 0.5), the sphere seen along its centre line against an
// independent analog random walk in double (the walk's estimate of a path is L a^n for n
// collisions, each with the albedo as its survival): the renderer's image (a 0.5 degree
// field, every ray within 0.02 of the centre line) within 4 combined standard errors.
TEST(MediaRender, AbsorbingSphereMatchesARandomWalk) {
  const float L = 1.f, albedo = 0.7f, st = 1.5f, g = 0.5f;
  const Scene s = furnace_scene(homogeneous({st * (1 - albedo), st * (1 - albedo), st * (1 - albedo)},
                                            {st * albedo, st * albedo, st * albedo}, g),
                                L, 0.5f, 4);
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> U(0, 1);
  const int walks = 400000;
  double sum = 0, sum2 = 0;
  for (int w = 0; w < walks; ++w) {
    double p[3] = {0, 0, -1}, d[3] = {0, 0, 1}, weight = 1;
    for (;;) {
      // the distance to the sphere's boundary along d from p inside it
      const double b = p[0] * d[0] + p[1] * d[1] + p[2] * d[2];
      const double c = p[0] * p[0] + p[1] * p[1] + p[2] * p[2] - 1;
      const double exit = -b + std::sqrt(std::max(b * b - c, 0.0));
      const double t = -std::log(1 - U(rng)) / st;
      if (t >= exit) break;
      for (int i = 0; i < 3; ++i) p[i] += t * d[i];
      weight *= albedo;
      const double ct = hg_cos_forward(g, U(rng)), phi = 2 * M_PI * U(rng);
      const double sn = std::sqrt(std::max(0.0, 1 - ct * ct));
      // a frame around d
      double a[3] = {std::fabs(d[0]) > 0.9 ? 0.0 : 1.0, std::fabs(d[0]) > 0.9 ? 1.0 : 0.0, 0};
      double t1[3] = {a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2], a[0] * d[1] - a[1] * d[0]};
      const double l1 = std::sqrt(t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2]);
      for (double& x : t1) x /= l1;
      const double t2[3] = {d[1] * t1[2] - d[2] * t1[1], d[2] * t1[0] - d[0] * t1[2], d[0] * t1[1] - d[1] * t1[0]};
      double nd[3];
      for (int i = 0; i < 3; ++i) nd[i] = ct * d[i] + sn * (std::cos(phi) * t1[i] + std::sin(phi) * t2[i]);
      for (int i = 0; i < 3; ++i) d[i] = nd[i];
      if (weight < 1e-12) break;
    }
    sum += weight * L;
    sum2 += weight * L * weight * L;
  }
  const double walk = sum / walks, walk_se = std::sqrt((sum2 / walks - walk * walk) / walks);
  for (const MediaEst& e : {media_estimators[0], media_estimators[3]}) {
    const RenderResult r = render_scene(s, media_options(e, 1000, scaled(4096u, 512u), 6));
    const ImageMean m = media_image_mean(r);
    for (int c = 0; c < 3; ++c) {
      const double z = (m.mean[c] - walk) / std::sqrt(m.se[c] * m.se[c] + walk_se * walk_se);
      std::printf("[ absorbing sphere ] %s channel %d: %.5f vs walk %.5f (z %.2f)\n", e.name, c, m.mean[c], walk, z);
      EXPECT_LT(std::fabs(z), 4.0) << e.name << " channel " << c;
    }
  }
}

namespace {

// A foggy room: a closed diffuse box (material 0) with a small lamp under its ceiling,
// filled with a scattering, absorbing medium (medium 0) in which the camera sits (the
// camera's medium; no interface anywhere); not finalized.
Scene foggy_room(int res) {
  Scene s;
  s.source = "test:foggy-room";
  s.media.push_back(homogeneous({0.05f, 0.1f, 0.2f}, {0.3f, 0.25f, 0.2f}, 0.3f));
  s.camera_medium = 0;
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.6f, 0.6f}));
  Mesh room = media_box({-2, 0, -2}, {2, 3, 2});
  room.material = 0;
  s.meshes.push_back(room);
  Mesh lamp;
  lamp.name = "lamp";
  lamp.material = 0;
  add_quad(lamp, {-0.3f, 2.9f, -0.3f}, {0.6f, 0, 0}, {0, 0, 0.6f});
  lamp.emission = {8, 8, 8};
  lamp.two_sided = true;
  s.meshes.push_back(lamp);
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 70;
  camera_look_at(s.camera, {0, 1.5f, -1.8f}, {0, 1.2f, 0}, {0, 1, 0});
  return s;
}

}  // namespace

// The foggy room: light-only, phase/BSDF-only, one-sample MIS and RIS each agree with
// multi-sample MIS within 4 combined standard errors of the image mean, per channel (the
// channels' coefficients differ), depth 6.
TEST(MediaRender, FoggyRoomEstimatorsAgree) {
  Scene s = foggy_room(16);
  finalize_scene(s);
  const uint32_t spp = scaled(256u, 32u);
  const RenderResult ref = render_scene(s, media_options(media_estimators[0], 6, spp, 7));
  const ImageMean mr = media_image_mean(ref);
  for (const MediaEst& e : media_estimators) {
    if (e.strategy == Strategy::mis && e.mode == MisMode::multi) continue;
    const RenderResult r = render_scene(s, media_options(e, 6, e.strategy == Strategy::bsdf ? 4 * spp : spp, 8));
    const ImageMean m = media_image_mean(r);
    for (int c = 0; c < 3; ++c) {
      const double z = (m.mean[c] - mr.mean[c]) / std::sqrt(m.se[c] * m.se[c] + mr.se[c] * mr.se[c]);
      std::printf("[ foggy room ] %s channel %d: %.5f vs mis %.5f (z %.2f)\n", e.name, c, m.mean[c], mr.mean[c], z);
      EXPECT_LT(std::fabs(z), 4.0) << e.name << " channel " << c;
    }
  }
  EXPECT_GT(mr.mean[0], 0.0);
}

// Shadow rays and camera rays through several media: a slab of medium b nested inside a
// slab of medium a (b's interface: b inside, a outside), both absorbing, between the
// camera and a diffuse wall lit head-on by a distant source from the camera's side. Each
// ray crosses 0.4 of a and 0.2 of b, so the wall's pixel is rho E / pi T^2 with
// T = exp(-0.4 sigma_a - 0.2 sigma_b) per channel (the light's way and the camera's), for
// every estimator that samples a delta source; to 1e-4 (the chords across the 0.5 degree
// field).
TEST(MediaRender, ShadowAndCameraRaysThroughNestedMedia) {
  Scene s;
  s.source = "test:nested-slabs";
  s.media.push_back(homogeneous({1.0f, 2.0f, 0.5f}, {0, 0, 0}));
  s.media.push_back(homogeneous({3.0f, 1.0f, 0.2f}, {0, 0, 0}));
  s.materials.push_back(interface_material());
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  Mesh a = media_box({-50, -50, 0}, {50, 50, 0.6f});
  a.material = 0;
  a.medium_inside = 0;
  s.meshes.push_back(a);
  Mesh b = media_box({-40, -40, 0.2f}, {40, 40, 0.4f});
  b.material = 0;
  b.medium_inside = 1;
  b.medium_outside = 0;
  s.meshes.push_back(b);
  Mesh wall;
  wall.name = "wall";
  wall.material = 1;
  add_quad(wall, {-20, -20, 3}, {40, 0, 0}, {0, 40, 0});
  s.meshes.push_back(wall);
  Light sun;
  sun.type = LightKind::distant;
  sun.e1 = {0, 0, -1};  // towards the light: the camera's side
  sun.radiance = {2, 2, 2};
  s.lights.push_back(sun);
  s.camera.width = s.camera.height = 8;
  s.camera.fov_deg = 0.5f;
  camera_look_at(s.camera, {0, 0, -5}, {0, 0, 0}, {0, 1, 0});
  finalize_scene(s);
  const double sa[3] = {1.0, 2.0, 0.5}, sb[3] = {3.0, 1.0, 0.2};
  for (const MediaEst& e : media_estimators) {
    if (e.strategy == Strategy::bsdf || e.mode == MisMode::one) continue;  // (a delta source: light samples only)
    const RenderResult r = render_scene(s, media_options(e, 1, 2, 9));
    for (size_t i = 0; i < r.mean.size(); ++i) {
      const int c = static_cast<int>(i % 3);
      const double T = std::exp(-0.4 * sa[c] - 0.2 * sb[c]);
      const double want = 0.5 / M_PI * 2 * T * T;
      ASSERT_NEAR(r.mean[i], want, 1e-4 * want) << e.name << " channel " << c;
    }
  }
}

// Shadow rays in a scene with media but no interface take occlusion queries and the
// transmittance of the medium at their origin (wave/media.h shadow_transmittance); with an
// interface anywhere, nearest hits through the interfaces (shadow_media). The foggy room
// with and without an interface quad far outside it, which no ray reaches: the same bits,
// for every estimator.
TEST(MediaRender, ShadowRaysWithoutInterfacesGiveTheBitsOfTracingThroughThem) {
  Scene s = foggy_room(12);
  s.media.push_back(homogeneous({0.5f, 0.2f, 0.4f}, {0, 0, 0}));
  s.materials.push_back(interface_material());
  Mesh block = media_box({-0.5f, 0, -0.5f}, {0.5f, 1, 0.5f});  // an absorbing block behind a diffuse skin
  block.material = 0;
  block.medium_inside = 1;
  block.medium_outside = 0;
  s.meshes.push_back(block);
  Scene with = s;
  Mesh far = media_box({10, 0, 10}, {11, 1, 11});  // outside the closed room
  far.material = 1;
  far.medium_inside = 1;
  far.medium_outside = 0;
  with.meshes.push_back(far);
  finalize_scene(s);
  finalize_scene(with);
  for (const MediaEst& e : media_estimators) {
    const RenderOptions o = media_options(e, 5, 8, 21);
    const RenderResult a = render_scene(s, o), b = render_scene(with, o);
    if (e.strategy != Strategy::bsdf) {
      EXPECT_GT(a.stats.rays_shadow, 0u) << e.name;
    }
    EXPECT_EQ(a.mean, b.mean) << e.name;
  }
}

namespace {

// A box of medium 0 (interface), a box of medium 1 nested in it (interface), an opaque
// block in the first and a cut-out interface sheet (alpha 0.5) outside: the scene of the
// lane-by-lane media tests below. Medium 0 scatters (and emits emission0), 1 only absorbs.
Scene nested_boxes(Rgb emission0 = {0, 0, 0}) {
  Scene s;
  s.source = "test:nested-boxes";
  s.media.push_back(homogeneous({0.7f, 1.3f, 0.2f}, {0.3f, 0.1f, 0.5f}, 0, emission0));
  s.media.push_back(homogeneous({2.0f, 0.4f, 1.0f}, {0, 0, 0}));
  s.materials.push_back(interface_material());
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  Mesh a = media_box({-1, -1, -1}, {1, 1, 1});
  a.material = 0;
  a.medium_inside = 0;
  s.meshes.push_back(a);
  Mesh b = media_box({-0.3f, -0.3f, -0.3f}, {0.3f, 0.3f, 0.3f});
  b.material = 0;
  b.medium_inside = 1;
  b.medium_outside = 0;
  s.meshes.push_back(b);
  Mesh block = media_box({0.4f, -0.9f, -0.9f}, {0.6f, 0.9f, 0.9f});
  block.material = 1;
  block.medium_inside = block.medium_outside = 0;
  s.meshes.push_back(block);
  Mesh sheet;  // an interface with holes: medium 0 behind it, none in front
  sheet.name = "sheet";
  sheet.material = 0;
  sheet.medium_inside = 0;
  add_quad(sheet, {-3, -3, 2}, {6, 0, 0}, {0, 6, 0});
  sheet.alpha.value = 0.5f;
  s.meshes.push_back(sheet);
  finalize_scene(s);
  return s;
}

// The medium at a point of nested_boxes() (outside the block)
int nested_medium_at(vec3f p) {
  const auto in = [&](float h) { return std::fabs(p.x) < h && std::fabs(p.y) < h && std::fabs(p.z) < h; };
  return in(0.3f) ? 1 : in(1.f) ? 0 : -1;
}

// A point of nested_boxes() in none of its surfaces' insides but the media's
vec3f nested_point(std::mt19937& rng) {
  std::uniform_real_distribution<float> U(0.f, 1.f);
  vec3f p;
  do p = {-1.6f + 3.2f * U(rng), -1.6f + 3.2f * U(rng), -1.6f + 3.2f * U(rng)};
  while (p.x > 0.35f && p.x < 0.65f && std::fabs(p.y) < 0.95f && std::fabs(p.z) < 0.95f);
  return p;
}

// nested_boxes() with media that only absorb and no interface: the boxes' walls are diffuse
// surfaces that separate the media (every ray stops at them), the sheet left out.
Scene absorbing_boxes() {
  Scene s;
  s.source = "test:absorbing-boxes";
  s.media.push_back(homogeneous({0.7f, 1.3f, 0.f}, {0, 0, 0}));
  s.media.push_back(homogeneous({2.0f, 0.4f, 1.0f}, {0, 0, 0}));
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  Mesh a = media_box({-1, -1, -1}, {1, 1, 1});
  a.medium_inside = 0;
  s.meshes.push_back(a);
  Mesh b = media_box({-0.3f, -0.3f, -0.3f}, {0.3f, 0.3f, 0.3f});
  b.medium_inside = 1;
  b.medium_outside = 0;
  s.meshes.push_back(b);
  Mesh block = media_box({0.4f, -0.9f, -0.9f}, {0.6f, 0.9f, 0.9f});
  block.medium_inside = block.medium_outside = 0;
  s.meshes.push_back(block);
  finalize_scene(s);
  return s;
}

}  // namespace

// Shadow rays in a scene with interfaces (wave/media.h shadow_media): an occlusion query in
// which the interfaces do not occlude but mark the rays that meet them, then a walk of the
// marked ones alone, against walking every ray (shadow_media_walked), lane by lane: the
// same transmittance bits and the same occlusion. A box of medium 0 (interface), a box of
// medium 1 nested in it (interface), an opaque block in the first, a cut-out interface sheet
// (alpha 0.5: half of the rays pass a hole, which is no crossing) and shadow rays of random
// lengths from points in all three regions; each kind of ray (walked, in one medium,
// occluded) must occur. And the query itself: without its marks an interface occludes;
// and the route of scenes without interfaces (plain occlusion queries, then
// shadow_transmittance) gives the walk's bits for every ray that meets no interface.
TEST(MediaRender, ShadowRaysWalkOnlyWhereTheyMeetAnInterface) {
  const Scene s = nested_boxes();
  ASSERT_TRUE(s.meshes[3].has_alpha());
  const Accel accel(s);
  const SceneViews views = build_views(s, LightPick::power);
  ASSERT_TRUE(views.geom.media.has_interfaces);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  int walked = 0, one_medium = 0, occluded = 0;
  for (int round = 0; round < 40; ++round) {
    auto t = std::make_unique<TileBuffers>();
    const int n = 16 * 8 - 3;  // a partial last packet
    t->points.count = n;
    for (int k = 0; k < n; ++k) {
      const vec3f p = nested_point(rng);
      const int m = nested_medium_at(p);
      t->points.nx[k] = 0, t->points.ny[k] = 1, t->points.nz[k] = 0;
      t->points.medf[k] = t->points.medb[k] = m;
      std::normal_distribution<float> N;
      const vec3f d = normalize(vec3f{N(rng), N(rng), N(rng)});
      Ray16& r = t->shadow[k / packet_width];
      const int l = k % packet_width;
      r.org_x[l] = p.x, r.org_y[l] = p.y, r.org_z[l] = p.z;
      r.dir_x[l] = d.x, r.dir_y[l] = d.y, r.dir_z[l] = d.z;
      r.tnear[l] = 0;
      r.tfar[l] = 0.1f + 4.f * U(rng);
      r.mask[l] = ~0u;
      r.time[l] = 0;
      t->tech.valid[k] = k % 7 == 3 ? 0 : -1;
      t->tech.cr[k] = 0.5f + U(rng), t->tech.cg[k] = 0.5f + U(rng), t->tech.cb[k] = 0.5f + U(rng);
    }
    for (int k = n; k < max_tile_lanes; ++k) t->tech.valid[k] = 0;
    auto w = std::make_unique<TileBuffers>(*t), o = std::make_unique<TileBuffers>(*t);
    const auto trace = [&](const int32_t* v, RayHit16& q) { accel.intersect16(v, q, false, Bvh::scene); };
    std::vector<int> met(static_cast<size_t>(n), 0);
    shadow_media(
        views.geom, shadow_lanes(*t), n,
        [&](const int32_t* v, Ray16& r, int32_t* crossed) {
          const int p = static_cast<int>(&r - t->shadow);
          Ray16 plain = r;
          accel.occluded16(v, plain, false);  // without marks: an interface occludes
          accel.occluded16(v, r, false, crossed);
          for (int l = 0; l < packet_width; ++l) {
            if (!v[l]) continue;
            if (r.tfar[l] == -INFINITY) ++occluded;
            else if (crossed[l]) ++walked;
            else ++one_medium;
            met[static_cast<size_t>(p * packet_width + l)] = crossed[l];
            EXPECT_EQ(plain.tfar[l] == -INFINITY, crossed[l] || r.tfar[l] == -INFINITY) << "lane " << l;
          }
        },
        trace);
    shadow_media_walked(views.geom, *w, n, trace);
    // the route of scenes without interfaces: plain occlusion queries, then the medium at
    // each origin; the walk's bits wherever a ray meets no interface
    for (int p = 0; p < packets_for(n); ++p) accel.occluded16(o->tech.valid + p * packet_width, o->shadow[p], false);
    shadow_transmittance(views.geom, shadow_lanes(*o), n);
    for (int k = 0; k < n; ++k) {
      if (!t->tech.valid[k]) continue;
      const int l = k % packet_width;
      EXPECT_EQ(t->shadow[k / packet_width].tfar[l] == -INFINITY, w->shadow[k / packet_width].tfar[l] == -INFINITY) << k;
      EXPECT_EQ(t->tech.cr[k], w->tech.cr[k]) << "round " << round << " lane " << k;
      EXPECT_EQ(t->tech.cg[k], w->tech.cg[k]) << "round " << round << " lane " << k;
      EXPECT_EQ(t->tech.cb[k], w->tech.cb[k]) << "round " << round << " lane " << k;
      if (met[static_cast<size_t>(k)]) continue;
      EXPECT_EQ(o->shadow[k / packet_width].tfar[l] == -INFINITY, w->shadow[k / packet_width].tfar[l] == -INFINITY) << k;
      EXPECT_EQ(o->tech.cr[k], w->tech.cr[k]) << "round " << round << " lane " << k;
      EXPECT_EQ(o->tech.cg[k], w->tech.cg[k]) << "round " << round << " lane " << k;
      EXPECT_EQ(o->tech.cb[k], w->tech.cb[k]) << "round " << round << " lane " << k;
    }
  }
  std::printf("[ shadow rays ] walked %d, in one medium %d, occluded %d\n", walked, one_medium, occluded);
  EXPECT_GT(walked, 100);
  EXPECT_GT(one_medium, 100);
  EXPECT_GT(occluded, 100);
}

namespace {

// n random rays from points of nested_boxes()' three regions (every ninth lane not traced),
// traced in accel, with random hero channels and distances; then their flights in SIMD
// (a) and by the scalar rounds alone (b), the same rejected counts.
struct FlightPair {
  std::unique_ptr<TileBuffers> a, b;
};
FlightPair random_flights(const Accel& accel, const SceneViews& views, std::mt19937& rng, int n) {
  std::uniform_real_distribution<float> U(0.f, 1.f);
  std::normal_distribution<float> N;
  auto a = std::make_unique<TileBuffers>();
  for (int k = 0; k < n; ++k) {
    const vec3f p = nested_point(rng);
    const vec3f d = normalize(vec3f{N(rng), N(rng), N(rng)});
    RayHit16& r = a->bounce[k / packet_width];
    const int l = k % packet_width;
    r.ray.org_x[l] = p.x, r.ray.org_y[l] = p.y, r.ray.org_z[l] = p.z;
    r.ray.dir_x[l] = d.x, r.ray.dir_y[l] = d.y, r.ray.dir_z[l] = d.z;
    r.ray.tnear[l] = 0;
    r.ray.tfar[l] = 3.0e38f;
    r.ray.mask[l] = ~0u;
    r.ray.time[l] = 0;
    r.geomID[l] = invalid_id;
    r.instID[0][l] = invalid_id;
    a->tech.valid[k] = k % 9 == 4 ? 0 : -1;
    a->media.med[k] = nested_medium_at(p);
    a->media.u0[k] = U(rng);
    a->media.u1[k] = U(rng);
  }
  for (int k = n; k < max_tile_lanes; ++k) a->tech.valid[k] = 0;
  for (int p = 0; p < packets_for(n); ++p) accel.intersect16(a->tech.valid + p * packet_width, a->bounce[p], false);
  auto b = std::make_unique<TileBuffers>(*a);
  const auto trace = [&](const int32_t* v, RayHit16& q) { accel.intersect16(v, q, false, Bvh::scene); };
  uint64_t rej_a = 0, rej_b = 0;
  medium_flights<true>(views.geom, a->bounce, a->tech.valid, n, a->media, rej_a, trace);
  medium_flights<false>(views.geom, b->bounce, b->tech.valid, n, b->media, rej_b, trace);
  EXPECT_EQ(rej_a, rej_b);
  return {std::move(a), std::move(b)};
}

}  // namespace

// The free flights' first round in SIMD (wave/media.h first_flights_simd) against the
// scalar rounds alone (medium_flights<false>), lane by lane, every output bit: the
// weights, the emission, the medium at the hit, the hits (collisions as the medium's row)
// and which rays stay valid, for rays from the three regions of nested_boxes() (medium 0
// scatters and emits, medium 1 only absorbs, outside none; some rays pass interfaces and
// run the scalar rounds in both), with hero channels and distances drawn at random. Each
// kind of end (a collision, a surface, nowhere) must occur.
TEST(MediaRender, FirstFlightsInSimdGiveTheScalarBits) {
  const Scene s = nested_boxes({0.5f, 2.0f, 1.0f});
  const Accel accel(s);
  const SceneViews views = build_views(s, LightPick::power);
  std::mt19937 rng(11);
  int collisions = 0, surfaces = 0, nowhere = 0;
  for (int round = 0; round < 30; ++round) {
    const int n = 16 * 8 - 5;
    const auto [a, b] = random_flights(accel, views, rng, n);
    for (int k = 0; k < n; ++k) {
      const int p = k / packet_width, l = k % packet_width;
      ASSERT_EQ(a->tech.valid[k], b->tech.valid[k]) << k;
      if (!a->tech.valid[k]) continue;
      const MediumLanes &x = a->media, &y = b->media;
      for (const auto& [u, v] : {std::pair{x.wr[k], y.wr[k]}, {x.wg[k], y.wg[k]}, {x.wb[k], y.wb[k]}, {x.er[k], y.er[k]},
                                 {x.eg[k], y.eg[k]}, {x.eb[k], y.eb[k]}})
        ASSERT_EQ(std::memcmp(&u, &v, sizeof(float)), 0) << "round " << round << " lane " << k << ": " << u << " vs " << v;
      ASSERT_EQ(x.med[k], y.med[k]) << k;
      const RayHit16 &ra = a->bounce[p], &rb = b->bounce[p];
      ASSERT_EQ(ra.geomID[l], rb.geomID[l]) << k;
      ASSERT_EQ(ra.primID[l], rb.primID[l]) << k;
      for (const auto& [u, v] : {std::pair{ra.ray.tfar[l], rb.ray.tfar[l]}, {ra.Ng_x[l], rb.Ng_x[l]}, {ra.Ng_y[l], rb.Ng_y[l]},
                                 {ra.Ng_z[l], rb.Ng_z[l]}, {ra.u[l], rb.u[l]}, {ra.v[l], rb.v[l]}, {ra.ray.org_x[l], rb.ray.org_x[l]},
                                 {ra.ray.org_y[l], rb.ray.org_y[l]}, {ra.ray.org_z[l], rb.ray.org_z[l]}})
        ASSERT_EQ(std::memcmp(&u, &v, sizeof(float)), 0) << "round " << round << " lane " << k << ": " << u << " vs " << v;
      if (ra.geomID[l] == invalid_id) ++nowhere;
      else if (static_cast<int32_t>(ra.geomID[l]) >= views.geom.media.geom0) ++collisions;
      else ++surfaces;
    }
  }
  std::printf("[ flights ] collisions %d, surfaces %d, nowhere %d\n", collisions, surfaces, nowhere);
  EXPECT_GT(collisions, 200);
  EXPECT_GT(surfaces, 100);
  EXPECT_GT(nowhere, 100);
}

// Media that only absorb, without interfaces (MediumView::absorb_only: wave/media.h
// absorbing_flights, in SIMD and without random numbers) against the scalar rounds
// (medium_flights<false>), lane by lane, every output bit, for rays from inside both boxes
// and from outside them (a channel that does not absorb, rays that meet nothing, lanes not
// traced). Each kind of ray must occur.
TEST(MediaRender, AbsorbingFlightsInSimdGiveTheScalarBits) {
  const Scene s = absorbing_boxes();
  const Accel accel(s);
  const SceneViews views = build_views(s, LightPick::power);
  ASSERT_TRUE(views.geom.media.absorb_only);
  ASSERT_FALSE(build_views(nested_boxes(), LightPick::power).geom.media.absorb_only);
  std::mt19937 rng(12);
  int inside = 0, outside = 0, nowhere = 0;
  for (int round = 0; round < 20; ++round) {
    const int n = 16 * 8 - 5;
    const auto [a, b] = random_flights(accel, views, rng, n);
    for (int k = 0; k < n; ++k) {
      const int p = k / packet_width, l = k % packet_width;
      ASSERT_EQ(a->tech.valid[k], b->tech.valid[k]) << k;
      const MediumLanes &x = a->media, &y = b->media;
      for (const auto& [u, v] : {std::pair{x.wr[k], y.wr[k]}, {x.wg[k], y.wg[k]}, {x.wb[k], y.wb[k]}, {x.er[k], y.er[k]},
                                 {x.eg[k], y.eg[k]}, {x.eb[k], y.eb[k]}})
        ASSERT_EQ(std::memcmp(&u, &v, sizeof(float)), 0) << "round " << round << " lane " << k << ": " << u << " vs " << v;
      ASSERT_EQ(x.med[k], y.med[k]) << k;
      ASSERT_EQ(x.eq_med[k], y.eq_med[k]) << k;
      if (!a->tech.valid[k]) continue;
      const RayHit16 &ra = a->bounce[p], &rb = b->bounce[p];
      ASSERT_EQ(ra.geomID[l], rb.geomID[l]) << k;
      ASSERT_EQ(std::memcmp(&ra.ray.tfar[l], &rb.ray.tfar[l], sizeof(float)), 0) << k;
      if (ra.geomID[l] == invalid_id) ++nowhere;
      else if (x.med[k] >= 0) ++inside;
      else ++outside;
    }
  }
  std::printf("[ absorbing flights ] inside %d, outside %d, nowhere %d\n", inside, outside, nowhere);
  EXPECT_GT(inside, 300);
  EXPECT_GT(outside, 100);
  EXPECT_GT(nowhere, 100);
}
