// Renderer: one render of [begin, end) samples per pixel, as oneTBB tasks of one tile
// each on per-worker tile buffers kept from one render to the next.
#include "render/render.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <x86intrin.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "render/filter_table.h"
#include "render/guide.h"
#include "render/bdpt.h"
#include "render/light_paths.h"
#include "render/tile_pipeline.h"
#include "wave/accumulate.h"
#include "wave/optimal_mis.h"

namespace tuile {

using clock_type = std::chrono::steady_clock;

// Each worker's tile buffers (about 0.7 MB), made once and reused by every render: making
// them per render (zeroed, so page faults on every call) cost a measurable share of short
// progressive renders.
struct Renderer::BufferPool {
  tbb::enumerable_thread_specific<std::unique_ptr<TileBuffers>> buffers{[] { return std::make_unique<TileBuffers>(); }};
};

Renderer::Renderer(const Scene& scene, const Accel& accel, const RenderOptions& options)
    : scene_(scene), accel_(accel), opt_(options), views_(std::make_unique<SceneViews>()),
      pool_(std::make_unique<BufferPool>()) {
  validate(opt_);
  opt_.est.aov_mis_weight = opt_.est.aov_mis_weight || opt_.aov_mis_weight;
  // the skies' maps are sampled by their compensated distributions where BSDF sampling
  // covers every direction beside the light technique (light/sky_map.h), and the power
  // picker then weighs a sky by that part of it
  const Estimator& e = opt_.est;
  const bool bsdf_covers = (e.strategy == Strategy::mis && e.bsdf_samples > 0) || (e.strategy == Strategy::ris && e.ris_bsdf > 0);
  *views_ = build_views(scene, opt_.est.pick, bsdf_covers);
  views_->lights.sky_dist = bsdf_covers ? sky_dist_compensated : sky_dist_full;
  // optimal MIS takes a BSDF sample that escapes as one point of the sky, whose light density
  // is that of the one sky (several skies would each see the same direction)
  if (optimal_mis(e) && views_->lights.sky_count > 1)
    throw std::invalid_argument("--heuristic optimal: the scene has " + std::to_string(views_->lights.sky_count) +
                                " skies (LightSource \"infinite\" with different maps); it handles one");
  views_->camera.filter = build_filter(opt_.filter, views_->filter_table);  // the pixel filter's tables, once
  // Bounce rays against the emitters alone (then an occlusion ray to the emitter a ray
  // reaches, or, where there is a sky, to infinity for a ray that reaches none): a ray
  // that starts in a medium, or that may pass an "interface" surface into one, needs its
  // nearest hit in the scene (its flight decides what it reaches). In a scene with media
  // but no interfaces, a ray that starts in vacuum meets no medium before a surface.
  const bool interfaces = (scene.features & feat_media) != 0 && views_->geom.media.has_interfaces;
  if (interfaces && opt_.bounce == BounceTrace::emitters)
    throw std::invalid_argument("--bounce-rays emitters: the scene has \"interface\" surfaces between media, which only rays "
                                "traced against the whole scene pass; use --bounce-rays scene or auto");
  if (interfaces) {
    bounce_against_emitters_ = false;
  } else if (opt_.bounce == BounceTrace::automatic) {
    size_t all = scene.spheres.size() + scene.instanced_triangle_count(), emitting = 0;
    for (const Mesh& m : scene.meshes)
      if (m.emissive()) emitting += m.triangle_count();
    for (const Sphere& sp : scene.spheres) emitting += sp.emissive();
    bounce_against_emitters_ = 2 * emitting <= all;
  } else {
    bounce_against_emitters_ = opt_.bounce == BounceTrace::emitters;
  }
  // resampled importance sampling's BSDF candidates look for the nearest emitter alone
  if (bounce_against_emitters_ || (opt_.est.strategy == Strategy::ris && opt_.est.ris_bsdf > 0)) accel_.prepare_emitters();
  if (opt_.est.guide) {  // the guide's stages run in the general pipeline
    opt_.general_pipeline = true;
    float lo[3], hi[3];
    accel_.bounds(lo, hi);
    guide_ = std::make_unique<Guide>(lo, hi, opt_.est.guide_learn, opt_.est.guide_alpha);
  }
  if (opt_.est.light_paths) {  // (inactive without an area light or a delta lobe: the path tracer has every path)
    float lo[3], hi[3];
    accel_.bounds(lo, hi);
    light_paths_ = std::make_unique<LightPaths>(scene, *views_, opt_.est, scene.camera.width, scene.camera.height, lo, hi);
    if (!light_paths_->active()) light_paths_.reset();
  }
  if (opt_.est.bdpt) {
    float lo[3], hi[3];
    accel_.bounds(lo, hi);
    bdpt_ = std::make_unique<Bdpt>(scene, *views_, opt_.est, scene.camera.width, scene.camera.height, lo, hi);
  }
}

Renderer::~Renderer() = default;

const LightBvh* Renderer::light_bvh() const { return views_->light_bvh.get(); }
double Renderer::light_bvh_seconds() const { return views_->light_bvh_seconds; }
float Renderer::light_pick_probability(int i) const { return views_->lights.pick_pdf[i]; }

int Renderer::tile_count() const {
  const int ts = opt_.tile;
  return div_up(scene_.camera.width, ts) * div_up(scene_.camera.height, ts);
}

TileRect Renderer::tile_rect(int tile) const {
  const int ts = opt_.tile, tiles_x = div_up(scene_.camera.width, ts);
  TileRect r;
  r.x0 = (tile % tiles_x) * ts;
  r.y0 = (tile / tiles_x) * ts;
  r.w = std::min(ts, scene_.camera.width - r.x0);
  r.h = std::min(ts, scene_.camera.height - r.y0);
  return r;
}

std::string Renderer::pipeline_name(std::string* why) const {
  std::string w;
  const PipelineEntry e = pick_pipeline(*views_, opt_.est, opt_.general_pipeline, w);
  if (why) *why = w;
  return e.name;
}

void Renderer::guide_rebuild(uint32_t until) {
  guide_->rebuild(until);
  views_->geom.guide = guide_->distributions() > 0 ? &guide_->view() : nullptr;
}

bool Renderer::guide_catch_up(uint32_t begin) {
  const uint32_t want = std::min(begin, guide_->learn());
  if (guide_recorded_ == want) return true;
  guide_->reset();
  views_->geom.guide = nullptr;
  guide_recorded_ = 0;
  Film scratch;
  for (uint32_t s = 0; s < want;) {
    const uint32_t e = std::min(want, guide_->iteration_end(s));
    const RenderStats st = render_range(scratch, s, e, nullptr, nullptr, nullptr, true);
    if (st.cancelled) {
      guide_->reset();
      views_->geom.guide = nullptr;
      return false;
    }
    if (e == guide_->iteration_end(s)) guide_rebuild(e);
    s = guide_recorded_ = e;
  }
  return true;
}

RenderStats Renderer::render_guided_part(Film& film, uint32_t begin, uint32_t end, const std::vector<int>& only) {
  if (!guide_) throw std::logic_error("render_guided_part without --guide");
  const bool learning = begin < guide_->learn();
  if (learning && (end > guide_->iteration_end(begin) || guide_->learned() > begin ||
                   guide_->iteration_end(guide_->learned()) < guide_->iteration_end(begin)))
    throw std::logic_error("render_guided_part: samples [" + std::to_string(begin) + ", " + std::to_string(end) +
                           ") are not in the learning iteration after the guide's " + std::to_string(guide_->learned()));
  if (!learning && guide_->learned() != guide_->learn())
    throw std::logic_error("render_guided_part: the guide has not finished learning");
  return render_range(film, begin, end, nullptr, &only, nullptr, learning);
}

std::vector<uint64_t> Renderer::guide_records() const {
  if (!guide_) throw std::logic_error("guide_records without --guide");
  return guide_->records();
}

void Renderer::guide_end_iteration(uint32_t until, const std::vector<uint64_t>& sums) {
  if (!guide_) throw std::logic_error("guide_end_iteration without --guide");
  guide_->set_records(sums);
  guide_rebuild(until);
  guide_recorded_ = until;
}

void Renderer::guide_restart() {
  if (!guide_) return;
  guide_->reset();
  views_->geom.guide = nullptr;
  guide_recorded_ = 0;
}

RenderStats Renderer::render(Film& film, uint32_t begin, uint32_t end, Profile* profile, const std::vector<int>* only,
                             const Film* prior) {
  if (!guide_) return render_range(film, begin, end, profile, only, prior, false);
  if (only)
    throw std::invalid_argument("--guide learns from every tile of a pass on one process: it does not render a part of "
                                "the tiles (a distributed render)");
  RenderStats total;
  total.cancelled = !guide_catch_up(begin);
  for (uint32_t s = begin; s < end && !total.cancelled;) {
    const bool learning = s < guide_->learn();
    const uint32_t e = learning ? std::min(end, guide_->iteration_end(s)) : end;
    const RenderStats st = render_range(film, s, e, profile, nullptr, prior, learning);
    const double worst = std::max(total.worst_ratio, st.worst_ratio);
    total.add_counts(st);
    total.worst_ratio = worst;
    total.pipeline = st.pipeline;
    total.bounce_against_emitters = st.bounce_against_emitters;
    if (st.cancelled) {  // the film is partial and will be dropped: so are the records
      total.cancelled = true;
      guide_->drop_records();
      guide_recorded_ = guide_->learned();
      break;
    }
    if (learning && e == guide_->iteration_end(s)) guide_rebuild(e);
    s = e;
    if (learning) guide_recorded_ = e;
  }
  return total;
}

// ris: the light candidates' pairs, and the BSDF candidates' and the last BSDF sample's
// (the path's continuation, the delta lobes)
int Renderer::light_passes() const {
  const Estimator& est = opt_.est;
  return est.strategy == Strategy::ris
             ? est.ris_light
             : (est.pick == LightPick::all ? views_->lights.count : 1) * (est.one_sample() ? 1 : est.light_samples);
}

int Renderer::bsdf_passes() const {
  const Estimator& est = opt_.est;
  return est.strategy == Strategy::ris ? est.ris_bsdf + 1 : est.one_sample() ? 1 : est.bsdf_samples;
}

SampleLayout Renderer::sample_layout() const {
  const Estimator& est = opt_.est;
  const bool has_media = views_->geom.has_media;
  return SampleLayout{static_cast<uint32_t>(est.strategy == Strategy::ris ? bsdf_passes() : est.bsdf_samples),
                      static_cast<uint32_t>(light_passes()), has_media, has_media && est.equiangular};
}

std::string Renderer::light_paths_sources() const { return light_paths_ ? light_paths_->describe() : std::string(); }
std::string Renderer::bdpt_sources() const { return bdpt_ ? bdpt_->describe() : std::string(); }

uint32_t Renderer::light_chunk_samples() const {
  const uint64_t pixels = static_cast<uint64_t>(scene_.camera.width) * static_cast<uint64_t>(scene_.camera.height);
  return static_cast<uint32_t>(std::min<uint64_t>(1u << 20, std::max<uint64_t>(1, (uint64_t(1) << 22) / std::max<uint64_t>(1, pixels))));
}

// Samples [s0, s1) of every pixel's light paths, in batches of about 2^20 paths (their
// splats kept per tile), each batch's splats added to sums in tile order. An image of more
// than 2^20 pixels takes a batch's tiles in groups of about 2^20 pixels (at least 8 tiles a
// thread), each group's splats added once it is done: the same additions in the same order
// (tile by tile, each tile's in the order its paths made them), with the splats of one group
// in memory instead of the whole image's (bdpt at 3840x2160 held 1.7 GB).
void Renderer::trace_light_paths(std::vector<double>& sums, uint32_t s0, uint32_t s1, std::atomic<bool>& skipped) {
  const Camera& cam = scene_.camera;
  const Estimator& est = opt_.est;
  const uint32_t first_pair = sample_layout().depth_base(static_cast<uint32_t>(est.max_depth));
  const int ts = opt_.tile, tiles_x = div_up(cam.width, ts), tiles = tiles_x * div_up(cam.height, ts);
  const uint64_t all_pixels = static_cast<uint64_t>(cam.width) * static_cast<uint64_t>(cam.height);
  const uint32_t batch = static_cast<uint32_t>(std::max<uint64_t>(1, (uint64_t(1) << 20) / std::max<uint64_t>(1, all_pixels)));
  auto& buffers = pool_->buffers;
  const int threads = opt_.threads > 0 ? opt_.threads : tbb::this_task_arena::max_concurrency();
  const int group = std::max(8 * threads, static_cast<int>((uint64_t(1) << 20) / (static_cast<uint64_t>(ts) * static_cast<uint64_t>(ts))));
  tbb::task_arena arena(threads);
  std::vector<std::vector<LightPathSplat>> splats(static_cast<size_t>(tiles));
  for (uint32_t b0 = s0; b0 < s1 && !skipped.load(); b0 += std::min(batch, s1 - b0)) {
    const uint32_t b1 = b0 + std::min(batch, s1 - b0);
    for (int g0 = 0; g0 < tiles && !skipped.load(); g0 += group) {
      const int g1 = std::min(tiles, g0 + group);
      arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<int>(g0, g1, 1),
                          [&](const tbb::blocked_range<int>& r) {
                            TileBuffers& tb = *buffers.local();
                            for (int t = r.begin(); t < r.end(); ++t) {
                              if (cancel_ && cancel_->load(std::memory_order_relaxed)) {
                                skipped.store(true, std::memory_order_relaxed);
                                return;
                              }
                              if (bdpt_)
                                bdpt_->trace_tile(accel_, tb, t, ts, tiles_x, b0, b1, splats[static_cast<size_t>(t)],
                                                  tb.stats.rejected_bsdf);
                              else
                                light_paths_->trace_tile(accel_, tb, t, ts, tiles_x, b0, b1, first_pair,
                                                         splats[static_cast<size_t>(t)], tb.stats.rejected_bsdf);
                            }
                          },
                          tbb::simple_partitioner());
      });
      if (skipped.load()) break;
      for (int t = g0; t < g1; ++t) {
        std::vector<LightPathSplat>& list = splats[static_cast<size_t>(t)];
        for (const LightPathSplat& sp : list) {
          double* px = sums.data() + 3 * static_cast<size_t>(sp.pixel);
          px[0] += sp.r;
          px[1] += sp.g;
          px[2] += sp.b;
        }
        std::vector<LightPathSplat>().swap(list);  // (its memory too: the next groups' tiles are others)
      }
    }
  }
}

