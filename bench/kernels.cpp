// Micro-benchmarks of each kernel stage on one tile's worth of lanes (Google Benchmark).
// items_per_second is lanes (samples) per second; compare the SIMD and scalar rows of the
// same kernel for the SIMD speed-up measured in one run.
#include <benchmark/benchmark.h>

#include <memory>
#include <random>
#include <vector>

#include "wave/generate.h"
#include "wave/surface_hits.h"
#include "mis.h"
#include "sample/rng.h"
#include "wave/sample_bsdf.h"
#include "wave/sample_lights.h"
#include "wave/emitter_hits.h"
#include "accel/embree.h"
#include "render/render.h"
#include "scene/scene.h"

using namespace tuile;

namespace {

constexpr int lanes = 256;

struct Fixture {
  Scene scene = load_scene("built-in:cornell");
  SceneViews views;
  std::unique_ptr<TileBuffers> tb = std::make_unique<TileBuffers>();
  Estimator est;
  explicit Fixture(LightPoint point = LightPoint::solid_angle) {
    views = build_views(scene, LightPick::power);
    est.point = point;
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> U(0.f, 1.f);
    tb->points.count = lanes;
    for (int k = 0; k < max_tile_lanes; ++k) {
      tb->points.px[k] = 0.1f + 0.8f * U(rng);
      tb->points.py[k] = 0.f;
      tb->points.pz[k] = 0.1f + 0.8f * U(rng);
      tb->points.nx[k] = 0.f;
      tb->points.ny[k] = 1.f;
      tb->points.nz[k] = 0.f;
      tb->points.eps[k] = 1e-6f;
      tb->points.ar[k] = tb->points.ag[k] = tb->points.ab[k] = 0.7f;
      tb->points.pixel[k] = static_cast<uint32_t>(k);
      tb->points.lane[k] = k;
      tb->tech.u0[k] = U(rng);
      tb->tech.u1[k] = U(rng);
      tb->tech.u2[k] = U(rng);
      tb->tech.u3[k] = U(rng);
      tb->lanes.fx[k] = static_cast<float>(k % 16);
      tb->lanes.fy[k] = static_cast<float>(k / 16);
      tb->lanes.pixel[k] = static_cast<uint32_t>(k);
      tb->queue.light[k] = 0;
      tb->queue.x[k] = tb->points.px[k];
      tb->queue.y[k] = 0.f;
      tb->queue.z[k] = tb->points.pz[k];
      tb->queue.dx[k] = 0.f;
      tb->queue.dy[k] = 1.f;
      tb->queue.dz[k] = 0.f;
      tb->queue.dist[k] = 1.f;
      tb->queue.beta_r[k] = tb->queue.beta_g[k] = tb->queue.beta_b[k] = 0.7f;
      tb->queue.pdf[k] = 1.f / 3.14159265f;  // straight up from a floor: cos / pi
    }
    tb->queue.count = lanes;
  }
};

template <class T> void BM_sample_lights(benchmark::State& state) {
  Fixture f(static_cast<LightPoint>(state.range(0)));
  LightPass pass;
  pass.fixed_light = 0;
  constexpr int w = lane_traits<T>::width;
  for (auto _ : state) {
    for (int k = 0; k < lanes; k += w) sample_lights_lanes<T, kind_area, false>(f.views.geom, f.views.lights, f.est, pass, *f.tb, k);
    benchmark::DoNotOptimize(f.tb->tech.cr[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
// The rectangle-only light stage as the renderer runs it (two batches per call), with the
// source broadcast (one light) or gathered per lane (picked with the alias table).
template <class T, bool Pick> void BM_sample_lights_rect(benchmark::State& state) {
  Fixture f;
  LightPass pass;
  pass.fixed_light = Pick ? -1 : 0;
  for (auto _ : state) {
    for (int k = 0; k < lanes; k += lane_traits<T>::width)
      sample_lights_lanes<T, kind_area | kind_rects, Pick>(f.views.geom, f.views.lights, f.est, pass, *f.tb, k);
    benchmark::DoNotOptimize(f.tb->tech.cr[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
// The parts of the light kernel on the same lanes: Urena's map alone (setup and sample)
// and the whole point sampler (map, fallback rule, area fallback).
template <class T> void BM_rectangle_map(benchmark::State& state) {
  Fixture f;
  const LightGeom<T> g = broadcast_light<T>(f.views.lights, 0);
  constexpr int w = lane_traits<T>::width;
  for (auto _ : state) {
    for (int k = 0; k < lanes; k += w) {
      const Vec3<T> x = load3<T>(f.tb->points.px + k, f.tb->points.py + k, f.tb->points.pz + k);
      const SphericalRectangle<T> r =
          spherical_rectangle_setup_unit(x, g.p0, g.ex, g.ey, g.len1, g.len2);
      Vec3<T> d;
      T t;
      sample_spherical_rectangle(r, load<T>(f.tb->tech.u2 + k), load<T>(f.tb->tech.u3 + k), d, t);
      store(f.tb->tech.cr + k, d.x + d.y + d.z + t + r.omega);
    }
    benchmark::DoNotOptimize(f.tb->tech.cr[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
template <class T> void BM_light_point(benchmark::State& state) {
  Fixture f;
  const LightGeom<T> g = broadcast_light<T>(f.views.lights, 0);
  constexpr int w = lane_traits<T>::width;
  for (auto _ : state) {
    for (int k = 0; k < lanes; k += w) {
      const Vec3<T> x = load3<T>(f.tb->points.px + k, f.tb->points.py + k, f.tb->points.pz + k);
      const LightPointSample<T> s = sample_light_point<kind_area>(LightPoint::solid_angle, g, x,
                                                                   load<T>(f.tb->tech.u2 + k), load<T>(f.tb->tech.u3 + k));
      store(f.tb->tech.cr + k, s.wi.x + s.wi.y + s.wi.z + s.dist + s.pdf_sa);
    }
    benchmark::DoNotOptimize(f.tb->tech.cr[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
template <class T> void BM_sample_bsdf(benchmark::State& state) {
  Fixture f;
  constexpr int w = lane_traits<T>::width;
  for (auto _ : state) {
    for (int k = 0; k < lanes; k += w) sample_bsdf_lanes<T>(f.views.geom, f.est, *f.tb, k);
    benchmark::DoNotOptimize(f.tb->bounce[0].ray.dir_x[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
template <class T> void BM_mis_weight(benchmark::State& state) {
  Fixture f(static_cast<LightPoint>(state.range(0)));
  constexpr int w = lane_traits<T>::width;
  for (auto _ : state) {
    for (int k = 0; k < lanes; k += w) weight_lanes<T>(f.views.lights, f.est, 1.f, 1.f, *f.tb, k);
    benchmark::DoNotOptimize(f.tb->tech.cr[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
template <class T> void BM_generate(benchmark::State& state) {
  Fixture f;
  constexpr int w = lane_traits<T>::width;
  for (auto _ : state) {
    for (int k = 0; k < lanes; k += w) generate_lanes<T>(f.views.camera, *f.tb, k);
    benchmark::DoNotOptimize(f.tb->cam[0].ray.dir_x[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
// The whole camera-hit stage on one traced 16x16 tile at the image centre.
template <class T> void BM_camera_hits(benchmark::State& state) {
  Fixture f;
  Accel accel(f.scene);
  for (int k = 0; k < lanes; ++k) {
    f.tb->lanes.fx[k] = static_cast<float>(f.scene.camera.width / 2 - 8 + k % 16);
    f.tb->lanes.fy[k] = static_cast<float>(f.scene.camera.height / 2 - 8 + k / 16);
  }
  generate(f.views.camera, f.est, 0, SampleLayout::camera, lanes, *f.tb);
  for (int p = 0; p < lanes / packet_width; ++p) accel.intersect16(f.tb->lanes.cam_valid + p * packet_width, f.tb->cam[p], true);
  for (auto _ : state) {
    camera_hits<true, T>(f.views.geom, f.views.lights, f.est, 0, SampleLayout{}.technique_choice(), lanes, *f.tb);
    benchmark::DoNotOptimize(f.tb->points.px[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
template <class T> void BM_heuristic(benchmark::State& state) {
  alignas(64) float a[lanes], b[lanes], out[lanes];
  for (int i = 0; i < lanes; ++i) a[i] = 0.1f + i, b[i] = 3.f + 0.5f * i;
  constexpr int w = lane_traits<T>::width;
  const Heuristic h = static_cast<Heuristic>(state.range(0));
  for (auto _ : state) {
    for (int i = 0; i < lanes; i += w) store(out + i, mis_weight(h, load<T>(a + i), load<T>(b + i), MisParams{}));
    benchmark::DoNotOptimize(out[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}
void BM_sampler(benchmark::State& state) {
  Fixture f;
  const SamplerKind kind = static_cast<SamplerKind>(state.range(0));
  uint32_t s = 0;
  for (auto _ : state) {
    sample_pairs(kind, 1, f.tb->lanes.pixel, s++, 64, 3, lanes, f.tb->tech.u0, f.tb->tech.u1);
    benchmark::DoNotOptimize(f.tb->tech.u0[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}

// The hash-based samplers from keys cached per pixel and pair, as the renderer draws them
// within a tile: only the per-sample part (args as registered below).
void BM_sampler_keyed(benchmark::State& state) {
  Fixture f;
  const SamplerKind kind = static_cast<SamplerKind>(state.range(0));
  std::vector<uint32_t> key(lanes), ku(lanes), kv(lanes);
  const PairKeys keys{key.data(), ku.data(), kv.data()};
  make_pair_keys(1, f.tb->lanes.pixel, 3, lanes, keys);
  uint32_t s = 0;
  for (auto _ : state) {
    sample_pairs_keyed(kind, 1, s++, 3, keys, lanes, f.tb->tech.u0, state.range(1) ? f.tb->tech.u1 : nullptr);
    benchmark::DoNotOptimize(f.tb->tech.u0[0]);
  }
  state.SetItemsProcessed(state.iterations() * lanes);
}

}  // namespace

// Arg: 0 = area, 1 = solid angle
BENCHMARK_TEMPLATE(BM_sample_lights, vfloat)->Arg(0)->Arg(1);
BENCHMARK_TEMPLATE(BM_sample_lights, vfloat2)->Arg(0)->Arg(1);
BENCHMARK_TEMPLATE(BM_sample_lights, float)->Arg(0)->Arg(1);
// one, two and four batches at a time (the stage runs four, then two, then one)
BENCHMARK_TEMPLATE(BM_sample_lights_rect, vfloat, false);
BENCHMARK_TEMPLATE(BM_sample_lights_rect, vfloat2, false);
BENCHMARK_TEMPLATE(BM_sample_lights_rect, vfloat4, false);
BENCHMARK_TEMPLATE(BM_sample_lights_rect, vfloat2, true);
BENCHMARK_TEMPLATE(BM_sample_lights_rect, vfloat4, true);
BENCHMARK_TEMPLATE(BM_rectangle_map, vfloat);
BENCHMARK_TEMPLATE(BM_rectangle_map, vfloat2);
BENCHMARK_TEMPLATE(BM_rectangle_map, vfloat4);
BENCHMARK_TEMPLATE(BM_light_point, vfloat);
BENCHMARK_TEMPLATE(BM_light_point, vfloat2);
BENCHMARK_TEMPLATE(BM_mis_weight, vfloat)->Arg(0)->Arg(1);
BENCHMARK_TEMPLATE(BM_mis_weight, float)->Arg(0)->Arg(1);
BENCHMARK_TEMPLATE(BM_sample_bsdf, vfloat);
BENCHMARK_TEMPLATE(BM_sample_bsdf, float);
BENCHMARK_TEMPLATE(BM_generate, vfloat);
BENCHMARK_TEMPLATE(BM_generate, float);
BENCHMARK_TEMPLATE(BM_camera_hits, vfloat);
BENCHMARK_TEMPLATE(BM_camera_hits, float);
// Arg: heuristic 0 balance, 1 power, 2 cutoff, 3 maximum
BENCHMARK_TEMPLATE(BM_heuristic, vfloat)->DenseRange(0, 3);
BENCHMARK_TEMPLATE(BM_heuristic, float)->DenseRange(0, 3);
// Arg: 0 independent, 1 stratified, 2 sobol
BENCHMARK(BM_sampler)->DenseRange(0, 2);
// Args: sampler (0 = independent, 2 = sobol), both dimensions (1) or the first only (0)
BENCHMARK(BM_sampler_keyed)->Args({0, 1})->Args({0, 0})->Args({2, 1})->Args({2, 0});
