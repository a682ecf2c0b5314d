// Environment maps (light/sky_map.h, light/kinds/infinite.h, src/scene/sky_map.cpp): the
// equal-area square and its inverse, the texel distributions (chi-square against their
// pdf, the pdf integrating to 1 over the sphere, the density of a sampled direction equal
// to the density looked up for it), a floor under a rotated map against the exact integral
// of the map over its hemisphere for every estimator, the orientation of a map with one
// colour per octant against the lookup written out by hand, the file formats and the
// errors pbrt-v4 gives, and `tuile envmap`.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <array>
#include <functional>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb/stb_image_write.h>

#include "light/dispatch.h"
#include "render/render.h"
#include "chi2.h"
#include "render_util.h"
#include "scene/image_io.h"
#include "scene/pbrt.h"
#include "scene/sky_map.h"
#include "test_scale.h"
#include "wave/escaped.h"

using namespace tuile;
using namespace tuile::test;
namespace fs = std::filesystem;

namespace {

using Sky = LightKindOps<LightKind::infinite>;

fs::path scratch() {
  const fs::path d = fs::temp_directory_path() / ("tuile_test_sky_map_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

RgbImage image_of(int w, int h, const std::function<Rgb(int, int)>& f) {
  RgbImage img;
  img.width = w;
  img.height = h;
  img.rgb.resize(static_cast<size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Rgb c = f(x, y);
      float* p = &img.rgb[(static_cast<size_t>(y) * w + x) * 3];
      p[0] = c.r;
      p[1] = c.g;
      p[2] = c.b;
    }
  return img;
}

SkyMap map_of(const RgbImage& img) {
  SkyMap m;
  std::string why;
  EXPECT_TRUE(make_sky_map("test", img, m, why)) << why;
  return m;
}

// A sky's LightGeom in the identity frame reading map view (distribution dist).
LightGeom<float> sky_geom(const SkyMapView& view, int dist) {
  LightGeom<float> g;
  g.type = static_cast<int32_t>(LightKind::infinite);
  g.p0 = {0, 0, 0};
  g.e1 = {1, 0, 0};
  g.e2 = {0, 1, 0};
  g.n = {0, 0, 1};
  g.sky_maps = &view;
  g.sky_map_count = 1;
  g.sky_dist = dist;
  return g;
}

// A map with structure at every scale: a gradient, a bright blob and a dark band.
Rgb busy_texel(int x, int y, int n) {
  const float u = (x + 0.5f) / n, v = (y + 0.5f) / n;
  const float blob = std::exp(-((u - 0.3f) * (u - 0.3f) + (v - 0.6f) * (v - 0.6f)) * 200.f);
  const float band = (v > 0.1f && v < 0.2f) ? 0.f : 1.f;
  return {band * (0.2f + u) + 40.f * blob, band * (0.3f + 0.5f * v) + 20.f * blob, 0.5f * band + 5.f * blob};
}


}  // namespace

// The square maps onto unit directions and back (pbrt-v4's pair), the centre to +z and the
// corners to -z; the SIMD lanes give the scalar bits.
TEST(SkyMap, EqualAreaSquareRoundTrip) {
  const vec3f c = equal_area_square_to_sphere(0.5f, 0.5f);
  EXPECT_NEAR(c.z, 1.f, 1e-6f);
  EXPECT_NEAR(equal_area_square_to_sphere(0.f, 0.f).z, -1.f, 1e-6f);
  EXPECT_NEAR(equal_area_square_to_sphere(1.f, 0.5f).z, 0.f, 1e-6f);  // the edge midpoints are the equator
  const int n = 97;
  float us[n * n], vs[n * n];
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const float u = (i + 0.37f) / n, v = (j + 0.61f) / n;
      us[j * n + i] = u;
      vs[j * n + i] = v;
      const vec3f w = equal_area_square_to_sphere(u, v);
      ASSERT_NEAR(length(w), 1.f, 2e-6f) << u << " " << v;
      float pu, pv;
      equal_area_sphere_to_square(w, pu, pv);
      ASSERT_NEAR(pu, u, 3e-5f) << u << " " << v;
      ASSERT_NEAR(pv, v, 3e-5f) << u << " " << v;
    }
  for (int k = 0; k + simd_width <= n * n; k += simd_width) {
    const Vec3<vfloat> w = equal_area_square_to_sphere(vfloat::load_unaligned(us + k), vfloat::load_unaligned(vs + k));
    vfloat pu, pv;
    equal_area_sphere_to_square(w, pu, pv);
    for (int l = 0; l < simd_width; ++l) {
      const vec3f s = equal_area_square_to_sphere(us[k + l], vs[k + l]);
      float su, sv;
      equal_area_sphere_to_square(s, su, sv);
      ASSERT_EQ(w.x.get(l), s.x);
      ASSERT_EQ(w.y.get(l), s.y);
      ASSERT_EQ(w.z.get(l), s.z);
      ASSERT_EQ(pu.get(l), su);
      ASSERT_EQ(pv.get(l), sv);
    }
  }
}

// The search from the cut points finds the interval the whole CDF's binary search finds,
// for every u on a fine grid, at the cuts themselves (j / cuts) and one float either side,
// at each CDF value and one float either side, in the scalar reference and every SIMD
// lane: on a busy map's rows, a row with runs of empty texels (equal CDF values), a map of
// one bright texel, and maps whose rows are shorter than four (one cut).
TEST(SkyMap, CutPointsFindTheIntervalOfTheWholeSearch) {
  std::vector<SkyMap> maps;
  for (int res : {1, 2, 3, 5, 32, 64}) {
    maps.push_back(map_of(image_of(res, res, [&](int x, int y) { return busy_texel(x, y, res); })));
    maps.push_back(map_of(image_of(res, res, [&](int x, int y) {
      return (x % 7 < 3 || y == 1) ? Rgb{0, 0, 0} : Rgb{float(1 + (x * y) % 5), 1, 1};
    })));
  }
  maps.push_back(map_of(image_of(16, 16, [](int x, int y) { return x == 11 && y == 3 ? Rgb{5, 6, 7} : Rgb{0, 0, 0}; })));
  int checked = 0;
  for (const SkyMap& m : maps)
    for (int dist : {sky_dist_full, sky_dist_compensated}) {
      const SkyMapView v = sky_map_view(m);
      const SkyDistView& d = v.dist[dist];
      const int n = m.res;
      ASSERT_EQ(d.cuts, static_cast<int32_t>(std::bit_ceil(static_cast<unsigned>(std::max(n / 4, 1)))));
      for (int row = -1; row < n; ++row) {  // -1: the marginal
        const float* cdf = row < 0 ? d.marg_cdf : d.cond_cdf + row * (n + 1);
        const int32_t* cut = row < 0 ? d.marg_cut : d.cond_cut + row * (d.cuts + 1);
        std::vector<float> us;
        for (int k = 0; k < 4099; ++k) us.push_back(static_cast<float>(k) / 4099.f);
        for (int j = 0; j <= d.cuts; ++j) {
          const float t = static_cast<float>(j) / static_cast<float>(d.cuts);
          us.insert(us.end(), {t, std::nextafter(t, 0.f), std::nextafter(t, 1.f)});
        }
        for (int i = 0; i <= n; ++i) us.insert(us.end(), {cdf[i], std::nextafter(cdf[i], 0.f), std::nextafter(cdf[i], 1.f)});
        us.erase(std::remove_if(us.begin(), us.end(), [](float u) { return !(u >= 0.f && u < 1.f); }), us.end());
        while (us.size() % simd_width != 0) us.push_back(0.5f);
        for (size_t k = 0; k < us.size(); k += simd_width) {
          const vint lanes = find_interval_cut<vfloat>(cdf, vint(0), cut, vint(0), d.cuts, vfloat::load_unaligned(&us[k]));
          for (int l = 0; l < simd_width; ++l) {
            const float u = us[k + static_cast<size_t>(l)];
            const int32_t whole = find_interval<float>(cdf, n, 0, u);
            ASSERT_EQ(find_interval_cut<float>(cdf, 0, cut, 0, d.cuts, u), whole) << "res " << n << " row " << row << " u " << u;
            ASSERT_EQ(lanes.get(l), whole) << "res " << n << " row " << row << " u " << u << " lane " << l;
            ++checked;
          }
        }
      }
    }
  EXPECT_GT(checked, 1000000);
}

// The lanes of a batch that draw from a map, few (one by one through the scalar template)
// or many (the batch's gathers), in batches of one and two registers, give each lane the
// scalar reference's direction, density, texel and radiance bit for bit; lanes of a
// constant sky (no map) keep the uniform sphere's. Every count of map lanes, each lane
// with its own rotated frame, both distributions.
template <class T> void expect_sky_lanes_match_scalar(const SkyMapView& view) {
  constexpr int W = lane_traits<T>::width;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  for (int dist : {sky_dist_full, sky_dist_compensated})
    for (int lanes = 0; lanes <= W; ++lanes)
      for (int round = 0; round < 4; ++round) {
        std::vector<int> order(W);
        for (int i = 0; i < W; ++i) order[static_cast<size_t>(i)] = i;
        std::shuffle(order.begin(), order.end(), rng);
        alignas(64) float p0x[W], ax[9][W], u1[W], u2[W], lr[W], lg[W], lb[W];
        std::vector<LightGeom<float>> gs(W);
        for (int i = 0; i < W; ++i) {
          p0x[i] = -1.f;
          const float t = 6.2831853f * U(rng), c = std::cos(t), sn = std::sin(t);
          const vec3f e1{c, sn, 0}, e2{-sn * 0.6f, c * 0.6f, 0.8f}, n = cross(e1, e2);
          const vec3f axes[3] = {e1, e2, n};
          for (int a = 0; a < 3; ++a) {
            ax[3 * a][i] = axes[a].x;
            ax[3 * a + 1][i] = axes[a].y;
            ax[3 * a + 2][i] = axes[a].z;
          }
          u1[i] = U(rng);
          u2[i] = U(rng);
          lr[i] = 1.f + U(rng);
          lg[i] = 2.f + U(rng);
          lb[i] = 3.f + U(rng);
        }
        // the other lanes: a constant sky (p0.x -1) or a distant source whose p0.x falls in
        // the maps' range (it must take no map)
        alignas(64) int32_t type[W];
        for (int i = 0; i < W; ++i) {
          const bool distant = U(rng) < 0.5f;
          type[i] = static_cast<int32_t>(distant ? LightKind::distant : LightKind::infinite);
          if (distant) p0x[i] = 0.f;
        }
        for (int j = 0; j < lanes; ++j) {
          p0x[order[static_cast<size_t>(j)]] = 0.f;
          type[order[static_cast<size_t>(j)]] = static_cast<int32_t>(LightKind::infinite);
        }
        LightGeom<T> g;
        g.type = load_i32<T>(type);
        g.p0 = {load<T>(p0x), T(0.f), T(0.f)};
        g.e1 = {load<T>(ax[0]), load<T>(ax[1]), load<T>(ax[2])};
        g.e2 = {load<T>(ax[3]), load<T>(ax[4]), load<T>(ax[5])};
        g.n = {load<T>(ax[6]), load<T>(ax[7]), load<T>(ax[8])};
        g.sky_maps = &view;
        g.sky_map_count = 1;
        g.sky_dist = dist;
        const SkySample<T> s = Sky::sample_direction(g, load<T>(u1), load<T>(u2));
        T r = load<T>(lr), gr = load<T>(lg), b = load<T>(lb);
        Sky::apply_texel(g, s.texel, r, gr, b);
        alignas(64) float wx[W], wy[W], wz[W], pdf[W], cr[W], cg[W], cb[W];
        alignas(64) int32_t tex[W];
        store(wx, s.wi.x);
        store(wy, s.wi.y);
        store(wz, s.wi.z);
        store(pdf, s.pdf);
        store(tex, s.texel);
        store(cr, r);
        store(cg, gr);
        store(cb, b);
        for (int i = 0; i < W; ++i) {
          LightGeom<float> h = sky_geom(view, dist);
          h.type = type[i];
          h.p0.x = p0x[i];
          h.e1 = {ax[0][i], ax[1][i], ax[2][i]};
          h.e2 = {ax[3][i], ax[4][i], ax[5][i]};
          h.n = {ax[6][i], ax[7][i], ax[8][i]};
          const SkySample<float> q = Sky::sample_direction(h, u1[i], u2[i]);
          float qr = lr[i], qg = lg[i], qb = lb[i];
          Sky::apply_texel(h, q.texel, qr, qg, qb);
          const std::string at = "width " + std::to_string(W) + ", " + std::to_string(lanes) + " map lanes, lane " +
                                 std::to_string(i) + ", dist " + std::to_string(dist);
          ASSERT_EQ(wx[i], q.wi.x) << at;
          ASSERT_EQ(wy[i], q.wi.y) << at;
          ASSERT_EQ(wz[i], q.wi.z) << at;
          ASSERT_EQ(pdf[i], q.pdf) << at;
          ASSERT_EQ(tex[i], q.texel) << at;
          ASSERT_EQ(tex[i] >= 0, p0x[i] == 0.f && type[i] == static_cast<int32_t>(LightKind::infinite)) << at;
          ASSERT_EQ(cr[i], qr) << at;
          ASSERT_EQ(cg[i], qg) << at;
          ASSERT_EQ(cb[i], qb) << at;
        }
      }
}

TEST(SkyMap, FewAndManyMapLanesGiveTheScalarBits) {
  const int res = 32;
  const SkyMap m = map_of(image_of(res, res, [&](int x, int y) { return busy_texel(x, y, res); }));
  const SkyMapView view = sky_map_view(m);
  expect_sky_lanes_match_scalar<vfloat>(view);
  expect_sky_lanes_match_scalar<vfloat2>(view);
}

// Both distributions of a busy map: the density of directions integrates to 1 over the
// sphere (the square's points mapped to directions, the density looked up from the
// direction), a sampled direction's density equals the one looked up for it (but where
// rounding puts it on a texel edge), and a chi-square test of 200000 samples over the
// texels against their probabilities passes at 0.1% (a correct sampler fails one of the two
// with probability 2e-3; the seed is fixed).
TEST(SkyMap, DistributionsIntegrateSampleAndAgree) {
  const int res = 32;
  const SkyMap m = map_of(image_of(res, res, [&](int x, int y) { return busy_texel(x, y, res); }));
  const SkyMapView view = sky_map_view(m);
  for (int dist : {sky_dist_full, sky_dist_compensated}) {
    const LightGeom<float> g = sky_geom(view, dist);
    const int q = 4 * res;
    double integral = 0;
    for (int j = 0; j < q; ++j)
      for (int i = 0; i < q; ++i)
        integral += Sky::pdf_direction(g, equal_area_square_to_sphere((i + 0.5f) / q, (j + 0.5f) / q));
    integral *= 4 * 3.14159265358979 / (static_cast<double>(q) * q);
    EXPECT_NEAR(integral, 1.0, 1e-4) << "dist " << dist;
    std::mt19937 rng(7 + dist);
    std::uniform_real_distribution<float> U(0.f, 1.f);
    const int samples = static_cast<int>(scaled(200000u, 20000u));
    std::vector<double> obs(static_cast<size_t>(res * res), 0.0), expd(static_cast<size_t>(res * res), 0.0);
    int mismatched = 0;
    for (int s = 0; s < samples; ++s) {
      const SkySample<float> d = Sky::sample_direction(g, U(rng), U(rng));
      ASSERT_GT(d.pdf, 0.f);
      ASSERT_NEAR(length(d.wi), 1.f, 2e-6f);
      obs[static_cast<size_t>(d.texel)] += 1;
      const float looked = Sky::pdf_direction(g, d.wi);
      if (std::fabs(looked - d.pdf) > 1e-6f * d.pdf) ++mismatched;
    }
    EXPECT_LT(mismatched, samples / 1000) << "dist " << dist;
    for (int t = 0; t < res * res; ++t)
      expd[static_cast<size_t>(t)] = samples * m.weight(dist, static_cast<size_t>(t)) * m.dist[dist].inv_mean / (res * res);
    const Chi2 c = chi2_test(obs, expd);
    std::printf("[ sky map ] dist %d: chi2 %.1f dof %d p %.3g, %d of %d pdf mismatches\n", dist, c.chi2, c.dof, c.p, mismatched, samples);
    EXPECT_GT(c.p, 1e-3) << "dist " << dist;
  }
  // the compensated distribution leaves the texels below the mean to BSDF sampling
  double mean = 0;
  for (int t = 0; t < res * res; ++t) mean += m.weight(sky_dist_full, static_cast<size_t>(t));
  mean /= res * res;
  for (int t = 0; t < res * res; ++t)
    EXPECT_EQ(m.weight(sky_dist_compensated, static_cast<size_t>(t)) == 0.f, m.weight(sky_dist_full, static_cast<size_t>(t)) <= mean * (1 + 1e-6)) << t;
}

// A map of one bright texel: every sample lands in it, with the density of that texel (N^2
// / (4 pi)), under both distributions; a map of zeros is drawn uniformly (and has no power).
TEST(SkyMap, OneBrightTexelAndAllZeros) {
  const int res = 16;
  const SkyMap one = map_of(image_of(res, res, [](int x, int y) { return x == 11 && y == 3 ? Rgb{5, 6, 7} : Rgb{0, 0, 0}; }));
  const SkyMapView v1 = sky_map_view(one);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  for (int dist : {sky_dist_full, sky_dist_compensated}) {
    const LightGeom<float> g = sky_geom(v1, dist);
    for (int s = 0; s < 2000; ++s) {
      const SkySample<float> d = Sky::sample_direction(g, U(rng), U(rng));
      ASSERT_EQ(d.texel, 3 * res + 11);
      ASSERT_NEAR(d.pdf, res * res / (4 * 3.14159265f), 1e-3f);
    }
  }
  const SkyMap zero = map_of(image_of(res, res, [](int, int) { return Rgb{0, 0, 0}; }));
  EXPECT_EQ(zero.mean[0] + zero.mean[1] + zero.mean[2], 0.0);
  const SkyMapView v0 = sky_map_view(zero);
  const LightGeom<float> g = sky_geom(v0, sky_dist_full);
  for (int s = 0; s < 200; ++s) {
    const SkySample<float> d = Sky::sample_direction(g, U(rng), U(rng));
    ASSERT_NEAR(d.pdf, 1 / (4 * 3.14159265f), 1e-6f);
  }
}

namespace {

// pbrt's Rotate(angle, axis) for a unit axis, written out (Rodrigues), applied to v.
std::array<double, 3> rotate(double deg, std::array<double, 3> a, std::array<double, 3> v) {
  const double t = deg * 3.14159265358979 / 180, c = std::cos(t), s = std::sin(t);
  const double d = a[0] * v[0] + a[1] * v[1] + a[2] * v[2];
  const std::array<double, 3> x = {a[1] * v[2] - a[2] * v[1], a[2] * v[0] - a[0] * v[2], a[0] * v[1] - a[1] * v[0]};
  return {v[0] * c + x[0] * s + a[0] * d * (1 - c), v[1] * c + x[1] * s + a[1] * d * (1 - c), v[2] * c + x[2] * s + a[2] * d * (1 - c)};
}

// "Rotate 30 0 1 0" then "Rotate -90 1 0 0": world = Ry(30) Rx(-90) light, and back.
std::array<double, 3> light_to_world(std::array<double, 3> v) { return rotate(30, {0, 1, 0}, rotate(-90, {1, 0, 0}, v)); }
std::array<double, 3> world_to_light(std::array<double, 3> v) { return rotate(90, {1, 0, 0}, rotate(-30, {0, 1, 0}, v)); }
const char* sky_rotation = "AttributeBegin\nRotate 30 0 1 0\nRotate -90 1 0 0\n";

std::string floor_scene(const std::string& light) {
  return "LookAt 0 3 0  0.2 0 0.1  0 0 1\nCamera \"perspective\" \"float fov\" 30\n"
         "Film \"rgb\" \"integer xresolution\" 16 \"integer yresolution\" 16\nWorldBegin\n"
         "Material \"diffuse\" \"rgb reflectance\" [0.5 0.5 0.5]\n"
         "Shape \"trianglemesh\" \"point3 P\" [-1000 0 -1000  -1000 0 1000  1000 0 1000  1000 0 -1000] \"integer indices\" [0 1 2 0 2 3]\n" +
         light;
}

}  // namespace

// A floor (albedo 0.5, facing +y) under a busy map turned by the transform in force: its
// radiance is exactly 0.5 / pi times the integral of the map's radiance times the cosine
// over the floor's hemisphere, computed here texel by texel (64 points per texel, each
// texel's radiance over its cell: nearest lookup) with the rotation written out by hand.
// Every estimator, pick and heuristic within 4 standard errors of it (8 estimators x 3
// channels: a correct renderer fails one with probability ~1.5e-3 over seeds; fixed seeds).
TEST(SkyMap, FloorUnderARotatedMapIsTheExactIntegral) {
  const int res = 32;
  const RgbImage img = image_of(res, res, [&](int x, int y) { return busy_texel(x, y, res); });
  const fs::path dir = scratch();
  write_pfm((dir / "busy.pfm").string(), img);
  Scene s = load_pbrt_string(floor_scene(std::string(sky_rotation) + "LightSource \"infinite\" \"string filename\" \"busy.pfm\" \"float scale\" 0.7\nAttributeEnd\n"),
                             "sky.pbrt", dir.string());
  finalize_scene(s);
  ASSERT_EQ(s.lights.size(), 1u);
  ASSERT_EQ(s.sky_maps.size(), 1u);
  double E[3] = {0, 0, 0};
  const int q = 8;
  for (int y = 0; y < res; ++y)
    for (int x = 0; x < res; ++x) {
      double cs = 0;
      for (int j = 0; j < q; ++j)
        for (int i = 0; i < q; ++i) {
          const vec3f w = equal_area_square_to_sphere((x + (i + 0.5f) / q) / res, (y + (j + 0.5f) / q) / res);
          cs += std::max(0.0, light_to_world({w.x, w.y, w.z})[1]);  // the floor's normal is +y
        }
      cs *= 4 * 3.14159265358979 / (static_cast<double>(res) * res * q * q);
      const size_t t = static_cast<size_t>(y * res + x);
      E[0] += img.rgb[3 * t] * cs;
      E[1] += img.rgb[3 * t + 1] * cs;
      E[2] += img.rgb[3 * t + 2] * cs;
    }
  struct Est {
    const char* name;
    Strategy strategy;
    LightPick pick;
    Heuristic heuristic;
    MisMode mode;
  };
  const Est ests[] = {
      {"mis power", Strategy::mis, LightPick::power, Heuristic::power, MisMode::multi},
      {"mis balance", Strategy::mis, LightPick::uniform, Heuristic::balance, MisMode::multi},
      {"mis max one-sample", Strategy::mis, LightPick::uniform, Heuristic::maximum, MisMode::one},
      {"mis bvh", Strategy::mis, LightPick::bvh, Heuristic::power, MisMode::multi},
      {"light", Strategy::light, LightPick::power, Heuristic::power, MisMode::multi},
      {"light area", Strategy::light, LightPick::area, Heuristic::power, MisMode::multi},
      {"bsdf", Strategy::bsdf, LightPick::power, Heuristic::power, MisMode::multi},
      {"ris", Strategy::ris, LightPick::power, Heuristic::power, MisMode::multi},
  };
  uint32_t seed = 40;
  for (const Est& e : ests) {
    RenderOptions o;
    o.est.strategy = e.strategy;
    o.est.pick = e.pick;
    o.est.heuristic = e.heuristic;
    o.est.mode = e.mode;
    o.est.max_depth = 1;
    o.est.sampler = SamplerKind::independent;
    o.est.spp = scaled(64u, 16u);
    o.est.seed = ++seed;
    o.threads = 2;
    const RenderResult r = render_scene(s, o);
    const std::vector<float> var = r.film.variance_of_mean();
    for (int c = 0; c < 3; ++c) {
      const double want = 0.5 / 3.14159265358979 * 0.7 * E[c];
      double mean = 0, v = 0;
      for (size_t i = static_cast<size_t>(c); i < r.mean.size(); i += 3) {
        mean += r.mean[i];
        v += var[i];
      }
      const double n = static_cast<double>(r.mean.size() / 3);
      mean /= n;
      const double se = std::sqrt(v) / n;
      const double z = (mean - want) / se;
      std::printf("[ sky map floor ] %s channel %d: %.5f vs %.5f (z %.2f, se/mean %.2g)\n", e.name, c, mean, want, z, se / want);
      EXPECT_LT(std::fabs(z), 4.0) << e.name << " channel " << c << ": " << mean << " vs " << want;
    }
    EXPECT_EQ(r.stats.rejected_light + r.stats.rejected_bsdf, 0u) << e.name;
  }
  fs::remove_all(dir);
}

// A map whose texels are all the same is a constant sky: a white furnace (a sphere on a
// floor, albedo 1) under it is the map's radiance everywhere, with MIS (its compensated
// distribution: uniform) and with light sampling, within 4 standard errors.
TEST(SkyMap, ConstantMapFurnace) {
  const fs::path dir = scratch();
  write_pfm((dir / "flat.pfm").string(), image_of(8, 8, [](int, int) { return Rgb{0.4f, 0.4f, 0.4f}; }));
  Scene s = load_pbrt_string(
      "LookAt 0 2.5 -5  0 1.2 0  0 1 0\nCamera \"perspective\" \"float fov\" 60\n"
      "Film \"rgb\" \"integer xresolution\" 16 \"integer yresolution\" 16\nWorldBegin\n"
      "Material \"diffuse\" \"rgb reflectance\" [1 1 1]\n"
      "Shape \"trianglemesh\" \"point3 P\" [-100 0 -100  -100 0 100  100 0 100  100 0 -100] \"integer indices\" [0 1 2 0 2 3]\n"
      "AttributeBegin\nTranslate 0 1 0\nShape \"sphere\" \"float radius\" 1\nAttributeEnd\n"
      "LightSource \"infinite\" \"string filename\" \"flat.pfm\"\n",
      "furnace.pbrt", dir.string());
  finalize_scene(s);
  ASSERT_TRUE(s.sky_maps[0].constant);
  for (Strategy st : {Strategy::mis, Strategy::light}) {
    RenderOptions o;
    o.est.strategy = st;
    o.est.pick = LightPick::uniform;
    o.est.max_depth = 200;
    o.est.sampler = SamplerKind::independent;
    o.est.spp = scaled(64u, 16u);
    o.est.seed = 5;
    o.threads = 2;
    const RenderResult r = render_scene(s, o);
    const std::vector<float> var = r.film.variance_of_mean();
    double mean = 0, v = 0;
    for (size_t i = 0; i < r.mean.size(); ++i) {
      mean += r.mean[i];
      v += var[i];
    }
    const double n = static_cast<double>(r.mean.size());
    const double z = (mean / n - 0.4) / (std::sqrt(v) / n);
    std::printf("[ sky map furnace ] strategy %d: %.5f (z %.2f)\n", static_cast<int>(st), mean / n, z);
    EXPECT_LT(std::fabs(z), 4.0) << static_cast<int>(st);
  }
  fs::remove_all(dir);
}

// Orientation: a map with a distinct colour per octant of its frame (the octant of each
// texel's centre), turned by the scene's transform. The sky's radiance along 2000 world
// directions (the escaped-ray stage's lookup) is the colour of the octant the hand-written
// inverse rotation puts them in (directions within 0.06 of an octant's edge skipped); and
// the camera, looking at a sky alone, sees the colour of its direction's octant.
TEST(SkyMap, OctantColoursUnderTheSceneTransform) {
  const int res = 64;
  auto octant = [](double x, double y, double z) { return (x > 0 ? 1 : 0) + (y > 0 ? 2 : 0) + (z > 0 ? 4 : 0); };
  auto colour = [](int o) { return Rgb{1.f + o, 0.5f * (o + 1), 10.f - o}; };
  const RgbImage img = image_of(res, res, [&](int x, int y) {
    const vec3f w = equal_area_square_to_sphere((x + 0.5f) / res, (y + 0.5f) / res);
    return colour(octant(w.x, w.y, w.z));
  });
  const fs::path dir = scratch();
  write_pfm((dir / "octants.pfm").string(), img);
  Scene s = load_pbrt_string("LookAt 0 0 0  1 0.5 -0.4  0 1 0\nCamera \"perspective\" \"float fov\" 5\n"
                             "Film \"rgb\" \"integer xresolution\" 4 \"integer yresolution\" 4\nWorldBegin\n" +
                                 std::string(sky_rotation) + "LightSource \"infinite\" \"string filename\" \"octants.pfm\"\nAttributeEnd\n",
                             "octants.pbrt", dir.string());
  finalize_scene(s);
  const SceneViews views = build_views(s, LightPick::power);
  std::mt19937 rng(12);
  std::normal_distribution<double> N(0, 1);
  int checked = 0;
  for (int k = 0; k < 2000; ++k) {
    std::array<double, 3> d = {N(rng), N(rng), N(rng)};
    const double l = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (double& c : d) c /= l;
    const std::array<double, 3> wl = world_to_light(d);
    if (std::fabs(wl[0]) < 0.06 || std::fabs(wl[1]) < 0.06 || std::fabs(wl[2]) < 0.06) continue;
    const Rgb want = colour(octant(wl[0], wl[1], wl[2]));
    float r, g, b;
    sky_radiance<float>(views.lights, views.lights.sky_light[0], vec3f(float(d[0]), float(d[1]), float(d[2])), r, g, b);
    ASSERT_EQ(r, want.r) << d[0] << " " << d[1] << " " << d[2];
    ASSERT_EQ(g, want.g);
    ASSERT_EQ(b, want.b);
    ++checked;
  }
  EXPECT_GT(checked, 1200);
  // the camera looks along world (1, 0.5, -0.4), well inside an octant of the map's frame
  const double cl = std::sqrt(1 + 0.25 + 0.16);
  const std::array<double, 3> wl = world_to_light({1 / cl, 0.5 / cl, -0.4 / cl});
  ASSERT_GT(std::min(std::fabs(wl[0]), std::min(std::fabs(wl[1]), std::fabs(wl[2]))), 0.1);
  const Rgb want = colour(octant(wl[0], wl[1], wl[2]));
  RenderOptions o;
  o.est.spp = 4;
  const RenderResult r = render_scene(s, o);
  for (size_t i = 0; i < r.mean.size(); i += 3) {
    EXPECT_NEAR(r.mean[i], want.r, 1e-5f);
    EXPECT_NEAR(r.mean[i + 1], want.g, 1e-5f);
    EXPECT_NEAR(r.mean[i + 2], want.b, 1e-5f);
  }
  // and the hand-written frame is the one the loader took
  const std::array<double, 3> z = light_to_world({0, 0, 1});
  EXPECT_NEAR(s.lights[0].p0.x, z[0], 1e-6);
  EXPECT_NEAR(s.lights[0].p0.y, z[1], 1e-6);
  EXPECT_NEAR(s.lights[0].p0.z, z[2], 1e-6);
  fs::remove_all(dir);
}

// The formats: the same texels (all in [0.1, 0.9]) through PFM (exact), EXR (read as half:
// 1e-3), HDR (RGBE, 8 bits under the pixel's largest channel: 4e-3) and PNG (8-bit sRGB:
// 1e-2), absolute; an 8-bit PNG of one channel has no RGB.
TEST(SkyMap, FormatsReadTheSameTexels) {
  const fs::path dir = scratch();
  const RgbImage img = image_of(8, 8, [](int x, int y) { return Rgb{0.1f + 0.1f * x, 0.15f + 0.1f * y, 0.5f}; });
  write_pfm((dir / "m.pfm").string(), img);
  write_exr((dir / "m.exr").string(), 8, 8, img.rgb);
  ASSERT_TRUE(stbi_write_hdr((dir / "m.hdr").string().c_str(), 8, 8, 3, img.rgb.data()));
  write_png((dir / "m.png").string(), 8, 8, img.rgb);
  const std::pair<const char*, float> files[] = {{"m.pfm", 0.f}, {"m.exr", 1e-3f}, {"m.hdr", 4e-3f}, {"m.png", 1e-2f}};
  for (const auto& [name, tol] : files) {
    RgbImage back;
    std::string why;
    ASSERT_TRUE(read_rgb_image((dir / name).string(), back, why)) << name << ": " << why;
    ASSERT_EQ(back.width, 8);
    ASSERT_EQ(back.height, 8);
    for (size_t i = 0; i < img.rgb.size(); ++i) ASSERT_NEAR(back.rgb[i], img.rgb[i], tol) << name << " " << i;
  }
  std::vector<unsigned char> grey(64, 100);
  ASSERT_TRUE(stbi_write_png((dir / "grey.png").string().c_str(), 8, 8, 1, grey.data(), 8));
  RgbImage back;
  std::string why;
  EXPECT_FALSE(read_rgb_image((dir / "grey.png").string(), back, why));
  EXPECT_NE(why.find("R, G and B"), std::string::npos) << why;
  fs::remove_all(dir);
}

// Bad maps stop the load with an error naming the file and line, as pbrt-v4's: not square,
// a NaN texel, an infinite one, a grey PFM, a truncated PFM, a missing file, and both "L"
// and "filename".
TEST(SkyMap, BadMapsAreErrorsWithFileAndLine) {
  const fs::path dir = scratch();
  write_pfm((dir / "wide.pfm").string(), image_of(8, 4, [](int, int) { return Rgb{1, 1, 1}; }));
  write_pfm((dir / "nan.pfm").string(), image_of(4, 4, [](int x, int y) { return x == 2 && y == 1 ? Rgb{1, NAN, 1} : Rgb{1, 1, 1}; }));
  write_pfm((dir / "inf.pfm").string(), image_of(4, 4, [](int x, int) { return x == 3 ? Rgb{INFINITY, 1, 1} : Rgb{1, 1, 1}; }));
  {
    std::ofstream f(dir / "grey.pfm", std::ios::binary);
    f << "Pf\n4 4\n-1\n";
    const std::vector<float> z(16, 1.f);
    f.write(reinterpret_cast<const char*>(z.data()), 64);
    std::ofstream t(dir / "short.pfm", std::ios::binary);
    t << "PF\n4 4\n-1\n";
    t.write(reinterpret_cast<const char*>(z.data()), 64);
  }
  const std::pair<std::string, std::string> cases[] = {
      {"\"string filename\" \"wide.pfm\"", "not square"},
      {"\"string filename\" \"nan.pfm\"", "NaN"},
      {"\"string filename\" \"inf.pfm\"", "infinite"},
      {"\"string filename\" \"grey.pfm\"", "R, G and B"},
      {"\"string filename\" \"short.pfm\"", "truncated"},
      {"\"string filename\" \"missing.pfm\"", "no such file"},
      {"\"string filename\" \"wide.pfm\" \"rgb L\" [1 1 1]", "both"},
  };
  for (const auto& [params, what] : cases) {
    try {
      Scene s = load_pbrt_string(floor_scene("\nLightSource \"infinite\" " + params + "\n"), "bad.pbrt", dir.string());
      ADD_FAILURE() << params << " was accepted";
    } catch (const SceneError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("bad.pbrt:8"), std::string::npos) << m;
      EXPECT_NE(m.find(what), std::string::npos) << m;
    }
  }
  fs::remove_all(dir);
  // a map larger than the lookups index: refused before its texels are read
  RgbImage huge;
  huge.width = huge.height = sky_map_max_res + 1;
  SkyMap m;
  std::string why;
  EXPECT_FALSE(make_sky_map("huge", huge, m, why));
  EXPECT_NE(why.find("more than 16384 texels a side"), std::string::npos) << why;
  RgbImage small;
  small.width = small.height = 2;
  small.rgb.assign(12, 1.f);
  EXPECT_TRUE(make_sky_map("small", small, m, why)) << why;
}

