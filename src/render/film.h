// The film: per-pixel sums in double that renders add to, and the images made from them.
#pragma once
#include <cstddef>
#include <cstdint>
#include <new>
#include <vector>

namespace tuile {

// Allocates on 64-byte boundaries (whole cache lines: the film's rows are streamed).
template <class T> struct CacheLineAllocator {
  using value_type = T;
  CacheLineAllocator() = default;
  template <class U> CacheLineAllocator(const CacheLineAllocator<U>&) noexcept {}
  T* allocate(size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(64))); }
  void deallocate(T* p, size_t) noexcept { ::operator delete(p, std::align_val_t(64)); }
  template <class U> bool operator==(const CacheLineAllocator<U>&) const noexcept { return true; }
};
template <class T> using FilmArray = std::vector<T, CacheLineAllocator<T>>;

// Per-pixel sums in double: 10^7 samples in one pixel lose nothing. A film without
// samples holds zeros (reset).
struct Film {
  int width = 0, height = 0;
  uint64_t samples = 0;  // per pixel
  FilmArray<double> sum;     // 3 per pixel
  FilmArray<double> sum_sq;  // 3 per pixel
  FilmArray<double> w_sum;   // BSDF-technique MIS weight, summed over emitter hits
  FilmArray<double> w_cnt;
  FilmArray<float> max_sample;  // largest single-sample luminance
  // --heuristic optimal: each pixel's moments of the optimal MIS system (9 per pixel,
  // wave/optimal_mis.h), which its later samples' weights are solved from; empty otherwise
  FilmArray<double> optimal;
  void reset(int w, int h);
  // Adds another film's samples (the same size): sums added, largest samples kept. A film
  // made by rendering [a, b) into a fresh film and then added gives the bits of rendering
  // [a, b) into this one directly (each tile adds its sums once either way).
  void add(const Film& more);
  // mean radiance, variance of the mean (per channel), mean BSDF MIS weight
  float mean_of(size_t k) const { return static_cast<float>(sum[k] / static_cast<double>(samples)); }  // samples > 0
  std::vector<float> mean() const;
  std::vector<float> variance_of_mean() const;
  std::vector<float> mis_weight() const;
};

}  // namespace tuile
