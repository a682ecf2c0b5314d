// Counter-based random numbers: every value is a pure function of
// (seed, pixel, sample index, dimension), so images do not depend on threads,
// tile size or tile order.
//
// Three samplers, all producing pairs (u, v) in [0,1)^2 for a "dimension pair":
//  - independent: a 32-bit integer hash of the counters (lowbias32 finaliser,
//    C. Wellons' hash-prospector constants).
//  - stratified: per dimension pair, spp jittered strata (an n x n grid when spp is a
//    square, else Latin-hypercube strata per axis), visited in an order permuted per
//    pixel and pair by a bijective hash with cycle walking.
//  - sobol: the first two Sobol' dimensions (a (0,2)-sequence), Owen-scrambled by the
//    hash-based nested uniform scramble of Burley 2020 ("Practical Hash-based Owen
//    Scrambling", JCGT 9(4)), with the sample index itself scrambled per pixel and pair
//    so that pairs are decorrelated (padding).
// Templated on U = uint32_t (scalar reference) or vuint (one SIMD batch). This file holds
// the hashes, scrambles and the scalar reference (sample_pair_scalar); sample/rng_simd.h
// the same computation rearranged for SIMD, equal bit for bit; sample/rng.h the entry
// points the stages call.
#pragma once
#include <algorithm>
#include <type_traits>

#include "lanes/simd.h"

