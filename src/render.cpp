#include "render.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <x86intrin.h>
#include <chrono>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include "../kernels/accumulate.h"
#include "../kernels/generate.h"
#include "../kernels/hit.h"
#include "../kernels/sample_cosine.h"
#include "../kernels/sample_lights.h"
#include "../kernels/weight.h"

namespace tuile {

void Film::reset(int w, int h) {
  width = w;
  height = h;
  samples = 0;
  const size_t n = static_cast<size_t>(w) * h;
  sum.assign(3 * n, 0.0);
  sum_sq.assign(3 * n, 0.0);
  w_sum.assign(n, 0.0);
  w_cnt.assign(n, 0.0);
  max_sample.assign(n, 0.f);
}

std::vector<float> Film::mean() const {
  std::vector<float> out(sum.size(), 0.f);
  if (samples == 0) return out;
  for (size_t i = 0; i < sum.size(); ++i) out[i] = mean_of(i);
  return out;
}

std::vector<float> Film::variance_of_mean() const {
  std::vector<float> out(sum.size(), 0.f);
  if (samples < 2) return out;
  const double n = static_cast<double>(samples);
  for (size_t i = 0; i < sum.size(); ++i) {
    const double m = sum[i] / n;
    const double var = std::max(0.0, (sum_sq[i] / n - m * m)) * n / (n - 1);
    out[i] = static_cast<float>(var / n);
  }
  return out;
}

std::vector<float> Film::mis_weight() const {
  std::vector<float> out(w_sum.size(), 0.f);
  for (size_t i = 0; i < w_sum.size(); ++i) out[i] = w_cnt[i] > 0 ? static_cast<float>(w_sum[i] / w_cnt[i]) : 0.f;
  return out;
}

// Vose's alias method: O(1) sampling of a discrete distribution.
static void build_alias(const std::vector<float>& p, std::vector<float>& prob, std::vector<int32_t>& alias) {
  const size_t n = p.size();
  prob.assign(n, 1.f);
  alias.resize(n);
  std::iota(alias.begin(), alias.end(), 0);
  std::vector<double> scaled(n);
  std::vector<int32_t> small, large;
  for (size_t i = 0; i < n; ++i) {
    scaled[i] = static_cast<double>(p[i]) * static_cast<double>(n);
    (scaled[i] < 1.0 ? small : large).push_back(static_cast<int32_t>(i));
  }
  while (!small.empty() && !large.empty()) {
    const int32_t s = small.back(), l = large.back();
    small.pop_back();
    prob[s] = static_cast<float>(scaled[s]);
    alias[s] = l;
    scaled[l] = (scaled[l] + scaled[s]) - 1.0;
    if (scaled[l] < 1.0) {
      large.pop_back();
      small.push_back(l);
    }
  }
  for (int32_t i : large) prob[i] = 1.f;
  for (int32_t i : small) prob[i] = 1.f;  // numerical leftovers
}


SceneViews build_views(const Scene& scene, LightPick pick) {
  SceneViews out;
  SceneViews& v = out;
  const auto& lights = scene.lights;
  const size_t n = lights.size();
  v.lights.any_two_sided = false;
  for (const Light& l : lights) {
    v.type.push_back(static_cast<int32_t>(l.type));
    v.p0x.push_back(l.p0.x); v.p0y.push_back(l.p0.y); v.p0z.push_back(l.p0.z);
    v.e1x.push_back(l.e1.x); v.e1y.push_back(l.e1.y); v.e1z.push_back(l.e1.z);
    v.e2x.push_back(l.e2.x); v.e2y.push_back(l.e2.y); v.e2z.push_back(l.e2.z);
    v.Lr.push_back(l.radiance.r); v.Lg.push_back(l.radiance.g); v.Lb.push_back(l.radiance.b);
    v.two_sided.push_back(l.two_sided ? 1.f : 0.f);
    v.lights.any_two_sided = v.lights.any_two_sided || l.two_sided;
    LightGeom<float> g;
    g.type = static_cast<int32_t>(l.type);
    g.e1 = l.e1;
    g.e2 = l.e2;
    g.area = l.area;
    light_geom_derive(g);
    v.area.push_back(g.area);
    v.len1.push_back(g.len1); v.len2.push_back(g.len2);
    v.inv_len1.push_back(g.inv_len1); v.inv_len2.push_back(g.inv_len2);
    v.rect.push_back(g.rect);
    v.exx.push_back(g.ex.x); v.exy.push_back(g.ex.y); v.exz.push_back(g.ex.z);
    v.eyx.push_back(g.ey.x); v.eyy.push_back(g.ey.y); v.eyz.push_back(g.ey.z);
    // the emitting side's unit normal; a rectangle's is cross(ex, ey), which rectangle
    // pipelines compute from the unit edges instead of reading it (the same bits)
    vec3f nn{0, 0, 0};
    if (g.rect > 0.5f) nn = cross(g.ex, g.ey);
    else if (l.type == LightType::triangle || l.type == LightType::parallelogram) nn = normalize(cross(l.e1, l.e2));
    v.nx.push_back(nn.x); v.ny.push_back(nn.y); v.nz.push_back(nn.z);
    (is_delta(l.type) ? v.has_delta : v.has_area) = true;
    v.all_rects = v.all_rects && l.type == LightType::parallelogram && g.rect > 0.5f;
  }
  // pick distribution
  v.pick_pdf.assign(n, 0.f);
  if (n > 0) {
    std::vector<double> weight(n, 1.0);
    if (pick == LightPick::area) {
      double mean_area = 0;
      int na = 0;
      for (const Light& l : lights)
        if (!is_delta(l.type)) mean_area += l.area, ++na;
      mean_area = na ? mean_area / na : 1.0;
      for (size_t i = 0; i < n; ++i) weight[i] = is_delta(lights[i].type) ? mean_area : lights[i].area;
    } else if (pick == LightPick::power) {
      for (size_t i = 0; i < n; ++i) weight[i] = std::max(0.f, lights[i].power);
    }
    double total = 0;
    for (double w : weight) total += w;
    if (!(total > 0) || !std::isfinite(total)) {
      std::fill(weight.begin(), weight.end(), 1.0);
      total = static_cast<double>(n);
    }
    for (size_t i = 0; i < n; ++i)
      v.pick_pdf[i] = pick == LightPick::all ? 1.f : static_cast<float>(weight[i] / total);
    std::vector<float> p(n);
    for (size_t i = 0; i < n; ++i) p[i] = static_cast<float>(weight[i] / total);
    build_alias(p, v.alias_prob, v.alias_idx);
  }
  // Small and medium tables are read with permutes of vector loads (lookup_small,
  // lookup_medium): pad them to their tier's size so that those loads stay inside.
  const int tier = table_tier(n);
  if (n > 0 && tier != tier_gather) {
    const size_t padded = static_cast<size_t>(tier == tier_small ? small_table_size : medium_table_size);
    for (auto* f : {&v.p0x, &v.p0y, &v.p0z, &v.e1x, &v.e1y, &v.e1z, &v.e2x, &v.e2y, &v.e2z, &v.nx, &v.ny, &v.nz, &v.Lr,
                    &v.Lg, &v.Lb, &v.area, &v.two_sided, &v.len1, &v.len2, &v.inv_len1, &v.inv_len2, &v.rect,
                    &v.exx, &v.exy, &v.exz, &v.eyx, &v.eyy, &v.eyz,
                    &v.pick_pdf, &v.alias_prob})
      f->resize(padded, 0.f);
    v.type.resize(padded, 0);
    v.alias_idx.resize(padded, 0);
  }
  LightView& L = v.lights;
  L.count = static_cast<int32_t>(n);
  L.tier = tier;
  L.type = v.type.data();
  L.p0x = v.p0x.data(); L.p0y = v.p0y.data(); L.p0z = v.p0z.data();
  L.e1x = v.e1x.data(); L.e1y = v.e1y.data(); L.e1z = v.e1z.data();
  L.e2x = v.e2x.data(); L.e2y = v.e2y.data(); L.e2z = v.e2z.data();
  L.nx = v.nx.data(); L.ny = v.ny.data(); L.nz = v.nz.data();
  L.Lr = v.Lr.data(); L.Lg = v.Lg.data(); L.Lb = v.Lb.data();
  L.one_radiance = n > 0;
  for (size_t i = 1; i < n; ++i)
    L.one_radiance = L.one_radiance && v.Lr[i] == v.Lr[0] && v.Lg[i] == v.Lg[0] && v.Lb[i] == v.Lb[0];
  L.area = v.area.data();
  L.two_sided = v.two_sided.data();
  L.len1 = v.len1.data(); L.len2 = v.len2.data();
  L.inv_len1 = v.inv_len1.data(); L.inv_len2 = v.inv_len2.data();
  L.rect = v.rect.data();
  L.exx = v.exx.data(); L.exy = v.exy.data(); L.exz = v.exz.data();
  L.eyx = v.eyx.data(); L.eyy = v.eyy.data(); L.eyz = v.eyz.data();
  L.pick_pdf = v.pick_pdf.data();
  L.alias_prob = v.alias_prob.data();
  L.alias_idx = v.alias_idx.data();

  const int32_t default_material = static_cast<int32_t>(scene.materials.size());
  // Flattened triangles, gathered by the camera-hit stage at 9 * triangle in int32 lanes.
  size_t tris = 0;
  for (const Mesh& m : scene.meshes) tris += m.triangle_count();
  if (9 * (tris + 1) > static_cast<size_t>(INT32_MAX))
    throw std::runtime_error("scene has " + std::to_string(tris) + " triangles; at most " +
                             std::to_string(INT32_MAX / 9 - 1) + " are supported");
  v.tri_pos.reserve(9 * (tris + 1));
  v.tri_light.reserve(tris + 1);
  for (const Mesh& m : scene.meshes) {
    v.geom_material.push_back(m.material >= 0 ? m.material : default_material);
    v.tri_offset.push_back(static_cast<int32_t>(v.tri_light.size()));
    for (size_t t = 0; t < m.triangle_count(); ++t) {
      for (int k = 0; k < 3; ++k) {
        const float* p = m.positions.data() + 3 * static_cast<size_t>(m.indices[3 * t + k]);
        v.tri_pos.insert(v.tri_pos.end(), p, p + 3);
      }
      v.tri_light.push_back(m.prim_light.empty() ? -1 : m.prim_light[t]);
    }
    v.indices.push_back(m.indices.data());
    v.positions.push_back(m.positions.data());
    v.uvs.push_back(m.uvs.empty() ? nullptr : m.uvs.data());
  }
  for (const Sphere& s : scene.spheres) {
    v.geom_material.push_back(s.material >= 0 ? s.material : default_material);
    v.sphere_center.insert(v.sphere_center.end(), {s.center.x, s.center.y, s.center.z, s.radius});
    v.sphere_light.push_back(s.light);
    v.tri_offset.push_back(0);
  }
  v.sphere_light.push_back(-1);  // never empty
  v.tri_pos.insert(v.tri_pos.end(), 9, 0.f);  // a spare triangle: never empty
  v.tri_light.push_back(-1);
  for (const Material& m : scene.materials) {
    v.mat_r.push_back(m.reflectance.r);
    v.mat_g.push_back(m.reflectance.g);
    v.mat_b.push_back(m.reflectance.b);
    v.mat_texture.push_back(m.texture);
    v.geom.has_textures |= m.texture >= 0;
  }
  v.mat_r.push_back(0.5f);  // the default material
  v.mat_g.push_back(0.5f);
  v.mat_b.push_back(0.5f);
  v.mat_texture.push_back(-1);
  for (const Texture& t : scene.textures) {
    v.tex_rgb.push_back(t.rgb.data());
    v.tex_w.push_back(t.width);
    v.tex_h.push_back(t.height);
  }
  GeomView& G = v.geom;
  G.mesh_count = static_cast<int32_t>(scene.meshes.size());
  G.geom_material = v.geom_material.data();
  G.sphere_center = v.sphere_center.data();
  G.tri_offset = v.tri_offset.data();
  G.tri_pos = v.tri_pos.data();
  G.tri_light = v.tri_light.data();
  G.sphere_light = v.sphere_light.data();
  G.mat_r = v.mat_r.data();
  G.mat_g = v.mat_g.data();
  G.mat_b = v.mat_b.data();
  G.mat_texture = v.mat_texture.data();
  G.indices = v.indices.data();
  G.positions = v.positions.data();
  G.uvs = v.uvs.data();
  G.tex_rgb = v.tex_rgb.data();
  G.tex_w = v.tex_w.data();
  G.tex_h = v.tex_h.data();

  const Camera& c = scene.camera;
  CameraView& cv = v.camera;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 4; ++k) cv.m[r][k] = c.world_from_camera[r][k];
  const float aspect = static_cast<float>(c.width) / static_cast<float>(c.height);
  if (c.screen[0] != 0 || c.screen[1] != 0 || c.screen[2] != 0 || c.screen[3] != 0) {
    cv.sx0 = c.screen[0]; cv.sx1 = c.screen[1]; cv.sy0 = c.screen[2]; cv.sy1 = c.screen[3];
  } else if (aspect > 1.f) {
    cv.sx0 = -aspect; cv.sx1 = aspect; cv.sy0 = -1; cv.sy1 = 1;
  } else {
    cv.sx0 = -1; cv.sx1 = 1; cv.sy0 = -1 / aspect; cv.sy1 = 1 / aspect;
  }
  cv.tan_half = std::tan(0.5f * c.fov_deg * 3.14159265f / 180.f);
  cv.inv_w = 1.f / static_cast<float>(c.width);
  cv.inv_h = 1.f / static_cast<float>(c.height);
  return out;
}

