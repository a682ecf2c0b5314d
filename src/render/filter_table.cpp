// The pixel filter's tables: per axis, the 128 cells of equal probability of a
// piecewise-constant density that follows |f1| (their ends: the quantiles of |f1|, from its
// integral over 4096 fine cells), and the scale 1 / (pdf ∫f1) that makes the weight
// f1 / (pdf ∫f1) average 1, ∫f1 taken over the cells exactly as stored.
#include "render/filter_table.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace tuile {

bool filter_kind_from_name(const std::string& name, FilterKind& out) {
  for (int k = 0; k < 5; ++k)
    if (name == filter_kind_names[k]) {
      out = static_cast<FilterKind>(k);
      return true;
    }
  return false;
}

FilterKind parse_filter_kind(const std::string& name) {
  FilterKind k;
  if (!filter_kind_from_name(name, k))
    throw std::invalid_argument("--filter '" + name + "': unknown filter (expected box, triangle, gaussian, mitchell or sinc)");
  return k;
}

namespace {
constexpr float max_radius = 32.f;
}

std::string filter_problem(const FilterParams& p, std::string* param) {
  auto bad = [&](const char* name, const std::string& what) {
    if (param) *param = name;
    return what;
  };
  auto radius_ok = [](float r) { return std::isfinite(r) && r > 0 && r <= max_radius; };
  if (!radius_ok(p.xradius)) return bad("xradius", "a radius in (0, 32] pixels");
  if (!radius_ok(p.yradius)) return bad("yradius", "a radius in (0, 32] pixels");
  // (a sigma far below a pixel makes every table entry but the centre underflow: the filter vanishes)
  if (p.kind == FilterKind::gaussian && !(std::isfinite(p.sigma) && p.sigma >= 1e-4f)) return bad("sigma", "a finite number >= 1e-4");
  if (p.kind == FilterKind::mitchell && !(std::isfinite(p.b) && std::abs(p.b) <= 100))
    return bad("B", "a finite number in [-100, 100]");
  if (p.kind == FilterKind::mitchell && !(std::isfinite(p.c) && std::abs(p.c) <= 100))
    return bad("C", "a finite number in [-100, 100]");
  if (p.kind == FilterKind::sinc && !(std::isfinite(p.tau) && p.tau > 0)) return bad("tau", "a finite number > 0");
  return "";
}

std::string describe(const FilterParams& p) {
  char buf[160];
  const char* name = filter_kind_names[static_cast<int>(p.kind)];
  int n = std::snprintf(buf, sizeof(buf), "%s xradius=%g yradius=%g", name, p.xradius, p.yradius);
  if (p.kind == FilterKind::gaussian) std::snprintf(buf + n, sizeof(buf) - n, " sigma=%g", p.sigma);
  if (p.kind == FilterKind::mitchell) std::snprintf(buf + n, sizeof(buf) - n, " B=%g C=%g", p.b, p.c);
  if (p.kind == FilterKind::sinc) std::snprintf(buf + n, sizeof(buf) - n, " tau=%g", p.tau);
  return buf;
}

namespace {

// Simpson's rule of f1 and |f1| over [x0, x1] with m intervals (m even; f1 as the kernel computes it).
void cell_integrals(const FilterView& v, const FilterAxis& a, double x0, double x1, int m, double& signed_int,
                    double& abs_int) {
  const double h = (x1 - x0) / m;
  double s = 0, sa = 0;
  for (int k = 0; k <= m; ++k) {
    const double f = filter_value_1d<float>(v, a, static_cast<float>(x0 + h * k));
    const double c = (k == 0 || k == m) ? 1 : (k % 2 ? 4 : 2);
    s += c * f;
    sa += c * std::abs(f);
  }
  signed_int = s * h / 3;
  abs_int = sa * h / 3;
}

}  // namespace

