// Specialised pipelines (wave/features.h: leave out what a scene does not need) give the
// same image as the general reference pipeline from the same seed, bit for bit: they skip
// stages and lookups whose results cannot change the image. Every combination of
// features a scene and estimator can ask for is registered.
#include <gtest/gtest.h>

#include <cstring>
#include <set>
#include <string>

#include "render/tile_pipeline.h"
#include "media_util.h"
#include "render_util.h"

using namespace tuile;

namespace {

Scene point_lit() {
  Scene s = builtin_scene("cornell");
  s.meshes.pop_back();  // no area light
  Light p;
  p.type = LightKind::point;
  p.p0 = {0.5f, 0.9f, 0.5f};
  p.radiance = {1, 1, 1};
  s.lights.push_back(p);
  Light spot;
  spot.type = LightKind::spot;
  spot.p0 = {0.2f, 0.9f, 0.8f};
  spot.e1 = normalize(vec3f{0.2f, -1, -0.3f});
  spot.e2 = {0.9f, 0.8f, 0};
  spot.radiance = {2, 1, 1};
  s.lights.push_back(spot);
  return s;
}
Scene single_point() {
  Scene s = point_lit();
  s.lights.pop_back();
  return s;
}
Scene mixed() {
  Scene s = builtin_scene("cornell");
  Light d;
  d.type = LightKind::distant;
  d.e1 = normalize(vec3f{0.1f, 1, 0.4f});
  d.radiance = {0.5f, 0.5f, 0.5f};
  s.lights.push_back(d);
  return s;
}

// Cornell's room with a surface of every kind: rough and smooth conductors, rough and
// smooth glass, a thin pane, diffuse transmission and a coat; a spot light besides the
// area light, so that both techniques and delta lobes meet delta and area sources.
Scene materials() {
  Scene s = mixed();
  Material rough;
  rough.kind = MaterialKind::conductor;
  rough.eta_rgb = {0.2f, 0.9f, 1.1f};
  rough.k_rgb = {3.9f, 2.4f, 2.1f};
  rough.alpha_u.value = 0.3f;
  rough.alpha_v.value = 0.1f;
  s.materials[1] = rough;  // the red wall
  Material coat;
  coat.kind = MaterialKind::coated_diffuse;
  coat.reflectance = {0.1f, 0.5f, 0.2f};
  coat.alpha_u.value = coat.alpha_v.value = 0.05f;
  s.materials[2] = coat;  // the green wall
  auto add = [&](Material m, vec3f c, float r) {
    s.materials.push_back(m);
    Sphere b;
    b.center = c;
    b.radius = r;
    b.material = static_cast<int>(s.materials.size() - 1);
    s.spheres.push_back(b);
  };
  Material mirror = rough;
  mirror.alpha_u.value = mirror.alpha_v.value = 0.f;
  add(mirror, {0.25f, 0.2f, 0.3f}, 0.15f);
  Material glass;
  glass.kind = MaterialKind::dielectric;
  glass.eta = 1.5f;
  add(glass, {0.7f, 0.2f, 0.4f}, 0.15f);
  glass.alpha_u.value = glass.alpha_v.value = 0.2f;
  add(glass, {0.5f, 0.5f, 0.6f}, 0.1f);
  Material thin;
  thin.kind = MaterialKind::thin_dielectric;
  add(thin, {0.2f, 0.6f, 0.7f}, 0.1f);
  Material translucent;
  translucent.kind = MaterialKind::diffuse_transmission;
  add(translucent, {0.8f, 0.6f, 0.7f}, 0.1f);
  Light spot;
  spot.type = LightKind::spot;
  spot.p0 = {0.2f, 0.9f, 0.8f};
  spot.e1 = normalize(vec3f{0.2f, -1, -0.3f});
  spot.e2 = {0.9f, 0.8f, 0};
  spot.radiance = {2, 1, 1};
  s.lights.push_back(spot);
  return s;
}

struct Case {
  const char* name;
  Scene (*make)();
};

}  // namespace

