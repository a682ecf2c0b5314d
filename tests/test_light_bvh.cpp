// The light BVH picker (kernels/light/bvh.h, src/render/light_bvh.cpp): the probability
// pmf() reports is the probability pick() has, checked by counting (a pick maps [0, 1) onto
// the sources as intervals whose lengths are their pmfs, so N stratified numbers count each
// source's pmf to within 2/N); the pmfs of a shading point sum to the probability that a
// pick finds a source (1 wherever some source can reach the point); pick's pmf equals
// pmf() bit for bit; every SIMD lane equals the scalar reference; the quantized bounds are
// conservative (every node above a source has importance wherever the source can shine);
// the build is the same whatever the threads, its depth stays within the bit trail, and it
// takes at most 64 bytes per source.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "light/bvh.h"
#include "render/light_bvh.h"
// (after the lane headers, which include the AVX-512 intrinsics with GCC 12's spurious
// warnings silenced: oneTBB's headers would include them first otherwise)
#include <tbb/task_arena.h>

using namespace tuile;

namespace {

// Sources of every kind with powers over six decades, scattered over a 10 m box.
std::vector<Light> mixed_lights(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  auto dir = [&] {
    const float z = 2 * U(rng) - 1, phi = 6.2831853f * U(rng), r = std::sqrt(std::max(0.f, 1 - z * z));
    return vec3f{r * std::cos(phi), r * std::sin(phi), z};
  };
  std::vector<Light> out;
  for (int i = 0; i < n; ++i) {
    Light l;
    const int kind = i % 7;
    l.p0 = {10 * U(rng) - 5, 10 * U(rng) - 5, 10 * U(rng) - 5};
    const float L = std::pow(10.f, 6 * U(rng) - 3);
    l.radiance = {L, 0.5f * L, 0.2f * L};
    if (kind <= 2) {
      l.type = kind == 0 ? LightKind::triangle : LightKind::parallelogram;
      l.e1 = dir() * (0.05f + U(rng));
      l.e2 = dir() * (0.05f + U(rng));
      l.area = length(cross(l.e1, l.e2)) * (kind == 0 ? 0.5f : 1.f);
      l.two_sided = kind == 2;
    } else if (kind == 3) {
      l.type = LightKind::sphere;
      l.e1 = {0.02f + 0.3f * U(rng), 0, 0};
    } else if (kind == 4) {
      l.type = LightKind::point;
    } else if (kind == 5) {
      l.type = LightKind::spot;
      l.e1 = dir();
      l.e2 = {0.9f, 0.7f, 0};
    } else {
      l.type = LightKind::triangle;  // a coplanar family: many sources share an axis
      l.p0.y = 4.9f;
      l.e1 = {0.2f, 0, 0};
      l.e2 = {0, 0, 0.2f};
      l.area = 0.02f;
    }
    out.push_back(l);
  }
  return out;
}

struct Query {
  vec3f x, n;
};
std::vector<Query> queries(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(-6.f, 6.f);
  std::vector<Query> q;
  for (int i = 0; i < n; ++i) {
    vec3f nn{U(rng), U(rng), U(rng)};
    nn = i % 5 == 0 ? vec3f{0, 0, 0} : normalize(nn);  // some without orientation
    q.push_back({{U(rng), U(rng), U(rng)}, nn});
  }
  return q;
}

}  // namespace

