// The roofline's bound: the packets one render traced, replayed through Embree alone.
#include "measure/roofline.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <x86intrin.h>

#include <algorithm>
#include <chrono>
#include <cstring>

#include "render/tile_pipeline.h"

namespace tuile {

using clock_type = std::chrono::steady_clock;

// A packet copied with vector loads and stores (a library memcpy may use string stores,
// which the loads of the next call cannot forward from).
template <class P> inline void copy_packet(P& dst, const P& src) noexcept {
  static_assert(sizeof(P) % (sizeof(float) * simd_width) == 0);
  const float* s = reinterpret_cast<const float*>(&src);
  float* d = reinterpret_cast<float*>(&dst);
  for (size_t k = 0; k < sizeof(P) / sizeof(float); k += simd_width) store(d + k, load<vfloat>(s + k));
}

// Times only the Embree calls (time-stamp counter around each call, converted with the
// replay's own ticks-per-second), not the copies of the recorded packets and valid masks
// into local (cached) memory: the sum over threads divided by the thread count.
double replay_rays(const Accel& accel, const RayRecord& rays, int threads) {
  const size_t nc = rays.camera.size(), ns = rays.shadow.size(), nb = rays.bounce.size(), ne = rays.bounce_emitters.size();
  const int n_threads = threads > 0 ? threads : tbb::this_task_arena::max_concurrency();
  tbb::enumerable_thread_specific<uint64_t> call_ticks(0);
  const auto t0 = clock_type::now();
  const uint64_t ticks0 = __rdtsc();
  tbb::task_arena arena(n_threads);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nc + ns + nb + ne, 16), [&](const tbb::blocked_range<size_t>& r) {
      RayHit16 hit;
      Ray16 ray;
      alignas(64) int32_t valid[packet_width];
      uint64_t& ticks = call_ticks.local();
      // copies the recorded packet and mask to local memory, then times the call alone
      auto timed = [&](auto& local, const auto& rec, auto&& call) {
        copy_packet(local, rec.packet);
        std::memcpy(valid, rec.valid, sizeof(valid));
        clear_high_vector_registers();
        const uint64_t c0 = __rdtsc();
        call();
        ticks += __rdtsc() - c0;
      };
      for (size_t i = r.begin(); i < r.end(); ++i) {
        if (i < nc) timed(hit, rays.camera[i], [&] { accel.intersect16(valid, hit, true); });
        else if (i < nc + ns) timed(ray, rays.shadow[i - nc], [&] { accel.occluded16(valid, ray, false); });
        else if (i < nc + ns + nb) timed(hit, rays.bounce[i - nc - ns], [&] { accel.intersect16(valid, hit, false); });
        else timed(hit, rays.bounce_emitters[i - nc - ns - nb], [&] { accel.intersect16(valid, hit, false, Bvh::emitters); });
      }
    });
  });
  const double wall = std::chrono::duration<double>(clock_type::now() - t0).count();
  const double sec_per_tick = wall / static_cast<double>(std::max<uint64_t>(1, __rdtsc() - ticks0));
  uint64_t total = 0;
  for (uint64_t t : call_ticks) total += t;
  return static_cast<double>(total) * sec_per_tick / n_threads;
}

// The recorded rays of each kind as pointer-SoA streams of one tile's packets each (inactive
// lanes are left out), traced with rtcIntersectNp / rtcOccludedNp.
double replay_rays_stream(const Accel& accel, const RayRecord& rays, int threads) {
  struct Stream {
    std::vector<float> f[16];
    std::vector<uint32_t> u[6];
    unsigned n = 0;
    bool occluded = false, coherent = false;
    Bvh bvh = Bvh::scene;
  };
  std::vector<Stream> streams;
  constexpr size_t per_stream = max_tile_lanes / packet_width;  // packets of one tile
  auto build = [&](const auto& packets, bool occluded, bool coherent, Bvh bvh) {
    for (size_t start = 0; start < packets.size(); start += per_stream) {
      Stream st;
      st.occluded = occluded;
      st.coherent = coherent;
      st.bvh = bvh;
      for (size_t p = start; p < std::min(packets.size(), start + per_stream); ++p) {
        const auto& rec = packets[p];
        const Ray16* r;
        if constexpr (std::is_same_v<std::decay_t<decltype(rec.packet)>, RayHit16>) r = &rec.packet.ray;
        else r = &rec.packet;
        for (int l = 0; l < packet_width; ++l) {
          if (!rec.valid[l]) continue;
          const float vals[9] = {r->org_x[l], r->org_y[l], r->org_z[l], r->tnear[l], r->dir_x[l],
                                 r->dir_y[l], r->dir_z[l], r->time[l],  r->tfar[l]};
          for (int k = 0; k < 9; ++k) st.f[k].push_back(vals[k]);
          for (int k = 9; k < 16; ++k) st.f[k].push_back(0.f);
          st.u[0].push_back(r->mask[l]);
          st.u[1].push_back(0);
          st.u[2].push_back(0);
          for (int k = 3; k < 6; ++k) st.u[k].push_back(invalid_id);
          ++st.n;
        }
      }
      streams.push_back(std::move(st));
    }
  };
  build(rays.camera, false, true, Bvh::scene);
  build(rays.shadow, true, false, Bvh::scene);
  build(rays.bounce, false, false, Bvh::scene);
  build(rays.bounce_emitters, false, false, Bvh::emitters);
  const auto t0 = clock_type::now();
  tbb::task_arena arena(threads > 0 ? threads : tbb::this_task_arena::max_concurrency());
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, streams.size(), 1), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        Stream st = streams[i];  // a fresh copy: tracing overwrites tfar and hits
        Accel::StreamRays sr{st.f[0].data(),  st.f[1].data(),  st.f[2].data(),  st.f[3].data(),  st.f[4].data(),
                             st.f[5].data(),  st.f[6].data(),  st.f[7].data(),  st.f[8].data(),  st.u[0].data(),
                             st.u[1].data(),  st.u[2].data(),  st.f[9].data(),  st.f[10].data(), st.f[11].data(),
                             st.f[12].data(), st.f[13].data(), st.u[3].data(),  st.u[4].data(),  st.u[5].data()};
        if (st.occluded) accel.occluded_stream(sr, st.n, st.coherent);
        else accel.intersect_stream(sr, st.n, st.coherent, st.bvh);
      }
    });
  });
  return std::chrono::duration<double>(clock_type::now() - t0).count();
}

}  // namespace tuile
