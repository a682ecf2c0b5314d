// The chi-square test of the sampling tests: cells sorted by expected count, those below
// min_expected pooled (pbrt-v4's approach; cells a sub-grid integration saw as empty
// included), the p-value from the Wilson-Hilferty approximation (dof >= 10 in every use).
#pragma once
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace tuile::test {

struct Chi2 {
  double chi2 = 0, p = 0;
  int dof = 0;
};

inline Chi2 chi2_test(const std::vector<double>& obs, const std::vector<double>& expd, double min_expected = 5.0) {
  std::vector<size_t> idx(obs.size());
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = i;
  std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return expd[a] < expd[b]; });
  Chi2 r;
  double pool_o = 0, pool_e = 0;
  int cells = 0;
  for (size_t k : idx) {
    pool_o += obs[k];
    pool_e += expd[k];
    if (pool_e >= min_expected) {
      r.chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
      ++cells;
      pool_o = pool_e = 0;
    }
  }
  if (pool_e > 0) {
    r.chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
    ++cells;
  } else if (pool_o > 0) {
    r.chi2 = std::numeric_limits<double>::infinity();
  }
  r.dof = cells - 1;
  const double k = r.dof;
  const double z = (std::cbrt(r.chi2 / k) - (1.0 - 2.0 / (9.0 * k))) / std::sqrt(2.0 / (9.0 * k));
  r.p = 0.5 * std::erfc(z / std::sqrt(2.0));
  return r;
}

}  // namespace tuile::test
