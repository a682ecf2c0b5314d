// Object instances (pbrt-v4's ObjectBegin / ObjectInstance), traced by Embree as instances
// of one BVH per object: the same image as the scene flattened by hand, exact answers
// under extreme instance transforms, and bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "media_util.h"
#include "render_util.h"
#include "scene/pbrt.h"
#include "test_scale.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// A floor, an area light and a sky; three objects with their own definition transforms
// (a coated tetrahedron with vertex normals beside a conductor triangle; a dielectric
// sphere over a diffuse quad with uv; two hair fibres, a tube and a flat ribbon), placed
// seven times: a translation, a non-uniform scale, a mirror, a uniform scale turned about
// z, nested attribute blocks, and the fibres moved, and scaled and turned (uniformly: a
// curve flattened by hand under a non-uniform scale is a round tube of the mean width, an
// instance of it an elliptic one, as in pbrt-v4).
const char* inst_head = R"(LookAt 0 3 -8  0 0.5 0  0 1 0
Camera "perspective" "float fov" [45]
Film "rgb" "integer xresolution" [48] "integer yresolution" [36]
WorldBegin
LightSource "infinite" "rgb L" [0.3 0.3 0.3]
AttributeBegin
AreaLightSource "diffuse" "rgb L" [8 8 8]
Translate 0 4 0
Rotate 90 1 0 0
Shape "bilinearmesh" "point3 P" [-1 -1 0 1 -1 0 -1 1 0 1 1 0]
AttributeEnd
Material "diffuse" "rgb reflectance" [0.5 0.5 0.5]
Shape "trianglemesh" "point3 P" [-10 0 -10 10 0 -10 10 0 10 -10 0 10] "integer indices" [0 1 2 0 2 3]
)";
struct Obj {
  const char* name;
  const char* def;     // the transform of the definition
  const char* shapes;  // its shapes
};
const Obj inst_objects[] = {
    {"tet", "Translate 0 0.1 0\nRotate 20 0 1 0\n",
     R"(Material "coateddiffuse" "rgb reflectance" [0.7 0.2 0.1] "float roughness" 0.1
Shape "trianglemesh" "point3 P" [-0.5 0 -0.5 0.5 0 -0.5 0 1 0 0.5 0 0.5] "integer indices" [0 1 2 1 3 2 3 0 2 0 1 3] "normal N" [0 -1 0 0.6 0.8 0 0 1 0 0.8 0 0.6]
Material "conductor" "float roughness" 0.2
Shape "trianglemesh" "point3 P" [0.6 0 0 1.2 0 0 0.9 0.8 0.2] "integer indices" [0 1 2]
)"},
    {"ball", "Translate 0 0.3 0\n",
     R"(Material "dielectric"
Shape "sphere" "float radius" 0.3
Material "diffuse" "rgb reflectance" [0.2 0.6 0.3]
Shape "trianglemesh" "point3 P" [-0.6 -0.29 -0.6 0.6 -0.29 -0.6 0.6 -0.29 0.6 -0.6 -0.29 0.6] "integer indices" [0 1 2 0 2 3] "point2 uv" [0 0 1 0 1 1 0 1]
)"},
    {"fur", "Translate 0 0.05 0\n",
     R"(Material "hair" "float eumelanin" 1.3
Shape "curve" "point3 P" [-0.4 0 0 -0.1 0.6 0.1 0.2 0.3 -0.1 0.4 0.9 0] "float width" 0.06 "string type" "cylinder"
Shape "curve" "point3 P" [-0.4 0 0.3 -0.1 0.5 0.4 0.2 0.2 0.2 0.4 0.8 0.3] "float width" 0.05 "string type" "flat"
)"},
};
struct Placement {
  int object;
  const char* open;   // transforms (and attribute blocks) before the instance
  const char* close;  // what closes them
};
const Placement inst_placements[] = {
    {0, "AttributeBegin\nTranslate -2 0 0\n", "AttributeEnd\n"},
    {0, "AttributeBegin\nTranslate 0 0.2 1\nScale 1.5 0.7 1.2\nRotate 30 0 1 0\n", "AttributeEnd\n"},
    {0, "AttributeBegin\nTranslate 2 0 0\nScale -1 1 1\n", "AttributeEnd\n"},
    {1, "AttributeBegin\nTranslate 0.4 0.1 -1.8\nRotate 45 0 0 1\nScale 0.8 0.8 0.8\n", "AttributeEnd\n"},
    {1, "AttributeBegin\nTranslate -1 0 -2\nAttributeBegin\nRotate -30 0 1 0\n", "AttributeEnd\nAttributeEnd\n"},
    {2, "AttributeBegin\nTranslate -0.9 0 -3.5\n", "AttributeEnd\n"},
    {2, "AttributeBegin\nTranslate 1.2 0 -3\nScale 1.3 1.3 1.3\nRotate 60 0 1 0\n", "AttributeEnd\n"},
};

