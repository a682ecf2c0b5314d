// The tile renderer: owns the light/geometry views the kernels read, the film, and the
// oneTBB scheduling of tiles. One render = [sample_begin, sample_end) samples per pixel.
#pragma once
#include <cstdint>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "../kernels/tile.h"
#include "embree.h"
#include "scene.h"

namespace tuile {

// What a BSDF (bounce) ray is traced against. scene: its nearest hit in the whole scene.
// emitters: its nearest emitter, then, for the rays that reach the front of one, an
// occlusion ray up to it (2^-12 short, as shadow rays): the same estimator, with far
// fewer nodes visited where the emitters are a small part of the scene. automatic:
// emitters where they are at most half of the scene's primitives.
enum class BounceTrace : int { automatic = 0, scene = 1, emitters = 2 };

struct RenderOptions {
  Estimator est;
  BounceTrace bounce = BounceTrace::automatic;
  int threads = 0;    // 0 = all cores
  int tile = 16;      // 16 or 32 (any 1..32 accepted)
  bool aov_variance = false;
  bool aov_mis_weight = false;
  bool general_pipeline = false;  // --pipeline general: the unspecialised reference
};

// The stages of a tile, as profiled.
enum class Stage : int {
  generate = 0,
  intersect_camera,
  camera_hits,
  sample_lights,
  intersect_shadow,
  sample_cosine,
  intersect_bounce,
  mis_weight,
  accumulate,
};
inline constexpr int stage_count = 9;
const char* stage_name(Stage s);

struct TraceEvent {
  Stage stage;
  int tile;
  double start_us, dur_us;
  int thread = 0;
};

template <class P> struct RecordedPacket {
  P packet;
  int32_t valid[packet_width];
};
// The packets one pass traces, in order (profile --roofline).
struct RayRecord {
  std::vector<RecordedPacket<RayHit16>> camera, bounce;
  std::vector<RecordedPacket<Ray16>> shadow;  // shadow rays and bounce visibility rays
  bool bounce_emitters = false;               // bounce rays were traced against the emitters
};

// Filled by Renderer::render when given: time per stage summed over threads, and
// optionally one trace event per stage call.
struct Profile {
  bool trace = false;
  size_t max_events = 2000000;  // per thread
  int threads = 1;
  double wall_seconds = 0;
  double stage_seconds[stage_count] = {};
  std::vector<TraceEvent> events;
  bool record_rays = false;  // keep the first pass's packets in `rays`
  RayRecord rays;
};

// Traces the recorded packets through Embree alone, in the same packets and flags, with
// the given thread count; returns the seconds taken (the roofline's bound).
double replay_rays(const Accel& accel, const RayRecord& rays, int threads);
// The same rays as pointer-SoA streams (rtcIntersectNp), one stream per tile's packets;
// the time includes a copy of each stream, as the packet replay includes its copies.
double replay_rays_stream(const Accel& accel, const RayRecord& rays, int threads);

// Allocates on 64-byte boundaries (whole cache lines: the film's rows are streamed).
template <class T> struct CacheLineAllocator {
  using value_type = T;
  CacheLineAllocator() = default;
  template <class U> CacheLineAllocator(const CacheLineAllocator<U>&) noexcept {}
  T* allocate(size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(64))); }
  void deallocate(T* p, size_t) noexcept { ::operator delete(p, std::align_val_t(64)); }
  template <class U> bool operator==(const CacheLineAllocator<U>&) const noexcept { return true; }
};
template <class T> using FilmArray = std::vector<T, CacheLineAllocator<T>>;

// Per-pixel sums in double: 10^7 samples in one pixel lose nothing. A film without
// samples holds zeros (reset).
struct Film {
  int width = 0, height = 0;
  uint64_t samples = 0;  // per pixel
  FilmArray<double> sum;     // 3 per pixel
  FilmArray<double> sum_sq;  // 3 per pixel
  FilmArray<double> w_sum;   // BSDF-technique MIS weight, summed over emitter hits
  FilmArray<double> w_cnt;
  FilmArray<float> max_sample;  // largest single-sample luminance
  void reset(int w, int h);
  // mean radiance, variance of the mean (per channel), mean BSDF MIS weight
  float mean_of(size_t k) const { return static_cast<float>(sum[k] / static_cast<double>(samples)); }  // samples > 0
  std::vector<float> mean() const;
  std::vector<float> variance_of_mean() const;
  std::vector<float> mis_weight() const;
};

