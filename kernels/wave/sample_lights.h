// Stage 3, sample lights: one light sample per shading point for pass j.
// Reads the shading points, the light table and two dimension pairs of the sampler;
// writes the shadow packets (Embree's RTCRay16 layout) and each lane's contribution if
// the shadow ray turns out unoccluded. Lanes are independent; masks, not branches.
// Estimator (Veach's thesis eq. 9.13 with MIS; the course's light sampling):
//   f_r L_e cos(theta_x) w_light / (rate_light p_light),  p_light = P(source) p_point(solid angle)
// with f_r and the BSDF technique's pdf from the shading point's BSDF (bsdf/), w_light from
// the heuristic on q = n p of both techniques (multi-sample) or q = c p (one-sample, c =
// choice probability, then rate_light = c). Delta lights: w = 1.
#pragma once
#include <algorithm>
#include <type_traits>

#include "light/bvh.h"
#include "medium/equiangular.h"
#include "wave/alpha.h"
#include "wave/guide.h"
#include "wave/optimal_mis.h"
#include "wave/surface_bsdf.h"

namespace tuile {

struct LightPass {
  int32_t fixed_light = -1;  // >= 0 with --light-pick all: every lane samples this source
  // Each technique's rate: its sample count n_i (multi-sample MIS) or its choice
  // probability c_i (one-sample), the factor of q_i = rate_i p_i and of 1 / (rate_i p_i).
  float rate_light = 1.f;
  float rate_bsdf = 1.f;
};

// One light sample of lanes [k, k + width) before any weight: the source and point drawn
// (u0: the pick, u2 u3: the point), the BSDF's value and density for the direction, and
// the shadow ray to the point. The light technique's estimate is
// f Le cos_x scale w / (rate_light pdf_l) with pdf_l = pick pdf_sa (a delta source's: pick);
// resampled importance sampling (ris.h) takes the same samples as candidates.
template <class T> struct LightCandidate {
  BsdfEval<T> fe;       // the BSDF's value and density for wi
  Vec3<T> wi_dir;       // wi, the unit direction towards the point drawn
  T Le_r, Le_g, Le_b;   // the source's radiance
  T cos_x, scale;       // |cos| at the shading normal (transmitting surfaces) and the sample's scale
  T pick, pdf_sa;       // the pick's probability and the point's density in solid angle
  mask_t<T> is_delta;   // a delta source (no density: pdf_l is the pick's probability)
  i32_t<T> light;       // the source
  mask_t<T> ok;         // an active lane, a valid point, on the emitting side, cos_x > 0
  Vec3<T> org, dir;     // the shadow ray, stopping at tfar
  T tfar;
  mask_t<T> ray_ok;     // the ray is finite (Embree does not skip non-finite rays)
};

// Cut-out emitters: each lane's radiance times the alpha at the point y drawn on its source
// (the mean of what rays that meet y see: pbrt-v4 masks the point by a hash instead), so
// light sampling estimates what the hits see. Scalar over the lanes, only in scenes whose
// sources have an alpha.
template <class T>
inline void apply_light_alpha(const LightView& L, const i32_t<T>& light, const Vec3<T>& y, LightCandidate<T>& out) {
  constexpr int W = lane_traits<T>::width;
  alignas(64) int32_t li[W];
  alignas(64) float yx[W], yy[W], yz[W], a[W];
  store(li, light);
  store(yx, y.x);
  store(yy, y.y);
  store(yz, y.z);
  for (int i = 0; i < W; ++i) {
    a[i] = 1.f;
    if (li[i] < 0 || li[i] >= L.count) continue;
    const int32_t sh = L.alpha_shape[li[i]];
    if (sh >= 0) {
      const float v = alpha_at_point(L.alpha_shapes[sh], static_cast<uint32_t>(std::max(L.alpha_prim[li[i]], 0)), yx[i], yy[i], yz[i]);
      a[i] = std::clamp(v, 0.f, 1.f);
    }
  }
  const T alpha = load<T>(a);
  out.Le_r = out.Le_r * alpha;
  out.Le_g = out.Le_g * alpha;
  out.Le_b = out.Le_b * alpha;
}

// The shadow ray of a light sample s drawn on source g, from out.org (set) to the point y
// (x + wi dist; at_infinity: none), itself offset off the source towards the origin (pbrt's
// "spawn ray to"): at grazing angles the ray along wi from a lifted origin would meet the
// source's plane early. Embree's packet t is good to ~1e-5 relative (measured), so the ray
// stops 2^-12 of its length short. Sets out.dir, out.tfar and out.ray_ok.
template <unsigned Kinds, class T>
inline void shadow_ray_to_light(const LightGeom<T>& g, const LightPointSample<T>& s, const mask_t<T>& at_infinity,
                                const Vec3<T>& y, LightCandidate<T>& out) {
  // error bound of the light point, per axis (it is p0 + u e1 + v e2, or x + t wi), with
  // |e1| + |e2| bounding every axis's |e1_i| + |e2_i| (a sphere's |e1| is its radius)
  const T g7 = T(gamma_err(7));
  const T edges = g.len1 + g.len2;
  const Vec3<T> err_y{g7 * (abs(g.p0.x) + edges + abs(y.x)), g7 * (abs(g.p0.y) + edges + abs(y.y)),
                      g7 * (abs(g.p0.z) + edges + abs(y.z))};
  // the source's normal at y facing x (none for point-like sources)
  Vec3<T> ny(T(0.f), T(0.f), T(0.f));
  for_each_light_shape<Kinds>(g, [&](auto ops, const mask_t<T>& m) { ny = sel(m, ops.endpoint_normal(g, y, s.wi), ny); });
  const T eps_y = abs(ny.x) * err_y.x + abs(ny.y) * err_y.y + abs(ny.z) * err_y.z;
  const Vec3<T> target = y + ny * eps_y;
  const Vec3<T> to = target - out.org;
  const T len2 = dot(to, to);
  const T ilen = rsqrt_nr(sel(len2 > T(0.f), len2, T(1.f)));
  const T len = len2 * ilen;
  out.dir = sel(at_infinity || !(len > T(0.f)), s.wi, to * ilen);
  out.tfar = sel(at_infinity, T(LightKindOps<LightKind::distant>::infinite_distance), len * T(1.f - 1.f / 4096.f));
  // one test on the sum: a NaN or infinite term makes it non-finite
  out.ray_ok = is_finite(((out.dir.x + out.dir.y) + (out.dir.z + out.tfar)) + ((out.org.x + out.org.y) + out.org.z));
}

// The point --equiangular aims at on a source (wave/equiangular.h): a triangle's or
// parallelogram's centroid, a sphere's centre, a point or spot source's position. Distant
// sources and the sky have none (positional false).
template <class T> inline Vec3<T> light_aim_point(const LightGeom<T>& g, mask_t<T>& positional) {
  using I = i32_t<T>;
  positional = f_mask_from_i(g.type <= I(static_cast<int32_t>(LightKind::spot)));
  const T share = sel(f_mask_from_i(g.type == I(static_cast<int32_t>(LightKind::triangle))), T(1.f / 3.f),
                      sel(f_mask_from_i(g.type == I(static_cast<int32_t>(LightKind::parallelogram))), T(0.5f), T(0.f)));
  return g.p0 + (g.e1 + g.e2) * share;
}

// --equiangular: the light sample at a free flight's collision (a shading point in a
// medium) shares its paths with the segment light sample of the ray that reached it
// (wave/equiangular.h) where the collision lies in that sample's stretch
// (ShadingPoints::eq_lo <= 0): the weight of the collision's technique, the heuristic on
// q = rate_light P(source | x) p_flight(s) against P_alias(source) p_equiangular(s), both
// in the stretch's distance (the point's density on the source, the same for both, drops
// out). 1 elsewhere and for sources without a position.
template <class T>
inline T collision_segment_weight(const GeomView& G, const LightView& L, const Estimator& est, float rate_light,
                                  const TileBuffers& tb, int k, const i32_t<T>& light, const T& pick) {
  const T lo = load<T>(tb.points.eq_lo + k);
  const auto in = lo <= T(0.f);
  if (none(in)) return T(1.f);
  const i32_t<T> li = max(light, i32_t<T>(0));
  mask_t<T> positional;
  const Vec3<T> c = light_aim_point(gather_light(L, li), positional);
  const Vec3<T> x = load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k);
  const Vec3<T> d = Vec3<T>(T(0.f), T(0.f), T(0.f)) - load3<T>(tb.points.wox + k, tb.points.woy + k, tb.points.woz + k);
  const EquiangularFrame<T> f = equiangular_frame(x, d, c, lo, load<T>(tb.points.eq_hi + k));
  const T q_eq = gather(L.pick_pdf, li) * equiangular_pdf(f, T(0.f));
  const i32_t<T> m = max(load_i32<T>(tb.points.medf + k), i32_t<T>(0));
  T pd(0.f);
  for (int ch = 0; ch < 3; ++ch) {
    const T st = gather(G.media.sigma_t[ch], m);
    pd += st * lane_math::exp_nonpositive(st * lo);
  }
  const T q_flight = T(rate_light) * pick * (pd * T(1.f / 3.f));
  return sel(in && positional, mis_weight(est.heuristic, q_flight, q_eq, est.mis), T(1.f));
}

