// Bidirectional path tracing (--bdpt): render/bdpt.h.
#include "render/bdpt.h"

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <stdexcept>
#include <string>

#include "light/kinds.h"
#include "light/table.h"
#include "render/bdpt_mis.h"
#include "render/light_paths.h"
#include "sample/layout.h"
#include "sample/rng.h"
#include "sample/sampling.h"
#include "scene/scene.h"
#include "wave/accumulate.h"
#include "wave/emitter_hits.h"
#include "wave/escaped.h"
#include "wave/generate.h"
#include "wave/media.h"
#include "wave/surface_bsdf.h"
#include "wave/surface_hits.h"

namespace tuile {

namespace {

using V3 = Vec3<float>;
using Bsdf = SurfaceBsdf<float, bsdf_all>;
using Sky = LightKindOps<LightKind::infinite>;

bool area_kind(int32_t type) {
  return type == static_cast<int32_t>(LightKind::triangle) || type == static_cast<int32_t>(LightKind::parallelogram) ||
         type == static_cast<int32_t>(LightKind::sphere);
}
bool at_infinity(int32_t type) {
  return type == static_cast<int32_t>(LightKind::distant) || type == static_cast<int32_t>(LightKind::infinite);
}
// A source no strategy meets from the camera's side: a point, a spot, a distant source.
bool delta_source(int32_t type) { return positional_light(type) || type == static_cast<int32_t>(LightKind::distant); }

// A subpath's vertex. z0 is the camera (p its position, ng zero); y0 a point on a source
// (ng its normal on the side it emits to). fwd: the density of this vertex from the one
// before on its subpath, rev: from the one after, both per unit area (0 for a delta
// sample, which the weights read as pbrt's remap0 does).
struct Vertex {
  V3 p{0.f, 0.f, 0.f}, ng{0.f, 0.f, 0.f};  // ng: the geometric normal on the side the subpath arrived from
  Bsdf bsdf{};                              // surface vertices: wo towards the vertex before
  float beta[3] = {0.f, 0.f, 0.f};          // the subpath's throughput up to this vertex
  float fwd = 0.f, rev = 0.f;
  float eps = 0.f;     // ray offset
  int32_t light = -1;  // camera subpath: the source this point is on, facing the vertex before; y0: its source
  int32_t medf = -1, medb = -1;  // the media on the side of ng and behind it (a point in a medium: its medium, ng zero)
  bool delta = false;  // the direction sampled here was a delta lobe's
  bool infinite = false;  // y0 of a source at infinity (p: where its ray starts on the disc)
  float mis = 0.f;     // the prefix sum of the balance heuristic's ratios up to here (bdpt_mis.h)
};

// A point in a medium: its BSDF is the phase function, its normals zero.
bool in_medium(const Vertex& v) { return v.bsdf.kind == static_cast<int32_t>(MaterialKind::phase); }

// |cos| of the unit w at v against its geometric normal: 1 at a point on no surface (the
// camera, a point or spot source, a point in a medium), as pbrt-v4's medium interactions.
float cos_geo(const Vertex& v, const V3& w) {
  return v.ng.x == 0.f && v.ng.y == 0.f && v.ng.z == 0.f ? 1.f : std::abs(dot(v.ng, w));
}

// |cos| of the unit w at surface or medium vertex v against its shading normal (1 in a
// medium: the phase function has no cosine).
float cos_shading(const Vertex& v, const V3& w) { return in_medium(v) ? 1.f : std::abs(dot(v.bsdf.n, w)); }

// The medium a ray from vertex v along d starts in.
int32_t ray_medium(const Vertex& v, const V3& d) { return dot(v.ng, d) >= 0.f ? v.medf : v.medb; }

// The BSDF of surface vertex v with the viewer along the unit w (the path tracer's
// convention: the normals on the viewer's side of the geometric normal, which side of the
// surface the viewer is on in `side`, the shading normal turned to w's side).
Bsdf viewed_from(const Vertex& v, const V3& w) {
  Bsdf b = v.bsdf;
  V3 ns = dot(b.n, v.ng) < 0.f ? V3(0.f, 0.f, 0.f) - b.n : b.n;
  if (dot(v.ng, w) < 0.f) {
    ns = V3(0.f, 0.f, 0.f) - ns;
    b.side = -b.side;
  }
  if (dot(ns, w) < 0.f) ns = V3(0.f, 0.f, 0.f) - ns;
  b.n = ns;
  b.wo = w;
  return b;
}

// The density of reaching vertex `to` from `from` along a direction of density pdf: per unit
// area at `to` (pdf cos / d^2), per unit solid angle where `to` is at infinity (pdf), and
// where `from` is, pdf is per unit area of its disc (pdf cos).
float to_area(float pdf, const Vertex& from, const Vertex& to);

// |cos| of the unit-less direction e at vertex v, over |e| (1 at a point on no surface: the
// camera, a point or spot source, whose densities per unit area are per unit solid angle
// over d^2, as pbrt-v4's ConvertDensity).
float cosine_over_length(const Vertex& v, const V3& e, float len) {
  if (v.ng.x == 0.f && v.ng.y == 0.f && v.ng.z == 0.f) return 1.f;
  return std::abs(dot(v.ng, e)) / len;
}

float to_area(float pdf, const Vertex& from, const Vertex& to) {
  if (to.infinite) return pdf;
  const V3 e = to.p - from.p;
  const float d2 = dot(e, e);
  const float c = cosine_over_length(to, e, std::sqrt(d2));
  return from.infinite ? pdf * c : pdf * c / d2;
}

// A light vertex y joined along the unit w (from y): its BSDF's factor as importance carries
// it, times |ns.w|: Veach's shading-normal factor |ns.wo| |ng.w| / |ng.wo| and etap^2 on a
// transmission through a dielectric; 0 where wo grazes the surface.
float importance_join(const GeomView& G, const Vertex& y, const V3& w) {
  if (in_medium(y)) return 1.f;
  const V3 wo = y.bsdf.wo;
  const float ngo = std::abs(dot(y.ng, wo));
  if (!(ngo > 0.f)) return 0.f;
  float k = std::abs(dot(y.bsdf.n, wo)) / ngo * std::abs(dot(y.ng, w));
  if (y.bsdf.kind == static_cast<int32_t>(MaterialKind::dielectric) && dot(y.ng, w) < 0.f) {
    const float eta = G.mat_param[mp_eta][y.bsdf.mat];
    const float etap = y.bsdf.side > 0.f ? eta : 1.f / eta;
    k *= etap * etap;
  }
  return k;
}

// A point's ray origin for a ray along d: off the surface on d's side.
V3 offset(const V3& p, const V3& ng, float eps, const V3& d) { return p + ng * (dot(ng, d) < 0.f ? -eps : eps); }

float offset_eps(const V3& p) {
  return (std::max(std::max(std::abs(p.x), std::abs(p.y)), std::abs(p.z)) + 1.f) * 0x1p-16f;
}

// A join that needs a shadow ray: strategy (s, t) of lane `lane`, its weighted
// contribution c, and for t = 1 where it lands.
struct Job {
  int lane, s, t;
  float c[3];
  double rx, ry;
  V3 org, dir;
  float tfar;
  int32_t med;  // the medium the shadow ray starts in
};

}  // namespace

struct Bdpt::Scratch {
  std::vector<std::vector<Vertex>> cam, light;  // [vertex][lane]
  std::vector<int> ncam, nlight;
  std::vector<float> br, bg, bb, pend, m0, u0, u1, u2, u3, u4, u5, sr, sg, sb;
  std::vector<int32_t> pend_light;
  // per lane: the camera subpath's ray that escaped the scene (t: its vertex at infinity's
  // index + 1, 0 if none), its direction, density and throughput
  std::vector<int> esc_t;
  std::vector<V3> esc_d;
  std::vector<float> esc_pdf, esc_r, esc_g, esc_b;
  std::vector<Job> jobs;
  std::vector<int32_t> jmed;          // the jobs' media, a batch's
  std::vector<float> mr, mg, mb;      // per lane: the media's emission the camera subpath gathered (s = 0, weight 1)
};

struct BdptPool {
  tbb::enumerable_thread_specific<Bdpt::Scratch> local;
};

std::string bdpt_refusal(const Scene& scene) {
  if (!scene.curves.empty()) return "the scene has curves (hair), which bdpt does not render yet";
  if (rendered_medium(scene, scene.camera_medium) >= 0)
    for (const Light& l : scene.lights)
      if (l.type == LightKind::distant || l.type == LightKind::infinite)
        return "the camera sits in a medium and a source is at infinity (its light subpaths would start outside "
               "that medium), which bdpt does not render";
  return "";
}

Bdpt::Bdpt(const Scene& scene, const SceneViews& v, const Estimator& est, int width, int height, const float* lo,
           const float* hi)
    : v_(v), est_(est), width_(width), height_(height), cam_(v.camera, width, height, "--bdpt"),
      pool_(std::make_unique<BdptPool>()) {
  const LightView& L = v.lights;
  const GeomView& G = v.geom;
  const std::string why = bdpt_refusal(scene);
  if (!why.empty()) throw std::invalid_argument("--bdpt: " + why + " (render it without --bdpt)");
  if (G.has_hair) throw std::invalid_argument("--bdpt: the scene's views hold what it refuses");
  source_media(scene, v, medium_out_, medium_in_);
  for (int32_t i = 0; i < L.count; ++i)
    if (!area_kind(L.type[i]) && !positional_light(L.type[i]) && !at_infinity(L.type[i]))
      throw std::invalid_argument("--bdpt: the scene's light table holds a source it does not sample");
  double r2 = 0;
  bool bounded = true;
  for (int a = 0; a < 3; ++a) {
    bounded = bounded && std::isfinite(lo[a]) && std::isfinite(hi[a]) && lo[a] <= hi[a];
    centre_[a] = 0.5f * (lo[a] + hi[a]);
    r2 += 0.25 * static_cast<double>(hi[a] - lo[a]) * static_cast<double>(hi[a] - lo[a]);
  }
  radius_ = static_cast<float>(std::sqrt(r2));
  if (!bounded || !(radius_ > 0.f) || !std::isfinite(radius_)) {  // (nothing to hit: the disc is any disc)
    centre_[0] = centre_[1] = centre_[2] = 0.f;
    radius_ = 1.f;
  }
  pmf_.assign(static_cast<size_t>(L.count), 0.f);
  double total = 0;
  std::vector<double> power;
  for (int32_t i = 0; i < L.count; ++i) {
    const int32_t s = L.one_radiance ? 0 : i;
    const double lum = static_cast<double>(luminance<float>(L.Lr[s], L.Lg[s], L.Lb[s]));
    double p = 0;
    if (area_kind(L.type[i])) {
      p = lum * L.area[i] * (L.two_sided[i] > 0.5f ? 2 : 1);
    } else if (at_infinity(L.type[i])) {  // the scene's (light/kinds: pi R^2 times the irradiance)
      p = static_cast<double>(scene.lights[static_cast<size_t>(i)].power);
      if (L.type[i] == static_cast<int32_t>(LightKind::infinite)) skies_.push_back(i);
    } else {
      p = positional_power(L.type[i], broadcast_light<float>(L, i), lum);
    }
    if (!(p > 0) || !std::isfinite(p)) continue;
    lights_.push_back(i);
    power.push_back(p);
    total += p;
  }
  double run = 0;
  for (size_t k = 0; k < lights_.size(); ++k) {
    run += power[k];
    cdf_.push_back(static_cast<float>(run / total));
    pmf_[static_cast<size_t>(lights_[k])] = static_cast<float>(power[k] / total);
  }
  if (!cdf_.empty()) cdf_.back() = 1.f;
}

Bdpt::~Bdpt() = default;

std::string Bdpt::describe() const {
  const LightView& L = v_.lights;
  int area = 0, positional = 0, distant = 0, skies = 0;
  for (const int32_t l : lights_) {
    area += area_kind(L.type[l]);
    positional += positional_light(L.type[l]);
    distant += L.type[l] == static_cast<int32_t>(LightKind::distant);
    skies += L.type[l] == static_cast<int32_t>(LightKind::infinite);
  }
  std::string s = std::to_string(lights_.size()) + " source(s) with power, picked by power for the light subpaths and "
                  "the s = 1 joins alike (" + std::to_string(area) + " area, " + std::to_string(positional) +
                  " point or spot, " + std::to_string(distant) + " distant, " + std::to_string(skies) + " sky)";
  if (distant + skies > 0) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "; the light subpaths from the sources at infinity start on a disc of radius %.4g round (%.4g, %.4g, %.4g)",
                  static_cast<double>(radius_), static_cast<double>(centre_[0]), static_cast<double>(centre_[1]),
                  static_cast<double>(centre_[2]));
    s += buf;
  }
  if (v_.geom.has_media)
    s += "; media: every ray's free flight on both subpaths (the path tracer's), the joins through the media and "
         "their interfaces, the media's emission on the camera subpath";
  return s;
}

