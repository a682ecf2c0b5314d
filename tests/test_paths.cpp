// Paths (Estimator::max_depth > 1): next-event estimation and MIS at every vertex, the
// continuation along a BSDF sample, Russian roulette, delta chains. Checked against
// exact answers where they exist (white furnaces, a slab of glass, a floor lit through a
// mirror), against each other where they do not (every strategy, with and without
// Russian roulette, must estimate the same image), and bit for bit across threads, tile
// sizes and pipelines. Statistical comparisons use independent random numbers (honest
// per-pixel variances) and |z| < 5 over sums of many pixels (close to normal): a correct
// renderer fails one comparison with probability ~6e-7.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "bsdf/conductor.h"
#include "render/views.h"
#include "render_util.h"
#include "wave/generate.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// A closed cube [-1, 1]^3 whose six faces emit E towards the inside and reflect with
// material 0; the camera at the centre.
Scene furnace(const Material& wall, float E, int res = 16) {
  Scene s;
  s.source = "test:furnace";
  s.materials.push_back(wall);
  const vec3f faces[6][3] = {{{-1, -1, -1}, {0, 2, 0}, {0, 0, 2}}, {{1, -1, -1}, {0, 0, 2}, {0, 2, 0}},
                             {{-1, -1, -1}, {0, 0, 2}, {2, 0, 0}}, {{-1, 1, -1}, {2, 0, 0}, {0, 0, 2}},
                             {{-1, -1, -1}, {2, 0, 0}, {0, 2, 0}}, {{-1, -1, 1}, {0, 2, 0}, {2, 0, 0}}};
  for (const auto& f : faces) {
    Mesh m;
    m.name = "wall";
    m.material = 0;
    m.emission = {E, E, E};
    add_quad(m, f[0], f[1], f[2]);  // cross(e1, e2) points inside: the emitting side
    s.meshes.push_back(m);
  }
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 70;
  camera_look_at(s.camera, {0, 0, 0}, {0.3f, -0.2f, 1}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

RenderOptions path_options(int depth, Strategy st = Strategy::mis, uint32_t spp = 64) {
  RenderOptions o;
  o.est.max_depth = depth;
  o.est.strategy = st;
  o.est.sampler = SamplerKind::independent;
  o.est.spp = spp;
  o.est.seed = 11;
  o.threads = 2;
  return o;
}

// The sum of the image's pixel means (all channels) and its standard error.
struct ImageSum {
  double sum = 0, se = 0;
  size_t values = 0;
};
ImageSum image_sum(const Film& f) {
  const std::vector<float> m = f.mean(), v = f.variance_of_mean();
  ImageSum s;
  double var = 0;
  for (size_t i = 0; i < m.size(); ++i) {
    s.sum += m[i];
    var += v[i];
  }
  s.se = std::sqrt(var);
  s.values = m.size();
  return s;
}

Film render_film(const Scene& s, const RenderOptions& o, RenderStats* stats = nullptr) {
  Accel accel(s);
  Renderer r(s, accel, o);
  Film f;
  f.reset(s.camera.width, s.camera.height);
  const RenderStats st = r.render(f, 0, o.est.spp);
  if (stats) *stats = st;
  return f;
}

Material conductor(float alpha) {
  Material m;
  m.kind = MaterialKind::conductor;
  m.eta_rgb = {1, 1, 1};
  m.k_rgb = {1e4f, 1e4f, 1e4f};  // F = k^2 / ((1 + eta)^2 + k^2) at normal incidence: 1 - 4e-8
  m.alpha_u.value = m.alpha_v.value = alpha;
  return m;
}

}  // namespace

// BSDF sampling in a diffuse furnace: every sample of every pixel is exactly the camera-
// visible E plus a^k E from each of N bounces (cosine sampling's weight is the albedo, and
// every ray hits an emitting wall), so every pixel is E (1 - a^(N+1)) / (1 - a) up to
// float rounding. Russian roulette is off (it would add noise, not bias).
TEST(Paths, DiffuseFurnaceIsExactWithBsdfSampling) {
  const float a = 0.5f, E = 0.8f;
  const Scene s = furnace(diffuse_material(Rgb{a, a, a}), E);
  for (int N : {1, 2, 3, 6, 12}) {
    RenderOptions o = path_options(N, Strategy::bsdf, 4);
    o.est.rr_depth = 1000;
    RenderStats st;
    const Film f = render_film(s, o, &st);
    const std::vector<float> m = f.mean();
    const double want = E * (1 - std::pow(a, N + 1)) / (1 - a);
    size_t off = 0;
    for (size_t i = 0; i < m.size(); ++i)
      if (std::abs(m[i] - want) > 1e-5 * want) ++off;
    // a ray may slip through an edge between two walls (Embree's non-robust mode): a few
    // samples of a few pixels; nothing else may differ
    EXPECT_LE(off, m.size() / 100) << "depth " << N << ": " << off << " values differ from " << want;
    const ImageSum is = image_sum(f);
    EXPECT_NEAR(is.sum / static_cast<double>(is.values), want, 2e-3 * want) << "depth " << N;
    EXPECT_EQ(st.rejected_bsdf + st.rejected_camera + st.rejected_light, 0u);
    // every path that stays inside reaches vertex N
    EXPECT_GE(static_cast<double>(st.path_vertices), 0.99 * (N - 1) * static_cast<double>(st.samples)) << "depth " << N;
  }
}

// The same furnace with next-event estimation and MIS (every strategy), Russian roulette
// at its default threshold, and with MIS at pbrt-v4's (1) and a higher one (4): E (1 -
// a^(N+1)) / (1 - a) at depth N, and E / (1 - a) when the depth is large enough that only
// Russian roulette ends the paths. A lower threshold ends fewer paths: more vertices per
// path (about 5.4 at 0.25 against 3.5 at 1 here, where a path's throughput falls by 0.6
// per vertex).
TEST(Paths, DiffuseFurnaceEveryStrategyWithRussianRoulette) {
  const float a = 0.6f, E = 1.f;
  const Scene s = furnace(diffuse_material(Rgb{a, a, a}), E);
  std::map<float, double> per_path_mis;
  for (Strategy st : {Strategy::mis, Strategy::light, Strategy::bsdf, Strategy::ris})
    for (float t : {Estimator{}.rr_threshold, 1.f, 4.f})
    for (int N : {3, 1000}) {
      if (st != Strategy::mis && t != Estimator{}.rr_threshold) continue;
      RenderOptions o = path_options(N, st, 64);
      o.est.rr_threshold = t;
      RenderStats stats;
      const Film f = render_film(s, o, &stats);
      const ImageSum is = image_sum(f);
      const double want = E * (N > 100 ? 1 / (1 - a) : (1 - std::pow(a, N + 1)) / (1 - a)) * static_cast<double>(is.values);
      // (a BSDF-sampled furnace whose paths never fall below the threshold before the depth
      // has no noise at all: then the sum is exact up to rounding)
      const double dev = std::abs(is.sum - want);
      EXPECT_LT(is.se > 0 ? dev / is.se : dev / (1e-6 * want), 5.0)
          << describe(o.est) << ": " << is.sum / is.values << " vs " << want / is.values << " (se " << is.se / is.values << ")";
      if (N > 100) {  // Russian roulette ended every path long before the depth
        const double per_path = 1.0 + static_cast<double>(stats.path_vertices) / static_cast<double>(stats.samples);
        EXPECT_LT(per_path, 20.0);
        if (st == Strategy::mis) per_path_mis[t] = per_path;
      }
    }
  ASSERT_EQ(per_path_mis.size(), 3u);
  EXPECT_GT(per_path_mis[0.25f], per_path_mis[1.f] + 1.0);
  EXPECT_GT(per_path_mis[1.f], per_path_mis[4.f] + 0.5);
}

// A furnace of smooth mirrors (F = 1 - 4e-8): every path is a delta chain of weight 1, so
// every pixel is E (N + 1) at depth N whatever the strategy; Russian roulette (by pbrt-v4's
// rule) leaves throughput 1 alone. A rough conductor of F = 1 loses what single-scattering
// microfacets lose (shadowing and masking, more at grazing angles): its image must equal
// an independent simulation of the same furnace (random walks in the cube, analytic ray-
// wall intersections, the scalar BSDF's own samples) and stay below E (N + 1).
TEST(Paths, ConductorFurnace) {
  const float E = 0.5f;
  {
    const Scene s = furnace(conductor(0.f), E);
    for (int N : {1, 4, 20})
      for (Strategy st : {Strategy::mis, Strategy::light}) {
        const Film f = render_film(s, path_options(N, st, 2));
        const std::vector<float> m = f.mean();
        size_t off = 0;
        for (float v : m) off += std::abs(v - E * (N + 1)) > 1e-4f * E * (N + 1);
        EXPECT_LE(off, m.size() / 100) << "depth " << N;
      }
  }
  const float alpha = 0.3f;
  const Scene s = furnace(conductor(alpha), E);
  const int N = 5;
  const SceneViews views = build_views(s, LightPick::power);
  // the simulation: camera rays through uniform points of uniform pixels
  const ConductorBsdf<float> bsdf{alpha, alpha, {1, 1, 1}, {1e4f, 1e4f, 1e4f}};
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  const int paths = 400000;
  double sum = 0, sum2 = 0;
  for (int n = 0; n < paths; ++n) {
    Vec3<float> o, d;
    camera_ray(views.camera, U(rng) * static_cast<float>(s.camera.width), U(rng) * static_cast<float>(s.camera.height), o, d);
    d = normalize(d);
    double L = 0, beta = 1;
    for (int k = 0;; ++k) {
      float t = INFINITY;
      int axis = 0;
      const float dc[3] = {d.x, d.y, d.z}, oc[3] = {o.x, o.y, o.z};
      for (int a = 0; a < 3; ++a)
        if (dc[a] != 0.f) {
          const float ta = ((dc[a] > 0 ? 1.f : -1.f) - oc[a]) / dc[a];
          if (ta < t) {
            t = ta;
            axis = a;
          }
        }
      L += beta * E;  // every wall emits E towards the inside
      if (k == N) break;
      Vec3<float> nrm{0, 0, 0};
      (axis == 0 ? nrm.x : axis == 1 ? nrm.y : nrm.z) = dc[axis] > 0 ? -1.f : 1.f;
      Vec3<float> tx, ty;
      make_basis(nrm, tx, ty);
      const Vec3<float> wo_w = Vec3<float>(0.f, 0.f, 0.f) - d;
      const Vec3<float> wo{dot(wo_w, tx), dot(wo_w, ty), dot(wo_w, nrm)};
      const BsdfSample<float> bs = bsdf.sample(wo, U(rng), U(rng), U(rng));
      if (!bs.valid) break;
      beta *= bs.weight.r;
      o = o + d * t;
      d = normalize(tx * bs.wi.x + ty * bs.wi.y + nrm * bs.wi.z);
    }
    sum += L;
    sum2 += L * L;
  }
  const double sim = sum / paths, sim_se = std::sqrt((sum2 / paths - sim * sim) / paths);
  for (Strategy st : {Strategy::mis, Strategy::light, Strategy::bsdf, Strategy::ris}) {
    const Film f = render_film(s, path_options(N, st, 64));
    const ImageSum is = image_sum(f);
    const double mean = is.sum / static_cast<double>(is.values), se = is.se / static_cast<double>(is.values);
    EXPECT_LT(std::abs(mean - sim) / std::sqrt(se * se + sim_se * sim_se), 5.0)
        << describe(path_options(N, st).est) << ": " << mean << " vs simulated " << sim;
    EXPECT_LT(mean, E * (N + 1) + 5 * se);
  }
  EXPECT_LT(sim, 0.97 * E * (N + 1));  // the loss is there (and the simulation sees it too)
}

// Delta chains through glass: a slab of glass (eta 1.5, smooth) in front of a light that
// fills the view, seen at normal incidence (a 2 degree field). Through the slab's two
// faces the light arrives as L (1 - R)^2 at depth 2 (enter, leave), and with the internal
// reflections of a deep path as L (1 - R)^2 sum R^(2k) = L (1 - R) / (1 + R) (the 1/eta^2
// of entering and the eta^2 of leaving cancel). Depth 1 sees nothing: the first vertex's
// BSDF ray reaches the slab's far face, not the light.
TEST(Paths, LightThroughGlassSlab) {
  Scene s;
  s.source = "test:slab";
  s.materials.push_back(glass_material());
  s.materials.push_back(diffuse_material(Rgb{0, 0, 0}));
  Mesh slab;
  slab.name = "slab";
  slab.material = 0;
  // a closed box x, y in [-10, 10], z in [-0.1, 0.1], outward normals
  const float h = 10, t = 0.1f;
  add_quad(slab, {-h, -h, t}, {2 * h, 0, 0}, {0, 2 * h, 0});           // +z
  add_quad(slab, {-h, -h, -t}, {0, 2 * h, 0}, {2 * h, 0, 0});          // -z
  add_quad(slab, {-h, -h, -t}, {0, 0, 2 * t}, {0, 2 * h, 0});          // -x
  add_quad(slab, {h, -h, -t}, {0, 2 * h, 0}, {0, 0, 2 * t});           // +x
  add_quad(slab, {-h, -h, -t}, {2 * h, 0, 0}, {0, 0, 2 * t});          // -y
  add_quad(slab, {-h, h, -t}, {0, 0, 2 * t}, {2 * h, 0, 0});           // +y
  s.meshes.push_back(slab);
  Mesh light;
  light.name = "light";
  light.material = 1;
  light.emission = {2, 2, 2};
  add_quad(light, {-50, -50, -2}, {100, 0, 0}, {0, 100, 0});  // faces +z, towards the camera
  s.meshes.push_back(light);
  s.camera.width = s.camera.height = 16;
  s.camera.fov_deg = 2;
  camera_look_at(s.camera, {0, 0, 5}, {0, 0, 0}, {0, 1, 0});
  finalize_scene(s);
  const double R = 0.04;  // ((1.5 - 1) / (1.5 + 1))^2; within 1e-6 of it over the field
  const struct {
    int depth;
    double want;
  } cases[] = {{1, 0.0}, {2, 2 * (1 - R) * (1 - R)}, {40, 2 * (1 - R) / (1 + R)}};
  for (const auto& c : cases)
    for (Strategy st : {Strategy::mis, Strategy::light, Strategy::bsdf, Strategy::ris}) {
      // the knob's samples (at least 32 per pixel): the z-test's standard error is the samples'
      RenderOptions o = path_options(c.depth, st, scaled(256u, 32u));
      const Film f = render_film(s, o);
      const ImageSum is = image_sum(f);
      const double mean = is.sum / static_cast<double>(is.values);
      if (c.want == 0) {
        EXPECT_EQ(mean, 0.0) << describe(o.est);
        continue;
      }
      EXPECT_LT(std::abs(is.sum - c.want * static_cast<double>(is.values)) / is.se, 5.0)
          << describe(o.est) << ": " << mean << " vs " << c.want;
    }
}

// A delta chain ending at a mirror: a diffuse floor lit only through a vertical mirror
// (F = 1) by a source that faces the mirror, away from the floor the camera sees. At depth
// 2 the floor's radiance is rho / pi times the irradiance of the source's mirror image
// (Lambert's polygon formula), found only by BSDF sampling: floor -> mirror -> source.
TEST(Paths, FloorLitThroughMirror) {
  PlaneScene p = plane_scene({-1, 1.5f, 0}, 50, 16, 0.5f);
  Scene& s = p.scene;
  s.materials.push_back(conductor(0.f));
  s.materials.push_back(diffuse_material(Rgb{0, 0, 0}));
  Mesh mirror;
  mirror.name = "mirror";
  mirror.material = 1;
  add_quad(mirror, {1, 0, -100}, {0, 0, 200}, {0, 10, 0});  // x = 1, facing -x
  s.meshes.push_back(mirror);
  Mesh light;
  light.name = "light";
  light.material = 2;
  light.emission = {3, 3, 3};
  add_quad(light, {0.5f, 1, -0.3f}, {0, 0.2f, 0}, {0, 0, 0.6f});  // x = 0.5, facing +x (the mirror)
  s.meshes.push_back(light);
  // its mirror image in x = 1 (the exact answer's source; not in the scene)
  p.sources.push_back({{{1.5f, 1, -0.3f}, {1.5f, 1.2f, -0.3f}, {1.5f, 1.2f, 0.3f}, {1.5f, 1, 0.3f}}, 3.f});
  finalize_scene(s);
  const std::vector<double> exact = exact_image(p);
  for (Strategy st : {Strategy::mis, Strategy::bsdf, Strategy::ris}) {
    RenderOptions o = path_options(2, st, 1024);
    const Film f = render_film(s, o);
    const std::vector<float> m = f.mean(), v = f.variance_of_mean();
    const int W = s.camera.width, B = 4;
    double total = 0;
    for (int by = 0; by < W; by += B)
      for (int bx = 0; bx < W; bx += B) {
        double a = 0, want = 0, var = 0;
        for (int y = by; y < by + B; ++y)
          for (int x = bx; x < bx + B; ++x)
            for (int c = 0; c < 3; ++c) {
              const size_t i = 3 * (static_cast<size_t>(y) * W + x) + c;
              a += m[i];
              var += v[i];
              want += exact[i / 3];
            }
        total += want;
        EXPECT_LT(std::abs(a - want) / std::sqrt(var), 5.0) << describe(o.est) << " block " << bx << "," << by << ": " << a
                                                            << " vs " << want;
      }
    EXPECT_GT(total, 0.0);
    // depth 1 cannot see it
    const Film f1 = render_film(s, path_options(1, st, 16));
    EXPECT_EQ(image_sum(f1).sum, 0.0);
  }
}

namespace {

// A closed room (diffuse walls of three colours, a rough conductor floor, a coated block
// that shadows part of it) lit by a small ceiling light: occlusion, glossy surfaces and
// paths of several bounces.
Scene glossy_room(int res) {
  Scene s;
  s.source = "test:glossy-room";
  s.materials.push_back(diffuse_material(Rgb{0.7f, 0.7f, 0.7f}));
  s.materials.push_back(diffuse_material(Rgb{0.7f, 0.2f, 0.2f}));
  s.materials.push_back(diffuse_material(Rgb{0.2f, 0.7f, 0.2f}));
  s.materials.push_back(conductor(0.25f));
  s.materials.back().eta_rgb = {0.2f, 0.9f, 1.1f};
  s.materials.back().k_rgb = {3.9f, 2.4f, 2.1f};
  Material coat;
  coat.kind = MaterialKind::coated_diffuse;
  coat.reflectance = {0.6f, 0.5f, 0.3f};
  coat.alpha_u.value = coat.alpha_v.value = 0.2f;
  s.materials.push_back(coat);
  auto wall = [&](int mat, vec3f p0, vec3f e1, vec3f e2) {
    Mesh m;
    m.name = "wall";
    m.material = mat;
    add_quad(m, p0, e1, e2);
    s.meshes.push_back(m);
  };
  wall(3, {-1, 0, -1}, {0, 0, 2}, {2, 0, 0});   // floor (y = 0)
  wall(0, {-1, 2, -1}, {2, 0, 0}, {0, 0, 2});   // ceiling
  wall(1, {-1, 0, -1}, {0, 2, 0}, {0, 0, 2});   // left
  wall(2, {1, 0, -1}, {0, 0, 2}, {0, 2, 0});    // right
  wall(0, {-1, 0, -1}, {2, 0, 0}, {0, 2, 0});   // back
  wall(0, {-1, 0, 1}, {0, 2, 0}, {2, 0, 0});    // front (behind the camera)
  // a block on the floor
  wall(4, {-0.5f, 0.8f, -0.4f}, {0, 0, 0.6f}, {0.6f, 0, 0});  // its top
  wall(4, {-0.5f, 0, 0.2f}, {0, 0.8f, 0}, {0.6f, 0, 0});      // its front
  Mesh light;
  light.name = "light";
  light.material = 0;
  light.emission = {12, 10, 8};
  add_quad(light, {-0.25f, 1.99f, -0.25f}, {0.5f, 0, 0}, {0, 0, 0.5f});  // faces down
  s.meshes.push_back(light);
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 60;
  camera_look_at(s.camera, {0, 1, 0.95f}, {0, 0.7f, -1}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

struct Image {
  std::string name;
  std::vector<float> mean, var;
};
Image render_image(const Scene& s, const RenderOptions& o) {
  const Film f = render_film(s, o);
  return {describe(o.est), f.mean(), f.variance_of_mean()};
}

// Per 8x8 block (all channels) and per channel over the image: |z| < 5.
void expect_same_image(const Image& ref, const Image& o, int W) {
  const int B = 8;
  double ca[3] = {}, cb[3] = {}, cv[3] = {};
  for (int by = 0; by < W; by += B)
    for (int bx = 0; bx < W; bx += B) {
      double a = 0, b = 0, v = 0;
      for (int y = by; y < by + B; ++y)
        for (int x = bx; x < bx + B; ++x)
          for (int c = 0; c < 3; ++c) {
            const size_t i = 3 * (static_cast<size_t>(y) * W + x) + c;
            a += ref.mean[i];
            b += o.mean[i];
            v += ref.var[i] + o.var[i];
            ca[c] += ref.mean[i];
            cb[c] += o.mean[i];
            cv[c] += ref.var[i] + o.var[i];
          }
      EXPECT_LT(std::abs(b - a) / std::sqrt(v), 5.0) << o.name << " block " << bx << "," << by << ": " << b << " vs " << a;
    }
  for (int c = 0; c < 3; ++c)
    EXPECT_LT(std::abs(cb[c] - ca[c]) / std::sqrt(cv[c]), 5.0) << o.name << " channel " << c << ": " << cb[c] << " vs " << ca[c];
}

}  // namespace

// MIS at every vertex: light sampling alone, BSDF sampling alone, MIS (balance, power,
// one-sample, 2 light + 2 BSDF samples, the light BVH with MIS and with RIS) and MIS without Russian roulette estimate the same
// image at depth 4, where most of the light has bounced at least twice. A bias in the
// emitter-hit weights past the first vertex, a continuation counted twice or a Russian
// roulette that does not reweight fails it.
TEST(Paths, EveryStrategyAndRussianRouletteEstimateTheSameImage) {
  const int W = 24;
  const Scene s = glossy_room(W);
  // (the |z| < 5 of expect_same_image comes from these samples' own variance: the sanitizer
  // tree's TUILE_TEST_SCALE draws fewer of them)
  RenderOptions base = path_options(4, Strategy::mis, scaled(512u));
  base.est.heuristic = Heuristic::balance;
  const Image ref = render_image(s, base);
  double total = 0;
  for (float v : ref.mean) total += v;
  ASSERT_GT(total, 0.0);
  // depth 4 adds visibly to depth 1 (indirect light): the comparison is about paths
  RenderOptions direct = base;
  direct.est.max_depth = 1;
  const Image d1 = render_image(s, direct);
  double total1 = 0;
  for (float v : d1.mean) total1 += v;
  EXPECT_GT(total, 1.3 * total1);
  std::vector<RenderOptions> others;
  for (Strategy st : {Strategy::light, Strategy::bsdf}) {
    RenderOptions o = base;
    o.est.strategy = st;
    others.push_back(o);
  }
  RenderOptions o = base;
  o.est.heuristic = Heuristic::power;
  others.push_back(o);
  o = base;
  o.est.mode = MisMode::one;
  others.push_back(o);
  o = base;
  o.est.light_samples = 2;
  o.est.bsdf_samples = 2;
  o.est.spp = scaled(256u);
  others.push_back(o);
  // many lights (#19): the light BVH's picks, with MIS and with resampled importance
  // sampling (8 light and 1 BSDF candidates) at every vertex
  o = base;
  o.est.pick = LightPick::bvh;
  others.push_back(o);
  o.est.strategy = Strategy::ris;
  others.push_back(o);
  o = base;
  o.est.rr_depth = 1000;  // no Russian roulette
  o.est.seed = 12;
  others.push_back(o);
  for (const RenderOptions& x : others) expect_same_image(ref, render_image(s, x), W);
}

// The same bits whatever the threads, the tile size (which changes the lanes' order and the
// packets' make-up) and the pipeline (the specialised one against the general reference).
TEST(Paths, DeterministicAcrossThreadsTilesAndPipelines) {
  const Scene s = glossy_room(40);
  RenderOptions o = path_options(6, Strategy::mis, 8);
  o.est.sampler = SamplerKind::sobol;
  o.threads = 1;
  o.tile = 16;
  const std::vector<float> ref = render_film(s, o).mean();
  auto variant = [&](int threads, int tile, bool general) {
    RenderOptions x = o;
    x.threads = threads;
    x.tile = tile;
    x.general_pipeline = general;
    const std::vector<float> m = render_film(s, x).mean();
    ASSERT_EQ(m.size(), ref.size());
    EXPECT_EQ(std::memcmp(m.data(), ref.data(), m.size() * sizeof(float)), 0)
        << "threads " << threads << " tile " << tile << (general ? " general" : "");
  };
  variant(2, 16, false);
  variant(2, 32, false);
  variant(1, 7, false);
  variant(2, 16, true);
  // the diffuse room's pipeline too (no materials: the diffuse stages)
  const Scene d = furnace(diffuse_material(Rgb{0.5f, 0.6f, 0.7f}), 1.f, 24);
  const std::vector<float> a = render_film(d, o).mean();
  RenderOptions x = o;
  x.threads = 2;
  x.tile = 8;
  const std::vector<float> b = render_film(d, x).mean();
  x.general_pipeline = true;
  const std::vector<float> c = render_film(d, x).mean();
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(a.data(), c.data(), a.size() * sizeof(float)), 0);
}