FilterView build_filter(const FilterParams& p, std::vector<float>& storage) {
  std::string param;
  const std::string problem = filter_problem(p, &param);
  if (!problem.empty())
    throw std::invalid_argument("PixelFilter \"" + std::string(filter_kind_names[static_cast<int>(p.kind)]) + "\": " + param +
                                " must be " + problem);
  FilterView v;
  v.kind = p.kind;
  const float radius[2] = {p.xradius, p.yradius};
  for (int d = 0; d < 2; ++d) {
    v.axis[d].r = radius[d];
    v.box_a[d] = 0.5f - radius[d];  // r = 0.5: exactly 0 and 1, so offsets are u itself
    v.box_b[d] = 2.f * radius[d];
  }
  storage.clear();
  if (!v.weighted()) return v;
  if (p.kind == FilterKind::mitchell) {
    const float B = p.b, C = p.c;
    const float c[7] = {12 - 9 * B - 6 * C, -18 + 12 * B + 6 * C, 6 - 2 * B, -B - 6 * C, 6 * B + 30 * C, -12 * B - 48 * C,
                        8 * B + 24 * C};
    for (int k = 0; k < 7; ++k) v.coef[k] = c[k] / 6.f;
  }
  constexpr int M = filter_cells;
  storage.assign(2 * 3 * static_cast<size_t>(M), 0.f);
  for (int d = 0; d < 2; ++d) {
    FilterAxis& a = v.axis[d];
    const float r = radius[d];
    if (p.kind == FilterKind::gaussian) {
      a.t_scale = 1.f / (2.f * p.sigma * p.sigma);
      a.f_at_r = lane_math::exp_nonpositive<float>(-(r * r) * a.t_scale);
    } else if (p.kind == FilterKind::mitchell) {
      a.t_scale = 2.f / r;
    } else {
      a.t_scale = 1.f / p.tau;
    }
    float* x0 = storage.data() + static_cast<size_t>(3 * M * d);
    float* dx = x0 + M;
    float* scale = dx + M;
    // |f1| over 4096 fine cells, its CDF piecewise linear between their ends
    constexpr int nf = 4096;
    const double h = 2.0 * r / nf;
    std::vector<double> acc(nf + 1, 0.0);
    for (int j = 0; j < nf; ++j) {
      double s, sa;
      cell_integrals(v, a, -r + h * j, -r + h * (j + 1), 8, s, sa);
      acc[j + 1] = acc[j] + sa;
    }
    const double total_abs = acc[nf];
    if (!(total_abs > 0) || !std::isfinite(total_abs))
      throw std::invalid_argument("PixelFilter " + describe(p) + ": the filter vanishes");
    // the k / M quantiles, as floats; the cells between them as the kernel places them
    std::vector<float> q(M + 1);
    int j = 0;
    for (int k = 0; k <= M; ++k) {
      const double target = total_abs * k / M;
      while (j < nf - 1 && acc[j + 1] <= target) ++j;
      const double mass = acc[j + 1] - acc[j];
      const double frac = mass > 0 ? std::clamp((target - acc[j]) / mass, 0.0, 1.0) : 0.0;
      q[k] = static_cast<float>(-r + h * (j + frac));
    }
    q[0] = -r;
    q[M] = r;
    double total_signed = 0;
    std::vector<double> cell_signed(M);
    for (int k = 0; k < M; ++k) {
      x0[k] = q[k];
      dx[k] = q[k + 1] - q[k];
      double sa;
      cell_integrals(v, a, x0[k], static_cast<double>(x0[k]) + dx[k], 64, cell_signed[k], sa);
      total_signed += cell_signed[k];
    }
    if (!(total_signed > 0))
      throw std::invalid_argument("PixelFilter " + describe(p) + ": the filter's integral is not positive");
    for (int k = 0; k < M; ++k) scale[k] = static_cast<float>(M * static_cast<double>(dx[k]) / total_signed);
    a.x0 = x0;
    a.dx = dx;
    a.scale = scale;
  }
  return v;
}

}  // namespace tuile
