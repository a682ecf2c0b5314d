// The light BVH's build: per-source bounds, pbrt-v4's split cost, a parallel recursive
// build into a depth-first layout fixed by the splits alone.
#include "render/light_bvh.h"

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <numeric>

namespace tuile {

namespace {

constexpr double kPi = 3.14159265358979323846;

// A cone of directions: axis w (unit), cos of its half-angle; cos = -1 is every direction,
// and empty() a cone that holds none (the union's identity).
struct Cone {
  double w[3] = {0, 0, 1};
  double cos = 2;  // > 1: empty
  bool empty() const { return cos > 1; }
};

struct Bounds {
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  Cone cone;
  double cos_e = 1;  // cos theta_e (the emission beyond the cone; pi/2 for area sources)
  double phi = 0;
  bool two_sided = false;

  void grow(const vec3f& p) {
    const double q[3] = {p.x, p.y, p.z};
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], q[a]);
      hi[a] = std::max(hi[a], q[a]);
    }
  }
  double centroid(int a) const { return 0.5 * (lo[a] + hi[a]); }
  double area() const {
    const double d[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
    return 2 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0]);
  }
};

double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double angle_between(const double* a, const double* b) {
  // numerically careful for nearly equal or opposite vectors (pbrt's AngleBetween)
  if (dot3(a, b) < 0) {
    const double s[3] = {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
    return kPi - 2 * std::asin(std::min(1.0, std::sqrt(dot3(s, s)) / 2));
  }
  const double d[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
  return 2 * std::asin(std::min(1.0, std::sqrt(dot3(d, d)) / 2));
}

// The smallest cone (of this construction) holding both (pbrt-v4's DirectionCone Union).
Cone cone_union(const Cone& a, const Cone& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  // the same axis (many sources share a plane): the wider cone, without trigonometry
  if (a.w[0] == b.w[0] && a.w[1] == b.w[1] && a.w[2] == b.w[2]) return a.cos <= b.cos ? a : b;
  const double ta = std::acos(std::clamp(a.cos, -1.0, 1.0)), tb = std::acos(std::clamp(b.cos, -1.0, 1.0));
  const double td = angle_between(a.w, b.w);
  if (std::min(td + tb, kPi) <= ta) return a;
  if (std::min(td + ta, kPi) <= tb) return b;
  const double to = (ta + td + tb) / 2;
  Cone all;
  all.cos = -1;
  if (to >= kPi) return all;
  const double tr = to - ta;
  double axis[3] = {a.w[1] * b.w[2] - a.w[2] * b.w[1], a.w[2] * b.w[0] - a.w[0] * b.w[2], a.w[0] * b.w[1] - a.w[1] * b.w[0]};
  const double len = std::sqrt(dot3(axis, axis));
  if (!(len > 0)) return all;
  for (double& v : axis) v /= len;
  // Rodrigues: rotate a.w by tr about axis
  const double c = std::cos(tr), s = std::sin(tr), k = dot3(axis, a.w);
  const double cr[3] = {axis[1] * a.w[2] - axis[2] * a.w[1], axis[2] * a.w[0] - axis[0] * a.w[2],
                        axis[0] * a.w[1] - axis[1] * a.w[0]};
  Cone out;
  for (int i = 0; i < 3; ++i) out.w[i] = a.w[i] * c + cr[i] * s + axis[i] * k * (1 - c);
  const double l = std::sqrt(dot3(out.w, out.w));
  for (double& v : out.w) v /= l;
  out.cos = std::cos(to);
  return out;
}

Bounds bounds_union(const Bounds& a, const Bounds& b) {
  if (a.phi == 0) return b;
  if (b.phi == 0) return a;
  Bounds u;
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

// pbrt-v4's solid-angle measure of a cone of normals and its emission (M_Omega), for the
// split cost.
double cone_measure(const Bounds& b) {
  const double to = std::acos(std::clamp(b.cone.cos, -1.0, 1.0)), te = std::acos(std::clamp(b.cos_e, -1.0, 1.0));
  const double tw = std::min(to + te, kPi), so = std::sin(to);
  return 2 * kPi * (1 - std::cos(to)) + kPi / 2 * (2 * tw * so - std::cos(to - 2 * tw) - 2 * to * so + std::cos(to));
}

double max_component(const Rgb& c) { return std::max({c.r, c.g, c.b}); }

// A source's bounds as pbrt-v4's lights give them (its Bounds()); phi = 0: never picked.
Bounds light_bounds(const Light& l) {
  Bounds b;
  const double L = max_component(l.radiance);
  switch (l.type) {
    case LightType::triangle:
    case LightType::parallelogram: {
      b.grow(l.p0);
      b.grow(l.p0 + l.e1);
      b.grow(l.p0 + l.e2);
      if (l.type == LightType::parallelogram) b.grow(l.p0 + l.e1 + l.e2);
      const vec3f n = normalize(cross(l.e1, l.e2));
      b.cone.w[0] = n.x, b.cone.w[1] = n.y, b.cone.w[2] = n.z;
      b.cone.cos = 1;
      b.cos_e = 0;  // cos(pi / 2)
      b.two_sided = l.two_sided;
      b.phi = L * l.area * kPi * (l.two_sided ? 2 : 1);
      break;
    }
    case LightType::sphere: {
      const float r = l.e1.x;
      b.grow(l.p0 - vec3f{r, r, r});
      b.grow(l.p0 + vec3f{r, r, r});
      b.cone.cos = -1;
      b.cos_e = 0;
      b.phi = L * 4 * kPi * double(r) * r * kPi;
      break;
    }
    case LightType::point:
      b.grow(l.p0);
      b.cone.cos = -1;
      b.cos_e = 0;
      b.phi = 4 * kPi * L;
      break;
    case LightType::spot: {
      b.grow(l.p0);
      b.cone.w[0] = l.e1.x, b.cone.w[1] = l.e1.y, b.cone.w[2] = l.e1.z;
      const double cs = std::clamp(double(l.e2.x), -1.0, 1.0), ce = std::clamp(double(l.e2.y), -1.0, 1.0);
      b.cone.cos = cs;
      b.cos_e = std::cos(std::acos(ce) - std::acos(cs));
      b.phi = 4 * kPi * L;  // pbrt-v4's (an overestimate, as its comment says)
      break;
    }
    case LightType::distant:
      break;  // not in the tree
  }
  if (!(b.phi > 0) || !std::isfinite(b.phi)) b.phi = 0;
  return b;
}

struct Builder {
  const std::vector<Bounds>& lb;
  std::vector<int32_t>& order;  // the tree's sources, reordered by the splits
  LightBvh& out;

  // pbrt-v4's cost of a node: phi M_Omega Kr area (Kr: the box's largest extent over its
  // extent on the split axis, against thin slabs split across).
  static double cost(const Bounds& b, const Bounds& parent, int axis) {
    const double ext[3] = {parent.hi[0] - parent.lo[0], parent.hi[1] - parent.lo[1], parent.hi[2] - parent.lo[2]};
    const double kr = ext[axis] > 0 ? std::max({ext[0], ext[1], ext[2]}) / ext[axis] : 1;
    return b.phi * cone_measure(b) * kr * b.area();
  }

  void write_node(int32_t k, const Bounds& b) {
    const size_t i = static_cast<size_t>(k);
    const double c[3] = {b.centroid(0), b.centroid(1), b.centroid(2)};
    const double d[3] = {b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]};
    out.cx[i] = static_cast<float>(c[0]);
    out.cy[i] = static_cast<float>(c[1]);
    out.cz[i] = static_cast<float>(c[2]);
    // the sphere must hold the box after the centre's rounding: radius rounded up, plus
    // the centre's error
    const double err = std::max({std::abs(c[0] - out.cx[i]), std::abs(c[1] - out.cy[i]), std::abs(c[2] - out.cz[i])});
    out.radius[i] = std::nextafter(static_cast<float>(0.5 * std::sqrt(dot3(d, d)) + std::sqrt(3.0) * err), INFINITY);
    out.wx[i] = static_cast<float>(b.cone.w[0]);
    out.wy[i] = static_cast<float>(b.cone.w[1]);
    out.wz[i] = static_cast<float>(b.cone.w[2]);
    out.phi[i] = static_cast<float>(b.phi);
    // cosines rounded down: cones only widen (and a rounded axis is covered by 1e-6)
    out.cos_o[i] = b.cone.cos >= 1 ? 1.f : std::max(-1.f, static_cast<float>(b.cone.cos - 1e-6));
    out.cos_e[i] = std::max(-1.f, static_cast<float>(b.cos_e - 1e-6));
    out.two_sided[i] = b.two_sided ? 1.f : 0.f;
  }

  // Builds sources order[begin, end) into nodes [node, node + 2 (end - begin) - 1); returns
  // their bounds.
  Bounds build(int32_t node, size_t begin, size_t end, uint64_t trail, int depth) {
    const size_t n = end - begin;
    if (n == 1) {
      const int32_t l = order[begin];
      const Bounds& b = lb[static_cast<size_t>(l)];
      write_node(node, b);
      out.child[static_cast<size_t>(node)] = -1 - l;
      out.trail_lo[static_cast<size_t>(l)] = static_cast<uint32_t>(trail);
      out.trail_hi[static_cast<size_t>(l)] = static_cast<uint32_t>(trail >> 32);
      return b;
    }
    Bounds all, centroids;
    for (size_t i = begin; i < end; ++i) {
      const Bounds& b = lb[static_cast<size_t>(order[i])];
      all = bounds_union(all, b);
      for (int a = 0; a < 3; ++a) {
        centroids.lo[a] = std::min(centroids.lo[a], b.centroid(a));
        centroids.hi[a] = std::max(centroids.hi[a], b.centroid(a));
      }
    }
    // the split: pbrt-v4's cost over 12 buckets per axis; the index median where the
    // centroids coincide, or where the depth must stay within the bit trail's 64 levels
    size_t mid = begin + n / 2;
    // (a cost split may leave n - 1 sources on one side: it is allowed while the levels
    // left below it could still halve them down to one)
    const int levels_left = 63 - depth;
    const bool room = levels_left >= 1 && std::ldexp(1.0, levels_left - 1) >= static_cast<double>(n);
    int best_axis = -1;
    double best_split = 0;
    if (room) {
      constexpr int nb = 12;
      double best = INFINITY;
      for (int a = 0; a < 3; ++a) {
        const double lo = centroids.lo[a], hi = centroids.hi[a];
        if (!(hi > lo)) continue;
        Bounds bucket[nb];
        for (size_t i = begin; i < end; ++i) {
          const Bounds& b = lb[static_cast<size_t>(order[i])];
          const int k = std::min(nb - 1, static_cast<int>(nb * ((b.centroid(a) - lo) / (hi - lo))));
          bucket[k] = bounds_union(bucket[k], b);
        }
        for (int s = 1; s < nb; ++s) {
          Bounds l, r;
          for (int k = 0; k < s; ++k) l = bounds_union(l, bucket[k]);
          for (int k = s; k < nb; ++k) r = bounds_union(r, bucket[k]);
          if (l.phi == 0 && r.phi == 0) continue;
          const double c = cost(l, all, a) + cost(r, all, a);
          if (c < best) {
            best = c;
            best_axis = a;
            best_split = lo + (hi - lo) * s / nb;
          }
        }
      }
    }
    if (best_axis >= 0) {
      const auto first = order.begin() + static_cast<std::ptrdiff_t>(begin), last = order.begin() + static_cast<std::ptrdiff_t>(end);
      const auto m = std::stable_partition(first, last, [&](int32_t l) { return lb[static_cast<size_t>(l)].centroid(best_axis) < best_split; });
      const size_t k = static_cast<size_t>(m - order.begin());
      if (k > begin && k < end) mid = k;
    }
    const size_t n0 = mid - begin;
    const int32_t c0 = node + 1, c1 = node + static_cast<int32_t>(2 * n0);
    Bounds b0, b1;
    const uint64_t t1 = trail | (uint64_t(1) << depth);
    if (n > 4096)
      tbb::parallel_invoke([&] { b0 = build(c0, begin, mid, trail, depth + 1); },
                           [&] { b1 = build(c1, mid, end, t1, depth + 1); });
    else {
      b0 = build(c0, begin, mid, trail, depth + 1);
      b1 = build(c1, mid, end, t1, depth + 1);
    }
    const Bounds b = bounds_union(b0, b1);
    write_node(node, b);
    out.child[static_cast<size_t>(node)] = c1;
    return b;
  }
};

int tree_depth(const LightBvh& t, int32_t node, int d) {
  const int32_t c = t.child[static_cast<size_t>(node)];
  if (c < 0) return d;
  return std::max(tree_depth(t, node + 1, d + 1), tree_depth(t, c, d + 1));
}

}  // namespace

LightBvh build_light_bvh(const std::vector<Light>& lights) {
  LightBvh t;
  const size_t nl = lights.size();
  std::vector<Bounds> lb(nl);
  t.where.assign(nl, 0);
  t.trail_lo.assign(nl, 0);
  t.trail_hi.assign(nl, 0);
  std::vector<int32_t> order;
  for (size_t i = 0; i < nl; ++i) {
    if (lights[i].type == LightType::distant) {
      if (max_component(lights[i].radiance) > 0) {
        t.where[i] = 2;
        t.distant_light.push_back(static_cast<int32_t>(i));
      }
      continue;
    }
    lb[i] = light_bounds(lights[i]);
    if (lb[i].phi > 0) {
      t.where[i] = 1;
      order.push_back(static_cast<int32_t>(i));
    }
  }
  const size_t n = order.size();
  const size_t nodes = n ? 2 * n - 1 : 0;
  for (auto* v : {&t.cx, &t.cy, &t.cz, &t.radius, &t.wx, &t.wy, &t.wz, &t.phi, &t.cos_o, &t.cos_e, &t.two_sided})
    v->assign(nodes, 0.f);
  t.child.assign(nodes, -1);
  if (n > 0) {
    Builder b{lb, order, t};
    b.build(0, 0, n, 0, 0);
    t.depth = tree_depth(t, 0, 0);
  }
  return t;
}

LightBvhView LightBvh::view() const {
  LightBvhView v;
  v.nodes = static_cast<int32_t>(child.size());
  v.distant = static_cast<int32_t>(distant_light.size());
  v.distant_light = distant_light.data();
  v.p_distant = distant_light.empty() ? 0.f
                : child.empty()        ? 1.f
                                       : static_cast<float>(distant_light.size()) / static_cast<float>(distant_light.size() + 1);
  v.cx = cx.data(), v.cy = cy.data(), v.cz = cz.data(), v.radius = radius.data();
  v.wx = wx.data(), v.wy = wy.data(), v.wz = wz.data();
  v.phi = phi.data(), v.cos_o = cos_o.data(), v.cos_e = cos_e.data(), v.two_sided = two_sided.data();
  v.child = child.data();
  v.trail_lo = trail_lo.data(), v.trail_hi = trail_hi.data();
  v.where = where.data();
  return v;
}

size_t LightBvh::bytes() const {
  size_t b = 0;
  for (const auto* v : {&cx, &cy, &cz, &radius, &wx, &wy, &wz, &phi, &cos_o, &cos_e, &two_sided}) b += v->size() * sizeof(float);
  b += child.size() * sizeof(int32_t) + trail_lo.size() * 8 + where.size() * 4 + distant_light.size() * 4;
  return b;
}

}  // namespace tuile
