// The SIMD fast path of the counter-based samplers (sample/rng_core.h): blocks of
// batches, Sobol' bit reversal with GFNI where the build has it, the same bits as the
// scalar reference (tested lane by lane).
#pragma once
#include <algorithm>
#include <type_traits>
#include "lanes/simd.h"
#include "sample/rng_core.h"

namespace tuile {

// SIMD fast path of sample_pairs: the same bits as sample_pair_scalar (tested lane by
// lane), in fewer instructions.
namespace rng_simd {

constexpr uint32_t xorshift16(uint32_t x) noexcept { return x ^ (x >> 16); }
inline vuint xorshift16(const vuint& x) noexcept { return x ^ (x >> 16); }

// hash_u32 = xorshift16(mix(xorshift16(x))), and xorshift16 is a linear involution, so a
// chain of hashes keeps the value before the last xorshift16 ("pre" value):
// hash_u32(xorshift16(p) ^ c) = xorshift16(mix(p ^ xorshift16(c))).
inline vuint mix(vuint x) noexcept {
  x *= vuint(0x7feb352du);
  x ^= x >> 15;
  x *= vuint(0x846ca68bu);
  return x;
}

// The GF(2)-affine matrix of a linear map on bytes, in the layout of gf2p8affineqb:
// output bit r is the parity of the input and byte 7 - r of the matrix.
template <class F> constexpr uint64_t byte_matrix(F f) noexcept {
  uint64_t m = 0;
  for (int r = 0; r < 8; ++r)
    for (int c = 0; c < 8; ++c)
      if ((f(1u << c) >> r) & 1u) m |= uint64_t{1} << (8 * (7 - r) + c);
  return m;
}
// reverse_bits within a byte, and the superset sum within a byte (sobol_dim1's first
// three steps).
constexpr uint64_t byte_reverse_matrix = byte_matrix([](uint32_t x) {
  uint32_t r = 0;
  for (int b = 0; b < 8; ++b) r |= ((x >> b) & 1u) << (7 - b);
  return r;
});
constexpr uint64_t byte_superset_matrix = byte_matrix([](uint32_t x) {
  x ^= (x >> 1) & 0x55u;
  x ^= (x >> 2) & 0x33u;
  x ^= (x >> 4) & 0x0fu;
  return x;
});

// With GFNI, bit permutations within bytes are one gf2p8affineqb and byte moves within
// 32-bit lanes one pshufb. Byte patterns: byte k of `p` is the source byte of output
// byte k of every 32-bit lane, 0x80 for zero.
#if defined(__AVX512F__)
#if defined(__GFNI__) && defined(__AVX512BW__)
#define TUILE_RNG_GFNI 1
inline vuint byte_affine(const vuint& x, uint64_t m) noexcept {
  static_assert(simd_width == 16);
  return _mm512_gf2p8affine_epi64_epi8(static_cast<__m512i>(x), _mm512_set1_epi64(static_cast<long long>(m)), 0);
}
inline vuint byte_shuffle(const vuint& x, uint32_t p) noexcept {
  const __m128i q = _mm_setr_epi32(static_cast<int>(p), static_cast<int>(p + 0x04040404u),
                                   static_cast<int>(p + 0x08080808u), static_cast<int>(p + 0x0c0c0c0cu));
  return _mm512_shuffle_epi8(static_cast<__m512i>(x), _mm512_broadcast_i32x4(q));
}
#endif
#elif defined(__AVX2__)
#if defined(__GFNI__)
#define TUILE_RNG_GFNI 1
inline vuint byte_affine(const vuint& x, uint64_t m) noexcept {
  static_assert(simd_width == 8);
  return _mm256_gf2p8affine_epi64_epi8(static_cast<__m256i>(x), _mm256_set1_epi64x(static_cast<long long>(m)), 0);
}
inline vuint byte_shuffle(const vuint& x, uint32_t p) noexcept {
  const __m128i q = _mm_setr_epi32(static_cast<int>(p), static_cast<int>(p + 0x04040404u),
                                   static_cast<int>(p + 0x08080808u), static_cast<int>(p + 0x0c0c0c0cu));
  return _mm256_shuffle_epi8(static_cast<__m256i>(x), _mm256_broadcastsi128_si256(q));
}
#endif
#endif

#if defined(TUILE_RNG_GFNI)
inline vuint reverse_bits(const vuint& x) noexcept { return byte_shuffle(byte_affine(x, byte_reverse_matrix), 0x00010203u); }
// reverse_bits(x) >> 8
inline vuint reverse_bits_shr8(const vuint& x) noexcept {
  return byte_shuffle(byte_affine(x, byte_reverse_matrix), 0x80000102u);
}
// The superset sum of sobol_dim1: within bytes, then across the bytes of each lane.
inline vuint superset_sum(const vuint& x) noexcept {
  vuint s = byte_affine(x, byte_superset_matrix);
  s ^= byte_shuffle(s, 0x80038001u);  // (s >> 8) & 0x00ff00ff
  return s ^ byte_shuffle(s, 0x80800302u);  // s >> 16
}
#else
inline vuint reverse_bits(const vuint& x) noexcept { return tuile::reverse_bits(x); }
inline vuint reverse_bits_shr8(const vuint& x) noexcept { return tuile::reverse_bits(x) >> 8; }
inline vuint superset_sum(vuint x) noexcept {
  x ^= (x >> 1) & vuint(0x55555555u);
  x ^= (x >> 2) & vuint(0x33333333u);
  x ^= (x >> 4) & vuint(0x0f0f0f0fu);
  x ^= (x >> 8) & vuint(0x00ff00ffu);
  x ^= (x >> 16) & vuint(0x0000ffffu);
  return x;
}
#endif

// A value below 2^24 to a float in [0, 1), as u32_to_unit.
inline vfloat unit24(const vuint& x) noexcept { return u32_to_f32(x) * vfloat(1.0f / 16777216.0f); }

// The lane-invariant parts of stream_key and of the samplers.
struct StreamConsts {
  static constexpr uint32_t g = 0x9e3779b9u, c = 0x7f4a7c15u;  // hash_combine's b * g + c
  uint32_t ka, kb;  // stream_key's pre value is mix(mix(xorshift16(pixel * g + c) ^ ka) ^ kb)
  uint32_t index;   // independent: xorshift16(index * g + c); sobol: the first permutation's
                    // x ^ x * 0x3d20adea of x = reverse_bits(index)
};

// Each batch is one long chain of dependent multiplies: the functions below run N batches
// interleaved step by step so that several chains are in flight (8 batches: 1.8x the
// throughput of one at a time with AVX-512).
#define TUILE_RNG_EACH _Pragma("GCC unroll 8") for (int k = 0; k < N; ++k)

template <int N> inline void stream_keys(const StreamConsts& sc, const uint32_t* pixel, vuint (&key)[N]) noexcept {
  TUILE_RNG_EACH {
    const vuint t = vuint::load_unaligned(pixel + k * simd_width) * vuint(sc.g) + vuint(sc.c);
    key[k] = mix(xorshift16(t) ^ vuint(sc.ka));
  }
  TUILE_RNG_EACH key[k] = mix(key[k] ^ vuint(sc.kb));
}

// the independent sampler's pair from the stream keys (h is overwritten); V: whether v is
// wanted (false: the first dimension only, the same u)
template <int N, bool V>
inline void independent_from_keys(const StreamConsts& sc, vuint (&h)[N], float* u, float* v) noexcept {
  TUILE_RNG_EACH h[k] = mix(h[k] ^ vuint(sc.index));  // hash_combine(key, index)
  TUILE_RNG_EACH {
    unit24(xorshift16(h[k]) >> 8).store_unaligned(u + k * simd_width);
    if constexpr (V) unit24(xorshift16(mix(h[k] ^ vuint(xorshift16(0x68e31da4u)))) >> 8).store_unaligned(v + k * simd_width);
  }
}

template <int N, bool V>
inline void independent_block(const StreamConsts& sc, const uint32_t* pixel, float* u, float* v) noexcept {
  vuint h[N];
  stream_keys<N>(sc, pixel, h);
  independent_from_keys<N, V>(sc, h, u, v);
}

// laine_karras_permutation(x, xorshift16(p)) of N batches: the seed's high half is p's.
template <int N> inline void laine_karras_permutation(vuint (&x)[N], const vuint (&p)[N]) noexcept {
  TUILE_RNG_EACH x[k] ^= x[k] * vuint(0x3d20adeau);
  TUILE_RNG_EACH x[k] = (x[k] + (p[k] ^ (p[k] >> 16))) * ((p[k] >> 16) | vuint(1u));
  TUILE_RNG_EACH x[k] ^= x[k] * vuint(0x05526c56u);
  TUILE_RNG_EACH x[k] ^= x[k] * vuint(0x53a22864u);
}

// The parts of sobol_pair_bits that depend on the stream key only (not on the sample
// index): the key's pre value and the pre values of the seeds of u and v.
template <int N>
inline void sobol_seeds(const vuint (&key)[N], vuint (&ku)[N], vuint (&kv)[N]) noexcept {
  TUILE_RNG_EACH ku[k] = mix(key[k] ^ vuint(xorshift16(0x1b873593u)));
  TUILE_RNG_EACH kv[k] = mix(key[k] ^ vuint(xorshift16(0xcc9e2d51u)));
}

// sobol_pair_bits from the key and the seeds (V as for independent_from_keys)
template <int N, bool V>
inline void sobol_from_keys(const StreamConsts& sc, const vuint (&key)[N], const vuint (&ku)[N], const vuint (&kv)[N],
                            float* u, float* v) noexcept {
  vuint x[N], y[N];
  // NUS(index, key)
  TUILE_RNG_EACH {
    const vuint hi = key[k] >> 16;
    x[k] = (vuint(sc.index) + (key[k] ^ hi)) * (hi | vuint(1u));
  }
  TUILE_RNG_EACH x[k] ^= x[k] * vuint(0x05526c56u);
  TUILE_RNG_EACH x[k] = reverse_bits(x[k] ^ x[k] * vuint(0x53a22864u));
  if constexpr (V) {
    TUILE_RNG_EACH y[k] = superset_sum(x[k]);
    laine_karras_permutation(y, kv);
    TUILE_RNG_EACH unit24(reverse_bits_shr8(y[k])).store_unaligned(v + k * simd_width);
  }
  laine_karras_permutation(x, ku);
  TUILE_RNG_EACH unit24(reverse_bits_shr8(x[k])).store_unaligned(u + k * simd_width);
}

// sobol_pair_bits
template <int N, bool V> inline void sobol_block(const StreamConsts& sc, const uint32_t* pixel, float* u, float* v) noexcept {
  vuint key[N], ku[N], kv[N];
  stream_keys<N>(sc, pixel, key);
  sobol_seeds<N>(key, ku, kv);
  sobol_from_keys<N, V>(sc, key, ku, kv, u, v);
}

// The cached forms: keys (and for Sobol' the seeds) made once per pixel and pair by
// key_block, then read per sample.
template <int N>
inline void key_block(const StreamConsts& sc, const uint32_t* pixel, uint32_t* key, uint32_t* ku, uint32_t* kv) noexcept {
  vuint k_[N], u_[N], v_[N];
  stream_keys<N>(sc, pixel, k_);
  sobol_seeds<N>(k_, u_, v_);
  TUILE_RNG_EACH {
    k_[k].store_unaligned(key + k * simd_width);
    u_[k].store_unaligned(ku + k * simd_width);
    v_[k].store_unaligned(kv + k * simd_width);
  }
}
template <int N, bool V>
inline void keyed_block(SamplerKind kind, const StreamConsts& sc, const uint32_t* key, const uint32_t* ku,
                        const uint32_t* kv, float* u, float* v) noexcept {
  vuint k_[N];
  TUILE_RNG_EACH k_[k] = vuint::load_unaligned(key + k * simd_width);
  if (kind == SamplerKind::independent) return independent_from_keys<N, V>(sc, k_, u, v);
  vuint u_[N], v_[N];
  TUILE_RNG_EACH {
    u_[k] = vuint::load_unaligned(ku + k * simd_width);
    if constexpr (V) v_[k] = vuint::load_unaligned(kv + k * simd_width);
  }
  sobol_from_keys<N, V>(sc, k_, u_, v_, u, v);
}
#undef TUILE_RNG_EACH

// permute_index for one batch of keys: the same bijection; each lane walks its cycle until
// its value is in [0, n), finished lanes keep theirs.
inline vuint permute_index_lanes(uint32_t index, uint32_t n, const vuint& key) noexcept {
  if (n <= 1) return vuint(0u);
  uint32_t m = n - 1;
  m |= m >> 1; m |= m >> 2; m |= m >> 4; m |= m >> 8; m |= m >> 16;
  const vuint mask(m), k1 = hash_u32(key) | vuint(1u), k2 = hash_u32(key ^ vuint(0xa511e9b3u));
  vuint i(index);
  auto todo = i == i;
  do {
    vuint y = (i * k1) & mask;
    y ^= (y & mask) >> 3;
    y = (y + k2) & mask;
    y ^= (y >> 5);
    y = (y * vuint(0x9e3779b1u)) & mask;
    y ^= y >> 7;
    i = xsimd::select(todo, y, i);
    todo = todo && (i >= vuint(n));
  } while (xsimd::any(todo));
  return i;
}

// The stratified sampler for one batch of pixels: the same bits as sample_pair_scalar.
inline void stratified_batch(uint32_t seed, const uint32_t* pixel, uint32_t index, uint32_t spp, uint32_t pair,
                             float* u, float* v) noexcept {
  const vuint key = stream_key<vuint>(seed, vuint::load_unaligned(pixel), pair);
  const vuint h = hash_combine(key, vuint(index));
  const vfloat ju = u32_to_unit(h), jv = u32_to_unit(hash_u32(h ^ vuint(0x68e31da4u)));
  vfloat fu = ju, fv = jv;
  if (index < spp && spp != 0) {
    uint32_t side = 1;
    while ((side + 1) * (side + 1) <= spp) ++side;
    if (side * side == spp) {
      // cell / side and cell % side through exact float arithmetic (cell < spp < 2^24)
      const vfloat cell = u32_to_f32(permute_index_lanes(index, spp, key)), fs(static_cast<float>(side));
      const vfloat q = xsimd::floor(cell / fs);
      const vfloat r = cell - q * fs;
      fu = (r + ju) / fs;
      fv = (q + jv) / fs;
    } else {
      const vfloat fn(static_cast<float>(spp));
      fu = (u32_to_f32(permute_index_lanes(index, spp, key)) + ju) / fn;
      fv = (u32_to_f32(permute_index_lanes(index, spp, key ^ vuint(0x85ebca6bu))) + jv) / fn;
    }
    fu = xsimd::select(fu < vfloat(1.f), fu, vfloat(0x1.fffffep-1f));
    fv = xsimd::select(fv < vfloat(1.f), fv, vfloat(0x1.fffffep-1f));
  }
  fu.store_unaligned(u);
  fv.store_unaligned(v);
}

// Blocks of N batches while they fit, then N/2, ... 1 for the rest; returns the lanes done.
template <int N, class Block> inline int run_blocks(int i, int count, const Block& block) noexcept {
  for (; i + N * simd_width <= count; i += N * simd_width) block(std::integral_constant<int, N>{}, i);
  if constexpr (N > 1) return run_blocks<N / 2>(i, count, block);
  else return i;
}

}  // namespace rng_simd

}  // namespace tuile
