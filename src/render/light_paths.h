// Light paths (--light-paths, Estimator::light_paths): a light tracer for the caustic paths
// a path tracer finds only by chance, splitting path space with it.
//
// The split. A path from the camera to an area light, x1 (the camera's hit) ... xk (next to
// the light), belongs to the light tracer when xk scattered by a delta lobe (a mirror, smooth
// glass) and x1 is rough (light_traced_kind: a diffuse surface, diffuse transmission, a point
// in a medium): the caustics seen directly on diffuse surfaces and in media, whatever lies
// between x1 and xk. (A glossy or coated x1 stays the path tracer's: joined to the camera,
// its value near the mirror direction, met by chance, made fireflies far worse than the
// path tracer's, which samples that lobe; measured on staircase2's coated floor.) The
// path tracer counts them only through a BSDF sample of a delta lobe that meets the light
// (no light sample has a value there), so it drops exactly those emitter hits
// (drop_light_traced_hits) and counts everything else as before; the light tracer counts
// exactly these paths. Each estimator is unbiased for its part, so the sum is. The sky and
// emitting media are the path tracer's alone (it reaches them by light samples); distant
// sources below.
//
// Point and spot sources. A path whose vertex next to one scattered by a delta lobe has no
// sample of the path tracer's at all: a light sample stops at the lobe and no BSDF sample
// meets a point, so a path tracer renders no caustic of a point or spot source (pbrt-v4's
// `path` neither). The light tracer takes exactly those paths, emitting from the source's
// position (uniform on the sphere, or in a spot's cone with its falloff in the weight, the
// throughput I falloff / (p(source) pdf(d))) with the first vertex a delta lobe's, as from
// an area source, into the medium the source sits in (Light::medium: pbrt-v4's outside
// medium at its LightSource); the path tracer leaves nothing out.
//
// Distant sources (a sun). A path whose vertex next to a distant source is near-specular (a
// microfacet lobe of alphas at most sun_glossy_alpha, 0.25, constant: GeomView::mat_lt_glossy;
// the light of a cup's coat of roughness 0.01, which the path tracer meets only when a BSDF
// sample from the rough vertex before finds the highlight's direction) and whose first
// vertex is rough or a coated diffuse of alphas coat_join_alpha or more (sun_traced_material,
// wave/path.h; the path tracer's first_rough 0.5 for a coat: the chairs of dining-room in the
// glints off its cups, whose samples from the coat find a highlight narrower than the coat's
// lobe by chance) belongs to the light tracer too; its light paths from a distant source
// join coated diffuse vertices to the camera as well as rough ones. The path tracer reaches
// such a path only by the light sample at xk, so it drops exactly those light samples
// (sample_lights.h, where LightView::lt_glossy and mat_lt_glossy are set). The light tracer emits from a
// distant source towards those surfaces alone: a point uniform on discs, one per surface
// whose material is flagged (its bounding sphere seen along the source's direction), the
// density at a point the number of discs holding it over their total area, the ray coming
// from beyond the scene's bounds along the source's direction; its first vertex must be a
// flagged material that scatters by a non-delta lobe, or smooth glass's delta lobe. A delta
// lobe's light from a delta source (a sun through a window's glass) is no path of the path
// tracer's at all: its light sample stops at the lobe. So the discs are round the surfaces
// of smooth glass (dielectric, thin dielectric) too, and such a light path joins the camera
// where a point source's does (below); the path tracer leaves nothing out for them. Not
// round mirrors and smooth coats: their share of a sun's light is small where the sun
// lights the room directly, and the light paths' rare splats there cost more than the
// light they add (classroom's stainless chairs: 0.03% of its image, one seed in six
// relMSE 0.10 -> 0.34); those paths stay unsampled, as in a path tracer. Flagged: conductors, dielectrics and coats with
// constant alphas in [smooth_alpha, sun_glossy_alpha] (light_traced_alpha, 0.1, where an
// area source's light is taken too: one flag per material), on meshes and spheres; not in
// scenes with media or instances (the disc bounds and the source's medium: the path
// tracer keeps those paths).
//
// Area sources at near-specular vertices (--light-paths=glossy, Estimator::
// light_paths_glossy). A path whose vertex next to an area source is flagged as above and
// whose first vertex is rough is the light tracer's too: veach-mis's caustics of its small
// bright sphere off its smoothest plate onto the wall, which the path tracer finds once in
// a million samples, each worth thousands of its pixel. There MIS has two techniques at the
// flagged vertex, so the path tracer leaves out both: its light samples there
// (sample_lights.h, LightView::lt_glossy set for the area sources too) and its BSDF
// samples' emitter hits from there (drop_light_traced_hits); the light tracer emits from
// the source as from any area source and takes a flagged material's non-delta lobes at its
// first vertex besides delta ones. Not auto's choice: on rooms whose error is not in such
// caustics it costs more than it saves (the kitchen: 0.90x the efficiency).
//
// The light tracer. Per sample, one path per pixel of the image (a tile's pixels key the
// sampler; the path may land anywhere): a source picked by power, a point uniform on it, a
// cosine-weighted direction, the throughput Le A pi / p(source). Its first vertex must take a
// delta lobe's sample (else the path is the path tracer's and ends). From its second vertex
// on, every rough vertex (light_traced_kind) is joined to the camera (a pinhole: its point projects to a raster
// position, whose pixels get the contribution through the pixel filter, normalised): the
// BSDF with the camera as the viewer, the cosine at the vertex, the camera's importance
// |M q|^3 / (A |det M|) per unit solid angle and pixel (A the screen window's area at
// camera distance 1, q the direction in camera space, M world_from_camera), 1 / d^2, and the
// transmittance to the camera through media and interfaces (the shadow stages). Then the
// path goes on along a BSDF sample with the adjoint's weight: the radiance transport's
// f cos / p times etap^2 for a transmission through a dielectric (importance carries no
// 1 / eta^2) and Veach's shading-normal factor |ns.wo| |ng.wi| / (|ng.wo| |ns.wi|); Russian
// roulette on its throughput over its first one. The hit, medium, texture and BSDF stages
// are the path tracer's (bounce_hits, medium_flights, SurfaceBsdf), run on the tile's
// buffers after its camera samples.
//
// Determinism. A tile's splats (pixel, value) are kept in the order its paths made them and
// added to the film in tile order once every tile of a batch of samples is done (the
// renderer, render_range), so the image does not depend on threads or tile order. The
// sampler's pairs are the ones after the path tracer's deepest (first_pair). A source emits
// into the medium its shape's MediumInterface names on the side it emits to (vacuum without
// one), as pbrt-v4's light paths do.
#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "accel/embree.h"
#include "light/table.h"
#include "render/pinhole.h"
#include "render/views.h"
#include "wave/estimator.h"
#include "wave/tile.h"