// (sky: with the constant sky; without it, the bounce rays of the automatic choice are
// traced against the emitters' BVH, then an occlusion ray)
std::string with_sky(bool sky) {
  std::string t = inst_head;
  if (!sky) t.erase(t.find("LightSource \"infinite\""), t.find("AttributeBegin") - t.find("LightSource \"infinite\""));
  return t;
}
std::string instanced_text(bool sky = true) {
  std::string t = with_sky(sky);
  for (const Obj& o : inst_objects) t += std::string("ObjectBegin \"") + o.name + "\"\n" + o.def + o.shapes + "ObjectEnd\n";
  for (const Placement& p : inst_placements)
    t += std::string(p.open) + "ObjectInstance \"" + inst_objects[p.object].name + "\"\n" + p.close;
  return t;
}
// The same scene flattened by hand: each placement's transforms, then the object's
// definition transform and shapes, in the world.
std::string flattened_text(bool sky = true) {
  std::string t = with_sky(sky);
  for (const Placement& p : inst_placements) {
    const Obj& o = inst_objects[p.object];
    t += std::string(p.open) + "AttributeBegin\n" + o.def + o.shapes + "AttributeEnd\n" + p.close;
  }
  return t;
}

Scene load_text(const std::string& text) {
  Scene s = load_pbrt_string(text, "inst.pbrt", ".");
  finalize_scene(s);
  return s;
}

struct Est {
  const char* name;
  Strategy strategy;
  LightPick pick;
  MisMode mode;
};
const Est inst_estimators[] = {
    {"mis power", Strategy::mis, LightPick::power, MisMode::multi},
    {"mis bvh", Strategy::mis, LightPick::bvh, MisMode::multi},
    {"mis one-sample uniform", Strategy::mis, LightPick::uniform, MisMode::one},
    {"light", Strategy::light, LightPick::uniform, MisMode::multi},
    {"bsdf", Strategy::bsdf, LightPick::power, MisMode::multi},
    {"ris", Strategy::ris, LightPick::power, MisMode::multi},
};
RenderOptions est_options(const Est& e, int depth, uint32_t spp) {
  return independent_options(e.strategy, e.pick, e.mode, depth, spp, 3);
}

}  // namespace