// `tuile envmap`: a latitude-longitude map whose upper half (theta < pi / 2) is red and
// lower half blue becomes a square whose texels are red above the equator and blue below
// it (but the texels the equator crosses); a constant map stays that constant; the command
// writes the square at the input's width, and a broken input is an error, not a crash.
TEST(SkyMap, EnvmapConvertsLatitudeLongitude) {
  const RgbImage ll = image_of(64, 32, [](int, int y) { return y < 16 ? Rgb{1, 0, 0} : Rgb{0, 0, 1}; });
  const RgbImage sq = latlong_to_equal_area(ll, 32, 4);
  ASSERT_EQ(sq.width, 32);
  int checked = 0;
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      const vec3f w = equal_area_square_to_sphere((x + 0.5f) / 32, (y + 0.5f) / 32);
      if (std::fabs(w.z) < 0.15f) continue;
      const float* p = &sq.rgb[(static_cast<size_t>(y) * 32 + x) * 3];
      EXPECT_FLOAT_EQ(p[0], w.z > 0 ? 1.f : 0.f) << x << " " << y;
      EXPECT_FLOAT_EQ(p[2], w.z > 0 ? 0.f : 1.f) << x << " " << y;
      ++checked;
    }
  EXPECT_GT(checked, 600);
  const RgbImage flat = latlong_to_equal_area(image_of(16, 8, [](int, int) { return Rgb{0.25f, 0.5f, 2.f}; }), 8, 3);
  for (size_t i = 0; i < flat.rgb.size(); i += 3) {
    EXPECT_NEAR(flat.rgb[i], 0.25f, 1e-6f);
    EXPECT_NEAR(flat.rgb[i + 2], 2.f, 1e-5f);
  }
  const fs::path dir = scratch();
  write_pfm((dir / "ll.pfm").string(), ll);
  const std::string cmd = std::string(TUILE_BINARY) + " envmap " + (dir / "ll.pfm").string() + " " + (dir / "sq.exr").string() + " > /dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  int w = 0, h = 0;
  const std::vector<float> out = read_exr((dir / "sq.exr").string(), w, h);
  EXPECT_EQ(w, 64);
  EXPECT_EQ(h, 64);
  { std::ofstream bad(dir / "bad.pfm"); bad << "PF\n"; }
  const std::string cmd2 = std::string(TUILE_BINARY) + " envmap " + (dir / "bad.pfm").string() + " " + (dir / "x.exr").string() + " 2> /dev/null";
  const int rc = std::system(cmd2.c_str());
  EXPECT_TRUE(WIFEXITED(rc) && WEXITSTATUS(rc) == 1) << rc;
  fs::remove_all(dir);
}

