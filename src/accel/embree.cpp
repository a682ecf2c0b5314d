// The Embree door: device and scene build (the whole scene, and the emitters alone), and
// the packet and stream queries in Embree's own layouts.
#include "accel/embree.h"

#include <embree3/rtcore.h>

#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <algorithm>
#include <atomic>
#include <mutex>
#include <vector>

#include <xsimd/xsimd.hpp>

#include "wave/alpha.h"

namespace tuile {

static_assert(sizeof(Ray16) == sizeof(RTCRay16));
static_assert(sizeof(RayHit16) == sizeof(RTCRayHit16));
static_assert(offsetof(RayHit16, Ng_x) == offsetof(RTCRayHit16, hit.Ng_x));
static_assert(offsetof(RayHit16, geomID) == offsetof(RTCRayHit16, hit.geomID));
static_assert(offsetof(Ray16, tfar) == offsetof(RTCRay16, tfar));
static_assert(offsetof(Ray16, flags) == offsetof(RTCRay16, flags));

struct Accel::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  RTCScene emitters = nullptr;  // geometry attached at construction, built by prepare_emitters
  std::once_flag emitters_built;
  std::string error;
  std::vector<AlphaShape> alpha;  // the shapes with an alpha, each geometry's user data (reserved: stable)
  std::vector<struct SphereShape> spheres;  // each sphere's user data (reserved: stable)
  std::vector<RTCScene> objects;  // one BVH per instanced object (the second level)
  // Instances: Embree reports an instance's hits with the geometry's ID in its object's
  // scene and the instance geometry's ID (inst_base + i) in instID; fix_instances turns
  // them into the scene's row (rows[inst_row0[i] + local ID]) and the instance's index i.
  uint32_t inst_base = 0;
  std::vector<uint32_t> rows, inst_row0;
  // Embree's own memory (its device's allocations: BVHs, and the builds' transient data)
  std::atomic<int64_t> bytes{0}, peak{0};
  RTCScene of(Bvh t) const { return t == Bvh::emitters ? emitters : scene; }
  void fix_instances(const int32_t* valid, RayHit16& p) const noexcept {
    for (int k = 0; k < packet_width; ++k) {
      if ((valid && valid[k] != -1) || p.geomID[k] == invalid_id || p.instID[0][k] == invalid_id) continue;
      const uint32_t i = p.instID[0][k] - inst_base;
      p.geomID[k] = rows[inst_row0[i] + p.geomID[k]];
      p.instID[0][k] = i;
    }
  }
  static void clear_instances(const int32_t* valid, RayHit16& p) noexcept {
    for (int k = 0; k < packet_width; ++k)
      if (!valid || valid[k] == -1) p.instID[0][k] = invalid_id;
  }
};

static bool memory_callback(void* user, ssize_t bytes, bool) {
  auto* impl = static_cast<Accel::Impl*>(user);
  const int64_t now = impl->bytes += bytes;
  int64_t p = impl->peak.load();
  while (now > p && !impl->peak.compare_exchange_weak(p, now)) {
  }
  return true;
}

static void error_callback(void* user, RTCError code, const char* str) {
  auto* impl = static_cast<Accel::Impl*>(user);
  if (impl->error.empty()) impl->error = "Embree error " + std::to_string(static_cast<int>(code)) + ": " + (str ? str : "");
}

// Embree's intersection filter of a shape with an alpha (wave/alpha.h): a candidate hit the
// alpha test rejects is invalidated, and traversal goes on behind it. Every query calls it
// (packets, single rays, streams; the scene and the emitters' BVH; nearest hits and
// occlusion), so camera, shadow and bounce rays all see the same cutouts.
static void alpha_filter(const RTCFilterFunctionNArguments* args) {
  const auto* shape = static_cast<const AlphaShape*>(args->geometryUserPtr);
  const unsigned n = args->N;
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] != -1) continue;
    const float ray[6] = {RTCRayN_org_x(args->ray, n, i), RTCRayN_org_y(args->ray, n, i), RTCRayN_org_z(args->ray, n, i),
                          RTCRayN_dir_x(args->ray, n, i), RTCRayN_dir_y(args->ray, n, i), RTCRayN_dir_z(args->ray, n, i)};
    const uint32_t prim = RTCHitN_primID(args->hit, n, i), geom = RTCHitN_geomID(args->hit, n, i);
    const float a = alpha_at(*shape, prim, RTCHitN_u(args->hit, n, i), RTCHitN_v(args->hit, n, i));
    if (!alpha_keeps(a, ray, geom, prim)) args->valid[i] = 0;
  }
}

