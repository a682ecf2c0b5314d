// The light BVH's build: per-source bounds, pbrt-v4's split cost over 12 buckets per axis,
// a parallel recursive build into a depth-first layout fixed by the splits alone, and the
// nodes' bounds quantized conservatively (kernels/light/bvh.h's format).
//
// Speed (10^6 sources in about 1.3 s on one core): the split search never unions cones
// exactly. A bucket bounds its sources' cone axes by a box of directions and keeps the
// widest theta_o and theta_e; the cone of a set of buckets is then the box's cone (axis the
// box's centre, cosine the smallest dot product of that axis with the box's corners, a
// lower bound for every unit vector inside) widened by theta_o, and pbrt-v4's measure of it
// takes no trigonometry, computed for a whole node's candidates in SIMD batches. The 11
// splits of an axis take a prefix and a suffix sweep over the buckets; nodes of at most 16
// sources sort them by bucket instead and cost each distinct partition once. The sources
// are records that the build partitions in place (no gathers through an index), and the
// partition also bounds each side's centroids for the next level. The nodes' stored cones
// are still pbrt-v4's exact union, computed bottom-up from the children (2S unions).
#include "render/light_bvh.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "render/light_bvh_bounds.h"

namespace tuile {

namespace {

using namespace light_bvh_detail;

// Subtrees over more sources than this build their two children in parallel.
constexpr size_t kParallelSubtree = 4096;
// A node over more sources than this bins them in parallel, in chunks of kBinChunk whose
// partial buckets are added in chunk order (the same sums for any thread count).
constexpr size_t kParallelBin = size_t(1) << 16, kBinChunk = size_t(1) << 14;
// Nodes over at most this many sources search the same splits without buckets.
constexpr size_t kSmall = 16;

struct Builder {
  std::vector<Prim>& prims;
  LightBvh& out;

  void bin(size_t begin, size_t end, const float* clo, const float* cscale, Buckets& bk) const {
    for (size_t i = begin; i < end; ++i) {
      const Prim& p = prims[i];
      for (int a = 0; a < 3; ++a)
        if (cscale[a] > 0) bk.b[a][bucket_of(p, a, clo[a], cscale[a])].add(p);
    }
  }

  double inv_step[3] = {0, 0, 0};  // 1 / out.grid_step (0 where the step is 0)

  // Quantizes a grid coordinate outwards: the largest step at or below v (down) or the
  // smallest at or above it (up), as the kernel decodes them.
  uint32_t grid_q(float v, int a, bool up) const {
    const float lo = out.grid_lo[a], step = out.grid_step[a];
    const double t = (double(v) - lo) * inv_step[a];
    int32_t q = static_cast<int32_t>(std::clamp(up ? std::ceil(t) : std::floor(t), 0.0, 65535.0));
    if (up)
      while (q < 65535 && light_bvh_grid<float>(lo, step, q) < v) ++q;
    else
      while (q > 0 && light_bvh_grid<float>(lo, step, q) > v) --q;
    return static_cast<uint32_t>(q);
  }

  // The largest 15-bit cosine step at or below c.
  static uint32_t cos_q(double c) {
    int32_t q = static_cast<int32_t>(std::clamp(std::floor((c + 1) * (32767.0 / 2.0)), 0.0, 32767.0));
    while (q > 0 && double(light_bvh_cos<float>(q)) > c) --q;
    return static_cast<uint32_t>(q);
  }

  // The octahedral word of the unit vector w (each coordinate rounded to the nearest
  // step), and a bound on the angle between w and its decoding.
  static uint32_t axis_q(const double* w, double& err) {
    const double l1 = std::abs(w[0]) + std::abs(w[1]) + std::abs(w[2]);
    double x = w[0] / l1, y = w[1] / l1;
    if (w[2] < 0) {
      const double xf = (1 - std::abs(y)) * (x >= 0 ? 1 : -1), yf = (1 - std::abs(x)) * (y >= 0 ? 1 : -1);
      x = xf, y = yf;
    }
    const uint32_t word = static_cast<uint32_t>(std::clamp(std::nearbyint((x + 1) / 2 * 65535), 0.0, 65535.0)) |
                          static_cast<uint32_t>(std::clamp(std::nearbyint((y + 1) / 2 * 65535), 0.0, 65535.0)) << 16;
    const vec3f d = light_bvh_axis<float>(static_cast<int32_t>(word));
    double dd[3] = {d.x, d.y, d.z};
    const double l = std::sqrt(dot3(dd, dd));
    for (double& c : dd) c /= l;
    // the angle 2 asin(chord / 2); under a chord of 0.01 it exceeds the chord by at most
    // a factor 1 + 5e-6
    const double e[3] = {w[0] - dd[0], w[1] - dd[1], w[2] - dd[2]}, chord = std::sqrt(dot3(e, e));
    err = chord < 0.01 ? chord * (1 + 1e-5) : angle_between(w, dd);
    return word;
  }

