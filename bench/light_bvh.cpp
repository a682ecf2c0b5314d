// The light BVH (kernels/light/bvh.h, src/render/light_bvh.cpp) over S random small
// one-sided triangles in a 10 m box (random orientations, powers over two decades):
// - LightBvhBuild/S/threads: the build's wall time (threads 0: as many as oneTBB gives,
//   reported in the "threads" counter; 1: one thread), and bytes per source;
// - LightBvhPick/S and LightBvhPickSimd/S: one pick per sample (a uniform number at a random
//   shading point with a random normal), scalar and one SIMD batch; items_per_second is
//   samples per second, and the cost per sample grows like the tree's depth, log S.
#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <memory>
#include <random>
#include <vector>

#include "light/bvh.h"
#include "render/light_bvh.h"
// (after the lane headers, which include the AVX-512 intrinsics with GCC 12's spurious
// warnings silenced: oneTBB's headers would include them first otherwise)
#include <tbb/task_arena.h>

using namespace tuile;

namespace {

std::vector<Light> small_triangles(int n) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  std::vector<Light> out(static_cast<size_t>(n));
  for (Light& l : out) {
    l.type = LightKind::triangle;
    l.p0 = {10 * U(rng) - 5, 10 * U(rng) - 5, 10 * U(rng) - 5};
    const float z = 2 * U(rng) - 1, phi = 6.2831853f * U(rng), r = std::sqrt(std::max(0.f, 1 - z * z));
    const vec3f d{r * std::cos(phi), r * std::sin(phi), z};
    const vec3f t = normalize(cross(d, std::abs(d.x) > 0.5f ? vec3f{0, 1, 0} : vec3f{1, 0, 0}));
    const float s = 0.05f + 0.05f * U(rng);
    l.e1 = t * s;
    l.e2 = cross(d, t) * s;
    l.area = 0.5f * s * s;
    const float L = std::pow(10.f, 2 * U(rng) - 1);
    l.radiance = {L, L, L};
  }
  return out;
}

void BM_LightBvhBuild(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const std::vector<Light> lights = small_triangles(n);
  const int threads = state.range(1) > 0 ? static_cast<int>(state.range(1)) : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(threads);
  size_t bytes = 0;
  int depth = 0;
  for (auto _ : state) {
    arena.execute([&] {
      const LightBvh t = build_light_bvh(lights);
      bytes = t.bytes();
      depth = t.depth;
      benchmark::DoNotOptimize(t.child.data());
    });
  }
  state.SetItemsProcessed(state.iterations() * n);
  state.counters["threads"] = threads;
  state.counters["bytes_per_source"] = static_cast<double>(bytes) / n;
  state.counters["depth"] = depth;
}
BENCHMARK(BM_LightBvhBuild)
    ->ArgsProduct({{1000, 10000, 100000, 1000000}, {0, 1}})
    ->ArgNames({"sources", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// One tree per size, shared by the pick benchmarks.
const LightBvh& tree_of(int n) {
  static std::map<int, std::unique_ptr<LightBvh>> trees;
  auto& t = trees[n];
  if (!t) t = std::make_unique<LightBvh>(build_light_bvh(small_triangles(n)));
  return *t;
}

constexpr int kQueries = 1024;
struct Queries {
  alignas(64) float x[3][kQueries], n[3][kQueries], u[kQueries];
  Queries() {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> U(0.f, 1.f);
    for (int i = 0; i < kQueries; ++i) {
      for (int a = 0; a < 3; ++a) x[a][i] = 12 * U(rng) - 6;
      const float z = 2 * U(rng) - 1, phi = 6.2831853f * U(rng), r = std::sqrt(std::max(0.f, 1 - z * z));
      n[0][i] = r * std::cos(phi), n[1][i] = r * std::sin(phi), n[2][i] = z;
      u[i] = U(rng);
    }
  }
};

void BM_LightBvhPick(benchmark::State& state) {
  const LightBvh& tree = tree_of(static_cast<int>(state.range(0)));
  const LightBvhView B = tree.view();
  const BvhPicker picker{B};
  const auto q = std::make_unique<Queries>();
  for (auto _ : state) {
    float sum = 0;
    for (int i = 0; i < kQueries; ++i) {
      const PickContext<float> ctx{{q->x[0][i], q->x[1][i], q->x[2][i]}, {q->n[0][i], q->n[1][i], q->n[2][i]}};
      sum += picker.pick<tier_gather>(ctx, q->u[i]).pmf;
    }
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * kQueries);
  state.counters["depth"] = tree.depth;
}
BENCHMARK(BM_LightBvhPick)->RangeMultiplier(10)->Range(100, 1000000);

void BM_LightBvhPickSimd(benchmark::State& state) {
  const LightBvh& tree = tree_of(static_cast<int>(state.range(0)));
  const LightBvhView B = tree.view();
  const BvhPicker picker{B};
  const auto q = std::make_unique<Queries>();
  for (auto _ : state) {
    vfloat sum(0.f);
    for (int i = 0; i < kQueries; i += simd_width) {
      const PickContext<vfloat> ctx{load3<vfloat>(&q->x[0][i], &q->x[1][i], &q->x[2][i]),
                                    load3<vfloat>(&q->n[0][i], &q->n[1][i], &q->n[2][i])};
      sum += picker.pick<tier_gather>(ctx, load<vfloat>(&q->u[i])).pmf;
    }
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * kQueries);
  state.counters["depth"] = tree.depth;
}
BENCHMARK(BM_LightBvhPickSimd)->RangeMultiplier(10)->Range(100, 1000000);

}  // namespace
