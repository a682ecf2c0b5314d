// pbrt-v4's description of participating media, as the loader reads it: MakeNamedMedium
// (homogeneous: sigma_a, sigma_s, scale, g, Le, Lescale and the measured presets; the grid
// types named in a warning), MediumInterface on shapes (inside, outside, one name for both,
// forward references), the camera's medium, errors naming file and line, and the
// "interface" material, whose shapes do not scatter light: rays pass through them.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "render_util.h"
#include "scene/pbrt.h"

using namespace tuile;
using namespace tuile::test;

namespace {

const std::string media_quad = "Shape \"trianglemesh\" \"point3 P\" [-1 -1 0 1 -1 0 1 1 0 -1 1 0] \"integer indices\" [0 1 2 0 2 3]\n";

Scene media_world(const std::string& body, const std::string& before = "") {
  return load_pbrt_string(before + "WorldBegin\n" + body, "m.pbrt", ".");
}

std::string media_error(const std::string& body, const std::string& before = "") {
  try {
    media_world(body, before);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "(no error)";
}

bool has_text(const std::vector<std::string>& v, const std::string& what) {
  for (const std::string& w : v)
    if (w.find(what) != std::string::npos) return true;
  return false;
}

}  // namespace

TEST(Media, HomogeneousParameters) {
  const Scene s = media_world(
      "MakeNamedMedium \"fog\" \"string type\" \"homogeneous\" \"rgb sigma_a\" [0.1 0.2 0.3] \"rgb sigma_s\" [1 2 3] "
      "\"float scale\" 2 \"float g\" 0.7 \"rgb Le\" [0.5 0.5 0.5] \"float Lescale\" 4\n"
      "MakeNamedMedium \"default\" \"string type\" \"homogeneous\"\n");
  ASSERT_EQ(s.media.size(), 2u);
  const Medium& m = s.media[0];
  EXPECT_EQ(m.name, "fog");
  EXPECT_TRUE(m.supported);
  EXPECT_EQ(m.where, "m.pbrt:2");
  EXPECT_FLOAT_EQ(m.sigma_a.g, 0.4f);  // times scale
  EXPECT_FLOAT_EQ(m.sigma_s.b, 6.f);
  EXPECT_FLOAT_EQ(m.g, 0.7f);
  EXPECT_GT(m.Le.r, 0.f);
  EXPECT_NEAR(m.Le.r, m.Le.b, 1e-3f * m.Le.r);  // a grey emission stays grey, times Lescale
  // pbrt-v4's defaults: sigma_a = sigma_s = 1, g = 0, no emission
  EXPECT_FLOAT_EQ(s.media[1].sigma_a.r, 1.f);
  EXPECT_FLOAT_EQ(s.media[1].sigma_s.g, 1.f);
  EXPECT_FLOAT_EQ(s.media[1].g, 0.f);
  EXPECT_FLOAT_EQ(s.media[1].Le.r, 0.f);
  EXPECT_FALSE(has_text(s.warnings, "medium"));  // homogeneous media are rendered: nothing approximated
}

TEST(Media, PresetsAreMeasuredCoefficients) {
  const Scene s = media_world(
      "MakeNamedMedium \"milk\" \"string type\" \"homogeneous\" \"string preset\" \"Wholemilk\" \"float scale\" 10\n"
      "MakeNamedMedium \"skin\" \"string type\" \"homogeneous\" \"string preset\" \"Skin1\"\n"
      "MakeNamedMedium \"odd\" \"string type\" \"homogeneous\" \"string preset\" \"Nectar\" \"rgb sigma_a\" [2 2 2]\n");
  // Jensen et al. 2001, in mm^-1: whole milk sigma_s' (2.55, 3.21, 3.77), sigma_a (0.0011, 0.0024, 0.014)
  EXPECT_FLOAT_EQ(s.media[0].sigma_s.r, 25.5f);
  EXPECT_FLOAT_EQ(s.media[0].sigma_a.b, 0.14f);
  EXPECT_EQ(s.media[0].preset, "Wholemilk");
  EXPECT_FLOAT_EQ(s.media[1].sigma_a.b, 0.48f);
  EXPECT_FLOAT_EQ(s.media[2].sigma_a.r, 2.f);  // an unknown preset: a warning, the parameters
  EXPECT_TRUE(has_text(s.warnings, "m.pbrt:4: medium preset \"Nectar\" not found"));
}

TEST(Media, InterfacesBindShapesTheCameraAndPointSources) {
  const Scene s = media_world(
      "MediumInterface \"glass-inside\" \"\"\n" + media_quad +           // forward reference: defined below
          "AttributeBegin\nMediumInterface \"fog\"\n" + media_quad +  // one name: inside and outside
          "AttributeEnd\n" + media_quad +                              // back to the first interface
          "LightSource \"point\" \"rgb I\" [1 1 1]\n"                   // in no medium (the outside's "")
          "AttributeBegin\nMediumInterface \"glass-inside\" \"fog\"\n"
          "LightSource \"spot\" \"rgb I\" [1 1 1]\nAttributeEnd\n"     // in the outside one: fog
          "MakeNamedMedium \"fog\" \"string type\" \"homogeneous\"\n"
          "MakeNamedMedium \"glass-inside\" \"string type\" \"homogeneous\" \"rgb sigma_a\" [250 1000 1000]\n",
      "MediumInterface \"\" \"fog\"\n"
      "Camera \"perspective\"\n");
  ASSERT_EQ(s.meshes.size(), 3u);
  ASSERT_EQ(s.media.size(), 2u);
  EXPECT_EQ(s.meshes[0].medium_inside, 1);
  EXPECT_EQ(s.meshes[0].medium_outside, -1);
  EXPECT_EQ(s.meshes[1].medium_inside, 0);
  EXPECT_EQ(s.meshes[1].medium_outside, 0);
  EXPECT_EQ(s.meshes[2].medium_inside, 1);
  EXPECT_EQ(s.camera_medium, 0);  // the outside medium in force at Camera
  ASSERT_EQ(s.lights.size(), 2u);  // a point or spot source: the outside medium at LightSource
  EXPECT_EQ(s.lights[0].medium, -1);
  EXPECT_EQ(s.lights[1].medium, 0);
  EXPECT_EQ(s.media[0].bounding_shapes, 1);
  EXPECT_EQ(s.media[1].bounding_shapes, 2);
}

TEST(Media, GridMediaAreNamedInAWarning) {
  const Scene s = media_world(
      "MakeNamedMedium \"smoke\" \"string type\" \"nanovdb\" \"string filename\" \"smoke.nvdb\"\n"
      "MediumInterface \"smoke\" \"\"\n" + media_quad);
  ASSERT_EQ(s.media.size(), 1u);
  EXPECT_FALSE(s.media[0].supported);
  EXPECT_TRUE(has_text(s.warnings, "m.pbrt:2: medium type \"nanovdb\" is not supported"));
  EXPECT_EQ(s.meshes.size(), 1u);  // the shape renders without its medium
}

TEST(Media, BadMediaNameFileAndLine) {
  const struct {
    std::string body, where;
  } cases[] = {
      {"MediumInterface \"nowhere\" \"\"\n" + media_quad, "m.pbrt:2"},  // never defined: where the interface was
      {"MakeNamedMedium \"a\" \"string type\" \"homogeneous\" \"float g\" 1\n", "m.pbrt:2"},
      {"MakeNamedMedium \"a\" \"string type\" \"homogeneous\" \"rgb sigma_s\" [1 -1 1]\n", "m.pbrt:2"},
      {"MakeNamedMedium \"a\" \"string type\" \"homogeneous\" \"float scale\" -1\n", "m.pbrt:2"},
      {"MakeNamedMedium \"a\" \"string type\" \"fluffy\"\n", "m.pbrt:2"},
      {"MakeNamedMedium \"a\"\n", "m.pbrt:2"},
      {"MakeNamedMedium \"a\" \"string type\" \"homogeneous\"\nMakeNamedMedium \"a\" \"string type\" \"homogeneous\"\n",
       "m.pbrt:3"},
      {"MakeNamedMedium \"a\" \"string type\" \"homogeneous\" \"rgb sigma_a\" [nan 1 1]\n", "m.pbrt:2"},
  };
  for (const auto& c : cases) {
    const std::string e = media_error(c.body);
    EXPECT_EQ(e.rfind(c.where, 0), 0u) << c.body << " -> " << e;
  }
}

// An "interface" media_quad between the camera and an emitter of radiance 2: the camera sees the
// emitter through it, exactly (rays pass through media boundaries), and an interface is not
// an approximation. One between the same media on both sides is left out of the geometry
// (a note says so); one that bounds a medium stays (the medium stages pass rays through it),
// here with fog outside and nothing inside, met from the camera's empty side: the emitter
// behind it (inside) is 2 exactly.
TEST(Media, InterfaceShapesLetRaysThrough) {
  const std::string before = "LookAt 0 0 3 0 0 0 0 1 0\nCamera \"perspective\" \"float fov\" 30\n"
                             "Film \"rgb\" \"integer xresolution\" 8 \"integer yresolution\" 8\n";
  const std::string lamp = "AttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [2 2 2]\nTranslate 0 0 -1\nScale 10 10 1\n" +
                           media_quad + "AttributeEnd\n";
  for (const bool bounds : {false, true}) {
    const Scene s = media_world("MakeNamedMedium \"fog\" \"string type\" \"homogeneous\"\n" + lamp +
                                    "AttributeBegin\nMaterial \"interface\"\n" +
                                    (bounds ? "MediumInterface \"\" \"fog\"\n" : "MediumInterface \"fog\" \"fog\"\n") +
                                    "Scale 10 10 1\n" + media_quad + "AttributeEnd\n",
                                before);
    EXPECT_EQ(s.meshes.size(), bounds ? 2u : 1u);
    EXPECT_EQ(has_text(s.notes, "1 shape(s) with the \"interface\" material"), !bounds);
    EXPECT_FALSE(has_text(s.warnings, "interface"));
    EXPECT_EQ(s.media[0].bounding_shapes, 1);
    Scene f = s;
    finalize_scene(f);
    RenderOptions o;
    o.est.spp = 4;
    o.threads = 2;
    const RenderResult r = render_scene(f, o);
    for (size_t i = 0; i < r.mean.size(); ++i) EXPECT_FLOAT_EQ(r.mean[i], 2.f) << i;
  }
}

// volumetric-caustic's front wall is an "interface" (the box holds a gas): it is no grey
// wall and no approximation, it stays in the geometry as the boundary the medium stages
// pass rays through, and the gas is listed with the shapes that bound it.
TEST(Media, VolumetricCausticDescribesItsGas) {
  const std::string f = std::string(TUILE_SHARED_SCENES) + "/volumetric-caustic/scene-v4.pbrt";
  if (!std::filesystem::exists(f)) GTEST_SKIP() << "no " << f << " (the shared scenes are absent)";
  const Scene s = load_scene(f, {});
  ASSERT_EQ(s.media.size(), 1u);
  EXPECT_EQ(s.media[0].name, "gas");
  EXPECT_FLOAT_EQ(s.media[0].sigma_s.g, 1.f);
  EXPECT_FLOAT_EQ(s.media[0].sigma_a.g, 0.f);
  EXPECT_EQ(s.media[0].bounding_shapes, 3);  // the front wall (gas inside), the glass sphere and the light (gas outside)
  EXPECT_FALSE(has_text(s.warnings, "\"interface\" approximated"));
  EXPECT_FALSE(has_text(s.notes, "\"interface\" material"));  // (it bounds the gas: kept)
  Scene fin = s;
  finalize_scene(fin);
  EXPECT_TRUE(fin.features & feat_media);
}
