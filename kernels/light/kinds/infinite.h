// The sky (LightSource "infinite"): radiance arriving from every direction at infinity,
// the table's radiance times, for a sky with an environment map, the map's texel along the
// direction (light/sky_map.h: pbrt-v4's equal-area octahedral square in the light's frame
// e1, e2, n; nearest texel). A constant sky is drawn uniformly over the sphere of
// directions (density 1 / (4 pi)); a map by its texels' distribution (pdf_uv / (4 pi)),
// the compensated one where LightGeom::sky_dist asks for it, and then a constant sky is
// left to the BSDF technique (density 0, as pbrt-v4's UniformInfiniteLight under MIS:
// cosine-weighted BSDF samples already cover it without variance from the direction).
// It has no surface that a ray can hit: a ray that leaves the scene sees it
// (wave/escaped.h, which weights it against pdf_direction). Power: what the disc of the
// scene's bounding sphere (radius r) receives from it facing it, pi r^2 times the
// irradiance pi L (L: the radiance, a map's mean texel in it), as a distant source's
// pi r^2 L: so a sky and a distant source of the same irradiance weigh the same. (pbrt-v4
// takes 4 pi * pi r^2 L, the flux into the whole sphere, four times as much: measured on
// two sun-and-sky interiors, a sky given that share starves the sun, which only light
// sampling reaches, while BSDF samples also find the sky: bench/results.md.) Under MIS
// the power picker takes only the part of the sky its light samples draw (render/views.h:
// SkyMap::compensated_share of a map, none of a constant sky). Not in the light BVH (its
// pickers give it its power's share, as a distant source's).
// Table fields: p0.x the map's index in LightView::sky_maps (-1: constant), e1, e2, n the
// light frame's x, y, z axes in the world (orthonormal). The sky's functions are out of
// line (TUILE_OUT_OF_LINE): the flattened stages call them once per batch.
#pragma once
#include "light/kinds/common.h"
#include "light/sky_map.h"
#include "sample/sampling.h"