// Kinds: which kinds of source can occur (kind_area, kind_delta); Pick: whether lanes pick
// a source (false: every lane samples pass.fixed_light, as with one light or "all");
// Bsdfs: the kinds of surface (bsdf/material.h). Surfaces that transmit take light from
// below too (|cos|, and the shadow ray leaves from that side); a delta lobe has f = 0 here.
template <class T, unsigned Kinds = kind_all, bool Pick = true, unsigned Bsdfs = bsdf_diffuse>
TUILE_FLATTEN inline LightCandidate<T> light_candidate_lanes(const GeomView& G, const LightView& L, const Estimator& est,
                                                             const LightPass& pass, TileBuffers& tb, int k,
                                                             const mask_t<T>& active) {
  LightCandidate<T> out;
  const Vec3<T> x = load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k);
  const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
  const T eps = load<T>(tb.points.eps + k);

  LightGeom<T> g;
  T pick;
  i32_t<T> light_idx(pass.fixed_light);
  const AliasPicker picker{L};
  // the light BVH's context: the point and its geometric normal (pbrt-v4's), the same bits
  // the emitter-hit queue gives the pmf (emitter_hits.h)
  const PickContext<T> ctx{x, n};
  if constexpr (Pick) {
    // per-lane sources: gathers, or permutes of small and medium tables (the same values)
    with_table_tier(L, [&](auto tier) {
      constexpr int S = decltype(tier)::value;
      i32_t<T> idx;
      if (pass.fixed_light >= 0) {
        idx = i32_t<T>(pass.fixed_light);
        pick = picker.template pmf<S>(ctx, idx);
      } else {
        const T u = load<T>(tb.tech.u0 + k);
        const PickedLight<T> picked =
            L.bvh ? BvhPicker{*L.bvh}.template pick<S>(ctx, u) : picker.template pick<S>(ctx, u);
        idx = picked.light;
        pick = picked.pmf;
      }
      light_idx = idx;
      if constexpr ((Kinds & kind_rects) != 0) g = gather_rect_light<S>(L, idx);
      else g = gather_light<S>(L, idx);
      lookup_radiance<S>(L, idx, out.Le_r, out.Le_g, out.Le_b);
    });
  } else {  // every lane samples the same source: broadcasts, no gathers
    const int32_t li = pass.fixed_light;
    g = broadcast_light<T>(L, li);
    pick = picker.template pmf<tier_gather>(ctx, li);
    out.Le_r = T(L.Lr[li]);
    out.Le_g = T(L.Lg[li]);
    out.Le_b = T(L.Lb[li]);
  }
  const LightPointSample<T> s =
      sample_light_point<Kinds>(est.point, g, x, load<T>(tb.tech.u2 + k), load<T>(tb.tech.u3 + k));
  if constexpr ((Kinds & kind_sky) != 0)  // a sky's map: the radiance of the texel drawn
    LightKindOps<LightKind::infinite>::apply_texel(g, s.sky_texel, out.Le_r, out.Le_g, out.Le_b);

  // the shading normal where the scene has them (vertex normals, bump maps: the BSDF's
  // frame and the cosine), the geometric one n for offsets and which side wi leaves by
  const Vec3<T> ns = G.shading_normals ? load3<T>(tb.points.snx + k, tb.points.sny + k, tb.points.snz + k) : n;
  const SurfaceBsdf<T, Bsdfs> bsdf = load_surface_bsdf<T, Bsdfs>(G, tb.points, k, ns);
  out.fe = bsdf.eval(s.wi);
  out.wi_dir = s.wi;
  constexpr bool transmits = (Bsdfs & bsdf_transmits) != 0;
  const T cos_s = dot(ns, s.wi);
  out.cos_x = transmits ? abs(cos_s) : cos_s;
  if constexpr ((Bsdfs & bsdf_phase) != 0)  // a point in a medium: the phase function, no cosine
    if (G.has_media) out.cos_x = sel(bsdf.is(MaterialKind::phase), T(1.f), out.cos_x);
  // x is on the side the source emits to (one-sided planar sources), and the lanes whose
  // source is at infinity (the shadow ray has no end point)
  auto front = mask_t<T>(true), at_infinity = mask_t<T>(false);
  for_each_light_shape<Kinds>(g, [&](auto ops, const mask_t<T>& m) {
    using Ops = decltype(ops);
    if constexpr (Ops::planar) front = sel_mask(m, ops.lit_from(g, x), front);
    if constexpr (Ops::at_infinity) at_infinity = at_infinity || m;
  });
  out.pick = pick;
  out.light = light_idx;
  out.pdf_sa = s.pdf_sa;
  out.scale = s.scale;
  out.is_delta = s.is_delta;
  out.ok = active && s.valid && front && out.cos_x > T(0.f);
  // --light-paths: a flagged source's light at a near-specular vertex of a path whose first
  // vertex is rough (a distant source's: or coated diffuse, first_rough 0.5) is the light
  // tracer's (src/render/light_paths.h; the views are set only then, and first_rough only
  // from the path's second vertex on; the flagged delta sources are distant ones)
  if constexpr ((Kinds & (kind_delta | kind_area)) != 0 && (Bsdfs & ~bsdf_diffuse) != 0)
    if (L.lt_glossy != nullptr && G.mat_lt_glossy != nullptr) {
      const auto traced = f_mask_from_i(gather(L.lt_glossy, light_idx) != i32_t<T>(0)) &&
                          f_mask_from_i(gather(G.mat_lt_glossy, load_i32<T>(tb.points.mat + k)) != i32_t<T>(0)) &&
                          load<T>(tb.path.first_rough + k) >= sel(s.is_delta, T(0.5f), T(1.f));
      out.ok = out.ok && !traced;
    }

  // Shadow ray from the offset origin to the light point (shadow_ray_to_light)
  // (the offset goes to the side wi leaves by: below the surface for transmission, or
  // where a shading normal lets wi dip under the geometric plane, as pbrt-v4 offsets)
  out.org = transmits || G.shading_normals
                ? x + sel(dot(n, s.wi) < T(0.f), Vec3<T>(T(0.f), T(0.f), T(0.f)) - n, n) * eps
                : x + n * eps;
  const Vec3<T> y = x + s.wi * sel(at_infinity, T(0.f), s.dist);
  if (L.alpha_shape) apply_light_alpha(L, light_idx, y, out);
  shadow_ray_to_light<Kinds>(g, s, at_infinity, y, out);
  return out;
}

