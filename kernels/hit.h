// Stage 2b, camera hits: turns the camera packets Embree filled into compacted shading
// points (position, facing normal, albedo, ray offset), adds the radiance of emitters
// seen directly, and draws the one-sample MIS technique choice.
// Reads: camera packets, geometry/material/light tables. Writes: shading point arrays,
// tile radiance. Scalar per lane: it is gathers and compaction, not arithmetic.
#pragma once
#include "tile.h"

namespace tuile {

inline float luminance(float r, float g, float b) { return 0.2126f * r + 0.7152f * g + 0.0722f * b; }

// Reflectance at a hit: material constant or texture lookup (nearest texel, wrap).
inline void hit_albedo(const GeomView& G, uint32_t geom, uint32_t prim, float u, float v, float& r, float& g,
                       float& b) {
  const int32_t m = G.geom_material[geom];
  if (m < 0) {
    r = g = b = 0.5f;
    return;
  }
  r = G.mat_r[m];
  g = G.mat_g[m];
  b = G.mat_b[m];
  const int32_t t = G.mat_texture[m];
  if (t < 0 || static_cast<int32_t>(geom) >= G.mesh_count || !G.uvs[geom]) return;
  const uint32_t* idx = G.indices[geom] + 3 * prim;
  const float* uv = G.uvs[geom];
  const float w0 = 1.f - u - v;
  float s = w0 * uv[2 * idx[0]] + u * uv[2 * idx[1]] + v * uv[2 * idx[2]];
  float q = w0 * uv[2 * idx[0] + 1] + u * uv[2 * idx[1] + 1] + v * uv[2 * idx[2] + 1];
  s -= std::floor(s);
  q -= std::floor(q);
  const int w = G.tex_w[t], h = G.tex_h[t];
  const int x = std::min(w - 1, std::max(0, static_cast<int>(s * static_cast<float>(w))));
  const int y = std::min(h - 1, std::max(0, static_cast<int>((1.f - q) * static_cast<float>(h))));
  const float* texel = G.tex_rgb[t] + 3 * (static_cast<size_t>(y) * w + x);
  r *= texel[0];
  g *= texel[1];
  b *= texel[2];
}

// The light a ray hit, or -1.
inline int32_t light_of_hit(const GeomView& G, uint32_t geom, uint32_t prim) {
  if (geom == invalid_id) return -1;
  if (static_cast<int32_t>(geom) < G.mesh_count) {
    const int32_t* pl = G.prim_light[geom];
    return pl ? pl[prim] : -1;
  }
  return G.sphere_light[geom - G.mesh_count];
}

// Radiance a ray travelling along d sees when it hits light l at point y: one-sided
// planar sources emit on the side of their normal.
inline bool light_front(const LightView& L, int32_t l, float dx, float dy, float dz) {
  if (L.type[l] == lt_sphere || L.two_sided[l] > 0.f) return true;
  return dx * L.nx[l] + dy * L.ny[l] + dz * L.nz[l] < 0.f;
}

// SIMD half of the camera-hit stage, lanes [i, i + width): hit point, facing normal,
// material reflectance and ray offset for every lane, written in lane order to the queue
// arrays (scratch here). Point x = o + t d; the offset scales with the hit mesh's extent
// and the ray length, which bound the error of x along the normal.
template <class T> inline void camera_hit_lanes(const GeomView& G, TileBuffers& tb, int i) {
  const RayHit16& p = tb.cam[i / packet_width];
  const int l = i % packet_width;
  const i32_t<T> geom = load_i32<T>(reinterpret_cast<const int32_t*>(p.geomID + l));
  const auto hit = f_mask_from_i(geom >= i32_t<T>(0));  // invalid_id reads as -1
  const i32_t<T> gi = max(geom, i32_t<T>(0));
  const T t = load<T>(p.ray.tfar + l);
  const Vec3<T> o = load3<T>(p.ray.org_x + l, p.ray.org_y + l, p.ray.org_z + l);
  const Vec3<T> d = load3<T>(p.ray.dir_x + l, p.ray.dir_y + l, p.ray.dir_z + l);
  const Vec3<T> x = o + d * t;
  Vec3<T> ng = load3<T>(p.Ng_x + l, p.Ng_y + l, p.Ng_z + l);
  const T len = length(ng);
  const auto ok = hit && len > T(0.f) && is_finite(len) && is_finite(t);
  ng = ng * (T(1.f) / sel(ok, len, T(1.f)));
  ng = sel(dot(ng, d) > T(0.f), -ng, ng);  // face the viewer: diffuse reflection on both sides
  const i32_t<T> mat = gather(G.geom_material, gi);
  store3(tb.qx + i, tb.qy + i, tb.qz + i, x);
  store3(tb.qnx + i, tb.qny + i, tb.qnz + i, ng);
  store(tb.qar + i, gather(G.mat_r, mat));
  store(tb.qag + i, gather(G.mat_g, mat));
  store(tb.qab + i, gather(G.mat_b, mat));
  store(tb.qdist + i, offset_scale(x, gather(G.geom_extent, gi) + t));
  store(tb.qdx + i, sel(ok, T(1.f), T(0.f)));
}

// Emitters: false when the scene has no area light (no emitter lookups at all).
template <bool Emitters = true>
inline void camera_hits(const GeomView& G, const LightView& L, const Estimator& est, uint32_t sample, int lanes,
                        TileBuffers& tb) {
  const int padded_lanes = (lanes + packet_width - 1) / packet_width * packet_width;
  int i = 0;
  for (; i + simd_width <= padded_lanes; i += simd_width) camera_hit_lanes<vfloat>(G, tb, i);
  for (; i < padded_lanes; ++i) camera_hit_lanes<float>(G, tb, i);
  int n = 0;
  for (i = 0; i < lanes; ++i) {
    const RayHit16& p = tb.cam[i / packet_width];
    const int l = i % packet_width;
    const uint32_t geom = p.geomID[l];
    if (geom == invalid_id) continue;
    if (!(tb.qdx[i] > 0.f)) {
      ++tb.rejected_camera;
      continue;
    }
    if constexpr (Emitters) {
      const int32_t light = light_of_hit(G, geom, p.primID[l]);
      if (light >= 0 && light_front(L, light, p.ray.dir_x[l], p.ray.dir_y[l], p.ray.dir_z[l])) {
        tb.Lr[i] += L.Lr[light];
        tb.Lg[i] += L.Lg[light];
        tb.Lb[i] += L.Lb[light];
      }
    }
    float r = tb.qar[i], g = tb.qag[i], b = tb.qab[i];
    if (G.has_textures) hit_albedo(G, geom, p.primID[l], p.u[l], p.v[l], r, g, b);
    tb.px[n] = tb.qx[i];
    tb.py[n] = tb.qy[i];
    tb.pz[n] = tb.qz[i];
    tb.nx[n] = tb.qnx[i];
    tb.ny[n] = tb.qny[i];
    tb.nz[n] = tb.qnz[i];
    tb.eps[n] = tb.qdist[i];
    tb.ar[n] = r;
    tb.ag[n] = g;
    tb.ab[n] = b;
    tb.spix[n] = tb.pixel[i];
    tb.slane[n] = i;
    ++n;
  }
  tb.shade_count = n;
  // pad to whole packets with copies of a real point; padding lanes are never active
  const int padded = (n + packet_width - 1) / packet_width * packet_width;
  for (int k = n; k < padded; ++k) {
    tb.px[k] = tb.py[k] = tb.pz[k] = 0.f;
    tb.nx[k] = tb.ny[k] = 0.f;
    tb.nz[k] = 1.f;
    tb.eps[k] = 1e-6f;
    tb.ar[k] = tb.ag[k] = tb.ab[k] = 0.f;
    tb.spix[k] = n > 0 ? tb.spix[0] : 0u;
    tb.slane[k] = -1;
  }
  if (est.one_sample()) {
    sample_pairs(est.sampler, est.seed, tb.spix, sample, est.spp, 1, padded, tb.u0, tb.u1);
    const float c = est.one_sample_light_prob();
    for (int k = 0; k < padded; ++k) tb.choose_light[k] = tb.u0[k] < c ? 1.f : 0.f;
  }
}

}  // namespace tuile