struct RenderStats {
  double seconds = 0;
  uint64_t samples = 0;  // camera samples
  uint64_t rays_camera = 0, rays_shadow = 0, rays_bounce = 0;
  uint64_t rays_bounce_visibility = 0;  // occlusion rays of bounce rays that reached an emitter
  uint64_t rejected_camera = 0, rejected_light = 0, rejected_bsdf = 0;
  double worst_ratio = 0;  // largest single-sample luminance relative to its pixel mean
  std::string pipeline;
  bool bounce_emitters = false;  // bounce rays were traced against the emitters only
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
  }
};

// The scene as the kernels read it: SoA light table (with the pick distribution and its
// alias table), per-geometry lookups, camera. The views point into the vectors here and
// into the Scene, which must outlive them.
struct SceneViews {
  // light table, SoA
  std::vector<int32_t> type;
  SceneViews() = default;
  SceneViews(const SceneViews&) = delete;
  SceneViews& operator=(const SceneViews&) = delete;
  SceneViews(SceneViews&&) = default;
  SceneViews& operator=(SceneViews&&) = default;
  std::vector<float> p0x, p0y, p0z, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, Lr, Lg, Lb, area, two_sided;
  std::vector<float> len1, len2, inv_len1, inv_len2, rect, exx, exy, exz, eyx, eyy, eyz;
  std::vector<float> pick_pdf, alias_prob;
  std::vector<int32_t> alias_idx;
  LightView lights;
  // geometry
  std::vector<float> sphere_center;
  std::vector<int32_t> geom_material, sphere_light, mat_texture, tex_w, tex_h;
  std::vector<int32_t> tri_offset, tri_light;
  std::vector<float> tri_pos;
  std::vector<const uint32_t*> indices;
  std::vector<const float*> positions;
  std::vector<const float*> uvs, tex_rgb;
  std::vector<float> mat_r, mat_g, mat_b;
  GeomView geom;
  CameraView camera;
  bool has_area = false, has_delta = false;
  bool all_rects = true;  // every source is a rectangle (Urena's map, no type dispatch)
};


SceneViews build_views(const Scene& scene, LightPick pick);

class Renderer {
 public:
  Renderer(const Scene& scene, const Accel& accel, const RenderOptions& options);
  ~Renderer();
  // Adds samples [begin, end) of every pixel to the film. Not reentrant: the per-thread
  // tile buffers are kept from one call to the next (progressive renders and converge
  // do not pay for them again).
  RenderStats render(Film& film, uint32_t begin, uint32_t end, Profile* profile = nullptr);
  // The pipeline this scene and estimator select, and why.
  std::string pipeline_name(std::string* why = nullptr) const;
  // Whether bounce rays run against the emitters (BounceTrace resolved for this scene).
  bool bounce_emitters() const { return bounce_emitters_; }
  const RenderOptions& options() const { return opt_; }

 private:
  const Scene& scene_;
  const Accel& accel_;
  RenderOptions opt_;
  std::unique_ptr<SceneViews> views_;
  bool bounce_emitters_ = false;
  struct BufferPool;  // per-thread TileBuffers, made on a thread's first tile
  std::unique_ptr<BufferPool> pool_;
};

// Parses the names used on the command line and in scene files; throw std::invalid_argument.
Strategy parse_strategy(const std::string& s);
LightPick parse_light_pick(const std::string& s);
LightPoint parse_light_point(const std::string& s);
Heuristic parse_heuristic(const std::string& s);
MisMode parse_mis_mode(const std::string& s);
SamplerKind parse_sampler(const std::string& s);
BounceTrace parse_bounce_trace(const std::string& s);
std::string describe(const Estimator& e);

}  // namespace tuile
