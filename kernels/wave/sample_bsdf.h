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

#include "wave/surface_bsdf.h"

namespace tuile {

template <class T, unsigned Bsdfs = bsdf_diffuse>
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
  const BsdfSample<T> bs =
      bsdf.sample(several_lobes ? load<T>(tb.tech.u2 + k) : T(0.f), load<T>(tb.tech.u0 + k), load<T>(tb.tech.u1 + k));
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
template <unsigned Bsdfs = bsdf_diffuse>
inline void sample_bsdf(const GeomView& G, const Estimator& est, uint32_t sample, uint32_t pair, uint32_t lobe_pair,
                        TileBuffers& tb, bool only_delta = false, bool continuation = false) {
  const int padded = packet_padded(tb.points.count);
  point_pairs(est, tb, sample, pair, padded, tb.tech.u0, tb.tech.u1);
  if constexpr ((Bsdfs & ~bsdf_diffuse) != 0) point_pairs(est, tb, sample, lobe_pair, padded, tb.tech.u2, nullptr);
  else (void)lobe_pair;
  for_lane_batches<vfloat2>(0, padded, [&](auto lane, int k) {
    sample_bsdf_lanes<typename decltype(lane)::type, Bsdfs>(G, est, tb, k, only_delta, continuation);
  });
  for (int p = 0; p < padded / packet_width; ++p) reset_hit(tb.bounce[p]);
}

}  // namespace tuile