static void attach_alpha(RTCGeometry g, const AlphaShape* shape) {
  rtcSetGeometryUserData(g, const_cast<AlphaShape*>(shape));
  rtcSetGeometryIntersectFilterFunction(g, alpha_filter);
  rtcSetGeometryOccludedFilterFunction(g, alpha_filter);
}

// Every occlusion query's context: crossed, when the query asks, gets a lane's mark (by
// the ray's id) where the ray met a surface rays pass between media (passes_between_media).
struct OcclusionContext {
  RTCIntersectContext ctx;
  int32_t* crossed = nullptr;
};

static OcclusionContext occlusion_context(bool coherent, int32_t* crossed) {
  OcclusionContext oc;
  rtcInitIntersectContext(&oc.ctx);
  oc.ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  oc.crossed = crossed;
  return oc;
}

// The occlusion filter of a surface rays pass between media: past its alpha test (a hole
// is no crossing), a query that asks records the crossing and goes on behind it, so its
// answer is whether any other surface occludes; a query that does not ask is occluded
// here, as by any surface.
static void interface_occluded_filter(const RTCFilterFunctionNArguments* args) {
  if (args->geometryUserPtr) alpha_filter(args);
  const auto* oc = reinterpret_cast<const OcclusionContext*>(args->context);
  if (!oc->crossed) return;
  const unsigned n = args->N;
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] != -1) continue;
    oc->crossed[RTCRayN_id(args->ray, n, i)] = 1;
    args->valid[i] = 0;
  }
}

// A sphere as Embree user geometry: its own ray test, in double per ray. Embree's
// SPHERE_POINT primitives intersect packets one ray at a time through its curve machinery,
// which made every ray of a scene with one sphere several times slower (bench/results.md,
// "Spheres as user geometry"). filtered: the shape has an alpha or rays pass it between
// media, so a candidate hit goes through the geometry's filter functions (with the alpha's
// AlphaShape as their user data, as for the other shapes).
struct SphereShape {
  double cx = 0, cy = 0, cz = 0, r = 0;
  const AlphaShape* alpha = nullptr;
  bool filtered = false;
};

static void sphere_bounds(const RTCBoundsFunctionArguments* args) {
  const auto* s = static_cast<const SphereShape*>(args->geometryUserPtr);
  const float c[3] = {static_cast<float>(s->cx), static_cast<float>(s->cy), static_cast<float>(s->cz)};
  const float r = static_cast<float>(s->r);
  // widened by a float step each way: the bounds in float, the test in double
  args->bounds_o->lower_x = std::nextafter(c[0] - r, -INFINITY);
  args->bounds_o->lower_y = std::nextafter(c[1] - r, -INFINITY);
  args->bounds_o->lower_z = std::nextafter(c[2] - r, -INFINITY);
  args->bounds_o->upper_x = std::nextafter(c[0] + r, INFINITY);
  args->bounds_o->upper_y = std::nextafter(c[1] + r, INFINITY);
  args->bounds_o->upper_z = std::nextafter(c[2] + r, INFINITY);
}

