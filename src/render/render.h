// The tile renderer: owns the views the kernels read and the oneTBB scheduling of
// tiles. One render adds [sample_begin, sample_end) samples per pixel to a film.
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "accel/embree.h"
#include "render/film.h"
#include "render/options.h"
#include "render/profile.h"
#include "render/views.h"
#include "scene/scene.h"

namespace tuile {

struct RenderStats {
  double seconds = 0;
  uint64_t samples = 0;  // camera samples
  uint64_t rays_camera = 0, rays_shadow = 0, rays_bounce = 0;
  uint64_t rays_bounce_visibility = 0;  // occlusion rays of bounce rays that reached an emitter
  uint64_t rejected_camera = 0, rejected_light = 0, rejected_bsdf = 0;
  uint64_t path_vertices = 0;  // paths: shading points past the camera's hits
  double worst_ratio = 0;  // largest single-sample luminance relative to its pixel mean
  std::string pipeline;
  bool bounce_against_emitters = false;  // bounce rays were traced against the emitters only
  bool cancelled = false;  // the cancel flag stopped the render: some tiles did not run, the film is partial
  // Adds the counters of another render (seconds and samples included).
  void add_counts(const RenderStats& o) {
    seconds += o.seconds;
    samples += o.samples;
    rays_camera += o.rays_camera;
    rays_shadow += o.rays_shadow;
    rays_bounce += o.rays_bounce;
    rays_bounce_visibility += o.rays_bounce_visibility;
    rejected_camera += o.rejected_camera;
    rejected_light += o.rejected_light;
    rejected_bsdf += o.rejected_bsdf;
    path_vertices += o.path_vertices;
  }
};

// A tile's pixels: [x0, x0 + w) x [y0, y0 + h).
struct TileRect {
  int x0 = 0, y0 = 0, w = 0, h = 0;
};

class Guide;  // render/guide.h
class LightPaths;  // render/light_paths.h
class Bdpt;  // render/bdpt.h
struct SampleLayout;  // sample/layout.h

class Renderer {
 public:
  Renderer(const Scene& scene, const Accel& accel, const RenderOptions& options);
  ~Renderer();
  // Adds samples [begin, end) of every pixel to the film. Not reentrant: the per-thread
  // tile buffers are kept from one call to the next (progressive renders and converge
  // do not pay for them again).
  // With `only`, just those tiles run (their pixels get the bits a whole render gives them;
  // the others are left alone): the unit of work of a distributed render.
  // With --heuristic optimal, each pixel's weights are solved from the moments of its
  // earlier samples: those in `prior` when given (the image a pass film is added to),
  // else those already in the film.
  // With --guide, samples [begin, end) are guided by what the samples before them taught
  // the guide (render/guide.h): a render that starts where the guide has not learned
  // (a resumed one) first renders the samples it learns from, into a film it drops.
  RenderStats render(Film& film, uint32_t begin, uint32_t end, Profile* profile = nullptr,
                     const std::vector<int>* only = nullptr, const Film* prior = nullptr);
  // --guide: the guide (null without)
  const Guide* guide() const { return guide_.get(); }
  // --guide in a distributed render (dist/mpi_render.cpp), where every process steps its
  // guide through the learning iterations together with the others:
  // - render_guided_part adds samples [begin, end) of the tiles `only` with the guide as it
  //   stands, recording into it where begin < learn; the range lies within one learning
  //   iteration (Guide::iteration_end), or after learning;
  // - guide_records gives what this process recorded since the last iteration ended;
  // - guide_end_iteration makes the guide of samples [0, until) (until an iteration's end)
  //   from the sums of every process's records;
  // - guide_restart forgets what the guide learned (a new render from sample 0).
  // Fed the same sums, every process makes the guide a single process makes.
  RenderStats render_guided_part(Film& film, uint32_t begin, uint32_t end, const std::vector<int>& only);
  std::vector<uint64_t> guide_records() const;
  void guide_end_iteration(uint32_t until, const std::vector<uint64_t>& sums);
  void guide_restart();
  int tile_count() const;
  TileRect tile_rect(int tile) const;
  // --light-paths (null light tracer: none): a render's light paths, traced after its
  // camera paths, come in chunks of about 2^22 paths (light_chunk_samples() samples of
  // every pixel, counted from the render's begin), each added into a zeroed image of
  // width x height x 3 doubles in tile order and then to the film: a distributed render
  // (dist/mpi_render.cpp) traces the chunks on any rank with render_light_chunk and adds
  // them in the same order, for the single process's bits. render(..., only) leaves its
  // light paths out when set_light_paths_apart(true), and refuses them otherwise.
  // --bdpt renders everything this way (its camera paths' splats too): render(..., only)
  // then renders nothing of its own.
  bool has_light_paths() const { return light_paths_ != nullptr || bdpt_ != nullptr; }
  // What the light tracer emits from (LightPaths::describe), or "" without one.
  std::string light_paths_sources() const;
  // What bdpt's light subpaths start from (Bdpt::describe), or "" without bdpt.
  std::string bdpt_sources() const;
  uint32_t light_chunk_samples() const;
  RenderStats render_light_chunk(std::vector<double>& sums, uint32_t begin, uint32_t end);
  void set_light_paths_apart(bool apart) { light_paths_apart_ = apart; }
  // The pipeline this scene and estimator select, and why.
  std::string pipeline_name(std::string* why = nullptr) const;
  // Whether bounce rays run against the emitters (BounceTrace resolved for this scene).
  bool bounce_against_emitters() const { return bounce_against_emitters_; }
  const RenderOptions& options() const { return opt_; }
  // The light BVH (--light-pick bvh with two sources or more; else null) and its build time.
  const LightBvh* light_bvh() const;
  double light_bvh_seconds() const;
  // The alias table's probability of picking source i (the scene's order; 1 for every
  // source with --light-pick all), as this estimator's light samples use it.
  float light_pick_probability(int i) const;
  // A flag (set from anywhere, e.g. a signal handler) that stops a render at the next tile
  // boundary: the tiles not yet started are skipped and RenderStats::cancelled is set.
  void set_cancel_flag(const std::atomic<bool>* flag) { cancel_ = flag; }

 private:
  int light_passes() const;  // the light samples' sampler pairs a vertex takes
  int bsdf_passes() const;   // the BSDF samples'
  SampleLayout sample_layout() const;
  void trace_light_paths(std::vector<double>& sums, uint32_t s0, uint32_t s1, std::atomic<bool>& skipped);
  RenderStats render_range(Film& film, uint32_t begin, uint32_t end, Profile* profile, const std::vector<int>* only,
                           const Film* prior, bool record);
  // --guide: brings the guide to what samples [0, min(begin, learn)) teach it
  bool guide_catch_up(uint32_t begin);
  void guide_rebuild(uint32_t until);
  const Scene& scene_;
  const Accel& accel_;
  RenderOptions opt_;
  std::unique_ptr<SceneViews> views_;
  bool bounce_against_emitters_ = false;
  struct BufferPool;  // per-thread TileBuffers, made on a thread's first tile
  std::unique_ptr<BufferPool> pool_;
  const std::atomic<bool>* cancel_ = nullptr;
  std::unique_ptr<Guide> guide_;
  uint32_t guide_recorded_ = 0;  // the samples [0, n) whose records the guide holds or learned from
  std::unique_ptr<LightPaths> light_paths_;  // --light-paths, where there is something to trace
  bool light_paths_apart_ = false;
  std::unique_ptr<Bdpt> bdpt_;  // --bdpt
};

}  // namespace tuile