// Each worker's tile buffers (about 0.7 MB), made once and reused by every render: making
// them per render (zeroed, so page faults on every call) cost a measurable share of short
// progressive renders.
struct Renderer::BufferPool {
  tbb::enumerable_thread_specific<std::unique_ptr<TileBuffers>> buffers{[] { return std::make_unique<TileBuffers>(); }};
};

Renderer::Renderer(const Scene& scene, const Accel& accel, const RenderOptions& options)
    : scene_(scene), accel_(accel), opt_(options), views_(std::make_unique<SceneViews>()),
      pool_(std::make_unique<BufferPool>()) {
  if (opt_.tile < 1 || opt_.tile > max_tile_side) throw std::invalid_argument("tile size must be in 1..32");
  if (opt_.est.light_samples < 1 || opt_.est.bsdf_samples < 1)
    throw std::invalid_argument("--light-samples and --bsdf-samples must be >= 1");
  if (!(opt_.est.mis.beta > 0) || !std::isfinite(opt_.est.mis.beta)) throw std::invalid_argument("--beta must be > 0");
  if (!(opt_.est.mis.alpha >= 0 && opt_.est.mis.alpha <= 1)) throw std::invalid_argument("--alpha must be in [0, 1]");
  opt_.est.aov_mis_weight = opt_.est.aov_mis_weight || opt_.aov_mis_weight;
  *views_ = build_views(scene, opt_.est.pick);
  if (opt_.bounce == BounceTrace::automatic) {
    size_t all = scene.spheres.size(), emitting = 0;
    for (const Mesh& m : scene.meshes) {
      all += m.triangle_count();
      if (m.emissive()) emitting += m.triangle_count();
    }
    for (const Sphere& sp : scene.spheres) emitting += sp.emission.r > 0 || sp.emission.g > 0 || sp.emission.b > 0;
    bounce_emitters_ = 2 * emitting <= all;
  } else {
    bounce_emitters_ = opt_.bounce == BounceTrace::emitters;
  }
  if (bounce_emitters_) accel_.prepare_emitters();
}

