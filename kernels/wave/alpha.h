// Alpha cutouts (pbrt-v4's shape parameter "alpha", a float or a float texture): where a
// shape's alpha is 0 a ray passes through it, where it is between 0 and 1 the hit is kept
// with probability alpha. Embree's intersection filters apply it to every ray (camera,
// shadow, bounce, the emitters' BVH; src/accel/embree.cpp); the light stage multiplies a
// light sample's radiance by the alpha at the point drawn, the mean of what the hits see
// there (sample_lights.h), so light sampling of a cut-out emitter stays unbiased.
// Scalar, cold: only the shapes that have an alpha run it.
#pragma once
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

namespace tuile {

// One shape with an alpha: a mesh (indices, positions and uv per vertex; uv nullptr for
// pbrt's default (0,0), (1,0), (1,1)) or a sphere (no uv: a constant alpha).
struct AlphaShape {
  const uint32_t* indices = nullptr;
  const float* positions = nullptr;
  const float* uvs = nullptr;
  float value = 1;                   // the constant alpha, when tex is nullptr
  const float* tex = nullptr;        // a float texture, one value per texel, top row first
  int32_t tex_w = 0, tex_h = 0;
};

// A float texture at (u, v), bilinear with repeat wrap (pbrt-v4's imagemap defaults, at the
// full resolution): texel centres at half-integers, v = 1 the top row (pbrt flips t = 1 - v).
inline float bilinear_texel(const float* val, int32_t w, int32_t h, float u, float v) noexcept {
  if (!std::isfinite(u) || !std::isfinite(v)) return val[0];
  const float s = u - std::floor(u), q0 = 1.f - v, q = q0 - std::floor(q0);  // in [0, 1]
  const float x = s * static_cast<float>(w) - 0.5f, y = q * static_cast<float>(h) - 0.5f;
  const float xf = std::floor(x), yf = std::floor(y);
  const float fx = x - xf, fy = y - yf;
  int x0 = static_cast<int>(xf), y0 = static_cast<int>(yf);  // in [-1, w - 1], [-1, h - 1]
  int x1 = x0 + 1, y1 = y0 + 1;
  if (x0 < 0) x0 += w;
  if (y0 < 0) y0 += h;
  if (x1 >= w) x1 -= w;
  if (y1 >= h) y1 -= h;
  const size_t W = static_cast<size_t>(w);
  const float v00 = val[static_cast<size_t>(y0) * W + static_cast<size_t>(x0)];
  const float v10 = val[static_cast<size_t>(y0) * W + static_cast<size_t>(x1)];
  const float v01 = val[static_cast<size_t>(y1) * W + static_cast<size_t>(x0)];
  const float v11 = val[static_cast<size_t>(y1) * W + static_cast<size_t>(x1)];
  return (1.f - fy) * ((1.f - fx) * v00 + fx * v10) + fy * ((1.f - fx) * v01 + fx * v11);
}

// The alpha of triangle prim at barycentrics (b1, b2) (a sphere's: its constant).
inline float alpha_at(const AlphaShape& s, uint32_t prim, float b1, float b2) noexcept {
  if (!s.tex) return s.value;
  const uint32_t* idx = s.indices + 3 * static_cast<size_t>(prim);
  float uv[3][2] = {{0, 0}, {1, 0}, {1, 1}};
  if (s.uvs)
    for (int j = 0; j < 3; ++j) {
      uv[j][0] = s.uvs[2 * static_cast<size_t>(idx[j])];
      uv[j][1] = s.uvs[2 * static_cast<size_t>(idx[j]) + 1];
    }
  const float b0 = 1.f - b1 - b2;
  const float u = b0 * uv[0][0] + b1 * uv[1][0] + b2 * uv[2][0];
  const float v = b0 * uv[0][1] + b1 * uv[1][1] + b2 * uv[2][1];
  return bilinear_texel(s.tex, s.tex_w, s.tex_h, u, v);
}

// The alpha at a point y of triangle prim (its barycentrics solved from the triangle's
// vertices): the light stage's lookup at a point it drew.
inline float alpha_at_point(const AlphaShape& s, uint32_t prim, float yx, float yy, float yz) noexcept {
  if (!s.tex) return s.value;
  const uint32_t* idx = s.indices + 3 * static_cast<size_t>(prim);
  const float* p0 = s.positions + 3 * static_cast<size_t>(idx[0]);
  const float* p1 = s.positions + 3 * static_cast<size_t>(idx[1]);
  const float* p2 = s.positions + 3 * static_cast<size_t>(idx[2]);
  const double e1[3] = {double(p1[0]) - p0[0], double(p1[1]) - p0[1], double(p1[2]) - p0[2]};
  const double e2[3] = {double(p2[0]) - p0[0], double(p2[1]) - p0[1], double(p2[2]) - p0[2]};
  const double d[3] = {double(yx) - p0[0], double(yy) - p0[1], double(yz) - p0[2]};
  const auto dot = [](const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
  const double d11 = dot(e1, e1), d12 = dot(e1, e2), d22 = dot(e2, e2), d1 = dot(d, e1), d2 = dot(d, e2);
  const double det = d11 * d22 - d12 * d12;
  if (!(det > 0)) return alpha_at(s, prim, 0, 0);
  const double b1 = std::clamp((d22 * d1 - d12 * d2) / det, 0.0, 1.0);
  const double b2 = std::clamp((d11 * d2 - d12 * d1) / det, 0.0, 1.0 - b1);
  return alpha_at(s, prim, static_cast<float>(b1), static_cast<float>(b2));
}

// pbrt-v4's test of a fractional alpha: the hit is kept when a hash of the ray, in [0, 1),
// is below alpha. The hash takes the ray's origin and direction bits and the primitive hit,
// so two cut-out surfaces along one ray decide independently (pbrt-v4 spawns a new ray
// from each ignored hit, which changes its origin), and a ray decides the same in a packet
// and alone.
inline bool alpha_keeps(float alpha, const float (&ray)[6], uint32_t geom, uint32_t prim) noexcept {
  if (alpha >= 1.f) return true;
  if (!(alpha > 0.f)) return false;
  uint64_t h = 0x9e3779b97f4a7c15ull ^ (static_cast<uint64_t>(geom) << 32 | prim);
  for (const float f : ray) {
    h ^= std::bit_cast<uint32_t>(f);
    h *= 0xff51afd7ed558ccdull;
    h ^= h >> 33;
  }
  h *= 0xc4ceb9fe1a85ec53ull;
  h ^= h >> 33;
  return static_cast<float>(h >> 40) * 0x1p-24f < alpha;
}

}  // namespace tuile