namespace tuile {

// A direction drawn towards a light at infinity, its density in solid angle and, for a sky
// with a map, the texel it came from (-1 otherwise).
template <class T> struct SkySample {
  Vec3<T> wi;
  T pdf;
  i32_t<T> texel;
};

template <> struct LightKindOps<LightKind::infinite> {
  static constexpr LightKind kind = LightKind::infinite;
  static constexpr bool planar = false, at_infinity = true;

  // f(map, lanes) for each environment map among the lanes of skies (the lanes of a
  // constant sky take none, nor those of other kinds, whose p0.x is a point's).
  template <class T, class F> static void for_each_map(const LightGeom<T>& g, F&& f) {
    if (g.sky_map_count == 0) return;
    const auto sky = f_mask_from_i(g.type == i32_t<T>(static_cast<int32_t>(kind)));
    const auto in = sky && g.p0.x >= T(0.f) && g.p0.x < T(static_cast<float>(g.sky_map_count));
    const i32_t<T> mi = to_i32(sel(in, g.p0.x, T(-1.f)));
    for (int32_t k = 0; k < g.sky_map_count; ++k) {
      const mask_t<T> m = f_mask_from_i(mi == i32_t<T>(k));
      if (any(m)) f(g.sky_maps[k], m);
    }
  }
  // A constant sky's density: uniform, or none where the compensated distributions are asked for.
  static float constant_pdf(int dist) { return dist == sky_dist_compensated ? 0.f : inv_4pi_f; }

  // Whether the lanes of m are few enough to take one at a time (a batch has at most an
  // eighth of its lanes in the map): a sky is a few per cent of a scene's light picks, yet
  // most batches of a light stage hold one such lane, and the batch's searches gather for
  // every lane where one lane's takes a few loads. The scalar lanes run the same templates
  // at T = float: the same bits.
  template <class T> static bool few_lanes(const mask_t<T>& m) {
    if constexpr (lane_traits<T>::width == 1) return false;
    else return count(m) <= lane_traits<T>::width / 8;
  }
  // One map's direction, density and texel from u1, u2 (the light's frame e1, e2, n).
  template <class T>
  static void sample_map(const SkyMapView& map, int dist, const Vec3<T>& e1, const Vec3<T>& e2, const Vec3<T>& n, const T& u1,
                         const T& u2, Vec3<T>& wi, T& pdf, i32_t<T>& texel) {
    const SkyMapSample<T> ms = sample_sky_map(map, dist, u1, u2);
    wi = from_sky_frame(equal_area_square_to_sphere(ms.pu, ms.pv), e1, e2, n);
    pdf = ms.pdf_uv * T(inv_4pi_f);
    texel = ms.texel;
  }

  template <class T> TUILE_OUT_OF_LINE static SkySample<T> sample_direction(const LightGeom<T>& g, const T& u1, const T& u2) {
    SkySample<T> s{sample_uniform_sphere(u1, u2), T(constant_pdf(g.sky_dist)), i32_t<T>(-1)};
    for_each_map(g, [&](const SkyMapView& map, const mask_t<T>& m) {
      if constexpr (lane_traits<T>::width > 1) {
        if (few_lanes<T>(m)) {  // the lanes of m one by one, the others keep theirs
          constexpr int W = lane_traits<T>::width;
          alignas(64) float on[W], a1[W], a2[W], e[9][W], w[3][W], pdf[W];
          alignas(64) int32_t tex[W];
          store(on, sel(m, T(1.f), T(0.f)));
          store(a1, u1);
          store(a2, u2);
          const T* axes[9] = {&g.e1.x, &g.e1.y, &g.e1.z, &g.e2.x, &g.e2.y, &g.e2.z, &g.n.x, &g.n.y, &g.n.z};
          for (int c = 0; c < 9; ++c) store(e[c], *axes[c]);
          store(w[0], s.wi.x);
          store(w[1], s.wi.y);
          store(w[2], s.wi.z);
          store(pdf, s.pdf);
          store(tex, s.texel);
          for (int i = 0; i < W; ++i) {
            if (on[i] == 0.f) continue;
            Vec3<float> wi;
            sample_map<float>(map, g.sky_dist, {e[0][i], e[1][i], e[2][i]}, {e[3][i], e[4][i], e[5][i]},
                              {e[6][i], e[7][i], e[8][i]}, a1[i], a2[i], wi, pdf[i], tex[i]);
            w[0][i] = wi.x;
            w[1][i] = wi.y;
            w[2][i] = wi.z;
          }
          s.wi = {load<T>(w[0]), load<T>(w[1]), load<T>(w[2])};
          s.pdf = load<T>(pdf);
          s.texel = load_i32<T>(tex);
          return;
        }
      }
      Vec3<T> wi;
      T pdf;
      i32_t<T> texel;
      sample_map<T>(map, g.sky_dist, g.e1, g.e2, g.n, u1, u2, wi, pdf, texel);
      s.wi = sel(m, wi, s.wi);
      s.pdf = sel(m, pdf, s.pdf);
      s.texel = sel(i_mask_from_f(m), texel, s.texel);
    });
    return s;
  }
  // The texel of each map lane along the world direction wi (-1 for constant skies).
  template <class T> TUILE_OUT_OF_LINE static i32_t<T> texel_along(const LightGeom<T>& g, const Vec3<T>& wi) {
    i32_t<T> texel(-1);
    for_each_map(g, [&](const SkyMapView& map, const mask_t<T>& m) {
      T pu, pv;
      equal_area_sphere_to_square(to_sky_frame(wi, g.e1, g.e2, g.n), pu, pv);
      texel = sel(i_mask_from_f(m), sky_texel(map.res, pu, pv), texel);
    });
    return texel;
  }
  // The density sample_direction gives a direction whose texel is texel (texel_along's).
  template <class T> TUILE_OUT_OF_LINE static T pdf_of_texel(const LightGeom<T>& g, const i32_t<T>& texel) {
    T pdf(constant_pdf(g.sky_dist));
    for_each_map(g, [&](const SkyMapView& map, const mask_t<T>& m) {
      const i32_t<T> t = sel(i_mask_from_f(m), texel, i32_t<T>(0));
      pdf = sel(m, sky_map_pdf_uv<T>(map, g.sky_dist, t) * T(inv_4pi_f), pdf);
    });
    return pdf;
  }
  // The density sample_direction gives the direction wi.
  template <class T> static T pdf_direction(const LightGeom<T>& g, const Vec3<T>& wi) {
    if (g.sky_map_count == 0) return T(constant_pdf(g.sky_dist));
    return pdf_of_texel(g, texel_along(g, wi));
  }
  // The radiance (r, gr, b: the table's on entry) times the texel of the map lanes (texel
  // from sample_direction or texel_along; lanes with texel -1 keep theirs).
  template <class T> TUILE_OUT_OF_LINE static void apply_texel(const LightGeom<T>& g, const i32_t<T>& texel, T& r, T& gr, T& b) {
    for_each_map(g, [&](const SkyMapView& map, const mask_t<T>& in_map) {
      if constexpr (lane_traits<T>::width > 1) {
        if (few_lanes<T>(in_map)) {  // few lanes: three loads each instead of three gathers
          constexpr int W = lane_traits<T>::width;
          alignas(64) float on[W], c[3][W];
          alignas(64) int32_t tex[W];
          store(on, sel(in_map, T(1.f), T(0.f)));
          store(tex, texel);
          store(c[0], r);
          store(c[1], gr);
          store(c[2], b);
          for (int i = 0; i < W; ++i) {
            if (on[i] == 0.f || tex[i] < 0) continue;
            const float* t = map.texels + 4 * static_cast<size_t>(tex[i]);
            c[0][i] = c[0][i] * t[0];
            c[1][i] = c[1][i] * t[1];
            c[2][i] = c[2][i] * t[2];
          }
          r = load<T>(c[0]);
          gr = load<T>(c[1]);
          b = load<T>(c[2]);
          return;
        }
      }
      const auto mi = i_mask_from_f(in_map) && texel >= i32_t<T>(0);
      const mask_t<T> m = f_mask_from_i(mi);
      const i32_t<T> t = sel(mi, texel, i32_t<T>(0)) * i32_t<T>(4);
      r = sel(m, r * gather(map.texels, t), r);
      gr = sel(m, gr * gather(map.texels + 1, t), gr);
      b = sel(m, b * gather(map.texels + 2, t), b);
    });
  }
  // the shadow ray goes as far as a ray can: no end point to offset
  template <class T> static Vec3<T> endpoint_normal(const LightGeom<T>&, const Vec3<T>&, const Vec3<T>&) {
    return Vec3<T>(T(0.f), T(0.f), T(0.f));
  }
  // lum: the luminance of the table's radiance times the map's mean texel
  static float power(const LightShape&, float lum, float scene_radius) {
    return 3.14159265f * 3.14159265f * scene_radius * scene_radius * lum;
  }
  static bool bounds(const LightShape&, double, LightBounds&) { return false; }
};

}  // namespace tuile
