// Error metrics of a render against a reference (MSE, relMSE, efficiency).
#include "measure/metrics.h"

#include "render/film.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tuile {

static void check_sizes(const std::vector<float>& x, const std::vector<float>& ref) {
  if (x.size() != ref.size())
    throw std::invalid_argument("image and reference differ in size (" + std::to_string(x.size()) + " vs " +
                                std::to_string(ref.size()) + " values)");
  if (x.empty()) throw std::invalid_argument("empty image");
}

double mse(const std::vector<float>& x, const std::vector<float>& ref) {
  check_sizes(x, ref);
  double s = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    const double d = static_cast<double>(x[i]) - static_cast<double>(ref[i]);
    s += d * d;
  }
  return s / static_cast<double>(x.size());
}

double relmse(const std::vector<float>& x, const std::vector<float>& ref, double eps) {
  check_sizes(x, ref);
  double s = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    const double r = ref[i];
    const double d = static_cast<double>(x[i]) - r;
    s += d * d / (r * r + eps);
  }
  return s / static_cast<double>(x.size());
}

double efficiency(double rel, double seconds) {
  if (!(rel >= 0) || !(seconds >= 0)) return std::numeric_limits<double>::quiet_NaN();
  const double p = rel * seconds;
  return p > 0 ? 1.0 / p : std::numeric_limits<double>::infinity();
}

double loglog_slope(const std::vector<double>& x, const std::vector<double>& y) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (size_t i = 0; i < x.size() && i < y.size(); ++i) {
    if (!(x[i] > 0) || !(y[i] > 0) || !std::isfinite(x[i]) || !std::isfinite(y[i])) continue;
    const double lx = std::log(x[i]), ly = std::log(y[i]);
    sx += lx, sy += ly, sxx += lx * lx, sxy += lx * ly;
    ++n;
  }
  const double den = n * sxx - sx * sx;
  if (n < 2 || !(std::fabs(den) > 1e-12 * (1 + sxx * n))) return std::numeric_limits<double>::quiet_NaN();
  return (n * sxy - sx * sy) / den;
}

double loglog_interpolate(const std::vector<double>& x, const std::vector<double>& y, double at) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const size_t n = std::min(x.size(), y.size());
  if (n == 0 || !(at > 0) || at < x.front() || at > x[n - 1]) return nan;
  for (size_t i = 0; i + 1 < n; ++i) {
    if (at < x[i] || at > x[i + 1]) continue;
    if (!(x[i] > 0) || !(y[i] > 0) || !(y[i + 1] > 0)) return nan;
    if (x[i + 1] == x[i]) return y[i];
    const double t = (std::log(at) - std::log(x[i])) / (std::log(x[i + 1]) - std::log(x[i]));
    return std::exp(std::log(y[i]) + t * (std::log(y[i + 1]) - std::log(y[i])));
  }
  return at == x[n - 1] ? y[n - 1] : nan;
}

double estimated_relmse(const Film& film, double eps) {
  if (film.samples < min_samples_for_error_estimate) return INFINITY;
  const std::vector<float> mean = film.mean(), var = film.variance_of_mean();
  double s = 0;
  for (size_t i = 0; i < mean.size(); ++i) s += double(var[i]) / (double(mean[i]) * double(mean[i]) + eps);
  return mean.empty() ? 0.0 : s / static_cast<double>(mean.size());
}

}  // namespace tuile
