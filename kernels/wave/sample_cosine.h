// Stage 4, sample the BSDF: one direction per shading point drawn by its BSDF (Lambert's:
// cosine-weighted, p = cos/pi), written as bounce rays, with the sample's throughput
// f cos / p and pdf kept for the emitter-hit queue.
// Reads the shading points and one dimension pair; writes the bounce packets (Embree's
// RTCRayHit16 layout), the lanes' validity, throughput and pdf.
#pragma once
#include <algorithm>

#include "bsdf/lambert.h"
#include "wave/tile.h"

namespace tuile {

template <class T> TUILE_FLATTEN inline void sample_cosine_lanes(const Estimator& est, TileBuffers& tb, int k) {
  auto active = (T(static_cast<float>(k)) + lane_iota<T>()) < T(static_cast<float>(tb.points.count));
  if (est.one_sample()) active = active && (load<T>(tb.points.choose_light + k) < T(0.5f));
  const Vec3<T> x = load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k);
  const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
  const T eps = load<T>(tb.points.eps + k);
  static_assert(!Lambert<T>::reads_wo, "the shading points keep no direction towards the viewer");
  const Lambert<T> bsdf{{load<T>(tb.points.ar + k), load<T>(tb.points.ag + k), load<T>(tb.points.ab + k)}};
  const BsdfSample<T> bs =
      bsdf.sample(SurfacePoint<T>{n, Vec3<T>(T(0.f), T(0.f), T(0.f))}, load<T>(tb.tech.u0 + k), load<T>(tb.tech.u1 + k));
  store_rays(tb.bounce, k, x + n * eps, bs.wi, T(3.0e38f));
  store_valid(tb.tech.valid + k, active && bs.valid);
  store(tb.tech.beta_r + k, bs.weight.r);
  store(tb.tech.beta_g + k, bs.weight.g);
  store(tb.tech.beta_b + k, bs.weight.b);
  store(tb.tech.pdf + k, bs.pdf);
}

inline void sample_cosine(const Estimator& est, uint32_t sample, uint32_t pair, TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  point_pairs(est, tb, sample, pair, padded, tb.tech.u0, tb.tech.u1);
  for_lane_batches<vfloat2>(0, padded, [&](auto lane, int k) { sample_cosine_lanes<typename decltype(lane)::type>(est, tb, k); });
  for (int p = 0; p < padded / packet_width; ++p) reset_hit(tb.bounce[p]);
}

}  // namespace tuile