namespace tuile {

enum class SamplerKind : int { independent = 0, stratified = 1, sobol = 2 };

template <class U> inline U hash_u32(U x) noexcept {
  x ^= x >> 16;
  x *= U(0x7feb352du);
  x ^= x >> 15;
  x *= U(0x846ca68bu);
  x ^= x >> 16;
  return x;
}

template <class U> inline U hash_combine(U a, U b) noexcept { return hash_u32(a ^ (b * U(0x9e3779b9u) + U(0x7f4a7c15u))); }

// 24 high bits to a float in [0, 1): exactly representable, never 1.
template <class U> inline auto u32_to_unit(U x) noexcept {
  constexpr float k = 1.0f / 16777216.0f;
  if constexpr (std::is_same_v<U, uint32_t>) return static_cast<float>(x >> 8) * k;
  else return u32_to_f32(x >> 8) * vfloat(k);
}

template <class U> inline U reverse_bits(U x) noexcept {
  x = ((x >> 1) & U(0x55555555u)) | ((x & U(0x55555555u)) << 1);
  x = ((x >> 2) & U(0x33333333u)) | ((x & U(0x33333333u)) << 2);
  x = ((x >> 4) & U(0x0f0f0f0fu)) | ((x & U(0x0f0f0f0fu)) << 4);
  x = ((x >> 8) & U(0x00ff00ffu)) | ((x & U(0x00ff00ffu)) << 8);
  return (x >> 16) | (x << 16);
}

// Burley 2020, eq. for the Laine-Karras-style permutation on reversed bits.
template <class U> inline U laine_karras_permutation(U x, U seed) noexcept {
  x ^= x * U(0x3d20adeau);
  x += seed;
  x *= (seed >> 16) | U(1u);
  x ^= x * U(0x05526c56u);
  x ^= x * U(0x53a22864u);
  return x;
}
template <class U> inline U nested_uniform_scramble(U x, U seed) noexcept {
  return reverse_bits(laine_karras_permutation(reverse_bits(x), seed));
}

// Sobol' dimension 0 (van der Corput) and 1 (generator matrix of the polynomial x + 1),
// as 32-bit fixed point.
template <class U> inline U sobol_dim0(U i) noexcept { return reverse_bits(i); }
// Dimension 1's matrix is Pascal's triangle mod 2: by Lucas' theorem output bit j is the
// XOR of the index bits k that contain j as a bit subset, a superset-sum computed in five
// masked xor-shifts (equal to the column-by-column product, tested).
template <class U> inline U sobol_dim1(U i) noexcept {
  i ^= (i >> 1) & U(0x55555555u);
  i ^= (i >> 2) & U(0x33333333u);
  i ^= (i >> 4) & U(0x0f0f0f0fu);
  i ^= (i >> 8) & U(0x00ff00ffu);
  i ^= (i >> 16) & U(0x0000ffffu);
  return reverse_bits(i);
}

// The textbook product with the generator matrix column by column (reference for tests).
inline uint32_t sobol_dim1_reference(uint32_t i) noexcept {
  uint32_t r = 0, v = 0x80000000u;
  for (int b = 0; b < 32; ++b) {
    if ((i >> b) & 1u) r ^= v;
    v ^= v >> 1;
  }
  return r;
}

// Scrambled Sobol' pair (u, v) bits for sample `index` of the stream `key`: the textbook
// composition NUS(sobol0(NUS(index, key)), s1), NUS(sobol1(NUS(index, key)), s2) with the
// bit reversals that cancel removed (3 reversals instead of 8; equal, tested).
// rev_index = reverse_bits(index), the same for every lane.
template <class U> inline void sobol_pair_bits(U rev_index, U key, U& u, U& v) noexcept {
  const U i = reverse_bits(laine_karras_permutation(rev_index, key));  // NUS(index, key)
  u = reverse_bits(laine_karras_permutation(i, hash_u32(key ^ U(0x1b873593u))));
  U sup = i;  // reverse_bits(sobol_dim1(i)): the superset sum without its final reversal
  sup ^= (sup >> 1) & U(0x55555555u);
  sup ^= (sup >> 2) & U(0x33333333u);
  sup ^= (sup >> 4) & U(0x0f0f0f0fu);
  sup ^= (sup >> 8) & U(0x00ff00ffu);
  sup ^= (sup >> 16) & U(0x0000ffffu);
  v = reverse_bits(laine_karras_permutation(sup, hash_u32(key ^ U(0xcc9e2d51u))));
}

// Key of one pixel's sample stream for one dimension pair.
template <class U> inline U stream_key(uint32_t seed, U pixel, uint32_t pair) noexcept {
  return hash_combine(hash_combine(U(hash_u32(seed + 0x51ed270bu)), pixel), U(hash_u32(pair * 0x2c1b3c6du + 1u)));
}

// A bijection of [0, n) chosen by key: a bijective hash on the enclosing power of two,
// with cycle walking back into [0, n). Scalar: used per lane by the stratified sampler.
inline uint32_t permute_index(uint32_t i, uint32_t n, uint32_t key) noexcept {
  if (n <= 1) return 0;
  uint32_t mask = n - 1;
  mask |= mask >> 1; mask |= mask >> 2; mask |= mask >> 4; mask |= mask >> 8; mask |= mask >> 16;
  const uint32_t k1 = hash_u32(key) | 1u, k2 = hash_u32(key ^ 0xa511e9b3u);
  do {
    i = (i * k1) & mask;           // odd multiplier: bijective mod 2^k
    i ^= (i & mask) >> 3;          // xorshift: bijective
    i = (i + k2) & mask;
    i ^= (i >> 5);
    i = (i * 0x9e3779b1u | 0u) & mask;
    i ^= i >> 7;
  } while (i >= n);
  return i;
}

// One dimension pair for one lane (scalar reference of every sampler).
inline void sample_pair_scalar(SamplerKind kind, uint32_t seed, uint32_t pixel, uint32_t index, uint32_t spp,
                               uint32_t pair, float& u, float& v) noexcept {
  const uint32_t key = stream_key<uint32_t>(seed, pixel, pair);
  switch (kind) {
    case SamplerKind::independent: {
      const uint32_t h = hash_combine(key, index);
      u = u32_to_unit(h);
      v = u32_to_unit(hash_u32(h ^ 0x68e31da4u));
      return;
    }
    case SamplerKind::sobol: {
      uint32_t bu, bv;
      sobol_pair_bits(reverse_bits(index), key, bu, bv);
      u = u32_to_unit(bu);
      v = u32_to_unit(bv);
      return;
    }
    case SamplerKind::stratified: {
      const uint32_t h = hash_combine(key, index);
      const float ju = u32_to_unit(h), jv = u32_to_unit(hash_u32(h ^ 0x68e31da4u));
      if (index >= spp || spp == 0) {  // beyond the planned count: plain random
        u = ju; v = jv;
        return;
      }
      uint32_t side = 1;
      while ((side + 1) * (side + 1) <= spp) ++side;
      if (side * side == spp) {
        const uint32_t cell = permute_index(index, spp, key);
        u = (static_cast<float>(cell % side) + ju) / static_cast<float>(side);
        v = (static_cast<float>(cell / side) + jv) / static_cast<float>(side);
      } else {
        u = (static_cast<float>(permute_index(index, spp, key)) + ju) / static_cast<float>(spp);
        v = (static_cast<float>(permute_index(index, spp, key ^ 0x85ebca6bu)) + jv) / static_cast<float>(spp);
      }
      u = u < 1.f ? u : 0x1.fffffep-1f;
      v = v < 1.f ? v : 0x1.fffffep-1f;
      return;
    }
  }
  u = v = 0.f;
}

}  // namespace tuile