TEST(LightBvh, PmfIsThePickProbabilityAndSumsToOne) {
  for (int nl : {1, 2, 3, 17, 300}) {
    std::vector<Light> lights = mixed_lights(nl, 5u + static_cast<uint32_t>(nl));
    if (nl == 17) {  // distant sources beside the tree
      Light d;
      d.type = LightKind::distant;
      d.e1 = {0, 1, 0};
      d.radiance = {1, 1, 1};
      lights.push_back(d);
      lights.push_back(d);
    }
    if (nl == 300) lights[7].radiance = {0, 0, 0};  // no power: never picked
    const LightBvh tree = build_light_bvh(lights);
    const LightBvhView B = tree.view();
    const BvhPicker picker{B};
    const int N = 1 << 16;
    for (const Query& q : queries(12, 9)) {
      const PickContext<float> ctx{q.x, q.n};
      std::vector<double> count(lights.size(), 0.0);
      double found = 0;
      for (int i = 0; i < N; ++i) {
        const float u = (static_cast<float>(i) + 0.5f) / static_cast<float>(N);
        const PickedLight<float> p = picker.pick<tier_gather>(ctx, u);
        if (!(p.pmf > 0.f)) continue;
        ASSERT_GE(p.light, 0);
        ASSERT_LT(p.light, static_cast<int32_t>(lights.size()));
        const float again = picker.pmf<tier_gather>(ctx, p.light);
        ASSERT_EQ(std::memcmp(&again, &p.pmf, sizeof(float)), 0)
            << nl << " lights: pick's pmf " << p.pmf << " vs pmf() " << again << " for light " << p.light;
        count[static_cast<size_t>(p.light)] += 1;
        found += 1;
      }
      double sum = 0;
      for (size_t l = 0; l < lights.size(); ++l) {
        const double pmf = picker.pmf<tier_gather>(ctx, static_cast<int32_t>(l));
        sum += pmf;
        // each source's share of the stratified numbers is its pmf, to the numbers' spacing
        // (and the float remapping's rounding, a few ulps per level)
        EXPECT_NEAR(count[l] / N, pmf, 3.0 / N + 1e-5 * pmf) << nl << " lights, light " << l;
        if (nl == 300 && l == 7) {
          EXPECT_EQ(pmf, 0.0);
        }
      }
      // the pmfs sum to the probability that a pick finds a source (below 1 only where a
      // descent meets children of zero importance under a parent whose bounds reach x)
      EXPECT_NEAR(sum, found / N, 1e-4) << nl << " lights";
      EXPECT_LE(sum, 1.0 + 1e-4) << nl << " lights";
      if (nl >= 5) {
        EXPECT_GT(sum, 0.5) << nl << " lights";  // a point light reaches everything
      }
    }
  }
}

// Only planar one-sided sources, all facing +y, and a point below them all: nothing can
// reach it, every pmf is 0 and every pick fails; a point above sees them all.
TEST(LightBvh, SourcesFacingAwayAreNeverPicked) {
  std::vector<Light> lights;
  for (int i = 0; i < 20; ++i) {
    Light l;
    l.type = LightKind::parallelogram;
    l.p0 = {static_cast<float>(i % 5), 1, static_cast<float>(i / 5)};
    l.e1 = {0, 0, 0.5f};
    l.e2 = {0.5f, 0, 0};  // cross = +y
    l.area = 0.25f;
    l.radiance = {1.f + static_cast<float>(i), 1, 1};
    lights.push_back(l);
  }
  const LightBvh tree = build_light_bvh(lights);
  const LightBvhView B = tree.view();
  const BvhPicker picker{B};
  const PickContext<float> below{{2, 0, 2}, {0, 1, 0}}, above{{2, 3, 2}, {0, -1, 0}};
  double sb = 0, sa = 0;
  for (int l = 0; l < 20; ++l) {
    sb += picker.pmf<tier_gather>(below, l);
    sa += picker.pmf<tier_gather>(above, l);
  }
  EXPECT_EQ(sb, 0.0);
  EXPECT_NEAR(sa, 1.0, 1e-5);
  for (float u : {0.f, 0.3f, 0.99f}) EXPECT_EQ(picker.pick<tier_gather>(below, u).pmf, 0.f);
  // nearer and brighter sources get more: the one under the point (light 12, at 2..2.5)
  // and the brightest (light 19) beat a far dim one (light 0)
  EXPECT_GT(picker.pmf<tier_gather>(above, 12), picker.pmf<tier_gather>(above, 0));
}

