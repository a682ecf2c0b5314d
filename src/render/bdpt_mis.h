// The balance heuristic's weight of a bidirectional join (render/bdpt.h), two ways: pbrt-v4's
// walk over the path's vertices (MISWeight, the reference), and the same sums in constant
// time from prefix sums kept per subpath vertex (what bdpt runs).
//
// A path of s light vertices y0..y(s-1) and t camera vertices z0..z(t-1) (z0 the camera)
// could have been made by each strategy that splits it at another edge; the weight of (s, t)
// is 1 / (1 + the sum over those strategies of their density over this one's). Walking out
// from the join, each vertex multiplies the ratio by its reverse density over its forward
// one (zeros read as one, pbrt's remap0: a delta vertex's), and a strategy counts where
// neither vertex of its edge is a delta vertex (a source is never a delta light here). Only
// the two vertices next to the join on each side see other densities than their subpath's
// (the join's directions); the rest of each side's sum is a prefix of its subpath:
//   camera: P(k) = r(k) (c(k) + P(k - 1)), P(0) = 0, over z1..z(t-3);
//   light:  P(k) = r(k) (c(k) + P(k - 1)), P(-1) = 0, over y0..y(s-3);
// r(k) the ratio of vertex k, c(k) 1 where the strategy at its edge counts. A point or spot
// source is a delta light: no strategy reaches y0 from the camera's side, as if a delta
// vertex stood before y0 (delta_light).
#pragma once

namespace tuile {

struct BdptPd {
  float fwd, rev;  // per unit area; 0 where a delta lobe sampled the direction
  bool delta;      // this vertex's direction on was sampled by a delta lobe
};

inline float bdpt_remap0(float f) { return f != 0.f ? f : 1.f; }

// pbrt-v4's MISWeight: l[0..s) the light vertices, c[0..t) the camera's, their densities as
// the join (s, t) sees them (its endpoints' delta flags false, their and their neighbours'
// reverse densities through the join).
inline float bdpt_mis_walk(const BdptPd* l, int s, const BdptPd* c, int t, bool delta_light = false) {
  if (s + t == 2) return 1.f;
  float sum = 0.f, ri = 1.f;
  for (int i = t - 1; i > 0; --i) {
    ri *= bdpt_remap0(c[i].rev) / bdpt_remap0(c[i].fwd);
    if (!c[i].delta && !c[i - 1].delta) sum += ri;
  }
  ri = 1.f;
  for (int i = s - 1; i >= 0; --i) {
    ri *= bdpt_remap0(l[i].rev) / bdpt_remap0(l[i].fwd);
    if (!l[i].delta && !(i > 0 ? l[i - 1].delta : delta_light)) sum += ri;
  }
  return 1.f / (1.f + sum);
}

// The prefix sum P(k) of a subpath's vertex k from the one before (P(k - 1); 0 before the
// first counted vertex: z1, y0), its densities, its delta flag and the one before's (before
// y0: delta_light).
inline float bdpt_prefix(float before, const BdptPd& v, bool delta_before) {
  const float r = bdpt_remap0(v.rev) / bdpt_remap0(v.fwd);
  return r * ((!v.delta && !delta_before ? 1.f : 0.f) + before);
}

// One side of a join from its n vertices (s or t): the last two's forward densities and
// reverse densities through the join (fwd1, rev1: the join's own vertex; fwd2, rev2: the one
// before it), the delta flags of the two before the join's vertex (delta2, delta3; before
// y0: delta_light, else false), and the prefix sum three vertices from the join (prefix3).
// first: the side's first vertex that is a strategy's (1 for the camera's, 0 for the light's).
struct BdptSide {
  int n;
  float fwd1, rev1, fwd2, rev2;
  bool delta2, delta3;
  float prefix3;
};

inline float bdpt_side_sum(const BdptSide& d, int first) {
  if (d.n - 1 < first) return 0.f;  // (no vertex of this side but the camera)
  float sum = 0.f;
  const float r1 = bdpt_remap0(d.rev1) / bdpt_remap0(d.fwd1);
  if (!d.delta2) sum += r1;
  if (d.n - 2 < first) return sum;
  const float r2 = r1 * bdpt_remap0(d.rev2) / bdpt_remap0(d.fwd2);
  if (!d.delta2 && !d.delta3) sum += r2;
  if (d.n - 3 < first) return sum;
  return sum + r2 * d.prefix3;
}

// The weight of join (s = light.n, t = camera.n) from the prefix sums: bdpt_mis_walk's.
inline float bdpt_mis(const BdptSide& light, const BdptSide& camera) {
  if (light.n + camera.n == 2) return 1.f;
  const float w = 1.f / (1.f + bdpt_side_sum(camera, 1) + bdpt_side_sum(light, 0));
  return w >= 0.f ? w : 0.f;  // (a sum that overflowed: another strategy is infinitely likelier)
}

}  // namespace tuile