// Every estimator renders the instanced scene as the scene flattened by hand, to rounding:
// the points of an instance are placed in the world by its matrix in float (the flattened
// copy's vertices by the composed matrix in double, then rounded), so a pixel differs by a
// few ulps, unless one of its paths meets a decision (a Fresnel choice, Russian roulette,
// an edge) on the other side of the rounding and goes elsewhere: then the pixel is another
// sample of the same estimate (the caustics under the glass spheres differ most, then the
// hair, whose lobes magnify the rounding of where a ray meets a fibre). Measured (48x36,
// 8 spp, depth 5, every estimator, AMD EPYC with AVX-512): 98.1-98.8% of the values agree
// to 1e-4 relative (99.3-99.5% without the fibres), the largest difference 0.78 relative
// (a caustic pixel: at 256 spp the ball's 4x4 regions agree to 1e-3), the sums within 0.25
// standard errors (counting the two images as independent, which overstates it). Bounds:
// 97% and 4 standard errors, so that a wrong normal, side or offset on an instance (each
// covers 2-5% of the values, most of which would change) fails.
TEST(Instances, SameImageAsFlattenedByHand) {
  const Scene inst = load_text(instanced_text());
  const Scene flat = load_text(flattened_text());
  ASSERT_EQ(inst.instances.size(), 7u);
  ASSERT_EQ(inst.objects.size(), 3u);
  ASSERT_TRUE(flat.instances.empty());
  ASSERT_EQ(inst.instanced_triangle_count(), flat.triangle_count());
  ASSERT_LT(inst.triangle_count(), flat.triangle_count());
  // (bounce rays against the whole scene in the first three runs; in the others against
  // the emitters' BVH then an occlusion ray, to infinity where they find no emitter under the
  // sky; the last two without the sky)
  const Scene inst_nosky = load_text(instanced_text(false)), flat_nosky = load_text(flattened_text(false));
  for (int run = 0; run < 8; ++run) {
    const Est& e = inst_estimators[run >= 6 ? run - 6 : run];
    RenderOptions o = est_options(e, 5, 8);
    if (run < 3) o.bounce = BounceTrace::scene;
    const RenderResult a = render_scene(run >= 6 ? inst_nosky : inst, o);
    const RenderResult b = render_scene(run >= 6 ? flat_nosky : flat, o);
    ASSERT_EQ(a.stats.bounce_against_emitters, run >= 3) << e.name;
    ASSERT_EQ(a.mean.size(), b.mean.size());
    const std::vector<float> va = a.film.variance_of_mean(), vb = b.film.variance_of_mean();
    double sa = 0, sb = 0, worst = 0, var = 0;
    size_t close = 0;
    for (size_t i = 0; i < a.mean.size(); ++i) {
      ASSERT_TRUE(std::isfinite(a.mean[i])) << e.name;
      sa += a.mean[i];
      sb += b.mean[i];
      var += double(va[i]) + double(vb[i]);
      const double d = std::fabs(a.mean[i] - b.mean[i]) / std::max({1e-3, double(std::fabs(a.mean[i])), double(std::fabs(b.mean[i]))});
      worst = std::max(worst, d);
      close += d <= 1e-4;
    }
    const double frac = double(close) / double(a.mean.size()), z = (sa - sb) / std::sqrt(var);
    std::printf("[ instances ] %s: sums %.4f / %.4f (z %.2f), %.2f%% of the values within 1e-4, largest %.3g\n", e.name, sa,
                sb, z, 100 * frac, worst);
    EXPECT_LT(std::fabs(z), 4.0) << e.name;
    EXPECT_GT(frac, 0.97) << e.name;
    EXPECT_EQ(a.stats.rejected_camera, b.stats.rejected_camera) << e.name;
  }
}