TEST(LightBvh, LanesEqualScalar) {
  const std::vector<Light> lights = mixed_lights(500, 3);
  const LightBvh tree = build_light_bvh(lights);
  const LightBvhView B = tree.view();
  const BvhPicker picker{B};
  const std::vector<Query> q = queries(64 * simd_width, 4);
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  std::uniform_int_distribution<int> L(0, 499);
  for (size_t k = 0; k + simd_width <= q.size(); k += simd_width) {
    alignas(64) float x[3][simd_width], n[3][simd_width], u[simd_width];
    alignas(64) int32_t li[simd_width];
    for (int j = 0; j < simd_width; ++j) {
      const Query& a = q[k + static_cast<size_t>(j)];
      x[0][j] = a.x.x, x[1][j] = a.x.y, x[2][j] = a.x.z;
      n[0][j] = a.n.x, n[1][j] = a.n.y, n[2][j] = a.n.z;
      u[j] = U(rng);
      li[j] = L(rng);
    }
    const PickContext<vfloat> ctx{load3<vfloat>(x[0], x[1], x[2]), load3<vfloat>(n[0], n[1], n[2])};
    const PickedLight<vfloat> p = picker.pick<tier_gather>(ctx, load<vfloat>(u));
    const vfloat pm = picker.pmf<tier_gather>(ctx, load_i32<vfloat>(li));
    alignas(64) float pmf_v[simd_width], pick_pmf[simd_width];
    alignas(64) int32_t pick_l[simd_width];
    store(pmf_v, pm);
    store(pick_pmf, p.pmf);
    store(pick_l, p.light);
    for (int j = 0; j < simd_width; ++j) {
      const PickContext<float> c1{{x[0][j], x[1][j], x[2][j]}, {n[0][j], n[1][j], n[2][j]}};
      const PickedLight<float> s = picker.pick<tier_gather>(c1, u[j]);
      const float sp = picker.pmf<tier_gather>(c1, li[j]);
      EXPECT_EQ(std::memcmp(&sp, &pmf_v[j], 4), 0) << "pmf lane " << j << ": " << pmf_v[j] << " vs " << sp;
      EXPECT_EQ(std::memcmp(&s.pmf, &pick_pmf[j], 4), 0) << "pick pmf lane " << j;
      if (s.pmf > 0.f) {
        EXPECT_EQ(s.light, pick_l[j]) << "pick lane " << j;
      }
    }
  }
}