// "illuminance" E scales a map so that its upper hemisphere (+z of its frame) gives a
// surface facing it E (pbrt-v4's normalisation); "scale" multiplies; a "portal" is named in
// a warning (the map is sampled over the whole sphere).
TEST(SkyMap, IlluminanceAndScale) {
  const fs::path dir = scratch();
  const int res = 16;
  write_pfm((dir / "busy.pfm").string(), image_of(res, res, [&](int x, int y) { return busy_texel(x, y, res); }));
  Scene a = load_pbrt_string(floor_scene("LightSource \"infinite\" \"string filename\" \"busy.pfm\" \"float illuminance\" 10\n"), "e.pbrt", dir.string());
  ASSERT_EQ(a.sky_maps.size(), 1u);
  EXPECT_NEAR(a.lights[0].radiance.g * sky_map_upper_illuminance(a.sky_maps[0]), 10.0, 1e-4);
  Scene b = load_pbrt_string(floor_scene("LightSource \"infinite\" \"string filename\" \"busy.pfm\" \"float scale\" 3 \"point3 portal\" [0 1 0  1 1 0  1 1 1  0 1 1]\n"),
                             "p.pbrt", dir.string());
  EXPECT_FLOAT_EQ(b.lights[0].radiance.r, 3.f);
  bool named = false;
  for (const std::string& w : b.warnings) named = named || (w.find("p.pbrt:7") != std::string::npos && w.find("portal") != std::string::npos);
  EXPECT_TRUE(named);
  // the illuminance of a constant map of 1 over the hemisphere is pi
  SkyMap flat = map_of(image_of(64, 64, [](int, int) { return Rgb{1, 1, 1}; }));
  EXPECT_NEAR(sky_map_upper_illuminance(flat), 3.14159265, 1e-2);  // texel centres: 0.1% off at 64 x 64
  fs::remove_all(dir);
}