namespace tuile {

// What --light-paths auto (the default) turns on: whether the scene holds paths that the
// path tracer finds only by chance and the light tracer at a steady rate, where the light
// tracer's cost per sample is known to pay (bench/results.md, "Light paths by default" and
// "Area sources' glossy caustics"):
// - glossy (--light-paths=glossy), when glossy_allowed (not --strategy ris): small bright
//   sources' glints, at least 1% of the area sources' power falling on near-specular
//   surfaces (constant alphas in [smooth_alpha, light_traced_alpha]) from a source that
//   looks small from them (its solid angle plus the lobe's below 0.003 sr: a lamp a
//   hundredth of its distance across over a near-mirror), in a scene without media or
//   instances; estimated from each triangle's centre, occlusion left out;
// - on, the sun's glints: a distant source and, on a mesh or sphere, a material of constant
//   alphas in [smooth_alpha, light_traced_alpha] (through a mix too), in a scene without
//   media or instances (the paths the light tracer takes from a distant source);
// - on, volumetric caustics: an area light, a surface with a delta lobe (constant alphas
//   below smooth_alpha, or thin glass) and a medium that scatters (a caustic in a fog,
//   which a light sample never reaches).
// - on, caustics onto surfaces from small sources: at least 0.3% of the area sources' power
//   falling on smooth glass or mirrors (area_caustic_share) from a source that looks small
//   from them (below 0.003 sr; veach-bidir's spot lamp over its glass egg: 0.016).
// - on, a point or spot source's caustics: such a source and a surface with a delta lobe;
//   and a distant source's through a window: such a source and
//   smooth glass (dielectric or thin), in a scene without media or instances. No cost
//   is weighed here: without the light tracer those paths are missing from the image, not
//   noisy.
// An area light's caustics through glass onto surfaces from large sources are not enough:
// there the path tracer's own samples of them cost less (staircase2, 1.3e-4: 0.68x the
// efficiency with light paths; kitchen 0.89x, bathroom 0.89x, living-room-3 0.94x, whose
// glass and mirrors see only large sources), nor are its glints off rougher lobes or from
// larger sources (kitchen 0.90x, bathroom 0.87x, staircase2 0.70x with
// --light-paths=glossy). Scene-level facts only (no views), so that the flags can resolve
// it.
enum class LightPathsPay { no, on, glossy };
LightPathsPay light_paths_pay(const Scene& scene, bool glossy_allowed);
// The share of the area sources' power that falls on near-specular surfaces from a source
// whose highlight there is small (light_paths_pay's glossy choice): each triangle's (a
// sphere's six points') light from each source taken as from a point of its power and
// normal, without occlusion; 0 without area sources.
double area_glint_share(const Scene& scene);
// The same for the delta lobes (constant alphas below smooth_alpha, thin glass): the share
// of the area sources' power that falls on smooth glass and mirrors from a source that looks
// small from them (light_paths_pay's caustics onto surfaces).
double area_caustic_share(const Scene& scene);
// Lane i's ray (a light path's next segment) from org along the unit d, traced to the
// nearest hit (tb.bounce, tb.tech.valid): the light tracer's and bdpt's.
void set_light_ray(TileBuffers& tb, int i, const Vec3<float>& org, const Vec3<float>& d);
// The adjoint's factor on a light path's BSDF sample wi at a surface point (geometric normal
// ng, shading normal ns, wo towards the vertex before; material mat of kind `kind`, the
// viewer's side `side`): Veach's shading-normal factor |ns.wo| |ng.wi| / (|ng.wo| |ns.wi|)
// where the scene has shading normals, and etap^2 on a transmission through a dielectric
// (importance carries no 1 / eta^2).
float adjoint_factor(const GeomView& G, int32_t mat, int32_t kind, float side, const Vec3<float>& ng, const Vec3<float>& ns,
                     const Vec3<float>& wo, const Vec3<float>& wi);

// An area source's alpha at its point y (1 without a cut-out): a point drawn on a cut-out
// emitter emits its alpha times the radiance, as the path tracer's light samples weigh it
// (wave/sample_lights.h apply_light_alpha); the rays that meet it pass its holes (Embree's
// filters). The light tracer's and bdpt's.
float emitter_alpha(const LightView& L, int32_t l, const Vec3<float>& y);

// The medium each source of the light table emits into (-1: vacuum): out, an area source's
// on the side of its shape its normal is on (in, behind it: a two-sided source's back); a
// point or spot source's, the one it sits in (Light::medium, out); a source at infinity's,
// -1. All -1 in a scene without media. The light tracer's and bdpt's.
void source_media(const Scene& scene, const SceneViews& v, std::vector<int32_t>& out, std::vector<int32_t>& in);

// Point and spot sources (positional: on no surface, a delta in position).
bool positional_light(int32_t type);
// pbrt-v4's spot falloff at cos_t from the spot's axis: smoothstep from the cone's edge
// (g.e2.y, the cosine of its total width) to the falloff's start (g.e2.x).
float spot_falloff(const LightGeom<float>& g, float cos_t);
// A positional source's emitted direction from (u, v): uniform on the sphere for a point
// source, uniform in the cone for a spot (pbrt-v4's SampleUniformCone), the falloff at d
// in `falloff` (1 for a point source); returns the density per unit solid angle.
float sample_positional_direction(int32_t type, const LightGeom<float>& g, float u, float v, Vec3<float>& d, float& falloff);
// pbrt-v4's power of a positional source whose intensity has luminance lum: 4 pi lum, a
// spot's 2 pi lum (1 - (cos_start + cos_end) / 2).
double positional_power(int32_t type, const LightGeom<float>& g, double lum);

class LightPaths {
 public:
  // Sets v's mat_lt_glossy and lt_glossy where distant sources are traced (the path
  // tracer's stages read them); lo, hi: the scene's bounds.
  LightPaths(const Scene& scene, SceneViews& v, const Estimator& est, int width, int height, const float lo[3],
             const float hi[3]);
  // Something to trace: an area, point or spot light and a surface that can scatter by a
  // delta lobe, or a distant source and a near-specular surface.
  bool active() const { return active_; }
  const std::string& why_inactive() const { return why_; }
  // What it emits from: the sources by kind, and a distant source's discs (round how many
  // near-specular surfaces and surfaces with a delta lobe, or one round them all).
  std::string describe() const;
  // The light paths of the pixels of tile `tile` for samples [begin, end), their splats
  // appended to out; rejected counts contributions that were not finite.
  void trace_tile(const Accel& accel, TileBuffers& tb, int tile, int tile_size, int tiles_x, uint32_t begin, uint32_t end,
                  uint32_t first_pair, std::vector<LightPathSplat>& out, uint64_t& rejected) const;

