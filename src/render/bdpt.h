// Bidirectional path tracing (--bdpt, Estimator::bdpt): Veach's estimator, as pbrt-v4's
// `bdpt` integrator defines it, over the path tracer's surfaces and BSDFs.
//
// Per pixel and sample, a camera subpath z0 (the pinhole), z1, ... and a light subpath y0
// (a point on an area source), y1, ... are traced, each vertex's direction sampled by its
// BSDF (the light subpath's with the adjoint's weights, as the light tracer of
// light_paths.h: Veach's shading-normal factor and no 1 / eta^2 on transmissions), Russian
// roulette as the path tracer plays it. Every pair of a light prefix y0..y(s-1) and a camera
// prefix z0..z(t-1) with s + t - 2 <= the depth is a strategy for the path of s + t
// vertices they make:
// - s = 0: the camera subpath met an emitter (its front, or either side of a two-sided one);
// - s = 1: a point sampled on a source (picked by power, uniform in area; a point or spot
//   source's position) joined to z(t-1);
// - t = 1: y(s-1) joined to the camera, splatted where it is seen (pbrt-v4's light tracer);
// - s, t >= 2: y(s-1) joined to z(t-1) by a shadow ray.
// (s = 1, t = 1, a point on a source joined to the camera, is left out, as pbrt-v4 does;
// s = 0, t = 2 has weight 1.) Each is weighted by the balance heuristic over the strategies
// that could have made its path (pbrt-v4's MISWeight: the ratios of each vertex's reverse
// and forward densities in area measure, walked from the joined vertices outwards, delta
// lobes and zero densities skipped as pbrt's remap0), so that the weights of a path sum to
// one and the estimator is unbiased. The densities: a source is picked by power and a point
// on it uniform in area, its direction cosine-weighted (half of that on each side of a
// two-sided source); a point source's direction uniform on the sphere, a spot's uniform in
// its cone (its falloff in the weight), both delta lights (y0 on no surface: no strategy
// meets them from the camera's side); the camera's as Pinhole::ray_density. A vertex's reverse density is its
// neighbour's BSDF density with the viewer and the sampled direction exchanged.
//
// Sources at infinity (pbrt-v4's infinite and distant lights in its bdpt): a light subpath
// from one starts on the disc of the scene's bounding sphere (radius R) facing its
// direction, uniform on it (density 1 / (pi R^2) per unit area of the disc, so the next
// vertex's density is that times its cosine, without 1 / d^2), its direction drawn from the
// sky's map (or a distant source's one direction). The vertex at infinity's densities are
// per unit solid angle: forward, the density with which the light side draws that direction
// (the pick times the map's density, summed over the skies); reverse, the BSDF's. A camera
// subpath that escapes the scene meets every sky along its ray (s = 0); s = 1 draws a
// direction from the picked sky, or takes the distant source's, and traces a shadow ray to
// infinity. A distant source is a delta light (no strategy meets it from the camera's side).
//
// Media (homogeneous, pbrt-v4's bdpt's way): every ray of either subpath takes the path
// tracer's free flight (medium_flights: its weight joins the throughput, interfaces are
// passed), from the medium it starts in (the camera's, a source's by source_media, a
// vertex's on the ray's side). A collision is a vertex whose BSDF is the medium's phase
// function and whose normals are zero, so its joins and its densities per unit area have no
// cosine (cos_geo, cos_shading); the joins' shadow rays carry the transmittance through
// the media and their interfaces (trace_shadow_lanes). The weights' densities leave out
// the distance sampling's, as pbrt-v4's do: the weights of a path still sum to one. The
// media's emission is gathered along the camera subpath's rays from its first D vertices
// (the path tracer's segments), weight 1: no other strategy meets it.
//
// What it renders: surfaces of every material the path tracer knows but hair, in vacuum or
// homogeneous media, lit by area sources (triangles, parallelograms, spheres), point, spot
// and distant sources and skies (constant or with a map); an emitter with an alpha cut-out
// emits its alpha times its radiance where a point is drawn on it (as the path tracer's
// light samples weigh it), and the rays that meet it pass its holes. It refuses
// (std::invalid_argument) curves: pbrt-v4's hair BSDF is not reciprocal (its offset h
// belongs to the ray that arrived, which on a light subpath is the light's), and under a
// white sky a furnace of fibers, which the path tracer renders at exactly 1, came out 1.04
// through bdpt's light subpaths; and a source at infinity with the camera in a medium (its
// light subpaths would start on the disc in vacuum, where the escaped rays end in that
// medium).
//
// Determinism: as the light tracer's splats (the renderer adds a tile's splats in tile
// order), each lane's camera-side contributions summed in strategy order into one splat per
// pixel and sample, so the image depends on neither threads nor tile order, and over MPI its
// sample ranges are units of their own (Renderer::render_light_chunk).
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "accel/embree.h"
#include "render/pinhole.h"
#include "render/views.h"
#include "wave/estimator.h"
#include "wave/tile.h"

namespace tuile {

struct Scene;
struct BdptPool;  // the threads' scratch (bdpt.cpp)

// Why bdpt does not render this scene ("" where it does): curves, or a source at infinity
// with the camera in a medium.
std::string bdpt_refusal(const Scene& scene);

class Bdpt {
 public:
  // Throws std::invalid_argument naming what the scene has that bdpt does not render. lo, hi:
  // the scene's bounds (the sources at infinity emit through its bounding sphere's disc).
  Bdpt(const Scene& scene, const SceneViews& v, const Estimator& est, int width, int height, const float* lo,
       const float* hi);
  ~Bdpt();
  // The paths of the pixels of tile `tile` for samples [begin, end): every contribution
  // appended to out (the camera side's one per pixel and sample, the light tracer's where
  // they land); rejected counts contributions that were not finite.
  void trace_tile(const Accel& accel, TileBuffers& tb, int tile, int tile_size, int tiles_x, uint32_t begin, uint32_t end,
                  std::vector<LightPathSplat>& out, uint64_t& rejected) const;
  // What its light subpaths start from, for `tuile info`: the sources picked (by power, for
  // the light subpaths and the s = 1 joins alike) by kind, and the disc of the sources at
  // infinity.
  std::string describe() const;

  struct Scratch;

 private:
  const SceneViews& v_;
  Estimator est_;
  int width_, height_;
  Pinhole cam_;
  std::vector<int32_t> lights_;  // the sources with power, in table order
  std::vector<float> cdf_;       // their power, cumulated (last 1)
  std::vector<float> pmf_;       // per source of the table: its pick probability
  std::vector<int32_t> skies_;   // the table's skies (LightKind::infinite)
  std::vector<int32_t> medium_out_, medium_in_;  // per source: the medium it emits into (source_media)
  float centre_[3] = {0.f, 0.f, 0.f}, radius_ = 1.f;  // the scene's bounding sphere
  std::unique_ptr<BdptPool> pool_;
};

}  // namespace tuile
