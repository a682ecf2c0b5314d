// pbrt-v4's path regularization (Estimator::regularize, --regularize, the Integrator's
// "bool regularize"): after a path's first non-specular BSDF sample, every later vertex's
// Trowbridge-Reitz alphas below 0.3 become clamp(2 alpha, 0.1, 0.3). Checked exactly: a
// scene whose camera sees only a diffuse floor renders, regularized, the same bits as the
// same scene with the panels' alphas regularized by hand (every vertex after the floor is
// regularized, none before it); a camera that sees a mirror, then a glossy ceiling, renders
// the same bits regularized or not at depth 2 (a specular sample does not start it), and
// other images from depth 3 on; the twin rows of the material table.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "bsdf/microfacet.h"
#include "render/views.h"
#include "render_util.h"

using namespace tuile;
using namespace tuile::test;

namespace {

Material conductor(float alpha) {
  Material m;
  m.kind = MaterialKind::conductor;
  m.eta_rgb = {0.2f, 0.9f, 1.1f};
  m.k_rgb = {3.9f, 2.4f, 2.1f};
  m.alpha_u.value = m.alpha_v.value = alpha;
  return m;
}

// The panels beside the floor, out of the camera's view: a mirror, a glossy conductor, a
// glass sheet in front of part of them, a coated diffuse and a coated conductor (whose base
// is regularized too), a rough conductor that regularization leaves alone (alpha 0.4) and a
// glossy one at the limit (0.3: left alone); reg: their alphas regularized by hand.
std::vector<Material> panel_materials(bool reg) {
  const auto r = [&](float a) { return reg ? regularized_alpha(a) : a; };
  std::vector<Material> out;
  Material m = conductor(0.f);
  m.alpha_u.value = r(0.f);
  m.alpha_v.value = r(0.f);
  out.push_back(m);
  m = conductor(0.08f);
  m.alpha_u.value = r(0.08f);
  m.alpha_v.value = r(0.04f);
  out.push_back(m);
  Material glass;
  glass.kind = MaterialKind::dielectric;
  glass.eta = 1.5f;
  glass.alpha_u.value = glass.alpha_v.value = r(0.f);
  out.push_back(glass);
  Material coat;
  coat.kind = MaterialKind::coated_diffuse;
  coat.reflectance = {0.6f, 0.5f, 0.3f};
  coat.alpha_u.value = coat.alpha_v.value = r(0.02f);
  out.push_back(coat);
  Material cc;
  cc.kind = MaterialKind::coated_conductor;
  cc.eta_rgb = {0.2f, 0.9f, 1.1f};
  cc.k_rgb = {3.9f, 2.4f, 2.1f};
  cc.alpha_u.value = cc.alpha_v.value = r(0.f);
  cc.base_alpha_u.value = cc.base_alpha_v.value = r(0.2f);
  out.push_back(cc);
  out.push_back(conductor(0.4f));
  m = conductor(0.3f);
  m.alpha_v.value = 0.3f;
  out.push_back(m);
  return out;
}

// The floor (diffuse, y = 0) seen from above; the panels stand at x = 1, facing -x, side by
// side along z, a glass sheet at x = 0.8 in front of the first two; a light at x = 0.5
// faces them. Nothing but the floor is in the camera's view, so every vertex after the
// first follows a non-specular (Lambert) sample.
Scene floor_and_panels(bool reg_by_hand) {
  PlaneScene p = plane_scene({-1, 1.5f, 0}, 50, 16, 0.5f);
  Scene& s = p.scene;
  const std::vector<Material> panels = panel_materials(reg_by_hand);
  const int first = static_cast<int>(s.materials.size());
  for (const Material& m : panels) s.materials.push_back(m);
  s.materials.push_back(diffuse_material(Rgb{0, 0, 0}));
  const int black = static_cast<int>(s.materials.size()) - 1;
  const float z0[] = {-2.f, -1.f, 0.f, 1.f, 2.f, 3.f};
  const int order[] = {0, 1, 3, 4, 5, 6};  // (2, the glass, is the sheet)
  for (int i = 0; i < 6; ++i) {
    Mesh m;
    m.name = "panel";
    m.material = first + order[i];
    add_quad(m, {1, 0, z0[i]}, {0, 0, 1}, {0, 3, 0});  // x = 1, facing -x
    s.meshes.push_back(m);
  }
  // a conductor whose alphas are float textures (per point: regularize_points), of values
  // in [1/16, 1/8] (doubled by hand: twice the bilinear lookup, bit for bit, and inside
  // regularization's [0.1, 0.3])
  FloatTexture t;
  t.name = "alpha";
  t.width = t.height = 2;
  t.value = {0.0625f, 0.125f, 0.09375f, 0.0625f};
  if (reg_by_hand)
    for (float& x : t.value) x *= 2;
  s.float_textures.push_back(t);
  Material tex = conductor(0.0625f);
  tex.alpha_u.texture = tex.alpha_v.texture = static_cast<int>(s.float_textures.size()) - 1;
  tex.remap_roughness = false;
  s.materials.push_back(tex);
  Mesh tp;
  tp.name = "textured panel";
  tp.material = static_cast<int>(s.materials.size()) - 1;
  add_quad(tp, {1, 0, 4}, {0, 0, 1}, {0, 3, 0});
  tp.uvs = {0, 0, 1, 0, 1, 1, 0, 1};
  s.meshes.push_back(tp);
  Mesh sheet;
  sheet.name = "glass";
  sheet.material = first + 2;
  add_quad(sheet, {0.8f, 0, -2}, {0, 0, 2}, {0, 3, 0});
  s.meshes.push_back(sheet);
  Mesh light;
  light.name = "light";
  light.material = black;
  light.emission = {6, 6, 6};
  add_quad(light, {0.5f, 1, -0.5f}, {0, 0.3f, 0}, {0, 0, 1});  // x = 0.5, facing +x
  s.meshes.push_back(light);
  finalize_scene(s);
  return s;
}

RenderOptions options(Strategy st, int depth, bool regularize) {
  RenderOptions o;
  o.est.strategy = st;
  o.est.max_depth = depth;
  o.est.spp = 16;
  o.est.seed = 3;
  o.est.regularize = regularize;
  o.threads = 2;
  return o;
}

std::vector<float> render_mean(const Scene& s, const RenderOptions& o) { return render_scene(s, o).film.mean(); }

double sum_of(const std::vector<float>& v) {
  double t = 0;
  for (float x : v) t += x;
  return t;
}

}  // namespace