TEST(Pipeline, SpecialisedEqualsGeneral) {
  if (general_pipeline_only)
    GTEST_SKIP() << "this build compiles the general pipeline alone (TUILE_PIPELINES=general): no specialised one to compare";
  const Case cases[] = {{"point-lit", point_lit},
                        {"single-point", single_point},
                        {"cornell", [] { return builtin_scene("cornell"); }},
                        {"two-panels", [] { return builtin_scene("two-panels"); }},
                        {"mixed", mixed},
                        {"materials", materials}};
  int distinct_pipelines = 0;
  std::string last;
  for (const Case& c : cases)
    for (Strategy st : {Strategy::light, Strategy::bsdf, Strategy::mis})
      for (LightPick pk : {LightPick::power, LightPick::all})
        for (MisMode mode : {MisMode::multi, MisMode::one}) {
          if (mode == MisMode::one && st != Strategy::mis) continue;
          Scene s = c.make();
          s.camera.width = 40;
          s.camera.height = 24;
          finalize_scene(s);
          RenderOptions o;
          o.est.strategy = st;
          o.est.pick = pk;
          o.est.mode = mode;
          o.est.spp = 4;
          o.est.seed = 3;
          Accel accel(s);
          Film a, b;
          RenderOptions og = o;
          og.general_pipeline = true;
          Renderer rs(s, accel, o), rg(s, accel, og);
          const RenderStats ss = rs.render(a, 0, o.est.spp);
          const RenderStats sg = rg.render(b, 0, o.est.spp);
          ASSERT_EQ(sg.pipeline, "general");
          if (ss.pipeline != last) {
            ++distinct_pipelines;
            last = ss.pipeline;
          }
          const std::vector<float> ma = a.mean(), mb = b.mean();
          ASSERT_EQ(std::memcmp(ma.data(), mb.data(), ma.size() * sizeof(float)), 0)
              << c.name << " " << describe(o.est) << " pipeline " << ss.pipeline;
          // the specialised pipeline does not trace what it does not need
          if (std::string(c.name).find("point") != std::string::npos) {
            EXPECT_EQ(ss.rays_bounce, 0u) << ss.pipeline;
            // (with --strategy light the general pipeline traces the specular samples only)
            if (st != Strategy::light) {
              EXPECT_GT(sg.rays_bounce, 0u);
            }
          }
          if (st == Strategy::light && std::string(c.name) != "materials") {
            EXPECT_EQ(ss.rays_bounce, 0u) << c.name;  // (specular surfaces need their BSDF samples)
          }
        }
  EXPECT_GE(distinct_pipelines, 4);
}

namespace {

// Options for the tests of the emitters' BVH below: 8 spp, the MIS-weight AOV.
RenderOptions bounce_options(Strategy st, MisMode mode, int depth, uint32_t seed) {
  RenderOptions o;
  o.est.strategy = st;
  o.est.mode = mode;
  o.est.spp = 8;
  o.est.seed = seed;
  o.est.max_depth = depth;
  o.aov_mis_weight = true;
  return o;
}

// The scene rendered with o, its bounce rays traced against the whole scene and against the
// emitters (o.bounce set to each): the same image and MIS-weight AOV, bit for bit, and the
// same bounce rays; only the second takes visibility rays, and some.
void expect_bounce_modes_agree(const Scene& s, const Accel& accel, RenderOptions o, const std::string& name) {
  RenderOptions oe = o;
  o.bounce = BounceTrace::scene;
  oe.bounce = BounceTrace::emitters;
  Renderer rs(s, accel, o), re(s, accel, oe);
  ASSERT_FALSE(rs.bounce_against_emitters());
  ASSERT_TRUE(re.bounce_against_emitters());
  Film a, b;
  const RenderStats ss = rs.render(a, 0, o.est.spp);
  const RenderStats se = re.render(b, 0, o.est.spp);
  const std::vector<float> ma = a.mean(), mb = b.mean();
  const std::string what = name + " " + describe(o.est);
  ASSERT_EQ(std::memcmp(ma.data(), mb.data(), ma.size() * sizeof(float)), 0) << what;
  ASSERT_EQ(a.w_sum, b.w_sum) << what;
  ASSERT_EQ(a.w_cnt, b.w_cnt) << what;
  EXPECT_EQ(ss.rays_bounce, se.rays_bounce) << what;
  EXPECT_EQ(ss.rays_bounce_visibility, 0u) << what;
  EXPECT_GT(se.rays_bounce_visibility, 0u) << what;
  double sum = 0;
  for (float v : ma) sum += v;
  EXPECT_GT(sum, 0.0) << what;
}

}  // namespace

