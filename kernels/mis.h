// MIS weights of Veach & Guibas 1995 (§3.4; Veach's thesis ch. 9) for two techniques.
// Reads q_self = n_self p_self and q_other = n_other p_other (multi-sample: n = sample
// count; one-sample: n = the technique's selection probability c). Writes nothing.
// Every heuristic is evaluated in ratio form (r = q_other / q_self) so pdfs from 1e-30 to
// 1e30, zero and infinity give a finite weight in [0, 1], and w(a, b) + w(b, a) = 1.
#pragma once
#include "lanes/simd.h"

namespace tuile {

// optimal: Kondapaneni et al. 2019's weights (wave/optimal_mis.h): the balance heuristic
// plus a per-pixel control variate at the first vertex, the power heuristic after it.
enum class Heuristic : int { balance = 0, power = 1, cutoff = 2, maximum = 3, optimal = 4 };

struct MisParams {
  float beta = 2.f;   // power heuristic exponent
  float alpha = 0.1f; // cutoff threshold
};

template <class T> inline T pow_pos(T r, float beta) {
  if (beta == 2.f) return r * r;
  return sel(r > T(0.f), exp(T(beta) * log(r)), T(0.f));
}

// Weight of the technique with q_self when the other technique has q_other.
template <Heuristic H, class T> inline T mis_weight(T q_self, T q_other, const MisParams& p) {
  q_self = sel(q_self > T(0.f), q_self, T(0.f));     // NaN or negative -> 0
  q_other = sel(q_other > T(0.f), q_other, T(0.f));
  const auto self_inf = q_self > T(3.4028234e38f);
  const auto other_inf = q_other > T(3.4028234e38f);
  const auto self_zero = q_self <= T(0.f);
  const auto other_zero = q_other <= T(0.f);
  // r in [0, inf]; where both are infinite or both are zero, treat them as equal
  T r = sel(self_zero, T(1.f), q_other / sel(self_zero, T(1.f), q_self));
  r = sel(self_inf && other_inf, T(1.f), r);
  r = sel(self_inf && !other_inf, T(0.f), r);
  T w;
  if constexpr (H == Heuristic::balance) {
    w = T(1.f) / (T(1.f) + r);
  } else if constexpr (H == Heuristic::power) {
    const T rb = pow_pos(r, p.beta);
    w = sel(rb < T(3.4028234e38f), T(1.f) / (T(1.f) + rb), T(0.f));
  } else if constexpr (H == Heuristic::cutoff) {
    // with q_max the larger q: w = 0 when q_self < alpha q_max; otherwise normalised over
    // the techniques above the cutoff.
    const auto self_cut = r > T(1.f / p.alpha);             // q_self < alpha q_other
    const auto other_cut = r < T(p.alpha);                  // q_other < alpha q_self
    w = sel(self_cut, T(0.f), sel(other_cut, T(1.f), T(1.f) / (T(1.f) + r)));
  } else {
    w = sel(r < T(1.f), T(1.f), sel(r > T(1.f), T(0.f), T(0.5f)));
  }
  // limits: a zero-density technique gets nothing; both zero share equally (r = 1)
  w = sel(self_zero && !other_zero, T(0.f), w);
  w = sel(other_zero && !self_zero, T(1.f), w);
  return w;
}

template <class T> inline T mis_weight(Heuristic h, T q_self, T q_other, const MisParams& p) {
  switch (h) {
    case Heuristic::balance: return mis_weight<Heuristic::balance>(q_self, q_other, p);
    case Heuristic::power: return mis_weight<Heuristic::power>(q_self, q_other, p);
    case Heuristic::cutoff: return mis_weight<Heuristic::cutoff>(q_self, q_other, p);
    case Heuristic::maximum: return mis_weight<Heuristic::maximum>(q_self, q_other, p);
    // the stages add the balance heuristic's share; wave/optimal_mis.h the rest
    case Heuristic::optimal: return mis_weight<Heuristic::balance>(q_self, q_other, p);
  }
  return T(0.f);
}

}  // namespace tuile