TEST(Regularize, TwinRowsHoldTheRegularizedAlphas) {
  EXPECT_EQ(regularized_alpha(0.f), 0.1f);
  EXPECT_EQ(regularized_alpha(0.05f), 0.1f);
  EXPECT_EQ(regularized_alpha(0.08f), 0.16f);
  EXPECT_EQ(regularized_alpha(0.2f), 0.3f);
  EXPECT_EQ(regularized_alpha(0.3f), 0.3f);
  EXPECT_EQ(regularized_alpha(0.7f), 0.7f);
  const Scene s = floor_and_panels(false);
  const SceneViews v = build_views(s, LightPick::power);
  const GeomView& G = v.geom;
  const size_t n = s.materials.size() + 1;  // (and the default material)
  int twins = 0;
  for (size_t m = 0; m < n; ++m) {
    const int32_t r = G.mat_reg[m];
    const Material& mat = m < s.materials.size() ? s.materials[m] : Material{};
    const bool changes = mat.kind != MaterialKind::diffuse && mat.alpha_u.value < 0.3f;
    if (!changes) {
      EXPECT_EQ(r, static_cast<int32_t>(m)) << "material " << m;
      continue;
    }
    ++twins;
    ASSERT_GE(r, static_cast<int32_t>(n)) << "material " << m;
    EXPECT_EQ(G.mat_reg[r], r);
    EXPECT_EQ(G.mat_kind[r], G.mat_kind[m]);
    EXPECT_EQ(G.mat_param[mp_ax][r], regularized_alpha(mat.alpha_u.value));
    EXPECT_EQ(G.mat_param[mp_ay][r], regularized_alpha(mat.alpha_v.value));
    EXPECT_EQ(G.mat_param[mp_bax][r], mat.kind == MaterialKind::coated_conductor ? regularized_alpha(mat.base_alpha_u.value)
                                                                                  : G.mat_param[mp_bax][m]);
    EXPECT_EQ(G.mat_param[mp_eta][r], G.mat_param[mp_eta][m]);
    EXPECT_EQ(G.mat_param[mp_eta_r][r], G.mat_param[mp_eta_r][m]);
  }
  EXPECT_EQ(twins, 6);  // (the textured conductor's too: its constant columns)
  EXPECT_TRUE(G.has_rough_tex);
}