namespace {

// A diffuse object of albedo 0.5 alone under a constant sky 1, placed by an instance of
// scale s and translation (t, t, t); the camera placed with it. Convex: every path leaves
// after its first bounce, so BSDF sampling, multi-sample MIS and RIS (which leave a constant
// sky to the BSDF technique) give every sample exactly 0.5 on the object and 1 beside it: a
// ray offset too small (the surface hit again at the origin) shows as less, a point placed
// wrong as a shifted silhouette.
Scene furnace_instance(bool sphere, float s, float t) {
  Scene sc;
  sc.source = "test:instanced-furnace";
  sc.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  sc.objects.push_back("object");
  if (sphere) {
    Sphere sp;
    sp.center = {0, 0, 0};
    sp.radius = 1;
    sp.material = 0;
    sp.object = 0;
    sc.spheres.push_back(sp);
  } else {
    Mesh box = media_box({-1, -1, -1}, {1, 1, 1});
    box.material = 0;
    box.object = 0;
    sc.meshes.push_back(box);
  }
  Instance in;
  for (int r = 0; r < 3; ++r) {
    in.world_from_object[r][r] = s;
    in.world_from_object[r][3] = t;
  }
  // turned 30 degrees about y (a cube then shows three faces)
  const float c = std::cos(0.5235988f), sn = std::sin(0.5235988f);
  in.world_from_object[0][0] = s * c;
  in.world_from_object[0][2] = s * sn;
  in.world_from_object[2][0] = -s * sn;
  in.world_from_object[2][2] = s * c;
  sc.instances.push_back(in);
  Light sky;
  sky.type = LightKind::infinite;
  sky.radiance = {1, 1, 1};
  sc.lights.push_back(sky);
  sc.camera.width = sc.camera.height = 24;
  sc.camera.fov_deg = 40;
  camera_look_at(sc.camera, {t + s * 1.5f, t + s * 2.f, t - s * 5.f}, {t, t, t}, {0, 1, 0});
  finalize_scene(sc);
  return sc;
}

}  // namespace

// Scale 1e-3 and 1e3, a translation of 1e4 (and both): every pixel is exactly 0.5 where it
// sees only the object, 1 where it sees only the sky, between them on the silhouette; the
// object covers the same pixels at every placement. Tolerance 2e-6 (float rounding of a
// sum of 0.5s; one ray of a pixel's 16 that meets the surface again would lower it by
// 0.5 / 16 * 0.5).
TEST(Instances, ExactUnderExtremeTransforms) {
  const struct {
    float s, t;
  } placements[] = {{1, 0}, {1e-3f, 0}, {1e3f, 0}, {1, 1e4f}, {1e3f, 1e4f}};
  const Est exact[] = {inst_estimators[4], inst_estimators[0], inst_estimators[5]};
  for (bool sphere : {true, false}) {
    std::vector<float> coverage;
    for (const auto& pl : placements) {
      const Scene sc = furnace_instance(sphere, pl.s, pl.t);
      for (const Est& e : exact) {
        const RenderResult r = render_scene(sc, est_options(e, 5, 16));
        const std::string what = std::string(sphere ? "sphere" : "box") + " s " + std::to_string(pl.s) + " t " +
                                 std::to_string(pl.t) + " " + e.name;
        int object = 0, sky = 0;
        std::vector<float> cov;
        for (size_t i = 0; i < r.mean.size(); i += 3) {
          const float v = r.mean[i];
          ASSERT_GE(v, 0.5f - 2e-6f) << what << " pixel " << i / 3;
          ASSERT_LE(v, 1.f + 2e-6f) << what << " pixel " << i / 3;
          object += std::fabs(v - 0.5f) <= 2e-6f;
          sky += std::fabs(v - 1.f) <= 2e-6f;
          cov.push_back(v);
        }
        EXPECT_GT(object, 60) << what;
        EXPECT_GT(sky, 200) << what;
        EXPECT_EQ(r.stats.rejected_camera + r.stats.rejected_bsdf + r.stats.rejected_light, 0u) << what;
        // the same silhouette as at scale 1 (pixels that differ: at most a few on its edge)
        if (coverage.empty()) {
          coverage = cov;
        } else {
          int moved = 0;
          for (size_t i = 0; i < cov.size(); ++i) moved += std::fabs(cov[i] - coverage[i]) > 0.02f;
          EXPECT_LE(moved, 4) << what;
        }
      }
    }
  }
}

