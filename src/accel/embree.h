// The only door to Embree: device, scene build, and the packet queries.
// Nothing else in tuile includes an Embree header.
#pragma once
#include <cstdint>
#include <memory>
#include <string>

#include "lanes/packet.h"
#include "scene/scene.h"

namespace tuile {

struct EmbreeOptions {
  bool robust = false;        // RTC_SCENE_FLAG_ROBUST: watertight traversal, at a cost in speed
  std::string device_config;  // e.g. "max_isa=avx2"
  int compact = -1;           // RTC_SCENE_FLAG_COMPACT: 1 on, 0 off, -1 for scenes of 2^23 triangles and more
};

// Which BVH a query runs against: the whole scene, or only its emissive meshes and
// spheres (the same geomIDs and primIDs; empty when the scene has no emitter).
enum class Bvh { scene, emitters };

class Accel {
 public:
  // Builds the BVH over every mesh, sphere and curve of the scene, and attaches the
  // emitters to a second scene (built by prepare_emitters). geomID == mesh index for
  // meshes, meshes.size() + i for sphere i, in both; then the curves (the scene alone).
  // Instanced objects (Scene::instances) are two levels: one BVH per object, placed by
  // Embree instances; a query's hit of an instance reports the shape's row as geomID, as
  // for any other shape, and the instance's index in instID[0] (invalid_id elsewhere).
  // Throws SceneError if Embree fails.
  Accel(const Scene& scene, const EmbreeOptions& options = {});
  ~Accel();
  Accel(const Accel&) = delete;
  Accel& operator=(const Accel&) = delete;

  // Builds the emitters' BVH (once; thread-safe). Queries with Bvh::emitters need it:
  // a render that traces against the whole scene never pays for it.
  void prepare_emitters() const;
  // valid[i] = -1 for active lanes, 0 for inactive (Embree's convention).
  void intersect16(const int32_t* valid, RayHit16& packet, bool coherent,
                   Bvh bvh = Bvh::scene) const noexcept;
  // crossed (16 lanes, or null): a surface rays pass between media (passes_between_media)
  // does not occlude; the query sets crossed[packet.id[i]] = 1 for a ray i that met one
  // (ids in 0..15, the caller's). Without it, such a surface occludes like any other.
  void occluded16(const int32_t* valid, Ray16& packet, bool coherent, int32_t* crossed = nullptr) const noexcept;
  void intersect1(RayHit16& packet, int lane) const noexcept;  // reference path for tests
  // The same rays through Embree's stream API (rtcIntersectNp / rtcOccludedNp on
  // pointer-SoA arrays of n rays): used only to measure packets against streams.
  struct StreamRays {
    float *org_x, *org_y, *org_z, *tnear, *dir_x, *dir_y, *dir_z, *time, *tfar;
    uint32_t *mask, *id, *flags;
    float *Ng_x, *Ng_y, *Ng_z, *u, *v;
    uint32_t *primID, *geomID, *instID;
  };
  void intersect_stream(StreamRays& rays, unsigned n, bool coherent, Bvh bvh = Bvh::scene) const noexcept;
  void occluded_stream(StreamRays& rays, unsigned n, bool coherent) const noexcept;
  double build_seconds() const { return build_seconds_; }
  // The scene's bounding box (Embree's rtcGetSceneBounds): lo[3], hi[3]
  void bounds(float* lo, float* hi) const noexcept;
  bool compact() const { return compact_; }  // the BVHs were built with RTC_SCENE_FLAG_COMPACT
  // Embree's own allocations (its BVHs; at peak, its builds' transient data too), in bytes
  struct Memory {
    int64_t now = 0, peak = 0;
  };
  Memory embree_memory() const;

 public:
  struct Impl;  // opaque (public so Embree's C callbacks can name it)

 private:
  std::unique_ptr<Impl> impl_;
  double build_seconds_ = 0;
  bool compact_ = false;
};

}  // namespace tuile
