// Texture lookups of the shading points: reflectance texels (nearest, in three prefetching
// passes), pbrt's mix materials resolved per point, float textures filtered bilinearly
// (roughness per hit, the displacement of bump mapping). Scalar per point (cold in the
// wavefront: only textured scenes run them). Reads the geometry and material tables and
// the shading points; writes the points' albedo, material and alphas.
#pragma once
#include <algorithm>
#include <cmath>

#include "wave/alpha.h"
#include "wave/tile.h"
#include "lanes/vec.h"

namespace tuile {
// The texture of a hit's material, or -1 (spheres and meshes without uv have none).
inline int32_t hit_texture(const GeomView& G, uint32_t geom) {
  const int32_t t = G.mat_texture[G.geom_material[geom]];  // never -1 material: build_views appends a default
  if (t < 0 || !G.uvs[geom]) return -1;  // (nullptr for every kind but meshes)
  return t;
}

// The texel (nearest, wrap) of texture t at barycentrics (u, v) of triangle prim.
inline const float* hit_texel(const GeomView& G, int32_t t, uint32_t geom, uint32_t prim, float u, float v) {
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
  return G.tex_rgb[t] + 3 * (static_cast<size_t>(y) * w + x);
}

// Texels in three passes over the tile's textured shading points, each prefetching what the
// next reads (vertex indices, then uv, then the texel), so that the cache misses of a
// large scene overlap instead of following one another.
inline void apply_texels(const GeomView& G, TileBuffers& tb) {
  const int nt = tb.textured.count;
  for (int j = 0; j < nt; ++j) {
    const uint32_t* idx = G.indices[tb.textured.geom[j]] + 3 * tb.textured.prim[j];
    const float* uv = G.uvs[tb.textured.geom[j]];
    for (int c = 0; c < 3; ++c) __builtin_prefetch(uv + 2 * idx[c]);
  }
  for (int j = 0; j < nt; ++j) {
    tb.textured.texel[j] = hit_texel(G, tb.textured.texture[j], tb.textured.geom[j], tb.textured.prim[j], tb.textured.u[j], tb.textured.v[j]);
    __builtin_prefetch(tb.textured.texel[j]);
  }
  for (int j = 0; j < nt; ++j) {
    const int k = tb.textured.point[j];
    const float* t = tb.textured.texel[j];
    tb.points.ar[k] = t[0];  // the texel replaces the material's constant
    tb.points.ag[k] = t[1];
    tb.points.ab[k] = t[2];
  }
}

// pbrt's mix materials: each shading point whose material is a mix takes one of its two,
// the second with probability amount, from a hash of the point's position and direction
// (deterministic, as pbrt-v4's MixMaterial::ChooseMaterial), with that material's
// reflectance (its texture is not looked up: the texels follow the hit geometry's material).
inline void resolve_mixes(const GeomView& G, ShadingPoints& P) {
  for (int k = 0; k < P.count; ++k) {
    const int32_t m = P.mat[k];
    if (G.mat_mix0[m] < 0) continue;
    uint32_t h = 0x9e3779b9u;
    for (const float f : {P.px[k], P.py[k], P.pz[k], P.wox[k], P.woy[k], P.woz[k]}) {
      h ^= std::bit_cast<uint32_t>(f) + 0x7f4a7c15u + (h << 6) + (h >> 2);
      h *= 0x85ebca6bu;
      h ^= h >> 13;
    }
    const float u = static_cast<float>(h >> 8) * 0x1p-24f;
    const int32_t chosen = u < G.mat_mix_amount[m] ? G.mat_mix1[m] : G.mat_mix0[m];
    P.mat[k] = chosen;
    P.ar[k] = G.mat_r[chosen];
    P.ag[k] = G.mat_g[chosen];
    P.ab[k] = G.mat_b[chosen];
  }
}

// Float texture t at (u, v), filtered bilinearly with repeat wrap (wave/alpha.h).
inline float float_texture_bilinear(const GeomView& G, int32_t t, float u, float v) {
  return bilinear_texel(G.ftex_value[t], G.ftex_w[t], G.ftex_h[t], u, v);
}

// pbrt-v4's MIPMap::Filter (its non-EWA filters) of float texture t at (u, v), for a
// lookup whose footprint is `width` wide in texture space (2 max(|du/dx|, |dv/dx|, |du/dy|,
// |dv/dy|)): the level l = levels - 1 + log2(width); past the last level its one texel;
// else at level i = max(0, floor(l)) the nearest texel (point), the bilinear value
// (bilinear), or the blend of levels i and i + 1 by l - i (trilinear; bilinear at level 0
// while l < 1, as pbrt-v4). A texture without levels (never a bump map): level 0.
inline float float_texture_filtered(const GeomView& G, int32_t t, float u, float v, float width) {
  const int32_t n = G.ftex_levels ? G.ftex_levels[t] : 0;
  if (n <= 0) return float_texture_bilinear(G, t, u, v);
  const float* mip = G.ftex_mip[t];
  const int32_t* mw = G.ftex_mip_w[t];
  const int32_t* mh = G.ftex_mip_h[t];
  const size_t* at = G.ftex_mip_at[t];
  const float level = static_cast<float>(n - 1) + std::log2(std::max(width, 1e-8f));
  if (!(level < static_cast<float>(n - 1))) return mip[at[n - 1]];
  const int i = std::max(0, static_cast<int>(std::floor(level)));
  const auto bilerp = [&](int k) { return bilinear_texel(mip + at[k], mw[k], mh[k], u, v); };
  switch (G.ftex_filter[t]) {  // TexFilter (scene/scene.h): 0 point, 1 bilinear, 2 trilinear
    case 0: {
      if (!std::isfinite(u) || !std::isfinite(v)) return mip[at[i]];
      const float s = u - std::floor(u), q0 = 1.f - v, q = q0 - std::floor(q0);
      int x = static_cast<int>(std::round(s * static_cast<float>(mw[i]) - 0.5f));
      int y = static_cast<int>(std::round(q * static_cast<float>(mh[i]) - 0.5f));
      x = ((x % mw[i]) + mw[i]) % mw[i];
      y = ((y % mh[i]) + mh[i]) % mh[i];
      return mip[at[i] + static_cast<size_t>(y) * static_cast<size_t>(mw[i]) + static_cast<size_t>(x)];
    }
    case 1:
      return bilerp(i);
    default:
      break;
  }
  if (i == 0) return bilerp(0);
  const float f = level - static_cast<float>(i);
  return (1.f - f) * bilerp(i) + f * bilerp(i + 1);
}

// Textured roughness: each point's Trowbridge-Reitz alphas, from its material's float
// textures at the hit's uv (bilinear, wrap; pbrt's default (0,0), (1,0), (1,1) without uv;
// through RoughnessToAlpha = sqrt where the material remaps), or the material's constants.
// Spheres have no uv here: they take the constants.
inline void apply_roughness_textures(const GeomView& G, ShadingPoints& P) {
  const float* cu = G.mat_param[mp_ax];
  const float* cv = G.mat_param[mp_ay];
  for (int k = 0; k < P.count; ++k) {
    const int32_t m = P.mat[k];
    float a[2] = {cu[m], cv[m]};
    const int32_t g = P.geom[k];
    for (int i = 0; i < 2; ++i) {
      const int32_t t = G.mat_alpha_tex[2 * m + i];
      if (t < 0 || !is_mesh(G, g)) continue;
      const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(P.prim[k]);
      float uv[3][2] = {{0, 0}, {1, 0}, {1, 1}};
      if (const float* UV = G.uvs[g])
        for (int j = 0; j < 3; ++j) {
          uv[j][0] = UV[2 * static_cast<size_t>(idx[j])];
          uv[j][1] = UV[2 * static_cast<size_t>(idx[j]) + 1];
        }
      const float b1 = P.bu[k], b2 = P.bv[k], b0 = 1.f - b1 - b2;
      const float u = b0 * uv[0][0] + b1 * uv[1][0] + b2 * uv[2][0];
      const float v = b0 * uv[0][1] + b1 * uv[1][1] + b2 * uv[2][1];
      const float r = std::max(float_texture_bilinear(G, t, u, v), 0.f);
      a[i] = G.mat_remap[m] ? std::sqrt(r) : r;
    }
    P.ax[k] = a[0];
    P.ay[k] = a[1];
  }
}

}  // namespace tuile
