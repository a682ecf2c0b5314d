// `tuile render` and `tuile bench` over MPI ranks (see dist.h). Rank 0 coordinates: it
// loads the scene like every rank, hands out units (one pass of the render over a block of
// tiles) to the ranks that ask, keeps each pass's blocks until the whole pass is in, and
// then adds the pass to the image in block order: the sums and their order are those of a
// single-process render, whatever rank rendered what. Workers render a unit with the same
// Renderer on their own threads and send back the tiles' sums in double.
//
// With --guide, the guide learns from every tile of each learning iteration before the next
// one: the units are also cut at the iterations' ends (steps), and after the last unit of an
// iteration rank 0 sends no more until every rank has added its records into one sum
// (integers: the same sums, whichever rank recorded what) and made the guide from it. A
// resumed render's units first render the samples the guide learns from again, their image
// dropped. So every rank's guide, and the image, are those of a single process.
//
// Failures end the job with a message naming the rank: a scene that fails to load (the
// error printed once, by rank 0, with how many ranks met it), a unit that throws, or a rank
// that sends nothing for --mpi-timeout seconds (rank 0 writes the complete passes it has
// and aborts the job). A rank that dies makes mpirun end the job (its message names the
// rank); rank 0 then gets SIGTERM and writes what it has, as for a stop signal.
#include <mpi.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <functional>
#include <map>
#include <tuple>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "app/prepare.h"
#include "app/render_job.h"
#include "app/signals.h"
#include "dist/dist.h"
#include "render/checkpoint.h"
#include "render/guide.h"
#include "render/passes.h"
#include "render/render.h"

