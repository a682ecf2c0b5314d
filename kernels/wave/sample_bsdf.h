// Stage 4, sample the BSDF: one direction per shading point drawn by its material's BSDF
// (bsdf/material.h: Lambert's cosine-weighted directions, microfacet visible normals,
// specular lobes), written as bounce rays, with the sample's throughput f cos / p, its pdf
// and whether it came from a delta lobe kept for the emitter-hit queue. A direction below
// the surface (transmission) leaves from that side of it.
// Reads the shading points and the BSDF pairs (direction; lobe choice where a kind has
// several lobes); writes the bounce packets (Embree's RTCRayHit16 layout), the lanes'
// validity, throughput, pdf and delta flag.
// only_delta: the light technique alone was asked for (--strategy light): only samples of
// delta lobes, which no light sample can produce, are traced.
// continuation (paths, a vertex before the last): every point samples its BSDF and traces
// the ray, whatever the strategy and the one-sample choice, since the path goes on along
// it; the emitter-hit stage then counts only the hits the technique would have made
// (weight 0 under --strategy light, except delta lobes; one-sample: the points that chose
// the BSDF technique).
#pragma once
#include <algorithm>

#include "wave/guide.h"
#include "wave/surface_bsdf.h"

namespace tuile {

// Guided: the general pipeline, which mixes the guide in where the renderer learned one
// (G.guide; wave/guide.h): the first number u0 chooses the guide (u0 < alpha) or the BSDF,
// rescaled to [0, 1) for the technique it chose, and the sample's throughput and pdf are
// the mixture's.
template <class T, unsigned Bsdfs = bsdf_diffuse, bool Guided = false>
TUILE_FLATTEN inline void sample_bsdf_lanes(const GeomView& G, const Estimator& est, TileBuffers& tb, int k,
                                            bool only_delta = false, bool continuation = false) {
  auto active = (T(static_cast<float>(k)) + lane_iota<T>()) < T(static_cast<float>(tb.points.count));
  if (est.one_sample() && !continuation) active = active && (load<T>(tb.points.choose_light + k) < T(0.5f));
  const Vec3<T> x = load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k);
  const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
  const T eps = load<T>(tb.points.eps + k);
  const Vec3<T> ns = G.shading_normals ? load3<T>(tb.points.snx + k, tb.points.sny + k, tb.points.snz + k) : n;
  const SurfaceBsdf<T, Bsdfs> bsdf = load_surface_bsdf<T, Bsdfs>(G, tb.points, k, ns);
  constexpr bool several_lobes = (Bsdfs & ~bsdf_diffuse) != 0;
  T u0 = load<T>(tb.tech.u0 + k);
  const T u1 = load<T>(tb.tech.u1 + k);
  T alpha(0.f);
  i32_t<T> dist(0);
  auto from_guide = mask_t<T>(false);
  const bool guided = Guided && G.guide;
  if (guided) {
    alpha = load<T>(tb.points.guide_alpha + k);  // (guide_points, this vertex)
    dist = load_i32<T>(tb.points.guide_dist + k);
    from_guide = u0 < alpha;
    const T rescaled = sel(from_guide, u0 / sel(from_guide, alpha, T(1.f)), (u0 - alpha) / (T(1.f) - alpha));
    u0 = min(max(rescaled, T(0.f)), T(0x1.fffffep-1f));
  }
  BsdfSample<T> bs = bsdf.sample(several_lobes ? load<T>(tb.tech.u2 + k) : T(0.f), u0, u1);
  if (guided && any(alpha > T(0.f))) {
    const auto mixed = alpha > T(0.f);
    // a BSDF sample: its density in the mixture (a delta lobe's weight over the (1 - alpha)
    // it is drawn with)
    const T pb_mix = guide_mixture_pdf(G, alpha, dist, bs.wi, bs.pdf);
    const T rb = sel(mixed && !bs.delta, bs.pdf / sel(pb_mix > T(0.f), pb_mix, T(1.f)),
                     sel(mixed, T(1.f) / (T(1.f) - alpha), T(1.f)));
    bs.weight = {bs.weight.r * rb, bs.weight.g * rb, bs.weight.b * rb};
    bs.pdf = sel(mixed && !bs.delta, pb_mix, bs.pdf);
    if (any(from_guide)) {  // a direction of the guide: the BSDF's value and density for it
      const Vec3<T> wg = guide_sample(*G.guide, dist, u0, u1);
      // guided points are diffuse or in a medium (guided_kind): the Lambertian lobe, or the
      // phase function, is their whole BSDF, so the other kinds' lobes in the packet need
      // not be evaluated for this direction
      BsdfEval<T> fe = Lambert<T>{bsdf.rho}.eval(SurfacePoint<T>{bsdf.n, bsdf.wo}, wg);
      const T cos_s = dot(ns, wg);
      T cos_x = (Bsdfs & bsdf_transmits) != 0 ? abs(cos_s) : cos_s;
      if constexpr ((Bsdfs & bsdf_phase) != 0) {
        const auto ph = bsdf.is(MaterialKind::phase);
        if (any(ph)) {
          const T p = hg_phase(dot(bsdf.wo, wg), bsdf.param(mp_hg_g));
          fe.f = {sel(ph, p, fe.f.r), sel(ph, p, fe.f.g), sel(ph, p, fe.f.b)};
          fe.pdf = sel(ph, p, fe.pdf);
          cos_x = sel(ph, T(1.f), cos_x);  // a point in a medium: no cosine
        }
      }
      const T pg_mix = guide_mixture_pdf(G, alpha, dist, wg, fe.pdf);
      const auto ok = cos_x > T(0.f) && pg_mix > T(0.f);
      const T r = sel(ok, cos_x / sel(ok, pg_mix, T(1.f)), T(0.f));
      bs.wi = sel(from_guide, wg, bs.wi);
      bs.weight = {sel(from_guide, fe.f.r * r, bs.weight.r), sel(from_guide, fe.f.g * r, bs.weight.g),
                   sel(from_guide, fe.f.b * r, bs.weight.b)};
      bs.pdf = sel(from_guide, pg_mix, bs.pdf);
      bs.delta = bs.delta && !from_guide;
      bs.valid = sel_mask(from_guide, ok, bs.valid);
    }
  }
  if ((Bsdfs & bsdf_transmits) != 0 || G.shading_normals) {  // leave by the side wi points to
    const auto below = dot(n, bs.wi) < T(0.f);
    store_rays(tb.bounce, k, x + sel(below, Vec3<T>(T(0.f), T(0.f), T(0.f)) - n, n) * eps, bs.wi, T(3.0e38f));
  } else {
    store_rays(tb.bounce, k, x + n * eps, bs.wi, T(3.0e38f));
  }
  auto valid = active && bs.valid;
  if constexpr ((Bsdfs & bsdf_delta_capable) != 0)
    if (only_delta && !continuation) valid = valid && bs.delta;
  store_valid(tb.tech.delta + k, bs.delta);  // (every pipeline: the paths' rough flag reads it, wave/path.h)
  store_valid(tb.tech.valid + k, valid);
  store(tb.tech.beta_r + k, bs.weight.r);
  store(tb.tech.beta_g + k, bs.weight.g);
  store(tb.tech.beta_b + k, bs.weight.b);
  store(tb.tech.pdf + k, bs.pdf);
}

// pair: SampleLayout::bsdf(m) (the direction); lobe_pair: SampleLayout::bsdf_lobe(m), read
// only where some surface has several lobes.
template <unsigned Bsdfs = bsdf_diffuse, bool Guided = false>
inline void sample_bsdf(const GeomView& G, const Estimator& est, uint32_t sample, uint32_t pair, uint32_t lobe_pair,
                        TileBuffers& tb, bool only_delta = false, bool continuation = false) {
  const int padded = packet_padded(tb.points.count);
  point_pairs(est, tb, sample, pair, padded, tb.tech.u0, tb.tech.u1);
  if constexpr ((Bsdfs & ~bsdf_diffuse) != 0) point_pairs(est, tb, sample, lobe_pair, padded, tb.tech.u2, nullptr);
  else (void)lobe_pair;
  for_lane_batches<vfloat2>(0, padded, [&](auto lane, int k) {
    sample_bsdf_lanes<typename decltype(lane)::type, Bsdfs, Guided>(G, est, tb, k, only_delta, continuation);
  });
  for (int p = 0; p < padded / packet_width; ++p) reset_hit(tb.bounce[p]);
}

}  // namespace tuile