// The quantized bounds hold the exact ones: from points a source can reach (in front of a
// one-sided planar source, anywhere around a two-sided one, a sphere or a point light,
// inside a spotlight's falloff cone), near and far, every node on the source's path from
// the root has importance > 0, with the receiver unoriented or facing the source, so its
// pmf is > 0.
TEST(LightBvh, BoundsAreConservative) {
  const std::vector<Light> lights = mixed_lights(3000, 21);
  const LightBvh tree = build_light_bvh(lights);
  const LightBvhView B = tree.view();
  const BvhPicker picker{B};
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  auto dir = [&] {
    const float z = 2 * U(rng) - 1, phi = 6.2831853f * U(rng), r = std::sqrt(std::max(0.f, 1 - z * z));
    return vec3f{r * std::cos(phi), r * std::sin(phi), z};
  };
  int checked = 0;
  for (size_t l = 0; l < lights.size(); l += 3) {
    const Light& L = lights[l];
    const bool planar = L.type == LightKind::triangle || L.type == LightKind::parallelogram;
    const vec3f nl = planar ? normalize(cross(L.e1, L.e2)) : vec3f{0, 0, 0};
    for (int k = 0; k < 12; ++k) {
      // a point of the source, and a direction it emits into
      float a = U(rng), b = U(rng);
      if (L.type == LightKind::triangle && a + b > 1) a = 1 - a, b = 1 - b;
      vec3f p = planar ? L.p0 + L.e1 * a + L.e2 * b : L.p0;
      vec3f d = dir();
      if (planar && !L.two_sided && dot(d, nl) < 0) d = -d;
      if (planar && std::abs(dot(d, nl)) < 1e-3f) continue;
      if (L.type == LightKind::sphere) p = L.p0 + d * L.e1.x;
      if (L.type == LightKind::spot && dot(d, L.e1) < 0.71f) continue;  // outside the falloff cone
      const float t = k % 3 == 0 ? 1e-3f : k % 3 == 1 ? 0.2f : 4.f;
      const vec3f x = p + d * t;
      for (const vec3f& n : {vec3f{0, 0, 0}, -d}) {
        const PickContext<float> ctx{x, n};
        const uint64_t trail = tree.trail_lo[l] | uint64_t(tree.trail_hi[l]) << 32;
        int32_t node = 0;
        for (int depth = 0;; ++depth) {
          EXPECT_GT(light_bvh_importance(B, node, x, n), 0.f)
              << "light " << l << " (type " << static_cast<int>(L.type) << "), node " << node << " at depth " << depth
              << ", distance " << t;
          const int32_t second = tree.child[static_cast<size_t>(node)];
          if (second < 0) {
            EXPECT_EQ(-1 - second, static_cast<int32_t>(l));
            break;
          }
          node = (trail >> depth) & 1 ? second : node + 1;
        }
        EXPECT_GT(picker.pmf<tier_gather>(ctx, static_cast<int32_t>(l)), 0.f) << "light " << l;
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 5000);
}

// At most 64 bytes per source, everything included (the budget).
TEST(LightBvh, AtMost64BytesPerSource) {
  for (int n : {1000, 100000}) {
    const LightBvh tree = build_light_bvh(mixed_lights(n, 13));
    EXPECT_LE(tree.bytes(), size_t(64) * static_cast<size_t>(n)) << n << " sources";
  }
}

// The same tree for any thread count (the layout follows the splits only, and the sums of
// the parallel binning run over fixed chunks in a fixed order), within the bit trail's 62
// levels: built on one thread and on two, every array is the same bits. Bytes per source
// printed (no speed asserted here).
TEST(LightBvh, BuildIsDeterministicAndShallow) {
  // enough sources that the root bins in parallel chunks and the subtrees run as tasks
  const std::vector<Light> lights = mixed_lights(150000, 11);
  LightBvh a, b;
  tbb::task_arena(1).execute([&] { a = build_light_bvh(lights); });
  tbb::task_arena(2).execute([&] { b = build_light_bvh(lights); });
  auto same = [](const auto& x, const auto& y) {
    return x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * sizeof(x[0])) == 0;
  };
  EXPECT_TRUE(same(a.child, b.child));
  EXPECT_TRUE(same(a.trail_lo, b.trail_lo));
  EXPECT_TRUE(same(a.trail_hi, b.trail_hi));
  EXPECT_TRUE(same(a.phi, b.phi));
  EXPECT_TRUE(same(a.box_x, b.box_x));
  EXPECT_TRUE(same(a.box_y, b.box_y));
  EXPECT_TRUE(same(a.box_z, b.box_z));
  EXPECT_TRUE(same(a.axis, b.axis));
  EXPECT_TRUE(same(a.cone, b.cone));
  EXPECT_EQ(a.child.size(), 2 * lights.size() - 1);
  EXPECT_LE(a.depth, light_bvh_max_depth);
  EXPECT_GE(a.depth, 18);  // at least log2(150000)
  std::printf("[ light bvh ] %zu sources: depth %d, %.1f bytes per source\n", lights.size(), a.depth,
              static_cast<double>(a.bytes()) / static_cast<double>(lights.size()));
}

// A lopsided tree: point sources along a diagonal with growing spacing and powers 2^i, so
// the cost splits peel off the brightest few at a time; the tree stays within the bit
// trail's 62 levels and its picks stay exact.
TEST(LightBvh, DepthStaysWithinTheTrail) {
  std::vector<Light> lights;
  for (int i = 0; i < 120; ++i) {
    Light l;
    l.type = LightKind::point;
    const float x = std::pow(1.2f, static_cast<float>(i));
    l.p0 = {x, x, x};
    l.radiance = {std::ldexp(1.f, i), 1, 1};
    lights.push_back(l);
  }
  const LightBvh tree = build_light_bvh(lights);
  std::printf("[ light bvh ] 120 sources of powers 2^i on a line: depth %d\n", tree.depth);
  EXPECT_LE(tree.depth, light_bvh_max_depth);
  const LightBvhView B = tree.view();
  const BvhPicker picker{B};
  const PickContext<float> ctx{{0.5f, 1, 0}, {0, 0, 0}};
  double sum = 0;
  for (int l = 0; l < 120; ++l) sum += picker.pmf<tier_gather>(ctx, l);
  EXPECT_NEAR(sum, 1.0, 1e-4);
  const int N = 1 << 14;
  for (int i = 0; i < N; ++i) {
    const float u = (static_cast<float>(i) + 0.5f) / static_cast<float>(N);
    const PickedLight<float> p = picker.pick<tier_gather>(ctx, u);
    if (!(p.pmf > 0.f)) continue;
    const float again = picker.pmf<tier_gather>(ctx, p.light);
    ASSERT_EQ(std::memcmp(&again, &p.pmf, sizeof(float)), 0) << "light " << p.light;
  }
}