// Regularized, the scene renders the bits of the same scene with its alphas regularized
// by hand: every vertex after the floor's Lambert sample takes the twin rows, for every
// strategy and both pickers. Not regularized, it renders another image.
TEST(Regularize, AfterADiffuseBounceEqualsTheAlphasRegularizedByHand) {
  const Scene plain = floor_and_panels(false), by_hand = floor_and_panels(true);
  for (Strategy st : {Strategy::mis, Strategy::light, Strategy::bsdf, Strategy::ris}) {
    for (LightPick pick : {LightPick::power, LightPick::bvh}) {
      RenderOptions o = options(st, 5, true);
      o.est.pick = pick;
      const std::vector<float> reg = render_mean(plain, o);
      o.est.regularize = false;
      const std::vector<float> hand = render_mean(by_hand, o);
      ASSERT_EQ(reg.size(), hand.size());
      size_t differ = 0;
      for (size_t i = 0; i < reg.size(); ++i) differ += reg[i] != hand[i];
      EXPECT_EQ(differ, 0u) << describe(o.est) << ": " << differ << " of " << reg.size() << " values differ";
      EXPECT_GT(sum_of(reg), 0.0) << describe(o.est);
      if (st == Strategy::mis && pick == LightPick::power) {
        const std::vector<float> unreg = render_mean(plain, o);
        EXPECT_NE(sum_of(unreg), sum_of(reg)) << "regularization changed nothing";
      }
    }
  }
  // one-sample MIS too
  RenderOptions o = options(Strategy::mis, 4, true);
  o.est.mode = MisMode::one;
  EXPECT_EQ(render_mean(plain, o), [&] {
    RenderOptions h = o;
    h.est.regularize = false;
    return render_mean(by_hand, h);
  }());
}

namespace {

// A mirror floor (alpha 0) seen from above, a glossy conductor ceiling (alpha 0.05) that the
// mirror shows, and a light between them facing the ceiling.
Scene mirror_and_ceiling() {
  Scene s;
  s.source = "test:mirror-ceiling";
  s.materials.push_back(conductor(0.f));
  s.materials.push_back(conductor(0.05f));
  s.materials.push_back(diffuse_material(Rgb{0, 0, 0}));
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.6f, 0.6f}));
  Mesh floor;
  floor.name = "mirror";
  floor.material = 0;
  add_quad(floor, {-50, 0, -50}, {0, 0, 100}, {100, 0, 0});  // faces up
  s.meshes.push_back(floor);
  Mesh ceiling;
  ceiling.name = "ceiling";
  ceiling.material = 1;
  add_quad(ceiling, {-50, 3, -50}, {100, 0, 0}, {0, 0, 100});  // faces down
  s.meshes.push_back(ceiling);
  Mesh wall;
  wall.name = "wall";  // a diffuse wall beside: the paths' later vertices
  wall.material = 3;
  add_quad(wall, {-2, 0, -50}, {0, 0, 100}, {0, 3, 0});
  s.meshes.push_back(wall);
  Mesh light;
  light.name = "light";
  light.material = 2;
  light.emission = {8, 8, 8};
  add_quad(light, {-0.3f, 2.5f, -0.3f}, {0, 0, 0.6f}, {0.6f, 0, 0});  // faces up
  s.meshes.push_back(light);
  s.camera.width = s.camera.height = 16;
  s.camera.fov_deg = 40;
  camera_look_at(s.camera, {0.8f, 1, 0}, {0.8f, 0, 0}, {0, 0, 1});
  finalize_scene(s);
  return s;
}

}  // namespace

// The camera sees the mirror (a specular sample), which shows the glossy ceiling lit by
// the light: at depth 2 no path has taken a non-specular sample before the ceiling, so
// regularization changes no bit; from depth 3 on (the ceiling's glossy sample) it does.
TEST(Regularize, SpecularSamplesDoNotStartIt) {
  const Scene s = mirror_and_ceiling();
  for (Strategy st : {Strategy::mis, Strategy::ris}) {
    const std::vector<float> off2 = render_mean(s, options(st, 2, false));
    const std::vector<float> on2 = render_mean(s, options(st, 2, true));
    EXPECT_GT(sum_of(off2), 0.0);
    EXPECT_EQ(off2, on2) << "depth 2";
    const std::vector<float> off4 = render_mean(s, options(st, 4, false));
    const std::vector<float> on4 = render_mean(s, options(st, 4, true));
    EXPECT_NE(sum_of(off4), sum_of(on4)) << "depth 4";
  }
}