// The nearest t in (tnear, tfar] where the ray o + t d meets the sphere, or -1: the
// roots in the form of Haines et al. ("Precision Improvements for Ray/Sphere
// Intersection", Ray Tracing Gems 2019), the discriminant from the distance of the line to
// the centre, so that neither a far sphere nor a ray leaving its surface loses the root.
static double sphere_hit(const SphereShape& s, const double o[3], const double d[3], double tnear, double tfar) {
  const double f[3] = {o[0] - s.cx, o[1] - s.cy, o[2] - s.cz};
  const double a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  if (!(a > 0)) return -1;
  const double b = -(f[0] * d[0] + f[1] * d[1] + f[2] * d[2]);  // -b / 2 of the usual form
  const double l[3] = {f[0] + b / a * d[0], f[1] + b / a * d[1], f[2] + b / a * d[2]};
  const double disc = a * (s.r * s.r - (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]));
  if (!(disc >= 0)) return -1;
  const double c = f[0] * f[0] + f[1] * f[1] + f[2] * f[2] - s.r * s.r;
  const double q = b + std::copysign(std::sqrt(disc), b);
  double t0 = q / a, t1 = q != 0 ? c / q : t0;
  if (t0 > t1) std::swap(t0, t1);
  if (t0 > tnear && t0 <= tfar) return t0;
  if (t1 > tnear && t1 <= tfar) return t1;
  return -1;
}

// sphere_hit for the rays [i0, i0 + W) of an N-wide packet (W doubles a SIMD register),
// into t (-1: none): the same operations in the same order, so the same bits per ray.
using vdouble = xsimd::batch<double>;
static void sphere_hits_simd(const SphereShape& s, RTCRayN* ray, unsigned n, unsigned i0, double* t) {
  constexpr unsigned W = vdouble::size;
  alignas(64) double v[8][W];
  for (unsigned k = 0; k < W; ++k) {
    const unsigned i = i0 + k;
    v[0][k] = RTCRayN_org_x(ray, n, i), v[1][k] = RTCRayN_org_y(ray, n, i), v[2][k] = RTCRayN_org_z(ray, n, i);
    v[3][k] = RTCRayN_dir_x(ray, n, i), v[4][k] = RTCRayN_dir_y(ray, n, i), v[5][k] = RTCRayN_dir_z(ray, n, i);
    v[6][k] = RTCRayN_tnear(ray, n, i), v[7][k] = RTCRayN_tfar(ray, n, i);
  }
  const vdouble d[3] = {vdouble::load_aligned(v[3]), vdouble::load_aligned(v[4]), vdouble::load_aligned(v[5])};
  const vdouble f[3] = {vdouble::load_aligned(v[0]) - vdouble(s.cx), vdouble::load_aligned(v[1]) - vdouble(s.cy),
                        vdouble::load_aligned(v[2]) - vdouble(s.cz)};
  const vdouble a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  const vdouble b = -(f[0] * d[0] + f[1] * d[1] + f[2] * d[2]);
  const vdouble l[3] = {f[0] + b / a * d[0], f[1] + b / a * d[1], f[2] + b / a * d[2]};
  const vdouble disc = a * (vdouble(s.r * s.r) - (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]));
  const vdouble c = f[0] * f[0] + f[1] * f[1] + f[2] * f[2] - vdouble(s.r * s.r);
  const vdouble q = b + xsimd::copysign(xsimd::sqrt(disc), b);
  const vdouble t0 = q / a, t1 = xsimd::select(q != vdouble(0.), c / q, t0);
  const vdouble lo = xsimd::select(t0 > t1, t1, t0), hi = xsimd::select(t0 > t1, t0, t1);
  const vdouble tn = vdouble::load_aligned(v[6]), tf = vdouble::load_aligned(v[7]);
  vdouble r = xsimd::select((hi > tn) && (hi <= tf), hi, vdouble(-1.));
  r = xsimd::select((lo > tn) && (lo <= tf), lo, r);
  r = xsimd::select((a > vdouble(0.)) && (disc >= vdouble(0.)), r, vdouble(-1.));
  r.store_unaligned(t);
}

