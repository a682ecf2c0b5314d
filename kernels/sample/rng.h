// The samplers' entry points: a dimension pair of random numbers for a run of lanes
// (sample_pairs), and the per-pixel stream keys a tile caches for its first pairs
// (PairKeys, make_pair_keys, sample_pairs_keyed). Every value is a pure function of
// (seed, pixel, sample index, dimension pair): sample/rng_core.h says how.
#pragma once
#include "sample/rng_simd.h"

namespace tuile {

// The lane-invariant constants of the hash-based samplers for one pair and sample index.
inline rng_simd::StreamConsts stream_consts(SamplerKind kind, uint32_t seed, uint32_t index, uint32_t pair) noexcept {
  using SC = rng_simd::StreamConsts;
  SC sc;
  sc.ka = rng_simd::xorshift16(hash_u32(seed + 0x51ed270bu));
  sc.kb = rng_simd::xorshift16(hash_u32(pair * 0x2c1b3c6du + 1u) * SC::g + SC::c);
  if (kind == SamplerKind::independent) {
    sc.index = rng_simd::xorshift16(index * SC::g + SC::c);
  } else {
    const uint32_t r = tuile::reverse_bits(index);
    sc.index = r ^ r * 0x3d20adeau;
  }
  return sc;
}

// One dimension pair for W lanes (pixel per lane, same sample index): SIMD for the
// hash-based samplers, the scalar reference per lane for stratified. v = nullptr: the
// first dimension only (the same u, for half the work with the hash-based samplers).
inline void sample_pairs(SamplerKind kind, uint32_t seed, const uint32_t* pixel, uint32_t index, uint32_t spp,
                         uint32_t pair, int count, float* u, float* v) noexcept {
  using namespace rng_simd;
  int i = 0;
  if (kind != SamplerKind::stratified) {
    const StreamConsts sc = stream_consts(kind, seed, index, pair);
    auto blocks = [&](auto want_v) {
      constexpr bool V = decltype(want_v)::value;
      if (kind == SamplerKind::independent)
        return run_blocks<8>(0, count, [&](auto n, int j) { independent_block<n(), V>(sc, pixel + j, u + j, V ? v + j : nullptr); });
      return run_blocks<8>(0, count, [&](auto n, int j) { sobol_block<n(), V>(sc, pixel + j, u + j, V ? v + j : nullptr); });
    };
    i = v ? blocks(std::true_type{}) : blocks(std::false_type{});
  } else if (spp < (1u << 24) && v) {  // stratified: SIMD batches (exact float cell arithmetic below 2^24)
    for (; i + simd_width <= count; i += simd_width) stratified_batch(seed, pixel + i, index, spp, pair, u + i, v + i);
  }
  for (; i < count; ++i) {
    float vi;
    sample_pair_scalar(kind, seed, pixel[i], index, spp, pair, u[i], vi);
    if (v) v[i] = vi;
  }
}

// Stream keys of one pair cached per lane (the sample index does not enter them), so that
// the samples of a tile hash each pixel's key once instead of once per sample. Only the
// hash-based samplers use them (cacheable).
struct PairKeys {
  uint32_t *key, *ku, *kv;
};
inline bool cacheable(SamplerKind kind) noexcept { return kind != SamplerKind::stratified; }
inline void make_pair_keys(uint32_t seed, const uint32_t* pixel, uint32_t pair, int count, const PairKeys& keys) noexcept {
  using namespace rng_simd;
  const StreamConsts sc = stream_consts(SamplerKind::sobol, seed, 0, pair);
  const int done =
      run_blocks<8>(0, count, [&](auto n, int j) { key_block<n()>(sc, pixel + j, keys.key + j, keys.ku + j, keys.kv + j); });
  if (done < count) {  // a partial batch: through a padded copy
    alignas(64) uint32_t p[simd_width], k[simd_width], ku[simd_width], kv[simd_width];
    for (int l = 0; l < simd_width; ++l) p[l] = pixel[std::min(done + l, count - 1)];
    key_block<1>(sc, p, k, ku, kv);
    for (int l = 0; done + l < count; ++l) {
      keys.key[done + l] = k[l];
      keys.ku[done + l] = ku[l];
      keys.kv[done + l] = kv[l];
    }
  }
}
// sample_pairs from cached keys: the same bits.
inline void sample_pairs_keyed(SamplerKind kind, uint32_t seed, uint32_t index, uint32_t pair, const PairKeys& keys,
                               int count, float* u, float* v) noexcept {
  using namespace rng_simd;
  const StreamConsts sc = stream_consts(kind, seed, index, pair);
  auto blocks = [&](auto want_v) {
    constexpr bool V = decltype(want_v)::value;
    return run_blocks<8>(0, count, [&](auto n, int j) {
      keyed_block<n(), V>(kind, sc, keys.key + j, keys.ku + j, keys.kv + j, u + j, V ? v + j : nullptr);
    });
  };
  const int done = v ? blocks(std::true_type{}) : blocks(std::false_type{});
  if (done < count) {  // a partial batch: through a padded copy
    alignas(64) uint32_t k[simd_width], ku[simd_width], kv[simd_width];
    alignas(64) float uu[simd_width], vv[simd_width];
    for (int l = 0; l < simd_width; ++l) {
      const int i = std::min(done + l, count - 1);
      k[l] = keys.key[i];
      ku[l] = keys.ku[i];
      kv[l] = keys.kv[i];
    }
    keyed_block<1, true>(kind, sc, k, ku, kv, uu, vv);
    for (int l = 0; done + l < count; ++l) {
      u[done + l] = uu[l];
      if (v) v[done + l] = vv[l];
    }
  }
}

}  // namespace tuile
