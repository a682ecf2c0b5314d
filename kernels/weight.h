// Stage 5, MIS weight: bounce rays that hit the front of an emitter get the weight of
// the BSDF technique and add rho L_e w_bsdf / n_bsdf to their pixel (cosine sampling of a
// Lambertian BSDF makes f cos / p = rho). The light technique's density for the same
// direction (pick probability times the point density in solid angle, under the same
// fallback rule as sampling) enters q_light. Also records w_bsdf for the mis_weight AOV.
// Reads the bounce packets, the shading points, the tables; writes the tile radiance.
#pragma once
#include "hit.h"

namespace tuile {

// Lanes [j, j + width) of the hit queue.
template <class T>
TUILE_FLATTEN inline void weight_lanes(const LightView& L, const Estimator& est, float n_light, float n_bsdf, TileBuffers& tb,
                         int j) {
  constexpr float inv_pi = 0.318309886f;
  const auto live = (T(static_cast<float>(j)) + lane_iota<T>()) < T(static_cast<float>(tb.queue_count));
  const i32_t<T> idx = load_i32<T>(tb.qlight + j);
  const Vec3<T> x = load3<T>(tb.qx + j, tb.qy + j, tb.qz + j);
  const Vec3<T> n = load3<T>(tb.qnx + j, tb.qny + j, tb.qnz + j);
  const Vec3<T> wi = load3<T>(tb.qdx + j, tb.qdy + j, tb.qdz + j);
  const T dist = load<T>(tb.qdist + j);
  const LightGeom<T> g = gather_light(L, idx);
  const T pdf_l = gather(L.pick_pdf, idx) * pdf_light_point_sa(est.point, g, x, wi, dist);
  T w(1.f);
  if (est.strategy == Strategy::mis) {
    const T q_b = T(n_bsdf) * dot(n, wi) * T(inv_pi);
    w = mis_weight(est.heuristic, q_b, T(n_light) * pdf_l, est.mis);
  } else if (est.strategy == Strategy::light) {
    w = T(0.f);  // the general pipeline traces BSDF rays even when they must not count
  }
  const T factor = sel(live, w / T(n_bsdf), T(0.f));
  store(tb.cr + j, load<T>(tb.qar + j) * gather(L.Lr, idx) * factor);
  store(tb.cg + j, load<T>(tb.qag + j) * gather(L.Lg, idx) * factor);
  store(tb.cb + j, load<T>(tb.qab + j) * gather(L.Lb, idx) * factor);
  store(tb.wb + j, w);
}

// Queues the bounce rays that hit the front of an emitter, weights them, adds them.
inline void weight_bounce(const GeomView& G, const LightView& L, const Estimator& est, float n_light, float n_bsdf,
                          TileBuffers& tb) {
  int nq = 0;
  for (int k = 0; k < tb.shade_count; ++k) {
    if (!tb.valid[k]) continue;
    const RayHit16& r = tb.bounce[k / packet_width];
    const int l = k % packet_width;
    const int32_t light = light_of_hit(G, r.geomID[l], r.primID[l]);
    if (light < 0 || !light_front(L, light, r.ray.org_x[l], r.ray.org_y[l], r.ray.org_z[l], r.ray.dir_x[l],
                                  r.ray.dir_y[l], r.ray.dir_z[l]))
      continue;
    tb.qx[nq] = tb.px[k];
    tb.qy[nq] = tb.py[k];
    tb.qz[nq] = tb.pz[k];
    tb.qnx[nq] = tb.nx[k];
    tb.qny[nq] = tb.ny[k];
    tb.qnz[nq] = tb.nz[k];
    tb.qdx[nq] = r.ray.dir_x[l];
    tb.qdy[nq] = r.ray.dir_y[l];
    tb.qdz[nq] = r.ray.dir_z[l];
    // distance from x itself (the ray started eps above it along n)
    tb.qdist[nq] = r.ray.tfar[l] + tb.eps[k] * (tb.nx[k] * r.ray.dir_x[l] + tb.ny[k] * r.ray.dir_y[l] +
                                               tb.nz[k] * r.ray.dir_z[l]);
    tb.qar[nq] = tb.ar[k];
    tb.qag[nq] = tb.ag[k];
    tb.qab[nq] = tb.ab[k];
    tb.qlight[nq] = light;
    tb.qlane[nq] = tb.slane[k];
    ++nq;
  }
  tb.queue_count = nq;
  if (nq == 0) return;
  const int padded = (nq + simd_width - 1) / simd_width * simd_width;
  for (int j = nq; j < padded; ++j) {  // padding: a valid light index, no contribution
    tb.qx[j] = tb.qy[j] = tb.qz[j] = 0.f;
    tb.qnx[j] = tb.qny[j] = 0.f;
    tb.qnz[j] = 1.f;
    tb.qdx[j] = tb.qdy[j] = 0.f;
    tb.qdz[j] = 1.f;
    tb.qdist[j] = 1.f;
    tb.qar[j] = tb.qag[j] = tb.qab[j] = 0.f;
    tb.qlight[j] = tb.qlight[0];
  }
  for (int j = 0; j < padded; j += simd_width) weight_lanes<vfloat>(L, est, n_light, n_bsdf, tb, j);
  if (est.strategy == Strategy::light) return;
  for (int j = 0; j < nq; ++j) {
    const float r = tb.cr[j], g = tb.cg[j], b = tb.cb[j];
    if (!(std::isfinite(r) && std::isfinite(g) && std::isfinite(b))) {
      ++tb.rejected_bsdf;
      continue;
    }
    const int i = tb.qlane[j];
    tb.Lr[i] += r;
    tb.Lg[i] += g;
    tb.Lb[i] += b;
    if (est.aov_mis_weight) {
      tb.wsum[i] += tb.wb[j];
      tb.wcnt[i] += 1.f;
    }
  }
}

}  // namespace tuile
