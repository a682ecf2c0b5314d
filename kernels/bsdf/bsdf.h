// The BSDF interface every stage uses for f, its pdf and sampled directions, lane-generic
// (T = float, the scalar reference, or a SIMD batch):
//   eval(sp, wi)       -> {f, pdf}            f in 1/sr per channel, pdf in solid angle
//   sample(sp, u1, u2) -> {wi, weight, pdf, delta, valid}   weight = f cos / pdf
//   pdf(sp, wi)        -> pdf                 the density sample() draws wi with
// where sp is the shading point's local geometry (SurfacePoint) and wi points away from
// the surface, world space. The shape of yocto-gl's eval_bsdfcos / sample_bsdfcos /
// sample_bsdfcos_pdf and Mitsuba 3's BSDF::eval / sample / pdf.
//
// To add a BSDF: a struct with these three members, its parameters loaded per lane from
// the shading points (ShadingPoints in wave/tile.h), and a chi-square test of sample()
// against pdf() plus a check that weight = f cos / pdf (tests/test_bsdf.cpp). A BSDF that
// reads the direction towards the viewer sets reads_wo, so that the stages load it.
#pragma once
#include "lanes/simd.h"
#include "lanes/vec.h"

namespace tuile {

// The surface kinds of pbrt-v4's materials tuile renders (kernels/bsdf), in the order of
// their bit in Features::bsdfs.
enum class MaterialKind : int32_t {
  diffuse = 0,               // Lambert: reflectance
  conductor = 1,             // Trowbridge-Reitz microfacets, complex Fresnel (eta, k); smooth: a mirror
  dielectric = 2,            // eta, smooth (delta) or Trowbridge-Reitz reflection + transmission
  thin_dielectric = 3,       // eta, a thin slab: delta reflection and straight transmission
  diffuse_transmission = 4,  // Lambert reflection (reflectance) and transmission (transmittance)
  coated_diffuse = 5,        // a dielectric coat (eta, alphas) over a diffuse base (reflectance)
  coated_conductor = 6,      // a dielectric coat over a conductor base (eta_rgb, k_rgb, base alphas)
  hair = 7,                  // pbrt-v4's HairBxDF (bsdf/hair.h): sigma_a, eta, beta_m, beta_n, alpha
  // a point inside a participating medium (wave/media.h): Henyey-Greenstein's phase function
  // (medium/homogeneous.h) in place of a BSDF, f = pdf = p(wo, wi) with no cosine; never a
  // scene's material, one row of the material table per medium (render/views.cpp)
  phase = 8,
};
inline constexpr int material_kind_count = 9;
inline constexpr const char* material_kind_names[material_kind_count] = {
    "diffuse", "conductor", "dielectric", "thindielectric", "diffusetransmission", "coateddiffuse", "coatedconductor", "hair",
    "phase"};

// --light-paths (src/render/light_paths.h): the kinds at which the light tracer joins its
// paths to the camera, and which the path tracer therefore leaves it as a path's first
// vertex: the rough ones, whose value is bounded whatever the directions (Lambert, diffuse
// transmission, a medium's phase function). A glossy or coated surface's value is large
// near its mirror direction, which a light path would hit by chance: the path tracer,
// which samples that lobe, keeps them (an area light's caustics: measured on staircase2's
// coated floor).
inline bool light_traced_kind(int32_t kind) noexcept {
  return kind == static_cast<int32_t>(MaterialKind::diffuse) || kind == static_cast<int32_t>(MaterialKind::diffuse_transmission) ||
         kind == static_cast<int32_t>(MaterialKind::phase);
}

// The kinds whose top lobe is a Trowbridge-Reitz microfacet lobe of alphas mp_ax, mp_ay
// (regularization's twins, --light-paths' near-specular flags).
inline bool microfacet_kind(int32_t kind) noexcept {
  return kind == static_cast<int32_t>(MaterialKind::conductor) || kind == static_cast<int32_t>(MaterialKind::dielectric) ||
         kind == static_cast<int32_t>(MaterialKind::coated_diffuse) ||
         kind == static_cast<int32_t>(MaterialKind::coated_conductor);
}

// One bit per MaterialKind, in its order.
enum BsdfBits : unsigned {
  bsdf_diffuse = 1u << 0,
  bsdf_conductor = 1u << 1,
  bsdf_dielectric = 1u << 2,
  bsdf_thin_dielectric = 1u << 3,
  bsdf_diffuse_transmission = 1u << 4,
  bsdf_coated_diffuse = 1u << 5,
  bsdf_coated_conductor = 1u << 6,
  bsdf_hair = 1u << 7,
  bsdf_phase = 1u << 8,
  bsdf_all = (1u << 9) - 1,
};
// Kinds that can send light through the surface, and kinds with a specular (delta) lobe.
inline constexpr unsigned bsdf_transmits =
    bsdf_dielectric | bsdf_thin_dielectric | bsdf_diffuse_transmission | bsdf_hair | bsdf_phase;
inline constexpr unsigned bsdf_delta_capable =
    bsdf_conductor | bsdf_dielectric | bsdf_thin_dielectric | bsdf_coated_diffuse | bsdf_coated_conductor;


template <class T> struct Rgb3 {
  T r, g, b;
};

// The local geometry a BSDF is evaluated at: the shading normal (unit, on the side of
// the incoming ray) and, for BSDFs with reads_wo, the unit direction towards the viewer.
template <class T> struct SurfacePoint {
  Vec3<T> n;
  Vec3<T> wo;
};

template <class T> struct BsdfEval {
  Rgb3<T> f;  // the BSDF's value (1/sr), per channel
  T pdf;     // the density sample() gives wi, solid-angle measure
};

template <class T> struct BsdfSample {
  Vec3<T> wi;       // unit, world space
  Rgb3<T> weight;    // f cos / pdf, per channel
  T pdf;            // solid-angle measure (meaningless where delta)
  mask_t<T> delta;  // a specular lobe: no other technique can hit wi
  mask_t<T> valid;  // false: no direction (weight 0)
};

}  // namespace tuile