// The same bits whatever the threads and the tile size (which change the lanes' order and
// the packets' make-up), for paths under a map beside a sun, with MIS (compensated) and
// RIS, and the sphere lit through its bounces.
TEST(SkyMap, BitsAcrossThreadsAndTiles) {
  const fs::path dir = scratch();
  const int res = 16;
  write_pfm((dir / "busy.pfm").string(), image_of(res, res, [&](int x, int y) { return busy_texel(x, y, res); }));
  Scene s = load_pbrt_string(
      "LookAt 0 2.5 -5  0 1.2 0  0 1 0\nCamera \"perspective\" \"float fov\" 60\n"
      "Film \"rgb\" \"integer xresolution\" 24 \"integer yresolution\" 20\nWorldBegin\n"
      "Material \"diffuse\" \"rgb reflectance\" [0.6 0.5 0.4]\n"
      "Shape \"trianglemesh\" \"point3 P\" [-100 0 -100  -100 0 100  100 0 100  100 0 -100] \"integer indices\" [0 1 2 0 2 3]\n"
      "Material \"conductor\" \"float roughness\" 0.2\n"
      "AttributeBegin\nTranslate 0 1 0\nShape \"sphere\" \"float radius\" 1\nAttributeEnd\n"
      "LightSource \"distant\" \"point3 from\" [1 3 -1] \"point3 to\" [0 0 0] \"rgb L\" [2 2 2]\n" +
          std::string(sky_rotation) + "LightSource \"infinite\" \"string filename\" \"busy.pfm\"\nAttributeEnd\n",
      "bits.pbrt", dir.string());
  finalize_scene(s);
  for (Strategy st : {Strategy::mis, Strategy::ris}) {
    RenderOptions o;
    o.est.strategy = st;
    o.est.max_depth = 4;
    o.est.spp = 4;
    o.threads = 1;
    o.tile = 16;
    const std::vector<float> ref = render_scene(s, o).mean;
    for (const auto& [threads, tile] : {std::pair{2, 16}, std::pair{2, 8}, std::pair{1, 7}}) {
      RenderOptions x = o;
      x.threads = threads;
      x.tile = tile;
      const std::vector<float> m = render_scene(s, x).mean;
      ASSERT_EQ(m.size(), ref.size());
      EXPECT_EQ(std::memcmp(m.data(), ref.data(), m.size() * sizeof(float)), 0)
          << "strategy " << static_cast<int>(st) << " threads " << threads << " tile " << tile;
    }
  }
  fs::remove_all(dir);
}