 private:
  const SceneViews& v_;
  Estimator est_;
  int width_, height_;
  bool active_ = false;
  std::string why_;
  std::vector<int32_t> lights_;      // the area sources, the point and spot ones, then the distant ones
  std::vector<float> cdf_;           // their power, cumulated (last 1)
  std::vector<float> pmf_;
  std::vector<int32_t> medium_out_;  // per area source: the medium on its normal's side, and behind it
  std::vector<int32_t> medium_in_;
  // distant sources: the discs they emit through (centre, radius: the flagged surfaces'
  // bounding spheres), picked by area (cdf), their total area, the scene's bounding sphere
  struct Disc {
    float cx, cy, cz, r;
  };
  std::vector<Disc> discs_;
  std::vector<float> disc_cdf_;
  double disc_area_ = 0;
  bool area_glossy_ = false;        // area sources' light at near-specular vertices is the light tracer's too
  bool sun_through_glass_ = false;  // distant sources' light through smooth glass is the light tracer's (no media, instances)
  bool glossy_discs_ = false;       // some disc is round a near-specular surface
  int near_specular_surfaces_ = 0, glass_surfaces_ = 0;  // the discs' surfaces (before merging)
  std::vector<uint8_t> sun_glass_;  // per material: smooth glass a distant source's light paths go through (sun_through_glass_)
  float scene_c_[3] = {}, scene_r_ = 0;
  std::optional<Pinhole> cam_;  // the camera (set where active)

  // mat_lt_glossy and the discs (round the flagged surfaces, and with sun_through_glass
  // round those of smooth glass too: sun_glass_)
  void flag_glossy(const Scene& scene, SceneViews& v, bool sun_through_glass);
  void emit_distant(int32_t l, float pmf, float u, float u2, float u3, TileBuffers& tb, int i) const;
};

}  // namespace tuile
