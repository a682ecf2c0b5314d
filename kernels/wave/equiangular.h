// Segment light samples (--equiangular, Estimator::equiangular): the direct light that a
// path's ray scatters along its way through a medium, sampled per ray instead of only at
// its free flight's collision.
//
// In a medium, the light stage samples the sources from each collision (sample_lights.h),
// and a collision lies wherever the free flight put it, knowing nothing of the sources. A
// collision a few millimetres from a small source then takes a light sample worth 1 / r^2:
// volumetric-caustic's 5 x 4 mm lamp in its gas made most of that scene's error so, spread
// over the whole image by the paths whose later collisions fell next to the lamp. Here each
// ray that runs through a scattering medium (its first stretch of one, with only vacuum
// before it: MediumLanes::eq_med, eq_a, eq_b from medium_flights) takes one more light
// sample: a source picked by the alias table (LightView::pick_pdf, position-free), a
// distance along the stretch by equiangular sampling towards the source's aim point
// (medium/equiangular.h: the density is the source's 1 / r^2, so the sample is bounded), and
// at that point a light sample of that source as the light stage draws one, with the
// medium's phase function and its transmittance to the point and on to the source.
//
// Unbiased, by two partitions of unity. At each point of a stretch the light stage's
// heuristic splits the direct light between light sampling and phase sampling, as at a
// collision (the segment sample takes the light technique's weight the light stage would
// give there: w_nee). The light technique's share is then sampled along the stretch two
// ways, the free flight's collision and the equiangular distance, combined by the
// heuristic on the distance's densities times the source's probability
// (collision_segment_weight in sample_lights.h at the collisions, w_seg here); the point's
// density on the source is the same in both and drops out. A collision outside the stretch
// (past an interface into another medium) keeps weight 1, and so does a distant source or
// the sky, which no segment sample aims at. Phase sampling's emitter hits keep their weights.
//
// The contribution is relative to the throughput at the ray's origin (before its flight's
// weight): the tile pipeline adds it to the path's pixel. Not with --strategy bsdf or ris,
// --mis-mode one, --light-pick all, --heuristic optimal or --guide (src/render/options.cpp).
#pragma once
#include "wave/media.h"
#include "wave/sample_lights.h"