  void write_node(int32_t k, const NodeBounds& b) {
    const size_t i = static_cast<size_t>(k);
    uint32_t* box[3] = {out.box_x.data(), out.box_y.data(), out.box_z.data()};
    for (int a = 0; a < 3; ++a) box[a][i] = grid_q(b.lo[a], a, false) | grid_q(b.hi[a], a, true) << 16;
    // the cone widened by its axis's encoding error (and 1e-6 for the kernel's float
    // arithmetic), then its cosine rounded down
    double err = 0;
    out.axis[i] = b.cone.theta >= kPi ? 0u : axis_q(b.cone.w, err);
    const double theta = b.cone.theta + err + 1e-6;
    // (1 - theta^2 / 2 is below cos theta, and within 5e-10 of it under 0.01)
    const uint32_t qo = theta >= kPi ? 0u : cos_q(theta < 0.01 ? 1 - theta * theta / 2 : std::cos(theta));
    out.cone[i] = qo | cos_q(b.cos_e) << 15 | (b.two_sided ? light_bvh_two_sided : 0u);
    out.phi[i] = static_cast<float>(b.phi);
  }

  // The split of sources [begin, end) (centroids bounded by cb) with pbrt-v4's least cost,
  // as (axis, bucket): sources in buckets below it go first; axis -1: none.
  std::pair<int, int> best_split(size_t begin, size_t end, const CentroidBox& cb, const float* cscale) const {
    const size_t n = end - begin;
    Buckets bk;
    if (n > kParallelBin) {
      const size_t chunks = (n + kBinChunk - 1) / kBinChunk;
      std::vector<Buckets> part(chunks);
      tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        bin(begin + c * kBinChunk, std::min(end, begin + (c + 1) * kBinChunk), cb.lo, cscale, part[c]);
      });
      for (const Buckets& p : part)
        for (int a = 0; a < 3; ++a)
          for (int k = 0; k < kBuckets; ++k)
            if (p.b[a][k].count) bk.b[a][k].add(p.b[a][k]);
    } else {
      bin(begin, end, cb.lo, cscale, bk);
    }
    // Kr (pbrt-v4): the node's largest extent over its extent on the split axis, against
    // thin slabs split across
    Bucket all = Bucket::none();
    for (int a = 0; a < 3; ++a)
      if (cscale[a] > 0) {
        for (const Bucket& b : bk.b[a]) all.add(b);
        break;
      }
    const double ext[3] = {double(all.hi(0)) - all.lo(0), double(all.hi(1)) - all.lo(1), double(all.hi(2)) - all.lo(2)};
    const double max_ext = std::max({ext[0], ext[1], ext[2]});
    SplitSearch search;
    for (int a = 0; a < 3; ++a) {
      if (!(cscale[a] > 0)) continue;
      const Bucket* b = bk.b[a];
      const double kr = ext[a] > 0 ? max_ext / ext[a] : 1;
      // the splits between non-empty buckets (the others repeat them): a suffix sweep,
      // then a prefix sweep
      int ks[kBuckets], m = 0;
      for (int k = 0; k < kBuckets; ++k)
        if (b[k].count) ks[m++] = k;
      if (m < 2) continue;
      const int first = search.nsets;  // the right sides, j = 1 .. m - 1
      search.nsets += m - 1;
      search.sets[first + m - 2] = b[ks[m - 1]];
      for (int j = m - 2; j >= 1; --j) {
        search.sets[first + j - 1] = search.sets[first + j];
        search.sets[first + j - 1].add(b[ks[j]]);
      }
      Bucket left = b[ks[0]];
      for (int j = 1; j < m; ++j) {
        if (j > 1) left.add(b[ks[j - 1]]);
        search.cands[search.ncands++] = {a, ks[j], search.add_set(left), first + j - 1, kr};
      }
    }
    return search.best();
  }