Renderer::~Renderer() = default;

const char* stage_name(Stage s) {
  static const char* names[] = {"generate",       "intersect camera", "camera hits", "sample lights",
                                "intersect shadow", "sample cosine",  "intersect bounce", "MIS weight",
                                "accumulate"};
  return names[static_cast<int>(s)];
}

namespace {

using clock_type = std::chrono::steady_clock;

// What one render shares with its tile tasks.
struct TileContext {
  const SceneViews& v;
  const Accel& accel;
  const Estimator& est;
  Film& film;
  int tile_size, tiles_x, width, height;
  int light_passes, bsdf_passes, S;
  float n_light, n_bsdf;
  bool bounce_emitters;   // bounce rays against the emitters, then visibility rays
  bool fresh_film;        // the film held no samples (zeros) when the render began
  Profile* profile;       // null when not profiling
  uint64_t origin_ticks;
};

// Per-thread profiling state.
struct ThreadProfile {
  uint64_t stage_ticks[stage_count] = {};
  std::vector<TraceEvent> events;
  RayRecord rays;
};

// Keeps a copy of a packet about to be traced, for the roofline replay (first pass only).
template <class P> inline void record(std::vector<RecordedPacket<P>>& out, const P& p, const int32_t* valid) {
  RecordedPacket<P> r;
  r.packet = p;
  std::memcpy(r.valid, valid, sizeof(r.valid));
  out.push_back(r);
}

// Times the stages of a tile when profiling; a single well-predicted branch otherwise. Reads
// the time-stamp counter once per stage boundary (about 8.5 ns in this VM; clock_gettime
// costs several times more), converted to seconds with the ratio of counter ticks to wall
// time over the whole render. What is left for the "scheduling" row is the time between
// tiles (task scheduling).
struct StageTimer {
  ThreadProfile* tp;
  const TileContext& c;
  int tile;
  uint64_t t0 = 0;
  StageTimer(ThreadProfile* p, const TileContext& ctx, int t) : tp(p), c(ctx), tile(t) {}
  void start() {
#ifndef TUILE_NO_PROFILE_HOOKS
    if (tp) t0 = __rdtsc();
#endif
  }
  // Runs f outside the current stage's time (the roofline's packet copies).
  template <class F> void untimed(F&& f) {
    const uint64_t a = __rdtsc();
    f();
    t0 += __rdtsc() - a;
  }
  // Ends the running stage as s and starts the next one: one counter read per stage
  // boundary, and no time falls between stages.
  void lap([[maybe_unused]] Stage s) {
#ifdef TUILE_NO_PROFILE_HOOKS
    return;
#endif
    if (!tp) return;
    const uint64_t t1 = __rdtsc();
    tp->stage_ticks[static_cast<int>(s)] += t1 - t0;
    if (c.profile->trace && tp->events.size() < c.profile->max_events)
      tp->events.push_back({s, tile, static_cast<double>(t0 - c.origin_ticks), static_cast<double>(t1 - t0)});
    t0 = t1;
  }
};

inline int active_lanes(const int32_t* valid) {
  if constexpr (packet_width % simd_width == 0) {
    int n = 0;
    for (int l = 0; l < packet_width; l += simd_width)
      n += count(f_mask_from_i(load_i32<vfloat>(valid + l) != vint(0)));
    return n;
  }
  int n = 0;
  for (int l = 0; l < packet_width; ++l) n += valid[l] != 0;
  return n;
}

// The tile pipeline, instantiated per scene shape (DESIGN.md: leave out what a scene does
// not need). Kinds: kinds of source present; Light/Bsdf: whether the technique's stages
// run; Pick: whether lanes pick a source; Emitters: whether hits look up emitters.
template <unsigned Kinds, bool Light, bool Bsdf, bool Pick, bool Emitters>
void run_tile(const TileContext& c, TileBuffers& tb, ThreadProfile* tp, int tile, uint32_t begin, uint32_t end) {
  const SceneViews& v = c.v;
  const Estimator& est = c.est;
  Film& film = c.film;
  const int ts = c.tile_size;
  const int x0 = (tile % c.tiles_x) * ts, y0 = (tile / c.tiles_x) * ts;
  const int tw = std::min(ts, c.width - x0), th = std::min(ts, c.height - y0);
  const int lanes = tw * th;
  StageTimer timer(tp, c, tile);
  timer.start();
  // Lane order: 4x4 pixel blocks, one per packet of 16 (a smaller footprint than a row of
  // 16, so Embree's packets are more coherent), where the tile divides into them; rows
  // otherwise. Every lane's numbers depend on its pixel only, so the image does not change.
  const bool blocks = tw % 4 == 0 && th % 4 == 0 && packet_width == 16;
  int i = 0;
  auto set_lane = [&](int x, int y) {
    tb.fx[i] = static_cast<float>(x);
    tb.fy[i] = static_cast<float>(y);
    tb.pixel[i++] = static_cast<uint32_t>(y) * static_cast<uint32_t>(c.width) + static_cast<uint32_t>(x);
  };
  if (blocks) {
    for (int by = y0; by < y0 + th; by += 4)
      for (int bx = x0; bx < x0 + tw; bx += 4)
        for (int j = 0; j < 16; ++j) set_lane(bx + j % 4, by + j / 4);
  } else {
    for (int y = y0; y < y0 + th; ++y)
      for (int x = x0; x < x0 + tw; ++x) set_lane(x, y);
  }
  const int cam_packets = (lanes + packet_width - 1) / packet_width;
  timer.lap(Stage::generate);
  clear_tile_sums(tb, lanes);
  timer.lap(Stage::accumulate);
  // The sampler's keys of the pairs this pipeline draws (pair numbers as below), hashed
  // once per pixel for all of the tile's samples.
  tb.keyed = 0;
  if (cacheable(est.sampler)) {
    uint32_t want = 1u;  // camera
    if (est.one_sample()) want |= 2u;
    if (Bsdf)
      for (int m = 0; m < c.bsdf_passes; ++m) want |= 1u << std::min(2 + m, 31);
    if (Light)
      for (int j = 0; j < c.light_passes; ++j) {
        const int pair = 2 + est.bsdf_samples + 2 * j;
        if (Pick && est.pick != LightPick::all) want |= 1u << std::min(pair, 31);
        want |= 1u << std::min(pair + 1, 31);
      }
    want &= (1u << TileBuffers::key_pairs) - 1u;
    const int padded = cam_packets * packet_width;
    for (int i = lanes; i < padded; ++i) tb.pixel[i] = tb.pixel[0];  // as generate pads
    for (uint32_t bits = want; bits; bits &= bits - 1) {
      const int p = std::countr_zero(bits);
      make_pair_keys(est.seed, tb.pixel, static_cast<uint32_t>(p), padded, tb.lane_keys(p));
    }
    tb.keyed = want;
  }
  timer.lap(Stage::generate);
  for (uint32_t s = begin; s < end; ++s) {
    generate(v.camera, est, s, lanes, tb);
    timer.lap(Stage::generate);
    const bool rec = tp && c.profile->record_rays && s == begin;
    clear_high_vector_registers();
    for (int p = 0; p < cam_packets; ++p) {
      if (rec) timer.untimed([&] { record(tp->rays.camera, tb.cam[p], tb.cam_valid + p * packet_width); });
      c.accel.intersect16(tb.cam_valid + p * packet_width, tb.cam[p], true);
    }
    tb.rays_camera += static_cast<uint64_t>(lanes);
    timer.lap(Stage::intersect_camera);
    camera_hits<Emitters>(v.geom, v.lights, est, s, lanes, tb);
    timer.lap(Stage::camera_hits);
    const int packets = (tb.shade_count + packet_width - 1) / packet_width;
    if constexpr (Light) {
      if (tb.shade_count > 0) {
        for (int j = 0; j < c.light_passes; ++j) {
          LightPass pass;
          pass.fixed_light = est.pick == LightPick::all ? j % c.S : (Pick ? -1 : 0);
          pass.n_light = c.n_light;
          pass.n_bsdf = c.n_bsdf;
          sample_lights<Kinds, Pick>(v.lights, est, pass, s, static_cast<uint32_t>(2 + est.bsdf_samples + 2 * j), tb);
          timer.lap(Stage::sample_lights);
          clear_high_vector_registers();
          for (int p = 0; p < packets; ++p) {
            const int32_t* valid = tb.valid + p * packet_width;
            const int active = active_lanes(valid);
            if (!active) continue;
            if (rec) timer.untimed([&] { record(tp->rays.shadow, tb.shadow[p], valid); });
            c.accel.occluded16(valid, tb.shadow[p], false);
            tb.rays_shadow += static_cast<uint64_t>(active);
          }
          timer.lap(Stage::intersect_shadow);
          accumulate_shadow(tb);
          timer.lap(Stage::accumulate);
        }
      }
    }
    if constexpr (Bsdf) {
      if (tb.shade_count > 0) {
        for (int m = 0; m < c.bsdf_passes; ++m) {
          sample_cosine(est, s, static_cast<uint32_t>(2 + m), tb);
          timer.lap(Stage::sample_cosine);
          clear_high_vector_registers();
          const Target target = c.bounce_emitters ? Target::emitters : Target::scene;
          for (int p = 0; p < packets; ++p) {
            const int32_t* valid = tb.valid + p * packet_width;
            const int active = active_lanes(valid);
            if (!active) continue;
            if (rec) timer.untimed([&] { record(tp->rays.bounce, tb.bounce[p], valid); });
            c.accel.intersect16(valid, tb.bounce[p], false, target);
            tb.rays_bounce += static_cast<uint64_t>(active);
          }
          timer.lap(Stage::intersect_bounce);
          queue_bounce_hits<vfloat, Kinds>(v.geom, v.lights, tb, c.bounce_emitters);
          if (c.bounce_emitters && tb.queue_count > 0) {
            const int qpackets = bounce_visibility_rays(tb);
            timer.lap(Stage::mis_weight);
            clear_high_vector_registers();
            for (int p = 0; p < qpackets; ++p) {
              if (rec) timer.untimed([&] { record(tp->rays.shadow, tb.shadow[p], tb.qvalid + p * packet_width); });
              c.accel.occluded16(tb.qvalid + p * packet_width, tb.shadow[p], false);
            }
            tb.rays_bounce_visibility += static_cast<uint64_t>(tb.queue_count);
            timer.lap(Stage::intersect_bounce);
            read_bounce_visibility(tb);
          }
          weight_queue<Kinds>(v.lights, est, c.n_light, c.n_bsdf, tb);
          timer.lap(Stage::mis_weight);
        }
      }
    }
    // one sample of every pixel into the tile's double sums
    accumulate_samples(tb, lanes, est.aov_mis_weight);
    timer.lap(Stage::accumulate);
  }
  // The tile's sums into the film, once. Each pixel belongs to one tile, so the film
  // gets the same bits for any thread count and tile order. A fresh film (0) gets the
  // bits of adding sample by sample; a film that already holds samples (progressive
  // renders) gets its old sum plus this render's partial sum: other rounding than adding
  // one sample at a time, equally deterministic.
  const FilmSums fs{film.sum.data(),    film.sum_sq.data(),           film.w_sum.data(), film.w_cnt.data(),
                    film.max_sample.data(), static_cast<size_t>(c.width)};
  if (c.fresh_film && blocks && can_stream_tile(x0, tw, th, fs)) stream_tile_to_film(tb, x0, y0, th, fs, est.aov_mis_weight);
  else add_tile_to_film(tb, lanes, fs, est.aov_mis_weight);
  timer.lap(Stage::accumulate);
}

using TileFn = void (*)(const TileContext&, TileBuffers&, ThreadProfile*, int, uint32_t, uint32_t);

struct PipelineEntry {
  const char* name;
  TileFn fn;
};

// The instantiated pipelines. "general" runs every stage and every lookup whatever the
// scene: it is the reference the specialised ones must match.
template <unsigned K, bool L, bool B, bool P, bool E> constexpr TileFn tile_fn() { return &run_tile<K, L, B, P, E>; }

// The pipelines of scenes with area lights only (kinds K): MIS, light or BSDF technique,
// with or without a per-lane pick; names in that order (mis pick, mis single, light pick,
// light single, bsdf).
template <unsigned K>
PipelineEntry area_pipeline(const char* const (&names)[5], bool light, bool bsdf, bool pick) {
  if (light && bsdf)
    return pick ? PipelineEntry{names[0], tile_fn<K, true, true, true, true>()}
                : PipelineEntry{names[1], tile_fn<K, true, true, false, true>()};
  if (light)
    return pick ? PipelineEntry{names[2], tile_fn<K, true, false, true, true>()}
                : PipelineEntry{names[3], tile_fn<K, true, false, false, true>()};
  return {names[4], tile_fn<K, false, true, false, true>()};
}

PipelineEntry pick_pipeline(const SceneViews& v, const Estimator& est, bool general, std::string& why) {
  if (general) {
    why = "forced with --pipeline general";
    return {"general", tile_fn<kind_all, true, true, true, true>()};
  }
  const bool area = v.has_area, delta = v.has_delta;
  const bool light = v.lights.count > 0 && (est.strategy != Strategy::bsdf || delta);
  const bool bsdf = area && est.strategy != Strategy::light;
  const bool pick = v.lights.count > 1 && est.pick != LightPick::all;
  why = std::string(area ? "area lights" : "no area light") + ", " + (delta ? "delta lights" : "no delta light") + ", " +
        std::to_string(v.lights.count) + " light(s), pick " + (pick ? "per lane" : "none") + ", strategy " +
        (est.strategy == Strategy::mis ? "mis" : est.strategy == Strategy::light ? "light" : "bsdf");
  if (!area && !delta) return {"no-lights", tile_fn<kind_all, false, false, false, false>()};
  if (!area) {  // only delta lights: no BSDF rays, no MIS, no emitter lookups
    return pick ? PipelineEntry{"delta/light/pick", tile_fn<kind_delta, true, false, true, false>()}
                : PipelineEntry{"delta/light/single", tile_fn<kind_delta, true, false, false, false>()};
  }
  if (!delta && v.all_rects) {  // rectangles only: no dispatch on the kind of source
    static constexpr const char* names[5] = {"rect/mis/pick", "rect/mis/single", "rect/light/pick",
                                             "rect/light/single", "rect/bsdf"};
    return area_pipeline<kind_area | kind_rects>(names, light, bsdf, pick);
  }
  if (!delta) {
    static constexpr const char* names[5] = {"area/mis/pick", "area/mis/single", "area/light/pick",
                                             "area/light/single", "area/bsdf"};
    return area_pipeline<kind_area>(names, light, bsdf, pick);
  }
  if (bsdf)
    return pick ? PipelineEntry{"mixed/mis/pick", tile_fn<kind_all, true, true, true, true>()}
                : PipelineEntry{"mixed/mis/single", tile_fn<kind_all, true, true, false, true>()};
  return pick ? PipelineEntry{"mixed/light/pick", tile_fn<kind_all, true, false, true, true>()}
              : PipelineEntry{"mixed/light/single", tile_fn<kind_all, true, false, false, true>()};
}

}  // namespace

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
  const size_t nc = rays.camera.size(), ns = rays.shadow.size(), nb = rays.bounce.size();
  const int n_threads = threads > 0 ? threads : tbb::this_task_arena::max_concurrency();
  tbb::enumerable_thread_specific<uint64_t> call_ticks(0);
  const auto t0 = clock_type::now();
  const uint64_t ticks0 = __rdtsc();
  tbb::task_arena arena(n_threads);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nc + ns + nb, 16), [&](const tbb::blocked_range<size_t>& r) {
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
        else
          timed(hit, rays.bounce[i - nc - ns], [&] {
            accel.intersect16(valid, hit, false, rays.bounce_emitters ? Target::emitters : Target::scene);
          });
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
    Target target = Target::scene;
  };
  std::vector<Stream> streams;
  constexpr size_t per_stream = max_tile_lanes / packet_width;  // packets of one tile
  auto build = [&](const auto& packets, bool occluded, bool coherent, Target target) {
    for (size_t start = 0; start < packets.size(); start += per_stream) {
      Stream st;
      st.occluded = occluded;
      st.coherent = coherent;
      st.target = target;
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
  build(rays.camera, false, true, Target::scene);
  build(rays.shadow, true, false, Target::scene);
  build(rays.bounce, false, false, rays.bounce_emitters ? Target::emitters : Target::scene);
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
        else accel.intersect_stream(sr, st.n, st.coherent, st.target);
      }
    });
  });
  return std::chrono::duration<double>(clock_type::now() - t0).count();
}