namespace tuile {

// Lanes [k, k + width) of the rays [0, count) of packets (valid: traced; ml: their flights),
// with S.u0 .. u3 their random numbers: each ray's segment light sample, its shadow ray
// (S.shadow from the point in the medium, S.valid) and contribution (S.cr, cg, cb) times
// beta, the throughput at the ray's origin (beta[c] null: 1), if the ray turns out
// unoccluded (the media's transmittance on the way is the shadow stage's).
template <class T, unsigned Kinds = kind_all>
TUILE_FLATTEN inline void segment_light_lanes(const GeomView& G, const LightView& L, const Estimator& est,
                                              float rate_light, float rate_bsdf, const RayHit16* packets,
                                              const int32_t* valid, int count, const MediumLanes& ml,
                                              const float* const* beta, SegmentLights& S, int k) {
  using I = i32_t<T>;
  const MediumView& M = G.media;
  const RayHit16& r = packets[k / packet_width];
  const int l = k % packet_width;
  const I med = load_i32<T>(ml.eq_med + k);
  auto active = f_mask_from_i((I(k) + lane_iota_i32<T>() < I(count)) && load_i32<T>(valid + k) != I(0) && med >= I(0));
  if (none(active)) {
    store_valid(S.valid + k, active);
    return;
  }
  const I m = sel(i_mask_from_f(active), med, I(0));
  const Vec3<T> o = load3<T>(r.ray.org_x + l, r.ray.org_y + l, r.ray.org_z + l);
  const Vec3<T> d = load3<T>(r.ray.dir_x + l, r.ray.dir_y + l, r.ray.dir_z + l);
  const T a = load<T>(ml.eq_a + k), b = load<T>(ml.eq_b + k);

  // the source, by the alias table; the point aimed at
  LightGeom<T> g;
  I light;
  T p_alias, Le_r, Le_g, Le_b;
  with_table_tier(L, [&](auto tier) {
    constexpr int Tier = decltype(tier)::value;
    light = pick_light<T, Tier>(L, load<T>(S.u0 + k));
    p_alias = lget<Tier>(L.pick_pdf, light);
    if constexpr ((Kinds & kind_rects) != 0) g = gather_rect_light<Tier>(L, light);
    else g = gather_light<Tier>(L, light);
    lookup_radiance<Tier>(L, light, Le_r, Le_g, Le_b);
  });
  mask_t<T> positional;
  const Vec3<T> c = light_aim_point(g, positional);
  active = active && positional && p_alias > T(0.f);

  // the distance, equiangular towards c
  const EquiangularFrame<T> f = equiangular_frame(o, d, c, a, b);
  const T s_eq = equiangular_sample(f, a, b, load<T>(S.u1 + k));
  const T p_eq = equiangular_pdf(f, s_eq);
  const Vec3<T> x = o + d * s_eq;

  // a light sample of the source at x, as the light stage draws one
  const LightPointSample<T> ls = sample_light_point<Kinds>(est.point, g, x, load<T>(S.u2 + k), load<T>(S.u3 + k));
  auto front = mask_t<T>(true);
  for_each_light_shape<Kinds>(g, [&](auto ops, const mask_t<T>& mk) {
    using Ops = decltype(ops);
    if constexpr (Ops::planar) front = sel_mask(mk, ops.lit_from(g, x), front);
  });
  const I mat = gather(G.geom_material, I(M.geom0) + m);
  const T phase = hg_phase(dot(Vec3<T>(T(0.f), T(0.f), T(0.f)) - d, ls.wi), gather(G.mat_param[mp_hg_g], mat));
  T pick = p_alias;
  if (L.bvh) {  // the light stage's pick at x (a point in a medium: no normal)
    with_table_tier(L, [&](auto tier) {
      constexpr int Tier = decltype(tier)::value;
      pick = BvhPicker{*L.bvh}.template pmf<Tier>(PickContext<T>{x, Vec3<T>(T(0.f), T(0.f), T(0.f))}, light);
    });
  }
  // the light technique's share at x (w_nee), and this technique's share of it (w_seg)
  T w_nee(1.f);
  if (est.strategy == Strategy::mis)
    w_nee = sel(ls.is_delta, T(1.f), mis_weight(est.heuristic, T(rate_light) * pick * ls.pdf_sa, T(rate_bsdf) * phase, est.mis));
  T st[3], tr[3], p_flight(0.f);
  for (int ch = 0; ch < 3; ++ch) {
    st[ch] = gather(M.sigma_t[ch], m);
    tr[ch] = lane_math::exp_nonpositive(T(0.f) - st[ch] * (s_eq - a));
    p_flight += st[ch] * tr[ch];
  }
  p_flight *= T(1.f / 3.f);
  const T w_seg = mis_weight(est.heuristic, p_alias * p_eq, T(rate_light) * pick * p_flight, est.mis);
  const T denom = p_alias * p_eq * sel(ls.is_delta, T(1.f), ls.pdf_sa);
  const auto ok = active && f.ok && ls.valid && front && denom > T(0.f) && phase > T(0.f) && w_seg * w_nee > T(0.f);
  const T factor = sel(ok, w_nee * w_seg * phase * ls.scale / sel(ok, denom, T(1.f)), T(0.f));

  LightCandidate<T> out;
  out.Le_r = Le_r;
  out.Le_g = Le_g;
  out.Le_b = Le_b;
  out.org = x;
  if (L.alpha_shape) apply_light_alpha(L, light, x + ls.wi * ls.dist, out);
  shadow_ray_to_light<Kinds>(g, ls, mask_t<T>(false), x + ls.wi * ls.dist, out);
  const T Le[3] = {out.Le_r, out.Le_g, out.Le_b};
  T cc[3];
  for (int ch = 0; ch < 3; ++ch) {
    const T bt = beta[ch] ? load<T>(beta[ch] + k) : T(1.f);
    cc[ch] = bt * tr[ch] * gather(M.sigma_s[ch], m) * Le[ch] * factor;
  }
  const T sum = cc[0] + cc[1] + cc[2];
  const auto live = ok && out.ray_ok && is_finite(sum) && sum > T(0.f);
  store(S.cr + k, sel(live, cc[0], T(0.f)));
  store(S.cg + k, sel(live, cc[1], T(0.f)));
  store(S.cb + k, sel(live, cc[2], T(0.f)));
  store_rays(S.shadow, k, out.org, out.dir, out.tfar);
  store_valid(S.valid + k, live);
}

}  // namespace tuile
