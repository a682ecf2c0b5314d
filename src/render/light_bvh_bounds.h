// The light BVH's build, its parts (src/render/light_bvh.cpp builds the tree from them):
// cones of directions and their union, a source's bounds and its record for the split
// search (Prim), nodes' exact bounds, and the buckets and candidate splits of pbrt-v4's
// split cost with its solid-angle measure of emission in SIMD batches. Internal to the
// build (light_bvh.cpp, light_bvh_bounds.cpp).
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

#include "lanes/simd.h"
#include "scene/scene.h"

namespace tuile::light_bvh_detail {

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr int kBuckets = 12;

// A cone of directions: axis w (unit), its half-angle theta and cos theta; theta = pi is
// every direction, and empty() a cone that holds none (the union's identity).
struct Cone {
  double w[3] = {0, 0, 1};
  double cos = 2;  // > 1: empty
  double theta = 0;
  bool empty() const { return cos > 1; }
  static Cone all() {
    Cone c;
    c.cos = -1;
    c.theta = kPi;
    return c;
  }
};

inline double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
// The angle between two unit vectors (numerically careful near 0 and pi).
double angle_between(const double* a, const double* b);
// The smallest cone (of this construction) holding both (pbrt-v4's DirectionCone Union).
Cone cone_union(const Cone& a, const Cone& b);

// A source as the split search reads it (68 bytes, partitioned in place by the build): 16
// floats that a bucket takes the minimum of, lane by lane (maxima negated), so that adding
// a source to a bucket is one to four SIMD minima:
//   0-2 box min, 3-5 -box max, 6-8 cone axis w, 9-11 -w, 12 cos theta_o, 13 cos theta_e
//   (both rounded down), 14 -theta_e (rounded up), 15 power phi (the buckets sum it apart
//   and leave their lane 15 unread);
// then the light's index, bit 31: two-sided.
struct Prim {
  float v[16];
  uint32_t light;
  float lo(int a) const { return v[a]; }
  float hi(int a) const { return -v[3 + a]; }
  float centroid(int a) const { return 0.5f * (v[a] - v[3 + a]); }
};
inline constexpr uint32_t kTwoSidedBit = 0x80000000u;

// dst = min(dst, src) over 16 floats.
inline void min16(float* dst, const float* src) {
  for (int k = 0; k < 16; k += simd_width)
    xsimd::min(vfloat::load_unaligned(dst + k), vfloat::load_unaligned(src + k)).store_unaligned(dst + k);
}

inline float round_down(double v) {
  const float f = static_cast<float>(v);
  return static_cast<double>(f) > v ? std::nextafter(f, -INFINITY) : f;
}
inline float round_up(double v) {
  const float f = static_cast<float>(v);
  return static_cast<double>(f) < v ? std::nextafter(f, INFINITY) : f;
}

inline double max_component(const Rgb& c) { return std::max({c.r, c.g, c.b}); }

// A source's bounds as pbrt-v4's lights give them (its Bounds()); false: never picked (no
// power, or a distant source).
bool light_prim(const Light& l, uint32_t index, Prim& p);

// A node's exact bounds (the union of its sources'), before quantization.
struct NodeBounds {
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  Cone cone;
  double cos_e = 1, phi = 0;
  bool two_sided = false;
};

NodeBounds leaf_bounds(const Prim& p);
NodeBounds bounds_union(const NodeBounds& a, const NodeBounds& b);

// The bounds of the centroids of a set of sources.
struct CentroidBox {
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  void grow(const Prim& p) {
    for (int a = 0; a < 3; ++a) {
      const float c = p.centroid(a);
      lo[a] = std::min(lo[a], c);
      hi[a] = std::max(hi[a], c);
    }
  }
};

// A bucket of the split search: the minima of its sources' Prim::v (their box, the box of
// their cone axes, the widest theta_o and theta_e), their power and count. Plain data (the
// split search keeps arrays of them uninitialized): none() is the empty bucket.
struct Bucket {
  float v[16];
  double phi;
  size_t count;

  static Bucket none() {
    Bucket b;
    std::fill(b.v, b.v + 16, INFINITY);
    b.phi = 0;
    b.count = 0;
    return b;
  }
  static Bucket of(const Prim& p) {
    Bucket b;
    std::copy(p.v, p.v + 16, b.v);
    b.phi = p.v[15];
    b.count = 1;
    return b;
  }
  void add(const Prim& p) {
    min16(v, p.v);
    phi += p.v[15];
    ++count;
  }
  void add(const Bucket& b) {
    min16(v, b.v);
    phi += b.phi;
    count += b.count;
  }
  float lo(int a) const { return v[a]; }
  float hi(int a) const { return -v[3 + a]; }
  double area() const {
    const double d[3] = {double(hi(0)) - lo(0), double(hi(1)) - lo(1), double(hi(2)) - lo(2)};
    return 2 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0]);
  }
};

// pbrt-v4's solid-angle measure of the emission, M_Omega(theta_o, theta_e) =
//   2 pi (1 - cos theta_o) + pi / 2 (2 theta_w sin theta_o - cos(theta_o - 2 theta_w)
//   - 2 theta_o sin theta_o + cos theta_o),  theta_w = min(theta_o + theta_e, pi),
// of a cone that holds each of count buckets': theta_o = theta_box + the widest theta_o,
// theta_box the angle of the cone around the bucket's box of axes (axis the box's centre,
// cosine the smallest dot product of that axis with the box's corners). In cosines, without
// trigonometry: cos(a + b) = cos a cos b - sin a sin b while a + b < pi, and
//   theta_w = pi:                    the bracket is 2 sin theta_o (pi - theta_o)
//   theta_w = theta_o + theta_e:     2 theta_e sin theta_o - cos(theta_o + 2 theta_e) + cos theta_o,
// theta_o itself by a polynomial arc cosine (within 7e-5, Abramowitz and Stegun 4.4.45).
// In float, a batch of buckets at a time (a cost heuristic: lane by lane, so the same
// values wherever a bucket sits in its batch).
void cone_measures(const Bucket* b, int count, float* out);

// The candidate splits of a node: the two sides of each as buckets, and the choice of the
// cheapest, in the order the candidates came (the first of equal costs wins).
struct SplitSearch {
  static constexpr int kMaxSets = 128, kMaxCands = 64;
  Bucket sets[kMaxSets];
  int nsets = 0;
  struct Cand {
    int axis, bucket, left, right;  // the split, and its sides in sets
    double kr;
  } cands[kMaxCands];
  int ncands = 0;

  int add_set(const Bucket& b) {
    sets[nsets] = b;
    return nsets++;
  }
  // pbrt-v4's cost: (phi M_Omega area of each side) Kr; (axis, bucket), axis -1: no split.
  std::pair<int, int> best() const;
};

struct Buckets {
  Bucket b[3][kBuckets];
  Buckets() { std::fill(&b[0][0], &b[0][0] + 3 * kBuckets, Bucket::none()); }
};

// The bucket of a source's centroid on axis a, for the centroid range starting at lo with
// kBuckets / extent in scale (the split search and the partition agree through it).
inline int bucket_of(const Prim& p, int a, float lo, float scale) {
  const int k = static_cast<int>((p.centroid(a) - lo) * scale);
  return std::clamp(k, 0, kBuckets - 1);
}

}  // namespace tuile::light_bvh_detail
