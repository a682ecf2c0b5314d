// Bump mapping (pbrt-v4's "displacement", surface_hits.h bump_normal): a plane displaced
// by a linear d(u, v) shades with the analytic tilted normal, a bump tilted past the
// viewer reflects on wo's side of it (as pbrt-v4's two-sided BxDFs), a constant displacement
// changes no bit, a pbrt file's float imagemap displacement loads and renders without a
// warning, and the image does not depend on the thread count or the pipeline.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "render_util.h"
#include "wave/textures.h"
#include "scene/pbrt.h"

namespace fs = std::filesystem;
using namespace tuile;
using namespace tuile::test;

namespace {

// The floor y = 0, x and z in [-1, 1], outward normal +y, with uv u = (x + 3) / 4 and
// v = (3 - z) / 4 (both in [1/4, 3/4]; dp/du = (4, 0, 0), dp/dv = (0, 0, -4): a uv that is
// right-handed about the normal, so that pbrt's shading frame with vertex normals agrees).
// Displacement (material 0's, float texture 0): an 8 x 8 image of c1 u + c2 v sampled at
// the texel centres, whose bilinear interpolation is that plane exactly inside the
// centres (u, v in [1/16, 15/16]). Seen from (0, 1, 0) looking down (the view stays in
// x, z in [-0.58, 0.58]), lit by a distant light towards l.
struct BumpPlane {
  Scene scene;
  float c1 = 2.f, c2 = -1.2f, rho = 0.5f, E = 2.f;
  vec3f l = normalize(vec3f{-0.6f, 1.f, 0.3f});
};

// (b: the slopes and the light to use; its scene is built here)
BumpPlane bump_plane(bool normals, bool displaced = true, int res = 16, BumpPlane b = {}) {
  Scene& s = b.scene;
  s.source = "test:bump-plane";
  Material m = diffuse_material(Rgb{b.rho, b.rho, b.rho});
  if (displaced) {
    FloatTexture t;
    t.name = "ramp";
    t.width = t.height = 8;
    for (int j = 0; j < 8; ++j)
      for (int i = 0; i < 8; ++i) {
        const float u = (static_cast<float>(i) + 0.5f) / 8.f, v = 1.f - (static_cast<float>(j) + 0.5f) / 8.f;
        t.value.push_back(b.c1 * u + b.c2 * v);
      }
    s.float_textures.push_back(t);
    m.displacement = 0;
  }
  s.materials.push_back(m);
  Mesh floor;
  floor.name = "floor";
  floor.material = 0;
  add_quad(floor, {-1, 0, -1}, {0, 0, 2}, {2, 0, 0});
  for (size_t i = 0; i < 4; ++i) {
    const float x = floor.positions[3 * i], z = floor.positions[3 * i + 2];
    floor.uvs.insert(floor.uvs.end(), {(x + 3.f) / 4.f, (3.f - z) / 4.f});
    if (normals) floor.normals.insert(floor.normals.end(), {0.f, 1.f, 0.f});
  }
  s.meshes.push_back(floor);
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 60;
  camera_look_at(s.camera, {0, 1, 0}, {0, 0, 0}, {0, 0, 1});
  Light light;
  light.type = LightKind::distant;
  light.e1 = b.l;
  light.radiance = {b.E, b.E, b.E};
  s.lights.push_back(light);
  finalize_scene(s);
  return b;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

}  // namespace

// The surface y = h(x, z) = c1 u + c2 v = c1 (x + 3) / 4 + c2 (3 - z) / 4 has the normal
// (-dh/dx, 1, -dh/dz) = (-c1 / 4, 1, c2 / 4), and under a distant light every pixel of a
// diffuse floor is rho / pi E cos(N, l) exactly (the light sample is the same for every
// sample; a BSDF sample cannot reach a delta light). Error: the texels and their bilinear
// weights are exact to a few ulps of |d| <= 2, so the finite difference over du ~ 1/8 of
// a pixel's 0.018 in u (2.3e-3) is good to ~1e-6 / 2.3e-3 ~ 5e-4 of the slope 2, and the
// cosine to less than that: 1e-3 relative. The flat floor is 4 % darker, and the normal
// tilted the wrong way 35 %: a sign or a scale error cannot pass.
TEST(Bump, LinearDisplacementTiltsTheNormalExactly) {
  for (bool normals : {false, true}) {
    const BumpPlane b = bump_plane(normals);
    const SceneViews views = build_views(b.scene, LightPick::power);
    ASSERT_TRUE(views.geom.has_bump);
    ASSERT_TRUE(views.geom.shading_normals);
    EXPECT_TRUE(b.scene.warnings.empty()) << b.scene.warnings[0];
    const vec3f N = normalize(vec3f{-b.c1 / 4.f, 1.f, b.c2 / 4.f});
    const double exact = b.rho / M_PI * b.E * dot(N, b.l);
    const double flat = b.rho / M_PI * b.E * b.l.y;
    ASSERT_GT(std::fabs(exact - flat), 0.03 * exact);
    for (Strategy st : {Strategy::light, Strategy::mis}) {
      RenderOptions o;
      o.est.strategy = st;
      o.est.spp = 2;
      const RenderResult r = render_scene(b.scene, o);
      ASSERT_EQ(r.mean.size(), 3u * 16 * 16);
      for (size_t i = 0; i < r.mean.size(); ++i)
        ASSERT_NEAR(r.mean[i], exact, 1e-3 * exact) << "normals " << normals << " " << describe(o.est) << " pixel " << i / 3;
    }
  }
}

// A bump steep enough to tilt the shading normal past the viewer: pbrt-v4's BxDFs are
// two-sided in the shading frame, so a diffuse point reflects the light that arrives on
// wo's side of the tilted plane (cos |N . l|) and none from the other side; tuile turns
// the shading normal towards wo (shading_normals.h). The floor's normal is
// N = normalize(-10, 1, 0) (c1 = 40): wo lies below that plane at the points with
// x < -0.1 and above it elsewhere, and the light (towards l, above the floor) lies below
// it. So the pixels left of x = -0.1 see rho / pi E |N . l| exactly and those right of it
// 0; a pixel straddling the line holds a mix. A shading normal turned towards the
// geometric viewer side instead (tuile before) leaves every pixel black.
TEST(Bump, SteepBumpReflectsOnWoSideOfTheShadingNormal) {
  for (bool normals : {false, true}) {
    BumpPlane steep;
    steep.c1 = 40.f;
    steep.c2 = 0.f;
    steep.l = normalize(vec3f{1.f, 0.3f, 0.f});
    const BumpPlane b = bump_plane(normals, true, 16, steep);
    const Scene& s = b.scene;
    const vec3f N = normalize(vec3f{-b.c1 / 4.f, 1.f, 0.f});
    ASSERT_LT(dot(N, b.l), 0.f);
    const double exact = b.rho / M_PI * b.E * std::fabs(dot(N, b.l));
    RenderOptions o;
    o.est.spp = 4;
    const RenderResult r = render_scene(s, o);
    ASSERT_EQ(r.mean.size(), 3u * 16 * 16);
    int lit = 0, dark = 0, mixed = 0;
    for (size_t i = 0; i < r.mean.size(); i += 3) {
      const float v = r.mean[i];
      ASSERT_TRUE(std::isfinite(v));
      ASSERT_GE(v, 0.f);
      ASSERT_LE(v, exact * (1 + 1e-3)) << "pixel " << i / 3;
      if (std::fabs(v - exact) <= 1e-3 * exact) ++lit;
      else if (v == 0.f) ++dark;
      else ++mixed;
    }
    // x < -0.1 is 41% of the view (x in [-0.577, 0.577]); one column of 16 straddles the line
    EXPECT_GE(lit, 16 * 5) << "normals " << normals;
    EXPECT_GE(dark, 16 * 7) << "normals " << normals;
    EXPECT_LE(mixed, 16 * 2) << "normals " << normals;
  }
}

// A displacement that is the same everywhere moves the surface without turning it: the
// render is the one without displacement, bit for bit (an area light and MIS, so that
// BSDF sampling and the emitter hits run too).
TEST(Bump, ConstantDisplacementChangesNothing) {
  for (bool normals : {false, true}) {
    BumpPlane a = bump_plane(normals, false), b = bump_plane(normals, true);
    for (float& v : b.scene.float_textures[0].value) v = 0.3f;
    for (Scene* s : {&a.scene, &b.scene}) {
      Mesh lamp;
      lamp.name = "lamp";
      lamp.emission = {4, 4, 4};
      add_quad(lamp, {0.4f, 0.6f, -0.3f}, {0.6f, 0, 0}, {0, 0, 0.6f});  // facing down, out of view
      s->meshes.push_back(lamp);
      finalize_scene(*s);
    }
    EXPECT_FALSE(build_views(b.scene, LightPick::power).geom.has_bump);
    RenderOptions o;
    o.est.spp = 4;
    const std::vector<float> ra = render_scene(a.scene, o).mean;
    EXPECT_TRUE(same_bits(ra, render_scene(b.scene, o).mean)) << "normals " << normals;
    EXPECT_GT(*std::max_element(ra.begin(), ra.end()), 1.2f * *std::min_element(ra.begin(), ra.end()))
        << "the lamp lights the floor unevenly";
  }
}

// A bumpy texture (random texels) with an area light: the image is the same for 1 and 2
// threads and for the general pipeline, and differs from the flat render.
TEST(Bump, DeterministicOverThreadsAndPipelines) {
  BumpPlane b = bump_plane(true, true, 64), flat = bump_plane(true, false, 64);  // 16 tiles
  FloatTexture& t = b.scene.float_textures[0];
  uint32_t h = 12345;
  for (float& v : t.value) {
    h = h * 1664525u + 1013904223u;
    v = 0.05f * static_cast<float>(h >> 8) * 0x1p-24f;
  }
  for (Scene* s : {&b.scene, &flat.scene}) {
    Mesh lamp;
    lamp.name = "lamp";
    lamp.emission = {4, 4, 4};
    add_quad(lamp, {0.4f, 0.6f, -0.3f}, {0.6f, 0, 0}, {0, 0, 0.6f});
    s->meshes.push_back(lamp);
    finalize_scene(*s);
  }
  RenderOptions o;
  o.est.spp = 4;
  o.threads = 1;
  const RenderResult one = render_scene(b.scene, o);
  o.threads = 2;
  EXPECT_TRUE(same_bits(one.mean, render_scene(b.scene, o).mean));
  o.general_pipeline = true;
  EXPECT_TRUE(same_bits(one.mean, render_scene(b.scene, o).mean));
  o.general_pipeline = false;
  EXPECT_FALSE(same_bits(one.mean, render_scene(flat.scene, o).mean));
  EXPECT_EQ(one.stats.rejected_camera + one.stats.rejected_light + one.stats.rejected_bsdf, 0u);
  for (float v : one.mean) ASSERT_TRUE(std::isfinite(v));
}

// pbrt-v4 files: a float imagemap as a material's displacement loads and renders without
// a warning (a mesh without uv takes pbrt's default parameterisation); on a sphere it is
// reported.
TEST(Bump, PbrtFloatImagemapDisplacement) {
  const fs::path dir = fs::temp_directory_path() /
                       ("tuile_test_bump_" + std::to_string(std::chrono::steady_clock::now().time_since_epoch().count()));
  fs::create_directories(dir);
  {  // a 4 x 1 TGA ramp (uncompressed, 24-bit, top row first; read as sRGB, as pbrt-v4 reads it)
    std::string s(18, '\0');
    s[2] = 2;
    s[12] = 4, s[14] = 1, s[16] = 24, s[17] = 0x20;
    for (int v : {0, 85, 170, 255}) s += std::string(3, char(v));
    std::ofstream(dir / "ramp.tga", std::ios::binary) << s;
  }
  const std::string head =
      "LookAt 0 3 0  0 0 0  0 0 1\nCamera \"perspective\" \"float fov\" 50\n"
      "Film \"rgb\" \"integer xresolution\" 16 \"integer yresolution\" 16\nWorldBegin\n"
      "LightSource \"distant\" \"point3 from\" [-1 2 0.5] \"point3 to\" [0 0 0] \"rgb L\" [2 2 2]\n"
      "Texture \"bumps\" \"float\" \"imagemap\" \"string filename\" \"ramp.tga\" \"float scale\" 0.2\n";
  const std::string quad =
      "Shape \"trianglemesh\" \"point3 P\" [-1 0 -1  -1 0 1  1 0 1  1 0 -1] \"integer indices\" [0 1 2 0 2 3]\n";
  const std::string quad_uv =
      "Shape \"trianglemesh\" \"point3 P\" [-1 0 -1  -1 0 1  1 0 1  1 0 -1] \"integer indices\" [0 1 2 0 2 3]"
      " \"point2 uv\" [0 0  0 1  1 1  1 0]\n";
  auto load = [&](const std::string& body) {
    Scene s = load_pbrt_string(head + body, "bump.pbrt", dir.string());
    finalize_scene(s);
    return s;
  };
  const Scene bumped = load("Material \"diffuse\" \"texture displacement\" \"bumps\"\n" + quad_uv + quad);
  const Scene flat = load("Material \"diffuse\"\n" + quad_uv + quad);
  for (const std::string& w : bumped.warnings) EXPECT_EQ(w.find("displacement"), std::string::npos) << w;
  ASSERT_EQ(bumped.meshes.size(), 2u);
  const Material& m = bumped.materials[size_t(bumped.meshes[0].material)];
  ASSERT_GE(m.displacement, 0);
  EXPECT_EQ(bumped.float_textures[size_t(m.displacement)].width, 4);
  EXPECT_TRUE(build_views(bumped, LightPick::power).geom.has_bump);
  RenderOptions o;
  o.est.spp = 2;
  const RenderResult a = render_scene(bumped, o), b = render_scene(flat, o);
  for (float v : a.mean) ASSERT_TRUE(std::isfinite(v));
  EXPECT_FALSE(same_bits(a.mean, b.mean));
  // the bumped quads as an instance (squashed, mirrored and turned) render as the same
  // quads flattened by hand, to rounding: the bump's frame is built from the vertices and
  // vertex normals placed in the world
  {
    const std::string xf = "Translate 0.1 0 0\nScale -0.8 1.3 0.9\nRotate 20 0 1 0\n";
    const std::string shapes = "Material \"diffuse\" \"texture displacement\" \"bumps\"\n" + quad_uv;
    const Scene inst = load("ObjectBegin \"b\"\n" + shapes + "ObjectEnd\nAttributeBegin\n" + xf +
                            "ObjectInstance \"b\"\nAttributeEnd\n");
    const Scene hand = load("AttributeBegin\n" + xf + shapes + "AttributeEnd\n");
    ASSERT_EQ(inst.instances.size(), 1u);
    const RenderResult x = render_scene(inst, o), y = render_scene(hand, o);
    ASSERT_EQ(x.mean.size(), y.mean.size());
    size_t close = 0;
    double sx = 0, sy = 0;
    for (size_t i = 0; i < x.mean.size(); ++i) {
      close += std::fabs(x.mean[i] - y.mean[i]) <= 1e-4f * std::max(1e-3f, std::fabs(y.mean[i]));
      sx += x.mean[i];
      sy += y.mean[i];
    }
    EXPECT_GE(close, x.mean.size() * 98 / 100) << "of " << x.mean.size();
    EXPECT_NEAR(sx / sy, 1.0, 1e-4);
    EXPECT_FALSE(same_bits(x.mean, render_scene(flat, o).mean));
  }
  const Scene sphere = load("Material \"diffuse\" \"texture displacement\" \"bumps\"\nShape \"sphere\"\n");
  bool warned = false;
  for (const std::string& w : sphere.warnings) warned = warned || w.find("spheres") != std::string::npos;
  EXPECT_TRUE(warned);
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// pbrt-v4's MIP pyramid (scene.h build_mip, as Image::GeneratePyramid): a power-of-two
// image keeps its texels at level 0 and each next level averages 2 x 2 of them, down to
// one texel, the mean; an image that is not a power of two is first resampled up by a
// windowed sinc, whose normalised weights keep a constant image constant and, unlike any
// interpolation, overshoot at a sharp edge (clamped at 0 below, as pbrt-v4).
TEST(Bump, MipPyramidAsPbrtV4) {
  FloatTexture t;
  t.width = 4;
  t.height = 2;
  t.value = {1, 2, 3, 4, 5, 6, 7, 8};
  build_mip(t);
  ASSERT_EQ(t.mip_w, (std::vector<int32_t>{4, 2, 1}));
  ASSERT_EQ(t.mip_h, (std::vector<int32_t>{2, 1, 1}));
  for (size_t i = 0; i < 8; ++i) EXPECT_EQ(t.mip[t.mip_at[0] + i], t.value[i]);
  EXPECT_FLOAT_EQ(t.mip[t.mip_at[1]], (1 + 2 + 5 + 6) / 4.f);
  EXPECT_FLOAT_EQ(t.mip[t.mip_at[1] + 1], (3 + 4 + 7 + 8) / 4.f);
  EXPECT_FLOAT_EQ(t.mip[t.mip_at[2]], 4.5f);

  FloatTexture c;
  c.width = 3;
  c.height = 5;
  c.value.assign(15, 0.7f);
  build_mip(c);
  ASSERT_EQ(c.mip_w, (std::vector<int32_t>{4, 2, 1, 1}));
  ASSERT_EQ(c.mip_h, (std::vector<int32_t>{8, 4, 2, 1}));
  for (float v : c.mip) EXPECT_NEAR(v, 0.7f, 1e-6f);

  FloatTexture e;  // a step 0 | 1 across 6 texels, resampled to 8
  e.width = 6;
  e.height = 1;
  e.value = {0, 0, 0, 1, 1, 1};
  build_mip(e);
  ASSERT_EQ(e.mip_w.front(), 8);
  float lo = 1, hi = 0;
  for (int i = 0; i < 8; ++i) {
    lo = std::min(lo, e.mip[e.mip_at[0] + static_cast<size_t>(i)]);
    hi = std::max(hi, e.mip[e.mip_at[0] + static_cast<size_t>(i)]);
  }
  EXPECT_EQ(lo, 0.f);   // the undershoot, clamped
  EXPECT_GT(hi, 1.01f);  // the overshoot of the sinc
}

// The bump map's lookup (wave/textures.h float_texture_filtered, pbrt-v4's MIPMap::Filter):
// the level log2(width) above the finest; below it the finest level's bilinear value;
// past the coarsest its one texel (the mean); between, the nearest texel (point), the
// bilinear value at the lower level (bilinear) or the blend of the two levels (trilinear).
TEST(Bump, MipLookupPicksPbrtV4sLevel) {
  FloatTexture t;
  t.width = t.height = 8;
  uint32_t h = 12345;
  for (int i = 0; i < 64; ++i) {
    h = h * 1664525u + 1013904223u;
    t.value.push_back(static_cast<float>(h >> 8) / 16777216.f);
  }
  build_mip(t);
  ASSERT_EQ(t.mip_w.size(), 4u);  // 8, 4, 2, 1
  const float* fv[1] = {t.value.data()};
  const int32_t fw[1] = {8}, fh[1] = {8}, levels[1] = {4};
  const float* mip[1] = {t.mip.data()};
  const int32_t* mw[1] = {t.mip_w.data()};
  const int32_t* mh[1] = {t.mip_h.data()};
  const size_t* at[1] = {t.mip_at.data()};
  int32_t filter[1] = {1};
  GeomView G;
  G.ftex_value = fv;
  G.ftex_w = fw;
  G.ftex_h = fh;
  G.ftex_mip = mip;
  G.ftex_mip_w = mw;
  G.ftex_mip_h = mh;
  G.ftex_mip_at = at;
  G.ftex_levels = levels;
  G.ftex_filter = filter;
  const auto level_bilerp = [&](int k, float u, float v) {
    return bilinear_texel(t.mip.data() + t.mip_at[static_cast<size_t>(k)], t.mip_w[static_cast<size_t>(k)],
                          t.mip_h[static_cast<size_t>(k)], u, v);
  };
  const float mean = t.mip[t.mip_at[3]];
  for (const float u : {0.13f, 0.5f, 0.87f, 1.31f})
    for (const float v : {0.07f, 0.44f, 0.93f}) {
      const float s = u - std::floor(u), q = (1.f - v) - std::floor(1.f - v);  // (top row first: t = 1 - v)
      for (int32_t f : {0, 1, 2}) {
        filter[0] = f;
        // below the finest level (width under one texel: l < 0): the finest level's
        // bilinear value, or its nearest texel (point)
        const int x0 = static_cast<int>(std::round(s * 8 - 0.5f)) & 7, y0 = static_cast<int>(std::round(q * 8 - 0.5f)) & 7;
        const float finest = f == 0 ? t.value[static_cast<size_t>(8 * y0 + x0)] : float_texture_bilinear(G, 0, u, v);
        EXPECT_EQ(float_texture_filtered(G, 0, u, v, 1.f / 64), finest) << f;
        EXPECT_EQ(float_texture_filtered(G, 0, u, v, 0.f), finest) << f;
        // past the coarsest: the mean
        EXPECT_EQ(float_texture_filtered(G, 0, u, v, 1.f), mean) << f;
        EXPECT_EQ(float_texture_filtered(G, 0, u, v, 5.f), mean) << f;
      }
      // l = 3 + log2(w) = 1.5: level 1 (4 x 4) and level 2 (2 x 2)
      const float w = std::exp2(1.5f - 3.f);
      filter[0] = 1;
      EXPECT_FLOAT_EQ(float_texture_filtered(G, 0, u, v, w), level_bilerp(1, u, v));
      filter[0] = 2;
      EXPECT_NEAR(float_texture_filtered(G, 0, u, v, w), 0.5f * (level_bilerp(1, u, v) + level_bilerp(2, u, v)), 1e-6f);
      filter[0] = 0;  // the nearest texel of level 1
      const int x = static_cast<int>(std::round(s * 4 - 0.5f)) & 3, y = static_cast<int>(std::round(q * 4 - 0.5f)) & 3;
      EXPECT_EQ(float_texture_filtered(G, 0, u, v, w), t.mip[t.mip_at[1] + static_cast<size_t>(4 * y + x)]);
    }
}