// The nearest hit of each valid ray of an N-wide packet, in td (-1: none): in SIMD where
// a register's rays hold two valid ones or more (Embree also calls with a single valid ray
// of a packet, when it traverses the packet's rays one at a time), else one ray at a time.
static void sphere_hits(const SphereShape& s, const int* valid, RTCRayN* ray, unsigned n, double* td) {
  constexpr unsigned W = vdouble::size;
  const auto one = [&](unsigned i) {
    const double o[3] = {RTCRayN_org_x(ray, n, i), RTCRayN_org_y(ray, n, i), RTCRayN_org_z(ray, n, i)};
    const double d[3] = {RTCRayN_dir_x(ray, n, i), RTCRayN_dir_y(ray, n, i), RTCRayN_dir_z(ray, n, i)};
    td[i] = sphere_hit(s, o, d, RTCRayN_tnear(ray, n, i), RTCRayN_tfar(ray, n, i));
  };
  for (unsigned i0 = 0; i0 < n; i0 += W) {
    unsigned live = 0;
    for (unsigned k = i0; k < i0 + W && k < n; ++k) live += valid[k] == -1;
    if (live >= 2 && i0 + W <= n) {
      sphere_hits_simd(s, ray, n, i0, td + i0);
      continue;
    }
    for (unsigned k = i0; k < i0 + W && k < n; ++k) {
      td[k] = -1;
      if (valid[k] == -1) one(k);
    }
  }
}

// Ray i of an N-wide packet, met by the sphere at td (t in float): the hit (Ng from the
// centre to the point, u = v = 0) and the ray as one ray ending there, as the filter
// functions see a candidate (its id kept for the media's marks).
struct SphereCandidate {
  RTCRay ray;
  RTCHit hit;
};
static SphereCandidate sphere_candidate(const SphereShape& s, RTCRayN* ray, unsigned n, unsigned i, double td, float t,
                                        unsigned primID, unsigned geomID, const RTCIntersectContext* context) {
  SphereCandidate c;
  RTCRay& r = c.ray;
  r.org_x = RTCRayN_org_x(ray, n, i), r.org_y = RTCRayN_org_y(ray, n, i), r.org_z = RTCRayN_org_z(ray, n, i);
  r.dir_x = RTCRayN_dir_x(ray, n, i), r.dir_y = RTCRayN_dir_y(ray, n, i), r.dir_z = RTCRayN_dir_z(ray, n, i);
  r.tnear = RTCRayN_tnear(ray, n, i), r.tfar = t, r.time = 0, r.mask = RTCRayN_mask(ray, n, i);
  r.id = RTCRayN_id(ray, n, i), r.flags = 0;
  RTCHit& h = c.hit;
  h.Ng_x = static_cast<float>(static_cast<double>(r.org_x) + td * r.dir_x - s.cx);
  h.Ng_y = static_cast<float>(static_cast<double>(r.org_y) + td * r.dir_y - s.cy);
  h.Ng_z = static_cast<float>(static_cast<double>(r.org_z) + td * r.dir_z - s.cz);
  h.u = h.v = 0.f;
  h.primID = primID;
  h.geomID = geomID;
  h.instID[0] = context->instID[0];
  return c;
}

// The filter functions' verdict on a candidate (for a sphere with an alpha, or one rays
// pass between media); Filter is rtcFilterIntersection or rtcFilterOcclusion.
template <class Args, class Filter>
static bool sphere_filter_keeps(const SphereShape& s, const Args* args, SphereCandidate& c, Filter filter) {
  if (!s.filtered) return true;
  int keep = -1;
  RTCFilterFunctionNArguments fa{&keep, const_cast<AlphaShape*>(s.alpha), args->context, reinterpret_cast<RTCRayN*>(&c.ray),
                                 reinterpret_cast<RTCHitN*>(&c.hit), 1};
  filter(args, &fa);
  return keep == -1;
}

// Both sphere callbacks: each valid ray of the packet whose nearest root lies within its
// tfar, as f(i, td, t) (the root in double, and as the float Embree stores).
template <class Args, class F> static void for_each_sphere_root(const SphereShape& s, const Args* args, RTCRayN* ray, F&& f) {
  const unsigned n = args->N;
  double td[16];
  if (n > 16) return;  // (Embree's widest packet is 16)
  sphere_hits(s, args->valid, ray, n, td);
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] != -1 || td[i] < 0) continue;
    const float t = static_cast<float>(td[i]);
    if (t <= RTCRayN_tfar(ray, n, i)) f(i, td[i], t);
  }
}