std::string Renderer::pipeline_name(std::string* why) const {
  std::string w;
  const PipelineEntry e = pick_pipeline(*views_, opt_.est, opt_.general_pipeline, w);
  if (why) *why = w;
  return e.name;
}

RenderStats Renderer::render(Film& film, uint32_t begin, uint32_t end, Profile* profile) {
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
                (cam.width + ts - 1) / ts,
                cam.width,
                cam.height,
                (est.pick == LightPick::all ? v.lights.count : 1) * (one ? 1 : est.light_samples),
                one ? 1 : est.bsdf_samples,
                v.lights.count,
                one ? c_l : static_cast<float>(est.light_samples),
                one ? 1.f - c_l : static_cast<float>(est.bsdf_samples),
                bounce_emitters_,
                film.samples == 0,
                profile,
                __rdtsc()};
  std::string why;
  const PipelineEntry pipe = pick_pipeline(v, est, opt_.general_pipeline, why);
  const int tiles = c.tiles_x * ((cam.height + ts - 1) / ts);

  auto& buffers = pool_->buffers;
  for (auto& p : buffers) p->reset_statistics();
  tbb::enumerable_thread_specific<ThreadProfile> profiles;
  const auto t0 = clock_type::now();
  const uint64_t ticks0 = __rdtsc();
  const int threads = opt_.threads > 0 ? opt_.threads : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(threads);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, tiles, 1),
                      [&](const tbb::blocked_range<int>& r) {
                        TileBuffers& tb = *buffers.local();
                        ThreadProfile* tp = profile ? &profiles.local() : nullptr;
                        for (int t = r.begin(); t < r.end(); ++t) pipe.fn(c, tb, tp, t, begin, end);
                      },
                      tbb::simple_partitioner());
  });
  RenderStats st;
  st.seconds = std::chrono::duration<double>(clock_type::now() - t0).count();
  const double sec_per_tick = st.seconds / static_cast<double>(std::max<uint64_t>(1, __rdtsc() - ticks0));
  st.pipeline = pipe.name;
  st.bounce_emitters = bounce_emitters_;
  film.samples += end - begin;
  st.samples = static_cast<uint64_t>(end - begin) * static_cast<uint64_t>(cam.width) * cam.height;
  for (auto& p : buffers) {
    st.rays_camera += p->rays_camera;
    st.rays_shadow += p->rays_shadow;
    st.rays_bounce += p->rays_bounce;
    st.rays_bounce_visibility += p->rays_bounce_visibility;
    st.rejected_camera += p->rejected_camera;
    st.rejected_light += p->rejected_light;
    st.rejected_bsdf += p->rejected_bsdf;
  }
  if (profile) {
    profile->threads = threads;
    profile->wall_seconds += st.seconds;
    int tid = 0;
    for (ThreadProfile& tp : profiles) {
      for (int k = 0; k < stage_count; ++k)
        profile->stage_seconds[k] += static_cast<double>(tp.stage_ticks[k]) * sec_per_tick;
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
      profile->rays.bounce_emitters = bounce_emitters_;
      ++tid;
    }
  }
  // the worst accident, from the pixel means (no mean image allocated)
  for (size_t i = 0; i < film.max_sample.size() && film.samples > 0; ++i) {
    const float y = luminance(film.mean_of(3 * i), film.mean_of(3 * i + 1), film.mean_of(3 * i + 2));
    if (y > 0) st.worst_ratio = std::max(st.worst_ratio, static_cast<double>(film.max_sample[i] / y));
  }
  return st;
}

