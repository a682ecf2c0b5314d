// Light pickers: which source a light sample takes, and with what probability. The
// interface (pbrt-v4's LightSampler):
//   pick(ctx, u)   -> {light, pmf}   one uniform number
//   pmf(ctx, light)                  the probability pick gives that source from ctx
// where ctx is the shading point and normal, for pickers that depend on them (a light
// BVH); a picker that ignores them says so (reads_context = false), and the stages then
// leave ctx's fields they do not have unset. The alias table (Vose's method over the
// --light-pick distribution: uniform, area or power) is the picker today.
#pragma once
#include "light/table.h"

namespace tuile {

template <class T> struct PickContext {
  Vec3<T> x, n;  // the shading point and its normal (read only where reads_context)
};

template <class T> struct PickedLight {
  i32_t<T> light;
  T pmf;
};

// Picks a source with the alias table: one uniform number, O(1).
template <class T, int Tier = tier_gather> inline i32_t<T> pick_light(const LightView& L, T u) {
  const T scaled = u * T(static_cast<float>(L.count));
  i32_t<T> i = to_i32(scaled);
  i = min(i, i32_t<T>(L.count - 1));
  const T frac = scaled - to_f32(i);
  const T prob = lget<Tier>(L.alias_prob, i);
  const i32_t<T> alt = lget<Tier>(L.alias_idx, i);
  if constexpr (std::is_same_v<T, float>) return frac < prob ? i : alt;
  else return sel(i_mask_from_f(frac < prob), i, alt);
}

// The alias table of the source distribution, O(1) per pick; independent of the shading
// point.
struct AliasPicker {
  static constexpr bool reads_context = false;
  const LightView& L;

  template <int Tier, class T> PickedLight<T> pick(const PickContext<T>&, const T& u) const noexcept {
    const i32_t<T> i = pick_light<T, Tier>(L, u);
    return {i, lget<Tier>(L.pick_pdf, i)};
  }
  // idx: a lane index vector, or one source for every lane (a plain int32_t).
  template <int Tier, class T, class I> T pmf(const PickContext<T>&, const I& idx) const noexcept {
    return T(lget<Tier>(L.pick_pdf, idx));
  }
};

}  // namespace tuile
