// The path guide's learning: see guide.h.
#include "render/guide.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <bit>

namespace tuile {

Guide::Guide(const float* lo, const float* hi, uint32_t learn, float alpha) : learn_(learn), alpha_(alpha) {
  for (int a = 0; a < 3; ++a) {
    const bool ok = std::isfinite(lo[a]) && std::isfinite(hi[a]) && lo[a] <= hi[a];
    // a little beyond the scene, so that points on its faces fall inside
    const float pad = ok ? 1e-3f * (hi[a] - lo[a]) + 1e-4f : 0.f;
    box_.lo[a] = ok ? lo[a] - pad : -1.f;
    box_.hi[a] = ok ? hi[a] + pad : 1.f;
  }
  reset();
}

namespace {

// A quadtree with its sums, read out of a guide's recording pool: per node (local indices,
// four children side by side) its first child or -1, its depth and its records' sum.
struct SummedQuad {
  std::vector<int32_t> child, depth;
  std::vector<double> sum;
};

void read_quad(const std::vector<int32_t>& pool_child, const std::vector<uint64_t>& pool_acc, int32_t g, int32_t l,
               SummedQuad& t) {
  const int32_t c = pool_child[static_cast<size_t>(g)];
  if (c < 0) {
    t.sum[static_cast<size_t>(l)] = static_cast<double>(pool_acc[static_cast<size_t>(g)]);
    return;
  }
  const auto first = static_cast<int32_t>(t.child.size());
  t.child[static_cast<size_t>(l)] = first;
  const int32_t d = t.depth[static_cast<size_t>(l)] + 1;
  t.child.insert(t.child.end(), 4, -1);
  t.depth.insert(t.depth.end(), 4, d);
  t.sum.insert(t.sum.end(), 4, 0.0);
  double s = 0;
  for (int32_t q = 0; q < 4; ++q) {
    read_quad(pool_child, pool_acc, c + q, first + q, t);
    s += t.sum[static_cast<size_t>(first + q)];
  }
  t.sum[static_cast<size_t>(l)] = s;
}

// A quadtree every cell of which is `depth` deep.
void uniform_quad(std::vector<int32_t>& child, int32_t l, int depth) {
  if (depth == 0) return;
  const auto first = static_cast<int32_t>(child.size());
  child[static_cast<size_t>(l)] = first;
  child.insert(child.end(), 4, -1);
  for (int32_t q = 0; q < 4; ++q) uniform_quad(child, first + q, depth - 1);
}

// The tree the next iteration records into (Müller et al. 2017): a cell splits while its
// share of the light (its sum, or its parent's over four where this iteration's tree had no
// cell so fine) exceeds `share`; finer cells of the old tree whose share fell below it merge.
void refine_quad(const SummedQuad& t, int32_t l, double sum, double total, int depth, double share,
                 std::vector<int32_t>& out, int32_t o) {
  if (!(sum > share * total) || depth >= guide_quad_depth) return;
  const auto first = static_cast<int32_t>(out.size());
  out[static_cast<size_t>(o)] = first;
  out.insert(out.end(), 4, -1);
  const int32_t c = l >= 0 ? t.child[static_cast<size_t>(l)] : -1;
  for (int32_t q = 0; q < 4; ++q)
    refine_quad(t, c >= 0 ? c + q : -1, c >= 0 ? t.sum[static_cast<size_t>(c + q)] : sum / 4, total, depth + 1, share,
                out, first + q);
}

}  // namespace

void Guide::reset() {
  child_.assign(1, -1);
  axis_.assign(1, 0);
  split_.assign(1, 0.f);
  depth_ = 1;
  leaf_dist_.assign(guide_classes, -1);
  quads_.assign(1, Quad(1, -1));
  uniform_quad(quads_[0], 0, start_depth);
  Quads all;
  all.fill(0);
  leaf_rec_.assign(1, all);
  install_records();
  root_.clear();
  qchild_.clear();
  qshare_.clear();
  qdepth_ = 0;
  learned_ = 0;
  refresh_view();
}

// Lays the leaves' recording trees (quads_, by leaf_rec_) out in the pool, empty.
void Guide::install_records() {
  const size_t slots = child_.size() * guide_classes;
  rec_root_.assign(slots, -1);
  rec_child_.clear();
  for (size_t n = 0; n < child_.size(); ++n) {
    if (child_[n] >= 0) continue;
    for (int c = 0; c < guide_classes; ++c) {
      const Quad& q = quads_[static_cast<size_t>(leaf_rec_[n][static_cast<size_t>(c)])];
      const auto off = static_cast<int32_t>(rec_child_.size());
      rec_root_[n * guide_classes + static_cast<size_t>(c)] = off;
      for (const int32_t k : q) rec_child_.push_back(k >= 0 ? k + off : -1);
    }
  }
  rec_acc_.assign(rec_child_.size(), 0);
  count_.assign(slots, 0);
  quads_.clear();
  leaf_rec_.clear();
}

uint32_t Guide::iteration_end(uint32_t s) const noexcept {
  uint32_t b = 1;
  while (b <= s && b < learn_) b *= 2;
  return std::min(b, learn_);
}

int Guide::node_of(float x, float y, float z) const noexcept {
  int32_t n = 0;
  while (child_[static_cast<size_t>(n)] >= 0) {
    const int a = axis_[static_cast<size_t>(n)];
    const float c = a == 0 ? x : a == 1 ? y : z;
    n = child_[static_cast<size_t>(n)] + (c >= split_[static_cast<size_t>(n)] ? 1 : 0);
  }
  return n;
}

int Guide::leaves() const noexcept {
  return static_cast<int>(std::count_if(child_.begin(), child_.end(), [](int32_t c) { return c < 0; }));
}

void Guide::record(float x, float y, float z, float nx, float ny, float nz, float dx, float dy, float dz,
                   float value) noexcept {
  if (!(value >= 0.f) || !std::isfinite(x + y + z + dx + dy + dz + nx + ny + nz)) return;
  const size_t n = static_cast<size_t>(node_of(x, y, z)) * guide_classes +
                   static_cast<size_t>(guide_class<float>(Vec3<float>(nx, ny, nz)));
  float pu, pv;
  equal_area_sphere_to_square(Vec3<float>(dx, dy, dz), pu, pv);
  int32_t cell = rec_root_[n];
  while (rec_child_[static_cast<size_t>(cell)] >= 0) {
    const int hu = pu >= 0.5f ? 1 : 0, hv = pv >= 0.5f ? 1 : 0;
    pu = 2.f * pu - static_cast<float>(hu);
    pv = 2.f * pv - static_cast<float>(hv);
    cell = rec_child_[static_cast<size_t>(cell)] + hu + 2 * hv;
  }
  const auto q = static_cast<uint64_t>(static_cast<double>(std::min(value, max_value)) * fixed_scale + 0.5);
  std::atomic_ref<uint64_t>(rec_acc_[static_cast<size_t>(cell)]).fetch_add(q, std::memory_order_relaxed);
  std::atomic_ref<uint64_t>(count_[n]).fetch_add(1, std::memory_order_relaxed);
}

void Guide::drop_records() {
  std::fill(rec_acc_.begin(), rec_acc_.end(), 0);
  std::fill(count_.begin(), count_.end(), 0);
}

int32_t Guide::alloc_pair() {
  const auto c = static_cast<int32_t>(child_.size());
  child_.insert(child_.end(), 2, -1);
  axis_.insert(axis_.end(), 2, 0);
  split_.insert(split_.end(), 2, 0.f);
  return c;
}

// Makes node id an inner node split at `mid` along axis a: returns its first child (the two
// side by side) and their boxes l and r.
int32_t Guide::split_node(int32_t id, int a, float mid, const Box& b, Box& l, Box& r) {
  const int32_t c = alloc_pair();
  child_[static_cast<size_t>(id)] = c;
  axis_[static_cast<size_t>(id)] = a;
  split_[static_cast<size_t>(id)] = mid;
  l = b;
  r = b;
  l.hi[a] = mid;
  r.lo[a] = mid;
  return c;
}

void Guide::make_leaf(int32_t id, const Dists& dist, const Quads& rec) {
  child_[static_cast<size_t>(id)] = -1;
  leaf_dist_.resize(child_.size() * guide_classes, -1);
  std::copy(dist.begin(), dist.end(), leaf_dist_.begin() + static_cast<ptrdiff_t>(id) * guide_classes);
  Quads none;
  none.fill(-1);
  leaf_rec_.resize(child_.size(), none);
  leaf_rec_[static_cast<size_t>(id)] = rec;
}

// Leaf `id` with distributions dist, recording trees rec and an estimated n records: split
// at the middle of its box's longest side while n exceeds the limit (each half estimated
// n / 2, with the same distributions and recording trees).
void Guide::subdivide(int32_t id, const Dists& dist, const Quads& rec, double n, const Box& b, int depth,
                      double limit) {
  depth_ = std::max(depth_, depth + 1);
  if (n <= limit || depth >= max_depth) {
    make_leaf(id, dist, rec);
    return;
  }
  int a = 0;
  for (int k = 1; k < 3; ++k)
    if (b.hi[k] - b.lo[k] > b.hi[a] - b.lo[a]) a = k;
  Box l, r;
  const int32_t c = split_node(id, a, 0.5f * (b.lo[a] + b.hi[a]), b, l, r);
  subdivide(c, dist, rec, n / 2, l, depth + 1, limit);
  subdivide(c + 1, dist, rec, n / 2, r, depth + 1, limit);
}

void Guide::rebuild_node(const std::vector<int32_t>& oc, const std::vector<int32_t>& oa, const std::vector<float>& os,
                         const std::vector<Dists>& odist, const std::vector<Quads>& orec,
                         const std::vector<uint64_t>& ocount, int32_t old, int32_t id, const Box& b, int depth,
                         double limit) {
  const auto o = static_cast<size_t>(old);
  if (oc[o] < 0) {
    uint64_t n = 0;
    for (int c = 0; c < guide_classes; ++c) n += ocount[o * guide_classes + static_cast<size_t>(c)];
    subdivide(id, odist[o], orec[o], static_cast<double>(n), b, depth, limit);
    return;
  }
  depth_ = std::max(depth_, depth + 1);
  Box l, r;
  const int32_t c = split_node(id, oa[o], os[o], b, l, r);
  rebuild_node(oc, oa, os, odist, orec, ocount, oc[o], c, l, depth + 1, limit);
  rebuild_node(oc, oa, os, odist, orec, ocount, oc[o] + 1, c + 1, r, depth + 1, limit);
}

void Guide::rebuild(uint32_t until) {
  // each old leaf's distributions from its records, and the trees the next iteration records into
  root_.clear();
  qchild_.clear();
  qshare_.clear();
  qdepth_ = 0;
  quads_.clear();
  Dists none;
  none.fill(-1);
  std::vector<Dists> dist(child_.size(), none);
  std::vector<Quads> rec(child_.size(), none);
  for (size_t slot = 0; slot < child_.size() * guide_classes; ++slot) {
    const size_t n = slot / guide_classes, cls = slot % guide_classes;
    if (child_[n] >= 0) continue;
    SummedQuad t;
    t.child.assign(1, -1);
    t.depth.assign(1, 0);
    t.sum.assign(1, 0.0);
    read_quad(rec_child_, rec_acc_, rec_root_[slot], 0, t);
    const double total = t.sum[0];
    rec[n][cls] = static_cast<int32_t>(quads_.size());
    if (count_[slot] >= min_records && total > 0) {
      // the distribution: each cell's share of the light, plus a floor (floor_share of it,
      // spread by area) so that no direction the records missed is left out
      dist[n][cls] = distributions();
      const auto off = static_cast<int32_t>(qchild_.size());
      root_.push_back(off);
      const double fl = floor_share * total;
      auto energy = [&](size_t k) { return t.sum[k] + fl * std::ldexp(1.0, -2 * t.depth[k]); };
      for (size_t k = 0; k < t.child.size(); ++k) {
        const int32_t c = t.child[k];
        qchild_.push_back(c >= 0 ? c + off : -1);
        const double e = energy(k);
        for (int32_t q = 0; q < 4; ++q)
          qshare_.push_back(c >= 0 ? static_cast<float>(energy(static_cast<size_t>(c + q)) / e) : 0.f);
        qdepth_ = std::max(qdepth_, t.depth[k]);
      }
      Quad next(1, -1);
      refine_quad(t, 0, total, total, 0, quad_split, next, 0);
      quads_.push_back(std::move(next));
    } else if (count_[slot] == 0) {
      Quad next(1, -1);  // nothing recorded here: a coarse tree, so that empty classes cost little
      uniform_quad(next, 0, 2);
      quads_.push_back(std::move(next));
    } else {
      quads_.push_back(std::move(t.child));  // too few records to refine by: the same cells again
    }
  }
  // the new tree: the old one's splits, its leaves split further where they had many records
  const uint32_t begin = until <= 1 ? 0 : std::max(1u, std::bit_floor(until - 1));
  const double limit = split_records * std::sqrt(static_cast<double>(std::max(1u, until - begin)));
  const std::vector<int32_t> oc = child_, oa = axis_;
  leaf_dist_.clear();
  leaf_rec_.clear();
  const std::vector<float> os = split_;
  const std::vector<uint64_t> ocount = count_;
  child_.assign(1, -1);
  axis_.assign(1, 0);
  split_.assign(1, 0.f);
  depth_ = 1;
  rebuild_node(oc, oa, os, dist, rec, ocount, 0, 0, box_, 0, limit);
  leaf_dist_.resize(child_.size() * guide_classes, -1);
  install_records();
  learned_ = until;
  refresh_view();
}

void Guide::refresh_view() {
  view_.depth = depth_;
  view_.child = child_.data();
  view_.axis = axis_.data();
  view_.split = split_.data();
  view_.leaf_dist = leaf_dist_.data();
  view_.root = root_.empty() ? nullptr : root_.data();
  view_.quad_child = qchild_.empty() ? nullptr : qchild_.data();
  view_.quad_share = qshare_.empty() ? nullptr : qshare_.data();
  view_.quad_depth = qdepth_;
  view_.alpha = alpha_;
}

}  // namespace tuile