// The exact floor of tests/test_render_exact.cpp (Lambert's polygon formula) with the
// floor an instance: of scale 1e-3 and 1e3 (its mesh scaled by the inverse), and moved
// 1e4 along x and z with the sources and the camera. Image mean within 4 standard errors
// of the exact one for light sampling, MIS and the light BVH's picks.
TEST(Instances, LambertFloorAsAnInstance) {
  const struct {
    float s, t;
  } placements[] = {{1e-3f, 0}, {1e3f, 0}, {1, 1e4f}};
  PlaneScene ref = plane_scene({0, 0.5f, 0}, 90, 24);
  add_source_quad(ref, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  finalize_scene(ref.scene);
  const std::vector<double> exact = exact_image(ref, 6);
  for (const auto& pl : placements) {
    PlaneScene p = plane_scene({pl.t, 0.5f, pl.t}, 90, 24);
    add_source_quad(p, {pl.t - 0.5f, 1, pl.t - 0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
    Scene& s = p.scene;
    Mesh& floor = s.meshes[0];
    ASSERT_EQ(floor.name, "floor");
    for (float& v : floor.positions) v /= pl.s;
    floor.object = 0;
    s.objects.push_back("floor");
    Instance in;
    for (int r = 0; r < 3; ++r) in.world_from_object[r][r] = pl.s;
    in.world_from_object[0][3] = in.world_from_object[2][3] = pl.t;
    s.instances.push_back(in);
    finalize_scene(s);
    const Est ests[] = {inst_estimators[0], inst_estimators[1], inst_estimators[2], inst_estimators[3]};
    for (const Est& e : ests) {
      const RenderResult r = render_scene(s, est_options(e, 1, scaled(64u, 16u)));
      const double z = z_of_mean(r, exact);
      std::printf("[ instances ] floor s %g t %g %s: z %.2f\n", pl.s, pl.t, e.name, z);
      EXPECT_LT(std::fabs(z), 4.0) << "s " << pl.s << " t " << pl.t << " " << e.name;
      EXPECT_EQ(r.stats.rejected_camera + r.stats.rejected_light, 0u) << e.name;
    }
  }
}

// Bad input: an instance of an unknown object and a singular instance transform are errors
// naming the file and line; an object without shapes renders nothing, with a warning.
TEST(Instances, BadInput) {
  const std::string head = "WorldBegin\nObjectBegin \"tri\"\nShape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2]\nObjectEnd\n";
  auto error_of = [](const std::string& text) {
    try {
      Scene s = load_pbrt_string(text, "bad.pbrt", ".");
      finalize_scene(s);
    } catch (const SceneError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  std::string e = error_of(head + "ObjectInstance \"nope\"\n");
  EXPECT_NE(e.find("bad.pbrt:5"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown object"), std::string::npos) << e;
  e = error_of(head + "AttributeBegin\nScale 0 1 1\nObjectInstance \"tri\"\nAttributeEnd\n");
  EXPECT_NE(e.find("bad.pbrt:7"), std::string::npos) << e;
  EXPECT_NE(e.find("singular"), std::string::npos) << e;
  e = error_of(head + "AttributeBegin\nScale 1e-20 1e-20 1e-20\nObjectInstance \"tri\"\nAttributeEnd\n");
  EXPECT_NE(e.find("singular"), std::string::npos) << e;
  Scene s = load_pbrt_string(head + "ObjectBegin \"empty\"\nObjectEnd\nObjectInstance \"empty\"\nObjectInstance \"tri\"\n", "e.pbrt", ".");
  finalize_scene(s);
  EXPECT_EQ(s.instances.size(), 1u);
  bool warned = false;
  for (const std::string& w : s.warnings) warned = warned || w.find("\"empty\" has no shapes") != std::string::npos;
  EXPECT_TRUE(warned);
  // a scene built in code: a NaN in a transform, an instance of no object
  Scene c;
  c.source = "code";
  c.objects.push_back("o");
  Instance in;
  in.world_from_object[1][1] = std::nanf("");
  in.where = "code:3";
  c.instances.push_back(in);
  try {
    finalize_scene(c);
    ADD_FAILURE() << "a NaN transform was accepted";
  } catch (const SceneError& x) {
    EXPECT_NE(std::string(x.what()).find("code:3"), std::string::npos) << x.what();
  }
  c.instances[0] = Instance{};
  c.instances[0].object = 4;
  EXPECT_THROW(finalize_scene(c), SceneError);
}