// The power picker's weight of a sky (light/kinds/infinite.h, render/views.h): pi r^2 times
// its irradiance pi L (a quarter of pbrt-v4's power), as a distant source weighs pi r^2 E;
// and under MIS, where its light samples come from the compensated distribution, only the
// map's part above its mean (SkyMap::compensated_share), none of a constant sky (left to the
// BSDF technique there). Weights against a distant source's, from the pick table.
TEST(SkyMap, PowerPickerWeighsTheSkyByWhatItsLightSamplesDraw) {
  const int res = 32;
  const RgbImage img = image_of(res, res, [&](int x, int y) {  // a bright quarter on a dim rest
    return x < res / 2 && y < res / 2 ? Rgb{8.f, 8.f, 8.f} : Rgb{1.f, 1.f, 1.f};
  });
  const fs::path dir = scratch();
  write_pfm((dir / "quarter.pfm").string(), img);
  const std::string head = "LookAt 0 0 0  0 0 1  0 1 0\nCamera \"perspective\"\nFilm \"rgb\" \"integer xresolution\" 4 "
                           "\"integer yresolution\" 4\nWorldBegin\nLightSource \"distant\" \"rgb L\" [2 2 2]\n";
  const double pi = 3.14159265358979;
  // the sky's pick over the distant source's, and pi L_sky / E_sun from the scene's radiances
  // (the map's mean texel in L_sky): what the two weights' ratio must be before compensation
  auto ratios = [&](const Scene& s, bool compensated, double& want) {
    const SceneViews v = build_views(s, LightPick::power, compensated);
    int sky = -1, sun = -1;
    for (int i = 0; i < v.lights.count; ++i) (is_sky(static_cast<LightKind>(v.lights.type[i])) ? sky : sun) = i;
    EXPECT_GE(sky, 0);
    EXPECT_GE(sun, 0);
    const Light& ls = s.lights[static_cast<size_t>(sky)];
    double L = luminance(ls.radiance);
    if (ls.sky_map >= 0) {
      const double* m = s.sky_maps[static_cast<size_t>(ls.sky_map)].mean;
      L = luminance(Rgb{ls.radiance.r * float(m[0]), ls.radiance.g * float(m[1]), ls.radiance.b * float(m[2])});
    }
    want = pi * L / luminance(s.lights[static_cast<size_t>(sun)].radiance);
    return static_cast<double>(v.lights.pick_pdf[sky]) / static_cast<double>(v.lights.pick_pdf[sun]);
  };
  double want = 0;
  {
    Scene s = load_pbrt_string(head + "LightSource \"infinite\" \"string filename\" \"quarter.pfm\"\n", "quarter.pbrt",
                               dir.string());
    finalize_scene(s);
    const double mean = 0.25 * 8 + 0.75 * 1, above = 0.25 * (8 - mean);
    ASSERT_EQ(s.sky_maps.size(), 1u);
    EXPECT_NEAR(s.sky_maps[0].compensated_share, above / mean, 1e-6);
    // pi^2 r^2 L against pi r^2 E: pbrt-v4's weight would be four times this
    const double full = ratios(s, false, want);
    EXPECT_GT(want, 0);
    EXPECT_NEAR(full, want, 1e-4 * want);
    EXPECT_NEAR(ratios(s, true, want), want * above / mean, 1e-4 * want);
  }
  {
    Scene s = load_pbrt_string(head + "LightSource \"infinite\" \"rgb L\" [3 3 3]\n", "constant.pbrt", dir.string());
    finalize_scene(s);
    const double full = ratios(s, false, want);
    EXPECT_GT(want, 0);
    EXPECT_NEAR(full, want, 1e-4 * want);
    EXPECT_EQ(ratios(s, true, want), 0.0);
  }
}