namespace tuile {

bool mpi_available() { return true; }

namespace {

// Seconds rank 0 waits, after a stop signal, for the units in flight.
constexpr double stop_grace_seconds = 0.25;

enum Tag : int { tag_unit = 1, tag_result = 2, tag_stop = 3, tag_error = 4, tag_report = 5, tag_guide = 6 };

// Per pixel of a result: sum r g b, sum of squares r g b, MIS-weight sum and count, largest sample.
constexpr int values_per_pixel = 9;
// A result message: these header values, then the pixels of the unit's tiles in order.
enum Header : int { h_step = 0, h_block, h_seconds, h_rays_camera, h_rays_shadow, h_rays_bounce, h_rays_vis,
                    h_rej_camera, h_rej_light, h_rej_bsdf, header_size };

struct Mpi {
  int rank = 0, size = 1;
  Mpi() {
    int provided = 0;
    MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
  }
  ~Mpi() { MPI_Finalize(); }
};

void sleep_briefly() {
  const timespec ts{0, 500000};  // 0.5 ms between polls: rank 0 leaves the cores to the workers
  nanosleep(&ts, nullptr);
}

// The first error any rank met, known to every rank; rank 0 gets its text (and how many
// ranks met an error). Empty when none did.
std::string agree_on_errors(const Mpi& mpi, const std::string& mine, int& failed_ranks, int& first_rank) {
  const int bad = mine.empty() ? 0 : 1;
  MPI_Allreduce(&bad, &failed_ranks, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD);
  const int candidate = bad ? mpi.rank : mpi.size;
  MPI_Allreduce(&candidate, &first_rank, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  if (failed_ranks == 0) return {};
  std::string text = mine;
  if (first_rank != 0) {
    if (mpi.rank == first_rank) {
      MPI_Send(mine.data(), static_cast<int>(mine.size()), MPI_CHAR, 0, tag_error, MPI_COMM_WORLD);
    } else if (mpi.rank == 0) {
      MPI_Status st;
      MPI_Probe(first_rank, tag_error, MPI_COMM_WORLD, &st);
      int n = 0;
      MPI_Get_count(&st, MPI_CHAR, &n);
      text.assign(static_cast<size_t>(n), '\0');
      MPI_Recv(text.data(), n, MPI_CHAR, first_rank, tag_error, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    }
  }
  return text;
}

// A step: samples [begin, end) of pass `pass` (-1: samples a resumed render learns its guide
// from again, whose image is dropped); `barrier`: a learning iteration of the guide ends
// with it, so its records are summed over the ranks before the next step starts.
struct Step {
  int pass = 0;
  uint32_t begin = 0, end = 0;
  bool barrier = false;
};

// The units of a render: for every step (the passes from `done` to spp, cut at the guide's
// iterations), every block of tiles.
// With --light-paths, each step's light paths too, in the renderer's chunks (render.h): a
// unit whose block is blocks + j traces chunk j of its step for the whole image (none for
// the steps a resumed render learns its guide from again: their image is dropped).
struct Units {
  std::vector<uint32_t> pass_begin, pass_end;  // per pass
  std::vector<Step> steps;
  std::vector<int> pass_steps;  // per pass, its steps
  int blocks = 0, tiles_per_block = 1, tiles = 0;
  uint32_t light_chunk = 0;  // samples per chunk of light paths (0: none)
  std::vector<int> step_index;   // per step: its place among its pass's steps
  std::vector<int> step_chunk0;  // per step: its first light chunk's place among its pass's
  std::vector<int> pass_chunks;  // per pass: its light chunks, over its steps
  std::vector<std::pair<uint32_t, uint32_t>> order;  // (step, block) of every unit, in the order sent
  std::vector<int> block_tiles(int b) const {
    std::vector<int> t;
    for (int i = b * tiles_per_block; i < std::min(tiles, (b + 1) * tiles_per_block); ++i) t.push_back(i);
    return t;
  }
  int light_chunks(size_t step) const {
    const Step& s = steps[step];
    return light_chunk == 0 || s.pass < 0 ? 0 : static_cast<int>((s.end - s.begin + light_chunk - 1) / light_chunk);
  }
  int step_units(size_t step) const { return blocks + light_chunks(step); }
  int pass_light_chunks(size_t pass) const { return pass_chunks[pass]; }
  // a pass of several steps (the guide's learning iterations) with light chunks: rank 0
  // keeps each step's camera sums apart, to add them between the steps' chunks
  bool steps_apart(size_t pass) const { return pass_steps[pass] > 1 && pass_chunks[pass] > 0; }
  int count() const { return static_cast<int>(order.size()); }
};

Units plan_units(const Renderer& r, const PassPlan& plan, uint32_t done, uint32_t spp, int workers, int tile_side) {
  Units u;
  for (uint32_t s = done; s < spp;) {
    const uint32_t e = plan.next_end(s, spp);
    u.pass_begin.push_back(s);
    u.pass_end.push_back(e);
    s = e;
  }
  u.pass_steps.assign(u.pass_begin.size(), 0);
  const Guide* g = r.guide();
  // cuts [b, e) at the guide's iterations while it learns
  auto add = [&](int pass, uint32_t b, uint32_t e) {
    for (uint32_t s = b; s < e;) {
      const bool learning = g && s < g->learn();
      const uint32_t t = learning ? std::min(e, g->iteration_end(s)) : e;
      u.steps.push_back({pass, s, t, learning && t == g->iteration_end(s)});
      if (pass >= 0) ++u.pass_steps[static_cast<size_t>(pass)];
      s = t;
    }
  };
  if (g) add(-1, 0, std::min(done, g->learn()));
  for (size_t k = 0; k < u.pass_begin.size(); ++k) add(static_cast<int>(k), u.pass_begin[k], u.pass_end[k]);
  u.tiles = r.tile_count();
  // about 2^20 samples a unit at the largest pass, and at least four units per worker a pass
  uint32_t widest = 1;
  for (size_t k = 0; k < u.pass_begin.size(); ++k) widest = std::max(widest, u.pass_end[k] - u.pass_begin[k]);
  const uint64_t per_tile = static_cast<uint64_t>(tile_side) * tile_side * widest;
  u.tiles_per_block = static_cast<int>(std::max<uint64_t>(1, (uint64_t(1) << 20) / per_tile));
  u.tiles_per_block = std::min(u.tiles_per_block, std::max(1, u.tiles / (4 * std::max(1, workers))));
  u.blocks = (u.tiles + u.tiles_per_block - 1) / u.tiles_per_block;
  u.light_chunk = r.has_light_paths() ? r.light_chunk_samples() : 0;
  u.pass_chunks.assign(u.pass_begin.size(), 0);
  std::vector<int> seen(u.pass_begin.size(), 0);
  for (size_t k = 0; k < u.steps.size(); ++k) {
    const int pass = u.steps[k].pass;
    u.step_index.push_back(pass < 0 ? 0 : seen[static_cast<size_t>(pass)]++);
    u.step_chunk0.push_back(pass < 0 ? 0 : u.pass_chunks[static_cast<size_t>(pass)]);
    if (pass >= 0) u.pass_chunks[static_cast<size_t>(pass)] += u.light_chunks(k);
  }
  for (size_t k = 0; k < u.steps.size(); ++k)  // (a step's light chunks first: they take longest)
    for (int j = 0; j < u.step_units(k); ++j)
      u.order.emplace_back(static_cast<uint32_t>(k), static_cast<uint32_t>((j + u.blocks) % u.step_units(k)));
  return u;
}

// ---------------------------------------------------------------------------------------
// A worker: units in, tile sums out, until rank 0 says stop.

struct WorkerReport {  // sent to rank 0 at the end (bench)
  double units = 0, samples = 0, render_seconds = 0, comm_seconds = 0;
};

void test_failure_hook(const Mpi& mpi) {
  // Test hooks (tests/test_mpi.cpp): make one rank exit or stop answering after its first unit
  // (or after TUILE_TEST_FAIL_AFTER units).
  const char* r = std::getenv("TUILE_TEST_FAIL_RANK");
  if (!r || std::atoi(r) != mpi.rank) return;
  static int done = 1;
  const char* after = std::getenv("TUILE_TEST_FAIL_AFTER");
  if (after && done++ < std::atoi(after)) return;
  const char* mode = std::getenv("TUILE_TEST_FAIL_MODE");
  if (mode && std::string(mode) == "hang")
    for (;;) pause();
  _exit(3);
}

void run_worker(const Mpi& mpi, Renderer& renderer, const Units& u, int width, int height) {
  renderer.guide_restart();  // every render learns from sample 0 (bench renders again)
  Film film;
  film.reset(width, height);
  WorkerReport rep;
  std::vector<double> msg, light;
  bool first = true;
  renderer.set_light_paths_apart(true);  // (the light paths are units of their own)
  for (;;) {
    const auto w0 = std::chrono::steady_clock::now();
    MPI_Status st;
    MPI_Probe(0, MPI_ANY_TAG, MPI_COMM_WORLD, &st);
    uint32_t unit[2] = {0, 0};
    MPI_Recv(unit, 2, MPI_UINT32_T, 0, st.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    rep.comm_seconds += seconds_since(w0);
    if (st.MPI_TAG == tag_stop) break;
    if (st.MPI_TAG == tag_guide) {  // a learning iteration ended: every rank sums its records
      const auto g0 = std::chrono::steady_clock::now();
      std::vector<uint64_t> rec = renderer.guide_records();
      // nonblocking as rank 0's (a blocking collective does not match a nonblocking one)
      MPI_Request req;
      MPI_Iallreduce(MPI_IN_PLACE, rec.data(), static_cast<int>(rec.size()), MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD, &req);
      MPI_Wait(&req, MPI_STATUS_IGNORE);
      rep.comm_seconds += seconds_since(g0);
      try {
        renderer.guide_end_iteration(u.steps[unit[0]].end, rec);
      } catch (const std::exception& e) {
        const std::string text = e.what();
        MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, 0, tag_error, MPI_COMM_WORLD);
      }
      continue;
    }
    if (!first) test_failure_hook(mpi);
    first = false;
    const Step& step = u.steps[unit[0]];
    const uint32_t block = unit[1];
    try {
      if (block >= static_cast<uint32_t>(u.blocks)) {  // a chunk of the step's light paths: the whole image's sums
        const uint32_t b = step.begin + (block - static_cast<uint32_t>(u.blocks)) * u.light_chunk;
        const RenderStats rs = renderer.render_light_chunk(light, b, std::min(step.end, b + u.light_chunk));
        msg.assign(header_size, 0.0);
        msg[h_step] = unit[0];
        msg[h_block] = block;
        msg[h_seconds] = rs.seconds;
        msg[h_rej_bsdf] = static_cast<double>(rs.rejected_bsdf);
        msg.insert(msg.end(), light.begin(), light.end());
        rep.units += 1;
        rep.render_seconds += rs.seconds;
        const auto s0 = std::chrono::steady_clock::now();
        MPI_Send(msg.data(), static_cast<int>(msg.size()), MPI_DOUBLE, 0, tag_result, MPI_COMM_WORLD);
        rep.comm_seconds += seconds_since(s0);
        continue;
      }
      const std::vector<int> tiles = u.block_tiles(static_cast<int>(block));
      // the unit's pixels start from zero, so each gets exactly its tile's sums
      for (int t : tiles) {
        const TileRect r = renderer.tile_rect(t);
        for (int y = r.y0; y < r.y0 + r.h; ++y)
          for (int x = r.x0; x < r.x0 + r.w; ++x) {
            const size_t i = static_cast<size_t>(y) * width + x;
            for (int c = 0; c < 3; ++c) film.sum[3 * i + c] = film.sum_sq[3 * i + c] = 0.0;
            film.w_sum[i] = film.w_cnt[i] = 0.0;
            film.max_sample[i] = 0.f;
          }
      }
      film.samples = 0;
      const RenderStats rs = renderer.guide() ? renderer.render_guided_part(film, step.begin, step.end, tiles)
                                              : renderer.render(film, step.begin, step.end, nullptr, &tiles);
      msg.assign(header_size, 0.0);
      msg[h_step] = unit[0];
      msg[h_block] = block;
      msg[h_seconds] = rs.seconds;
      msg[h_rays_camera] = static_cast<double>(rs.rays_camera);
      msg[h_rays_shadow] = static_cast<double>(rs.rays_shadow);
      msg[h_rays_bounce] = static_cast<double>(rs.rays_bounce);
      msg[h_rays_vis] = static_cast<double>(rs.rays_bounce_visibility);
      msg[h_rej_camera] = static_cast<double>(rs.rejected_camera);
      msg[h_rej_light] = static_cast<double>(rs.rejected_light);
      msg[h_rej_bsdf] = static_cast<double>(rs.rejected_bsdf);
      for (int t : tiles) {
        const TileRect r = renderer.tile_rect(t);
        for (int y = r.y0; y < r.y0 + r.h; ++y)
          for (int x = r.x0; x < r.x0 + r.w; ++x) {
            const size_t i = static_cast<size_t>(y) * width + x;
            for (int c = 0; c < 3; ++c) msg.push_back(film.sum[3 * i + c]);
            for (int c = 0; c < 3; ++c) msg.push_back(film.sum_sq[3 * i + c]);
            msg.push_back(film.w_sum[i]);
            msg.push_back(film.w_cnt[i]);
            msg.push_back(static_cast<double>(film.max_sample[i]));
          }
      }
      rep.units += 1;
      rep.samples += static_cast<double>(rs.samples);
      rep.render_seconds += rs.seconds;
      const auto s0 = std::chrono::steady_clock::now();
      MPI_Send(msg.data(), static_cast<int>(msg.size()), MPI_DOUBLE, 0, tag_result, MPI_COMM_WORLD);
      rep.comm_seconds += seconds_since(s0);
    } catch (const std::exception& e) {
      const std::string text = e.what();
      MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, 0, tag_error, MPI_COMM_WORLD);
    }
  }
  const double r[4] = {rep.units, rep.samples, rep.render_seconds, rep.comm_seconds};
  MPI_Send(r, 4, MPI_DOUBLE, 0, tag_report, MPI_COMM_WORLD);
}

// ---------------------------------------------------------------------------------------
// Rank 0: hands out units in pass order, keeps results until their pass is complete.

struct CoordinatorResult {
  StopReason reason = StopReason::complete;
  RenderStats stats;
  std::string failure;  // a rank's error or silence: the job ends with it
  std::vector<WorkerReport> reports;  // per rank (index 0 unused)
};

CoordinatorResult coordinate(const Mpi& mpi, Renderer& renderer, const Units& u, Film& film, double timeout,
                             const std::atomic<bool>* stop, const std::function<void(const Film&)>& after_pass,
                             bool progress) {
  CoordinatorResult out;
  renderer.guide_restart();  // rank 0 keeps its guide's tree in step with the workers'
  const int workers = mpi.size - 1;
  const int passes = static_cast<int>(u.pass_begin.size());
  const int total_units = u.count();
  int next_unit = 0, merged_passes = 0;
  // (pass, block) -> the sums of its steps so far, and how many steps they are
  std::map<std::pair<int, int>, std::vector<double>> pending;
  std::map<std::pair<int, int>, int> pending_steps;
  std::vector<double> pass_sum;  // with light paths: a pass's sums before they join the image
  // with light paths and the guide: (pass, block, the step's place in the pass) -> that
  // step's sums of the block's pixels (3 a pixel)
  std::map<std::tuple<int, int, int>, std::vector<double>> step_sums;
  std::vector<int> returned(u.steps.size(), 0);  // per step, its blocks in
  // the first step that ends a learning iteration whose records are not summed yet: no unit
  // after it goes out before that (steps.size(): none)
  auto next_barrier = [&](size_t from) {
    while (from < u.steps.size() && !u.steps[from].barrier) ++from;
    return from;
  };
  size_t barrier = next_barrier(0);
  std::vector<int> outstanding(static_cast<size_t>(mpi.size), 0);
  std::vector<std::chrono::steady_clock::time_point> last_heard(static_cast<size_t>(mpi.size),
                                                                 std::chrono::steady_clock::now());
  auto can_send = [&] {
    return next_unit < total_units && u.order[static_cast<size_t>(next_unit)].first <= barrier;
  };
  auto send_unit = [&](int w) {
    const uint32_t unit[2] = {u.order[static_cast<size_t>(next_unit)].first, u.order[static_cast<size_t>(next_unit)].second};
    MPI_Send(unit, 2, MPI_UINT32_T, w, tag_unit, MPI_COMM_WORLD);
    ++next_unit;
    ++outstanding[static_cast<size_t>(w)];
    last_heard[static_cast<size_t>(w)] = std::chrono::steady_clock::now();
  };
  // two units in flight per worker, so none waits for rank 0 between units
  auto fill = [&] {
    for (int round = 0; round < 2; ++round)
      for (int w = 1; w <= workers && can_send(); ++w)
        if (outstanding[static_cast<size_t>(w)] < 2) send_unit(w);
  };
  fill();
  const auto t0 = std::chrono::steady_clock::now();
  bool stopping = false;
  auto stop_time = t0;
  while (merged_passes < passes) {
    if (stop && stop->load() && !stopping) {
      stopping = true;  // no new units; what is in flight may still complete a pass
      stop_time = std::chrono::steady_clock::now();
      out.reason = StopReason::cancelled;
    }
    bool busy = false;
    for (int w = 1; w <= workers; ++w) busy = busy || outstanding[static_cast<size_t>(w)] > 0;
    if (!stopping && !busy && barrier < u.steps.size() && returned[barrier] == u.step_units(barrier)) {
      // a learning iteration of the guide is complete (every unit up to it is in: none is
      // sent past it, so no worker is still recording or sending): every rank adds its
      // records into one sum and makes the guide from it; rank 0 (which records nothing)
      // waits for the sum with the timeout, as for a unit
      const uint32_t msg[2] = {static_cast<uint32_t>(barrier), 0};
      for (int w = 1; w <= workers; ++w) MPI_Send(msg, 2, MPI_UINT32_T, w, tag_guide, MPI_COMM_WORLD);
      std::vector<uint64_t> rec = renderer.guide_records();
      MPI_Request req;
      MPI_Iallreduce(MPI_IN_PLACE, rec.data(), static_cast<int>(rec.size()), MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD, &req);
      const auto r0 = std::chrono::steady_clock::now();
      for (int done = 0; !done;) {
        MPI_Test(&req, &done, MPI_STATUS_IGNORE);
        if (done) break;
        if (stop && stop->load()) {  // e.g. mpirun ending the job because a rank died
          out.reason = StopReason::cancelled;
          out.stats.seconds = seconds_since(t0);
          return out;
        }
        if (seconds_since(r0) > timeout) {
          out.failure = "the ranks have not all sent the guide's records for " + std::to_string(static_cast<int>(timeout)) +
                        " s (--mpi-timeout)";
          return out;
        }
        sleep_briefly();
      }
      renderer.guide_end_iteration(u.steps[barrier].end, rec);
      barrier = next_barrier(barrier + 1);
      fill();
      continue;
    }
    if (!busy) break;  // stopping, and nothing more will come
    // after a stop signal the units in flight get a short grace (a rank that died never answers)
    if (stopping && seconds_since(stop_time) > stop_grace_seconds) break;
    int flag = 0;
    MPI_Status st;
    MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st);
    if (!flag) {
      for (int w = 1; w <= workers; ++w)
        if (outstanding[static_cast<size_t>(w)] > 0 &&
            seconds_since(last_heard[static_cast<size_t>(w)]) > timeout) {
          out.failure = "rank " + std::to_string(w) + " has not answered for " + std::to_string(static_cast<int>(timeout)) +
                        " s (--mpi-timeout)";
          return out;
        }
      sleep_briefly();
      continue;
    }
    const int w = st.MPI_SOURCE;
    last_heard[static_cast<size_t>(w)] = std::chrono::steady_clock::now();
    if (st.MPI_TAG == tag_error) {
      int n = 0;
      MPI_Get_count(&st, MPI_CHAR, &n);
      std::string text(static_cast<size_t>(n), '\0');
      MPI_Recv(text.data(), n, MPI_CHAR, w, tag_error, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      out.failure = "rank " + std::to_string(w) + ": " + text;
      return out;
    }
    int n = 0;
    MPI_Get_count(&st, MPI_DOUBLE, &n);
    std::vector<double> msg(static_cast<size_t>(n));
    MPI_Recv(msg.data(), n, MPI_DOUBLE, w, tag_result, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    --outstanding[static_cast<size_t>(w)];
    if (!stopping && can_send()) send_unit(w);
    const int step = static_cast<int>(msg[h_step]), block = static_cast<int>(msg[h_block]);
    ++returned[static_cast<size_t>(step)];
    const int pass = u.steps[static_cast<size_t>(step)].pass;
    if (pass < 0) continue;  // the guide learning again on a resume: the image has these samples
    // a light chunk's place among its pass's chunks (over the pass's steps)
    const int key = block >= u.blocks ? u.blocks + u.step_chunk0[static_cast<size_t>(step)] + (block - u.blocks) : block;
    // a single process adds each step's camera sums and then its light chunks
    if (block < u.blocks && u.steps_apart(static_cast<size_t>(pass))) {
      std::vector<double>& own = step_sums[{pass, block, u.step_index[static_cast<size_t>(step)]}];
      for (size_t at = header_size; at < msg.size(); at += values_per_pixel) own.insert(own.end(), &msg[at], &msg[at] + 3);
    }
    // a pass's steps come in order (a barrier stands between two of one pass): their sums
    // are added as a single process adds them to the pass's film, which starts from zero
    std::vector<double>& acc = pending[{pass, key}];
    if (acc.empty()) {
      acc = std::move(msg);
    } else {
      for (int h = h_seconds; h < header_size; ++h) acc[static_cast<size_t>(h)] += msg[static_cast<size_t>(h)];
      for (size_t at = header_size; at < acc.size(); at += values_per_pixel) {
        for (int v = 0; v < values_per_pixel - 1; ++v) acc[at + static_cast<size_t>(v)] += msg[at + static_cast<size_t>(v)];
        const size_t m = at + values_per_pixel - 1;
        acc[m] = std::max(acc[m], msg[m]);
      }
    }
    ++pending_steps[{pass, key}];
    // add every pass whose blocks are all in, in pass order, blocks in order
    for (;;) {
      const int k = merged_passes;
      bool complete = k < passes;
      // the pass's light chunks (one unit each), over its steps
      const int chunks = complete ? u.pass_light_chunks(static_cast<size_t>(k)) : 0;
      for (int b = 0; b < u.blocks + chunks && complete; ++b) {
        const auto it = pending_steps.find({k, b});
        complete = it != pending_steps.end() && it->second == (b < u.blocks ? u.pass_steps[static_cast<size_t>(k)] : 1);
      }
      if (!complete) break;
      // with light paths, the pass's sums are made first (its camera paths', then its light
      // chunks' in order; with several steps, step by step) and then added to the image, as
      // a single process adds a pass
      const bool stepped = u.steps_apart(static_cast<size_t>(k));
      if (chunks > 0) pass_sum.assign(film.sum.size(), 0.0);
      auto add_chunk = [&](int b) {
        std::vector<double>& m = pending[{k, b}];
        for (size_t i = 0; i < pass_sum.size(); ++i) pass_sum[i] += m[header_size + i];
        out.stats.seconds += m[h_seconds];
        out.stats.rejected_bsdf += static_cast<uint64_t>(m[h_rej_bsdf]);
        pending.erase({k, b});
        pending_steps.erase({k, b});
      };
      if (stepped)
        for (size_t sk = 0; sk < u.steps.size(); ++sk) {
          if (u.steps[sk].pass != k) continue;
          const int si = u.step_index[sk];
          for (int b = 0; b < u.blocks; ++b) {
            const std::vector<double>& own = step_sums[{k, b, si}];
            size_t at = 0;
            for (int t : u.block_tiles(b)) {
              const TileRect r = renderer.tile_rect(t);
              for (int y = r.y0; y < r.y0 + r.h; ++y)
                for (int x = r.x0; x < r.x0 + r.w; ++x) {
                  const size_t i = static_cast<size_t>(y) * film.width + x;
                  for (int c = 0; c < 3; ++c) pass_sum[3 * i + c] += own[at++];
                }
            }
            step_sums.erase({k, b, si});
          }
          for (int j = 0; j < u.light_chunks(sk); ++j) add_chunk(u.blocks + u.step_chunk0[sk] + j);
        }
      double* sum_to = stepped ? nullptr : chunks > 0 ? pass_sum.data() : film.sum.data();
      for (int b = 0; b < u.blocks + chunks; ++b) {
        if (b >= u.blocks) {
          if (!stepped) add_chunk(b);
          continue;
        }
        std::vector<double>& m = pending[{k, b}];
        size_t at = header_size;
        for (int t : u.block_tiles(b)) {
          const TileRect r = renderer.tile_rect(t);
          for (int y = r.y0; y < r.y0 + r.h; ++y)
            for (int x = r.x0; x < r.x0 + r.w; ++x) {
              const size_t i = static_cast<size_t>(y) * film.width + x;
              for (int c = 0; c < 3; ++c, ++at)
                if (sum_to) sum_to[3 * i + c] += m[at];
              for (int c = 0; c < 3; ++c) film.sum_sq[3 * i + c] += m[at++];
              film.w_sum[i] += m[at++];
              film.w_cnt[i] += m[at++];
              film.max_sample[i] = std::max(film.max_sample[i], static_cast<float>(m[at++]));
            }
        }
        RenderStats& s = out.stats;
        s.seconds += m[h_seconds];
        s.rays_camera += static_cast<uint64_t>(m[h_rays_camera]);
        s.rays_shadow += static_cast<uint64_t>(m[h_rays_shadow]);
        s.rays_bounce += static_cast<uint64_t>(m[h_rays_bounce]);
        s.rays_bounce_visibility += static_cast<uint64_t>(m[h_rays_vis]);
        s.rejected_camera += static_cast<uint64_t>(m[h_rej_camera]);
        s.rejected_light += static_cast<uint64_t>(m[h_rej_light]);
        s.rejected_bsdf += static_cast<uint64_t>(m[h_rej_bsdf]);
        pending.erase({k, b});
        pending_steps.erase({k, b});
      }
      if (chunks > 0)
        for (size_t i = 0; i < pass_sum.size(); ++i) film.sum[i] += pass_sum[i];
      film.samples += u.pass_end[static_cast<size_t>(k)] - u.pass_begin[static_cast<size_t>(k)];
      out.stats.samples += static_cast<uint64_t>(u.pass_end[static_cast<size_t>(k)] - u.pass_begin[static_cast<size_t>(k)]) *
                           static_cast<uint64_t>(film.width) * static_cast<uint64_t>(film.height);
      ++merged_passes;
      if (after_pass) after_pass(film);
      if (progress)
        std::fprintf(stderr, "\rtuile: %d of %d passes (%llu spp) on %d ranks, %.1f s   ", merged_passes, passes,
                     static_cast<unsigned long long>(film.samples), mpi.size, seconds_since(t0));
    }
  }
  if (progress) std::fprintf(stderr, "\n");
  out.stats.seconds = seconds_since(t0);  // wall time of the distributed render
  return out;
}

// Stops every worker and collects their reports.
std::vector<WorkerReport> stop_workers(const Mpi& mpi) {
  std::vector<WorkerReport> reps(static_cast<size_t>(mpi.size));
  for (int w = 1; w < mpi.size; ++w) {
    const uint32_t none[2] = {0, 0};
    MPI_Send(none, 2, MPI_UINT32_T, w, tag_stop, MPI_COMM_WORLD);
  }
  for (int w = 1; w < mpi.size; ++w) {
    // results still in flight (after a stop) are read and dropped
    for (;;) {
      MPI_Status st;
      MPI_Probe(w, MPI_ANY_TAG, MPI_COMM_WORLD, &st);
      if (st.MPI_TAG == tag_report) {
        double r[4];
        MPI_Recv(r, 4, MPI_DOUBLE, w, tag_report, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        reps[static_cast<size_t>(w)] = {r[0], r[1], r[2], r[3]};
        break;
      }
      int n = 0;
      MPI_Get_count(&st, MPI_BYTE, &n);
      std::vector<char> drop(static_cast<size_t>(n));
      MPI_Recv(drop.data(), n, MPI_BYTE, w, st.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    }
  }
  return reps;
}

// Loads the scene on every rank (rank 0 through the render job), agreeing on errors.
// Returns false (after rank 0 printed the error once) when any rank failed.
bool load_everywhere(const Mpi& mpi, const RenderFlags& f, std::unique_ptr<RenderJob>& job,
                     std::unique_ptr<Prepared>& prepared) {
  std::string error;
  try {
    if (mpi.rank == 0) job = std::make_unique<RenderJob>(start_render_job(f));
    else prepared = std::make_unique<Prepared>(prepare(f));
  } catch (const std::exception& e) {
    error = e.what();
  }
  int failed = 0, first = 0;
  const std::string text = agree_on_errors(mpi, error, failed, first);
  if (failed == 0) return true;
  if (mpi.rank == 0)
    std::cerr << "tuile: error: " << text << " (rank " << first << "; " << failed << " of " << mpi.size
              << " ranks failed)\n";
  return false;
}

}  // namespace

int run_render_distributed(const RenderFlags& flags) {
  RenderFlags f = flags;
  Mpi mpi;
  if (f.time_budget > 0 || f.target_error > 0) {
    if (mpi.rank == 0)
      std::cerr << "tuile: error: --time-budget and --target-error are not supported under mpirun yet\n";
    return 1;
  }
  // a pixel's optimal MIS weights come from its earlier passes, which the ranks render at
  // the same time: the units would not be independent
  if (f.heuristic == "optimal") {
    if (mpi.rank == 0)
      std::cerr << "tuile: error: --heuristic optimal solves each pixel's weights from its earlier passes, which the "
                   "ranks of mpirun render at the same time; render it in one process\n";
    return 1;
  }
  std::unique_ptr<RenderJob> job;
  std::unique_ptr<Prepared> prepared;
  if (!load_everywhere(mpi, f, job, prepared)) return 1;
  const Prepared& p = mpi.rank == 0 ? *job->p : *prepared;
  Renderer renderer(p.scene, *p.accel, p.opt);
  // every rank derives the same units from the same plan; rank 0 says where a resume starts
  uint32_t done = mpi.rank == 0 ? static_cast<uint32_t>(job->film.samples) : 0;
  MPI_Bcast(&done, 1, MPI_UINT32_T, 0, MPI_COMM_WORLD);
  const uint64_t pixels = static_cast<uint64_t>(p.scene.camera.width) * static_cast<uint64_t>(p.scene.camera.height);
  const PassPlan plan = fixed_passes(pixels);
  const Units u = plan_units(renderer, plan, done, p.opt.est.spp, mpi.size - 1, p.opt.tile);
  const std::atomic<bool>& stop = install_stop_signals();
  if (mpi.rank != 0) {
    run_worker(mpi, renderer, u, p.scene.camera.width, p.scene.camera.height);
    return 0;
  }
  print_scene_warnings(f, *job);
  const auto start = std::chrono::steady_clock::now();
  auto last_checkpoint = start;
  const CoordinatorResult res = coordinate(
      mpi, renderer, u, job->film, f.mpi_timeout, &stop,
      [&](const Film& fl) {
        if (f.checkpoint_seconds > 0 && seconds_since(last_checkpoint) >= f.checkpoint_seconds) {
          try {
            save_checkpoint(job->ckpt, job->fingerprint, job->plan, fl);
          } catch (const std::exception& e) {
            std::cerr << "\ntuile: warning: " << e.what() << "\n";
          }
          last_checkpoint = std::chrono::steady_clock::now();
        }
      },
      !f.quiet && isatty(2));
  if (!res.failure.empty()) {
    std::cerr << "tuile: error: " << res.failure << "; ending the job\n";
    try {  // what rank 0 has merged is not lost
      finish_render_job(f, *job, StopReason::failed, res.stats, seconds_since(start), NAN);
    } catch (const std::exception& e) {
      std::cerr << "tuile: error: " << e.what() << "\n";
    }
    MPI_Abort(MPI_COMM_WORLD, 1);
    return 1;
  }
  if (res.reason == StopReason::cancelled) {
    // a stop signal (mpirun passes one on when it ends the job, e.g. because a rank died):
    // write the complete passes, then end every rank
    const int code = finish_render_job(f, *job, res.reason, res.stats, seconds_since(start), NAN);
    MPI_Abort(MPI_COMM_WORLD, code);
    return code;
  }
  stop_workers(mpi);
  return finish_render_job(f, *job, res.reason, res.stats, seconds_since(start), NAN);
}

int run_bench_distributed(const BenchFlags& bf) {
  Mpi mpi;
  RenderFlags f = bf.render;
  std::unique_ptr<RenderJob> job;
  std::unique_ptr<Prepared> prepared;
  f.output.clear();
  // bench writes no image: rank 0 loads through prepare like the others
  std::string error;
  try {
    prepared = std::make_unique<Prepared>(prepare(f));
  } catch (const std::exception& e) {
    error = e.what();
  }
  int failed = 0, first = 0;
  const std::string text = agree_on_errors(mpi, error, failed, first);
  if (failed > 0) {
    if (mpi.rank == 0)
      std::cerr << "tuile: error: " << text << " (rank " << first << "; " << failed << " of " << mpi.size
                << " ranks failed)\n";
    return 1;
  }
  const Prepared& p = *prepared;
  Renderer renderer(p.scene, *p.accel, p.opt);
  const uint64_t pixels = static_cast<uint64_t>(p.scene.camera.width) * static_cast<uint64_t>(p.scene.camera.height);
  const Units u = plan_units(renderer, fixed_passes(pixels), 0, p.opt.est.spp, mpi.size - 1, p.opt.tile);
  const int runs = std::max(1, bf.repeat) + std::max(0, bf.warmup);
  std::vector<double> totals;
  std::vector<WorkerReport> sum(static_cast<size_t>(mpi.size));
  for (int run = 0; run < runs; ++run) {
    if (mpi.rank != 0) {
      run_worker(mpi, renderer, u, p.scene.camera.width, p.scene.camera.height);
      continue;
    }
    Film film;
    film.reset(p.scene.camera.width, p.scene.camera.height);
    const CoordinatorResult res = coordinate(mpi, renderer, u, film, f.mpi_timeout, nullptr, {}, false);
    if (!res.failure.empty()) {
      std::cerr << "tuile: error: " << res.failure << "; ending the job\n";
      MPI_Abort(MPI_COMM_WORLD, 1);
    }
    const std::vector<WorkerReport> reps = stop_workers(mpi);
    if (run < std::max(0, bf.warmup)) continue;
    totals.push_back(static_cast<double>(res.stats.samples) / res.stats.seconds);
    for (int w = 1; w < mpi.size; ++w) {
      sum[static_cast<size_t>(w)].units += reps[static_cast<size_t>(w)].units;
      sum[static_cast<size_t>(w)].samples += reps[static_cast<size_t>(w)].samples;
      sum[static_cast<size_t>(w)].render_seconds += reps[static_cast<size_t>(w)].render_seconds;
      sum[static_cast<size_t>(w)].comm_seconds += reps[static_cast<size_t>(w)].comm_seconds;
    }
  }
  if (mpi.rank != 0) return 0;
  std::sort(totals.begin(), totals.end());
  const double median = totals[totals.size() / 2];
  std::printf("scene: %s\nranks: %d (rank 0 coordinates, %d render)\nunits per pass: %d blocks of %d tiles\n",
              p.scene.source.c_str(), mpi.size, mpi.size - 1, u.blocks, u.tiles_per_block);
  std::printf("total: %.2f M samples/s (median of %zu; min %.2f, max %.2f)\n", median * 1e-6, totals.size(),
              totals.front() * 1e-6, totals.back() * 1e-6);
  std::printf("%-6s %8s %14s %14s %16s\n", "rank", "units", "M samples/s", "render s", "communication s");
  for (int w = 1; w < mpi.size; ++w) {
    const WorkerReport& r = sum[static_cast<size_t>(w)];
    std::printf("%-6d %8.0f %14.2f %14.3f %16.3f\n", w, r.units,
                r.render_seconds > 0 ? r.samples / r.render_seconds * 1e-6 : 0.0, r.render_seconds, r.comm_seconds);
  }
  return 0;
}

}  // namespace tuile
