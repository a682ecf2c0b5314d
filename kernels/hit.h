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
  const int32_t m = G.geom_material[geom];  // never -1: build_views appends a default material
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

// Whether a ray from o travelling along d sees the emitting side of light l: one-sided
// planar sources emit on the side of their normal, spheres outwards (a ray starting
// inside a sphere light sees no emission, as in pbrt).
inline bool light_front(const LightView& L, int32_t l, float ox, float oy, float oz, float dx, float dy, float dz) {
  if (L.type[l] == lt_sphere) {
    const float cx = ox - L.p0x[l], cy = oy - L.p0y[l], cz = oz - L.p0z[l], r = L.e1x[l];
    return cx * cx + cy * cy + cz * cz > r * r;
  }
  if (L.two_sided[l] > 0.f) return true;
  return dx * L.nx[l] + dy * L.ny[l] + dz * L.nz[l] < 0.f;
}

// Ray offset for a surface point: the per-axis error bound of the point projected on the
// normal (pbrt-v4's OffsetRayOrigin), never zero so the new ray starts off the plane.
inline float offset_along_normal(vec3f err, vec3f n) {
  return std::fabs(n.x) * err.x + std::fabs(n.y) * err.y + std::fabs(n.z) * err.z + 1e-30f;
}

// SIMD half of the camera-hit stage, lanes [i, i + width): hit point, facing normal,
// material reflectance for every lane, written in lane order to the queue arrays
// (scratch here). The point o + t d is refined with its error bound in the scalar half.
template <class T> TUILE_FLATTEN inline void camera_hit_lanes(const GeomView& G, TileBuffers& tb, int i) {
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
  store(tb.qdx + i, sel(ok, T(1.f), T(0.f)));
}

// Emitters: false when the scene has no area light (no emitter lookups at all).
template <bool Emitters = true>
inline void camera_hits(const GeomView& G, const LightView& L, const Estimator& est, uint32_t sample, int lanes,
                        TileBuffers& tb) {
  const int padded_lanes = (lanes + packet_width - 1) / packet_width * packet_width;
  int i = 0;
  for (; i < padded_lanes; i += simd_width) camera_hit_lanes<vfloat>(G, tb, i);
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
      if (light >= 0 && light_front(L, light, p.ray.org_x[l], p.ray.org_y[l], p.ray.org_z[l], p.ray.dir_x[l],
                                    p.ray.dir_y[l], p.ray.dir_z[l])) {
        tb.Lr[i] += L.Lr[light];
        tb.Lg[i] += L.Lg[light];
        tb.Lb[i] += L.Lb[light];
      }
    }
    float r = tb.qar[i], g = tb.qag[i], b = tb.qab[i];
    if (G.has_textures) hit_albedo(G, geom, p.primID[l], p.u[l], p.v[l], r, g, b);
    // The hit point and its error bound (pbrt-v4): for triangles from the barycentrics,
    // err_i = gamma(7) sum_k |b_k v_k,i|, so an axis-aligned plane at any distance keeps
    // an exact coordinate; for spheres reprojected onto the surface, err = gamma(5) |x|.
    vec3f x{tb.qx[i], tb.qy[i], tb.qz[i]};
    const vec3f nrm{tb.qnx[i], tb.qny[i], tb.qnz[i]};
    vec3f err;
    if (static_cast<int32_t>(geom) < G.mesh_count) {
      const uint32_t* tri = G.indices[geom] + 3 * p.primID[l];
      const float* P = G.positions[geom];
      const float b1 = p.u[l], b2 = p.v[l], b0 = 1.f - b1 - b2;
      const float* v0 = P + 3 * tri[0];
      const float* v1 = P + 3 * tri[1];
      const float* v2 = P + 3 * tri[2];
      x = {b0 * v0[0] + b1 * v1[0] + b2 * v2[0], b0 * v0[1] + b1 * v1[1] + b2 * v2[1],
           b0 * v0[2] + b1 * v1[2] + b2 * v2[2]};
      const float g7 = gamma_err(7);
      err = {g7 * (std::fabs(b0 * v0[0]) + std::fabs(b1 * v1[0]) + std::fabs(b2 * v2[0])),
             g7 * (std::fabs(b0 * v0[1]) + std::fabs(b1 * v1[1]) + std::fabs(b2 * v2[1])),
             g7 * (std::fabs(b0 * v0[2]) + std::fabs(b1 * v1[2]) + std::fabs(b2 * v2[2]))};
    } else {
      const float* c = G.sphere_center + 4 * (geom - G.mesh_count);
      vec3f rel{x.x - c[0], x.y - c[1], x.z - c[2]};
      rel = rel * (c[3] / length(rel));
      x = {c[0] + rel.x, c[1] + rel.y, c[2] + rel.z};
      const float g5 = gamma_err(5);
      err = {g5 * std::fabs(x.x), g5 * std::fabs(x.y), g5 * std::fabs(x.z)};
    }
    tb.px[n] = x.x;
    tb.py[n] = x.y;
    tb.pz[n] = x.z;
    tb.nx[n] = nrm.x;
    tb.ny[n] = nrm.y;
    tb.nz[n] = nrm.z;
    tb.eps[n] = offset_along_normal(err, nrm);
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