  // best_split for a node of at most kSmall sources, the same splits without the buckets'
  // overhead: on each axis the sources sorted by bucket, the splits between buckets, and
  // each partition's two costs computed once (a partition met again on another axis only
  // has another Kr).
  std::pair<int, int> best_split_small(size_t begin, size_t end, const CentroidBox& cb, const float* cscale) const {
    const int n = static_cast<int>(end - begin);
    SplitSearch search;  // sets 0 .. n - 1: the sources alone
    Bucket all = Bucket::none();
    for (int i = 0; i < n; ++i) {
      search.add_set(Bucket::of(prims[begin + static_cast<size_t>(i)]));
      all.add(search.sets[i]);
    }
    const double ext[3] = {double(all.hi(0)) - all.lo(0), double(all.hi(1)) - all.lo(1), double(all.hi(2)) - all.lo(2)};
    const double max_ext = std::max({ext[0], ext[1], ext[2]});
    uint32_t seen_mask[SplitSearch::kMaxCands];
    int seen_left[SplitSearch::kMaxCands], seen_right[SplitSearch::kMaxCands], seen = 0;
    for (int a = 0; a < 3; ++a) {
      if (!(cscale[a] > 0)) continue;
      const double kr = ext[a] > 0 ? max_ext / ext[a] : 1;
      int key[kSmall], ord[kSmall];
      for (int i = 0; i < n; ++i) {
        key[i] = bucket_of(prims[begin + static_cast<size_t>(i)], a, cb.lo[a], cscale[a]);
        int j = i;  // insertion sort by bucket, stable
        for (; j > 0 && key[ord[j - 1]] > key[i]; --j) ord[j] = ord[j - 1];
        ord[j] = i;
      }
      Bucket right[kSmall];  // right[t]: sources ord[t..n)
      right[n - 1] = search.sets[ord[n - 1]];
      for (int t = n - 2; t >= 1; --t) {
        right[t] = right[t + 1];
        right[t].add(search.sets[ord[t]]);
      }
      Bucket left = search.sets[ord[0]];
      uint32_t mask = 1u << ord[0];
      for (int t = 1; t < n; ++t) {
        if (t > 1) {
          left.add(search.sets[ord[t - 1]]);
          mask |= 1u << ord[t - 1];
        }
        if (key[ord[t]] == key[ord[t - 1]]) continue;
        const uint32_t id = mask & 1u ? mask : ~mask & ((1u << n) - 1);  // the side holding source 0
        int k = 0;
        while (k < seen && seen_mask[k] != id) ++k;
        if (k == seen) {
          seen_mask[seen] = id;
          seen_left[seen] = t == 1 ? ord[0] : search.add_set(left);
          seen_right[seen] = t == n - 1 ? ord[n - 1] : search.add_set(right[t]);
          ++seen;
        }
        search.cands[search.ncands++] = {a, key[ord[t]], seen_left[k], seen_right[k], kr};
      }
    }
    return search.best();
  }

  // Builds sources prims[begin, end) (centroids bounded by cb) into nodes [node, node +
  // 2 (end - begin) - 1); returns their exact bounds and the deepest leaf's depth.
  NodeBounds build(int32_t node, size_t begin, size_t end, const CentroidBox& cb, uint64_t trail, int depth, int& deepest) {
    const size_t n = end - begin;
    if (n == 1) {
      const Prim& p = prims[begin];
      const NodeBounds b = leaf_bounds(p);
      write_node(node, b);
      const uint32_t l = p.light & ~kTwoSidedBit;
      out.child[static_cast<size_t>(node)] = -1 - static_cast<int32_t>(l);
      out.trail_lo[l] = static_cast<uint32_t>(trail);
      out.trail_hi[l] = static_cast<uint32_t>(trail >> 32);
      deepest = depth;
      return b;
    }
    // the split: pbrt-v4's cost over 12 buckets per axis; the index median where the
    // centroids coincide, or where the depth must stay within the bit trail's 62 levels (a
    // cost split may leave n - 1 sources on one side: it is allowed while the levels left
    // below it could still halve them down to one)
    const int levels_left = light_bvh_max_depth - depth;
    const bool room = levels_left >= 1 && std::ldexp(1.0, levels_left - 1) >= static_cast<double>(n);
    float cscale[3];
    for (int a = 0; a < 3; ++a) {
      const float e = cb.hi[a] - cb.lo[a];
      cscale[a] = e > 0 ? static_cast<float>(kBuckets) / e : 0.f;
      if (!std::isfinite(cscale[a])) cscale[a] = 0.f;
    }
    std::pair<int, int> split{-1, 0};
    if (room && n > kSmall) split = best_split(begin, end, cb, cscale);
    else if (room && n > 2) split = best_split_small(begin, end, cb, cscale);
    size_t mid = begin + n / 2;
    CentroidBox cb0, cb1;
    if (split.first >= 0) {
      // partition in place (Hoare), bounding each side's centroids on the way
      const int a = split.first, s = split.second;
      auto first = [&](const Prim& p) { return bucket_of(p, a, cb.lo[a], cscale[a]) < s; };
      size_t i = begin, j = end;
      for (;;) {
        while (i < j && first(prims[i])) cb0.grow(prims[i++]);
        while (i < j && !first(prims[j - 1])) cb1.grow(prims[--j]);
        if (i >= j) break;
        std::swap(prims[i], prims[j - 1]);
        cb0.grow(prims[i++]);
        cb1.grow(prims[--j]);
      }
      mid = i;  // both sides hold sources: the buckets counted them
    } else {
      for (size_t i = begin; i < mid; ++i) cb0.grow(prims[i]);
      for (size_t i = mid; i < end; ++i) cb1.grow(prims[i]);
    }
    const size_t n0 = mid - begin;
    const int32_t c0 = node + 1, c1 = node + static_cast<int32_t>(2 * n0);
    NodeBounds b0, b1;
    int d0 = 0, d1 = 0;
    const uint64_t t1 = trail | (uint64_t(1) << depth);
    if (n > kParallelSubtree)
      tbb::parallel_invoke([&] { b0 = build(c0, begin, mid, cb0, trail, depth + 1, d0); },
                           [&] { b1 = build(c1, mid, end, cb1, t1, depth + 1, d1); });
    else {
      b0 = build(c0, begin, mid, cb0, trail, depth + 1, d0);
      b1 = build(c1, mid, end, cb1, t1, depth + 1, d1);
    }
    deepest = std::max(d0, d1);
    const NodeBounds b = bounds_union(b0, b1);
    write_node(node, b);
    out.child[static_cast<size_t>(node)] = c1;
    return b;
  }
};

}  // namespace