void Bdpt::trace_tile(const Accel& accel, TileBuffers& tb, int tile, int tile_size, int tiles_x, uint32_t begin,
                      uint32_t end, std::vector<LightPathSplat>& out, uint64_t& rejected) const {
  if (lights_.empty()) return;  // nothing emits: a black image
  Scratch& S = pool_->local.local();
  const GeomView& G = v_.geom;
  const LightView& L = v_.lights;
  const Estimator& est = est_;
  Estimator hits = est;  // the hit stages' estimator: no one-sample choice, no regularization
  hits.mode = MisMode::multi;
  hits.regularize = false;
  const int D = est.max_depth;
  const int x0 = (tile % tiles_x) * tile_size, y0 = (tile / tiles_x) * tile_size;
  const int tw = std::min(tile_size, width_ - x0), th = std::min(tile_size, height_ - y0);
  const int lanes = tw * th;
  const int padded = packet_padded(lanes);
  for (int i = 0; i < padded; ++i) {
    const int j = i < lanes ? i : 0;
    tb.lanes.fx[i] = static_cast<float>(x0 + j % tw);
    tb.lanes.fy[i] = static_cast<float>(y0 + j / tw);
    tb.lanes.pixel[i] = static_cast<uint32_t>(y0 + j / tw) * static_cast<uint32_t>(width_) + static_cast<uint32_t>(x0 + j % tw);
  }
  tb.keys.keyed = 0;  // (no cached keys: every pair is drawn here)
  for (auto* a : {&S.br, &S.bg, &S.bb, &S.pend, &S.m0, &S.u0, &S.u1, &S.u2, &S.u3, &S.u4, &S.u5, &S.sr, &S.sg, &S.sb,
                  &S.mr, &S.mg, &S.mb})
    a->resize(lane_array);
  S.jmed.resize(lane_array);
  const bool media = G.has_media;
  S.pend_light.resize(lane_array);
  for (auto* a : {&S.esc_pdf, &S.esc_r, &S.esc_g, &S.esc_b}) a->resize(lane_array);
  S.esc_t.resize(lane_array);
  S.esc_d.resize(lane_array);
  S.ncam.resize(lane_array);
  S.nlight.resize(lane_array);
  auto layer = [](std::vector<std::vector<Vertex>>& path, int j) {
    while (static_cast<int>(path.size()) <= j) path.emplace_back(lane_array);
  };
  layer(S.cam, 0);
  layer(S.light, 0);
  // the sampler's pairs: the camera's position in the pixel (SampleLayout::camera, as the
  // path tracer), four per camera vertex (its BSDF direction; lobe and Russian roulette; the
  // s = 1 join's source and point), three for the emission, two per light vertex
  const uint32_t light_base = 1 + 4 * static_cast<uint32_t>(D + 1);
  auto cam_pair = [](int j, int what) { return 1 + 4 * static_cast<uint32_t>(j - 1) + static_cast<uint32_t>(what); };
  auto light_pair = [&](int j, int what) { return light_base + 3 + 2 * static_cast<uint32_t>(j - 1) + static_cast<uint32_t>(what); };
  // in a scene with media, one more per ray for its free flight (after the others, so that
  // the pairs of a scene without media are as they were): the ray that leaves vertex j - 1
  const uint32_t flight_base = light_base + 3 + 2 * static_cast<uint32_t>(D + 1);
  auto flight_pair = [&](bool from_light, int j) {
    return flight_base + (from_light ? static_cast<uint32_t>(D + 1) : 0u) + static_cast<uint32_t>(j - 1);
  };
  auto pairs = [&](uint32_t s, uint32_t pair, float* u, float* w) {
    sample_pairs(est.sampler, est.seed, tb.lanes.pixel, s, est.spp, pair, padded, u, w);
  };
  const float inv_t = 1.f / est.rr_threshold;
  auto trace = [&](const int32_t* valid, RayHit16& p) { accel.intersect16(valid, p, false, Bvh::scene); };
  ShadingPoints& P = tb.points;
  auto start_points = [&]() {
    for (int i = 0; i < padded; ++i) {
      P.lane[i] = i;
      P.pixel[i] = tb.lanes.pixel[i];
      tb.path.throughput_r[i] = tb.path.throughput_g[i] = tb.path.throughput_b[i] = 0.f;
      tb.path.eta_scale[i] = 1.f;
      tb.path.rough[i] = tb.path.first_rough[i] = 0.f;
    }
    P.count = lanes;
  };

  // One subpath's walk from its first rays (set in tb.bounce and tb.tech.valid, one per
  // lane; in a scene with media, tb.media.med the media they start in): each ray's free
  // flight (its weight joins the throughput) ends at vertex j of the lane, a surface or a
  // point in a medium, whose BSDF (or phase function) samples the next direction, until
  // vertex `last`. from_light: the adjoint's weights; else the emitters met are noted, and
  // the media's emission on the way is gathered (s = 0: no other strategy meets it), along
  // the rays of the first D vertices (the path tracer's: the segments before the last vertex).
  auto walk = [&](uint32_t s, bool from_light, std::vector<std::vector<Vertex>>& path, std::vector<int>& n, int last,
                  bool traced) {
    for (int j = 1;; ++j) {
      const int count = P.count;
      const int cp = packet_padded(count);
      if (j > 1 || !traced)
        for (int p = 0; p < cp / packet_width; ++p) {
          reset_hit(tb.bounce[p]);
          trace(tb.tech.valid + p * packet_width, tb.bounce[p]);
        }
      if (media) {
        pairs(s, flight_pair(from_light, j), S.u0.data(), S.u1.data());
        for (int k = 0; k < count; ++k) {
          tb.media.u0[k] = S.u0[static_cast<size_t>(P.lane[k])];
          tb.media.u1[k] = S.u1[static_cast<size_t>(P.lane[k])];
        }
        medium_flights(G, tb.bounce, tb.tech.valid, count, tb.media, rejected, trace);
        for (int k = 0; k < count; ++k) {
          if (!tb.tech.valid[k]) continue;
          const size_t ln = static_cast<size_t>(P.lane[k]);
          if (!from_light && j <= D) {
            S.mr[ln] += S.br[ln] * tb.media.er[k];
            S.mg[ln] += S.bg[ln] * tb.media.eg[k];
            S.mb[ln] += S.bb[ln] * tb.media.eb[k];
          }
          S.br[ln] *= tb.media.wr[k];
          S.bg[ln] *= tb.media.wg[k];
          S.bb[ln] *= tb.media.wb[k];
        }
      }
      if (!from_light)
        for (int k = 0; k < count; ++k) {
          const int lane = P.lane[k];
          S.pend_light[lane] = -1;
          if (!tb.tech.valid[k]) continue;
          if (!skies_.empty() && static_cast<int32_t>(tb.bounce[k / packet_width].geomID[k % packet_width]) < 0) {
            const RayHit16& r = tb.bounce[k / packet_width];  // escaped: the skies' vertex z(j)
            const int ln = k % packet_width;
            const size_t li = static_cast<size_t>(lane);
            S.esc_t[li] = j + 1;
            S.esc_d[li] = V3(r.ray.dir_x[ln], r.ray.dir_y[ln], r.ray.dir_z[ln]);
            S.esc_pdf[li] = S.pend[li];
            S.esc_r[li] = S.br[li];
            S.esc_g[li] = S.bg[li];
            S.esc_b[li] = S.bb[li];
            continue;
          }
          const int32_t l = bounce_hit_light<float>(G, tb, k, true);
          if (l < 0 || pmf_[static_cast<size_t>(l)] == 0.f) continue;
          const RayHit16& r = tb.bounce[k / packet_width];
          const int ln = k % packet_width;
          const V3 o{r.ray.org_x[ln], r.ray.org_y[ln], r.ray.org_z[ln]}, d{r.ray.dir_x[ln], r.ray.dir_y[ln], r.ray.dir_z[ln]};
          if (light_front_lanes<float, true>(L, l, o, d)) S.pend_light[lane] = l;
        }
      bounce_hits<vfloat, true>(G, L, hits, s, 0, tb);
      const int np_ = P.count;
      if (np_ == 0) break;
      layer(path, j);
      for (int k = 0; k < np_; ++k) {
        const int lane = P.lane[k];
        Vertex& v = path[static_cast<size_t>(j)][static_cast<size_t>(lane)];
        const Vertex& prev = path[static_cast<size_t>(j - 1)][static_cast<size_t>(lane)];
        v.p = {P.px[k], P.py[k], P.pz[k]};
        v.ng = {P.nx[k], P.ny[k], P.nz[k]};
        const V3 ns = G.shading_normals ? V3(P.snx[k], P.sny[k], P.snz[k]) : v.ng;
        v.bsdf = load_surface_bsdf<float, bsdf_all>(G, P, k, ns);
        v.eps = P.eps[k];
        v.beta[0] = S.br[lane];
        v.beta[1] = S.bg[lane];
        v.beta[2] = S.bb[lane];
        v.light = from_light ? -1 : S.pend_light[lane];
        v.medf = media ? P.medf[k] : -1;
        v.medb = media ? P.medb[k] : -1;
        v.infinite = false;
        v.fwd = to_area(S.pend[lane], prev, v);
        v.rev = 0.f;
        v.delta = false;
        n[static_cast<size_t>(lane)] = j + 1;
      }
      if (j >= last) break;
      const int np = packet_padded(np_);
      pairs(s, from_light ? light_pair(j, 0) : cam_pair(j, 0), S.u0.data(), S.u1.data());
      pairs(s, from_light ? light_pair(j, 1) : cam_pair(j, 1), S.u2.data(), S.u3.data());
      const bool roulette = j > est.rr_depth;
      for (int k = 0; k < np; ++k) {
        tb.tech.valid[k] = 0;
        if (k >= np_) continue;
        const int lane = P.lane[k];
        const size_t ln = static_cast<size_t>(lane);
        Vertex& v = path[static_cast<size_t>(j)][ln];
        Vertex& prev = path[static_cast<size_t>(j - 1)][ln];
        const BsdfSample<float> bs = v.bsdf.sample(S.u2[ln], S.u0[ln], S.u1[ln]);
        if (!bs.valid) continue;
        const V3 wo = v.bsdf.wo;
        // the adjoint: Veach's shading-normal factor, no 1 / eta^2 on transmissions
        const float adj = from_light && !in_medium(v)
                              ? adjoint_factor(G, v.bsdf.mat, v.bsdf.kind, v.bsdf.side, v.ng, v.bsdf.n, wo, bs.wi)
                              : 1.f;
        float br = S.br[ln] * bs.weight.r * adj, bg = S.bg[ln] * bs.weight.g * adj, bb = S.bb[ln] * bs.weight.b * adj;
        const float m = std::max(std::max(br, bg), bb);
        if (!std::isfinite(m)) {
          ++rejected;
          continue;
        }
        if (!(m > 0.f)) continue;
        if (roulette) {
          const float rr = m * (from_light ? S.m0[ln] : 1.f) * inv_t;
          if (rr < 1.f) {
            if (S.u3[ln] >= rr) continue;
            br /= rr;
            bg /= rr;
            bb /= rr;
          }
        }
        S.br[ln] = br;
        S.bg[ln] = bg;
        S.bb[ln] = bb;
        v.delta = bs.delta;
        S.pend[ln] = bs.delta ? 0.f : bs.pdf;
        if (bs.delta) {
          prev.rev = 0.f;
        } else {  // the vertex before, as the next one's BSDF would sample it
          prev.rev = to_area(viewed_from(v, bs.wi).eval(wo).pdf, v, prev);
        }
        set_light_ray(tb, k, offset(v.p, v.ng, v.eps, bs.wi), bs.wi);
        if (media) tb.media.med[k] = ray_medium(v, bs.wi);
      }
    }
  };

  // the densities of emission from a point of source l with normal n (on its emitting
  // side) towards unit w: per unit area of the source, and per unit solid angle
  auto emit_sa = [&](int32_t l, const V3& n, const V3& w) {
    if (L.type[l] == static_cast<int32_t>(LightKind::point)) return 1.f / (4.f * pi_f);
    if (L.type[l] == static_cast<int32_t>(LightKind::spot)) {  // uniform in the cone
      const LightGeom<float> g = broadcast_light<float>(L, l);
      return dot(w, g.e1) >= g.e2.y ? 1.f / (2.f * pi_f * (1.f - g.e2.y)) : 0.f;
    }
    const float c = dot(n, w);
    if (L.two_sided[l] > 0.5f) return std::abs(c) * (0.5f / pi_f);
    return c > 0.f ? c * (1.f / pi_f) : 0.f;
  };
  auto point_on = [&](int32_t l, float ua, float ub, V3& n) {
    const LightGeom<float> g = broadcast_light<float>(L, l);
    V3 y;
    if (L.type[l] == static_cast<int32_t>(LightKind::sphere)) {
      y = LightKindOps<LightKind::sphere>::area_point(g, ua, ub);
      n = normalize(y - g.p0);
    } else if (L.type[l] == static_cast<int32_t>(LightKind::triangle)) {
      y = LightKindOps<LightKind::triangle>::area_point(g, ua, ub);
      n = g.n;
    } else {
      y = LightKindOps<LightKind::parallelogram>::area_point(g, ua, ub);
      n = g.n;
    }
    return y;
  };
  auto pick = [&](float u) {
    return lights_[std::min(static_cast<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), u) - cdf_.begin()), cdf_.size() - 1)];
  };
  auto radiance = [&](int32_t l, float c[3]) {
    const int32_t sl = L.one_radiance ? 0 : l;
    c[0] = L.Lr[sl];
    c[1] = L.Lg[sl];
    c[2] = L.Lb[sl];
  };
  // an area source's emission at its point y times its alpha there (emitter_alpha)
  auto cut = [&](int32_t l, const V3& y, float le[3]) {
    const float a = emitter_alpha(L, l, y);
    for (int c = 0; c < 3; ++c) le[c] *= a;
  };
  // a source at infinity's direction towards it (wi), its density per unit solid angle (1
  // for a distant source's one direction) and its radiance along it (le, the table's on entry)
  auto infinite_direction = [&](int32_t l, float u1, float u2, V3& wi, float le[3]) {
    LightGeom<float> g = broadcast_light<float>(L, l);
    if (L.type[l] == static_cast<int32_t>(LightKind::distant)) {
      wi = g.e1;
      return 1.f;
    }
    g.sky_dist = sky_dist_full;  // (every direction: the camera's side draws none of them alone)
    const SkySample<float> ss = Sky::sample_direction(g, u1, u2);
    wi = ss.wi;
    if (ss.texel >= 0) Sky::apply_texel(g, ss.texel, le[0], le[1], le[2]);
    return ss.pdf;
  };
  // the density with which the light side draws the direction wi towards the skies: each
  // sky's pick times its density, summed (pbrt-v4's InfiniteLightDensity)
  auto sky_density = [&](const V3& wi) {
    float d = 0.f;
    for (const int32_t l : skies_) {
      const float pmf = pmf_[static_cast<size_t>(l)];
      if (pmf == 0.f) continue;
      LightGeom<float> g = broadcast_light<float>(L, l);
      g.sky_dist = sky_dist_full;
      d += pmf * Sky::pdf_direction(g, wi);
    }
    return d;
  };
  const float disc_pdf = 1.f / (pi_f * radius_ * radius_);  // per unit area of the disc
  const V3 centre{centre_[0], centre_[1], centre_[2]};
  auto finite3 = [](const float c[3]) { return std::isfinite(c[0]) && std::isfinite(c[1]) && std::isfinite(c[2]); };
  auto nonzero3 = [](const float c[3]) { return c[0] > 0.f || c[1] > 0.f || c[2] > 0.f; };

  for (uint32_t s = begin; s < end; ++s) {
    // the camera subpaths: z0 the camera, z1 its ray's hit
    generate(v_.camera, est, s, SampleLayout::camera, lanes, tb);
    for (int p = 0; p < padded / packet_width; ++p) {
      accel.intersect16(tb.lanes.cam_valid + p * packet_width, tb.cam[p], true, Bvh::scene);
      tb.bounce[p] = tb.cam[p];
    }
    start_points();
    const V3 eye{static_cast<float>(cam_.origin()[0]), static_cast<float>(cam_.origin()[1]), static_cast<float>(cam_.origin()[2])};
    for (int i = 0; i < padded; ++i) {
      tb.tech.valid[i] = i < lanes ? tb.lanes.cam_valid[i] : 0;
      const float w = tb.lanes.weighted ? tb.lanes.fw[i] : 1.f;
      S.br[static_cast<size_t>(i)] = S.bg[static_cast<size_t>(i)] = S.bb[static_cast<size_t>(i)] = w;
      const RayHit16& r = tb.cam[i / packet_width];
      const int ln = i % packet_width;
      S.pend[static_cast<size_t>(i)] =
          static_cast<float>(cam_.ray_density(V3(r.ray.dir_x[ln], r.ray.dir_y[ln], r.ray.dir_z[ln])));
      Vertex& z0 = S.cam[0][static_cast<size_t>(i)];
      z0 = Vertex{};
      z0.p = eye;
      S.ncam[static_cast<size_t>(i)] = 1;
      S.esc_t[static_cast<size_t>(i)] = 0;
      S.mr[static_cast<size_t>(i)] = S.mg[static_cast<size_t>(i)] = S.mb[static_cast<size_t>(i)] = 0.f;
      tb.media.med[i] = G.media.camera;
    }
    walk(s, false, S.cam, S.ncam, D + 1, true);

    // lane i's light subpath after y0: its throughput le times scale (Russian roulette's
    // reference), the density pend of its first ray's direction (the disc's, from a source
    // at infinity), that ray; none where the throughput is zero or not finite
    auto start = [&](int i, const float le[3], float scale, float pend, const V3& org, const V3& dir, int32_t med) {
      const size_t li = static_cast<size_t>(i);
      tb.media.med[i] = med;
      S.br[li] = le[0] * scale;
      S.bg[li] = le[1] * scale;
      S.bb[li] = le[2] * scale;
      const float m0 = std::max(std::max(S.br[li], S.bg[li]), S.bb[li]);
      if (!(m0 > 0.f) || !std::isfinite(m0)) return;
      S.m0[li] = 1.f / m0;
      S.pend[li] = pend;
      set_light_ray(tb, i, org, dir);
    };
    // the light subpaths: y0 on a source picked by power, uniform in area, its direction
    // cosine-weighted (either side of a two-sided source, by u1)
    pairs(s, light_base, S.u0.data(), S.u1.data());
    pairs(s, light_base + 1, S.u2.data(), S.u3.data());
    pairs(s, light_base + 2, S.u4.data(), S.u5.data());
    start_points();
    for (int i = 0; i < padded; ++i) {
      const size_t li = static_cast<size_t>(i);
      tb.tech.valid[i] = 0;
      S.nlight[li] = 0;
      if (i >= lanes) continue;
      const int32_t l = pick(S.u0[li]);
      if (at_infinity(L.type[l])) {  // y0 on the disc facing the direction, beyond the scene
        const float pmf = pmf_[static_cast<size_t>(l)];
        float le[3];
        radiance(l, le);
        V3 wi;
        const float pdf_dir = infinite_direction(l, S.u4[li], S.u5[li], wi, le);
        if (!(pdf_dir > 0.f)) continue;
        V3 t, b;
        make_basis(wi, t, b);
        const float rr = radius_ * std::sqrt(S.u2[li]), phi = 2.f * pi_f * S.u3[li];
        const V3 o = centre + t * (rr * std::cos(phi)) + b * (rr * std::sin(phi)) + wi * (radius_ * 1.01f + 1e-3f * (radius_ + 1.f));
        const bool distant = L.type[l] == static_cast<int32_t>(LightKind::distant);
        Vertex& y0 = S.light[0][li];
        y0 = Vertex{};
        y0.p = o;
        y0.light = l;
        y0.infinite = true;
        for (int c = 0; c < 3; ++c) y0.beta[c] = le[c] / pmf;
        y0.fwd = distant ? pmf : sky_density(wi);
        S.nlight[li] = 1;
        start(i, le, 1.f / (pmf * disc_pdf * pdf_dir), disc_pdf, o, V3(0.f, 0.f, 0.f) - wi, -1);
        continue;
      }
      if (positional_light(L.type[l])) {  // a point or spot source: y0 its position, on no surface
        const LightGeom<float> g = broadcast_light<float>(L, l);
        const float pmf = pmf_[static_cast<size_t>(l)];
        float le[3];
        radiance(l, le);
        Vertex& y0 = S.light[0][li];
        y0 = Vertex{};
        y0.p = g.p0;
        y0.light = l;
        for (int c = 0; c < 3; ++c) y0.beta[c] = le[c] / pmf;
        y0.fwd = pmf;
        S.nlight[li] = 1;
        V3 d;
        float falloff;
        const float pdf_dir = sample_positional_direction(L.type[l], g, S.u4[li], S.u5[li], d, falloff);
        start(i, le, falloff / (pmf * pdf_dir), pdf_dir, g.p0, d, medium_out_[static_cast<size_t>(l)]);
        continue;
      }
      V3 n;
      const V3 y = point_on(l, S.u2[li], S.u3[li], n);
      const bool two = L.two_sided[l] > 0.5f;
      const bool back = two && S.u1[li] >= 0.5f;
      if (back) n = V3(0.f, 0.f, 0.f) - n;
      const float pmf = pmf_[static_cast<size_t>(l)];
      const float pdf_pos = pmf / L.area[l];
      float le[3];
      radiance(l, le);
      cut(l, y, le);
      Vertex& y0 = S.light[0][li];
      y0 = Vertex{};
      y0.p = y;
      y0.ng = n;
      y0.light = l;
      y0.eps = offset_eps(y);
      for (int c = 0; c < 3; ++c) y0.beta[c] = le[c] / pdf_pos;
      y0.fwd = pdf_pos;
      S.nlight[li] = 1;
      V3 t, b;
      make_basis(n, t, b);
      const V3 dl = sample_cosine_hemisphere<float>(S.u4[li], S.u5[li]);
      if (!(dl.z > 0.f)) continue;
      const V3 d = normalize(t * dl.x + b * dl.y + n * dl.z);
      const float pdf_dir = dl.z * ((two ? 0.5f : 1.f) / pi_f);
      start(i, le, 1.f / (pdf_pos * pdf_dir) * dl.z, pdf_dir, y + n * y0.eps, d,
            (back ? medium_in_ : medium_out_)[static_cast<size_t>(l)]);
    }
    walk(s, true, S.light, S.nlight, D, false);
    // each subpath vertex's prefix sum of the weights' ratios (bdpt_mis.h)
    for (int i = 0; i < lanes; ++i) {
      const size_t ln = static_cast<size_t>(i);
      float p = 0.f;
      for (int k = 1; k < S.ncam[ln]; ++k) {
        Vertex& z = S.cam[static_cast<size_t>(k)][ln];
        p = bdpt_prefix(p, {z.fwd, z.rev, z.delta}, S.cam[static_cast<size_t>(k - 1)][ln].delta);
        z.mis = p;
      }
      p = 0.f;
      for (int k = 0; k < S.nlight[ln]; ++k) {
        Vertex& y = S.light[static_cast<size_t>(k)][ln];
        p = bdpt_prefix(p, {y.fwd, y.rev, y.delta},
                        k > 0 ? S.light[static_cast<size_t>(k - 1)][ln].delta : delta_source(L.type[y.light]));
        y.mis = p;
      }
    }

    // the joins
    S.jobs.clear();
    std::copy_n(S.mr.begin(), lanes, S.sr.begin());  // (the media's emission: zero without media)
    std::copy_n(S.mg.begin(), lanes, S.sg.begin());
    std::copy_n(S.mb.begin(), lanes, S.sb.begin());
    auto add_lane = [&](int lane, const float c[3]) {
      S.sr[static_cast<size_t>(lane)] += c[0];
      S.sg[static_cast<size_t>(lane)] += c[1];
      S.sb[static_cast<size_t>(lane)] += c[2];
    };
    // one side of a join: its n vertices, the reverse densities through the join of its
    // last two (rev2 unused where there is one), whether a delta light stands before y0
    auto delta_light = [&](int lane) { return delta_source(L.type[S.light[0][static_cast<size_t>(lane)].light]); };
    auto side = [&](const std::vector<std::vector<Vertex>>& path, int lane, int n, float fwd1, float rev1, float rev2,
                    bool dl) {
      const size_t ln = static_cast<size_t>(lane);
      BdptSide d{n, fwd1, rev1, 0.f, rev2, n == 1 && dl, n == 2 && dl, 0.f};
      if (n >= 2) {
        const Vertex& v2 = path[static_cast<size_t>(n - 2)][ln];
        d.fwd2 = v2.fwd;
        d.delta2 = v2.delta;
      }
      if (n >= 3) {
        const Vertex& v3 = path[static_cast<size_t>(n - 3)][ln];
        d.delta3 = v3.delta;
        d.prefix3 = v3.mis;
      }
      return d;
    };
    const BdptSide none{0, 0.f, 0.f, 0.f, 0.f, false, false, 0.f};
    // the density of reaching `to` from `from` along a direction of solid-angle density pdf
    auto area = [](float pdf, const V3& from, const Vertex& to) {
      if (to.infinite) return pdf;
      const V3 e = to.p - from;
      const float d2 = dot(e, e);
      return pdf * cosine_over_length(to, e, std::sqrt(d2)) / d2;
    };
    auto shadow = [&](Job& j, const V3& a, const V3& na, float ea, const V3& b, const V3& nb, float eb) {
      const V3 ab = b - a;
      j.org = ea > 0.f ? offset(a, na, ea, ab) : a;
      const V3 end_ = eb > 0.f ? offset(b, nb, eb, V3(0.f, 0.f, 0.f) - ab) : b;
      const V3 e = end_ - j.org;
      const float len = std::sqrt(dot(e, e));
      j.dir = e * (1.f / len);
      j.tfar = len * (1.f - 1.f / 4096.f);
      return len > 0.f && std::isfinite(len);
    };
    auto push = [&](Job& j) {
      if (!nonzero3(j.c)) return;
      if (!finite3(j.c)) {
        ++rejected;
        return;
      }
      S.jobs.push_back(j);
    };
    int most = 0;
    for (int i = 0; i < lanes; ++i) most = std::max(most, S.ncam[static_cast<size_t>(i)]);
    // s = 0: the camera subpath's emitters
    for (int i = 0; i < lanes; ++i) {
      const size_t ln = static_cast<size_t>(i);
      for (int t = 2; t <= S.ncam[ln]; ++t) {
        const Vertex& z = S.cam[static_cast<size_t>(t - 1)][ln];
        if (z.light < 0) continue;
        float c[3];
        radiance(z.light, c);
        for (int k = 0; k < 3; ++k) c[k] *= z.beta[k];
        if (!nonzero3(c)) continue;
        float w = 1.f;
        if (t > 2) {
          const Vertex& zm = S.cam[static_cast<size_t>(t - 2)][ln];
          const V3 we = normalize(zm.p - z.p);
          w = bdpt_mis(none, side(S.cam, i, t, z.fwd, pmf_[static_cast<size_t>(z.light)] / L.area[z.light],
                                  area(emit_sa(z.light, z.ng, we), z.p, zm), false));
        }
        for (int k = 0; k < 3; ++k) c[k] *= w;
        if (!finite3(c)) {
          ++rejected;
          continue;
        }
        add_lane(i, c);
      }
    }
    // s = 0 at infinity: the camera subpath's ray that escaped meets every sky along it
    if (!skies_.empty())
      for (int i = 0; i < lanes; ++i) {
        const size_t ln = static_cast<size_t>(i);
        const int t = S.esc_t[ln];
        if (t < 2) continue;
        const V3 d = S.esc_d[ln];
        float c[3] = {0.f, 0.f, 0.f};
        for (const int32_t l : skies_) {
          float r, g, b;
          sky_radiance<float>(L, l, d, r, g, b);
          c[0] += r;
          c[1] += g;
          c[2] += b;
        }
        c[0] *= S.esc_r[ln];
        c[1] *= S.esc_g[ln];
        c[2] *= S.esc_b[ln];
        if (!nonzero3(c)) continue;
        float w = 1.f;
        if (t > 2) {  // z(t-2) as y1 of a light subpath from the disc: its density per area times its cosine
          const Vertex& zm = S.cam[static_cast<size_t>(t - 2)][ln];
          w = bdpt_mis(none, side(S.cam, i, t, S.esc_pdf[ln], sky_density(d), disc_pdf * cos_geo(zm, d), false));
        }
        for (int k = 0; k < 3; ++k) c[k] *= w;
        if (!finite3(c)) {
          ++rejected;
          continue;
        }
        add_lane(i, c);
      }
    // s = 1: a point on a source joined to z(t-1), t - 1 in 1..D
    for (int j = 1; j < most && j <= D; ++j) {
      pairs(s, cam_pair(j, 2), S.u0.data(), S.u1.data());
      pairs(s, cam_pair(j, 3), S.u2.data(), S.u3.data());
      for (int i = 0; i < lanes; ++i) {
        const size_t ln = static_cast<size_t>(i);
        if (S.ncam[ln] <= j) continue;
        const int t = j + 1;
        const Vertex& z = S.cam[static_cast<size_t>(j)][ln];
        const int32_t l = pick(S.u0[ln]);
        if (at_infinity(L.type[l])) {  // a direction towards it, a shadow ray to infinity
          float le[3];
          radiance(l, le);
          V3 w;
          const float pdf_dir = infinite_direction(l, S.u2[ln], S.u3[ln], w, le);
          if (!(pdf_dir > 0.f)) continue;
          const BsdfEval<float> fz = z.bsdf.eval(w);
          const float pmf = pmf_[static_cast<size_t>(l)];
          Job job{};
          job.lane = i;
          job.s = 1;
          job.t = t;
          const float gg = cos_shading(z, w) / (pmf * pdf_dir);
          job.c[0] = z.beta[0] * fz.f.r * le[0] * gg;
          job.c[1] = z.beta[1] * fz.f.g * le[1] * gg;
          job.c[2] = z.beta[2] * fz.f.b * le[2] * gg;
          if (!nonzero3(job.c)) continue;
          const bool distant = L.type[l] == static_cast<int32_t>(LightKind::distant);
          const BdptSide ls{1, distant ? pmf : sky_density(w), fz.pdf, 0.f, 0.f, distant, false, 0.f};
          const float zrev = disc_pdf * cos_geo(z, w);
          const float zmrev =
              t > 2 ? area(viewed_from(z, w).eval(z.bsdf.wo).pdf, z.p, S.cam[static_cast<size_t>(t - 2)][ln]) : 0.f;
          const float wgt = bdpt_mis(ls, side(S.cam, i, t, z.fwd, zrev, zmrev, false));
          for (float& c : job.c) c *= wgt;
          job.org = offset(z.p, z.ng, z.eps, w);
          job.dir = w;
          job.tfar = INFINITY;
          job.med = ray_medium(z, w);
          push(job);
          continue;
        }
        if (positional_light(L.type[l])) {  // its position, the falloff's intensity towards z
          const LightGeom<float> g = broadcast_light<float>(L, l);
          const V3 e = g.p0 - z.p;
          const float d2 = dot(e, e);
          const float dist = std::sqrt(d2);
          if (!(dist > 0.f)) continue;
          const V3 w = e * (1.f / dist);
          const float falloff =
              L.type[l] == static_cast<int32_t>(LightKind::spot) ? spot_falloff(g, -dot(w, g.e1)) : 1.f;
          if (!(falloff > 0.f)) continue;
          const BsdfEval<float> fz = z.bsdf.eval(w);
          const float pmf = pmf_[static_cast<size_t>(l)];
          float le[3];
          radiance(l, le);
          Job job{};
          job.lane = i;
          job.s = 1;
          job.t = t;
          const float gg = cos_shading(z, w) * falloff / (d2 * pmf);
          job.c[0] = z.beta[0] * fz.f.r * le[0] * gg;
          job.c[1] = z.beta[1] * fz.f.g * le[1] * gg;
          job.c[2] = z.beta[2] * fz.f.b * le[2] * gg;
          if (!nonzero3(job.c)) continue;
          const BdptSide ls{1, pmf, fz.pdf / d2, 0.f, 0.f, true, false, 0.f};  // (a delta light)
          const float zrev = emit_sa(l, V3(0.f, 0.f, 0.f), V3(0.f, 0.f, 0.f) - w) * cos_geo(z, w) / d2;
          const float zmrev =
              t > 2 ? area(viewed_from(z, w).eval(z.bsdf.wo).pdf, z.p, S.cam[static_cast<size_t>(t - 2)][ln]) : 0.f;
          const float wgt = bdpt_mis(ls, side(S.cam, i, t, z.fwd, zrev, zmrev, false));
          for (float& c : job.c) c *= wgt;
          job.med = ray_medium(z, w);
          if (shadow(job, z.p, z.ng, z.eps, g.p0, V3(0.f, 0.f, 0.f), 0.f)) push(job);
          continue;
        }
        V3 n;
        const V3 y = point_on(l, S.u2[ln], S.u3[ln], n);
        const V3 e = y - z.p;
        const float d2 = dot(e, e);
        const float dist = std::sqrt(d2);
        if (!(dist > 0.f)) continue;
        const V3 w = e * (1.f / dist);
        const float cl = dot(n, w);  // (the source faces z where cl < 0)
        if (!(L.two_sided[l] > 0.5f) && !(cl < 0.f)) continue;
        const BsdfEval<float> fz = z.bsdf.eval(w);
        const float pdf_pos = pmf_[static_cast<size_t>(l)] / L.area[l];
        float le[3];
        radiance(l, le);
        cut(l, y, le);
        Job job{};
        job.lane = i;
        job.s = 1;
        job.t = t;
        const float g = cos_shading(z, w) * std::abs(cl) / (d2 * pdf_pos);
        job.c[0] = z.beta[0] * fz.f.r * le[0] * g;
        job.c[1] = z.beta[1] * fz.f.g * le[1] * g;
        job.c[2] = z.beta[2] * fz.f.b * le[2] * g;
        if (!nonzero3(job.c)) continue;
        const V3 nf = cl < 0.f ? n : V3(0.f, 0.f, 0.f) - n;  // the source's normal on z's side
        const BdptSide ls{1, pdf_pos, fz.pdf * std::abs(cl) / d2, 0.f, 0.f, false, false, 0.f};
        const float zrev = emit_sa(l, nf, V3(0.f, 0.f, 0.f) - w) * cos_geo(z, w) / d2;
        const float zmrev = t > 2 ? area(viewed_from(z, w).eval(z.bsdf.wo).pdf, z.p, S.cam[static_cast<size_t>(t - 2)][ln]) : 0.f;
        const float wgt = bdpt_mis(ls, side(S.cam, i, t, z.fwd, zrev, zmrev, false));
        for (float& c : job.c) c *= wgt;
        job.med = ray_medium(z, w);
        if (shadow(job, z.p, z.ng, z.eps, y, nf, offset_eps(y))) push(job);
      }
    }
    for (int i = 0; i < lanes; ++i) {
      const size_t ln = static_cast<size_t>(i);
      // t = 1: y(s-1) joined to the camera, s - 1 in 1..D
      for (int sl = 2; sl <= S.nlight[ln]; ++sl) {
        const Vertex& y = S.light[static_cast<size_t>(sl - 1)][ln];
        const Vertex& ym = S.light[static_cast<size_t>(sl - 2)][ln];
        double rx, ry, vv[3], d2, density;
        if (!cam_.see(y.p, rx, ry, vv, d2, density)) continue;
        const double dist = std::sqrt(d2);
        const V3 w{static_cast<float>(vv[0] / dist), static_cast<float>(vv[1] / dist), static_cast<float>(vv[2] / dist)};
        const BsdfEval<float> fy = y.bsdf.eval(w);
        const V3 wo = y.bsdf.wo;
        const float k0 = importance_join(G, y, w);
        if (!(k0 > 0.f)) continue;
        const float imp = static_cast<float>(density / d2);
        Job job{};
        job.lane = i;
        job.s = sl;
        job.t = 1;
        job.rx = rx;
        job.ry = ry;
        job.c[0] = y.beta[0] * fy.f.r * k0 * imp;
        job.c[1] = y.beta[1] * fy.f.g * k0 * imp;
        job.c[2] = y.beta[2] * fy.f.b * k0 * imp;
        if (!nonzero3(job.c)) continue;
        const float yrev = static_cast<float>(density) * cos_geo(y, w) / static_cast<float>(d2);
        const float wgt =
            bdpt_mis(side(S.light, i, sl, y.fwd, yrev, area(viewed_from(y, w).eval(wo).pdf, y.p, ym), delta_light(i)),
                     side(S.cam, i, 1, 0.f, 0.f, 0.f, false));
        for (float& c : job.c) c *= wgt;
        job.med = ray_medium(y, w);
        if (shadow(job, y.p, y.ng, y.eps, eye, V3(0.f, 0.f, 0.f), 0.f)) push(job);
      }
      // s, t >= 2: y(s-1) joined to z(t-1)
      for (int t = 2; t <= S.ncam[ln]; ++t) {
        const Vertex& z = S.cam[static_cast<size_t>(t - 1)][ln];
        const Vertex& zm = S.cam[static_cast<size_t>(t - 2)][ln];
        for (int sl = 2; sl <= S.nlight[ln] && sl + t - 2 <= D; ++sl) {
          const Vertex& y = S.light[static_cast<size_t>(sl - 1)][ln];
          const Vertex& ym = S.light[static_cast<size_t>(sl - 2)][ln];
          const V3 e = y.p - z.p;
          const float d2 = dot(e, e);
          const float dist = std::sqrt(d2);
          if (!(dist > 0.f)) continue;
          const V3 w = e * (1.f / dist);  // from z to y
          const V3 mw = V3(0.f, 0.f, 0.f) - w;
          const BsdfEval<float> fz = z.bsdf.eval(w);
          if (!(fz.f.r > 0.f || fz.f.g > 0.f || fz.f.b > 0.f)) continue;
          const BsdfEval<float> fy = y.bsdf.eval(mw);
          if (!(fy.f.r > 0.f || fy.f.g > 0.f || fy.f.b > 0.f)) continue;
          const V3 wo = y.bsdf.wo;
          const float ky = importance_join(G, y, mw);
          if (!(ky > 0.f)) continue;
          const float g = ky * cos_shading(z, w) / d2;
          Job job{};
          job.lane = i;
          job.s = sl;
          job.t = t;
          job.c[0] = z.beta[0] * fz.f.r * y.beta[0] * fy.f.r * g;
          job.c[1] = z.beta[1] * fz.f.g * y.beta[1] * fy.f.g * g;
          job.c[2] = z.beta[2] * fz.f.b * y.beta[2] * fy.f.b * g;
          if (!nonzero3(job.c)) continue;
          const float zmrev = t > 2 ? area(viewed_from(z, w).eval(z.bsdf.wo).pdf, z.p, zm) : 0.f;
          const float wgt = bdpt_mis(side(S.light, i, sl, y.fwd, fz.pdf * cos_geo(y, w) / d2,
                                          area(viewed_from(y, mw).eval(wo).pdf, y.p, ym), delta_light(i)),
                                     side(S.cam, i, t, z.fwd, fy.pdf * cos_geo(z, w) / d2, zmrev, false));
          for (float& c : job.c) c *= wgt;
          job.med = ray_medium(z, w);
          if (shadow(job, z.p, z.ng, z.eps, y.p, y.ng, y.eps)) push(job);
        }
      }
    }
    // the joins' shadow rays, in whole packets; in a scene with media, through them and
    // their interfaces (the path tracer's shadow stages: the contributions times the
    // transmittance)
    const int cap = packet_width * static_cast<int>(std::size(tb.shadow));
    for (size_t j0 = 0; j0 < S.jobs.size(); j0 += static_cast<size_t>(cap)) {
      const int n = static_cast<int>(std::min(S.jobs.size() - j0, static_cast<size_t>(cap)));
      const int np = packet_padded(n);
      for (int k = 0; k < np; ++k) {
        tb.tech.valid[k] = k < n ? -1 : 0;
        if (k >= n) continue;
        const Job& jb = S.jobs[j0 + static_cast<size_t>(k)];
        Ray16& sh = tb.shadow[k / packet_width];
        const int ln = k % packet_width;
        sh.org_x[ln] = jb.org.x;
        sh.org_y[ln] = jb.org.y;
        sh.org_z[ln] = jb.org.z;
        sh.dir_x[ln] = jb.dir.x;
        sh.dir_y[ln] = jb.dir.y;
        sh.dir_z[ln] = jb.dir.z;
        sh.tfar[ln] = jb.tfar;
        tb.tech.cr[k] = jb.c[0];
        tb.tech.cg[k] = jb.c[1];
        tb.tech.cb[k] = jb.c[2];
        S.jmed[static_cast<size_t>(k)] = jb.med;
      }
      trace_shadow_lanes(G, ShadowLanes{tb.shadow, tb.tech.valid, tb.tech.cr, tb.tech.cg, tb.tech.cb, nullptr, nullptr, nullptr,
                                        S.jmed.data(), S.jmed.data()},
                         n, [&](const int32_t* valid, Ray16& sh, int32_t* crossed) { accel.occluded16(valid, sh, false, crossed); },
                         trace);
      for (int k = 0; k < n; ++k) {
        if (tb.shadow[k / packet_width].tfar[k % packet_width] == -INFINITY) continue;
        const Job& jb = S.jobs[j0 + static_cast<size_t>(k)];
        const float c[3] = {tb.tech.cr[k], tb.tech.cg[k], tb.tech.cb[k]};
        if (jb.t == 1) cam_.splat(jb.rx, jb.ry, c, out);
        else add_lane(jb.lane, c);
      }
    }
    for (int i = 0; i < lanes; ++i) {
      const size_t ln = static_cast<size_t>(i);
      if (S.sr[ln] == 0.f && S.sg[ln] == 0.f && S.sb[ln] == 0.f) continue;
      out.push_back({tb.lanes.pixel[i], S.sr[ln], S.sg[ln], S.sb[ln]});
    }
  }
}

}  // namespace tuile