Strategy parse_strategy(const std::string& s) {
  if (s == "light") return Strategy::light;
  if (s == "bsdf") return Strategy::bsdf;
  if (s == "mis") return Strategy::mis;
  throw std::invalid_argument("unknown strategy '" + s + "' (expected light, bsdf or mis)");
}
LightPick parse_light_pick(const std::string& s) {
  if (s == "all") return LightPick::all;
  if (s == "uniform") return LightPick::uniform;
  if (s == "area") return LightPick::area;
  if (s == "power") return LightPick::power;
  throw std::invalid_argument("unknown light pick '" + s + "' (expected all, uniform, area or power)");
}
LightPoint parse_light_point(const std::string& s) {
  if (s == "area") return LightPoint::area;
  if (s == "solid-angle") return LightPoint::solid_angle;
  throw std::invalid_argument("unknown light point '" + s + "' (expected area or solid-angle)");
}
Heuristic parse_heuristic(const std::string& s) {
  if (s == "balance") return Heuristic::balance;
  if (s == "power") return Heuristic::power;
  if (s == "cutoff") return Heuristic::cutoff;
  if (s == "maximum") return Heuristic::maximum;
  throw std::invalid_argument("unknown heuristic '" + s + "' (expected balance, power, cutoff or maximum)");
}
MisMode parse_mis_mode(const std::string& s) {
  if (s == "multi") return MisMode::multi;
  if (s == "one") return MisMode::one;
  throw std::invalid_argument("unknown MIS mode '" + s + "' (expected multi or one)");
}
BounceTrace parse_bounce_trace(const std::string& s) {
  if (s == "auto") return BounceTrace::automatic;
  if (s == "scene") return BounceTrace::scene;
  if (s == "emitters") return BounceTrace::emitters;
  throw std::invalid_argument("unknown bounce-rays mode '" + s + "' (expected auto, scene or emitters)");
}