static void sphere_intersect(const RTCIntersectFunctionNArguments* args) {
  const auto* s = static_cast<const SphereShape*>(args->geometryUserPtr);
  const unsigned n = args->N;
  RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, n);
  RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, n);
  for_each_sphere_root(*s, args, ray, [&](unsigned i, double td, float t) {
    SphereCandidate c = sphere_candidate(*s, ray, n, i, td, t, args->primID, args->geomID, args->context);
    if (!sphere_filter_keeps(*s, args, c, rtcFilterIntersection)) return;
    RTCRayN_tfar(ray, n, i) = t;
    RTCHitN_Ng_x(hit, n, i) = c.hit.Ng_x;
    RTCHitN_Ng_y(hit, n, i) = c.hit.Ng_y;
    RTCHitN_Ng_z(hit, n, i) = c.hit.Ng_z;
    RTCHitN_u(hit, n, i) = 0.f;
    RTCHitN_v(hit, n, i) = 0.f;
    RTCHitN_primID(hit, n, i) = c.hit.primID;
    RTCHitN_geomID(hit, n, i) = c.hit.geomID;
    RTCHitN_instID(hit, n, i, 0) = c.hit.instID[0];
  });
}

static void sphere_occluded(const RTCOccludedFunctionNArguments* args) {
  const auto* s = static_cast<const SphereShape*>(args->geometryUserPtr);
  const unsigned n = args->N;
  RTCRayN* ray = args->ray;
  for_each_sphere_root(*s, args, ray, [&](unsigned i, double td, float t) {
    if (s->filtered) {
      SphereCandidate c = sphere_candidate(*s, ray, n, i, td, t, args->primID, args->geomID, args->context);
      if (!sphere_filter_keeps(*s, args, c, rtcFilterOcclusion)) return;
    }
    RTCRayN_tfar(ray, n, i) = -INFINITY;
  });
}

