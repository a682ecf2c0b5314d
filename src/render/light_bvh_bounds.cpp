// The light BVH's parts (light_bvh_bounds.h): the cone union, each source's bounds (each
// light kind's own, light/kinds/), nodes' exact bounds, and the split search's measure of
// emission and costs.
#include "render/light_bvh_bounds.h"

#include "light/dispatch.h"

namespace tuile::light_bvh_detail {

double angle_between(const double* a, const double* b) {
  // numerically careful for nearly equal or opposite vectors (pbrt's AngleBetween)
  if (dot3(a, b) < 0) {
    const double s[3] = {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
    return kPi - 2 * std::asin(std::min(1.0, std::sqrt(dot3(s, s)) / 2));
  }
  const double d[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
  return 2 * std::asin(std::min(1.0, std::sqrt(dot3(d, d)) / 2));
}

Cone cone_union(const Cone& a, const Cone& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  if (a.theta >= kPi || b.theta >= kPi) return Cone::all();
  // the same axis (many sources share a plane): the wider cone, without trigonometry
  if (a.w[0] == b.w[0] && a.w[1] == b.w[1] && a.w[2] == b.w[2]) return a.theta >= b.theta ? a : b;
  const double td = angle_between(a.w, b.w);
  if (std::min(td + b.theta, kPi) <= a.theta) return a;
  if (std::min(td + a.theta, kPi) <= b.theta) return b;
  const double to = (a.theta + td + b.theta) / 2;
  if (to >= kPi) return Cone::all();
  const double tr = to - a.theta;
  double axis[3] = {a.w[1] * b.w[2] - a.w[2] * b.w[1], a.w[2] * b.w[0] - a.w[0] * b.w[2], a.w[0] * b.w[1] - a.w[1] * b.w[0]};
  const double len = std::sqrt(dot3(axis, axis));
  if (!(len > 0)) return Cone::all();
  for (double& v : axis) v /= len;
  // Rodrigues: rotate a.w by tr about axis
  const double c = std::cos(tr), s = std::sin(tr), k = dot3(axis, a.w);
  const double cr[3] = {axis[1] * a.w[2] - axis[2] * a.w[1], axis[2] * a.w[0] - axis[0] * a.w[2],
                        axis[0] * a.w[1] - axis[1] * a.w[0]};
  Cone out;
  for (int i = 0; i < 3; ++i) out.w[i] = a.w[i] * c + cr[i] * s + axis[i] * k * (1 - c);
  const double l = std::sqrt(dot3(out.w, out.w));
  for (double& v : out.w) v /= l;
  out.theta = to;
  out.cos = std::cos(to);
  return out;
}

bool light_prim(const Light& l, uint32_t index, Prim& p) {
  LightBounds b;  // each kind's own (light/kinds/)
  if (!light_bounds(l, max_component(l.radiance), b)) return false;
  if (!(b.phi > 0) || !std::isfinite(b.phi)) return false;
  for (int a = 0; a < 3; ++a) {
    p.v[a] = (&b.lo.x)[a];
    p.v[3 + a] = -(&b.hi.x)[a];
    p.v[6 + a] = (&b.w.x)[a];
    p.v[9 + a] = -(&b.w.x)[a];
  }
  p.v[12] = round_down(b.cos_o);
  p.v[13] = round_down(b.cos_e);
  p.v[14] = -round_up(std::acos(std::clamp(b.cos_e, -1.0, 1.0)));
  p.v[15] = static_cast<float>(b.phi);
  p.light = index | (b.two_sided ? kTwoSidedBit : 0u);
  return true;
}

NodeBounds leaf_bounds(const Prim& p) {
  NodeBounds b;
  for (int a = 0; a < 3; ++a) {
    b.lo[a] = p.lo(a);
    b.hi[a] = p.hi(a);
    b.cone.w[a] = p.v[6 + a];
  }
  // renormalized in double, so that the exact union's rotations start from unit vectors
  const double l = std::sqrt(dot3(b.cone.w, b.cone.w));
  for (double& v : b.cone.w) v /= l;
  const double cos_o = p.v[12];
  b.cone.cos = cos_o;
  b.cone.theta = cos_o >= 1 ? 0 : cos_o <= -1 ? kPi : std::acos(cos_o);
  b.cos_e = p.v[13];
  b.phi = p.v[15];
  b.two_sided = (p.light & kTwoSidedBit) != 0;
  return b;
}

NodeBounds bounds_union(const NodeBounds& a, const NodeBounds& b) {
  NodeBounds u;
  for (int i = 0; i < 3; ++i) {
    u.lo[i] = std::min(a.lo[i], b.lo[i]);
    u.hi[i] = std::max(a.hi[i], b.hi[i]);
  }
  u.cone = cone_union(a.cone, b.cone);
  u.cos_e = std::min(a.cos_e, b.cos_e);
  u.phi = a.phi + b.phi;
  u.two_sided = a.two_sided || b.two_sided;
  return u;
}

inline vfloat clamp1(const vfloat& x) { return xsimd::min(vfloat(1.f), xsimd::max(vfloat(-1.f), x)); }

void cone_measures(const Bucket* b, int count, float* out) {
  constexpr int W = simd_width;
  const float pi = static_cast<float>(kPi);
  for (int i = 0; i < count; i += W) {
    alignas(64) float cm_[W], wl_[3][W], wh_[3][W], ce_[W], te_[W], res[W];
    for (int l = 0; l < W; ++l) {
      const Bucket& q = b[std::min(i + l, count - 1)];
      cm_[l] = q.v[12], ce_[l] = q.v[13], te_[l] = -q.v[14];
      for (int a = 0; a < 3; ++a) wl_[a][l] = q.v[6 + a], wh_[a][l] = -q.v[9 + a];
    }
    const vfloat one(1.f), zero(0.f), minus1(-1.f);
    const vfloat cm = clamp1(vfloat::load_aligned(cm_));
    const vfloat ce = clamp1(vfloat::load_aligned(ce_)), theta_e = vfloat::load_aligned(te_);
    vfloat len2 = zero, lowest = zero;
    auto same = vfloat::load_aligned(wl_[0]) == vfloat::load_aligned(wh_[0]);
    for (int a = 0; a < 3; ++a) {
      const vfloat wl = vfloat::load_aligned(wl_[a]), wh = vfloat::load_aligned(wh_[a]), m = wl + wh;
      len2 = len2 + m * m;
      lowest = lowest + xsimd::min(m * wl, m * wh);
      same = same && wl == wh;
    }
    const auto has_axis = len2 > vfloat(1e-12f);
    const vfloat cb = sel(same, one, sel(has_axis, clamp1(lowest / xsimd::sqrt(sel(has_axis, len2, one))), minus1));
    const vfloat sm = xsimd::sqrt(xsimd::max(zero, one - cm * cm)), sb = xsimd::sqrt(xsimd::max(zero, one - cb * cb));
    const auto narrow = cb > -cm;  // theta_box + theta_o < pi
    const vfloat co = sel(narrow, clamp1(cb * cm - sb * sm), minus1);
    const vfloat so = sel(narrow, xsimd::max(zero, sb * cm + cb * sm), zero);
    const vfloat se = xsimd::sqrt(xsimd::max(zero, one - ce * ce));
    const vfloat ac = xsimd::abs(co);
    const vfloat r = xsimd::sqrt(xsimd::max(zero, one - ac)) * (vfloat(1.5707288f) + ac * (vfloat(-0.2121144f) + ac * (vfloat(0.0742610f) - vfloat(0.0187293f) * ac)));
    const vfloat theta_o = sel(co >= zero, r, vfloat(pi) - r);
    const vfloat wide = vfloat(2.f) * so * (vfloat(pi) - theta_o);
    const vfloat tight = vfloat(2.f) * theta_e * so - (co * (vfloat(2.f) * ce * ce - one) - so * (vfloat(2.f) * se * ce)) + co;
    const vfloat rest = sel(co <= -ce, wide, tight);
    const vfloat m = sel(cm <= minus1, vfloat(4 * pi), vfloat(2 * pi) * (one - co) + vfloat(pi / 2) * rest);
    m.store_aligned(res);
    std::copy(res, res + std::min(W, count - i), out + i);
  }
}

std::pair<int, int> SplitSearch::best() const {
  float m[kMaxSets];
  cone_measures(sets, nsets, m);
  double cost[kMaxSets];
  for (int i = 0; i < nsets; ++i) cost[i] = sets[i].phi * m[i] * sets[i].area();
  double lowest = INFINITY;
  std::pair<int, int> split{-1, 0};
  for (int i = 0; i < ncands; ++i) {
    const Cand& c = cands[i];
    const double v = (cost[c.left] + cost[c.right]) * c.kr;
    if (v < lowest) lowest = v, split = {c.axis, c.bucket};
  }
  return split;
}

}  // namespace tuile::light_bvh_detail