RenderStats Renderer::render_light_chunk(std::vector<double>& sums, uint32_t begin, uint32_t end) {
  if (!has_light_paths()) throw std::logic_error("render_light_chunk: the render has no light paths");
  const auto t0 = clock_type::now();
  const size_t n = 3 * static_cast<size_t>(scene_.camera.width) * static_cast<size_t>(scene_.camera.height);
  sums.assign(n, 0.0);
  auto& buffers = pool_->buffers;
  for (auto& p : buffers) p->stats.reset();
  std::atomic<bool> skipped{false};
  trace_light_paths(sums, begin, end, skipped);
  RenderStats st;
  st.seconds = std::chrono::duration<double>(clock_type::now() - t0).count();
  st.cancelled = skipped.load();
  for (auto& p : buffers) st.rejected_bsdf += p->stats.rejected_bsdf;
  return st;
}

RenderStats Renderer::render_range(Film& film, uint32_t begin, uint32_t end, Profile* profile, const std::vector<int>* only,
                                   const Film* prior, bool record) {
  const Camera& cam = scene_.camera;
  if (film.width != cam.width || film.height != cam.height) film.reset(cam.width, cam.height);
  const SceneViews& v = *views_;
  const Estimator& est = opt_.est;
  const bool one = est.one_sample();
  const float c_l = one ? est.one_sample_light_prob() : 0.f;
  const int ts = opt_.tile;
  TileContext c{v,
                accel_,
                est,
                film,
                ts,
                div_up(cam.width, ts),
                cam.width,
                cam.height,
                light_passes(),
                bsdf_passes(),
                v.lights.count,
                SampleLayout{},
                one ? c_l : static_cast<float>(est.light_samples),
                one ? 1.f - c_l : static_cast<float>(est.bsdf_samples),
                bounce_against_emitters_,
                film.samples == 0,
                profile,
                __rdtsc()};
  if (optimal_mis(est)) {  // the moments of optimal MIS (wave/optimal_mis.h)
    const size_t n = static_cast<size_t>(cam.width) * static_cast<size_t>(cam.height);
    if (film.optimal.size() != 9 * n) film.optimal.assign(9 * n, 0.0);
    const Film& before = prior ? *prior : film;
    if (before.samples > 0 && before.optimal.size() == 9 * n) {
      c.opt_prior = before.optimal.data();
      c.opt_prior_samples = before.samples;
    }
    c.opt_film = film.optimal.data();
  }
  if (record) c.guide_rec = guide_.get();
  c.layout = sample_layout();
  std::string why;
  const PipelineEntry pipe = pick_pipeline(v, est, opt_.general_pipeline, why);
  const int all_tiles = c.tiles_x * (div_up(cam.height, ts));
  const int tiles = only ? static_cast<int>(only->size()) : all_tiles;

  auto& buffers = pool_->buffers;
  for (auto& p : buffers) p->stats.reset();
  tbb::enumerable_thread_specific<ThreadProfile> profiles;
  const auto t0 = clock_type::now();
  const uint64_t ticks0 = __rdtsc();
  const int threads = opt_.threads > 0 ? opt_.threads : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(threads);
  std::atomic<bool> skipped{false};
  if (!bdpt_) arena.execute([&] {  // (bdpt: every contribution comes with the light chunks below)
    tbb::parallel_for(tbb::blocked_range<int>(0, tiles, 1),
                      [&](const tbb::blocked_range<int>& r) {
                        TileBuffers& tb = *buffers.local();
                        ThreadProfile* tp = profile ? &profiles.local() : nullptr;
                        for (int t = r.begin(); t < r.end(); ++t) {
                          if (cancel_ && cancel_->load(std::memory_order_relaxed)) {
                            skipped.store(true, std::memory_order_relaxed);
                            return;
                          }
                          pipe.fn(c, tb, tp, only ? (*only)[static_cast<size_t>(t)] : t, begin, end);
                        }
                      },
                      tbb::simple_partitioner());
  });
  // --light-paths: the light tracer's paths of every pixel, chunk by chunk (render.h), each
  // chunk's splats added into a zeroed image and that image to the film
  if (has_light_paths() && !skipped.load()) {
    if (only && !light_paths_apart_)
      throw std::invalid_argument(std::string(bdpt_ ? "--bdpt" : "--light-paths") + ": a light path lands anywhere in the image, so the light tracer does not "
                                  "render a part of the tiles alone");
    if (!only) {
      std::vector<double> sums;
      for (uint32_t s0 = begin; s0 < end && !skipped.load();) {
        const uint32_t s1 = s0 + std::min(light_chunk_samples(), end - s0);
        sums.assign(film.sum.size(), 0.0);
        trace_light_paths(sums, s0, s1, skipped);
        if (skipped.load()) break;
        for (size_t i = 0; i < sums.size(); ++i) film.sum[i] += sums[i];
        s0 = s1;
      }
    }
  }
  RenderStats st;
  st.seconds = std::chrono::duration<double>(clock_type::now() - t0).count();
  const double sec_per_tick = st.seconds / static_cast<double>(std::max<uint64_t>(1, __rdtsc() - ticks0));
  st.pipeline = bdpt_ ? "bdpt" : pipe.name;
  st.cancelled = skipped.load();
  st.bounce_against_emitters = bounce_against_emitters_;
  film.samples += end - begin;
  uint64_t pixels = static_cast<uint64_t>(cam.width) * static_cast<uint64_t>(cam.height);
  if (only) {
    pixels = 0;
    for (int t : *only) {
      const TileRect r = tile_rect(t);
      pixels += static_cast<uint64_t>(r.w) * static_cast<uint64_t>(r.h);
    }
  }
  st.samples = static_cast<uint64_t>(end - begin) * pixels;
  for (auto& p : buffers) {
    st.rays_camera += p->stats.rays_camera;
    st.rays_shadow += p->stats.rays_shadow;
    st.rays_bounce += p->stats.rays_bounce;
    st.rays_bounce_visibility += p->stats.rays_bounce_visibility;
    st.rejected_camera += p->stats.rejected_camera;
    st.rejected_light += p->stats.rejected_light;
    st.rejected_bsdf += p->stats.rejected_bsdf;
    st.path_vertices += p->stats.path_vertices;
  }
  if (profile) {
    profile->threads = threads;
    profile->wall_seconds += st.seconds;
    int tid = 0;
    for (ThreadProfile& tp : profiles) {
      for (int k = 0; k < stage_count; ++k)
        profile->stage_seconds[k] += static_cast<double>(tp.stage_ticks[k]) * sec_per_tick;
      for (int d = 0; d < profile_depths; ++d) {
        if (tp.depth_points[d] == 0 && tp.depth_lane_packets[d] == 0) continue;
        profile->depths = std::max(profile->depths, d + 1);
        for (int k = 0; k < stage_count; ++k)
          profile->depth_seconds[d][k] += static_cast<double>(tp.depth_ticks[d][k]) * sec_per_tick;
        profile->depth_points[d] += static_cast<double>(tp.depth_points[d]);
        profile->depth_packets[d] += static_cast<double>(tp.depth_packets[d]);
        profile->depth_lane_packets[d] += static_cast<double>(tp.depth_lane_packets[d]);
      }
      for (TraceEvent e : tp.events) {
        e.thread = tid;
        e.start_us *= sec_per_tick * 1e6;  // recorded in ticks
        e.dur_us *= sec_per_tick * 1e6;
        profile->events.push_back(e);
      }
      auto append = [](auto& dst, auto& src) { dst.insert(dst.end(), src.begin(), src.end()); };
      append(profile->rays.camera, tp.rays.camera);
      append(profile->rays.shadow, tp.rays.shadow);
      append(profile->rays.bounce, tp.rays.bounce);
      append(profile->rays.bounce_emitters, tp.rays.bounce_emitters);
      ++tid;
    }
  }
  // the worst accident, from the pixel means (no mean image allocated; not for a part of the tiles)
  for (size_t i = 0; i < film.max_sample.size() && film.samples > 0 && !only; ++i) {
    const float y = luminance(film.mean_of(3 * i), film.mean_of(3 * i + 1), film.mean_of(3 * i + 2));
    if (y > 0) st.worst_ratio = std::max(st.worst_ratio, static_cast<double>(film.max_sample[i] / y));
  }
  return st;
}

}  // namespace tuile
