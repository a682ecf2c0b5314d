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

// Emitters: false when the scene has no area light (no emitter lookups at all).
template <bool Emitters = true>
inline void camera_hits(const GeomView& G, const LightView& L, const Estimator& est, uint32_t sample, int lanes,
                        TileBuffers& tb) {
  int n = 0;
  for (int i = 0; i < lanes; ++i) {
    const RayHit16& p = tb.cam[i / packet_width];
    const int l = i % packet_width;
    const uint32_t geom = p.geomID[l];
    if (geom == invalid_id) continue;
    const float t = p.ray.tfar[l];
    const vec3f o{p.ray.org_x[l], p.ray.org_y[l], p.ray.org_z[l]};
    const vec3f d{p.ray.dir_x[l], p.ray.dir_y[l], p.ray.dir_z[l]};
    // the hit point: from the triangle's barycentrics (error bounded by the vertices'
    // magnitude, not by the ray length), from the ray for spheres
    vec3f x = o + d * t;
    float extent = t;
    if (static_cast<int32_t>(geom) < G.mesh_count) {
      const uint32_t* tri = G.indices[geom] + 3 * p.primID[l];
      const float* P = G.positions[geom];
      const vec3f v0{P[3 * tri[0]], P[3 * tri[0] + 1], P[3 * tri[0] + 2]};
      const vec3f v1{P[3 * tri[1]], P[3 * tri[1] + 1], P[3 * tri[1] + 2]};
      const vec3f v2{P[3 * tri[2]], P[3 * tri[2] + 1], P[3 * tri[2] + 2]};
      const float bu = p.u[l], bv = p.v[l];
      x = v0 * (1.f - bu - bv) + v1 * bu + v2 * bv;
      extent = std::max(max_abs(v0), std::max(max_abs(v1), max_abs(v2)));
    }
    vec3f ng{p.Ng_x[l], p.Ng_y[l], p.Ng_z[l]};
    const float len = length(ng);
    if (!(len > 0.f) || !std::isfinite(len) || !std::isfinite(t)) {
      ++tb.rejected_camera;
      continue;
    }
    ng = ng * (1.f / len);
    if (dot(ng, d) > 0.f) ng = -ng;  // face the viewer: diffuse reflection on both sides
    const int32_t light = Emitters ? light_of_hit(G, geom, p.primID[l]) : -1;
    if (light >= 0 && light_front(L, light, d.x, d.y, d.z)) {
      tb.Lr[i] += L.Lr[light];
      tb.Lg[i] += L.Lg[light];
      tb.Lb[i] += L.Lb[light];
    }
    float r, g, b;
    hit_albedo(G, geom, p.primID[l], p.u[l], p.v[l], r, g, b);
    tb.px[n] = x.x;
    tb.py[n] = x.y;
    tb.pz[n] = x.z;
    tb.nx[n] = ng.x;
    tb.ny[n] = ng.y;
    tb.nz[n] = ng.z;
    tb.eps[n] = offset_scale(x, extent);
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