SamplerKind parse_sampler(const std::string& s) {
  if (s == "independent") return SamplerKind::independent;
  if (s == "stratified") return SamplerKind::stratified;
  if (s == "sobol") return SamplerKind::sobol;
  throw std::invalid_argument("unknown sampler '" + s + "' (expected independent, stratified or sobol)");
}

std::string describe(const Estimator& e) {
  static const char* strategies[] = {"light", "bsdf", "mis"};
  static const char* picks[] = {"all", "uniform", "area", "power"};
  static const char* points[] = {"area", "solid-angle"};
  static const char* heuristics[] = {"balance", "power", "cutoff", "maximum"};
  static const char* samplers[] = {"independent", "stratified", "sobol"};
  std::string s = std::string("strategy=") + strategies[static_cast<int>(e.strategy)] +
                  " light-pick=" + picks[static_cast<int>(e.pick)] + " light-point=" + points[static_cast<int>(e.point)];
  if (e.strategy == Strategy::mis)
    s += std::string(" heuristic=") + heuristics[static_cast<int>(e.heuristic)] +
         (e.mode == MisMode::one ? " mis-mode=one" : " mis-mode=multi");
  s += " light-samples=" + std::to_string(e.light_samples) + " bsdf-samples=" + std::to_string(e.bsdf_samples) +
       " sampler=" + samplers[static_cast<int>(e.sampler)] + " spp=" + std::to_string(e.spp) +
       " seed=" + std::to_string(e.seed);
  return s;
}

}  // namespace tuile