LightBvh build_light_bvh(const std::vector<Light>& lights) {
  LightBvh t;
  const size_t nl = lights.size();
  t.trail_lo.assign(nl, 0);
  t.trail_hi.assign(nl, light_bvh_outside);
  // every source's bounds, in parallel; then the tree's sources in light order
  std::vector<Prim> all(nl);
  std::vector<uint8_t> in_tree(nl, 0);
  tbb::parallel_for(size_t(0), nl, [&](size_t i) { in_tree[i] = light_prim(lights[i], static_cast<uint32_t>(i), all[i]); });
  std::vector<Prim> prims;
  prims.reserve(nl);
  for (size_t i = 0; i < nl; ++i) {
    if (in_tree[i]) prims.push_back(all[i]);
    else if (kind_info(lights[i].type).at_infinity && max_component(lights[i].radiance) > 0) {
      t.trail_hi[i] = light_bvh_outside | light_bvh_distant;
      t.distant_light.push_back(static_cast<int32_t>(i));
    }
  }
  std::vector<Prim>().swap(all);
  const size_t n = prims.size();
  const size_t nodes = n ? 2 * n - 1 : 0;
  for (auto* v : {&t.box_x, &t.box_y, &t.box_z, &t.axis, &t.cone}) v->assign(nodes, 0u);
  t.phi.assign(nodes, 0.f);
  t.child.assign(nodes, -1);
  if (n == 0) return t;
  // the grid of the nodes' boxes: the sources' box in 65535 steps, the step rounded up
  // until the last line holds the box
  CentroidBox cb;
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (const Prim& p : prims) {
    cb.grow(p);
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], p.lo(a));
      hi[a] = std::max(hi[a], p.hi(a));
    }
  }
  for (int a = 0; a < 3; ++a) {
    t.grid_lo[a] = lo[a];
    float step = round_up((double(hi[a]) - lo[a]) / 65535.0);
    if (step > 0)
      while (light_bvh_grid<float>(lo[a], step, 65535) < hi[a]) step = std::nextafter(step, INFINITY);
    t.grid_step[a] = step;
  }
  Builder b{prims, t};
  for (int a = 0; a < 3; ++a) b.inv_step[a] = t.grid_step[a] > 0 ? 1.0 / t.grid_step[a] : 0.0;
  b.build(0, 0, n, cb, 0, 0, t.depth);
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
  for (int a = 0; a < 3; ++a) v.grid_lo[a] = grid_lo[a], v.grid_step[a] = grid_step[a];
  v.box_x = box_x.data(), v.box_y = box_y.data(), v.box_z = box_z.data();
  v.axis = axis.data(), v.cone = cone.data();
  v.phi = phi.data();
  v.child = child.data();
  v.trail_lo = trail_lo.data(), v.trail_hi = trail_hi.data();
  return v;
}

size_t LightBvh::bytes() const {
  size_t b = 0;
  for (const auto* v : {&box_x, &box_y, &box_z, &axis, &cone, &trail_lo, &trail_hi}) b += v->size() * sizeof(uint32_t);
  return b + phi.size() * sizeof(float) + child.size() * sizeof(int32_t) + distant_light.size() * sizeof(int32_t);
}

}  // namespace tuile