// Guided: the general pipeline, where the BSDF technique's density is the mixture with the
// path guide's (wave/guide.h) at guided points.
template <class T, unsigned Kinds = kind_all, bool Pick = true, unsigned Bsdfs = bsdf_diffuse, bool Guided = false>
TUILE_FLATTEN inline void sample_lights_lanes(const GeomView& G, const LightView& L, const Estimator& est, const LightPass& pass,
                                              TileBuffers& tb, int k) {
  auto active = (T(static_cast<float>(k)) + lane_iota<T>()) < T(static_cast<float>(tb.points.count));
  if (est.one_sample()) active = active && (load<T>(tb.points.choose_light + k) > T(0.5f));
  const LightCandidate<T> s = light_candidate_lanes<T, Kinds, Pick, Bsdfs>(G, L, est, pass, tb, k, active);
  const T pdf_l = s.pick * s.pdf_sa;
  T w(1.f);
  if (est.strategy == Strategy::mis) {
    const T q_l = T(pass.rate_light) * pdf_l;
    T pdf_b = s.fe.pdf;
    if (Guided && G.guide) {
      const i32_t<T> dist = load_i32<T>(tb.points.guide_dist + k);  // (guide_points, this vertex)
      const T alpha = load<T>(tb.points.guide_alpha + k);
      pdf_b = guide_mixture_pdf(G, alpha, dist, s.wi_dir, pdf_b);
    }
    const T q_b = T(pass.rate_bsdf) * pdf_b;
    w = sel(s.is_delta, T(1.f), mis_weight(est.heuristic, q_l, q_b, est.mis));
  } else if (est.strategy == Strategy::bsdf) {
    w = sel(s.is_delta, T(1.f), T(0.f));  // area lights are left to the BSDF technique
  }
  if constexpr ((Bsdfs & bsdf_phase) != 0)
    if (est.equiangular && G.has_media) w = w * collision_segment_weight(G, L, est, pass.rate_light, tb, k, s.light, s.pick);
  const T denom = T(pass.rate_light) * sel(s.is_delta, s.pick, pdf_l);
  const auto ok = s.ok && denom > T(0.f) && w > T(0.f);
  const T factor = sel(ok, w * s.cos_x * rcp_nr(sel(ok, denom, T(1.f))) * s.scale, T(0.f));
  const T c_r = s.fe.f.r * s.Le_r * factor;
  const T c_g = s.fe.f.g * s.Le_g * factor;
  const T c_b = s.fe.f.b * s.Le_b * factor;
  // the channels are >= 0 or NaN: their sum is finite iff each one is
  const T c_sum = c_r + c_g + c_b;
  const auto fin = is_finite(c_sum);
  // --heuristic optimal: a sample that adds nothing still counts, by whether it is lit
  // (wave/optimal_mis.h), so its shadow ray is traced; and the techniques' densities
  const bool optimal = optimal_mis(est);
  auto live = ok && fin && (optimal ? mask_t<T>(true) : c_sum > T(0.f));
  if (optimal) {
    store(tb.tech.pl + k, sel(s.is_delta, s.pick, pdf_l));
    store(tb.tech.pb + k, sel(s.is_delta, T(0.f), s.fe.pdf));
  }
  store(tb.tech.cr + k, sel(live, c_r, T(0.f)));
  store(tb.tech.cg + k, sel(live, c_g, T(0.f)));
  store(tb.tech.cb + k, sel(live, c_b, T(0.f)));
  // count contributions dropped as non-finite where the sample itself was fine
  if (any(ok && !fin)) tb.stats.rejected_light += static_cast<uint64_t>(count(ok && !fin));
  if (any(live && !s.ray_ok)) tb.stats.rejected_light += static_cast<uint64_t>(count(live && !s.ray_ok));
  live = live && s.ray_ok;
  store_rays(tb.shadow, k, s.org, s.dir, s.tfar);
  store_valid(tb.tech.valid + k, live);
}