Accel::Accel(const Scene& scene, const EmbreeOptions& options) : impl_(std::make_unique<Impl>()) {
  const auto t0 = std::chrono::steady_clock::now();
  impl_->device = rtcNewDevice(options.device_config.empty() ? nullptr : options.device_config.c_str());
  if (!impl_->device) throw SceneError("Embree: cannot create a device (config '" + options.device_config + "')");
  rtcSetDeviceErrorFunction(impl_->device, error_callback, impl_.get());
  rtcSetDeviceMemoryMonitorFunction(impl_->device, memory_callback, impl_.get());
  impl_->scene = rtcNewScene(impl_->device);
  impl_->emitters = rtcNewScene(impl_->device);
  // Large scenes (2^23 stored triangles and more) build compact BVHs: leaves that index the
  // scene's shared vertex buffers instead of copying the triangles, 29 bytes per triangle
  // less and a faster build (16 M triangles: 1603 against 2071 MiB at peak, BVH 3.0 against
  // 4.5 s), for ~30% fewer samples per second (bench/results.md, "Large scenes").
  const bool compact = options.compact == 1 || (options.compact < 0 && scene.triangle_count() >= (size_t(1) << 23));
  compact_ = compact;
  for (RTCScene sc : {impl_->scene, impl_->emitters}) {
    rtcSetSceneFlags(sc, RTCSceneFlags((options.robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE) | (compact ? RTC_SCENE_FLAG_COMPACT : 0)));
    rtcSetSceneBuildQuality(sc, RTC_BUILD_QUALITY_MEDIUM);
  }

  // Each emitter is a second geometry object on the same shared buffers, attached to the
  // emitters' scene under the same ID.
  impl_->alpha.reserve(scene.meshes.size() + scene.spheres.size());
  impl_->spheres.reserve(scene.spheres.size());
  // Instanced objects' shapes go to their object's scene under local IDs 0, 1, ... (rows
  // maps them back to the scene's rows); every other shape to the scene under its row.
  for (size_t o = 0; o < scene.objects.size(); ++o) {
    impl_->objects.push_back(rtcNewScene(impl_->device));
    rtcSetSceneFlags(impl_->objects.back(), RTCSceneFlags((options.robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE) |
                                                          (compact ? RTC_SCENE_FLAG_COMPACT : 0)));
    rtcSetSceneBuildQuality(impl_->objects.back(), RTC_BUILD_QUALITY_MEDIUM);
  }
  std::vector<std::vector<uint32_t>> object_rows(scene.objects.size());
  const auto attach = [&](RTCScene sc, RTCGeometry g, unsigned row, int object) {
    if (sc == impl_->scene && object >= 0) {
      auto& r = object_rows[static_cast<size_t>(object)];
      rtcAttachGeometryByID(impl_->objects[static_cast<size_t>(object)], g, static_cast<unsigned>(r.size()));
      r.push_back(row);
    } else {
      rtcAttachGeometryByID(sc, g, row);
    }
  };
  unsigned id = 0;
  for (const Mesh& m : scene.meshes) {
    const AlphaShape* alpha = nullptr;
    if (m.has_alpha()) {
      impl_->alpha.push_back(alpha_shape(scene, m));
      alpha = &impl_->alpha.back();
    }
    for (RTCScene sc : {impl_->scene, impl_->emitters}) {
      if (sc == impl_->emitters && !m.emissive()) continue;
      RTCGeometry g = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
      const size_t nv = m.positions.size() / 3, nt = m.triangle_count();
      // Shared buffers: Embree reads the scene's own arrays (it may read 4 bytes past the
      // last vertex; finalize_scene pads positions for that), no copy.
      rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m.positions.data(), 0,
                                 3 * sizeof(float), nv);
      rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, m.indices.data(), 0,
                                 3 * sizeof(uint32_t), nt);
      if (alpha) attach_alpha(g, alpha);
      if (passes_between_media(scene, m.material, m.medium_inside, m.medium_outside, m.emissive())) {
        rtcSetGeometryUserData(g, const_cast<AlphaShape*>(alpha));
        rtcSetGeometryOccludedFilterFunction(g, interface_occluded_filter);
      }
      rtcCommitGeometry(g);
      attach(sc, g, id, m.object);
      rtcReleaseGeometry(g);
    }
    ++id;
  }
  for (const Sphere& s : scene.spheres) {
    const bool emissive = s.emissive();
    const AlphaShape* alpha = nullptr;
    if (s.alpha < 1) {
      AlphaShape a;
      a.value = s.alpha;
      impl_->alpha.push_back(a);
      alpha = &impl_->alpha.back();
    }
    const bool passes = passes_between_media(scene, s.material, s.medium_inside, s.medium_outside, emissive);
    SphereShape shape;
    shape.cx = s.center.x, shape.cy = s.center.y, shape.cz = s.center.z, shape.r = s.radius;
    shape.alpha = alpha;
    shape.filtered = alpha || passes;
    impl_->spheres.push_back(shape);
    const SphereShape* user = &impl_->spheres.back();
    for (RTCScene sc : {impl_->scene, impl_->emitters}) {
      if (sc == impl_->emitters && !emissive) continue;
      RTCGeometry g = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_USER);
      rtcSetGeometryUserPrimitiveCount(g, 1);
      rtcSetGeometryUserData(g, const_cast<SphereShape*>(user));
      rtcSetGeometryBoundsFunction(g, sphere_bounds, const_cast<SphereShape*>(user));
      rtcSetGeometryIntersectFunction(g, sphere_intersect);
      rtcSetGeometryOccludedFunction(g, sphere_occluded);
      if (alpha) {
        rtcSetGeometryIntersectFilterFunction(g, alpha_filter);
        rtcSetGeometryOccludedFilterFunction(g, alpha_filter);
      }
      if (passes) rtcSetGeometryOccludedFilterFunction(g, interface_occluded_filter);
      rtcCommitGeometry(g);
      attach(sc, g, id, s.object);
      rtcReleaseGeometry(g);
    }
    ++id;
  }
  // Curves (pbrt-v4's "curve"): cubic Bezier segments of 4 control points each (x y z r,
  // the scene's own buffer), in the scene's BVH alone (they never emit).
  for (const Curves& c : scene.curves) {
    const RTCGeometryType type = c.type == CurveType::flat     ? RTC_GEOMETRY_TYPE_FLAT_BEZIER_CURVE
                                 : c.type == CurveType::ribbon ? RTC_GEOMETRY_TYPE_NORMAL_ORIENTED_BEZIER_CURVE
                                                               : RTC_GEOMETRY_TYPE_ROUND_BEZIER_CURVE;
    RTCGeometry g = rtcNewGeometry(impl_->device, type);
    const size_t ns = c.segment_count();
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, c.points.data(), 0, 4 * sizeof(float),
                               4 * ns);
    if (c.type == CurveType::ribbon)
      rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_NORMAL, 0, RTC_FORMAT_FLOAT3, c.normals.data(), 0, 3 * sizeof(float),
                                 4 * ns);
    auto* first = static_cast<uint32_t*>(
        rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT, sizeof(uint32_t), ns));
    for (size_t s = 0; s < ns; ++s) first[s] = static_cast<uint32_t>(4 * s);
    if (passes_between_media(scene, c.material, c.medium_inside, c.medium_outside, false))
      rtcSetGeometryOccludedFilterFunction(g, interface_occluded_filter);
    rtcCommitGeometry(g);
    attach(impl_->scene, g, id, c.object);
    rtcReleaseGeometry(g);
    ++id;
  }
  // The objects' BVHs, then their instances in the scene under IDs after every row.
  for (RTCScene o : impl_->objects) rtcCommitScene(o);
  impl_->inst_base = id;
  for (const auto& r : object_rows) {
    impl_->inst_row0.push_back(static_cast<uint32_t>(impl_->rows.size()));
    impl_->rows.insert(impl_->rows.end(), r.begin(), r.end());
  }
  std::vector<uint32_t> object_row0 = std::move(impl_->inst_row0);
  impl_->inst_row0.clear();
  impl_->inst_row0.reserve(scene.instances.size());
  for (const Instance& in : scene.instances) {
    RTCGeometry g = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(g, impl_->objects[static_cast<size_t>(in.object)]);
    rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, &in.world_from_object[0][0]);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(impl_->scene, g, id++);
    rtcReleaseGeometry(g);
    impl_->inst_row0.push_back(object_row0[static_cast<size_t>(in.object)]);
  }
  rtcCommitScene(impl_->scene);
  if (!impl_->error.empty()) throw SceneError(impl_->error);
  build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void Accel::prepare_emitters() const {
  std::call_once(impl_->emitters_built, [this] {
    rtcCommitScene(impl_->emitters);
    if (!impl_->error.empty()) throw SceneError(impl_->error);
  });
}

