// Stage 5, MIS weight: bounce rays that hit the front of an emitter get the weight of
// the BSDF technique and add rho L_e w_bsdf / n_bsdf to their pixel (cosine sampling of a
// Lambertian BSDF makes f cos / p = rho). The light technique's density for the same
// direction (pick probability times the point density in solid angle, under the same
// fallback rule as sampling) enters q_light. Also records w_bsdf for the mis_weight AOV.
// Reads the bounce packets, the shading points, the tables; writes the tile radiance.
#pragma once
#include "hit.h"

namespace tuile {

template <class T>
inline void weight_lanes(const LightView& L, const Estimator& est, float n_light, float n_bsdf, TileBuffers& tb,
                         int k) {
  constexpr float inv_pi = 0.318309886f;
  const i32_t<T> li = load_i32<T>(tb.hit_light + k);
  const auto hit = f_mask_from_i(li >= i32_t<T>(0));
  const i32_t<T> idx = max(li, i32_t<T>(0));
  const RayHit16& r = tb.bounce[k / packet_width];
  const int l = k % packet_width;
  const Vec3<T> x = load3<T>(tb.px + k, tb.py + k, tb.pz + k);
  const Vec3<T> n = load3<T>(tb.nx + k, tb.ny + k, tb.nz + k);
  const Vec3<T> wi = load3<T>(r.ray.dir_x + l, r.ray.dir_y + l, r.ray.dir_z + l);
  const T t = load<T>(r.ray.tfar + l);
  // distance from x itself (the ray started eps above it)
  const T dist = t + load<T>(tb.eps + k) * dot(n, wi);
  const LightGeom<T> g = gather_light(L, idx);
  const T pdf_l = gather(L.pick_pdf, idx) * pdf_light_point_sa(est.point, g, x, wi, dist);
  T w(1.f);
  if (est.strategy == Strategy::mis) {
    const T q_b = T(n_bsdf) * dot(n, wi) * T(inv_pi);
    w = mis_weight(est.heuristic, q_b, T(n_light) * pdf_l, est.mis);
  } else if (est.strategy == Strategy::light) {
    w = T(0.f);  // the general pipeline traces BSDF rays even when they must not count
  }
  const T factor = sel(hit, w / T(n_bsdf), T(0.f));
  store(tb.cr + k, load<T>(tb.ar + k) * gather(L.Lr, idx) * factor);
  store(tb.cg + k, load<T>(tb.ag + k) * gather(L.Lg, idx) * factor);
  store(tb.cb + k, load<T>(tb.ab + k) * gather(L.Lb, idx) * factor);
  store(tb.wb + k, w);
}

inline void weight_bounce(const GeomView& G, const LightView& L, const Estimator& est, float n_light, float n_bsdf,
                          TileBuffers& tb) {
  const int padded = (tb.shade_count + packet_width - 1) / packet_width * packet_width;
  for (int k = 0; k < padded; ++k) {
    int32_t light = -1;
    if (tb.valid[k]) {
      const RayHit16& r = tb.bounce[k / packet_width];
      const int l = k % packet_width;
      light = light_of_hit(G, r.geomID[l], r.primID[l]);
      if (light >= 0 && !light_front(L, light, r.ray.dir_x[l], r.ray.dir_y[l], r.ray.dir_z[l])) light = -1;
    }
    tb.hit_light[k] = light;
  }
  int k = 0;
  for (; k + simd_width <= padded; k += simd_width) weight_lanes<vfloat>(L, est, n_light, n_bsdf, tb, k);
  for (; k < padded; ++k) weight_lanes<float>(L, est, n_light, n_bsdf, tb, k);
  for (k = 0; k < tb.shade_count; ++k) {
    if (tb.hit_light[k] < 0 || est.strategy == Strategy::light) continue;
    const float r = tb.cr[k], g = tb.cg[k], b = tb.cb[k];
    if (!(std::isfinite(r) && std::isfinite(g) && std::isfinite(b))) {
      ++tb.rejected_bsdf;
      continue;
    }
    const int i = tb.slane[k];
    tb.Lr[i] += r;
    tb.Lg[i] += g;
    tb.Lb[i] += b;
    tb.wsum[i] += tb.wb[k];
    tb.wcnt[i] += 1.f;
  }
}

}  // namespace tuile