// Draws the pass's random numbers (pick_pair and point_pair: SampleLayout's light_pick and
// light_point of this light sample) and runs the lanes of every shading point.
template <unsigned Kinds = kind_all, bool Pick = true, unsigned Bsdfs = bsdf_diffuse, bool Guided = false>
inline void sample_lights(const GeomView& G, const LightView& L, const Estimator& est, const LightPass& pass, uint32_t sample,
                          uint32_t pick_pair, uint32_t point_pair, TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  if (Pick && pass.fixed_light < 0)  // the pick reads the first dimension only
    point_pairs(est, tb, sample, pick_pair, padded, tb.tech.u0, nullptr);
  point_pairs(est, tb, sample, point_pair, padded, tb.tech.u2, tb.tech.u3);
  // four batches at a time (vfloat4), then two: the solid-angle maps are latency-bound
  // chains, so interleaved batches keep the core busy. Where the surfaces are more than
  // diffuse, two (vfloat2): the BSDF's evaluation makes four batches spill their registers
  // (the light stage of kitchen, bathroom, coffee, staircase2 took 12-35% less time).
  using Batch = std::conditional_t<Bsdfs == bsdf_diffuse, vfloat4, vfloat2>;
  for_lane_batches<Batch>(0, padded, [&](auto lane, int k) {
    sample_lights_lanes<typename decltype(lane)::type, Kinds, Pick, Bsdfs, Guided>(G, L, est, pass, tb, k);
  });
}

// After the shadow query: unoccluded lanes add their contribution to their shading
// point's sum (accumulate adds it to the pixel). Lanes that were not traced or were
// occluded (Embree sets tfar = -inf) add nothing.
template <class T> inline void accumulate_shadow_lanes(TileBuffers& tb, int k) {
  const T tfar = load<T>(tb.shadow[k / packet_width].tfar + k % packet_width);
  const auto lit = f_mask_from_i(load_i32<T>(tb.tech.valid + k) != i32_t<T>(0)) && tfar != T(-INFINITY);
  store(tb.radiance.r + k, load<T>(tb.radiance.r + k) + sel(lit, load<T>(tb.tech.cr + k), T(0.f)));
  store(tb.radiance.g + k, load<T>(tb.radiance.g + k) + sel(lit, load<T>(tb.tech.cg + k), T(0.f)));
  store(tb.radiance.b + k, load<T>(tb.radiance.b + k) + sel(lit, load<T>(tb.tech.cb + k), T(0.f)));
}

template <class T = vfloat> inline void accumulate_shadow(TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  for (int k = 0; k < padded; k += lane_traits<T>::width) accumulate_shadow_lanes<T>(tb, k);
}

}  // namespace tuile