// Bounce rays traced against the emitters alone, then an occlusion ray to the emitter they
// reached, give the image of bounce rays traced against the whole scene, bit for bit on
// these scenes (no occluder lies within 2^-12 of an emitter's distance, where the two
// visibility tests could differ): the same hits, distances and MIS weights. On paths (max
// depth 4) the emitters alone see the last vertex's rays and, at the vertices before, the
// rays of the paths that end there (Russian roulette decided before the trace); the others
// their nearest hit in the scene, which their next vertex needs.
TEST(Pipeline, BounceRaysAgainstEmittersEqualScene) {
  auto spheres = [] {
    Scene s = builtin_scene("cornell");
    Sphere lamp;
    lamp.center = {0.3f, 0.75f, 0.3f};
    lamp.radius = 0.05f;
    lamp.material = 0;
    lamp.emission = {3, 2, 1};
    s.spheres.push_back(lamp);
    Sphere ball;  // casts shadows from both lights
    ball.center = {0.45f, 0.45f, 0.45f};
    ball.radius = 0.12f;
    ball.material = 1;
    s.spheres.push_back(ball);
    return s;
  };
  const Case cases[] = {{"cornell", [] { return builtin_scene("cornell"); }},
                        {"two-panels", [] { return builtin_scene("two-panels"); }},
                        {"mixed", mixed},
                        {"spheres", spheres},
                        {"materials", materials}};
  for (const Case& c : cases)
    for (int depth : {1, 4})
    for (Strategy st : {Strategy::bsdf, Strategy::mis})
      for (MisMode mode : {MisMode::multi, MisMode::one}) {
        if (mode == MisMode::one && st != Strategy::mis) continue;
        Scene s = c.make();
        s.camera.width = 48;
        s.camera.height = 32;
        finalize_scene(s);
        Accel accel(s);
        // some bounce rays reached an emitter (and some of those are occluded in every
        // scene here: the images differ if occluded emitters count)
        expect_bounce_modes_agree(s, accel, bounce_options(st, mode, depth, 5), c.name);
      }
}

namespace {

// An open court (a floor and two walls, diffuse) with a sphere lamp, a block casting
// shadows and a glass box holding a medium that scatters and absorbs, with a lamp of its own
// inside; under a sky (sky), the box's medium (which emits) there or not (medium). The camera
// is in vacuum; no surface is an interface.
Scene court(bool sky, bool medium) {
  Scene s;
  s.source = "test:court";
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.5f, 0.4f}));
  s.materials.push_back(glass_material(1.5f));
  add_named_quad(s, "floor", 0, {-4, 0, -4}, {0, 0, 8}, {8, 0, 0});
  add_named_quad(s, "back", 0, {-4, 0, 3}, {8, 0, 0}, {0, 3, 0});
  add_named_quad(s, "left", 0, {-3, 0, -4}, {0, 3, 0}, {0, 0, 8});
  add_named_quad(s, "inner lamp", 0, {-0.2f, 0.5f, 0.8f}, {0.4f, 0, 0}, {0, 0, 0.4f}, 6.f);
  s.meshes.back().two_sided = true;
  Mesh block = media_box({0.8f, 0, 0.2f}, {1.2f, 0.8f, 0.6f});
  block.material = 0;
  s.meshes.push_back(block);
  Mesh box = media_box({-0.5f, 0, 0.5f}, {0.5f, 1, 1.5f});
  box.material = 1;
  if (medium) {
    s.media.push_back(homogeneous({0.3f, 0.6f, 0.9f}, {0.8f, 0.6f, 0.4f}, 0.2f, {0.5f, 0.3f, 0.2f}));
    box.medium_inside = 0;
  }
  s.meshes.push_back(box);
  Sphere lamp;
  lamp.center = {1.5f, 1.6f, 0.f};
  lamp.radius = 0.15f;
  lamp.material = 0;
  lamp.emission = {20, 16, 12};
  s.spheres.push_back(lamp);
  if (sky) {
    Light l;
    l.type = LightKind::infinite;
    l.radiance = {0.4f, 0.6f, 1.f};
    s.lights.push_back(l);
  }
  s.camera.width = 48;
  s.camera.height = 32;
  s.camera.fov_deg = 60;
  camera_look_at(s.camera, {0.5f, 1.8f, -2.5f}, {0, 0.5f, 1}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

}  // namespace

