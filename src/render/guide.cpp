// The path guide's learning: see guide.h.
#include "render/guide.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <bit>
#include <stdexcept>
#include <string>

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

void Guide::reset() {
  child_.assign(1, -1);
  axis_.assign(1, 0);
  split_.assign(1, 0.f);
  depth_ = 1;
  leaf_dist_.assign(guide_classes, -1);
  acc_.assign(guide_classes * guide_cells, 0);
  count_.assign(guide_classes, 0);
  func_.clear();
  cond_.clear();
  marg_.clear();
  learned_ = 0;
  refresh_view();
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

void guide_bilinear_cells(const Vec3<float>& d, int cell[4], float w[4]) noexcept {
  float pu, pv;
  equal_area_sphere_to_square(d, pu, pv);
  const float fu = pu * guide_res - 0.5f, fv = pv * guide_res - 0.5f;
  const float u0 = std::floor(fu), v0 = std::floor(fv), au = fu - u0, av = fv - v0;
  for (int k = 0; k < 4; ++k) {
    int cu = static_cast<int>(u0) + (k & 1), cv = static_cast<int>(v0) + (k >> 1);
    // past an edge of the square: the octahedral map folds it onto itself, mirrored
    if (cu < 0 || cu >= guide_res) {
      cu = cu < 0 ? 0 : guide_res - 1;
      cv = guide_res - 1 - cv;
    }
    if (cv < 0 || cv >= guide_res) {
      cv = cv < 0 ? 0 : guide_res - 1;
      cu = guide_res - 1 - cu;
    }
    cell[k] = cv * guide_res + cu;
    w[k] = ((k & 1) ? au : 1.f - au) * ((k >> 1) ? av : 1.f - av);
  }
}

void Guide::record(float x, float y, float z, int cls, float dx, float dy, float dz, float value) noexcept {
  if (!(value >= 0.f) || !std::isfinite(x + y + z + dx + dy + dz) || cls < 0 || cls >= guide_classes) return;
  const size_t slot = static_cast<size_t>(node_of(x, y, z)) * guide_classes + static_cast<size_t>(cls);
  int cell[4];
  float w[4];
  guide_bilinear_cells(Vec3<float>(dx, dy, dz), cell, w);
  const double v = static_cast<double>(std::min(value, max_value)) * fixed_scale;
  for (int k = 0; k < 4; ++k)
    if (const auto q = static_cast<uint64_t>(v * w[k] + 0.5))
      std::atomic_ref<uint64_t>(acc_[slot * guide_cells + static_cast<size_t>(cell[k])]).fetch_add(q, std::memory_order_relaxed);
  std::atomic_ref<uint64_t>(count_[slot]).fetch_add(1, std::memory_order_relaxed);
}

std::vector<uint64_t> Guide::records() const {
  std::vector<uint64_t> r(acc_);
  r.insert(r.end(), count_.begin(), count_.end());
  return r;
}

void Guide::set_records(const std::vector<uint64_t>& r) {
  if (r.size() != acc_.size() + count_.size())
    throw std::invalid_argument("the guide's records: " + std::to_string(r.size()) + " values where its tree holds " +
                                std::to_string(acc_.size() + count_.size()));
  std::copy(r.begin(), r.begin() + static_cast<std::ptrdiff_t>(acc_.size()), acc_.begin());
  std::copy(r.begin() + static_cast<std::ptrdiff_t>(acc_.size()), r.end(), count_.begin());
}

void Guide::drop_records() {
  std::fill(acc_.begin(), acc_.end(), 0);
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

// Leaf `id` with distribution dist and an estimated n records: split at the middle of its
// box's longest side while n exceeds the limit (each half estimated n / 2, with the same
// distribution).
void Guide::subdivide(int32_t id, const Dists& dist, double n, const Box& b, int depth, double limit) {
  depth_ = std::max(depth_, depth + 1);
  if (n <= limit || depth >= max_depth) {
    child_[static_cast<size_t>(id)] = -1;
    leaf_dist_.resize(child_.size() * guide_classes, -1);
    std::copy(dist.begin(), dist.end(), leaf_dist_.begin() + static_cast<ptrdiff_t>(id) * guide_classes);
    return;
  }
  int a = 0;
  for (int k = 1; k < 3; ++k)
    if (b.hi[k] - b.lo[k] > b.hi[a] - b.lo[a]) a = k;
  Box l, r;
  const int32_t c = split_node(id, a, 0.5f * (b.lo[a] + b.hi[a]), b, l, r);
  subdivide(c, dist, n / 2, l, depth + 1, limit);
  subdivide(c + 1, dist, n / 2, r, depth + 1, limit);
}

void Guide::rebuild_node(const std::vector<int32_t>& oc, const std::vector<int32_t>& oa, const std::vector<float>& os,
                         const std::vector<Dists>& odist, const std::vector<uint64_t>& ocount, int32_t old, int32_t id,
                         const Box& b, int depth, double limit) {
  const auto o = static_cast<size_t>(old);
  if (oc[o] < 0) {
    uint64_t n = 0;
    for (int c = 0; c < guide_classes; ++c) n += ocount[o * guide_classes + static_cast<size_t>(c)];
    subdivide(id, odist[o], static_cast<double>(n), b, depth, limit);
    return;
  }
  depth_ = std::max(depth_, depth + 1);
  Box l, r;
  const int32_t c = split_node(id, oa[o], os[o], b, l, r);
  rebuild_node(oc, oa, os, odist, ocount, oc[o], c, l, depth + 1, limit);
  rebuild_node(oc, oa, os, odist, ocount, oc[o] + 1, c + 1, r, depth + 1, limit);
}

void Guide::rebuild(uint32_t until) {
  // each old leaf's distribution from its records
  func_.clear();
  cond_.clear();
  marg_.clear();
  Dists none;
  none.fill(-1);
  std::vector<Dists> dist(child_.size(), none);
  for (size_t slot = 0; slot < child_.size() * guide_classes; ++slot) {
    const size_t n = slot / guide_classes;
    if (child_[n] >= 0 || count_[slot] < min_records) continue;
    double h[guide_cells];
    double total = 0;
    for (int c = 0; c < guide_cells; ++c) total += h[c] = static_cast<double>(acc_[slot * guide_cells + c]);
    if (!(total > 0)) continue;
    // a floor of 2% of the mean, so that no direction the records missed is left out
    const double floor = 0.02 * total / guide_cells, sum = total + floor * guide_cells;
    dist[n][slot % guide_classes] = distributions();
    double cum_rows = 0;
    marg_.push_back(0.f);
    for (int r = 0; r < guide_res; ++r) {
      double row = 0;
      for (int c = 0; c < guide_res; ++c) row += h[r * guide_res + c] + floor;
      double cum = 0;
      cond_.push_back(0.f);
      for (int c = 0; c < guide_res; ++c) {
        const double f = h[r * guide_res + c] + floor;
        func_.push_back(static_cast<float>(f * guide_cells / sum));
        cum += f;
        cond_.push_back(c + 1 == guide_res ? 1.f : static_cast<float>(cum / row));
      }
      cum_rows += row;
      marg_.push_back(r + 1 == guide_res ? 1.f : static_cast<float>(cum_rows / sum));
    }
  }
  // the new tree: the old one's splits, its leaves split further where they had many records
  const uint32_t begin = until <= 1 ? 0 : std::max(1u, std::bit_floor(until - 1));
  const double limit = split_records * std::sqrt(static_cast<double>(std::max(1u, until - begin)));
  const std::vector<int32_t> oc = child_, oa = axis_;
  leaf_dist_.clear();
  const std::vector<float> os = split_;
  const std::vector<uint64_t> ocount = count_;
  child_.assign(1, -1);
  axis_.assign(1, 0);
  split_.assign(1, 0.f);
  depth_ = 1;
  rebuild_node(oc, oa, os, dist, ocount, 0, 0, box_, 0, limit);
  leaf_dist_.resize(child_.size() * guide_classes, -1);
  acc_.assign(child_.size() * guide_classes * guide_cells, 0);
  count_.assign(child_.size() * guide_classes, 0);
  learned_ = until;
  refresh_view();
}

void Guide::refresh_view() {
  view_.depth = depth_;
  view_.child = child_.data();
  view_.axis = axis_.data();
  view_.split = split_.data();
  view_.leaf_dist = leaf_dist_.data();
  view_.func = func_.empty() ? nullptr : func_.data();
  view_.cond_cdf = cond_.empty() ? nullptr : cond_.data();
  view_.marg_cdf = marg_.empty() ? nullptr : marg_.data();
  view_.alpha = alpha_;
}

}  // namespace tuile