Accel::Memory Accel::embree_memory() const { return {impl_->bytes.load(), impl_->peak.load()}; }

Accel::~Accel() {
  if (impl_->scene) rtcReleaseScene(impl_->scene);
  for (RTCScene o : impl_->objects) rtcReleaseScene(o);
  if (impl_->emitters) rtcReleaseScene(impl_->emitters);
  if (impl_->device) rtcReleaseDevice(impl_->device);
}

void Accel::intersect16(const int32_t* valid, RayHit16& packet, bool coherent, Bvh bvh) const noexcept {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  const bool inst = !impl_->inst_row0.empty() && bvh == Bvh::scene;
  if (inst) Impl::clear_instances(valid, packet);
  rtcIntersect16(valid, impl_->of(bvh), &ctx, reinterpret_cast<RTCRayHit16*>(&packet));
  if (inst) impl_->fix_instances(valid, packet);
}

void Accel::occluded16(const int32_t* valid, Ray16& packet, bool coherent, int32_t* crossed) const noexcept {
  OcclusionContext oc = occlusion_context(coherent, crossed);
  rtcOccluded16(valid, impl_->scene, &oc.ctx, reinterpret_cast<RTCRay16*>(&packet));
}

static RTCRayHitNp to_np(Accel::StreamRays& r) {
  RTCRayHitNp np;
  np.ray = {r.org_x, r.org_y, r.org_z, r.tnear, r.dir_x, r.dir_y, r.dir_z, r.time, r.tfar, r.mask, r.id, r.flags};
  np.hit.Ng_x = r.Ng_x;
  np.hit.Ng_y = r.Ng_y;
  np.hit.Ng_z = r.Ng_z;
  np.hit.u = r.u;
  np.hit.v = r.v;
  np.hit.primID = r.primID;
  np.hit.geomID = r.geomID;
  np.hit.instID[0] = r.instID;
  return np;
}

