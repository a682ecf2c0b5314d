// Stage 4, sample cosine: one cosine-weighted direction per shading point (p = cos/pi,
// the exact importance sampling of a Lambertian BSDF), written as bounce rays.
// Reads the shading points and one dimension pair; writes the bounce packets
// (Embree's RTCRayHit16 layout) and the lanes' validity.
#pragma once
#include <algorithm>

#include "wave/tile.h"

namespace tuile {

template <class T> TUILE_FLATTEN inline void sample_cosine_lanes(const Estimator& est, TileBuffers& tb, int k) {
  auto active = (T(static_cast<float>(k)) + lane_iota<T>()) < T(static_cast<float>(tb.points.count));
  if (est.one_sample()) active = active && (load<T>(tb.points.choose_light + k) < T(0.5f));
  const Vec3<T> x = load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k);
  const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
  const T eps = load<T>(tb.points.eps + k);
  const Vec3<T> local = sample_cosine_hemisphere(load<T>(tb.tech.u0 + k), load<T>(tb.tech.u1 + k));
  Vec3<T> t, b;
  make_basis(n, t, b);
  const Vec3<T> d = normalize(t * local.x + b * local.y + n * local.z);
  const auto ok = active && local.z > T(0.f);
  store_rays(tb.bounce, k, x + n * eps, d, T(3.0e38f));
  store_valid(tb.tech.valid + k, ok);
}

inline void sample_cosine(const Estimator& est, uint32_t sample, uint32_t pair, TileBuffers& tb) {
  const int padded = (tb.points.count + packet_width - 1) / packet_width * packet_width;
  point_pairs(est, tb, sample, pair, padded, tb.tech.u0, tb.tech.u1);
  for_lane_batches<vfloat2>(0, padded, [&](auto lane, int k) { sample_cosine_lanes<typename decltype(lane)::type>(est, tb, k); });
  for (int p = 0; p < padded / packet_width; ++p) reset_hit(tb.bounce[p]);
}

}  // namespace tuile