// Bounce rays against the emitters where a scene has a sky or media (no interfaces): the
// rays of the paths that end (and the last vertex's) that start in vacuum look for the
// emitters alone, then an occlusion ray to the emitter reached or, where there is a sky, to
// infinity; the rays that start in a medium look for their nearest hit in the scene. The
// same image, MIS-weight AOV and bounce rays as against the whole scene, bit for bit (an
// escaped ray that counted without its occlusion ray, or a ray in the medium traced against
// the emitters, whose flight would then gather the medium's emission and draw its segment
// light samples up to the emitter instead of its nearest hit, would change it).
TEST(Pipeline, BounceRaysAgainstEmittersSkyAndMedia) {
  for (int variant = 0; variant < 3; ++variant) {
    const bool sky = variant != 1, medium = variant != 0;
    const Scene s = court(sky, medium);
    Accel accel(s);
    for (int depth : {1, 5})
      for (Strategy st : {Strategy::bsdf, Strategy::mis})
        for (MisMode mode : {MisMode::multi, MisMode::one}) {
          if (mode == MisMode::one && st != Strategy::mis) continue;
          RenderOptions o = bounce_options(st, mode, depth, 3);
          // (segment light samples: their segment ends at the ray's nearest hit)
          o.est.equiangular = medium && st == Strategy::mis && mode == MisMode::multi;
          EXPECT_TRUE(Renderer(s, accel, RenderOptions{}).bounce_against_emitters());  // (auto: 3 emitting of 33)
          expect_bounce_modes_agree(s, accel, o, std::string(sky ? "sky " : "") + (medium ? "medium" : ""));
        }
  }
}

// Where a surface is an "interface" between media, a ray may pass it into a medium on its
// way to an emitter: every bounce ray looks for its nearest hit in the scene, and asking
// for the emitters is an error that says why. The same slab in glass: the emitters.
TEST(Pipeline, BounceRaysWithInterfaces) {
  const Medium md = homogeneous({0.2f, 0.2f, 0.2f}, {0.3f, 0.3f, 0.3f});
  const Scene s = slab_scene(md, 1.f, {2, 2, 2});
  Accel accel(s);
  RenderOptions o;
  EXPECT_FALSE(Renderer(s, accel, o).bounce_against_emitters());
  o.bounce = BounceTrace::emitters;
  try {
    Renderer bad(s, accel, o);
    ADD_FAILURE() << "--bounce-rays emitters with interfaces was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("interface"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--bounce-rays scene"), std::string::npos) << e.what();
  }
  const Scene g = slab_scene(md, 1.f, {2, 2, 2}, glass_material());
  Accel ga(g);
  EXPECT_TRUE(Renderer(g, ga, o).bounce_against_emitters());
}

// auto traces against the emitters only where they are at most half of the primitives
TEST(Pipeline, BounceRaysAutomatic) {
  for (const char* name : {"cornell", "two-panels"}) {
    Scene s = builtin_scene(name);
    finalize_scene(s);
    Accel accel(s);
    RenderOptions o;
    Renderer r(s, accel, o);
    EXPECT_EQ(r.bounce_against_emitters(), std::string(name) == "cornell") << name;
  }
}

TEST(Pipeline, EveryReachableFeatureSetIsRegisteredAndNamed) {
  std::set<std::string> names;
  for (unsigned kinds : {0u, unsigned(bsdf_diffuse), unsigned(bsdf_conductor), unsigned(bsdf_diffuse_transmission),
                         unsigned(bsdf_all)})
  for (int area = 0; area < 2; ++area)
    for (int delta = 0; delta < 2; ++delta)
      for (int rects = 0; rects < 2; ++rects)
        for (int count : {0, 1, 5})
          for (Strategy st : {Strategy::light, Strategy::bsdf, Strategy::mis})
            for (LightPick pk : {LightPick::all, LightPick::uniform, LightPick::power}) {
              if ((count == 0) != (!area && !delta)) continue;  // a scene with sources has a kind
              SceneViews v;
              v.features = (area ? feat_area_lights : 0u) | (delta ? feat_delta_lights : 0u) |
                           (rects ? feat_rect_lights_only : 0u);
              v.lights.count = count;
              v.bsdf_kinds = kinds;
              Estimator est;
              est.strategy = st;
              est.pick = pk;
              std::string why;
              const Features f = pipeline_features(v, est, false, why);
              EXPECT_TRUE(pipeline_registered(f)) << features_name(f) << " (" << why << ")";
              // (a build with TUILE_PIPELINES=general appends that the general pipeline runs it)
              const std::string name = pick_pipeline(v, est, false, why).name;
              names.insert(name.substr(0, name.find(" (run by the general pipeline")));
            }
  // the names of the specialised pipelines, derived from their features
  for (const char* n : {"no-lights", "delta/light/pick", "delta/light/single", "rect/mis/pick", "rect/mis/single",
                        "rect/light/pick", "rect/light/single", "rect/bsdf", "area/mis/pick", "area/bsdf",
                        "mixed/mis/pick", "mixed/light/single"})
    EXPECT_EQ(names.count(n), 1u) << n;
  std::string why;
  SceneViews v;
  EXPECT_EQ(pick_pipeline(v, Estimator{}, true, why).name, "general");
  EXPECT_EQ(pipeline_features(v, Estimator{}, true, why), general_features);
}
