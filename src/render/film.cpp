// Film: the per-pixel double sums a render adds to, and the images made from them.
#include "render/film.h"

#include <algorithm>
#include <cmath>

namespace tuile {

void Film::reset(int w, int h) {
  width = w;
  height = h;
  samples = 0;
  const size_t n = static_cast<size_t>(w) * h;
  sum.assign(3 * n, 0.0);
  sum_sq.assign(3 * n, 0.0);
  w_sum.assign(n, 0.0);
  w_cnt.assign(n, 0.0);
  max_sample.assign(n, 0.f);
  if (!optimal.empty()) optimal.assign(9 * n, 0.0);
}

void Film::add(const Film& more) {
  for (size_t i = 0; i < sum.size(); ++i) sum[i] += more.sum[i];
  for (size_t i = 0; i < sum_sq.size(); ++i) sum_sq[i] += more.sum_sq[i];
  for (size_t i = 0; i < w_sum.size(); ++i) w_sum[i] += more.w_sum[i];
  for (size_t i = 0; i < w_cnt.size(); ++i) w_cnt[i] += more.w_cnt[i];
  for (size_t i = 0; i < max_sample.size(); ++i) max_sample[i] = std::max(max_sample[i], more.max_sample[i]);
  if (!more.optimal.empty()) {
    if (optimal.size() != more.optimal.size()) optimal.assign(more.optimal.size(), 0.0);
    for (size_t i = 0; i < optimal.size(); ++i) optimal[i] += more.optimal[i];
  }
  samples += more.samples;
}

std::vector<float> Film::mean() const {
  std::vector<float> out(sum.size(), 0.f);
  if (samples == 0) return out;
  for (size_t i = 0; i < sum.size(); ++i) out[i] = mean_of(i);
  return out;
}

std::vector<float> Film::variance_of_mean() const {
  std::vector<float> out(sum.size(), 0.f);
  if (samples < 2) return out;
  const double n = static_cast<double>(samples);
  for (size_t i = 0; i < sum.size(); ++i) {
    const double m = sum[i] / n;
    const double var = std::max(0.0, (sum_sq[i] / n - m * m)) * n / (n - 1);
    out[i] = static_cast<float>(var / n);
  }
  return out;
}

std::vector<float> Film::mis_weight() const {
  std::vector<float> out(w_sum.size(), 0.f);
  for (size_t i = 0; i < w_sum.size(); ++i) out[i] = w_cnt[i] > 0 ? static_cast<float>(w_sum[i] / w_cnt[i]) : 0.f;
  return out;
}

}  // namespace tuile