void Accel::intersect_stream(StreamRays& r, unsigned n, bool coherent, Bvh bvh) const noexcept {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  RTCRayHitNp np = to_np(r);
  const bool inst = !impl_->inst_row0.empty() && bvh == Bvh::scene;
  if (inst) std::fill_n(r.instID, n, RTC_INVALID_GEOMETRY_ID);
  rtcIntersectNp(impl_->of(bvh), &ctx, &np, n);
  if (inst)
    for (unsigned j = 0; j < n; ++j)
      if (r.geomID[j] != RTC_INVALID_GEOMETRY_ID && r.instID[j] != RTC_INVALID_GEOMETRY_ID) {
        r.instID[j] -= impl_->inst_base;
        r.geomID[j] = impl_->rows[impl_->inst_row0[r.instID[j]] + r.geomID[j]];
      }
}

void Accel::occluded_stream(StreamRays& r, unsigned n, bool coherent) const noexcept {
  OcclusionContext oc = occlusion_context(coherent, nullptr);
  RTCRayHitNp np = to_np(r);
  rtcOccludedNp(impl_->scene, &oc.ctx, &np.ray, n);
}

void Accel::intersect1(RayHit16& p, int i) const noexcept {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  rh.ray.org_x = p.ray.org_x[i];
  rh.ray.org_y = p.ray.org_y[i];
  rh.ray.org_z = p.ray.org_z[i];
  rh.ray.tnear = p.ray.tnear[i];
  rh.ray.dir_x = p.ray.dir_x[i];
  rh.ray.dir_y = p.ray.dir_y[i];
  rh.ray.dir_z = p.ray.dir_z[i];
  rh.ray.time = 0;
  rh.ray.tfar = p.ray.tfar[i];
  rh.ray.mask = p.ray.mask[i];
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx, &rh);
  if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID && rh.hit.instID[0] != RTC_INVALID_GEOMETRY_ID) {
    const uint32_t k = rh.hit.instID[0] - impl_->inst_base;
    rh.hit.geomID = impl_->rows[impl_->inst_row0[k] + rh.hit.geomID];
    rh.hit.instID[0] = k;
  }
  p.instID[0][i] = rh.hit.instID[0];
  p.ray.tfar[i] = rh.ray.tfar;
  p.geomID[i] = rh.hit.geomID;
  p.primID[i] = rh.hit.primID;
  p.Ng_x[i] = rh.hit.Ng_x;
  p.Ng_y[i] = rh.hit.Ng_y;
  p.Ng_z[i] = rh.hit.Ng_z;
  p.u[i] = rh.hit.u;
  p.v[i] = rh.hit.v;
}

void Accel::bounds(float* lo, float* hi) const noexcept {
  RTCBounds b;
  rtcGetSceneBounds(impl_->scene, &b);
  lo[0] = b.lower_x, lo[1] = b.lower_y, lo[2] = b.lower_z;
  hi[0] = b.upper_x, hi[1] = b.upper_y, hi[2] = b.upper_z;
}

}  // namespace tuile
